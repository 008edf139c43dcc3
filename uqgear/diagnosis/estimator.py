"""The Diagnosis estimator: settings checked in ``__init__``, the work in ``fit``, results in ``*_`` attributes.

``fit`` reads as the six steps of docs/model/unmodelled-effects.md section 6: steps 1 and 2
here (features: :mod:`.case` and :mod:`.allowances`; predictive distribution:
:mod:`.discrepancy`), steps 3 to 6 in :mod:`.pipeline`, which calls each fit in turn (fits:
:mod:`.nominal`, :mod:`.screening`, :mod:`.fitting`; held-out scoring: :mod:`.heldout`,
:mod:`.scoring`; several effects: :mod:`.selection`) and decides by the rules of
:mod:`.verdict`, built once per case. The fitted attributes are set in one place
(:meth:`~.fitted.FittedState._adopt`).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..common.steps import StepLog
from ..physics.design import Design
from .allowances.pitch_errors import DEFAULT_CLASSES, check_classes
from .allowances.reference import attach_reference, learn_reference
from .case import RigCase, prepare_case
from .change.estimator import ChangeDiagnosis
from .change.options import check_reference_options, is_differential
from .dataset import held_spectra, result_dataset, unfitted_dataset
from .decision import Decision
from .effects import check_effects
from .execution import RunExecutor
from .fitted import DiagnosisFit, FittedState, cpu_seconds, total_timings
from .gap_maps import uninformative_reason
from .inputs import (
    DiagnosisInputs,
    DiagnosisSeeds,
    ReferenceInput,
    check_settings,
    check_workers,
    read_inputs,
    resolve_design,
    split_seed,
)
from .outputs import completed, json_clean, summary
from .pipeline import diagnose_case
from .result import DiagnosisResult
from .scoring import capped_squares
from .settings import DiagnosisSettings


def _worst_runs(outcome: DiagnosisResult) -> list[int]:
    """The two runs the nominal model predicts worst on held-out runs, in run order (their spectra are kept)."""
    z = outcome.nominal_held.z
    worst = np.argsort([-np.nansum(capped_squares(z[op])) for op in range(outcome.case.n_op)])
    return sorted(int(op) for op in worst[:2])


def _features(
    inputs: DiagnosisInputs, *, settings: DiagnosisSettings, seeds: DiagnosisSeeds, workers: int, steps: StepLog
) -> tuple[RigCase, dict[str, Any] | None]:
    """Step 1: the campaign's features and noise models, with a healthy reference's correction where given.

    Returns the case and the reference's summary (None without a reference).
    """
    with steps.step("extract the rig features"):
        case = prepare_case(inputs.rig, inputs.design, seed=seeds.noise, settings=settings)
    if inputs.reference is None:
        return case, None
    learned = inputs.learned
    if learned is None:
        with steps.step("fit the nominal model to the reference campaign and learn its transfer correction") as found:
            learned = learn_reference(
                inputs.reference, inputs.design, source=inputs.reference_source, seed=seeds.reference, workers=workers
            )
            found.update(seconds=learned.summary["seconds"])
    with steps.step("correct the model features by the reference's transfer correction"):
        return attach_reference(
            case,
            learned,
            inputs.rig,
            speed_tolerance=settings.reference.speed_tolerance,
            torque_tolerance=settings.reference.torque_tolerance,
        )


def _cannot_decide(case: RigCase, settings: DiagnosisSettings, steps: StepLog) -> str | None:
    """Why the data cannot decide (no line above the noise floor in enough runs), or None."""
    with steps.step("check that the data can decide") as found:
        features = settings.features
        reason = uninformative_reason(case, snr=features.signal_snr, min_runs=features.min_informative_runs)
        found.update(informative=reason is None)
    return reason


class Diagnosis(FittedState):
    """Sim-to-real gap diagnosis of a rig campaign: where model and rig disagree, which effect explains it.

    Parameters
    ----------
    effects : sequence of str, optional
        Candidate effects (default: every registered family, :mod:`uqgear.diagnosis.effects`).
    settings : DiagnosisSettings, optional
        Thresholds and budgets (default: the documented ones).
    seed : int, SeedSequence or DiagnosisSeeds
        Seeds the noise calibration, the bootstrap and a reference's fit
        (children 0 to 2 of one seed, or a :class:`~.inputs.DiagnosisSeeds`).
    workers : int, optional
        Worker processes for the simulations (default: one per CPU, at most 8).
    design : Design, design file or name, optional
        The nominal design, replacing the rig file's (default: the file's).
    calibration : path or xarray.Dataset, optional
        A calibration of the campaign (``posterior.nc`` of ``uqgear calibrate``
        or its folder): the nominal fit starts from its posterior medians.
    pitch_classes : (float, float) or None
        ISO 1328-1 classes of the rig's gears (default 6 to 8; None: perfect gears).
    reference_route, reference_gears : str
        ``change``/``transfer``, ``same``/``replaced`` gears (docs/model/unmodelled-effects.md section 6.1).

    Attributes
    ----------
    nominal_ : FitResult or None
        The nominal model's fit (None when the data cannot decide).
    ranking_ : list of CandidateScore
        The best variant of each candidate effect, best first.
    effects_ : list of SelectedEffect
        The named effects in order, with their shares of the gap shrink.
    decision_ : Decision
        The verdict, its reason and the figures that decided it.
    remaining_gap_ : float
        The held-out gap the final model leaves.
    result_ : xarray.Dataset
        Gap maps over op x channel x family, scores, held-out spectra (``diagnosis.nc``).
    summary_ : dict
        The JSON-ready record (``diagnosis.json``); :meth:`to_dict` returns it.
    outcome_ : DiagnosisResult or None
        Everything found (None when the data cannot decide).
    change_ : ChangeOutcome or None
        Against a healthy reference: the change test and the effects' scores on it (else None).
    features_ : RigCase
        The campaign as compared after step 1 (features, line interference, a reference's correction).
    case_ : RigCase
        The campaign the verdict was reached on (with the pitch-error allowance where it applies).
    design_, steps_ : Design, StepLog
        The nominal design; the finished steps with what they found (kept by a failure).
    fitted_ : DiagnosisFit
        Everything above in one frozen record (:mod:`.fitted`).

    Examples
    --------
    >>> import uqgear
    >>> rig = uqgear.read_rig(uqgear.example_rig_file("eccentricity")).isel(op=[2, 4, 6], time=slice(0, 5120))
    >>> uqgear.Diagnosis(effects=["eccentricity"], workers=1).fit(rig).decision_.verdict
    'eccentricity'
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
        pitch_classes: tuple[float, float] | None = DEFAULT_CLASSES,
        reference_route: str = "change", reference_gears: str = "same",
    ) -> None:
        self.effects = check_effects(effects)
        self.settings = check_settings(settings)
        self.pitch_classes = check_classes(pitch_classes)
        self.seed, self.seeds = split_seed(seed)
        self.workers = check_workers(workers)
        # a design given replaces the file's before the file is read: its copy is then not validated
        self.design = None if design is None else resolve_design(design, None)
        self.calibration = calibration
        self.reference_route, self.reference_gears = check_reference_options(reference_route, reference_gears)

    def fit(self, rig: str | os.PathLike[str] | xr.Dataset, reference: ReferenceInput | None = None) -> Diagnosis:
        """Diagnose a rig campaign (optionally against a healthy reference campaign of the same rig).

        Parameters
        ----------
        rig : path or xarray.Dataset
            A ``uqgear-rig/1`` file or Dataset.
        reference : path, xarray.Dataset or ReferenceCorrection, optional
            A campaign of the same rig with a known good gearbox: what changed since it (a learned correction, or
            ``reference_route="transfer"``, corrects the model instead; docs/model/unmodelled-effects.md section 6.1).

        Returns
        -------
        Diagnosis
            ``self``, with the fitted attributes set.

        Raises
        ------
        RigDataError
            The rig data do not follow the format or carry no usable signal.
        DiagnosisError
            A reference of another design or test plan, a bad calibration posterior.
        InternalError
            A step failed after the input was accepted (``steps_`` holds the finished ones).
        """
        started, cpu_started = time.perf_counter(), cpu_seconds()
        self.steps_ = StepLog()  # the finished steps, kept when a later one fails
        if reference is not None and is_differential(self.reference_route, reference):
            # what changed since a healthy reference: the differential estimator's record is this one's
            return self._adopt(self._change_route().fit(rig, reference, steps=self.steps_).fitted_)
        inputs = read_inputs(rig, reference, design=self.design, calibration=self.calibration, settings=self.settings)
        # 1. features: the records reduced as the model's will be (with the allowances that act on them)
        case, reference_summary = _features(
            inputs, settings=self.settings, seeds=self.seeds, workers=self.workers, steps=self.steps_
        )
        # 2. predictive distribution: the case's noise models; valid data may still carry no signal
        reason = _cannot_decide(case, self.settings, self.steps_)
        if reason is not None:
            timings = total_timings({}, started, cpu_started, self.workers)
            undecided = Decision("inconclusive", reason)
            return self._adopt(self._undecided(case, undecided, inputs, reference_summary, timings))
        with self.steps_.step("start the worker processes"):
            executor = RunExecutor(case, self.workers)
        try:
            outcome = diagnose_case(
                case.with_executor(executor),
                inputs.posterior,
                effects=self.effects,
                settings=self.settings,
                pitch_classes=self.pitch_classes,
                seed=self.seeds.run,
                steps=self.steps_,
            )
            with self.steps_.step("simulate the held-out spectra"):
                spectra = held_spectra(outcome, _worst_runs(outcome))
        finally:
            executor.close()
        timings = total_timings(outcome.timings, started, cpu_started, self.workers)
        return self._adopt(self._fitted(outcome, spectra, case, inputs, reference_summary, timings))

    def _change_route(self) -> ChangeDiagnosis:
        """The differential diagnosis with this diagnosis's settings."""
        return ChangeDiagnosis(
            effects=self.effects,
            settings=self.settings,
            seed=self.seeds,
            workers=self.workers,
            design=self.design,
            calibration=self.calibration,
            gears=self.reference_gears,
        )

    def _fitted(
        self,
        outcome: DiagnosisResult,
        spectra: xr.Dataset,
        features: RigCase,
        inputs: DiagnosisInputs,
        reference_summary: dict[str, Any] | None,
        timings: dict[str, float],
    ) -> DiagnosisFit:
        """The record of a diagnosis that ran its six steps."""
        with self.steps_.step("summarise the results"):
            content = json_clean(
                summary(
                    outcome.case, outcome.decision, source=inputs.source, effects=outcome.effects,
                    seed_text=str(self.seed.entropy), timings=timings, settings=outcome.settings, result=outcome,
                )
            )
            start = "calibration posterior medians" if inputs.posterior is not None else "design values"
            content["nominal"]["start"] = start
            maps = result_dataset(outcome, spectra)
        content = completed(content, maps, inputs.design, reference_summary, inputs.rig)
        return DiagnosisFit(
            inputs.design, self.steps_, features, outcome.case, outcome.decision, content, maps, outcome=outcome
        )

    def _undecided(
        self,
        case: RigCase,
        decision: Decision,
        inputs: DiagnosisInputs,
        reference_summary: dict[str, Any] | None,
        timings: dict[str, float],
    ) -> DiagnosisFit:
        """The record of valid data that cannot decide: said so at once, without fitting noise."""
        with self.steps_.step("summarise the results"):
            content = json_clean(
                summary(
                    case, decision, source=inputs.source, effects=self.effects, seed_text=str(self.seed.entropy),
                    timings=timings, settings=self.settings,
                )
            )
            maps = unfitted_dataset(case, decision, self.effects)
        content = completed(content, maps, inputs.design, reference_summary, inputs.rig)
        return DiagnosisFit(inputs.design, self.steps_, case, case, decision, content, maps)


__all__ = ["Diagnosis"]
