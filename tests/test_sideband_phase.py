"""The sideband phase-sum test of an eccentric shaft (uqgear.diagnosis.allowances.sideband_phase).

Checked against what the phase sum is built to be: blind to where a record
starts and to the modulation's own phase, sure of a pure amplitude
modulation's value, and scored by a density that prefers the hypothesis
whose draws sit where the rig's sums are. The whole test on constructed
class-7 campaigns is in tests/test_pitch_error_campaigns.py (slow).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from uqgear.diagnosis.allowances.sideband_phase import (
    ModulationEvidence,
    log_density,
    phase_sums,
    shafts_tested,
    sideband_triples,
)
from uqgear.diagnosis.settings import DEFAULT_SETTINGS

_NAMES = ["pinion1", "mesh1", "mesh1_sb_pinion+1", "mesh1_sb_pinion-1", "mesh2", "mesh2_sb_pinion+1",
          "mesh2_sb_pinion-1", "mesh1_sb_gear+1", "mesh1_sb_gear-1"]


def _modulated_phasors(start: float, modulation_phase: float, carrier_phase: float, z: int = 21) -> np.ndarray:
    """Line phasors of a carrier at order n z amplitude-modulated at order 1, the record starting at ``start`` rad.

    (1 + m cos(theta + psi)) cos(n z theta + chi) gives sidebands m/2 at
    n z +- 1 with phases chi +- psi; a record starting at shaft angle
    ``start`` turns each line of order q by q * start.
    """
    phasors = np.zeros(len(_NAMES), dtype=complex)
    for harmonic, (carrier, upper, lower) in zip((1, 2), ((1, 2, 3), (4, 5, 6))):
        order = harmonic * z
        phasors[carrier] = np.exp(1j * (carrier_phase + order * start))
        phasors[upper] = 0.1 * np.exp(1j * (carrier_phase + modulation_phase + (order + 1) * start))
        phasors[lower] = 0.1 * np.exp(1j * (carrier_phase - modulation_phase + (order - 1) * start))
    phasors[0] = 0.5 * np.exp(1j * (0.3 + start))
    return phasors


def test_triples_find_each_harmonic_with_both_sidebands_only():
    assert sideband_triples(_NAMES, "pinion") == [(1, 2, 3), (4, 5, 6)]
    # the gear's second harmonic lacks its sidebands here: only the first is a triple
    assert sideband_triples(_NAMES, "gear") == [(1, 7, 8)]
    assert sideband_triples(["mesh1", "mesh1_sb_pinion+1"], "pinion") == []


def test_a_pure_amplitude_modulation_sums_to_zero_wherever_the_record_starts():
    triples = sideband_triples(_NAMES, "pinion")
    for start, psi, chi in [(0.0, 0.0, 0.0), (1.234, 2.0, -0.7), (-3.0, 5.5, 2.9)]:
        sums = phase_sums(_modulated_phasors(start, psi, chi), triples)
        np.testing.assert_allclose(np.exp(1j * sums), 1.0, atol=1e-9)


def test_the_sum_does_not_follow_the_start_but_a_phase_modulation_moves_it():
    triples = sideband_triples(_NAMES, "pinion")
    base = _modulated_phasors(0.0, 0.4, 0.1)
    # a phase (frequency) modulation has sidebands in quadrature-opposite sign: lower one negated
    turned = base.copy()
    turned[[3, 6]] *= -1.0
    for start in (0.0, 0.77, 2.5):
        shifted = turned * np.exp(1j * start * np.array([1, 21, 22, 20, 42, 43, 41, 22, 20]))
        np.testing.assert_allclose(np.cos(phase_sums(shifted, triples)), -1.0, atol=1e-9)


def test_the_density_prefers_draws_centred_on_the_observed_sum():
    rng = np.random.default_rng(4)
    observed = np.array([0.2, -0.1])
    near = 0.2 + 0.05 * rng.standard_normal((30, 2))
    far = math.pi / 2 + 0.05 * rng.standard_normal((30, 2))
    noise = np.array([0.01, 0.01])
    assert np.all(log_density(observed, near, noise) > log_density(observed, far, noise) + 10.0)
    # a noisy sum tells the two apart far less: its own noise widens both densities
    loud = np.array([4.0, 4.0])
    gap_loud = log_density(observed, near, loud) - log_density(observed, far, loud)
    assert np.all(gap_loud < 2.0) and np.all(gap_loud > 0.0)


def test_the_density_integrates_to_one_over_the_circle():
    drawn = 1.0 + 0.3 * np.random.default_rng(5).standard_normal((40, 1))
    grid = np.linspace(-math.pi, math.pi, 4001)[:, None]
    density = np.exp(log_density(grid, drawn, np.array([0.05])))
    assert np.trapezoid(density[:, 0], grid[:, 0]) == pytest.approx(1.0, abs=1e-3)


def test_only_shafts_whose_sidebands_stand_off_their_carrier_are_tested():
    class Design:
        z1, z2 = 21, 101

    class Case:
        design = Design()

    assert shafts_tested(Case()) == ["pinion"]
    Design.z2 = 30
    assert 21 / 30 >= DEFAULT_SETTINGS.phases.min_sideband_orders and shafts_tested(Case()) == ["pinion", "gear"]


def test_evidence_is_decisive_only_at_its_threshold_and_not_on_one_operating_point():
    per_op = np.zeros((8, 3, 2))
    per_op[3, 0, 0] = 900.0           # all of it at one operating point
    lone = ModulationEvidence.from_sums("pinion", 12e-6, {0.01: per_op}, 48, threshold=150.0)
    assert lone.log_ratio == pytest.approx(0.0) and lone.total == pytest.approx(900.0) and not lone.decisive
    spread = np.zeros((8, 3, 2))
    spread[[0, 2, 3, 5], 0, 0] = [60.0, 160.0, 700.0, 450.0]
    found = ModulationEvidence.from_sums("pinion", 12e-6, {0.01: per_op, 0.03: spread}, 48, threshold=150.0)
    assert found.kappa == 0.03 and found.log_ratio == pytest.approx(670.0) and found.decisive
    assert found.summary()["named"] and found.supported_kappas() == [0.03]
    assert not ModulationEvidence.from_sums("pinion", 12e-6, {0.01: spread}, 0, threshold=150.0).decisive
