"""Report section and findings of the ``continuation`` analysis: branches over the brute-force sweeps.

Every number stated is computed here from the result Dataset (:func:`continuation_facts`), so a test
can recompute it from the netCDF file: per case (an end of the T2 interval, say) where the teeth
begin to separate, where two stable responses coexist and with which peak mesh forces, where an up-
and a down-sweep jump, the first period doubling and Neimark-Sacker points, and each bifurcation's
interval over the cases.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, cast

import numpy as np
import xarray as xr
from matplotlib import colormaps

from .finding import Finding
from .page import new_figure
from .presentation import axis_label, format_value, short_name
from .sections import Section, add_figure, json_attr, renderer, section_from_attrs

#: Stability-changing bifurcations (a stable stretch ends at one of these).
STABILITY_TYPES = ("fold", "period_doubling", "neimark_sacker", "branch_point")
#: Colours of the brute-force sweep points (colour-blind safe, and told apart by marker shape too).
SWEEP_STYLE = {"up": ("#0072B2", "^", "up-sweep"), "down": ("#D55E00", "v", "down-sweep")}
#: Bifurcation markers.
BIFURCATION_MARKERS = {
    "fold": ("o", "fold"),
    "period_doubling": ("s", "period doubling"),
    "neimark_sacker": ("D", "Neimark-Sacker"),
    "branch_point": ("P", "branch point"),
    "grazing_separation": ("x", "grazing: separation begins"),
    "grazing_back_side": ("+", "grazing: back-side impact begins"),
}
#: Relative change of the peak mesh force between neighbouring sweep points taken as a jump.
JUMP_FRACTION = 0.1


def _names(ds: xr.Dataset) -> list[str]:
    """The variable names of a continuation result (strings, as the analysis writes them)."""
    return cast(list[str], list(ds.data_vars))


def _case_label(ds: xr.Dataset, case: int) -> str:
    names = [name[len("case_") :] for name in _names(ds) if name.startswith("case_")]
    if not names:
        fixed = json_attr(ds, "fixed_inputs", {})
        shown = [
            f"{short_name(name)} = {format_value(name, float(fixed[name]))}"
            for name in ("drive_torque", "adhesion_torque")
            if isinstance(fixed.get(name), (int, float))
        ]
        return ", ".join(shown) or "the study's inputs"
    return ", ".join(
        f"{short_name(name)} = {format_value(name, float(ds[f'case_{name}'].values[case]))}" for name in names
    )


def _table(ds: xr.Dataset, case: int) -> list[dict[str, Any]]:
    rows = []
    kinds = np.asarray(ds["bifurcation_type"].values)[case].astype(str)
    for k, kind in enumerate(kinds):
        if not kind:
            continue
        rows.append(
            {
                name[len("bifurcation_") :]: ds[name].values[case, k].item()
                for name in _names(ds)
                if name.startswith("bifurcation_") and ds[name].dims == ("case", "bifurcation")
            }
        )
    return rows


def stable_stretches(ds: xr.Dataset, case: int) -> list[dict[str, Any]]:
    """Stable stretches of every branch: parameter range (ends at the bifurcation where stability changes)
    and the parameter and peak mesh force of their points."""
    stretches = []
    table = _table(ds, case)
    for branch in range(ds.sizes["branch"]):
        stable = np.asarray(ds["stable"].values[case, branch])
        parameter = np.asarray(ds["parameter"].values[case, branch], dtype=float)
        force = np.asarray(ds["peak_mesh_force"].values[case, branch], dtype=float)
        arclength = np.asarray(ds["arclength"].values[case, branch], dtype=float)
        index = 0
        while index < stable.size:
            if stable[index] != 1:
                index += 1
                continue
            stop = index
            while stop + 1 < stable.size and stable[stop + 1] == 1:
                stop += 1
            ends = [parameter[index], parameter[stop]]
            kinds = ["", ""]
            for position, neighbour in ((0, index - 1), (1, stop + 1)):
                if 0 <= neighbour < stable.size and stable[neighbour] == 0:
                    low, high = sorted((arclength[neighbour], arclength[index if position == 0 else stop]))
                    found = [
                        row
                        for row in table
                        if row["branch"] == branch
                        and row["type"] in STABILITY_TYPES
                        and low <= row["arclength"] <= high
                    ]
                    if found:
                        ends[position], kinds[position] = float(found[0]["parameter"]), str(found[0]["type"])
            order = np.argsort(ends)
            stretches.append(
                {
                    "branch": branch,
                    "period": int(ds["branch_period"].values[case, branch]),
                    "low": float(ends[order[0]]),
                    "high": float(ends[order[1]]),
                    "low_kind": kinds[order[0]],
                    "high_kind": kinds[order[1]],
                    "parameter": parameter[index : stop + 1],
                    "force": force[index : stop + 1],
                }
            )
            index = stop + 1
    return stretches


def coexistence(ds: xr.Dataset, case: int) -> list[dict[str, Any]]:
    """Parameter ranges where two (or more) stable orbits coexist, with their peak mesh forces at the middle."""
    stretches = stable_stretches(ds, case)
    # stretches that only touch (a parent and its doubled orbit at a period doubling) do not coexist
    least = 10.0 * float(ds.attrs.get("location_tolerance", 0.0))
    found = []
    for a in range(len(stretches)):
        for b in range(a + 1, len(stretches)):
            low = max(stretches[a]["low"], stretches[b]["low"])
            high = min(stretches[a]["high"], stretches[b]["high"])
            if high - low <= least:
                continue
            middle = 0.5 * (low + high)
            forces = []
            for stretch in (stretches[a], stretches[b]):
                order = np.argsort(stretch["parameter"])
                forces.append(float(np.interp(middle, stretch["parameter"][order], stretch["force"][order])))
            low_kind = max((stretches[a], stretches[b]), key=lambda item: item["low"])["low_kind"]
            high_kind = min((stretches[a], stretches[b]), key=lambda item: item["high"])["high_kind"]
            found.append(
                {
                    "low": low,
                    "high": high,
                    "middle": middle,
                    "forces": sorted(forces),
                    "periods": sorted([stretches[a]["period"], stretches[b]["period"]]),
                    "between_folds": low_kind == high_kind == "fold",
                }
            )
    return sorted(found, key=lambda item: item["low"])


def sweep_jumps(ds: xr.Dataset, case: int, start: str) -> list[tuple[float, float]]:
    """Neighbouring sweep values between which the sweep's peak mesh force jumps (more than ``JUMP_FRACTION``)."""
    values = np.asarray(ds["sweep_value"].values, dtype=float)
    force = np.asarray(ds["sweep_peak_mesh_force"].sel(start=start).values[case], dtype=float)
    change = np.abs(np.diff(force)) / np.maximum(np.abs(force[:-1]), 1e-300)
    return [(float(values[i]), float(values[i + 1])) for i in np.nonzero(change > JUMP_FRACTION)[0]]


def first_separation(ds: xr.Dataset, case: int, start: str = "up") -> float:
    """The first sweep value with the teeth apart some of the time (NaN if none)."""
    values = np.asarray(ds["sweep_value"].values, dtype=float)
    fraction = np.asarray(ds["sweep_fraction_separation"].sel(start=start).values[case], dtype=float)
    hits = np.nonzero(fraction > 0)[0]
    return float(values[hits[0]]) if hits.size else float("nan")


def continuation_facts(ds: xr.Dataset) -> dict[str, Any]:
    """Every number the section and the headline state, per case and over the cases."""
    cases = []
    for case in range(ds.sizes.get("case", 1)):
        table = [row for row in _table(ds, case) if row["period"] == 1 and row["branch"] == 0]
        onset = sorted(row["parameter"] for row in table if row["type"] == "grazing_separation" and row["side"] > 0)
        entry: dict[str, Any] = {
            "case": case,
            "label": _case_label(ds, case),
            "separation_onset": onset[0] if onset else float("nan"),
            "coexistence": coexistence(ds, case),
            "folds": sorted((row["parameter"], row["sweep"]) for row in table if row["type"] == "fold"),
            "period_doubling": sorted(
                row["parameter"] for row in _table(ds, case) if row["type"] == "period_doubling" and row["period"] == 1
            ),
            "neimark_sacker": sorted(row["parameter"] for row in table if row["type"] == "neimark_sacker"),
        }
        if "sweep_peak_mesh_force" in ds:
            entry.update(
                jumps_up=sweep_jumps(ds, case, "up"),
                jumps_down=sweep_jumps(ds, case, "down"),
                sweep_separation=first_separation(ds, case, "up"),
            )
        cases.append(entry)
    intervals = {}
    for key in ("separation_onset",):
        values = [entry[key] for entry in cases if np.isfinite(entry[key])]
        intervals[key] = (min(values), max(values)) if values else None
    for key in ("period_doubling", "neimark_sacker"):
        firsts = [entry[key][0] for entry in cases if entry[key]]
        intervals[key] = (min(firsts), max(firsts)) if firsts else None
    return {
        "parameter": str(ds.attrs.get("parameter", "pinion_speed")),
        "cases": cases,
        "intervals": intervals,
        "tolerance": float(ds.attrs.get("location_tolerance", np.nan)),
    }


def _value(facts: dict[str, Any], value: float) -> str:
    return format_value(facts["parameter"], value)


def continuation_sentences(facts: dict[str, Any]) -> list[str]:
    """The findings in words, answer first."""
    sentences = []
    name = facts["parameter"]
    onset = facts["intervals"]["separation_onset"]
    per_case = [(entry["label"], entry["separation_onset"]) for entry in facts["cases"]]
    found = [(label, value) for label, value in per_case if np.isfinite(value)]
    never = [label for label, value in per_case if not np.isfinite(value)]
    if len(found) > 1:
        sentences.append(
            f"Teeth begin to separate between {_value(facts, onset[0])} and {_value(facts, onset[1])} "
            "over the cases ("
            + "; ".join(f"{label}: {_value(facts, value)}" for label, value in found)
            + ")"
            + (f"; never in the range at {', '.join(never)}" if never else "")
        )
    elif found:
        sentences.append(
            f"Teeth begin to separate at {_value(facts, found[0][1])} ({found[0][0]})"
            + (f"; never in the range at {', '.join(never)}" if never else "")
        )
    for entry in facts["cases"]:
        for item in entry["coexistence"]:
            periods = (
                ""
                if item["periods"] == [1, 1]
                else (" (period-" + " and period-".join(str(p) for p in item["periods"]) + ")")
            )
            history = (
                "an up-sweep stays on the lower one up to the fold at the top of the range, a down-sweep "
                "on the upper one down to the fold at its bottom"
                if item["between_folds"]
                else "the start decides"
            )
            sentences.append(
                f"{entry['label']}: between {_value(facts, item['low'])} and {_value(facts, item['high'])} two "
                f"stable responses{periods} coexist, peak mesh force {item['forces'][0] / 1e3:.4g} or "
                f"{item['forces'][1] / 1e3:.4g} kN (at {_value(facts, item['middle'])}); which one the gear holds "
                f"depends on its history: {history}"
            )
        for key, words in (("period_doubling", "period doubling"), ("neimark_sacker", "Neimark-Sacker (torus)")):
            if entry[key]:
                sentences.append(
                    f"{entry['label']}: {words} of the period-1 orbit at "
                    + ", ".join(_value(facts, v) for v in entry[key][:6])
                )
    for key, words in (("period_doubling", "first period doubling"), ("neimark_sacker", "first Neimark-Sacker point")):
        interval = facts["intervals"][key]
        if interval is not None and sum(bool(entry[key]) for entry in facts["cases"]) > 1:
            sentences.append(
                f"The {words} of {short_name(name)} moves between {_value(facts, interval[0])} and "
                f"{_value(facts, interval[1])} over the cases"
            )
    return sentences


def continuation_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """Headline statements of every continuation result (one per sentence, with the numbers)."""
    findings = []
    for ds in results:
        if str(ds.attrs.get("analysis_type")) != "continuation" or "bifurcation_type" not in ds:
            continue
        facts = continuation_facts(ds)
        for sentence in continuation_sentences(facts):
            findings.append(
                Finding(
                    sentence + f" ({ds.attrs.get('analysis_name', 'continuation')}, located "
                    f"to {_value(facts, facts['tolerance'])}).",
                    facts,
                    "continuation",
                )
            )
    return findings


def _draw_branches(ax: Any, ds: xr.Dataset, variable: str, factor: float, phases: bool = False) -> None:
    cases = ds.sizes.get("case", 1)
    cmap = colormaps["cividis"]
    for case in range(cases):
        colour = cmap(0.15 + 0.7 * case / max(cases - 1, 1))
        for branch in range(ds.sizes["branch"]):
            parameter = np.asarray(ds["parameter"].values[case, branch], dtype=float)
            stable = np.asarray(ds["stable"].values[case, branch])
            values = np.asarray(ds[variable].values[case, branch], dtype=float)
            values = values if values.ndim == 2 else values[:, None]
            count = int(ds["branch_period"].values[case, branch]) if phases else 1
            for column in range(max(count, 1)):
                for flag, style in ((1, "-"), (0, "--")):
                    # each stretch with its neighbouring points, so stable and unstable lines meet
                    edge = np.convolve((stable == flag).astype(float), [1, 1, 1], mode="same") > 0
                    shown = np.where(edge, values[:, column], np.nan)
                    ax.plot(
                        parameter,
                        shown * factor,
                        linestyle=style,
                        color=colour,
                        linewidth=1.4 if flag else 1.0,
                        zorder=3,
                    )
        for kind, (marker, _) in BIFURCATION_MARKERS.items():
            rows = [row for row in _table(ds, case) if row["type"] == kind]
            if rows and variable in ("peak_mesh_force",):
                ax.plot(
                    [row["parameter"] for row in rows],
                    [row["peak_mesh_force"] * factor for row in rows],
                    linestyle="none",
                    marker=marker,
                    color="black",
                    markersize=6,
                    markerfacecolor="none",
                    zorder=4,
                )


def _draw_sweeps(ax: Any, ds: xr.Dataset, variable: str, factor: float) -> None:
    if variable not in ds:
        return
    values = np.asarray(ds["sweep_value"].values, dtype=float)
    for start, (colour, marker, _) in SWEEP_STYLE.items():
        data = np.asarray(ds[variable].sel(start=start).values, dtype=float) * factor
        for case in range(data.shape[0]):
            column = data[case]
            if column.ndim == 2:
                ax.plot(
                    np.repeat(values, column.shape[1]),
                    column.ravel(),
                    linestyle="none",
                    marker=marker,
                    markersize=1.8,
                    color=colour,
                    alpha=0.5,
                    zorder=2,
                )
            else:
                ax.plot(
                    values, column, linestyle="none", marker=marker, markersize=3, color=colour, alpha=0.6, zorder=2
                )


def _legend(ax: Any, ds: xr.Dataset) -> None:
    from matplotlib.lines import Line2D

    handles = [
        Line2D([], [], color="black", linestyle="-", label="stable orbit"),
        Line2D([], [], color="black", linestyle="--", label="unstable orbit"),
    ]
    cmap = colormaps["cividis"]
    cases = ds.sizes.get("case", 1)
    handles += [
        Line2D([], [], color=cmap(0.15 + 0.7 * c / max(cases - 1, 1)), label=_case_label(ds, c)) for c in range(cases)
    ]
    if "sweep_peak_mesh_force" in ds:
        handles += [
            Line2D([], [], color=colour, marker=marker, linestyle="none", label=label)
            for colour, marker, label in SWEEP_STYLE.values()
        ]
    handles += [
        Line2D([], [], color="black", marker=marker, linestyle="none", markerfacecolor="none", label=label)
        for marker, label in BIFURCATION_MARKERS.values()
    ]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)


@renderer("continuation")
def _render_continuation(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    parameter = str(ds.attrs.get("parameter", "pinion_speed"))
    _add_branches_figure(section, ds, parameter, dpi)
    _add_stability_figure(section, ds, parameter, dpi)
    facts = continuation_facts(ds)
    section.findings.extend(continuation_sentences(facts))
    section.findings.extend(_sweep_jump_sentences(facts))
    table = _bifurcation_table(ds, parameter)
    if table:
        section.tables.append(table)
    section.facts.append(
        (
            "continuation",
            f"{float(ds.attrs.get('continuation_seconds', np.nan)):.1f} s, "
            f"{int(ds.attrs.get('orbit_passes', 0))} mesh periods integrated",
        )
    )
    if "sweep_seconds" in ds.attrs:
        section.facts.append(
            (
                "brute-force sweeps",
                f"{float(ds.attrs['sweep_seconds']):.1f} s, {int(ds.attrs.get('model_runs', 0))} runs",
            )
        )
    section.caveats.append(
        "branches are followed from the period-1 orbit at the start of the range (and the "
        "period-doubled orbits off it); responses on other branches, tori and chaos are seen "
        "only in the sweeps"
    )
    if json_attr(ds, "envelope", []):
        section.caveats.append(
            "the interval of a bifurcation point is its spread over the cases continued "
            f"({ds.sizes.get('case', 1)} values across each envelope parameter)"
        )
    return section


def _add_branches_figure(section: Section, ds: xr.Dataset, parameter: str, dpi: int) -> None:
    """The branches' Poincaré points and peak mesh force over the brute-force sweeps."""
    figure = new_figure(9.5, 7.5)
    top, bottom = figure.subplots(2, 1, sharex=True)
    _draw_branches(top, ds, "orbit_poincare_x", 1e6, phases=True)
    _draw_sweeps(top, ds, "sweep_poincare_x", 1e6)
    limits = top.get_ylim()
    half = float(ds.attrs.get("half_backlash", np.nan)) * 1e6
    if np.isfinite(half):
        for level in (half, -half):
            if limits[0] <= level <= limits[1]:
                top.axhline(level, color="0.5", linestyle=":", linewidth=0.8)
    top.set_ylabel("Poincaré points of DTE $x_n$ [µm]")
    top.set_title(
        "periodic orbits (solid stable, dashed unstable) over the brute-force sweeps; dotted: x = ±b", fontsize=9
    )
    _draw_branches(bottom, ds, "peak_mesh_force", 1e-3)
    _draw_sweeps(bottom, ds, "sweep_peak_mesh_force", 1e-3)
    bottom.set_ylabel("peak mesh force [kN]")
    bottom.set_xlabel(axis_label(parameter))
    _legend(top, ds)
    add_figure(
        section,
        figure,
        f"Branches of periodic orbits against {short_name(parameter)} (continuation, "
        "solid where stable, dashed where unstable; markers: located bifurcations) over the points of "
        "brute-force sweeps up (blue, up triangles) and down (orange, down triangles) in which every run "
        "starts from its neighbour's final state.",
        dpi,
    )


def _add_stability_figure(section: Section, ds: xr.Dataset, parameter: str, dpi: int) -> None:
    """The largest Floquet multiplier modulus along the branches."""
    figure = new_figure(9.5, 3.6)
    ax = figure.subplots()
    _draw_branches(ax, ds, "spectral_radius", 1.0)
    ax.axhline(1.0, color="0.3", linestyle=":", linewidth=1.0)
    ax.set_ylabel("largest Floquet multiplier |µ|")
    ax.set_xlabel(axis_label(parameter))
    ax.set_title("stability: an orbit is stable while every multiplier lies inside the unit circle", fontsize=9)
    add_figure(section, figure, "Largest Floquet multiplier modulus along the branches (1: the stability limit).", dpi)


def _sweep_jump_sentences(facts: dict[str, Any]) -> list[str]:
    """Per case with sweeps: where the up- and down-sweeps jump and where the continuation folds."""
    sentences = []
    for entry in facts["cases"]:
        if "jumps_up" in entry:
            sentences.append(
                f"{entry['label']}, brute-force sweeps: the up-sweep jumps "
                + (
                    ", ".join(f"between {_value(facts, a)} and {_value(facts, b)}" for a, b in entry["jumps_up"])
                    or "nowhere"
                )
                + ", the down-sweep "
                + (
                    ", ".join(f"between {_value(facts, a)} and {_value(facts, b)}" for a, b in entry["jumps_down"])
                    or "nowhere"
                )
                + "; continuation folds at "
                + (
                    ", ".join(f"{_value(facts, v)} ({sweep or 'unstable stretch'})" for v, sweep in entry["folds"])
                    or "none"
                )
            )
    return sentences


def _bifurcation_table(ds: xr.Dataset, parameter: str) -> str | None:
    """The located bifurcations of every case as an HTML table (none located: None)."""
    rows = []
    for case in range(ds.sizes.get("case", 1)):
        for row in _table(ds, case):
            rows.append(
                f"<tr><td>{_case_label(ds, case)}</td><td>{row['type']}</td><td>{row['period']}</td>"
                f"<td>{row['parameter']:.6g}</td><td>{row['tolerance']:.2g}</td>"
                f"<td>{row['peak_mesh_force'] / 1e3:.4g}</td><td>{row['sweep']}</td></tr>"
            )
    if not rows:
        return None
    return (
        "<table><tr><th>case</th><th>bifurcation</th><th>branch period</th>"
        f"<th>{short_name(parameter)}</th><th>within</th><th>peak mesh force [kN]</th>"
        "<th>sweep that jumps there</th></tr>" + "".join(rows) + "</table>"
    )


__all__ = [
    "continuation_facts",
    "continuation_sentences",
    "continuation_findings",
    "coexistence",
    "stable_stretches",
    "sweep_jumps",
    "first_separation",
]
