"""The ``uqgear`` command line.

::

    uqgear validate STUDY.yaml
    uqgear run STUDY.yaml --out DIR [--scheduler ADDRESS] [--workers N] [--resume] [--quiet]
    uqgear report DIR
    uqgear simulate --speed RPM [--drive-torque NM] [--adhesion-torque NM] [--design NAME|FILE]
                    [--out FILE.png|FILE.nc]
    uqgear synth-rig --design FILE --out FILE.nc [--effect NAME:param=value ...] [--true KEY=VALUE ...] [--seed N]
                     [--ramp START:STOP:RATE[:TORQUE] ...] [--foreign GRADE [--gears-seed N]]
    uqgear calibrate RIG.nc --out DIR [--design FILE] [--params ...]
    uqgear diagnose RIG.nc --out DIR [--design FILE] [--effects ...] [--reference HEALTHY.nc]
    uqgear blindtest --out DIR [--n-per-effect N] [--seed S] [--suite library|real_world|encoderless|runup|foreign]

A user mistake (a study that breaks the schema, a missing file, bad YAML, an
unreachable scheduler, a rig file without usable signal) ends with exit status
2 and a one-line message on standard error, without a traceback, and leaves no
partial output: every command that writes a folder writes into a hidden
sibling folder ``.DIR.partial`` and renames it to ``DIR`` only when everything
is written (:class:`~uqgear.common.transaction.OutputFolder`, which the Python
API's writers use too). Such mistakes are
found before the work starts. An interrupted run (Ctrl-C, a killed job) keeps
that folder, with its chunk checkpoints, so that ``--resume`` continues where
it stopped.

A failure of uqgear's own computation after the input was accepted
(:class:`~uqgear.common.errors.InternalError`) is no mistake of the user's:
it ends with exit status 1 and one line ``uqgear: internal error during
diagnosis step 'STEP': ...`` naming the step that failed, and keeps what was
finished: ``diagnose``, ``calibrate`` and ``blindtest`` publish their folder
with the outputs written so far and ``failure.json`` (the step, the error, its
traceback, the finished steps and what they found); ``run`` keeps its work
folder for ``--resume``.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from .common.errors import InternalError, UqgearError, UqgearWarning
from .common.transaction import OutputFolder, is_empty_folder, partial_folder

#: Exit status of an internal failure after the input was accepted.
EXIT_INTERNAL_ERROR = 1
#: Exit status of a user mistake.
EXIT_USER_ERROR = 2
#: Exit status after Ctrl-C.
EXIT_INTERRUPTED = 130


class _Parser(argparse.ArgumentParser):
    """argparse with one-line error messages and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USER_ERROR, f"uqgear: error: {message} (see '{self.prog} --help')\n")


def _one_line(message: object) -> str:
    return " ".join(str(message).split())


def _fail(message: object) -> int:
    print(f"uqgear: error: {_one_line(message)}", file=sys.stderr)
    return EXIT_USER_ERROR


def _run_command(args: argparse.Namespace) -> int:
    """Run a command's handler; uqgear's own warnings (an undercut design, ...) print as one line each."""
    with warnings.catch_warnings():
        python_style = warnings.showwarning
        shown: set[str] = set()  # a design read from several places (file, copies) is reported once

        def show(message, category, filename, lineno, file=None, line=None) -> None:
            if not issubclass(category, UqgearWarning):
                python_style(message, category, filename, lineno, file, line)
            elif _one_line(message) not in shown:
                shown.add(_one_line(message))
                print(f"uqgear: warning: {_one_line(message)}", file=sys.stderr)

        warnings.showwarning = show
        return args.handler(args)


#: What each command computes, for the message of an internal failure.
_WORK = {
    "run": "study run",
    "calibrate": "calibration",
    "diagnose": "diagnosis",
    "blindtest": "blind test",
    "simulate": "simulation",
    "synth-rig": "virtual rig simulation",
    "report": "report",
}


def _internal_failure(command: str, exc: InternalError) -> int:
    """One line naming the failed step and where the finished outputs are; exit status 1."""
    kept = ""
    if exc.kept:
        from .common.steps import FAILURE_RECORD

        record = Path(exc.kept) / FAILURE_RECORD
        kept = f"; finished outputs kept in {exc.kept}" + (f" (see {FAILURE_RECORD})" if record.is_file() else "")
    print(
        _one_line(
            f"uqgear: internal error during {_WORK.get(command, command)} step '{exc.step}': "
            f"{exc.detail}{kept}; this is not a mistake in the input, please report it"
        ),
        file=sys.stderr,
    )
    return EXIT_INTERNAL_ERROR


# ---------------------------------------------------------------------------- validate


def _command_validate(args: argparse.Namespace) -> int:
    from .study.schema import load_study

    study = load_study(args.study)
    kinds = ", ".join(f"{spec.name} ({spec.type})" for spec in study.analyses)
    print(f"{args.study}: valid study {study.name!r} with {len(study.analyses)} analyses: {kinds}")
    return 0


# ---------------------------------------------------------------------------- run


def _command_run(args: argparse.Namespace) -> int:
    from .study.schema import load_study

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        return _fail(f"--out {out}: exists and is not a folder; expected a new or empty folder")
    if out.is_dir() and not is_empty_folder(out) and not args.resume:
        return _fail(
            f"--out {out}: folder exists and is not empty; choose a new folder, remove it, "
            "or pass --resume to continue or update that run"
        )
    OutputFolder(out, where="--out", existing="replace").check()
    if args.workers is not None and args.workers < 1:
        return _fail(f"--workers: expected a positive integer; got {args.workers}")
    # the study is validated completely before anything is created
    study = load_study(args.study)

    from .study.running import run_study

    try:
        run_study(
            study,
            out,
            scheduler=args.scheduler,
            workers=args.workers,
            resume=args.resume,
            show_progress=not args.quiet,
            report=study.outputs.report,
            dpi=study.outputs.dpi,
            existing="replace",
        )
    except KeyboardInterrupt:
        print(
            f"uqgear: interrupted; finished work is kept in {partial_folder(out)}; run again with --resume to continue",
            file=sys.stderr,
        )
        return EXIT_INTERRUPTED
    if not args.quiet:
        print(f"results written to {out}" + (f" (report: {out / 'report.html'})" if study.outputs.report else ""))
    return 0


# ---------------------------------------------------------------------------- examples


def _first_comment(path: Path) -> str:
    """The study's description, or its first comment line."""
    from .common.yamlio import YAMLError, load_yaml

    text = path.read_text()
    try:
        raw = load_yaml(text)
    except YAMLError:
        raw = None
    if isinstance(raw, dict) and isinstance(raw.get("description"), str):
        return " ".join(raw["description"].split())
    for line in text.splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip()
    return ""


def _command_examples(args: argparse.Namespace) -> int:
    from .common.resources import bundled_file, bundled_names

    if args.action == "copy":
        return _copy_example(args)
    if args.action is not None:
        return _fail(f"examples: unknown action {args.action[:40]!r}; expected 'copy' or nothing")
    print("Bundled studies (uqgear run NAME --out DIR; uqgear examples copy NAME DEST.yaml to edit one):")
    for name in bundled_names("study"):
        text = _first_comment(bundled_file("study", name))
        print(f"  {name:24s} {text[:90] + ('...' if len(text) > 90 else '')}")
    print("Bundled designs (design: {name: NAME} in a study, --design NAME on the command line):")
    for name in bundled_names("design"):
        print(f"  {name:24s} {bundled_file('design', name)}")
    print(
        "Example rig campaigns (uqgear calibrate FILE / uqgear diagnose FILE; uqgear.example_rig_file(NAME) in Python):"
    )
    for name in bundled_names("rig"):
        print(f"  {name:24s} {bundled_file('rig', name)}")
    return 0


def _copy_example(args: argparse.Namespace) -> int:
    from .common.fileio import write_text_atomic
    from .common.resources import bundled_file

    if args.name is None or args.dest is None:
        return _fail("examples copy: expected a study name and a destination: uqgear examples copy NAME DEST.yaml")
    source = bundled_file("study", args.name)
    dest = Path(args.dest)
    if dest.is_dir():
        dest = dest / source.name
    if dest.suffix.lower() not in (".yaml", ".yml"):
        return _fail(f"examples copy: {args.dest}: expected a folder or a file name ending in .yaml")
    _check_new_file(dest, args.force, f"examples copy: {dest}")
    write_text_atomic(dest, source.read_text())
    print(f"study {source.stem} copied to {dest} (run it with: uqgear run {dest} --out DIR)")
    return 0


# ---------------------------------------------------------------------------- report


def _command_report(args: argparse.Namespace) -> int:
    from .report.study_report import write_report
    from .study.limits import check_dpi

    path = write_report(Path(args.directory), dpi=check_dpi(args.dpi, "--dpi"))
    print(f"report written to {path}")
    return 0


# ---------------------------------------------------------------------------- simulate


def _command_simulate(args: argparse.Namespace) -> int:
    from .physics.design import load_design
    from .study.limits import check_dpi, check_operating_value, check_run_length

    design = load_design(args.design)
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.suffix.lower() not in (".png", ".nc"):
            return _fail(f"--out {out}: expected a file name ending in .png (figure) or .nc (data)")
        _check_new_file(out, args.force)
    # the limits a study puts on the same values
    speed = check_operating_value("pinion_speed", args.speed, "--speed")
    drive = (
        check_operating_value("drive_torque", args.drive_torque, "--drive-torque")
        if args.drive_torque is not None
        else design.operation.drive_torque
    )
    adhesion = (
        check_operating_value("adhesion_torque", args.adhesion_torque, "--adhesion-torque")
        if args.adhesion_torque is not None
        else drive * design.z2 / design.z1
    )
    n_periods, keep_periods = check_run_length(
        args.n_periods, args.keep_periods, where=("--n-periods", "--keep-periods")
    )
    dpi = check_dpi(args.dpi, "--dpi")

    from .report import simulation_figure_png
    from .study.analyses import quick_run
    from .uq.results import save_result

    run = quick_run(design, speed, drive, adhesion, n_periods=n_periods, keep_periods=keep_periods)
    print(
        f"pinion speed {speed:g} rpm, T1 {drive / 1e3:.4g} kN m, T2 {adhesion / 1e3:.4g} kN m "
        f"({design.name}): {run.attrs['regime']} ({run.attrs['regime_reason']})"
    )
    print(
        f"  DTE RMS {run.attrs['dte_rms'] * 1e6:.4g} um, peak-to-peak "
        f"{run.attrs['dte_peak_to_peak'] * 1e6:.4g} um, dynamic load factor "
        f"{run.attrs['dynamic_load_factor']:.4g}, separated {100 * run.attrs['fraction_separation']:.3g} % "
        f"of the time, back-side contact {100 * run.attrs['fraction_back_contact']:.3g} %"
    )
    if out is not None:
        if out.suffix.lower() == ".png":
            from .common.fileio import atomic_path

            data = simulation_figure_png(run, dpi=dpi)
            with atomic_path(out) as temporary:
                temporary.write_bytes(data)
        else:
            save_result(run, out, design=design)
        print(f"written to {out}")
    return 0


def _check_new_file(out: Path, force: bool, where: str | None = None) -> None:
    """An output file goes into an existing folder and replaces a file only with ``--force``.

    ``where`` names the file in messages (default ``--out OUT``).
    """
    where = f"--out {out}" if where is None else where
    if out.is_dir():
        raise UqgearError(f"{where}: is a folder; expected a file name")
    if out.exists() and not force:
        raise UqgearError(f"{where}: exists; choose another name or pass --force to overwrite it")
    if not out.parent.is_dir():
        raise UqgearError(f"{where}: the folder {out.parent} does not exist")


# ---------------------------------------------------------------------------- rig data


def _parse_assignments(items: Sequence[str], option: str) -> dict[str, float]:
    """``KEY=VALUE`` pairs of a repeated option, values as floats."""
    values: dict[str, float] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise UqgearError(f"{option} {item!r}: expected KEY=VALUE")
        try:
            values[key.strip()] = float(raw)
        except ValueError:
            raise UqgearError(f"{option} {item!r}: expected a number after '='") from None
    return values


def _new_output_folder(out: Path) -> Path:
    """``--out``: a new or empty folder, checked before any work (the library writes it as a whole)."""
    OutputFolder(out, where="--out", existing="refuse").check()
    return out


def _comma_list(items: list[str] | None) -> list[str] | None:
    """Names given as separate arguments and/or comma-separated ones; None when none were given."""
    return [name for item in items for name in item.split(",") if name] if items else None


def _command_synth_rig(args: argparse.Namespace) -> int:
    from .physics.design import load_design
    from .physics.effects import parse_effect
    from .rig.virtual_rig import synth_rig
    from .rig.virtual_runup import parse_ramps, synth_runup_rig

    design = load_design(args.design)
    effects = [parse_effect(text) for text in args.effect]
    true_parameters = _parse_assignments(args.true, "--true")
    out = Path(args.out)
    if out.suffix != ".nc":
        return _fail(f"--out {out}: expected a file name ending in .nc")
    _check_new_file(out, args.force)
    if args.noise < 0:
        return _fail(f"--noise: expected a relative noise level >= 0; got {args.noise:g}")
    options: dict[str, Any] = {"effects": effects, "seed": args.seed, "relative_noise": args.noise}
    ramps = parse_ramps(args.ramp, option="--ramp") if args.ramp else None
    rig, gears = "virtual rig", ""
    if args.foreign is not None:
        from .rig.foreign_synth import synth_foreign_rig

        if true_parameters:  # the foreign rig's physics is not the model's: it has no model parameters to set
            return _fail("--true: the foreign rig (--foreign) has no true model parameters; leave --true out")
        synth_foreign_rig(design, out, args.foreign, ramps=ramps, gears_seed=args.gears_seed, option="--foreign",
                          **options)
        gears_seed = args.seed if args.gears_seed is None else args.gears_seed
        rig, gears = "foreign virtual rig", f", grade {args.foreign:g} gears of gears seed {gears_seed}"
    elif args.gears_seed is not None:
        return _fail("--gears-seed: seeds the gears of the foreign rig; give it with --foreign GRADE")
    elif ramps is not None:
        synth_runup_rig(design, out, ramps, true_parameters=true_parameters, **options)
    else:
        synth_rig(design, out, true_parameters=true_parameters, **options)
    described = "; ".join(repr(effect) for effect in effects) or "no effect"
    print(f"{rig} campaign written to {out} ({design.name}{gears}, {described}, seed {args.seed})")
    return 0


def _pitch_classes(words: list[str]) -> tuple[float, float] | None:
    """``--pitch-classes``: two ISO 1328-1 classes, or ``none`` (the calibration or diagnosis checks their range)."""
    if [word.lower() for word in words] == ["none"]:
        return None
    try:
        values = tuple(float(word) for word in words)
    except ValueError:
        values = ()
    if len(values) != 2:
        raise UqgearError(f"--pitch-classes: expected two ISO 1328-1 classes (e.g. 6 8) or none; got {' '.join(words)}")
    return values[0], values[1]


def _command_calibrate(args: argparse.Namespace) -> int:
    from .calibration import calibrate

    rig = Path(args.rig)
    if not rig.is_file():
        return _fail(f"{rig}: rig data file not found")
    classes = _pitch_classes(args.pitch_classes)
    out = _new_output_folder(Path(args.out))
    result = calibrate(
        rig,
        out,
        design=args.design,
        params=_comma_list(args.params),
        seed=args.seed,
        threads=args.workers,
        pitch_classes=classes,
        discrepancy=args.discrepancy,
    )
    summary = result.to_dict()
    state = "converged" if summary.get("converged") else "NOT converged (see calibration.json)"
    print(f"calibration of {rig} {state}; results in {out}")
    if not summary.get("converged"):
        print(f"  {summary.get('message', '')}")
    for warning in summary.get("warnings") or []:
        print(f"  warning: {warning}")
    for name, values in (summary.get("parameters") or {}).items():
        if isinstance(values, dict) and "q05" in values:
            print(f"  {name:22s} median {values['q50']:.6g}   90 % interval [{values['q05']:.6g}, {values['q95']:.6g}]")
    return 0


def _command_diagnose(args: argparse.Namespace) -> int:
    from .diagnosis import diagnose

    rig = Path(args.rig)
    if not rig.is_file():
        return _fail(f"{rig}: rig data file not found")
    reference = Path(args.reference) if args.reference else None
    if reference is not None and not reference.is_file():
        return _fail(f"--reference {reference}: rig data file not found")
    classes = _pitch_classes(args.pitch_classes)
    out = _new_output_folder(Path(args.out))
    result = diagnose(
        rig,
        out,
        design=args.design,
        effects=_comma_list(args.effects),
        seed=args.seed,
        workers=args.workers,
        reference=reference,
        pitch_classes=classes,
        reference_route=args.reference_route,
        reference_gears=args.reference_gears,
    )
    gap = result.get("gap", {})
    if gap.get("baseline") is None:
        # nothing was compared (verdict inconclusive): the reason, not a row of Nones
        print(
            f"diagnosis of {rig}: verdict {result['verdict']} ({_one_line(result.get('reason', ''))}); results in {out}"
        )
        return 0
    against = f" against reference {reference}" if reference is not None else ""
    print(
        f"diagnosis of {rig}{against}: verdict {result['verdict']}; gap {gap.get('metric', '')} "
        f"{gap.get('baseline')} -> {gap.get('with_effect')} (shrink {gap.get('shrink_fraction')}); results in {out}"
    )
    return 0


def _command_blindtest(args: argparse.Namespace) -> int:
    from .validation import blindtest

    if args.n_per_effect < 1:
        return _fail(f"--n-per-effect: expected a positive integer; got {args.n_per_effect}")
    out = _new_output_folder(Path(args.out))
    if args.suite == "foreign":
        return _foreign_blindtest(args, out)
    result = blindtest(out, n_per_effect=args.n_per_effect, seed=args.seed, workers=args.workers, suite=args.suite)
    sets = result["effect_sets"]
    print(
        f"blind test ({args.suite}): {result['n_campaigns']} campaigns, accuracy {result['accuracy']:.2f} "
        f"({result['accuracy_detectable']:.2f} counting 'none' as right where the effect is invisible), "
        f"effect sets exactly right {sets['set_exact']:.2f} ({sets['set_exact_identifiable']:.2f} against the "
        f"effects the data can tell), false alarms on healthy controls "
        f"{result['false_alarms']} of {result['healthy_controls']}; results in {out}"
    )
    return 0


def _foreign_blindtest(args: argparse.Namespace, out: Path) -> int:
    """The differential diagnosis's blind test on the foreign virtual rig (``blindtest.json`` in ``out``)."""
    import json

    from .common.fileio import write_text_atomic
    from .validation.foreign_suite import run_foreign_suite

    result = run_foreign_suite(seed=args.seed, n_per_effect=args.n_per_effect, workers=args.workers)
    # the folder appears with its file, as the other suites' do
    with OutputFolder(out, where="--out", existing="refuse") as work:
        write_text_atomic(work / "blindtest.json", json.dumps(result, indent=1, default=str))
    print(
        f"blind test (foreign): {len(result['campaigns'])} campaigns, exactly right {result['exactly_right']:.2f} "
        f"(effects {result['effects_exactly_right']:.2f}; {result['exactly_right_visible']:.2f} counting 'none' as "
        f"right where an effect's noise-free change stays below the change test's thresholds, "
        f"{result['effects_visible']} effects visible), healthy tests none: {result['healthy_none']}; "
        f"results in {out}"
    )
    return 0


# ---------------------------------------------------------------------------- main


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``uqgear`` command."""
    parser = _Parser(
        prog="uqgear",
        description="Dynamics of railway traction gears under uncertainty: "
        "run YAML studies, write netCDF results and self-contained HTML reports.",
    )
    from . import __version__

    parser.add_argument("--version", action="version", version=f"uqgear {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    commands.required = True

    validate = commands.add_parser(
        "validate",
        help="check a study file against the schema",
        description="Check a study file; print a summary or the first problem.",
    )
    validate.add_argument("study", metavar="STUDY.yaml")
    validate.set_defaults(handler=_command_validate)

    run = commands.add_parser(
        "run",
        help="run a study, write DIR/<analysis>.nc and DIR/report.html",
        description="Run every analysis of a study. Results appear in DIR only when the whole run has succeeded.",
    )
    run.add_argument(
        "study", metavar="STUDY.yaml", help="a study file, or the name of a bundled study (uqgear examples lists them)"
    )
    run.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="output folder (new or empty, or an earlier run's folder with --resume)",
    )
    run.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="dask scheduler address (tcp://host:8786); default: in-process on all local cores",
    )
    run.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="with --scheduler: use N of its workers; without: N threads for the in-process integrator",
    )
    run.add_argument(
        "--resume",
        action="store_true",
        help="reuse finished analyses and chunk checkpoints of an interrupted or earlier run into DIR",
    )
    run.add_argument("--quiet", action="store_true", help="no progress bars or summary line")
    run.set_defaults(handler=_command_run)

    examples = commands.add_parser(
        "examples",
        help="list the bundled studies, designs and rig campaigns; copy a study to edit",
        description="Without arguments: list what ships with uqgear. "
        "'examples copy NAME DEST' writes the bundled study NAME to DEST "
        "(a .yaml file or a folder).",
    )
    examples.add_argument("action", nargs="?", metavar="copy", help="copy a bundled study")
    examples.add_argument("name", nargs="?", metavar="NAME", help="bundled study name (see the list)")
    examples.add_argument("dest", nargs="?", metavar="DEST", help="destination file or folder")
    examples.add_argument("--force", action="store_true", help="overwrite DEST if it exists")
    examples.set_defaults(handler=_command_examples)

    report = commands.add_parser(
        "report",
        help="rebuild DIR/report.html from the saved results",
        description="Rebuild the HTML report from the .nc files in DIR alone.",
    )
    report.add_argument("directory", metavar="DIR")
    report.add_argument("--dpi", type=int, default=110, help="figure resolution (default 110)")
    report.set_defaults(handler=_command_report)

    simulate = commands.add_parser(
        "simulate",
        help="one quick run with a plot",
        description="Simulate one operating point; print its regime and QoIs; "
        "optionally write a figure (time history, phase plane, Poincare map, "
        "spectrum) or the data.",
    )
    simulate.add_argument("--speed", type=float, required=True, metavar="RPM", help="pinion speed in rpm")
    simulate.add_argument(
        "--drive-torque", type=float, metavar="NM", help="drive torque T1 in N m (default: the design's rated torque)"
    )
    simulate.add_argument(
        "--adhesion-torque",
        type=float,
        metavar="NM",
        help="adhesion torque T2 in N m (default: T1 z2/z1, balancing T1)",
    )
    simulate.add_argument(
        "--design",
        default="locomotive",
        metavar="NAME|FILE",
        help="bundled design name or design YAML file (default: locomotive)",
    )
    simulate.add_argument("--out", metavar="FILE.png|FILE.nc", help="write a figure or the data")
    simulate.add_argument("--n-periods", type=int, default=400, help="mesh periods integrated (default 400)")
    simulate.add_argument(
        "--keep-periods", type=int, default=200, help="mesh periods kept after the transient (default 200)"
    )
    simulate.add_argument("--dpi", type=int, default=110, help="figure resolution (default 110)")
    simulate.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    simulate.set_defaults(handler=_command_simulate)

    synth = commands.add_parser(
        "synth-rig",
        help="simulate a virtual-rig campaign in the rig format",
        description="Simulate a test-rig campaign (8 operating points by default) "
        "with chosen true parameters, sensor noise and unmodelled effects, and write "
        "it as a uqgear-rig/1 netCDF file; with --foreign, a campaign of the foreign virtual rig.",
    )
    synth.add_argument("--design", default="locomotive", metavar="NAME|FILE",
                       help="nominal design (bundled name or YAML file; default: locomotive)")
    synth.add_argument("--out", required=True, metavar="FILE.nc", help="rig file to write")
    synth.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    synth.add_argument("--effect", action="append", default=[], metavar="NAME:param=value,...",
                       help="add an unmodelled effect, e.g. eccentricity:amplitude=12e-6,kappa=0.03 (repeatable)")
    synth.add_argument("--true", action="append", default=[], metavar="KEY=VALUE",
                       help="true value differing from the nominal design, e.g. mesh_stiffness_scale=0.97 or "
                       "k1=1.05e9 (repeatable)")
    synth.add_argument("--seed", type=int, default=0, help="seed of noise and record starts (default 0)")
    synth.add_argument("--noise", type=float, default=0.02,
                       help="sensor noise as a fraction of each record's RMS (default 0.02)")
    synth.add_argument("--ramp", action="append", default=[], metavar="START:STOP:RATE[:TORQUE]",
                       help="a run-up (or coast-down) START to STOP rpm at RATE rpm/s, drive torque TORQUE N m "
                       "(default 7000), recorded instead of the steady runs (repeatable)")
    synth.add_argument("--foreign", type=float, metavar="GRADE",
                       help="record the foreign virtual rig (a gearbox of another model form than the model's) "
                       "with gears drawn at ISO 1328-1 class GRADE (1 to 11); takes --effect, --noise, --seed "
                       "and --ramp, not --true")
    synth.add_argument("--gears-seed", type=int, metavar="N",
                       help="with --foreign: seed of the drawn gears (default: --seed); one seed gives the same "
                       "gears steady and with --ramp, so a healthy reference and a test campaign of one "
                       "--gears-seed and different --seed share their gears, as diagnose --reference needs")
    synth.set_defaults(handler=_command_synth_rig)

    calibrate = commands.add_parser(
        "calibrate",
        help="Bayesian calibration of the model against rig data",
        description="Calibrate mesh stiffness scale, mesh damping, backlash, STE "
        "amplitude and bearing stiffness (and T2 per run) against a rig file with "
        "emcee; write DIR/posterior.nc, DIR/calibration.json, DIR/report.html.",
    )
    calibrate.add_argument("rig", metavar="RIG.nc")
    calibrate.add_argument("--out", required=True, metavar="DIR", help="new or empty output folder")
    calibrate.add_argument(
        "--design",
        metavar="NAME|FILE",
        help="nominal design, replacing the rig file's "
        "(whose copy is then not checked; default: the rig file's design)",
    )
    calibrate.add_argument(
        "--params",
        nargs="+",
        metavar="NAME",
        help="parameters to calibrate (default: mesh_stiffness_scale zeta_mesh backlash ste_amplitude k1 k2)",
    )
    calibrate.add_argument("--seed", type=int, default=0, help="sampler seed (default 0)")
    calibrate.add_argument("--workers", type=int, metavar="N", help="integrator threads (default: all cores)")
    calibrate.add_argument(
        "--pitch-classes",
        nargs="+",
        default=["6", "8"],
        metavar="CLASS",
        help="ISO 1328-1 flank tolerance classes of the rig's gears, lowest and highest, for "
        "the pitch-error correction (default 6 8); 'none': read the level from the sidebands",
    )
    calibrate.add_argument(
        "--discrepancy",
        action="store_true",
        help="add a model-discrepancy function of speed and torque per channel and harmonic "
        "(for a rig whose physics the model does not have; docs/validation/calibration.md)",
    )
    calibrate.set_defaults(handler=_command_calibrate)

    diagnose = commands.add_parser(
        "diagnose",
        help="where model and rig disagree, which unmodelled effect causes it, how far the gap shrinks",
        description="Calibrate the nominal model, map the standardised gap over "
        "op x channel x feature family, fit each candidate effect and score it on "
        "held-out operating points; write DIR/diagnosis.json, DIR/diagnosis.nc, "
        "DIR/report.html.",
    )
    diagnose.add_argument("rig", metavar="RIG.nc")
    diagnose.add_argument("--out", required=True, metavar="DIR", help="new or empty output folder")
    diagnose.add_argument(
        "--design",
        metavar="NAME|FILE",
        help="nominal design, replacing the rig file's "
        "(whose copy is then not checked; default: the rig file's design)",
    )
    diagnose.add_argument(
        "--effects", nargs="+", metavar="NAME", help="candidate effects (default: all six of the library)"
    )
    diagnose.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    diagnose.add_argument("--workers", type=int, metavar="N", help="worker processes (default: one per CPU, at most 8)")
    diagnose.add_argument(
        "--reference",
        metavar="HEALTHY.nc",
        help="a campaign of the same rig with a known good gearbox: the diagnosis says what "
        "changed since it, where, and which effect explains what share of the change",
    )
    diagnose.add_argument(
        "--reference-gears",
        choices=("same", "replaced"),
        default="same",
        help="with --reference: the test runs the reference's gears (default) or a replaced set "
        "of the same quality, whose manufacturing spread is then allowed for",
    )
    diagnose.add_argument(
        "--reference-route",
        choices=("change", "transfer"),
        default="change",
        help="with --reference: judge the change on condition-monitoring features and score the "
        "effects on it (default), or learn the reference's transfer correction of the model",
    )
    diagnose.add_argument(
        "--pitch-classes",
        nargs="+",
        default=["6", "8"],
        metavar="CLASS",
        help="ISO 1328-1 flank tolerance classes of the rig's gears, lowest and highest "
        "(default 6 8): where the sidebands show pitch errors on both shafts, what such "
        "errors do is model error, not an effect; 'none': perfect gears",
    )
    diagnose.set_defaults(handler=_command_diagnose)

    blind = commands.add_parser(
        "blindtest",
        help="blind check of the diagnosis on virtual-rig campaigns",
        description="Generate campaigns with withheld effects (and healthy controls), "
        "diagnose them, write the confusion matrix, shrink statistics and detection "
        "thresholds (DIR/blindtest.json, DIR/blindtest.nc, DIR/report.html). Campaigns "
        "follow the public campaigns' service points, bearing-clearance ones a light-load "
        "bearing check; healthy controls alternate both.",
    )
    blind.add_argument("--out", required=True, metavar="DIR", help="new or empty output folder")
    blind.add_argument("--n-per-effect", type=int, default=3, metavar="N", help="campaigns per effect (default 3)")
    blind.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    blind.add_argument(
        "--suite",
        choices=("library", "real_world", "encoderless", "runup", "foreign"),
        default="library",
        help="library: each effect alone on a clean rig (default); real_world: two effects at "
        "once, a transfer-path resonance with a healthy reference, speed wander, pitch errors and "
        "healthy controls with those nuisances (--n-per-effect campaigns of each kind); encoderless: "
        "each effect alone on a rig with accelerometers only, no TE, and two such healthy controls; "
        "runup: the real_world kinds without pitch errors, each recorded as a run-up and a coast-down; "
        "foreign: what changed since a healthy reference on a rig whose physics is not the model's",
    )
    blind.add_argument(
        "--workers", type=int, metavar="N", help="worker processes of each diagnosis (default: one per CPU, at most 8)"
    )
    blind.set_defaults(handler=_command_blindtest)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``uqgear`` command; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return _run_command(args)
    except InternalError as exc:
        return _internal_failure(args.command, exc)
    except UqgearError as exc:
        return _fail(exc)
    except FileNotFoundError as exc:
        return _fail(f"{exc.filename}: no such file or folder")
    except PermissionError as exc:
        return _fail(f"{exc.filename}: permission denied")
    except KeyboardInterrupt:
        print("uqgear: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
