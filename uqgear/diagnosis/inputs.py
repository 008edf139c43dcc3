"""The inputs of a diagnosis, read and checked before any work: the rig campaign, design, calibration, reference.

A mistake in any of them is the user's (:class:`~uqgear.diagnosis.DiagnosisError`
or :class:`~uqgear.common.errors.RigDataError`, exit status 2 on the command
line) and costs no work.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xarray as xr

from ..common.errors import RigDataError
from ..physics.design import Design
from ..uq.results import load_result
from ..uq.seeds import as_seed_sequence, child_seed
from .allowances.compatibility import check_design_match, match_operating_points
from .allowances.reference import ReferenceCorrection
from .errors import DiagnosisError
from .settings import DEFAULT_SETTINGS, DiagnosisSettings

#: A reference: a rig file, a Dataset, or a correction already learned from one.
ReferenceInput = str | os.PathLike[str] | xr.Dataset | ReferenceCorrection


@dataclass(frozen=True)
class DiagnosisSeeds:
    """The random streams of one diagnosis: the noise calibration, the fits' bootstrap, the reference's fit.

    :meth:`from_seed` derives them from one seed as its children 0, 1 and 2;
    a caller that draws its own streams (the blind test) names them.
    """

    noise: np.random.SeedSequence
    run: np.random.SeedSequence
    reference: np.random.SeedSequence

    @classmethod
    def from_seed(cls, seed: np.random.SeedSequence) -> DiagnosisSeeds:
        return cls(child_seed(seed, 0), child_seed(seed, 1), child_seed(seed, 2))


def as_seed(seed: int | np.random.SeedSequence) -> np.random.SeedSequence:
    """A seed as a SeedSequence (DiagnosisError naming ``seed`` otherwise)."""
    return as_seed_sequence(seed, error=DiagnosisError)


def split_seed(seed: int | np.random.SeedSequence | DiagnosisSeeds) -> tuple[np.random.SeedSequence, DiagnosisSeeds]:
    """A diagnosis's seed (its entropy is the record's ``seed``) and its random streams.

    An int or SeedSequence gives its streams as its children 0 to 2
    (:meth:`DiagnosisSeeds.from_seed`); streams given are kept, the run's
    stream standing for the seed.

    Examples
    --------
    >>> from uqgear.diagnosis.inputs import split_seed
    >>> seed, seeds = split_seed(7)
    >>> seed.entropy, seeds.run.spawn_key
    (7, (1,))
    """
    if isinstance(seed, DiagnosisSeeds):
        return seed.run, seed
    root = as_seed(seed)
    return root, DiagnosisSeeds.from_seed(root)


def check_settings(settings: DiagnosisSettings | None) -> DiagnosisSettings:
    """The settings given, or the documented ones (DiagnosisError naming ``settings`` for another type)."""
    if settings is not None and not isinstance(settings, DiagnosisSettings):
        raise DiagnosisError(f"settings: expected a DiagnosisSettings; got {type(settings).__name__}")
    return DEFAULT_SETTINGS if settings is None else settings


@dataclass(frozen=True)
class DiagnosisInputs:
    """The checked inputs of one diagnosis."""

    rig: xr.Dataset
    source: str
    design: Design
    posterior: xr.Dataset | None = None
    reference: xr.Dataset | None = None
    reference_source: str = ""
    learned: ReferenceCorrection | None = None


def read_inputs(
    rig: str | os.PathLike[str] | xr.Dataset,
    reference: ReferenceInput | None,
    *,
    design: Design | None,
    calibration: str | os.PathLike[str] | xr.Dataset | None,
    settings: DiagnosisSettings = DEFAULT_SETTINGS,
    match_points: bool = True,
) -> DiagnosisInputs:
    """Read and check every input of a diagnosis before any work (``design``: one given, replacing the file's).

    ``match_points=False`` leaves the reference's operating points unmatched (the differential route carries the
    reference to the test's speeds itself)."""
    dataset, source = load_rig_input(rig, design=design)
    nominal_design = design if design is not None else resolve_design(None, dataset)
    posterior = load_calibration(calibration) if calibration is not None else None
    if reference is None:
        return DiagnosisInputs(dataset, source, nominal_design, posterior)
    reference_data, reference_source, learned = load_reference(
        reference, dataset, design=design, settings=settings, match_points=match_points
    )
    return DiagnosisInputs(dataset, source, nominal_design, posterior, reference_data, reference_source, learned)


def load_rig_input(rig: str | os.PathLike[str] | xr.Dataset, *, design: Design | None = None) -> tuple[xr.Dataset, str]:
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
    from ..rig.ramp_records import steady_campaign
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
    dataset = steady_campaign(dataset, design=design, where=where)  # ramp records -> operating points (speed bins)
    check_usable_signal(
        dataset,
        where=where,
        min_operating_points=DEFAULT_SETTINGS.features.min_informative_runs,
        purpose="the diagnosis",
        why="each operating point is predicted by the model fitted to the others",
    )
    return dataset, source


def resolve_design(design: Design | str | os.PathLike[str] | None, rig: xr.Dataset | None) -> Design:
    """The nominal design: one given (a Design, a design file or name), else the rig file's."""
    from ..physics.design import load_design
    from ..rig.format import rig_design

    if design is None:
        if rig is None:
            raise DiagnosisError("design: expected a Design, a design file or name, or a rig file that states one")
        return rig_design(rig)
    if isinstance(design, Design):
        return design
    if isinstance(design, (str, os.PathLike)):
        return load_design(str(design))
    raise DiagnosisError(
        f"design: expected a Design, a design file or name, or None (the rig file's design); "
        f"got {type(design).__name__}"
    )


def load_calibration(calibration: str | os.PathLike[str] | xr.Dataset) -> xr.Dataset:
    """A calibration posterior from a Dataset, a ``posterior.nc`` file or the folder holding it."""
    if isinstance(calibration, xr.Dataset):
        return calibration
    if not isinstance(calibration, (str, os.PathLike)):
        raise DiagnosisError(
            f"calibration: expected a posterior.nc path, its folder or a Dataset; got {type(calibration).__name__}"
        )
    path = Path(calibration)
    if path.is_dir():
        path = path / "posterior.nc"
    if not path.is_file():
        raise DiagnosisError(f"calibration: {path}: no such file (expected posterior.nc of uqgear calibrate)")

    return load_result(path)


def load_reference(
    reference: ReferenceInput,
    test: xr.Dataset,
    *,
    design: Design | None = None,
    settings: DiagnosisSettings = DEFAULT_SETTINGS,
    match_points: bool = True,
) -> tuple[xr.Dataset, str, ReferenceCorrection | None]:
    """A healthy reference campaign, checked against the test campaign before any work.

    Returns the reference Dataset, the text naming it and, when ``reference``
    is an already learned :class:`~uqgear.diagnosis.allowances.reference.ReferenceCorrection`
    (to reuse one reference for several test campaigns), that correction.

    Raises
    ------
    RigDataError
        The reference is not a rig file or Dataset in the format, or carries no usable signal.
    DiagnosisError
        Its design or channels differ from the test campaign's, or a test
        operating point has no reference point at the same speed and torque
        (:mod:`uqgear.diagnosis.allowances.reference`).
    """
    learned = None
    if isinstance(reference, ReferenceCorrection):
        learned, dataset, source = reference, reference.rig, reference.source
    elif isinstance(reference, (str, os.PathLike)):
        if not Path(reference).is_file():
            raise DiagnosisError(
                f"reference: {reference}: no such file (expected a uqgear-rig/1 campaign of the "
                "same rig with a healthy gearbox)"
            )
        dataset, source = load_rig_input(reference, design=design)
    elif isinstance(reference, xr.Dataset):
        dataset, source = load_rig_input(reference, design=design)
    else:
        raise DiagnosisError(
            f"reference: expected a uqgear-rig/1 file path or an xarray Dataset; got {type(reference).__name__}"
        )
    check_design_match(test, dataset, where=source)
    if not match_points and learned is None:
        from .change.detection import check_coverage

        check_coverage(
            test,
            dataset,
            where=source,
            speed_tolerance=settings.reference.speed_tolerance,
            torque_tolerance=settings.reference.torque_tolerance,
        )
        return dataset, source, learned
    match_operating_points(
        test,
        dataset,
        where=source,
        speed_tolerance=settings.reference.speed_tolerance,
        torque_tolerance=settings.reference.torque_tolerance,
    )
    return dataset, source, learned


def default_workers() -> int:
    """Worker processes by default: one per CPU this process may use, at most 8.

    Runs are single-threaded (:class:`~.execution.RunExecutor`), so each CPU gets
    a worker: on 2 CPUs two workers diagnose an 8-run campaign about 1.5x
    faster than one (benchmarks/diagnosis.py). Beyond 8 a fit's batches
    (one run per operating point and parameter) no longer keep them busy.
    """
    try:
        available = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        available = os.cpu_count() or 1
    return max(1, min(available, 8))


def check_workers(workers: int | None) -> int:
    """Worker processes: an integer >= 1, or :func:`default_workers` for None."""
    if workers is None:
        return default_workers()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise DiagnosisError(f"workers: expected an integer >= 1; got {workers!r}")
    return int(workers)


__all__ = [
    "DiagnosisSeeds",
    "DiagnosisInputs",
    "ReferenceInput",
    "as_seed",
    "check_settings",
    "split_seed",
    "read_inputs",
    "load_rig_input",
    "resolve_design",
    "load_calibration",
    "load_reference",
    "default_workers",
    "check_workers",
]
