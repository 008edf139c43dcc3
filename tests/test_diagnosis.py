"""Tests of the sim-to-real gap diagnosis (uqgear.diagnosis).

Fast tests check the pieces against independent truths: Rice-distributed
line amplitudes drawn from complex Gaussian noise, closed-form Rice moments,
white-noise statistics, synthetic rig records with a known fixed-frequency
line, the periodic tiling against a full simulation, the verdict rules on
hand-made rankings, and the model with the README's true parameters against
a labelled campaign. The slow tests run the whole diagnosis on every
labelled campaign in data/rig/ and compare the verdict with the README's label.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import scipy.stats
import xarray as xr
from helpers import candidate_score

from uqgear.common.errors import RigDataError, UqgearError
from uqgear.diagnosis import (
    DiagnosisError,
    decide,
    decide_verdict,
    diagnose,
    effects,
    fit_problem,
    fitting,
    inputs,
    processing,
    scoring,
    screening,
    signatures,
)
from uqgear.diagnosis import case as rig_case
from uqgear.diagnosis import discrepancy as disc
from uqgear.diagnosis import execution as runs
from uqgear.diagnosis import simulation as sim
from uqgear.diagnosis.case import prepare_case
from uqgear.diagnosis.settings import DEFAULT_SETTINGS
from uqgear.physics.design import load_design
from uqgear.rig.features import extract_features
from uqgear.rig.format import make_rig_dataset, read_rig

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"

# Labels of the campaigns in data/rig/ (data/rig/README.md): file -> verdict
LABELLED = {"healthy.nc": "none", "healthy_b.nc": "none", "eccentricity.nc": "eccentricity",
            "tooth_damage.nc": "tooth_damage", "torque_ripple.nc": "torque_ripple",
            "adhesion_oscillation.nc": "adhesion_oscillation", "friction.nc": "friction"}

# True parameters of healthy.nc (data/rig/README.md)
HEALTHY_TRUTH = {"mesh_stiffness_scale": 0.970, "zeta_mesh": 0.052, "backlash": 0.300e-3,
                 "ste_amplitude": 16.07e-6, "k1": 1.010e9, "k2": 1.889e9}
HEALTHY_T2 = [29.78e3, 26.12e3, 30.70e3, 38.23e3, 39.38e3, 27.09e3, 25.82e3, 21.30e3]




def _layout_for_lines(n: int) -> disc.FeatureLayout:
    return disc.FeatureLayout(tuple(f"line{i}" for i in range(n)), ("mesh_harmonic",) * n, ("line",) * n,
                           np.arange(n))


# ---------------------------------------------------------------------------------------------- discrepancies

def test_rice_moments_match_scipy_and_the_normal_limit():
    sigma = np.full(5, 2.0)
    nu = np.array([0.0, 0.5, 2.0, 6.0, 30.0])
    mean, spread = disc._rice_moments(nu, sigma)
    for k in range(nu.size):
        assert mean[k] == pytest.approx(scipy.stats.rice.mean(nu[k] / sigma[k], scale=sigma[k]), rel=1e-7)
        assert spread[k] == pytest.approx(scipy.stats.rice.std(nu[k] / sigma[k], scale=sigma[k]), rel=1e-5)
    # far above the noise (where scipy's series overflows): mean nu + s^2/(2 nu), spread s (1 - s^2/(8 nu^2))
    mean, spread = disc._rice_moments(np.array([3000.0]), np.array([2.0]))
    assert mean[0] == pytest.approx(3000.0 + 4.0 / 6000.0, rel=1e-12)
    assert spread[0] == pytest.approx(2.0 * (1.0 - 4.0 / (8.0 * 3000.0 ** 2)), rel=1e-6)


@pytest.mark.parametrize("nu_over_s", [0.0, 1.5, 8.0, 400.0])
def test_line_discrepancy_is_standard_normal_for_noisy_lines(nu_over_s):
    # amplitude of a line nu plus complex Gaussian noise of s per quadrature: Rice(nu, s) by construction
    rng = np.random.default_rng(3)
    s = 0.7
    n = 40000
    observed = np.abs(nu_over_s * s + s * (rng.standard_normal(n) + 1j * rng.standard_normal(n)))
    noise = disc.NoiseModel(line_scale=np.array([s]), band_power=np.array([1.0, 0.1]),
                         total_power=np.array([1.0, 0.1]), kurtosis_spread=0.1)
    z, scale = disc.standardised_discrepancy(observed.reshape(n, 1, 1, 1), np.full((n, 1, 1, 1), nu_over_s * s),
                                          np.ones((1, 1)), [noise], _layout_for_lines(1),
                                          {"line": 0.0, "band": 0.0, "rms": 0.0, "kurtosis": 0.0})
    z = z.ravel()
    assert abs(z.mean()) < 0.03
    assert z.std() == pytest.approx(1.0, abs=0.03)
    # tail calibration: the Rayleigh floor must not produce excess 3-sigma alarms
    assert np.mean(np.abs(z) > 3.0) < 0.0045
    assert scale.ravel()[0] == pytest.approx(1.0)


def test_model_error_widens_large_lines_only():
    noise = disc.NoiseModel(line_scale=np.array([1.0, 1.0]), band_power=np.array([1.0, 0.1]),
                         total_power=np.array([1.0, 0.1]), kurtosis_spread=0.1)
    model = np.array([0.0, 1000.0]).reshape(1, 1, 2)
    observed = np.array([1.2, 1100.0]).reshape(1, 1, 2)   # a 10 % high line
    errors = {"line": 0.05, "band": 0.0, "rms": 0.0, "kurtosis": 0.0}
    z, scale = disc.standardised_discrepancy(observed, model, np.ones((1, 1)), [noise], _layout_for_lines(2), errors)
    # 100 above a model of 1000 with a 5 % relative error: about 2 sigma, not 100 (the Rice mean
    # sits sigma^2/(2 nu) above nu)
    sigma = math.hypot(1.0, 50.0)
    assert z[0, 0, 1] == pytest.approx((100.0 - sigma ** 2 / 2000.0) / sigma, rel=2e-3)
    assert scale[0, 0, 1] == pytest.approx(math.hypot(1.0, 50.0), rel=1e-6)
    assert scale[0, 0, 0] == pytest.approx(1.0)


def test_band_power_discrepancy_adds_noise_power():
    layout = disc.FeatureLayout(("low_band_rms",), ("low_frequency",), ("band",), np.array([0]))
    noise = disc.NoiseModel(line_scale=np.array([np.nan]), band_power=np.array([0.01, 0.002]),
                         total_power=np.array([1.0, 0.1]), kurtosis_spread=0.1)
    sigma = 3.0
    # a model band RMS of 0.4 plus the noise's 0.01 sigma^2 of mean square: rig value sqrt(0.16 + 0.09)
    observed = np.full((1, 1, 1), math.sqrt(0.16 + 0.01 * sigma ** 2))
    z, _ = disc.standardised_discrepancy(observed, np.full((1, 1, 1), 0.4), np.full((1, 1), sigma), [noise], layout,
                                      {"line": 0.0, "band": 0.1, "rms": 0.0, "kurtosis": 0.0})
    assert abs(z.item()) < 1e-9


def test_band_noise_replaces_the_floor_for_the_low_band_only():
    layout = disc.FeatureLayout(("low_band_rms", "rms"), ("low_frequency", "broadband"), ("band", "rms"),
                                np.array([0, 1]))
    noise = disc.NoiseModel(line_scale=np.array([np.nan, np.nan]), band_power=np.array([0.01, 0.002]),
                            total_power=np.array([1.0, 0.1]), kurtosis_spread=0.1)
    floor, band_noise = 3.0, 1.0
    model = np.array([0.4, 2.0]).reshape(1, 1, 2)
    # the band holds the band's noise, the RMS the floor's
    observed = np.array([math.sqrt(0.16 + 0.01 * band_noise ** 2), math.sqrt(4.0 + floor ** 2)]).reshape(1, 1, 2)
    errors = {"line": 0.0, "band": 0.1, "rms": 0.1, "kurtosis": 0.0}
    z, _ = disc.standardised_discrepancy(observed, model, np.full((1, 1), floor), [noise], layout, errors,
                                         band_noise_std=np.full((1, 1), band_noise))
    assert np.allclose(z, 0.0, atol=1e-9)
    expected = disc.expected_rig_features(model, np.full((1, 1), floor), [noise], layout,
                                          band_noise_std=np.full((1, 1), band_noise))
    assert np.allclose(expected, observed, rtol=1e-12)
    # without it the band expects the floor's noise: a rig band below the prediction
    z_floor, _ = disc.standardised_discrepancy(observed, model, np.full((1, 1), floor), [noise], layout, errors)
    assert z_floor[0, 0, 0] < -1.0 and z_floor[0, 0, 1] == pytest.approx(0.0, abs=1e-9)


def test_band_floor_reads_the_sensor_noise_under_a_forest_of_gear_lines(design):
    # one-second records at 800 rpm: white noise of unit std, a line at every gear order from 150 Hz
    # to 7 kHz rising with the square of frequency (as the accelerations of a manufactured gear pair
    # do), and an oscillation of 25 Hz inside the low band
    fs, size, speed = 20480.0, 20480, 800.0
    options = dict(rig_case.FEATURE_OPTIONS, band_limit=fs / 2.56)
    processor = processing.RunProcessor(design, speed, fs, size, options)
    rng = np.random.default_rng(7)
    time = np.arange(size) / fs
    gear_order = speed / 60.0 * design.z1 / design.z2
    forest = np.zeros(size)
    for frequency in np.arange(math.ceil(150.0 / gear_order), 7000.0 / gear_order) * gear_order:
        forest += 0.4 * (frequency / 1000.0) ** 2 * np.cos(2 * np.pi * frequency * time + rng.uniform(0, 2 * np.pi))
    oscillation = 3.0 * np.cos(2 * np.pi * 25.0 * time)
    noise = rng.standard_normal((6, size))
    plain = processor.band_floor(noise)
    noisy_floor = processor.features(noise + forest + oscillation)[:, processor.columns["noise_std"]]
    under_forest = processor.band_floor(noise + forest + oscillation)
    # 79 bins: the median reads the density to about 16 %, its square root to about 8 % (1 sigma)
    assert np.all(np.abs(plain - 1.0) < 0.25) and abs(plain.mean() - 1.0) < 0.1
    assert np.all(noisy_floor > 2.0)  # the floor between the lines reads the forest, not the sensor
    assert np.all(np.abs(under_forest - 1.0) < 0.25) and abs(under_forest.mean() - 1.0) < 0.1
    # too few bins to read a median: no estimate
    short = processing.RunProcessor(design, speed, fs, 2048, options)
    assert np.isnan(short.band_floor(noise[:1, :2048])).all()


def test_robust_log_density_has_normal_core_and_flat_floor():
    core = disc.robust_log_density(np.array([0.0]), np.array([1.0]))
    assert core.item() == pytest.approx(math.log(0.99 / math.sqrt(2 * math.pi) + 0.01 / 200.0), rel=1e-12)
    far = disc.robust_log_density(np.array([50.0, 5000.0]), np.array([1.0, 1.0]))
    assert far[0] == pytest.approx(far[1])
    assert far[0] == pytest.approx(math.log(0.01 / 200.0), abs=1e-9)
    # a wider prediction pays near the data
    assert disc.robust_log_density(np.array([0.0]), np.array([4.0])).item() < core.item() - 1.0


# ---------------------------------------------------------------------------------------------- gap metric

def test_gap_metric_is_zero_for_noise_and_known_for_offsets():
    rng = np.random.default_rng(0)
    # mean z^2 - 1 scatters by sqrt(2/n) about 0; the square root makes that 0.05 at n = 2e5
    assert scoring.gap_metric(rng.standard_normal(200000)) < 0.1
    assert scoring.gap_metric(np.full(100, 3.0)) == pytest.approx(math.sqrt(8.0))
    # each feature counts at most 10 sigma
    assert scoring.gap_metric(np.full(10, 1e6)) == pytest.approx(math.sqrt(99.0))
    assert scoring.gap_metric(np.array([np.nan, 3.0])) == pytest.approx(math.sqrt(8.0))
    assert math.isnan(scoring.gap_metric(np.array([np.nan])))


def test_shrink_fraction_and_bootstrap():
    assert scoring.shrink_fraction(2.0, 0.5) == pytest.approx(0.75)
    assert scoring.shrink_fraction(0.0, 0.5) == 0.0
    rng = np.random.default_rng(1)
    before = np.full((8, 3, 20), 4.0)
    after = rng.standard_normal((8, 3, 20))
    central, low, high = scoring.bootstrap_shrink(before, after, rng)
    assert central > 0.9 and low > 0.85 and high <= 1.0
    # a gap left as it was does not shrink
    central, low, high = scoring.bootstrap_shrink(before, before, rng)
    assert central == pytest.approx(0.0) and low == pytest.approx(0.0) and high == pytest.approx(0.0)
    # a gap confined to one run, removed by the effect: resamples without that run have no gap
    # to shrink and do not count, so the interval stays at 100 %
    before = rng.standard_normal((8, 3, 20))
    before[1] += 6.0
    after = rng.standard_normal((8, 3, 20))
    central, low, high = scoring.bootstrap_shrink(before, after, rng)
    assert central > 0.9 and low > 0.5
    # ... and one the effect leaves in place is not called shrunk
    central, low, high = scoring.bootstrap_shrink(before, before + 0.01 * rng.standard_normal(before.shape), rng)
    assert abs(central) < 0.05 and low < 0.05
    # nothing to shrink at all
    quiet = rng.standard_normal((8, 3, 20)) * 0.5
    assert scoring.bootstrap_shrink(quiet, quiet, rng) == (0.0, 0.0, 0.0)


# ---------------------------------------------------------------------------------------------- verdict rules

_entry = candidate_score


def test_verdict_none_when_nominal_within_noise():
    verdict, reason = decide_verdict(0.2, [_entry("friction", 4.0, 0.3)])
    assert verdict == "none" and "within noise" in reason
    assert decide_verdict(0.2, [])[0] == "none"


def test_verdict_names_effect_with_score_and_shrink():
    verdict, reason = decide_verdict(3.0, [_entry("tooth_damage", 120.0, 0.95), _entry("friction", 20.0, 0.1)])
    assert verdict == "tooth_damage" and "shrinks" in reason
    # strong evidence names the effect even when the omnibus gap is small
    assert decide_verdict(0.4, [_entry("torque_ripple", 40.0, 0.8)])[0] == "torque_ripple"


def test_verdict_unexplained_when_no_candidate_removes_the_gap():
    assert decide_verdict(3.0, [_entry("eccentricity", 200.0, 0.2)])[0] == "unexplained"
    # a gap just above noise that the effect brings within noise is explained, though it shrank < 50 %
    friction = _entry("friction", 160.0, 0.4, low=0.3, gap_with_effect=0.44)
    verdict, reason = decide_verdict(0.74, [friction])
    assert verdict == "friction" and "within noise" in reason
    # one that leaves a significant gap is named only as a partial explanation, with the rest unexplained
    partial = decide(0.74, [replace(friction, gap_with_effect=0.6)])
    assert partial.verdict == "friction" and partial.partial and partial.remaining_gap == 0.6
    assert decide_verdict(0.74, [replace(friction, gap_with_effect=0.6, shrink_interval=(0.1, 0.6))])[0] \
        == "unexplained"
    assert decide_verdict(0.74, [replace(friction, shrink_interval=(-0.1, 1.0))])[0] == "unexplained"
    assert decide_verdict(3.0, [_entry("eccentricity", 5.0, 0.9)])[0] == "unexplained"
    # a shrink whose interval reaches below zero is not evidence
    assert decide_verdict(3.0, [_entry("friction", 50.0, 0.6, low=-0.2)])[0] == "unexplained"
    assert decide_verdict(3.0, [])[0] == "unexplained"


def test_verdict_never_names_an_effect_that_adds_nothing_to_its_fit():
    """A candidate as good with its effect off owes its score to the refitted nominal parameters."""
    damage = _entry("tooth_damage", 130.0, 1.0)
    assert decide_verdict(0.58, [replace(damage, effect_gain=40.0)])[0] == "tooth_damage"
    assert decide_verdict(0.58, [replace(damage, effect_gain=0.3)])[0] == "unexplained"
    assert decide_verdict(0.3, [replace(damage, effect_gain=0.3)])[0] == "none"


# ---------------------------------------------------------------------------------------------- processing

@pytest.fixture(scope="module")
def short_processor(design):
    options = dict(rig_case.FEATURE_OPTIONS, band_limit=20480.0 / 2.56)
    return processing.RunProcessor(design, 1250.0, 20480.0, 4096, options)


def test_model_features_match_extract_features(design, short_processor):
    rng = np.random.default_rng(5)
    time = np.arange(4096) / 20480.0
    record = (1e-6 * np.cos(2 * np.pi * 437.5 * time + 0.3) + 2e-7 * np.sin(2 * np.pi * 20.83 * time)
              + 1e-8 * rng.standard_normal(time.size))
    signals = xr.Dataset({"te": (("op", "time"), record[None], {"units": "m"})},
                         coords={"time": time, "pinion_speed": ("op", [1250.0])})
    reference = extract_features(signals, design)["te"].values[0]
    ours = short_processor.model_features(record[None])[0]
    both = np.isfinite(ours)
    assert np.allclose(ours[both], reference[both], rtol=1e-10, atol=0.0)
    assert np.allclose(short_processor.features(record[None])[0], reference, rtol=1e-10, equal_nan=True)


def test_line_noise_scale_matches_monte_carlo(short_processor):
    rng = np.random.default_rng(11)
    noise = rng.standard_normal((1500, 4096))
    amplitudes = short_processor.features(noise)[:, short_processor.line_columns]
    # E[A^2] = 2 s^2 for a Rayleigh amplitude of per-quadrature scale s
    monte_carlo = np.sqrt(np.mean(amplitudes ** 2, axis=0) / 2.0)
    exact = short_processor.line_noise[short_processor.line_columns]
    fitted = np.isfinite(exact)
    # 1500 records estimate each scale to about 2 % (1 sigma)
    assert np.allclose(monte_carlo[fitted], exact[fitted], rtol=0.08)


def test_periodic_tiling_matches_full_simulation(design):
    simulator = sim.CampaignSimulator(design, [1250.0], [6000.0], 20480.0, 4096, ("te", "acc_pinion", "acc_gear"))
    periodic = simulator.run(0, design, 1.0, 30000.0, (), "pinion")
    full = simulator.run(0, design, 1.0, 30000.0, (), "free")
    assert periodic.periodic and not full.periodic
    options = dict(rig_case.FEATURE_OPTIONS, band_limit=8000.0)
    processor = processing.RunProcessor(design, 1250.0, 20480.0, 4096, options)
    names = processor.names
    for channel in ("te", "acc_pinion"):
        a = processor.model_features(periodic.records[channel][None])[0]
        b = processor.model_features(full.records[channel][None])[0]
        for feature in ("mesh1", "mesh2", "mesh3", "rms"):
            k = names.index(feature)
            assert a[k] == pytest.approx(b[k], rel=2e-3), (channel, feature)


def test_runs_of_an_operating_point_together_are_each_the_run_alone(design, monkeypatch):
    """Runs integrated together (SIMD lanes) give each run's records bit for bit as the one-sample
    integrator does alone: tiled and whole-record runs, forcing that repeats every mesh period and
    forcing that does not, a run found not to repeat over its window, one with pitch errors."""
    from uqgear.physics import batch_setup
    from uqgear.physics.effects import make_effect
    from uqgear.physics.history_batch import STATE_HISTORY_COLUMNS
    from uqgear.physics.integration import integrate_fast
    from uqgear.physics.model import HISTORY_COLUMNS
    from uqgear.physics.pitch_errors import draw_pitch_errors

    # every group in lanes, however few its runs, so that the lanes are what is compared
    monkeypatch.setattr(batch_setup, "MINIMUM_FILL", 0.0)
    simulator = sim.CampaignSimulator(design, [1250.0], [6000.0], 20480.0, 4096, ("te", "acc_pinion", "acc_gear"))
    tooth = (make_effect("tooth_damage", {"depth": 0.05, "tooth": 3.0}),)
    # deeper, the damage leaves a slow transient: not yet repeating after the run-in, so simulated whole
    deep = (make_effect("tooth_damage", {"depth": 0.3, "tooth": 3.0}),)
    run_out = (make_effect("eccentricity", {"amplitude": 2e-5, "kappa": 0.05}),)
    ripple = (make_effect("torque_ripple", {"amplitude": 0.05}),)
    stiffer = design.replace(k1=design.k1 * 1.2)
    requests = [
        runs.RunTask(0, design, 1.0, 30000.0, (), "mesh"),
        runs.RunTask(0, stiffer, 1.05, 31000.0, (), "mesh"),
        runs.RunTask(0, design, 1.0, 30000.0, tooth, "gear"),
        runs.RunTask(0, design, 0.98, 29000.0, tooth, "gear"),
        runs.RunTask(0, design, 1.0, 30000.0, run_out, "pinion"),
        # a ripple at 6 p times the rotation does not repeat every mesh period: simulated whole
        runs.RunTask(0, design, 1.0, 30000.0, ripple, "mesh"),
        runs.RunTask(0, design, 1.0, 30000.0, deep, "gear"),
        runs.RunTask(0, design, 1.0, 30000.0, tooth, "free"),
        runs.RunTask(0, design, 1.0, 30000.0, (), "free", draw_pitch_errors(design, 7, np.random.default_rng(3))),
    ]
    together = simulator.runs(0, requests)
    windows = [run.window for run in together]
    assert windows[:5] == ["mesh", "mesh", "gear", "gear", "pinion"] and windows[5:] == ["free"] * 4
    columns = [HISTORY_COLUMNS.index(name) for name in STATE_HISTORY_COLUMNS]

    def one_at_a_time(setups, n_periods, keep_periods, samples_per_period, steps_per_mode):
        return [(history[:, columns], poincare) for history, poincare, _ in (
            integrate_fast(setup, n_periods, keep_periods, samples_per_period, steps_per_mode, setup.static_state())
            for setup in setups)]

    monkeypatch.setattr(sim, "integrate_histories", one_at_a_time)
    for task, run in zip(requests, together):
        alone = simulator.run(0, task.design, task.mesh_stiffness_scale, task.adhesion_torque, task.effects,
                              task.periodicity, pitch_errors=task.pitch_errors)
        assert (alone.periodic, alone.window) == (run.periodic, run.window)
        assert all(alone.records[name].tobytes() == run.records[name].tobytes() for name in simulator.channels)


def _largest_prime_factor(number):
    factor, largest = 2, 1
    while factor * factor <= number:
        while number % factor == 0:
            largest, number = factor, number // factor
        factor += 1
    return max(largest, number)


def test_whole_record_window_has_a_fast_fft_length_and_covers_record_and_guards(design):
    """A whole-record run keeps a length with prime factors of at most 11 (fast FFTs), never shorter
    than the record with its guards, out of the fewest whole mesh periods that hold it."""
    speeds = [600.0, 1250.0, 2800.0, 3400.0]
    simulator = sim.CampaignSimulator(design, speeds, [6000.0] * 4, 20480.0, 20480, ("te", "acc_gear"))
    for op, speed in enumerate(speeds):
        periods, samples = simulator.whole_window(op)
        per_period = simulator.samples_per_period[op]
        needed = (20480 / 20480.0 + 2 * sim._GUARD) * design.z1 * speed / 60.0 * per_period
        assert _largest_prime_factor(samples) <= 11
        assert needed <= samples <= needed + 0.02 * needed + per_period
        assert (periods - 1) * per_period < samples <= periods * per_period
    run = simulator.run(0, design, 1.0, 30000.0, (), "free")
    assert {values.shape for values in run.records.values()} == {(20480,)}


def test_runs_are_bit_identical_however_many_workers(healthy_case):
    """Runs are reduced in groups fixed by the task list alone, one BLAS thread everywhere: the worker
    count (and the dispatch order the executor picks from measured costs) never changes a bit."""
    case = healthy_case
    design = case.design
    tasks = [runs.RunTask(op, design, scale, float(case.adhesion_lower[op]), (), "mesh")
             for scale in (0.95, 1.0) for op in (0, 3, 7)]
    tasks += [runs.RunTask(7, design, 1.0, float(case.adhesion_upper[7]), (), "free")]
    alone = [runs.execute_run(case, task) for task in tasks]
    sequential = runs.execute_runs(case, tasks)
    executor = runs.RunExecutor(case, workers=2)
    try:
        assert executor.pool is not None
        first = executor.map(tasks)
        again = executor.map(tasks)          # dispatched in another order, dearest operating point first
    finally:
        executor.close()
    for (a, pa), (b, pb), (c, pc) in zip(sequential, first, again):
        assert np.array_equal(a, b, equal_nan=True) and np.array_equal(a, c, equal_nan=True)
        assert pa == pb == pc
    # reduced alone or in company, a run's features agree to rounding (of each channel's largest line)
    for (a, _), (b, _) in zip(alone, sequential):
        assert np.array_equal(np.isfinite(a), np.isfinite(b))
        for row_a, row_b in zip(a, b):
            finite = np.isfinite(row_a)
            assert np.allclose(row_a[finite], row_b[finite], rtol=1e-9, atol=1e-9 * np.max(np.abs(row_a[finite])))


def test_run_groups_hold_one_operating_point_each_and_keep_every_task():
    task = runs.RunTask
    tasks = [task(op, None, 1.0, 0.0, (), "mesh") for op in [3, 1, 3, 3, 1] + [2] * 19]
    groups = runs.run_groups(tasks)
    assert sorted(index for group in groups for index in group) == list(range(len(tasks)))
    assert all(len({tasks[i].op for i in group}) == 1 for group in groups)
    assert max(len(group) for group in groups) == runs.GROUP_SIZE
    assert [len(group) for group in groups if tasks[group[0]].op == 2] == [8, 8, 3]
    with pytest.raises(RuntimeError, match="one operating point"):
        runs.execute_group(None, tasks[:2])


def test_frequency_locked_line_found_and_order_lines_ignored(design):
    fs, n = 20480.0, 8192
    time = np.arange(n) / fs
    speeds = np.array([600.0, 1300.0, 2100.0, 3100.0])
    rng = np.random.default_rng(2)
    te = np.stack([2e-6 * np.cos(2 * np.pi * 21 * s / 60 * time) + 3e-7 * np.sin(2 * np.pi * 15.0 * time + s)
                   + 2e-7 * np.cos(2 * np.pi * s / 60 * time)          # order-locked 1x line
                   + 1e-9 * rng.standard_normal(n) for s in speeds])
    lower = speeds * 0 + 25000.0
    rig = make_rig_dataset(time=time, pinion_speed=speeds, drive_torque=np.full(4, 6000.0),
                           adhesion_torque_lower=lower, adhesion_torque_upper=lower + 5000.0,
                           channels={"te": te}, design=design, title="synthetic", source="test", history="test")
    case = prepare_case(rig, design, seed=np.random.SeedSequence(0))
    lines = signatures.frequency_locked_lines(case)
    assert [round(line["frequency"]) for line in lines] == [15]
    assert lines[0]["ops"] == [0, 1, 2, 3]
    assert signatures.signature_hints(case, lines)["adhesion_frequency"] == pytest.approx(15.0, abs=2.5)


def test_true_parameters_reproduce_healthy_campaign(healthy_case):
    """With the README's true parameters the model is within noise of healthy.nc (no fit)."""
    case = healthy_case
    problem = fit_problem.FitProblem(case, None)
    lower, upper = case.adhesion_lower, case.adhesion_upper
    vector = problem.vector(HEALTHY_TRUTH, (np.array(HEALTHY_T2) - lower) / (upper - lower))
    vector = vector.copy()
    model, _ = problem.model_features([vector])
    z, _ = problem.discrepancy(model[0])
    z = np.where(case.mask(), z, np.nan)
    assert scoring.gap_metric(z) < 0.2
    assert np.nanmax(np.abs(z)) < 5.0


def test_calibration_posterior_gives_the_nominal_start(healthy_case):
    case = healthy_case
    rng = np.random.default_rng(0)
    draws = {"mesh_stiffness_scale": 0.97, "zeta_mesh": 0.052, "k1": 1.01e9, "backlash": 3.1e-4}
    t2 = case.adhesion_lower + np.linspace(0.1, 0.9, case.n_op) * (case.adhesion_upper - case.adhesion_lower)
    posterior = xr.Dataset({name: (("chain", "draw"), value * (1 + 0.01 * rng.standard_normal((4, 51))))
                            for name, value in draws.items()})
    posterior["adhesion_torque"] = (("chain", "draw", "op"), np.broadcast_to(t2, (4, 51, case.n_op)).copy())
    start, positions = fitting.calibration_start(posterior, case)
    assert set(start) == set(draws)
    for name, value in draws.items():
        assert start[name] == pytest.approx(value, rel=0.01)
    assert np.allclose(positions, np.linspace(0.1, 0.9, case.n_op))
    with pytest.raises(DiagnosisError, match="calibration: the posterior has none of the parameters"):
        fitting.calibration_start(xr.Dataset({"other": ("draw", [1.0])}), case)
    with pytest.raises(DiagnosisError, match="calibration: .*no such file"):
        inputs.load_calibration(DATA / "no_such_calibration")


def test_adhesion_profile_finds_each_runs_torque(healthy_case):
    """From the bottom of every interval, the grid profile puts T2 within a grid step of the truth."""
    case = healthy_case
    problem = fit_problem.FitProblem(case, None)
    lower, upper = case.adhesion_lower, case.adhesion_upper
    truth = (np.array(HEALTHY_T2) - lower) / (upper - lower)
    profiled = fitting.profile_adhesion(problem, problem.vector(HEALTHY_TRUTH, 0.0))
    found = profiled[problem.n_global:]
    step = fitting._T2_GRID[1] - fitting._T2_GRID[0]
    assert np.all(np.abs(found - truth) <= step), (found, truth)


def test_improved_nominal_escapes_a_stuck_nominal_fit(healthy_case):
    """A fit that moved the nominal parameters to a better optimum restarts the nominal fit; a worse one does not."""
    case = healthy_case
    problem = fit_problem.FitProblem(case, None)
    lower, upper = case.adhesion_lower, case.adhesion_upper
    positions = (np.array(HEALTHY_T2) - lower) / (upper - lower)
    # a nominal fit stopped far off: damping and STE amplitude 60 % high, two solver steps
    wrong = dict(HEALTHY_TRUTH, zeta_mesh=1.6 * HEALTHY_TRUTH["zeta_mesh"],
                 ste_amplitude=1.6 * HEALTHY_TRUTH["ste_amplitude"])
    stuck = fitting.fit(problem, [problem.vector(wrong, positions)], max_evaluations=2)
    good = fitting.fit(problem, [problem.vector(HEALTHY_TRUTH, positions)], max_evaluations=2)
    assert good.cost < stuck.cost - DEFAULT_SETTINGS.nominal.nominal_margin
    better = screening.improved_nominal(stuck, [good])
    assert better is not None and better.cost <= good.cost + DEFAULT_SETTINGS.nominal.nominal_margin
    assert better.values["zeta_mesh"] == pytest.approx(HEALTHY_TRUTH["zeta_mesh"], rel=0.15)
    assert screening.improved_nominal(good, [stuck]) is None
    assert screening.improved_nominal(good, []) is None


def test_full_fit_refines_an_earlier_full_fit_of_its_candidate(healthy_case):
    """A full fit given its candidate's full fit against an earlier base starts there, Cauchy stage alone.

    From that optimum it takes fewer evaluations and ends no higher; an
    earlier fit worse than the usual starts leaves the fit as it was, bit for bit.
    """
    case = healthy_case
    problem = fit_problem.FitProblem(case, None)
    positions = (np.array(HEALTHY_T2) - case.adhesion_lower) / (case.adhesion_upper - case.adhesion_lower)
    base = fitting.fit(problem, [problem.vector(HEALTHY_TRUTH, positions)], max_evaluations=2)
    candidate = effects.candidates_for("friction", case.design)[0]
    screened = fitting.fit_candidate(case, candidate, base, full=False, max_evaluations=2)
    settings = {"full": True, "max_evaluations": 4, "start": screened}
    plain = fitting.fit_candidate(case, candidate, base, **settings)
    again = fitting.fit_candidate(case, candidate, base, **settings, earlier=plain)
    assert again.cost <= plain.cost
    assert again.evaluations < plain.evaluations
    # the same fit far off (mesh damping 60 % high): the usual starts win, nothing changes
    far = plain.vector.copy()
    index = [spec.name for spec in plain.problem.specs].index("zeta_mesh")
    far[index] = plain.problem.vector(dict(plain.values, zeta_mesh=1.6 * plain.values["zeta_mesh"]), 0.0)[index]
    ignored = fitting.fit_candidate(case, candidate, base, **settings, earlier=replace(plain, vector=far))
    assert np.array_equal(ignored.vector, plain.vector) and ignored.cost == plain.cost


# ---------------------------------------------------------------------------------------------- bad input

def test_unknown_effect_is_rejected(tmp_path):
    with pytest.raises(DiagnosisError, match="effects: 'gear_whine' is not a library effect"):
        diagnose(DATA / "healthy.nc", tmp_path, effects=["gear_whine"])
    with pytest.raises(UqgearError, match="effects"):
        effects.candidates_for("wear", load_design("locomotive"))


def test_invalid_rig_inputs_are_rejected(tmp_path):
    with pytest.raises(RigDataError, match="rig data file not found"):
        diagnose(tmp_path / "missing.nc", tmp_path / "out")
    broken = tmp_path / "broken.nc"
    broken.write_text("not a netCDF file")
    with pytest.raises(RigDataError, match="broken.nc"):
        diagnose(broken, tmp_path / "out")
    rig = read_rig(DATA / "healthy.nc")
    rig.attrs["conventions"] = "other/1"
    with pytest.raises(RigDataError, match="conventions: expected 'uqgear-rig/1'"):
        diagnose(rig, tmp_path / "out")
    with pytest.raises(RigDataError, match="expected a uqgear-rig/1 file path or an xarray Dataset"):
        diagnose(42, tmp_path / "out")


def test_bad_options_are_rejected(tmp_path):
    with pytest.raises(DiagnosisError, match="seed: expected a non-negative integer"):
        diagnose(DATA / "healthy.nc", tmp_path, seed=-1)
    with pytest.raises(DiagnosisError, match="workers: expected an integer >= 1"):
        diagnose(DATA / "healthy.nc", tmp_path, workers=0)
    with pytest.raises(DiagnosisError, match="design: expected a Design"):
        diagnose(DATA / "healthy.nc", tmp_path, design=3.5)
    with pytest.raises(DiagnosisError, match="effects: expected at least one"):
        diagnose(DATA / "healthy.nc", tmp_path, effects=[])
    rig = read_rig(DATA / "healthy.nc")
    with pytest.raises(DiagnosisError, match="model_error.wobble: unknown feature kind"):
        prepare_case(rig, load_design("locomotive"), seed=np.random.SeedSequence(0), model_error={"wobble": 0.1})
    with pytest.raises(DiagnosisError, match=r"model_error.line: expected a relative error in \[0, 1\)"):
        prepare_case(rig, load_design("locomotive"), seed=np.random.SeedSequence(0), model_error={"line": 2.0})


# ---------------------------------------------------------------------------------------------- labelled campaigns

@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(LABELLED))
def test_labelled_campaign_verdict(name, tmp_path):
    """The diagnosis names each labelled campaign's effect (none for the healthy ones)."""
    # the report (figures, a few seconds) is checked on two files, one per verdict kind
    report = name in ("healthy.nc", "eccentricity.nc")
    content = diagnose(DATA / name, tmp_path, seed=0, report=report)
    assert content["verdict"] == LABELLED[name], content["reason"]
    # one effect acts on each labelled campaign: forward selection adds none beside it
    assert [entry["effect"] for entry in content["effects"]] == \
        ([] if LABELLED[name] == "none" else [LABELLED[name]]), content["reason"]
    on_disk = json.loads((tmp_path / "diagnosis.json").read_text())
    assert on_disk["verdict"] == content["verdict"]
    assert set(on_disk) >= {"verdict", "gap", "where", "ranking"}
    assert set(on_disk["gap"]) >= {"metric", "baseline", "with_effect", "shrink_fraction", "evaluated_on"}
    if report:
        assert (tmp_path / "report.html").read_text().startswith("<!DOCTYPE html>")
    maps = xr.open_dataset(tmp_path / "diagnosis.nc")
    assert maps["gap_map_nominal"].dims == ("op", "channel", "family")
    maps.close()
    ranking = content["ranking"]
    assert [entry["score"] for entry in ranking] == sorted((entry["score"] for entry in ranking), reverse=True)
    if LABELLED[name] == "none":
        assert content["gap"]["baseline"] <= DEFAULT_SETTINGS.verdict.noise_gap
    else:
        assert ranking[0]["effect"] == LABELLED[name]
        assert content["gap"]["shrink_fraction"] >= 0.7


def test_a_strong_effect_that_explains_part_of_the_gap_is_named_with_an_unexplained_remainder():
    partial = _entry("bearing_clearance", 182.0, 0.45, low=0.3, gap_with_effect=1.4)
    decision = decide(2.6, [partial])
    assert decision.verdict == "bearing_clearance" and decision.partial
    assert decision.remaining_gap == 1.4 and "remains unexplained" in decision.reason
    # a shrink interval reaching below the partial threshold is not enough
    weak = replace(partial, shrink_interval=(0.1, 0.6))
    assert decide(2.6, [weak]).verdict == "unexplained"
    # nor is an effect that adds nothing to its own fit
    assert decide(2.6, [replace(partial, effect_gain=1.0)]).verdict == "unexplained"
    # a full explanation is not partial
    full = decide(2.6, [replace(partial, shrink_fraction=0.8, shrink_interval=(0.6, 0.9))])
    assert full.verdict == "bearing_clearance" and not full.partial


def test_a_figure_within_its_spread_of_its_threshold_is_flagged_borderline():
    knife_edge = _entry("bearing_clearance", 182.0, 0.5, low=0.42, gap_with_effect=0.9, standard_error=40.0)
    decision = decide(2.6, [knife_edge], nominal_gap_interval=(2.1, 3.0))
    assert [entry["figure"] for entry in decision.borderline] == ["shrink_fraction"]
    assert decision.borderline[0]["interval"] == [0.42, 0.6]
    # a score whose own standard error reaches the threshold, and a nominal gap whose interval holds noise
    close = _entry("friction", 12.0, 0.9, standard_error=5.0)
    flagged = decide(0.6, [close], nominal_gap_interval=(0.3, 0.9)).borderline
    assert {entry["figure"] for entry in flagged} == {"score", "nominal_gap"}
    # clear decisions carry no flag
    clear = _entry("friction", 120.0, 0.9, standard_error=5.0)
    assert decide(3.0, [clear], nominal_gap_interval=(2.5, 3.5)).borderline == ()


def test_bootstrap_gap_brackets_the_gap():
    rng = np.random.default_rng(4)
    z = rng.standard_normal((8, 3, 20)) * 2.0
    low, high = scoring.bootstrap_gap(z, rng)
    assert low <= scoring.gap_metric(z) <= high and high - low > 0


def test_low_band_noise_never_exceeds_the_floor(healthy_case):
    case = healthy_case
    usable = case.usable
    assert np.all(np.isfinite(case.band_noise_std[usable]))
    assert np.all(case.band_noise_std[usable] <= case.noise_std[usable])


def test_one_spectral_line_enters_the_comparison_once(healthy_case):
    # on the locomotive design (z1 = 21, 3 pole pairs) the first motor line (18 pinion orders) is the
    # pinion's third lower sideband of the first mesh harmonic: the line fit reads one amplitude for both
    # names, and the comparison (every fit, gap and allowance) takes it once, under its first name
    case = healthy_case
    names = case.layout.names
    motor, sideband = names.index("motor_ripple1"), names.index("mesh1_sb_pinion-3")
    np.testing.assert_array_equal(case.observed[..., motor], case.observed[..., sideband])
    compared = case.mask()
    assert compared[..., sideband].all() and not compared[..., motor].any()
    # every run compares as many lines as its line fit has distinct centres in the band
    line = np.array(case.layout.kinds) == "line"
    for op, processor in enumerate(case.processors):
        assert compared[op][:, line].sum(axis=-1).tolist() == [processor.fit.n_centres] * len(case.channels)


def test_model_runs_hold_the_linear_algebra_to_one_thread_and_find_its_pools_once(monkeypatch):
    import threadpoolctl

    made = []
    original = threadpoolctl.ThreadpoolController

    def counted():
        made.append(1)
        return original()

    monkeypatch.setattr(runs, "_THREAD_POOLS", None)
    monkeypatch.setattr(runs, "ThreadpoolController", counted)
    before = [pool["num_threads"] for pool in threadpoolctl.threadpool_info()]
    for _ in range(3):
        with runs.one_blas_thread():
            assert {pool["num_threads"] for pool in threadpoolctl.threadpool_info()} == {1}
    assert made == [1]
    assert [pool["num_threads"] for pool in threadpoolctl.threadpool_info()] == before
