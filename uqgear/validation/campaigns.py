"""The virtual rig's campaign plans for the blind test: what each campaign is made of, withheld from the diagnosis.

:func:`plan_campaigns` (suite ``library``) gives each effect family's
campaigns over its strength ladder (weak near detectability, medium, the
public campaigns' own strong level; :attr:`~uqgear.diagnosis.effects.EffectFamily.ladder`)
on two designs, with healthy controls; :func:`plan_real_world` (suite
``real_world``) gives campaigns that are not the model plus one effect on a
clean rig: two effects at once, a transfer-path resonance with a healthy
reference, speed wander, pitch errors, and healthy controls with those
nuisances. :func:`rig_campaign` makes a planned campaign with the virtual rig.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import xarray as xr

from ..diagnosis import DiagnosisError, effect_family
from ..diagnosis.effects import LIBRARY
from ..physics.design import Design
from ..physics.effects import Effect
from ..rig.transfer_path import apply_transfer_path
from ..rig.virtual_rig import (
    DEFAULT_DRIVE_TORQUES,
    DEFAULT_PINION_SPEEDS,
    bearing_check_operating_points,
    simulate_campaign,
)

#: Label of the healthy controls (the verdict they should get).
HEALTHY = "none"

#: Relative strengths of the effect ladder: weak (near detectability), medium, strong.
STRENGTHS: tuple[str, ...] = ("weak", "medium", "strong")

#: Test plans of the campaigns: the public campaigns' 8 service points, or the light-load
#: run through the bearing modes (:func:`uqgear.rig.virtual_rig.bearing_check_operating_points`).
PLANS: tuple[str, ...] = ("service", "bearing_check")

#: A further plan of the real-world suite: 8 runs at 500-1400 rpm (service torques), where the gear's
#: sidebands lie 0.2 pinion orders, 2-5 Hz, from their carrier and speed wander moves the lines most.
LOW_SPEED_PLAN = "low_speed"
LOW_SPEED_PINION_SPEEDS: tuple[float, ...] = (500.0, 600.0, 700.0, 800.0, 950.0, 1100.0, 1250.0, 1400.0)

#: Blind-test suites: the library's effects one at a time on a clean rig, real-world campaigns, each
#: effect on a rig without encoders (accelerometers only), or the real-world campaigns as run-ups and
#: coast-downs (:mod:`.runup_campaigns`).
SUITES: tuple[str, ...] = ("library", "real_world", "encoderless", "runup")

#: The encoder-less suite's channels: the two bearing housings' accelerometers, no TE.
ENCODERLESS_CHANNELS: tuple[str, ...] = ("acc_pinion", "acc_gear")

#: The designs a blind test alternates.
DESIGNS: tuple[str, ...] = ("reference", "second")

#: The library's effect families, the ones a blind test plans campaigns of.
LIBRARY_EFFECTS: tuple[str, ...] = tuple(family.name for family in LIBRARY)


def second_design(reference: Design) -> Design:
    """The second blind-test design: z1 = 17, z2 = 88, module 10 mm, x1 = +0.3, x2 = -0.3, b = 130 mm."""
    return reference.replace(z1=17, z2=88, module=0.010, x1=0.3, x2=-0.3, face_width=0.130)


@dataclass(frozen=True)
class CampaignSpec:
    """One blind-test campaign: its truth (withheld from the diagnosis) and how to generate it."""

    identifier: str
    truth: str
    strength: str
    strength_value: float
    design_name: str
    effect_values: dict[str, object]
    true_parameters: dict[str, float]
    plan: str = "service"
    # further effects acting at once, as (name, values) pairs (the real-world suite)
    extra_effects: tuple[tuple[str, dict[str, object]], ...] = ()
    # rig nuisances: options of simulate_campaign (speed_wander, line_interference, relative_noise,
    # pitch_errors, channels, encoder_run_out) and "transfer_path" (frequency, damping) on acc_pinion;
    # "reference": the diagnosis gets a healthy campaign of the same rig (same nuisances, own seed)
    nuisances: dict[str, object] = field(default_factory=dict)
    # the verdict a right diagnosis gives where it is not the truth's: "unexplained" for a campaign whose only
    # departure from the model is one sensor's own artefact (no gear effect acts, none may be named)
    expected_verdict: str = ""

    def right_verdict(self) -> str:
        """The verdict a right diagnosis gives: ``expected_verdict`` where set, else the truth."""
        return self.expected_verdict or self.truth

    def effects(self) -> list[Effect]:
        """The physics effects acting on the campaign, the leading one first."""
        leading = [] if self.truth == HEALTHY else [effect_family(self.truth).make(self.effect_values)]
        return leading + [effect_family(name).make(values) for name, values in self.extra_effects]

    def truth_set(self) -> list[str]:
        """The library effects acting on the campaign, in order (empty for a healthy control)."""
        return [effect.name for effect in self.effects()]


def check_count(name: str, value: object, lowest: int) -> int:
    """An integer setting of at least ``lowest`` (DiagnosisError naming it otherwise)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lowest:
        raise DiagnosisError(f"{name}: expected an integer >= {lowest}; got {value!r}")
    return int(value)


def plan_campaigns(
    n_per_effect: int,
    rng: np.random.Generator,
    *,
    effects: Sequence[str] | None = None,
    designs: Sequence[str] = DESIGNS,
    n_healthy: int | None = None,
) -> list[CampaignSpec]:
    """The campaigns of a blind test: per effect ``n_per_effect`` over the strength ladder and designs.

    True nominal parameters scatter around the design (stiffness scale
    +-7 %, mesh damping and STE amplitude +-20 %, bearing stiffnesses and
    backlash +-10 %); phases, teeth, shafts and stick-slip frequencies are
    drawn at random. Campaigns follow the service plan, except bearing
    clearance ones: the bearing check plan, the only one where a clearance
    can show (each family's ``plan``). ``effects`` default to the library's.
    Healthy controls (``n_healthy``, default ``2 n_per_effect``)
    use the same scatter without an effect and alternate the two plans
    (service first), so that false alarms are checked on both.
    """
    n_per_effect = check_count("n_per_effect", n_per_effect, 1)
    n_healthy = 2 * n_per_effect if n_healthy is None else check_count("n_healthy", n_healthy, 0)
    effects = LIBRARY_EFFECTS if effects is None else tuple(effects)
    for name in effects:
        if name not in LIBRARY_EFFECTS:
            raise DiagnosisError(f"effects: {name!r} is not a library effect; expected {', '.join(LIBRARY_EFFECTS)}")
    check_designs(designs)
    specs: list[CampaignSpec] = []
    # strongest first when there are fewer campaigns than levels: the ladder starts from a clear case
    order = (2, 0, 1)
    for truth in list(effects) + [HEALTHY]:
        count = n_healthy if truth == HEALTHY else n_per_effect
        for k in range(count):
            # healthy controls alternate the plans first and the designs second
            design_name = designs[(k // len(PLANS) if truth == HEALTHY else k) % len(designs)]
            true_parameters = scattered_truth(rng)
            if truth == HEALTHY:
                specs.append(
                    CampaignSpec(
                        f"{truth}-{k}", truth, "-", 0.0, design_name, {}, true_parameters, PLANS[k % len(PLANS)]
                    )
                )
                continue
            level = order[k % 3]
            family = effect_family(truth)
            strength = family.ladder[level]
            effect_values = effect_draw(truth, strength, rng)
            plan = family.plan
            specs.append(
                CampaignSpec(
                    f"{truth}-{k}", truth, STRENGTHS[level], strength, design_name, effect_values, true_parameters, plan
                )
            )
    return specs


# The real-world suite's kinds, each a function of the draw. Strengths are the ladder's strong level
# (the public campaigns' own) or medium, so that a miss is the rig's doing, not the effect's weakness.
# The nuisance sets without pitch errors are public: the run-up suite (runup_campaigns) takes them too.
RESONANCE_NUISANCES: dict[str, object] = {"transfer_path": (2500.0, 0.05)}
WANDER_NUISANCES: dict[str, object] = {"speed_wander": [(0.005, 1.3)]}
_PITCH: dict[str, object] = {"pitch_errors": 7}
MAINS_NOISE_NUISANCES: dict[str, object] = {"line_interference": {50.0: 0.5, 150.0: 0.2}, "relative_noise": 0.03}
_ALL_NUISANCES: dict[str, object] = {**WANDER_NUISANCES, **_PITCH, **MAINS_NOISE_NUISANCES}
ACCELEROMETER_NUISANCES: dict[str, object] = {"channels": ("acc_pinion", "acc_gear")}
# an eccentric encoder mounting on both shafts: TE lines at 1x pinion and 1x gear rotation, nothing else
ENCODER_NUISANCES: dict[str, object] = {"encoder_run_out": {"pinion": 8e-6, "gear": 8e-6}}
_REAL_WORLD_KINDS: tuple[tuple[str, tuple[str, ...], dict[str, object]], ...] = (
    # (kind, effects (leading first), nuisances)
    ("two_effects", ("eccentricity", "tooth_damage"), {}),
    ("two_effects", ("torque_ripple", "tooth_damage"), {}),
    ("two_effects_nuisances", ("eccentricity", "friction"), _ALL_NUISANCES),
    ("resonance_reference", ("eccentricity",), {**RESONANCE_NUISANCES, "reference": True}),
    ("wander", ("tooth_damage",), WANDER_NUISANCES),
    ("pitch_errors", ("eccentricity",), _PITCH),
    ("control_wander", (), WANDER_NUISANCES),
    ("control_pitch_errors", (), _PITCH),
    ("control_mains_noise", (), MAINS_NOISE_NUISANCES),
    ("control_all_nuisances", (), _ALL_NUISANCES),
    ("control_resonance_reference", (), {**RESONANCE_NUISANCES, "reference": True}),
    # healthy class-7 gears at low speeds under wander of several levels and rates, 3-5 % noise, with and
    # without the TE: the gear's sidebands crowd their carrier where the order tracking follows the wander
    (
        "control_wander_accelerometers",
        (),
        {**WANDER_NUISANCES, **_PITCH, "relative_noise": 0.03, **ACCELEROMETER_NUISANCES},
    ),
    (
        "control_low_speed_wander",
        (),
        {"speed_wander": [(0.01, 0.7)], **_PITCH, "relative_noise": 0.03, "plan": LOW_SPEED_PLAN},
    ),
    (
        "control_low_speed_wander_accelerometers",
        (),
        {
            "speed_wander": [(0.01, 2.0)],
            "pitch_errors": 8,
            "relative_noise": 0.05,
            **ACCELEROMETER_NUISANCES,
            "plan": LOW_SPEED_PLAN,
        },
    ),
    # one sensor's artefact: the encoder's mounting run-out alone (unexplained, on te), and beside a run-out
    ("encoder_run_out", (), {**ENCODER_NUISANCES, "expected_verdict": "unexplained"}),
    ("encoder_run_out", ("eccentricity",), ENCODER_NUISANCES),
)

# keys of a kind's nuisances that are not options of the virtual rig
_PLAN_KEYS = ("plan", "expected_verdict")


def effect_draw(name: str, strength: float, rng: np.random.Generator) -> dict[str, object]:
    """Random values of an effect at a strength: phases, teeth, shafts and frequencies drawn (its family's draw)."""
    # the phase is drawn for every family, used or not, so that each family's draws follow the same stream
    phase = float(rng.uniform(0.0, 2.0 * math.pi))
    return effect_family(name).campaign_values(strength, phase, rng)


def scattered_truth(rng: np.random.Generator) -> dict[str, float]:
    """True nominal parameters scattered around the design's."""
    return {
        "mesh_stiffness_scale": float(rng.uniform(0.93, 1.07)),
        "zeta_mesh_factor": float(rng.uniform(0.8, 1.25)),
        "ste_amplitude_factor": float(rng.uniform(0.8, 1.2)),
        "k1_factor": float(rng.uniform(0.9, 1.1)),
        "k2_factor": float(rng.uniform(0.9, 1.1)),
        "backlash_factor": float(rng.uniform(0.9, 1.1)),
    }


def plan_real_world(
    n_per_kind: int, rng: np.random.Generator, *, designs: Sequence[str] = DESIGNS
) -> list[CampaignSpec]:
    """The real-world suite: campaigns that are not the model plus one effect on a clean rig.

    Per kind (``n_per_kind`` each, alternating the designs): two effects of
    different families at once (strong run-out or torque ripple with a
    medium or strong cracked tooth; run-out with friction under every
    nuisance), one effect with a 2.5 kHz resonance (damping 0.05) on the
    pinion accelerometer's path diagnosed against a healthy reference
    campaign of the same rig, one with +-0.5 % speed wander at 1.3 Hz, one
    with ISO 1328-1 class 7 pitch errors, and healthy controls carrying each
    nuisance (wander, pitch errors, 50/150 Hz mains with 3 % noise, all of
    them, the resonance with its reference). True nominal parameters
    scatter as in :func:`plan_campaigns`.
    """
    return plan_kinds(_REAL_WORLD_KINDS, n_per_kind, rng, designs=designs, default_plan="service")


def plan_kinds(
    kinds: Sequence[tuple[str, tuple[str, ...], Mapping[str, object]]],
    n_per_kind: int,
    rng: np.random.Generator,
    *,
    designs: Sequence[str] = DESIGNS,
    default_plan: str = "service",
    prefix: str = "",
) -> list[CampaignSpec]:
    """Campaigns of a suite of kinds (kind, effects with the leading one first, nuisances), ``n_per_kind`` each.

    The real-world suite's rule, shared by every suite built from its kinds: designs alternate, the true
    nominal parameters scatter (:func:`scattered_truth`), the leading effect is drawn at its ladder's strong
    level and a second one strong or medium, in this order from ``rng``; a kind's nuisances may name its
    ``plan`` (else ``default_plan``) and its ``expected_verdict``. Identifiers start with ``prefix``.
    """
    n_per_kind = check_count("n_per_kind", n_per_kind, 1)
    check_designs(designs)
    specs: list[CampaignSpec] = []
    for kind, effect_names, nuisances in kinds:
        for k in range(n_per_kind):
            design_name = designs[k % len(designs)]
            truth = scattered_truth(rng)
            plan = str(nuisances.get("plan", default_plan))
            expected = str(nuisances.get("expected_verdict", ""))
            rig_nuisances = {key: value for key, value in nuisances.items() if key not in _PLAN_KEYS}
            drawn = []
            for position, name in enumerate(effect_names):
                # the leading effect strong; a second one strong or medium
                level = 2 if position == 0 else (2, 1)[int(rng.integers(2))]
                strength = effect_family(name).ladder[level]
                drawn.append((name, strength, STRENGTHS[level], effect_draw(name, strength, rng)))
            if not drawn:
                identifier = f"{prefix}{kind}-{k}"
                healthy = CampaignSpec(
                    identifier, HEALTHY, "-", 0.0, design_name, {}, truth, plan, (), rig_nuisances, expected
                )
                specs.append(healthy)
                continue
            name, strength, level_name, values = drawn[0]
            extra = tuple((other, other_values) for other, _, _, other_values in drawn[1:])
            specs.append(
                CampaignSpec(
                    f"{prefix}{kind}-{'+'.join(effect_names)}-{k}", name, level_name, strength, design_name, values,
                    truth, plan, extra, rig_nuisances, expected,
                )
            )
    return specs


def plan_encoderless(
    n_per_effect: int, rng: np.random.Generator, *, designs: Sequence[str] = DESIGNS, n_healthy: int = 2
) -> list[CampaignSpec]:
    """The encoder-less suite: each library effect alone on a rig with accelerometers only, no TE.

    Per effect ``n_per_effect`` campaigns (alternating the designs, its
    family's plan), its strength drawn log-uniformly across its ladder's
    range (weak to strong) and its other values by its family's draw (the
    stick-slip frequency uniformly in 6-30 Hz); every second campaign runs
    under +-0.5 % speed wander at 1.3 Hz. ``n_healthy`` healthy controls
    (alternating the plans, the second with the wander). True nominal
    parameters scatter as in :func:`plan_campaigns`.

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.validation import plan_encoderless
    >>> specs = plan_encoderless(1, np.random.default_rng(0))
    >>> [spec.identifier for spec in specs][:2], specs[0].nuisances["channels"]
    (['encoderless-eccentricity-0', 'encoderless-tooth_damage-0'], ('acc_pinion', 'acc_gear'))
    """
    n_per_effect = check_count("n_per_effect", n_per_effect, 1)
    n_healthy = check_count("n_healthy", n_healthy, 0)
    check_designs(designs)
    specs: list[CampaignSpec] = []
    for truth in LIBRARY_EFFECTS + (HEALTHY,):
        for k in range(n_healthy if truth == HEALTHY else n_per_effect):
            design_name = designs[k % len(designs)]
            scatter = scattered_truth(rng)
            nuisances: dict[str, object] = {"channels": ENCODERLESS_CHANNELS, **(WANDER_NUISANCES if k % 2 else {})}
            identifier = f"encoderless-{truth}-{k}"
            if truth == HEALTHY:
                plan = PLANS[k % len(PLANS)]
                specs.append(CampaignSpec(identifier, truth, "-", 0.0, design_name, {}, scatter, plan, (), nuisances))
                continue
            family = effect_family(truth)
            weak, _, strong = family.ladder
            strength = float(math.exp(rng.uniform(math.log(weak), math.log(strong))))
            values = effect_draw(truth, strength, rng)
            specs.append(
                CampaignSpec(
                    identifier, truth, "drawn", strength, design_name, values, scatter, family.plan, (), nuisances
                )
            )
    return specs


def true_values(spec: CampaignSpec, design: Design) -> dict[str, float]:
    """The campaign's true nominal parameters in natural units (its scatter applied to the design's)."""
    return scattered_values(spec.true_parameters, design)


def scattered_values(factors: Mapping[str, float], design: Design) -> dict[str, float]:
    """Parameters in natural units from a scatter (:func:`scattered_truth`) applied to the design's values."""
    return {
        "mesh_stiffness_scale": factors["mesh_stiffness_scale"],
        "zeta_mesh": design.zeta_mesh * factors["zeta_mesh_factor"],
        "ste_amplitude": design.ste_amplitude * factors["ste_amplitude_factor"],
        "k1": design.k1 * factors["k1_factor"],
        "k2": design.k2 * factors["k2_factor"],
        "backlash": design.backlash * factors["backlash_factor"],
    }


def operating_points_of(plan: str, design: Design, n_ops: int = 8) -> dict[str, np.ndarray]:
    """The runs of a test plan (``n_ops`` of its 8, spread over them) for a design."""
    if plan == "service":
        table = {"pinion_speed": np.asarray(DEFAULT_PINION_SPEEDS), "drive_torque": np.asarray(DEFAULT_DRIVE_TORQUES)}
    elif plan == LOW_SPEED_PLAN:
        table = {"pinion_speed": np.asarray(LOW_SPEED_PINION_SPEEDS), "drive_torque": np.asarray(DEFAULT_DRIVE_TORQUES)}
    elif plan == "bearing_check":
        ops = bearing_check_operating_points(design)
        table = {str(name): ops[name].values for name in ops.data_vars}
    else:
        raise DiagnosisError(f"plan: expected one of {', '.join((*PLANS, LOW_SPEED_PLAN))}; got {plan!r}")
    size = table["pinion_speed"].size
    index = np.unique(np.round(np.linspace(0, size - 1, min(n_ops, size))).astype(int))
    return {name: np.asarray(values)[index] for name, values in table.items()}


def rig_campaign(
    spec: CampaignSpec,
    design: Design,
    operating_points: Mapping[str, np.ndarray],
    truth: Mapping[str, float],
    effects: Sequence[Effect],
    seed: np.random.SeedSequence,
    duration: float,
    title: str,
) -> xr.Dataset:
    """A blind-test campaign from the virtual rig, with the spec's nuisances (transfer path last)."""
    options: dict[str, Any] = {
        key: value for key, value in spec.nuisances.items() if key not in ("transfer_path", "reference")
    }
    rig = simulate_campaign(
        design,
        operating_points,
        true_parameters=dict(truth),
        effects=effects,
        seed=seed,
        duration=duration,
        run_in=0.3,
        title=title,
        **options,
    )
    if "transfer_path" in spec.nuisances:
        frequency, damping = cast(tuple[float, float], spec.nuisances["transfer_path"])
        rig = apply_transfer_path(rig, "acc_pinion", frequency, damping)
    return rig


def check_designs(designs: Sequence[str]) -> None:
    """Refuse a design name other than ``reference`` and ``second``."""
    for name in designs:
        if name not in DESIGNS:
            raise DiagnosisError(f"designs: {name!r} unknown; expected 'reference' and/or 'second'")


__all__ = [
    "HEALTHY",
    "STRENGTHS",
    "PLANS",
    "LOW_SPEED_PLAN",
    "LOW_SPEED_PINION_SPEEDS",
    "SUITES",
    "DESIGNS",
    "LIBRARY_EFFECTS",
    "CampaignSpec",
    "second_design",
    "plan_campaigns",
    "plan_real_world",
    "plan_kinds",
    "plan_encoderless",
    "ENCODERLESS_CHANNELS",
    "effect_draw",
    "scattered_truth",
    "RESONANCE_NUISANCES",
    "WANDER_NUISANCES",
    "MAINS_NOISE_NUISANCES",
    "ACCELEROMETER_NUISANCES",
    "ENCODER_NUISANCES",
    "true_values",
    "operating_points_of",
    "rig_campaign",
    "check_count",
    "check_designs",
]
