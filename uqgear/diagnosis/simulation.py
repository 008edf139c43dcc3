"""Model records of a campaign's runs on the rig's time grid.

:class:`CampaignSimulator` integrates the model for each run (steady state
after a run-in, one period tiled when the response repeats) and band-limits
and resamples it like the rig's acquisition; :class:`~.processing.RunProcessor`
then reduces records of either source with exactly the rig's feature processing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import scipy.fft

from ..physics.design import Design, design_key_bounds
from ..physics.effects import Effect
from ..physics.history_batch import STATE_HISTORY_COLUMNS, integrate_histories
from ..physics.integration import steps_per_period
from ..physics.model import HISTORY_COLUMNS, ModelSetup, build_model
from ..physics.pitch_errors import PitchErrors
from ..physics.runup import runup_history
from ..physics.speed_profile import SpeedProfile
from ..rig.order_tracking import angle_resampled, integrated_angle
from ..rig.ramp_segments import SEGMENT_GUARD, SEGMENT_LEAD, SegmentCleaner, SegmentProfile
from ..rig.virtual_rig import frequency_filter
from .errors import DiagnosisError

# Run-in simulated before the kept window: about 8 time constants of the
# slowest linear decay (18 ms on the reference design: a transient falls by 3e-4).
_RUN_IN = 0.15
# A window is taken as one period of the steady response when the state
# returns to within this share of its peak-to-peak range. What is left of
# the start-up transient after the run-in (a few 1e-3 of the range on the
# slow gear mode at some speeds, measured) is below it, and tiling the
# window leaves that out as the steady response should; a quasi-periodic or
# chaotic response misses by 5e-2 to 1 and is simulated in full.
_PERIODIC_TOLERANCE = 1e-2
# Guard on each side of a non-periodic window, so that the band-limiting
# filter's wrap-around stays outside the record.
_GUARD = 0.025
# Output rate of a ramp segment's simulation, in rig sampling rates: the band-limiting then reads the
# rig's sample times on this grid by linear interpolation, as it reads a steady run's upsampled grid.
_RAMP_OVERSAMPLING = 2
# Highest mesh-stiffness scale for which the step count is fixed in advance,
# so that finite-difference neighbours integrate on the same grid.
MAX_STIFFNESS_SCALE = 1.5


# ---------------------------------------------------------------------------------------------- model records

#: How the steady response of a model with an effect repeats: over a mesh
#: period, a pinion or a gear revolution, or not at all (simulated in full).
#: A ramp segment's run is simulated in full whatever its periodicity.
PERIODICITIES = ("mesh", "pinion", "gear", "free")


class ModelRun(Protocol):
    """What a model run of an operating point is (:class:`~uqgear.diagnosis.execution.RunTask` is one)."""

    @property
    def design(self) -> Design: ...

    @property
    def mesh_stiffness_scale(self) -> float: ...

    @property
    def adhesion_torque(self) -> float: ...

    @property
    def effects(self) -> Sequence[Effect]: ...

    @property
    def periodicity(self) -> str: ...

    @property
    def pitch_errors(self) -> PitchErrors | None: ...


@dataclass(frozen=True)
class _Run:
    """A :class:`ModelRun` given by its parts (:meth:`CampaignSimulator.run`)."""

    design: Design
    mesh_stiffness_scale: float
    adhesion_torque: float
    effects: Sequence[Effect]
    periodicity: str
    pitch_errors: PitchErrors | None = None


@dataclass(frozen=True)
class SimulatedRun:
    """Model records of one run on the rig's time grid, and how they were obtained."""

    records: dict[str, np.ndarray]
    periodic: bool
    window: str


@dataclass(frozen=True)
class _SegmentReading:
    """What every model run of one ramp segment shares: its speed profile, its cleaning, its pinion angle."""

    segment: SegmentProfile
    profile: SpeedProfile
    cleaner: SegmentCleaner
    angle: np.ndarray


class RigGrid:
    """Model records band-limited like the rig's anti-alias filter and read at the rig's sample times.

    Filters, tapers and interpolation weights are built once per grid: they
    are the same for every run of an operating point.

    Parameters
    ----------
    fs : float
        Rig sampling rate, Hz.
    size : int
        Samples per rig record.
    channels : sequence of str
        Rig channels produced (their filters: TE as is, accelerations as the second derivative).
    """

    def __init__(self, fs: float, size: int, channels: Sequence[str]) -> None:
        self.fs = float(fs)
        self.size = int(size)
        self.channels = tuple(channels)
        self.passband = self.fs / 2.56
        self.stopband = self.fs / 2.0
        self.rig_time = np.arange(self.size) / self.fs
        self._grid_cache: dict[tuple[Any, ...], Any] = {}

    def upsampling(self, rate: float) -> int:
        """Upsampling factor from the simulation's ``rate`` to a grid fine enough for linear interpolation."""
        return max(1, int(math.ceil(4.0 * self.fs / rate)))

    def resampled(
        self,
        key: tuple[Any, ...],
        centred: np.ndarray,
        rate: float,
        factor: int,
        steps_per_second: float,
        offset: float,
        *,
        periodic: bool,
    ) -> np.ndarray:
        """Channels sampled at ``rate`` band-limited, upsampled ``factor`` times and read at the rig's times.

        The rig's time ``t`` sits at ``(t + offset) * steps_per_second`` steps
        of the upsampled grid (periodic: wrapped).
        """
        size = centred.shape[1]
        # scipy's real FFT takes half numpy's time on these lengths; numpy's inverse is the faster one
        spectrum = scipy.fft.rfft(centred, axis=1) * self._filters(size, rate)
        fine = np.fft.irfft(spectrum, n=size * factor, axis=1) * factor
        index, following, weight = self._interpolation(
            (*key, size * factor), offset, steps_per_second, size * factor, periodic=periodic
        )
        # np.take gathers the same samples as fancy indexing, several times faster
        left = np.take(fine, index, axis=1)
        return left + weight * (np.take(fine, following, axis=1) - left)

    def _filters(self, size: int, rate: float) -> np.ndarray:
        """The anti-alias filter (and derivative) of each channel, (n_channel, size // 2 + 1), built once per grid."""
        key = ("filters", size, rate)
        if key not in self._grid_cache:
            self._grid_cache[key] = np.stack(
                [
                    frequency_filter(size, rate, self.passband, self.stopband, _raw_order(channel))
                    for channel in self.channels
                ]
            )
        return self._grid_cache[key]

    def edge_taper(self, size: int, rate: float) -> np.ndarray:
        """Raised-cosine edges of a non-periodic window (inside its guards), built once per grid."""
        key = ("taper", size, rate)
        if key not in self._grid_cache:
            time = np.arange(size) / rate
            taper = np.ones(size)
            edge = 0.6 * _GUARD
            left, right = time < edge, time > time[-1] - edge
            taper[left] = 0.5 * (1.0 - np.cos(np.pi * time[left] / edge))
            taper[right] = 0.5 * (1.0 - np.cos(np.pi * (time[-1] - time[right]) / edge))
            self._grid_cache[key] = taper
        return self._grid_cache[key]

    def _interpolation(
        self, key: tuple[Any, ...], offset: float, steps_per_second: float, size: int, *, periodic: bool
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Left and right neighbours and weights of linear interpolation on a uniform grid of ``size`` points.

        The rig's times sit at ``(t + offset) * steps_per_second`` grid steps
        (computed on a cache miss only); a periodic grid wraps (its last point's
        right neighbour is the first): that point's index is stored as -1, so
        that ``index + 1`` is 0. Built once per grid: the rig's time points
        are the same for every run.
        """
        if key not in self._grid_cache:
            position = (self.rig_time + offset) * steps_per_second
            if periodic:
                position = np.mod(position, size)
            index = np.clip(np.floor(position).astype(np.intp), 0, size - 2 if not periodic else size - 1)
            weight = position - index
            if periodic:
                # the right neighbour of the last point is the first: a wrapped index
                index = np.where(index >= size - 1, index - size, index)
            self._grid_cache[key] = (index, index + 1, weight)
        return self._grid_cache[key]


def _raw_order(channel: str) -> int:
    """Time derivatives between the simulated displacement and the channel (0: TE, 2: accelerations)."""
    return 0 if channel == "te" else 2


class CampaignSimulator:
    """Model records of a campaign's runs on the rig's time grid.

    Each run is integrated from static equilibrium over a run-in, then over
    one period of its steady response (a mesh period, a pinion or a gear
    revolution, by the effects present), which is tiled over the record; a
    run whose state does not return after that period (a quasi-periodic or
    chaotic response, a slowly settling one, or an effect at a frequency of
    its own) is simulated over the whole record instead. Displacements are band-limited like the
    rig's anti-alias filter and accelerations taken as their second
    derivative in the frequency domain (sampling y'' directly would alias
    the jumps of the mesh stiffness), then resampled onto the rig's grid.

    Parameters
    ----------
    design : Design
        Nominal design.
    speeds, drive_torques : array_like
        Per run: pinion speed (rpm) and drive torque (N m).
    fs : float
        Rig sampling rate, Hz.
    size : int
        Samples per rig record.
    channels : sequence of str
        Rig channels to produce.
    steps_per_mode : int
        RK4 steps per period of the fastest mode.
    segments : sequence of SegmentProfile or None, optional
        Per run, the ramp segment it was cut from (:func:`uqgear.rig.ramp_segments.segment_profiles`):
        such a run is simulated through the speeds the segment swept and read as the rig read it
        (:meth:`ramp_run`); None (the default for every run) for a steady run.
    """

    def __init__(
        self,
        design: Design,
        speeds: Sequence[float] | np.ndarray,
        drive_torques: Sequence[float] | np.ndarray,
        fs: float,
        size: int,
        channels: Sequence[str],
        steps_per_mode: int = 24,
        segments: Sequence[SegmentProfile | None] | None = None,
    ) -> None:
        self.design = design
        self.speeds = np.asarray(speeds, dtype=float)
        self.drive_torques = np.asarray(drive_torques, dtype=float)
        self.fs = float(fs)
        self.size = int(size)
        self.duration = self.size / self.fs
        self.channels = tuple(channels)
        self.steps_per_mode = int(steps_per_mode)
        self.grid = RigGrid(self.fs, self.size, self.channels)
        self.stopband = self.grid.stopband
        self.segments = tuple(segments) if segments is not None else (None,) * self.speeds.size
        if len(self.segments) != self.speeds.size:
            raise RuntimeError(f"internal: {len(self.segments)} segment profiles for {self.speeds.size} runs")
        self.segment_runner = SegmentRunner(self)
        # the stiffest bearings a fit may propose (candidates.nominal_parameters), inside the design's range
        stiff = design.replace(
            k1=min(design.k1 * 2.0, design_key_bounds("k1")[1]), k2=min(design.k2 * 2.0, design_key_bounds("k2")[1])
        )
        self.samples_per_period = []
        for speed, torque in zip(self.speeds, self.drive_torques):
            # every neighbour of a fit integrates on the same grid: the steps of the stiffest model,
            # kept every step or (at twice the stop band and more) every other step
            steps = steps_per_period(
                build_model(
                    stiff, speed, torque, torque * design.z2 / design.z1, mesh_stiffness_scale=MAX_STIFFNESS_SCALE
                ),
                self.steps_per_mode,
            )
            steps += steps % 2
            mesh_frequency = design.z1 * speed / 60.0
            half = steps // 2
            self.samples_per_period.append(half if half * mesh_frequency >= 2.2 * self.stopband else steps)

    def mesh_frequency(self, op: int) -> float:
        return self.design.z1 * self.speeds[op] / 60.0

    def run_in_periods(self, op: int) -> int:
        """Mesh periods simulated from static equilibrium before a run's kept window (the start-up transient)."""
        return int(math.ceil(_RUN_IN * self.mesh_frequency(op)))

    def window_periods(self, periodicity: str, op: int) -> int:
        """Mesh periods in one period of the steady response."""
        if periodicity == "mesh":
            return 2
        if periodicity == "pinion":
            return self.design.z1
        if periodicity == "gear":
            return self.design.z2
        return int(math.ceil((self.duration + 2 * _GUARD) * self.mesh_frequency(op))) + 1

    def whole_window(self, op: int) -> tuple[int, int]:
        """Mesh periods simulated for a whole-record run, and the samples of them kept.

        The record with its guards, lengthened to the next length whose FFT
        is fast (:func:`scipy.fft.next_fast_len`): the band-limiting
        transforms of a length with a large prime factor cost up to ten times
        more (a few hundred samples more of the end guard cost nothing).
        """
        per_period = self.samples_per_period[op]
        samples = scipy.fft.next_fast_len(self.window_periods("free", op) * per_period)
        return -(-samples // per_period), samples

    def run(
        self,
        op: int,
        design: Design,
        mesh_stiffness_scale: float,
        adhesion_torque: float,
        effects: Sequence[Effect],
        periodicity: str,
        *,
        pitch_errors: PitchErrors | None = None,
    ) -> SimulatedRun:
        """Model records of run ``op`` (dict channel -> (N,) array on the rig grid).

        ``periodicity`` is the expected period of the steady response; a run
        found not to repeat over it is simulated in full (always, with
        ``pitch_errors``: their pattern repeats only after z1 z2 / gcd mesh periods).
        """
        run = _Run(design, mesh_stiffness_scale, adhesion_torque, tuple(effects), periodicity, pitch_errors)
        return self.runs(op, [run])[0]

    def runs(self, op: int, runs: Sequence[ModelRun]) -> list[SimulatedRun]:
        """Model records of several runs of operating point ``op``, each as :meth:`run` makes it.

        The runs are integrated together (:func:`~uqgear.physics.history_batch.integrate_histories`:
        SIMD lanes, each run's numbers the same as alone): first every run that may repeat over its
        periodicity's window, then, over the whole record, the rest and those found not to repeat.
        """
        for run in runs:
            if run.periodicity not in PERIODICITIES:
                raise DiagnosisError(
                    f"periodicity: expected one of {', '.join(PERIODICITIES)}; got {run.periodicity!r}"
                )
        if self.segments[op] is not None and all(run.pitch_errors is None for run in runs):
            return [self.ramp_run(op, run) for run in runs]
        setups = [self._setup(op, run) for run in runs]
        run_in = self.run_in_periods(op)
        results: list[SimulatedRun | None] = [None] * len(runs)
        windows: dict[int, list[int]] = {}
        whole = []
        for index, run in enumerate(runs):
            if run.pitch_errors is not None or run.periodicity == "free":
                whole.append(index)
            else:
                windows.setdefault(self.window_periods(run.periodicity, op), []).append(index)
        for window, members in windows.items():
            simulated = self._integrate(op, [setups[index] for index in members], run_in + window + 1, window + 1)
            for index, (signals, poincare) in zip(members, simulated):
                results[index] = self._tiled(op, signals, poincare, window, runs[index].periodicity)
                if results[index] is None:
                    whole.append(index)
        periods, samples = self.whole_window(op)
        whole.sort()
        simulated = self._integrate(op, [setups[index] for index in whole], run_in + periods, periods)
        for index, (signals, _) in zip(whole, simulated):
            results[index] = self._whole(op, {name: values[:samples] for name, values in signals.items()})
        return results  # type: ignore[return-value]

    def ramp_run(self, op: int, run: ModelRun) -> SimulatedRun:
        """Model records of a ramp segment's run, read as the rig read the segment (:class:`SegmentRunner`)."""
        return self.segment_runner.run(op, run)

    def _setup(self, op: int, run: ModelRun) -> ModelSetup:
        return build_model(
            run.design,
            float(self.speeds[op]),
            float(self.drive_torques[op]),
            float(run.adhesion_torque),
            mesh_stiffness_scale=float(run.mesh_stiffness_scale),
            effects=run.effects,
            pitch_errors=run.pitch_errors,
        )

    def _integrate(
        self, op: int, setups: Sequence[ModelSetup], n_periods: int, keep_periods: int
    ) -> list[tuple[dict[str, np.ndarray], np.ndarray]]:
        """Displacements and TE over the kept periods of each run, and the state at each kept period start.

        Calls the fast integrator directly: the full :func:`uqgear.simulate`
        Dataset (a dozen histories with attributes) costs as much as the
        integration of a short periodic window.
        """
        columns = {name: index for index, name in enumerate(STATE_HISTORY_COLUMNS)}
        simulated = []
        for history, poincare in integrate_histories(
            setups, n_periods, keep_periods, self.samples_per_period[op], self.steps_per_mode
        ):
            signals = {name: history[:, columns[name]] for name in ("y1", "y2", "x")}
            signals["te"] = signals["x"] - signals["y1"] + signals["y2"] + history[:, columns["ste"]]
            simulated.append((signals, poincare))
        return simulated

    def _tiled(
        self, op: int, signals: Mapping[str, np.ndarray], poincare: np.ndarray, window: int, periodicity: str
    ) -> SimulatedRun | None:
        """Records tiled from the first ``window`` mesh periods of a simulation, or None if they do not repeat."""
        f_mesh = self.mesh_frequency(op)
        per_period = self.samples_per_period[op]
        kept = window * per_period
        # the state one window later must be where it started, else the response is not periodic
        spread = np.array([np.ptp(signals[name][:kept]) for name in ("y1", "y2", "x")])
        change = np.abs(poincare[window, :3] - poincare[0, :3])
        if np.any(change > _PERIODIC_TOLERANCE * np.maximum(spread, 1e-12)):
            return None
        period = window / f_mesh
        rate = per_period * f_mesh
        factor = self.grid.upsampling(rate)
        raw = np.stack([_raw_signal(signals, channel)[:kept] for channel in self.channels])
        values = self.grid.resampled(
            ("periodic", op),
            raw - raw.mean(axis=1, keepdims=True),
            rate,
            factor,
            kept * factor / period,
            0.0,
            periodic=True,
        )
        return SimulatedRun(dict(zip(self.channels, values)), True, periodicity)

    def _whole(self, op: int, signals: Mapping[str, np.ndarray]) -> SimulatedRun:
        """Records from a simulation of the whole record (with its guards), band-limited and resampled."""
        rate = self.samples_per_period[op] * self.mesh_frequency(op)
        size = signals["te"].size
        factor = self.grid.upsampling(rate)
        raw = np.stack([_raw_signal(signals, channel) for channel in self.channels])
        centred = (raw - raw.mean(axis=1, keepdims=True)) * self.grid.edge_taper(size, rate)
        values = self.grid.resampled(("free", op), centred, rate, factor, rate * factor, _GUARD, periodic=False)
        return SimulatedRun(dict(zip(self.channels, values)), False, "free")


def _raw_signal(signals: Mapping[str, np.ndarray], channel: str) -> np.ndarray:
    """The simulated displacement a channel is made of (accelerations: its second derivative)."""
    if channel == "te":
        return signals["te"]
    return signals["y1" if channel == "acc_pinion" else "y2"]


class SegmentRunner:
    """The runs of a campaign's ramp segments, each driven through the speeds its segment swept.

    Built by :class:`CampaignSimulator` (its ``segments``); what every run of
    one segment shares (its speed profile, cleaning and pinion angle) is
    built once per segment.
    """

    def __init__(self, campaign: CampaignSimulator) -> None:
        self.campaign = campaign
        self._readings: dict[int, _SegmentReading] = {}

    def run(self, op: int, run: ModelRun) -> SimulatedRun:
        """Model records of a ramp segment's run, read as the rig read the segment.

        The model runs through the segment's speed profile from
        :data:`~uqgear.rig.ramp_segments.SEGMENT_LEAD` s before its first sample
        (after a run-in at the speed there) to a guard after its last; the
        records are band-limited and read at the rig's sample times like a
        steady run's, cleaned as the segment was
        (:class:`~uqgear.rig.ramp_segments.SegmentCleaner`) and resampled to
        uniform angle with the model's own angle, as the order tracking
        resampled the rig's. The speed-varying model takes no pitch errors: a
        run with them is read as a steady run (:meth:`CampaignSimulator.runs`).
        """
        reading = self._segment_reading(op)
        profile = reading.profile
        rate = self.campaign.fs * _RAMP_OVERSAMPLING
        _, history = runup_history(
            run.design,
            profile,
            float(self.campaign.drive_torques[op]),
            float(run.adhesion_torque),
            sample_rate=rate,
            mesh_stiffness_scale=float(run.mesh_stiffness_scale),
            effects=reading.segment.turned_effects(self.campaign.design, tuple(run.effects), profile, SEGMENT_LEAD),
            steps_per_mode=self.campaign.steps_per_mode,
            run_in_periods=int(math.ceil(_RUN_IN * self.campaign.design.z1 * profile.start_speed / 60.0)),
        )
        signals = {name: history[:, HISTORY_COLUMNS.index(name)] for name in ("y1", "y2", "x")}
        signals["te"] = signals["x"] - signals["y1"] + signals["y2"] + history[:, HISTORY_COLUMNS.index("ste")]
        raw = np.stack([_raw_signal(signals, channel) for channel in self.campaign.channels])
        size = raw.shape[1]
        factor = self.campaign.grid.upsampling(rate)
        centred = (raw - raw.mean(axis=1, keepdims=True)) * self.campaign.grid.edge_taper(size, rate)
        # zeros after the tapered end: a length whose FFT is fast (the band-limiting costs up to ten times
        # more on a length with a large prime factor)
        padded = np.pad(centred, ((0, 0), (0, scipy.fft.next_fast_len(size, real=True) - size)))
        values = self.campaign.grid.resampled(
            ("ramp", op, padded.shape[1]), padded, rate, factor, rate * factor, SEGMENT_LEAD, periodic=False
        )
        channels = self.campaign.channels
        cleaned = np.stack([reading.cleaner.clean(row, channel) for row, channel in zip(values, channels)])
        rows = [index for index, channel in enumerate(channels) if channel != "te"]
        tracked = angle_resampled(cleaned, reading.angle, self.campaign.fs, rows)
        return SimulatedRun(dict(zip(self.campaign.channels, tracked)), False, "ramp")

    def _segment_reading(self, op: int) -> _SegmentReading:
        """How the model's records of ramp segment ``op`` are made and read, built once per segment."""
        if op not in self._readings:
            segment = self.campaign.segments[op]
            if segment is None:
                raise RuntimeError(f"internal: run {op} is not a ramp segment")
            speed = segment.speed_at(self.campaign.grid.rig_time)
            angle = integrated_angle(speed, self.campaign.fs)
            profile = segment.profile(SEGMENT_LEAD, SEGMENT_GUARD)
            cleaner = SegmentCleaner(speed, self.campaign.fs, self.campaign.design)
            self._readings[op] = _SegmentReading(segment, profile, cleaner, angle)
        return self._readings[op]
