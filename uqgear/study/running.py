"""A study run written as a whole: ``uqgear.run_study`` and ``uqgear run`` publish their folder once it is complete.

The analyses are run into a hidden work folder beside the output folder
(:class:`~uqgear.common.transaction.OutputFolder`), with their chunk
checkpoints inside it; it becomes the output folder only when every result
(and the report, when asked for) is written. An interruption or an internal
failure keeps the work folder, so that ``resume=True`` continues where it
stopped; a mistake in the input leaves nothing.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from ..common.transaction import Existing, OutputFolder
from .analyses import run_study as run_analyses
from .schema import Study

#: Folder of chunk checkpoints inside the work folder.
CHECKPOINTS = ".checkpoints"


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


def run_study(study: Study, out_dir: str | os.PathLike[str], *, scheduler: str | None = None,
              workers: int | None = None, resume: bool = False, show_progress: bool = True, report: bool = False,
              dpi: int = 110, existing: Existing = "merge") -> list[Path]:
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
        written = run_analyses(study, work, scheduler=scheduler, workers=workers, resume=resume,
                               show_progress=show_progress, checkpoint_dir=work / CHECKPOINTS)
        if report:
            from ..report.study_report import write_report

            write_report(work, dpi=dpi)
        # chunk checkpoints only serve an interrupted run; a finished analysis is reused from its result file
        shutil.rmtree(work / CHECKPOINTS, ignore_errors=True)
    return [out / path.name for path in written]


__all__ = ["CHECKPOINTS", "copy_previous", "run_study"]
