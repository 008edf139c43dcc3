"""The pair-load extremes the batch kernels keep for the tooth stresses: every path keeps the same, and keeping
them changes nothing else.

References: the one-sample kernel against the SIMD lanes (bit for bit, as for every other QoI), the
classical path against the per-pair path with pitch errors of 1e-15 m (physically none: the same up
to rounding, as tests/test_path_equivalence.py checks the DTE), and the same batch without the
option (every other output bit for bit).
"""

from __future__ import annotations

import numpy as np
import pytest
from effect_families import FAMILIES

import uqgear
from uqgear.physics import batch_setup
from uqgear.physics.batch_setup import PAIR_EXTREME_INFO
from uqgear.physics.pitch_errors import PitchErrors

DESIGN = uqgear.load_design("locomotive")
#: (rpm, T1, T2): in contact, and light near the mesh resonance where the teeth separate and strike
#: on the back side (a negative smallest pair load)
POINTS = ((2000.0, 7000.0, 33.8e3), (4400.0, 2000.0, 21146.0), (3600.0, 7000.0, 25e3))
RUN = {"n_periods": 40, "keep_periods": 24}
#: 1e-15 m on every tooth: the per-pair path; a common offset shifts every pair's deflection alike
OFFSET = 1e-15
#: The classical and per-pair paths' extremes agree to rounding (the DTE does to about 5e-14)
TOLERANCE = 1e-10


def _samples():
    columns = zip(*POINTS, strict=True)
    return uqgear.samples_from_mapping(dict(zip(("pinion_speed", "drive_torque", "adhesion_torque"), columns)))


def _paths(monkeypatch, **kw):
    """The batch by each kernel family: one sample, lanes, pairs, pair lanes."""
    # every group in the lanes, however few its runs
    monkeypatch.setattr(batch_setup, "MINIMUM_FILL", 0.0)
    tiny = PitchErrors(np.full(DESIGN.z1, OFFSET), np.full(DESIGN.z2, OFFSET))
    paths = {"one-sample": (False, None), "lanes": (True, None), "pairs": (False, tiny), "pair lanes": (True, tiny)}
    return {
        path: uqgear.simulate_batch(DESIGN, _samples(), lanes=lanes, pitch_errors=pitch, threads=1, **kw)
        for path, (lanes, pitch) in paths.items()
    }


@pytest.mark.parametrize("family", ["healthy", "tooth_damage", "eccentricity"])
def test_every_kernel_family_keeps_the_same_pair_load_extremes(monkeypatch, family):
    runs = _paths(monkeypatch, effects=FAMILIES[family], stresses=True, **RUN)
    for name in PAIR_EXTREME_INFO:
        assert np.array_equal(runs["lanes"][name].values, runs["one-sample"][name].values), name
        assert np.array_equal(runs["pair lanes"][name].values, runs["pairs"][name].values), name
        assert runs["pairs"][name].values == pytest.approx(runs["one-sample"][name].values, rel=TOLERANCE), name
    extremes = runs["one-sample"]
    # the loads are those of pairs in mesh: positive on the drive side; at the light point the teeth strike back
    assert np.all(extremes["pair_load_max"].values > 0.0) and np.all(extremes["flank_load_gear"].values > 0.0)
    assert extremes["pair_load_min"].values[1] < 0.0 < extremes["pair_load_min"].values[0]


@pytest.mark.parametrize("lanes", [True, False])
def test_keeping_the_extremes_changes_no_other_output(monkeypatch, lanes):
    monkeypatch.setattr(batch_setup, "MINIMUM_FILL", 0.0)
    tiny = PitchErrors(np.full(DESIGN.z1, 2e-6), np.zeros(DESIGN.z2))
    for pitch in (None, tiny):
        kw = {"lanes": lanes, "pitch_errors": pitch, "history_per_period": 8, "rig_channels": True,
              "final_state": True, "threads": 1, "effects": FAMILIES["tooth_damage"], **RUN}
        plain = uqgear.simulate_batch(DESIGN, _samples(), **kw)
        stressed = uqgear.simulate_batch(DESIGN, _samples(), stresses=True, **kw)
        assert set(stressed.data_vars) == set(plain.data_vars) | set(PAIR_EXTREME_INFO)
        for name in plain.data_vars:
            assert np.array_equal(plain[name].values, stressed[name].values, equal_nan=True), (name, pitch)


def test_the_evaluator_option_is_part_of_its_key():
    plain = uqgear.BatchEvaluator(DESIGN, fixed={"pinion_speed": 3000.0}, **RUN)
    stressed = uqgear.BatchEvaluator(DESIGN, fixed={"pinion_speed": 3000.0}, stresses=True, **RUN)
    assert plain.key() != stressed.key()
    out = stressed(uqgear.samples_from_mapping({"adhesion_torque": [25e3]}))
    assert out["pair_load_max"].attrs["units"] == "N" and out["flank_load_pinion"].attrs["units"] == "N m-1"
