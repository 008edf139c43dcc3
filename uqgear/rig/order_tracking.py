"""Computed order tracking: records resampled to uniform pinion angle.

Every analysis of rig records (features, calibration, diagnosis, blind tests)
reads order lines at ``order * n1 / 60`` Hz, which holds only while the
pinion turns at a constant speed. A traction motor under speed control wanders
by tenths of a percent within a second; the mesh harmonics, at hundreds to
thousands of Hz, then smear over many frequency bins and their amplitudes read
low (a phase excursion of beta rad on a line leaves J0(beta) of it in place).
:func:`track_orders` undoes that once, where the records are read:

1. **Pinion angle from the signals.** Each mesh harmonic k z1 of each channel
   is demodulated with the current angle estimate (``x(t) exp(-i k z1
   theta(t))``) and low-passed to a half-width of half the pinion rotation
   frequency, so that pinion-order sidebands (run-out, a damaged tooth) stay
   outside the estimate. The unwrapped phase of what is left, divided by
   k z1, is the deviation of the pinion angle from the estimate; the lines are
   averaged with weights by their phase precision (strong, high lines count
   most), and the estimate is refined over a few passes, which recovers
   wander wider than the band of the first pass. Lines below 30 dB over the
   noise in that band, or whose amplitude collapses within the record, are
   not used. When the rig file carries an instantaneous speed channel
   ``pinion_speed_signal`` (rpm over op and time, a tachometer), it is
   integrated instead.
2. **Resampling.** The records are resampled (polyphase 4x upsampling, then a
   cubic spline) at the instants where the estimated angle is uniform over
   the record's angle range. The result is what a constant-speed rig at the
   record's mean speed would have recorded: same ``time`` axis, ``pinion_speed``
   set to the estimated mean (the stated one is kept as
   ``pinion_speed_stated``). Accelerations (m s-2) are divided by the
   squared ratio of instantaneous to mean speed: a response that follows the
   shaft angle has its accelerations scaled so (the quasi-steady limit, well
   below the resonances; it removes the sidebands at the wander frequency
   that would otherwise leak into the line fit).
3. **Only where it matters** (mode ``auto``): a record is resampled when the
   wander would shift the phase of the highest analysed mesh harmonic by more
   than 0.2 rad (an amplitude loss of about 1 %), or the mean speed differs
   from the stated one by more than a tenth of a frequency bin there, and
   the excursion stands well above the estimate's own noise. Records at a
   constant speed are left as they are, so their features are bit for bit
   those without tracking.

Limits, which any tachometer-free tracking shares (a tachometer channel removes
them): gear-order modulation of the mesh inside the demodulation band (gear
run-out, gear pitch errors) cannot be told from speed wander in a record of a
few gear revolutions, so in a resampled record the phase-modulation half of
such a sideband is taken as wander (a lone gear-order sideband of a
synthetic test reads about 35 % low after tracking; projecting the gear orders
out of the estimate would absorb the wander itself); wander faster than half
the pinion rotation frequency is outside the estimate's band. Records that
need no tracking keep their gear sidebands intact. A model compared with a
resampled record must lose the same share of its sidebands:
:class:`TrackerImage` removes it from a constant-speed record's line
phasors to first order, with the weights the estimate gave each line
(``speed_reference_weight``).

This module does no file I/O and no plotting.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.signal
import xarray as xr
from scipy.interpolate import CubicSpline

from ..common.errors import RigDataError, StudyError
from ..physics.design import Design
from .sampling import SIGNAL_CHANNELS, band_limit_of, sampling_rate

#: Modes of :func:`track_orders`.
TRACKING_MODES: tuple[str, ...] = ("auto", "always", "never")

#: Variables over the non-time dimensions that :func:`track_orders` adds.
SPEED_ESTIMATE_VARIABLES: tuple[str, ...] = (
    "pinion_speed_stated",
    "speed_mean",
    "speed_min",
    "speed_max",
    "order_tracked",
)

#: Optional rig variable: instantaneous pinion speed (rpm) over (op, time).
TACHOMETER_VARIABLE = "pinion_speed_signal"

# Half-width of the demodulation band as a fraction of the pinion rotation
# frequency: pinion-order sidebands at +-1 order stay outside with margin.
_BAND_FRACTION = 0.5
# A line enters the angle estimate when its power is this many times the
# noise power inside the demodulation band (30 dB: phase noise ~0.02 rad).
_MIN_LINE_SNR = 1000.0
# Phase excursion (rad) of the highest analysed mesh harmonic above which a
# record is resampled: J0(0.2) = 0.990.
_SMEAR_LIMIT = 0.2
# Mean-speed error, in frequency bins of the highest analysed harmonic, above
# which a record is resampled.
_BIN_LIMIT = 0.1
# The excursion must also exceed this many standard deviations of the
# estimate's own noise.
_NOISE_MARGIN = 6.0
_PASSES = 4
_UPSAMPLING = 4


def check_tracking_mode(mode: object) -> str:
    """``mode`` if it is one of :data:`TRACKING_MODES`, else a StudyError naming ``order_tracking``."""
    if mode not in TRACKING_MODES:
        raise StudyError(f"order_tracking: expected one of {', '.join(TRACKING_MODES)}; got {mode!r}")
    return str(mode)


@dataclass(frozen=True)
class AngleEstimate:
    """Pinion angle of one record, estimated from its signals.

    Attributes
    ----------
    angle : ndarray or None
        Pinion angle (rad) at each sample, from 0; None when no line was
        strong enough.
    angle_std : float
        Standard deviation of the estimate's noise (rad of pinion angle).
    lines : tuple of str
        The lines used, e.g. ``("te:mesh1", "te:mesh2")``.
    reason : str
        Why no estimate could be made (empty when there is one).
    weights : tuple of float
        Each line's weight in the estimate (summing to 1; empty for a
        tachometer, whose angle rests on no line).
    """

    angle: np.ndarray | None
    angle_std: float
    lines: tuple[str, ...]
    reason: str = ""
    weights: tuple[float, ...] = ()


def _lowpass(values: np.ndarray, cutoff: float, fs: float) -> np.ndarray:
    """Zero-phase low-pass of complex rows, with even-reflection padding over the filter's memory."""
    # third order run forward and back: 1/(1 + 2^12) of power left at the
    # pinion sidebands (twice the cutoff), little ringing from the record ends;
    # even reflection keeps the phasor continuous where odd reflection of a
    # rotating phasor would not
    sos = scipy.signal.butter(3, cutoff, fs=fs, output="sos")
    padlen = min(values.shape[-1] - 1, int(3.0 * fs / cutoff))
    real = scipy.signal.sosfiltfilt(sos, values.real, axis=-1, padtype="even", padlen=padlen)
    imaginary = scipy.signal.sosfiltfilt(sos, values.imag, axis=-1, padtype="even", padlen=padlen)
    return real + 1j * imaginary


def _noise_density(record: np.ndarray, fs: float) -> float:
    """One-sided noise density of a record: its periodogram's median (lines are few, bins many)."""
    _, density = scipy.signal.periodogram(record, fs, window="hann", detrend="constant")
    return float(np.median(density[1:])) / math.log(2.0)


def estimate_pinion_angle(
    records: Sequence[np.ndarray],
    names: Sequence[str],
    fs: float,
    pinion_speed: float,
    z1: int,
    *,
    band_limit: float,
    n_harmonics: int = 3,
) -> AngleEstimate:
    """Pinion angle of one record from the phases of its mesh harmonics.

    Parameters
    ----------
    records : sequence of ndarray
        The channels of one record (each of N samples, no NaN).
    names : sequence of str
        Channel names, for :attr:`AngleEstimate.lines`.
    fs : float
        Sampling rate, Hz.
    pinion_speed : float
        Stated mean pinion speed, rpm (the starting estimate).
    z1 : int
        Pinion teeth.
    band_limit : float
        Highest usable frequency, Hz.
    n_harmonics : int
        Mesh harmonics k = 1..n_harmonics considered.

    Returns
    -------
    AngleEstimate
    """
    size = records[0].size
    time = np.arange(size) / fs
    shaft_frequency = pinion_speed / 60.0
    half_band = _BAND_FRACTION * shaft_frequency
    angle = 2.0 * math.pi * shaft_frequency * time
    candidates = [
        (channel, k)
        for channel in range(len(records))
        for k in range(1, n_harmonics + 1)
        if k * z1 * shaft_frequency * 1.03 + half_band <= band_limit
    ]
    if not candidates:
        return AngleEstimate(None, math.nan, (), "no mesh harmonic inside the usable band")
    centred = [np.asarray(record, dtype=float) - float(np.mean(record)) for record in records]
    densities = [_noise_density(record, fs) for record in centred]
    used: list[tuple[int, int]] = []
    weights = np.zeros(0)
    angle_std = math.nan
    for _ in range(_PASSES):
        rows = np.stack([centred[channel] * np.exp(-1j * k * z1 * angle) for channel, k in candidates])
        baseband = _lowpass(rows, half_band, fs)
        magnitude = np.abs(baseband)
        typical = np.median(magnitude, axis=1)
        # a real line x = A cos(...) demodulates to A/2; noise of one-sided
        # density N0 gives N0 * half_band of complex power inside the band
        noise_power = np.array([densities[channel] * half_band for channel, _ in candidates])
        snr = typical**2 / np.maximum(noise_power, 1e-300)
        steady = np.min(magnitude[:, size // 20 : size - size // 20], axis=1) > 0.3 * typical
        usable = np.flatnonzero((snr >= _MIN_LINE_SNR) & steady)
        if usable.size == 0:
            return AngleEstimate(None, math.nan, (), "no mesh harmonic stands 30 dB over the noise in its band")
        orders = np.array([candidates[i][1] * z1 for i in usable], dtype=float)
        # phase variance of a line ~ noise power / (2 |A/2|^2); in pinion-angle units / order^2
        variance = 1.0 / (2.0 * snr[usable] * orders**2)
        weights = (1.0 / variance) / np.sum(1.0 / variance)
        phases = np.unwrap(np.angle(baseband[usable]), axis=1)
        phases -= phases.mean(axis=1, keepdims=True)
        correction = np.sum(weights[:, None] * phases / orders[:, None], axis=0)
        angle = angle + correction
        used = [candidates[i] for i in usable]
        angle_std = math.sqrt(1.0 / np.sum(1.0 / variance))
        if float(np.max(np.abs(correction))) * z1 * n_harmonics < 1e-4:
            break
    lines = tuple(f"{names[channel]}:mesh{k}" for channel, k in used)
    return AngleEstimate(angle - angle[0], angle_std, lines, weights=tuple(float(w) for w in weights))


def integrated_angle(speed: np.ndarray, fs: float) -> np.ndarray:
    """Pinion angle (rad, 0 at the first sample) integrated from speeds in rpm sampled at ``fs`` Hz (trapezoidal
    rule): the tachometer's angle, and the one a ramp segment's cleaning and model read.

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.rig.order_tracking import integrated_angle
    >>> round(float(integrated_angle(np.full(1001, 600.0), 1000.0)[-1] / (2 * np.pi)), 6)  # 10 rev/s for 1 s
    10.0
    """
    rate = 2.0 * math.pi * np.asarray(speed, dtype=float) / 60.0
    return np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) / fs)])


def tachometer_angle(speed_signal: np.ndarray, fs: float) -> AngleEstimate:
    """Pinion angle (rad) integrated from an instantaneous speed record in rpm (:func:`integrated_angle`)."""
    speed = np.asarray(speed_signal, dtype=float)
    if not np.all(np.isfinite(speed)) or np.any(speed <= 0):
        return AngleEstimate(None, math.nan, (), f"{TACHOMETER_VARIABLE} has non-finite or non-positive speeds")
    return AngleEstimate(integrated_angle(speed, fs), 0.0, (TACHOMETER_VARIABLE,))


def resample_to_angle(records: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Records (C, N) resampled at the instants of uniform angle over the record's angle range.

    The output keeps N samples: sample j is where the angle is
    ``angle[0] + j (angle[-1] - angle[0]) / (N - 1)``; on the input's time
    axis that is a record at the mean speed. The records are band-limited
    (anti-aliased), so a polyphase 4x upsampling followed by a cubic spline
    interpolates them to well below 1e-4 of the amplitude in the band.
    """
    size = records.shape[-1]
    uniform = np.linspace(angle[0], angle[-1], size)
    instants = np.interp(uniform, angle, np.arange(size, dtype=float))
    fine = scipy.signal.resample_poly(records, _UPSAMPLING, 1, axis=-1)
    grid = np.arange(fine.shape[-1]) / _UPSAMPLING
    return CubicSpline(grid, fine, axis=-1)(instants)


def angle_resampled(
    records: np.ndarray, angle: np.ndarray, fs: float, acceleration_rows: Sequence[int] = ()
) -> np.ndarray:
    """Records (C, N) at uniform pinion ``angle`` (rad, one per sample), as the order tracking leaves them.

    :func:`resample_to_angle`, and the rows ``acceleration_rows`` (accelerations)
    divided by (rate / mean rate)^2 at the resampled instants: the shaft turned at
    rate(t) there, and a response that follows the angle has accelerations scaled
    by that square. The model's records of a ramp segment go through this with the
    model's own angle (:mod:`uqgear.rig.ramp_segments`).

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.rig.order_tracking import angle_resampled
    >>> fs = 4096.0
    >>> time = np.arange(4096) / fs
    >>> angle = 2 * np.pi * (20.0 * time + 2.0 * time**2)  # 20 -> 24 rev/s
    >>> record = np.cos(5 * angle)[None, :]  # the fifth order
    >>> tracked = angle_resampled(record, angle, fs)
    >>> uniform = np.linspace(angle[0], angle[-1], time.size)
    >>> bool(np.max(np.abs(tracked[0, 50:-50] - np.cos(5 * uniform[50:-50]))) < 1e-3)
    True
    """
    resampled = resample_to_angle(records, angle)
    if acceleration_rows:
        size = angle.size
        # rpm, computed as the tracking's speed summary computes them
        mean = (angle[-1] - angle[0]) / ((size - 1) / fs) * 60.0 / (2.0 * math.pi)
        rate = np.gradient(angle) * fs * 60.0 / (2.0 * math.pi)
        uniform = np.linspace(angle[0], angle[-1], size)
        instant_rate = np.interp(uniform, angle, rate)
        resampled[list(acceleration_rows)] /= (instant_rate / mean) ** 2
    return resampled


@dataclass(frozen=True)
class _RecordResult:
    records: np.ndarray | None  # resampled (C, N) or None when left as it is
    mean: float  # rpm (NaN when no estimate)
    low: float
    high: float
    tracked: bool
    lines: str
    weights: str = ""  # each line's weight in the angle estimate, as lines


def _track_record(
    records: np.ndarray,
    names: Sequence[str],
    fs: float,
    stated: float,
    design: Design,
    mode: str,
    band_limit: float,
    n_harmonics: int,
    tachometer: np.ndarray | None,
    acceleration_rows: Sequence[int] = (),
) -> _RecordResult:
    if np.isnan(records).any():
        return _RecordResult(None, math.nan, math.nan, math.nan, False, "unusable record (NaN samples)")
    if not (math.isfinite(stated) and stated > 0):
        # the readers of the records reject such a speed with the variable's name
        return _RecordResult(None, math.nan, math.nan, math.nan, False, "no positive stated speed")
    if tachometer is not None and not np.isnan(tachometer).all():
        estimate = tachometer_angle(tachometer, fs)
    else:
        estimate = estimate_pinion_angle(
            list(records), names, fs, stated, design.z1, band_limit=band_limit, n_harmonics=n_harmonics
        )
    if estimate.angle is None:
        if mode == "always":
            raise RigDataError(
                f"order tracking: cannot estimate the pinion angle of a record at {stated:g} rpm: {estimate.reason}"
            )
        return _RecordResult(None, math.nan, math.nan, math.nan, False, estimate.reason)
    angle = estimate.angle
    size = angle.size
    duration = (size - 1) / fs
    mean_rate = (angle[-1] - angle[0]) / duration
    mean = mean_rate * 60.0 / (2.0 * math.pi)
    rate = np.gradient(angle) * fs * 60.0 / (2.0 * math.pi)
    # the estimate is least certain near the record ends: speeds and smear are read without 5 % at each end
    edge = size // 20
    interior = slice(edge, size - edge)
    low, high = float(np.min(rate[interior])), float(np.max(rate[interior]))
    top_order = n_harmonics * design.z1
    time = np.arange(size) / fs
    trend = np.polyval(np.polyfit(time, angle, 1), time)
    smear = top_order * float(np.max(np.abs(angle - trend)[interior]))
    bins = abs(mean - stated) / 60.0 * top_order * duration
    significant = smear > _NOISE_MARGIN * top_order * estimate.angle_std or estimate.angle_std == 0.0
    tracked = mode == "always" or (mode == "auto" and significant and (smear > _SMEAR_LIMIT or bins > _BIN_LIMIT))
    resampled = angle_resampled(records, angle, fs, acceleration_rows) if tracked else None
    weights = " ".join(repr(weight) for weight in estimate.weights)
    return _RecordResult(resampled, mean, low, high, tracked, " ".join(estimate.lines), weights)


def accelerations(signals: xr.Dataset, channels: Sequence[str]) -> tuple[bool, ...]:
    """Per channel, whether it is an acceleration (its ``units``, else the rig format's): resampling rescales those."""
    return tuple(
        signals[name].attrs.get("units", SIGNAL_CHANNELS.get(name, ("",))[0]) == "m s-2" for name in channels
    )


def _checked_channels(signals: xr.Dataset, channels: Sequence[str] | None) -> list[str]:
    """The channels to track (default: every rig channel present), all of one shape ending in ``time``."""
    if channels is None:
        channels = [name for name in SIGNAL_CHANNELS if name in signals.data_vars]
    channels = list(channels)
    if not channels:
        raise RigDataError(
            f"order tracking: no channel variable; expected at least one of {', '.join(SIGNAL_CHANNELS)}"
        )
    if "pinion_speed" not in signals.variables:
        raise RigDataError("order tracking: pinion_speed: missing (stated mean pinion speed in rpm)")
    dims = signals[channels[0]].dims
    for name in channels:
        if name not in signals.data_vars:
            raise RigDataError(f"order tracking: {name}: no such channel variable")
        if signals[name].dims != dims:
            raise RigDataError(
                f"order tracking: {name}: dimensions {signals[name].dims} differ from {dims} of {channels[0]}"
            )
    if "time" not in dims or dims[-1] != "time":
        raise RigDataError(f"order tracking: expected channel dimensions ending in 'time'; got {dims}")
    return channels


def _tachometer(signals: xr.Dataset, dims: tuple[Hashable, ...], size: int) -> np.ndarray | None:
    """The tachometer records (one row per record), None without a tachometer channel."""
    if TACHOMETER_VARIABLE not in signals.data_vars:
        return None
    if signals[TACHOMETER_VARIABLE].dims != dims:
        raise RigDataError(
            f"order tracking: {TACHOMETER_VARIABLE}: expected dimensions {dims}; "
            f"got {signals[TACHOMETER_VARIABLE].dims}"
        )
    return np.asarray(signals[TACHOMETER_VARIABLE].values, dtype=float).reshape(-1, size)


def _speed_estimates(signals: xr.Dataset, template: xr.DataArray, stated: np.ndarray, statistics: np.ndarray,
                     tracked: np.ndarray, references: list[str], weights: list[str]) -> dict[str, xr.DataArray]:
    """Per record: the stated and estimated speeds (mean, lowest, highest), whether it was tracked, and on what."""
    shape = template.shape

    def over_records(values: np.ndarray, attrs: dict) -> xr.DataArray:
        return xr.DataArray(values.reshape(shape), dims=template.dims, coords=template.coords, attrs=attrs)

    new_speed = np.where(tracked, statistics[0], stated)
    variables: dict[str, xr.DataArray] = {}
    variables["pinion_speed_stated"] = over_records(stated, {"units": "rpm", "long_name": "stated mean pinion speed"})
    variables["pinion_speed"] = over_records(new_speed, dict(signals["pinion_speed"].attrs, units="rpm"))
    variables["speed_mean"] = over_records(
        statistics[0], {"units": "rpm", "long_name": "mean pinion speed estimated from the signals"}
    )
    variables["speed_min"] = over_records(statistics[1], {"units": "rpm", "long_name": "lowest instantaneous speed"})
    variables["speed_max"] = over_records(statistics[2], {"units": "rpm", "long_name": "highest instantaneous speed"})
    variables["order_tracked"] = over_records(tracked, {"long_name": "record resampled to uniform pinion angle"})
    variables["speed_reference"] = over_records(
        np.array(references, dtype=object), {"long_name": "lines (or tachometer) the speed estimate rests on"}
    )
    variables["speed_reference_weight"] = over_records(
        np.array(weights, dtype=object), {"long_name": "weight of each line of speed_reference in the estimate"}
    )
    return variables


def track_orders(
    signals: xr.Dataset,
    design: Design,
    *,
    mode: str = "auto",
    channels: Sequence[str] | None = None,
    band_limit: float | None = None,
    n_harmonics: int = 3,
) -> xr.Dataset:
    """Estimate each record's pinion speed and resample records to uniform pinion angle.

    Parameters
    ----------
    signals : xarray.Dataset
        Channel variables with a ``time`` dimension and coordinate (rig data
        or model output), and ``pinion_speed`` (stated mean, rpm) over the
        other dimensions. An optional ``pinion_speed_signal`` variable
        (instantaneous speed in rpm, same dimensions as the channels) is used
        instead of the signals' own mesh phase; a record whose row is all NaN
        has no tachometer and is read from its signals.
    design : Design
        Gives z1.
    mode : {"auto", "always", "never"}
        ``auto`` resamples where the wander matters (module docstring),
        ``always`` every record (an error where no angle can be estimated),
        ``never`` none (the speed is still estimated and reported).
    channels : sequence of str, optional
        Channels to resample (default: those of the rig format present).
    band_limit : float, optional
        Highest usable frequency, Hz (default fs/2.56).
    n_harmonics : int
        Mesh harmonics used for the angle and for the resampling rule.

    Returns
    -------
    xarray.Dataset
        A copy of ``signals`` with resampled channel records where tracked,
        ``pinion_speed`` the estimated mean where tracked (the stated value
        elsewhere), and over the non-time dimensions: ``pinion_speed_stated``,
        ``speed_mean``, ``speed_min``, ``speed_max`` (rpm; min and max of the
        instantaneous speed over the record without its first and last 5 %),
        ``order_tracked`` (bool), ``speed_reference`` (the lines or the
        tachometer used, or why no estimate could be made) and
        ``speed_reference_weight`` (each line's weight in the estimate, as
        space-separated numbers; empty for a tachometer).

    Raises
    ------
    RigDataError
        No channel, channels of different dimensions, a missing speed, or (mode
        ``always``) a record whose angle cannot be estimated.
    StudyError
        An unknown mode.
    """
    mode = check_tracking_mode(mode)
    channels = _checked_channels(signals, channels)
    dims = signals[channels[0]].dims
    fs = sampling_rate(signals["time"].values, where="order tracking: time")
    limit = band_limit_of(band_limit, fs)
    template = signals[channels[0]].isel(time=0, drop=True)
    stated = np.asarray(
        signals["pinion_speed"].broadcast_like(template).transpose(*template.dims).values, dtype=float
    ).ravel()
    size = signals.sizes["time"]
    stacked = np.stack([np.asarray(signals[name].values).reshape(-1, size) for name in channels], axis=1)
    tachometer = _tachometer(signals, dims, size)
    n_records = stacked.shape[0]
    statistics = np.full((3, n_records), np.nan)  # mean, min, max speed (rpm)
    tracked = np.zeros(n_records, dtype=bool)
    references: list[str] = []
    weights: list[str] = []
    outputs: dict[str, np.ndarray | None] = dict.fromkeys(channels)
    acceleration_rows = [index for index, scaled in enumerate(accelerations(signals, channels)) if scaled]
    for record in range(n_records):
        result = _track_record(
            stacked[record].astype(float),
            channels,
            fs,
            float(stated[record]),
            design,
            mode,
            limit,
            n_harmonics,
            None if tachometer is None else tachometer[record],
            acceleration_rows,
        )
        statistics[:, record] = (result.mean, result.low, result.high)
        tracked[record] = result.tracked
        references.append(result.lines)
        weights.append(result.weights)
        if result.records is not None:
            for index, name in enumerate(channels):
                output = outputs[name]
                if output is None:
                    output = outputs[name] = np.array(signals[name].values, copy=True).reshape(-1, size)
                output[record] = result.records[index]
    result_ds = signals.copy()
    for name, values in outputs.items():
        if values is not None:
            result_ds[name] = signals[name].copy(data=values.reshape(signals[name].shape).astype(signals[name].dtype))
    for name, variable in _speed_estimates(signals, template, stated, statistics, tracked, references, weights).items():
        result_ds[name] = variable
    result_ds.attrs["order_tracking"] = mode
    return result_ds


@dataclass(frozen=True)
class TrackerImage:
    """What a record's order tracking from its own mesh lines does to a constant-speed record's mesh sidebands.

    The angle estimate of :func:`estimate_pinion_angle` reads the phase of
    the mesh harmonics inside half a pinion order, so it takes the phase
    modulation of the mesh by a gear-order effect (a gear run-out, gear pitch
    errors) for wander and resampling removes it. A model run at constant
    speed has no wander, but compared with such a record it must lose the
    same share of its sidebands. To first order in the sidebands (a few
    percent of their mesh line), the resampled record is
    ``x(t) - x'(t) dtheta(t) / Omega`` with ``dtheta`` the estimate's
    deviation from a uniform angle: the weighted phase modulation of the
    lines the estimate read, each over its order, passed through the
    demodulation filter; accelerations are also divided by the squared
    speed ratio, as :func:`track_orders` divides them.

    Attributes
    ----------
    channels, harmonics, weights : tuple
        Per line of the estimate: its channel (index), mesh harmonic ``k`` and weight.
    z1 : int
        Pinion teeth.
    accelerations : tuple of bool
        Per channel, whether it is an acceleration (divided by the squared speed ratio).

    Examples
    --------
    A record whose mesh line carries a pure phase modulation at a gear order
    loses both sidebands when the estimate reads that line alone:

    >>> import numpy as np
    >>> image = TrackerImage(channels=(0,), harmonics=(1,), weights=(1.0,), z1=20, accelerations=(False,))
    >>> mesh = np.array([[[2.0]]])                      # (run, channel, harmonic)
    >>> depth = 0.01                                    # rad of phase modulation
    >>> plus = 1j * mesh[..., None] * depth / 2         # (run, channel, harmonic, offset)
    >>> minus = 1j * mesh[..., None] * depth / 2
    >>> after_plus, after_minus = image.sidebands(mesh, plus, minus, np.array([0.05]))
    >>> bool(np.abs(after_plus).max() < 1e-6 * abs(plus).max())
    True
    """

    channels: tuple[int, ...]
    harmonics: tuple[int, ...]
    weights: tuple[float, ...]
    z1: int
    accelerations: tuple[bool, ...]

    def deviation(self, mesh: np.ndarray, plus: np.ndarray, minus: np.ndarray, offsets: np.ndarray) -> np.ndarray:
        """The estimate's angle deviation (R, M), rad of pinion angle, as a phasor at each offset order.

        ``mesh`` (R, C, K): each channel's mesh harmonics; ``plus`` and
        ``minus`` (R, C, K, M): their upper and lower sidebands at the
        ``offsets`` (M, pinion orders, positive), all as phasors ``a - i b``
        of ``a cos + b sin``.
        """
        deviation = np.zeros((mesh.shape[0], offsets.size), dtype=complex)
        for channel, harmonic, weight in zip(self.channels, self.harmonics, self.weights):
            line = mesh[:, channel, harmonic - 1][:, None]
            upper, lower = plus[:, channel, harmonic - 1], minus[:, channel, harmonic - 1]
            with np.errstate(divide="ignore", invalid="ignore"):
                modulation = -1j * (upper / line - np.conj(lower / line))
            deviation += weight * np.where(np.isfinite(modulation), modulation, 0.0) / (harmonic * self.z1)
        # the demodulation filter: a third-order Butterworth run forward and back
        return deviation / (1.0 + (offsets / _BAND_FRACTION) ** 6)

    def sidebands(
        self, mesh: np.ndarray, plus: np.ndarray, minus: np.ndarray, offsets: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The upper and lower sidebands (R, C, K, M) after the tracking (arguments as :meth:`deviation`)."""
        deviation = self.deviation(mesh, plus, minus, offsets)[:, None, None, :]
        orders = (np.arange(1, mesh.shape[2] + 1) * self.z1)[None, None, :, None]
        line = np.where(np.isfinite(mesh), mesh, 0.0)[..., None]
        shift_plus = -0.5j * orders * line * deviation
        shift_minus = -0.5j * orders * line * np.conj(deviation)
        scaled = np.array(self.accelerations, dtype=bool)[None, :, None, None]
        # the division by the squared speed ratio: an amplitude modulation of -2 dtheta' / Omega
        shift_plus = shift_plus + np.where(scaled, -1j * offsets * line * deviation, 0.0)
        shift_minus = shift_minus + np.where(scaled, 1j * offsets * line * np.conj(deviation), 0.0)
        return plus + shift_plus, minus + shift_minus


def tracker_image(
    row: dict[str, object], channels: Sequence[str], z1: int, scaled: Sequence[bool]
) -> TrackerImage | None:
    """The :class:`TrackerImage` of one record's :func:`speed_summary` row, or None.

    ``scaled``: per channel, whether :func:`track_orders` rescaled it as an
    acceleration (:func:`accelerations` of the tracked signals). None where
    the record was not resampled, or was resampled on a tachometer (which
    reads the true angle and takes nothing from the sidebands).
    """
    reference = str(row.get("reference", ""))
    weights = row.get("reference_weights") or []
    if not row.get("order_tracked") or not reference or not isinstance(weights, list):
        return None
    lines = reference.split()
    if len(lines) != len(weights) or any(":mesh" not in line for line in lines):
        return None
    index = {name: position for position, name in enumerate(channels)}
    parsed = [line.split(":mesh") for line in lines]
    if any(channel not in index for channel, _ in parsed):
        return None
    return TrackerImage(
        channels=tuple(index[channel] for channel, _ in parsed),
        harmonics=tuple(int(harmonic) for _, harmonic in parsed),
        weights=tuple(float(weight) for weight in weights),
        z1=int(z1),
        accelerations=tuple(bool(value) for value in scaled),
    )


def speed_summary(tracked: xr.Dataset) -> list[dict[str, object]]:
    """Per-operating-point speed estimate of :func:`track_orders` output, JSON-ready."""
    rows: list[dict[str, object]] = []
    for op in range(tracked.sizes.get("op", 1)):
        pick = tracked.isel(op=op) if "op" in tracked.dims else tracked

        def number(name: str, pick: xr.Dataset = pick) -> float | None:
            value = float(np.asarray(pick[name].values).ravel()[0])
            return value if math.isfinite(value) else None

        mean = number("speed_mean")
        low, high = number("speed_min"), number("speed_max")
        wander = None if mean is None or low is None or high is None else 0.5 * (high - low) / mean
        rows.append(
            {
                "op": op,
                "stated_rpm": number("pinion_speed_stated"),
                "mean_rpm": mean,
                "min_rpm": low,
                "max_rpm": high,
                "wander": wander,
                "order_tracked": bool(np.asarray(pick["order_tracked"].values).ravel()[0]),
                "reference": str(np.asarray(pick["speed_reference"].values).ravel()[0]),
            }
        )
        if "speed_reference_weight" in pick:
            text = str(np.asarray(pick["speed_reference_weight"].values).ravel()[0])
            rows[-1]["reference_weights"] = [float(value) for value in text.split()]
        if "op_source" in pick.coords:
            # a campaign with ramp records: which record the operating point comes from
            rows[-1]["source"] = str(np.asarray(pick["op_source"].values).ravel()[0])
    return rows


__all__ = [
    "TRACKING_MODES",
    "SPEED_ESTIMATE_VARIABLES",
    "TACHOMETER_VARIABLE",
    "AngleEstimate",
    "estimate_pinion_angle",
    "tachometer_angle",
    "integrated_angle",
    "resample_to_angle",
    "track_orders",
    "check_tracking_mode",
    "accelerations",
    "TrackerImage",
    "tracker_image",
    "speed_summary",
]
