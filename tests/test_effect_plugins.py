"""Effect families as plug-ins of the diagnosis (uqgear.diagnosis.effects).

Fast tests check the registry (library order, refusals) and every library
family's variants against its physics slot: the fitted parameters' bounds
lie inside what the effect accepts and every start lies inside the bounds;
and that a family registered from outside gets the defaults of the hooks the
rules ask (no run-out, nothing in proportion) and can give its physics to
the foreign rig. The slow test registers a toy effect that no diagnosis module knows (a
drive-torque fluctuation at twice the pinion's rotation, as a cardan joint
makes), makes a virtual-rig campaign with it, and checks that the diagnosis
screens it, fits it in full and names it with the strength it was made with.
"""

from __future__ import annotations

import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from uqgear.common.errors import RigDataError
from uqgear.diagnosis import Diagnosis, DiagnosisError, register_effect, unregister_effect
from uqgear.diagnosis.effects import (
    LIBRARY,
    START_PHASES,
    EffectFamily,
    RunOut,
    check_effects,
    effect_family,
    effect_names,
    hooks_of,
    run_out_family,
)
from uqgear.diagnosis.scoring import CandidateScore
from uqgear.diagnosis.screening import with_modulation_gain
from uqgear.diagnosis.verdict import run_out_check, verdict_rules
from uqgear.physics.effects import EFFECTS, Effect, EffectParameter
from uqgear.rig.foreign_rig import effect_vector, register_foreign_physics
from uqgear.rig.virtual_rig import simulate_campaign
from uqgear.validation import operating_points_of


class CardanRipple(Effect):
    """Drive torque T1 (1 + r cos(2 W1 t + phase)): a cardan joint's fluctuation at twice the shaft's rotation."""

    name = "cardan_ripple"
    PARAMETERS = {"amplitude": EffectParameter(0.02, 0.0, 0.5, "1", "relative drive torque fluctuation r"),
                  "phase": EffectParameter(0.0, -2 * math.pi, 2 * math.pi, "rad", "phase")}

    def apply(self, setup) -> None:
        # the torque-ripple slots, at the second pinion order instead of the motor's
        setup.set_slot("ripple_amplitude", self.values["amplitude"])
        setup.set_slot("ripple_omega", 2.0 * setup.pinion_rotation)
        setup.set_slot("ripple_phase", self.values["phase"])


class CardanRippleFamily(EffectFamily):
    """What the diagnosis needs of the toy effect: one variant, amplitude and phase fitted."""

    name = "cardan_ripple"
    physics = CardanRipple
    strength = "amplitude"
    ladder = (0.002, 0.01, 0.05)

    def variants(self, design, hints):
        fitted = (self.strength_parameter("amplitude", 0.01, upper=0.3),
                  self.parameter("phase", 1.0, 0.0, 2.0 * math.pi))
        starts = self.grid(amplitude=(0.003, 0.05), phase=START_PHASES)
        return [self.candidate("cardan_ripple", (), fitted, starts, "pinion")]


def test_the_library_is_registered_in_the_physics_order():
    assert effect_names()[:len(LIBRARY)] == tuple(EFFECTS)
    assert check_effects(None) == effect_names() and check_effects("friction") == ("friction",)
    with pytest.raises(DiagnosisError, match="effects: 'wear' is not a library effect"):
        effect_family("wear")
    with pytest.raises(DiagnosisError, match="'friction' is a library effect and stays registered"):
        unregister_effect("friction")
    with pytest.raises(DiagnosisError, match="'friction' is already registered"):
        register_effect(effect_family("friction"))


@pytest.mark.parametrize("family", LIBRARY, ids=lambda family: family.name)
def test_every_library_family_fits_inside_what_its_physics_accepts(family, design):
    assert family.physics is EFFECTS[family.name] and family.strength in family.physics.PARAMETERS
    hints = {"eccentricity_pinion": 8e-6, "eccentricity_gear": 2e-5, "adhesion_frequency": 12.0}
    variants = family.variants(design, hints)
    assert variants and len({variant.label for variant in variants}) == len(variants)
    for variant in variants:
        for spec in variant.fitted:
            definition = family.physics.PARAMETERS[spec.name.split(".", 1)[1]]
            assert definition.lower <= spec.lower < spec.upper <= definition.upper, spec
            low, high = spec.bounds()
            for start in variant.starts:
                assert low <= spec.to_optimiser(start[spec.name]) <= high
        # the variant builds its physics effect at any start
        effect = variant.make(variant.starts[0])
        assert isinstance(effect, family.physics)
    # a virtual-rig campaign's values at each strength build the effect too
    rng = np.random.default_rng(0)
    for strength in family.ladder:
        assert family.make(family.campaign_values(strength, 1.0, rng)).values[family.strength] == strength


def test_only_the_run_out_family_has_the_run_out_hooks():
    assert [family.name for family in LIBRARY if family.run_out is not None] == ["eccentricity"]
    assert effect_family("eccentricity").run_out == RunOut("amplitude", "phase", "shaft", "kappa")
    assert dict(effect_family("eccentricity").proportional) == {"kappa": 2500.0}
    assert all(not family.proportional for family in LIBRARY if family.name != "eccentricity")
    assert run_out_family().name == "eccentricity" and run_out_family(["friction"]) is None
    assert effect_family("eccentricity").run_out_shaft({"shaft": "gear", "amplitude": 1e-6}) == "gear"


def _toy_score(design):
    """A hand-built full-fit score of the toy (what the rules read of it)."""
    (variant,) = CardanRippleFamily().variants(design, {})
    fit = SimpleNamespace(problem=SimpleNamespace(candidate=variant),
                          values={"cardan_ripple.amplitude": 0.05, "cardan_ripple.phase": 1.0})
    held = SimpleNamespace(z=np.zeros((2, 1, 1)))
    return CandidateScore("cardan_ripple", variant.label, fit, held, "full", 70.2, 20.0, 5.0, 65.2, 0.0, 0.0,
                          (0.0, 0.0), effect_gain=29.0, channels=("te",))


def test_a_registered_toy_gets_the_hooks_defaults(design):
    """A family that sets no hook is no run-out: no run-out check, no modulation measure, nothing in proportion."""
    family = CardanRippleFamily()
    assert family.run_out is None and dict(family.proportional) == {}
    assert family.run_out_shaft({"amplitude": 0.05}) is None
    # an unregistered name gets the same defaults
    assert hooks_of("cardan_ripple").run_out is None and dict(hooks_of("cardan_ripple").proportional) == {}
    register_effect(family)
    try:
        assert hooks_of("cardan_ripple") is family
        assert run_out_family().name == "eccentricity"
        score = _toy_score(design)
        bounds = (("pinion", 22e-6), ("gear", 30e-6))
        assert run_out_check(score, replace(verdict_rules(case="pitch_errors"), run_out_bounds=bounds)) is None
        assert with_modulation_gain(SimpleNamespace(run_out_allowance={"pinion": 22e-6}), score) is score
        assert score.modulation_gain is None
    finally:
        unregister_effect("cardan_ripple")


def test_the_foreign_rig_takes_a_registered_physics():
    """The foreign rig's effect slots are filled through its registry: a toy gives its own, an unknown is refused."""
    class Unknown(Effect):
        name = "unknown_toy"

    with pytest.raises(RigDataError, match="the foreign rig has no physics for 'unknown_toy'"):
        effect_vector([Unknown()], None)

    @register_foreign_physics(CardanRipple)
    def _cardan(values, design, eff):
        # the drive torque ripple's slots, at the second pinion order
        eff[8:11] = (values["amplitude"], 2.0, values["phase"])

    eff = effect_vector([CardanRipple({"amplitude": 0.05, "phase": 1.0})], None)
    assert eff[8:11].tolist() == [0.05, 2.0, 1.0] and not eff[:8].any() and not eff[11:].any()
    assert effect_vector([EFFECTS["friction"]({"coefficient": 0.08})], None)[7] == 0.08


@pytest.mark.slow
def test_a_registered_toy_effect_is_screened_fitted_and_named(design):
    """No diagnosis module knows the toy: its family module (here, this test) and a registry call suffice."""
    rig = simulate_campaign(design, operating_points_of("service", design, 4), seed=3, duration=0.5, run_in=0.3,
                            effects=[CardanRipple({"amplitude": 0.05, "phase": 1.0})])
    register_effect(CardanRippleFamily())
    try:
        assert "cardan_ripple" in effect_names()
        diagnosis = Diagnosis(effects=["cardan_ripple", "eccentricity"], workers=1).fit(rig)
    finally:
        unregister_effect("cardan_ripple")
    assert "cardan_ripple" not in effect_names()
    steps = [entry["step"] for entry in diagnosis.steps_.finished]
    assert "screen cardan_ripple" in steps and "fit cardan_ripple in full" in steps
    assert diagnosis.decision_.verdict == "cardan_ripple", diagnosis.decision_.reason
    (named,) = diagnosis.effects_
    assert named.entry.stage == "full" and named.entry.parameters()["amplitude"] == pytest.approx(0.05, rel=0.1)
    # the hooks' defaults: no run-out check and no modulation measure for it
    assert named.entry.run_out is None and named.entry.modulation_gain is None
    assert diagnosis.to_dict()["effects"][0]["effect"] == "cardan_ripple"
