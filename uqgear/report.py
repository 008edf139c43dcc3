"""Self-contained HTML reports of study results.

:func:`write_report` reads the ``<analysis>.nc`` files of a run folder (and
nothing else) and writes ``report.html``: one file, figures embedded as
base64 PNG, no script, style sheet or font fetched from the network. It holds

* the study summary: design table, uncertain parameters, seed, package
  versions, run time;
* one section per analysis with its figures (envelope bands, bifurcation
  diagrams with their envelopes, regime maps, time history / phase plane /
  Poincare map / spectrum panels, Sobol bars with confidence intervals,
  polynomial-chaos validation), the findings computed from the data and the
  caveats (surrogate error, non-smooth regions, distributions assumed);
* all findings and caveats collected at the top.

Figures are drawn with matplotlib's Agg canvas (no pyplot, no display);
colour maps are perceptually uniform (cividis, viridis), so they read in
grey, and curves differ by line style and marker too. Every axis names its
quantity and unit.

Each analysis type has one renderer, registered with :func:`renderer`; a
result of an unknown type still gets a section listing its variables.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure
from matplotlib import colormaps

from .fileio import write_text_atomic
from .errors import UqgearError
from .dynamics import UNDETERMINED
from .interval import (FLAG_FALLBACK, FLAG_NONFINITE, FLAG_NONSMOOTH, FLAG_SURROGATE_ERROR,
                       FLAG_VERTEX_EXCEEDED)
from .results import load_result

REPORT_NAME = "report.html"
# interval flags that say something about the QoI itself (not just "recomputed by the fallback")
_OWN_FLAGS = FLAG_VERTEX_EXCEEDED | FLAG_SURROGATE_ERROR | FLAG_NONSMOOTH | FLAG_NONFINITE

# name -> (label, unit shown, factor from SI to the unit shown)
_DISPLAY: dict[str, tuple[str, str, float]] = {
    "pinion_speed": ("pinion speed $n_1$", "rpm", 1.0),
    "drive_torque": ("drive torque $T_1$", "kN m", 1e-3),
    "adhesion_torque": ("adhesion torque $T_2$", "kN m", 1e-3),
    "mesh_stiffness_scale": ("mesh stiffness scale", "-", 1.0),
    "k1": ("pinion bearing stiffness $k_1$", "GN/m", 1e-9),
    "k2": ("gear bearing stiffness $k_2$", "GN/m", 1e-9),
    "zeta_mesh": ("mesh damping ratio $\\zeta_m$", "-", 1.0),
    "zeta1": ("pinion bearing damping ratio $\\zeta_1$", "-", 1.0),
    "zeta2": ("gear bearing damping ratio $\\zeta_2$", "-", 1.0),
    "backlash": ("backlash $2b$", "µm", 1e6),
    "ste_amplitude": ("STE amplitude $e_r$", "µm", 1e6),
    "m1": ("pinion mass $m_1$", "kg", 1.0),
    "m2": ("gear mass $m_2$", "kg", 1.0),
    "I1": ("pinion inertia $I_1$", "kg m²", 1.0),
    "I2": ("gear inertia $I_2$", "kg m²", 1.0),
    "face_width": ("face width", "mm", 1e3),
    "dte_mean": ("mean DTE", "µm", 1e6),
    "dte_rms": ("RMS DTE", "µm", 1e6),
    "dte_peak_to_peak": ("peak-to-peak DTE", "µm", 1e6),
    "dynamic_load_factor": ("dynamic load factor", "-", 1.0),
    "acc_pinion_rms": ("RMS pinion acceleration", "m/s²", 1.0),
    "acc_gear_rms": ("RMS gear acceleration", "m/s²", 1.0),
    "fraction_drive_contact": ("time in drive-side contact", "%", 100.0),
    "fraction_separation": ("time with teeth apart", "%", 100.0),
    "fraction_back_contact": ("time in back-side contact", "%", 100.0),
    "largest_lyapunov": ("largest Lyapunov exponent", "1/s", 1.0),
}

_SHORT_NAMES = {"adhesion_torque": "T2", "drive_torque": "T1", "pinion_speed": "speed",
                "mesh_stiffness_scale": "mesh stiffness scale", "zeta_mesh": "mesh damping",
                "ste_amplitude": "STE amplitude", "k1": "pinion bearing stiffness",
                "k2": "gear bearing stiffness", "backlash": "backlash"}
_LINE_STYLES = ("-", "--", "-.", ":", (0, (5, 1, 1, 1)), (0, (3, 1, 1, 1, 1, 1)))
_MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">")


def display(name: str) -> tuple[str, str, float]:
    """Axis label, unit and SI-to-unit factor of a variable or QoI."""
    if name in _DISPLAY:
        return _DISPLAY[name]
    return (name.replace("_", " "), "-", 1.0)


def axis_label(name: str) -> str:
    """``label [unit]`` for an axis."""
    label, unit, _ = display(name)
    return f"{label} [{unit}]"


def format_value(name: str, value: float) -> str:
    """A value in display units with its unit, e.g. ``38.2 kN m``."""
    _, unit, factor = display(name)
    if not np.isfinite(value):
        return "n/a"
    shown = f"{value * factor:.4g}"
    return shown if unit in ("-", "") else f"{shown} {unit}"


def short_name(name: str) -> str:
    return _SHORT_NAMES.get(name, name.replace("_", " "))


# ---------------------------------------------------------------------------- report model


@dataclass
class ReportFigure:
    """One embedded figure."""

    caption: str
    png: bytes


@dataclass
class Section:
    """The part of the report belonging to one analysis."""

    name: str
    kind: str
    title: str
    description: str = ""
    figures: list[ReportFigure] = field(default_factory=list)
    findings: list[str] = field(default_factory=list)
    caveats: list[str] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    facts: list[tuple[str, str]] = field(default_factory=list)


Renderer = Callable[[xr.Dataset, int], Section]
RENDERERS: dict[str, Renderer] = {}


def renderer(kind: str) -> Callable[[Renderer], Renderer]:
    """Decorator registering the report renderer of an analysis type."""
    def decorate(function: Renderer) -> Renderer:
        RENDERERS[kind] = function
        return function

    return decorate


def _new_figure(width: float, height: float) -> Figure:
    figure = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def figure_png(figure: Figure, dpi: int) -> bytes:
    """PNG bytes of a figure."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def _json_attr(ds: xr.Dataset | xr.DataArray, name: str, default: Any) -> Any:
    value = ds.attrs.get(name)
    if value is None:
        return default
    if isinstance(value, str):
        try:
            return json.loads(value)
        except ValueError:
            return default
    return value


def _section(ds: xr.Dataset) -> Section:
    name = str(ds.attrs.get("analysis_name", "analysis"))
    kind = str(ds.attrs.get("analysis_type", "unknown"))
    section = Section(name=name, kind=kind, title=f"{name} ({kind.replace('_', ' ')})",
                      description=str(ds.attrs.get("analysis_description", "")))
    runs = ds.attrs.get("model_runs")
    if runs is not None:
        section.facts.append(("model runs", f"{int(runs)}"))
    seconds = ds.attrs.get("run_time_s")
    if seconds is not None:
        section.facts.append(("run time", f"{float(seconds):.1f} s"))
    settings = _json_attr(ds, "simulation_settings", {})
    if settings:
        section.facts.append(("simulation", f"{settings.get('n_periods')} mesh periods, last "
                                            f"{settings.get('keep_periods')} kept"
                                            + (", Lyapunov exponent" if settings.get("lyapunov") else "")))
    points = _json_attr(ds, "operating_points", {})
    # the inputs actually held fixed (with the nominal values of uncertain parameters and defaults)
    fixed = _json_attr(ds, "fixed_inputs", None) or {
        key: value for key, value in points.items() if not isinstance(value, list)}
    if fixed:
        section.facts.append(("fixed inputs", ", ".join(f"{short_name(k)} = {format_value(k, v)}"
                                                        for k, v in fixed.items())))
    return section


def _add_figure(section: Section, figure: Figure, caption: str, dpi: int) -> None:
    section.figures.append(ReportFigure(caption, figure_png(figure, dpi)))


# ---------------------------------------------------------------------------- findings helpers


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
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


def _range_text(name: str, values: np.ndarray, start: int, stop: int) -> str:
    if start == stop:
        return f"at {format_value(name, values[start])}"
    low, high = format_value(name, values[start]), format_value(name, values[stop])
    _, unit, _ = display(name)
    if unit not in ("-", "") and low.endswith(unit) and high.endswith(unit):
        low = low[: -len(unit)].strip()
    return f"between {low} and {high}"


def _condition_text(name: str, values: np.ndarray, present: np.ndarray) -> str:
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
        return (f"for {label} in [{format_value(name, values[indices[0]])}, "
                f"{format_value(name, values[indices[-1]])}]")
    shown = ", ".join(format_value(name, values[i]) for i in indices[:6])
    return f"for {label} = {shown}" + (" ..." if indices.size > 6 else "")


def _regime_order(labels: Sequence[str]) -> list[str]:
    def key(label: str) -> tuple[int, int, str]:
        if label.startswith("period-"):
            try:
                return (0, int(label.split("-", 1)[1]), label)
            except ValueError:
                return (0, 999, label)
        order = {"quasi-periodic": 1, "chaotic": 2}
        return (order.get(label, 3), 0, label)

    return sorted(set(labels), key=key)


def _regime_colours(labels: Sequence[str]) -> dict[str, Any]:
    # light for period-1 to dark for chaotic: the order reads in grey as well
    cmap = colormaps["cividis_r"]
    count = max(len(labels), 2)
    return {label: cmap(0.08 + 0.84 * index / (count - 1)) for index, label in enumerate(labels)}


_REGIME_CODES = {"quasi-periodic": "Q", "chaotic": "C", "undetermined": "?"}


def _regime_code(label: str) -> str:
    if label.startswith("period-n"):
        return "n"
    if label.startswith("period-"):
        return label.split("-", 1)[1]
    return _REGIME_CODES.get(label, label[:1].upper())


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
    condition_values = (np.asarray(regime[condition].values, dtype=float) if condition else None)
    sentences = []
    subharmonic = np.char.startswith(labels, "period-") & (labels != "period-1")
    groups = [("period-n (n > 1)", subharmonic)] if subharmonic.any() else []
    groups += [(label, labels == label) for label in ("quasi-periodic", "chaotic", UNDETERMINED)
               if (labels == label).any()]
    for label, present in groups:
        ranges = _runs(present.any(axis=1))
        if len(ranges) > 3:
            # many short windows (a rich bifurcation diagram): one sentence listing them
            _, unit, factor = display(sweep)
            spans = ", ".join(f"{values[a] * factor:.4g}" if a == b else
                              f"{values[a] * factor:.4g}-{values[b] * factor:.4g}" for a, b in ranges)
            text = f"{label} in {len(ranges)} windows: {spans}" + ("" if unit in ("-", "") else f" {unit}")
            if label.startswith("period-n"):
                periods = sorted({int(item.split("-", 1)[1]) for item in labels[present]})
                text += f" (n = {', '.join(map(str, periods))})"
            if condition is not None and condition_values is not None:
                text += " " + _condition_text(condition, condition_values, present.any(axis=0))
            sentences.append(text)
            continue
        for start, stop in ranges:
            text = f"{label} {_range_text(sweep, values, start, stop)}"
            if label.startswith("period-n"):
                members = labels[start:stop + 1][present[start:stop + 1]]
                periods = sorted({int(item.split("-", 1)[1]) for item in members})
                text = (f"period-{periods[0]} " if len(periods) == 1 else
                        f"period-n (n = {', '.join(map(str, periods))}) ") + text[len(label) + 1:]
            if condition is not None and condition_values is not None:
                text += " " + _condition_text(condition, condition_values, present[start:stop + 1].any(axis=0))
            sentences.append(text)
    if not sentences:
        span = f"[{format_value(sweep, values[0])}, {format_value(sweep, values[-1])}]"
        sentences.append(f"period-1 (harmonic) response everywhere on {short_name(sweep)} in {span}"
                         + (f" and over all {short_name(condition)} values" if condition else ""))
    return sentences


# ---------------------------------------------------------------------------- simulate


def _draw_simulation(figure: Figure, run: xr.Dataset, spectrum_axis: str = "order", title: str = "") -> None:
    """Time history, phase plane, Poincare map and spectrum of one run."""
    axes = figure.subplots(2, 2)
    x = np.asarray(run["x"].values) * 1e6
    velocity = np.asarray(run["x_velocity"].values) * 1e3
    cycles = np.asarray(run["mesh_cycle"].values)
    half_backlash = float(run["half_backlash"].values) * 1e6 if "half_backlash" in run else float("nan")
    shown = cycles >= cycles[-1] - 10.0
    ax = axes[0, 0]
    ax.plot(cycles[shown], x[shown], color="black", linewidth=1.0)
    if np.isfinite(half_backlash):
        for level in (half_backlash, -half_backlash):
            ax.axhline(level, color="0.5", linestyle="--", linewidth=0.8)
    ax.set_xlabel("time [mesh periods]")
    ax.set_ylabel("DTE $x$ [µm]")
    ax.set_title("time history (last 10 mesh periods; dashed: ±b)", fontsize=9)
    ax = axes[0, 1]
    ax.plot(x, velocity, color="0.35", linewidth=0.5)
    poincare_x = np.asarray(run["poincare_x"].values) * 1e6
    poincare_v = np.asarray(run["poincare_x_velocity"].values) * 1e3
    ax.plot(poincare_x, poincare_v, linestyle="none", marker="o", markersize=3, color="black",
            label="Poincaré points")
    ax.set_xlabel("DTE $x$ [µm]")
    ax.set_ylabel("DTE velocity $\\dot{x}$ [mm/s]")
    ax.set_title("phase plane", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    ax = axes[1, 0]
    ax.plot(poincare_x, poincare_v, linestyle="none", marker=".", markersize=4, color="black")
    ax.set_xlabel("$x_n$ [µm]")
    ax.set_ylabel("$\\dot{x}_n$ [mm/s]")
    ax.set_title("Poincaré map (once per mesh period)", fontsize=9)
    ax = axes[1, 1]
    amplitude = np.asarray(run["spectrum_x"].values) * 1e6
    if spectrum_axis == "frequency":
        abscissa = np.asarray(run["spectrum_frequency"].values)
        ax.set_xlabel("frequency [Hz]")
    else:
        abscissa = np.asarray(run["order"].values)
        ax.set_xlabel("order [multiples of pinion rotation]")
    positive = amplitude > 0
    ax.semilogy(abscissa[positive], amplitude[positive], color="black", linewidth=0.8)
    z1 = float(run.attrs.get("z1", np.nan))
    if np.isfinite(z1):
        mesh = z1 if spectrum_axis != "frequency" else float(run["mesh_frequency"].values)
        for harmonic in (1, 2, 3):
            ax.axvline(harmonic * mesh, color="0.55", linestyle=":", linewidth=0.8)
        ax.set_xlim(0, min(abscissa[-1], 4.2 * mesh))
    ax.set_ylabel("amplitude of $x$ [µm]")
    ax.set_title("DTE spectrum (dotted: mesh harmonics)", fontsize=9)
    if title:
        figure.suptitle(title, fontsize=10)


def _run_title(run: xr.Dataset, swept: Sequence[str]) -> str:
    parts = [f"{short_name(name)} = {format_value(name, float(run[name].values))}"
             for name in ("pinion_speed", "drive_torque", "adhesion_torque", *swept)
             if name in run and run[name].ndim == 0 and name not in ("run",)]
    parts = list(dict.fromkeys(parts))
    label = str(run["label"].values) if "label" in run else ""
    regime = str(run["regime"].values) if "regime" in run else ""
    text = ", ".join(parts)
    text += f": {regime}"
    if label and label != regime:
        text += f" (expected: {label})"
    return text


def simulation_figure_png(run: xr.Dataset, *, dpi: int = 110, spectrum_axis: str = "order") -> bytes:
    """PNG of the four panels of one run (:func:`uqgear.analyses.simulate_point` output)."""
    figure = _new_figure(9.0, 6.6)
    _draw_simulation(figure, run, spectrum_axis, _run_title(run, ()))
    return figure_png(figure, dpi)


@renderer("simulate")
def _render_simulate(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    swept = _json_attr(ds, "swept", [])
    axis = str(ds.attrs.get("spectrum_axis", "order"))
    for index in range(ds.sizes.get("run", 0)):
        run = ds.isel(run=index)
        title = _run_title(run, swept)
        figure = _new_figure(9.0, 6.6)
        _draw_simulation(figure, run, axis, title)
        _add_figure(section, figure, title + ". " + str(run["regime_reason"].values), dpi)
        label = str(run["label"].values) if "label" in run else ""
        regime = str(run["regime"].values)
        text = (f"{title}; RMS DTE {format_value('dte_rms', float(run['dte_rms'].values))}, dynamic load "
                f"factor {float(run['dynamic_load_factor'].values):.3g}, teeth apart "
                f"{100 * float(run['fraction_separation'].values):.3g} % and in back-side contact "
                f"{100 * float(run['fraction_back_contact'].values):.3g} % of the time")
        section.findings.append(text)
        if label and not _label_matches(label, regime):
            section.caveats.append(f"run {index} was listed as '{label}' in the study but is classified "
                                   f"'{regime}': the representative speeds need updating")
    return section


def _label_matches(label: str, regime: str) -> bool:
    label = label.strip().lower()
    if label in ("period-n", "period-n>1", "subharmonic"):
        return regime.startswith("period-") and regime != "period-1"
    return label == regime


# ---------------------------------------------------------------------------- bifurcation and regime map


def _collapse_periods(labels: np.ndarray, keep: int = 4) -> np.ndarray:
    """Long periods merged into one class, so a map with many of them stays readable."""
    def merged(label: str) -> str:
        if label.startswith("period-"):
            try:
                if int(label.split("-", 1)[1]) > keep:
                    return f"period-n (n > {keep})"
            except ValueError:
                return label
        return label

    return np.vectorize(merged, otypes=[object])(labels).astype(str)


def _regime_strip(ax: Any, regime: xr.DataArray, sweep: str, condition: str | None) -> None:
    labels = np.asarray(regime.transpose(sweep, ...).values).astype(str)
    if labels.ndim == 1:
        labels = labels[:, None]
    if len(set(labels.ravel().tolist())) > 7:
        labels = _collapse_periods(labels)
    order = _regime_order(labels.ravel().tolist())
    colours = _regime_colours(order)
    codes = np.vectorize(order.index)(labels)
    cmap = ListedColormap([colours[label] for label in order])
    norm = BoundaryNorm(np.arange(len(order) + 1) - 0.5, len(order))
    values = np.asarray(regime[sweep].values, dtype=float) * display(sweep)[2]
    edges = _edges(values)
    if condition is None:
        rows = np.array([0.0, 1.0])
        ax.set_yticks([])
    else:
        condition_values = np.asarray(regime[condition].values, dtype=float) * display(condition)[2]
        rows = _edges(condition_values)
        ax.set_ylabel(axis_label(condition))
    ax.pcolormesh(edges, rows, codes.T, cmap=cmap, norm=norm, shading="flat")
    handles = [_patch(colours[label], label) for label in order]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    ax.set_xlabel(axis_label(sweep))


def _patch(colour: Any, label: str) -> Any:
    from matplotlib.patches import Patch

    return Patch(facecolor=colour, edgecolor="black", linewidth=0.4, label=label)


def _edges(values: np.ndarray) -> np.ndarray:
    if values.size == 1:
        return np.array([values[0] - 0.5, values[0] + 0.5])
    middle = 0.5 * (values[1:] + values[:-1])
    return np.concatenate([[values[0] - (middle[0] - values[0])], middle,
                           [values[-1] + (values[-1] - middle[-1])]])


def _classification_caveat(ds: xr.Dataset) -> str:
    settings = _json_attr(ds, "simulation_settings", {})
    keep = settings.get("keep_periods", "?")
    if settings.get("lyapunov"):
        return (f"regimes classified from {keep} Poincaré points: period-n by repetition (0.1 % of the "
                "orbit size), chaotic vs quasi-periodic by the largest Lyapunov exponent")
    return (f"regimes classified from {keep} Poincaré points without a Lyapunov exponent: chaotic vs "
            "quasi-periodic rests on the 0-1 test, which converges slowly for quasi-periodic responses "
            "(set simulation.lyapunov: true to confirm)")


@renderer("bifurcation")
def _render_bifurcation(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    parameter = str(ds.attrs.get("parameter", next(iter(d for d in ds.dims if d != "period"))))
    envelope = _json_attr(ds, "envelope", [])
    condition = envelope[0] if envelope else None
    scale = display(parameter)[2]
    figure = _new_figure(9.0, 6.4 if condition else 5.4)
    top, bottom = figure.subplots(2, 1, height_ratios=(3, 1), sharex=True)
    points = ds["poincare_x"]
    values = np.asarray(ds[parameter].values, dtype=float)
    if condition:
        others = [dim for dim in points.dims if dim not in (parameter, "period", condition)]
        if others:
            points = points.isel({dim: 0 for dim in others})
        condition_values = np.asarray(ds[condition].values, dtype=float)
        cmap = colormaps["cividis"]
        for index, level in enumerate(condition_values):
            column = points.sel({condition: level}).transpose(parameter, "period").values * 1e6
            colour = cmap(index / max(len(condition_values) - 1, 1))
            top.plot(np.repeat(values * scale, column.shape[1]), column.ravel(), linestyle="none",
                     marker=_MARKERS[index % len(_MARKERS)], markersize=2.2, color=colour, alpha=0.8,
                     label=f"{short_name(condition)} = {format_value(condition, level)}")
        top.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0,
                   markerscale=2.5, title="envelope member", title_fontsize=7)
        top.set_title(f"bifurcation envelope: union of Poincaré points over {short_name(condition)} "
                      f"in [{format_value(condition, condition_values[0])}, "
                      f"{format_value(condition, condition_values[-1])}]", fontsize=9)
        regime = ds["regime"].transpose(parameter, condition, ...)
    else:
        column = points.transpose(parameter, "period").values * 1e6
        top.plot(np.repeat(values * scale, column.shape[1]), column.ravel(), linestyle="none", marker=".",
                 markersize=2.0, color="black")
        top.set_title("bifurcation diagram: Poincaré points of the DTE", fontsize=9)
        regime = ds["regime"]
    top.set_ylabel("Poincaré points of DTE $x_n$ [µm]")
    _regime_strip(bottom, regime, parameter, condition)
    _add_figure(section, figure, f"Bifurcation diagram against {short_name(parameter)}"
                + (f", over {short_name(condition)} (colour and marker)" if condition else "")
                + "; below: response regime per column.", dpi)
    section.findings.extend(regime_findings(regime, parameter, condition))
    section.caveats.append(_classification_caveat(ds))
    if condition:
        section.caveats.append(f"the envelope is the union over {ds.sizes[condition]} values of "
                               f"{short_name(condition)} across its interval; regimes confined between "
                               "these values can be missed")
    return section


@renderer("regime_map")
def _render_regime_map(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    axes_names = _json_attr(ds, "axes", [d for d in ds["regime"].dims][:2])
    first, second = axes_names[0], axes_names[1]
    regime = ds["regime"].transpose(first, second)
    figure = _new_figure(9.0, 5.2)
    ax = figure.subplots()
    _regime_strip(ax, regime, first, second)
    labels = np.asarray(regime.values).astype(str)
    if labels.size <= 600:
        x_values = np.asarray(ds[first].values, dtype=float) * display(first)[2]
        y_values = np.asarray(ds[second].values, dtype=float) * display(second)[2]
        # the strip's colours (long periods possibly merged) decide the text colour
        shown = _collapse_periods(labels) if len(set(labels.ravel().tolist())) > 7 else labels
        order = _regime_order(shown.ravel().tolist())
        for i, x_value in enumerate(x_values):
            for j, y_value in enumerate(y_values):
                if labels[i, j] == "period-1":
                    continue
                dark = order.index(shown[i, j]) >= len(order) / 2
                ax.text(x_value, y_value, _regime_code(labels[i, j]), ha="center", va="center", fontsize=6,
                        color="white" if dark else "black")
    ax.set_title(f"response regime over {short_name(first)} x {short_name(second)} "
                 "(cell code: period n, Q quasi-periodic, C chaotic; blank: period 1)", fontsize=9)
    _add_figure(section, figure, f"Regime map over {short_name(first)} and {short_name(second)}.", dpi)
    if "fraction_separation" in ds:
        figure = _new_figure(9.0, 4.6)
        ax = figure.subplots()
        separation = ds["fraction_separation"].transpose(first, second).values * 100
        mesh = ax.pcolormesh(_edges(np.asarray(ds[first].values, float) * display(first)[2]),
                             _edges(np.asarray(ds[second].values, float) * display(second)[2]),
                             separation.T, cmap="viridis", shading="flat")
        figure.colorbar(mesh, ax=ax, label="tooth separation [% of time]")
        ax.set_xlabel(axis_label(first))
        ax.set_ylabel(axis_label(second))
        ax.set_title("fraction of time with the teeth apart (contact loss)", fontsize=9)
        _add_figure(section, figure, "Contact loss over the same grid.", dpi)
    section.findings.extend(regime_findings(regime, first, second))
    if "fraction_separation" in ds:
        separated = ds["fraction_separation"].transpose(first, second) > 0.0
        values = np.asarray(ds[first].values, dtype=float)
        for start, stop in _runs(separated.values.any(axis=1)):
            peak = float(ds["fraction_separation"].isel({first: slice(start, stop + 1)}).max())
            section.findings.append(
                f"teeth separate (contact loss) {_range_text(first, values, start, stop)} "
                + _condition_text(second, np.asarray(ds[second].values, dtype=float),
                                  separated.values[start:stop + 1].any(axis=0))
                + f", up to {100 * peak:.3g} % of the time")
    section.caveats.append(_classification_caveat(ds))
    return section


# ---------------------------------------------------------------------------- interval


def _sweep_dim(ds: xr.Dataset, exclude: Sequence[str]) -> str | None:
    for dim in ds.dims:
        if dim not in exclude:
            return str(dim)
    return None


def _qois_of(ds: xr.Dataset) -> list[str]:
    options = _json_attr(ds, "analysis_options", {})
    return [name for name in options.get("qois", []) if name in ds]


@renderer("interval")
def _render_interval(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    qois = _qois_of(ds)
    options = _json_attr(ds, "analysis_options", {})
    parameters = options.get("parameters", [])
    sweep = _sweep_dim(ds, ("bound", "check", "node", "sample", "param"))
    label = ", ".join(short_name(p) for p in parameters)
    if not qois:
        return section
    figure = _new_figure(9.0, 2.9 * len(qois))
    axes = np.atleast_1d(figure.subplots(len(qois), 1, sharex=True))
    for ax, name in zip(axes, qois):
        _, unit, factor = display(name)
        bounds = ds[name]
        lower = bounds.sel(bound="lower").values * factor
        upper = bounds.sel(bound="upper").values * factor
        nominal = ds[f"{name}_nominal"].values * factor if f"{name}_nominal" in ds else None
        if sweep is not None and lower.ndim == 1:
            x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
            ax.fill_between(x, lower, upper, color=colormaps["cividis"](0.75), alpha=0.6,
                            label=f"envelope over {label}")
            ax.plot(x, lower, color="black", linewidth=1.0, linestyle="-")
            ax.plot(x, upper, color="black", linewidth=1.0, linestyle="-")
            if nominal is not None:
                ax.plot(x, nominal, color="black", linestyle="--", linewidth=1.0, label="nominal (midpoints)")
            flagged = _flags(ds, name)
            if flagged is not None and flagged.any():
                ax.plot(x[flagged], upper[flagged], linestyle="none", marker="x", color="black", markersize=6,
                        label="flagged (non-smooth or surrogate error)")
            ax.legend(fontsize=7, loc="best")
        else:
            ax.bar([0], [float(np.ravel(upper)[0] - np.ravel(lower)[0])], bottom=[float(np.ravel(lower)[0])],
                   color=colormaps["cividis"](0.75), edgecolor="black", width=0.4)
            ax.set_xticks([])
        ax.set_ylabel(f"{display(name)[0]} [{unit}]")
        _interval_findings(section, ds, name, sweep, label)
    axes[-1].set_xlabel(axis_label(sweep) if sweep else "")
    method = ds.attrs.get("method", options.get("method", "?"))
    _add_figure(section, figure, f"QoI envelopes over {label} ({method} method; band: lower to upper "
                "bound, dashed: response at the interval midpoints; x: bounds flagged by the method's own "
                "checks).", dpi)
    redone = _flags(ds, qois[0], FLAG_FALLBACK) if qois else None
    if redone is not None and redone.any() and sweep is not None:
        values = np.asarray(ds[sweep].values, dtype=float)
        section.caveats.append(f"the {ds.attrs.get('fallback', 'fallback')} fallback recomputed all QoIs at "
                               f"{int(redone.sum())} of {redone.size} points: "
                               + ", ".join(format_value(sweep, v) for v in values[redone][:12])
                               + (", ..." if redone.sum() > 12 else ""))
    if "runs" in ds.attrs:
        section.facts.append(("interval method", f"{method}, {int(ds.attrs['runs'])} runs including "
                                                 f"{int(ds.attrs.get('fallback_runs', 0))} by the fallback"))
    reasons = _json_attr(ds["flag"], "flag_reasons", []) if "flag" in ds else []
    if reasons:
        section.tables.append("<details><summary>Why bounds were flagged (" + str(len(reasons))
                              + " entries)</summary>" + _list(reasons) + "</details>")
    return section


def _flags(ds: xr.Dataset, name: str, bits: int = _OWN_FLAGS) -> np.ndarray | None:
    """Sweep points where the bounds of ``name`` carry any of the flag ``bits``."""
    if "flag" in ds and "qoi" in ds["flag"].dims and name in ds["qoi"].values:
        return (np.asarray(ds["flag"].sel(qoi=name).values).astype(int) & bits) != 0
    return None


def _interval_findings(section: Section, ds: xr.Dataset, name: str, sweep: str | None, label: str) -> None:
    bounds = ds[name]
    lower = np.asarray(bounds.sel(bound="lower").values, dtype=float)
    upper = np.asarray(bounds.sel(bound="upper").values, dtype=float)
    width = upper - lower
    title = display(name)[0]
    if sweep is not None and lower.ndim == 1:
        values = np.asarray(ds[sweep].values, dtype=float)
        peak = int(np.nanargmax(upper))
        widest = int(np.nanargmax(width))
        section.findings.append(
            f"{title}: highest upper bound {format_value(name, upper[peak])} at "
            f"{format_value(sweep, values[peak])}; widest band over {label} "
            f"{format_value(name, width[widest])} (from {format_value(name, lower[widest])} to "
            f"{format_value(name, upper[widest])}) at {format_value(sweep, values[widest])}")
        flagged = _flags(ds, name)
        if flagged is not None and flagged.any():
            fallback = str(ds.attrs.get("fallback", "none"))
            where = ", ".join(format_value(sweep, v) for v in values[flagged][:10])
            section.caveats.append(
                f"{title}: bounds flagged at {int(flagged.sum())} of {flagged.size} points ({where}"
                + (", ..." if flagged.sum() > 10 else "") + "): surrogate error above tolerance, "
                "non-smooth, non-monotone or non-finite response"
                + (f"; recomputed there by the {fallback} fallback" if fallback != "none"
                   else "; no fallback was run: treat these bands with care"))
    else:
        section.findings.append(f"{title} in [{format_value(name, float(np.ravel(lower)[0]))}, "
                                f"{format_value(name, float(np.ravel(upper)[0]))}] over {label}")
    if "surrogate_error_relative" in ds and name in ds["qoi"].values:
        error = np.asarray(ds["surrogate_error_relative"].sel(qoi=name).values, dtype=float)
        if np.isfinite(error).any():
            section.caveats.append(f"{title}: largest estimated error of the bounds "
                                   f"{100 * float(np.nanmax(error)):.3g} % of the band width")


# ---------------------------------------------------------------------------- monte carlo and pce


def _interval_treatment_caveat(ds: xr.Dataset, what: str) -> str | None:
    treatment = str(ds.attrs.get("interval_treatment", ""))
    if treatment and not treatment.startswith("none"):
        if not treatment.startswith("interval"):
            treatment = "interval parameters " + treatment
        return f"{what}: {treatment}"
    return None


def _render_pbox(ds: xr.Dataset, dpi: int, section: Section, qois: Sequence[str]) -> Section:
    """Bounds of statistics over the interval parameters (a probability box)."""
    sweep = _sweep_dim(ds, ("statistic", "quantile", "bound", "qoi"))
    levels = np.asarray(ds["quantile"].values, dtype=float)
    intervals = ", ".join(short_name(name) for name in _json_attr(ds, "interval_parameters", {}))
    figure = _new_figure(9.0, 2.8 * len(qois))
    axes = np.atleast_1d(figure.subplots(len(qois), 1, sharex=sweep is not None))
    for ax, name in zip(axes, qois):
        _, unit, factor = display(name)
        mean = ds[name].sel(statistic="mean") * factor
        low = ds[f"{name}_quantile"].isel(quantile=0).sel(bound="lower") * factor
        high = ds[f"{name}_quantile"].isel(quantile=-1).sel(bound="upper") * factor
        if sweep is not None:
            x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
            ax.fill_between(x, low.values, high.values, color=colormaps["cividis"](0.85), alpha=0.5,
                            label=f"{100 * levels[0]:g}-{100 * levels[-1]:g} % quantiles, outer bounds")
            ax.fill_between(x, mean.sel(bound="lower").values, mean.sel(bound="upper").values,
                            color=colormaps["cividis"](0.35), alpha=0.8, label="mean: bounds over the intervals")
            ax.legend(fontsize=7, loc="best")
            ax.set_ylabel(f"{display(name)[0]} [{unit}]")
        else:
            ax.bar([0, 1], [float(high - low), float(mean.sel(bound="upper") - mean.sel(bound="lower"))],
                   bottom=[float(low), float(mean.sel(bound="lower"))], color=colormaps["cividis"](0.6),
                   edgecolor="black", width=0.5)
            ax.set_xticks([0, 1], [f"{100 * levels[0]:g}-{100 * levels[-1]:g} % quantiles", "mean"])
            ax.set_ylabel(f"{display(name)[0]} [{unit}]")
        lower = np.atleast_1d(mean.sel(bound="lower").values) / factor
        upper = np.atleast_1d(mean.sel(bound="upper").values) / factor
        widest = int(np.nanargmax(upper - lower))
        where = "" if sweep is None else f" (widest at {format_value(sweep, float(ds[sweep].values[widest]))})"
        section.findings.append(
            f"{display(name)[0]}: the mean over the random parameters lies in "
            f"[{format_value(name, lower[widest])}, {format_value(name, upper[widest])}] over {intervals}{where}")
    if sweep is not None:
        axes[-1].set_xlabel(axis_label(sweep))
    _add_figure(section, figure, f"Probability box: Monte Carlo statistics over the random parameters, bounded "
                f"over the intervals ({intervals}); no distribution is assumed for the intervals.", dpi)
    section.caveats.append(f"p-box from a scan of {ds.attrs.get('scan_points', '?')} points per interval "
                           f"parameter with {ds.attrs.get('n_samples', '?')} random samples each (common random "
                           "numbers); extremes between scan points can be missed")
    return section


@renderer("monte_carlo")
def _render_monte_carlo(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    qois = _qois_of(ds)
    if qois and "bound" in ds[qois[0]].dims:
        return _render_pbox(ds, dpi, section, qois)
    sweep = _sweep_dim(ds, ("statistic", "quantile", "sample"))
    if not qois:
        return section
    figure = _new_figure(9.0, 2.8 * len(qois))
    axes = np.atleast_1d(figure.subplots(len(qois), 1, sharex=sweep is not None))
    levels = np.asarray(ds["quantile"].values, dtype=float)
    for ax, name in zip(axes, qois):
        _, unit, factor = display(name)
        mean = ds[name].sel(statistic="mean").values * factor
        quantiles = ds[f"{name}_quantile"].values * factor
        if sweep is not None:
            x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
            ax.fill_between(x, quantiles[..., 0], quantiles[..., -1], color=colormaps["cividis"](0.75),
                            alpha=0.6, label=f"{100 * levels[0]:g}-{100 * levels[-1]:g} % quantiles")
            ax.plot(x, mean, color="black", linewidth=1.2, label="mean")
            if f"{name}_samples" in ds:
                samples = ds[f"{name}_samples"].transpose(sweep, "sample").values * factor
                ax.plot(np.repeat(x, samples.shape[1]), samples.ravel(), linestyle="none", marker=".",
                        markersize=1.5, color="0.4", label="samples")
            ax.legend(fontsize=7, loc="best")
            peak = int(np.nanargmax(ds[name].sel(statistic="std").values))
            section.findings.append(
                f"{display(name)[0]}: mean from {format_value(name, np.nanmin(mean) / factor)} to "
                f"{format_value(name, np.nanmax(mean) / factor)}; largest spread (std "
                f"{format_value(name, float(ds[name].sel(statistic='std').values[peak]))}) at "
                f"{format_value(sweep, float(ds[sweep].values[peak]))}")
        else:
            values = ds[f"{name}_samples"].values * factor if f"{name}_samples" in ds else None
            if values is not None:
                ax.hist(values[np.isfinite(values)], bins=20, color=colormaps["cividis"](0.6), edgecolor="black")
            ax.set_xlabel(f"{display(name)[0]} [{unit}]")
            ax.set_ylabel("count")
            section.findings.append(
                f"{display(name)[0]}: mean {format_value(name, float(mean.ravel()[0]) / factor)}, std "
                f"{format_value(name, float(ds[name].sel(statistic='std').values.ravel()[0]))}")
        if sweep is not None:
            ax.set_ylabel(f"{display(name)[0]} [{unit}]")
    if sweep is not None:
        axes[-1].set_xlabel(axis_label(sweep))
    _add_figure(section, figure, f"Monte Carlo: mean and quantile band of each QoI "
                f"({ds.attrs.get('n_samples', '?')} samples per point).", dpi)
    caveat = _interval_treatment_caveat(ds, "Monte Carlo")
    if caveat:
        section.caveats.append(caveat)
    return section


@renderer("pce")
def _render_pce(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    qois = _qois_of(ds)
    if not qois:
        return section
    figure = _new_figure(9.0, 3.2 * math.ceil(len(qois) / 2))
    axes = np.atleast_1d(figure.subplots(math.ceil(len(qois) / 2), 2)).ravel()
    for ax, name in zip(axes, qois):
        _, unit, factor = display(name)
        model = ds[f"{name}_validation_model"].values.ravel() * factor
        surrogate = ds[f"{name}_validation_surrogate"].values.ravel() * factor
        ax.plot(model, surrogate, linestyle="none", marker="o", markersize=3, color="black")
        finite = np.isfinite(model) & np.isfinite(surrogate)
        if finite.any():
            low = min(model[finite].min(), surrogate[finite].min())
            high = max(model[finite].max(), surrogate[finite].max())
            ax.plot([low, high], [low, high], color="0.5", linestyle="--", linewidth=1.0, label="exact")
        ax.set_xlabel(f"model: {display(name)[0]} [{unit}]")
        ax.set_ylabel(f"surrogate [{unit}]")
        error = np.asarray(ds[f"{name}_validation_error"].values, dtype=float)
        worst = float(np.nanmax(error)) if np.isfinite(error).any() else float("nan")
        loo = np.asarray(ds[f"{name}_loo_error"].values, dtype=float)
        best_loo = np.nanmin(loo, axis=-1) if np.isfinite(loo).any() else np.array([np.nan])
        ax.set_title(f"validation error up to {100 * worst:.3g} % of std", fontsize=9)
        orders = np.asarray(ds[f"{name}_order"].values).ravel()
        section.findings.append(
            f"{display(name)[0]}: polynomial order {', '.join(str(o) for o in sorted(set(orders.tolist())))} "
            f"chosen by leave-one-out error (at most {100 * float(np.nanmax(best_loo)):.3g} %); independent "
            f"validation error up to {100 * worst:.3g} % of the standard deviation")
        if not np.isfinite(worst) or worst > 0.1:
            section.caveats.append(f"{display(name)[0]}: the polynomial surrogate misses the model by "
                                   f"{100 * worst:.3g} % of its spread at independent check points; its "
                                   "moments and Sobol indices are unreliable there (non-smooth response?)")
    for ax in axes[len(qois):]:
        ax.set_visible(False)
    _add_figure(section, figure, "Polynomial chaos validation: surrogate against model at independent "
                "check points (all operating points).", dpi)
    caveat = _interval_treatment_caveat(ds, "polynomial chaos")
    if caveat:
        section.caveats.append(caveat)
    return section


# ---------------------------------------------------------------------------- sobol


def _sobol_bars(ax: Any, indices: xr.DataArray, confidence: xr.DataArray | None,
                parameters: Sequence[str]) -> None:
    positions = np.arange(len(parameters))
    for offset, (index_name, hatch, shade) in enumerate((("S1", "", 0.35), ("ST", "//", 0.8))):
        values = indices.sel(index=index_name).transpose("param").values
        errors = confidence.sel(index=index_name).transpose("param").values if confidence is not None else None
        ax.bar(positions + (offset - 0.5) * 0.38, values, width=0.38, yerr=errors, capsize=3,
               color=colormaps["cividis"](shade), edgecolor="black", hatch=hatch,
               label="first order $S_1$" if index_name == "S1" else "total order $S_T$")
    ax.set_xticks(positions, [short_name(p) for p in parameters], rotation=15, ha="right")
    ax.set_ylabel("Sobol index [-]")
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.legend(fontsize=7)


def _sobol_lines(ds: xr.Dataset, name: str, sweep: str, parameters: Sequence[str], level: float) -> Figure:
    indices = ds[name]
    confidence = ds.get(f"{name}_conf")
    figure = _new_figure(9.0, 3.8)
    ax = figure.subplots()
    x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
    cmap = colormaps["viridis"]
    for index, parameter in enumerate(parameters):
        total = indices.sel(index="ST", param=parameter).transpose(sweep).values
        colour = cmap(index / max(len(parameters) - 1, 1))
        ax.plot(x, total, linestyle=_LINE_STYLES[index % len(_LINE_STYLES)],
                marker=_MARKERS[index % len(_MARKERS)], markersize=4, color=colour, label=short_name(parameter))
        if confidence is not None:
            half = confidence.sel(index="ST", param=parameter).transpose(sweep).values
            ax.fill_between(x, total - half, total + half, color=colour, alpha=0.15)
    ax.set_xlabel(axis_label(sweep))
    ax.set_ylabel("total-order Sobol index $S_T$ [-]")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    ax.set_title(f"{display(name)[0]}: total-order Sobol indices (bands: {100 * level:g} % confidence "
                 "intervals)", fontsize=9)
    return figure


def _sobol_findings(ds: xr.Dataset, name: str, sweep: str | None, parameters: Sequence[str]) -> list[str]:
    title = display(name)[0]
    totals = ds[name].sel(index="ST")
    totals = totals.transpose(sweep, "param").values if sweep else totals.transpose("param").values[None, :]
    defined = np.isfinite(totals).any(axis=1)
    dominant = np.where(defined, np.argmax(np.nan_to_num(totals, nan=-np.inf), axis=1), -1)
    values = np.asarray(ds[sweep].values, float) if sweep else None
    sentences = []
    for start, stop in _runs_of_values(dominant):
        where = "" if sweep is None else " " + _range_text(sweep, values, start, stop)
        if dominant[start] < 0:
            sentences.append(f"{title}: indices undefined{where} (the QoI does not vary over the parameters)")
            continue
        ranking = np.argsort(-np.nan_to_num(totals[start], nan=-np.inf))
        sentences.append(f"{title}: {short_name(parameters[dominant[start]])} dominates{where} (S_T up to "
                         f"{np.nanmax(totals[start:stop + 1, dominant[start]]):.2f}); ranking"
                         + ("" if start == stop else " at the first point") + ": "
                         + ", ".join(f"{short_name(parameters[i])} {totals[start, i]:.2f}" for i in ranking))
    return sentences


@renderer("diagnose")
def _render_diagnose(ds: xr.Dataset, dpi: int) -> Section:
    from .diagnosis_report import gap_map_plot, spectra_plot

    section = _section(ds)
    content = _json_attr(ds, "diagnosis", {})
    verdict = str(content.get("verdict", ds.attrs.get("verdict", "?")))
    gap = content.get("gap", {})
    section.facts.append(("rig file", str(ds.attrs.get("rig", (content.get("rig") or {}).get("source", "")))))
    section.facts.append(("verdict", verdict))
    if gap:
        section.facts.append(("held-out gap, nominal model", f"{float(gap['baseline']):.3g}"))
        if gap.get("effect"):
            interval = gap.get("shrink_interval") or [math.nan, math.nan]
            section.facts.append((f"held-out gap with {gap['effect']}", f"{float(gap['with_effect']):.3g}"))
            section.facts.append(("shrink fraction (90 % interval)",
                                  f"{100 * float(gap['shrink_fraction']):.0f} % ({100 * float(interval[0]):.0f} "
                                  f"to {100 * float(interval[1]):.0f} %)"))
        section.facts.append(("evaluated on", str((gap.get("evaluated_on") or {}).get("scheme", ""))))
    if content.get("reason"):
        section.findings.append(f"verdict {verdict}: {content['reason']}")
    where = content.get("where") or []
    if where:
        section.findings.append("the nominal model misses most at " + "; ".join(
            f"{entry['channel']} {entry['feature']} (runs {', '.join(map(str, entry['ops']))}, "
            f"RMS z {float(entry['score']):.1f})" for entry in where[:4]))
    ranking = content.get("ranking") or []
    if ranking:
        def parameters(entry: dict) -> str:
            values = (entry.get("parameters") or {}).items()
            return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in values)

        rows = "".join(f"<tr><td>{html.escape(str(entry['effect']))}</td><td>{float(entry['score']):.1f}</td>"
                       f"<td>{100 * float(entry['shrink_fraction']):.0f} %</td>"
                       f"<td>{html.escape(parameters(entry))}</td></tr>" for entry in ranking)
        section.tables.append("<table><tr><th>candidate effect</th><th>score (nats)</th><th>shrink</th>"
                              f"<th>fitted parameters</th></tr>{rows}</table>")
    if "gap_map_nominal" in ds:
        figure = gap_map_plot(ds, "gap_map_nominal", "nominal model, held-out runs")
        section.figures.append(ReportFigure("Gap map of the nominal model on held-out runs (channel / feature "
                                            "family x run).", figure_png(figure, dpi)))
    if "gap_map_with_effect" in ds:
        figure = gap_map_plot(ds, "gap_map_with_effect", f"with {ds['candidate'].values[0]}, held-out runs")
        section.figures.append(ReportFigure("The same map with the best candidate effect added.",
                                            figure_png(figure, dpi)))
    if "amplitude_spectrum" in ds:
        section.figures.append(ReportFigure("Held-out spectra of the two runs with the largest nominal gap: rig, "
                                            "nominal model and model with the effect.",
                                            figure_png(spectra_plot(ds), dpi)))
    if verdict == "unexplained":
        section.caveats.append("a significant gap remains that no candidate effect of the library removes")
    return section


@renderer("calibrate")
def _render_calibrate(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    summary = _json_attr(ds, "calibration", {})
    converged = bool(summary.get("converged"))
    estimates = summary.get("parameters") if converged else (summary.get("unconverged_estimates") or {}).get(
        "parameters", {})
    rows = "".join(f"<tr><td>{html.escape(name)}</td><td>{values['q50']:.6g}</td><td>{values['q05']:.6g}</td>"
                   f"<td>{values['q95']:.6g}</td></tr>" for name, values in (estimates or {}).items())
    section.tables.append("<table><tr><th>parameter</th><th>median</th><th>5 %</th><th>95 %</th></tr>"
                          f"{rows}</table>")
    diagnostics = summary.get("diagnostics", {})
    section.facts.append(("rig file", str(summary.get("rig", ds.attrs.get("rig", "")))))
    section.facts.append(("converged", "yes" if converged else "NO: estimates are not a result"))
    for key, label in (("tau_max", "largest integrated autocorrelation time (steps)"),
                       ("rhat_max", "largest split R-hat"), ("ess_min", "smallest effective sample size"),
                       ("acceptance_mean", "mean acceptance fraction")):
        if key in diagnostics:
            section.facts.append((label, f"{float(diagnostics[key]):.4g}"))
    names = [name for name in ds.data_vars if set(ds[name].dims) == {"chain", "draw"}]
    if names:
        figure = _new_figure(9.0, 1.9 * ((len(names) + 2) // 3))
        axes = np.atleast_1d(figure.subplots((len(names) + 2) // 3, 3)).ravel()
        for ax, name in zip(axes, names):
            ax.hist(ds[name].values.ravel(), bins=40, color="0.35")
            ax.set_xlabel(axis_label(name), fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in axes[len(names):]:
            ax.set_visible(False)
        _add_figure(section, figure, "Posterior marginals of the calibrated parameters.", dpi)
    check = summary.get("predictive_check") or {}
    if "fraction_within_2_sigma" in check:
        verdict = "passed" if check.get("passed") else "FAILED: the model does not explain these data"
        section.findings.append(f"posterior predictive check with the real model {verdict}: "
                                f"{100 * float(check['fraction_within_2_sigma']):.0f} % of the features within "
                                f"2 sigma (noise and model error), largest |z| {float(check['max_abs_z']):.3g}")
    if not converged:
        section.caveats.append("the sampler did not converge: the estimates shown are not a result")
    return section


@renderer("sobol")
def _render_sobol(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    qois = [name for name in _qois_of(ds) if "param" in ds[name].dims]
    if not qois:
        return section
    parameters = [str(p) for p in ds["param"].values]
    sweep = _sweep_dim(ds, ("param", "param_2", "index", "bound", "sample", "statistic", "quantile", "order"))
    level = float(ds.attrs.get("conf_level", 0.95))
    for name in qois:
        indices = ds[name]
        confidence = ds.get(f"{name}_conf")
        points = [{}] if sweep is None else [{sweep: i} for i in range(ds.sizes[sweep])]
        if len(points) <= 4:
            figure = _new_figure(9.0, 3.4 * len(points))
            axes = np.atleast_1d(figure.subplots(len(points), 1, sharex=True))
            for ax, where in zip(axes, points):
                _sobol_bars(ax, indices.isel(where), None if confidence is None else confidence.isel(where),
                            parameters)
                title = f"{display(name)[0]}: Sobol indices, {100 * level:g} % confidence intervals"
                if where:
                    title += f" at {format_value(sweep, float(ds[sweep].values[where[sweep]]))}"
                ax.set_title(title, fontsize=9)
            _add_figure(section, figure, f"Sobol indices of {display(name)[0]} (bars: first and total "
                        "order, whiskers: bootstrap confidence intervals).", dpi)
        if sweep is not None and ds.sizes[sweep] >= 2:
            _add_figure(section, _sobol_lines(ds, name, sweep, parameters, level), f"Total-order Sobol "
                        f"indices of {display(name)[0]} against {short_name(sweep)}.", dpi)
        section.findings.extend(_sobol_findings(ds, name, sweep, parameters))
    treatment = str(ds.attrs.get("interval_treatment", ""))
    distributions = _json_attr(ds, "distribution_assumed", {})
    if distributions:
        assumed = [short_name(k) for k, v in distributions.items() if str(v).startswith("uniform on interval")]
        given = [f"{short_name(k)} {v}" for k, v in distributions.items()
                 if not str(v).startswith("uniform on interval")]
        if assumed:
            section.caveats.append("Sobol indices need distributions: the interval parameters "
                                   + ", ".join(assumed) + " are treated as uniform on their intervals, an "
                                   "assumption made for the sensitivity ranking only (an interval implies "
                                   "no distribution)")
        if given:
            section.caveats.append("Sobol indices use the distributions " + "; ".join(given))
    elif treatment:
        section.caveats.append(f"Sobol indices: interval parameters {treatment}")
    held = _json_attr(ds, "held_at_nominal", {})
    if held:
        section.caveats.append("held at nominal values: " + ", ".join(
            f"{short_name(k)} = {format_value(k, v)}" for k, v in held.items()))
    widths = [float(np.nanmax(ds[f"{name}_conf"].sel(index="ST").values)) for name in qois
              if f"{name}_conf" in ds and np.isfinite(ds[f"{name}_conf"].values).any()]
    if widths and max(widths) > 0.1:
        section.caveats.append(f"confidence intervals of the total-order indices reach ±{max(widths):.2f} "
                               f"with N = {ds.attrs.get('n_base', '?')} base samples: rankings closer than "
                               "that are not resolved (increase samples)")
    return section


def _runs_of_values(values: np.ndarray) -> list[tuple[int, int]]:
    ranges = []
    start = 0
    for index in range(1, len(values) + 1):
        if index == len(values) or values[index] != values[start]:
            ranges.append((start, index - 1))
            start = index
    return ranges


# ---------------------------------------------------------------------------- generic


def _render_generic(ds: xr.Dataset, dpi: int) -> Section:
    section = _section(ds)
    rows = "".join(f"<tr><td>{html.escape(str(name))}</td><td>{html.escape(str(dict(ds[name].sizes)))}</td>"
                   f"<td>{html.escape(str(ds[name].attrs.get('units', '')))}</td></tr>"
                   for name in ds.data_vars)
    section.tables.append(f"<table><tr><th>variable</th><th>dims</th><th>units</th></tr>{rows}</table>")
    return section


# ---------------------------------------------------------------------------- HTML


_STYLE = """
body { font-family: sans-serif; max-width: 1100px; margin: 2em auto; padding: 0 1em; color: #111; }
h1 { font-size: 1.6em; } h2 { font-size: 1.3em; border-bottom: 1px solid #999; margin-top: 2em; }
h3 { font-size: 1.1em; }
table { border-collapse: collapse; margin: 0.5em 0; font-size: 0.9em; }
td, th { border: 1px solid #bbb; padding: 2px 8px; text-align: left; vertical-align: top; }
th { background: #eee; }
figure { margin: 1em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: 0.9em; color: #333; }
.caveats li { color: #6b3a00; }
pre { background: #f4f4f4; padding: 0.5em; overflow-x: auto; font-size: 0.85em; }
"""


def _table(rows: Sequence[tuple[str, str]], header: tuple[str, str] | None = None, table_id: str = "") -> str:
    head = f"<tr><th>{html.escape(header[0])}</th><th>{html.escape(header[1])}</th></tr>" if header else ""
    body = "".join(f"<tr><td>{html.escape(str(a))}</td><td>{html.escape(str(b))}</td></tr>" for a, b in rows)
    identifier = f' id="{table_id}"' if table_id else ""
    return f"<table{identifier}>{head}{body}</table>"


def _list(items: Sequence[str], css_class: str = "") -> str:
    if not items:
        return "<p>None.</p>"
    css = f' class="{css_class}"' if css_class else ""
    return f"<ul{css}>" + "".join(f"<li>{html.escape(item)}</li>" for item in items) + "</ul>"


def _design_rows(ds: xr.Dataset) -> list[tuple[str, str]]:
    design = _json_attr(ds, "design", {})
    units = {"module": "m", "pressure_angle": "deg", "face_width": "m", "youngs_modulus": "Pa",
             "m1": "kg", "m2": "kg", "I1": "kg m²", "I2": "kg m²", "k1": "N/m", "k2": "N/m",
             "backlash": "m (total, 2b)", "ste_amplitude": "m", "z1": "teeth", "z2": "teeth"}
    return [(key, f"{value:.6g} {units.get(key, '')}".strip() if isinstance(value, (int, float)) else str(value))
            for key, value in design.items()]


def _uncertain_rows(ds: xr.Dataset) -> list[tuple[str, str]]:
    rows = []
    for name, entry in _json_attr(ds, "uncertain_parameters", {}).items():
        if entry.get("kind") == "interval":
            text = (f"interval [{format_value(name, entry['lower'])}, {format_value(name, entry['upper'])}]")
        else:
            parameters = ", ".join(f"{k}={v:.6g}" for k, v in entry.get("parameters", {}).items())
            text = f"{entry.get('distribution')}({parameters}) [{display(name)[1]}]"
        if entry.get("source") and entry.get("source") != "given":
            text += f"; {entry['source']}"
        rows.append((name, text))
    return rows


def build_report(results: Sequence[xr.Dataset], *, dpi: int = 110) -> str:
    """The HTML text of a report on the results of one run.

    Parameters
    ----------
    results : sequence of xarray.Dataset
        Analysis results as written by :func:`uqgear.analyses.run_study`
        (with their provenance attributes), in analysis order.
    dpi : int
        Figure resolution.

    Returns
    -------
    str
        One self-contained HTML document.
    """
    if not results:
        raise UqgearError("report: expected at least one analysis result; got none")
    first = results[0]
    sections = []
    for ds in results:
        kind = str(ds.attrs.get("analysis_type", ""))
        sections.append(RENDERERS.get(kind, _render_generic)(ds, dpi))
    study_name = str(first.attrs.get("study_name", "study"))
    versions = _json_attr(first, "provenance_versions", {})
    if "numba_target_cpu" in first.attrs:
        versions["kernels compiled for (CPU)"] = str(first.attrs["numba_target_cpu"])
    total_time = sum(float(ds.attrs.get("run_time_s", 0.0)) for ds in results)
    total_runs = sum(int(ds.attrs.get("model_runs", 0)) for ds in results)
    summary = [
        ("study", study_name),
        ("description", str(first.attrs.get("study_description", ""))),
        ("study file", str(first.attrs.get("study_path", ""))),
        ("design", f"{first.attrs.get('design_name', '')} (from {first.attrs.get('design_source', '')})"),
        ("design overrides", ", ".join(f"{k} = {v}" for k, v in _json_attr(first, "design_overrides", {}).items())
         or "none"),
        ("seed", str(first.attrs.get("study_seed", first.attrs.get("seed", "")))),
        ("analyses", ", ".join(f"{s.name} ({s.kind})" for s in sections)),
        ("model runs", str(total_runs)),
        ("run time", f"{total_time:.1f} s (sum over analyses)"),
        ("results created", str(first.attrs.get("created", ""))),
        ("report created", datetime.now(timezone.utc).isoformat(timespec="seconds")),
    ]
    parts = [
        "<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
        f"<title>uqgear report: {html.escape(study_name)}</title>", f"<style>{_STYLE}</style></head><body>",
        f"<h1>uqgear report: {html.escape(study_name)}</h1>",
        '<section id="summary"><h2>Study summary</h2>', _table(summary, table_id="summary-table"),
        '<h3 id="design">Design</h3>', _table(_design_rows(first), ("key", "value"), "design-table"),
        '<h3 id="uncertain">Uncertain parameters</h3>',
        _table(_uncertain_rows(first), ("parameter", "definition"), "uncertain-table")
        if _uncertain_rows(first) else "<p>None.</p>",
        '<h3 id="versions">Versions</h3>', _table(sorted(versions.items()), ("package", "version"),
                                                  "versions-table"),
        "</section>",
        '<section id="findings"><h2>Findings</h2>',
    ]
    for section in sections:
        if section.findings:
            parts.append(f"<h3>{html.escape(section.title)}</h3>" + _list(section.findings))
    parts.append("</section>")
    parts.append('<section id="caveats"><h2>Caveats</h2>')
    caveats = [f"{section.name}: {caveat}" for section in sections for caveat in section.caveats]
    parts.append(_list(caveats, "caveats"))
    parts.append("</section>")
    for section in sections:
        parts.append(f'<section class="analysis" id="analysis-{html.escape(section.name)}" '
                     f'data-type="{html.escape(section.kind)}">')
        parts.append(f"<h2>{html.escape(section.title)}</h2>")
        if section.description:
            parts.append(f"<p>{html.escape(section.description)}</p>")
        if section.facts:
            parts.append(_table(section.facts))
        for figure in section.figures:
            encoded = base64.b64encode(figure.png).decode("ascii")
            parts.append(f'<figure><img alt="{html.escape(figure.caption)}" '
                         f'src="data:image/png;base64,{encoded}"><figcaption>{html.escape(figure.caption)}'
                         "</figcaption></figure>")
        parts.extend(section.tables)
        parts.append("<h3>Findings</h3>" + _list(section.findings))
        parts.append("<h3>Caveats</h3>" + _list(section.caveats, "caveats"))
        parts.append("</section>")
    study_text = str(first.attrs.get("study", ""))
    if study_text:
        parts.append(f'<section id="study-text"><h2>Study definition</h2><pre>{html.escape(study_text)}</pre>'
                     "</section>")
    parts.append("</body></html>")
    return "\n".join(parts)


def load_results(directory: str | Path) -> list[xr.Dataset]:
    """The analysis results (``*.nc``) of a run folder, in analysis order.

    Raises
    ------
    UqgearError
        If the folder does not exist or holds no result files.
    """
    folder = Path(directory)
    if not folder.is_dir():
        raise UqgearError(f"{folder}: no such folder; expected the output folder of 'uqgear run'")
    paths = sorted(path for path in folder.glob("*.nc") if not path.name.startswith("."))
    if not paths:
        raise UqgearError(f"{folder}: no result files (*.nc); expected the output folder of 'uqgear run'")
    results = [load_result(path) for path in paths]
    for path, ds in zip(paths, results):
        if "analysis_type" not in ds.attrs:
            raise UqgearError(f"{path}: not an analysis result of 'uqgear run' (no analysis_type attribute)")
    return sorted(results, key=lambda ds: int(ds.attrs.get("analysis_index", 0)))


def write_report(directory: str | Path, *, dpi: int = 110) -> Path:
    """Build ``<directory>/report.html`` from the result files in the folder (written atomically)."""
    folder = Path(directory)
    text = build_report(load_results(folder), dpi=dpi)
    target = folder / REPORT_NAME
    write_text_atomic(target, text)
    return target


__all__ = ["build_report", "write_report", "load_results", "simulation_figure_png", "renderer", "RENDERERS",
           "regime_findings", "display", "axis_label", "format_value", "REPORT_NAME"]
