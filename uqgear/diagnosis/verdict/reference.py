"""The verdict against a healthy reference: whether the change since it is there, and which effect explains it.

The differential route (:mod:`uqgear.diagnosis.change`) judges the change
since the reference on condition-monitoring features and scores every
candidate on the change it predicts; these rules name the best when it
explains at least ``change_share`` of the change and leads the next by
``change_margin``, else the change is ``unexplained`` with where it lies
(docs/model/unmodelled-effects.md section 6.1).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

from ..decision import Decision
from .rules import VerdictRules

if TYPE_CHECKING:  # the change route imports these rules: its types are read for the signatures only
    from ..change.detection import ChangeTest
    from ..change.scoring import ChangeScore


def where_text(where: Sequence[dict[str, Any]], limit: int = 3) -> str:
    """The largest changes (:meth:`~uqgear.diagnosis.change.detection.ChangeTest.where`) in words."""
    parts = []
    for entry in where[:limit]:
        shaft = f" of the {entry['shaft']}" if entry["shaft"] else ""
        parts.append(
            f"{entry['channel']} {entry['family'].replace('_', ' ')}{shaft} {entry['direction']} "
            f"{abs(entry['largest_db']):.1f} dB at {', '.join(f'{s:g}' for s in entry['speeds_rpm'])} rpm"
        )
    return "; ".join(parts)


def decide_change(test: ChangeTest, scores: Sequence[ChangeScore], rules: VerdictRules) -> Decision:
    """The verdict of the differential diagnosis and its reason.

    Parameters
    ----------
    test : ChangeTest
        The change since the reference (:func:`~uqgear.diagnosis.change.detection.judge_change`).
    scores : sequence of ChangeScore
        The candidates' scores on the change, best first.
    rules : VerdictRules
        The rules of the ``reference`` case (:func:`~.rules.verdict_rules`).

    Returns
    -------
    Decision
    """
    change = rules.change
    largest = test.largest()
    if not test.changed:
        return Decision(
            "none",
            f"no feature changed beyond what two healthy campaigns of this rig differ by: the largest change "
            f"({largest['channel']} {largest['feature']} at {largest['speed_rpm']:g} rpm) is "
            f"{largest['change_db']:+.1f} dB against a threshold of {largest['threshold_db']:.1f} dB",
        )
    where = where_text(test.where())
    best = scores[0] if scores else None
    if best is None or best.share < change.change_share:
        share = "no candidate" if best is None else f"the best candidate, {best.label}, explains {best.share:.0%}"
        return Decision(
            "unexplained",
            f"changed since the reference ({where}); {share} of the change, below {change.change_share:.0%}",
        )
    runner_up = scores[1] if len(scores) > 1 else None
    next_text = "" if runner_up is None else f" (next: {runner_up.label}, {runner_up.share:.0%})"
    if runner_up is not None and best.share - runner_up.share < change.change_margin:
        return Decision(
            "unexplained",
            f"changed since the reference ({where}); {best.label} explains {best.share:.0%} of the change, "
            f"{runner_up.label} {runner_up.share:.0%}: less than {change.change_margin:.0%} apart, "
            "neither is named",
        )
    return Decision(
        best.effect,
        f"changed since the reference ({where}); {best.label} explains {best.share:.0%} of the change" + next_text,
    )


__all__ = ["where_text", "decide_change"]
