"""The model runs of a diagnosis: what a run is, how runs are reduced to features, and the worker processes."""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
from threadpoolctl import ThreadpoolController, threadpool_limits

from ..physics.design import Design
from ..physics.effects import Effect
from ..physics.pitch_errors import PitchErrors
from ..rig.order_tracking import TrackerImage
from .processing import RunProcessor
from .simulation import CampaignSimulator, SimulatedRun


class RunContext(Protocol):
    """What running a task reads of a prepared campaign (:class:`~uqgear.diagnosis.case.RigCase` is one)."""

    @property
    def simulator(self) -> CampaignSimulator: ...

    @property
    def processors(self) -> list[RunProcessor]: ...

    @property
    def channels(self) -> tuple[str, ...]: ...

    @property
    def transfer(self) -> np.ndarray | None: ...

    @property
    def line_gain(self) -> np.ndarray | None: ...

    @property
    def tracking(self) -> tuple[TrackerImage | None, ...]: ...


#: What a run's records can be reduced to, and the :class:`~.processing.RunProcessor` method that does it.
REDUCTIONS = {"features": "model_features", "phasors": "model_phasors", "line_phasors": "model_line_phasors"}


@dataclass(frozen=True)
class RunTask:
    """One run to simulate and reduce to features: all a worker process needs besides the case."""

    op: int
    design: Design
    mesh_stiffness_scale: float
    adhesion_torque: float
    effects: tuple[Effect, ...]
    periodicity: str
    # per-tooth pitch errors of the gears (allowances.pitch_errors); None: perfect gears
    pitch_errors: PitchErrors | None = None
    # what the records are reduced to (:data:`REDUCTIONS`): features, or complex line phasors with the
    # other features (real part), or the line phasors alone
    reduction: str = "features"
    # whether the features read the model's mesh sidebands as the rig's order tracking left the rig's
    # where it resampled the record (:class:`~uqgear.rig.order_tracking.TrackerImage`)
    tracked: bool = True


# The BLAS and OpenMP thread pools of this process, found on first use (finding them inspects every
# loaded library, about 5 ms, the cost of a small periodic run); a forked worker inherits them. By
# the first model run numpy's and scipy's BLAS are loaded (they are at import of this package).
_THREAD_POOLS: ThreadpoolController | None = None


def one_blas_thread() -> AbstractContextManager[Any]:
    """A context in which the linear algebra of this process runs on one thread.

    The thread pools are found once per process, not on every call.
    """
    global _THREAD_POOLS
    if _THREAD_POOLS is None:
        _THREAD_POOLS = ThreadpoolController()
    return _THREAD_POOLS.limit(limits=1)


def simulate_task(case: RunContext, task: RunTask) -> SimulatedRun:
    """The model records of a run on the rig's time grid."""
    return case.simulator.run(
        task.op,
        task.design,
        task.mesh_stiffness_scale,
        task.adhesion_torque,
        task.effects,
        task.periodicity,
        pitch_errors=task.pitch_errors,
    )


def execute_run(case: RunContext, task: RunTask) -> tuple[np.ndarray, bool]:
    """Simulate a run and reduce its records with the rig's processing: (n_channel, all features), periodic."""
    # one BLAS thread, as every grouped path (execute_runs, the workers) reduces its runs
    with one_blas_thread():
        return execute_group(case, [task])[0]


def execute_group(case: RunContext, tasks: Sequence[RunTask]) -> list[tuple[np.ndarray, bool]]:
    """Simulate runs of one operating point and reduce their records together.

    The line fit reads its least-squares basis (tens of MB) once per call:
    records of the same run in one call share that read, which is most of a
    periodic run's cost.
    """
    ops = {task.op for task in tasks}
    if len(ops) != 1:
        # an internal invariant (run_groups makes the groups): the step log reports it as internal
        raise RuntimeError(f"execute_group: expected runs of one operating point; got runs {sorted(ops)}")
    op = ops.pop()
    reductions = {(task.reduction, task.tracked) for task in tasks}
    if len(reductions) != 1 or not {reduction for reduction, _ in reductions} <= set(REDUCTIONS):
        raise RuntimeError(f"execute_group: expected runs reduced alike, one of {REDUCTIONS}; got {reductions}")
    # integrated together: runs of one operating point share SIMD lanes (each run's numbers as alone)
    runs = case.simulator.runs(op, tasks)
    stacked = np.concatenate([np.stack([run.records[channel] for channel in case.channels]) for run in runs])
    reduction, tracked = reductions.pop()
    reduce = getattr(case.processors[op], REDUCTIONS[reduction])
    # The rig's record was resampled on its own mesh lines: the features the fits compare read the
    # model's sidebands as that resampling left them, unless the task says otherwise (under the
    # pitch-error allowance, :attr:`~.case.RigCase.reads_tracked`). The phasor reductions (the
    # allowance's draws, the sideband phase sums) read the model as it runs.
    tracking = case.tracking[op] if tracked and case.tracking and reduction == "features" else None
    features = (reduce(stacked) if tracking is None else reduce(stacked, tracking)).reshape(
        len(runs), len(case.channels), -1
    )
    if case.transfer is not None:
        # the rig sees the gear through its transfer paths: the model's features as the rig would record them
        transferred = features * case.transfer[op]
        if case.line_gain is not None:
            rms = case.processors[op].columns["rms"]
            transferred[..., rms] = (
                transferred_rms(features, case.line_gain[op], case.processors[op]) * case.transfer[op][:, rms]
            )
        features = transferred
    return [(features[index], run.periodic) for index, run in enumerate(runs)]


def transferred_rms(features: np.ndarray, line_gain: np.ndarray, processor: RunProcessor) -> np.ndarray:
    """The RMS of model records seen through a transfer path with gain ``line_gain`` at each line.

    A transfer path acts on frequency: a resonance near one mesh harmonic
    raises that line, not the record's RMS as a whole. The mean square is
    the lines' power (half the squared amplitude of each distinct line)
    plus the rest; each line's power is scaled by its squared gain, the
    rest kept (a reference's direct RMS correction then scales the
    result). One ratio read at a reference run would not follow a test
    campaign whose line mix differs (docs/model/unmodelled-effects.md section 6.1, step 3).

    Parameters
    ----------
    features : array (..., all features)
        Model features (amplitudes or phasors of the lines), not yet transferred.
    line_gain : array (..., all features)
        The path's gain at each line column, broadcast against ``features``.
    processor : RunProcessor
        The run's processing (its columns).

    Returns
    -------
    array (...)
    """
    columns = processor.distinct_line_columns
    amplitude = np.nan_to_num(np.abs(features[..., columns]))
    gain = np.broadcast_to(line_gain, features.shape)[..., columns]
    line_power = 0.5 * np.sum(amplitude**2, axis=-1)
    rest = np.maximum(np.real(features[..., processor.columns["rms"]]) ** 2 - line_power, 0.0)
    return np.sqrt(rest + 0.5 * np.sum((gain * amplitude) ** 2, axis=-1))


# Most runs of one operating point reduced in one call (:func:`execute_group`):
# enough to share the line fit's basis, few enough to spread a batch over workers.
GROUP_SIZE = 8


def run_groups(tasks: Sequence[RunTask]) -> list[list[int]]:
    """Indices of ``tasks`` in groups of one operating point, at most :data:`GROUP_SIZE` each.

    The grouping depends on the task list alone, never on the number of
    workers: every run is reduced in the same company, so the numbers are
    the same bit for bit however the groups are spread.
    """
    by_op: dict[int, list[int]] = {}
    for index, task in enumerate(tasks):
        by_op.setdefault(task.op, []).append(index)
    groups = []
    for op in sorted(by_op):
        indices = by_op[op]
        groups += [indices[start : start + GROUP_SIZE] for start in range(0, len(indices), GROUP_SIZE)]
    return groups


def execute_runs(
    case: RunContext,
    tasks: Sequence[RunTask],
    group_map: Callable[[list[list[RunTask]]], list[list[tuple[np.ndarray, bool]]]] | None = None,
) -> list[tuple[np.ndarray, bool]]:
    """Features and periodicity of each task, in order, computed group by group (:func:`run_groups`).

    ``group_map`` maps the task groups to their results (a worker pool's
    map); by default they are computed here, with one BLAS thread as in a
    worker.
    """
    groups = run_groups(tasks)
    grouped = [[tasks[index] for index in group] for group in groups]
    if group_map is None:
        with one_blas_thread():
            results = [execute_group(case, group) for group in grouped]
    else:
        results = group_map(grouped)
    out: list[tuple[np.ndarray, bool] | None] = [None] * len(tasks)
    for group, values in zip(groups, results):
        for index, value in zip(group, values):
            out[index] = value
    return out  # type: ignore[return-value]


# The case a forked worker process inherits from its parent (set just before
# the pool is created): the processors hold large least-squares bases that
# are cheaper to share by fork than to pickle.
_INHERITED_CASE: RunContext | None = None


def _worker_execute(tasks: list[RunTask]) -> tuple[list[tuple[np.ndarray, bool]], float]:
    assert _INHERITED_CASE is not None, "worker started without a case"  # internal invariant, not user input
    started = time.perf_counter()
    results = execute_group(_INHERITED_CASE, tasks)
    return results, time.perf_counter() - started


def _single_threaded_worker() -> None:
    # the workers are the parallelism: a multi-threaded BLAS in each would only spin on the same cores
    threadpool_limits(1)


class RunExecutor:
    """Runs :class:`RunTask` lists sequentially or over forked worker processes.

    Every run's linear algebra is single-threaded, in this process as in a
    worker: the runs of a batch are the parallelism (a threaded BLAS on top
    of them only busy-waits, measured: the same wall time at twice the CPU
    time), and one thread count everywhere keeps the numbers bit for bit the
    same however many workers there are.

    Parameters
    ----------
    case : RunContext
        The prepared campaign (:class:`~uqgear.diagnosis.case.RigCase`).
    workers : int
        Worker processes (1: in this process). Needs the ``fork`` start
        method; elsewhere runs stay in this process.
    """

    def __init__(self, case: RunContext, workers: int = 1) -> None:
        global _INHERITED_CASE
        self.case = case
        self.pool = None
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            _INHERITED_CASE = case
            try:
                self.pool = multiprocessing.get_context("fork").Pool(workers, initializer=_single_threaded_worker)
            finally:
                _INHERITED_CASE = None
        self.workers = workers if self.pool is not None else 1
        # seconds per run of each operating point, as last measured: the dearest groups go out first
        self._run_seconds: dict[int, float] = {}

    def map(self, tasks: Sequence[RunTask]) -> list[tuple[np.ndarray, bool]]:
        if self.pool is None or len(tasks) < 2:
            return execute_runs(self.case, tasks)
        return execute_runs(self.case, tasks, self._spread)

    def _spread(self, groups: list[list[RunTask]]) -> list[list[tuple[np.ndarray, bool]]]:
        """Results of the groups, computed by the workers, the longest expected first.

        A run that does not repeat (simulated over the whole record) costs
        several times a periodic one, and such runs gather at a few
        operating points: sent last, their groups would leave the other
        workers idle. Only the order of dispatch changes, never a group.
        """
        assert self.pool is not None  # internal invariant: called only with a pool
        expected = [len(group) * self._run_seconds.get(group[0].op, math.inf) for group in groups]
        order = sorted(range(len(groups)), key=lambda index: -expected[index])
        answers = self.pool.map(_worker_execute, [groups[index] for index in order], chunksize=1)
        results: list[list[tuple[np.ndarray, bool]]] = [[] for _ in groups]
        for index, (values, seconds) in zip(order, answers):
            results[index] = values
            self._run_seconds[groups[index][0].op] = seconds / len(groups[index])
        return results

    def close(self) -> None:
        if self.pool is not None:
            self.pool.close()
            self.pool.join()
            self.pool = None


__all__ = [
    "RunContext",
    "RunTask",
    "RunExecutor",
    "simulate_task",
    "execute_run",
    "execute_group",
    "execute_runs",
    "run_groups",
    "transferred_rms",
    "one_blas_thread",
    "GROUP_SIZE",
    "REDUCTIONS",
]
