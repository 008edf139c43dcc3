"""The nominal model fitted to the campaign, the pitch-error allowance taken in, its held-out predictions.

Step 3 of docs/model/unmodelled-effects.md section 6 for the nominal model: the fit (from the
design's values, or a calibration posterior's medians), the pitch-error
allowance where the rig's sidebands show pitch errors (and the nominal refit
it calls for), the held-out predictions of a nominal fit, and the check
whether the candidates' full fits show that it stopped in a local optimum.
The passes that refit it from there are the orchestrator's (:mod:`.pipeline`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
import xarray as xr

from ..common.steps import StepLog
from ..uq.seeds import child_seed
from .allowances.pitch_errors import PitchErrorAllowance, pitch_error_allowance
from .case import RigCase
from .fitting import FitResult, calibration_start, fit, fit_nominal
from .heldout import HeldOut, leave_one_out
from .scoring import gap_metric
from .screening import improved_nominal
from .settings import DiagnosisSettings
from .state import DiagnosisState

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


def check_nominal(state: DiagnosisState, fits: Sequence[FitResult]) -> FitResult | None:
    """:func:`~.screening.improved_nominal` of the full fits so far, a step of the log timed as the nominal fit."""
    clock = time.perf_counter()
    with state.steps.step("check the nominal fit against the candidate fits") as found:
        better = improved_nominal(state.nominal, fits, settings=state.settings)
        found.update(refitted=better is not None, full_fits=len(fits))
    state.timings["nominal_fit"] += time.perf_counter() - clock
    return better


def nominal_held_out(nominal: FitResult, steps: StepLog, timings: dict[str, float]) -> tuple[HeldOut, float]:
    """The nominal fit's held-out predictions and gap, a step of the log timed as the nominal fit."""
    clock = time.perf_counter()
    with steps.step("predict held-out runs with the nominal model") as found:
        held = leave_one_out(nominal)
        gap = gap_metric(held.z)
        found.update(nominal_gap=gap)
    timings["nominal_fit"] += time.perf_counter() - clock
    return held, gap


__all__ = [
    "PITCH_ERROR_STREAM",
    "fit_nominal_model",
    "allow_pitch_errors",
    "check_nominal",
    "nominal_held_out",
]
