"""Everything a diagnosis found: the nominal fit, the ranked candidates, the decision and the named set.

The record :class:`~uqgear.diagnosis.Diagnosis` keeps as ``outcome_`` and
:mod:`.outputs` writes out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from .allowances.pitch_errors import PitchErrorAllowance, run_outs_not_told_apart
from .allowances.sideband_phase import ModulationEvidence
from .case import RigCase
from .decision import Decision
from .effect_set import SelectedEffect, SelectionRound
from .effects import hooks_of
from .fitting import FitResult
from .heldout import HeldOut
from .scoring import CandidateScore
from .settings import DEFAULT_SETTINGS, DiagnosisSettings


@dataclass(frozen=True)
class DiagnosisResult:
    """Everything a diagnosis found (the record of :meth:`uqgear.diagnosis.Diagnosis.fit`)."""

    case: RigCase
    nominal: FitResult
    nominal_held: HeldOut
    scores: list[CandidateScore]  # best variant per effect, ranked best first
    all_scores: list[CandidateScore]  # every variant and stage
    decision: Decision
    nominal_gap: float
    where: list[dict[str, Any]]
    families: list[dict[str, Any]]
    locked_lines: list[dict[str, Any]]
    hints: dict[str, float]
    effects: tuple[str, ...]
    timings: dict[str, float]
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
    # the sideband phase-sum tests of the shafts with no eccentricity named (allowances.sideband_phase)
    modulation: list[ModulationEvidence] = field(default_factory=list)
    settings: DiagnosisSettings = DEFAULT_SETTINGS

    @property
    def verdict(self) -> str:
        return self.decision.verdict

    @property
    def reason(self) -> str:
        return self.decision.reason

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
        return self.selected[-1].entry.gap_with_effect if self.selected else self.nominal_gap

    def ranking(self) -> list[dict[str, Any]]:
        """JSON-ready ranking, best first (``modulation_gain`` where it was measured)."""
        return [
            {
                **s.figures(),
                "variant": s.label,
                "delta_log_density": s.delta_log_density,
                "penalty": s.penalty,
                "parameters": s.parameters(),
                "fit": s.stage,
            }
            for s in self.scores
        ]

    @property
    def named_shafts(self) -> list[str]:
        """The shafts whose run-out the diagnosis named (effects with a :attr:`~.effects.EffectFamily.run_out` hook)."""
        shafts = (
            hooks_of(candidate.effect).run_out_shaft(dict(candidate.choices))
            for chosen in self.selected
            for candidate in chosen.entry.fit.problem.candidates
        )
        return sorted({shaft for shaft in shafts if shaft is not None})

    def cannot_tell(self) -> list[dict[str, Any]]:
        """Run-outs the lines cannot tell from the gears' own pitch errors.

        The ``cannot_tell`` entries of ``diagnosis.json``
        (:func:`~uqgear.diagnosis.allowances.pitch_errors.run_outs_not_told_apart`).
        """
        return run_outs_not_told_apart(
            self.pitch_errors, self.named_shafts, share_threshold=self.settings.pitch.large_run_out_share
        )


__all__ = ["DiagnosisResult", "SelectedEffect", "SelectionRound"]
