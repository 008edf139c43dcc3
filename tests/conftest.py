"""Fixtures shared by the test modules."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uqgear.diagnosis.case import prepare_case
from uqgear.physics.design import load_design
from uqgear.rig.format import read_rig, rig_design

#: Test files that take longest (minutes on 2 cores, measured), started first: with one file per
#: process (pytest-xdist's --dist loadfile) a long file collected last would finish alone.
LONGEST_FIRST = ("test_packaging.py", "test_study.py", "test_diagnosis.py", "test_dynamics.py",
                 "test_calibration.py", "test_cli.py", "test_blindtest.py", "test_diagnosis_multi.py",
                 "test_reference.py", "test_prediction.py", "test_calibration_discrepancy.py")


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


@pytest.fixture(scope="module")
def healthy_case():
    """The labelled healthy campaign prepared for diagnosis (features, noise, processing)."""
    rig = read_rig(RIG_DATA / "healthy.nc")
    return prepare_case(rig, rig_design(rig), seed=np.random.SeedSequence(0))
