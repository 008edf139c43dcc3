"""Steps 3 to 6 of a diagnosis in their order: every loop over the fits and every call to the verdict's rules.

The order is that of docs/model/unmodelled-effects.md section 6 (:func:`diagnose_case`):

1. the nominal fit, the pitch-error allowance with its refit, the frequency-locked lines and the
   signature hints, the nominal model's held-out predictions (:mod:`.nominal`);
2. a pass against the nominal fit (:func:`candidate_pass`): every candidate screened and the
   promoted ones fitted in full (:func:`~.screening.screen_and_promote`), the nominal fit checked
   against those full fits (:func:`~.nominal.check_nominal`); where the gap is open and its
   strongest candidate leads a set (:func:`set_comes_first`, on a copy of the random stream), the
   extra full fits wait; otherwise they are made while the gap stays open (:func:`extra_full_fits`);
3. while a pass finds a better nominal fit, another pass from it (:func:`nominal_passes`);
4. step 5, the first effect's decision (:func:`decide_first`);
5. step 6, the set of effects (:func:`effect_set`), forward selection round by round
   (:func:`forward_selection`, :func:`next_effect`);
6. where the extra full fits waited on a set that explains nothing together: those fits, the
   passes they call for, then steps 5 and 6 again (:func:`verdict_and_set`);
7. an eccentric shaft its sideband phases name (:func:`with_phase_named_shaft`).

Each step called here (:mod:`.nominal`, :mod:`.screening`, :mod:`.selection`) measures and returns
what it measured; which step comes next, and every decision on a gap (:mod:`.verdict`), is made
here. The steps draw from one random stream in turn (:class:`~.state.DiagnosisState`), so this
order fixes the numbers.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import xarray as xr

from ..common.steps import StepLog
from .allowances.pitch_errors import PitchErrorAllowance
from .case import RigCase
from .decision import Decision
from .effect_set import SelectedEffect, SelectionRound
from .effects import run_out_family
from .first_effect import FirstDecision, nominal_gap_maps
from .fitting import FitResult
from .gap_maps import family_character, where_gap
from .heldout import HeldOut
from .nominal import allow_pitch_errors, check_nominal, fit_nominal_model, nominal_held_out
from .result import DiagnosisResult
from .scoring import CandidateScore, bootstrap_gap
from .screening import ScoredCandidates, effect_gains, fits_ahead, scored_in_full, screen_and_promote, with_effect_gains
from .selection import NamedSet, open_choices, phase_named_run_out, round_fits, selected_effects
from .settings import DiagnosisSettings
from .side_by_side import Outcome
from .signatures import every_channel_locked_lines, frequency_locked_lines, signature_hints
from .state import DiagnosisState
from .verdict.cross_channel import with_character
from .verdict.named import decide, leads_a_set, ranked
from .verdict.rules import verdict_rules
from .verdict.sets import lead_decision, phase_named_decision, set_decision, unled_decision


def open_gap(state: DiagnosisState, best: Mapping[str, CandidateScore]) -> bool:
    """Whether the best fits so far leave the gap open (:func:`~.verdict.named.decide` on them as they are).

    Open is ``unexplained``, or an effect not told apart from one channel's
    artefact: another candidate may yet explain it on every channel. It is
    asked of the case's rules without the density route
    (:meth:`~.verdict.rules.VerdictRules.shrink_only`): an open gap is one
    above noise that no candidate shrinks enough.
    """
    return decide(state.nominal_gap, ranked(best, state.rules), state.rules.shrink_only()).open_gap


def first_decision(
    state: DiagnosisState, best: Mapping[str, CandidateScore], rng: np.random.Generator
) -> tuple[Decision, list[CandidateScore], list[CandidateScore], tuple[float, float]]:
    """Step 5's decision on the best score per effect, its bootstrap intervals drawn from ``rng``.

    Returns the decision, the scores best first, the ranking (with the run-out checks, the
    leader with the bootstrap interval of its gap) and the nominal gap's bootstrap interval.
    """
    settings = state.settings
    scores = sorted(best.values(), key=lambda entry: -entry.score)
    ranking = ranked(best, state.rules)
    # drawn after the shrink bootstraps, so their numbers do not depend on this
    nominal_interval = bootstrap_gap(state.nominal_held.z, rng, settings.verdict.bootstrap_resamples)
    if scores:
        leader_interval = bootstrap_gap(scores[0].held.z, rng, settings.verdict.bootstrap_resamples)
        ranking[0] = replace(ranking[0], gap_interval=leader_interval)
    decision = decide(state.nominal_gap, ranking, state.rules, nominal_gap_interval=nominal_interval)
    return decision, scores, ranking, nominal_interval


def starts_a_set(state: DiagnosisState, decision: Decision, ranking: Sequence[CandidateScore]) -> bool:
    """Whether step 6 starts a set from the gap's strongest candidate (section 6.2).

    It does where a gap above noise is left unnamed (``unexplained``, an
    effect not told apart from a sensor's artefact, or ``none`` where the
    gap's interval reaches into noise) and the best candidate meets the
    evidence rules of :func:`~.verdict.named.leads_a_set`.
    """
    unnamed_gap = decision.open_gap or (
        decision.verdict == "none" and state.nominal_gap > state.settings.verdict.noise_gap
    )
    return unnamed_gap and bool(ranking) and leads_a_set(ranking[0], state.rules)


def set_comes_first(state: DiagnosisState, best: Mapping[str, CandidateScore]) -> bool:
    """Whether, on these scores, step 6 would start a set from the gap's strongest candidate.

    The decision is made as :func:`decide_first` makes it, on a copy of the
    random stream: the state's stream is left where it was.
    """
    # Step 5 draws its bootstrap intervals from the diagnosis's stream. Asked here, before the extra
    # full fits, the same decision is made on a copy of that stream: drawing from the stream itself
    # would shift every number drawn after it, and left where it was, the stream gives step 5 the very
    # intervals (and so the decision) this check saw.
    decision, _, ranking, _ = first_decision(state, best, copy.deepcopy(state.rng))
    return starts_a_set(state, decision, ranking)


def _extra_fits_wait(state: DiagnosisState, scored: ScoredCandidates) -> ScoredCandidates | None:
    """The scores with every fit's effect gain where a pass's extra full fits wait on a set, else None.

    Whether they wait (:func:`set_comes_first`, a step of the log) is judged
    on copies of the best fits with their effect gains.
    """
    clock = time.perf_counter()
    with state.steps.step("decide whether the extra full fits wait for a set") as found:
        gains = effect_gains(state, scored.all_scores)
        waits = set_comes_first(
            state, {name: replace(entry, effect_gain=gains[id(entry)]) for name, entry in scored.best.items()}
        )
        found.update(extra_fits_wait_for_a_set=waits)
    state.timings["full_fits"] += time.perf_counter() - clock
    return scored.with_gains(gains) if waits else None


def extra_full_fits(
    state: DiagnosisState, scored: ScoredCandidates, extra: Sequence[CandidateScore], *, check: bool
) -> ScoredCandidates:
    """Further screened variants fitted in full, in order, while the gap stays open; then every fit's effect gain.

    Each fit is computed beside the next one (:func:`~.screening.fits_ahead`): while the gap stays
    open the next fit is made anyway, and one that is not needed is discarded unread, so the
    numbers are those of one fit after the other. ``check``: the nominal fit is checked against
    the full fits again where these added any (:func:`~.nominal.check_nominal`).
    """
    clock = time.perf_counter()
    full_before = len(scored.full_fits)
    ahead: dict[int, Outcome[tuple[FitResult, HeldOut]]] = {}
    for index, entry in enumerate(extra):
        if not open_gap(state, scored.best):
            break
        if index not in ahead:
            ahead.update(enumerate(fits_ahead(state, extra[index : index + 2]), start=index))
        scored = scored.taken_up(entry, scored_in_full(state, entry, ahead.pop(index)))
    scored = with_effect_gains(state, scored)
    state.timings["full_fits"] += time.perf_counter() - clock
    scored = replace(scored, waiting=())
    if not check or len(scored.full_fits) == full_before:
        # no full fit since the check before: it would find the same
        return scored
    return replace(scored, better=check_nominal(state, scored.full_fits))


def candidate_pass(state: DiagnosisState, attempt: int, *, set_first: bool) -> ScoredCandidates:
    """Every candidate scored against the pass's nominal fit; ``better``: a better nominal fit found.

    The nominal fit is checked as soon as the promoted candidates are fitted
    in full (not in the last pass allowed, ``nominal_refits``): once it is
    known to be stuck, the pass's further full fits against it are not made.
    The extra full fits are there so that a gap is not called unexplained
    while a variant the screening cannot judge could explain it. Where the
    gap is open and its strongest candidate leads a set (``set_first``;
    :func:`set_comes_first`), that set is tried first (step 6): the extra
    fits wait (``waiting``), since a named set leaves no gap unexplained.
    """
    check = attempt < state.settings.nominal.nominal_refits
    scored = screen_and_promote(state)
    if check:
        better = check_nominal(state, scored.full_fits)
        if better is not None:
            return replace(scored, better=better)
    if scored.extra and set_first and open_gap(state, scored.best):
        waiting = _extra_fits_wait(state, scored)
        if waiting is not None:
            return replace(waiting, waiting=waiting.extra)
    return extra_full_fits(state, scored, scored.extra, check=check)


@dataclass(frozen=True)
class NominalPasses:
    """The candidates scored against the last nominal fit, with what a later pass needs.

    ``state`` is the state of the last pass (its nominal fit), ``scored``
    its scores (``waiting``: the extra full fits that wait on a set),
    ``attempt`` the pass's number and ``earlier`` the full fits against
    earlier nominal fits, by label.
    """

    state: DiagnosisState
    scored: ScoredCandidates
    attempt: int
    earlier: Mapping[str, FitResult]

    @property
    def best(self) -> dict[str, CandidateScore]:
        return self.scored.best


def nominal_passes(
    state: DiagnosisState, scored: ScoredCandidates, attempt: int, earlier: Mapping[str, FitResult], *, set_first: bool
) -> NominalPasses:
    """Further passes while a pass's full fits find a better nominal fit (``scored.better``).

    The candidates were scored against a nominal fit stuck in a local
    optimum: the nominal model's held-out predictions are made again from
    the better fit and every candidate is scored again against it, each full
    fit starting from where it got to as well (at most ``nominal_refits``
    passes after the first).
    """
    while scored.better is not None:
        earlier = {**earlier, **{entry.label: entry.fit for entry in scored.all_scores if entry.stage == "full"}}
        attempt += 1
        held, gap = nominal_held_out(scored.better, state.steps, state.timings)
        state = replace(state.with_nominal(scored.better, held, gap), earlier_full_fits=dict(earlier))
        scored = candidate_pass(state, attempt, set_first=set_first)
    return NominalPasses(state, scored, attempt, earlier)


def decide_first(
    state: DiagnosisState, best: Mapping[str, CandidateScore], locked_lines: Sequence[Mapping[str, Any]]
) -> FirstDecision:
    """The verdict on the candidates' held-out scores against the nominal model (step 5), and where the gap lies."""
    with state.steps.step("decide the verdict") as found:
        decision, scores, ranking, nominal_interval = first_decision(state, best, state.rng)
        where, families = nominal_gap_maps(state, locked_lines)
        if decision.one_channel:
            decision = with_character(decision, families)
        found.update(verdict=decision.verdict, reason=decision.reason)
    return FirstDecision(decision, scores, ranking, nominal_interval, where, families)


def next_effect(
    state: DiagnosisState, base: CandidateScore, named: Sequence[str], tried: SelectionRound | None = None
) -> SelectionRound:
    """One forward-selection round (:func:`~.selection.round_fits`), and whether it adds its best effect.

    :func:`~.verdict.named.decide` on top of the base, with the leader's
    run-out check and the bootstrap interval of its gap, adds it or not.
    """
    fits = round_fits(state, base, named, tried)
    if fits.leader is None:
        return SelectionRound(fits.base, fits.gap_before, [], None, fits.void)
    chosen = ranked({fits.leader.effect: fits.leader}, state.rules)[0]
    resamples = state.settings.verdict.bootstrap_resamples
    chosen = replace(chosen, gap_interval=bootstrap_gap(chosen.held.z, state.rng, resamples))
    # no density evidence here: a further effect must shrink a gap that is there, or it only soaks up what
    # the allowance already forgives (docs/model/unmodelled-effects.md section 6.4)
    decision = decide(fits.gap_before, [chosen], state.rules.shrink_only())
    added = chosen.effect if decision.verdict == chosen.effect else None
    assert chosen.gap_interval is not None
    return SelectionRound(
        fits.base, fits.gap_before, fits.ranking, added, decision.reason + fits.note, decision, chosen.gap_interval
    )


def forward_selection(
    state: DiagnosisState,
    first: CandidateScore,
    first_decision: Decision,
    *,
    first_gap_interval: Sequence[float] = (math.nan, math.nan),
) -> tuple[list[SelectedEffect], list[SelectionRound]]:
    """Add effects one at a time after the first while a significant held-out gap remains.

    The first effect's fit (``first``) is the base; each round
    (:func:`next_effect`) screens the effects not yet named on top of it,
    fits the best in full with all effects present and adds it when
    :func:`~.verdict.named.decide`, applied to the gap that remains, names
    it; the model with it is the next base. Rounds stop when the remaining
    gap is within ``noise_gap`` (where the pitch-error allowance applies,
    only at a gap of 0: its widened error can hold a further effect's
    evidence below the noise gap, and the effect is added when it shrinks
    what is left), when a round adds nothing, or at ``max_effects``.

    Returns
    -------
    selected : list of SelectedEffect
        The named effects in order (the first one included), with their shrink shares.
    rounds : list of SelectionRound
        The rounds after the first, the last one possibly adding nothing.
    """
    settings = state.settings
    entries, decisions = [first], [first_decision]
    intervals: list[tuple[float, float]] = [(float(first_gap_interval[0]), float(first_gap_interval[1]))]
    rounds: list[SelectionRound] = []
    while len(entries) < settings.selection.max_effects and (
        entries[-1].gap_with_effect > settings.verdict.noise_gap
        or (state.rules.pitch_allowance and entries[-1].gap_with_effect > 0.0)
    ):
        selection = next_effect(state, entries[-1], [entry.effect for entry in entries], rounds[-1] if rounds else None)
        rounds.append(selection)
        if selection.added is None or selection.decision is None:
            break
        # the added effect's best fit leads its round's ranking (its full fit was started from the best screening)
        entries.append(selection.scores[0])
        decisions.append(selection.decision)
        intervals.append(selection.gap_interval)
    return selected_effects(state, entries, decisions, intervals), rounds


def _led_set(state: DiagnosisState, first: FirstDecision) -> NamedSet:
    """An unexplained gap whose strongest candidate leads a forward selection: the set, if it explains the gap.

    Two effects of about equal size each explain less than half of the gap
    alone: the strongest, clearly carried by its effect, is the base of a
    forward selection, and the set is named only if it explains the gap
    together (:func:`~.verdict.sets.set_decision`'s rule).
    """
    clock = time.perf_counter()
    lead = first.scores[0]
    provisional = lead_decision(lead)
    trial, trial_rounds = forward_selection(state, lead, provisional, first_gap_interval=first.leader_gap_interval)
    # added up: a set tried before the extra full fits may be tried again after them
    state.timings["forward_selection"] = state.timings.get("forward_selection", 0.0) + time.perf_counter() - clock
    with state.steps.step("decide whether a set of effects explains the gap") as finding:
        joint = (
            set_decision(provisional, trial, trial_rounds, state.nominal_gap, state.rules) if len(trial) > 1 else None
        )
        if joint is not None and not joint.partial:
            named = NamedSet(trial, trial_rounds, joint, led=True)
        else:
            named = NamedSet(decision=unled_decision(first.decision, lead, trial))
        verdict = named.decision.verdict if named.decision is not None else first.decision.verdict
        finding.update(effects=[chosen.entry.effect for chosen in named.selected], verdict=verdict)
    return named


def _grown_set(state: DiagnosisState, first: FirstDecision) -> NamedSet:
    """The first effect named: further effects while a significant gap remains (forward selection)."""
    clock = time.perf_counter()
    selected, rounds = forward_selection(
        state, first.scores[0], first.decision, first_gap_interval=first.leader_gap_interval
    )
    if rounds:
        # added up: a set tried before the extra full fits may be tried again after them
        state.timings["forward_selection"] = state.timings.get("forward_selection", 0.0) + time.perf_counter() - clock
    with state.steps.step("decide the effect set") as finding:
        decision = set_decision(first.decision, selected, rounds, state.nominal_gap, state.rules)
        finding.update(effects=[chosen.entry.effect for chosen in selected], partial=decision.partial)
    return NamedSet(selected, rounds, decision)


def effect_set(state: DiagnosisState, first: FirstDecision) -> NamedSet:
    """Step 6's set of effects named together, before the sideband phase test.

    A forward selection runs from the named first effect, or from an
    unexplained gap's strongest candidate where it meets the evidence rules
    (:func:`starts_a_set`).
    """
    decision = first.decision
    if first.scores and starts_a_set(state, decision, first.ranking):
        return _led_set(state, first)
    if decision.verdict in state.effects:
        return _grown_set(state, first)
    return NamedSet(decision=decision)


def with_phase_named_shaft(state: DiagnosisState, named: NamedSet, *, allowance_applied: bool) -> NamedSet:
    """The set with an eccentric shaft its sideband phases name (:func:`~.selection.phase_named_run_out`).

    The test applies where the pitch-error allowance was applied, a family
    that reads as a shaft run-out (:func:`~.effects.run_out_family`:
    eccentricity) is a candidate not in the set, the gap is not left open
    (``unexplained``, or an effect not told apart from a sensor's artefact)
    and the set has room for it. The run-out its phases name is added to the
    set by :func:`~.verdict.sets.phase_named_decision`.
    """
    decision = named.decision
    assert decision is not None  # internal invariant: step 6 always ends with a decision
    family = run_out_family(state.effects)
    if (
        not allowance_applied
        or family is None
        or decision.open_gap
        or len(named.selected) >= state.settings.selection.max_effects
        or family.name in [chosen.entry.effect for chosen in named.selected]
    ):
        return named
    clock = time.perf_counter()
    evidence, fitted = phase_named_run_out(state, family, named.selected)
    named = replace(named, modulation=evidence)
    if fitted is not None:
        gap = fitted.entry.gap_with_effect
        added, whole = phase_named_decision(
            decision, fitted.reason, gap, set_named=bool(named.selected), effect=family.name
        )
        interval = bootstrap_gap(fitted.entry.held.z, state.rng, state.settings.verdict.bootstrap_resamples)
        chosen = SelectedEffect(
            fitted.entry, fitted.gap_before, fitted.share, added, interval, open_choices(state, fitted.entry)
        )
        named = replace(named, selected=[*named.selected, chosen], decision=whole)
    state.timings["sideband_phases"] = time.perf_counter() - clock
    return named


def verdict_and_set(
    passes: NominalPasses, locked: list[dict[str, Any]], *, allowance_applied: bool
) -> tuple[NominalPasses, FirstDecision, NamedSet]:
    """Steps 5 and 6: the first effect's verdict, the set of effects, an eccentric shaft its phases name.

    Where the extra full fits waited on the set the gap's strongest
    candidate leads and that set explains nothing together, they are made
    (with the further passes a better nominal fit calls for, the set no
    longer tried first) and steps 5 and 6 decide again with them.
    """
    first = decide_first(passes.state, passes.best, locked)
    named = effect_set(passes.state, first)
    if passes.scored.waiting and not named.led:
        state = passes.state
        check = passes.attempt < state.settings.nominal.nominal_refits
        scored = extra_full_fits(state, passes.scored, passes.scored.waiting, check=check)
        passes = nominal_passes(state, scored, passes.attempt, passes.earlier, set_first=False)
        first = decide_first(passes.state, passes.best, locked)
        named = effect_set(passes.state, first)
    return passes, first, with_phase_named_shaft(passes.state, named, allowance_applied=allowance_applied)


def _outcome(
    state: DiagnosisState,
    first: FirstDecision,
    named: NamedSet,
    *,
    locked: list[dict[str, Any]],
    hints: dict[str, float],
    all_scores: list[CandidateScore],
    allowance: PitchErrorAllowance,
) -> DiagnosisResult:
    """Everything steps 3 to 6 found, with where the final model's held-out gap lies."""
    settings, case = state.settings, state.case
    assert named.decision is not None  # internal invariant: step 6 always ends with a decision
    selected = named.selected
    final_held = selected[-1].entry.held if selected else state.nominal_held
    if selected:
        remaining_where = where_gap(final_held.z, case, where_z=settings.verdict.where_z)
        remaining_families = family_character(
            final_held.z, case, locked, noise_gap=settings.verdict.noise_gap, where_z=settings.verdict.where_z
        )
    else:
        # with no effect named the final model is the nominal one: its maps are already made
        remaining_where, remaining_families = first.where, first.families
    return DiagnosisResult(
        case=case,
        nominal=state.nominal,
        nominal_held=state.nominal_held,
        scores=first.scores,
        all_scores=all_scores,
        decision=named.decision,
        nominal_gap=state.nominal_gap,
        where=first.where,
        families=first.families,
        locked_lines=locked,
        hints=hints,
        effects=state.effects,
        timings=state.timings,
        nominal_gap_interval=first.nominal_gap_interval,
        selected=selected,
        rounds=named.rounds,
        final_held=final_held,
        remaining_where=remaining_where,
        remaining_families=remaining_families,
        remaining_interval=selected[-1].gap_interval if selected else first.nominal_gap_interval,
        pitch_errors=allowance,
        modulation=named.modulation,
        settings=settings,
    )


def diagnose_case(
    case: RigCase,
    posterior: xr.Dataset | None,
    *,
    effects: tuple[str, ...],
    settings: DiagnosisSettings,
    pitch_classes: tuple[float, float] | None,
    seed: np.random.SeedSequence,
    steps: StepLog,
) -> DiagnosisResult:
    """Steps 3 to 6 on a prepared campaign whose simulations run on workers (module docstring).

    ``seed`` seeds the bootstrap's random stream and the pitch errors' draws.
    """
    timings: dict[str, float] = {"order_tracking": case.tracking_s}
    timings.update(dict.fromkeys(("nominal_fit", "screening", "full_fits"), 0.0))
    # 3. fit: the nominal model, the pitch-error allowance where the sidebands call for it
    case, nominal = fit_nominal_model(case, posterior, settings=settings, steps=steps, timings=timings)
    case, nominal, allowance = allow_pitch_errors(
        case, nominal, classes=pitch_classes, seed=seed, settings=settings, steps=steps, timings=timings
    )
    with steps.step("find frequency-locked lines and signature hints") as found:
        locked = frequency_locked_lines(case, settings=settings)
        # the hints read every channel's lines (a campaign without encoders has no TE lines)
        hints = signature_hints(case, every_channel_locked_lines(case, settings=settings))
        found.update(hints=dict(hints))
    # 3-4. every candidate fitted and scored on held-out runs against the nominal model, which is refitted
    # where a candidate's full fit shows it stuck; the verdict's rules of this case: plain, or with the
    # pitch-error allowance
    held, gap = nominal_held_out(nominal, steps, timings)
    rng = np.random.default_rng(seed)
    rules = verdict_rules(settings, case)
    state = DiagnosisState(case, settings, rules, effects, hints, rng, steps, timings, nominal, held, gap)
    passes = nominal_passes(state, candidate_pass(state, 0, set_first=True), 0, {}, set_first=True)
    # 5-6. the verdict, and the set of effects named together
    passes, first, named = verdict_and_set(passes, locked, allowance_applied=allowance.applied)
    return _outcome(
        passes.state,
        first,
        named,
        locked=locked,
        hints=hints,
        all_scores=passes.scored.all_scores,
        allowance=allowance,
    )


__all__ = [
    "open_gap",
    "first_decision",
    "starts_a_set",
    "set_comes_first",
    "extra_full_fits",
    "candidate_pass",
    "NominalPasses",
    "nominal_passes",
    "decide_first",
    "next_effect",
    "forward_selection",
    "effect_set",
    "with_phase_named_shaft",
    "verdict_and_set",
    "diagnose_case",
]
