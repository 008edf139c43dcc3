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
* **An effect the other channels cannot see.** The rule above reads the
  other channels' silence as evidence against the effect only where they
  could have seen it. Each candidate's reach on a channel
  (:func:`~.scoring.channel_reach`) is what its fit would gain there on
  held-out runs were it real: half the sum of squares of its prediction in
  noise spreads. Where the reach on the other channels together is below
  what the rule asks of them (``score_threshold`` or
  ``cross_channel_gain`` nats, as above), their silence says nothing:
  even if the effect acted as fitted they could not carry that evidence.
  An effect that explains the gap there (named but for this rule, not
  ``partial``) and the channel's own artefact then fit the data alike, and
  the verdict is ``inconclusive`` naming both (:class:`~.decision.Ambiguity`),
  with the measurements that would separate them: the effect family's
  (:meth:`~.effects.EffectFamily.separated_by`), the sensor's (a second
  sensor, or the sensor remounted) and a healthy reference. What reads as
  the effect on that channel is the family's
  (:meth:`~.effects.EffectFamily.look_alike`), else the sensor's artefacts
  in general.

docs/model/unmodelled-effects.md section 6, step 5 ("Cross-channel consistency") states the
rule; its evidence is in docs/validation/diagnosis.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..decision import Ambiguity, Decision
from ..effects import effect_family, hooks_of
from ..scoring import CandidateScore
from ..settings import VerdictSettings
from .rules import DEFAULT_RULES, VerdictRules

#: Per channel: its sensor's own artefacts (no effect of the gears makes them, no other channel shares them),
#: and the measurement that tells them from an effect of the gears the other channels cannot see.
SENSOR_ARTEFACTS: dict[str, tuple[str, str]] = {
    "te": (
        "an encoder's own artefact (its mounting run-out, its disc's eccentricity)",
        "a second encoder on the same shaft, or this one remounted at another angle: an encoder's own artefact "
        "moves with its mounting, an effect of the gears does not",
    ),
    "acc_pinion": (
        "the pinion-side accelerometer's own artefact (a sensor resonance, a loose mounting)",
        "a second accelerometer on the pinion-side housing, or this one remounted: a sensor's own artefact moves "
        "with its mounting, an effect of the gears does not",
    ),
    "acc_gear": (
        "the gear-side accelerometer's own artefact (a sensor resonance, a loose mounting)",
        "a second accelerometer on the gear-side housing, or this one remounted: a sensor's own artefact moves "
        "with its mounting, an effect of the gears does not",
    ),
}
#: A channel the table does not hold.
_ANY_SENSOR = (
    "that sensor's own artefact",
    "a second sensor beside this one, or this one remounted: a sensor's own artefact moves with its mounting, an "
    "effect of the gears does not",
)
#: Where an ambiguous verdict's reason lists what would separate its two explanations.
_SEPARATE = "What would separate them: "
#: What separates the two on any channel.
_REFERENCE = (
    "a healthy reference campaign of this rig recorded with the same sensors, diagnosed against "
    "(uqgear diagnose --reference): a sensor's artefact is in both, an effect of the gears that developed since is not"
)


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
    needed : float
        What the rule asked of the other channels together (nats), for ``one_channel``.
    reach : float
        For ``one_channel``: the candidate's reach on every other channel together
        (:func:`~.scoring.channel_reach`, nats; NaN where it was not measured).
    """

    consistent: bool
    channel: int | None = None
    kind: str = ""
    share: float = 0.0
    others: float = 0.0
    needed: float = 0.0
    reach: float = math.nan

    @property
    def unseen(self) -> bool:
        """Evidence on one channel alone where the others could not have seen the effect (its reach there is short)."""
        return self.kind == "one_channel" and self.reach < self.needed


@dataclass(frozen=True, eq=False)
class ChannelEvidence:
    """Per channel, what a candidate's fit predicts against what the rig shows (held-out runs, nats).

    Attributes
    ----------
    shown : numpy.ndarray
        What the rig shows that the model without the effect lacks: that
        model's held-out gap on each channel (``channel_gaps_before``).
    left : numpy.ndarray
        The held-out gap the model with the effect leaves there (``channel_gaps_after``).
    gain : numpy.ndarray
        The held-out density the effect gains there (``channel_gains``; negative: it loses).
    reach : numpy.ndarray
        What the effect would gain there were it real (``channel_reach``,
        :func:`~uqgear.diagnosis.scoring.channel_reach`).
    """

    shown: np.ndarray
    left: np.ndarray
    gain: np.ndarray
    reach: np.ndarray

    @classmethod
    def of(cls, score: CandidateScore) -> ChannelEvidence:
        """The per-channel figures of a scored candidate."""
        return cls(
            np.asarray(score.channel_gaps_before, dtype=float),
            np.asarray(score.channel_gaps_after, dtype=float),
            np.asarray(score.channel_gains, dtype=float),
            np.asarray(score.channel_reach, dtype=float),
        )


def predicts_unseen(evidence: ChannelEvidence, thresholds: VerdictSettings) -> ChannelCheck | None:
    """The channel where the fit predicts a discrepancy the rig does not show (the worst such), or None.

    The rig shows none there (the model without the effect is within
    ``noise_gap``), while the model with it leaves a gap above ``noise_gap``
    and loses at least ``cross_channel_gain`` nats.
    """
    noise_gap = thresholds.noise_gap
    with np.errstate(invalid="ignore"):
        shows_none = evidence.shown <= noise_gap
        predicts = (evidence.left > noise_gap) & (evidence.gain <= -thresholds.cross_channel_gain)
        unseen = np.flatnonzero(shows_none & predicts)
    if not unseen.size:
        return None
    channel = int(unseen[np.argmax(evidence.left[unseen])])
    return ChannelCheck(False, channel, "predicts_unseen", float(evidence.left[channel]))


def confined_to_one(evidence: ChannelEvidence, thresholds: VerdictSettings) -> ChannelCheck | None:
    """The channel the fit's evidence is confined to, where the other channels gain too little together, or None.

    The others must gain ``cross_channel_gain`` nats together, or
    ``score_threshold`` where the rig shows a gap on the strongest channel
    alone; the check records what the effect would gain on them were it
    real (its reach), so that their silence counts against it only where
    they could have seen it.
    """
    gain = np.nan_to_num(evidence.gain, nan=0.0)
    strongest = int(np.argmax(gain))
    others = float(np.sum(np.maximum(np.delete(gain, strongest), 0.0)))
    # where the rig shows a gap on that channel alone, the others must carry the evidence to name an effect
    # by themselves: a refit of the nominal parameters alone gains a few nats on a clean channel
    with np.errstate(invalid="ignore"):
        alone = bool(evidence.shown[strongest] > thresholds.noise_gap) and bool(
            np.all(np.nan_to_num(np.delete(evidence.shown, strongest), nan=0.0) <= thresholds.noise_gap)
        )
    needed = thresholds.score_threshold if alone else thresholds.cross_channel_gain
    if others >= needed:
        return None
    # the others' silence counts against the effect only where they could have seen it
    reach = float(np.sum(np.delete(evidence.reach, strongest))) if evidence.reach.size == gain.size else math.nan
    return ChannelCheck(False, strongest, "one_channel", float(gain[strongest]), others, needed, reach)


def check_channels(score: CandidateScore, rules: VerdictRules = DEFAULT_RULES) -> ChannelCheck:
    """The cross-channel rule (module docstring) for a scored candidate: what it predicts per channel against the rig.

    Examples
    --------
    A run-out read off the TE alone (both accelerometers gain nothing, though
    as fitted it would gain 55 nats there were it real) is one channel's:

    >>> from types import SimpleNamespace
    >>> score = SimpleNamespace(effect="eccentricity", channel_gains=(812.0, 0.4, -0.3),
    ...                         channel_gaps_before=(3.1, 0.0, 0.0), channel_gaps_after=(0.2, 0.0, 0.0),
    ...                         channel_reach=(900.0, 30.0, 25.0))
    >>> check = check_channels(score)
    >>> check.consistent, check.channel, check.kind, check.unseen
    (False, 0, 'one_channel', False)

    One too weak for the accelerometers to see is not told from the encoder's artefact:

    >>> check_channels(SimpleNamespace(**{**vars(score), "channel_reach": (900.0, 0.2, 0.1)})).unseen
    True
    """
    evidence = ChannelEvidence.of(score)
    if evidence.gain.size < 2:
        # one channel recorded: nothing to compare it with
        return ChannelCheck(True)
    unseen = predicts_unseen(evidence, rules.thresholds)
    if unseen is not None:
        return unseen
    if effect_family(score.effect).one_channel:
        return ChannelCheck(True)
    confined = confined_to_one(evidence, rules.thresholds)
    return ChannelCheck(True) if confined is None else confined


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


def ambiguity_of(score: CandidateScore, check: ChannelCheck) -> Ambiguity:
    """The two explanations of a gap on one channel whose other channels cannot see ``score``'s effect."""
    index = check.channel if check.channel is not None else 0
    channel = score.channels[index]
    family = hooks_of(score.effect)
    artefact, sensor = SENSOR_ARTEFACTS.get(channel, _ANY_SENSOR)
    reach = tuple(
        (name, float(value)) for position, (name, value) in enumerate(zip(score.channels, score.channel_reach))
        if position != index
    )
    return Ambiguity(
        effect=score.effect,
        channel=channel,
        artefact=family.look_alike(channel) or artefact,
        reach=reach,
        needed=check.needed,
        separated_by=(*family.separated_by(), sensor, _REFERENCE),
    )


def ambiguous_reason(score: CandidateScore, ambiguity: Ambiguity) -> str:
    """Why the verdict names neither of two explanations, in words: what each explains and what would separate them."""
    others = ", ".join(name for name, _ in ambiguity.reach)
    reach = sum(value for _, value in ambiguity.reach)
    return (
        f"{score.effect} explains the held-out gap on {ambiguity.channel} (it gains {score.score:.1f} nats of "
        f"held-out predictive density after its parameter penalty and shrinks the gap by "
        f"{100 * score.shrink_fraction:.0f} %), and {others} do not show it; but as fitted it would gain "
        f"{reach:.1f} nats on {others} together were it real, below the {ambiguity.needed:g} the cross-channel "
        f"rule asks of them, so they could not have seen it. {ambiguity.artefact[0].upper()}"
        f"{ambiguity.artefact[1:]} explains the data as well: these data cannot tell the two apart. {_SEPARATE}"
        + "; ".join(ambiguity.separated_by)
    )


def inconsistent_decision(
    best: CandidateScore,
    nominal_gap: float,
    borderline: tuple[dict[str, Any], ...],
    rules: VerdictRules,
    channels: ChannelCheck,
    *,
    explains: bool = False,
) -> Decision:
    """``none``, ``unexplained`` or ``inconclusive`` where the leading candidate fails the cross-channel rule.

    ``explains``: the candidate would be named but for this rule, and not
    ``partial``. Where it does and the other channels could not have seen it
    (:attr:`ChannelCheck.unseen`), a gap above noise is ``inconclusive``
    between the effect and the channel's own artefact.
    """
    why = inconsistency_reason(best, channels, best.channels)
    confined = channels.kind == "one_channel" and channels.channel is not None and channels.channel < len(best.channels)
    if confined and explains and channels.unseen and nominal_gap > rules.thresholds.noise_gap:
        ambiguity = ambiguity_of(best, channels)
        return Decision(
            "inconclusive",
            f"the nominal model's held-out gap is {nominal_gap:.2f} (above {rules.thresholds.noise_gap:g}); "
            f"{ambiguous_reason(best, ambiguity)}",
            borderline=borderline,
            one_channel=ambiguity.channel,
            ambiguity=ambiguity,
        )
    if nominal_gap <= rules.thresholds.noise_gap:
        return Decision(
            "none",
            f"the nominal model's held-out gap {nominal_gap:.2f} is within noise "
            f"(threshold {rules.thresholds.noise_gap:g}); "
            f"{why}",
            borderline=borderline,
        )
    return Decision(
        "unexplained",
        f"the nominal model's held-out gap is {nominal_gap:.2f} (above {rules.thresholds.noise_gap:g}); {why}",
        borderline=borderline,
        one_channel=best.channels[channels.channel] if confined and channels.channel is not None else "",
    )


def with_character(decision: Decision, families: Sequence[Mapping[str, Any]]) -> Decision:
    """A one-channel decision with its gap's character on that channel added to its reason.

    In an ambiguous verdict it goes before the measurements that would
    separate the two explanations, which end the reason.
    """
    text = one_channel_character(decision.one_channel, families)
    head, separate, tail = decision.reason.partition(_SEPARATE)
    if decision.ambiguity is None or not separate:
        return replace(decision, reason=decision.reason + text)
    return replace(decision, reason=f"{head.rstrip('. ')}{text}. {separate}{tail}")


def one_channel_character(channel: str, families: Sequence[Mapping[str, Any]]) -> str:
    """What a gap confined to one channel is made of: its families above noise with their character."""
    rows = [row for row in families if row["channel"] == channel and row["character"]]
    if not rows:
        return ""
    parts = [f"{row['family']} ({', '.join(row['character'])}; gap {row['score']:.2f})" for row in rows]
    return f"; on {channel} the gap lies in " + ", ".join(parts)


__all__ = [
    "SENSOR_ARTEFACTS",
    "ChannelCheck",
    "ChannelEvidence",
    "predicts_unseen",
    "confined_to_one",
    "check_channels",
    "inconsistency_reason",
    "ambiguity_of",
    "ambiguous_reason",
    "inconsistent_decision",
    "one_channel_character",
    "with_character",
]
