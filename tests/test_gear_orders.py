"""Tests of the pitch-error allowance scaled to the rig's own gears (uqgear.diagnosis.gear_orders).

Checked against closed forms and synthetic data with a known truth: the
order powers of a pure cosine of tooth positions, the class scaling of the
factor range, the grouping of the line features by gear and order, and the
fitted factor of synthetic lines drawn with a known factor (random phasors
of the allowance's spread around a model line, plus noise), which must come
back within its sampling error, clipped to its range where the truth lies
beyond it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from uqgear.diagnosis.discrepancy import FeatureLayout
from uqgear.diagnosis.gear_orders import (ORDERS, drawn_amplitudes, factor_bounds, factors_summary,
                                          fitted_factors, line_groups, order_powers, scaled_line_errors)
from uqgear.physics.pitch_errors import draw_pitch_errors


def test_order_powers_of_a_cosine_of_the_tooth_positions():
    teeth = 23
    k = np.arange(teeth)
    positions = 4e-6 * np.cos(2 * np.pi * 2 * k / teeth + 0.4) + 1e-6 * np.sin(2 * np.pi * 3 * k / teeth)
    powers = order_powers(positions)
    assert powers == pytest.approx([0.0, 16e-12, 1e-12], abs=1e-20)
    # one row per gear of a stack
    assert order_powers(np.stack([positions, 2 * positions])).shape == (2, len(ORDERS))


def test_the_factor_range_brackets_one_and_two_classes_up_double_every_tolerance(design):
    rng = np.random.default_rng(3)
    drawn = [draw_pitch_errors(design, 7, rng) for _ in range(12)]
    seven = factor_bounds(design, (7, 7), drawn, np.random.default_rng(0), draws=1500)
    nine = factor_bounds(design, (9, 9), drawn, np.random.default_rng(0), draws=1500)
    assert set(seven) == {(gear, order) for gear in ("pinion", "gear") for order in ORDERS}
    for key, (low, high) in seven.items():
        # an exponential power: its 1 % and 99 % quantiles are 0.01 and 4.6 times its mean
        assert 0.002 < low < 0.05 and 2.5 < high < 9.0, (key, low, high)
        # tolerances grow by sqrt(2) a class: powers by 2, so two classes up is four times
        assert nine[key] == pytest.approx((4 * low, 4 * high), rel=1e-9)
    # the draws' RMS first-order |E_1| is a run-out of micrometres on class-7 gears (docs/model.md 6.4)
    amplitudes = drawn_amplitudes(drawn)
    assert 3e-6 < amplitudes[("pinion", 1)] < 30e-6 and amplitudes[("gear", 1)] > amplitudes[("pinion", 1)]


def _case(observed: np.ndarray, noise: float):
    """A stand-in case: a pinion shaft line and sideband of order 2, a pinion sideband of order 1, a gear one of 3."""
    names = ("shaft_pinion2", "mesh1_sb_pinion+2", "mesh1_sb_pinion-1", "mesh1_sb_gear+3", "rms")
    families = ("shaft_pinion", "sideband_pinion", "sideband_pinion", "sideband_gear", "broadband")
    kinds = ("line", "line", "line", "line", "rms")
    layout = FeatureLayout(names, families, kinds, np.arange(len(names)))

    class Case:
        pass

    case = Case()
    case.layout, case.observed = layout, observed
    case.mask = lambda: np.isfinite(observed)
    case.line_noise_sigma = lambda: np.where(np.array(kinds) == "line", noise, np.nan) * np.ones(observed.shape)
    return case


def test_line_groups_gather_shaft_line_and_sidebands_of_one_gear_and_order():
    case = _case(np.ones((2, 1, 5)), 1.0)
    assert {key: list(value) for key, value in line_groups(case).items()} == {
        ("pinion", 2): [0, 1], ("pinion", 1): [2], ("gear", 3): [3]}


@pytest.mark.parametrize("truth", [0.2, 1.0, 3.0])
def test_a_known_factor_comes_back_from_synthetic_lines(truth):
    rng = np.random.default_rng(7)
    n_op, n_channel, noise = 40, 3, 1.0
    allowance = rng.uniform(2.0, 20.0, (n_op, n_channel, 4))          # per-quadrature spreads, line features
    model_lines = np.zeros((n_op, n_channel, 4))
    model_lines[..., 0] = 30.0                                         # the model has the shaft line
    spread = np.sqrt(noise ** 2 + truth * allowance ** 2)
    phasor = model_lines + spread * (rng.standard_normal(spread.shape) + 1j * rng.standard_normal(spread.shape))
    observed = np.concatenate([np.abs(phasor), np.full((n_op, n_channel, 1), 5.0)], axis=-1)
    model = np.concatenate([model_lines, np.full((n_op, n_channel, 1), 5.0)], axis=-1)
    case = _case(observed, noise)
    bounds = {key: (0.01, 5.0) for key in (("pinion", 1), ("pinion", 2), ("gear", 3))}
    factors = fitted_factors(case, model, allowance, {"line": 0.0}, bounds)
    # pinion order 2 pools 240 lines: within 25 %; the single-feature groups within a factor 1.6
    assert factors[("pinion", 2)] == pytest.approx(truth, rel=0.25)
    assert truth / 1.6 < factors[("gear", 3)] < truth * 1.6, factors
    assert truth / 1.6 < factors[("pinion", 1)] < truth * 1.6, factors
    scaled = scaled_line_errors(case, allowance, factors)
    assert scaled[..., 3] == pytest.approx(allowance[..., 3] * math.sqrt(factors[("gear", 3)]))
    summary = factors_summary(factors, bounds, {key: 2e-6 for key in bounds})
    assert summary["pinion"]["2"]["factor"] == factors[("pinion", 2)] and summary["gear"]["3"]["high"] == 5.0
    # as |E_j|: the draws' RMS times the square root of the factor
    assert summary["pinion"]["2"]["amplitude_m"] == pytest.approx(2e-6 * math.sqrt(factors[("pinion", 2)]))
    assert summary["gear"]["3"]["amplitude_range_m"] == pytest.approx([2e-6 * 0.1, 2e-6 * math.sqrt(5.0)])


def test_a_factor_beyond_what_the_classes_give_is_held_at_the_range():
    rng = np.random.default_rng(8)
    allowance = np.full((30, 2, 4), 10.0)
    spread = np.sqrt(1.0 + 40.0 * allowance ** 2)
    observed = np.abs(spread * (rng.standard_normal(spread.shape) + 1j * rng.standard_normal(spread.shape)))
    observed = np.concatenate([observed, np.ones((30, 2, 1))], axis=-1)
    case = _case(observed, 1.0)
    bounds = {key: (0.05, 4.0) for key in (("pinion", 1), ("pinion", 2), ("gear", 3))}
    factors = fitted_factors(case, np.zeros_like(observed), allowance, {"line": 0.0}, bounds)
    assert factors == {key: pytest.approx(4.0) for key in bounds}
