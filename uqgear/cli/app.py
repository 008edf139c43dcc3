"""The ``uqgear`` command's parser and entry point (:mod:`uqgear.cli` says what it does)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from ..common.errors import InternalError, UqgearError
from .base import EXIT_INTERRUPTED, CommandParser, fail, internal_failure, run_command
from .model_commands import add_model_commands
from .rig_commands import add_rig_commands
from .study_commands import add_study_commands


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``uqgear`` command: its commands, each with its handler.

    Examples
    --------
    >>> from uqgear.cli import build_parser
    >>> args = build_parser().parse_args(["simulate", "--speed", "3000"])
    >>> args.command, args.speed, args.design
    ('simulate', 3000.0, 'locomotive')
    """
    parser = CommandParser(
        prog="uqgear",
        description="Dynamics of railway traction gears under uncertainty: "
        "run YAML studies, write netCDF results and self-contained HTML reports.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"uqgear {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=CommandParser)
    commands.required = True

    add_study_commands(commands)
    add_model_commands(commands)
    add_rig_commands(commands)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``uqgear`` command; returns the exit status.

    Examples
    --------
    A user mistake is one line on standard error and exit status 2:

    >>> import contextlib, io
    >>> from uqgear.cli import main
    >>> with contextlib.redirect_stderr(io.StringIO()) as err:
    ...     status = main(["validate", "no-such-study.yaml"])
    >>> status, err.getvalue().count("\\n")
    (2, 1)
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return run_command(args)
    except InternalError as exc:
        return internal_failure(args.command, exc)
    except UqgearError as exc:
        return fail(exc)
    except FileNotFoundError as exc:
        return fail(f"{exc.filename}: no such file or folder")
    except PermissionError as exc:
        return fail(f"{exc.filename}: permission denied")
    except KeyboardInterrupt:
        print("uqgear: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


__all__ = ["build_parser", "main"]
