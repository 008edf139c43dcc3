"""Blind checks of the gap diagnosis on virtual-rig campaigns whose effects are withheld.

:func:`blindtest` makes the campaigns of a suite (:mod:`.campaigns`) with
uqgear's own virtual rig, hands each to a :class:`~uqgear.diagnosis.Diagnosis`
without its label, judges how visible its effects are independently of the
diagnosis (:mod:`.oracle`) and scores the verdicts (:mod:`.scores`):
confusion matrix, accuracy, false alarms on healthy controls, the shrink of
the held-out gap when the effect is identified, a detection threshold per
effect and how well the named effect sets match the true ones.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..common.fileio import write_text_atomic
from ..common.transaction import OutputFolder
from ..diagnosis import Diagnosis, DiagnosisError, DiagnosisSeeds
from ..diagnosis.inputs import as_seed, check_workers
from ..diagnosis.outputs import json_clean
from ..diagnosis.settings import DEFAULT_SETTINGS
from ..physics.design import Design, load_design
from ..physics.effects import Effect
from ..rig.format import write_rig
from ..rig.ramp_records import points_truth
from ..rig.virtual_rig import DEFAULT_PINION_SPEEDS
from ..uq.results import json_default, save_result
from .campaigns import (
    HEALTHY,
    LIBRARY_EFFECTS,
    SUITES,
    CampaignSpec,
    check_count,
    operating_points_of,
    plan_campaigns,
    plan_encoderless,
    plan_real_world,
    rig_campaign,
    second_design,
    true_values,
)
from .oracle import effect_visibility, oracle_gap
from .runup_campaigns import RAMP_PLANS, plan_runup, runup_campaign
from .scores import blindtest_dataset, summarise

# Attributes of a virtual-rig campaign that say what it holds: taken off before the diagnosis sees it.
_TRUTH_ATTRIBUTES = ("true_parameters", "effects", "noise")


def _blind(rig: xr.Dataset) -> xr.Dataset:
    """The campaign as the diagnosis sees it: the rig data with the nominal design only, no label, no truth."""
    blind = rig.copy()
    for name in _TRUTH_ATTRIBUTES:
        blind.attrs.pop(name, None)
    return blind


def diagnose_campaign(
    spec: CampaignSpec,
    design: Design,
    seed: np.random.SeedSequence,
    folder: Path,
    *,
    n_ops: int,
    duration: float,
    workers: int,
) -> dict[str, Any]:
    """Make one campaign, diagnose it blind, and judge the verdict; returns its entry of ``blindtest.json``.

    Writes the campaign's ``rig.nc`` and ``diagnosis.json`` into ``folder``.
    """
    clock = time.perf_counter()
    # a fourth child leaves the first three (and so every library-suite campaign) as they were
    generation_seed, noise_seed, diagnosis_seed, reference_seed = seed.spawn(4)
    truth = true_values(spec, design)
    if spec.plan in RAMP_PLANS:

        def make(effects: list[Effect], seed: np.random.SeedSequence, title: str) -> xr.Dataset:
            return runup_campaign(spec, design, truth, effects, seed, title)

    else:
        operating_points = operating_points_of(spec.plan, design, n_ops)

        def make(effects: list[Effect], seed: np.random.SeedSequence, title: str) -> xr.Dataset:
            return rig_campaign(spec, design, operating_points, truth, effects, seed, duration, title)

    rig = make(spec.effects(), generation_seed, f"blind-test campaign {spec.identifier}")
    folder.mkdir(parents=True, exist_ok=True)
    write_rig(folder / "rig.nc", rig)
    healthy_seed, learn_seed = reference_seed.spawn(2)
    reference = None
    if spec.nuisances.get("reference"):
        # a healthy campaign of the same rig (its nuisances, its own noise and T2), learned blind too
        reference = _blind(make([], healthy_seed, f"healthy reference of {spec.identifier}"))
    diagnosis = Diagnosis(
        design=design,
        seed=DiagnosisSeeds(noise_seed, diagnosis_seed, learn_seed),
        workers=workers,
        reference_route="transfer",
    ).fit(_blind(rig), reference=reference)
    # the true T2 of each operating point the diagnosis read (a ramp's for each of its segments)
    sources = [str(row.get("source", "steady")) for row in diagnosis.features_.speed]
    recorded_truth = points_truth(rig, sources) or {}
    known = {**truth, "adhesion_torque": recorded_truth["adhesion_torque"]}
    entry = _judged(
        spec,
        diagnosis,
        truth,
        oracle_gap(diagnosis.features_, spec, known),
        effect_visibility(diagnosis.case_, spec, known),
    )
    entry["seconds"] = time.perf_counter() - clock
    # the diagnosis's own stages (benchmarks/diagnosis.py --suite reads them)
    entry["timing_s"] = dict(diagnosis.summary_.get("timing_s", {}))
    ranking = diagnosis.outcome_.ranking() if diagnosis.outcome_ is not None else []
    write_text_atomic(
        folder / "diagnosis.json", json.dumps(json_clean({**entry, "ranking": ranking}), indent=2, default=json_default)
    )
    return entry


def _judged(
    spec: CampaignSpec,
    diagnosis: Diagnosis,
    truth: Mapping[str, float],
    visibility: float,
    per_effect: Mapping[str, float],
) -> dict[str, Any]:
    """A campaign's entry: its truth, what the diagnosis named, and whether that was right."""
    noise_gap = DEFAULT_SETTINGS.verdict.noise_gap
    decision, outcome = diagnosis.decision_, diagnosis.outcome_
    best = diagnosis.ranking_[0] if diagnosis.ranking_ else None
    named = best if best is not None and best.effect == decision.verdict else None
    detectable = spec.truth == HEALTHY or visibility > noise_gap
    return {
        "id": spec.identifier,
        "truth": spec.truth,
        "truth_effects": spec.truth_set(),
        "effects_named": [chosen.entry.effect for chosen in diagnosis.effects_],
        "shrink_shares": [chosen.shrink_share for chosen in diagnosis.effects_],
        "strength": spec.strength,
        "strength_value": spec.strength_value,
        "design": spec.design_name,
        "plan": spec.plan,
        "nuisances": dict(spec.nuisances),
        "effect_values": spec.effect_values,
        "true_parameters": truth,
        "verdict": decision.verdict,
        "reason": decision.reason,
        "partial": bool(decision.partial),
        "borderline": [figure["figure"] for figure in decision.borderline],
        "expected_verdict": spec.right_verdict(),
        "correct": decision.verdict == spec.right_verdict(),
        "correct_detectable": decision.verdict == spec.right_verdict()
        or (not detectable and decision.verdict == HEALTHY),
        "detectable": bool(detectable),
        "oracle_gap": visibility,
        "nominal_gap": outcome.nominal_gap if outcome is not None else float("nan"),
        "effect_visibility": dict(per_effect),
        "identifiable_effects": [name for name, gap in per_effect.items() if gap > noise_gap],
        "shrink_fraction": named.shrink_fraction if named is not None else None,
        "shrink_interval": list(named.shrink_interval) if named is not None else None,
        "best_candidate": best.effect if best is not None else None,
        "best_score": best.score if best is not None else None,
        # run-outs the lines cannot tell from the gears' own pitch errors (reported, not named)
        "cannot_tell": (
            [f"{entry['effect']}[{entry['shaft']}]" for entry in outcome.cannot_tell()] if outcome is not None else []
        ),
        "sideband_phase_log_ratios": (
            {evidence.shaft: evidence.log_ratio for evidence in outcome.modulation} if outcome is not None else {}
        ),
    }


def planned_campaigns(
    seed: int | np.random.SeedSequence,
    *,
    suite: str = "library",
    n_per_effect: int = 3,
    effects: Sequence[str] = LIBRARY_EFFECTS,
    designs: Sequence[str] = ("reference", "second"),
    n_healthy: int | None = None,
) -> list[tuple[CampaignSpec, Design, np.random.SeedSequence]]:
    """The campaigns of a blind test (:func:`blindtest`'s arguments), in order, each with its design and seed.

    Examples
    --------
    >>> from uqgear.validation import planned_campaigns
    >>> spec, design, seed = planned_campaigns(1, suite="real_world", n_per_effect=1)[0]
    >>> spec.identifier, design.name
    ('two_effects-eccentricity+tooth_damage-0', 'locomotive')
    """
    if suite not in SUITES:
        raise DiagnosisError(f"suite: expected one of {', '.join(SUITES)}; got {suite!r}")
    if suite == "encoderless":
        # the seed's third child: the first two, the other suites' streams, are not drawn from
        plan_seed, campaigns_seed = as_seed(seed).spawn(3)[2].spawn(2)
        healthy = {} if n_healthy is None else {"n_healthy": n_healthy}
        specs = plan_encoderless(n_per_effect, np.random.default_rng(plan_seed), designs=designs, **healthy)
    elif suite == "runup":
        # the seed's fourth child, a stream of its own
        plan_seed, campaigns_seed = as_seed(seed).spawn(4)[3].spawn(2)
        specs = plan_runup(n_per_effect, np.random.default_rng(plan_seed), designs=designs)
    else:
        plan_seed, campaigns_seed = as_seed(seed).spawn(2)
        if suite == "library":
            specs = plan_campaigns(
                n_per_effect, np.random.default_rng(plan_seed), effects=effects, designs=designs, n_healthy=n_healthy
            )
        else:
            specs = plan_real_world(n_per_effect, np.random.default_rng(plan_seed), designs=designs)
    reference = load_design("locomotive")
    designs_by_name = {"reference": reference, "second": second_design(reference)}
    campaign_seeds = campaigns_seed.spawn(len(specs))
    return [(spec, designs_by_name[spec.design_name], one) for spec, one in zip(specs, campaign_seeds)]


def blindtest(
    out_dir: str | os.PathLike[str],
    *,
    n_per_effect: int = 3,
    seed: int | np.random.SeedSequence = 0,
    effects: Sequence[str] | None = None,
    designs: Sequence[str] = ("reference", "second"),
    n_healthy: int | None = None,
    n_ops: int = 8,
    duration: float = 1.0,
    workers: int | None = None,
    report: bool = True,
    suite: str = "library",
) -> dict[str, Any]:
    """Run a blind test of the diagnosis and write ``blindtest.json``, ``blindtest.nc`` and ``report.html``.

    Parameters
    ----------
    out_dir : path
        Output folder; each campaign's rig file and diagnosis summary go to
        ``campaigns/<id>/``. Everything appears together once the whole
        blind test is written.
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
    suite : {"library", "real_world", "encoderless", "runup"}
        ``library``: each library effect alone on a clean rig (above).
        ``real_world`` (:func:`plan_real_world`): ``n_per_effect`` campaigns
        of each real-world kind: two effects at once, a transfer-path
        resonance with a healthy reference, speed wander, pitch errors, and
        healthy controls carrying those nuisances; ``effects`` and
        ``n_healthy`` do not apply. ``encoderless``
        (:func:`~.campaigns.plan_encoderless`): ``n_per_effect`` campaigns of
        each library effect on a rig without encoders (accelerometers only),
        its strength drawn across its ladder, half of them under speed
        wander, and ``n_healthy`` (default 2) such healthy controls;
        ``effects`` does not apply.
        ``runup`` (:func:`~.runup_campaigns.plan_runup`): ``n_per_effect``
        campaigns of each real-world kind but those whose only nuisance is
        pitch errors, each recorded as a run-up and a coast-down that the
        diagnosis cuts into 8 operating points; ``effects``, ``n_healthy``,
        ``n_ops`` and ``duration`` do not apply.

    Returns
    -------
    dict
        The content of ``blindtest.json``; ``effect_sets`` scores the named
        sets against the true ones (per-effect precision and recall,
        exactly right sets, two-effect campaigns).

    Examples
    --------
    The options are checked before any campaign is simulated, and a mistake
    leaves no folder:

    >>> import pathlib, tempfile
    >>> import uqgear
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     out = pathlib.Path(folder) / "blindtest"
    ...     try:
    ...         uqgear.blindtest(out, n_ops=2)
    ...     except uqgear.UqgearError as error:
    ...         print(type(error).__name__, "-", error, "-", out.exists())
    DiagnosisError - n_ops: expected an integer >= 3; got 2 - False

    The smallest blind test, one eccentricity campaign of three short runs
    diagnosed with the default settings (about a minute):

    >>> with tempfile.TemporaryDirectory() as folder:  # doctest: +SKIP
    ...     content = uqgear.blindtest(pathlib.Path(folder) / "blindtest", n_per_effect=1, effects=["eccentricity"],
    ...                                n_healthy=0, n_ops=3, duration=0.25, designs=("reference",), report=False)
    >>> content["n_campaigns"], content["accuracy"], content["false_alarms"]  # doctest: +SKIP
    (1, 1.0, 0)
    """
    started = time.perf_counter()
    seed_sequence = as_seed(seed)
    effect_names = tuple(LIBRARY_EFFECTS if effects is None else effects)
    n_ops = check_count("n_ops", n_ops, 3)
    if n_ops > len(DEFAULT_PINION_SPEEDS):
        raise DiagnosisError(f"n_ops: expected at most {len(DEFAULT_PINION_SPEEDS)}; got {n_ops}")
    workers = check_workers(workers)
    planned = planned_campaigns(
        seed_sequence, suite=suite, n_per_effect=n_per_effect, effects=effect_names, designs=designs,
        n_healthy=n_healthy,
    )
    specs = [spec for spec, _, _ in planned]
    if suite != "library":
        effect_names = tuple(dict.fromkeys(name for spec in specs for name in spec.truth_set()))
    # nothing appears in out_dir until the whole blind test is written
    with OutputFolder(out_dir) as out:
        campaigns = [
            diagnose_campaign(
                spec,
                design,
                campaign_seed,
                out / "campaigns" / spec.identifier,
                n_ops=n_ops,
                duration=duration,
                workers=workers,
            )
            for spec, design, campaign_seed in planned
        ]
        content = summarise(
            campaigns, effect_names, seconds=time.perf_counter() - started, seed_text=str(seed_sequence.entropy)
        )
        save_result(blindtest_dataset(content), out / "blindtest.nc", seed=seed_sequence)
        write_text_atomic(out / "blindtest.json", json.dumps(json_clean(content), indent=2, default=json_default))
        if report:
            from ..report.diagnosis_report import write_blindtest_report

            write_blindtest_report(json_clean(content), out / "report.html")
    return json_clean(content)


__all__ = ["blindtest", "diagnose_campaign"]
