"""Diagnoses of constructed virtual-rig campaigns on class-7 gears (uqgear.diagnosis.allowances).

The modules: pitch_errors, pitch_orders (the rig's own gears, order by order) and sideband_phase.

Each campaign is built here with its pitch errors, effects and seed chosen
for the property it checks (docs/model/unmodelled-effects.md section 6.4):

- a healthy gear pair whose gear came out fine at one order: the allowance
  scaled to the rig's own gears reads that order's factor far below the
  classes' mean, within its range, and the verdict is `none`; the pinion's
  sideband phases hold no eccentricity;
- a 12 um pinion run-out with a stiffness modulation (kappa 0.03), a size
  the pinion's own first-order errors make too: named on its held-out
  density below the noise gap, on the pinion, with nothing else, for its
  modulation (its fitted run-out within what the classes make);
- friction and such a run-out on class-7 gears, 3 % noise: friction is
  named first and no wrong effect with it (torque ripple's motor line
  shares a sideband friction raises), and the run-out, which the line
  amplitudes cannot tell from the pinion's own errors, is named by the
  phase sums of the pinion's first sidebands.

The figures these rules were set on are in docs/validation/diagnosis.md,
"The pitch-error allowance". Apart from tests/test_manufacturing.py so
that the two workers share the slow tests.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from uqgear import validation as blind_test
from uqgear.diagnosis import Diagnosis, DiagnosisSeeds
from uqgear.diagnosis.settings import DEFAULT_SETTINGS
from uqgear.physics.effects import make_effect
from uqgear.physics.pitch_errors import PitchErrors, draw_pitch_errors, order_powers
from uqgear.rig.virtual_rig import simulate_campaign

#: A 12 um pinion run-out with a mesh-stiffness modulation: within what class 6-8 pinions make (95 %: 22 um).
_RUN_OUT = {"shaft": "pinion", "amplitude": 12e-6, "phase": 0.7, "kappa": 0.03}


def _with_order_power(positions: np.ndarray, order: int, power: float) -> np.ndarray:
    """Tooth positions whose ``order``-th Fourier coefficient has ``|E_j|^2 = power``, its phase and the rest kept."""
    teeth = positions.size
    basis = np.exp(2j * np.pi * order * np.arange(teeth) / teeth)
    coefficient = 2.0 / teeth * np.sum(positions * np.conj(basis))
    component = np.real(coefficient * basis)
    return positions - component + component * math.sqrt(power) / abs(coefficient)


def _class_7_campaign(design, effects, errors, seed):
    # the service plan's 8 runs of 1 s (on 4 runs of 0.5 s the forest of pitch-error lines is the noise floor)
    ops = blind_test.operating_points_of("service", design, 8)
    return simulate_campaign(design, ops, effects=effects, seed=seed, duration=1.0, run_in=0.3, pitch_errors=errors)


def _diagnosed(rig, design, effects):
    seeds = DiagnosisSeeds(np.random.SeedSequence(1), np.random.SeedSequence(2), np.random.SeedSequence(3))
    return Diagnosis(effects=effects, design=design, seed=seeds, workers=1).fit(rig)


@pytest.mark.slow
def test_a_healthy_class_7_gear_that_came_out_fine_at_one_order_is_scaled_there_and_none(design):
    """The gear's second-order errors at 3 % of the class's mean power: an allowance at the mean is far too wide there.

    Its factor, fitted from the rig's own second-order lines, must read it
    (below 0.3, inside its range), the other groups keep theirs, and a
    healthy pair is `none` with nothing named.
    """
    rng = np.random.default_rng(701)
    mean_power = float(np.mean(order_powers(np.array([draw_pitch_errors(design, 7, rng).gear for _ in range(2000)]),
                                            (2,))))
    drawn = draw_pitch_errors(design, 7, np.random.default_rng(702))
    errors = PitchErrors(drawn.pinion, _with_order_power(drawn.gear, 2, 0.03 * mean_power))
    assert order_powers(errors.gear, (2,))[0] == pytest.approx(0.03 * mean_power)
    rig = _class_7_campaign(design, [], errors, seed=703)
    # eccentricity: the candidate a gear's own errors at an order most resemble, and the one whose
    # pinion sideband phases are tested
    result = _diagnosed(rig, design, ["eccentricity"]).outcome_
    assert result.pitch_errors.applied
    assert result.verdict == "none" and result.selected == [], result.reason
    assert result.nominal_gap <= 0.5
    factors = result.pitch_errors.factors
    assert factors[("gear", 2)] < 0.3, factors
    low, high = result.pitch_errors.factor_bounds[("gear", 2)]
    assert low <= factors[("gear", 2)] <= high
    summary = result.pitch_errors.summary()["order_factors"]
    assert summary["gear"]["2"]["factor"] == factors[("gear", 2)] and summary["pinion"]["1"]["amplitude_m"] > 0
    # the pinion's sideband phases were tested and hold no eccentricity
    assert [evidence.shaft for evidence in result.modulation] == ["pinion"]
    assert not result.modulation[0].decisive


@pytest.mark.slow
def test_a_run_out_within_the_pinions_own_errors_is_named_on_its_held_out_density_and_nothing_else(design):
    """A 12 um pinion run-out with kappa 0.03 on class-7 gears (classes 6-8 make up to 22 um, 95 %).

    The amplitudes alone cannot tell it from the pinion's own first-order
    errors, which add to it; its mesh-stiffness modulation, which pitch
    errors do not make, can. With the allowance scaled to the rig's own
    gears the nominal gap is within noise, and the run-out is named on its
    held-out density at the 90 % lower bound: on the pinion, with no damaged
    tooth beside it, its fitted run-out within what the classes make and its
    modulation found.
    """
    rig = _class_7_campaign(design, [make_effect("eccentricity", _RUN_OUT)], 7, seed=704)
    diagnosis = _diagnosed(rig, design, ["eccentricity", "tooth_damage"])
    result = diagnosis.outcome_
    assert result.pitch_errors.applied and result.nominal_gap <= 0.5
    assert result.verdict == "eccentricity", result.reason
    assert [chosen.entry.effect for chosen in result.selected] == ["eccentricity"]
    assert result.named_shafts == ["pinion"], result.reason
    assert "lower bound" in result.reason, result.reason
    entry = result.selected[0].entry
    # the amplitude reads the run-out with the pinion's own first order: within the classes' bound
    low, high = entry.parameter_intervals()["amplitude"]
    assert 0.0 < low <= high < diagnosis.case_.run_out_allowance["pinion"], (low, high)
    # named for the modulation pitch errors do not make: switching it off costs more than the effect-gain rule asks
    assert entry.modulation_gain >= DEFAULT_SETTINGS.verdict.effect_gain_threshold
    kappa_low, kappa_high = entry.parameter_intervals()["kappa"]
    assert kappa_low <= _RUN_OUT["kappa"] <= kappa_high, (kappa_low, kappa_high)
    assert result.cannot_tell() == []


@pytest.mark.slow
def test_friction_on_class_7_gears_is_named_first_and_a_run_out_by_its_sideband_phases(design):
    """Friction 0.12 and a 12 um pinion run-out (kappa 0.03) on class-7 gears, 3 % noise.

    Friction acting with the pitch errors raises the TE's pinion sidebands
    below the first mesh harmonic; torque ripple's motor line (order 18)
    shares the third of them on the 21-tooth pinion. With each model's own
    allowance friction is named first and torque ripple not at all. The
    run-out is within the pinion's own first-order errors, so its line
    amplitudes cannot name it; its mesh-stiffness modulation sets the phase
    sums of the pinion's first sidebands where pitch errors do not, and it
    is named by them, its run-out left open by the amplitudes and its
    interval holding the truth.
    """

    effects = [make_effect("friction", {"coefficient": 0.12}), make_effect("eccentricity", _RUN_OUT)]
    ops = blind_test.operating_points_of("service", design, 8)
    rig = simulate_campaign(design, ops, effects=effects, seed=705, duration=1.0, run_in=0.3, pitch_errors=7,
                            relative_noise=0.03)
    result = _diagnosed(rig, design, ["friction", "torque_ripple", "eccentricity"]).outcome_
    assert result.pitch_errors.applied
    named = [chosen.entry.effect for chosen in result.selected]
    assert named == ["friction", "eccentricity"], result.reason
    assert result.named_shafts == ["pinion"], result.reason
    # the pinion's first order reads as errors many class 6-8 pinions have: the amplitudes cannot name it
    share = result.pitch_errors.summary()["order_factors"]["pinion"]["1"]["share_of_class_gears_below"]
    assert share < DEFAULT_SETTINGS.pitch.large_run_out_share
    evidence = result.modulation[0]
    assert evidence.shaft == "pinion" and evidence.decisive
    assert evidence.log_ratio >= DEFAULT_SETTINGS.phases.phase_evidence_threshold
    assert evidence.total > evidence.log_ratio
    assert "phase sums of the pinion's first sidebands" in result.reason
    chosen = result.selected[1]
    assert chosen.entry.parameters()["kappa"] == evidence.kappa
    low, high = chosen.entry.parameter_intervals()["amplitude"]
    assert low <= _RUN_OUT["amplitude"] <= high and low <= evidence.run_out <= high, (low, high)
    assert "90 % interval" in result.reason
    assert result.cannot_tell() == []
