"""The nominal model fitted to the campaign, the pitch-error allowance taken in, and its held-out refits.

Step 3 of docs/model/unmodelled-effects.md section 6 for the nominal model: the fit (from the
design's values, or a calibration posterior's medians), the pitch-error
allowance where the rig's sidebands show pitch errors (and the nominal refit
it calls for), and the loop that scores the candidates against the nominal
fit and restarts that fit where a candidate's fit shows it stopped in a
local optimum.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np
import xarray as xr

from ..common.steps import StepLog
from ..uq.seeds import child_seed
from .allowances.pitch_errors import PitchErrorAllowance, pitch_error_allowance
from .case import RigCase
from .fitting import FitResult, calibration_start, fit, fit_nominal
from .heldout import HeldOut, leave_one_out
from .scoring import CandidateScore, gap_metric
from .screening import ScoredCandidates, improved_nominal, score_candidates
from .screening import fit_waiting as waiting_fits
from .settings import DiagnosisSettings
from .state import DiagnosisState
from .verdict.rules import VerdictRules

# Child of the diagnosis's run seed that draws the pitch errors (the bootstrap uses the seed itself).
PITCH_ERROR_STREAM = 7


def fit_nominal_model(
    case: RigCase,
    posterior: xr.Dataset | None,
    *,
    settings: DiagnosisSettings,
    steps: StepLog,
    timings: dict[str, float],
) -> tuple[RigCase, FitResult]:
    """The nominal fit, from a calibration posterior's medians where one is given (its backlash taken over).

    Returns the case (with the calibrated backlash in its design) and the fit.

    Raises
    ------
    DiagnosisError
        A calibration posterior without the nominal parameters (input: checked before the fit).
    """
    start, positions = None, None
    if posterior is not None:
        start, positions = calibration_start(posterior, case)
        if "backlash" in start:
            case = case.with_design(case.design.replace(backlash=start.pop("backlash")))
    clock = time.perf_counter()
    with steps.step("fit the nominal model") as found:
        budget = settings.nominal.nominal_evaluations
        nominal = (
            fit_nominal(case, max_evaluations=budget)
            if start is None
            else fit_nominal(case, max_evaluations=budget, start=start, positions=positions)
        )
        found.update(parameters=nominal.values, adhesion_torque=list(nominal.adhesion_torques), cost=nominal.cost)
    timings["nominal_fit"] += time.perf_counter() - clock
    return case, nominal


def allow_pitch_errors(
    case: RigCase,
    nominal: FitResult,
    *,
    classes: tuple[float, float] | None,
    seed: np.random.SeedSequence,
    settings: DiagnosisSettings,
    steps: StepLog,
    timings: dict[str, float],
) -> tuple[RigCase, FitResult, PitchErrorAllowance]:
    """The pitch-error allowance of ``classes`` taken into the case's model error, and the nominal model refitted.

    Where the allowance does not apply, the case and the fit come back as they were.
    """
    clock = time.perf_counter()
    with steps.step("allow for the gears' pitch errors") as found:
        allowance = pitch_error_allowance(
            case, nominal, classes=classes, seed=child_seed(seed, PITCH_ERROR_STREAM), settings=settings
        )
        found.update(applied=allowance.applied, reason=allowance.reason)
        if allowance.applied:
            case = allowance.apply(case)
            # the nominal parameters were pulled by what pitch errors did to the features: refit
            nominal = fit(
                nominal.problem.on_case(case),
                [nominal.vector],
                max_evaluations=settings.nominal.nominal_evaluations,
                tolerance=1e-3,
            ).after(nominal)
            found.update(parameters=nominal.values, cost=nominal.cost)
    timings["pitch_errors"] = time.perf_counter() - clock
    return case, nominal, allowance


def _checked_nominal(
    nominal: FitResult,
    fits: Sequence[FitResult],
    *,
    settings: DiagnosisSettings,
    steps: StepLog,
    timings: dict[str, float],
) -> FitResult | None:
    """:func:`~.screening.improved_nominal` of the full fits so far, a step of the log timed as the nominal fit."""
    clock = time.perf_counter()
    with steps.step("check the nominal fit against the candidate fits") as found:
        better = improved_nominal(nominal, fits, settings=settings)
        found.update(refitted=better is not None, full_fits=len(fits))
    timings["nominal_fit"] += time.perf_counter() - clock
    return better


@dataclass(frozen=True)
class NominalPasses:
    """The candidates scored against the last nominal fit, with what a later pass needs.

    ``state`` is the state of the last pass (its nominal fit), ``scored``
    its scores (:class:`~.screening.ScoredCandidates`; ``waiting`` the
    extra full fits that wait on a set), ``attempt`` the pass's number and
    ``earlier`` the full fits against earlier nominal fits, by label.
    """

    state: DiagnosisState
    scored: ScoredCandidates
    attempt: int
    earlier: Mapping[str, FitResult]

    @property
    def best(self) -> dict[str, CandidateScore]:
        return self.scored.best

    @property
    def all_scores(self) -> list[CandidateScore]:
        return self.scored.all_scores


def _held_out(nominal: FitResult, steps: StepLog, timings: dict[str, float]) -> tuple[HeldOut, float]:
    """The nominal fit's held-out predictions and gap, a step of the log timed as the nominal fit."""
    clock = time.perf_counter()
    with steps.step("predict held-out runs with the nominal model") as found:
        held = leave_one_out(nominal)
        gap = gap_metric(held.z)
        found.update(nominal_gap=gap)
    timings["nominal_fit"] += time.perf_counter() - clock
    return held, gap


def _escape(state: DiagnosisState, attempt: int) -> Callable[[Sequence[FitResult]], FitResult | None] | None:
    """The check of a pass's nominal fit against its full fits; none in the last pass allowed."""
    if attempt == state.settings.nominal.nominal_refits:
        return None
    return partial(_checked_nominal, state.nominal, settings=state.settings, steps=state.steps, timings=state.timings)


def _passes(
    state: DiagnosisState, scored: ScoredCandidates, attempt: int, earlier: dict[str, FitResult], *, set_first: bool
) -> NominalPasses:
    """Further passes while a pass's full fits find a better nominal fit (``scored.better``)."""
    while scored.better is not None:
        # the candidates were scored against a nominal fit stuck in a local optimum: score them again,
        # their full fits starting from where they got to as well
        earlier.update((entry.label, entry.fit) for entry in scored.all_scores if entry.stage == "full")
        attempt += 1
        nominal = scored.better
        held, gap = _held_out(nominal, state.steps, state.timings)
        state = replace(state.with_nominal(nominal, held, gap), earlier_full_fits=dict(earlier))
        scored = score_candidates(state, escape=_escape(state, attempt), set_first=set_first)
    return NominalPasses(state, scored, attempt, earlier)


def score_against_nominal(
    case: RigCase,
    nominal: FitResult,
    *,
    effects: tuple[str, ...],
    hints: Mapping[str, float],
    rng: np.random.Generator,
    settings: DiagnosisSettings,
    rules: VerdictRules,
    steps: StepLog,
    timings: dict[str, float],
) -> NominalPasses:
    """Every candidate scored against the nominal fit's held-out predictions (:func:`~.screening.score_candidates`).

    Where a candidate's full fit shows that the nominal fit stopped in a
    local optimum (:func:`~.screening.improved_nominal`), the nominal model
    is refitted from there and the candidates are scored again against it,
    at most ``nominal_refits`` times. The check comes as soon as the
    promoted candidates are fitted in full: once the nominal fit is known to
    be stuck, the pass's further full fits against it are not made
    (:func:`~.screening.score_candidates`). The last pass's extra full fits
    may wait on a set (``waiting``; :func:`fit_waiting`).

    ``rules`` are the case's verdict rules (:func:`~.verdict.rules.verdict_rules`).
    Returns the state the later steps share with the best score per effect and every score.
    """
    held, gap = _held_out(nominal, steps, timings)
    state = DiagnosisState(case, settings, rules, effects, hints, rng, steps, timings, nominal, held, gap)
    scored = score_candidates(state, escape=_escape(state, 0))
    return _passes(state, scored, 0, {}, set_first=True)


def fit_waiting(passes: NominalPasses) -> NominalPasses:
    """The extra full fits that waited on a set that explains nothing together (:func:`~.screening.fit_waiting`).

    Where they show the nominal fit stuck, the passes go on from the better
    fit as in :func:`score_against_nominal`, their extra fits no longer
    waiting on a set: the set was tried.
    """
    state = passes.state
    scored = waiting_fits(state, passes.scored, escape=_escape(state, passes.attempt))
    return _passes(state, scored, passes.attempt, dict(passes.earlier), set_first=False)


__all__ = [
    "PITCH_ERROR_STREAM",
    "fit_nominal_model",
    "allow_pitch_errors",
    "NominalPasses",
    "score_against_nominal",
    "fit_waiting",
]
