"""The report section of a ``runup`` analysis: the run-up and coast-down envelopes, their jumps, the order map.

Two figures: the peak mesh force per speed bin, run-up and coast-down, as bands over the interval
parameters with the jumps and the continuation's folds marked; and the order map of the DTE (the
largest amplitude of each order over the interval cases and both senses of travel). The findings say,
answer first, the largest peak on each ramp and where, the jump speeds beside the fold speeds, and the
speed ranges where run-up and coast-down differ (the hysteresis of coexisting responses).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from matplotlib import colormaps
from matplotlib.figure import Figure

from .finding import Finding
from .order_map_figures import order_map_figure
from .page import new_figure
from .sections import Section, add_figure, renderer, section_from_attrs

#: Relative difference of the run-up and coast-down peaks in a bin above which the bin is in the hysteresis.
HYSTERESIS_TOLERANCE = 0.1


def _ranges(mask: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> list[tuple[float, float]]:
    """Speed ranges (bin edges) of the runs of True in ``mask``."""
    ranges: list[tuple[float, float]] = []
    start = None
    for index, flag in enumerate([*mask.tolist(), False]):
        if flag and start is None:
            start = index
        elif not flag and start is not None:
            ranges.append((float(lower[start]), float(upper[index - 1])))
            start = None
    return ranges


def hysteresis(ds: xr.Dataset, tolerance: float = HYSTERESIS_TOLERANCE) -> list[tuple[float, float]]:
    """Speed ranges where the run-up's and the coast-down's peak mesh force differ in some interval case.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.report.runup_sections import hysteresis
    >>> peaks = np.array([[[100.0, 100.0, 100.0, 100.0]], [[100.0, 150.0, 160.0, 100.0]]])
    >>> ds = xr.Dataset(
    ...     {"peak_mesh_force_case": (("direction", "case", "pinion_speed"), peaks)},
    ...     coords={"direction": ["up", "down"], "pinion_speed": [1000.0, 1100.0, 1200.0, 1300.0],
    ...             "bin_lower": ("pinion_speed", [950.0, 1050.0, 1150.0, 1250.0]),
    ...             "bin_upper": ("pinion_speed", [1050.0, 1150.0, 1250.0, 1350.0])},
    ... )
    >>> hysteresis(ds)
    [(1050.0, 1250.0)]
    """
    if "peak_mesh_force_case" not in ds or set(ds["direction"].values) != {"up", "down"}:
        return []
    peaks = ds["peak_mesh_force_case"].transpose("direction", "case", "pinion_speed")
    up = np.asarray(peaks.sel(direction="up").values, dtype=float)
    down = np.asarray(peaks.sel(direction="down").values, dtype=float)
    scale = np.maximum(np.abs(up), np.abs(down))
    differ = (np.abs(up - down) > tolerance * scale).any(axis=0)
    return _ranges(differ, ds["bin_lower"].values, ds["bin_upper"].values)


def _span(ds: xr.Dataset) -> str:
    start, stop, rate = (float(ds.attrs[key]) for key in ("speed_start", "speed_stop", "ramp_rate"))
    text = f"{start:.0f}-{stop:.0f} rpm at {rate:g} rpm/s"
    if "case_adhesion_torque" in ds.coords:
        t2 = np.asarray(ds["case_adhesion_torque"].values, dtype=float)
        text += f", T2 = {t2.min() / 1e3:.1f}-{t2.max() / 1e3:.1f} kN m"
    return text


def _peak_finding(ds: xr.Dataset) -> Finding:
    peak = ds["peak_mesh_force_case"]
    parts, facts = [], {}
    for direction in peak["direction"].values:
        values = peak.sel(direction=direction)
        flat = int(np.nanargmax(values.values))
        case, bin_index = np.unravel_index(flat, values.shape)
        speed = float(values["pinion_speed"].values[bin_index])
        facts[f"peak_{direction}"] = float(values.values[case, bin_index])
        facts[f"speed_{direction}"] = speed
        name = "run-up" if direction == "up" else "coast-down"
        parts.append(f"{name} {facts[f'peak_{direction}'] / 1e3:.1f} kN at {speed:.0f} rpm")
    text = f"Run-up and coast-down {_span(ds)}: peak mesh force " + ", ".join(parts)
    return Finding(text, facts, "runup")


def _jump_finding(ds: xr.Dataset) -> Finding | None:
    if "jump_speed" not in ds:
        return None
    width = float(ds.attrs.get("jump_bin", np.nanmax(ds["bin_upper"].values - ds["bin_lower"].values)))
    parts: list[str] = []
    facts: dict[str, Any] = {"bin_width": width}
    for direction in ds["direction"].values:
        speeds = ds["jump_speed"].sel(direction=direction).values
        found = np.unique(speeds[np.isfinite(speeds)])
        name = "the run-up" if direction == "up" else "the coast-down"
        facts[f"jumps_{direction}"] = found.tolist()
        parts.append(f"{name} at {', '.join(f'{s:.0f}' for s in found)} rpm" if found.size else f"{name} nowhere")
    text = "The peak mesh force jumps: " + "; ".join(parts)
    if "fold_speed" in ds:
        folds = [
            f"{float(s):.0f} rpm ({str(w)})"
            for s, w in zip(ds["fold_speed"].values.ravel(), ds["fold_sweep"].values.ravel())
            if np.isfinite(s)
        ]
        distance = np.abs(ds["jump_fold_distance"].values)
        facts["fold_speeds"] = [float(s) for s in ds["fold_speed"].values.ravel() if np.isfinite(s)]
        text += f"; continuation's folds at {', '.join(folds) or 'none in the span'}"
        if np.isfinite(distance).any():
            facts["largest_distance"] = float(np.nanmax(distance))
            text += f", the jumps within {facts['largest_distance']:.0f} rpm of them (located to {width:.0f} rpm)"
    return Finding(text, facts, "runup")


def runup_statements(ds: xr.Dataset) -> list[Finding]:
    """The first screen's statements of one ``runup`` result: peaks, jumps beside folds, hysteresis."""
    findings = [_peak_finding(ds)]
    jumps = _jump_finding(ds)
    if jumps is not None:
        findings.append(jumps)
    ranges = hysteresis(ds)
    if ranges:
        spans = ", ".join(f"{low:.0f}-{high:.0f} rpm" for low, high in ranges)
        findings.append(
            Finding(
                f"Run-up and coast-down differ by more than {HYSTERESIS_TOLERANCE:.0%} between {spans}: coexisting "
                "responses, the run-up on the branch from below and the coast-down on the one from above",
                {"hysteresis": ranges},
                "runup",
            )
        )
    return findings


def runup_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """The first screen's statements of every ``runup`` result."""
    found = [ds for ds in results if str(ds.attrs.get("analysis_type", "")) == "runup"]
    return [finding for ds in found for finding in runup_statements(ds)]


def _envelope_figure(ds: xr.Dataset) -> Figure:
    figure = new_figure(9.0, 4.8)
    ax = figure.subplots()
    speeds = np.asarray(ds["pinion_speed"].values, dtype=float)
    peak = ds["peak_mesh_force_case"] / 1e3
    for index, direction in enumerate(peak["direction"].values):
        colour = colormaps["cividis"](0.15 + 0.6 * index)
        values = peak.sel(direction=direction)
        label = "run-up" if direction == "up" else "coast-down"
        ax.fill_between(speeds, values.min("case"), values.max("case"), step="mid", color=colour, alpha=0.35)
        ax.step(speeds, values.max("case"), where="mid", color=colour, label=f"{label} (band over the cases)")
        if "jump_speed" in ds:
            for speed in np.unique(ds["jump_speed"].sel(direction=direction).values):
                if np.isfinite(speed):
                    ax.axvline(float(speed), color=colour, linestyle=":", linewidth=1.0)
    if "fold_speed" in ds:
        for speed in np.unique(ds["fold_speed"].values):
            if np.isfinite(speed):
                ax.axvline(float(speed), color="red", linewidth=0.8, alpha=0.6)
        ax.plot([], [], color="red", linewidth=0.8, label="continuation fold")
    ax.set_xlabel("pinion speed [rpm]")
    ax.set_ylabel("peak mesh force per speed bin [kN]")
    ax.legend(fontsize=7, loc="best")
    return figure


@renderer("runup")
def _render_runup(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    if "peak_mesh_force_case" not in ds:
        return section
    add_figure(
        section,
        _envelope_figure(ds),
        f"Peak mesh force along the ramps, {_span(ds)} (dotted: jumps; red: folds of the continued branches)",
        dpi,
    )
    if "order_amplitude" in ds:
        add_figure(
            section,
            order_map_figure(ds[["order_amplitude"]], "te"),
            "Order map of the DTE over the ramp (largest over the interval cases and both senses of travel)",
            dpi,
        )
    section.findings.extend(finding.text for finding in runup_statements(ds))
    names = json.loads(str(ds.attrs.get("parameters", "[]")))
    section.facts.append(("bounded over", ", ".join(names) or "nothing (single values)"))
    section.facts.append(("interval cases", str(ds.sizes.get("case", 1))))
    section.facts.append(("ramp simulation time", f"{float(ds.attrs.get('runup_seconds', np.nan)):.1f} s"))
    return section


__all__ = ["runup_findings", "runup_statements", "hysteresis", "HYSTERESIS_TOLERANCE"]
