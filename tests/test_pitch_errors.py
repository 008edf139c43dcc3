"""Pitch errors: per-tooth offsets in the pair loop (docs/model/equations.md section 2.6) and the rig's ISO draw."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import uqgear
from uqgear.common.errors import OperatingPointError
from uqgear.physics import _kernels as K
from uqgear.physics.effects import EFFECTS, make_effect
from uqgear.physics.model import build_model
from uqgear.physics.pitch_errors import PitchErrors, draw_pitch_errors, iso1328_single_pitch_tolerance
from uqgear.rig.virtual_rig import simulate_campaign
from uqgear.uq.seeds import as_seed_sequence, child_seed


@pytest.fixture(scope="module")
def grade7(design):
    return draw_pitch_errors(design, 7, np.random.default_rng(np.random.SeedSequence(7)))


def _relative(run, reference, name="x"):
    a, b = run[name].values, reference[name].values
    return float(np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean((b - b.mean()) ** 2)))


# --------------------------------------------------------------------------- zero errors change nothing

def test_zero_pitch_errors_give_the_results_without_any_bit_for_bit(design):
    zeros = PitchErrors.zeros(design)
    for method, periods in (("fast", 80), ("scipy", 30)):
        kw = {"method": method, "n_periods": periods, "keep_periods": 10}
        plain = uqgear.simulate(design, 2500.0, 7000.0, 33000.0, **kw)
        with_zeros = uqgear.simulate(design, 2500.0, 7000.0, 33000.0, pitch_errors=zeros, **kw)
        for name in plain.data_vars:
            assert plain[name].values.tobytes() == with_zeros[name].values.tobytes(), (method, name)
    samples = uqgear.samples_from_mapping({"pinion_speed": [1200.0, 4400.0], "adhesion_torque": [25e3, 33e3]})
    kw = {"n_periods": 100, "keep_periods": 30, "history_per_period": 8, "rig_channels": True, "threads": 1}
    plain = uqgear.simulate_batch(design, samples, **kw)
    with_zeros = uqgear.simulate_batch(design, samples, pitch_errors=zeros, **kw)
    for name in plain.data_vars:
        assert plain[name].values.tobytes() == with_zeros[name].values.tobytes(), name


def test_the_pair_path_with_zero_offsets_reproduces_the_classical_path(design):
    """Forced onto the per-pair path, zero offsets give the classical result to rounding:
    sum_i k_i f(x) against (sum_i k_i) f(x)."""
    kw = {"effects": [make_effect("friction", {"coefficient": 0.1}), make_effect("tooth_damage", {"depth": 0.3})]}
    for speed, drive, adhesion in ((1700.0, 2000.0, 21146.0), (4400.0, 7000.0, 33000.0)):
        classical = build_model(design, speed, drive, adhesion, **kw)
        forced = build_model(design, speed, drive, adhesion, **kw)
        forced.parameters[K.PITCH_ERRORS] = 1.0
        results = []
        for setup, kernel in ((classical, K.integrate_history), (forced, K.integrate_history_pairs)):
            steps = 96
            history = np.empty((30 * steps, 12))
            kernel(setup.static_state(), setup.parameters, setup.pair_stiffness,
                                setup.period_stiffness, setup.factor_pinion, setup.factor_gear, setup.breakpoints,
                                steps, 120, 30, 1, history, np.empty((30, 6)))
            results.append(history)
        x0, x1 = results[0][:, 2], results[1][:, 2]
        assert np.max(np.abs(x1 - x0)) <= 1e-7 * np.ptp(x0)
        assert np.array_equal(results[0][:, 11], results[1][:, 11])


# --------------------------------------------------------------------------- fast path against the reference

@pytest.mark.parametrize("speed, drive, adhesion", [
    (600.0, 7000.0, 33000.0),     # low speed, every pair loaded
    (1700.0, 2000.0, 21146.0),    # light load: pairs with large offsets lose contact
    (4400.0, 7000.0, 33000.0),    # mesh resonance with tooth separation
])
def test_fast_matches_scipy_with_pitch_errors(design, grade7, speed, drive, adhesion):
    kw = {"n_periods": 150, "keep_periods": 30, "pitch_errors": grade7}
    ref = uqgear.simulate(design, speed, drive, adhesion, method="scipy", **kw)
    fast = uqgear.simulate(design, speed, drive, adhesion, method="fast", **kw)
    plain = uqgear.simulate(design, speed, drive, adhesion, n_periods=150, keep_periods=30)
    for name in ("x", "y1", "y2", "te", "mesh_force"):
        assert _relative(fast, ref, name) <= 1e-3, name
    assert np.mean(ref["contact"].values == fast["contact"].values) >= 0.999
    # and the errors are not lost on the way: the TE moves by more than 10 %
    assert _relative(plain, ref, "te") > 0.1
    assert ref.attrs["contact_events"] >= 0
    assert np.array_equal(fast.attrs["pitch_errors_pinion"], grade7.pinion)


def test_fast_matches_scipy_with_pitch_errors_and_effects(design, grade7):
    effects = [make_effect("friction", {"coefficient": 0.1}), make_effect("tooth_damage", {"depth": 0.3}),
               make_effect("eccentricity", {"amplitude": 12e-6, "kappa": 0.05})]
    kw = {"n_periods": 120, "keep_periods": 60, "pitch_errors": grade7, "effects": effects}
    ref = uqgear.simulate(design, 1700.0, 2000.0, 21146.0, method="scipy", **kw)
    fast = uqgear.simulate(design, 1700.0, 2000.0, 21146.0, method="fast", **kw)
    for name in ("x", "y1", "y2", "te"):
        assert _relative(fast, ref, name) <= 1e-3, name


# --------------------------------------------------------------------------- independent checks

def test_a_common_offset_of_every_pinion_tooth_is_a_pure_shift_of_the_dte(design):
    """F = sum k_i f(x - e) is the classical force at x - e: x moves by e, y1 and y2 do not."""
    e = 4e-6
    common = PitchErrors(np.full(design.z1, e), np.zeros(design.z2))
    for method, periods in (("fast", 120), ("scipy", 40)):
        kw = {"method": method, "n_periods": periods, "keep_periods": 20}
        plain = uqgear.simulate(design, 1700.0, 2000.0, 21146.0, **kw)
        shifted = uqgear.simulate(design, 1700.0, 2000.0, 21146.0, pitch_errors=common, **kw)
        scale = np.ptp(plain["x"].values)
        assert np.max(np.abs(shifted["x"].values - e - plain["x"].values)) <= 1e-6 * scale
        assert np.max(np.abs(shifted["te"].values - e - plain["te"].values)) <= 1e-6 * scale
        for name in ("y1", "y2", "mesh_force"):
            assert np.max(np.abs(shifted[name].values - plain[name].values)) <= 1e-6 * np.ptp(plain[name].values)
        assert np.array_equal(shifted["contact"].values, plain["contact"].values)


def test_one_pinion_tooth_offset_gives_pinion_orders_of_the_quasi_static_amplitude(design):
    """Quasi-static, the mesh force is the torques' F_T, so pinion tooth 0 with an offset e0
    moves the TE by e0 k_0(t) / k(t) while it is in mesh (its share of the mesh stiffness)
    and by nothing otherwise: lines at the pinion rotation orders, computed here from the
    stiffness tables alone."""
    e0 = 3e-6
    z1 = design.z1
    single = np.zeros(z1)
    single[0] = e0
    errors = PitchErrors(single, np.zeros(design.z2))
    per_period = 64
    kw = {"n_periods": 3 * z1, "keep_periods": 2 * z1, "samples_per_period": per_period}
    speed = 30.0   # mesh at 10.5 Hz, pinion orders near 0.5 Hz: far below the first mode (270 Hz)
    plain = uqgear.simulate(design, speed, 7000.0, 33000.0, **kw)
    with_errors = uqgear.simulate(design, speed, 7000.0, 33000.0, pitch_errors=errors, **kw)
    difference = with_errors["te"].values - plain["te"].values
    # expected: tooth 0 is in mesh during meshing numbers 0 mod z1, at u base pitches along the path
    setup = build_model(design, speed, 7000.0, 33000.0)
    eps = setup.derived["contact_ratio"]
    grid = np.linspace(0.0, eps, setup.pair_stiffness.size)
    cycles = plain["time"].values * setup.mesh_frequency
    expected = np.zeros_like(cycles)
    for n_ref in range(z1 * 3):
        u = cycles - n_ref
        in_mesh = (u >= 0.0) & (u < eps)
        if n_ref % z1 == 0 and np.any(in_mesh):
            phase = cycles[in_mesh] - np.floor(cycles[in_mesh])
            total = sum(np.where(phase + i < eps, np.interp(phase + i, grid, setup.pair_stiffness), 0.0)
                        for i in range(math.ceil(eps)))
            expected[in_mesh] += e0 * np.interp(u[in_mesh], grid, setup.pair_stiffness) / total
    # lines at the pinion orders 1..3 over two whole revolutions
    revolutions = 2
    spectrum = np.fft.rfft(difference) / difference.size
    reference = np.fft.rfft(expected) / expected.size
    for order in (1, 2, 3):
        line, want = spectrum[order * revolutions], reference[order * revolutions]
        assert abs(line) == pytest.approx(abs(want), rel=0.03), order
        assert abs(line - want) <= 0.05 * abs(want), order
    # about e0 / z1 on average: a revolution's mean shift
    assert np.mean(difference) == pytest.approx(np.mean(expected), rel=0.03)


# --------------------------------------------------------------------------- ISO 1328-1 and the rig's draw

def test_iso1328_single_pitch_tolerance_by_formula_5():
    # pinion of the locomotive design: d = 189 mm, m_n = 9 mm -> 0.189 + 3.6 + 5 = 8.789 um at class 5
    assert iso1328_single_pitch_tolerance(0.189, 0.009, 5) == pytest.approx(8.789e-6, rel=1e-12)
    assert iso1328_single_pitch_tolerance(0.189, 0.009, 7) == pytest.approx(2 * 8.789e-6, rel=1e-12)
    assert iso1328_single_pitch_tolerance(0.909, 0.009, 6) == pytest.approx(9.509e-6 * math.sqrt(2), rel=1e-12)
    for grade, message in ((0, "1..11"), (12, "1..11"), (7.0, "integer in 1..11"), (True, "1..11")):
        with pytest.raises(OperatingPointError, match=message):
            iso1328_single_pitch_tolerance(0.189, 0.009, grade)


def test_drawn_pitch_errors_have_the_iso_magnitudes(design):
    """Single pitch deviations (e_k - e_{k-1}) / cos(alpha): zero sum, sigma f_pT/2 (less the closure)."""
    rng = np.random.default_rng(np.random.SeedSequence(2024))
    cos_alpha = math.cos(math.radians(design.pressure_angle))
    for teeth, draws_of in ((design.z1, "pinion"), (design.z2, "gear")):
        tolerance = iso1328_single_pitch_tolerance(design.module * teeth, design.module, 7)
        singles = []
        for _ in range(300):
            offsets = getattr(draw_pitch_errors(design, 7, rng), draws_of)
            assert offsets.shape == (teeth,)
            assert abs(np.mean(offsets)) <= 1e-18
            single = (offsets - np.roll(offsets, 1)) / cos_alpha
            assert abs(np.sum(single)) <= 1e-17
            singles.append(single)
        singles = np.concatenate(singles)
        assert np.mean(singles) == pytest.approx(0.0, abs=0.02 * tolerance)
        assert np.std(singles) == pytest.approx(0.5 * tolerance * math.sqrt(1 - 1 / teeth), rel=0.03)
        # about 95 % inside the tolerance
        assert 0.93 <= np.mean(np.abs(singles) <= tolerance) <= 0.97


def test_rig_pitch_errors_are_drawn_from_their_own_stream_and_reproducible(design):
    ops = {"pinion_speed": [1250.0, 3400.0], "drive_torque": [6000.0, 5500.0]}
    kw = {"duration": 0.1, "run_in": 0.05, "seed": 5}
    first = simulate_campaign(design, ops, pitch_errors=7, **kw)
    again = simulate_campaign(design, ops, pitch_errors=7, **kw)
    plain = simulate_campaign(design, ops, **kw)
    for name in ("te", "acc_pinion", "acc_gear"):
        assert first[name].values.tobytes() == again[name].values.tobytes()
        assert not np.allclose(first[name].values, plain[name].values)
    record = json.loads(first.attrs["noise"])["pitch_errors"]
    expected = draw_pitch_errors(design, 7, np.random.default_rng(child_seed(as_seed_sequence(5), 1002)))
    assert record["iso1328_class"] == 7
    assert np.array_equal(record["pinion"], expected.pinion) and np.array_equal(record["gear"], expected.gear)
    assert record["single_pitch_tolerance_pinion"] == pytest.approx(2 * 8.789e-6)
    # every other draw as without pitch errors: the true T2 of each run, the noise streams
    assert json.loads(first.attrs["true_parameters"]) == json.loads(plain.attrs["true_parameters"])
    assert "pitch_errors" not in json.loads(plain.attrs["noise"])
    # explicit offsets, as a mapping: the same campaign
    explicit = simulate_campaign(design, ops, pitch_errors={"pinion": expected.pinion, "gear": expected.gear}, **kw)
    assert explicit["te"].values.tobytes() == first["te"].values.tobytes()
    assert json.loads(explicit.attrs["noise"])["pitch_errors"]["iso1328_class"] is None


def test_pitch_errors_are_no_diagnosis_candidate():
    assert "pitch_errors" not in EFFECTS


# --------------------------------------------------------------------------- input errors

@pytest.mark.parametrize("make, message", [
    (lambda d: PitchErrors(np.zeros(d.z1 - 1), np.zeros(d.z2)).check(d),
     r"pitch_errors.pinion: expected 21 values \(one per tooth\); got 20"),
    (lambda d: PitchErrors(np.zeros(d.z1), np.zeros(d.z2 + 1)).check(d),
     r"pitch_errors.gear: expected 101 values \(one per tooth\); got 102"),
    (lambda d: PitchErrors(np.zeros(d.z1), [0.0, 0.0, 0.0, math.nan]),
     r"pitch_errors.gear\[3\]: expected a finite offset"),
    (lambda d: PitchErrors([0.0, 5.0], np.zeros(d.z2)),
     r"pitch_errors.pinion\[1\]: expected a finite offset within \+-0.001 m \(SI metres"),
    (lambda d: PitchErrors(np.zeros((2, 2)), np.zeros(d.z2)), r"pitch_errors.pinion: expected a 1-D array"),
    (lambda d: PitchErrors(["a"], np.zeros(d.z2)), r"pitch_errors.pinion: expected one pitch offset per tooth"),
    (lambda d: build_model(d, 1000.0, 7000.0, 33000.0, pitch_errors=np.zeros(d.z1)),
     r"pitch_errors: expected a PitchErrors"),
    (lambda d: build_model(d, 1000.0, 7000.0, 33000.0, pitch_errors=PitchErrors(np.zeros(3), np.zeros(d.z2))),
     r"pitch_errors.pinion: expected 21 values"),
    (lambda d: simulate_campaign(d, {"pinion_speed": [1000.0], "drive_torque": [5000.0]}, pitch_errors=12,
                                 duration=0.05, run_in=0.0, seed=1),
     r"pitch_errors: expected an ISO 1328-1 flank tolerance class"),
    (lambda d: simulate_campaign(d, {"pinion_speed": [1000.0], "drive_torque": [5000.0]}, pitch_errors="7",
                                 duration=0.05, run_in=0.0, seed=1),
     r"pitch_errors: expected an ISO 1328-1 flank tolerance class \(integer 1..11\), a PitchErrors"),
    (lambda d: simulate_campaign(d, {"pinion_speed": [1000.0], "drive_torque": [5000.0]},
                                 pitch_errors={"pinion": np.zeros(d.z1)}, duration=0.05, run_in=0.0, seed=1),
     r"pitch_errors: expected the keys pinion and gear"),
])
def test_bad_pitch_errors_are_named(design, make, message):
    with pytest.raises(OperatingPointError, match=message):
        make(design)


def test_pitch_errors_are_read_only_and_described(design, grade7):
    with pytest.raises(ValueError):
        grade7.pinion[0] = 1.0
    assert "21 teeth" in repr(grade7) and "101 teeth" in repr(grade7)
    assert not PitchErrors.zeros(design).any and grade7.any


def test_a_draw_in_classes_is_the_reference_class_draw_scaled_by_sqrt_2_a_class(design):
    from uqgear.physics.pitch_errors import REFERENCE_CLASS, class_level, draw_in_classes

    assert class_level((REFERENCE_CLASS, REFERENCE_CLASS), 0.3) == 1.0
    assert class_level((5.0, 9.0), np.array([0.0, 0.5, 1.0])) == pytest.approx([0.5, 1.0, 2.0])
    scaled = draw_in_classes(design, (6.0, 8.0), 1.0, np.random.default_rng(4))
    reference = draw_pitch_errors(design, REFERENCE_CLASS, np.random.default_rng(4))
    assert scaled.pinion == pytest.approx(math.sqrt(2.0) * reference.pinion, rel=1e-15)
    assert scaled.gear == pytest.approx(math.sqrt(2.0) * reference.gear, rel=1e-15)
