"""Campaigns of the real-world blind test with pitch errors, rebuilt as ``uqgear blindtest`` builds them.

Seed 2's campaigns must name exactly their effects: friction and a 12 um
pinion run-out under every nuisance, and a 12 um run-out whose evidence the
pitch-error allowance spreads below the held-out gap
(uqgear.diagnosis.manufacturing, docs/model.md section 6.4). Apart from
tests/test_manufacturing.py so that the two workers share the slow tests.
"""

from __future__ import annotations

import numpy as np
import pytest

from uqgear.diagnosis import blind_test, pipeline, prepare_case


def _real_world_case(seed: int, prefix: str):
    """One campaign of the real-world blind test, rebuilt as ``uqgear blindtest --suite real_world`` builds it.

    Returns the blind case, its spec and the diagnosis's seed.
    """
    from uqgear.physics.design import load_design

    plan_seed, campaigns_seed = np.random.SeedSequence(seed).spawn(2)
    specs = blind_test.plan_real_world(1, np.random.default_rng(plan_seed))
    index = next(k for k, spec in enumerate(specs) if spec.identifier.startswith(prefix))
    spec = specs[index]
    generation, noise, diagnosis, _ = campaigns_seed.spawn(len(specs))[index].spawn(4)
    reference = load_design("locomotive")
    design = reference if spec.design_name == "reference" else blind_test.second_design(reference)
    rig = blind_test._rig_campaign(spec, design, blind_test.operating_points_of(spec.plan, design, 8),
                                   blind_test._true_values(spec, design), spec.effects(), generation, 1.0,
                                   f"seed {seed}")
    for name in ("true_parameters", "effects", "noise"):
        rig.attrs.pop(name, None)
    return prepare_case(rig, design, seed=noise), spec, diagnosis


@pytest.mark.slow
def test_friction_and_the_run_out_on_class_7_gears_are_named_not_a_motor_line_that_shares_a_sideband():
    """The real-world blind test's all-nuisances campaign of seed 2.

    A 12 um pinion run-out (kappa 0.03) and friction on class-7 gears, with
    +-0.5 % speed wander, 50/150 Hz mains and 3 % noise. Friction acting
    with the pitch errors raises the TE's pinion sidebands below the first
    mesh harmonic; torque ripple's motor line (order 18) shares the third of
    them on the 21-tooth pinion. Scored with the nominal model's pitch-error
    allowance, friction was screened at 33 nats and never fitted in full,
    and torque ripple (146 nats) was named first (session 11); with each
    fit's own allowance friction alone was named (session 12), the run-out
    (within the classes' own first-order run-out of up to 22 um) held back
    by the run-out guard. Its mesh-stiffness modulation lifts the guard, and
    torque ripple, which gains 21 nats on top of both at a held-out gap of
    0.00, must not be added on density alone: exactly the two.
    """
    case, spec, diagnosis = _real_world_case(2, "two_effects_nuisances")
    assert set(spec.truth_set()) == {"eccentricity", "friction"} and spec.nuisances.get("pitch_errors") == 7
    result = pipeline.run_diagnosis(case, seed=diagnosis)
    assert result.pitch_errors.applied
    named = [chosen.entry.effect for chosen in result.selected]
    assert named == ["friction", "eccentricity"], result.reason
    run_out = result.selected[1].entry
    assert run_out.modulation_gain >= 5.0 and 0.015 < run_out.parameters()["kappa"] < 0.05


@pytest.mark.slow
def test_a_run_out_whose_evidence_the_allowance_spreads_below_the_gap_is_named_on_its_density():
    """The real-world blind test's pitch-error campaign of seed 2: a 12 um pinion run-out on class-7 gears.

    With the allowance the nominal model's held-out gap is 0.00 (nothing to
    shrink) while the eccentricity gains 65 nats of held-out density with
    kappa 0.028 (true 0.03); it was `none` (session 12).
    """
    case, spec, diagnosis = _real_world_case(2, "pitch_errors")
    assert spec.truth_set() == ["eccentricity"] and spec.nuisances.get("pitch_errors") == 7
    result = pipeline.run_diagnosis(case, seed=diagnosis)
    assert result.pitch_errors.applied and result.nominal_gap <= 0.5
    assert result.verdict == "eccentricity", result.reason
    assert [chosen.entry.effect for chosen in result.selected] == ["eccentricity"]
    assert "lower bound" in result.reason
    assert result.best.modulation_gain >= 5.0 and result.ranking()[0]["modulation_gain"] == result.best.modulation_gain
