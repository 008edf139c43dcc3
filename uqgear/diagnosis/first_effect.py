"""Step 5: the first effect's decision on the candidates' held-out scores, and whether a set comes first.

:func:`decide_first` applies :func:`~.verdict.named.decide` with the case's
rules to the best score of each effect against the nominal model, with the
bootstrap intervals it draws and where the gap lies; :func:`starts_a_set` is the rule by which
step 6 starts a set from an unexplained gap's strongest candidate, and
:func:`set_comes_first` asks it before step 5 is taken, without drawing
from the diagnosis's random stream (docs/model/unmodelled-effects.md section
6, step 5, and section 6.2).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .decision import Decision
from .gap_maps import family_character, where_gap
from .scoring import CandidateScore, bootstrap_gap
from .state import DiagnosisState
from .verdict.cross_channel import with_character
from .verdict.named import decide, leads_a_set, ranked


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


def first_decision(
    state: DiagnosisState, best: Mapping[str, CandidateScore], rng: np.random.Generator
) -> tuple[Decision, list[CandidateScore], list[CandidateScore], tuple[float, float]]:
    """Step 5's decision on the best score per effect, its bootstrap intervals drawn from ``rng``.

    Returns the decision, the scores best first, the ranking (with the run-out checks, the
    leader with the bootstrap interval of its gap) and the nominal gap's bootstrap interval.
    """
    settings = state.settings
    scores = sorted(best.values(), key=lambda entry: -entry.score)
    ranking = ranked(best, state.rules)
    # drawn after the shrink bootstraps, so their numbers do not depend on this
    nominal_interval = bootstrap_gap(state.nominal_held.z, rng, settings.verdict.bootstrap_resamples)
    if scores:
        leader_interval = bootstrap_gap(scores[0].held.z, rng, settings.verdict.bootstrap_resamples)
        ranking[0] = replace(ranking[0], gap_interval=leader_interval)
    decision = decide(state.nominal_gap, ranking, state.rules, nominal_gap_interval=nominal_interval)
    return decision, scores, ranking, nominal_interval


def starts_a_set(state: DiagnosisState, decision: Decision, ranking: Sequence[CandidateScore]) -> bool:
    """Whether step 6 starts a set from the gap's strongest candidate (section 6.2).

    It does where a gap above noise is left unnamed (``unexplained``, an
    effect not told apart from a sensor's artefact, or ``none`` where the
    gap's interval reaches into noise) and the best
    candidate meets the evidence rules of :func:`leads_a_set`.
    """
    settings = state.settings
    unnamed_gap = decision.open_gap or (
        decision.verdict == "none" and state.nominal_gap > settings.verdict.noise_gap
    )
    return (
        unnamed_gap
        and bool(ranking)
        and leads_a_set(ranking[0], state.rules)
    )


def set_comes_first(state: DiagnosisState, best: Mapping[str, CandidateScore]) -> bool:
    """Whether, on these scores, step 6 would start a set from the gap's strongest candidate.

    The decision is made as :func:`decide_first` makes it, on a copy of the
    random stream: the state's stream is left where it was, so that the
    verdict drawn from it next is this one.
    """
    decision, _, ranking, _ = first_decision(state, best, copy.deepcopy(state.rng))
    return starts_a_set(state, decision, ranking)


def decide_first(
    state: DiagnosisState, best: Mapping[str, CandidateScore], locked_lines: Sequence[Mapping[str, Any]]
) -> FirstDecision:
    """The verdict on the candidates' held-out scores against the nominal model (step 5), and where the gap lies."""
    settings = state.settings
    with state.steps.step("decide the verdict") as found:
        decision, scores, ranking, nominal_interval = first_decision(state, best, state.rng)
        where = where_gap(state.nominal_held.z, state.case, where_z=settings.verdict.where_z)
        families = family_character(
            state.nominal_held.z,
            state.case,
            locked_lines,
            noise_gap=settings.verdict.noise_gap,
            where_z=settings.verdict.where_z,
        )
        if decision.one_channel:
            decision = with_character(decision, families)
        found.update(verdict=decision.verdict, reason=decision.reason)
    return FirstDecision(decision, scores, ranking, nominal_interval, where, families)


__all__ = ["FirstDecision", "first_decision", "starts_a_set", "set_comes_first", "decide_first"]
