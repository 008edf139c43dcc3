"""Every candidate screened against a base fit, the best fitted in full, each scored on held-out runs.

Steps 3 and 4 of docs/model/unmodelled-effects.md section 6 for the candidates: each variant of
each effect family is screened with its own parameters only (the base's
parameters and T2 stay at the base fit); the best effect, and runners-up
with evidence of their own, are fitted in full (all parameters), warm-started
from the screening fit (:func:`screen_and_promote`). Every fit is scored on
held-out runs against the base's held-out predictions. The base is the
nominal fit, or a forward-selection round's model with the effects named
so far (:mod:`.selection`). Fits that read nothing the others write run
two side by side (:mod:`.side_by_side`) and are scored in order. These
functions measure and return what they measured; which fits are made next,
and every decision on the scores, is the orchestrator's (:mod:`.pipeline`).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from .allowances.pitch_errors import modulation_gain, with_own_allowance
from .candidates import Candidate
from .case import RigCase
from .effects import candidates_for, hooks_of
from .fit_problem import robust_cost
from .fitting import FitResult, fit, fit_candidate
from .heldout import HeldOut, leave_one_out
from .scoring import CandidateScore, score_candidate
from .settings import DEFAULT_SETTINGS, DiagnosisSettings
from .side_by_side import Outcome, side_by_side
from .state import DiagnosisState


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
    refit = refit.after(nominal)
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


def with_modulation_gain(case: RigCase, full: CandidateScore) -> CandidateScore:
    """A run-out's full fit with its ``modulation_gain`` where pitch errors apply; any other entry as it is.

    A run-out is an effect whose family has a
    :attr:`~.effects.EffectFamily.run_out` hook (eccentricity in the library).
    Only where pitch errors apply does the run-out check
    (:func:`~.verdict.named.run_out_check`) need it; elsewhere it stays None at no cost.
    """
    family = hooks_of(full.effect)
    if family.run_out is None or not case.run_out_allowance:
        return full
    return replace(full, modulation_gain=modulation_gain(full.fit, family.parameter_name(family.run_out.modulation)))


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
            entry = score_candidate(
                result, held, base_held, "screening", state.rng, n_resamples=settings.verdict.bootstrap_resamples
            )
            screened.append(replace(entry, effect_gain=base.cost - result.cost) if on_top else entry)
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
    state: DiagnosisState,
    entry: CandidateScore,
    outcome: Outcome[tuple[FitResult, HeldOut]],
    base: CandidateScore | None = None,
) -> CandidateScore:
    """A screened candidate's full fit scored against its base's held-out predictions (its step in the log).

    The base is the nominal model, or ``base``, a forward-selection round's
    model with the effects named so far: its step names that base, and the
    full fit's ``effect_gain`` is what switching the new effect off costs
    (:func:`effect_off_costs`, under the fit's own error model). A fit made
    beside another (:func:`fits_in_full`) states its own seconds.
    """
    candidate = entry.fit.problem.candidate
    assert candidate is not None  # internal invariant: a screened entry has its candidate
    step = f"fit {candidate.label} in full"
    if base is not None:
        step = f"forward selection: {step} on top of {' + '.join(c.label for c in base.fit.problem.candidates)}"
    with state.steps.step(step) as finding:
        result, held = outcome.get()
        base_held = state.nominal_held if base is None else base.held
        full = score_candidate(
            result, held, base_held, "full", state.rng, n_resamples=state.settings.verdict.bootstrap_resamples
        )
        if base is not None:
            full = replace(full, effect_gain=effect_off_costs(base.fit, [result], own_error=True)[1][0] - result.cost)
        full = with_modulation_gain(state.case, full)
        finding.update(found(full), **({} if base is not None else {"fit_seconds": round(outcome.seconds, 3)}))
    return full


def fits_in_full(state: DiagnosisState, entries: Sequence[CandidateScore]) -> list[CandidateScore]:
    """Screened candidates fitted in full side by side (:func:`~.side_by_side.side_by_side`) and scored in order."""
    return [scored_in_full(state, entry, outcome) for entry, outcome in zip(entries, fits_ahead(state, entries))]


def fits_ahead(
    state: DiagnosisState, entries: Sequence[CandidateScore], base: FitResult | None = None
) -> list[Outcome[tuple[FitResult, HeldOut]]]:
    """Full fits of screened candidates, side by side, not yet scored (:func:`full_fit`).

    On top of the nominal fit, with the full fits against an earlier nominal
    fit as starts too, or on top of ``base``, a forward-selection round's
    model. Scoring draws from the random stream: the caller scores each in
    order (:func:`scored_in_full`), or discards one no longer needed unread,
    so that the numbers are those of one fit after the other.
    """
    on = (state.nominal, state.earlier_full_fits) if base is None else (base, None)
    return side_by_side(state.case, [partial(full_fit, state, entry, *on) for entry in entries])


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


def effect_gains(state: DiagnosisState, all_scores: Sequence[CandidateScore]) -> dict[int, float]:
    """What switching each fit's effect off costs, by ``id`` of its entry (:func:`effect_off_costs`).

    A full fit's is taken under its own error model; a screening's, which
    shares the nominal parameters, is the nominal fit's cost minus its own.
    """
    full_fits = [entry for entry in all_scores if entry.stage == "full"]
    costs = effect_off_costs(state.nominal, [entry.fit for entry in full_fits], own_error=True)[1]
    gains = {id(entry): cost - entry.fit.cost for entry, cost in zip(full_fits, costs)}
    gains.update((id(entry), state.nominal.cost - entry.fit.cost) for entry in all_scores if entry.stage == "screening")
    return gains


def with_effect_gains(state: DiagnosisState, scored: ScoredCandidates) -> ScoredCandidates:
    """These scores with every entry's ``effect_gain`` (:func:`effect_gains`), a step of the log."""
    with state.steps.step("switch the effects of the full fits off"):
        gains = effect_gains(state, scored.all_scores)
    return scored.with_gains(gains)


@dataclass(frozen=True)
class ScoredCandidates:
    """The candidates scored against one nominal fit: the best per effect, every score, and what comes next.

    Attributes
    ----------
    best : dict
        The best entry per effect so far (:func:`supersedes`).
    all_scores : list of CandidateScore
        Every screening and full fit, in the order made.
    extra : tuple of CandidateScore
        The screened variants not fitted in full, best screened first, at
        most ``extra_full_fits``: the extra full fits made, in order, while
        the gap stays unexplained.
    better : FitResult or None
        A better nominal fit the full fits found (None: none).
    waiting : tuple of CandidateScore
        The extra full fits that wait on the set the gap's strongest
        candidate leads (empty: none wait).
    """

    best: dict[str, CandidateScore]
    all_scores: list[CandidateScore]
    extra: tuple[CandidateScore, ...] = ()
    better: FitResult | None = None
    waiting: tuple[CandidateScore, ...] = ()

    @property
    def full_fits(self) -> list[FitResult]:
        """The fits of every full fit so far, in order."""
        return [entry.fit for entry in self.all_scores if entry.stage == "full"]

    def with_gains(self, gains: Mapping[int, float]) -> ScoredCandidates:
        """These scores with each entry's ``effect_gain`` from ``gains``, by ``id`` of the entry (:func:`effect_gains`).

        Every entry of ``all_scores`` is replaced by its copy with its gain, in
        ``best``, ``extra`` and ``waiting`` too: each holder reads the same copy.
        """
        copies = {id(entry): replace(entry, effect_gain=gains[id(entry)]) for entry in self.all_scores}

        def same(entry: CandidateScore) -> CandidateScore:
            return copies.get(id(entry), entry)

        return replace(
            self,
            best={effect: same(entry) for effect, entry in self.best.items()},
            all_scores=[same(entry) for entry in self.all_scores],
            extra=tuple(same(entry) for entry in self.extra),
            waiting=tuple(same(entry) for entry in self.waiting),
        )

    def taken_up(self, entry: CandidateScore, full: CandidateScore) -> ScoredCandidates:
        """These scores with ``full``, the full fit of the screened ``entry`` (it may become its effect's best)."""
        best = dict(self.best)
        if supersedes(full, best[entry.effect]):
            best[entry.effect] = full
        return replace(self, best=best, all_scores=[*self.all_scores, full])


def screen_and_promote(state: DiagnosisState) -> ScoredCandidates:
    """Every candidate screened against the nominal fit, the best fitted in full; the extra full fits' candidates.

    The runners-up with evidence of their own are fitted in full beside the
    best (:func:`_also_promoted`). An effect that changes the response only
    in a few runs (a bearing clearance where a bearing unloads) cannot be
    screened with the nominal parameters held where the nominal model put
    them to absorb that change: the next screened variants, best first, are
    the ``extra`` full fits made while the gap stays unexplained.
    """
    settings = state.settings
    clock = time.perf_counter()
    screened = screen(state, state.nominal, state.nominal_held, state.effects)
    state.timings["screening"] += time.perf_counter() - clock
    clock = time.perf_counter()
    best = best_per_effect(screened)
    order = sorted(best.values(), key=lambda entry: -entry.score)
    promoted = _also_promoted(state, order[0]) if order else (lambda entry: False)
    chosen = [entry for rank, entry in enumerate(order[: settings.screening.promoted]) if rank == 0 or promoted(entry)]
    scored = ScoredCandidates(best, list(screened))
    for entry, full in zip(chosen, fits_in_full(state, chosen)):
        scored = scored.taken_up(entry, full)
    state.timings["full_fits"] += time.perf_counter() - clock
    extra = sorted(
        (entry for entry in screened if not any(entry is done for done in chosen)), key=lambda entry: -entry.score
    )[: settings.screening.extra_full_fits]
    return replace(scored, extra=tuple(extra))


__all__ = [
    "effect_off_costs",
    "improved_nominal",
    "found",
    "supersedes",
    "with_modulation_gain",
    "best_per_effect",
    "screening_fits",
    "screen",
    "full_fit",
    "scored_in_full",
    "fits_in_full",
    "fits_ahead",
    "effect_gains",
    "with_effect_gains",
    "ScoredCandidates",
    "screen_and_promote",
]
