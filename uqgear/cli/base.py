"""What every command shares: exit statuses, one-line errors, output checks and option parsing.

A user mistake ends with exit status :data:`EXIT_USER_ERROR` and one line on standard error
(:func:`fail`); an internal failure after the input was accepted with :data:`EXIT_INTERNAL_ERROR` and
one line naming the step and the outputs kept (:func:`internal_failure`).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import NoReturn

from ..common.errors import InternalError, UqgearError, UqgearWarning
from ..common.transaction import OutputFolder

#: Exit status of an internal failure after the input was accepted.
EXIT_INTERNAL_ERROR = 1
#: Exit status of a user mistake.
EXIT_USER_ERROR = 2
#: Exit status after Ctrl-C.
EXIT_INTERRUPTED = 130


class CommandParser(argparse.ArgumentParser):
    """argparse with one-line error messages and exit status 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USER_ERROR, f"uqgear: error: {message} (see '{self.prog} --help')\n")


def one_line(message: object) -> str:
    """``message`` as one line: its whitespace, line breaks included, collapsed to single spaces.

    Examples
    --------
    >>> one_line("a study\\n  without   analyses")
    'a study without analyses'
    """
    return " ".join(str(message).split())


def fail(message: object) -> int:
    """Print ``uqgear: error: MESSAGE`` as one line on standard error; return the user-mistake exit status."""
    print(f"uqgear: error: {one_line(message)}", file=sys.stderr)
    return EXIT_USER_ERROR


def run_command(args: argparse.Namespace) -> int:
    """Run a command's handler; uqgear's own warnings (an undercut design, ...) print as one line each."""
    with warnings.catch_warnings():
        python_style = warnings.showwarning
        shown: set[str] = set()  # a design read from several places (file, copies) is reported once

        def show(message, category, filename, lineno, file=None, line=None) -> None:
            if not issubclass(category, UqgearWarning):
                python_style(message, category, filename, lineno, file, line)
            elif one_line(message) not in shown:
                shown.add(one_line(message))
                print(f"uqgear: warning: {one_line(message)}", file=sys.stderr)

        warnings.showwarning = show
        return args.handler(args)


#: What each command computes, for the message of an internal failure.
WORK = {
    "run": "study run",
    "calibrate": "calibration",
    "diagnose": "diagnosis",
    "blindtest": "blind test",
    "simulate": "simulation",
    "synth-rig": "virtual rig simulation",
    "report": "report",
}


def internal_failure(command: str, exc: InternalError) -> int:
    """One line naming the failed step and where the finished outputs are; exit status 1."""
    kept = ""
    if exc.kept:
        from ..common.steps import FAILURE_RECORD

        record = Path(exc.kept) / FAILURE_RECORD
        kept = f"; finished outputs kept in {exc.kept}" + (f" (see {FAILURE_RECORD})" if record.is_file() else "")
    print(
        one_line(
            f"uqgear: internal error during {WORK.get(command, command)} step '{exc.step}': "
            f"{exc.detail}{kept}; this is not a mistake in the input, please report it"
        ),
        file=sys.stderr,
    )
    return EXIT_INTERNAL_ERROR


def check_new_file(out: Path, force: bool, where: str | None = None) -> None:
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



def parse_assignments(items: Sequence[str], option: str) -> dict[str, float]:
    """``KEY=VALUE`` pairs of a repeated option, values as floats.

    Examples
    --------
    >>> parse_assignments(["k1=1.05e9", "mesh_stiffness_scale = 0.97"], "--true")
    {'k1': 1050000000.0, 'mesh_stiffness_scale': 0.97}
    """
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


def new_output_folder(out: Path) -> Path:
    """``--out``: a new or empty folder, checked before any work (the library writes it as a whole)."""
    OutputFolder(out, where="--out", existing="refuse").check()
    return out


def comma_list(items: list[str] | None) -> list[str] | None:
    """Names given as separate arguments and/or comma-separated ones; None when none were given.

    Examples
    --------
    >>> comma_list(["k1,k2", "backlash"]), comma_list(None)
    (['k1', 'k2', 'backlash'], None)
    """
    return [name for item in items for name in item.split(",") if name] if items else None


def pitch_classes(words: list[str]) -> tuple[float, float] | None:
    """``--pitch-classes``: two ISO 1328-1 classes, or ``none`` (the calibration or diagnosis checks their range).

    Examples
    --------
    >>> pitch_classes(["6", "8"]), pitch_classes(["none"])
    ((6.0, 8.0), None)
    """
    if [word.lower() for word in words] == ["none"]:
        return None
    try:
        values = tuple(float(word) for word in words)
    except ValueError:
        values = ()
    if len(values) != 2:
        raise UqgearError(f"--pitch-classes: expected two ISO 1328-1 classes (e.g. 6 8) or none; got {' '.join(words)}")
    return values[0], values[1]



__all__ = [
    "EXIT_INTERNAL_ERROR",
    "EXIT_INTERRUPTED",
    "EXIT_USER_ERROR",
    "CommandParser",
    "check_new_file",
    "comma_list",
    "fail",
    "internal_failure",
    "new_output_folder",
    "one_line",
    "parse_assignments",
    "pitch_classes",
    "run_command",
]
