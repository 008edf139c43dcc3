"""Campaigns of the real-world blind test with pitch errors, rebuilt as ``uqgear blindtest`` builds them.

Out-of-sample misses of the per-run allowance that the rig's own gears,
order by order, fix (uqgear.diagnosis.allowances.pitch_orders, docs/model/unmodelled-effects.md section
6.4): seed 3's healthy class-7 control is `none`, not `unexplained`, and
seed 4's 12 um pinion run-out is named on its held-out density, not left
`unexplained` behind a damaged tooth. Seed 2's friction and run-out under
every nuisance names friction and no wrong effect (the run-out is within
the pinion's own first-order errors), and seed 2's pitch-error campaign
names its run-out by the pinion's sideband phases. Apart from tests/test_manufacturing.py
so that the two workers share the slow tests.
"""

from __future__ import annotations

import numpy as np
import pytest

from uqgear import validation as blind_test
from uqgear.diagnosis import Diagnosis, DiagnosisSeeds
from uqgear.diagnosis.settings import DEFAULT_SETTINGS
from uqgear.validation.campaigns import true_values


def _real_world_case(seed: int, prefix: str):
    """One campaign of the real-world blind test, rebuilt and diagnosed as ``uqgear blindtest --suite real_world`` does.

    Returns the fitted diagnosis and the campaign's spec.
    """
    from uqgear.physics.design import load_design

    plan_seed, campaigns_seed = np.random.SeedSequence(seed).spawn(2)
    specs = blind_test.plan_real_world(1, np.random.default_rng(plan_seed))
    index = next(k for k, spec in enumerate(specs) if spec.identifier.startswith(prefix))
    spec = specs[index]
    generation, noise, diagnosis, reference = campaigns_seed.spawn(len(specs))[index].spawn(4)
    reference_design = load_design("locomotive")
    design = reference_design if spec.design_name == "reference" else blind_test.second_design(reference_design)
    rig = blind_test.rig_campaign(spec, design, blind_test.operating_points_of(spec.plan, design, 8),
                                  true_values(spec, design), spec.effects(), generation, 1.0, f"seed {seed}")
    for name in ("true_parameters", "effects", "noise"):
        rig.attrs.pop(name, None)
    seeds = DiagnosisSeeds(noise, diagnosis, reference.spawn(2)[1])
    return Diagnosis(design=design, seed=seeds, workers=1).fit(rig), spec


@pytest.mark.slow
def test_a_healthy_class_7_control_whose_gear_came_out_fine_at_one_order_is_none():
    """The real-world blind test's pitch-error control of seed 3.

    Its gear's own second-order errors came out at about a tenth of the
    classes' mean power: the allowance at the mean put its 168 second-order
    lines at a median z of -1.4 and left a held-out gap of 0.66,
    `unexplained`. Scaled to the rig order by order, the
    gap is within noise and nothing is named.
    """
    diagnosis, spec = _real_world_case(3, "control_pitch_errors")
    assert spec.truth_set() == [] and spec.nuisances.get("pitch_errors") == 7
    result = diagnosis.outcome_
    assert result.pitch_errors.applied
    assert result.verdict == "none" and result.selected == [], result.reason
    assert result.nominal_gap <= 0.5
    factors = result.pitch_errors.factors
    assert factors[("gear", 2)] < 0.3, factors
    low, high = result.pitch_errors.factor_bounds[("gear", 2)]
    assert low <= factors[("gear", 2)] <= high
    summary = result.pitch_errors.summary()["order_factors"]
    assert summary["gear"]["2"]["factor"] == factors[("gear", 2)] and summary["pinion"]["1"]["amplitude_m"] > 0
    # the pinion's sideband phases were tested and hold no eccentricity (-43 nats in the blind test)
    assert [evidence.shaft for evidence in result.modulation] == ["pinion"]
    assert result.modulation[0].log_ratio < 0.0 and not result.modulation[0].decisive


@pytest.mark.slow
def test_a_run_out_on_class_7_gears_is_named_not_left_unexplained_behind_a_damaged_tooth():
    """The real-world blind test's pitch-error campaign of seed 4: a 12 um pinion run-out (kappa 0.03).

    With the allowance at the classes' mean the nominal gap was 0.78, a
    damaged gear tooth led at 38 nats with 16 % of it and the campaign was
    `unexplained`. Scaled to the rig's own gears the gap
    is within noise and the run-out is named on its held-out density.
    """
    diagnosis, spec = _real_world_case(4, "pitch_errors")
    assert spec.truth_set() == ["eccentricity"] and spec.nuisances.get("pitch_errors") == 7
    result = diagnosis.outcome_
    assert result.pitch_errors.applied and result.nominal_gap <= 0.5
    assert result.verdict == "eccentricity", result.reason
    assert [chosen.entry.effect for chosen in result.selected] == ["eccentricity"]
    assert "lower bound" in result.reason


@pytest.mark.slow
def test_friction_on_class_7_gears_is_named_first_and_no_wrong_effect_with_it():
    """The real-world blind test's all-nuisances campaign of seed 2.

    A 12 um pinion run-out (kappa 0.03) and friction on class-7 gears, with
    +-0.5 % speed wander, 50/150 Hz mains and 3 % noise. Friction acting
    with the pitch errors raises the TE's pinion sidebands below the first
    mesh harmonic; torque ripple's motor line (order 18) shares the third of
    them on the 21-tooth pinion and can be named first. The
    run-out is named with friction only while the pinion's own first-order
    errors are held at the classes' mean; scaled to the
    rig, they take it (a run-out within what the classes make is not
    evidence of an eccentric shaft): friction alone, nothing wrong.
    """
    diagnosis, spec = _real_world_case(2, "two_effects_nuisances")
    assert set(spec.truth_set()) == {"eccentricity", "friction"} and spec.nuisances.get("pitch_errors") == 7
    result = diagnosis.outcome_
    assert result.pitch_errors.applied
    named = [chosen.entry.effect for chosen in result.selected]
    assert named[:1] == ["friction"] and set(named) <= {"friction", "eccentricity"}, result.reason
    if "eccentricity" not in named:
        # not named, but not passed over either: the pinion's first order reads larger than most class-6-8
        # pinions have (about 95 % of them), so the report says a run-out may hide there
        reports = result.cannot_tell()
        assert [entry["shaft"] for entry in reports] == ["pinion"], reports
        assert reports[0]["share_of_class_gears_below"] >= DEFAULT_SETTINGS.pitch.large_run_out_share
        assert result.pitch_errors.summary()["order_factors"]["pinion"]["1"]["share_of_class_gears_below"] == \
            reports[0]["share_of_class_gears_below"]


@pytest.mark.slow
def test_a_run_out_within_the_pinions_own_errors_is_named_by_its_sideband_phases():
    """The real-world blind test's pitch-error campaign of seed 2: a 12 um pinion run-out (kappa 0.03).

    The pinion's first order reads as its own class-7 errors (below the 90 %
    share of cannot_tell), the amplitudes name nothing and the verdict was
    `none` on amplitudes alone. The run-out's mesh-stiffness modulation sets
    the phase sums of the pinion's first sidebands where pitch errors do
    not: 1013 nats in the blind test, far beyond the 200 that name it, with
    the most favourable run left out (docs/model/unmodelled-effects.md section 6.4).
    """

    diagnosis, spec = _real_world_case(2, "pitch_errors")
    assert spec.truth_set() == ["eccentricity"] and spec.nuisances.get("pitch_errors") == 7
    assert dict(spec.effects()[0].values)["shaft"] == "pinion"
    result = diagnosis.outcome_
    assert result.pitch_errors.applied
    assert result.verdict == "eccentricity" and result.named_shafts == ["pinion"], result.reason
    evidence = result.modulation[0]
    assert evidence.shaft == "pinion" and evidence.decisive
    threshold = DEFAULT_SETTINGS.phases.phase_evidence_threshold
    assert evidence.log_ratio >= 2 * threshold and evidence.total > evidence.log_ratio
    assert "phase sums of the pinion's first sidebands" in result.reason
    chosen = result.selected[0]
    # the modulation the sums favour is held in the fit; the amplitudes leave the run-out open (the pinion's
    # own first-order errors), and its interval says so: it holds the true 12 um and the run-out read
    assert chosen.entry.parameters()["kappa"] == evidence.kappa
    low, high = chosen.entry.parameter_intervals()["amplitude"]
    assert low <= 12e-6 <= high and low <= evidence.run_out <= high
    assert "90 % interval" in result.reason
    assert result.cannot_tell() == []
