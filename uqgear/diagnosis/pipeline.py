"""The diagnosis pipeline: fit the nominal model and every candidate effect, score them on held-out runs, decide.

Sim-to-real gap diagnosis: where the model and the rig disagree, which
unmodelled effect causes it, and how far the gap shrinks once it is added.

Pipeline (docs/model.md section 6):

1. **Features.** The rig's records are reduced to the features of
   :mod:`uqgear.rig.features` (mesh harmonics, sideband families per shaft, shaft
   and motor lines, a low-frequency band, RMS, kurtosis). The model's records
   go through *the same* processing: each run is simulated (steady state after
   a run-in), band-limited like the rig's anti-alias filter, resampled onto
   the rig's time grid and fed to the same window-weighted line fit. A steady
   response that repeats over a mesh period, a pinion or a gear revolution is
   simulated over that period only and tiled (exact for a periodic
   response); anything else over the full record.
2. **Predictive distribution.** A feature of the rig is the model's value plus
   sensor noise plus model error. A line amplitude is Rice distributed about
   the model's amplitude with a per-quadrature spread from the record's white
   noise floor (exact for the weighted least-squares fit) and a relative
   model error; band powers add the noise power. The *standardised
   discrepancy* of a feature is its probability integral transform mapped to
   a standard normal, so it is N(0, 1) where the model is right, also for
   lines at the noise floor (censoring is built in).
3. **Fit.** The nominal model (mesh stiffness scale, mesh damping ratio, STE
   amplitude, bearing stiffnesses; T2 of each run inside its interval) is fitted by
   robust least squares on the standardised discrepancies with priors from
   the nominal design (a Laplace approximation of its posterior): soft-L1 on
   the mesh harmonics first, each run's T2 profiled on a grid (T2 can move a
   run across a regime boundary), then a Cauchy loss on all line and band
   features so that what the model class cannot produce loses its pull.
   Every candidate effect is screened with its own parameters on top of the
   nominal fit, from a start grid read off the data's signature (run-out
   from the 1x TE line, stick-slip frequency from frequency-locked lines);
   the best is refitted with all parameters. A calibration posterior
   (``uqgear calibrate``) can give the nominal fit's start.
4. **Held-out scoring.** Leave-one-operating-point-out predictions (one Newton
   step from the full fit without that run, the held-out run's T2 profiled,
   the prediction itself re-simulated) give the gap map on held-out runs, a
   robust predictive density per candidate and the gap metric before and
   after adding the effect.
5. **Verdict.** ``none`` when the nominal model is within noise on held-out
   runs; otherwise the best candidate when it clearly beats the nominal
   model (predictive density gain beyond a penalty per extra parameter, a
   gap that shrinks by at least half); otherwise ``unexplained``;
   ``inconclusive`` when no feature could be compared on held-out runs (and,
   decided before any fit by :func:`uqgear.diagnosis.workflow.diagnose`, when
   no line stands above the noise floor in two runs).
6. **Several effects (forward selection).** When an effect is named and
   its model still leaves a significant held-out gap, the model with it
   becomes the base: the other library effects (never the named one again,
   nor another variant of it) are screened on top of it with only their own
   parameters free, the best is fitted in full with all effects present in
   the simulation and scored on held-out runs against the base's held-out
   predictions; :func:`~.verdict.decide`, applied to the gap that remains,
   adds it or not. Repeated while a significant gap remains, at most three
   effects. The verdict stays the first effect; each effect's share of the
   shrink and the final model's remaining gap are reported with it.

Each step runs inside a :class:`~uqgear.common.steps.StepLog` step: a failure
after the input was accepted is an :class:`~uqgear.common.errors.InternalError`
naming the step, not a user error.

This module holds the steps 3 to 6 together (:func:`run_diagnosis`); the
pieces live in :mod:`.simulation` (step 1), :mod:`.discrepancy` (step 2),
:mod:`.candidates`, :mod:`.case` and :mod:`.fitting` (step 3),
:mod:`.scoring` (step 4) and :mod:`.verdict` (step 5). It does no
plotting; :func:`uqgear.diagnosis.workflow.diagnose` writes ``diagnosis.json``,
``diagnosis.nc`` (:mod:`.outputs`) and, through
:mod:`uqgear.report.diagnosis_report`, ``report.html``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import xarray as xr

from ..common.steps import StepLog
from ..physics.effects import EFFECTS
from ..uq.seeds import child_seed
from .candidates import candidates_for
from .case import FeatureModelError, RigCase
from .errors import DiagnosisError
from .fitting import FitResult, calibration_start, fit, fit_candidate, fit_nominal, robust_cost
from .manufacturing import (DEFAULT_CLASSES, check_classes, first_order_reads, modulation_gain, pitch_error_allowance,
                            with_own_allowance)
from .scoring import (CandidateScore, HeldOut, bootstrap_gap, gap_metric, leave_one_out, score_candidate,
                      shrink_fraction)
from .sideband_phase import ModulationEvidence, fit_modulated_run_out, modulation_evidence, shafts_tested
from .result import DiagnosisResult, SelectedEffect, SelectionRound
from .signatures import frequency_locked_lines, signature_hints
from .verdict import (EFFECT_GAIN_THRESHOLD, EFFECT_NAMES, NOISE_GAP_THRESHOLD, SCORE_THRESHOLD, SHRINK_THRESHOLD,
                      Decision, decide, decide_verdict, family_character, holds_against_pitch_errors, where_gap)

#: Candidates promoted from the screening fit (effect parameters only) to a full fit.
PROMOTED = 2
#: Most effects a diagnosis names together (forward selection).
MAX_EFFECTS = 3
# Child of the diagnosis seed that draws the pitch errors (the bootstrap uses the seed itself).
_PITCH_ERROR_STREAM = 7


def _check_effects(effects: Sequence[str] | None) -> tuple[str, ...]:
    if effects is None:
        return EFFECT_NAMES
    if isinstance(effects, str):
        effects = [effects]
    chosen = []
    for name in effects:
        if not isinstance(name, str) or name not in EFFECTS:
            raise DiagnosisError(f"effects: {name!r} is not a library effect; expected one or more of "
                                 f"{', '.join(EFFECT_NAMES)}")
        if name not in chosen:
            chosen.append(name)
    if not chosen:
        raise DiagnosisError(f"effects: expected at least one of {', '.join(EFFECT_NAMES)}; got none")
    return tuple(chosen)


# Full fits beyond the promoted ones while the gap stays unexplained (each costs about a screening).
_EXTRA_FULL_FITS = 3
# The nominal fit is restarted from a candidate's fit at most this many times.
_NOMINAL_REFITS = 2
# A candidate's nominal parameters must beat the nominal fit's robust cost by this much (about
# nats) to count as evidence that the nominal fit stopped in a local optimum.
_NOMINAL_MARGIN = 5.0


def effect_off_costs(nominal: FitResult, fits: Sequence[FitResult], *, own_error: bool = False
                     ) -> tuple[list[np.ndarray], list[float]]:
    """The base model at each fit's values of the base's parameters and T2 (its new effect off): vectors and costs.

    ``nominal`` is the base fit: the nominal model's, or in forward selection
    the model with the effects named before (the new effect is switched off,
    the others stay at the fit's values). ``own_error``: each cost is taken
    with that fit's model error (its own pitch-error allowance), so that an
    effect's gain is what switching it off costs under one error model,
    not what a wider allowance forgives; else with the base's.
    """
    problem = nominal.problem
    names = {spec.name for spec in problem.specs}
    starts = [problem.vector({key: value for key, value in candidate.values.items() if key in names},
                             candidate.vector[candidate.problem.n_global:]) for candidate in fits]
    if not starts:
        return [], []
    model, _ = problem.model_features(starts)
    errors = [fit_result.problem.model_error if own_error else None for fit_result in fits]
    return starts, [robust_cost(problem.residual_vector(problem.discrepancy(model[index], errors[index])[0], v))
                    for index, v in enumerate(starts)]


def improved_nominal(nominal: FitResult, fits: Sequence[FitResult], *,
                     margin: float = _NOMINAL_MARGIN) -> FitResult | None:
    """A better nominal fit found through the candidates' full fits, or None.

    Every candidate contains the nominal model (its effect at strength 0).
    A full candidate fit refits the nominal parameters and T2 too; if the
    nominal model alone, at those values, fits the data better than the
    nominal fit did, the nominal fit had stopped in a local optimum (light
    loads, with contact loss near the bearing modes, have several), and a
    candidate would otherwise be credited with what is only the better
    optimum. The nominal model is then refitted from the best such point.
    """
    problem = nominal.problem
    starts, costs = effect_off_costs(nominal, fits)
    if not starts:
        return None
    best = int(np.argmin(costs))
    if costs[best] >= nominal.cost - margin:
        return None
    refit = fit(problem, [starts[best]], max_evaluations=30, tolerance=1e-3)
    refit.after(nominal)
    return refit if refit.cost < nominal.cost - margin else None


def _found(entry: CandidateScore) -> dict[str, Any]:
    """What a candidate's fit found, for the step log."""
    return {"score": entry.score, "shrink_fraction": entry.shrink, "gap_with_effect": entry.gap,
            "parameters": entry.parameters()}


def _supersedes(full: CandidateScore, best: CandidateScore) -> bool:
    """Whether a full fit takes the place of its effect's best entry so far.

    When it scores higher; and always over the screening of its own
    variant when it was scored with its own pitch-error allowance (the
    screening was scored with the nominal model's: the two are not on one
    footing).
    """
    own = full.fit.problem.own_model_error is not None
    return full.score > best.score or (own and best.stage == "screening" and best.label == full.label)


def _score_candidates(case: RigCase, nominal: FitResult, nominal_held: HeldOut, nominal_gap: float,
                      effect_names: Sequence[str], hints: Mapping[str, float], rng: np.random.Generator,
                      promoted: int, timings: dict[str, float], steps: StepLog
                      ) -> tuple[dict[str, CandidateScore], list[CandidateScore]]:
    """Screen every candidate against the nominal fit, fit the best ones in full; best score per effect."""
    clock = time.perf_counter()
    screened: list[CandidateScore] = []
    for name in effect_names:
        for candidate in candidates_for(name, case.design, hints=hints):
            with steps.step(f"screen {candidate.label}") as found:
                result = fit_candidate(case, candidate, nominal, full=False, max_evaluations=6)
                screened.append(score_candidate(result, leave_one_out(result), nominal_held, "screening", rng))
                found.update(_found(screened[-1]))
    timings["screening"] += time.perf_counter() - clock

    clock = time.perf_counter()
    best_per_effect: dict[str, CandidateScore] = {}
    for entry in screened:
        if entry.effect not in best_per_effect or entry.score > best_per_effect[entry.effect].score:
            best_per_effect[entry.effect] = entry
    order = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
    all_scores = list(screened)
    # the runner-up is refitted too unless the screening already puts it far behind; with a pitch-error
    # allowance the screening judged every candidate by the nominal model's allowance, which an effect
    # that acts together with the pitch errors (friction) outgrows, so any runner-up with evidence of
    # its own is refitted (with its own allowance, with_own_allowance)
    if case.pitch_allowance is not None:
        def also_promoted(entry: CandidateScore) -> bool:
            return entry.score >= SCORE_THRESHOLD
    else:
        def also_promoted(entry: CandidateScore) -> bool:
            return entry.score > 0 and entry.score >= 0.25 * order[0].score
    chosen = [entry for rank, entry in enumerate(order[:promoted]) if rank == 0 or also_promoted(entry)]

    def fit_in_full(entries: Sequence[CandidateScore]) -> None:
        for entry in entries:
            candidate = entry.fit.problem.candidate
            with steps.step(f"fit {candidate.label} in full") as found:
                result = with_own_allowance(fit_candidate(case, candidate, nominal, full=True, max_evaluations=12,
                                                          start=entry.fit))
                full = score_candidate(result, leave_one_out(result), nominal_held, "full", rng)
                _measure_modulation(case, full)
                found.update(_found(full))
            all_scores.append(full)
            if _supersedes(full, best_per_effect[entry.effect]):
                best_per_effect[entry.effect] = full

    fit_in_full(chosen)
    # An effect that changes the response only in a few runs (a bearing clearance where a bearing
    # unloads) cannot be screened with the nominal parameters held where the nominal model put
    # them to absorb that change: before a gap is called unexplained the next candidate variants
    # get a full fit, best screened first, until one explains it.
    remaining = sorted((entry for entry in screened if not any(entry is done for done in chosen)),
                       key=lambda entry: -entry.score)
    for entry in remaining[:_EXTRA_FULL_FITS]:
        if decide_verdict(nominal_gap, _ranking_of(best_per_effect))[0] != "unexplained":
            break
        fit_in_full([entry])
    full_fits = [entry for entry in all_scores if entry.stage == "full"]
    with steps.step("switch the effects of the full fits off"):
        costs = effect_off_costs(nominal, [entry.fit for entry in full_fits], own_error=True)[1]
    for entry, cost in zip(full_fits, costs):
        entry.effect_gain = cost - entry.fit.cost
    for entry in screened:
        entry.effect_gain = nominal.cost - entry.fit.cost
    timings["full_fits"] += time.perf_counter() - clock
    return best_per_effect, all_scores


def _measure_modulation(case: RigCase, full: CandidateScore) -> None:
    """Set an eccentricity full fit's :attr:`~.scoring.CandidateScore.modulation_gain` where pitch errors apply.

    Only there does the run-out guard of :func:`_ranking_entry` need it;
    elsewhere it stays None at no cost.
    """
    if full.effect == "eccentricity" and case.run_out_allowance:
        full.modulation_gain = modulation_gain(full.fit)


def _ranking_entry(s: CandidateScore) -> dict[str, Any]:
    """What :func:`decide` needs of one candidate's scores.

    A run-out within what the gears' stated pitch-error classes make as a
    first-order run-out (``case.run_out_allowance``) is flagged
    ``within_pitch_errors``: it is not evidence of an eccentric shaft,
    unless the fit is also clearly worse without its mesh-stiffness
    modulation (``modulation_gain`` at least the effect-gain threshold),
    which pitch errors do not make.
    """
    entry = s.figures()
    if s.effect == "eccentricity" and s.fit.problem.case.run_out_allowance:
        bounds = s.fit.problem.case.run_out_allowance
        values = s.parameters()
        bound = bounds.get(str(values.get("shaft")))
        modulated = s.modulation_gain is not None and s.modulation_gain >= EFFECT_GAIN_THRESHOLD
        run_out = float(values.get("amplitude", math.nan))
        if bound is not None and run_out <= bound and not modulated:
            entry["within_pitch_errors"] = {"run_out": run_out, "bound": bound}
        elif bound is not None and run_out > bound:
            entry["beyond_pitch_errors"] = {"run_out": run_out, "bound": bound}
    return entry


def _ranking_of(best_per_effect: Mapping[str, CandidateScore]) -> list[dict[str, Any]]:
    """What :func:`decide_verdict` needs of the best variant of each effect, best first."""
    scores = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
    return [_ranking_entry(s) for s in scores]


def _leads_a_set(best: Mapping[str, Any], *, pitch_allowance: bool = False) -> bool:
    """Whether an unexplained gap's best candidate is strong enough to start a forward selection.

    The evidence rules of :func:`~.verdict.decide` without the one on how
    much of the gap it explains alone: a score beyond the threshold, a fit
    that is clearly worse with its effect off, and a shrink whose 90 %
    interval is above zero. With the pitch-error allowance the score must
    reach the threshold at its 90 % lower bound, as decide asks of an
    effect that does not halve the gap there: a set led by a weak first
    effect would name it anyway.
    """
    return (best["score"] >= SCORE_THRESHOLD and float(best.get("effect_gain", math.inf)) >= EFFECT_GAIN_THRESHOLD
            and best["shrink_interval"][0] > 0.0 and not best.get("within_pitch_errors")
            and (not pitch_allowance or holds_against_pitch_errors(best)))


def shrink_shares(nominal_gap: float, first_shrink: float, gaps: Sequence[float]) -> list[float]:
    """Each named effect's share of the held-out gap shrink, as a fraction of the nominal model's gap.

    The first effect's share is its shrink fraction (``first_shrink``, its
    gap ``gaps[0]`` against the nominal model's); each later one's is
    (gap before it - gap after it) / nominal gap, ``gaps`` being the
    held-out gaps after each effect of the set, in order. The shares add up
    to the shrink of the whole set, 1 - last gap / nominal gap.
    """
    shares = [float(first_shrink)] if gaps else []
    for before, after in zip(gaps[:-1], gaps[1:]):
        shares.append((before - after) / nominal_gap if nominal_gap > 0 else 0.0)
    return shares


def _next_effect(case: RigCase, base: CandidateScore, named: Sequence[str], effect_names: Sequence[str],
                 hints: Mapping[str, float], rng: np.random.Generator, steps: StepLog, *,
                 noise_gap: float = NOISE_GAP_THRESHOLD) -> SelectionRound:
    """One forward-selection round: the other effects screened on top of the base, the best fitted in full.

    Only the new effect's parameters are screened (the base's fit, its
    Jacobian and held-out predictions are reused); the best screened
    variant is fitted in full with every effect present, and scored against
    the base's held-out predictions; :func:`decide` on top of the base adds
    it or not.
    """
    base_fit, base_held = base.fit, base.held
    base_labels = tuple(candidate.label for candidate in base_fit.problem.candidates)
    screened: list[CandidateScore] = []
    for name in effect_names:
        if name in named:
            # an effect is never named twice, nor as another variant: it would only soak up noise
            continue
        for candidate in candidates_for(name, case.design, hints=hints):
            with steps.step(f"forward selection: screen {candidate.label} on top of {' + '.join(base_labels)}") \
                    as found:
                result = fit_candidate(case, candidate, base_fit, full=False, max_evaluations=6)
                screened.append(score_candidate(result, leave_one_out(result), base_held, "screening", rng))
                screened[-1].effect_gain = base_fit.cost - result.cost
                found.update(_found(screened[-1]))
    if not screened:
        return SelectionRound(base_labels, base.gap, [], None, "no other candidate effect is left to try")
    best_per_effect: dict[str, CandidateScore] = {}
    for entry in screened:
        if entry.effect not in best_per_effect or entry.score > best_per_effect[entry.effect].score:
            best_per_effect[entry.effect] = entry
    leader = max(screened, key=lambda entry: entry.score)
    candidate = leader.fit.problem.candidate
    with steps.step(f"forward selection: fit {candidate.label} in full on top of {' + '.join(base_labels)}") \
            as found:
        result = with_own_allowance(fit_candidate(case, candidate, base_fit, full=True, max_evaluations=12,
                                                  start=leader.fit))
        full = score_candidate(result, leave_one_out(result), base_held, "full", rng)
        full.effect_gain = effect_off_costs(base_fit, [result], own_error=True)[1][0] - result.cost
        _measure_modulation(case, full)
        found.update(_found(full))
    if _supersedes(full, best_per_effect[full.effect]):
        best_per_effect[full.effect] = full
    ranking = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
    best = best_per_effect[full.effect]
    figures = _ranking_entry(best)
    figures["gap_interval"] = list(bootstrap_gap(best.held.z, rng))
    # no density_evidence here: a further effect must shrink a gap that is there, or it only soaks up what
    # the allowance already forgives (measured: torque ripple's motor line on the sideband that friction
    # and pitch errors share, 21 nats on top of a gap of 0.00)
    decision = decide(base.gap, [figures], noise_gap=noise_gap, pitch_allowance=case.pitch_allowance is not None)
    added = best.effect if decision.verdict == best.effect else None
    return SelectionRound(base_labels, base.gap, ranking, added, decision.reason, decision,
                          tuple(figures["gap_interval"]))


def forward_selection(case: RigCase, nominal_gap: float, first: CandidateScore, first_decision: Decision,
                      effect_names: Sequence[str], hints: Mapping[str, float], rng: np.random.Generator,
                      steps: StepLog, *, first_gap_interval: Sequence[float] = (math.nan, math.nan),
                      max_effects: int = MAX_EFFECTS, noise_gap: float = NOISE_GAP_THRESHOLD
                      ) -> tuple[list[SelectedEffect], list[SelectionRound]]:
    """Add effects one at a time after the first while a significant held-out gap remains.

    The first effect's fit (``first``, named by :func:`decide`) is the base;
    each round screens the effects not yet named on top of it, fits the
    best in full with all effects present and adds it when :func:`decide`,
    applied to the gap that remains, names it (held-out score beyond the
    penalty, its own effect gain, a shrink of the remaining gap); the
    model with it is the next base. Rounds stop when the remaining gap is
    within ``noise_gap`` (where the pitch-error allowance applies, only at a
    gap of 0: its widened error can hold a further effect's evidence below
    the noise gap, and the effect is added when it shrinks what is left),
    when a round adds nothing, or at ``max_effects``.

    Returns
    -------
    selected : list of SelectedEffect
        The named effects in order (the first one included), with their shrink shares.
    rounds : list of SelectionRound
        The rounds after the first, the last one possibly adding nothing.
    """
    entries, decisions, intervals = [first], [first_decision], [tuple(first_gap_interval)]
    rounds: list[SelectionRound] = []
    # with the pitch-error allowance a gap within noise does not mean nothing is left: rounds go on while
    # there is any gap to shrink, until one adds nothing
    allowance_applies = case.pitch_allowance is not None
    while len(entries) < max_effects and (entries[-1].gap > noise_gap
                                          or (allowance_applies and entries[-1].gap > 0.0)):
        selection = _next_effect(case, entries[-1], [entry.effect for entry in entries], effect_names, hints, rng,
                                 steps, noise_gap=noise_gap)
        rounds.append(selection)
        if selection.added is None:
            break
        # the added effect's best fit leads its round's ranking (its full fit was started from the best screening)
        entries.append(selection.scores[0])
        decisions.append(selection.decision)
        intervals.append(selection.gap_interval)
    shares = shrink_shares(nominal_gap, first.shrink, [entry.gap for entry in entries])
    befores = [nominal_gap] + [entry.gap for entry in entries[:-1]]
    selected = [SelectedEffect(entry, before, share, decision, interval)
                for entry, before, share, decision, interval in zip(entries, befores, shares, decisions, intervals)]
    return selected, rounds


def set_decision(first_decision: Decision, selected: Sequence[SelectedEffect], rounds: Sequence[SelectionRound],
                 nominal_gap: float, *, shrink_threshold: float = SHRINK_THRESHOLD,
                 noise_gap: float = NOISE_GAP_THRESHOLD) -> Decision:
    """The decision for the named set: the first effect's verdict, ``partial`` and remaining gap of the whole set.

    With one effect named and no round run this is ``first_decision``
    itself. ``partial`` follows the rule of :func:`decide` applied to the
    set against the nominal model: an effect set is named with an
    unexplained remainder when it neither shrinks the nominal gap by
    ``shrink_threshold`` nor leaves a gap within noise.
    """
    if not selected or not rounds:
        return first_decision
    final_gap = selected[-1].entry.gap
    reason = first_decision.reason
    borderline = list(first_decision.borderline)
    for chosen in selected[1:]:
        names = " + ".join(entry.entry.effect for entry in selected[:selected.index(chosen)])
        entry = chosen.entry
        reason += (f"; on top of {names}, forward selection adds {entry.effect}: it gains {entry.score:.1f} nats "
                   f"of held-out predictive density after its penalty and shrinks the remaining held-out gap "
                   f"from {chosen.gap_before:.2f} to {entry.gap:.2f} (90 % interval of the shrink "
                   f"{100 * entry.shrink_low:.0f} to {100 * entry.shrink_high:.0f} %), "
                   f"{100 * chosen.shrink_share:.0f} % of the nominal gap")
        borderline += [{**figure, "effect": entry.effect} for figure in chosen.decision.borderline]
    last = rounds[-1]
    if last.added is None and last.scores:
        best = last.scores[0]
        reason += (f"; no further effect clearly explains the remaining gap of {last.gap_before:.2f} (the best, "
                   f"{best.effect}, scores {best.score:.1f} nats on top and shrinks it by "
                   f"{100 * best.shrink:.0f} %)")
    explains = shrink_fraction(nominal_gap, final_gap) >= shrink_threshold or final_gap <= noise_gap
    if not explains:
        reason += f"; a gap of {final_gap:.2f} (above {noise_gap:g}) remains unexplained"
    return Decision(first_decision.verdict, reason, partial=not explains, remaining_gap=final_gap,
                    borderline=tuple(borderline))


def _phase_named_run_out(case: RigCase, nominal: FitResult, nominal_held: HeldOut, nominal_gap: float,
                         selected: list[SelectedEffect], decision: Decision, rng: np.random.Generator,
                         steps: StepLog) -> tuple[list[ModulationEvidence],
                                                  tuple[list[SelectedEffect], Decision] | None]:
    """Test the shafts' sideband phase sums for an eccentricity the amplitudes cannot tell from pitch errors.

    Each shaft :func:`~.sideband_phase.shafts_tested` admits is tested
    against the final model (:func:`~.sideband_phase.modulation_evidence`);
    the shaft with the strongest decisive evidence gets its eccentricity
    fitted on top (:func:`~.sideband_phase.fit_modulated_run_out`) and added
    to the set, with its own share of the shrink (negative where it widens
    the held-out gap).
    """
    base_fit = selected[-1].entry.fit if selected else nominal
    base_held = selected[-1].entry.held if selected else nominal_held
    base_gap = selected[-1].entry.gap if selected else nominal_gap
    reads = first_order_reads(case.pitch_allowance)
    found_evidence = []
    for shaft in shafts_tested(case):
        if shaft not in reads:
            continue
        with steps.step(f"test the {shaft}'s sideband phases for an eccentric shaft") as found:
            evidence = modulation_evidence(case, base_fit, shaft, reads[shaft][0])
            found.update(evidence.summary())
        found_evidence.append(evidence)
    decisive = [evidence for evidence in found_evidence if evidence.decisive]
    if not decisive:
        return found_evidence, None
    evidence = max(decisive, key=lambda item: item.log_ratio)
    with steps.step(f"fit the eccentric {evidence.shaft} shaft the sideband phases name") as found:
        entry = fit_modulated_run_out(case, base_fit, base_held, evidence, rng)
        found.update(_found(entry))
    share = (base_gap - entry.gap) / nominal_gap if nominal_gap > 0 else 0.0
    run_out = entry.parameters()["amplitude"]
    low, high = entry.parameter_intervals().get("amplitude", (math.nan, math.nan))
    # the amplitudes cannot tell the run-out from the gear's own first-order errors: its interval says how much
    reason = (f"{evidence.reason()}; fitted on top, its run-out is left open by the line amplitudes, which "
              f"cannot tell it from the {evidence.shaft}'s own first-order errors ({1e6 * run_out:.3g} um, 90 % "
              f"interval {1e6 * low:.3g} to {1e6 * high:.3g} um), and it changes the held-out gap from "
              f"{base_gap:.2f} to {entry.gap:.2f}")
    added = Decision("eccentricity", reason, remaining_gap=entry.gap)
    chosen = SelectedEffect(entry, base_gap, share, added, tuple(bootstrap_gap(entry.held.z, rng)))
    decision = replace(decision, reason=f"{decision.reason}; {reason}", remaining_gap=entry.gap) if selected \
        else added
    return found_evidence, ([*selected, chosen], decision)


def run_diagnosis(case: RigCase, *, effects: Sequence[str] | None = None, seed: np.random.SeedSequence,
                  promoted: int = PROMOTED, calibration: xr.Dataset | None = None,
                  steps: StepLog | None = None, max_effects: int = MAX_EFFECTS,
                  pitch_classes: tuple[float, float] | None = DEFAULT_CLASSES) -> DiagnosisResult:
    """Fit the nominal model and every candidate, score them on held-out runs, decide.

    Candidates are screened with their own parameters only (the nominal
    parameters and T2 stay at the nominal fit); the best effect, and up to
    ``promoted`` - 1 runners-up within a quarter of its score, are then
    fitted in full (all parameters), warm-started from the screening fit,
    and keep whichever fit scores better on held-out runs; while that leaves
    a significant gap unexplained, up to three more variants are fitted in
    full, best screened first, before the verdict says so. If a full fit
    shows that the nominal fit stopped in a local optimum
    (:func:`improved_nominal`), the nominal model is refitted from there and
    the candidates are scored again against it. When an effect is named and
    a significant held-out gap remains, further effects are added by
    forward selection (:func:`forward_selection`, at most ``max_effects``
    in all). When the gap stays unexplained only because no effect explains
    enough of it alone, the strongest candidate (its evidence rules met,
    :func:`_leads_a_set`) starts a forward selection, and the set is named
    if together it shrinks the gap by half or leaves it within noise (two
    effects of about equal size). Where the rig's sidebands show pitch errors on both shafts,
    what pitch errors of ``pitch_classes`` do to each feature becomes model
    error of the nominal model, which is then refitted
    (:mod:`uqgear.diagnosis.manufacturing`).

    Parameters
    ----------
    case : RigCase
        The prepared campaign (:func:`prepare_case`), optionally with an executor attached.
    effects : sequence of str, optional
        Candidate effects (default all six).
    seed : SeedSequence
        Seeds the bootstrap of the shrink fractions.
    promoted : int
        At most this many effects get a full fit.
    calibration : xarray.Dataset, optional
        A calibration posterior; the nominal fit starts from its medians.
    max_effects : int
        Most effects named together by forward selection (1: the first one only).
    pitch_classes : (float, float) or None
        ISO 1328-1 flank tolerance classes (finest, coarsest) the gears are
        made to; None: perfect gears, no allowance for pitch errors.
    steps : StepLog, optional
        Records each finished step with what it found; a failure inside a
        step is raised as :class:`~uqgear.common.errors.InternalError`
        naming it, with the finished steps attached.

    Returns
    -------
    DiagnosisResult

    Raises
    ------
    DiagnosisError
        An unknown effect, a bad ``max_effects``, or a calibration posterior without the nominal parameters.
    InternalError
        A step failed after the input was accepted.
    """
    effect_names = _check_effects(effects)
    pitch_classes = check_classes(pitch_classes)
    if isinstance(max_effects, bool) or not isinstance(max_effects, (int, np.integer)) or max_effects < 1:
        raise DiagnosisError(f"max_effects: expected an integer >= 1; got {max_effects!r}")
    steps = StepLog() if steps is None else steps
    rng = np.random.default_rng(seed)
    timings: dict[str, float] = {"order_tracking": case.tracking_s, "nominal_fit": 0.0, "screening": 0.0,
                                 "full_fits": 0.0}
    start, positions = None, None
    if calibration is not None:
        # the posterior is input: checked here, before the work, so a bad one is the user's error
        start, positions = calibration_start(calibration, case)
        if "backlash" in start:
            case.design = case.design.replace(backlash=start.pop("backlash"))
    clock = time.perf_counter()
    with steps.step("fit the nominal model") as found:
        nominal = fit_nominal(case) if start is None else fit_nominal(case, start=start, positions=positions)
        found.update(parameters=nominal.values, adhesion_torque=list(nominal.adhesion_torques), cost=nominal.cost)
    timings["nominal_fit"] += time.perf_counter() - clock
    clock = time.perf_counter()
    with steps.step("allow for the gears' pitch errors") as found:
        allowance = pitch_error_allowance(case, nominal, classes=pitch_classes,
                                          seed=child_seed(seed, _PITCH_ERROR_STREAM))
        found.update(applied=allowance.applied, reason=allowance.reason)
        if allowance.applied:
            case.model_error_before_allowance = case.model_error
            case.pitch_allowance = allowance
            case.model_error = FeatureModelError.combined(case.model_error, allowance.absolute)
            # the nominal parameters were pulled by what pitch errors did to the features: refit
            nominal = fit(nominal.problem, [nominal.vector], max_evaluations=30, tolerance=1e-3).after(nominal)
            found.update(parameters=nominal.values, cost=nominal.cost)
    timings["pitch_errors"] = time.perf_counter() - clock
    with steps.step("find frequency-locked lines and signature hints") as found:
        locked = frequency_locked_lines(case)
        hints = signature_hints(case, locked)
        found.update(hints=dict(hints))
    for attempt in range(_NOMINAL_REFITS + 1):
        clock = time.perf_counter()
        with steps.step("predict held-out runs with the nominal model") as found:
            nominal_held = leave_one_out(nominal)
            nominal_gap = gap_metric(nominal_held.z)
            found.update(nominal_gap=nominal_gap)
        timings["nominal_fit"] += time.perf_counter() - clock
        best_per_effect, all_scores = _score_candidates(case, nominal, nominal_held, nominal_gap, effect_names,
                                                        hints, rng, promoted, timings, steps)
        if attempt == _NOMINAL_REFITS:
            break
        clock = time.perf_counter()
        with steps.step("check the nominal fit against the candidate fits") as found:
            better = improved_nominal(nominal, [entry.fit for entry in all_scores if entry.stage == "full"])
            found.update(refitted=better is not None)
        timings["nominal_fit"] += time.perf_counter() - clock
        if better is None:
            break
        # the candidates were scored against a nominal fit stuck in a local optimum: score them again
        nominal = better
    with steps.step("decide the verdict") as found:
        scores = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
        ranking = _ranking_of(best_per_effect)
        # drawn after the shrink bootstraps, so their numbers do not depend on this
        nominal_interval = bootstrap_gap(nominal_held.z, rng)
        if scores:
            ranking[0]["gap_interval"] = list(bootstrap_gap(scores[0].held.z, rng))
        decision = decide(nominal_gap, ranking, nominal_gap_interval=nominal_interval,
                          pitch_allowance=case.pitch_allowance is not None,
                          density_evidence=case.pitch_allowance is not None)
        where = where_gap(nominal_held.z, case)
        families = family_character(nominal_held.z, case, locked)
        found.update(verdict=decision.verdict, reason=decision.reason)
    selected: list[SelectedEffect] = []
    rounds: list[SelectionRound] = []
    if decision.verdict == "unexplained" and scores and _leads_a_set(ranking[0],
                                                                     pitch_allowance=case.pitch_allowance is not None):
        # two effects of about equal size each explain less than half of the gap alone: the strongest,
        # clearly carried by its effect, is the base of a forward selection, and the set is named only
        # if it explains the gap together (set_decision's rule)
        clock = time.perf_counter()
        first = scores[0]
        provisional = Decision(first.effect, (
            f"{first.effect} gains {first.score:.1f} nats of held-out predictive density over the nominal model "
            f"after its parameter penalty but alone shrinks the held-out gap by only {100 * first.shrink:.0f} % "
            f"(90 % interval {100 * first.shrink_low:.0f} to {100 * first.shrink_high:.0f} %)"),
            partial=True, remaining_gap=first.gap)
        trial, trial_rounds = forward_selection(case, nominal_gap, first, provisional, effect_names, hints, rng,
                                                steps, first_gap_interval=ranking[0]["gap_interval"],
                                                max_effects=max_effects)
        timings["forward_selection"] = time.perf_counter() - clock
        with steps.step("decide whether a set of effects explains the gap") as found:
            # set_decision's own rule: the set is partial unless it halves the gap or leaves it within noise
            joint = set_decision(provisional, trial, trial_rounds, nominal_gap) if len(trial) > 1 else None
            if joint is not None and not joint.partial:
                selected, rounds, decision = trial, trial_rounds, joint
            else:
                decision = Decision(decision.verdict, decision.reason + (
                    f"; forward selection from {first.effect} found no set that explains it together (held-out "
                    f"gap {trial[-1].entry.gap:.2f} with {' + '.join(entry.entry.effect for entry in trial)})"),
                    borderline=decision.borderline)
            found.update(effects=[chosen.entry.effect for chosen in selected], verdict=decision.verdict)
    elif decision.verdict in EFFECT_NAMES:
        # forward selection: a second round only while the named effect leaves a significant gap
        clock = time.perf_counter()
        selected, rounds = forward_selection(case, nominal_gap, scores[0], decision, effect_names, hints, rng, steps,
                                             first_gap_interval=ranking[0]["gap_interval"],
                                             max_effects=max_effects)
        if rounds:
            timings["forward_selection"] = time.perf_counter() - clock
        with steps.step("decide the effect set") as found:
            decision = set_decision(decision, selected, rounds, nominal_gap)
            found.update(effects=[chosen.entry.effect for chosen in selected], partial=decision.partial)
    modulation: list[ModulationEvidence] = []
    if allowance.applied and "eccentricity" in effect_names and decision.verdict != "unexplained" \
            and len(selected) < max_effects and "eccentricity" not in [chosen.entry.effect for chosen in selected]:
        clock = time.perf_counter()
        modulation, added = _phase_named_run_out(case, nominal, nominal_held, nominal_gap, selected, decision, rng,
                                                 steps)
        if added is not None:
            selected, decision = added
        timings["sideband_phases"] = time.perf_counter() - clock
    final_held = selected[-1].entry.held if selected else nominal_held
    remaining_interval = selected[-1].gap_interval if selected else nominal_interval
    return DiagnosisResult(case=case, nominal=nominal, nominal_held=nominal_held, scores=scores,
                           all_scores=all_scores, verdict=decision.verdict, reason=decision.reason,
                           nominal_gap=nominal_gap, where=where, families=families, locked_lines=locked, hints=hints,
                           effects=effect_names, timings=timings, decision=decision,
                           nominal_gap_interval=nominal_interval, selected=selected, rounds=rounds,
                           final_held=final_held,
                           # with no effect named the final model is the nominal one: its maps are already made
                           remaining_where=where_gap(final_held.z, case) if selected else where,
                           remaining_families=family_character(final_held.z, case, locked) if selected else families,
                           remaining_interval=tuple(remaining_interval), pitch_errors=allowance,
                           modulation=modulation)


