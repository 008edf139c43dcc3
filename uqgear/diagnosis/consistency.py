"""Cross-channel consistency: an effect of the gears shows on every channel that sees the mesh.

A gear effect changes the mesh, and through it the transmission error and
both bearing housings' accelerations; a sensor's own artefact (the run-out
of an encoder's mounting, a sensor's resonance, a loose accelerometer)
shows on that one channel only. Before an effect is named, its held-out
evidence is read channel by channel (:class:`~.scoring.CandidateScore`
``channel_gains``, ``channel_gaps_before``, ``channel_gaps_after``):

* **Evidence on one channel alone.** Where the campaign records two or
  more channels and the channels other than the one the candidate gains
  most on gain less than ``cross_channel_gain`` nats of held-out density
  together, its fitted model explains a discrepancy the other channels do
  not share: it is not named, and the gap is ``unexplained`` on that
  channel. Where the base model's held-out gap is above noise on that
  channel alone, the others must gain ``score_threshold`` (the evidence that
  names an effect at all): refitting the nominal parameters with the
  effect gains a few nats on a clean channel by itself. An effect family whose signature may lie on one channel (its
  :attr:`~.effects.EffectFamily.one_channel` reason, e.g. a low-frequency
  torque oscillation that moves the gears' relative angle far more than it
  accelerates the housings) is exempt.
* **No discrepancy where the rig shows none.** A candidate that leaves a
  held-out gap above ``noise_gap`` on a channel where the base model was
  within noise, and loses at least ``cross_channel_gain`` nats of held-out
  density there, predicts a discrepancy the rig does not show: not named.

docs/model/unmodelled-effects.md section 6, step 5 ("Cross-channel consistency") states the
rule; its evidence is in docs/validation/diagnosis.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .decision import Decision
from .effects import effect_family
from .scoring import CandidateScore
from .settings import DEFAULT_SETTINGS, DiagnosisSettings


@dataclass(frozen=True)
class ChannelCheck:
    """The outcome of the cross-channel rule for one candidate.

    Attributes
    ----------
    consistent : bool
        The candidate may be named as far as this rule goes.
    channel : int or None
        Where it is not: the channel its evidence is confined to, or the one
        where it predicts a discrepancy the rig does not show.
    kind : str
        ``""``, ``"one_channel"`` or ``"predicts_unseen"``.
    share : float
        The held-out density gain on ``channel`` (nats) for ``one_channel``;
        the candidate's gap there for ``predicts_unseen``.
    others : float
        The gain on every other channel together (nats), for ``one_channel``.
    """

    consistent: bool
    channel: int | None = None
    kind: str = ""
    share: float = 0.0
    others: float = 0.0


def check_channels(score: CandidateScore, *, settings: DiagnosisSettings = DEFAULT_SETTINGS) -> ChannelCheck:
    """The cross-channel rule (module docstring) for a scored candidate.

    Examples
    --------
    A run-out read off the TE alone (both accelerometers gain nothing) is one channel's:

    >>> from types import SimpleNamespace
    >>> score = SimpleNamespace(effect="eccentricity", channel_gains=(812.0, 0.4, -0.3),
    ...                         channel_gaps_before=(3.1, 0.0, 0.0), channel_gaps_after=(0.2, 0.0, 0.0))
    >>> check = check_channels(score)
    >>> check.consistent, check.channel, check.kind
    (False, 0, 'one_channel')
    """
    gains = np.asarray(score.channel_gains, dtype=float)
    if gains.size < 2:
        # one channel recorded: nothing to compare it with
        return ChannelCheck(True)
    before = np.asarray(score.channel_gaps_before, dtype=float)
    after = np.asarray(score.channel_gaps_after, dtype=float)
    with np.errstate(invalid="ignore"):
        unseen = np.flatnonzero(
            (before <= settings.verdict.noise_gap)
            & (after > settings.verdict.noise_gap)
            & (gains <= -settings.verdict.cross_channel_gain)
        )
    if unseen.size:
        channel = int(unseen[np.argmax(after[unseen])])
        return ChannelCheck(False, channel, "predicts_unseen", float(after[channel]))
    if effect_family(score.effect).one_channel:
        return ChannelCheck(True)
    finite = np.nan_to_num(gains, nan=0.0)
    strongest = int(np.argmax(finite))
    others = float(np.sum(np.maximum(np.delete(finite, strongest), 0.0)))
    # where the rig shows a gap on that channel alone, the others must carry the evidence to name an effect
    # by themselves: a refit of the nominal parameters alone gains a few nats on a clean channel
    with np.errstate(invalid="ignore"):
        alone = bool(before[strongest] > settings.verdict.noise_gap) and bool(
            np.all(np.nan_to_num(np.delete(before, strongest), nan=0.0) <= settings.verdict.noise_gap)
        )
    needed = settings.verdict.score_threshold if alone else settings.verdict.cross_channel_gain
    if others < needed:
        return ChannelCheck(False, strongest, "one_channel", float(finite[strongest]), others)
    return ChannelCheck(True)


def inconsistency_reason(score: CandidateScore, check: ChannelCheck, channels: tuple[str, ...] | list[str]) -> str:
    """Why a candidate that fails the cross-channel rule is not named, in words."""
    name = channels[check.channel] if check.channel is not None and check.channel < len(channels) else "one channel"
    others = ", ".join(channel for index, channel in enumerate(channels) if index != check.channel)
    if check.kind == "predicts_unseen":
        return (
            f"{score.effect} would leave a held-out gap of {check.share:.2f} on {name}, where the model without it "
            f"is within noise: it predicts a discrepancy the rig does not show"
        )
    return (
        f"{score.effect}'s held-out evidence lies on {name} alone ({check.share:.0f} nats; {check.others:.1f} on "
        f"{others} together): a gear effect changes the mesh and shows on every channel that sees it, so a "
        f"discrepancy on {name} alone is that sensor's own (an encoder's mounting run-out, a sensor resonance, a "
        f"loose accelerometer) as far as these data can tell"
    )


def inconsistent_decision(
    best: CandidateScore,
    nominal_gap: float,
    borderline: tuple[dict[str, Any], ...],
    settings: DiagnosisSettings,
    channels: ChannelCheck,
) -> Decision:
    """``none`` or ``unexplained`` where the leading candidate fails the cross-channel rule."""
    why = inconsistency_reason(best, channels, best.channels)
    confined = channels.kind == "one_channel" and channels.channel is not None and channels.channel < len(best.channels)
    if nominal_gap <= settings.verdict.noise_gap:
        return Decision(
            "none",
            f"the nominal model's held-out gap {nominal_gap:.2f} is within noise "
            f"(threshold {settings.verdict.noise_gap:g}); "
            f"{why}",
            borderline=borderline,
        )
    return Decision(
        "unexplained",
        f"the nominal model's held-out gap is {nominal_gap:.2f} (above {settings.verdict.noise_gap:g}); {why}",
        borderline=borderline,
        one_channel=best.channels[channels.channel] if confined and channels.channel is not None else "",
    )


def one_channel_character(channel: str, families: Sequence[Mapping[str, Any]]) -> str:
    """What a gap confined to one channel is made of: its families above noise with their character."""
    rows = [row for row in families if row["channel"] == channel and row["character"]]
    if not rows:
        return ""
    parts = [f"{row['family']} ({', '.join(row['character'])}; gap {row['score']:.2f})" for row in rows]
    return f"; on {channel} the gap lies in " + ", ".join(parts)


__all__ = ["ChannelCheck", "check_channels", "inconsistency_reason", "inconsistent_decision", "one_channel_character"]
