"""The steps of a long computation as they finish, and the record kept when one fails.

A diagnosis or a calibration runs for minutes after its input was accepted.
:class:`StepLog` runs each step inside :func:`~uqgear.common.errors.internal_step`
(a failure names its step and is reported as internal, not as the user's
mistake) and keeps what every finished step found, so that a failure late in
the work does not lose it: :func:`write_failure_record` writes ``failure.json``
with the failed step, the error, the traceback and the finished steps.
"""

from __future__ import annotations

import json
import os
import time
import traceback
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from .errors import InternalError, internal_step
from .fileio import write_text_atomic

#: Name of the record a failed computation leaves in its output folder.
FAILURE_RECORD = "failure.json"


class StepLog:
    """The finished steps of one computation, in order, each with what it found.

    A failure inside a step is raised as :class:`InternalError` naming it;
    the steps finished before are attached to that error (``finished``).

    Examples
    --------
    >>> from uqgear.common.steps import StepLog
    >>> steps = StepLog()
    >>> with steps.step("count the teeth") as found:
    ...     found["teeth"] = 21 + 101
    >>> [(record["step"], record["teeth"]) for record in steps.finished]
    [('count the teeth', 122)]
    >>> try:
    ...     with steps.step("divide the load") as found:
    ...         found["share"] = 1 / 0
    ... except Exception as error:
    ...     print(type(error).__name__, error.step, [record["step"] for record in error.finished])
    InternalError divide the load ['count the teeth']
    """

    def __init__(self) -> None:
        self.finished: list[dict[str, Any]] = []

    @contextmanager
    def step(self, name: str) -> Iterator[dict[str, Any]]:
        """Run one step; yields a dict for what it found (JSON-ready values), kept when it finishes."""
        started = time.perf_counter()
        found: dict[str, Any] = {}
        try:
            with internal_step(name):
                yield found
        except InternalError as exc:
            if not exc.finished:
                exc.finished = list(self.finished)
            raise
        self.finished.append({"step": name, "seconds": round(time.perf_counter() - started, 3), **found})


def _json_ready(value: Any) -> Any:
    """Non-finite floats as None, numpy scalars as numbers, anything else unknown as text."""
    if isinstance(value, dict):
        return {str(key): _json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_ready(item) for item in value]
    if isinstance(value, bool) or value is None or isinstance(value, (str, int)):
        return value
    try:
        number = float(value)
    except (TypeError, ValueError):
        return str(value)
    return number if number == number and abs(number) != float("inf") else None


def write_failure_record(
    folder: str | os.PathLike[str], error: InternalError, *, command: str, inputs: dict[str, Any] | None = None
) -> Path:
    """Write ``failure.json`` into ``folder``: what failed, where, and what had finished.

    Parameters
    ----------
    folder : path
        The computation's output folder (it exists).
    error : InternalError
        The failure (its ``step``, ``cause`` and ``finished`` steps).
    command : str
        What was running (``"diagnosis"``, ``"calibration"``).
    inputs : dict, optional
        The inputs, to rerun it (rig file, seed, options).

    Returns
    -------
    pathlib.Path
        The record written.
    """
    folder = Path(folder)
    cause = error.cause
    outputs = sorted(item.name for item in folder.iterdir() if item.name != FAILURE_RECORD)
    content = {
        "status": "failed",
        "command": command,
        "internal_error": True,
        "failed_step": error.step,
        "error": error.detail,
        "outputs_finished": outputs,
        "finished_steps": error.finished,
        "inputs": inputs or {},
        "traceback": "".join(traceback.format_exception(type(cause), cause, cause.__traceback__)),
        "note": "an internal failure of uqgear after the input was accepted, not a mistake in the input; "
        "please report it with this file",
    }
    path = folder / FAILURE_RECORD
    write_text_atomic(path, json.dumps(_json_ready(content), indent=2))
    return path


__all__ = ["FAILURE_RECORD", "StepLog", "write_failure_record"]
