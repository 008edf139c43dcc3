"""What a diagnosis found: the named effects in order, the forward-selection rounds, the whole result.

The records :func:`uqgear.diagnosis.pipeline.run_diagnosis` returns and
:mod:`.outputs` writes out.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from .case import RigCase
from .fitting import FitResult
from .manufacturing import PitchErrorAllowance, run_outs_not_told_apart
from .scoring import CandidateScore, HeldOut
from .sideband_phase import ModulationEvidence
from .verdict import Decision


@dataclass
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
        The rule that added it (:func:`decide` on top of its base).
    gap_interval : pair of float
        Bootstrap 5 % and 95 % quantiles of the held-out gap with it.
    """

    entry: CandidateScore
    gap_before: float
    shrink_share: float
    decision: Decision
    gap_interval: tuple[float, float] = (math.nan, math.nan)

    def summary(self) -> dict[str, Any]:
        """JSON-ready: effect, variant, fitted parameters with their 90 % intervals, shrink share, scores."""
        entry = self.entry
        return {"effect": entry.effect, "variant": entry.label, "parameters": entry.parameters(),
                "parameter_intervals": entry.parameter_intervals(), "shrink_share": self.shrink_share,
                "score": entry.score, "shrink_fraction": entry.shrink,
                "shrink_interval": [entry.shrink_low, entry.shrink_high], "gap_before": self.gap_before,
                "gap_after": entry.gap, "gap_after_interval": [float(v) for v in self.gap_interval],
                "effect_gain": entry.effect_gain, "fit": entry.stage,
                "partial": self.decision.partial}


@dataclass
class SelectionRound:
    """A forward-selection round after the first effect: what was tried on top of which base, and the outcome."""

    base: tuple[str, ...]
    gap_before: float
    scores: list[CandidateScore]          # best variant per effect against the base, best first
    added: str | None
    reason: str
    decision: Decision | None = None
    gap_interval: tuple[float, float] = (math.nan, math.nan)   # of the best candidate's held-out gap

    def summary(self) -> dict[str, Any]:
        return {"base": list(self.base), "gap_before": self.gap_before, "added": self.added, "reason": self.reason,
                "candidates": [{"effect": s.effect, "variant": s.label, "score": s.score,
                                "shrink_fraction": s.shrink, "shrink_interval": [s.shrink_low, s.shrink_high],
                                "gap_with_effect": s.gap, "effect_gain": s.effect_gain, "fit": s.stage,
                                "parameters": s.parameters()} for s in self.scores]}


@dataclass
class DiagnosisResult:
    """Everything a diagnosis found (see :func:`run_diagnosis`)."""

    case: RigCase
    nominal: FitResult
    nominal_held: HeldOut
    scores: list[CandidateScore]          # best variant per effect, ranked best first
    all_scores: list[CandidateScore]      # every variant and stage
    verdict: str
    reason: str
    nominal_gap: float
    where: list[dict[str, Any]]
    families: list[dict[str, Any]]
    locked_lines: list[dict[str, Any]]
    hints: dict[str, float]
    effects: tuple[str, ...]
    timings: dict[str, float]
    decision: Decision | None = None
    nominal_gap_interval: tuple[float, float] = (math.nan, math.nan)
    # forward selection: the named effects in order, the rounds after the first, and the final
    # model's held-out predictions (the nominal model's when nothing is named)
    selected: list[SelectedEffect] = field(default_factory=list)
    rounds: list[SelectionRound] = field(default_factory=list)
    final_held: HeldOut | None = None
    remaining_where: list[dict[str, Any]] = field(default_factory=list)
    remaining_families: list[dict[str, Any]] = field(default_factory=list)
    remaining_interval: tuple[float, float] = (math.nan, math.nan)
    pitch_errors: PitchErrorAllowance | None = None
    # the sideband phase-sum tests of the shafts with no eccentricity named (uqgear.diagnosis.sideband_phase)
    modulation: list[ModulationEvidence] = field(default_factory=list)

    @property
    def best(self) -> CandidateScore | None:
        return self.scores[0] if self.scores else None

    @property
    def final(self) -> CandidateScore | None:
        """The model with every named effect (None when none is named)."""
        return self.selected[-1].entry if self.selected else None

    @property
    def remaining_gap(self) -> float:
        """Held-out gap of the final model (the nominal model's when no effect is named)."""
        return self.selected[-1].entry.gap if self.selected else self.nominal_gap

    def ranking(self) -> list[dict[str, Any]]:
        """JSON-ready ranking, best first (``modulation_gain`` where it was measured)."""
        return [{**s.figures(), "variant": s.label, "delta_log_density": s.delta_log_density, "penalty": s.penalty,
                 "parameters": s.parameters(), "fit": s.stage} for s in self.scores]

    @property
    def named_shafts(self) -> list[str]:
        """The shafts whose eccentricity the diagnosis named."""
        return sorted({dict(candidate.choices)["shaft"] for chosen in self.selected
                       for candidate in chosen.entry.fit.problem.candidates if candidate.effect == "eccentricity"})

    def cannot_tell(self) -> list[dict[str, Any]]:
        """Run-outs the lines cannot tell from the gears' own pitch errors.

        The ``cannot_tell`` entries of ``diagnosis.json``
        (:func:`~uqgear.diagnosis.manufacturing.run_outs_not_told_apart`).
        """
        return run_outs_not_told_apart(self.pitch_errors, self.named_shafts)
