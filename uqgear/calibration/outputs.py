"""Calibration outputs: ``posterior.nc``, ``calibration.json`` and ``report.html``, and ``uqgear calibrate``."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..common.errors import InternalError
from ..common.fileio import write_text_atomic
from ..common.steps import StepLog, write_failure_record
from ..common.transaction import OutputFolder
from ..physics.design import Design, load_design
from ..rig.format import read_rig
from ..rig.ramp_records import points_truth
from .estimator import Calibration
from .pitch_correction import DEFAULT_CLASSES
from .priors import DEFAULT_PARAMETERS


def write_calibration(
    calibration: Calibration, out_dir: str | os.PathLike[str], *, truth: Mapping[str, Any] | None = None
) -> dict[str, Path]:
    """Write ``posterior.nc``, ``calibration.json`` and ``report.html`` of a fitted calibration.

    Parameters
    ----------
    calibration : Calibration
        Fitted.
    out_dir : path
        Output folder (created if missing).
    truth : mapping, optional
        Known true values to mark in the report (e.g. of a virtual-rig file).

    Returns
    -------
    dict
        ``posterior``, ``json``, ``report`` -> paths written.
    """
    from ..report.calibration_report import write_calibration_report
    from ..uq.results import save_result

    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    content = calibration.to_dict()
    posterior_path = save_result(
        calibration.posterior_, folder / "posterior.nc", seed=calibration.seed, design=calibration.design_
    )
    json_path = folder / "calibration.json"
    write_text_atomic(json_path, json.dumps(content, indent=2, default=float))
    report_path = write_calibration_report(calibration, folder / "report.html", truth=truth)
    return {"posterior": posterior_path, "json": json_path, "report": report_path}


def calibrate(
    rig_path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    design: Design | str | os.PathLike[str] | None = None,
    params: Sequence[str] | None = None,
    seed: np.random.SeedSequence | int | None = 0,
    threads: int | None = None,
    pitch_classes: tuple[float, float] | None = DEFAULT_CLASSES,
    discrepancy: bool = False,
) -> Calibration:
    """Calibrate the model on a rig file and write the results (``uqgear calibrate``).

    Parameters
    ----------
    rig_path : path
        ``uqgear-rig/1`` file.
    out_dir : path
        Folder for ``posterior.nc``, ``calibration.json`` and ``report.html``, written as a whole
        (:class:`~uqgear.common.transaction.OutputFolder`): they appear once all are written, replacing
        the files of an earlier calibration there; a mistake in the input leaves nothing.
    design : Design or design file/name, optional
        Nominal design; default the file's ``design`` attribute. When given it
        replaces the file's, which is then not validated as a design.
    params : sequence of str, optional
        Parameters to calibrate (default :data:`DEFAULT_PARAMETERS`).
    seed : SeedSequence or int
        Source of all randomness.
    threads : int, optional
        Threads for the model runs.
    pitch_classes : (float, float) or None
        ISO 1328-1 classes of the rig's gears for the pitch-error correction
        (:class:`Calibration`); None: read from the rig's sidebands.
    discrepancy : bool
        Add the model-discrepancy term (:mod:`~uqgear.calibration.discrepancy`):
        for a rig whose physics the model does not have.

    Returns
    -------
    Calibration
        The fitted calibration.

    Raises
    ------
    RigDataError, CalibrationError, DesignError
        A mistake in the input, found before the work starts.
    InternalError
        A step failed after the input was accepted: ``out_dir`` keeps
        ``failure.json`` (the failed step, the error, the finished steps) and
        the error's ``kept`` names it.

    Examples
    --------
    A mistake in the input is found before any work and leaves no folder:

    >>> import pathlib, tempfile
    >>> import uqgear
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     out = pathlib.Path(folder) / "calibration"
    ...     try:
    ...         uqgear.calibrate(pathlib.Path(folder) / "missing.nc", out)
    ...     except uqgear.RigDataError as error:
    ...         print(str(error).endswith("missing.nc: rig data file not found"), out.exists())
    True False

    The bundled healthy campaign, calibrated with the default settings
    (minutes; :class:`Calibration` shows a small calibration that runs in
    seconds):

    >>> with tempfile.TemporaryDirectory() as folder:  # doctest: +SKIP
    ...     calibration = uqgear.calibrate(uqgear.example_rig_file("healthy"), folder)
    ...     print(sorted(path.name for path in pathlib.Path(folder).iterdir()))
    ['calibration.json', 'posterior.nc', 'report.html']
    """
    nominal = None if design is None else (design if isinstance(design, Design) else load_design(design))
    calibration = Calibration(
        params if params is not None else DEFAULT_PARAMETERS,
        design=nominal,
        seed=seed,
        threads=threads,
        pitch_classes=pitch_classes,
        discrepancy=discrepancy,
    )
    # nothing appears in out_dir until everything is written (a mistake in the input leaves nothing)
    with OutputFolder(out_dir) as work:
        try:
            calibration.fit(rig_path)
            steps = getattr(calibration, "steps_", StepLog())
            with steps.step("write the results"):
                # a virtual rig's truth per operating point, following the ramp segments the fit read
                sources = [str(row.get("source", "steady")) for row in calibration.speed_]
                truth = points_truth(read_rig(rig_path, design=nominal), sources)
                write_calibration(calibration, work, truth=truth)
        except InternalError as exc:
            write_failure_record(
                work,
                exc,
                command="calibration",
                inputs={
                    "rig": str(rig_path),
                    "params": list(calibration.parameters),
                    "seed": str(seed),
                    "discrepancy": discrepancy,
                    "design": design if isinstance(design, (str, os.PathLike)) else None,
                },
            )
            raise
    return calibration
