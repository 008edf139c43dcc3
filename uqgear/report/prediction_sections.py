"""The ``prediction`` analysis in the report: its first-screen statements and its section.

The first screen says, for the headline QoI (the peak mesh force where the
prediction has it), at the speed of the worst case: the band of the worst case
over the interval parameters from the design's tolerances (the calibration's
prior) and after calibration, on which rig data, which calibrated parameters
narrowed it, and where the prediction extrapolates beyond the campaign's
speeds and loads.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from matplotlib import colormaps

from .finding import Finding
from .findings import T2, t2_interval, t2_interval_end
from .page import new_figure
from .presentation import axis_label, display, format_value, short_name
from .sections import Section, add_figure, html_list, json_attr, renderer, section_from_attrs

#: QoIs in the order the first screen prefers them.
_HEADLINE_QOIS = ("peak_mesh_force", "dynamic_load_factor", "load_factor_rated", "dte_rms")


def _qois(ds: xr.Dataset) -> list[str]:
    return [
        str(name)
        for name in ds.data_vars
        if {"bound", "quantile"} <= set(ds[name].dims) and not str(name).endswith("_prior")
    ]


def _headline_qoi(ds: xr.Dataset) -> str | None:
    qois = _qois(ds)
    for name in _HEADLINE_QOIS:
        if name in qois:
            return name
    return qois[0] if qois else None


def _band(ds: xr.Dataset, name: str, index: dict[str, Any]) -> tuple[float, float, float]:
    """(lowest quantile, median, highest quantile) of the upper bound at one operating point."""
    upper = ds[name].sel(bound="upper").isel(index)
    values = np.asarray(upper.values, dtype=float).ravel()
    quantiles = np.asarray(ds["quantile"].values, dtype=float)
    middle = int(np.argmin(np.abs(quantiles - 0.5)))
    return float(values[0]), float(values[middle]), float(values[-1])


def _rail(ds: xr.Dataset, value: float) -> str:
    """', wet rail' / ', dry rail' where the worst T2 is an end of a rail-adhesion interval, else ', T2 = ...'."""
    interval = t2_interval([ds])
    if interval is None or not np.isfinite(value):
        return ""
    end = t2_interval_end(value, interval)
    if end and interval[2]:
        return f", {'wet' if end == 'low' else 'dry'} rail"
    return f", T2 = {format_value(T2, value)}"


def _narrowed_text(ds: xr.Dataset) -> str:
    shares = json_attr(ds, "narrowing", {})
    parts = [
        f"{short_name(name)} to {share * 100:.0f} %" if share >= 0.01 else f"{short_name(name)} to {share * 100:.1g} %"
        for name, share in shares.items()
        if np.isfinite(share)
    ]
    if not parts:
        return ""
    more = "" if len(parts) <= 3 else " (and more)"
    return "; the rig data narrowed " + ", ".join(parts[:3]) + " of their prior range" + more


def _worst_point(ds: xr.Dataset, name: str, *, inside: bool = False) -> dict[str, Any]:
    """Index of the operating point where the median draw's upper bound is highest (``inside``: within the
    rig campaign's range only)."""
    upper = ds[name].sel(bound="upper")
    quantiles = np.asarray(ds["quantile"].values, dtype=float)
    median = upper.isel(quantile=int(np.argmin(np.abs(quantiles - 0.5))))
    values = np.asarray(median.values, dtype=float)
    if inside and "extrapolated" in ds:
        values = np.where(np.asarray(ds["extrapolated"].transpose(*median.dims).values, dtype=bool), np.nan, values)
    if values.ndim == 0 or not np.isfinite(values).any():
        return {}
    flat = int(np.nanargmax(values))
    return dict(zip(map(str, median.dims), np.unravel_index(flat, values.shape)))


def _where(ds: xr.Dataset, index: dict[str, Any]) -> str:
    return ", ".join(format_value(dim, float(ds[dim].values[i])) for dim, i in index.items())


def _span(name: str, low: float, high: float) -> str:
    same = abs(high - low) <= 1e-9 * max(abs(high), 1.0)
    return format_value(name, low) if same else f"{format_value(name, low)} to {format_value(name, high)}"


def _outside_runs(values: np.ndarray, outside: np.ndarray) -> list[tuple[float, float]]:
    """Contiguous stretches of flagged values, e.g. ['1000 rpm', '4000 rpm to 4600 rpm']."""
    runs, start = [], None
    for i, flag in enumerate([*outside, False]):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            runs.append((start, i - 1))
            start = None
    return [(float(values[a]), float(values[b])) for a, b in runs]


def _extrapolation_text(ds: xr.Dataset) -> str | None:
    if "extrapolated" not in ds or not bool(np.asarray(ds["extrapolated"].values).any()):
        return None
    campaign: dict[str, list[float]] = json_attr(ds, "campaign_range", {})
    flagged = ds["extrapolated"]
    parts = []
    for dim in map(str, flagged.dims):
        values = np.asarray(ds[dim].values, dtype=float)
        outside = np.asarray(flagged.any(dim=[d for d in flagged.dims if d != dim]).values, dtype=bool)
        stretches = [_span(dim, low, high) for low, high in _outside_runs(values, outside)]
        if stretches:
            parts.append(f"{short_name(dim)} {' and '.join(stretches)}")
    ranges = ", ".join(
        f"{short_name(key)} {_span(key, float(span[0]), float(span[1]))}" for key, span in campaign.items()
    )
    return (
        f"The prediction extrapolates beyond the rig campaign ({ranges}) at "
        f"{'; '.join(parts) or 'fixed inputs outside it'}: there the model, not the rig data, carries it."
    )


def _statement(ds: xr.Dataset, name: str, index: dict[str, Any], short: bool = False) -> tuple[str, dict[str, Any]]:
    """'Peak mesh force at S rpm, wet rail: A-B kN from the design's tolerances, C-D kN after calibration on F'
    (``short``: 'at S rpm, wet rail: A-B kN before, C-D kN after')."""
    label, unit, factor = display(name)
    low, median, high = _band(ds, name, index)
    worst_t2 = ds[f"{name}_worst_{T2}"].isel(index).item() if f"{name}_worst_{T2}" in ds else np.nan
    where = f"{'' if short else label + ' '}at {_where(ds, index)}{_rail(ds, float(worst_t2))}"
    if "extrapolated" in ds and bool(ds["extrapolated"].isel(index).item()):
        where += " (beyond the rig campaign)"
    facts: dict[str, Any] = {"qoi": name, "posterior": [low, high], "median": median, "at": index}
    if f"{name}_prior" not in ds:
        return f"{where}: worst case over {short_name(T2)} {low * factor:.4g}-{high * factor:.4g} {unit}", facts
    prior_low, _, prior_high = _band(ds, f"{name}_prior", index)
    facts["prior"] = [prior_low, prior_high]
    source = str(ds.attrs.get("posterior_source", "")).rsplit("/", 1)[-1].split(" (")[0] or "the rig data"
    if short:
        before, after = f"{prior_low * factor:.4g}-{prior_high * factor:.4g}", f"{low * factor:.4g}-{high * factor:.4g}"
        return f"{where}: {before} {unit} before, {after} {unit} after", facts
    text = (
        f"{where}: {prior_low * factor:.4g}-{prior_high * factor:.4g} {unit} from the design's tolerances, "
        f"{low * factor:.4g}-{high * factor:.4g} {unit} after calibration on {source}"
    )
    return text, facts


def _first_statement(ds: xr.Dataset, name: str, index: dict[str, Any]) -> Finding:
    quantiles = np.asarray(ds["quantile"].values, dtype=float)
    level = f"{(quantiles[-1] - quantiles[0]) * 100:.0f} %"
    text, facts = _statement(ds, name, index)
    text = text[:1].upper() + text[1:]
    if "prior" in facts:
        text += f" ({level} bands of the worst case over {short_name(T2)})"
    else:
        text += f" ({level} band over {int(ds.attrs.get('draws', 0))} draws of the study's distributions)"
    inside = _worst_point(ds, name, inside=True)
    if inside and inside != index:
        within, facts["within_campaign"] = _statement(ds, name, inside, short=True)
        text += f"; within the campaign's range the worst is {within}"
    text += _narrowed_text(ds) + "."
    if not int(ds.attrs.get("posterior_converged", 1)):
        text += " The posterior had not converged (accepted by allow_unconverged): read the band as indicative."
    return Finding(text, facts, topic="prediction")


def prediction_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """First-screen statements of every ``prediction`` result."""
    findings = []
    for ds in results:
        if str(ds.attrs.get("analysis_type", "")) != "prediction":
            continue
        name = _headline_qoi(ds)
        index = _worst_point(ds, name) if name else {}
        if name is None or not index:
            continue
        findings.append(_first_statement(ds, name, index))
        effects = json_attr(ds, "effects", [])
        if effects:
            names = ", ".join(entry["effect"].replace("_", " ") for entry in effects)
            findings.append(
                Finding(
                    f"The prediction carries the diagnosed {names} with its fitted parameters"
                    + (" sampled from their 90 % intervals." if int(ds.attrs.get("effects_sampled", 0)) else "."),
                    {"effects": [entry["effect"] for entry in effects]},
                    topic="prediction",
                )
            )
        if int(ds.attrs.get("discrepancy", 0)):
            findings.append(
                Finding(
                    "The prediction carries the calibration's model discrepancy: where the rig's "
                    f"{ds.attrs.get('discrepancy_feature', 'te mesh harmonic 1')} differs from the model's, each "
                    "draw's dynamic part is scaled by a draw of that difference at the operating point (beyond the "
                    "campaign the discrepancy's trend is extrapolated too).",
                    {"discrepancy": True},
                    topic="prediction",
                )
            )
        extrapolation = _extrapolation_text(ds)
        if extrapolation:
            findings.append(Finding(extrapolation, {"extrapolated": True}, topic="prediction"))
    return findings


def _draw_qoi(ax: Any, ds: xr.Dataset, name: str, sweep: str) -> None:
    _, unit, factor = display(name)
    x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
    colours = {"_prior": colormaps["cividis"](0.85), "": colormaps["cividis"](0.25)}
    labels = {"_prior": "prior (design tolerances)", "": str(ds.attrs.get("draws_from", "posterior"))}
    for suffix in ("_prior", ""):
        if f"{name}{suffix}" not in ds:
            continue
        for bound in ("upper", "lower"):
            values = np.asarray(ds[f"{name}{suffix}"].sel(bound=bound).values, dtype=float) * factor
            ax.fill_between(
                x, values[0], values[-1], color=colours[suffix], alpha=0.5 if bound == "upper" else 0.25,
                label=f"{labels[suffix]}: {bound} bound",
            )
            ax.plot(x, values[values.shape[0] // 2], color=colours[suffix], linewidth=1.0)
    if "extrapolated" in ds:
        outside = np.asarray(ds["extrapolated"].values, dtype=bool)
        if outside.any():
            bottom = np.full(outside.sum(), ax.get_ylim()[0])
            ax.plot(x[outside], bottom, "k|", markersize=10, label="beyond the campaign")
    ax.set_ylabel(f"{display(name)[0]} [{unit}]")
    ax.legend(fontsize=7, loc="best")


@renderer("prediction")
def render_prediction(ds: xr.Dataset, dpi: int) -> Section:
    """Bands of each QoI's bounds over the interval parameters, posterior against prior, against speed."""
    section = section_from_attrs(ds)
    qois = _qois(ds)
    sweep = str(ds["extrapolated"].dims[0]) if "extrapolated" in ds and ds["extrapolated"].ndim else None
    if qois and sweep is not None and ds["extrapolated"].ndim == 1:
        figure = new_figure(9.0, 2.9 * len(qois))
        axes = np.atleast_1d(figure.subplots(len(qois), 1, sharex=True))
        for ax, name in zip(axes, qois):
            _draw_qoi(ax, ds, name, sweep)
        axes[-1].set_xlabel(axis_label(sweep))
        quantiles = np.asarray(ds["quantile"].values, dtype=float)
        add_figure(
            section,
            figure,
            f"Bounds over {', '.join(short_name(p) for p in json_attr(ds, 'parameters', []))} of each QoI: "
            f"bands from the {quantiles[0]:g} to the {quantiles[-1]:g} quantile over the draws, line at the "
            "median; dark: after calibration, light: the prior (design tolerances).",
            dpi,
        )
    section.findings.extend(finding.text for finding in prediction_findings([ds]))
    calibrated = json_attr(ds, "calibrated_parameters", [])
    if calibrated:
        section.facts.append(("calibrated", ", ".join(short_name(n) for n in calibrated)))
        section.facts.append(("posterior", f"{ds.attrs.get('posterior_source', '')}, {ds.attrs.get('draws')} draws"))
    section.facts.append(("interval nodes", str(ds.attrs.get("interval_nodes", ""))))
    effects = json_attr(ds, "effects", [])
    if effects:
        section.tables.append(html_list([f"{e['effect']}: {e['parameters']}" for e in effects]))
    return section


__all__ = ["prediction_findings", "render_prediction"]
