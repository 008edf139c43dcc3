"""A decision of the diagnosis: the verdict, its reason, and the figures that decided it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


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
        An unexplained gap whose leading candidate's evidence lies on this one
        channel alone (that sensor's own artefact as far as the data tell;
        empty otherwise).
    """

    verdict: str
    reason: str
    partial: bool = False
    remaining_gap: float | None = None
    borderline: tuple[dict[str, Any], ...] = ()
    one_channel: str = ""


__all__ = ["Decision"]
