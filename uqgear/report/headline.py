"""The few statements a gear designer acts on, computed from a study's result Datasets.

:func:`headline_findings` returns them as :class:`~uqgear.report.finding.Finding` objects (the
sentence and the numbers it rests on); the study report shows them first, in its "What this shows"
block. Each statement is made from the simulated runs themselves (the speed x T2 grids of the
bifurcation and regime-map analyses, the Sobol indices), never from a surrogate: the worst dynamic
load and where; where the teeth separate at each end of the T2 interval (wet and dry rail); whether
back-side contact ever occurs; the speed windows, per T2, where the response is not period-1; the
largest Sobol driver of each QoI per speed; and the statements of calibration and diagnosis results.
A rating's verdict comes first: per failure mode, the smallest ISO 6336 safety factor over the
interval, where, against the required minimum, and the fatigue damage over the stated service.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr

from .calibration_report import calibration_findings
from .coexistence_sections import coexistence_headline
from .continuation_sections import continuation_findings
from .diagnosis_report import diagnosis_findings
from .finding import Finding
from .findings import SPEED, T2, Grid, condition_text, grid, grids, t2_interval, t2_interval_end, true_index_runs
from .prediction_sections import prediction_findings
from .presentation import display, format_value, short_name
from .rating_sections import rating_findings
from .runup_sections import runup_findings
from .sections import json_attr

# ---------------------------------------------------------------------------- wording


def _speed(value: float) -> str:
    return format_value(SPEED, value)


def _t2(value: float) -> str:
    return format_value(T2, value)


def _t2_lead(value: float, interval: tuple[float, float, bool] | None) -> str:
    """'Wet rail (T2 = 21.15 kN m, low end of its interval)', 'T2 = 30 kN m', ..."""
    if not np.isfinite(value):
        return "At the T2 of each operating point"
    end = t2_interval_end(value, interval)
    if not end:
        return f"At T2 = {_t2(value)}"
    if interval is not None and interval[2]:
        rail = "Wet rail" if end == "low" else "Dry rail"
        return f"{rail} (T2 = {_t2(value)}, {end} end of its interval)"
    return f"At the {end} end of the T2 interval (T2 = {_t2(value)})"


def _t2_where(value: float, interval: tuple[float, float, bool] | None) -> str:
    """'T2 = 46.52 kN m (dry rail)' for the middle of a sentence."""
    if not np.isfinite(value):
        return "the T2 of that operating point"
    end = t2_interval_end(value, interval)
    if end and interval is not None and interval[2]:
        return f"T2 = {_t2(value)} ({'wet' if end == 'low' else 'dry'} rail)"
    return f"T2 = {_t2(value)}" + (f" ({end} end of its interval)" if end else "")


def _t2_span(values: np.ndarray) -> str:
    """'T2 21.15-46.52 kN m', 'T2 = 4.81 kN m' or '' over the finite values."""
    values = values[np.isfinite(values)]
    if not values.size:
        return ""
    if values.min() == values.max():
        return f"T2 = {_t2(values.min())}"
    return f"T2 {values.min() * 1e-3:.4g}-{_t2(values.max())}"


def _labels_text(labels: Sequence[str]) -> str:
    """Regime labels in the order given; more than three period-n labels as one 'period-n with n = ...'."""
    periods = [label for label in labels if label.startswith("period-")]
    if len(periods) <= 3:
        return ", ".join(labels)
    numbers = ", ".join(
        sorted(
            (label.split("-", 1)[1] for label in periods),
            key=lambda n: (not n.isdigit(), int(n) if n.isdigit() else 0, n),
        )
    )
    shown = [f"period-n with n = {numbers}"] + [label for label in labels if not label.startswith("period-")]
    return ", ".join(shown)


def _ranges(mask: np.ndarray, speeds: np.ndarray) -> list[tuple[float, float]]:
    return [(float(speeds[a]), float(speeds[b])) for a, b in true_index_runs(mask)]


def _ranges_text(ranges: Sequence[tuple[float, float]], speeds: np.ndarray, top: bool = True) -> str:
    """'between 3650 and 6000 rpm (the top of the sweep) and at 6100 rpm'; ``top``: say where a range
    reaches the highest speed simulated (it may go on above it)."""
    parts = []
    for low, high in ranges:
        text = f"at {_speed(low)}" if low == high else f"between {low:.4g} and {_speed(high)}"
        if top and high == speeds[-1] and speeds.size > 1:
            text += " (the top of the sweep)"
        parts.append(text)
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def _resolution(g: Grid) -> str:
    steps = np.diff(g.speeds)
    if steps.size and np.allclose(steps, steps[0]):
        return f"{g.source} runs, every {steps[0]:.4g} rpm"
    return f"{g.source} runs, {g.speeds.size} speeds"


# ---------------------------------------------------------------------------- statements


def worst_load_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """The largest dynamic load over every simulated grid run, and where."""
    interval = t2_interval(results)
    for name in ("peak_mesh_force", "dynamic_load_factor"):
        found = [g for g in grids(results, name) if np.isfinite(g.values.astype(float)).any()]
        if found:
            break
    else:
        return []
    value, g, i, j = _grid_max(found)
    runs = _finite_runs(found)
    sources = list(dict.fromkeys(item.source for item in found))
    facts: dict[str, Any] = {
        "qoi": name,
        "value": value,
        "speed": float(g.speeds[i]),
        "t2": float(g.t2[j]),
        "source": g.source,
        "runs": runs,
        "sources": sources,
    }
    where = f"at {_speed(g.speeds[i])}, {_t2_where(g.t2[j], interval)}"
    of_runs = f"; largest of the {runs} runs of {' and '.join(sources)}."
    if name == "dynamic_load_factor":
        text = (
            "Worst dynamic load factor (peak mesh force over the run's own static mesh force, not over the "
            f"rated load) {value:.3g} {where}{of_runs}"
        )
        return [Finding(text, facts, "worst_load")]
    text = f"Worst dynamic load: peak mesh force {value / 1e3:.4g} kN {where}"
    rated = [g for g in grids(results, "load_factor_rated") if np.isfinite(g.values.astype(float)).any()]
    if rated:
        factor, g_rated, a, b = _grid_max(rated)
        facts.update(
            factor_rated=factor,
            factor_speed=float(g_rated.speeds[a]),
            factor_t2=float(g_rated.t2[b]),
            factor_source=g_rated.source,
        )
        if (g_rated.speeds[a], g_rated.t2[b]) == (g.speeds[i], g.t2[j]):
            text += f", {factor:.3g} x the mesh force at rated torque"
        else:
            text += (
                f"; the largest factor over the mesh force at rated torque, {factor:.3g}, is at "
                f"{_speed(g_rated.speeds[a])}, {_t2_where(g_rated.t2[b], interval)}"
            )
    return [Finding(text + of_runs, facts, "worst_load")]


def _finite_runs(found: Sequence[Grid]) -> int:
    """How many grid points have a value (failed runs have NaN)."""
    return int(sum(np.isfinite(g.values.astype(float)).sum() for g in found))


def _failed(count: int) -> str:
    return f" ({count} failed runs not counted)" if count else ""


def _grid_max(found: Sequence[Grid]) -> tuple[float, Grid, int, int]:
    """The largest finite value over the grids: (value, grid, speed index, T2 index); first one on ties."""
    best: tuple[float, Grid, int, int] | None = None
    for g in found:
        values = g.values.astype(float)
        if not np.isfinite(values).any():
            continue
        i, j = np.unravel_index(int(np.nanargmax(values)), values.shape)
        if best is None or values[i, j] > best[0]:
            best = (float(values[i, j]), g, int(i), int(j))
    assert best is not None
    return best


def separation_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """Where the teeth separate, at each end of the T2 interval separately.

    From the grid with the finest speed steps that holds at least two T2 values (the interval's ends
    when the study sweeps T2 over its interval)."""
    candidates = grids(results, "fraction_separation")
    if not candidates:
        return []
    g = max(candidates, key=lambda item: (item.t2.size >= 2, item.speeds.size, item.t2.size))
    interval = t2_interval(results)
    ends = [(0, "low"), (g.t2.size - 1, "high")] if g.t2.size >= 2 else [(0, "only")]
    findings = []
    for j, end in ends:
        column = g.values[:, j].astype(float)
        ranges = _ranges(column > 0.0, g.speeds)
        peak = int(np.nanargmax(column)) if np.isfinite(column).any() else 0
        facts: dict[str, Any] = {
            "source": g.source,
            "t2": float(g.t2[j]),
            "end": end,
            "ranges": ranges,
            "max_fraction": float(np.nanmax(column)) if np.isfinite(column).any() else float("nan"),
            "max_speed": float(g.speeds[peak]),
        }
        lead = _t2_lead(g.t2[j], interval)
        if ranges:
            text = (
                f"{lead}: teeth separate {_ranges_text(ranges, g.speeds)}, up to "
                f"{100 * facts['max_fraction']:.3g} % of the time (at {_speed(g.speeds[peak])}); "
                f"{_resolution(g)}."
            )
        else:
            text = (
                f"{lead}: the teeth stay in contact at every speed from {g.speeds[0]:.4g} to "
                f"{_speed(g.speeds[-1])}{_failed(int((~np.isfinite(column)).sum()))}; {_resolution(g)}."
            )
        findings.append(Finding(text, facts, "separation"))
    return findings


def back_contact_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """Whether back-side contact (impact on the rear flanks) occurs in any simulated grid run, and where."""
    found = grids(results, "fraction_back_contact")
    if not found:
        return []
    interval = t2_interval(results)
    runs = _finite_runs(found)
    failed = sum(g.values.size for g in found) - runs
    sources = list(dict.fromkeys(g.source for g in found))
    speeds = np.concatenate([g.speeds for g in found])
    value, g, i, j = _grid_max(found)
    facts: dict[str, Any] = {"occurs": value > 0.0, "max_fraction": value, "runs": runs, "sources": sources}
    if value <= 0.0:
        t2 = _t2_span(np.concatenate([item.t2 for item in found]))
        span = f"speed {speeds.min():.4g}-{_speed(speeds.max())}" + (f", {t2}" if t2 else "")
        text = (
            f"No back-side contact (impact on the rear flanks) in any of the {runs} runs of "
            f"{' and '.join(sources)} ({span}){_failed(failed)}."
        )
        return [Finding(text, facts, "back_contact")]
    values = g.values.astype(float)
    by_t2: list[dict[str, Any]] = [
        {"t2": float(g.t2[k]), "ranges": _ranges(values[:, k] > 0.0, g.speeds)}
        for k in range(g.t2.size)
        if (values[:, k] > 0.0).any()
    ]
    facts.update(speed=float(g.speeds[i]), t2=float(g.t2[j]), source=g.source, by_t2=by_t2)
    shown = "; ".join(
        f"{_t2_where(entry['t2'], interval)} {_ranges_text(entry['ranges'], g.speeds)}" for entry in by_t2[:4]
    )
    more = f"; and at {len(by_t2) - 4} more T2 values" if len(by_t2) > 4 else ""
    text = (
        f"Back-side contact (impact on the rear flanks) occurs, up to {100 * value:.3g} % of the time at "
        f"{_speed(g.speeds[i])}, {_t2_where(g.t2[j], interval)}; in {g.source}: {shown}{more}."
    )
    return [Finding(text, facts, "back_contact")]


def regime_findings_headline(results: Sequence[xr.Dataset]) -> list[Finding]:
    """Speed windows where the response is not period-1, per T2 value, with the labels found there.

    From the grid with the most T2 values (the regime map); any label other than ``period-1``
    counts (period-n, quasi-periodic, chaotic, uncertain, ...)."""
    candidates = grids(results, "regime")
    if not candidates:
        return []
    g = max(candidates, key=lambda item: (item.t2.size, item.speeds.size))
    interval = t2_interval(results)
    labels = g.values.astype(str)
    other = labels != "period-1"
    found = list(dict.fromkeys(labels.T[other.T].tolist()))  # in order of T2, then speed
    windows: list[dict[str, Any]] = []
    for j in range(g.t2.size):
        if other[:, j].any():
            ranges = true_index_runs(other[:, j])
            windows.append(
                {
                    "t2": float(g.t2[j]),
                    "ranges": [(float(g.speeds[a]), float(g.speeds[b])) for a, b in ranges],
                    "labels": [list(dict.fromkeys(labels[a : b + 1, j].tolist())) for a, b in ranges],
                }
            )
    quiet = ~other.any(axis=0)
    facts: dict[str, Any] = {
        "source": g.source,
        "labels": found,
        "windows": windows,
        "period1_t2": [float(v) for v in g.t2[quiet]],
        "points": int(labels.size),
    }
    span = f"speed {g.speeds[0]:.4g}-{_speed(g.speeds[-1])}"
    if not windows:
        t2 = _t2_span(g.t2)
        text = f"Period-1 (harmonic) response at all {labels.size} points of {g.source} ({span}" + (
            f", {t2})." if t2 else ")."
        )
        return [Finding(text, facts, "regimes")]
    parts = []
    for window in windows:
        spans = ", ".join(
            f"{_ranges_text([r], g.speeds, top=False)} ({_labels_text(names)})"
            for r, names in zip(window["ranges"], window["labels"])
        )
        parts.append(f"at {_t2_where(window['t2'], interval)} {spans}")
    text = f"Response not period-1 (labels found: {_labels_text(found)}): " + "; ".join(parts)
    if quiet.any():
        condition = condition_text(T2, g.t2, quiet)
        text += f"; period-1 at every speed {condition}"
    return [Finding(text + f" ({g.source}, {span}).", facts, "regimes")]


def sobol_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """The largest total-order Sobol index of each QoI per speed, and whether it is resolved."""
    findings = []
    for ds in results:
        if str(ds.attrs.get("analysis_type")) != "sobol" or "param" not in ds.dims:
            continue
        options = json_attr(ds, "analysis_options", {})
        level = float(ds.attrs.get("conf_level", options.get("confidence_level", 0.95)))
        parameters = [str(p) for p in ds["param"].values]
        for name in options.get("qois", []):
            if name not in ds or set(ds[name].dims) - {"param", "index", SPEED} or "index" not in ds[name].dims:
                continue
            totals = ds[name].sel(index="ST")
            half = ds[f"{name}_conf"].sel(index="ST") if f"{name}_conf" in ds else xr.zeros_like(totals)
            if SPEED in totals.dims:
                speeds = np.asarray(ds[SPEED].values, dtype=float)
                totals, half = totals.transpose(SPEED, "param").values, half.transpose(SPEED, "param").values
            else:
                speeds = np.array([np.nan])
                totals, half = totals.transpose("param").values[None], half.transpose("param").values[None]
            points: list[dict[str, Any]] = []
            for k in range(speeds.size):
                if not np.isfinite(totals[k]).any():
                    points.append({"speed": float(speeds[k]), "top": None})
                    continue
                order = np.argsort(-np.nan_to_num(totals[k], nan=-np.inf), kind="stable")
                top, second = int(order[0]), (int(order[1]) if order.size > 1 else None)
                resolved = second is None or bool(totals[k, top] - half[k, top] > totals[k, second] + half[k, second])
                points.append(
                    {
                        "speed": float(speeds[k]),
                        "top": parameters[top],
                        "st": float(totals[k, top]),
                        "runner_up": None if second is None else parameters[second],
                        "runner_up_st": None if second is None else float(totals[k, second]),
                        "resolved": resolved,
                    }
                )
            findings.append(
                Finding(
                    _sobol_text(name, points, level),
                    {
                        "source": str(ds.attrs.get("analysis_name", "sobol")),
                        "qoi": name,
                        "points": points,
                        "conf_level": level,
                    },
                    "sobol",
                )
            )
    return findings


def _sobol_text(name: str, points: list[dict[str, Any]], level: float) -> str:
    groups: list[list[dict[str, Any]]] = []
    for point in points:
        if groups and groups[-1][0]["top"] == point["top"]:
            groups[-1].append(point)
        else:
            groups.append([point])
    parts = []
    for group in groups:
        if not np.isfinite(group[0]["speed"]):
            where = "at the study's operating point"
        elif len(group) > 4:
            where = f"from {group[0]['speed']:.4g} to {_speed(group[-1]['speed'])} ({len(group)} speeds)"
        else:
            shown = [f"{p['speed']:.4g}" for p in group]
            where = "at " + (shown[0] if len(shown) == 1 else ", ".join(shown[:-1]) + " and " + shown[-1]) + " rpm"
        if group[0]["top"] is None:
            parts.append(f"undefined {where} (the QoI does not vary)")
            continue
        values = ", ".join(f"{p['st']:.2f}" for p in group)
        parts.append(f"{short_name(group[0]['top'])} {where} (S_T {values})")
    quantity = display(name)[0].split(" (")[0]
    text = f"Largest driver of {quantity} (total Sobol index S_T): " + "; ".join(parts)
    unresolved = [p for p in points if p["top"] is not None and not p["resolved"]]
    if unresolved:
        text += f"; the lead is within the {100 * level:g} % confidence intervals of the runner-up " + ", ".join(
            ("" if not np.isfinite(p["speed"]) else f"at {_speed(p['speed'])} ")
            + f"({short_name(p['runner_up'])}, {p['runner_up_st']:.2f})"
            for p in unresolved
        )
    return text + "."


def rig_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """The headline statements of calibration and diagnosis results in a study."""
    findings = []
    for ds in results:
        kind = str(ds.attrs.get("analysis_type", ""))
        if kind == "calibrate":
            findings += calibration_findings(json_attr(ds, "calibration", {}))
        elif kind == "diagnose":
            findings += diagnosis_findings(json_attr(ds, "diagnosis", {}))
    return findings


def headline_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """Every headline statement of a study's results, in the order the report shows them."""
    return [
        *rating_findings(results),
        *prediction_findings(results),
        *worst_load_findings(results),
        *separation_findings(results),
        *back_contact_findings(results),
        *regime_findings_headline(results),
        *coexistence_headline(results),
        *continuation_findings(results),
        *runup_findings(results),
        *sobol_findings(results),
        *rig_findings(results),
    ]


def headline_note(results: Sequence[xr.Dataset]) -> str:
    """What the grid runs held fixed (drive torque, the other uncertain parameters), in one line."""
    for ds in results:
        if grid(ds, "regime") is None and grid(ds, "fraction_separation") is None:
            continue
        fixed = {
            k: v
            for k, v in json_attr(ds, "fixed_inputs", {}).items()
            if isinstance(v, (int, float)) and k not in (SPEED, T2)
        }
        if fixed:
            return (
                "Speed sweeps run with "
                + ", ".join(f"{short_name(k)} = {format_value(k, v)}" for k, v in fixed.items())
                + ". Details, figures and caveats below; provenance at the end."
            )
    return "Details, figures and caveats below; provenance at the end."


__all__ = [
    "headline_findings",
    "headline_note",
    "worst_load_findings",
    "separation_findings",
    "back_contact_findings",
    "regime_findings_headline",
    "sobol_findings",
    "rig_findings",
]
