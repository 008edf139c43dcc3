"""Findings computed from study results, in plain sentences: the stretches of a sweep where something
holds, and where each response regime occurs; and result variables on the pinion speed x T2 grid."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from .presentation import REGIME_ORDER, display, format_value, short_name
from .sections import json_attr


def true_index_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [start, stop] (inclusive) of consecutive True values."""
    ranges = []
    start = None
    for index, flag in enumerate(mask):
        if flag and start is None:
            start = index
        if not flag and start is not None:
            ranges.append((start, index - 1))
            start = None
    if start is not None:
        ranges.append((start, len(mask) - 1))
    return ranges


def range_text(name: str, values: np.ndarray, start: int, stop: int) -> str:
    """Where a stretch ``values[start..stop]`` of the variable ``name`` lies: 'at x' or 'between x and y'.

    The values are formatted as the report shows ``name``; a unit both ends carry is written once, after the
    upper end.
    """
    if start == stop:
        return f"at {format_value(name, values[start])}"
    low, high = format_value(name, values[start]), format_value(name, values[stop])
    _, unit, _ = display(name)
    if unit not in ("-", "") and low.endswith(unit) and high.endswith(unit):
        low = low[: -len(unit)].strip()
    return f"between {low} and {high}"


def t2_interval(results: Sequence[xr.Dataset]) -> tuple[float, float, bool] | None:
    """(lower, upper, from rail adhesion) of the T2 interval of the study, if T2 is an interval."""
    for ds in results:
        entry = json_attr(ds, "uncertain_parameters", {}).get(T2)
        if entry and entry.get("kind") == "interval":
            source = str(entry.get("source", ""))
            return float(entry["lower"]), float(entry["upper"]), ("mu in" in source or "adhesion" in source)
    return None


def t2_interval_end(value: float, interval: tuple[float, float, bool] | None) -> str:
    """'low' or 'high' where ``value`` is that end of the T2 interval, else ''."""
    if interval is None or not np.isfinite(value):
        return ""
    for name, bound in (("low", interval[0]), ("high", interval[1])):
        if abs(value - bound) <= 1e-6 * max(abs(bound), 1.0):
            return name
    return ""


def condition_text(name: str, values: np.ndarray, present: np.ndarray) -> str:
    """Where along a second axis a regime occurs: 'when T2 > x', 'for all T2', ..."""
    indices = np.nonzero(present)[0]
    label = short_name(name)
    if indices.size == 0:
        return ""
    if indices.size == 1:
        return f"at {label} = {format_value(name, values[indices[0]])}"
    if indices.size == values.size:
        return f"for all {label} in [{format_value(name, values[0])}, {format_value(name, values[-1])}]"
    contiguous = indices[-1] - indices[0] + 1 == indices.size
    if contiguous and indices[-1] == values.size - 1:
        return f"when {label} >= {format_value(name, values[indices[0]])}"
    if contiguous and indices[0] == 0:
        return f"when {label} <= {format_value(name, values[indices[-1]])}"
    if contiguous:
        return f"for {label} in [{format_value(name, values[indices[0]])}, {format_value(name, values[indices[-1]])}]"
    shown = ", ".join(format_value(name, values[i]) for i in indices[:6])
    return f"for {label} = {shown}" + (" ..." if indices.size > 6 else "")


def equal_value_runs(values: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges [start, stop] (inclusive) of consecutive equal values, covering ``values`` in order."""
    ranges = []
    start = 0
    for index in range(1, len(values) + 1):
        if index == len(values) or values[index] != values[start]:
            ranges.append((start, index - 1))
            start = index
    return ranges


def regime_findings(regime: xr.DataArray, sweep: str, condition: str | None = None) -> list[str]:
    """Sentences saying where each non-period-1 regime occurs along ``sweep``.

    Parameters
    ----------
    regime : DataArray of str
        Dims ``sweep`` and optionally ``condition`` (e.g. T2 values).
    sweep, condition : str
        Dim names.

    Returns
    -------
    list of str
        E.g. ``"chaotic between 1830 and 1990 rpm when T2 >= 38 kN m"``.
    """
    values = np.asarray(regime[sweep].values, dtype=float)
    labels = np.asarray(regime.transpose(sweep, ...).values).astype(str)
    if labels.ndim == 1:
        labels = labels[:, None]
    condition_values = np.asarray(regime[condition].values, dtype=float) if condition else None
    sentences = []
    subharmonic = np.char.startswith(labels, "period-") & (labels != "period-1")
    groups = [("period-n (n > 1)", subharmonic)] if subharmonic.any() else []
    # every other label is named too (quasi_periodic_or_long_period, uncertain, labels added later)
    others = sorted(
        {str(label) for label in labels.ravel() if not str(label).startswith("period-")},
        key=lambda label: (REGIME_ORDER.index(label) if label in REGIME_ORDER else len(REGIME_ORDER), label),
    )
    groups += [(label, labels == label) for label in others]
    for label, present in groups:
        ranges = true_index_runs(present.any(axis=1))
        if len(ranges) > 3:
            # many short windows (a rich bifurcation diagram): one sentence listing them
            _, unit, factor = display(sweep)
            spans = ", ".join(
                f"{values[a] * factor:.4g}" if a == b else f"{values[a] * factor:.4g}-{values[b] * factor:.4g}"
                for a, b in ranges
            )
            text = f"{label} in {len(ranges)} windows: {spans}" + ("" if unit in ("-", "") else f" {unit}")
            if label.startswith("period-n"):
                periods = sorted({int(item.split("-", 1)[1]) for item in labels[present]})
                text += f" (n = {', '.join(map(str, periods))})"
            if condition is not None and condition_values is not None:
                text += " " + condition_text(condition, condition_values, present.any(axis=0))
            sentences.append(text)
            continue
        for start, stop in ranges:
            text = f"{label} {range_text(sweep, values, start, stop)}"
            if label.startswith("period-n"):
                members = labels[start : stop + 1][present[start : stop + 1]]
                periods = sorted({int(item.split("-", 1)[1]) for item in members})
                text = (
                    f"period-{periods[0]} " if len(periods) == 1 else f"period-n (n = {', '.join(map(str, periods))}) "
                ) + text[len(label) + 1 :]
            if condition is not None and condition_values is not None:
                text += " " + condition_text(condition, condition_values, present[start : stop + 1].any(axis=0))
            sentences.append(text)
    if not sentences:
        span = f"[{format_value(sweep, values[0])}, {format_value(sweep, values[-1])}]"
        sentences.append(
            f"period-1 (harmonic) response everywhere on {short_name(sweep)} in {span}"
            + (f" and over all {short_name(condition)} values" if condition else "")
        )
    return sentences


def separation_findings(fraction: xr.DataArray, sweep: str, condition: str) -> list[str]:
    """Where the teeth separate along ``sweep``, stated for each end of ``condition`` separately.

    Parameters
    ----------
    fraction : DataArray
        Fraction of time with the teeth apart, dims ``sweep`` and ``condition`` (e.g. speed and T2).
    sweep, condition : str
        Dim names.

    Returns
    -------
    list of str
        One sentence for the lowest and one for the highest ``condition`` value (e.g. wet and dry
        rail), then, if there are values in between, where separation occurs at any of them, e.g.
        ``"teeth separate (contact loss) between 4300 and 4800 rpm at T2 = 46.52 kN m, up to 23 % of
        the time"``. A range found at one value of ``condition`` is never attributed to another.
    """
    grid = fraction.transpose(sweep, condition)
    values = np.asarray(grid[sweep].values, dtype=float)
    levels = np.asarray(grid[condition].values, dtype=float)
    rows, columns = np.argsort(values, kind="stable"), np.argsort(levels, kind="stable")
    values, levels = values[rows], levels[columns]
    data = np.asarray(grid.values, dtype=float)[np.ix_(rows, columns)]
    label = short_name(condition)

    def where(mask: np.ndarray) -> str:
        return " and ".join(range_text(sweep, values, a, b) for a, b in true_index_runs(mask))

    sentences = []
    for j in sorted({0, levels.size - 1}):
        column = data[:, j]
        at = f"at {label} = {format_value(condition, levels[j])}"
        if (column > 0.0).any():
            sentences.append(
                f"teeth separate (contact loss) {where(column > 0.0)} {at}, up to "
                f"{100 * float(np.nanmax(column)):.3g} % of the time"
            )
        else:
            sentences.append(
                f"no contact loss {at} anywhere on {short_name(sweep)} in "
                f"[{format_value(sweep, values[0])}, {format_value(sweep, values[-1])}]"
            )
    middle = data[:, 1:-1]
    if middle.size and (middle > 0.0).any():
        sentences.append(
            f"teeth separate (contact loss) at the {middle.shape[1]} {label} values in between "
            f"too: all of it {where(np.asarray((middle > 0.0).any(axis=1)))}, up to "
            f"{100 * float(np.nanmax(middle)):.3g} % of the time"
        )
    return sentences


# ---------------------------------------------------------------------------- speed x T2 grids

SPEED = "pinion_speed"
T2 = "adhesion_torque"


@dataclass(frozen=True)
class Grid:
    """One result variable on the pinion speed x T2 grid of an analysis (both axes ascending)."""

    source: str  # analysis name
    speeds: np.ndarray  # rpm, (n_speed,)
    t2: np.ndarray  # N m, (n_t2,); one NaN where T2 is not known
    values: np.ndarray  # (n_speed, n_t2)


def _fixed_t2(ds: xr.Dataset) -> float:
    """The one T2 of a result that does not sweep it (NaN if it varies or is not recorded)."""
    if T2 in ds.coords:
        values = np.unique(np.asarray(ds[T2].values, dtype=float))
        return float(values[0]) if values.size == 1 else float("nan")
    value = json_attr(ds, "fixed_inputs", {}).get(T2)
    return float(value) if isinstance(value, (int, float)) else float("nan")


def grid(ds: xr.Dataset, name: str) -> Grid | None:
    """``ds[name]`` as a :class:`Grid` if its dims are pinion speed and (optionally) T2, else None."""
    if name not in ds or SPEED not in ds[name].dims or not set(ds[name].dims) <= {SPEED, T2}:
        return None
    variable = ds[name]
    if T2 in variable.dims:
        variable = variable.transpose(SPEED, T2)
        t2 = np.asarray(ds[T2].values, dtype=float)
        values = np.asarray(variable.values)
    else:
        t2 = np.array([_fixed_t2(ds)])
        values = np.asarray(variable.values)[:, None]
    speeds = np.asarray(ds[SPEED].values, dtype=float)
    rows, columns = np.argsort(speeds, kind="stable"), np.argsort(t2, kind="stable")
    return Grid(
        str(ds.attrs.get("analysis_name", ds.attrs.get("analysis_type", "analysis"))),
        speeds[rows],
        t2[columns],
        values[np.ix_(rows, columns)],
    )


def grids(results: Sequence[xr.Dataset], name: str) -> list[Grid]:
    """Every speed x T2 grid of ``name`` in the results, in analysis order."""
    return [g for g in (grid(ds, name) for ds in results) if g is not None]
