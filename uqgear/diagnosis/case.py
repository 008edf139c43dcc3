"""A rig campaign prepared for diagnosis, and its model runs executed in this process or forked workers."""

from __future__ import annotations

import math
import multiprocessing
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from ..physics.design import Design
from ..physics.effects import Effect
from ..physics.pitch_errors import PitchErrors
from ..rig import features as feature_module
from ..rig.features import SIGNAL_CHANNELS
from ..rig.order_tracking import speed_summary, track_orders
from .discrepancy import FeatureLayout, NoiseModel, line_noise_sigma, noise_model
from .errors import DiagnosisError
from .interference import NOTCH_HALF_WIDTH, interference_lines
from .simulation import CampaignSimulator, RunProcessor, SimulatedRun

# Relative model error (standard deviation) by feature kind: line amplitudes,
# band powers (as amplitudes), the broadband RMS and kurtosis. With their true
# parameters and effect the model reproduces the reference campaigns' lines to
# well under 1 % (a few per cent for lines near the noise floor); 3 % leaves
# room for an independent rig without hiding a friction-sized change.
DEFAULT_MODEL_ERROR: dict[str, float] = {"line": 0.03, "band": 0.05, "rms": 0.03, "kurtosis": 0.05}

#: Options of the feature processing (as :func:`uqgear.rig.features.extract_features`).
FEATURE_OPTIONS: dict[str, Any] = {"n_harmonics": 3, "n_sidebands": 3, "n_shaft_orders": 3, "n_motor_lines": 2,
                                   "low_band": (2.0, 80.0), "window": "hann"}


class FeatureModelError(dict):
    """Relative model error per feature kind, widened feature by feature, and absolute model error.

    The dict's own items are the per-kind errors (what summaries and JSON
    show); looking a kind up returns them combined in quadrature with a
    per-feature widening (n_op, n_channel, features of that kind in layout
    order), e.g. the uncertainty of a reference campaign's transfer
    correction (:mod:`uqgear.diagnosis.reference`). Arrays broadcast where
    :func:`~uqgear.diagnosis.discrepancy.standardised_discrepancy` uses scalars.

    ``absolute`` holds, per kind, model error that does not scale with the
    model's value (same shapes): for lines a per-quadrature standard
    deviation in the channel's units, for band and RMS features a standard
    deviation of the power, for kurtosis one of the kurtosis; e.g. what the
    pitch errors of manufactured gears add (:mod:`uqgear.diagnosis.manufacturing`).
    """

    def __init__(self, base: Mapping[str, float], widening: Mapping[str, np.ndarray],
                 absolute: Mapping[str, np.ndarray] | None = None) -> None:
        super().__init__({key: float(value) for key, value in dict(base).items()})
        self.widening = {key: np.asarray(value, dtype=float) for key, value in widening.items()}
        self.absolute = {key: np.asarray(value, dtype=float) for key, value in (absolute or {}).items()}

    def __getitem__(self, kind: str) -> Any:
        base = super().__getitem__(kind)
        extra = self.widening.get(kind)
        if extra is None or extra.size == 0:
            return base
        return np.sqrt(base ** 2 + extra ** 2)

    @classmethod
    def combined(cls, current: Mapping[str, float], absolute: Mapping[str, np.ndarray]) -> "FeatureModelError":
        """``current`` (a plain mapping or one of these) with ``absolute`` added to its absolute errors."""
        widening = getattr(current, "widening", {})
        before = dict(getattr(current, "absolute", {}))
        for kind, values in absolute.items():
            values = np.asarray(values, dtype=float)
            before[kind] = np.sqrt(before[kind] ** 2 + values ** 2) if kind in before else values
        # dict() of one of these reads the per-kind errors, not the widened arrays
        return cls(dict(current), widening, before)


class AppliedPitchAllowance(Protocol):
    """What a case reads of the pitch-error allowance applied to it.

    :class:`uqgear.diagnosis.manufacturing.PitchErrorAllowance` is one; that
    module builds on this one, so the case names only what it reads.
    """

    applied: bool
    run_out_bound: Mapping[str, float]
    drawn_errors: Sequence[PitchErrors]


@dataclass
class RigCase:
    """A rig campaign prepared for diagnosis: features, noise, processing and simulator."""

    rig: xr.Dataset
    design: Design
    channels: tuple[str, ...]
    speeds: np.ndarray
    drive_torques: np.ndarray
    adhesion_lower: np.ndarray
    adhesion_upper: np.ndarray
    fs: float
    size: int
    processors: list[RunProcessor]
    layout: FeatureLayout
    observed: np.ndarray          # (n_op, n_channel, F) compared features
    observed_all: np.ndarray      # (n_op, n_channel, all features)
    noise_std: np.ndarray         # (n_op, n_channel)
    noise: list[NoiseModel]
    usable: np.ndarray            # (n_op, n_channel)
    simulator: CampaignSimulator
    model_error: dict[str, float]
    speed: list[dict[str, Any]]    # per run: the order tracking's speed estimate
    tracking_s: float              # time spent estimating speeds and resampling
    executor: "RunExecutor | None" = None
    # (n_op, n_channel, all features): the model's features are multiplied by it (a reference
    # campaign's transfer correction, uqgear.diagnosis.reference); None: unity
    transfer: np.ndarray | None = None
    # (n_op, n_channel, all features): the transfer path's gain at each line (1 elsewhere); the model's
    # RMS is then taken through it line by line (transferred_rms) before ``transfer`` scales it
    line_gain: np.ndarray | None = None
    # line interference left out of the low band (uqgear.diagnosis.interference)
    interference: list[dict[str, Any]] = field(default_factory=list)
    # the pitch-error allowance applied to the nominal model (a manufacturing.PitchErrorAllowance) and the
    # model error before it: a fit with effects is scored with its own model's allowance
    # (manufacturing.with_own_allowance); None: none applied
    pitch_allowance: AppliedPitchAllowance | None = None
    model_error_before_allowance: Mapping[str, float] | None = None

    @property
    def n_op(self) -> int:
        return int(self.speeds.size)

    @property
    def run_out_allowance(self) -> dict[str, float]:
        """Per gear, the first-order run-out the stated classes' pitch errors stay under, m
        (:func:`uqgear.diagnosis.manufacturing.run_out_bounds`); empty without an allowance (perfect gears)."""
        return {} if self.pitch_allowance is None else dict(self.pitch_allowance.run_out_bound)

    def line_noise_sigma(self) -> np.ndarray:
        """Per-quadrature noise spread of each compared line (n_op, n_channel, F; NaN for features not lines)."""
        return line_noise_sigma(self.noise_std, self.noise, self.layout)

    def mask(self) -> np.ndarray:
        """Features that enter the comparison: usable runs and finite rig features."""
        return np.isfinite(self.observed) & self.usable[..., None]

    def execute(self, tasks: Sequence["RunTask"]) -> list[tuple[np.ndarray, bool]]:
        """Simulate and reduce runs (through the executor when one is attached)."""
        if self.executor is not None:
            return self.executor.map(tasks)
        return execute_runs(self, tasks)


def prepare_case(rig: xr.Dataset, design: Design, *, seed: np.random.SeedSequence,
                 model_error: Mapping[str, float] | None = None, steps_per_mode: int = 24) -> RigCase:
    """Features, noise models, processors and simulator of a validated rig Dataset.

    The records are first order-tracked (:func:`uqgear.rig.order_tracking.track_orders`):
    every later step, and the model runs at each run's ``pinion_speed``, see
    constant-speed records at the estimated mean speed. Line interference on
    the accelerometers (:mod:`uqgear.diagnosis.interference`) is left out of
    the low band of every record.
    """
    errors = dict(DEFAULT_MODEL_ERROR)
    if model_error is not None:
        unknown = sorted(set(model_error) - set(errors))
        if unknown:
            raise DiagnosisError(f"model_error.{unknown[0]}: unknown feature kind; expected {', '.join(errors)}")
        for key, value in model_error.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < 1.0:
                raise DiagnosisError(f"model_error.{key}: expected a relative error in [0, 1); got {value!r}")
            errors[key] = float(value)
    channels = tuple(name for name in SIGNAL_CHANNELS if name in rig.data_vars)
    clock = time.perf_counter()
    rig = track_orders(rig, design)
    tracking_s = time.perf_counter() - clock
    fs = feature_module.sampling_rate(rig["time"].values, where="rig data: time")
    size = int(rig.sizes["time"])
    options = dict(FEATURE_OPTIONS, band_limit=feature_module.DEFAULT_BAND_FRACTION * fs)
    speeds = np.asarray(rig["pinion_speed"].values, dtype=float)
    processors: list[RunProcessor] = []
    cache: dict[float, RunProcessor] = {}
    for speed in speeds:
        if float(speed) not in cache:
            cache[float(speed)] = RunProcessor(design, float(speed), fs, size, options)
        processors.append(cache[float(speed)])
    layout = FeatureLayout.from_processor(processors[0])
    records = {channel: np.asarray(rig[channel].values, dtype=float) for channel in channels}
    observed_all = np.stack([np.stack([processors[op].features(records[channel][op][None])[0]
                                       for channel in channels]) for op in range(speeds.size)])
    noise_column = processors[0].columns["noise_std"]
    noise_std = observed_all[..., noise_column]
    usable = np.isfinite(observed_all).any(axis=-1) & np.isfinite(noise_std) & (noise_std > 0)
    interference = interference_lines(records, {c: noise_std[:, i] for i, c in enumerate(channels)},
                                      {c: usable[:, i] for i, c in enumerate(channels)}, speeds, fs,
                                      tuple(options["low_band"]), channels)
    if interference:
        # out of the low band of every record, rig and model alike (before the noise models read it)
        frequencies = sorted({line["frequency"] for line in interference})
        for processor in cache.values():
            processor.set_notch(frequencies, NOTCH_HALF_WIDTH)
        column = processors[0].columns["low_band_rms"]
        for op in range(speeds.size):
            for index, channel in enumerate(channels):
                record = records[channel][op]
                if not np.isnan(record).any():
                    observed_all[op, index, column] = processors[op].low_band_rms(record[None])[0]
    rng = np.random.default_rng(seed)
    noise_by_speed = {speed: noise_model(processor, rng) for speed, processor in cache.items()}
    noise = [noise_by_speed[float(speed)] for speed in speeds]
    simulator = CampaignSimulator(design, speeds, rig["drive_torque"].values, fs, size, channels, steps_per_mode)
    return RigCase(rig=rig, design=design, channels=channels, speeds=speeds,
                   drive_torques=np.asarray(rig["drive_torque"].values, dtype=float),
                   adhesion_lower=np.asarray(rig["adhesion_torque_lower"].values, dtype=float),
                   adhesion_upper=np.asarray(rig["adhesion_torque_upper"].values, dtype=float),
                   fs=fs, size=size, processors=processors, layout=layout,
                   observed=observed_all[..., layout.columns], observed_all=observed_all, noise_std=noise_std,
                   noise=noise, usable=usable, simulator=simulator, model_error=errors,
                   speed=speed_summary(rig), tracking_s=tracking_s, interference=interference)


@dataclass(frozen=True)
class RunTask:
    """One run to simulate and reduce to features: all a worker process needs besides the case."""

    op: int
    design: Design
    mesh_stiffness_scale: float
    adhesion_torque: float
    effects: tuple[Effect, ...]
    periodicity: str
    # per-tooth pitch errors of the gears (uqgear.diagnosis.manufacturing); None: perfect gears
    pitch_errors: PitchErrors | None = None
    # reduce to complex line phasors (lines) and the other features (real part) instead of features
    phasors: bool = False


def simulate_task(case: RigCase, task: RunTask) -> SimulatedRun:
    """The model records of a run on the rig's time grid."""
    return case.simulator.run(task.op, task.design, task.mesh_stiffness_scale, task.adhesion_torque, task.effects,
                              task.periodicity, pitch_errors=task.pitch_errors)


def execute_run(case: RigCase, task: RunTask) -> tuple[np.ndarray, bool]:
    """Simulate a run and reduce its records with the rig's processing: (n_channel, all features), periodic."""
    # one BLAS thread, as every grouped path (execute_runs, the workers) reduces its runs
    with threadpool_limits(1):
        return execute_group(case, [task])[0]


def execute_group(case: RigCase, tasks: Sequence[RunTask]) -> list[tuple[np.ndarray, bool]]:
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
    phasors = {task.phasors for task in tasks}
    if len(phasors) != 1:
        raise RuntimeError("execute_group: expected runs reduced alike (features or phasors); got both")
    runs = [simulate_task(case, task) for task in tasks]
    stacked = np.concatenate([np.stack([run.records[channel] for channel in case.channels]) for run in runs])
    reduce = case.processors[op].model_phasors if phasors.pop() else case.processors[op].model_features
    features = reduce(stacked).reshape(len(runs), len(case.channels), -1)
    if case.transfer is not None:
        # the rig sees the gear through its transfer paths: the model's features as the rig would record them
        transferred = features * case.transfer[op]
        if case.line_gain is not None:
            rms = case.processors[op].columns["rms"]
            transferred[..., rms] = (transferred_rms(features, case.line_gain[op], case.processors[op])
                                     * case.transfer[op][:, rms])
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
    campaign whose line mix differs: measured on a 2.5 kHz accelerometer
    resonance, the second mesh harmonic at 2.66 kHz moved the held-out
    RMS of a healthy control 20 noise spreads off.

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
    line_power = 0.5 * np.sum(amplitude ** 2, axis=-1)
    rest = np.maximum(np.real(features[..., processor.columns["rms"]]) ** 2 - line_power, 0.0)
    return np.sqrt(rest + 0.5 * np.sum((gain * amplitude) ** 2, axis=-1))


# Most runs of one operating point reduced in one call (:func:`execute_group`):
# enough to share the line fit's basis, few enough to spread a batch over workers.
_GROUP_SIZE = 8


def run_groups(tasks: Sequence[RunTask]) -> list[list[int]]:
    """Indices of ``tasks`` in groups of one operating point, at most :data:`_GROUP_SIZE` each.

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
        groups += [indices[start:start + _GROUP_SIZE] for start in range(0, len(indices), _GROUP_SIZE)]
    return groups


def execute_runs(case: RigCase, tasks: Sequence[RunTask],
                 group_map: Callable[[list[list[RunTask]]], list[list[tuple[np.ndarray, bool]]]] | None = None
                 ) -> list[tuple[np.ndarray, bool]]:
    """Features and periodicity of each task, in order, computed group by group (:func:`run_groups`).

    ``group_map`` maps the task groups to their results (a worker pool's
    map); by default they are computed here, with one BLAS thread as in a
    worker.
    """
    groups = run_groups(tasks)
    grouped = [[tasks[index] for index in group] for group in groups]
    if group_map is None:
        with threadpool_limits(1):
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
_INHERITED_CASE: RigCase | None = None


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
    case : RigCase
    workers : int
        Worker processes (1: in this process). Needs the ``fork`` start
        method; elsewhere runs stay in this process.
    """

    def __init__(self, case: RigCase, workers: int = 1) -> None:
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

