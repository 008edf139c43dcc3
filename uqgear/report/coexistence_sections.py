"""Coexisting responses in the study report: drawn on bifurcation diagrams and regime maps, said in words.

Results of a study run with ``simulation.starts`` carry ``attractor_count`` and, per attractor,
``attractor_peak_mesh_force`` (and the Poincare points of the up- and down-sweep starts). Where a
point holds more than one steady response the diagrams show the up-sweep and down-sweep points in
their own colours (and the regime map outlines the cell), and the findings name the speeds and the
peak mesh forces of the responses there.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from .finding import Finding
from .findings import true_index_runs
from .presentation import format_value, short_name

#: Colours and markers of the sweep starts (colour-blind safe, told apart by shape as well).
START_STYLE = {"up": ("#0072B2", "^", "up-sweep start"), "down": ("#D55E00", "v", "down-sweep start")}


def draw_sweep_starts(ax: Any, ds: xr.Dataset, parameter: str, condition: str | None, scale: float) -> bool:
    """Overlay the up- and down-sweep starts' Poincare points where a point holds more than one response;
    False when the result has none."""
    if "poincare_x_up" not in ds or "attractor_count" not in ds:
        return False
    order = (parameter, condition) if condition is not None else (parameter,)
    several = np.asarray(ds["attractor_count"].transpose(*order).values).reshape(ds.sizes[parameter], -1) > 1
    if not several.any():
        return False
    values = np.asarray(ds[parameter].values, dtype=float) * scale
    for start, (colour, marker, label) in START_STYLE.items():
        points = ds[f"poincare_x_{start}"].transpose(*order, "period").values * 1e6
        points = points.reshape(ds.sizes[parameter], -1, points.shape[-1])
        rows, members = np.nonzero(several)
        shown = points[rows, members]
        ax.plot(
            np.repeat(values[rows], shown.shape[1]),
            shown.ravel(),
            linestyle="none",
            marker=marker,
            markersize=3.0,
            color=colour,
            alpha=0.8,
            label=label,
        )
    return True


def mark_coexistence(ax: Any, ds: xr.Dataset, first: str, second: str, scales: tuple[float, float]) -> None:
    """Outline the regime-map cells that hold more than one steady response."""
    if "attractor_count" not in ds:
        return
    count = ds["attractor_count"].transpose(first, second).values
    x = np.asarray(ds[first].values, dtype=float) * scales[0]
    y = np.asarray(ds[second].values, dtype=float) * scales[1]
    rows, columns = np.nonzero(count > 1)
    if rows.size:
        ax.plot(
            x[rows],
            y[columns],
            linestyle="none",
            marker="s",
            markersize=11,
            markerfacecolor="none",
            markeredgecolor="#D55E00",
            markeredgewidth=1.6,
            label="two or more responses coexist",
        )


def coexistence_sentences(ds: xr.Dataset, sweep: str, condition: str | None = None) -> list[str]:
    """Where responses coexist along ``sweep`` (per ``condition`` value), with their peak mesh forces."""
    if "attractor_count" not in ds or sweep not in ds["attractor_count"].dims:
        return []
    count = ds["attractor_count"]
    forces = ds["attractor_peak_mesh_force"] if "attractor_peak_mesh_force" in ds else None
    levels = [None] if condition is None or condition not in count.dims else list(range(ds.sizes[condition]))
    values = np.asarray(ds[sweep].values, dtype=float)
    sentences = []
    for level in levels:
        selected = count if level is None else count.isel({condition: level})
        column = np.asarray(selected.transpose(sweep, ...).values).reshape(values.size, -1).max(axis=1)
        where = ""
        if level is not None:
            assert condition is not None  # levels are positions along the condition
            where = f" at {short_name(condition)} = {format_value(condition, float(ds[condition].values[level]))}"
        for start, stop in true_index_runs(column > 1):
            parts = []
            for index in range(start, min(stop, start + 3) + 1):
                if forces is None:
                    continue
                cell = forces.isel({sweep: index}) if level is None else forces.isel({sweep: index, condition: level})
                found = np.sort(np.asarray(cell.values, dtype=float).ravel())
                found = found[np.isfinite(found)]
                parts.append(
                    f"{' or '.join(f'{v / 1e3:.4g}' for v in found)} kN at {format_value(sweep, values[index])}"
                )
            span = (
                f"at {format_value(sweep, values[start])}"
                if start == stop
                else f"between {format_value(sweep, values[start])} and {format_value(sweep, values[stop])}"
            )
            sentences.append(
                f"{int(column[start : stop + 1].max())} steady responses coexist {span}{where}"
                + (f": peak mesh force {'; '.join(parts)}" if parts else "")
                + (" ..." if stop - start > 3 else "")
                + " (which one depends on the start)"
            )
    if not sentences:
        sentences.append(f"one steady response at every point (every point run from {_starts_text(ds)})")
    return sentences


def attractor_bound_sentences(ds: xr.Dataset, name: str, sweep: str | None) -> list[str]:
    """For bounds over attractors: where the upper bound comes from a response other than the rest start's."""
    if f"{name}_start" not in ds or sweep is None or ds[name].ndim != 2:
        return []
    values = np.asarray(ds[sweep].values, dtype=float)
    starts = np.asarray(ds[f"{name}_start"].sel(bound="upper").values).astype(str)
    upper = np.asarray(ds[name].sel(bound="upper").values, dtype=float)
    other = [i for i, start in enumerate(starts) if start != "rest"]
    if not other:
        return [f"{short_name(name)}: every upper bound is reached from rest"]
    shown = ", ".join(
        f"{format_value(sweep, values[i])} ({format_value(name, upper[i])}, {starts[i]} start)" for i in other[:6]
    )
    return [
        f"{short_name(name)}: the upper bound comes from a response not reached from rest at {shown}"
        + (" ..." if len(other) > 6 else "")
    ]


def branch_parameters(ds: xr.Dataset) -> list[str]:
    """The interval parameters whose values at the branches' node a result records (``branch_<parameter>``)."""
    return [str(name)[len("branch_") :] for name in ds.data_vars if str(name).startswith("branch_")]


def branch_sentences(ds: xr.Dataset, name: str, sweep: str | None) -> list[str]:
    """Where two responses coexist inside the bounds: the speeds, the interval parameter values and both values."""
    if f"{name}_branches" not in ds or sweep is None or ds[f"{name}_branches"].ndim != 2:
        return []
    pair = np.asarray(ds[f"{name}_branches"].transpose(sweep, "branch").values, dtype=float)
    shown = np.isfinite(pair).all(axis=1)
    values = np.asarray(ds[sweep].values, dtype=float)
    nodes = branch_parameters(ds)
    sentences = []
    for start, stop in true_index_runs(shown):
        span = (
            f"at {format_value(sweep, values[start])}"
            if start == stop
            else f"between {format_value(sweep, values[start])} and {format_value(sweep, values[stop])}"
        )
        widest = start + int(np.argmax(pair[start : stop + 1, 1] - pair[start : stop + 1, 0]))
        at = ", ".join(
            f"{short_name(node)} = {format_value(node, float(ds[f'branch_{node}'].values[widest]))}" for node in nodes
        )
        sentences.append(
            f"{short_name(name)}: two steady responses coexist {span}; at {format_value(sweep, values[widest])}"
            + (f" ({at})" if at else "")
            + f" {format_value(name, pair[widest, 0])} or {format_value(name, pair[widest, 1])}"
            + " (both drawn in the envelope figure)"
        )
    return sentences


def _starts_text(ds: xr.Dataset) -> str:
    import json

    try:
        settings = json.loads(str(ds.attrs.get("starts", "{}")))
    except ValueError:
        settings = {}
    parts = []
    if settings.get("sweeps", True):
        parts.append("its up- and down-sweep neighbours' final states")
    if settings.get("guided"):
        parts.append("the stable orbits the continuation found there")
    if settings.get("seeded"):
        parts.append(f"{settings['seeded']} random states")
    if settings.get("guided"):
        return (
            f"rest; the {ds.attrs.get('window_points', 'few')} points inside the speed windows where the continued "
            "branches fold, double, lose stability or graze also from " + ", ".join(parts)
        )
    return ", ".join(["rest", *parts])


def coexistence_headline(results: Sequence[xr.Dataset]) -> list[Finding]:
    """The coexisting responses of the grid result with the most points (bifurcation or regime map)."""
    candidates = [ds for ds in results if "attractor_count" in ds and "pinion_speed" in ds["attractor_count"].dims]
    if not candidates:
        return []
    ds = max(candidates, key=lambda item: item["attractor_count"].size)
    condition = next((dim for dim in ds["attractor_count"].dims if dim != "pinion_speed"), None)
    sentences = coexistence_sentences(ds, "pinion_speed", None if condition is None else str(condition))
    source = str(ds.attrs.get("analysis_name", "analysis"))
    count = ds["attractor_count"]
    facts = {"source": source, "points_with_several": int((count > 1).sum()), "most": int(count.max())}
    return [
        Finding(sentence[0].upper() + sentence[1:] + f" ({source}).", facts, "coexistence") for sentence in sentences
    ]


__all__ = [
    "attractor_bound_sentences",
    "draw_sweep_starts",
    "mark_coexistence",
    "coexistence_sentences",
    "coexistence_headline",
    "START_STYLE",
]
