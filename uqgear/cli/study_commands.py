"""The study commands: ``validate``, ``run``, ``examples`` and ``report``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..common.transaction import OutputFolder, is_empty_folder, partial_folder
from .base import EXIT_INTERRUPTED, check_new_file, fail

# ---------------------------------------------------------------------------- validate


def _command_validate(args: argparse.Namespace) -> int:
    from ..study.schema import load_study

    study = load_study(args.study)
    kinds = ", ".join(f"{spec.name} ({spec.type})" for spec in study.analyses)
    print(f"{args.study}: valid study {study.name!r} with {len(study.analyses)} analyses: {kinds}")
    return 0


# ---------------------------------------------------------------------------- run


def _command_run(args: argparse.Namespace) -> int:
    from ..study.schema import load_study

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        return fail(f"--out {out}: exists and is not a folder; expected a new or empty folder")
    if out.is_dir() and not is_empty_folder(out) and not args.resume:
        return fail(
            f"--out {out}: folder exists and is not empty; choose a new folder, remove it, "
            "or pass --resume to continue or update that run"
        )
    OutputFolder(out, where="--out", existing="replace").check()
    if args.workers is not None and args.workers < 1:
        return fail(f"--workers: expected a positive integer; got {args.workers}")
    # the study is validated completely before anything is created
    study = load_study(args.study)

    from ..study.running import run_study

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
    from ..common.yamlio import YAMLError, load_yaml

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
    from ..common.resources import bundled_file, bundled_names

    if args.action == "copy":
        return _copy_example(args)
    if args.action is not None:
        return fail(f"examples: unknown action {args.action[:40]!r}; expected 'copy' or nothing")
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
    from ..common.fileio import write_text_atomic
    from ..common.resources import bundled_file

    if args.name is None or args.dest is None:
        return fail("examples copy: expected a study name and a destination: uqgear examples copy NAME DEST.yaml")
    source = bundled_file("study", args.name)
    dest = Path(args.dest)
    if dest.is_dir():
        dest = dest / source.name
    if dest.suffix.lower() not in (".yaml", ".yml"):
        return fail(f"examples copy: {args.dest}: expected a folder or a file name ending in .yaml")
    check_new_file(dest, args.force, f"examples copy: {dest}")
    write_text_atomic(dest, source.read_text())
    print(f"study {source.stem} copied to {dest} (run it with: uqgear run {dest} --out DIR)")
    return 0


# ---------------------------------------------------------------------------- report


def _command_report(args: argparse.Namespace) -> int:
    from ..report.study_report import write_report
    from ..study.limits import check_dpi

    path = write_report(Path(args.directory), dpi=check_dpi(args.dpi, "--dpi"))
    print(f"report written to {path}")
    return 0




# ---------------------------------------------------------------------------- parsers


def add_study_commands(commands: Any) -> None:
    """The parsers of ``validate``, ``run``, ``examples`` and ``report`` in ``commands``."""
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


__all__ = ["add_study_commands"]
