"""Computed order tracking of run-up and coast-down records, and order maps over speed.

A record whose pinion speed changes (a run-up, a coast-down) holds its
shaft-locked components at fixed *orders* (cycles per pinion revolution, the
mesh at order z1), not at fixed frequencies. The analyses here:

1. **Resampling to uniform pinion angle** (:func:`resample_to_angle`). The
   pinion angle comes from the Dataset's ``pinion_angle`` (rad, unwrapped),
   or is integrated from its ``pinion_speed`` (rpm,
   :func:`angle_from_speed`); a tachometer pulse train gives it through
   :func:`angle_from_pulses`. The signals are upsampled 8x by a polyphase
   filter (:func:`scipy.signal.resample_poly` with a Kaiser-window FIR cut
   off at 0.95 of the original Nyquist frequency) and a cubic spline of that
   is read at the
   instants where the angle is a whole multiple of ``2 pi / S``. ``S``
   samples per revolution is the smallest power of two with ``S f_r >= f_s``
   at the lowest shaft frequency ``f_r`` of the record, so the angle grid is
   at least as fine as the time grid at every speed and resampling aliases
   nothing.
2. **Anti-aliasing, stated.** What the time samples hold above the Nyquist
   frequency ``f_s / 2`` is beyond recovery, and the polyphase filter's
   transition band takes the top of the band below it. An order ``k`` is
   resolvable in a block of revolutions when ``k f_r,max <= 0.8 f_s / 2``
   (:data:`RESOLVABLE_FRACTION`) at the block's top speed; orders above that
   limit read NaN, never an aliased value. The limit falls as the speed
   rises: 164 pinion orders at 3000 rpm and 20480 Hz.
3. **Order map** (:func:`order_map`). The angle-domain record is cut into
   blocks of a whole number of revolutions (overlapping), each windowed and
   projected on ``exp(-i k theta)`` at the requested orders, with the
   absolute pinion angle as phase reference: a component
   ``A cos(k theta + phi)`` reads amplitude ``A`` (the window's coherent gain
   divided out) and phase ``phi``. Blocks are binned by their
   window-weighted mean speed; a bin holds the mean amplitude and the
   circular mean phase of its blocks. :func:`order_spectrum` gives the same
   over a continuous order axis (the classic waterfall) for plotting.

A component at a fixed frequency (a structural resonance, a mains line)
moves through the orders as the speed changes and smears over the order
bins of a block; it shows in the map as a curve ``order = 60 f / n``, not at
a fixed order.

This module does no file I/O and no plotting.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import scipy.signal
import xarray as xr
from scipy.integrate import cumulative_trapezoid
from scipy.interpolate import CubicSpline

from ..common.errors import UqgearError
from ._checks import _check_positive
from .spectra import _time_step

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
    >>> from uqgear.dynamics.order_maps import OrderTrackingError, resample_to_angle
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
    >>> from uqgear.dynamics.order_maps import angle_from_speed
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
    >>> from uqgear.dynamics.order_maps import angle_from_pulses
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
    >>> from uqgear.dynamics.order_maps import resample_to_angle
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
    step = _time_step(ds, "resample_to_angle")
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


def _tracked(ds: xr.Dataset, signals: str | Sequence[str] | None, what: str) -> tuple[xr.Dataset, list[str]]:
    """The record over ``angle`` (resampled here when it is over ``time``) and the signal names."""
    if not isinstance(ds, xr.Dataset):
        raise OrderTrackingError(f"{what}: expected an xarray Dataset; got {type(ds).__name__}")
    if "angle" in ds.dims and "samples_per_revolution" in ds.attrs:
        return ds, _signal_names(ds, signals, what)
    names = _signal_names(ds, signals, what)
    return resample_to_angle(ds, names), names


# ---------------------------------------------------------------------------- blocks and bins


@dataclass(frozen=True)
class _Block:
    """One block of whole revolutions: its samples' slice, weighted-mean and top speed (rpm)."""

    start: int
    stop: int
    mean_speed: float
    top_speed: float


def _blocks(tracked: xr.Dataset, revolutions: int, overlap: float, taper: np.ndarray) -> Iterator[_Block]:
    length = taper.size
    hop = max(1, int(round(length * (1.0 - overlap))))
    speed = np.asarray(tracked["pinion_speed"].values, dtype=float)
    for start in range(0, speed.size - length + 1, hop):
        piece = speed[start : start + length]
        # the window-weighted mean: a component whose amplitude is linear in speed reads its value there
        yield _Block(start, start + length, float(np.dot(taper, piece) / taper.sum()), float(piece.max()))


def speed_bin_edges(speeds: Any, speed_bins: int | Sequence[float]) -> np.ndarray:
    """Edges (rpm) of speed bins: ``speed_bins`` equal bins over the speeds' range, or the edges given.

    Examples
    --------
    >>> from uqgear.dynamics.order_maps import speed_bin_edges
    >>> speed_bin_edges([500.0, 1200.0, 3000.0], 5).tolist()
    [500.0, 1000.0, 1500.0, 2000.0, 2500.0, 3000.0]
    """
    if isinstance(speed_bins, (int, np.integer)):
        if speed_bins < 1:
            raise OrderTrackingError(f"speed_bins: expected a positive number of bins; got {speed_bins}")
        values = np.asarray(speeds, dtype=float)
        low, high = float(np.min(values)), float(np.max(values))
        if not high > low:
            raise OrderTrackingError(f"speed_bins: the record's speed does not change ({low:g} rpm); give bin edges")
        return np.linspace(low, high, int(speed_bins) + 1)
    edges = np.asarray(speed_bins, dtype=float)
    if edges.ndim != 1 or edges.size < 2 or not np.all(np.isfinite(edges)) or np.any(np.diff(edges) <= 0.0):
        raise OrderTrackingError(f"speed_bins: expected at least 2 increasing finite edges (rpm); got {speed_bins!r}")
    return edges


def _bin_index(speeds: Any, edges: np.ndarray) -> np.ndarray:
    """Bin of each speed (-1 outside the edges; the top edge belongs to the last bin)."""
    values = np.asarray(speeds, dtype=float)
    index = np.searchsorted(edges, values, side="right") - 1
    index[values == edges[-1]] = edges.size - 2
    index[(values < edges[0]) | (values > edges[-1])] = -1
    return index


def _speed_coords(edges: np.ndarray) -> dict[str, xr.Variable]:
    """``pinion_speed`` (bin centres) with ``bin_lower`` and ``bin_upper`` alongside, all rpm."""
    centres = 0.5 * (edges[:-1] + edges[1:])
    return {
        "pinion_speed": xr.Variable(
            "pinion_speed", centres, {"units": "rpm", "long_name": "pinion speed (bin centre)"}
        ),
        "bin_lower": xr.Variable("pinion_speed", edges[:-1], {"units": "rpm", "long_name": "lower edge of the bin"}),
        "bin_upper": xr.Variable("pinion_speed", edges[1:], {"units": "rpm", "long_name": "upper edge of the bin"}),
    }


# ---------------------------------------------------------------------------- order maps


@dataclass(frozen=True)
class _Setup:
    """What an order map and an order spectrum share: the tracked record, its blocks and their bins."""

    tracked: xr.Dataset
    names: list[str]
    taper: np.ndarray
    blocks: list[_Block]
    bins: np.ndarray
    edges: np.ndarray
    limits: np.ndarray  # per speed bin: the highest resolvable pinion order of its blocks (NaN: empty bin)
    mesh_order: int | None
    scale: float  # pinion orders per order of the unit shown


def _mesh_order(ds: xr.Dataset, z1: int | None) -> int | None:
    if z1 is None:
        z1 = ds.attrs.get("design_z1", ds.attrs.get("z1"))
    if z1 is None:
        return None
    if int(z1) != z1 or int(z1) < 1:
        raise OrderTrackingError(f"z1: expected a positive whole number of pinion teeth; got {z1!r}")
    return int(z1)


def _setup(ds: xr.Dataset, signals: Any, options: dict[str, Any], what: str) -> _Setup:
    revolutions = options["revolutions_per_block"]
    if int(revolutions) != revolutions or revolutions < 1:
        raise OrderTrackingError(f"revolutions_per_block: expected a positive whole number; got {revolutions!r}")
    overlap = float(options["overlap"])
    if not 0.0 <= overlap < 1.0:
        raise OrderTrackingError(f"overlap: expected a fraction in [0, 1); got {options['overlap']!r}")
    if options["order_unit"] not in ("pinion", "mesh"):
        raise OrderTrackingError(f"order_unit: expected 'pinion' or 'mesh'; got {options['order_unit']!r}")
    mesh_order = _mesh_order(ds, options["z1"])
    if options["order_unit"] == "mesh" and mesh_order is None:
        raise OrderTrackingError("order_unit: 'mesh' needs z1 (the Dataset attr 'design_z1' or the z1 argument)")
    tracked, names = _tracked(ds, signals, what)
    per_revolution = int(tracked.attrs["samples_per_revolution"])
    try:
        taper = scipy.signal.get_window(options["window"], int(revolutions) * per_revolution, fftbins=True)
    except (ValueError, TypeError) as error:
        raise OrderTrackingError(
            f"window: expected a window name of scipy.signal.get_window; got {options['window']!r} ({error})"
        ) from None
    blocks = list(_blocks(tracked, int(revolutions), overlap, taper))
    if not blocks:
        raise OrderTrackingError(
            f"revolutions_per_block: the record turns {tracked.sizes['angle'] / per_revolution:.1f} revolutions, "
            f"fewer than one block of {revolutions}"
        )
    edges = speed_bin_edges([block.mean_speed for block in blocks], options["speed_bins"])
    bins = _bin_index([block.mean_speed for block in blocks], edges)
    nyquist_order = RESOLVABLE_FRACTION * 0.5 * float(tracked.attrs["sample_rate"])
    limits = np.full(edges.size - 1, np.inf)
    for block, index in zip(blocks, bins, strict=True):
        if index >= 0:
            block_limit = min(nyquist_order / (block.top_speed / 60.0), RESOLVABLE_FRACTION * 0.5 * per_revolution)
            limits[index] = min(limits[index], block_limit)
    limits[np.isinf(limits)] = np.nan
    scale = float(mesh_order) if options["order_unit"] == "mesh" and mesh_order is not None else 1.0
    return _Setup(tracked, names, taper, blocks, bins, edges, limits, mesh_order, scale)


def _block_values(setup: _Setup, block: _Block) -> np.ndarray:
    """The signals of one block (signal x sample), less their block means (no DC leaking into low orders)."""
    values = np.stack([np.asarray(setup.tracked[name].values[block.start : block.stop]) for name in setup.names])
    return (values - values.mean(axis=1, keepdims=True)) * setup.taper


def _units(setup: _Setup) -> tuple[str, list[str]]:
    units = [str(setup.tracked[name].attrs.get("units", "")) for name in setup.names]
    pairs = zip(setup.names, units, strict=True)
    shared = units[0] if len(set(units)) == 1 else "; ".join(f"{name}: {unit}" for name, unit in pairs)
    return shared, units


def _result_coords(setup: _Setup, orders: np.ndarray, unit: str) -> dict[str, Any]:
    _, units = _units(setup)
    long_name = "order (cycles per pinion revolution)" if unit == "pinion" else "mesh order (cycles per mesh period)"
    return {
        "signal": xr.Variable("signal", np.array(setup.names, dtype=object)),
        "signal_units": xr.Variable("signal", np.array(units, dtype=object)),
        **_speed_coords(setup.edges),
        "order": xr.Variable("order", orders, {"units": "1", "long_name": long_name}),
    }


def _result_attrs(setup: _Setup, options: dict[str, Any]) -> dict[str, Any]:
    attrs: dict[str, Any] = {
        "order_unit": options["order_unit"],
        "revolutions_per_block": int(options["revolutions_per_block"]),
        "overlap": float(options["overlap"]),
        "window": str(options["window"]),
        "samples_per_revolution": int(setup.tracked.attrs["samples_per_revolution"]),
        "sample_rate": float(setup.tracked.attrs["sample_rate"]),
        "resolvable_fraction": RESOLVABLE_FRACTION,
    }
    if setup.mesh_order is not None:
        attrs["mesh_order"] = setup.mesh_order
    return attrs


def _bin_summaries(setup: _Setup) -> dict[str, Any]:
    counts = np.bincount(setup.bins[setup.bins >= 0], minlength=setup.edges.size - 1)
    speeds = np.zeros(counts.size)
    np.add.at(
        speeds,
        setup.bins[setup.bins >= 0],
        [b.mean_speed for b, i in zip(setup.blocks, setup.bins, strict=True) if i >= 0],
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_speed = np.where(counts > 0, speeds / np.maximum(counts, 1), np.nan)
    return {
        "block_count": ("pinion_speed", counts, {"units": "1", "long_name": "blocks in the speed bin"}),
        "mean_speed": ("pinion_speed", mean_speed, {"units": "rpm", "long_name": "mean speed of the bin's blocks"}),
        "max_order": (
            "pinion_speed",
            setup.limits / setup.scale,
            {"units": "1", "long_name": "highest resolvable order in the bin"},
        ),
    }


def order_map(
    ds: xr.Dataset,
    signals: str | Sequence[str] | None = None,
    orders: Sequence[float] | None = None,
    *,
    revolutions_per_block: int = 8,
    overlap: float = 0.5,
    speed_bins: int | Sequence[float] = 10,
    order_unit: Literal["pinion", "mesh"] = "pinion",
    window: str = "hann",
    z1: int | None = None,
) -> xr.Dataset:
    """Amplitude and phase of order components over speed bins of a run-up or coast-down.

    Parameters
    ----------
    ds : xarray.Dataset
        A record over ``time`` with ``pinion_angle`` or ``pinion_speed`` (see
        :func:`resample_to_angle`), or the result of that function.
    signals : str or sequence of str, optional
        Signals analysed; by default those of :data:`RUNUP_SIGNALS` present.
    orders : sequence of float, optional
        Orders read, in ``order_unit``; by default 1 and the first three mesh
        orders (``z1``, ``2 z1``, ``3 z1`` pinion orders; 1, 2, 3 mesh orders).
    revolutions_per_block : int
        Pinion revolutions per block: the order resolution is 1 / this
        (pinion orders), the speed span of a block grows with it.
    overlap : float
        Fraction of a block shared with the next, in [0, 1).
    speed_bins : int or sequence of float
        Number of equal speed bins over the blocks' speeds, or their edges (rpm).
    order_unit : {"pinion", "mesh"}
        Orders per pinion revolution, or per mesh period (mesh order 1 = z1).
    window : str
        A window of :func:`scipy.signal.get_window`; its coherent gain is divided out.
    z1 : int, optional
        Pinion teeth; by default the Dataset attr ``design_z1`` (or ``z1``).

    Returns
    -------
    xarray.Dataset
        ``order_amplitude`` (signal units, single-sided: ``A cos(k theta +
        phi)`` reads ``A``) and ``order_phase`` (rad, ``phi``, the absolute
        pinion angle as reference), dims ``(signal, pinion_speed, order)``,
        ``pinion_speed`` the bin centres (rpm) with ``bin_lower`` and
        ``bin_upper``; NaN in an empty bin or above the bin's resolvable
        order ``max_order``. Per bin also ``block_count`` and ``mean_speed``
        (rpm, of its blocks). Each signal's units are in the coord
        ``signal_units``.

    Examples
    --------
    A mesh-order line of 2 um on a 1000 -> 2000 rpm run-up:

    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.order_maps import order_map
    >>> time = np.arange(0.0, 2.0, 1.0 / 20480)
    >>> angle = 2 * np.pi * (1000.0 * time + 250.0 * time**2) / 60.0
    >>> te = 2e-6 * np.cos(21 * angle + 0.5)
    >>> ds = xr.Dataset({"pinion_angle": ("time", angle), "te": ("time", te, {"units": "m"})},
    ...                 coords={"time": time}, attrs={"design_z1": 21})
    >>> result = order_map(ds, "te", [1.0], order_unit="mesh", speed_bins=[1000, 1500, 2000])
    >>> (result["order_amplitude"].sel(signal="te", order=1.0) * 1e6).round(4).values
    array([2., 2.])
    >>> result["order_phase"].sel(signal="te", order=1.0).round(4).values
    array([0.5, 0.5])
    """
    options = {
        "revolutions_per_block": revolutions_per_block,
        "overlap": overlap,
        "speed_bins": speed_bins,
        "order_unit": order_unit,
        "window": window,
        "z1": z1,
    }
    setup = _setup(ds, signals, options, "order_map")
    if orders is None:
        if setup.mesh_order is None:
            raise OrderTrackingError("orders: no default without z1 (attr 'design_z1'); name the orders")
        orders = [1.0 / setup.scale, *(float(setup.mesh_order * k) / setup.scale for k in (1, 2, 3))]
    shown = np.asarray(orders, dtype=float)
    if shown.ndim != 1 or shown.size == 0 or not np.all(np.isfinite(shown)) or np.any(shown <= 0.0):
        raise OrderTrackingError(f"orders: expected positive finite orders; got {orders!r}")
    pinion_orders = shown * setup.scale
    n_bins = setup.edges.size - 1
    amplitude_sum = np.zeros((len(setup.names), n_bins, shown.size))
    phasor_sum = np.zeros_like(amplitude_sum, dtype=complex)
    angle = np.asarray(setup.tracked["angle"].values)
    gain = 2.0 / setup.taper.sum()
    for block, index in zip(setup.blocks, setup.bins, strict=True):
        if index < 0:
            continue
        basis = np.exp(-1j * np.outer(angle[block.start : block.stop], pinion_orders))
        projection = gain * (_block_values(setup, block) @ basis)
        amplitude_sum[:, index] += np.abs(projection)
        with np.errstate(invalid="ignore", divide="ignore"):
            phasor_sum[:, index] += np.where(projection != 0.0, projection / np.abs(projection), 0.0)
    summaries = _bin_summaries(setup)
    counts = summaries["block_count"][1]
    with np.errstate(invalid="ignore", divide="ignore"):
        amplitude = amplitude_sum / counts[None, :, None]
    phase = np.angle(phasor_sum)
    unresolved = ~(pinion_orders[None, :] <= setup.limits[:, None]) | (counts[:, None] == 0)
    amplitude[:, unresolved] = np.nan
    phase[:, unresolved] = np.nan
    shared, _ = _units(setup)
    dims = ("signal", "pinion_speed", "order")
    data = {
        "order_amplitude": (dims, amplitude, {"units": shared, "long_name": "single-sided amplitude of the order"}),
        "order_phase": (dims, phase, {"units": "rad", "long_name": "phase of the order (cos(k theta + phase))"}),
        **summaries,
    }
    return xr.Dataset(data, coords=_result_coords(setup, shown, order_unit), attrs=_result_attrs(setup, options))


def order_spectrum(
    ds: xr.Dataset,
    signals: str | Sequence[str] | None = None,
    *,
    max_order: float | None = None,
    revolutions_per_block: int = 8,
    overlap: float = 0.5,
    speed_bins: int | Sequence[float] = 10,
    order_unit: Literal["pinion", "mesh"] = "pinion",
    window: str = "hann",
    z1: int | None = None,
) -> xr.Dataset:
    """Order spectra over speed bins on a continuous order axis: the waterfall of a run-up.

    Each block's windowed FFT over its whole revolutions gives order bins
    ``1 / revolutions_per_block`` pinion orders apart; a speed bin holds the
    mean amplitude of its blocks. Amplitudes are single-sided and
    window-corrected (exact for a line on an order bin, low by up to the
    window's scalloping loss between bins: use :func:`order_map` at the
    exact orders for values).

    Parameters
    ----------
    ds, signals, revolutions_per_block, overlap, speed_bins, order_unit, window, z1
        As in :func:`order_map`.
    max_order : float, optional
        Highest order kept, in ``order_unit``; by default the highest
        resolvable one (at the lowest speed bin).

    Returns
    -------
    xarray.Dataset
        ``order_spectrum`` (signal units) with dims ``(signal, pinion_speed,
        order)``, NaN above each bin's ``max_order``; ``block_count``,
        ``mean_speed`` and ``max_order`` per bin as in :func:`order_map`.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.order_maps import order_spectrum
    >>> time = np.arange(0.0, 2.0, 1.0 / 20480)
    >>> angle = 2 * np.pi * (1000.0 * time + 250.0 * time**2) / 60.0
    >>> ds = xr.Dataset({"pinion_angle": ("time", angle), "te": ("time", np.cos(21 * angle))},
    ...                 coords={"time": time})
    >>> waterfall = order_spectrum(ds, "te", max_order=50, speed_bins=2)
    >>> peak = waterfall["order_spectrum"].sel(signal="te").idxmax("order")
    >>> peak.values.tolist()
    [21.0, 21.0]
    """
    options = {
        "revolutions_per_block": revolutions_per_block,
        "overlap": overlap,
        "speed_bins": speed_bins,
        "order_unit": order_unit,
        "window": window,
        "z1": z1,
    }
    setup = _setup(ds, signals, options, "order_spectrum")
    # pinion orders, 1 / revolutions_per_block apart: a sample is 1 / S of a revolution
    orders = np.fft.rfftfreq(setup.taper.size, d=1.0 / int(setup.tracked.attrs["samples_per_revolution"]))
    top = np.nanmax(setup.limits)
    if max_order is not None:
        top = min(top, _check_positive("max_order", max_order) * setup.scale)
    kept = orders <= top
    n_bins = setup.edges.size - 1
    total = np.zeros((len(setup.names), n_bins, int(kept.sum())))
    gain = 2.0 / setup.taper.sum()
    for block, index in zip(setup.blocks, setup.bins, strict=True):
        if index >= 0:
            total[:, index] += gain * np.abs(np.fft.rfft(_block_values(setup, block), axis=1)[:, kept])
    summaries = _bin_summaries(setup)
    counts = summaries["block_count"][1]
    with np.errstate(invalid="ignore", divide="ignore"):
        amplitude = total / counts[None, :, None]
    amplitude[:, ~(orders[kept][None, :] <= setup.limits[:, None])] = np.nan
    shared, _ = _units(setup)
    data = {
        "order_spectrum": (
            ("signal", "pinion_speed", "order"),
            amplitude,
            {"units": shared, "long_name": "single-sided order spectrum"},
        ),
        **summaries,
    }
    coords = _result_coords(setup, orders[kept] / setup.scale, order_unit)
    return xr.Dataset(data, coords=coords, attrs=_result_attrs(setup, options))
