"""Features of gear signals per run and channel, for rig data and model output alike.

The signals are steady records at a constant, known mean pinion speed n1 (rpm):
the transmission error ``te`` (m) and the bearing-housing accelerations
``acc_pinion`` and ``acc_gear`` (m s-2), sampled at a uniform rate fs. At
constant speed the pinion angle is ``2 pi n1/60 t``, so resampling a record to
uniform angle changes nothing but the axis: the order of a frequency f is
``f / (n1/60)`` (multiples of one pinion revolution). Mesh order is z1, gear
order is z1/z2.

Features (one value per record):

``mesh{k}``
    Amplitude of the k-th mesh harmonic, order k z1 (family ``mesh_harmonic``).
``mesh{k}_sb_pinion{+j}``, ``mesh{k}_sb_pinion{-j}``
    Sidebands k z1 +- j (family ``sideband_pinion``: pinion-shaft modulation,
    e.g. eccentricity or a damaged pinion tooth).
``mesh{k}_sb_gear{+j}``, ``mesh{k}_sb_gear{-j}``
    Sidebands k z1 +- j z1/z2 (family ``sideband_gear``).
``shaft_pinion{j}``, ``shaft_gear{j}``
    The j-th shaft-order lines, orders j and j z1/z2 (families
    ``shaft_pinion``, ``shaft_gear``): run-out shows at 1x.
``motor_ripple{m}``
    Torque-ripple lines at order 6 p m for a motor with p pole pairs on the
    pinion shaft (family ``motor_line``; only when the design gives p).
``low_band_rms``
    RMS in a fixed frequency band, 2 to 80 Hz by default (family
    ``low_frequency``): adhesion oscillation lives at tens of Hz, not locked
    to any order.
``rms``, ``kurtosis``, ``crest_factor``, ``noise_std``
    Family ``broadband``. ``kurtosis`` is the plain (non-excess) fourth
    standardised moment, 3 for Gaussian noise; ``crest_factor`` is
    max|x| / rms; ``noise_std`` is the standard deviation of white noise whose
    spectral density equals the median spectral floor between the order lines.

Line amplitudes are amplitudes A of ``A cos(2 pi f t + phase)``, in the
channel's units. They come from one joint least-squares fit of all lines of the
feature set at their known frequencies, weighted by the analysis window, so
that lines closer than the window's main lobe (gear sidebands at low speed) do
not leak into each other; content outside the feature set leaks in as through
the window. Lines closer than one frequency bin (1/T for a record of length T)
cannot be told apart: a line within a bin of one earlier in the feature order
(mesh harmonics come first) is not fitted itself and reports that line's
amplitude (e.g. for z1 = 21 and p = 3 the motor line at order 18 is
``mesh1_sb_pinion-3``; at very low speed the gear sidebands merge into their
mesh harmonic). Lines above the usable band (the
band limit, by default fs/2.56, the usual anti-alias bandwidth) or below one
bin (1/T) are NaN.

A record with any NaN sample gives NaN for all its features: it is unusable for
that channel only (docs/rig-data-format.md).

This module does no file I/O and no plotting.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.signal
import xarray as xr
from numpy.typing import ArrayLike

from ..common.errors import DesignError, RigDataError, StudyError
from ..physics.design import Design
from .line_fit import LineFit
from .order_tracking import SPEED_ESTIMATE_VARIABLES, check_tracking_mode, track_orders
from .sampling import DEFAULT_BAND_FRACTION, SIGNAL_CHANNELS, sampling_rate
from .sampling import band_limit_of as _band_limit

#: Feature families, for mapping sim-to-real gaps over op x channel x family.
FEATURE_FAMILIES: tuple[str, ...] = (
    "mesh_harmonic",
    "sideband_pinion",
    "sideband_gear",
    "shaft_pinion",
    "shaft_gear",
    "motor_line",
    "low_frequency",
    "broadband",
)

# Bins on each side of a line that the noise-floor estimate leaves out: the
# Hann main lobe spans +-2 bins, one more keeps its skirt out of the median.
_NOISE_GUARD_BINS = 3

# Samples per float64 working block (records x samples): about 32 MB.
_BLOCK_SAMPLES = 4_000_000


@dataclass(frozen=True)
class FeatureDefinition:
    """One feature: its name, family and, for a spectral line, its order.

    Attributes
    ----------
    name : str
        Feature name, e.g. ``mesh1_sb_pinion+1``.
    family : str
        One of :data:`FEATURE_FAMILIES`.
    order : float
        Order (multiple of the pinion rotation) of a line feature; NaN for band
        and broadband features.
    dimensionless : bool
        True for ratios without units (kurtosis, crest factor); all other
        features carry the channel's units.
    """

    name: str
    family: str
    order: float = math.nan
    dimensionless: bool = False

    @property
    def is_line(self) -> bool:
        """Whether the feature is the amplitude of a spectral line."""
        return not math.isnan(self.order)


def _check_count(name: str, value: object, lowest: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lowest:
        raise StudyError(f"{name}: expected an integer >= {lowest}; got {value!r}")
    return int(value)


def feature_definitions(
    design: Design, *, n_harmonics: int = 3, n_sidebands: int = 3, n_shaft_orders: int = 3, n_motor_lines: int = 2
) -> tuple[FeatureDefinition, ...]:
    """The feature set for a design, in output order.

    Parameters
    ----------
    design : Design
        Gives z1, z2 and, optionally, ``motor_pole_pairs``.
    n_harmonics : int
        Mesh harmonics k = 1..n_harmonics.
    n_sidebands : int
        Sidebands j = 1..n_sidebands on each side of each mesh harmonic, per
        shaft. Must be below z1 so that every sideband has a positive order.
    n_shaft_orders : int
        Shaft-order lines j = 1..n_shaft_orders per shaft (0 for none).
    n_motor_lines : int
        Torque-ripple lines m = 1..n_motor_lines at order 6 p m (0 for none;
        none either when the design has no ``motor_pole_pairs``).

    Returns
    -------
    tuple of FeatureDefinition

    Raises
    ------
    DesignError
        ``design`` is not a :class:`~uqgear.physics.design.Design`.
    StudyError
        A count is not an integer in range.
    """
    if not isinstance(design, Design):
        raise DesignError(
            f"design: expected a uqgear Design (see uqgear.physics.design.load_design); got {type(design).__name__}"
        )
    n_harmonics = _check_count("n_harmonics", n_harmonics, 1)
    n_sidebands = _check_count("n_sidebands", n_sidebands, 0)
    n_shaft_orders = _check_count("n_shaft_orders", n_shaft_orders, 0)
    n_motor_lines = _check_count("n_motor_lines", n_motor_lines, 0)
    if n_sidebands >= design.z1:
        raise StudyError(
            f"n_sidebands: expected fewer than z1 = {design.z1} so that every sideband "
            f"order is positive; got {n_sidebands}"
        )
    gear_order = design.z1 / design.z2
    definitions: list[FeatureDefinition] = []
    for k in range(1, n_harmonics + 1):
        mesh_order = float(k * design.z1)
        definitions.append(FeatureDefinition(f"mesh{k}", "mesh_harmonic", mesh_order))
        for shaft, spacing in (("pinion", 1.0), ("gear", gear_order)):
            for j in range(1, n_sidebands + 1):
                for sign, symbol in ((+1, "+"), (-1, "-")):
                    definitions.append(
                        FeatureDefinition(
                            f"mesh{k}_sb_{shaft}{symbol}{j}", f"sideband_{shaft}", mesh_order + sign * j * spacing
                        )
                    )
    for shaft, spacing in (("pinion", 1.0), ("gear", gear_order)):
        for j in range(1, n_shaft_orders + 1):
            definitions.append(FeatureDefinition(f"shaft_{shaft}{j}", f"shaft_{shaft}", j * spacing))
    if design.motor_pole_pairs is not None:
        for m in range(1, n_motor_lines + 1):
            definitions.append(
                FeatureDefinition(f"motor_ripple{m}", "motor_line", float(6 * design.motor_pole_pairs * m))
            )
    definitions.append(FeatureDefinition("low_band_rms", "low_frequency"))
    definitions.append(FeatureDefinition("rms", "broadband"))
    definitions.append(FeatureDefinition("kurtosis", "broadband", dimensionless=True))
    definitions.append(FeatureDefinition("crest_factor", "broadband", dimensionless=True))
    definitions.append(FeatureDefinition("noise_std", "broadband"))
    return tuple(definitions)


def analysis_window(name: str, size: int) -> np.ndarray:
    try:
        return scipy.signal.get_window(name, size, fftbins=True)
    except (ValueError, TypeError) as exc:
        raise StudyError(f"window: expected a scipy.signal window name such as 'hann'; got {name!r} ({exc})") from None


def _check_speeds(speeds: np.ndarray, where: str) -> None:
    if not np.all(np.isfinite(speeds)) or np.any(speeds <= 0):
        raise RigDataError(f"{where}pinion_speed: expected finite speeds > 0 rpm; got {speeds.ravel()[:8]}")


def _prepare(
    signal: xr.DataArray, pinion_speed: float | xr.DataArray, where: str
) -> tuple[xr.DataArray, np.ndarray, np.ndarray, float]:
    """Records as (R, N) in their own dtype with matching speeds (R,), and fs."""
    if not isinstance(signal, xr.DataArray) or "time" not in signal.dims:
        raise RigDataError(
            f"{where}expected a DataArray with a 'time' dimension; got {getattr(signal, 'dims', type(signal).__name__)}"
        )
    if "time" not in signal.coords:
        raise RigDataError(f"{where}time: missing coordinate (sample instants in s)")
    fs = sampling_rate(signal["time"].values, where=f"{where}time")
    signal = signal.transpose(..., "time")
    template = signal.isel(time=0, drop=True)
    speed = xr.DataArray(pinion_speed) if not isinstance(pinion_speed, xr.DataArray) else pinion_speed
    extra = set(speed.dims) - set(template.dims)
    if extra:
        raise RigDataError(
            f"{where}pinion_speed: dimensions {sorted(extra, key=str)} are not dimensions of the signal {template.dims}"
        )
    speeds = np.asarray(speed.broadcast_like(template).transpose(*template.dims).values, dtype=float).ravel()
    _check_speeds(speeds, where)
    records = np.asarray(signal.values).reshape(-1, signal.sizes["time"])
    if not np.issubdtype(records.dtype, np.number):
        raise RigDataError(f"{where}expected numeric samples; got dtype {records.dtype}")
    return template, records, speeds, fs


def order_spectrum(
    signal: xr.DataArray,
    pinion_speed: float | xr.DataArray,
    *,
    orders: ArrayLike | None = None,
    window: str = "hann",
    padding: int = 4,
) -> xr.DataArray:
    """Amplitude spectrum against order (multiples of the pinion rotation).

    Each record (mean removed) is windowed and Fourier transformed with
    ``padding``-fold zero padding; amplitudes are scaled by 2 / sum(window), so
    a line ``A cos(...)`` at a bin reads A. At constant speed, uniform pinion
    angle is uniform time with the order axis ``f / (n1/60)``; records at
    different speeds are interpolated onto one common order grid.

    Parameters
    ----------
    signal : xarray.DataArray
        Records with a ``time`` dimension (and a ``time`` coordinate in s).
    pinion_speed : float or xarray.DataArray
        Mean pinion speed in rpm, over the signal's other dimensions.
    orders : array_like, optional
        Orders to evaluate at. By default from 0 to the Nyquist order of the
        fastest record, in steps of the finest padded bin of all records.
    window : str
        A :func:`scipy.signal.get_window` name.
    padding : int
        Zero-padding factor (>= 1) of the FFT, which makes the spectrum
        smooth enough to interpolate.

    Returns
    -------
    xarray.DataArray
        Dimensions of the signal with ``time`` replaced by ``order``; NaN above
        a record's Nyquist order or where the record has NaN samples.
    """
    padding = _check_count("padding", padding, 1)
    template, records, speeds, fs = _prepare(signal, pinion_speed, "")
    size = records.shape[1]
    taper = analysis_window(window, size)
    shaft_frequency = speeds / 60.0
    if orders is None:
        step = fs / (size * padding) / shaft_frequency.max()
        grid = np.arange(0.0, 0.5 * fs / shaft_frequency.max() + 0.5 * step, step)
    else:
        grid = np.asarray(orders, dtype=float).ravel()
        if grid.size == 0 or not np.all(np.isfinite(grid)) or np.any(grid < 0):
            raise StudyError(f"orders: expected finite orders >= 0; got {grid}")
    frequencies = np.fft.rfftfreq(size * padding, 1.0 / fs)
    spectra = np.full((records.shape[0], grid.size), np.nan)
    usable = ~np.isnan(records).any(axis=1)
    if usable.any():
        chosen = records[usable].astype(float)
        centred = chosen - chosen.mean(axis=1, keepdims=True)
        amplitude = np.abs(np.fft.rfft(centred * taper, n=size * padding, axis=1)) * (2.0 / taper.sum())
        amplitude[:, 0] *= 0.5
        for row, index in enumerate(np.flatnonzero(usable)):
            spectra[index] = np.interp(grid, frequencies / shaft_frequency[index], amplitude[row], right=np.nan)
    result = xr.DataArray(
        spectra.reshape(template.shape + (grid.size,)), dims=template.dims + ("order",), coords=template.coords
    ).assign_coords(order=grid)
    result["order"].attrs.update(units="1", long_name="order (multiples of the pinion rotation)")
    result.attrs.update(units=signal.attrs.get("units", ""), long_name="amplitude spectrum", window=window)
    return result


def _blocks(rows: np.ndarray, size: int) -> list[np.ndarray]:
    """Row indices in blocks that bound the float64 working copies."""
    records_per_block = max(1, _BLOCK_SAMPLES // size)
    return [rows[start : start + records_per_block] for start in range(0, rows.size, records_per_block)]


def line_amplitudes(
    signal: xr.DataArray,
    pinion_speed: float | xr.DataArray,
    orders: ArrayLike,
    *,
    window: str = "hann",
    band_limit: float | None = None,
) -> xr.DataArray:
    """Amplitudes of spectral lines at known orders.

    Parameters
    ----------
    signal : xarray.DataArray
        Records with a ``time`` dimension (and a ``time`` coordinate in s).
    pinion_speed : float or xarray.DataArray
        Mean pinion speed in rpm, over the signal's other dimensions.
    orders : array_like
        Positive line orders.
    window : str
        Weighting of the least-squares fit (:func:`scipy.signal.get_window` name).
    band_limit : float, optional
        Lines above this frequency in Hz are NaN; default fs/2.56.

    Returns
    -------
    xarray.DataArray
        Dimensions of the signal with ``time`` replaced by ``order``.
    """
    order_values = np.asarray(orders, dtype=float).ravel()
    if order_values.size == 0 or not np.all(np.isfinite(order_values)) or np.any(order_values <= 0):
        raise StudyError(f"orders: expected finite positive orders; got {order_values}")
    template, records, speeds, fs = _prepare(signal, pinion_speed, "")
    limit = _band_limit(band_limit, fs)
    taper = analysis_window(window, records.shape[1])
    amplitudes = _lines_by_speed(records, speeds, order_values, fs, limit, taper)
    result = xr.DataArray(
        amplitudes.reshape(template.shape + (order_values.size,)),
        dims=template.dims + ("order",),
        coords=template.coords,
    ).assign_coords(order=order_values)
    result.attrs.update(units=signal.attrs.get("units", ""), long_name="line amplitude", window=window)
    return result


def _lines_by_speed(
    records: np.ndarray, speeds: np.ndarray, orders: np.ndarray, fs: float, limit: float, taper: np.ndarray
) -> np.ndarray:
    """Line amplitudes (R, L); records sharing a speed share one fit; NaN rows where a sample is NaN."""
    amplitudes = np.full((records.shape[0], orders.size), np.nan)
    for speed in np.unique(speeds):
        fit = LineFit(orders * speed / 60.0, fs, records.shape[1], limit, taper)
        for block in _blocks(np.flatnonzero(speeds == speed), records.shape[1]):
            chunk = records[block].astype(float)
            usable = ~np.isnan(chunk).any(axis=1)
            amplitudes[block[usable]] = fit.amplitudes(chunk[usable])
    return amplitudes


def _noise_std(periodogram: np.ndarray, fs: float, excluded: np.ndarray) -> float:
    """Std of white noise whose density is the median floor of the kept bins.

    A periodogram bin of Gaussian noise is exponentially distributed about the
    true density, whose median is ln 2 times its mean.
    """
    kept = periodogram[~excluded]
    if kept.size == 0:
        return math.nan
    density = float(np.median(kept)) / math.log(2.0)
    return math.sqrt(density * 0.5 * fs)


def excluded_bins(
    frequencies: np.ndarray,
    speed: float,
    design: Design,
    line_orders: np.ndarray,
    n_sidebands: int,
    low_band: tuple[float, float],
    limit: float,
    resolution: float,
) -> np.ndarray:
    """Periodogram bins that the noise floor must not use: lines, low band, beyond the band."""
    shaft_frequency = speed / 60.0
    gear_order = design.z1 / design.z2
    guard = _NOISE_GUARD_BINS * resolution
    centres = [line_orders * shaft_frequency]
    # Tooth damage and run-out spread lines over every pinion order; leave them
    # out too, unless they are so dense (low speed, short record) that no bin
    # between them would remain.
    if shaft_frequency > 2 * guard + 2 * resolution:
        centres.append(np.arange(1, limit / shaft_frequency + 1) * shaft_frequency)
    # all mesh harmonics in the band with their gear sidebands, not just those in the feature set
    mesh_orders = np.arange(1, limit / (design.z1 * shaft_frequency) + 1) * design.z1
    offsets = np.arange(-n_sidebands, n_sidebands + 1) * gear_order
    centres.append((mesh_orders[:, None] + offsets[None, :]).ravel() * shaft_frequency)
    lines = np.sort(np.concatenate(centres))
    nearest = np.searchsorted(lines, frequencies)
    distance_above = np.abs(lines[np.clip(nearest, 0, lines.size - 1)] - frequencies)
    distance_below = np.abs(lines[np.clip(nearest - 1, 0, lines.size - 1)] - frequencies)
    near_line = np.minimum(distance_above, distance_below) <= guard
    return near_line | (frequencies <= low_band[1]) | (frequencies > limit)


def _check_low_band(low_band: tuple[float, float], fs: float) -> tuple[float, float]:
    if (
        not isinstance(low_band, (tuple, list))
        or len(low_band) != 2
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in low_band)
        or not 0 <= low_band[0] < low_band[1] <= 0.5 * fs
    ):
        raise StudyError(
            f"low_band: expected (lower, upper) in Hz with 0 <= lower < upper <= fs/2 = {0.5 * fs:g}; got {low_band!r}"
        )
    return float(low_band[0]), float(low_band[1])


def block_features(
    records: np.ndarray,
    fit: LineFit,
    excluded: np.ndarray,
    fs: float,
    taper: np.ndarray,
    low_band: tuple[float, float],
    columns: dict[str, int],
    line_columns: np.ndarray,
    n_features: int,
    *,
    lines: bool = True,
) -> np.ndarray:
    """Feature values (R, F) of float64 records (R, N) without NaN, all at one speed.

    With ``lines`` False the line columns are left NaN (a caller that fits
    the lines' phasors itself saves the second least-squares solve).
    """
    values = np.full((records.shape[0], n_features), np.nan)
    if lines:
        values[:, line_columns] = fit.amplitudes(records)
    centred = records - records.mean(axis=1, keepdims=True)
    frequencies, density = scipy.signal.periodogram(centred, fs, window=taper, detrend=False, scaling="density", axis=1)
    resolution = fs / records.shape[1]
    in_low_band = (frequencies >= low_band[0]) & (frequencies <= low_band[1])
    values[:, columns["low_band_rms"]] = np.sqrt(density[:, in_low_band].sum(axis=1) * resolution)
    square = centred * centred
    mean_square = np.mean(square, axis=1)
    rms = np.sqrt(mean_square)
    values[:, columns["rms"]] = rms
    with np.errstate(divide="ignore", invalid="ignore"):
        # a constant record has no defined shape: leave NaN rather than warn. The fourth power as a
        # square of squares: numpy's x**4 calls pow() per sample, 80 times slower (measured), and
        # this runs for every model run of a diagnosis
        values[:, columns["kurtosis"]] = np.where(
            mean_square > 0, np.mean(square * square, axis=1) / mean_square**2, np.nan
        )
        values[:, columns["crest_factor"]] = np.where(rms > 0, np.max(np.abs(centred), axis=1) / rms, np.nan)
    values[:, columns["noise_std"]] = [_noise_std(row, fs, excluded) for row in density]
    return values


def _record_features(
    channel_records: Sequence[np.ndarray],
    channel_speeds: Sequence[np.ndarray],
    fs: float,
    design: Design,
    definitions: Sequence[FeatureDefinition],
    *,
    n_sidebands: int,
    low_band: tuple[float, float],
    limit: float,
    window: str,
) -> list[np.ndarray]:
    """Feature values (R_c, F) per channel of records (R_c, N) at pinion speeds (R_c,) in rpm.

    Work goes speed by speed, so that every channel and sample at one speed
    shares one line fit, and block by block, so that float64 working copies
    stay small whatever the batch size.
    """
    size = channel_records[0].shape[1]
    taper = analysis_window(window, size)
    columns = {definition.name: index for index, definition in enumerate(definitions)}
    line_columns = np.array([index for index, definition in enumerate(definitions) if definition.is_line], dtype=int)
    line_orders = np.array([definitions[index].order for index in line_columns])
    frequencies = np.fft.rfftfreq(size, 1.0 / fs)
    outputs = [np.full((records.shape[0], len(definitions)), np.nan) for records in channel_records]
    for speed in np.unique(np.concatenate(channel_speeds)):
        fit = LineFit(line_orders * speed / 60.0, fs, size, limit, taper)
        excluded = excluded_bins(
            frequencies, float(speed), design, line_orders, n_sidebands, low_band, limit, fs / size
        )
        for records, speeds, output in zip(channel_records, channel_speeds, outputs):
            for block in _blocks(np.flatnonzero(speeds == speed), size):
                chunk = records[block].astype(float)
                usable = ~np.isnan(chunk).any(axis=1)
                if usable.any():
                    output[block[usable]] = block_features(
                        chunk[usable], fit, excluded, fs, taper, low_band, columns, line_columns, len(definitions)
                    )
    return outputs


def _checked_channels(signals: xr.Dataset, channels: Sequence[str] | None, where: str) -> list[str]:
    """The channels to read (default: every rig channel present), each over time, and a mean speed per run."""
    if channels is None:
        channels = [name for name in SIGNAL_CHANNELS if name in signals.data_vars]
        if not channels:
            raise RigDataError(f"{where}no channel variable; expected at least one of {', '.join(SIGNAL_CHANNELS)}")
    else:
        channels = list(channels)
        if not channels:
            raise StudyError("channels: expected at least one channel name; got none")
    for name in channels:
        if name not in signals.data_vars:
            present = ", ".join(map(str, signals.data_vars))
            raise RigDataError(f"{where}{name}: no such channel variable; present: {present}")
        if "time" not in signals[name].dims:
            raise RigDataError(f"{where}{name}: expected a 'time' dimension; got dims {signals[name].dims}")
    if "pinion_speed" not in signals.variables:
        raise RigDataError(f"{where}pinion_speed: missing (mean pinion speed in rpm over the runs)")
    speed = signals["pinion_speed"]
    if "time" in speed.dims:
        raise RigDataError(
            f"{where}pinion_speed: expected the mean speed per run, without a 'time' dimension; got dims {speed.dims}"
        )
    return channels


def _feature_dataset(signals: xr.Dataset, channels: Sequence[str], templates: Sequence[xr.DataArray],
                     values: Sequence[np.ndarray], definitions: Sequence[FeatureDefinition]) -> xr.Dataset:
    """Each channel's features over its run dims and ``feature``, with each line's family, order and frequency."""
    outputs: dict[str, xr.DataArray] = {}
    for name, template, block in zip(channels, templates, values):
        units = signals[name].attrs.get("units", SIGNAL_CHANNELS.get(name, ("", ""))[0])
        outputs[name] = xr.DataArray(
            block.reshape(template.shape + (len(definitions),)),
            dims=template.dims + ("feature",),
            coords=template.coords,
            attrs={
                "units": units,
                "long_name": f"features of {name}",
                "note": "features with dimensionless=True are ratios without units",
            },
        )

    orders = xr.DataArray(
        [definition.order for definition in definitions],
        dims="feature",
        attrs={"units": "1", "long_name": "line order (multiples of the pinion rotation)"},
    )
    features = xr.Dataset(outputs).assign_coords(
        feature=[definition.name for definition in definitions],
        family=("feature", [definition.family for definition in definitions], {"long_name": "feature family"}),
        order=orders,
        dimensionless=(
            "feature",
            [definition.dimensionless for definition in definitions],
            {"long_name": "feature is a ratio without units"},
        ),
    )
    return features.assign_coords(
        frequency=(signals["pinion_speed"] / 60.0 * orders).assign_attrs(units="Hz", long_name="line frequency")
    )


def extract_features(
    signals: xr.Dataset,
    design: Design,
    *,
    channels: Sequence[str] | None = None,
    n_harmonics: int = 3,
    n_sidebands: int = 3,
    n_shaft_orders: int = 3,
    n_motor_lines: int = 2,
    low_band: tuple[float, float] = (2.0, 80.0),
    band_limit: float | None = None,
    window: str = "hann",
    order_tracking: str = "auto",
) -> xr.Dataset:
    """Features of every record and channel (see the module docstring for the list).

    Parameters
    ----------
    signals : xarray.Dataset
        Channel variables (``te``, ``acc_pinion``, ``acc_gear`` or a subset)
        with a ``time`` dimension and coordinate (s, uniform), typically dims
        ``(op, time)``; any further dimensions (``sample``, ...) are kept. The
        mean pinion speed in rpm is the ``pinion_speed`` coordinate or variable
        over the non-time dimensions. Rig files and model output share this
        layout; nothing rig-specific is used.
    design : Design
        Gives z1, z2 and the optional ``motor_pole_pairs``.
    channels : sequence of str, optional
        Channels to analyse; by default those of :data:`SIGNAL_CHANNELS` present.
    n_harmonics, n_sidebands, n_shaft_orders, n_motor_lines : int
        Sizes of the feature set (:func:`feature_definitions`).
    low_band : (float, float)
        Band of ``low_band_rms`` in Hz.
    band_limit : float, optional
        Highest usable frequency in Hz: lines above it are NaN and the noise
        floor is taken below it. Default fs/2.56.
    window : str
        Analysis window (:func:`scipy.signal.get_window` name).
    order_tracking : {"auto", "always", "never"}
        Resampling of the records to uniform pinion angle before the features
        are read (:func:`uqgear.rig.order_tracking.track_orders`; ``auto``
        where the speed wanders enough to matter). Signals that already went
        through :func:`~uqgear.rig.order_tracking.track_orders` are used as
        they are.

    Returns
    -------
    xarray.Dataset
        One variable per channel with the signal's dimensions, ``time``
        replaced by ``feature``; ``attrs["units"]`` is the channel's unit, which
        every feature carries except those with ``dimensionless`` True.
        Coordinates along ``feature``: ``family``, ``order`` (NaN for non-line
        features), ``dimensionless``; ``frequency`` (Hz) over the speed's
        dimensions and ``feature``. Over the speed's dimensions the speed
        estimate of the order tracking: ``speed_mean``, ``speed_min``,
        ``speed_max`` (rpm), ``order_tracked`` and ``pinion_speed_stated``.

    Raises
    ------
    RigDataError
        A channel is missing or has no time dimension, the time axis is not
        uniform, or a speed is not positive.
    StudyError
        An option is out of range.

    Examples
    --------
    The transmission error of a virtual campaign with a clean rig and with an
    eccentric pinion (50 um): the mesh line sits at z1 n1 / 60, and the
    eccentricity raises the sidebands at the pinion's shaft order around it
    from numerical noise to a visible line:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> runs = {"pinion_speed": [1500.0, 3000.0], "drive_torque": [7000.0, 5000.0]}
    >>> clean = uqgear.simulate_campaign(design, runs, duration=0.25, run_in=0.05, seed=7, relative_noise=0.0)
    >>> eccentric = uqgear.simulate_campaign(design, runs, duration=0.25, run_in=0.05, seed=7, relative_noise=0.0,
    ...                                      effects=[uqgear.make_effect("eccentricity", {"amplitude": 50e-6})])
    >>> features = uqgear.extract_features(clean, design, channels=["te"])
    >>> features["frequency"].sel(feature="mesh1").values.tolist()
    [525.0, 1050.0]
    >>> (features["te"].sel(feature="mesh1") * 1e6).round(2).values        # um
    array([3.42, 4.07])
    >>> sideband = "mesh1_sb_pinion+1"
    >>> with_eccentricity = uqgear.extract_features(eccentric, design, channels=["te"])["te"].sel(feature=sideband)
    >>> bool((with_eccentricity > 1000 * features["te"].sel(feature=sideband)).all())
    True
    """
    where = "signals: "
    order_tracking = check_tracking_mode(order_tracking)
    if not isinstance(signals, xr.Dataset):
        raise RigDataError(f"{where}expected an xarray Dataset of channel variables; got {type(signals).__name__}")
    channels = _checked_channels(signals, channels, where)
    speed = signals["pinion_speed"]
    definitions = feature_definitions(
        design,
        n_harmonics=n_harmonics,
        n_sidebands=n_sidebands,
        n_shaft_orders=n_shaft_orders,
        n_motor_lines=n_motor_lines,
    )
    analysis_window(window, 8)

    prepared = [_prepare(signals[name], speed, f"{where}{name}: ") for name in channels]
    fs = prepared[0][3]
    for name, (_, _, _, rate) in zip(channels, prepared):
        if rate != fs:
            raise RigDataError(f"{where}{name}: sampling rate {rate:g} Hz differs from {fs:g} Hz of {channels[0]}")
    limit = _band_limit(band_limit, fs)
    band = _check_low_band(low_band, fs)
    if order_tracking != "never" and "order_tracked" not in signals.variables:
        # after the checks above, so that a wrong input is named as the features name it
        signals = track_orders(
            signals, design, mode=order_tracking, channels=channels, band_limit=limit, n_harmonics=n_harmonics
        )
        speed = signals["pinion_speed"]
        if bool(np.any(signals["order_tracked"].values)):
            prepared = [_prepare(signals[name], speed, f"{where}{name}: ") for name in channels]
    values = _record_features(
        [records for _, records, _, _ in prepared],
        [speeds for _, _, speeds, _ in prepared],
        fs,
        design,
        definitions,
        n_sidebands=n_sidebands,
        low_band=band,
        limit=limit,
        window=window,
    )
    features = _feature_dataset(signals, channels, [template for template, _, _, _ in prepared], values, definitions)
    if "order_tracked" in signals.variables:
        features = features.assign_coords({name: signals[name] for name in SPEED_ESTIMATE_VARIABLES})
    features.attrs.update(
        window=window,
        low_band=list(band),
        band_limit=limit,
        order_tracking=signals.attrs.get("order_tracking", "never"),
        sampling_rate=fs,
        n_harmonics=n_harmonics,
        n_sidebands=n_sidebands,
        n_shaft_orders=n_shaft_orders,
        n_motor_lines=n_motor_lines if design.motor_pole_pairs is not None else 0,
        z1=design.z1,
        z2=design.z2,
    )
    return features


__all__ = [
    "SIGNAL_CHANNELS",
    "FEATURE_FAMILIES",
    "DEFAULT_BAND_FRACTION",
    "FeatureDefinition",
    "feature_definitions",
    "sampling_rate",
    "order_spectrum",
    "line_amplitudes",
    "extract_features",
    "analysis_window",
    "LineFit",
    "excluded_bins",
    "block_features",
]
