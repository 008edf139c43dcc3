"""Order maps of run-ups and coast-downs over speed bins, and their waterfall.

The record, resampled to uniform pinion angle
(:func:`~uqgear.dynamics.angle_resampling.resample_to_angle`, which states
the anti-aliasing), is cut into blocks of a whole number of revolutions
(overlapping), each windowed and projected on ``exp(-i k theta)`` at the
requested orders, with the absolute pinion angle as phase reference: a
component ``A cos(k theta + phi)`` reads amplitude ``A`` (the window's
coherent gain divided out) and phase ``phi`` (:func:`order_map`). Blocks are
binned by their window-weighted mean speed, so a component whose amplitude is
linear in speed reads its value at the bin's mean block speed; a bin holds
the mean amplitude and the circular mean phase of its blocks, NaN for the
orders above the resolvable one at the top speed of any of its blocks.
:func:`order_spectrum` gives the same over a continuous order axis (the
classic waterfall) for plotting.

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

from ._checks import check_positive
from .angle_resampling import RESOLVABLE_FRACTION, OrderTrackingError, angle_record

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


def speed_bin_index(speeds: Any, edges: np.ndarray) -> np.ndarray:
    """Bin of each speed (-1 outside the edges; the top edge belongs to the last bin).

    ``edges`` are those of :func:`speed_bin_edges` (rpm); order maps and ramp envelopes bin alike.
    """
    values = np.asarray(speeds, dtype=float)
    index = np.searchsorted(edges, values, side="right") - 1
    index[values == edges[-1]] = edges.size - 2
    index[(values < edges[0]) | (values > edges[-1])] = -1
    return index


def speed_bin_coords(edges: np.ndarray) -> dict[str, xr.Variable]:
    """``pinion_speed`` (bin centres) with ``bin_lower`` and ``bin_upper`` alongside, all rpm.

    The speed coordinates of every result binned on ``edges`` (:func:`speed_bin_edges`).
    """
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
    tracked, names = angle_record(ds, signals, what)
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
    bins = speed_bin_index([block.mean_speed for block in blocks], edges)
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
        **speed_bin_coords(setup.edges),
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
        top = min(top, check_positive("max_order", max_order) * setup.scale)
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
