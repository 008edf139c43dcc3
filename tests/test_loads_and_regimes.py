"""Loads a designer sizes against (peak mesh force, load factor on the rated mesh force) and regime
labels that can be defended (long periods, Lyapunov exponent and 0-1 test side by side), with the
report's Poincare maps and spectra free of round-off artefacts.

Every number is checked against something computed another way: the simulate() history for the
batch accumulators, the involute base radius from the design keys for the rated force, closed-form
Poincare sequences for the classifier."""

from __future__ import annotations

import math

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest
import xarray as xr
from matplotlib.figure import Figure

import uqgear
from uqgear import dynamics
from uqgear.physics.integration import QOI_INFO
from uqgear.physics.model import rated_mesh_force
from uqgear.study.analysis_schemas import QOIS
from uqgear.study.schema import parse_study


def base_radius_from_keys(design) -> float:
    """r_b1 = m z1 cos(alpha) / 2 straight from the design keys (pressure angle in degrees)."""
    return design.module * design.z1 * math.cos(math.radians(design.pressure_angle)) / 2.0


# ---------------------------------------------------------------------------- loads

def test_rated_mesh_force_of_the_reference_design(design):
    r_b1 = base_radius_from_keys(design)
    assert r_b1 == pytest.approx(88.80e-3, abs=0.01e-3)         # README "Verification"
    assert design.operation.drive_torque == 7000.0
    assert rated_mesh_force(design) == pytest.approx(7000.0 / r_b1, rel=1e-12)
    assert rated_mesh_force(design) == pytest.approx(78.83e3, abs=10.0)


@pytest.fixture(scope="module")
def loaded_batch(design):
    # 1500 rpm at dry rail (period-1, teeth in contact) and 4400 rpm on wet rail (mesh resonance,
    # teeth separating): the peak force is not F_T times a common factor
    samples = uqgear.samples_from_mapping({"pinion_speed": [1500.0, 4400.0], "drive_torque": [7000.0, 5000.0],
                                           "adhesion_torque": [46000.0, 21146.0]})
    return uqgear.simulate_batch(design, samples, n_periods=150, keep_periods=40)


def test_peak_mesh_force_is_the_largest_force_of_the_history(design, loaded_batch):
    batch = loaded_batch
    assert batch["peak_mesh_force"].attrs["units"] == "N"
    assert batch["load_factor_rated"].attrs["units"] == "1"
    for i in range(2):
        steps = int(batch["steps_per_period"].values[i])
        # every grid point of the kept periods in the history: its maximum is the batch's peak
        run = uqgear.simulate(design, float(batch["pinion_speed"].values[i]),
                              float(batch["drive_torque"].values[i]), float(batch["adhesion_torque"].values[i]),
                              n_periods=150, keep_periods=40, samples_per_period=steps)
        assert run.attrs["steps_per_period"] == steps
        peak = float(run["mesh_force"].max())
        assert batch["peak_mesh_force"].values[i] == pytest.approx(peak, rel=1e-12)
        # the single-run path gives the same loads
        qois = dynamics.response_qois(run)
        assert qois["peak_mesh_force"].item() == pytest.approx(peak, rel=1e-12)
        assert qois["load_factor_rated"].item() == pytest.approx(peak / (7000.0 / base_radius_from_keys(design)),
                                                                 rel=1e-9)
        assert qois["dynamic_load_factor"].item() == pytest.approx(batch["dynamic_load_factor"].values[i],
                                                                   rel=1e-12)
    assert batch["fraction_separation"].values[1] > 0.05          # the case that separates


def test_load_factor_rated_and_dlf(design, loaded_batch):
    batch = loaded_batch
    rated = design.operation.drive_torque / base_radius_from_keys(design)
    np.testing.assert_allclose(batch["load_factor_rated"].values, batch["peak_mesh_force"].values / rated,
                               rtol=1e-9)
    # the dynamic load factor stays relative to the run's own F_T = m_e (R1 T1/I1 + R2 T2/I2),
    # computed here from the design keys
    r1 = base_radius_from_keys(design)
    r2 = design.module * design.z2 * math.cos(math.radians(design.pressure_angle)) / 2.0
    me = design.I1 * design.I2 / (design.I1 * r2 ** 2 + design.I2 * r1 ** 2)
    f_t = me * (r1 * batch["drive_torque"].values / design.I1 + r2 * batch["adhesion_torque"].values / design.I2)
    np.testing.assert_allclose(batch["dynamic_load_factor"].values, batch["peak_mesh_force"].values / f_t,
                               rtol=1e-9)
    # same peak relative to F_T and to the rated force: F_T moves with T2, the rated force does not
    ratio = batch["dynamic_load_factor"].values / batch["load_factor_rated"].values
    np.testing.assert_allclose(ratio, rated / f_t, rtol=1e-9)
    assert "own static mesh force" in QOI_INFO["dynamic_load_factor"][1]


def test_studies_may_ask_for_the_loads():
    assert {"peak_mesh_force", "load_factor_rated"} <= set(QOIS)
    assert QOI_INFO["peak_mesh_force"][0] == "N" and QOI_INFO["load_factor_rated"][0] == "1"
    study = parse_study("""
seed: 1
operating_points: {pinion_speed: [1000, 2000], drive_torque: 1000}
uncertain: {adhesion_torque: {interval: [20000, 40000]}}
analyses:
  - type: interval
    qois: [peak_mesh_force, load_factor_rated, dynamic_load_factor]
""")
    assert tuple(study.analyses[0].options["qois"]) == ("peak_mesh_force", "load_factor_rated",
                                                        "dynamic_load_factor")


def test_lyapunov_units_agree():
    # the kernel divides the log growth by the kept time: 1/s, and says so
    assert QOI_INFO["largest_lyapunov"][0] == "s-1"
    assert "1/s" in QOI_INFO["largest_lyapunov"][1]


# ---------------------------------------------------------------------------- regimes

def period_seven(n_points: int) -> np.ndarray:
    cycle = np.array([0.31, 0.87, 0.12, 0.55, 0.99, 0.40, 0.71])
    return np.tile(cycle, n_points // 7 + 1)[:n_points]


def test_period_needs_ten_repeats():
    few = dynamics.classify_response(period_seven(30))
    assert (few.label, few.period) == ("quasi_periodic_or_long_period", 0)
    assert few.evidence["repeat_period"] == 7
    assert "fewer than 10" in few.reason
    many = dynamics.classify_response(period_seven(100))
    assert (many.label, many.period) == ("period-7", 7)
    assert dynamics.classify_response(period_seven(70)).label == "period-7"     # exactly 10 repeats
    assert dynamics.classify_response(period_seven(69)).label == "quasi_periodic_or_long_period"
    batch = xr.Dataset({"poincare_x": (("sample", "period"), np.stack([period_seven(30), period_seven(30)]))})
    assert dynamics.classify_batch(batch)["regime"].values.tolist() == ["quasi_periodic_or_long_period"] * 2


def logistic(r: float, n_points: int) -> np.ndarray:
    value, orbit = 0.3, np.empty(n_points)
    for _ in range(1000):
        value = r * value * (1.0 - value)
    for index in range(n_points):
        value = r * value * (1.0 - value)
        orbit[index] = value
    return orbit


def test_disagreeing_tests_give_uncertain():
    chaotic = logistic(4.0, 300)                        # K near 1
    ring = 1.0 + np.cos(2.0 * math.pi * math.sqrt(2.0) * np.arange(300))    # quasi-periodic: K near 0
    assert dynamics.zero_one_test(chaotic) > 0.5 and dynamics.zero_one_test(ring) < 0.5
    assert dynamics.classify_response(chaotic, lyapunov=0.2).label == "chaotic"
    assert dynamics.classify_response(ring, lyapunov=0.0).label == "quasi-periodic"
    low_k = dynamics.classify_response(ring, lyapunov=0.2)
    assert low_k.label == "uncertain" and "Lyapunov exponent says chaotic" in low_k.reason
    high_k = dynamics.classify_response(chaotic, lyapunov=0.001)
    assert high_k.label == "uncertain" and "0-1 test says chaotic" in high_k.reason
    assert high_k.evidence["zero_one_k"] > 0.5 and high_k.evidence["largest_lyapunov"] == 0.001


def test_regime_vocabulary_is_known_to_the_report():
    from uqgear.dynamics.regimes import REGIME_LABELS
    from uqgear.report.presentation import REGIME_CODES, REGIME_ORDER

    assert {"uncertain", "quasi_periodic_or_long_period"} <= set(REGIME_LABELS)
    assert set(REGIME_LABELS) - {"period-n"} == set(REGIME_ORDER) == set(REGIME_CODES)


# ---------------------------------------------------------------------------- report figures

def simulation_run(poincare_x: np.ndarray, spectrum: np.ndarray) -> xr.Dataset:
    """A simulate_point()-shaped run: x = 150 um + 20 um cos, a period-1 Poincare map to round-off."""
    cycles = np.arange(20 * 64) / 64.0
    x = 150e-6 + 20e-6 * np.cos(2.0 * math.pi * cycles)
    n_orders = spectrum.size
    return xr.Dataset(
        {"x": ("mesh_cycle", x),
         "x_velocity": ("mesh_cycle", -20e-6 * 2 * math.pi * 900 * np.sin(2 * math.pi * cycles)),
         "poincare_x": ("period", poincare_x),
         "poincare_x_velocity": ("period", np.full(poincare_x.size, 1e-16)),
         "spectrum_x": ("order", spectrum), "spectrum_frequency": ("order", np.arange(n_orders) * 40.0),
         "half_backlash": ((), 150e-6), "mesh_frequency": ((), 840.0)},
        coords={"mesh_cycle": cycles, "order": np.arange(n_orders) * 1.0},
        attrs={"z1": 21})


def test_constant_poincare_map_has_no_offset_and_spectrum_is_floored():
    from uqgear.report.dynamics_sections import SPECTRUM_RANGE_DB, _draw_simulation

    rng = np.random.default_rng(5)
    poincare = 150e-6 + 1e-13 * rng.standard_normal(100)      # period-1 with round-off
    spectrum = np.full(100, 1e-22)
    spectrum[21] = 20e-6
    figure = Figure()
    _draw_simulation(figure, simulation_run(poincare, spectrum))
    figure.draw_without_rendering()        # lays out ticks and offset texts as a saved figure has them
    poincare_axes, spectrum_axes = figure.axes[2], figure.axes[3]
    assert poincare_axes.get_title().startswith("Poincaré map")
    for axis in (poincare_axes.xaxis, poincare_axes.yaxis):
        assert axis.get_offset_text().get_text() == ""
        assert axis.get_major_formatter().get_offset() == ""
    low, high = poincare_axes.get_xlim()
    assert high - low >= 1e-3 * 150.0                          # um: at least 0.1 % of the value
    assert low < 150.0 < high
    # the tick labels are the values themselves (um), not deviations from a hidden offset
    ticks = [float(tick.get_text().replace("\N{MINUS SIGN}", "-"))
             for tick in poincare_axes.get_xticklabels() if tick.get_text()]
    assert ticks and all(abs(value - 150.0) < 1.0 for value in ticks)
    # the spectrum is floored 120 dB below its peak (20 um), the 1e-22 m round-off not drawn as content
    assert SPECTRUM_RANGE_DB == 120.0
    assert spectrum_axes.get_ylim()[0] == pytest.approx(20.0 * 1e-6, rel=1e-12)
    assert "120 dB" in spectrum_axes.get_title()


def test_bifurcation_draws_contact_boundaries():
    from uqgear.report.dynamics_sections import _draw_contact_boundaries, _half_backlash

    ds = xr.Dataset({"poincare_x": (("pinion_speed", "period"), np.full((3, 20), 200e-6))},
                    coords={"pinion_speed": [1000.0, 2000.0, 3000.0]}, attrs={"half_backlash": 150e-6})
    b = _half_backlash(ds, "pinion_speed")
    assert b == 150e-6
    figure = Figure()
    ax = figure.subplots()
    lines = _draw_contact_boundaries(ax, ds["pinion_speed"].values, b)
    levels = sorted(float(line.get_ydata()[0]) for line in ax.get_lines())
    assert levels == pytest.approx([-150.0, 150.0])           # um
    labels = [text.get_text() for text in ax.get_legend().get_texts()]
    assert labels == [line.get_label() for line in lines]
    assert labels[0].startswith("x = +b") and labels[1].startswith("x = -b")
    # a swept backlash: b follows the column
    swept = xr.Dataset(coords={"backlash": [2e-4, 4e-4]})
    np.testing.assert_allclose(_half_backlash(swept, "backlash"), [1e-4, 2e-4])
