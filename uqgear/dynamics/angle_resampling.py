"""Computed order tracking: records of run-ups and coast-downs resampled to uniform pinion angle.

A record whose pinion speed changes (a run-up, a coast-down) holds its
shaft-locked components at fixed *orders* (cycles per pinion revolution, the
mesh at order z1), not at fixed frequencies; in the angle domain they are
lines again.

1. **Resampling to uniform pinion angle** (:func:`resample_to_angle`). The
   pinion angle comes from the Dataset's ``pinion_angle`` (rad, unwrapped),
   or is integrated from its ``pinion_speed`` (rpm,
   :func:`angle_from_speed`); a tachometer pulse train gives it through
   :func:`angle_from_pulses`. The signals are upsampled 8x by a polyphase
   filter (:func:`scipy.signal.resample_poly` with a Kaiser-window FIR cut
   off at 0.95 of the original Nyquist frequency) and a cubic spline of that
   is read at the instants where the angle is a whole multiple of
   ``2 pi / S``. ``S`` samples per revolution is the smallest power of two
   with ``S f_r >= f_s`` at the lowest shaft frequency ``f_r`` of the record,
   so the angle grid is at least as fine as the time grid at every speed and
   resampling aliases nothing.
2. **Anti-aliasing, stated.** What the time samples hold above the Nyquist
   frequency ``f_s / 2`` is beyond recovery, and the polyphase filter's
   transition band takes the top of the band below it. An order ``k`` is
   resolvable in a block of revolutions when ``k f_r,max <= 0.8 f_s / 2``
   (:data:`RESOLVABLE_FRACTION`) at the block's top speed; the order maps
   (:mod:`uqgear.dynamics.order_maps`) read orders above that limit as NaN,
   never an aliased value. The limit falls as the speed rises: 164 pinion
   orders at 3000 rpm and 20480 Hz.

:mod:`uqgear.rig.order_tracking` is the other tracking of the package: it
estimates the angle of a steady rig record, whose speed only wanders, from
its own mesh lines.

This module does no file I/O and no plotting.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.signal
import xarray as xr
from scipy.integrate import cumulative_trapezoid
from scipy.interpolate import CubicSpline

from ..common.errors import UqgearError
from .spectra import uniform_time_step

#: Fraction of the Nyquist frequency up to which an order line is read; above it, NaN.
RESOLVABLE_FRACTION = 0.8
#: Signals a run-up Dataset carries, in the order they are analysed by default.
RUNUP_SIGNALS: tuple[str, ...] = ("te", "mesh_force", "y1_acceleration", "y2_acceleration")

# Polyphase upsampling before the cubic spline: the spline is then read far
# below its own Nyquist frequency (a sine at 0.8 of the original Nyquist
# frequency is interpolated within 3e-5 of its amplitude; 4x leaves 5e-4).
_UPSAMPLING = 8
# The interpolation filter: 80 original samples long, Kaiser beta 10 (about
# 100 dB stop band, passband ripple ~1e-5), cut off at 0.95 of the original
# Nyquist frequency so that its transition band lies above the resolvable
# fraction. scipy's default (Kaiser beta 5) ripples by ~1e-3.
_FILTER_SAMPLES, _FILTER_BETA, _FILTER_CUTOFF = 80, 10.0, 0.95
# Samples at each end of the record left out of the angle grid, in original
# samples: the filter's edge transient (its half-length is 40).
_EDGE_SAMPLES = 48
# Densest angle grid accepted, in samples per revolution (a lowest speed of
# fs / 65536 revolutions per second).
_MAX_SAMPLES_PER_REVOLUTION = 2**16


class OrderTrackingError(UqgearError):
    """A record cannot be order tracked: no angle, a non-monotone angle, an unknown signal.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.angle_resampling import OrderTrackingError, resample_to_angle
    >>> ds = xr.Dataset({"te": ("time", np.zeros(1000))}, coords={"time": np.arange(1000) / 1e3})
    >>> try:
    ...     resample_to_angle(ds)
    ... except OrderTrackingError as error:
    ...     print(error)
    resample_to_angle: the Dataset has neither 'pinion_angle' (rad) nor 'pinion_speed' (rpm) over 'time'
    """


# ---------------------------------------------------------------------------- angle


def angle_from_speed(speed_rpm: Any, time: Any) -> np.ndarray:
    """Pinion angle (rad, from 0) integrated from a speed signal by the trapezoidal rule.

    Parameters
    ----------
    speed_rpm : array_like
        Instantaneous pinion speed (rpm) at each instant of ``time``.
    time : array_like
        Increasing instants (s).

    Returns
    -------
    numpy.ndarray
        ``2 pi / 60 * integral of speed dt``, 0 at the first instant.

    Examples
    --------
    A linear ramp from 600 to 1200 rpm in 1 s turns the pinion 15 revolutions:

    >>> import numpy as np
    >>> from uqgear.dynamics.angle_resampling import angle_from_speed
    >>> time = np.linspace(0.0, 1.0, 1001)
    >>> angle = angle_from_speed(600.0 + 600.0 * time, time)
    >>> round(float(angle[-1] / (2 * np.pi)), 9)
    15.0
    """
    speed = np.asarray(speed_rpm, dtype=float)
    instants = np.asarray(time, dtype=float)
    if speed.ndim != 1 or speed.shape != instants.shape or speed.size < 2:
        raise OrderTrackingError(
            f"pinion_speed: expected a 1-D speed signal on the {instants.size} instants of time; "
            f"got shape {speed.shape}"
        )
    if not np.all(np.isfinite(speed)):
        raise OrderTrackingError("pinion_speed: expected finite values; got NaN or infinity")
    if np.any(np.diff(instants) <= 0.0):
        raise OrderTrackingError("time: expected increasing instants")
    return np.asarray(cumulative_trapezoid(speed * (2.0 * np.pi / 60.0), instants, initial=0.0))


def angle_from_pulses(pulse_times: Any, time: Any, pulses_per_revolution: int = 1) -> np.ndarray:
    """Pinion angle (rad) at ``time`` from the instants of tachometer pulses.

    Pulse ``j`` marks the angle ``2 pi j / pulses_per_revolution``; between
    pulses the angle follows a monotone cubic (PCHIP) interpolant, so it
    never runs backwards. Instants outside the first and last pulse are
    extrapolated by the same cubic: trim the record to the pulses when the
    speed changes fast there.

    Parameters
    ----------
    pulse_times : array_like
        Increasing pulse instants (s), at least 4.
    time : array_like
        Instants (s) at which the angle is wanted.
    pulses_per_revolution : int
        Pulses per pinion revolution of the tachometer.

    Returns
    -------
    numpy.ndarray
        Angle (rad), 0 at the first pulse.

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.dynamics.angle_resampling import angle_from_pulses
    >>> pulses = np.arange(0.0, 1.0001, 0.001)  # 60 pulses/rev at 1000 rpm
    >>> angle = angle_from_pulses(pulses, [0.5, 1.0], pulses_per_revolution=60)
    >>> np.round(angle / (2 * np.pi), 6).tolist()
    [8.333333, 16.666667]
    """
    from scipy.interpolate import PchipInterpolator

    pulses = np.asarray(pulse_times, dtype=float)
    if pulses.ndim != 1 or pulses.size < 4 or np.any(np.diff(pulses) <= 0.0) or not np.all(np.isfinite(pulses)):
        raise OrderTrackingError(
            f"pulse_times: expected at least 4 finite increasing pulse instants; got {pulses.size} values"
        )
    if int(pulses_per_revolution) != pulses_per_revolution or pulses_per_revolution < 1:
        raise OrderTrackingError(f"pulses_per_revolution: expected a positive integer; got {pulses_per_revolution!r}")
    angles = 2.0 * np.pi * np.arange(pulses.size) / int(pulses_per_revolution)
    return np.asarray(PchipInterpolator(pulses, angles, extrapolate=True)(np.asarray(time, dtype=float)))


def _pinion_angle(ds: xr.Dataset, what: str) -> np.ndarray:
    """The pinion angle at each instant: ``pinion_angle``, else ``pinion_speed`` integrated; checked increasing."""
    time = np.asarray(ds["time"].values, dtype=float)
    if "pinion_angle" in ds.variables:
        angle = np.asarray(ds["pinion_angle"].values, dtype=float)
        name = "pinion_angle"
        if angle.shape != time.shape:
            dims = ds["pinion_angle"].dims
            raise OrderTrackingError(f"pinion_angle: expected values over 'time' only; got dims {dims}")
        if not np.all(np.isfinite(angle)):
            raise OrderTrackingError("pinion_angle: expected finite values; got NaN or infinity")
    elif "pinion_speed" in ds.variables and "time" in ds["pinion_speed"].dims:
        angle = angle_from_speed(ds["pinion_speed"].values, time)
        name = "pinion_speed"
    else:
        raise OrderTrackingError(
            f"{what}: the Dataset has neither 'pinion_angle' (rad) nor 'pinion_speed' (rpm) over 'time'"
        )
    steps = np.diff(angle)
    if np.all(steps < 0.0):
        # a pinion turning backwards: the analyses read the same in its own sense of rotation
        angle = -angle
    elif not np.all(steps > 0.0):
        raise OrderTrackingError(
            f"{name}: expected a strictly monotone pinion angle (speed never 0 nor changing sign); "
            f"it stalls or reverses at {int(np.sum(steps <= 0.0))} of {steps.size} steps"
        )
    return angle


def _signal_names(ds: xr.Dataset, signals: str | Sequence[str] | None, what: str) -> list[str]:
    if signals is None:
        names = [name for name in RUNUP_SIGNALS if name in ds.data_vars]
        if not names:
            raise OrderTrackingError(
                f"signals: {what} found none of the run-up signals {', '.join(RUNUP_SIGNALS)}; name the signals"
            )
        return names
    names = [signals] if isinstance(signals, str) else [str(name) for name in signals]
    if not names:
        raise OrderTrackingError("signals: expected at least one signal name; got none")
    for name in names:
        if name not in ds.data_vars:
            raise OrderTrackingError(
                f"signals: the Dataset has no variable {name!r}; it has {', '.join(map(str, ds.data_vars)) or 'none'}"
            )
        if ds[name].dims != ("time",) and ds[name].dims != ("angle",):
            raise OrderTrackingError(f"signals: {name!r} should be a history over 'time'; it has dims {ds[name].dims}")
    return names


def resample_to_angle(ds: xr.Dataset, signals: str | Sequence[str] | None = None) -> xr.Dataset:
    """Signals resampled from uniform time to uniform pinion angle (computed order tracking).

    Parameters
    ----------
    ds : xarray.Dataset
        A record on a uniform ``time`` coord (s) with ``pinion_angle`` (rad,
        unwrapped) or ``pinion_speed`` (rpm) over ``time``, and the signals.
    signals : str or sequence of str, optional
        Signals to resample; by default those of :data:`RUNUP_SIGNALS` present.

    Returns
    -------
    xarray.Dataset
        The signals over dim ``angle`` (rad, the absolute pinion angle, in
        steps of ``2 pi / S``), with ``time`` (s) and ``pinion_speed`` (rpm,
        the angle's time derivative) at each sample. Attrs:
        ``samples_per_revolution`` (S), ``sample_rate`` (Hz, of the time
        record), ``resolvable_fraction``, and ``design_z1`` when the record
        gives it.

    Examples
    --------
    An order-21 cosine on a run-up from 600 to 1800 rpm stays one cosine in
    the angle domain:

    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.angle_resampling import resample_to_angle
    >>> time = np.arange(0.0, 2.0, 1.0 / 8192)
    >>> angle = 2 * np.pi * (10.0 * time + 5.0 * time**2)
    >>> ds = xr.Dataset({"pinion_angle": ("time", angle), "te": ("time", np.cos(21 * angle))},
    ...                 coords={"time": time})
    >>> tracked = resample_to_angle(ds, "te")
    >>> tracked.attrs["samples_per_revolution"]
    1024
    >>> error = tracked["te"] - np.cos(21 * tracked["angle"])
    >>> bool(abs(error).max() < 1e-4)
    True
    """
    if not isinstance(ds, xr.Dataset):
        raise OrderTrackingError(f"resample_to_angle: expected an xarray Dataset; got {type(ds).__name__}")
    names = _signal_names(ds, signals, "resample_to_angle")
    step = uniform_time_step(ds, "resample_to_angle")
    sample_rate = 1.0 / step
    time = np.asarray(ds["time"].values, dtype=float)
    if time.size < 4 * _EDGE_SAMPLES:
        raise OrderTrackingError(f"time: expected at least {4 * _EDGE_SAMPLES} samples; got {time.size}")
    angle = _pinion_angle(ds, "resample_to_angle")
    angle_spline = CubicSpline(time, angle)
    lowest = float(np.min(angle_spline(time, 1))) / (2.0 * np.pi)
    if lowest <= 0.0:
        raise OrderTrackingError("pinion_angle: the angle's cubic fit runs backwards; the speed comes too near 0")
    samples_per_revolution = int(2 ** np.ceil(np.log2(sample_rate / lowest)))
    if samples_per_revolution > _MAX_SAMPLES_PER_REVOLUTION:
        raise OrderTrackingError(
            f"pinion_speed: the lowest speed {60.0 * lowest:.4g} rpm needs {samples_per_revolution} samples per "
            f"revolution at {sample_rate:g} Hz (at most {_MAX_SAMPLES_PER_REVOLUTION}); "
            "trim the record to higher speeds"
        )
    # the angle grid: whole multiples of 2 pi / S inside the record less its edge transient
    increment = 2.0 * np.pi / samples_per_revolution
    first = float(angle_spline(time[0] + _EDGE_SAMPLES * step))
    last = float(angle_spline(time[-1] - _EDGE_SAMPLES * step))
    grid = increment * np.arange(np.ceil(first / increment), np.floor(last / increment) + 1)
    instants = CubicSpline(angle, time)(grid)
    up_time = time[0] + np.arange(time.size * _UPSAMPLING) * (step / _UPSAMPLING)
    interpolation_filter = scipy.signal.firwin(
        _FILTER_SAMPLES * _UPSAMPLING + 1,
        _FILTER_CUTOFF * 0.5 * sample_rate,
        window=("kaiser", _FILTER_BETA),
        fs=sample_rate * _UPSAMPLING,
    )
    data: dict[str, Any] = {}
    for name in names:
        values = np.asarray(ds[name].values, dtype=float)
        if not np.all(np.isfinite(values)):
            raise OrderTrackingError(f"signals: {name!r} holds NaN or infinity")
        upsampled = scipy.signal.resample_poly(values, _UPSAMPLING, 1, window=interpolation_filter, padtype="line")
        data[name] = ("angle", CubicSpline(up_time, upsampled)(instants), dict(ds[name].attrs))
    speed = angle_spline(instants, 1) * (60.0 / (2.0 * np.pi))
    data["time"] = ("angle", instants, {"units": "s", "long_name": "instant of the angle sample"})
    data["pinion_speed"] = ("angle", speed, {"units": "rpm", "long_name": "pinion speed"})
    attrs: dict[str, Any] = {
        "samples_per_revolution": samples_per_revolution,
        "sample_rate": sample_rate,
        "resolvable_fraction": RESOLVABLE_FRACTION,
    }
    if "design_z1" in ds.attrs:
        attrs["design_z1"] = ds.attrs["design_z1"]
    angle_coord = xr.Variable("angle", grid, {"units": "rad", "long_name": "pinion angle"})
    return xr.Dataset(data, coords={"angle": angle_coord}, attrs=attrs)


def angle_record(ds: xr.Dataset, signals: str | Sequence[str] | None, what: str) -> tuple[xr.Dataset, list[str]]:
    """The record over ``angle`` (resampled here when it is over ``time``) and the signal names.

    The entry of every order analysis: a record already over ``angle`` (with ``samples_per_revolution``)
    is taken as it is, one over ``time`` goes through :func:`resample_to_angle`; ``signals`` (one name, a
    list or ``None`` for the run-up signals it has) is checked against it, naming ``what`` in an
    :class:`OrderTrackingError`.
    """
    if not isinstance(ds, xr.Dataset):
        raise OrderTrackingError(f"{what}: expected an xarray Dataset; got {type(ds).__name__}")
    if "angle" in ds.dims and "samples_per_revolution" in ds.attrs:
        return ds, _signal_names(ds, signals, what)
    names = _signal_names(ds, signals, what)
    return resample_to_angle(ds, names), names
