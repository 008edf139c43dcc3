"""The diagnosis from its inputs to its files: read and check the inputs, run, write the results."""

from __future__ import annotations

import json
import os
import resource
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..common.errors import InternalError, RigDataError
from ..common.fileio import write_text_atomic
from ..common.steps import StepLog, write_failure_record
from ..physics.design import Design
from ..uq.results import json_default, load_result, save_result
from ..uq.seeds import as_seed_sequence
from .case import RunExecutor, prepare_case
from .errors import DiagnosisError
from .outputs import _held_spectra, _json_clean, inconclusive_dataset, inconclusive_summary, result_dataset, summary
from .manufacturing import DEFAULT_CLASSES, check_classes
from .pipeline import _check_effects, run_diagnosis
from .scoring import capped_squares
from .verdict import MIN_INFORMATIVE_RUNS, uninformative_reason

if TYPE_CHECKING:
    from .reference import ReferenceCorrection

def _cpu_seconds() -> float:
    """CPU time of this process and of its finished worker processes, s."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _as_seed(seed: int | np.random.SeedSequence) -> np.random.SeedSequence:
    return as_seed_sequence(seed, error=DiagnosisError)


def load_rig_input(rig: str | os.PathLike[str] | xr.Dataset, *,
                   design: Design | None = None) -> tuple[xr.Dataset, str]:
    """A validated rig Dataset from a path or a Dataset, and a text naming its source.

    A ``design`` given replaces the file's: the file's ``design`` attribute is
    then not validated as a design (:func:`uqgear.rig.format.validate_rig`).

    Besides the format, the campaign must carry signal the diagnosis can use
    (:func:`uqgear.rig.usability.check_usable_signal`): records that are
    neither missing nor constant, at least one pinion revolution long, in at
    least two operating points (each is predicted by a fit to the others).

    Raises
    ------
    RigDataError
        Not a rig file or Dataset, not in the format, or no usable signal.
    """
    from ..rig.format import read_rig, validate_rig
    from ..rig.usability import check_usable_signal

    if isinstance(rig, xr.Dataset):
        validate_rig(rig, where="rig data", design=design)
        dataset, source = rig, str(rig.attrs.get("title", "rig Dataset"))
        where = "rig data"
    elif isinstance(rig, (str, os.PathLike)):
        dataset, source = read_rig(rig, design=design), str(rig)
        where = source
    else:
        raise RigDataError(f"rig: expected a uqgear-rig/1 file path or an xarray Dataset; got {type(rig).__name__}")
    check_usable_signal(dataset, where=where, min_operating_points=MIN_INFORMATIVE_RUNS, purpose="the diagnosis",
                        why="each operating point is predicted by the model fitted to the others")
    return dataset, source


def _resolve_design(design: Design | str | os.PathLike[str] | None, rig: xr.Dataset | None) -> Design:
    from ..physics.design import load_design
    from ..rig.format import rig_design

    if design is None:
        return rig_design(rig)
    if isinstance(design, Design):
        return design
    if isinstance(design, (str, os.PathLike)):
        return load_design(str(design))
    raise DiagnosisError(f"design: expected a Design, a design file or name, or None (the rig file's design); "
                         f"got {type(design).__name__}")



def load_calibration(calibration: str | os.PathLike[str] | xr.Dataset) -> xr.Dataset:
    """A calibration posterior from a Dataset, a ``posterior.nc`` file or the folder holding it."""
    if isinstance(calibration, xr.Dataset):
        return calibration
    if not isinstance(calibration, (str, os.PathLike)):
        raise DiagnosisError(f"calibration: expected a posterior.nc path, its folder or a Dataset; "
                             f"got {type(calibration).__name__}")
    path = Path(calibration)
    if path.is_dir():
        path = path / "posterior.nc"
    if not path.is_file():
        raise DiagnosisError(f"calibration: {path}: no such file (expected posterior.nc of uqgear calibrate)")

    return load_result(path)



def load_reference(reference: "str | os.PathLike[str] | xr.Dataset | ReferenceCorrection", test: xr.Dataset, *,
                   design: Design | None = None) -> "tuple[xr.Dataset, str, ReferenceCorrection | None]":
    """A healthy reference campaign, checked against the test campaign before any work.

    Returns the reference Dataset, the text naming it and, when ``reference``
    is an already learned :class:`~uqgear.diagnosis.reference.ReferenceCorrection`
    (to reuse one reference for several test campaigns), that correction.

    Raises
    ------
    RigDataError
        The reference is not a rig file or Dataset in the format, or carries no usable signal.
    DiagnosisError
        Its design or channels differ from the test campaign's, or a test
        operating point has no reference point at the same speed and torque
        (:mod:`uqgear.diagnosis.reference`).
    """
    from .reference import ReferenceCorrection, check_design_match, match_operating_points

    learned = None
    if isinstance(reference, ReferenceCorrection):
        learned, dataset, source = reference, reference.rig, reference.source
    elif isinstance(reference, (str, os.PathLike)):
        if not Path(reference).is_file():
            raise DiagnosisError(f"reference: {reference}: no such file (expected a uqgear-rig/1 campaign of the "
                                 "same rig with a healthy gearbox)")
        dataset, source = load_rig_input(reference, design=design)
    elif isinstance(reference, xr.Dataset):
        dataset, source = load_rig_input(reference, design=design)
    else:
        raise DiagnosisError(f"reference: expected a uqgear-rig/1 file path or an xarray Dataset; "
                             f"got {type(reference).__name__}")
    check_design_match(test, dataset, where=source)
    match_operating_points(test, dataset, where=source)
    return dataset, source, learned


def diagnosis_result(rig: str | os.PathLike[str] | xr.Dataset, *,
                     design: Design | str | os.PathLike[str] | None = None, effects: Sequence[str] | None = None,
                     seed: int | np.random.SeedSequence = 0, workers: int | None = None,
                     calibration: str | os.PathLike[str] | xr.Dataset | None = None,
                     reference: "str | os.PathLike[str] | xr.Dataset | ReferenceCorrection | None" = None,
                     pitch_classes: tuple[float, float] | None = DEFAULT_CLASSES
                     ) -> tuple[dict[str, Any], xr.Dataset]:
    """Diagnose the sim-to-real gap of a rig campaign without writing anything.

    Parameters are those of :func:`diagnose` (less the output options).

    Returns
    -------
    (content, maps) : tuple of dict and xarray.Dataset
        The content of ``diagnosis.json`` and the Dataset of ``diagnosis.nc``
        (gap maps over op x channel x family, scores, held-out spectra).
    """
    content, maps, _ = _diagnosis(rig, design=design, effects=effects, seed=seed, workers=workers,
                                  calibration=calibration, reference=reference, steps=StepLog(),
                                  pitch_classes=pitch_classes)
    return content, maps


def _diagnosis(rig, *, design, effects, seed, workers, calibration, steps: StepLog, reference=None,
               pitch_classes: tuple[float, float] | None = DEFAULT_CLASSES
               ) -> tuple[dict[str, Any], xr.Dataset, Design]:
    started = time.perf_counter()
    cpu_started = _cpu_seconds()
    # the input first, all of it: a mistake in it is the user's (exit 2) and costs no work
    effect_names = _check_effects(effects)
    pitch_classes = check_classes(pitch_classes)
    seed_sequence = _as_seed(seed)
    workers = _check_workers(workers)
    # a design given replaces the file's before the file is read: its copy is then not validated
    given = None if design is None else _resolve_design(design, None)
    dataset, source = load_rig_input(rig, design=given)
    nominal_design = given if given is not None else _resolve_design(None, dataset)
    posterior = load_calibration(calibration) if calibration is not None else None
    if reference is not None:
        reference_data, reference_source, learned = load_reference(reference, dataset, design=given)
    noise_seed, run_seed = seed_sequence.spawn(2)
    # from here on the input is accepted: a failure is ours, reported with its step
    with steps.step("extract the rig features"):
        case = prepare_case(dataset, nominal_design, seed=noise_seed)
    reference_summary = None
    if reference is not None:
        from .reference import attach_reference, learn_reference

        if learned is None:
            with steps.step("fit the nominal model to the reference campaign and learn its transfer correction") \
                    as found:
                # spawned after the others: a diagnosis without a reference draws the same numbers
                learned = learn_reference(reference_data, nominal_design, source=reference_source,
                                          seed=seed_sequence.spawn(1)[0], workers=workers)
                found.update(seconds=learned.summary["seconds"])
        with steps.step("correct the model features by the reference's transfer correction"):
            reference_summary = attach_reference(case, learned, dataset)
    with steps.step("check that the data can decide") as found:
        reason = uninformative_reason(case)
        found.update(informative=reason is None)
    if reason is not None:
        # valid data that cannot decide: said so at once, without minutes of fitting noise
        with steps.step("summarise the results"):
            timings = {"total_wall": time.perf_counter() - started, "total_cpu": _cpu_seconds() - cpu_started,
                       "workers": float(workers)}
            content = _json_clean(inconclusive_summary(case, reason, source=source, effects=effect_names,
                                                       seed_text=str(seed_sequence.entropy), timings=timings))
            maps = inconclusive_dataset(case, reason, effect_names)
            _add_reference(content, maps, reference_summary)
        return _noted(content, nominal_design), maps, nominal_design
    with steps.step("start the worker processes"):
        case.executor = RunExecutor(case, workers)
    try:
        result = run_diagnosis(case, effects=effect_names, seed=run_seed, calibration=posterior, steps=steps,
                               pitch_classes=pitch_classes)
        with steps.step("simulate the held-out spectra"):
            worst = np.argsort([-np.nansum(capped_squares(result.nominal_held.z[op])) for op in range(case.n_op)])
            spectra = _held_spectra(result, sorted(int(op) for op in worst[:2]))
    finally:
        case.executor.close()
        case.executor = None
    with steps.step("summarise the results"):
        timings = dict(result.timings, total_wall=time.perf_counter() - started,
                       total_cpu=_cpu_seconds() - cpu_started, workers=float(workers))
        content = _json_clean(summary(result, source=source, seed_text=str(seed_sequence.entropy), timings=timings))
        content["nominal"]["start"] = "calibration posterior medians" if posterior is not None else "design values"
        maps = result_dataset(result, spectra)
        maps.attrs["verdict"] = content["verdict"]
        _add_reference(content, maps, reference_summary)
    return _noted(content, nominal_design), maps, nominal_design


def _add_reference(content: dict[str, Any], maps: xr.Dataset, summary: dict[str, Any] | None) -> None:
    """The reference campaign's fit and learned correction in ``diagnosis.json`` (``reference``) and maps' attrs."""
    if summary is None:
        return
    content["reference"] = _json_clean(summary)
    maps.attrs["reference"] = str(summary["file"])
    if isinstance(content.get("timing_s"), dict):
        content["timing_s"]["reference_fit"] = summary["seconds"]


def _noted(content: dict[str, Any], design: Design) -> dict[str, Any]:
    """``content`` with ``design_notes``: what the model did with the design's geometry (an undercut tooth)."""
    from ..physics.geometry import geometry_notes

    content["design_notes"] = geometry_notes(design)
    return content


def default_workers() -> int:
    """Worker processes by default: one per CPU this process may use, at most 8.

    Runs are single-threaded (:class:`~.case.RunExecutor`), so each CPU gets
    a worker: on 2 CPUs two workers diagnose an 8-run campaign about 1.5x
    faster than one (benchmarks/diagnosis.py). Beyond 8 a fit's batches
    (one run per operating point and parameter) no longer keep them busy.
    """
    try:
        available = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        available = os.cpu_count() or 1
    return max(1, min(available, 8))


def _check_workers(workers: int | None) -> int:
    if workers is None:
        return default_workers()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise DiagnosisError(f"workers: expected an integer >= 1; got {workers!r}")
    return int(workers)


def make_out_dir(out_dir: str | os.PathLike[str]) -> Path:
    """The output folder, created if missing (DiagnosisError when it cannot be)."""
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DiagnosisError(f"out_dir: cannot create {out} ({exc})") from None
    return out


def diagnose(rig: str | os.PathLike[str] | xr.Dataset, out_dir: str | os.PathLike[str], *,
             design: Design | str | os.PathLike[str] | None = None, effects: Sequence[str] | None = None,
             seed: int | np.random.SeedSequence = 0, workers: int | None = None,
             calibration: str | os.PathLike[str] | xr.Dataset | None = None, report: bool = True,
             reference: "str | os.PathLike[str] | xr.Dataset | ReferenceCorrection | None" = None,
             pitch_classes: tuple[float, float] | None = DEFAULT_CLASSES) -> dict[str, Any]:
    """Diagnose the sim-to-real gap of a rig campaign and write the results.

    Parameters
    ----------
    rig : path or xarray.Dataset
        A ``uqgear-rig/1`` file or Dataset.
    out_dir : path
        Output folder (created if missing): ``diagnosis.json``,
        ``diagnosis.nc`` (gap maps, scores, spectra) and ``report.html``,
        each written atomically.
    design : Design, design file or name, optional
        The nominal design; by default the rig file's ``design`` attribute.
        When given it replaces the file's, which is then not validated as a
        design (it may even hold one that uqgear refuses).
    effects : sequence of str, optional
        Candidate effects (default: all six of the library).
    seed : int or SeedSequence
        Seeds the noise calibration and the bootstrap.
    workers : int, optional
        Worker processes for the simulations (default: one per CPU, at most 8, :func:`default_workers`).
    calibration : path or xarray.Dataset, optional
        A calibration of this campaign (``posterior.nc`` of ``uqgear
        calibrate``, or its folder): the nominal fit starts from its posterior
        medians (backlash included) instead of the design's values.
    report : bool
        Write ``report.html``.
    reference : path or xarray.Dataset, optional
        A campaign of the same rig recorded with a known good gearbox
        (:mod:`uqgear.diagnosis.reference`): what it shows against the fitted
        nominal model (the rig's transfer paths, its own structure) is
        learned per channel as a gain over frequency, with its uncertainty,
        and carried to this campaign, so that the diagnosis names what
        changed between the two. Same design and channels, and a reference
        run at the same speed (1 %) and drive torque (5 %) for every run, or
        it is refused. What was learned is ``reference`` in ``diagnosis.json``.
        An already learned
        :class:`~uqgear.diagnosis.reference.ReferenceCorrection` is reused as it is.
    pitch_classes : (float, float) or None
        ISO 1328-1 flank tolerance classes (finest, coarsest) the gears are
        made to, default 6 to 8. Where the rig's sidebands show pitch errors
        on both shafts, what random pitch errors of these classes do to each
        feature is model error of the nominal model, so that no effect is
        named for what a manufactured gear's pitch errors can do
        (:mod:`uqgear.diagnosis.manufacturing`; ``pitch_errors`` in
        ``diagnosis.json``). None: perfect gears.

    Returns
    -------
    dict
        The content of ``diagnosis.json``: ``verdict``, ``gap``, ``where``,
        ``ranking`` and more.

    Raises
    ------
    RigDataError
        The rig file or Dataset does not follow the format, or carries no
        usable signal (all missing or constant, records shorter than a pinion
        revolution, fewer than two operating points).
    DiagnosisError
        An unknown effect, a bad seed, design or worker count; a reference
        campaign of another design or test plan.
    InternalError
        A step failed after the input was accepted. The outputs finished
        before stay in ``out_dir``, with ``failure.json`` (the failed step,
        the error and its traceback, the finished steps and what they found);
        the error's ``kept`` names the folder.
    """
    # the cheap checks first: a bad option or folder fails before minutes of fitting
    _check_effects(effects)
    check_classes(pitch_classes)
    _as_seed(seed)
    _check_workers(workers)
    out = make_out_dir(out_dir)
    steps = StepLog()
    try:
        content, maps, nominal_design = _diagnosis(rig, design=design, effects=effects, seed=seed,
                                                   workers=workers, calibration=calibration, steps=steps,
                                                   reference=reference, pitch_classes=pitch_classes)
        with steps.step("write diagnosis.nc"):
            save_result(maps, out / "diagnosis.nc", seed=_as_seed(seed), design=nominal_design)
        with steps.step("write diagnosis.json"):
            write_text_atomic(out / "diagnosis.json", json.dumps(content, indent=2, default=json_default))
        if report:
            from ..report.diagnosis_report import write_diagnosis_report

            with steps.step("write report.html"):
                write_diagnosis_report(content, maps, out / "report.html")
    except InternalError as exc:
        inputs = {"rig": rig if isinstance(rig, (str, os.PathLike)) else "rig Dataset", "seed": str(seed),
                  "effects": list(effects) if effects is not None else None,
                  "design": design if isinstance(design, (str, os.PathLike)) else None,
                  "reference": str(reference) if isinstance(reference, (str, os.PathLike)) else
                  (None if reference is None else "reference campaign")}
        write_failure_record(out, exc, command="diagnosis", inputs=_json_clean(inputs))
        exc.kept = str(out)
        raise
    return content
