"""Fixtures shared by the test modules."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uqgear.diagnosis import prepare_case
from uqgear.physics.design import load_design
from uqgear.rig.format import read_rig, rig_design

#: The labelled rig campaigns copied into the repository (data/rig/README.md says what each holds).
RIG_DATA = Path(__file__).resolve().parent.parent / "data" / "rig"


@pytest.fixture(scope="module")
def design():
    """The bundled reference design (docs/model.md section 3)."""
    return load_design("locomotive")


@pytest.fixture(scope="module")
def healthy_case():
    """The labelled healthy campaign prepared for diagnosis (features, noise, processing)."""
    rig = read_rig(RIG_DATA / "healthy.nc")
    return prepare_case(rig, rig_design(rig), seed=np.random.SeedSequence(0))
