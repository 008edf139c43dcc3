"""Figures of run-ups and coast-downs: the order map over speed, and the up and down envelopes."""

from __future__ import annotations

import numpy as np
import xarray as xr
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from ..common.errors import UqgearError
from .page import figure_png, new_figure
from .presentation import LINE_STYLES, axis_label, display

#: Dynamic range of an order map's colour scale: floored this many dB below its peak.
ORDER_MAP_RANGE_DB = 60.0


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around increasing centres (half-way between them, mirrored at the ends)."""
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    middle = 0.5 * (centres[:-1] + centres[1:])
    return np.concatenate([[2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]])


def _map_variable(result: xr.Dataset) -> str:
    for name in ("order_spectrum", "order_amplitude"):
        if isinstance(result, xr.Dataset) and name in result.data_vars:
            return name
    raise UqgearError("order_map: expected an order_spectrum() or order_map() result (variable 'order_spectrum')")


def _draw_order_map(ax: Axes, figure: Figure, result: xr.Dataset, signal: str, range_db: float) -> None:
    """Speed x order cells coloured by amplitude in dB below the map's peak; blank above the resolvable order."""
    name = _map_variable(result)
    if signal not in result["signal"].values:
        raise UqgearError(f"signal: the order map has no signal {signal!r}; it has {list(result['signal'].values)}")
    amplitude = np.asarray(result[name].sel(signal=signal).transpose("pinion_speed", "order").values, dtype=float)
    finite = amplitude[np.isfinite(amplitude) & (amplitude > 0.0)]
    peak = float(finite.max()) if finite.size else 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        level = 20.0 * np.log10(amplitude / peak)
    level = np.where(np.isfinite(amplitude), np.maximum(level, -range_db), np.nan)
    speed_edges = np.append(result["bin_lower"].values, result["bin_upper"].values[-1])
    orders = np.asarray(result["order"].values, dtype=float)
    # a few irregular orders get a row each; evenly spaced ones (a study's half orders) sit on an order axis
    steps = np.diff(orders)
    discrete = name == "order_amplitude" and orders.size > 1 and not np.allclose(steps, steps[0])
    rows = _edges(np.arange(orders.size, dtype=float)) if discrete else _edges(orders)
    mesh = ax.pcolormesh(speed_edges, rows, np.ma.masked_invalid(level.T), cmap="magma", vmin=-range_db, vmax=0.0)
    units = str(result[name].attrs.get("units", ""))
    if "signal_units" in result.coords:
        units = str(result["signal_units"].sel(signal=signal).values)
    figure.colorbar(mesh, ax=ax, label=f"amplitude [dB re peak {peak:.3g} {units}]")
    unit = str(result.attrs.get("order_unit", "pinion"))
    if discrete:
        ax.set_yticks(np.arange(orders.size), [f"{order:g}" for order in orders])
    elif unit == "pinion" and ("mesh_order" in result.attrs or "design_z1" in result.attrs):
        z1 = float(result.attrs["mesh_order"] if "mesh_order" in result.attrs else result.attrs["design_z1"])
        for harmonic in np.arange(z1, orders[-1] + 1e-9, z1):
            ax.axhline(harmonic, color="white", linestyle=":", linewidth=0.6)
    ax.set_xlabel(axis_label("pinion_speed"))
    ax.set_ylabel("mesh order" if unit == "mesh" else "pinion order")
    ax.set_title(
        f"order map of {signal} (blank: above the resolvable order or no block; dotted: mesh harmonics)", fontsize=9
    )


def _draw_envelopes(ax: Axes, envelopes: xr.Dataset) -> None:
    """Peak per speed bin of each run direction, hysteresis ranges shaded."""
    signal = str(envelopes.attrs.get("signal", "mesh_force"))
    name = f"peak_{signal}"
    if name not in envelopes.data_vars or "direction" not in envelopes[name].dims:
        raise UqgearError(f"envelopes: expected an up_down_envelopes() result holding {name!r} over 'direction'")
    _, _, factor = display(name)
    speed = np.asarray(envelopes["pinion_speed"].values, dtype=float)
    for index, direction in enumerate(envelopes["direction"].values):
        values = np.asarray(envelopes[name].sel(direction=direction).values, dtype=float) * factor
        ax.plot(
            speed,
            values,
            color="black",
            linestyle=LINE_STYLES[index],
            marker=".",
            drawstyle="steps-mid",
            label=f"{direction}",
        )
    for low, high in zip(
        envelopes.attrs.get("hysteresis_ranges", [])[::2],
        envelopes.attrs.get("hysteresis_ranges", [])[1::2],
        strict=True,
    ):
        ax.axvspan(low, high, color="0.85", zorder=0)
    ax.set_xlabel(axis_label("pinion_speed"))
    ax.set_ylabel(axis_label(name))
    ax.legend(fontsize=8, title="run", title_fontsize=8)
    ax.set_title("peak per speed bin, run-up and coast-down (shaded: they differ)", fontsize=9)


def order_map_figure(
    result: xr.Dataset,
    signal: str | None = None,
    *,
    envelopes: xr.Dataset | None = None,
    range_db: float = ORDER_MAP_RANGE_DB,
) -> Figure:
    """The order map of one signal (speed x order, colour = amplitude in dB), and the up/down envelopes.

    Parameters
    ----------
    result : xarray.Dataset
        An :func:`~uqgear.dynamics.order_spectrum` result (a continuous
        order axis) or an :func:`~uqgear.dynamics.order_map` one (one row per
        order).
    signal : str, optional
        Signal drawn; by default the first.
    envelopes : xarray.Dataset, optional
        An :func:`~uqgear.dynamics.up_down_envelopes` result, drawn in a
        second panel with its hysteresis ranges shaded.
    range_db : float
        Colour range: amplitudes more than this many dB below the peak share
        the lowest colour.

    Returns
    -------
    matplotlib.figure.Figure
        On an Agg canvas, outside pyplot.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics import order_map
    >>> from uqgear.report import order_map_figure
    >>> time = np.arange(0.0, 2.0, 1.0 / 8192)
    >>> angle = 2 * np.pi * (1000.0 * time + 250.0 * time**2) / 60.0
    >>> run = xr.Dataset({"pinion_angle": ("time", angle), "te": ("time", np.cos(21 * angle))},
    ...                  coords={"time": time})
    >>> figure = order_map_figure(order_map(run, "te", [1.0, 21.0], speed_bins=3))
    >>> figure.axes[0].get_ylabel()
    'pinion order'
    """
    _map_variable(result)
    shown = str(result["signal"].values[0]) if signal is None else signal
    figure = new_figure(9.0, 7.6 if envelopes is not None else 4.6)
    axes = figure.subplots(2 if envelopes is not None else 1, 1, squeeze=False)[:, 0]
    _draw_order_map(axes[0], figure, result, shown, float(range_db))
    if envelopes is not None:
        _draw_envelopes(axes[1], envelopes)
        low = min(axes[0].get_xlim()[0], axes[1].get_xlim()[0])
        high = max(axes[0].get_xlim()[1], axes[1].get_xlim()[1])
        for ax in axes:
            ax.set_xlim(low, high)
    return figure


def order_map_figure_png(
    result: xr.Dataset,
    signal: str | None = None,
    *,
    envelopes: xr.Dataset | None = None,
    range_db: float = ORDER_MAP_RANGE_DB,
    dpi: int = 110,
) -> bytes:
    """PNG of :func:`order_map_figure`.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics import order_spectrum
    >>> from uqgear.report.order_map_figures import order_map_figure_png
    >>> time = np.arange(0.0, 2.0, 1.0 / 8192)
    >>> angle = 2 * np.pi * (1000.0 * time + 250.0 * time**2) / 60.0
    >>> run = xr.Dataset({"pinion_angle": ("time", angle), "te": ("time", np.cos(21 * angle), {"units": "m"})},
    ...                  coords={"time": time}, attrs={"design_z1": 21})
    >>> png = order_map_figure_png(order_spectrum(run, "te", max_order=50.0, speed_bins=4))
    >>> png[:4] == b"\\x89PNG"
    True
    """
    return figure_png(order_map_figure(result, signal, envelopes=envelopes, range_db=range_db), dpi)
