"""Tests of uqgear.dynamics against independent truth: maps and oscillators with
known regimes (logistic map, Ueda's Duffing oscillator), closed-form spectra and
hand-built simulate()-shaped Datasets with known statistics."""

from __future__ import annotations

import math
import sys
import types

import numpy as np
import pytest
import xarray as xr
from scipy.integrate import odeint

import uqgear.physics  # noqa: F401  (loaded before fake_integration stands in for its integration module)
from uqgear import dynamics
from uqgear.common.errors import UqgearError

# ----------------------------------------------------------------------------
# reference systems
# ----------------------------------------------------------------------------

def logistic_orbit(r: float, n_points: int, start: float = 0.3, transient: int = 2000) -> np.ndarray:
    """Orbit of x -> r x (1 - x) after a transient."""
    value = start
    for _ in range(transient):
        value = r * value * (1.0 - value)
    orbit = np.empty(n_points)
    for index in range(n_points):
        value = r * value * (1.0 - value)
        orbit[index] = value
    return orbit


def duffing_stroboscopic(forcing: float, n_keep: int = 500, n_transient: int = 100) -> np.ndarray:
    """Stroboscopic (t = 2 pi k) samples of (x, x') of x'' + 0.05 x' + x^3 = forcing cos t."""
    def rhs(state, t):
        return [state[1], -0.05 * state[1] - state[0] ** 3 + forcing * math.cos(t)]

    times = 2.0 * math.pi * np.arange(n_transient + n_keep + 1)
    states = odeint(rhs, [1.0, 0.0], times, rtol=1e-9, atol=1e-9, mxstep=100000)
    return states[n_transient + 1:]


@pytest.fixture(scope="module")
def ueda_chaotic() -> np.ndarray:
    # Ueda's classic chaotic attractor (forcing 7.5).
    return duffing_stroboscopic(7.5)


@pytest.fixture(scope="module")
def duffing_period_one() -> np.ndarray:
    return duffing_stroboscopic(0.3)


def quasi_periodic_points(n_points: int = 500) -> np.ndarray:
    """cos t + cos(sqrt2 t) sampled at t = 2 pi k: (x, x') on an ellipse."""
    phase = 2.0 * math.pi * math.sqrt(2.0) * np.arange(n_points)
    return np.column_stack([1.0 + np.cos(phase), -math.sqrt(2.0) * np.sin(phase)])


# ----------------------------------------------------------------------------
# detect_period
# ----------------------------------------------------------------------------

@pytest.mark.parametrize("period", [1, 2, 3, 5, 8])
def test_detect_period_synthetic_with_noise(period):
    rng = np.random.default_rng(np.random.SeedSequence(period))
    cycle = rng.permutation(np.linspace(0.2, 1.0, period))
    points = np.tile(cycle, 200 // period + 1)[:200] + 1e-6 * rng.standard_normal(200)
    assert dynamics.detect_period(points, max_period=8) == period
    assert dynamics.count_distinct_points(points) == period
    # Two components: x and a velocity that is a different function of the phase.
    velocity = np.tile(np.cos(7.0 * cycle), 200 // period + 1)[:200]
    assert dynamics.detect_period(np.column_stack([points, velocity])) == period


def test_detect_period_returns_smallest_and_zero_beyond_max():
    period_two = np.tile([0.1, 0.9], 50)
    assert dynamics.detect_period(period_two, max_period=8) == 2  # not 4, 6, 8
    period_nine = np.tile(np.linspace(0.1, 0.9, 9), 20)
    assert dynamics.detect_period(period_nine, max_period=8) == 0
    assert dynamics.detect_period(period_nine, max_period=9) == 9


def test_detect_period_tolerance_is_relative_to_scale():
    alternating = 1.0 + 2e-4 * np.tile([1.0, -1.0], 50)
    # Judged against the RMS value (1.0) the 4e-4 split is below rtol: period 1.
    assert dynamics.detect_period(alternating, rtol=1e-3) == 1
    # Judged against an orbit size of 0.01 it is a period-2 response.
    assert dynamics.detect_period(alternating, rtol=1e-3, scale=0.01) == 2


@pytest.mark.parametrize("r, period", [(3.2, 2), (3.5, 4), (3.83, 3), (4.0, 0)])
def test_detect_period_logistic_map(r, period):
    assert dynamics.detect_period(logistic_orbit(r, 400)) == period


# ----------------------------------------------------------------------------
# zero_one_test
# ----------------------------------------------------------------------------

def test_zero_one_test_regular_series_near_zero(duffing_period_one):
    assert abs(dynamics.zero_one_test(logistic_orbit(3.5, 1000), seed=1)) < 0.1
    assert abs(dynamics.zero_one_test(logistic_orbit(3.83, 1000), seed=2)) < 0.1
    assert abs(dynamics.zero_one_test(quasi_periodic_points(1000)[:, 0], seed=3)) < 0.1
    assert abs(dynamics.zero_one_test(duffing_period_one[:, 0], seed=4)) < 0.1
    assert dynamics.zero_one_test(np.full(100, 0.7), seed=5) == 0.0


def test_zero_one_test_chaotic_series_near_one(ueda_chaotic):
    assert dynamics.zero_one_test(logistic_orbit(4.0, 1000), seed=1) > 0.8
    assert dynamics.zero_one_test(ueda_chaotic[:, 0], seed=2) > 0.8


def test_zero_one_test_reproducible_from_seed():
    series = logistic_orbit(3.9, 300)
    first = dynamics.zero_one_test(series, seed=np.random.SeedSequence(11))
    assert first == dynamics.zero_one_test(series, seed=np.random.SeedSequence(11))
    assert first == dynamics.zero_one_test(series, seed=11)


# ----------------------------------------------------------------------------
# classify_response
# ----------------------------------------------------------------------------

def test_classify_period_two_logistic():
    result = dynamics.classify_response(logistic_orbit(3.2, 200))
    assert (result.label, result.period) == ("period-2", 2)
    assert result.evidence["distinct_points"] == 2
    assert "repeats every 2" in result.reason


def test_classify_period_one_duffing(duffing_period_one):
    result = dynamics.classify_response(duffing_period_one)
    assert (result.label, result.period) == ("period-1", 1)


def test_classify_chaotic_ueda(ueda_chaotic):
    result = dynamics.classify_response(ueda_chaotic, seed=7)
    assert (result.label, result.period) == ("chaotic", 0)
    assert result.evidence["zero_one_k"] > 0.8
    assert result.evidence["distinct_points"] > 400


def test_classify_quasi_periodic_ellipse():
    result = dynamics.classify_response(quasi_periodic_points(300))
    assert (result.label, result.period) == ("quasi-periodic", 0)
    assert result.evidence["zero_one_k"] < 0.1
    assert result.evidence["largest_lyapunov"] is None
    # A Lyapunov exponent that agrees with K confirms; one that disagrees makes the label uncertain.
    forced = dynamics.classify_response(quasi_periodic_points(300), lyapunov=0.2)
    assert forced.label == "uncertain" and forced.period == 0
    assert "the Lyapunov exponent says chaotic, the 0-1 test says regular" in forced.reason
    assert dynamics.classify_response(quasi_periodic_points(300), lyapunov=0.001).label == "quasi-periodic"


def test_classify_lyapunov_and_zero_one_side_by_side(ueda_chaotic):
    agreed = dynamics.classify_response(ueda_chaotic, lyapunov=0.3)
    assert agreed.label == "chaotic" and "agree" in agreed.reason
    assert agreed.evidence["zero_one_k"] > 0.8 and agreed.evidence["largest_lyapunov"] == 0.3
    stable = dynamics.classify_response(ueda_chaotic, lyapunov=-0.05)
    assert stable.label == "uncertain"
    assert "the 0-1 test says chaotic, the Lyapunov exponent says regular" in stable.reason


def test_classify_long_period():
    # A period-10 sequence of 200 points: K of the 0-1 test is unreliable here
    # (N/10 = 20 lags cover only two periods), the period test is not.
    cycle = np.random.default_rng(np.random.SeedSequence(10)).permutation(np.linspace(0.1, 1.0, 10))
    points = np.tile(cycle, 20)
    result = dynamics.classify_response(points)
    assert (result.label, result.period) == ("period-10", 10)
    assert dynamics.classify_response(points, max_period=8).period == 0
    assert dynamics.classify_response(points[:36]).period == 0  # seen fewer than 4 times


def test_response_class_is_immutable():
    result = dynamics.classify_response(logistic_orbit(3.2, 40))
    with pytest.raises(AttributeError):
        result.label = "chaotic"
    with pytest.raises(TypeError):
        result.evidence["zero_one_k"] = 1.0


# ----------------------------------------------------------------------------
# simulate()-shaped Datasets
# ----------------------------------------------------------------------------

SAMPLES_PER_PERIOD = 2000
MESH_FREQUENCY = 700.0  # Hz
Z1 = 21
HALF_BACKLASH = 1.5e-4


def fake_simulation(n_periods: int = 4, poincare: np.ndarray | None = None) -> xr.Dataset:
    """A simulate()-shaped run with closed-form histories.

    x = b (0.2 + 1.5 cos theta) with theta the mesh phase, so the contact
    fractions are arccos fractions; mesh_force = F_T (1 + 0.3 cos theta);
    accelerations are sines of known amplitude.
    """
    period = 1.0 / MESH_FREQUENCY
    time = np.arange(n_periods * SAMPLES_PER_PERIOD) * period / SAMPLES_PER_PERIOD
    theta = 2.0 * math.pi * MESH_FREQUENCY * time
    x = HALF_BACKLASH * (0.2 + 1.5 * np.cos(theta))
    static_force = 8.0e4
    contact = np.where(x > HALF_BACKLASH, 1, np.where(x < -HALF_BACKLASH, -1, 0)).astype(np.int8)
    if poincare is None:
        poincare = np.column_stack([np.full(50, x[0]), np.full(50, 0.0)])
    return xr.Dataset(
        {
            "x": ("time", x, {"units": "m"}),
            "x_velocity": ("time", -HALF_BACKLASH * 1.5 * 2 * math.pi * MESH_FREQUENCY * np.sin(theta),
                           {"units": "m s-1"}),
            "y1": ("time", 1e-6 * np.cos(theta), {"units": "m"}),
            "y1_velocity": ("time", -1e-6 * 2 * math.pi * MESH_FREQUENCY * np.sin(theta), {"units": "m s-1"}),
            "y1_acceleration": ("time", 30.0 * np.sin(theta), {"units": "m s-2"}),
            "y2_acceleration": ("time", 12.0 * np.sin(2 * theta + 0.3), {"units": "m s-2"}),
            "mesh_force": ("time", static_force * (1.0 + 0.3 * np.cos(theta)), {"units": "N"}),
            "contact": ("time", contact),
            "poincare_x": ("period", poincare[:, 0], {"units": "m"}),
            "poincare_x_velocity": ("period", poincare[:, 1], {"units": "m s-1"}),
        },
        coords={"time": ("time", time, {"units": "s"})},
        attrs={"pinion_speed": MESH_FREQUENCY * 60.0 / Z1, "mesh_frequency": MESH_FREQUENCY,
               "mesh_period": period, "half_backlash": HALF_BACKLASH, "static_mesh_force": static_force,
               "samples_per_period": SAMPLES_PER_PERIOD, "z1": Z1, "z2": 101},
    )


def test_contact_fractions_match_arccos_fractions():
    fractions = dynamics.contact_fractions(fake_simulation())
    # x > b <=> cos theta > 8/15; x < -b <=> cos theta < -0.8.
    drive = math.acos(8.0 / 15.0) / math.pi
    back = 1.0 - math.acos(-0.8) / math.pi
    assert fractions["fraction_drive_contact"].item() == pytest.approx(drive, abs=1e-3)
    assert fractions["fraction_back_contact"].item() == pytest.approx(back, abs=1e-3)
    assert fractions["fraction_separation"].item() == pytest.approx(1.0 - drive - back, abs=1e-3)
    assert fractions["fraction_separation"].attrs["units"] == "1"


def test_response_qois_closed_form():
    qois = dynamics.response_qois(fake_simulation())
    b = HALF_BACKLASH
    assert qois["dte_mean"].item() == pytest.approx(0.2 * b, rel=1e-9)
    assert qois["dte_rms"].item() == pytest.approx(1.5 * b / math.sqrt(2.0), rel=1e-9)
    assert qois["dte_peak_to_peak"].item() == pytest.approx(3.0 * b, rel=1e-9)
    assert qois["dynamic_load_factor"].item() == pytest.approx(1.3, rel=1e-12)
    assert qois["acc_pinion_rms"].item() == pytest.approx(30.0 / math.sqrt(2.0), rel=1e-9)
    assert qois["acc_gear_rms"].item() == pytest.approx(12.0 / math.sqrt(2.0), rel=1e-9)
    assert set(qois.data_vars) == {"dte_mean", "dte_rms", "dte_peak_to_peak", "dynamic_load_factor",
                                   "peak_mesh_force", "load_factor_rated",
                                   "acc_pinion_rms", "acc_gear_rms", "fraction_drive_contact",
                                   "fraction_separation", "fraction_back_contact"}
    # peak of F_T (1 + 0.3 cos theta) with F_T = 80 kN; no rated mesh force in the attrs: NaN
    assert qois["peak_mesh_force"].item() == pytest.approx(1.3 * 8.0e4, rel=1e-12)
    assert qois["peak_mesh_force"].attrs["units"] == "N"
    assert math.isnan(qois["load_factor_rated"].item())
    rated = dynamics.response_qois(fake_simulation().assign_attrs(rated_mesh_force=6.5e4))
    assert rated["load_factor_rated"].item() == pytest.approx(1.3 * 8.0e4 / 6.5e4, rel=1e-12)
    assert rated["load_factor_rated"].attrs["units"] == "1"
    assert rated["dynamic_load_factor"].item() == qois["dynamic_load_factor"].item()
    assert qois["dte_rms"].attrs["units"] == "m"
    assert qois["acc_gear_rms"].attrs["units"] == "m s-2"


def test_response_qois_errors():
    ds = fake_simulation()
    with pytest.raises(UqgearError, match="lacks the attribute 'static_mesh_force'"):
        dynamics.response_qois(ds.drop_attrs())
    with pytest.raises(UqgearError, match="lacks variable.*mesh_force"):
        dynamics.response_qois(ds.drop_vars("mesh_force"))
    bad_contact = ds.assign(contact=ds["contact"].where(ds["time"] > 0, 2))
    with pytest.raises(UqgearError, match="only -1, 0 and 1; got \\[2\\]"):
        dynamics.contact_fractions(bad_contact)


def test_phase_plane_and_poincare_section():
    ds = fake_simulation()
    plane = dynamics.phase_plane(ds, "y1")
    np.testing.assert_array_equal(plane["displacement"].values, ds["y1"].values)
    np.testing.assert_array_equal(plane["velocity"].values, ds["y1_velocity"].values)
    assert plane["velocity"].attrs["units"] == "m s-1"
    section = dynamics.poincare_section(ds)
    assert set(section.data_vars) == {"poincare_x", "poincare_x_velocity"}
    assert section["poincare_x"].dims == ("period",)
    with pytest.raises(UqgearError, match="lacks variable.*y2_velocity"):
        dynamics.phase_plane(ds, "y2")
    with pytest.raises(UqgearError, match="no poincare_"):
        dynamics.poincare_section(ds.drop_vars(["poincare_x", "poincare_x_velocity"]))


def test_classify_dataset_scales_by_orbit_size():
    # Period-2 Poincare points of x split by 1e-7 m around 2e-4 m: a period-1
    # response by the RMS fallback (5e-4 relative), but the orbit (x history)
    # has a peak-to-peak of only 2e-6 m, so against it the split is 5 %.
    split = np.tile([1.0, -1.0], 25)
    poincare = np.column_stack([2e-4 + 5e-8 * split, np.full(50, 1e-3)])
    ds = fake_simulation(poincare=poincare)
    ds["x"] = 2e-4 + 1e-6 * np.cos(2 * math.pi * MESH_FREQUENCY * ds["time"])
    result = dynamics.classify_dataset(ds)
    assert (result.label, result.period) == ("period-2", 2)
    assert dynamics.classify_response(poincare).label == "period-1"


# ----------------------------------------------------------------------------
# spectra
# ----------------------------------------------------------------------------

def test_amplitude_spectrum_exact_peak_on_bin():
    sample_rate, amplitude, frequency = 1200.0, 2.5, 120.0
    time = np.arange(1200) / sample_rate
    signal = 3.0 + amplitude * np.sin(2 * math.pi * frequency * time + 0.4)
    spectrum = dynamics.amplitude_spectrum(signal, sample_rate)
    assert spectrum.dims == ("frequency",)
    assert spectrum["frequency"].attrs["units"] == "Hz"
    peak = spectrum.idxmax("frequency").item()
    assert peak == pytest.approx(frequency)
    assert spectrum.max().item() == pytest.approx(amplitude, rel=1e-12)
    assert spectrum.sel(frequency=0.0).item() == pytest.approx(0.0, abs=1e-12)
    kept_mean = dynamics.amplitude_spectrum(signal, sample_rate, remove_mean=False)
    assert kept_mean.sel(frequency=0.0).item() == pytest.approx(3.0, rel=1e-12)
    boxcar = dynamics.amplitude_spectrum(signal, sample_rate, window="boxcar")
    assert boxcar.sel(frequency=frequency).item() == pytest.approx(amplitude, rel=1e-12)


def test_amplitude_spectrum_flattop_off_bin():
    sample_rate = 1000.0
    time = np.arange(2000) / sample_rate
    signal = 1.7 * np.cos(2 * math.pi * 101.23 * time)
    spectrum = dynamics.amplitude_spectrum(signal, sample_rate, window="flattop")
    assert spectrum.max().item() == pytest.approx(1.7, rel=2e-3)


def test_amplitude_spectrum_against_order():
    sample_rate, shaft_rpm = 2000.0, 600.0  # 10 Hz shaft
    time = np.arange(4000) / sample_rate
    signal = xr.DataArray(0.8 * np.sin(2 * math.pi * 210.0 * time), dims=["time"], attrs={"units": "m s-2"})
    spectrum = dynamics.amplitude_spectrum(signal, sample_rate, against="order", shaft_speed_rpm=shaft_rpm)
    assert spectrum.dims == ("order",)
    assert spectrum.idxmax("order").item() == pytest.approx(21.0)
    assert spectrum.sel(order=21.0).item() == pytest.approx(0.8, rel=1e-12)
    assert spectrum["frequency"].sel(order=21.0).item() == pytest.approx(210.0)
    assert spectrum.attrs["units"] == "m s-2"


def test_spectrum_dataset_mesh_order():
    ds = fake_simulation()
    ds["x"] = ds["x"] + 2e-6 * np.cos(4 * math.pi * MESH_FREQUENCY * ds["time"])
    spectra = dynamics.spectrum_dataset(ds, ["x", "y1_acceleration"], against="order")
    assert spectra.attrs["mesh_order"] == Z1
    x_spectrum = spectra["x"]
    assert x_spectrum.sel(order=Z1).item() == pytest.approx(1.5 * HALF_BACKLASH, rel=1e-9)
    assert x_spectrum.sel(order=2 * Z1).item() == pytest.approx(2e-6, rel=1e-6)
    assert spectra["y1_acceleration"].sel(order=Z1).item() == pytest.approx(30.0, rel=1e-9)
    by_frequency = dynamics.spectrum_dataset(ds)
    assert by_frequency["x"].sel(frequency=MESH_FREQUENCY).item() == pytest.approx(1.5 * HALF_BACKLASH, rel=1e-9)


def test_spectrum_errors():
    ds = fake_simulation()
    with pytest.raises(UqgearError, match="lacks variable.*te"):
        dynamics.spectrum_dataset(ds, "te")
    with pytest.raises(UqgearError, match="against: expected 'frequency' or 'order'; got 'angle'"):
        dynamics.amplitude_spectrum(np.ones(8), 10.0, against="angle")
    with pytest.raises(UqgearError, match="shaft_speed_rpm: required"):
        dynamics.amplitude_spectrum(np.ones(8), 10.0, against="order")
    with pytest.raises(UqgearError, match="window: expected a window name"):
        dynamics.amplitude_spectrum(np.ones(8), 10.0, window="nonsense")
    with pytest.raises(UqgearError, match="sample_rate: expected a positive"):
        dynamics.amplitude_spectrum(np.ones(8), -1.0)
    with pytest.raises(UqgearError, match="at least 2 samples"):
        dynamics.amplitude_spectrum([], 10.0)
    with pytest.raises(UqgearError, match="uniformly increasing 'time'"):
        dynamics.spectrum_dataset(ds.assign_coords(time=ds["time"] ** 2))
    with pytest.raises(UqgearError, match="lacks the attribute 'pinion_speed'"):
        dynamics.spectrum_dataset(ds.drop_attrs(), against="order")


# ----------------------------------------------------------------------------
# batches and sweeps
# ----------------------------------------------------------------------------

def logistic_batch(rs: list[float], n_periods: int = 60) -> xr.Dataset:
    poincare = np.array([logistic_orbit(r, n_periods) for r in rs])
    return xr.Dataset(
        {"poincare_x": (("sample", "period"), poincare, {"units": "m"})},
        coords={"r": ("sample", np.asarray(rs, dtype=float))},
    )


def test_classify_batch_logistic_regimes():
    batch = logistic_batch([3.2, 3.5, 3.83, 4.0, 2.8])
    batch["poincare_x"][4, 7] = np.nan  # a failed run
    classes = dynamics.classify_batch(batch, seed=3)
    assert classes["regime"].values.tolist() == ["period-2", "period-4", "period-3", "chaotic", "undetermined"]
    assert classes["response_period"].values.tolist() == [2, 4, 3, 0, 0]
    assert classes["zero_one_k"].values[3] > 0.5
    assert np.isnan(classes["zero_one_k"].values[4])
    np.testing.assert_array_equal(classes["r"].values, batch["r"].values)
    assert classes["regime"].dims == ("sample",)
    # Same frequencies c for every run: a run's K does not depend on the batch.
    alone = dynamics.classify_batch(logistic_batch([4.0]), seed=3)
    assert alone["zero_one_k"].item() == classes["zero_one_k"].values[3]


def test_classify_batch_lyapunov_units():
    # a chaotic sequence (K near 1): the exponent in 1/s is converted to nats per mesh period before
    # the threshold 0.01; unconverted, both would exceed it
    points = logistic_orbit(4.0, 200)
    batch = xr.Dataset(
        {"poincare_x": (("sample", "period"), np.tile(points, (2, 1))),
         "largest_lyapunov": ("sample", [50.0, 5.0], {"units": "s-1"})},
        coords={"pinion_speed": ("sample", [2000.0, 2000.0])},
        attrs={"z1": 30},  # mesh frequency 1000 Hz: exponents 0.05 and 0.005 per mesh period
    )
    classes = dynamics.classify_batch(batch)
    assert classes["regime"].values.tolist() == ["chaotic", "uncertain"]
    np.testing.assert_allclose(classes["lyapunov_per_period"].values, [0.05, 0.005], rtol=1e-12)
    assert classes["zero_one_k"].values[1] > 0.5
    assert "0.005 per mesh period" in str(classes["regime_reason"].values[1])


class FakeIntegration(types.ModuleType):
    """Stands in for uqgear.physics.integration: 'pinion_speed' s gives the logistic map
    at r = s / 1000, shifted by 'adhesion_torque' (to check the grid layout)."""

    def __init__(self):
        super().__init__("uqgear.physics.integration")
        self.calls = []

    def simulate_batch(self, design, samples, *, n_periods=400, keep_periods=200, lyapunov=False):
        self.calls.append((design, samples, n_periods, keep_periods))
        shift = samples["adhesion_torque"].values if "adhesion_torque" in samples else np.zeros(samples.sizes["sample"])
        poincare = np.array([logistic_orbit(speed / 1000.0, keep_periods) for speed in samples["pinion_speed"].values])
        poincare = poincare + shift[:, None]
        return xr.Dataset(
            {"poincare_x": (("sample", "period"), poincare),
             "dte_peak_to_peak": ("sample", np.ptp(poincare, axis=1))},
            coords={name: samples[name] for name in samples.data_vars},
        )


@pytest.fixture
def fake_integration(monkeypatch):
    module = FakeIntegration()
    monkeypatch.setitem(sys.modules, "uqgear.physics.integration", module)
    return module


def test_bifurcation_builds_samples_and_classifies(fake_integration):
    speeds = [3200.0, 3500.0, 3830.0, 4000.0]
    result = dynamics.bifurcation("locomotive", "pinion_speed", speeds, fixed={"drive_torque": 5000.0},
                                  n_periods=300, keep_periods=64)
    (design, samples, n_periods, keep_periods), = fake_integration.calls
    assert (design.name, n_periods, keep_periods) == ("locomotive", 300, 64)
    np.testing.assert_array_equal(samples["drive_torque"].values, [5000.0] * 4)
    assert result["poincare_x"].dims == ("pinion_speed", "period")
    np.testing.assert_array_equal(result["pinion_speed"].values, speeds)
    assert result["regime"].values.tolist() == ["period-2", "period-4", "period-3", "chaotic"]
    assert result["response_period"].values.tolist() == [2, 4, 3, 0]
    assert "dte_peak_to_peak" in result


def test_sweep_grid_layout(fake_integration):
    speeds, torques = [3200.0, 3500.0, 4000.0], [0.0, 10.0]
    grid = dynamics.sweep_grid("locomotive", {"pinion_speed": speeds, "adhesion_torque": torques},
                               keep_periods=40)
    assert grid["poincare_x"].dims == ("pinion_speed", "adhesion_torque", "period")
    assert len(fake_integration.calls) == 1
    expected = logistic_orbit(3.5, 40) + 10.0
    np.testing.assert_allclose(grid["poincare_x"].sel(pinion_speed=3500.0, adhesion_torque=10.0).values, expected)
    assert grid["regime"].sel(adhesion_torque=10.0).values.tolist() == ["period-2", "period-4", "chaotic"]
    # Classifying the unstacked grid directly (two run dims, period first) agrees.
    again = dynamics.classify_batch(grid.transpose("period", "adhesion_torque", "pinion_speed"))
    xr.testing.assert_equal(again["regime"].transpose(*grid["regime"].dims), grid["regime"])
    xr.testing.assert_equal(again["zero_one_k"].transpose(*grid["zero_one_k"].dims), grid["zero_one_k"])


def test_sweep_errors(fake_integration):
    with pytest.raises(UqgearError, match="parameter: expected the name"):
        dynamics.bifurcation("locomotive", "", [1.0])
    with pytest.raises(UqgearError, match="pinion_speed: expected a non-empty 1-D sequence"):
        dynamics.bifurcation("locomotive", "pinion_speed", [])
    with pytest.raises(UqgearError, match="fixed: 'pinion_speed' is also swept"):
        dynamics.bifurcation("locomotive", "pinion_speed", [1000.0], fixed={"pinion_speed": 2.0})
    with pytest.raises(UqgearError, match="expected distinct values"):
        dynamics.sweep_grid("locomotive", {"pinion_speed": [1.0, 1.0]})
    assert fake_integration.calls == []


def test_bifurcation_real_integrator():
    integration = pytest.importorskip("uqgear.physics.integration")
    if not hasattr(integration, "simulate_batch"):
        pytest.skip("uqgear.physics.integration.simulate_batch not written yet")
    # Light speeds at rated load: a smooth period-1 mesh response.
    result = dynamics.bifurcation("locomotive", "pinion_speed", [500.0, 800.0], n_periods=120, keep_periods=40)
    assert result["poincare_x"].dims == ("pinion_speed", "period")
    assert result.sizes["period"] == 40
    assert result["regime"].values.tolist() == ["period-1", "period-1"]
    assert np.all(result["zero_one_k"].values == 0.0)  # constant within tolerance


@pytest.mark.slow
def test_bifurcation_real_integrator_light_load_regimes():
    # Regression on the reference design at light load (T1 = 1 kN m, T2
    # balancing), as found when this module was written: a stable period-10
    # orbit (beyond the old max_period of 8), a period-2, and chaos with a
    # clearly positive Lyapunov exponent. Update if the model changes.
    integration = pytest.importorskip("uqgear.physics.integration")
    if not hasattr(integration, "simulate_batch"):
        pytest.skip("uqgear.physics.integration.simulate_batch not written yet")
    fixed = {"drive_torque": 1000.0, "adhesion_torque": 1000.0 * 101 / 21}
    result = dynamics.bifurcation("locomotive", "pinion_speed", [3250.0, 4750.0, 5750.0], fixed=fixed,
                                  n_periods=600, keep_periods=200)
    assert result["regime"].values.tolist() == ["period-10", "period-2", "chaotic"]


# ----------------------------------------------------------------------------
# bad input
# ----------------------------------------------------------------------------

def test_bad_inputs():
    series = logistic_orbit(3.2, 40)
    with pytest.raises(UqgearError, match="max_period: expected an integer >= 1; got 0"):
        dynamics.detect_period(series, max_period=0)
    with pytest.raises(UqgearError, match="max_period: expected an integer >= 1"):
        dynamics.classify_response(series, max_period=2.5)
    with pytest.raises(UqgearError, match="points: expected at least one Poincare point"):
        dynamics.detect_period([])
    with pytest.raises(UqgearError, match="series: the 0-1 test needs at least 20 values.*got 0"):
        dynamics.zero_one_test([])
    with pytest.raises(UqgearError, match="series: expected a 1-D sequence"):
        dynamics.zero_one_test(np.ones((30, 2)))
    with pytest.raises(UqgearError, match="series: expected finite values"):
        dynamics.zero_one_test(np.r_[series, np.nan])
    with pytest.raises(UqgearError, match="seed: expected a non-negative integer"):
        dynamics.zero_one_test(series, seed=-1)
    with pytest.raises(UqgearError, match="n_c: expected an integer >= 1"):
        dynamics.zero_one_test(series, n_c=0)
    with pytest.raises(UqgearError, match="rtol: expected a positive"):
        dynamics.detect_period(series, rtol=0.0)
    with pytest.raises(UqgearError, match="scale: expected one number or one per component"):
        dynamics.detect_period(series, scale=[1.0, 2.0, 3.0])
    with pytest.raises(UqgearError, match="poincare_points: expected at least 20 Poincare points"):
        dynamics.classify_response(series[:10])
    with pytest.raises(UqgearError, match="classify_dataset: the Dataset lacks variable.*poincare_x"):
        dynamics.classify_dataset(xr.Dataset({"x": ("time", np.ones(5))}))
    with pytest.raises(UqgearError, match="classify_batch: poincare_x should have a 'period' dim"):
        dynamics.classify_batch(xr.Dataset({"poincare_x": ("sample", np.ones(5))}))
    with pytest.raises(UqgearError, match="lyapunov: expected a number"):
        dynamics.classify_response(logistic_orbit(3.2, 40), lyapunov="high")
    with pytest.raises(UqgearError, match="expected an xarray Dataset; got dict"):
        dynamics.contact_fractions({"contact": [1, 0]})
