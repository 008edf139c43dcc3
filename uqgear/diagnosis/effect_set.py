"""The named effect set: each effect in the order forward selection added it, and each round that tried more."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ..physics.effect_draws import UncertainEffect
from ..physics.effects import Effect
from .decision import Decision
from .scoring import CandidateScore


@dataclass(frozen=True)
class SelectedEffect:
    """One effect of the named set, in the order forward selection added it.

    Attributes
    ----------
    entry : CandidateScore
        Its best fit with the effects named before it (its base) and its
        held-out scores against the base's held-out predictions.
    gap_before : float
        Held-out gap of the base (the nominal model's for the first effect).
    shrink_share : float
        How far it shrank the held-out gap, as a fraction of the nominal
        model's gap: (gap_before - gap with it) / nominal gap. The shares of
        the set add up to 1 - final gap / nominal gap.
    decision : Decision
        The rule that added it (:func:`~.verdict.named.decide` on top of its base).
    gap_interval : pair of float
        Bootstrap 5 % and 95 % quantiles of the held-out gap with it.
    choices : mapping of str to tuple of float
        Parameters the fit leaves open, with the values each can take (its
        family's :meth:`~.effects.base.EffectFamily.open_choices`).
    """

    entry: CandidateScore
    gap_before: float
    shrink_share: float
    decision: Decision
    gap_interval: tuple[float, float] = (math.nan, math.nan)
    choices: Mapping[str, tuple[float, ...]] = field(default_factory=dict)

    def to_uncertain(self) -> UncertainEffect:
        """The effect with its fitted parameters and their 90 % intervals (what a prediction samples)."""
        entry = self.entry
        intervals = {name: (low, high) for name, (low, high) in entry.parameter_intervals().items()}
        return UncertainEffect(entry.effect, entry.parameters(), intervals, self.choices)

    def to_effect(self) -> Effect:
        """The effect at its fitted parameters (``BatchEvaluator(..., effects=diagnosis.effects_)``)."""
        return self.to_uncertain().central()

    def summary(self) -> dict[str, Any]:
        """JSON-ready: effect, variant, fitted parameters with their 90 % intervals, shrink share, scores."""
        entry = self.entry
        choices = {key: list(values) for key, values in self.choices.items()}
        return {
            "effect": entry.effect,
            "variant": entry.label,
            "parameters": entry.parameters(),
            "parameter_intervals": entry.parameter_intervals(),
            **({"parameter_choices": choices} if choices else {}),
            "shrink_share": self.shrink_share,
            "score": entry.score,
            "shrink_fraction": entry.shrink_fraction,
            "shrink_interval": list(entry.shrink_interval),
            "gap_before": self.gap_before,
            "gap_after": entry.gap_with_effect,
            "gap_after_interval": [float(v) for v in self.gap_interval],
            "effect_gain": entry.effect_gain,
            "fit": entry.stage,
            "partial": self.decision.partial,
        }


@dataclass(frozen=True)
class SelectionRound:
    """A forward-selection round after the first effect: what was tried on top of which base, and the outcome."""

    base: tuple[str, ...]
    gap_before: float
    scores: list[CandidateScore]  # best variant per effect against the base, best first
    added: str | None
    reason: str
    decision: Decision | None = None
    gap_interval: tuple[float, float] = (math.nan, math.nan)  # of the best candidate's held-out gap

    def summary(self) -> dict[str, Any]:
        """JSON-ready: the base, what was tried on top of it and whether it was added."""
        return {
            "base": list(self.base),
            "gap_before": self.gap_before,
            "added": self.added,
            "reason": self.reason,
            "candidates": [
                {
                    "effect": s.effect,
                    "variant": s.label,
                    "score": s.score,
                    "shrink_fraction": s.shrink_fraction,
                    "shrink_interval": list(s.shrink_interval),
                    "gap_with_effect": s.gap_with_effect,
                    "effect_gain": s.effect_gain,
                    "fit": s.stage,
                    "parameters": s.parameters(),
                }
                for s in self.scores
            ],
        }


__all__ = ["SelectedEffect", "SelectionRound"]
