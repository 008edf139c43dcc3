"""Every candidate screened against the nominal fit, the best fitted in full, each scored on held-out runs.

Steps 3 and 4 of docs/model/unmodelled-effects.md section 6 for the candidates: each variant of
each effect family is screened with its own parameters only (the nominal
parameters and T2 stay at the nominal fit); the best effect, and runners-up
with evidence of their own, are fitted in full (all parameters), warm-started
from the screening fit; while the gap stays unexplained a few more variants
get a full fit. Every fit is scored on held-out runs against the nominal
model's held-out predictions. Fits that read nothing the others write run
two side by side (:mod:`.side_by_side`) and are scored in order. The
screening and the full fit take their base: forward selection
(:mod:`.selection`) runs them on top of the model with the effects named
so far.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import numpy as np

from .allowances.pitch_errors import modulation_gain, with_own_allowance
from .candidates import Candidate
from .case import RigCase
from .effects import candidates_for, hooks_of
from .first_effect import set_comes_first
from .fit_problem import robust_cost
from .fitting import FitResult, fit, fit_candidate
from .heldout import HeldOut, leave_one_out
from .scoring import CandidateScore, score_candidate
from .settings import DEFAULT_SETTINGS, DiagnosisSettings
from .side_by_side import Outcome, side_by_side
from .state import DiagnosisState
from .verdict.named import decide, ranked


def effect_off_costs(
    nominal: FitResult, fits: Sequence[FitResult], *, own_error: bool = False
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
    starts = [
        problem.vector(
            {key: value for key, value in candidate.values.items() if key in names},
            candidate.positions,
        )
        for candidate in fits
    ]
    if not starts:
        return [], []
    model, _ = problem.model_features(starts)
    errors = [fit_result.problem.model_error if own_error else None for fit_result in fits]
    return starts, [
        robust_cost(problem.residual_vector(problem.discrepancy(model[index], errors[index])[0], v))
        for index, v in enumerate(starts)
    ]


def improved_nominal(
    nominal: FitResult, fits: Sequence[FitResult], *, settings: DiagnosisSettings = DEFAULT_SETTINGS
) -> FitResult | None:
    """A better nominal fit found through the candidates' full fits, or None.

    Every candidate contains the nominal model (its effect at strength 0).
    A full candidate fit refits the nominal parameters and T2 too; if the
    nominal model alone, at those values, fits the data better than the
    nominal fit did (by ``nominal_margin``), the nominal fit had stopped in a
    local optimum (light loads, with contact loss near the bearing modes,
    have several), and a candidate would otherwise be credited with what is
    only the better optimum. The nominal model is then refitted from the
    best such point.
    """
    margin = settings.nominal.nominal_margin
    starts, costs = effect_off_costs(nominal, fits)
    if not starts:
        return None
    best = int(np.argmin(costs))
    if costs[best] >= nominal.cost - margin:
        return None
    refit = fit(nominal.problem, [starts[best]], max_evaluations=settings.nominal.nominal_evaluations, tolerance=1e-3)
    refit.after(nominal)
    return refit if refit.cost < nominal.cost - margin else None


def found(entry: CandidateScore) -> dict[str, Any]:
    """What a candidate's fit found, for the step log."""
    return {
        "score": entry.score,
        "shrink_fraction": entry.shrink_fraction,
        "gap_with_effect": entry.gap_with_effect,
        "parameters": entry.parameters(),
    }


def supersedes(full: CandidateScore, best: CandidateScore) -> bool:
    """Whether a full fit takes the place of its effect's best entry so far.

    When it scores higher; and always over the screening of its own
    variant when it was scored with its own pitch-error allowance (the
    screening was scored with the nominal model's: the two are not on one
    footing).
    """
    own = full.fit.problem.own_model_error is not None
    return full.score > best.score or (own and best.stage == "screening" and best.label == full.label)


def measure_modulation(case: RigCase, full: CandidateScore) -> None:
    """Set a run-out's full fit's ``modulation_gain`` where pitch errors apply.

    A run-out is an effect whose family has a
    :attr:`~.effects.EffectFamily.run_out` hook (eccentricity in the library).
    Only where pitch errors apply does the run-out check
    (:func:`~.verdict.named.run_out_check`) need it; elsewhere it stays None at no cost.
    """
    family = hooks_of(full.effect)
    if family.run_out is not None and case.run_out_allowance:
        full.modulation_gain = modulation_gain(full.fit, family.parameter_name(family.run_out.modulation))


def best_per_effect(entries: Sequence[CandidateScore]) -> dict[str, CandidateScore]:
    """The highest-scoring entry of each effect (the first of equals), in order of first appearance."""
    best: dict[str, CandidateScore] = {}
    for entry in entries:
        if entry.effect not in best or entry.score > best[entry.effect].score:
            best[entry.effect] = entry
    return best


def screening_fits(
    state: DiagnosisState, base: FitResult, candidates: Sequence[Candidate]
) -> list[Outcome[tuple[FitResult, HeldOut]]]:
    """Each candidate fitted on top of ``base`` with its own parameters only, and its held-out predictions.

    The fits read the base and write nothing the others read: they run side
    by side (:func:`~.side_by_side.side_by_side`), the results in order.
    """
    case, budget = state.case, state.settings.screening.screening_evaluations

    def job(candidate: Candidate) -> Callable[[], tuple[FitResult, HeldOut]]:
        def work() -> tuple[FitResult, HeldOut]:
            result = fit_candidate(case, candidate, base, full=False, max_evaluations=budget)
            return result, leave_one_out(result)

        return work

    return side_by_side(case, [job(candidate) for candidate in candidates])


def screen(
    state: DiagnosisState, base: FitResult, base_held: HeldOut, effects: Sequence[str], *, on_top: bool = False
) -> list[CandidateScore]:
    """Every variant of ``effects`` fitted on top of a base fit (its own parameters only), scored against the base.

    The base is the nominal fit (step 3) or, ``on_top``, a forward-selection
    round's model with the effects named so far (step 6): each step then
    names the base, and each screening's ``effect_gain`` is the cost it
    gains over the base (the nominal fit's screenings have theirs measured
    with the effect switched off, :func:`effect_off_costs`). Each is scored
    against the base's held-out predictions ``base_held``.
    """
    settings = state.settings
    candidates = [
        candidate for name in effects for candidate in candidates_for(name, state.case.design, hints=state.hints)
    ]
    labels = " + ".join(candidate.label for candidate in base.problem.candidates) if on_top else ""
    screened: list[CandidateScore] = []
    for candidate, outcome in zip(candidates, screening_fits(state, base, candidates)):
        step = f"forward selection: screen {candidate.label} on top of {labels}" if on_top else ""
        with state.steps.step(step or f"screen {candidate.label}") as finding:
            result, held = outcome.get()
            screened.append(
                score_candidate(
                    result, held, base_held, "screening", state.rng, n_resamples=settings.verdict.bootstrap_resamples
                )
            )
            if on_top:
                screened[-1].effect_gain = base.cost - result.cost
            finding.update(found(screened[-1]), fit_seconds=round(outcome.seconds, 3))
    return screened


def full_fit(
    state: DiagnosisState,
    entry: CandidateScore,
    base: FitResult,
    earlier: Mapping[str, FitResult] | None = None,
) -> tuple[FitResult, HeldOut]:
    """A screened candidate fitted on top of a base fit with all parameters free, its own pitch-error allowance.

    The base is the nominal fit or a forward-selection round's model;
    ``earlier`` holds full fits of the candidates from a pass before, by
    label, tried as starts too. Returns the fit and its held-out runs.
    Reads the state and the entry, writes nothing the other fits read
    (:func:`fits_in_full` runs several side by side).
    """
    settings = state.settings
    candidate = entry.fit.problem.candidate
    assert candidate is not None  # internal invariant: a screened entry has its candidate
    result = with_own_allowance(
        fit_candidate(
            state.case,
            candidate,
            base,
            full=True,
            max_evaluations=settings.screening.full_fit_evaluations,
            start=entry.fit,
            earlier=earlier.get(candidate.label) if earlier is not None else None,
        ),
        max_evaluations=settings.screening.full_fit_evaluations,
    )
    return result, leave_one_out(result)


def scored_in_full(
    state: DiagnosisState, entry: CandidateScore, outcome: Outcome[tuple[FitResult, HeldOut]]
) -> CandidateScore:
    """The full fit of a screened candidate scored against the nominal model (its step in the log)."""
    candidate = entry.fit.problem.candidate
    assert candidate is not None  # internal invariant: a screened entry has its candidate
    with state.steps.step(f"fit {candidate.label} in full") as finding:
        result, held = outcome.get()
        full = score_candidate(
            result, held, state.nominal_held, "full", state.rng, n_resamples=state.settings.verdict.bootstrap_resamples
        )
        measure_modulation(state.case, full)
        finding.update(found(full), fit_seconds=round(outcome.seconds, 3))
    return full


def fits_in_full(state: DiagnosisState, entries: Sequence[CandidateScore]) -> list[CandidateScore]:
    """Screened candidates fitted in full side by side (:func:`~.side_by_side.side_by_side`) and scored in order."""
    outcomes = side_by_side(
        state.case,
        [partial(full_fit, state, entry, state.nominal, state.earlier_full_fits) for entry in entries],
    )
    return [scored_in_full(state, entry, outcome) for entry, outcome in zip(entries, outcomes)]


def _also_promoted(state: DiagnosisState, leader: CandidateScore) -> Callable[[CandidateScore], bool]:
    """Which runners-up are fitted in full too.

    Unless the screening already puts them far behind the leader. With a
    pitch-error allowance the screening judged every candidate by the
    nominal model's allowance, which an effect that acts together with the
    pitch errors (friction) outgrows, so any runner-up with evidence of its
    own is fitted (with its own allowance).
    """
    settings = state.settings
    if state.rules.pitch_allowance:
        return lambda entry: entry.score >= settings.verdict.score_threshold
    return lambda entry: entry.score > 0 and entry.score >= settings.screening.runner_up_share * leader.score


def extra_full_fits(
    state: DiagnosisState,
    entries: Sequence[CandidateScore],
    best: dict[str, CandidateScore],
    taken_up: Callable[[CandidateScore, CandidateScore], None],
) -> None:
    """Further screened variants fitted in full, in order, while the gap stays unexplained.

    Each fit is computed beside the next one (:func:`~.side_by_side.side_by_side`): while the gap
    stays unexplained the next fit is made anyway, and one that is not needed is discarded
    unread, so the numbers are those of one fit after the other.
    ``taken_up`` records each scored fit (it updates ``best``).
    """
    ahead: dict[int, Outcome[tuple[FitResult, HeldOut]]] = {}
    for index, entry in enumerate(entries):
        if not _unexplained(state, best):
            break
        if index not in ahead:
            pair = entries[index : index + 2]
            jobs = [partial(full_fit, state, item, state.nominal, state.earlier_full_fits) for item in pair]
            outcomes = side_by_side(state.case, jobs)
            ahead.update({index + offset: outcome for offset, outcome in enumerate(outcomes)})
        taken_up(entry, scored_in_full(state, entry, ahead.pop(index)))


def _effect_gains(state: DiagnosisState, all_scores: Sequence[CandidateScore]) -> dict[int, float]:
    """What switching each fit's effect off costs, by ``id`` of its entry (:func:`effect_off_costs`).

    A full fit's is taken under its own error model; a screening's, which
    shares the nominal parameters, is the nominal fit's cost minus its own.
    """
    full_fits = [entry for entry in all_scores if entry.stage == "full"]
    costs = effect_off_costs(state.nominal, [entry.fit for entry in full_fits], own_error=True)[1]
    gains = {id(entry): cost - entry.fit.cost for entry, cost in zip(full_fits, costs)}
    gains.update((id(entry), state.nominal.cost - entry.fit.cost) for entry in all_scores if entry.stage == "screening")
    return gains


def _set_effect_gains(state: DiagnosisState, all_scores: Sequence[CandidateScore]) -> None:
    """Each entry's ``effect_gain`` (:func:`_effect_gains`), a step of the log."""
    with state.steps.step("switch the effects of the full fits off"):
        gains = _effect_gains(state, all_scores)
    for entry in all_scores:
        entry.effect_gain = gains[id(entry)]


def _unexplained(state: DiagnosisState, best: dict[str, CandidateScore]) -> bool:
    """Whether the best fits so far leave the gap open (:func:`~.verdict.named.decide` on them as they are).

    Open is ``unexplained``, or an effect not told apart from one channel's
    artefact: another candidate may yet explain it on every channel. It is
    asked of the case's rules without the density route
    (:meth:`~.verdict.rules.VerdictRules.shrink_only`): an open gap is one
    above noise that no candidate shrinks enough.
    """
    return decide(state.nominal_gap, ranked(best, state.rules), state.rules.shrink_only()).open_gap


@dataclass
class ScoredCandidates:
    """The candidates scored against one nominal fit: the best per effect, every score, and what comes next.

    ``better`` is a better nominal fit their full fits found (None: none);
    ``waiting`` the variants whose extra full fits wait on the set the gap's
    strongest candidate leads (:func:`score_candidates`), fitted by
    :func:`fit_waiting` only where that set explains nothing together.
    """

    best: dict[str, CandidateScore]
    all_scores: list[CandidateScore]
    better: FitResult | None = None
    waiting: list[CandidateScore] = field(default_factory=list)


def _extra_fits_and_gains(
    state: DiagnosisState,
    scored: ScoredCandidates,
    extra: Sequence[CandidateScore],
    full_before: int,
    escape: Callable[[Sequence[FitResult]], FitResult | None] | None,
) -> ScoredCandidates:
    """The extra full fits of ``extra`` while the gap stays unexplained, every fit's effect gain, the nominal check.

    ``full_before``: how many full fits the nominal fit was checked against
    already; ``escape`` checks it again where the extra fits added any.
    """
    clock = time.perf_counter()
    best, all_scores = scored.best, scored.all_scores

    def taken_up(entry: CandidateScore, full: CandidateScore) -> None:
        all_scores.append(full)
        if supersedes(full, best[entry.effect]):
            best[entry.effect] = full

    extra_full_fits(state, extra, best, taken_up)
    full_fits = [entry for entry in all_scores if entry.stage == "full"]
    _set_effect_gains(state, all_scores)
    state.timings["full_fits"] += time.perf_counter() - clock
    if escape is None or len(full_fits) == full_before:
        # no full fit since the check before: it would find the same
        return ScoredCandidates(best, all_scores)
    return ScoredCandidates(best, all_scores, escape([entry.fit for entry in full_fits]))


def score_candidates(
    state: DiagnosisState,
    *,
    escape: Callable[[Sequence[FitResult]], FitResult | None] | None = None,
    set_first: bool = True,
) -> ScoredCandidates:
    """Screen every candidate against the nominal fit, fit the best in full; best per effect, all, a better nominal.

    ``escape`` checks the nominal fit against full fits (:func:`improved_nominal`: a better nominal
    fit or None). It is asked once the promoted candidates are fitted in full and, where it finds
    nothing, again after the extra full fits. Where it finds a better nominal fit, this pass ends
    there: every candidate is then scored again against that fit, and a further full fit against
    the nominal fit it replaces would only have been a start.

    The extra full fits are there so that a gap is not called unexplained while a variant the
    screening cannot judge could explain it. Where the gap is unexplained and its strongest
    candidate leads a set (``set_first``; :func:`~.first_effect.set_comes_first`), that set is tried
    first (step 6): the extra fits wait (``waiting``), and are made (:func:`fit_waiting`) only
    where the set explains nothing together, since a named set leaves no gap unexplained.
    """
    settings = state.settings
    clock = time.perf_counter()
    screened = screen(state, state.nominal, state.nominal_held, state.effects)
    state.timings["screening"] += time.perf_counter() - clock
    clock = time.perf_counter()
    best = best_per_effect(screened)
    order = sorted(best.values(), key=lambda entry: -entry.score)
    all_scores = list(screened)
    promoted = _also_promoted(state, order[0]) if order else (lambda entry: False)
    chosen = [entry for rank, entry in enumerate(order[: settings.screening.promoted]) if rank == 0 or promoted(entry)]
    for entry, full in zip(chosen, fits_in_full(state, chosen)):
        all_scores.append(full)
        if supersedes(full, best[entry.effect]):
            best[entry.effect] = full
    state.timings["full_fits"] += time.perf_counter() - clock
    better = escape([entry.fit for entry in all_scores if entry.stage == "full"]) if escape is not None else None
    if better is not None:
        return ScoredCandidates(best, all_scores, better)
    # An effect that changes the response only in a few runs (a bearing clearance where a bearing
    # unloads) cannot be screened with the nominal parameters held where the nominal model put
    # them to absorb that change: before a gap is called unexplained the next candidate variants
    # get a full fit, best screened first, until one explains it.
    remaining = sorted(
        (entry for entry in screened if not any(entry is done for done in chosen)), key=lambda entry: -entry.score
    )[: settings.screening.extra_full_fits]
    if remaining and set_first and _unexplained(state, best):
        clock = time.perf_counter()
        with state.steps.step("decide whether the extra full fits wait for a set") as found:
            gains = _effect_gains(state, all_scores)
            # judged on copies with their gains, on a copy of the random stream: nothing is changed here
            waits = set_comes_first(
                state, {name: replace(entry, effect_gain=gains[id(entry)]) for name, entry in best.items()}
            )
            found.update(extra_fits_wait_for_a_set=waits)
        state.timings["full_fits"] += time.perf_counter() - clock
        if waits:
            for entry in all_scores:
                entry.effect_gain = gains[id(entry)]
            return ScoredCandidates(best, all_scores, waiting=remaining)
    return _extra_fits_and_gains(state, ScoredCandidates(best, all_scores), remaining, len(chosen), escape)


def fit_waiting(
    state: DiagnosisState,
    scored: ScoredCandidates,
    *,
    escape: Callable[[Sequence[FitResult]], FitResult | None] | None = None,
) -> ScoredCandidates:
    """The extra full fits that waited on a set (:func:`score_candidates`), while the gap stays unexplained.

    Then every fit's effect gain, and ``escape``'s check of the nominal fit against the full fits.
    """
    full_before = sum(entry.stage == "full" for entry in scored.all_scores)
    return _extra_fits_and_gains(state, scored, scored.waiting, full_before, escape)


__all__ = [
    "effect_off_costs",
    "improved_nominal",
    "supersedes",
    "measure_modulation",
    "best_per_effect",
    "screening_fits",
    "screen",
    "full_fit",
    "scored_in_full",
    "fits_in_full",
    "extra_full_fits",
    "ScoredCandidates",
    "score_candidates",
    "fit_waiting",
]
