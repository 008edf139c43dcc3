"""A study run written as a whole: ``uqgear.run_study`` and ``uqgear run`` publish their folder once it is complete.

The analyses are run into a hidden work folder beside the output folder
(:class:`~uqgear.common.transaction.OutputFolder`), with their chunk
checkpoints inside it; it becomes the output folder only when every result
(and the report, when asked for) is written. An interruption or an internal
failure keeps the work folder, so that ``resume=True`` continues where it
stopped; a mistake in the input leaves nothing.

Inside it, :func:`run_analyses` runs every analysis (:func:`run_analysis`, the
registered function of its type) and writes one ``<name>.nc`` per analysis
with provenance; an analysis whose file is already there with the same inputs
(:func:`analysis_key`) is not run again on resume.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import StudyError, UqgearError
from ..common.progress import progress
from ..common.transaction import Existing, OutputFolder
from ..physics.effect_draws import UncertainEffect
from ..uq.posterior import PosteriorDraws
from ..uq.results import load_result, save_result
from ..uq.runner import Runner
from .analyses import ANALYSES, ANALYSIS_KEY_ATTR, AnalysisContext
from .analysis_schemas import RIG_TYPES
from .analysis_specs import AnalysisSpec
from .model_inputs import resolve_effects, resolve_posterior
from .schema import Study

#: Folder of chunk checkpoints inside the work folder.
CHECKPOINTS = ".checkpoints"


def analysis_key(study: Study, spec: AnalysisSpec) -> str:
    """Hash of everything an analysis's result depends on (its entry, the study-wide inputs)."""
    payload = {
        "analysis": spec.raw,
        "index": spec.index,
        "seed": study.seed,
        "design": study.design.to_dict(),
        "operating_points": {name: list(s.values) for name, s in spec.operating_points.items()},
        "uncertain": {name: p.to_dict() for name, p in study.uncertain.items()},
        "simulation": spec.simulation.to_dict(),
    }
    # only when given: the keys of studies without them stay what they were
    if study.calibrated is not None:
        payload["calibrated"] = study.calibrated.to_dict()
    if study.effects is not None:
        payload["effects"] = study.effects.to_dict()
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()


def _analysis_attrs(study: Study, spec: AnalysisSpec, key: str, seconds: float) -> dict[str, Any]:
    return {
        "analysis_type": spec.type,
        "analysis_name": spec.name,
        "analysis_index": spec.index,
        "analysis_description": spec.description,
        ANALYSIS_KEY_ATTR: key,
        "analysis_options": json.dumps(dict(spec.options), default=list),
        "operating_points": json.dumps(
            {name: list(s.values) if s.sweep else s.value for name, s in spec.operating_points.items()}
        ),
        "uncertain_parameters": json.dumps({name: p.to_dict() for name, p in study.uncertain.items()}),
        "simulation_settings": json.dumps(spec.simulation.to_dict()),
        "study_name": study.name,
        "study_description": study.description,
        "study_path": study.path,
        "study_seed": str(study.seed),
        "design_name": study.design.name,
        "design_source": study.design_source,
        "design_overrides": json.dumps(dict(study.design_overrides)),
        "run_time_s": float(seconds),
    }


def run_analysis(
    study: Study,
    spec: AnalysisSpec,
    *,
    runner: Runner,
    resume: bool = False,
    threads: int | None = None,
    seed: np.random.SeedSequence | None = None,
    results: Mapping[str, xr.Dataset] | None = None,
) -> xr.Dataset:
    """Run one analysis of a study and return its Dataset (not saved).

    Parameters
    ----------
    study : Study
    spec : AnalysisSpec
        One of ``study.analyses``.
    runner : Runner
        Executes the model batches.
    resume : bool
        Reuse the runner's checkpoints.
    threads : int, optional
        Threads for in-process batch integration.
    seed : SeedSequence, optional
        The analysis's seed; default its child of the study seed.
    results : mapping of str to Dataset, optional
        Results of the analyses run before it, by name (a posterior or a
        diagnosis that ``uncertain.calibrated`` or ``model.effects`` names).
    """
    if spec.type not in ANALYSES:
        raise StudyError(
            f"analyses[{spec.index}].type: {spec.type!r} has no implementation; expected one of {', '.join(ANALYSES)}"
        )
    seed = seed if seed is not None else study.seed_sequences()[spec.index]
    key = analysis_key(study, spec)
    if spec.type in RIG_TYPES:
        # a calibration runs with the study's diagnosed effects (at their fitted values); a diagnosis with none
        posterior, discrepancy = None, None
        effects = study_effects(study, results or {}) if spec.type == "calibrate" else ()
    else:
        posterior, effects, discrepancy = model_inputs(study, results or {})
    if effects:
        simulation = dataclasses.replace(spec.simulation, effects=tuple(effect.central() for effect in effects))
        spec = dataclasses.replace(spec, simulation=simulation)
    context = AnalysisContext(
        study=study,
        spec=spec,
        seed=seed,
        runner=runner,
        resume=resume,
        threads=threads,
        posterior=posterior,
        effects=effects,
        discrepancy=discrepancy,
    )
    started = time.perf_counter()
    result = ANALYSES[spec.type](context)
    result.attrs.update(_analysis_attrs(study, spec, key, time.perf_counter() - started))
    if context.notes:
        result.attrs["notes"] = json.dumps(context.notes)
    return result


def study_effects(study: Study, results: Mapping[str, xr.Dataset]) -> tuple[UncertainEffect, ...]:
    """The study's diagnosed effects (``model.effects``), which every model run and a ``calibrate`` analysis carry;
    none without them."""
    return resolve_effects(study.effects, results) if study.effects is not None else ()


def model_inputs(
    study: Study, results: Mapping[str, xr.Dataset]
) -> tuple[PosteriorDraws | None, tuple[UncertainEffect, ...], Any]:
    """The study's calibrated posterior (thinned, seeded), diagnosed effects and the calibration's model
    discrepancy (None without one), resolved from files or results.

    The thinning has a seed of its own, the study seed's child after those of
    the analyses, so that every analysis of a study sees the same draws.
    """
    posterior, discrepancy = None, None
    if study.calibrated is not None:
        full, discrepancy = resolve_posterior(study.calibrated, study.design, results)
        thinning = np.random.SeedSequence(study.seed, spawn_key=(len(study.analyses),))
        posterior = full.thin(study.calibrated.draws, thinning)
    return posterior, study_effects(study, results), discrepancy


def _reusable(path: Path, key: str) -> bool:
    if not path.is_file():
        return False
    try:
        return load_result(path).attrs.get(ANALYSIS_KEY_ATTR) == key
    except UqgearError:
        return False


def run_analyses(
    study: Study,
    out_dir: str | Path,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    show_progress: bool = True,
    checkpoint_dir: str | Path | None = None,
) -> list[Path]:
    """Run every analysis of a study, writing ``<out_dir>/<name>.nc`` for each.

    Parameters
    ----------
    study : Study
    out_dir : str or Path
        Existing folder for the results.
    scheduler : str, optional
        Address of a dask scheduler; None runs in-process on all local cores.
    workers : int, optional
        With a scheduler: how many of its workers to use. Without: the number
        of threads of the in-process integrator.
    resume : bool
        Skip analyses whose result file is already in ``out_dir`` with the
        same inputs, and reuse the chunk checkpoints of the others.
    show_progress : bool
        Progress bars (shown only in a terminal).
    checkpoint_dir : str or Path, optional
        Folder of chunk checkpoints (default ``out_dir/.checkpoints``).

    Returns
    -------
    list of Path
        The result files, in analysis order.
    """
    out = Path(out_dir)
    checkpoints = Path(checkpoint_dir) if checkpoint_dir is not None else out / ".checkpoints"
    runner = Runner(
        chunk_size=study.chunk_size,
        scheduler=scheduler,
        workers=workers if scheduler is not None else None,
        checkpoint_dir=checkpoints,
        progress=show_progress,
    )
    threads = workers if scheduler is None else None
    seeds = study.seed_sequences()
    written = []
    finished: dict[str, Path] = {}
    sources = {source.analysis for source in (study.calibrated, study.effects) if source is not None}
    bar = progress(study.analyses, desc="analyses", unit="analysis", enabled=show_progress)
    for spec in bar:
        bar.set_postfix_str(spec.name)
        path = out / f"{spec.name}.nc"
        key = analysis_key(study, spec)
        if resume and _reusable(path, key):
            written.append(path)
            finished[spec.name] = path
            continue
        needed = {name: load_result(file) for name, file in finished.items() if name in sources}
        result = run_analysis(
            study, spec, runner=runner, resume=resume, threads=threads, seed=seeds[spec.index], results=needed
        )
        save_result(result, path, seed=seeds[spec.index], design=study.design, study_text=study.text)
        written.append(path)
        finished[spec.name] = path
    return written


def copy_previous(out: Path, work: Path) -> None:
    """Copy a finished run's results and checkpoints into the work folder (for ``resume``)."""
    for item in out.iterdir():
        target = work / item.name
        if target.exists():
            continue
        if item.is_dir():
            shutil.copytree(item, target)
        elif item.suffix == ".nc":
            shutil.copy2(item, target)


def run_study(
    study: Study,
    out_dir: str | os.PathLike[str],
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    show_progress: bool = True,
    report: bool = False,
    dpi: int = 110,
    existing: Existing = "merge",
) -> list[Path]:
    """Run every analysis of a study and write ``<out_dir>/<name>.nc`` for each, the folder as a whole.

    Parameters
    ----------
    study : Study
    out_dir : str or Path
        Output folder: new, empty, or an earlier run's (see ``existing``).
    scheduler : str, optional
        Address of a dask scheduler; None runs in-process on all local cores.
    workers : int, optional
        With a scheduler: how many of its workers to use. Without: the number
        of threads of the in-process integrator.
    resume : bool
        Continue a run that was interrupted (its work folder) or update an
        earlier one in ``out_dir``: analyses whose result is there with the
        same inputs are reused, the others resume from their checkpoints.
    show_progress : bool
        Progress bars (shown only in a terminal).
    report : bool
        Also write ``report.html`` (:func:`uqgear.report.write_report`).
    dpi : int
        The report's figure resolution.
    existing : {"merge", "replace", "refuse"}
        What an ``out_dir`` that holds files gets: each new file replaces
        its namesake (default), the whole folder is replaced, or it is refused.

    Returns
    -------
    list of Path
        The result files, in analysis order.

    Raises
    ------
    UqgearError
        ``out_dir`` cannot be written.
    InternalError
        An analysis failed after the study was accepted; its ``kept`` names
        the work folder, which ``resume=True`` continues from.

    Examples
    --------
    The band of the DTE RMS over the adhesion torque interval at two speeds,
    with short runs:

    >>> import tempfile
    >>> import uqgear
    >>> study = uqgear.parse_study('''
    ... name: t2_band
    ... seed: 1
    ... design: {name: locomotive}
    ... operating_points: {pinion_speed: [1000, 2000], drive_torque: 7000}
    ... uncertain:
    ...   adhesion_torque: {adhesion_coefficient: [0.15, 0.33], axle_load: 23000, wheel_radius: 0.625}
    ... simulation: {n_periods: 60, keep_periods: 20}
    ... analyses:
    ...   - {type: interval, name: band, parameters: [adhesion_torque], method: vertex}
    ... ''')
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     files = uqgear.run_study(study, folder, show_progress=False)
    ...     band = uqgear.load_result(files[0])
    >>> [path.name for path in files]
    ['band.nc']
    >>> (band["dte_rms"] * 1e6).round(1).values       # um, (speed, lower/upper)
    array([[ 4.8,  9.6],
           [ 6.2, 13.1]])
    >>> band.attrs["seed"], band.attrs["study"] == study.text
    ('1', True)
    """
    out = Path(out_dir)
    with OutputFolder(out, existing=existing, resumable=True, resume=resume) as work:
        if resume and out.is_dir():
            copy_previous(out, work)
        written = run_analyses(
            study,
            work,
            scheduler=scheduler,
            workers=workers,
            resume=resume,
            show_progress=show_progress,
            checkpoint_dir=work / CHECKPOINTS,
        )
        if report:
            from ..report.study_report import write_report

            write_report(work, dpi=dpi)
        # chunk checkpoints only serve an interrupted run; a finished analysis is reused from its result file
        shutil.rmtree(work / CHECKPOINTS, ignore_errors=True)
    return [out / path.name for path in written]


__all__ = ["CHECKPOINTS", "analysis_key", "run_analysis", "run_analyses", "copy_previous", "run_study"]
