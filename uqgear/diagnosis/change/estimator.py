"""The differential diagnosis as an estimator: what changed since a healthy reference, and which effect explains it.

:class:`ChangeDiagnosis` holds its settings from ``__init__``, does its work
in ``fit`` (the route of :mod:`.route`) and keeps what it found in the
fitted attributes of every diagnosis (:class:`~..fitted.FittedState`): the
same ``diagnosis.json`` keys and ``diagnosis.nc`` layout as a diagnosis
that fits the model, with no model fitted (``outcome_`` and ``nominal_``
None) and the change test in ``change_`` (docs/model/unmodelled-effects.md
section 6.1). :class:`~uqgear.diagnosis.Diagnosis` hands a reference
campaign to it by default.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from ...common.steps import StepLog
from ...physics.design import Design
from ..case import RigCase, prepare_case
from ..dataset import unfitted_dataset
from ..effects import check_effects
from ..errors import DiagnosisError
from ..fitted import DiagnosisFit, FittedState, cpu_seconds, total_timings
from ..inputs import (
    DiagnosisInputs,
    DiagnosisSeeds,
    ReferenceInput,
    check_settings,
    check_workers,
    read_inputs,
    resolve_design,
    split_seed,
)
from ..outputs import completed, json_clean, summary
from ..settings import DiagnosisSettings
from .options import check_reference_options
from .route import ChangeOutcome, change_dataset, diagnose_change


def _named_effect(named: dict[str, Any]) -> dict[str, Any]:
    """The named effect's entry of ``diagnosis.json``'s ``effects``: its variant, parameters and share of the change."""
    return {key: named[key] for key in ("effect", "variant", "parameters", "share")}


def change_record(
    case: RigCase,
    outcome: ChangeOutcome,
    inputs: DiagnosisInputs,
    *,
    effects: Sequence[str],
    seed_text: str,
    timings: dict[str, float],
    settings: DiagnosisSettings,
) -> tuple[dict[str, Any], xr.Dataset]:
    """``diagnosis.json``'s content and ``diagnosis.nc``'s data of a differential diagnosis.

    The record of a diagnosis that fitted no model (:func:`~..outputs.summary`,
    :func:`~..dataset.unfitted_dataset`) with the change's verdict, the
    named effect, the change test and scores (``change``) and the reference.
    """
    named = outcome.summary["named"]
    content = summary(
        case,
        outcome.decision,
        source=inputs.source,
        effects=effects,
        seed_text=seed_text,
        timings=timings,
        settings=settings,
        named=[_named_effect(named)] if named is not None else [],
    )
    content["change"] = outcome.summary
    content = json_clean(content)
    extra = change_dataset(outcome)
    maps = unfitted_dataset(case, outcome.decision, effects).assign_coords(dict(extra["coords"]))
    maps = maps.assign(dict(extra["data"]))
    reference = {"file": inputs.reference_source, "route": "change"}
    return completed(content, maps, inputs.design, reference, inputs.rig), maps


class ChangeDiagnosis(FittedState):
    """What changed in a rig since a healthy reference campaign of it, and which effect explains the change.

    No model is fitted to either campaign: the change is judged on
    condition-monitoring features, and each candidate effect is scored on
    the change it predicts (docs/model/unmodelled-effects.md section 6.1).

    Parameters
    ----------
    effects : sequence of str, optional
        Candidate effects (default: every registered family).
    settings : DiagnosisSettings, optional
        Thresholds (``settings.change`` above all; default: the documented ones).
    seed : int, SeedSequence or DiagnosisSeeds
        Seeds the noise models of the test campaign's features (as :class:`~uqgear.diagnosis.Diagnosis`).
    workers : int, optional
        Worker processes for the effects' simulations (default: one per CPU, at most 8).
    design : Design, design file or name, optional
        The nominal design, replacing the rig file's (default: the file's).
    calibration : path or xarray.Dataset, optional
        A calibration of the campaign, checked with the other inputs (the route fits no model).
    gears : str
        ``same`` (the reference's gears) or ``replaced`` (a new set of the same quality).

    Attributes
    ----------
    decision_ : Decision
        ``none`` (no change beyond what two healthy campaigns differ by), an
        effect, or ``unexplained``, with its reason.
    change_ : ChangeOutcome
        The change test and the effects' scores on it.
    summary_, result_ : dict, xarray.Dataset
        ``diagnosis.json``'s content and ``diagnosis.nc``'s data.
    outcome_, nominal_ : None
        No model is fitted; ``ranking_`` and ``effects_`` are empty, ``remaining_gap_`` NaN.
    features_, case_, design_, steps_, fitted_
        As :class:`~..fitted.FittedState`.

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.diagnosis.change.estimator import ChangeDiagnosis
    >>> runs = dict(op=[2, 4, 6], time=slice(0, 5120))
    >>> test = uqgear.read_rig(uqgear.example_rig_file("eccentricity")).isel(runs)
    >>> reference = uqgear.read_rig(uqgear.example_rig_file("healthy")).isel(runs)
    >>> fitted = ChangeDiagnosis(effects=["eccentricity"], workers=1).fit(test, reference)
    >>> fitted.decision_.verdict, fitted.nominal_ is None, fitted.summary_["reference"]["route"]
    ('eccentricity', True, 'change')
    """

    def __init__(
        self,
        *,
        effects: Sequence[str] | str | None = None,
        settings: DiagnosisSettings | None = None,
        seed: int | np.random.SeedSequence | DiagnosisSeeds = 0,
        workers: int | None = None,
        design: Design | str | os.PathLike[str] | None = None,
        calibration: str | os.PathLike[str] | xr.Dataset | None = None,
        gears: str = "same",
    ) -> None:
        self.effects = check_effects(effects)
        self.settings = check_settings(settings)
        self.seed, self.seeds = split_seed(seed)
        self.workers = check_workers(workers)
        self.design = None if design is None else resolve_design(design, None)
        self.calibration = calibration
        _, self.gears = check_reference_options("change", gears)

    def fit(
        self, rig: str | os.PathLike[str] | xr.Dataset, reference: ReferenceInput, *, steps: StepLog | None = None
    ) -> ChangeDiagnosis:
        """Judge what changed since the reference campaign and which effect explains it.

        Parameters
        ----------
        rig, reference : path or xarray.Dataset
            The test campaign and a campaign of the same rig with a known good
            gearbox (``uqgear-rig/1``). The inputs are read and checked first:
            the reference must cover at least one test run; its runs need not
            match the test's.
        steps : StepLog, optional
            The log the steps are kept in (default: a new one): a caller's log
            keeps the finished steps when a later one fails.

        Returns
        -------
        ChangeDiagnosis
            ``self``, with the fitted attributes set.
        """
        started, cpu_started = time.perf_counter(), cpu_seconds()
        settings = self.settings
        inputs = read_inputs(
            rig, reference, design=self.design, calibration=self.calibration, settings=settings, match_points=False
        )
        if inputs.reference is None:
            raise DiagnosisError("reference: expected a reference campaign (a rig file or Dataset); got a correction")
        steps = StepLog() if steps is None else steps
        with steps.step("extract the rig features"):
            case = prepare_case(inputs.rig, inputs.design, seed=self.seeds.noise, settings=settings)
        outcome = diagnose_change(
            inputs.rig,
            inputs.reference,
            inputs.design,
            self.effects,
            settings=settings,
            gears=self.gears,
            reference_source=inputs.reference_source,
            steps=steps,
            workers=self.workers,
        )
        with steps.step("summarise the results"):
            timings = dict(outcome.timings, order_tracking=case.tracking_s)
            content, maps = change_record(
                case,
                outcome,
                inputs,
                effects=self.effects,
                seed_text=str(self.seed.entropy),
                timings=total_timings(timings, started, cpu_started, self.workers),
                settings=settings,
            )
        return self._adopt(
            DiagnosisFit(inputs.design, steps, case, case, outcome.decision, content, maps, change=outcome)
        )


__all__ = ["ChangeDiagnosis", "change_record"]
