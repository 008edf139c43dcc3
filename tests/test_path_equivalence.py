"""Every integration path runs one model: the same DTE whichever path a run takes, for every effect and stiffness.

A run takes the per-pair path when it has pitch errors (docs/model/equations.md
section 2.6), in one-sample kernels or in SIMD lanes, and the classical path
otherwise; the scipy reference has both too. Pitch errors of 1e-15 m on every
tooth are physically none, so with and without them every path must give the
same DTE up to rounding: here to 1e-11 relative RMS, for each effect family and
each stiffness table (``ishikawa``, ``fourier``, ``constant``), at an operating
point in contact and at one where the teeth separate. A path with its own copy
of a rule (how a damaged tooth or friction shares a smooth stiffness table,
docs/model/mesh-stiffness.md section 4.2) fails here.
"""

from __future__ import annotations

import numpy as np
import pytest
from effect_families import FAMILIES

import uqgear
from uqgear.physics import batch_setup
from uqgear.physics.model import STIFFNESS_MODES
from uqgear.physics.pitch_errors import PitchErrors

#: Largest relative RMS difference of the DTE between two fast paths of one model: rounding (they
#: agree to about 5e-14; a second rule for a damaged tooth or friction moved them by 2e-4 to 0.4, a
#: second contact-split rule by 3e-8).
TOLERANCE = 1e-11
#: The same between the scipy reference's two right-hand sides at rtol 3e-14 (adaptive steps).
SCIPY_TOLERANCE = 1e-8
#: (rpm, T1, T2): the locomotive in contact, and light on wet rail near the mesh resonance (teeth apart)
POINTS = ((2000.0, 7000.0, 33.8e3), (4400.0, 2000.0, 21146.0))
#: The pitch error of every tooth, m: an offset common to all teeth shifts x by the pair's sum, 2 OFFSET
#: (docs/model/equations.md section 2.6), which the comparison takes off.
OFFSET = 1e-15
SHIFT = 2 * OFFSET
# short runs: a tooth damage shows within one pinion revolution (21 mesh periods)
RUN = {"n_periods": 40, "keep_periods": 24}


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


@pytest.fixture(scope="module")
def tiny(design):
    """1e-15 m on every tooth: no pitch errors physically, but the per-pair path."""
    return PitchErrors(np.full(design.z1, OFFSET), np.full(design.z2, OFFSET))


def _relative(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean((b - b.mean()) ** 2)))


def _batch(design, monkeypatch, pitch_errors, **kw) -> dict[str, np.ndarray]:
    """The DTE histories of :data:`POINTS` by the one-sample kernels and the lanes, classical and per pair."""
    # every group in the lanes, however few its runs (each point is a group of one)
    monkeypatch.setattr(batch_setup, "MINIMUM_FILL", 0.0)
    columns = zip(*POINTS, strict=True)
    samples = uqgear.samples_from_mapping(dict(zip(("pinion_speed", "drive_torque", "adhesion_torque"), columns)))
    paths = {"one-sample": (False, None), "lanes": (True, None), "pairs": (False, pitch_errors),
             "pair lanes": (True, pitch_errors)}
    return {path: uqgear.simulate_batch(design, samples, history_per_period=16, lanes=lanes, threads=1,
                                        pitch_errors=pitch, **kw)["x_history"].values - (SHIFT if pitch else 0.0)
            for path, (lanes, pitch) in paths.items()}


@pytest.mark.parametrize("stiffness", STIFFNESS_MODES)
@pytest.mark.parametrize("family", list(FAMILIES))
def test_every_fast_path_gives_the_same_dte(design, tiny, monkeypatch, family, stiffness):
    kw = {"effects": FAMILIES[family], "stiffness": stiffness, **RUN}
    for point in POINTS:
        classical = uqgear.simulate(design, *point, **kw)["x"].values
        pairs = uqgear.simulate(design, *point, pitch_errors=tiny, **kw)["x"].values - SHIFT
        assert _relative(pairs, classical) <= TOLERANCE, point
    runs = _batch(design, monkeypatch, tiny, **kw)
    reference = runs.pop("one-sample")
    for path, dte in runs.items():
        for i, point in enumerate(POINTS):
            assert _relative(dte[i], reference[i]) <= TOLERANCE, (path, point)


@pytest.mark.parametrize("stiffness", ["fourier", "constant"])
@pytest.mark.parametrize("family", ["tooth_damage", "friction"])
def test_the_scipy_reference_gives_the_same_dte_on_both_paths(design, tiny, family, stiffness):
    """The reference's two right-hand sides (the classical forcing and the per-pair one) share the
    stiffness rule: at rtol 3e-14 they agree to 1e-8 (at 1e-12 the adaptive steps alone differ by
    about that). The damaged tooth (tooth 0) is in mesh in the first periods, all of them kept."""
    kw = {"effects": FAMILIES[family], "stiffness": stiffness, "method": "scipy", "rtol": 3e-14,
          "n_periods": 3, "keep_periods": 3}
    point = POINTS[1]
    classical = uqgear.simulate(design, *point, **kw)["x"].values
    pairs = uqgear.simulate(design, *point, pitch_errors=tiny, **kw)["x"].values - SHIFT
    assert _relative(pairs, classical) <= SCIPY_TOLERANCE


@pytest.mark.parametrize("family", list(FAMILIES))
def test_with_mesh_damping_off_in_separation_every_fast_path_gives_the_same_dte(design, tiny, monkeypatch, family):
    """The damping switch (docs/model/equations.md) is one rule on every path: with the mesh damping off while
    the teeth are apart, the light wet-rail point (teeth separating) gives the same DTE on all of them, and not
    the DTE with the damping on (the switch acts there)."""
    kw = {"effects": FAMILIES[family], "damping_in_separation": False, **RUN}
    point = POINTS[1]
    classical = uqgear.simulate(design, *point, **kw)["x"].values
    pairs = uqgear.simulate(design, *point, pitch_errors=tiny, **kw)["x"].values - SHIFT
    assert _relative(pairs, classical) <= TOLERANCE
    damped = uqgear.simulate(design, *point, **{**kw, "damping_in_separation": True})["x"].values
    assert _relative(damped, classical) > 1e3 * TOLERANCE
    runs = _batch(design, monkeypatch, tiny, **kw)
    reference = runs.pop("one-sample")
    for path, dte in runs.items():
        assert _relative(dte[1], reference[1]) <= TOLERANCE, path
