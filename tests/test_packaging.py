"""The package as a user installs it: a wheel in a fresh venv, used from an empty folder.

Builds the wheel from this checkout (offline: ``--no-build-isolation``), installs
it (not editable) into a new virtual environment outside the checkout, and from
an empty folder loads the bundled design, runs the bundled smoke study to its
report twice (kernels compiled, then loaded: the same bits, see
tests/test_determinism.py) and calibrates two runs of the shipped rig campaign to its report. The new venv sees
this environment's dependencies through a ``.pth`` line but not its ``uqgear``:
the test checks that what runs is the installed copy.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import numpy as np
import pytest
from test_determinism import COLD_WARM_SCRIPT, differences, float_variables

from uqgear.common.resources import bundled_names

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow


def _run(arguments: list[str], cwd: Path, timeout: float = 900.0) -> subprocess.CompletedProcess:
    environment = {key: value for key, value in os.environ.items() if key not in ("PYTHONPATH", "PYTHONHOME")}
    environment.update({"UQGEAR_PROGRESS": "0", "MPLBACKEND": "Agg", "PIP_NO_INDEX": "1",
                        "NUMBA_CACHE_DIR": str(cwd / ".numba-cache")})
    completed = subprocess.run(arguments, cwd=cwd, env=environment, capture_output=True, text=True,
                               timeout=timeout)
    assert completed.returncode == 0, f"{arguments}\n{completed.stdout[-2000:]}\n{completed.stderr[-4000:]}"
    return completed


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    dist = tmp_path_factory.mktemp("dist")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--quiet",
          "--wheel-dir", str(dist), str(ROOT)], cwd=dist)
    (built,) = dist.glob("uqgear-*.whl")
    return built


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    """Python of a fresh venv with the wheel installed; its dependencies come from this environment."""
    venv = tmp_path_factory.mktemp("venv")
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)], cwd=venv)
    python = venv / "bin" / "python"
    site = Path(_run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     cwd=venv).stdout.strip())
    # this environment's packages, as plain path entries: .pth files there (an editable
    # uqgear) are not processed, so the only uqgear the venv can import is the wheel's
    ours = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "dependencies.pth").write_text("\n".join(sorted(ours)) + "\n")
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "--no-index",
          "--quiet", str(wheel)], cwd=venv)
    return python


def test_the_wheel_carries_the_bundled_files_and_no_source_tree(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    for kind, folder, suffix in (("design", "designs", ".yaml"), ("study", "studies", ".yaml"),
                                 ("rig", "rig", ".nc")):
        for name in bundled_names(kind):
            assert f"uqgear/data/{folder}/{name}{suffix}" in names
    assert not [name for name in names if name.startswith(("tests/", "data/", "studies/", "benchmarks/"))]
    # small: two example campaigns and text
    assert wheel.stat().st_size < 8 * 2**20


def test_the_installed_package_works_from_an_empty_folder(installed, tmp_path):
    work = tmp_path / "empty"
    work.mkdir()
    probe = _run([str(installed), "-c",
                  "import uqgear, uqgear.common; d = uqgear.load_design('locomotive'); "
                  "print(uqgear.__file__); print(d.name); print(uqgear.example_rig_file()); "
                  "print(uqgear.bundled_designs())"], cwd=work).stdout.splitlines()
    assert not probe[0].startswith(str(ROOT)) and "site-packages" in probe[0]
    assert probe[1] == "locomotive"
    assert Path(probe[2]).is_file() and "site-packages" in probe[2]
    assert "locomotive" in probe[3]

    uqgear = installed.parent / "uqgear"
    listing = _run([str(uqgear), "examples"], cwd=work).stdout
    assert "smoke" in listing and "healthy" in listing

    # the first run after install compiles the kernels, the second loads them from the cache the first
    # filled: the batch kernel, the harmonic kernel and the smoke study give the same bits (one cold
    # compilation serves this check and tests/test_determinism.py's)
    script = work / "cold_warm.py"
    script.write_text(COLD_WARM_SCRIPT)
    for state in ("cold", "warm"):
        _run([str(installed), str(script), str(work / f"{state}.npz"), str(work / state)], cwd=work)
        if state == "cold":
            assert any((work / ".numba-cache").rglob("*.nbi")), "the first run did not fill the numba cache"
    cold, warm = np.load(work / "cold.npz"), np.load(work / "warm.npz")
    assert len(cold.files) > 10
    assert differences({k: cold[k] for k in cold.files}, {k: warm[k] for k in warm.files}) == []
    files = sorted(path.name for path in (work / "cold").glob("*.nc"))
    assert len(files) >= 8 and files == sorted(path.name for path in (work / "warm").glob("*.nc"))
    compared = 0
    for file in files:
        first, second = float_variables(work / "cold" / file), float_variables(work / "warm" / file)
        compared += len(first)
        assert differences(first, second) == [], file
    assert compared > 50
    assert (work / "cold" / "report.html").stat().st_size > 10_000

    _run([str(uqgear), "examples", "copy", "smoke", "my_study.yaml"], cwd=work)
    _run([str(uqgear), "validate", "my_study.yaml"], cwd=work)

    # two parameters on two of the shipped campaign's runs, cut out by the installed copy's reader: what is
    # checked is the installed calibration path, not the posterior (tests/test_calibration.py holds the truth
    # on the whole campaign); the model runs of a calibration scale with the runs it fits
    _run([str(installed), "-c", "import uqgear, uqgear.rig; "
          "uqgear.rig.read_rig(uqgear.example_rig_file()).isel(op=[0, 4]).to_netcdf('two_runs.nc')"], cwd=work)
    _run([str(uqgear), "calibrate", "two_runs.nc", "--out", "cal", "--params", "mesh_stiffness_scale", "zeta_mesh"],
         cwd=work)
    assert (work / "cal" / "report.html").is_file()
    assert (work / "cal" / "posterior.nc").is_file()


def test_the_sdist_carries_what_the_test_suite_needs(tmp_path):
    _run([sys.executable, "-c", "import sys; from setuptools import build_meta; "
          f"print(build_meta.build_sdist({str(tmp_path)!r}))"], cwd=ROOT)
    (sdist,) = tmp_path.glob("uqgear-*.tar.gz")
    with tarfile.open(sdist) as archive:
        names = {name.split("/", 1)[1] for name in archive.getnames() if "/" in name}
    assert {"pyproject.toml", "README.md", "CHANGELOG.md", "MANIFEST.in", "data/rig/healthy.nc",
            "data/rig/tooth_damage.nc", "data/rig/README.md", "studies/smoke.yaml", "uqgear/data/rig/healthy.nc",
            ".ci/run", "docs/model/index.md"} <= names
    assert {f"tests/{path.name}" for path in (ROOT / "tests").glob("test_*.py")} <= names
