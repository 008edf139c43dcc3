"""A rig campaign prepared for diagnosis: its features, noise models, processing and simulator.

A :class:`RigCase` is never changed once made. What a step derives from it
(a reference's transfer correction, the pitch-error allowance, a calibrated
backlash, the worker processes that run its simulations) is a new case made
with :func:`dataclasses.replace`; the case a step was handed stays as it was.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import xarray as xr

from ..physics.design import Design
from ..physics.pitch_errors import PitchErrors
from ..rig import features as feature_module
from ..rig.features import SIGNAL_CHANNELS
from ..rig.order_tracking import TrackerImage, accelerations, speed_summary, track_orders, tracker_image
from ..rig.ramp_segments import segment_profiles
from .allowances.interference import NOTCH_HALF_WIDTH, LineInterference, interference_lines
from .discrepancy import FeatureLayout, NoiseModel, line_noise_sigma, noise_model
from .errors import DiagnosisError
from .execution import RunExecutor, RunTask, execute_runs
from .processing import RunProcessor
from .settings import DiagnosisSettings
from .simulation import CampaignSimulator

#: Options of the feature processing (as :func:`uqgear.rig.features.extract_features`).
FEATURE_OPTIONS: dict[str, Any] = {
    "n_harmonics": 3,
    "n_sidebands": 3,
    "n_shaft_orders": 3,
    "n_motor_lines": 2,
    "low_band": (2.0, 80.0),
    "window": "hann",
}


class FeatureModelError(dict):
    """Relative model error per feature kind, widened feature by feature, and absolute model error.

    The dict's own items are the per-kind errors (what summaries and JSON
    show); looking a kind up returns them combined in quadrature with a
    per-feature widening (n_op, n_channel, features of that kind in layout
    order), e.g. the uncertainty of a reference campaign's transfer
    correction (:mod:`uqgear.diagnosis.allowances.reference`). Arrays broadcast where
    :func:`~uqgear.diagnosis.discrepancy.standardised_discrepancy` uses scalars.

    ``absolute`` holds, per kind, model error that does not scale with the
    model's value (same shapes): for lines a per-quadrature standard
    deviation in the channel's units, for band and RMS features a standard
    deviation of the power, for kurtosis one of the kurtosis; e.g. what the
    pitch errors of manufactured gears add (:mod:`uqgear.diagnosis.allowances.pitch_errors`).
    """

    def __init__(
        self,
        base: Mapping[str, float],
        widening: Mapping[str, np.ndarray],
        absolute: Mapping[str, np.ndarray] | None = None,
    ) -> None:
        super().__init__({key: float(value) for key, value in dict(base).items()})
        self.widening = {key: np.asarray(value, dtype=float) for key, value in widening.items()}
        self.absolute = {key: np.asarray(value, dtype=float) for key, value in (absolute or {}).items()}

    def __getitem__(self, kind: str) -> Any:
        base = super().__getitem__(kind)
        extra = self.widening.get(kind)
        if extra is None or extra.size == 0:
            return base
        return np.sqrt(base**2 + extra**2)

    @classmethod
    def combined(cls, current: Mapping[str, float], absolute: Mapping[str, np.ndarray]) -> FeatureModelError:
        """``current`` (a plain mapping or one of these) with ``absolute`` added to its absolute errors."""
        widening = getattr(current, "widening", {})
        before = dict(getattr(current, "absolute", {}))
        for kind, values in absolute.items():
            values = np.asarray(values, dtype=float)
            before[kind] = np.sqrt(before[kind] ** 2 + values**2) if kind in before else values
        # dict() of one of these reads the per-kind errors, not the widened arrays
        return cls(dict(current), widening, before)


class AppliedPitchAllowance(Protocol):
    """What a case reads of the pitch-error allowance taken into it.

    :class:`uqgear.diagnosis.allowances.pitch_errors.PitchErrorAllowance` is one; that
    module builds on this one, so the case names only what it reads.
    """

    @property
    def applied(self) -> bool: ...

    @property
    def run_out_bound(self) -> Mapping[str, float]: ...

    @property
    def drawn_errors(self) -> Sequence[PitchErrors]: ...


@dataclass(frozen=True)
class RigCase:
    """A rig campaign prepared for diagnosis: features, noise, processing and simulator (never changed once made)."""

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
    observed: np.ndarray  # (n_op, n_channel, F) compared features
    observed_all: np.ndarray  # (n_op, n_channel, all features)
    noise_std: np.ndarray  # (n_op, n_channel)
    # (n_op, n_channel): the white noise the low band holds, read in the band, never above noise_std
    band_noise_std: np.ndarray
    noise: list[NoiseModel]
    usable: np.ndarray  # (n_op, n_channel)
    simulator: CampaignSimulator
    model_error: Mapping[str, float]
    speed: list[dict[str, Any]]  # per run: the order tracking's speed estimate
    tracking_s: float  # time spent estimating speeds and resampling
    # the worker processes that run its simulations (None: in this process)
    executor: RunExecutor | None = None
    # (n_op, n_channel, all features): the model's features are multiplied by it (a reference
    # campaign's transfer correction, allowances.reference); None: unity
    transfer: np.ndarray | None = None
    # (n_op, n_channel, all features): the transfer path's gain at each line (1 elsewhere); the model's
    # RMS is then taken through it line by line (transferred_rms) before ``transfer`` scales it
    line_gain: np.ndarray | None = None
    # line interference left out of the low band (allowances.interference)
    interference: LineInterference = field(default_factory=lambda: LineInterference([]))
    # the pitch-error allowance taken into the model error (allowances.pitch_errors) and the model error
    # before it: a fit with effects is scored with its own model's allowance (with_own_allowance); None: none
    pitch_allowance: AppliedPitchAllowance | None = None
    model_error_before_allowance: Mapping[str, float] | None = None
    # per run: what the rig's order tracking took from the mesh sidebands, which the model's features lose
    # alike (None where the record was not resampled on its own lines); empty: no run
    tracking: tuple[TrackerImage | None, ...] = ()

    @property
    def n_op(self) -> int:
        return int(self.speeds.size)

    @property
    def reads_tracked(self) -> bool:
        """Whether model runs are read as the rig's order tracking left the rig's records (:attr:`tracking`).

        Not under the pitch-error allowance: its widening of every sideband
        is read off model runs as they come (the rules of section 6.4 were
        set on that reading), and a candidate is judged on the same footing
        as the allowance it has to beat. Read through the tracking, a
        gear-order candidate on a class-7 gear under speed wander matches the
        tracked pitch-error sidebands the allowance does not cover
        (docs/validation/diagnosis.md, "Speed wander and gear-order sidebands").
        """
        return self.pitch_allowance is None

    @property
    def run_out_allowance(self) -> dict[str, float]:
        """Per gear, the first-order run-out the stated classes' pitch errors stay under, m.

        :func:`uqgear.physics.pitch_errors.run_out_bounds`; empty without an allowance (perfect gears).
        """
        return {} if self.pitch_allowance is None else dict(self.pitch_allowance.run_out_bound)

    def noise_std_for(self, kind: str) -> np.ndarray:
        """The white-noise level (n_op, n_channel) features of ``kind`` are compared with.

        The low band's own floor for the band (``"band"``), the floor between
        the lines for every other kind.
        """
        return self.band_noise_std if kind == "band" else self.noise_std

    def line_noise_sigma(self) -> np.ndarray:
        """Per-quadrature noise spread of each compared line (n_op, n_channel, F; NaN for features not lines)."""
        return line_noise_sigma(self.noise_std, self.noise, self.layout)

    def mask(self) -> np.ndarray:
        """Features that enter the comparison: usable runs and finite rig features, each spectral line once.

        A line within one bin of an earlier one reads that line's amplitude
        in rig and model alike (:class:`~uqgear.rig.line_fit.LineFit`); it is
        left out, so that one spectral line counts once in every fit and gap
        whatever the names it carries.
        """
        compared = np.isfinite(self.observed) & self.usable[..., None]
        for op, processor in enumerate(self.processors):
            compared[op, :, np.isin(self.layout.columns, processor.merged_columns)] = False
        return compared

    def observed_features(self) -> dict[str, np.ndarray]:
        """The compared rig features over runs by ``CHANNEL:FEATURE`` name (what effect families read hints off)."""
        return {
            f"{channel}:{name}": self.observed[:, c, f]
            for c, channel in enumerate(self.channels)
            for f, name in enumerate(self.layout.names)
        }

    def execute(self, tasks: Sequence[RunTask]) -> list[tuple[np.ndarray, bool]]:
        """Simulate and reduce runs (through the executor when the case has one)."""
        if self.executor is not None:
            return self.executor.map(tasks)
        return execute_runs(self, tasks)

    def with_design(self, design: Design) -> RigCase:
        """This case with another nominal design (a calibrated backlash)."""
        return replace(self, design=design)

    def with_executor(self, executor: RunExecutor | None) -> RigCase:
        """This case with its simulations run by ``executor``."""
        return replace(self, executor=executor)


def _check_model_error(model_error: Mapping[str, float] | None, defaults: Mapping[str, float]) -> dict[str, float]:
    errors = dict(defaults)
    if model_error is not None:
        unknown = sorted(set(model_error) - set(errors))
        if unknown:
            raise DiagnosisError(f"model_error.{unknown[0]}: unknown feature kind; expected {', '.join(errors)}")
        for key, value in model_error.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < 1.0:
                raise DiagnosisError(f"model_error.{key}: expected a relative error in [0, 1); got {value!r}")
            errors[key] = float(value)
    return errors


def _left_out_interference(
    records: Mapping[str, np.ndarray],
    noise_std: np.ndarray,
    usable: np.ndarray,
    speeds: np.ndarray,
    fs: float,
    options: Mapping[str, Any],
    channels: tuple[str, ...],
    processors: list[RunProcessor],
    observed_all: np.ndarray,
    settings: DiagnosisSettings,
) -> LineInterference:
    """Line interference on the accelerometers, left out of the low band of every record, rig and model alike.

    Done while the campaign is prepared, before the noise models read the
    processing: the processors (built for this campaign) are notched and the
    rig's low-band features in ``observed_all`` read again.
    """
    interference = interference_lines(
        records,
        {c: noise_std[:, i] for i, c in enumerate(channels)},
        {c: usable[:, i] for i, c in enumerate(channels)},
        speeds,
        fs,
        tuple(options["low_band"]),
        channels,
        threshold=settings.interference.interference_threshold,
        minimum_runs=settings.interference.interference_runs,
    )
    if interference.applied:
        for processor in {id(processor): processor for processor in processors}.values():
            processor.set_notch(interference.frequencies, NOTCH_HALF_WIDTH)
        column = processors[0].columns["low_band_rms"]
        for op in range(speeds.size):
            for index, channel in enumerate(channels):
                record = records[channel][op]
                if not np.isnan(record).any():
                    observed_all[op, index, column] = processors[op].low_band_rms(record[None])[0]
    return interference


def _band_noise_std(
    records: Mapping[str, np.ndarray], noise_std: np.ndarray, processors: list[RunProcessor], channels: tuple[str, ...]
) -> np.ndarray:
    """The white noise of each record's low band (n_op, n_channel): its own bins' floor, capped by ``noise_std``.

    Both are read from bins that lines and other content can only raise, so
    the lower is the nearer the sensor's noise
    (:meth:`~uqgear.diagnosis.processing.RunProcessor.band_floor`); after
    the interference notches, so that rig and model see the same bins.
    """
    floor = np.stack(
        [
            processors[op].band_floor(np.stack([records[channel][op] for channel in channels]))
            for op in range(noise_std.shape[0])
        ]
    )
    return np.where(np.isfinite(floor), np.fmin(floor, noise_std), noise_std)


def prepare_case(
    rig: xr.Dataset,
    design: Design,
    *,
    seed: np.random.SeedSequence,
    model_error: Mapping[str, float] | None = None,
    steps_per_mode: int = 24,
    settings: DiagnosisSettings | None = None,
) -> RigCase:
    """Features, noise models, processors and simulator of a validated rig Dataset.

    The records are first order-tracked (:func:`uqgear.rig.order_tracking.track_orders`):
    every later step, and the model runs at each run's ``pinion_speed``, see
    constant-speed records at the estimated mean speed. Line interference on
    the accelerometers (:mod:`uqgear.diagnosis.allowances.interference`) is left out of
    the low band of every record. ``model_error`` replaces some of the
    settings' relative model errors per feature kind.
    """
    settings = DiagnosisSettings() if settings is None else settings
    errors = _check_model_error(model_error, settings.predictive.model_error)
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
    observed_all = np.stack(
        [
            np.stack([processors[op].features(records[channel][op][None])[0] for channel in channels])
            for op in range(speeds.size)
        ]
    )
    noise_column = processors[0].columns["noise_std"]
    noise_std = observed_all[..., noise_column]
    usable = np.isfinite(observed_all).any(axis=-1) & np.isfinite(noise_std) & (noise_std > 0)
    interference = _left_out_interference(
        records, noise_std, usable, speeds, fs, options, channels, processors, observed_all, settings
    )
    band_noise_std = _band_noise_std(records, noise_std, processors, channels)
    rng = np.random.default_rng(seed)
    noise_by_speed = {speed: noise_model(processor, rng) for speed, processor in cache.items()}
    noise = [noise_by_speed[float(speed)] for speed in speeds]
    speed = speed_summary(rig)
    # a ramp segment's runs are read through the speeds it swept, where its record was resampled to uniform angle
    segments = segment_profiles(rig, tracked=[bool(row["order_tracked"]) for row in speed])
    simulator = CampaignSimulator(
        design, speeds, rig["drive_torque"].values, fs, size, channels, steps_per_mode, segments=segments
    )
    scaled = accelerations(rig, channels)
    return RigCase(
        rig=rig,
        design=design,
        channels=channels,
        speeds=speeds,
        drive_torques=np.asarray(rig["drive_torque"].values, dtype=float),
        adhesion_lower=np.asarray(rig["adhesion_torque_lower"].values, dtype=float),
        adhesion_upper=np.asarray(rig["adhesion_torque_upper"].values, dtype=float),
        fs=fs,
        size=size,
        processors=processors,
        layout=layout,
        observed=observed_all[..., layout.columns],
        observed_all=observed_all,
        noise_std=noise_std,
        band_noise_std=band_noise_std,
        noise=noise,
        usable=usable,
        simulator=simulator,
        model_error=errors,
        speed=speed,
        tracking_s=tracking_s,
        interference=interference,
        tracking=tuple(tracker_image(row, channels, design.z1, scaled) for row in speed),
    )


__all__ = ["FEATURE_OPTIONS", "FeatureModelError", "RigCase", "prepare_case"]
