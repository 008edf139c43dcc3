"""Helpers shared by the test modules (not a fixture: plain functions)."""

from __future__ import annotations

import math
import subprocess
from typing import Any

from uqgear.cli import main
from uqgear.diagnosis import CandidateScore


def candidate_score(effect: str, score: float, shrink: float, low: float | None = None, **figures: Any
                    ) -> CandidateScore:
    """A candidate's held-out figures as the verdict reads them, without a fit behind them.

    ``shrink`` is the shrink fraction, its interval [``low`` (default
    ``shrink`` - 0.1), min(``shrink`` + 0.1, 1)]; ``figures`` set the other
    fields (``gap_with_effect``, ``standard_error``, ``effect_gain``,
    ``gap_interval``, ``run_out``, ``shrink_interval``, ...). What is not given
    is unknown: an infinite standard error, gap and effect gain.
    """
    values: dict[str, Any] = {
        "effect": effect, "label": effect, "fit": None, "held": None, "stage": "full", "delta_log_density": score,
        "standard_error": math.inf, "penalty": 0.0, "score": score, "gap_with_effect": math.inf,
        "shrink_fraction": shrink,
        "shrink_interval": (shrink - 0.1 if low is None else low, min(shrink + 0.1, 1.0))}
    values.update(figures)
    if "shrink_interval" in figures:
        values["shrink_interval"] = tuple(figures["shrink_interval"])
    return CandidateScore(**values)


def cli_in_process(capsys: Any, *args: Any) -> subprocess.CompletedProcess:
    """The command line run in this process: what it does and refuses, not the interpreter's start.

    Its exit status, standard output and error as a finished process, like a real ``uqgear`` run's
    (the tests of a user mistake's exit 2 and the smoke run go through a real process).
    """
    capsys.readouterr()
    try:
        status = main([str(argument) for argument in args])
    except SystemExit as stop:  # argparse's refusals
        status = stop.code
    out, err = capsys.readouterr()
    return subprocess.CompletedProcess(list(args), status, out, err)
