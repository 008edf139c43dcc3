"""A decision of the diagnosis: the verdict, its reason, and the figures that decided it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Ambiguity:
    """Two explanations of one gap that the channels cannot separate: an effect too weak for the others to see.

    The effect explains the gap on ``channel``; its fit predicts too little
    on every other channel for them to see it, so the channel's own artefact
    explains the data as well (:mod:`~uqgear.diagnosis.verdict.cross_channel`).

    Attributes
    ----------
    effect : str
        The effect that explains the gap.
    channel : str
        The one channel that sees it.
    artefact : str
        That channel's own artefact that reads as the effect there, in words.
    reach : tuple of (str, float)
        Per other channel: the held-out density (nats) the effect's fit would
        gain there were it real (:func:`~.scoring.channel_reach`).
    needed : float
        What the cross-channel rule asks of the other channels together (nats).
    separated_by : tuple of str
        Measurements that would tell the two apart, as sentences.
    """

    effect: str
    channel: str
    artefact: str
    reach: tuple[tuple[str, float], ...]
    needed: float
    separated_by: tuple[str, ...]

    def summary(self) -> dict[str, Any]:
        """The record of ``diagnosis.json``'s ``ambiguity``: both candidates and what would separate them."""
        return {
            "candidates": [
                {"kind": "effect", "name": self.effect},
                {"kind": "sensor_artefact", "name": f"{self.channel} sensor artefact", "description": self.artefact},
            ],
            "channel": self.channel,
            "reach": dict(self.reach),
            "needed": self.needed,
            "separated_by": list(self.separated_by),
        }


@dataclass(frozen=True)
class Decision:
    """A verdict with the figures that decided it.

    Attributes
    ----------
    verdict, reason : str
        The verdict (a library effect, ``none``, ``unexplained`` or
        ``inconclusive``) and the rule that gave it, in words.
    partial : bool
        The named effect explains only part of the gap: what remains
        (``remaining_gap``) is significant and unexplained.
    remaining_gap : float or None
        Held-out gap with the named effect (``None`` when none is named).
    borderline : tuple of dict
        Deciding figures that lie within their own spread of their threshold
        (``figure``, ``value``, ``threshold``, ``interval``): a rerun on
        another campaign of the same rig could go the other way.
    one_channel : str
        A gap whose leading candidate's evidence lies on this one channel
        alone: that sensor's own artefact as far as the data tell
        (``unexplained``), or either of the two (``inconclusive`` with
        ``ambiguity``); empty otherwise.
    ambiguity : Ambiguity or None
        An ``inconclusive`` verdict between an effect the other channels
        cannot see and the one channel's own artefact (None otherwise).
    """

    verdict: str
    reason: str
    partial: bool = False
    remaining_gap: float | None = None
    borderline: tuple[dict[str, Any], ...] = ()
    one_channel: str = ""
    ambiguity: Ambiguity | None = None

    @property
    def open_gap(self) -> bool:
        """A significant gap no effect is named for: ``unexplained``, or an effect and an artefact not told apart."""
        return self.verdict == "unexplained" or self.ambiguity is not None


__all__ = ["Ambiguity", "Decision"]
