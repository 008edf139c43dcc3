"""Several effects at once: the fits of a forward-selection round, and of an eccentric shaft its phases name.

Step 6 of docs/model/unmodelled-effects.md section 6 (section 6.2): a
round takes the model with the effects named so far as its base, screens
the other effects on top of it with their own parameters, and fits the
best in full with every effect present, scored against the base's
held-out predictions (:func:`round_fits`). Where the pitch-error allowance
applies, a shaft's sideband phases can name an eccentricity the line
amplitudes cannot tell from the gears' own errors (section 6.4,
:func:`phase_named_run_out`). These functions measure; the rounds, and the
decisions that add an effect or end the selection, are the orchestrator's
(:mod:`.pipeline`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from .allowances.pitch_errors import first_order_reads
from .allowances.sideband_phase import ModulationEvidence, fit_modulated_run_out, modulation_evidence, shafts_tested
from .decision import Decision
from .effect_set import SelectedEffect, SelectionRound
from .effects import EffectFamily, hooks_of
from .scoring import CandidateScore
from .screening import best_per_effect, fits_ahead, found, scored_in_full, screen, supersedes
from .settings import DiagnosisSettings
from .state import DiagnosisState


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


@dataclass(frozen=True)
class RoundFits:
    """What one forward-selection round measured on top of its base (:func:`round_fits`).

    Attributes
    ----------
    base : tuple of str
        The labels of the base's effects.
    gap_before : float
        The base's held-out gap.
    ranking : list of CandidateScore
        The best fit per effect screened, best first (empty: nothing was screened).
    leader : CandidateScore or None
        The best fit of the best screening's effect (its full fit where that scores higher).
    void : str
        Why nothing was screened (empty where something was).
    note : str
        Where the best screening was not fitted in full, why (a clause of the round's reason).
    """

    base: tuple[str, ...]
    gap_before: float
    ranking: list[CandidateScore] = field(default_factory=list)
    leader: CandidateScore | None = None
    void: str = ""
    note: str = ""


def round_fits(
    state: DiagnosisState, base: CandidateScore, named: Sequence[str], tried: SelectionRound | None = None
) -> RoundFits:
    """One forward-selection round's fits: the other effects screened on top of the base, the best fitted in full.

    Only the new effect's parameters are screened (the base's fit, its
    Jacobian and held-out predictions are reused), for the effects
    :func:`still_open` leaves after the round before (``tried``); the best
    screened variant is fitted in full with every effect present where its
    screening could explain part of the remaining gap
    (:func:`worth_a_full_fit`), and scored against the base's held-out
    predictions (:func:`~.screening.scored_in_full`).
    """
    settings, base_fit = state.settings, base.fit
    base_labels = tuple(candidate.label for candidate in base_fit.problem.candidates)
    effects = still_open(state, named, tried)
    if tried is not None and not effects and any(name not in named for name in state.effects):
        # only a round before can leave nothing of the effects not yet named
        return RoundFits(base_labels, base.gap_with_effect, void=_void_reason(tried))
    screened = screen(state, base.fit, base.held, effects, on_top=True)
    if not screened:
        return RoundFits(base_labels, base.gap_with_effect, void="no other candidate effect is left to try")
    best = best_per_effect(screened)
    leader = max(screened, key=lambda entry: entry.score)
    note = ""
    if worth_a_full_fit(leader, settings):
        full = scored_in_full(state, leader, fits_ahead(state, [leader], base_fit)[0], base)
        if supersedes(full, best[full.effect]):
            best[full.effect] = full
    else:
        note = (
            f"; its screening on top explains none of the gap (shrink at most {leader.shrink_interval[1]:.0%}) "
            "and has no evidence of its own, so it was not fitted in full"
        )
    ranking = sorted(best.values(), key=lambda entry: -entry.score)
    return RoundFits(base_labels, base.gap_with_effect, ranking, best[leader.effect], note=note)


def selected_effects(
    state: DiagnosisState,
    entries: Sequence[CandidateScore],
    decisions: Sequence[Decision],
    intervals: Sequence[tuple[float, float]],
) -> list[SelectedEffect]:
    """The named effects in order with their shrink shares (:func:`shrink_shares`), the decisions that named them."""
    shares = shrink_shares(state.nominal_gap, entries[0].shrink_fraction, [entry.gap_with_effect for entry in entries])
    befores = [state.nominal_gap] + [entry.gap_with_effect for entry in entries[:-1]]
    return [
        SelectedEffect(entry, before, share, decision, interval, open_choices(state, entry))
        for entry, before, share, decision, interval in zip(entries, befores, shares, decisions, intervals)
    ]


def open_choices(state: DiagnosisState, entry: CandidateScore) -> dict[str, tuple[float, ...]]:
    """The parameters the fit of ``entry`` leaves open, with their values (its family's hook)."""
    return hooks_of(entry.effect).open_choices(entry.parameters(), state.case.design)


@dataclass(frozen=True)
class PhaseNamedFit:
    """The run-out a shaft's sideband phases name, fitted on top of the final model (:func:`phase_named_run_out`).

    ``entry`` is its fit scored against the final model's held-out
    predictions, ``gap_before`` the final model's gap, ``share`` its share of
    the shrink (negative where it widens the gap), ``reason`` what the
    phases and the fit say, in words.
    """

    entry: CandidateScore
    gap_before: float
    share: float
    reason: str


def phase_named_run_out(
    state: DiagnosisState, family: EffectFamily, selected: list[SelectedEffect]
) -> tuple[list[ModulationEvidence], PhaseNamedFit | None]:
    """Test the shafts' sideband phase sums for a run-out the amplitudes cannot tell from pitch errors.

    ``family`` is the effect a shaft run-out is named as (its
    :attr:`~.effects.EffectFamily.run_out` hook; eccentricity in the
    library). Each shaft :func:`~.allowances.sideband_phase.shafts_tested`
    admits is tested against the final model
    (:func:`~.allowances.sideband_phase.modulation_evidence`); the shaft with
    the strongest decisive evidence gets its run-out fitted on top
    (:func:`~.allowances.sideband_phase.fit_modulated_run_out`). Returns
    the evidence of every shaft tested and that fit (None: no shaft's
    evidence is decisive).
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
    return found_evidence, PhaseNamedFit(entry, base_gap, share, reason)


@dataclass(frozen=True)
class NamedSet:
    """Step 6's outcome: the named effects in order, the rounds after the first, the decision, the phase tests."""

    selected: list[SelectedEffect] = field(default_factory=list)
    rounds: list[SelectionRound] = field(default_factory=list)
    decision: Decision | None = None
    modulation: list[ModulationEvidence] = field(default_factory=list)
    # whether the set is one an unexplained gap's strongest candidate led (a set that explains it together)
    led: bool = False


__all__ = [
    "shrink_shares",
    "worth_a_full_fit",
    "still_open",
    "RoundFits",
    "round_fits",
    "selected_effects",
    "PhaseNamedFit",
    "phase_named_run_out",
    "NamedSet",
]
