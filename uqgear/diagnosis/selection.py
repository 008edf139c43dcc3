"""Several effects at once: forward selection after the first effect, and an eccentric shaft its phases name.

Step 6 of docs/model/unmodelled-effects.md section 6 (section 6.2): while the model with the
effects named so far leaves a significant held-out gap, it is the base of
another round; the other effects are screened on top of it with their own
parameters, the best is fitted in full with every effect present and scored
against the base's held-out predictions, and :func:`~.verdict.named.decide` on
the gap that remains adds it or not. Where the pitch-error allowance
applies, a shaft's sideband phases can then name an eccentricity the line
amplitudes cannot tell from the gears' own errors (section 6.4).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

from .allowances.pitch_errors import first_order_reads
from .allowances.sideband_phase import ModulationEvidence, fit_modulated_run_out, modulation_evidence, shafts_tested
from .decision import Decision
from .effect_set import SelectedEffect, SelectionRound
from .effects import EffectFamily, run_out_family
from .first_effect import FirstDecision, starts_a_set
from .scoring import CandidateScore, bootstrap_gap, score_candidate
from .screening import best_per_effect, effect_off_costs, found, full_fit, measure_modulation, screen, supersedes
from .settings import DiagnosisSettings
from .state import DiagnosisState
from .verdict.named import decide, ranked
from .verdict.sets import lead_decision, phase_named_decision, set_decision, unled_decision


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


def worth_a_full_fit(entry: CandidateScore, settings: DiagnosisSettings) -> bool:
    """Whether a forward-selection round's best screening on top of its base is fitted in full.

    It is, unless the screening explains none of the remaining gap and has
    no evidence either: the upper end of its shrink interval below
    ``partial_shrink``, what it leaves above ``noise_gap`` and its score
    below ``score_threshold``. A full fit starts from the screening's
    optimum and refits parameters the base fit already fitted, so it moves
    a screening only near where it already is: one that explains nothing
    and has no evidence is not expected to become a candidate the rule of
    :func:`~.verdict.named.decide` names (the rounds measured are in
    docs/validation/diagnosis.md, "Forward selection").
    """
    return (
        entry.shrink_interval[1] >= settings.verdict.partial_shrink
        or entry.gap_with_effect <= settings.verdict.noise_gap
        or entry.score >= settings.verdict.score_threshold
    )


def still_open(state: DiagnosisState, named: Sequence[str], tried: SelectionRound | None) -> list[str]:
    """The effects a round screens on top of its base: those not named, less those the round before showed void.

    An effect is never named twice, nor as another variant: it would only
    soak up noise. After a round with screenings (``tried``), an effect
    whose best fit on top of that round's base explained none of the gap
    and had no evidence of its own (:func:`worth_a_full_fit` false) is not
    screened again on top of the next base: that base adds the effect the
    round named, which explains features of its own, and an effect that
    explained nothing beside it gains nothing from it (the rounds measured
    are in docs/validation/diagnosis.md, "Forward selection").
    """
    remaining = [name for name in state.effects if name not in named]
    if tried is None or not tried.scores:
        return remaining
    shown = {entry.effect: worth_a_full_fit(entry, state.settings) for entry in tried.scores}
    return [name for name in remaining if shown.get(name, False)]


def _void_reason(tried: SelectionRound) -> str:
    """Why a round screens nothing: every other effect showed nothing on top of the round before's base."""
    others = [entry for entry in tried.scores if entry.effect != tried.added]  # best first
    best = ""
    if others:
        lead = others[0]
        reach = round(100 * lead.shrink_interval[1])  # an int: never "-0"
        best = f" (the best, {lead.effect}, scored {lead.score:.1f} nats, shrink at most {reach} %)"
    return f"no other effect explained any of the gap on top of {' + '.join(tried.base)}{best}, so none was screened"


def _full_on_top(state: DiagnosisState, base: CandidateScore, leader: CandidateScore) -> CandidateScore:
    """The round's leader fitted in full with every effect present, scored against the base's held-out runs."""
    settings, base_fit = state.settings, base.fit
    candidate = leader.fit.problem.candidate
    assert candidate is not None  # internal invariant: a screened entry has its candidate
    base_labels = " + ".join(c.label for c in base_fit.problem.candidates)
    with state.steps.step(f"forward selection: fit {candidate.label} in full on top of {base_labels}") as finding:
        result, held = full_fit(state, leader, base_fit)
        full = score_candidate(
            result, held, base.held, "full", state.rng, n_resamples=settings.verdict.bootstrap_resamples
        )
        full.effect_gain = effect_off_costs(base_fit, [result], own_error=True)[1][0] - result.cost
        measure_modulation(state.case, full)
        finding.update(found(full))
    return full


def next_effect(
    state: DiagnosisState, base: CandidateScore, named: Sequence[str], tried: SelectionRound | None = None
) -> SelectionRound:
    """One forward-selection round: the other effects screened on top of the base, the best fitted in full.

    Only the new effect's parameters are screened (the base's fit, its
    Jacobian and held-out predictions are reused), for the effects
    :func:`still_open` leaves after the round before (``tried``); the best
    screened variant is fitted in full with every effect present where its
    screening could explain part of the remaining gap
    (:func:`worth_a_full_fit`), and scored against the base's held-out
    predictions; :func:`~.verdict.named.decide` on top of the base adds it or not.
    """
    settings, base_fit = state.settings, base.fit
    base_labels = tuple(candidate.label for candidate in base_fit.problem.candidates)
    effects = still_open(state, named, tried)
    if tried is not None and not effects and any(name not in named for name in state.effects):
        # only a round before can leave nothing of the effects not yet named
        return SelectionRound(base_labels, base.gap_with_effect, [], None, _void_reason(tried))
    screened = screen(state, base.fit, base.held, effects, on_top=True)
    if not screened:
        return SelectionRound(base_labels, base.gap_with_effect, [], None, "no other candidate effect is left to try")
    best = best_per_effect(screened)
    leader = max(screened, key=lambda entry: entry.score)
    fitted_in_full = worth_a_full_fit(leader, settings)
    if fitted_in_full:
        full = _full_on_top(state, base, leader)
        if supersedes(full, best[full.effect]):
            best[full.effect] = full
    ranking = sorted(best.values(), key=lambda entry: -entry.score)
    chosen = ranked({leader.effect: best[leader.effect]}, state.rules)[0]
    chosen = replace(chosen, gap_interval=bootstrap_gap(chosen.held.z, state.rng, settings.verdict.bootstrap_resamples))
    # no density evidence here: a further effect must shrink a gap that is there, or it only soaks up what
    # the allowance already forgives (docs/model/unmodelled-effects.md section 6.4)
    decision = decide(base.gap_with_effect, [chosen], state.rules.shrink_only())
    added = chosen.effect if decision.verdict == chosen.effect else None
    reason = decision.reason
    if not fitted_in_full:
        reason += (
            f"; its screening on top explains none of the gap (shrink at most {leader.shrink_interval[1]:.0%}) "
            "and has no evidence of its own, so it was not fitted in full"
        )
    assert chosen.gap_interval is not None
    return SelectionRound(base_labels, base.gap_with_effect, ranking, added, reason, decision, chosen.gap_interval)


def forward_selection(
    state: DiagnosisState,
    first: CandidateScore,
    first_decision: Decision,
    *,
    first_gap_interval: Sequence[float] = (math.nan, math.nan),
) -> tuple[list[SelectedEffect], list[SelectionRound]]:
    """Add effects one at a time after the first while a significant held-out gap remains.

    The first effect's fit (``first``, named by :func:`~.verdict.named.decide`) is
    the base; each round (:func:`next_effect`) screens the effects not yet
    named on top of it, fits the best in full with all effects present and
    adds it when :func:`~.verdict.named.decide`, applied to the gap that remains,
    names it; the model with it is the next base. Rounds stop when the
    remaining gap is within ``noise_gap`` (where the pitch-error allowance
    applies, only at a gap of 0: its widened error can hold a further
    effect's evidence below the noise gap, and the effect is added when it
    shrinks what is left), when a round adds nothing, or at ``max_effects``.

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
    shares = shrink_shares(state.nominal_gap, first.shrink_fraction, [entry.gap_with_effect for entry in entries])
    befores = [state.nominal_gap] + [entry.gap_with_effect for entry in entries[:-1]]
    selected = [
        SelectedEffect(entry, before, share, decision, interval)
        for entry, before, share, decision, interval in zip(entries, befores, shares, decisions, intervals)
    ]
    return selected, rounds


def phase_named_run_out(
    state: DiagnosisState, family: EffectFamily, selected: list[SelectedEffect], decision: Decision
) -> tuple[list[ModulationEvidence], tuple[list[SelectedEffect], Decision] | None]:
    """Test the shafts' sideband phase sums for a run-out the amplitudes cannot tell from pitch errors.

    ``family`` is the effect a shaft run-out is named as (its
    :attr:`~.effects.EffectFamily.run_out` hook; eccentricity in the
    library). Each shaft :func:`~.allowances.sideband_phase.shafts_tested`
    admits is tested against the final model
    (:func:`~.allowances.sideband_phase.modulation_evidence`); the shaft with
    the strongest decisive evidence gets its run-out fitted on top
    (:func:`~.allowances.sideband_phase.fit_modulated_run_out`) and added to
    the set, with its own share of the shrink (negative where it widens the
    held-out gap).
    """
    settings, case = state.settings, state.case
    base_fit = selected[-1].entry.fit if selected else state.nominal
    base_held = selected[-1].entry.held if selected else state.nominal_held
    base_gap = selected[-1].entry.gap_with_effect if selected else state.nominal_gap
    reads = first_order_reads(case.pitch_allowance)  # type: ignore[arg-type]
    found_evidence = []
    for shaft in shafts_tested(case, min_orders=settings.phases.min_sideband_orders):
        if shaft not in reads:
            continue
        with state.steps.step(f"test the {shaft}'s sideband phases for an eccentric shaft") as finding:
            evidence = modulation_evidence(
                case,
                base_fit,
                shaft,
                reads[shaft][0],
                kappas=settings.phases.modulation_kappas,
                threshold=settings.phases.phase_evidence_threshold,
                draws_per_point=settings.phases.phase_draws_per_point,
            )
            finding.update(evidence.summary())
        found_evidence.append(evidence)
    decisive = [evidence for evidence in found_evidence if evidence.decisive]
    if not decisive:
        return found_evidence, None
    evidence = max(decisive, key=lambda item: item.log_ratio)
    with state.steps.step(f"fit the eccentric {evidence.shaft} shaft the sideband phases name") as finding:
        entry = fit_modulated_run_out(case, base_fit, base_held, evidence, state.rng, family=family, settings=settings)
        finding.update(found(entry))
    share = (base_gap - entry.gap_with_effect) / state.nominal_gap if state.nominal_gap > 0 else 0.0
    amplitude = family.run_out.amplitude  # type: ignore[union-attr]
    run_out = float(entry.parameters()[amplitude])  # type: ignore[arg-type]
    low, high = entry.parameter_intervals().get(amplitude, (math.nan, math.nan))
    # the amplitudes cannot tell the run-out from the gear's own first-order errors: its interval says how much
    reason = (
        f"{evidence.reason()}; fitted on top, its run-out is left open by the line amplitudes, which "
        f"cannot tell it from the {evidence.shaft}'s own first-order errors ({1e6 * run_out:.3g} um, 90 % "
        f"interval {1e6 * low:.3g} to {1e6 * high:.3g} um), and it changes the held-out gap from "
        f"{base_gap:.2f} to {entry.gap_with_effect:.2f}"
    )
    added, whole = phase_named_decision(
        decision, reason, entry.gap_with_effect, set_named=bool(selected), effect=family.name
    )
    chosen = SelectedEffect(
        entry, base_gap, share, added, bootstrap_gap(entry.held.z, state.rng, settings.verdict.bootstrap_resamples)
    )
    return found_evidence, ([*selected, chosen], whole)


@dataclass
class NamedSet:
    """Step 6's outcome: the named effects in order, the rounds after the first, the decision, the phase tests."""

    selected: list[SelectedEffect] = field(default_factory=list)
    rounds: list[SelectionRound] = field(default_factory=list)
    decision: Decision | None = None
    modulation: list[ModulationEvidence] = field(default_factory=list)
    # whether the set is one an unexplained gap's strongest candidate led (a set that explains it together)
    led: bool = False


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
            set_decision(provisional, trial, trial_rounds, state.nominal_gap, state.rules)
            if len(trial) > 1
            else None
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
    (:func:`~.first_effect.starts_a_set`).
    """
    decision = first.decision
    if first.scores and starts_a_set(state, decision, first.ranking):
        return _led_set(state, first)
    if decision.verdict in state.effects:
        return _grown_set(state, first)
    return NamedSet(decision=decision)


def with_phase_named_shaft(state: DiagnosisState, named: NamedSet, *, allowance_applied: bool) -> NamedSet:
    """The set with an eccentric shaft its sideband phases name (:func:`phase_named_run_out`), where the test applies.

    It applies where the pitch-error allowance was applied, a family that
    reads as a shaft run-out (:func:`~.effects.run_out_family`: eccentricity)
    is a candidate not in the set, the gap is not left open (``unexplained``,
    or an effect not told apart from a sensor's artefact) and the set has
    room for it. ``named`` is updated in place and returned.
    """
    settings = state.settings
    assert named.decision is not None
    in_set = [chosen.entry.effect for chosen in named.selected]
    family = run_out_family(state.effects)
    if (
        allowance_applied
        and family is not None
        and not named.decision.open_gap
        and len(named.selected) < settings.selection.max_effects
        and family.name not in in_set
    ):
        clock = time.perf_counter()
        named.modulation, added = phase_named_run_out(state, family, named.selected, named.decision)
        if added is not None:
            named.selected, named.decision = added
        state.timings["sideband_phases"] = time.perf_counter() - clock
    return named


__all__ = [
    "shrink_shares",
    "worth_a_full_fit",
    "still_open",
    "next_effect",
    "forward_selection",
    "phase_named_run_out",
    "NamedSet",
    "effect_set",
    "with_phase_named_shaft",
]
