"""The verdict on a set of effects: the decisions forward selection and the sideband phase test make.

The rules are :mod:`.named`'s applied to the set against the nominal
model (docs/model/unmodelled-effects.md section 6.2); every :class:`~.decision.Decision` of a
set is made here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from ..decision import Decision
from ..effect_set import SelectedEffect, SelectionRound
from ..scoring import CandidateScore, shrink_fraction
from .rules import DEFAULT_RULES, VerdictRules


def _percent(interval: Sequence[float]) -> str:
    return f"{100 * interval[0]:.0f} to {100 * interval[1]:.0f} %"


def set_decision(
    first_decision: Decision,
    selected: Sequence[SelectedEffect],
    rounds: Sequence[SelectionRound],
    nominal_gap: float,
    rules: VerdictRules = DEFAULT_RULES,
) -> Decision:
    """The decision for the named set: the first effect's verdict, ``partial`` and remaining gap of the whole set.

    With one effect named and no round run this is ``first_decision``
    itself. ``partial`` follows the rule of :func:`decide` applied to the
    set against the nominal model: an effect set is named with an
    unexplained remainder when it neither shrinks the nominal gap by
    ``shrink_threshold`` nor leaves a gap within ``noise_gap``.
    """
    if not selected or not rounds:
        return first_decision
    final_gap = selected[-1].entry.gap_with_effect
    reason = first_decision.reason
    borderline = list(first_decision.borderline)
    for chosen in selected[1:]:
        names = " + ".join(entry.entry.effect for entry in selected[: selected.index(chosen)])
        entry = chosen.entry
        reason += (
            f"; on top of {names}, forward selection adds {entry.effect}: it gains {entry.score:.1f} nats "
            f"of held-out predictive density after its penalty and shrinks the remaining held-out gap "
            f"from {chosen.gap_before:.2f} to {entry.gap_with_effect:.2f} (90 % interval of the shrink "
            f"{_percent(entry.shrink_interval)}), {100 * chosen.shrink_share:.0f} % of the nominal gap"
        )
        borderline += [{**figure, "effect": entry.effect} for figure in chosen.decision.borderline]
    last = rounds[-1]
    if last.added is None and last.scores:
        best = last.scores[0]
        reason += (
            f"; no further effect clearly explains the remaining gap of {last.gap_before:.2f} (the best, "
            f"{best.effect}, scores {best.score:.1f} nats on top and shrinks it by "
            f"{100 * best.shrink_fraction:.0f} %)"
        )
    elif last.added is None:
        reason += f"; {last.reason}"
    thresholds = rules.thresholds
    explains = (
        shrink_fraction(nominal_gap, final_gap) >= thresholds.shrink_threshold or final_gap <= thresholds.noise_gap
    )
    if not explains:
        reason += f"; a gap of {final_gap:.2f} (above {thresholds.noise_gap:g}) remains unexplained"
    return Decision(
        first_decision.verdict, reason, partial=not explains, remaining_gap=final_gap, borderline=tuple(borderline)
    )


def lead_decision(first: CandidateScore) -> Decision:
    """The provisional decision of an unexplained gap's strongest candidate that leads a forward selection.

    It names its effect ``partial``: alone it does not explain enough of the
    gap; :func:`set_decision` then judges the set it leads.
    """
    return Decision(
        first.effect,
        (
            f"{first.effect} gains {first.score:.1f} nats of held-out predictive density over the nominal model "
            f"after its parameter penalty but alone shrinks the held-out gap by only "
            f"{100 * first.shrink_fraction:.0f} % "
            f"(90 % interval {_percent(first.shrink_interval)})"
        ),
        partial=True,
        remaining_gap=first.gap_with_effect,
    )


def unled_decision(decision: Decision, first: CandidateScore, trial: Sequence[SelectedEffect]) -> Decision:
    """The unexplained decision kept when the set its strongest candidate led does not explain the gap."""
    return Decision(
        decision.verdict,
        decision.reason
        + (
            f"; forward selection from {first.effect} found no set that explains it together (held-out "
            f"gap {trial[-1].entry.gap_with_effect:.2f} with {' + '.join(entry.entry.effect for entry in trial)})"
        ),
        borderline=decision.borderline,
    )


def phase_named_decision(
    decision: Decision, reason: str, remaining_gap: float, *, set_named: bool, effect: str
) -> tuple[Decision, Decision]:
    """The decision that adds a shaft run-out the sideband phases name, and the set's decision with it.

    ``effect`` is the run-out's effect (the family with a
    :attr:`~.effects.EffectFamily.run_out` hook: eccentricity). Returns its
    own decision and the whole set's: the set's decision with the reason
    appended when a set was named before, else the run-out's own.
    """
    added = Decision(effect, reason, remaining_gap=remaining_gap)
    whole = (
        replace(decision, reason=f"{decision.reason}; {reason}", remaining_gap=remaining_gap) if set_named else added
    )
    return added, whole


__all__ = ["set_decision", "lead_decision", "unled_decision", "phase_named_decision"]
