"""Step 5's record: the first effect's decision, the figures it was made on, and where the gap lies.

The decision itself is the orchestrator's (:mod:`.pipeline`), by the rules of
:mod:`.verdict` (docs/model/unmodelled-effects.md section 6, step 5).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .decision import Decision
from .gap_maps import family_character, where_gap
from .scoring import CandidateScore
from .state import DiagnosisState


@dataclass(frozen=True)
class FirstDecision:
    """Step 5's outcome: the first effect's decision and the figures it was made on.

    Attributes
    ----------
    decision : Decision
    scores : list of CandidateScore
        The best variant of each effect, best first.
    ranking : list of CandidateScore
        The same with their run-out checks, the leader with the bootstrap interval of its gap.
    nominal_gap_interval : (float, float)
        Bootstrap 5 % and 95 % quantiles of the nominal model's held-out gap.
    where, families : list of dict
        Where the nominal model's held-out gap lies (:func:`~.gap_maps.where_gap`,
        :func:`~.gap_maps.family_character`).
    """

    decision: Decision
    scores: list[CandidateScore]
    ranking: list[CandidateScore]
    nominal_gap_interval: tuple[float, float]
    where: list[dict[str, Any]]
    families: list[dict[str, Any]]

    @property
    def leader_gap_interval(self) -> tuple[float, float]:
        """The leader's gap interval (NaN without a candidate)."""
        interval = self.ranking[0].gap_interval if self.ranking else None
        return interval if interval is not None else (math.nan, math.nan)


def nominal_gap_maps(
    state: DiagnosisState, locked_lines: Sequence[Mapping[str, Any]]
) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """Where the nominal model's held-out gap lies: cells beyond ``where_z``, and each family's character."""
    settings = state.settings
    where = where_gap(state.nominal_held.z, state.case, where_z=settings.verdict.where_z)
    families = family_character(
        state.nominal_held.z,
        state.case,
        locked_lines,
        noise_gap=settings.verdict.noise_gap,
        where_z=settings.verdict.where_z,
    )
    return where, families


__all__ = ["FirstDecision", "nominal_gap_maps"]
