"""Fixtures shared by the test modules."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

try:
    import fcntl
except ImportError:  # pragma: no cover - not POSIX: each test process runs its own smoke study
    fcntl = None  # type: ignore[assignment]

import numpy as np
import pytest

from uqgear.diagnosis.case import prepare_case
from uqgear.physics.design import load_design
from uqgear.rig.format import read_rig, rig_design

#: Test files that take longest (minutes on 2 cores, measured), started first: with one file per
#: process (pytest-xdist's --dist loadfile) a long file collected last would finish alone.
LONGEST_FIRST = ("test_packaging.py", "test_study.py", "test_diagnosis.py", "test_dynamics.py",
                 "test_calibration.py", "test_cli.py", "test_blindtest.py", "test_diagnosis_multi.py",
                 "test_change_diagnosis.py", "test_cross_channel.py", "test_pitch_error_campaigns.py",
                 "test_reference.py", "test_readme.py", "test_prediction.py", "test_calibration_discrepancy.py",
                 "test_manufacturing.py", "test_sound_failure.py")


def pytest_collection_modifyitems(config, items):
    """Put the longest test files first (a stable sort: the order inside each file is kept)."""
    rank = {name: index for index, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


#: The labelled rig campaigns copied into the repository (data/rig/README.md says what each holds).
RIG_DATA = Path(__file__).resolve().parent.parent / "data" / "rig"


@pytest.fixture(scope="module")
def design():
    """The bundled reference design (docs/model/geometry.md section 3)."""
    return load_design("locomotive")


@pytest.fixture(scope="session")
def healthy_case():
    """The labelled healthy campaign prepared for diagnosis (features, noise, processing).

    Prepared once per test process for every module that reads it: a prepared case is never changed
    (tests/test_diagnosis_estimator.py checks that), and preparing it costs seconds.
    """
    rig = read_rig(RIG_DATA / "healthy.nc")
    return prepare_case(rig, rig_design(rig), seed=np.random.SeedSequence(0))


@contextlib.contextmanager
def _exclusive(lock: Path):
    """Hold ``lock`` against the other test processes."""
    with open(lock, "w") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def smoke_study_run(tmp_path_factory) -> tuple[subprocess.CompletedProcess, Path]:
    """The bundled smoke study run once by name through the real command line, into a new nested folder.

    ``uqgear run smoke --out results/deeper/smoke`` from an empty folder, in a fresh interpreter: the
    finished process and the output folder. The run is the same for every test that reads it, so the
    test processes (pytest-xdist workers) share one: the first to ask runs it under a lock in their
    common temporary folder, the others read its result (without ``fcntl`` each process runs its own).
    Tests copy the folder before changing it.
    """
    root = tmp_path_factory.getbasetemp()
    if fcntl is not None and os.environ.get("PYTEST_XDIST_WORKER") is not None:
        root = root.parent
    record, cwd = root / "smoke-run.json", root / "smoke-run"
    out = Path("results") / "deeper" / "smoke"
    with _exclusive(root / "smoke-run.lock") if fcntl is not None else contextlib.nullcontext():
        if not record.is_file():
            shutil.rmtree(cwd, ignore_errors=True)
            cwd.mkdir()
            environment = {**os.environ, "UQGEAR_PROGRESS": "0", "MPLBACKEND": "Agg"}
            completed = subprocess.run([sys.executable, "-m", "uqgear", "run", "smoke", "--out", str(out)],
                                       cwd=cwd, env=environment, capture_output=True, text=True, timeout=900)
            record.write_text(json.dumps({"returncode": completed.returncode, "stdout": completed.stdout,
                                          "stderr": completed.stderr}))
    finished = json.loads(record.read_text())
    return subprocess.CompletedProcess(["uqgear", "run", "smoke", "--out", str(out)], **finished), cwd / out
