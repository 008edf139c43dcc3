"""Blind checks of the gap diagnosis on campaigns whose effect is withheld.

:func:`blindtest` generates rig campaigns with uqgear's own virtual rig
(:func:`uqgear.rig.virtual_rig.simulate_campaign`) for every effect of the
library and for healthy controls, with varied true parameters, effect
strengths (weak ones near detectability included) and designs (the
reference locomotive gear and a second design), hands each campaign to
:func:`uqgear.diagnosis.run_diagnosis` without its label, and scores the
verdicts: confusion matrix, accuracy, false alarms on healthy controls,
the shrink of the held-out gap when the effect is identified, and a
detection threshold per effect.

Whether an effect is visible at all is judged independently of the
diagnosis by an oracle: the campaign's features are simulated with the true
parameters with and without the effect; when the difference is within noise
and model error (oracle gap below the diagnosis' noise threshold), ``none``
is the right answer for that campaign and is counted so in
``accuracy_detectable`` (plain ``accuracy`` counts only the true label).
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from ..physics.design import Design, load_design
from .case import RunExecutor, RunTask, execute_run, execute_runs, prepare_case
from .discrepancy import expected_rig_features, standardised_discrepancy
from .errors import DiagnosisError
from .outputs import _json_clean
from .pipeline import run_diagnosis
from .scoring import capped_squares
from .verdict import EFFECT_NAMES, NOISE_GAP_THRESHOLD, VERDICTS
from .workflow import _as_seed, _check_workers, make_out_dir
from ..physics.effects import Effect, make_effect
from ..common.fileio import write_text_atomic
from ..uq.results import json_default, save_result
from ..rig.virtual_rig import (DEFAULT_DRIVE_TORQUES, DEFAULT_PINION_SPEEDS, bearing_check_operating_points,
                          simulate_campaign)

#: Label of the healthy controls (the verdict they should get).
HEALTHY = "none"

#: Relative strengths of the effect ladder: weak (near detectability), medium, strong.
STRENGTHS: tuple[str, ...] = ("weak", "medium", "strong")

#: Test plans of the campaigns: the public campaigns' 8 service points, or the light-load
#: run through the bearing modes (:func:`uqgear.rig.virtual_rig.bearing_check_operating_points`).
PLANS: tuple[str, ...] = ("service", "bearing_check")

# Strength parameter of each effect and its value per strength level. "weak" sits near the
# detection limit of the public campaigns' noise (oracle gap about 1, see oracle_gap), "strong"
# at the public campaigns' own levels. Bearing clearance has no signature while the bearings
# stay loaded (the dead zone is never entered, whatever its width), as they do at every service
# point; its campaigns follow the bearing check plan, where a bearing unloads, and there the
# signature saturates once the clearance exceeds the excursion past unloading (a few um).
_LADDER: dict[str, tuple[str, tuple[float, float, float]]] = {
    "eccentricity": ("amplitude", (3e-8, 3e-7, 12e-6)),
    "tooth_damage": ("depth", (0.005, 0.03, 0.35)),
    "friction": ("coefficient", (0.05, 0.08, 0.12)),
    "torque_ripple": ("amplitude", (0.003, 0.01, 0.06)),
    "adhesion_oscillation": ("amplitude", (0.003, 0.01, 0.05)),
    "bearing_clearance": ("clearance", (5e-7, 3e-6, 5e-5)),
}


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
    # pitch_errors) and "transfer_path" (frequency, damping) on acc_pinion; "reference": the
    # diagnosis gets a healthy campaign of the same rig (same nuisances, own seed)
    nuisances: dict[str, object] = field(default_factory=dict)

    def effects(self) -> list[Effect]:
        leading = [] if self.truth == HEALTHY else [make_effect(self.truth, self.effect_values)]
        return leading + [make_effect(name, values) for name, values in self.extra_effects]

    def truth_set(self) -> list[str]:
        """The library effects acting on the campaign, in order (empty for a healthy control)."""
        return [effect.name for effect in self.effects()]


def _check_count(name: str, value: object, lowest: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lowest:
        raise DiagnosisError(f"{name}: expected an integer >= {lowest}; got {value!r}")
    return int(value)


def plan_campaigns(n_per_effect: int, rng: np.random.Generator, *, effects: Sequence[str] = EFFECT_NAMES,
                   designs: Sequence[str] = ("reference", "second"), n_healthy: int | None = None
                   ) -> list[CampaignSpec]:
    """The campaigns of a blind test: per effect ``n_per_effect`` over the strength ladder and designs.

    True nominal parameters scatter around the design (stiffness scale
    +-7 %, mesh damping and STE amplitude +-20 %, bearing stiffnesses and
    backlash +-10 %); phases, teeth, shafts and stick-slip frequencies are
    drawn at random. Campaigns follow the service plan, except bearing
    clearance ones: the bearing check plan, the only one where a clearance
    can show. Healthy controls (``n_healthy``, default ``2 n_per_effect``)
    use the same scatter without an effect and alternate the two plans
    (service first), so that false alarms are checked on both.
    """
    n_per_effect = _check_count("n_per_effect", n_per_effect, 1)
    n_healthy = 2 * n_per_effect if n_healthy is None else _check_count("n_healthy", n_healthy, 0)
    for name in effects:
        if name not in EFFECT_NAMES:
            raise DiagnosisError(f"effects: {name!r} is not a library effect; expected {', '.join(EFFECT_NAMES)}")
    for name in designs:
        if name not in ("reference", "second"):
            raise DiagnosisError(f"designs: {name!r} unknown; expected 'reference' and/or 'second'")
    specs: list[CampaignSpec] = []
    # strongest first when there are fewer campaigns than levels: the ladder starts from a clear case
    order = (2, 0, 1)
    for truth in list(effects) + [HEALTHY]:
        count = n_healthy if truth == HEALTHY else n_per_effect
        for k in range(count):
            # healthy controls alternate the plans first and the designs second
            design_name = designs[(k // len(PLANS) if truth == HEALTHY else k) % len(designs)]
            true_parameters = _scattered_truth(rng)
            if truth == HEALTHY:
                specs.append(CampaignSpec(f"{truth}-{k}", truth, "-", 0.0, design_name, {}, true_parameters,
                                          PLANS[k % len(PLANS)]))
                continue
            level = order[k % 3]
            _, values = _LADDER[truth]
            strength = values[level]
            effect_values = _effect_draw(truth, strength, rng)
            plan = "bearing_check" if truth == "bearing_clearance" else "service"
            specs.append(CampaignSpec(f"{truth}-{k}", truth, STRENGTHS[level], strength, design_name,
                                      effect_values, true_parameters, plan))
    return specs


#: Blind-test suites: the library's effects one at a time on a clean rig, or real-world campaigns.
SUITES: tuple[str, ...] = ("library", "real_world")

# The real-world suite's kinds, each a function of the draw. Strengths are the ladder's strong level
# (the public campaigns' own) or medium, so that a miss is the rig's doing, not the effect's weakness.
_RESONANCE = {"transfer_path": (2500.0, 0.05)}
_WANDER = {"speed_wander": [(0.005, 1.3)]}
_PITCH = {"pitch_errors": 7}
_MAINS_NOISE = {"line_interference": {50.0: 0.5, 150.0: 0.2}, "relative_noise": 0.03}
_ALL_NUISANCES = {**_WANDER, **_PITCH, **_MAINS_NOISE}
_REAL_WORLD_KINDS: tuple[tuple[str, tuple[str, ...], dict[str, object]], ...] = (
    # (kind, effects (leading first), nuisances)
    ("two_effects", ("eccentricity", "tooth_damage"), {}),
    ("two_effects", ("torque_ripple", "tooth_damage"), {}),
    ("two_effects_nuisances", ("eccentricity", "friction"), _ALL_NUISANCES),
    ("resonance_reference", ("eccentricity",), {**_RESONANCE, "reference": True}),
    ("wander", ("tooth_damage",), _WANDER),
    ("pitch_errors", ("eccentricity",), _PITCH),
    ("control_wander", (), _WANDER),
    ("control_pitch_errors", (), _PITCH),
    ("control_mains_noise", (), _MAINS_NOISE),
    ("control_all_nuisances", (), _ALL_NUISANCES),
    ("control_resonance_reference", (), {**_RESONANCE, "reference": True}),
)


def _effect_draw(name: str, strength: float, rng: np.random.Generator) -> dict[str, object]:
    """Random values of an effect at a strength: phases, teeth, shafts and frequencies drawn."""
    parameter = _LADDER[name][0]
    values: dict[str, object] = {parameter: strength}
    phase = float(rng.uniform(0.0, 2.0 * math.pi))
    if name == "eccentricity":
        # stiffness modulation in proportion (the public campaign: 12 um with kappa 0.03)
        values.update(shaft=("pinion", "gear")[int(rng.integers(2))], phase=phase, kappa=float(strength / 4e-4))
    elif name == "tooth_damage":
        values.update(gear=("pinion", "gear")[int(rng.integers(2))], tooth=float(rng.integers(0, 17)))
    elif name == "torque_ripple":
        values.update(phase=phase)
    elif name == "adhesion_oscillation":
        values.update(frequency=float(rng.uniform(6.0, 30.0)), phase=phase)
    elif name == "bearing_clearance":
        values.update(bearing=("pinion", "gear", "both")[int(rng.integers(3))])
    return values


def _scattered_truth(rng: np.random.Generator) -> dict[str, float]:
    """True nominal parameters scattered around the design's."""
    return {
        "mesh_stiffness_scale": float(rng.uniform(0.93, 1.07)),
        "zeta_mesh_factor": float(rng.uniform(0.8, 1.25)),
        "ste_amplitude_factor": float(rng.uniform(0.8, 1.2)),
        "k1_factor": float(rng.uniform(0.9, 1.1)),
        "k2_factor": float(rng.uniform(0.9, 1.1)),
        "backlash_factor": float(rng.uniform(0.9, 1.1)),
    }


def plan_real_world(n_per_kind: int, rng: np.random.Generator, *, designs: Sequence[str] = ("reference", "second")
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
    n_per_kind = _check_count("n_per_kind", n_per_kind, 1)
    for name in designs:
        if name not in ("reference", "second"):
            raise DiagnosisError(f"designs: {name!r} unknown; expected 'reference' and/or 'second'")
    specs: list[CampaignSpec] = []
    for kind, effect_names, nuisances in _REAL_WORLD_KINDS:
        for k in range(n_per_kind):
            design_name = designs[k % len(designs)]
            truth = _scattered_truth(rng)
            drawn = []
            for position, name in enumerate(effect_names):
                # the leading effect strong; a second one strong or medium
                level = 2 if position == 0 else (2, 1)[int(rng.integers(2))]
                drawn.append((name, _LADDER[name][1][level], STRENGTHS[level], _effect_draw(name, _LADDER[name][1][level], rng)))
            if drawn:
                leading = drawn[0]
                specs.append(CampaignSpec(f"{kind}-{'+'.join(effect_names)}-{k}", leading[0], leading[2], leading[1],
                                          design_name, leading[3], truth, "service",
                                          tuple((name, values) for name, _, _, values in drawn[1:]),
                                          dict(nuisances)))
            else:
                specs.append(CampaignSpec(f"{kind}-{k}", HEALTHY, "-", 0.0, design_name, {}, truth, "service", (),
                                          dict(nuisances)))
    return specs


def _true_values(spec: CampaignSpec, design: Design) -> dict[str, float]:
    factors = spec.true_parameters
    return {"mesh_stiffness_scale": factors["mesh_stiffness_scale"],
            "zeta_mesh": design.zeta_mesh * factors["zeta_mesh_factor"],
            "ste_amplitude": design.ste_amplitude * factors["ste_amplitude_factor"],
            "k1": design.k1 * factors["k1_factor"], "k2": design.k2 * factors["k2_factor"],
            "backlash": design.backlash * factors["backlash_factor"]}


def oracle_gap(case, spec: CampaignSpec, truth: Mapping[str, Any]) -> float:
    """How visible the campaign's effect is: the gap between the true model with and without it.

    Both are simulated with the true parameters and T2; what a rig would
    record on average with the effect (:func:`uqgear.diagnosis.expected_rig_features`)
    is compared with the model without it, noise and model error as in the
    diagnosis: sqrt(mean(min(z^2, 10^2))) of those standardised shifts, the
    held-out gap a perfect nominal fit would leave beyond noise. 0 for a
    healthy control.
    """
    if spec.truth == HEALTHY:
        return 0.0
    design, scale, adhesion = _true_model(case, truth)
    effect = spec.effects()
    periodicity = "free"
    with_effect, without = [], []
    for op in range(case.n_op):
        with_effect.append(execute_run(case, RunTask(op, design, scale, float(adhesion[op]), tuple(effect),
                                                     periodicity))[0])
        without.append(execute_run(case, RunTask(op, design, scale, float(adhesion[op]), (), "mesh"))[0])
    columns = case.layout.columns
    # the noise the rig's records carry, as the diagnosis estimates it
    recorded = expected_rig_features(np.stack(with_effect)[..., columns], case.noise_std, case.noise, case.layout)
    return _capped_gap(case, recorded, np.stack(without)[..., columns])


def _true_model(case, truth: Mapping[str, Any]) -> tuple[Design, float, np.ndarray]:
    """The true design, mesh-stiffness scale and per-run T2 of a campaign's truth."""
    design = case.design.replace(**{key: float(truth[key]) for key in ("zeta_mesh", "ste_amplitude", "k1", "k2",
                                                                      "backlash")})
    return design, float(truth["mesh_stiffness_scale"]), np.asarray(truth["adhesion_torque"], dtype=float)


def _capped_gap(case, recorded: np.ndarray, plain: np.ndarray) -> float:
    """sqrt(mean(min(z^2, 10^2))) of the standardised shifts between what a rig records and a model."""
    shift, _ = standardised_discrepancy(recorded, plain, case.noise_std, case.noise, case.layout, case.model_error)
    squares = capped_squares(shift[case.mask()])
    squares = squares[np.isfinite(squares)]
    return float(math.sqrt(np.mean(squares))) if squares.size else 0.0


def effect_visibility(case, spec: CampaignSpec, truth: Mapping[str, Any]) -> dict[str, float]:
    """How visible each of a campaign's effects is next to the others, by the diagnosis's own model error.

    Per effect: the gap (as :func:`oracle_gap`) between the true model with
    all the campaign's effects and with all but that one, both over the
    whole record, standardised with ``case.model_error`` as the diagnosis
    left it: after a run, that holds the pitch-error allowance (and a
    reference's widening), so an effect that the stated manufacturing
    classes could make as well (a 12 um run-out on class-7 gears, whose
    own first-order run-out reaches 22 um) reads as what it is to the
    data. Empty for a healthy control.
    """
    effects = list(spec.effects())
    if not effects:
        return {}
    design, scale, adhesion = _true_model(case, truth)
    names = list(spec.truth_set())

    def features(chosen: Sequence[Effect]) -> np.ndarray:
        tasks = [RunTask(op, design, scale, float(adhesion[op]), tuple(chosen), "free") for op in range(case.n_op)]
        return np.stack([values for values, _ in execute_runs(case, tasks)])[..., case.layout.columns]

    recorded = expected_rig_features(features(effects), case.noise_std, case.noise, case.layout)
    return {name: _capped_gap(case, recorded, features(effects[:index] + effects[index + 1:]))
            for index, name in enumerate(names)}


def operating_points_of(plan: str, design: Design, n_ops: int = 8) -> dict[str, np.ndarray]:
    """The runs of a test plan (``n_ops`` of its 8, spread over them) for a design."""
    if plan == "service":
        table = {"pinion_speed": np.asarray(DEFAULT_PINION_SPEEDS), "drive_torque": np.asarray(DEFAULT_DRIVE_TORQUES)}
    elif plan == "bearing_check":
        ops = bearing_check_operating_points(design)
        table = {str(name): ops[name].values for name in ops.data_vars}
    else:
        raise DiagnosisError(f"plan: expected one of {', '.join(PLANS)}; got {plan!r}")
    size = table["pinion_speed"].size
    index = np.unique(np.round(np.linspace(0, size - 1, min(n_ops, size))).astype(int))
    return {name: np.asarray(values)[index] for name, values in table.items()}


def _thresholds(campaigns: Sequence[Mapping[str, Any]], effects: Sequence[str]) -> list[dict[str, Any]]:
    """Per effect: the weakest strength detected above which all were, and the strongest one missed."""
    rows = []
    for effect in effects:
        parameter = _LADDER[effect][0]
        cases = sorted((c for c in campaigns if c["truth"] == effect), key=lambda c: c["strength_value"])
        detected = [c["strength_value"] for c in cases if c["verdict"] == effect]
        missed = [c["strength_value"] for c in cases if c["verdict"] != effect]
        detected_from = None
        for value in sorted(detected):
            if all(m < value for m in missed):
                detected_from = value
                break
        note = ""
        invisible = [c for c in cases if c["verdict"] != effect and not c["detectable"]]
        if invisible:
            note = f"{len(invisible)} missed below detectability (oracle gap <= {NOISE_GAP_THRESHOLD:g})"
        rows.append({"effect": effect, "parameter": parameter, "detected_from": detected_from,
                     "missed_up_to": max(missed) if missed else None, "n": len(cases), "note": note})
    return rows


def blindtest(out_dir: str | os.PathLike[str], *, n_per_effect: int = 3, seed: int | np.random.SeedSequence = 0,
              effects: Sequence[str] | None = None, designs: Sequence[str] = ("reference", "second"),
              n_healthy: int | None = None, n_ops: int = 8, duration: float = 1.0, workers: int | None = None,
              report: bool = True, suite: str = "library") -> dict[str, Any]:
    """Run a blind test of the diagnosis and write ``blindtest.json``, ``blindtest.nc`` and ``report.html``.

    Parameters
    ----------
    out_dir : path
        Output folder (created if missing); each campaign's rig file and
        diagnosis summary go to ``campaigns/<id>/``.
    n_per_effect : int
        Campaigns per library effect (strong, weak, medium, strong, ...
        alternating the designs).
    seed : int or SeedSequence
        Source of every random choice (true parameters, effects, noise, T2).
    effects : sequence of str, optional
        Effects to test (default all six); the diagnosis always considers all six.
    designs : sequence of {"reference", "second"}
        Designs to alternate.
    n_healthy : int, optional
        Healthy controls, alternating the service and bearing check plans
        (default ``2 n_per_effect``).
    n_ops : int
        Runs per campaign (a subset of its plan's 8 operating points).
    duration : float
        Record length, s.
    workers : int, optional
        Worker processes of each diagnosis.
    report : bool
        Write ``report.html``.
    suite : {"library", "real_world"}
        ``library``: each library effect alone on a clean rig (above).
        ``real_world`` (:func:`plan_real_world`): ``n_per_effect`` campaigns
        of each real-world kind: two effects at once, a transfer-path
        resonance with a healthy reference, speed wander, pitch errors, and
        healthy controls carrying those nuisances; ``effects`` and
        ``n_healthy`` do not apply.

    Returns
    -------
    dict
        The content of ``blindtest.json``; ``effect_sets`` scores the named
        sets against the true ones (per-effect precision and recall,
        exactly right sets, two-effect campaigns).
    """
    started = time.perf_counter()
    seed_sequence = _as_seed(seed)
    effect_names = tuple(EFFECT_NAMES if effects is None else effects)
    n_ops = _check_count("n_ops", n_ops, 3)
    if n_ops > len(DEFAULT_PINION_SPEEDS):
        raise DiagnosisError(f"n_ops: expected at most {len(DEFAULT_PINION_SPEEDS)}; got {n_ops}")
    workers = _check_workers(workers)
    plan_seed, campaigns_seed = seed_sequence.spawn(2)
    if suite not in SUITES:
        raise DiagnosisError(f"suite: expected one of {', '.join(SUITES)}; got {suite!r}")
    if suite == "library":
        specs = plan_campaigns(n_per_effect, np.random.default_rng(plan_seed), effects=effect_names,
                               designs=designs, n_healthy=n_healthy)
    else:
        specs = plan_real_world(n_per_effect, np.random.default_rng(plan_seed), designs=designs)
        effect_names = tuple(dict.fromkeys(name for spec in specs for name in spec.truth_set()))
    campaign_seeds = campaigns_seed.spawn(len(specs))
    out = make_out_dir(out_dir)
    reference = load_design("locomotive")
    designs_by_name = {"reference": reference, "second": second_design(reference)}
    campaigns: list[dict[str, Any]] = []
    from ..rig.format import write_rig

    for spec, campaign_seed in zip(specs, campaign_seeds):
        clock = time.perf_counter()
        design = designs_by_name[spec.design_name]
        # a fourth child leaves the first three (and so every library-suite campaign) as they were
        generation_seed, noise_seed, diagnosis_seed, reference_seed = campaign_seed.spawn(4)
        truth = _true_values(spec, design)
        rig = _rig_campaign(spec, design, operating_points_of(spec.plan, design, n_ops), truth, spec.effects(),
                            generation_seed, duration, f"blind-test campaign {spec.identifier}")
        folder = out / "campaigns" / spec.identifier
        folder.mkdir(parents=True, exist_ok=True)
        write_rig(folder / "rig.nc", rig)
        # the diagnosis sees the rig data with the nominal design only: no label, no truth
        blind = rig.copy()
        for name in ("true_parameters", "effects", "noise"):
            blind.attrs.pop(name, None)
        case = prepare_case(blind, design, seed=noise_seed)
        if spec.nuisances.get("reference"):
            # a healthy campaign of the same rig (its nuisances, its own noise and T2), learned blind too
            from .reference import attach_reference, learn_reference

            healthy_seed, learn_seed = reference_seed.spawn(2)
            healthy = _rig_campaign(spec, design, operating_points_of(spec.plan, design, n_ops), truth, [],
                                    healthy_seed, duration, f"healthy reference of {spec.identifier}")
            for name in ("true_parameters", "effects", "noise"):
                healthy.attrs.pop(name, None)
            attach_reference(case, learn_reference(healthy, design, source=f"reference of {spec.identifier}",
                                                   seed=learn_seed, workers=workers), blind)
        recorded_truth = json.loads(rig.attrs["true_parameters"])
        visibility = oracle_gap(case, spec, {**truth, "adhesion_torque": recorded_truth["adhesion_torque"]})
        case.executor = RunExecutor(case, workers)
        try:
            result = run_diagnosis(case, seed=diagnosis_seed)
        finally:
            case.executor.close()
            case.executor = None
        best = result.best
        named = best if best is not None and best.effect == result.verdict else None
        detectable = spec.truth == HEALTHY or visibility > NOISE_GAP_THRESHOLD
        # after the diagnosis: its model error then holds the pitch-error allowance where one applies
        per_effect = effect_visibility(case, spec, {**truth, "adhesion_torque": recorded_truth["adhesion_torque"]})
        entry = {
            "id": spec.identifier, "truth": spec.truth, "truth_effects": spec.truth_set(),
            "effects_named": [chosen.entry.effect for chosen in result.selected],
            "shrink_shares": [chosen.shrink_share for chosen in result.selected],
            "strength": spec.strength,
            "strength_value": spec.strength_value, "design": spec.design_name, "plan": spec.plan,
            "nuisances": {key: value for key, value in spec.nuisances.items()},
            "effect_values": spec.effect_values, "true_parameters": truth,
            "verdict": result.verdict, "reason": result.reason,
            "partial": bool(result.decision is not None and result.decision.partial),
            "borderline": [entry["figure"] for entry in result.decision.borderline] if result.decision else [],
            "correct": result.verdict == spec.truth,
            "correct_detectable": result.verdict == spec.truth or (not detectable and result.verdict == HEALTHY),
            "detectable": bool(detectable), "oracle_gap": visibility, "nominal_gap": result.nominal_gap,
            "effect_visibility": per_effect,
            "identifiable_effects": [name for name, gap in per_effect.items() if gap > NOISE_GAP_THRESHOLD],
            "shrink_fraction": named.shrink if named is not None else None,
            "shrink_interval": [named.shrink_low, named.shrink_high] if named is not None else None,
            "best_candidate": best.effect if best is not None else None,
            "best_score": best.score if best is not None else None,
            # run-outs the lines cannot tell from the gears' own pitch errors (reported, not named)
            "cannot_tell": [f"{entry['effect']}[{entry['shaft']}]" for entry in result.cannot_tell()],
            "sideband_phase_log_ratios": {evidence.shaft: evidence.log_ratio for evidence in result.modulation},
            "seconds": time.perf_counter() - clock,
        }
        campaigns.append(entry)
        write_text_atomic(folder / "diagnosis.json",
                           json.dumps(_json_clean({**entry, "ranking": result.ranking()}), indent=2,
                                      default=json_default))
    content = summarise(campaigns, effect_names, seconds=time.perf_counter() - started,
                        seed_text=str(seed_sequence.entropy))
    save_result(blindtest_dataset(content), out / "blindtest.nc", seed=seed_sequence)
    write_text_atomic(out / "blindtest.json", json.dumps(_json_clean(content), indent=2, default=json_default))
    if report:
        from ..report.diagnosis_report import write_blindtest_report

        write_blindtest_report(_json_clean(content), out / "report.html")
    return _json_clean(content)


def _rig_campaign(spec: CampaignSpec, design: Design, operating_points: Mapping[str, np.ndarray],
                  truth: Mapping[str, float], effects: Sequence[Effect], seed: np.random.SeedSequence,
                  duration: float, title: str) -> xr.Dataset:
    """A blind-test campaign from the virtual rig, with the spec's nuisances (transfer path last)."""
    from ..rig.transfer_path import apply_transfer_path

    options = {key: value for key, value in spec.nuisances.items() if key not in ("transfer_path", "reference")}
    rig = simulate_campaign(design, operating_points, true_parameters=dict(truth), effects=effects, seed=seed,
                            duration=duration, run_in=0.3, title=title, **options)
    if "transfer_path" in spec.nuisances:
        frequency, damping = spec.nuisances["transfer_path"]
        rig = apply_transfer_path(rig, "acc_pinion", frequency, damping)
    return rig


def _truth_set(campaign: Mapping[str, Any]) -> set[str]:
    """The effects acting on a scored campaign (``truth_effects``, else its one ``truth``)."""
    if campaign.get("truth_effects") is not None:
        return set(campaign["truth_effects"])
    return set() if campaign["truth"] == HEALTHY else {campaign["truth"]}


def _named_set(campaign: Mapping[str, Any]) -> set[str]:
    """The effects a diagnosis named (``effects_named``, else its verdict when that is an effect)."""
    if campaign.get("effects_named") is not None:
        return set(campaign["effects_named"])
    return {campaign["verdict"]} if campaign["verdict"] in EFFECT_NAMES else set()


def set_scores(campaigns: Sequence[Mapping[str, Any]], effects: Sequence[str]) -> dict[str, Any]:
    """How well the named effect sets match the true ones.

    Per effect: precision (of the campaigns where it was named, the share
    where it acts) and recall (of the campaigns where it acts, the share
    where it was named), None where undefined (never named, never acting).
    ``set_exact``: the share of campaigns whose named set is exactly the
    true set; an empty true set counts only with the verdict ``none`` (an
    ``unexplained`` or ``inconclusive`` healthy control names nothing, but
    is not right).
    """
    names = list(dict.fromkeys([*effects, *(name for c in campaigns for name in _truth_set(c) | _named_set(c))]))
    rows = []
    for name in names:
        named = [c for c in campaigns if name in _named_set(c)]
        acting = [c for c in campaigns if name in _truth_set(c)]
        hits = sum(1 for c in named if name in _truth_set(c))
        # its share of the shrink where it was rightly named (campaigns that record the shares)
        shares = [c["shrink_shares"][list(c["effects_named"]).index(name)] for c in named
                  if name in _truth_set(c) and c.get("shrink_shares") is not None]
        rows.append({"effect": name, "named": len(named), "acting": len(acting), "correct": hits,
                     "precision": hits / len(named) if named else None,
                     "recall": hits / len(acting) if acting else None,
                     "shrink_share_median": float(np.median(shares)) if shares else None})
    exact = [(_named_set(c) == _truth_set(c)) and (bool(_truth_set(c)) or c["verdict"] == HEALTHY)
             for c in campaigns]
    # against the effects the data can tell (effect_visibility) where the campaign records them
    identifiable = [set(c["identifiable_effects"]) if c.get("identifiable_effects") is not None else _truth_set(c)
                    for c in campaigns]
    exact_identifiable = [_named_set(c) == wanted if _truth_set(c) else c["verdict"] == HEALTHY
                          for c, wanted in zip(campaigns, identifiable)]
    multi = [ok for c, ok in zip(campaigns, exact) if len(_truth_set(c)) > 1]
    controls = [c for c in campaigns if not _truth_set(c)]
    # effects missed but reported as not told apart from the gears' own errors (campaigns that record it)
    recorded = [c for c in campaigns if c.get("cannot_tell") is not None]
    missed = [(c, name) for c in recorded for name in sorted(_truth_set(c) - _named_set(c))]
    return {"per_effect": rows, "set_exact": sum(exact) / len(exact) if exact else math.nan,
            "set_exact_identifiable": sum(exact_identifiable) / len(exact_identifiable) if exact_identifiable
            else math.nan,
            "effects_not_identifiable": sum(len(_truth_set(c) - wanted) for c, wanted in zip(campaigns, identifiable)),
            "n_multi_effect": len(multi), "set_exact_multi_effect": sum(multi) / len(multi) if multi else None,
            "n_controls": len(controls),
            "controls_with_an_effect_named": sum(1 for c in controls if _named_set(c)),
            "effects_missed": len(missed),
            "effects_missed_reported_cannot_tell": sum(
                1 for c, name in missed if any(label.startswith(f"{name}[") for label in c["cannot_tell"])),
            "controls_with_cannot_tell": sum(1 for c in controls if c.get("cannot_tell"))}


def summarise(campaigns: Sequence[Mapping[str, Any]], effects: Sequence[str], *, seconds: float = math.nan,
              seed_text: str = "") -> dict[str, Any]:
    """Confusion matrix, accuracies, false alarms, shrink statistics, thresholds and effect-set scores.

    The confusion matrix and the accuracies score the verdict (the leading
    effect) against the campaign's ``truth``; ``effect_sets``
    (:func:`set_scores`) scores the named effect sets against the true ones.
    """
    labels = list(effects) + [HEALTHY]
    verdicts = list(VERDICTS)
    counts = np.zeros((len(labels), len(verdicts)), dtype=int)
    for c in campaigns:
        counts[labels.index(c["truth"]), verdicts.index(c["verdict"])] += 1
    n = len(campaigns)
    shrinks = np.array([c["shrink_fraction"] for c in campaigns if c["correct"] and c["truth"] != HEALTHY
                        and c["shrink_fraction"] is not None], dtype=float)
    false_alarms = sum(1 for c in campaigns if c["truth"] == HEALTHY and c["verdict"] in EFFECT_NAMES)
    return {
        "n_campaigns": n,
        "labels": labels,
        "accuracy": sum(c["correct"] for c in campaigns) / n if n else math.nan,
        "accuracy_detectable": sum(c["correct_detectable"] for c in campaigns) / n if n else math.nan,
        "false_alarms": false_alarms,
        "healthy_controls": sum(1 for c in campaigns if c["truth"] == HEALTHY),
        "confusion": {"truth": labels, "verdicts": verdicts, "counts": counts.tolist()},
        "shrink": {"n": int(shrinks.size),
                   "median": float(np.median(shrinks)) if shrinks.size else None,
                   "q25": float(np.quantile(shrinks, 0.25)) if shrinks.size else None,
                   "q75": float(np.quantile(shrinks, 0.75)) if shrinks.size else None,
                   "minimum": float(shrinks.min()) if shrinks.size else None},
        "thresholds": _thresholds(campaigns, effects),
        "effect_sets": set_scores(campaigns, effects),
        "campaigns": list(campaigns),
        "seconds": seconds,
        "seed": seed_text,
    }


def blindtest_dataset(content: Mapping[str, Any]) -> xr.Dataset:
    """The blind test as a Dataset: per-campaign table and the confusion matrix."""
    campaigns = content["campaigns"]

    def column(key: str, default: float = math.nan) -> np.ndarray:
        return np.array([default if c[key] is None else c[key] for c in campaigns], dtype=float)

    ds = xr.Dataset(
        {"confusion": (("truth", "verdict"), np.array(content["confusion"]["counts"], dtype=np.int64),
                       {"long_name": "campaigns per true effect and verdict", "units": "1"}),
         "strength_value": (("campaign",), column("strength_value"),
                            {"long_name": "value of the effect's strength parameter", "units": "effect units"}),
         "oracle_gap": (("campaign",), column("oracle_gap"),
                        {"long_name": "gap between the true model with and without the effect", "units": "1"}),
         "nominal_gap": (("campaign",), column("nominal_gap"),
                         {"long_name": "held-out gap of the fitted nominal model", "units": "1"}),
         "shrink_fraction": (("campaign",), column("shrink_fraction"),
                             {"long_name": "held-out gap shrink when the effect is named", "units": "1"}),
         "correct": (("campaign",), np.array([int(c["correct"]) for c in campaigns], dtype=np.int8),
                     {"long_name": "verdict equals the true label", "units": "1"}),
         "seconds": (("campaign",), column("seconds"), {"long_name": "generation and diagnosis time",
                                                        "units": "s"})},
        coords={"truth": ("truth", list(content["confusion"]["truth"])),
                "verdict": ("verdict", list(content["confusion"]["verdicts"])),
                "campaign": ("campaign", [c["id"] for c in campaigns]),
                "campaign_truth": ("campaign", [c["truth"] for c in campaigns]),
                "campaign_verdict": ("campaign", [c["verdict"] for c in campaigns]),
                "campaign_design": ("campaign", [c["design"] for c in campaigns]),
                "campaign_plan": ("campaign", [c.get("plan", "service") for c in campaigns]),
                "campaign_strength": ("campaign", [c["strength"] for c in campaigns])})
    ds.attrs.update(title="uqgear blind test of the gap diagnosis", accuracy=content["accuracy"],
                    accuracy_detectable=content["accuracy_detectable"], false_alarms=content["false_alarms"])
    return ds


__all__ = ["blindtest", "plan_campaigns", "plan_real_world", "SUITES", "summarise", "set_scores", "blindtest_dataset", "oracle_gap", "second_design",
           "operating_points_of", "CampaignSpec", "HEALTHY", "STRENGTHS", "PLANS"]
