"""Tests of the pitch-error allowance scaled to the rig's own gears (uqgear.diagnosis.allowances.pitch_orders).

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
from types import SimpleNamespace

import numpy as np
import pytest

from uqgear.diagnosis.allowances.pitch_errors import PitchErrorAllowance, run_outs_not_told_apart
from uqgear.diagnosis.allowances.pitch_orders import (
    ORDERS,
    bounds_of,
    class_powers,
    drawn_amplitudes,
    driving_order,
    factor_bounds,
    factors_summary,
    fitted_factors,
    line_groups,
    scaled_line_errors,
    share_below,
)
from uqgear.diagnosis.discrepancy import FeatureLayout
from uqgear.diagnosis.settings import DEFAULT_SETTINGS
from uqgear.physics.pitch_errors import draw_pitch_errors, order_powers
from uqgear.rig.features import FeatureDefinition, feature_definitions


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
    # the draws' RMS first-order |E_1| is a run-out of micrometres on class-7 gears
    # (docs/model/unmodelled-effects.md section 6.4)
    amplitudes = drawn_amplitudes(drawn)
    assert 3e-6 < amplitudes[("pinion", 1)] < 30e-6 and amplitudes[("gear", 1)] > amplitudes[("pinion", 1)]


def test_the_share_of_class_gears_below_a_read_factor_is_the_exponential_distribution(design):
    """|E_1|^2 of one class is exponential (E_1 sums many independent deviations): P(below f x mean) = 1 - exp(-f)."""
    drawn = [draw_pitch_errors(design, 7, np.random.default_rng(3)) for _ in range(12)]
    spread = class_powers(design, (7, 7), drawn, np.random.default_rng(0), draws=4000)
    assert bounds_of(spread) == factor_bounds(design, (7, 7), drawn, np.random.default_rng(0), draws=4000)
    for key, (powers, mean) in spread.items():
        # a factor on the allowance's mean power that is f times the classes' own mean power
        for f in (0.5, 1.0, 2.3):
            share = share_below(spread, {key: f * powers.mean() / mean})[key]
            assert share == pytest.approx(1.0 - math.exp(-f), abs=0.03), (key, f, share)
    # the larger the run-out read, the larger the share below it
    key = ("pinion", 1)
    assert share_below(spread, {key: 0.1})[key] < share_below(spread, {key: 1.0})[key] < share_below(
        spread, {key: 5.0})[key]


def _allowance(design, shares: dict, factors: dict) -> PitchErrorAllowance:
    drawn = tuple(draw_pitch_errors(design, 7, np.random.default_rng(seed)) for seed in range(12))
    return PitchErrorAllowance(True, "test", (6.0, 8.0), {}, len(drawn), {}, 0.0, 0.0, 0.0,
                               {"pinion": 22e-6, "gear": 52e-6}, drawn, dict.fromkeys(factors, (0.01, 5.0)),
                               factors, shares)


def test_a_first_order_error_large_for_the_classes_is_reported_as_a_run_out_that_cannot_be_told(design):
    factors = {("pinion", 1): 3.0, ("gear", 1): 0.5, ("gear", 2): 4.0}
    allowance = _allowance(design, {("pinion", 1): 0.93, ("gear", 1): 0.4, ("gear", 2): 0.97}, factors)
    reports = run_outs_not_told_apart(allowance, [])
    # the first order only: a large second-order error is no run-out
    assert [(entry["effect"], entry["shaft"]) for entry in reports] == [("eccentricity", "pinion")]
    entry = reports[0]
    # the run-out read is the draws' RMS |E_1| times the square root of the factor (independently from the draws)
    rms = math.sqrt(np.mean([order_powers(errors.pinion)[0] for errors in allowance.drawn_errors]))
    assert entry["run_out_m"] == pytest.approx(rms * math.sqrt(3.0), rel=1e-12)
    assert entry["share_of_class_gears_below"] == 0.93 and entry["classes"] == [6.0, 8.0]
    assert "pinion" in entry["reason"] and "93 %" in entry["reason"] and "cannot tell" in entry["reason"]
    # an eccentricity named on that shaft settles it; at the threshold it is reported, below it not
    assert run_outs_not_told_apart(allowance, ["pinion"]) == []
    share = DEFAULT_SETTINGS.pitch.large_run_out_share
    at = _allowance(design, {("pinion", 1): share, ("gear", 1): share - 1e-9},
                    factors)
    assert [entry["shaft"] for entry in run_outs_not_told_apart(at, [])] == ["pinion"]
    # no allowance, nothing to report
    assert run_outs_not_told_apart(None, []) == []
    not_applied = PitchErrorAllowance(False, "no classes", None, {}, 0, {}, 0.0, 0.0, 0.0)
    assert run_outs_not_told_apart(not_applied, []) == []


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
    case.design = SimpleNamespace(z1=21, z2=101)
    orders = (2.0, 23.0, 20.0, 21.0 + 3 * 21 / 101, math.nan)
    case.processors = [SimpleNamespace(definitions=[FeatureDefinition(*pair) for pair in zip(names, families, orders)])]
    case.mask = lambda: np.isfinite(observed)
    case.line_noise_sigma = lambda: np.where(np.array(kinds) == "line", noise, np.nan) * np.ones(observed.shape)
    return case


def test_line_groups_gather_shaft_line_and_sidebands_of_one_gear_and_order():
    case = _case(np.ones((2, 1, 5)), 1.0)
    assert {key: list(value) for key, value in line_groups(case).items()} == {
        ("pinion", 2): [0, 1], ("pinion", 1): [2], ("gear", 3): [3]}


def test_a_motor_line_on_a_gear_order_joins_that_group(design):
    # the locomotive design: z1 = 21, 3 pole pairs, so the first motor line (18 pinion orders) is the
    # pinion's third lower sideband of the first mesh harmonic, driven by the pinion's E_3; the second
    # (36 = 42 - 6) is driven by E_6, an order the allowance does not scale; neither is a gear order
    assert (design.z1, design.z2, design.motor_pole_pairs) == (21, 101, 3)
    processor = SimpleNamespace(definitions=list(feature_definitions(design)))
    layout = FeatureLayout.from_processor(processor)
    case = SimpleNamespace(design=design, processors=[processor], layout=layout)
    line_names = [name for name, kind in zip(layout.names, layout.kinds) if kind == "line"]
    groups = {key: [line_names[position] for position in value] for key, value in line_groups(case).items()}
    assert sorted(groups[("pinion", 3)]) == sorted(
        ["shaft_pinion3", "motor_ripple1"] + [f"mesh{k}_sb_pinion{sign}3" for k in (1, 2, 3) for sign in "+-"]
    )
    assert all("motor_ripple2" not in names for names in groups.values())
    assert all("motor_ripple1" not in names for key, names in groups.items() if key != ("pinion", 3))
    assert driving_order(36.0, 21, 1.0) == 6 and driving_order(18.0, 101, 21 / 101) is None


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
    bounds = dict.fromkeys((("pinion", 1), ("pinion", 2), ("gear", 3)), (0.01, 5.0))
    factors = fitted_factors(case, model, allowance, {"line": 0.0}, bounds)
    # pinion order 2 pools 240 lines: within 25 %; the single-feature groups within a factor 1.6
    assert factors[("pinion", 2)] == pytest.approx(truth, rel=0.25)
    assert truth / 1.6 < factors[("gear", 3)] < truth * 1.6, factors
    assert truth / 1.6 < factors[("pinion", 1)] < truth * 1.6, factors
    scaled = scaled_line_errors(case, allowance, factors)
    assert scaled[..., 3] == pytest.approx(allowance[..., 3] * math.sqrt(factors[("gear", 3)]))
    summary = factors_summary(factors, bounds, dict.fromkeys(bounds, 2e-06))
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
    bounds = dict.fromkeys((("pinion", 1), ("pinion", 2), ("gear", 3)), (0.05, 4.0))
    factors = fitted_factors(case, np.zeros_like(observed), allowance, {"line": 0.0}, bounds)
    assert factors == {key: pytest.approx(4.0) for key in bounds}
