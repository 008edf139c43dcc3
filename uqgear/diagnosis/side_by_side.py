"""Independent fits side by side: each on a thread of this process, their model runs on the workers together.

A fit alternates between work in this process (the least-squares step,
discrepancies, held-out predictions) and batches of model runs on the
worker processes, a handful of runs each; one fit at a time leaves the
workers idle while this process works, and the last runs of a batch leave
all but one worker idle. Two fits side by side fill those gaps. Only
fits that read nothing the others write go side by side (the screening
fits of the variants of one round), and each result is taken up in the
order the fits were listed, so the numbers are those of one fit after the
other, bit for bit: the fits are deterministic, and what draws random
numbers (the bootstrap of a score) runs afterwards, in order.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Generic, TypeVar

from .case import RigCase

Result = TypeVar("Result")

#: Fits run side by side: two keep the workers busy while this process works on the other fit.
FITS_AT_ONCE = 2


@dataclass(frozen=True)
class Outcome(Generic[Result]):
    """What one fit gave: its result or the error it raised, and its seconds on its own thread."""

    value: Result | None
    error: BaseException | None
    seconds: float

    def get(self) -> Result:
        """The result, or the fit's error raised here (inside the caller's step, which names it)."""
        if self.error is not None:
            raise self.error
        return self.value  # type: ignore[return-value]


def _attempt(job: Callable[[], Result]) -> Outcome[Result]:
    started = time.perf_counter()
    try:
        value = job()
    except Exception as error:  # noqa: BLE001 - handed back, raised where the caller takes the result up
        return Outcome(None, error, time.perf_counter() - started)
    return Outcome(value, None, time.perf_counter() - started)


def side_by_side(case: RigCase, jobs: Sequence[Callable[[], Result]]) -> list[Outcome[Result]]:
    """The outcomes of independent fits, in order; side by side where the case's runs go to worker processes.

    With the runs in this process (no worker processes) the fits run one
    after the other: threads would only take turns on the same core.
    """
    executor = case.executor
    if executor is None or executor.workers < 2 or len(jobs) < 2:
        return [_attempt(job) for job in jobs]
    threads = ThreadPoolExecutor(max_workers=min(FITS_AT_ONCE, len(jobs)), thread_name_prefix="uqgear-fit")
    try:
        outcomes = list(threads.map(_attempt, jobs))
    except BaseException:
        # Ctrl-C: the fits not started are dropped, and the caller does not wait for the running ones
        threads.shutdown(wait=False, cancel_futures=True)
        raise
    threads.shutdown(wait=True)
    return outcomes


__all__ = ["Outcome", "side_by_side", "FITS_AT_ONCE"]
