"""Study report sections of uncertainty propagation: interval envelopes, Monte Carlo statistics and
probability boxes, polynomial-chaos validation and Sobol indices."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from matplotlib import colormaps
from matplotlib.figure import Figure

from ..uq.interval import FLAG_FALLBACK, FLAG_NONFINITE, FLAG_NONSMOOTH, FLAG_SURROGATE_ERROR, FLAG_VERTEX_EXCEEDED
from .coexistence_sections import attractor_bound_sentences, branch_parameters, branch_sentences
from .findings import equal_value_runs, range_text
from .page import new_figure
from .presentation import LINE_STYLES, MARKERS, axis_label, display, format_value, short_name
from .sections import Section, add_figure, html_list, json_attr, renderer, section_from_attrs

# interval flags that say something about the QoI itself (not just "recomputed by the fallback")
_OWN_FLAGS = FLAG_VERTEX_EXCEEDED | FLAG_SURROGATE_ERROR | FLAG_NONSMOOTH | FLAG_NONFINITE


# ---------------------------------------------------------------------------- interval


def _sweep_dim(ds: xr.Dataset, exclude: Sequence[str]) -> str | None:
    for dim in ds.dims:
        if dim not in exclude:
            return str(dim)
    return None


def _qois_of(ds: xr.Dataset) -> list[str]:
    options = json_attr(ds, "analysis_options", {})
    return [name for name in options.get("qois", []) if name in ds]


def _draw_branches(ax: Any, ds: xr.Dataset, name: str, x: np.ndarray, factor: float) -> None:
    """Where responses coexist: the from-rest response and the other one reached from another start, apart."""
    if f"{name}_from_rest" not in ds or "coexisting" not in ds or ds["coexisting"].ndim != 1:
        return
    both = np.asarray(ds["coexisting"].values, dtype=bool) & np.asarray(ds["in_window"].values, dtype=bool)
    rest = ds[f"{name}_from_rest"].sel(bound="upper").values * factor
    upper = ds[name].sel(bound="upper").values * factor
    other = both & (np.abs(upper - rest) > 1e-9 * np.abs(rest))
    if not other.any():
        return
    ax.plot(x[other], rest[other], linestyle="none", marker="o", markerfacecolor="white", markeredgecolor="black",
            markersize=4, label="upper bound from rest")
    ax.plot(x[other], upper[other], linestyle="none", marker="^", color="tab:red", markersize=5,
            label="upper bound over every response (another start)")


def _draw_coexisting(ax: Any, ds: xr.Dataset, name: str, x: np.ndarray, factor: float) -> None:
    """Both branches where responses coexist, joined at each speed: the two responses lie inside the band when the
    bound comes from another value of the interval parameter, and the band alone would hide the jump."""
    if f"{name}_branches" not in ds or ds[f"{name}_branches"].ndim != 2:
        return
    pair = ds[f"{name}_branches"].transpose(..., "branch").values * factor
    shown = np.asarray(np.isfinite(pair).all(axis=1), dtype=bool)
    if not shown.any():
        return
    ax.vlines(x[shown], pair[shown, 0], pair[shown, 1], color="#D55E00", linewidth=0.8)
    for column, (marker, which) in enumerate((("v", "lower"), ("^", "upper"))):
        ax.plot(x[shown], pair[shown, column], linestyle="none", marker=marker, color="#D55E00", markersize=4,
                label=f"{which} branch where two responses coexist" + _branch_where(ds, shown))


def _branch_where(ds: xr.Dataset, shown: np.ndarray) -> str:
    """' (T2 = a-b kN m)': the interval parameter values at which the branches were found."""
    parts = []
    for name in branch_parameters(ds):
        values = np.asarray(ds[f"branch_{name}"].values, dtype=float)[shown]
        low, high = float(np.nanmin(values)), float(np.nanmax(values))
        text = format_value(name, low) if low == high else f"{format_value(name, low)} to {format_value(name, high)}"
        parts.append(f"{short_name(name)} = {text}")
    return f" ({', '.join(parts)})" if parts else ""


@renderer("interval")
def _render_interval(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    qois = _qois_of(ds)
    options = json_attr(ds, "analysis_options", {})
    parameters = options.get("parameters", [])
    sweep = _sweep_dim(ds, ("bound", "check", "node", "sample", "param"))
    label = ", ".join(short_name(p) for p in parameters)
    if not qois:
        return section
    figure = new_figure(9.0, 2.9 * len(qois))
    axes = np.atleast_1d(figure.subplots(len(qois), 1, sharex=True))
    for ax, name in zip(axes, qois):
        _plot_interval_bounds(ax, ds, name, sweep, label)
        _interval_findings(section, ds, name, sweep, label)
        section.findings.extend(attractor_bound_sentences(ds, name, sweep))
        section.findings.extend(branch_sentences(ds, name, sweep))
    axes[-1].set_xlabel(axis_label(sweep) if sweep else "")
    method = ds.attrs.get("method", options.get("method", "?"))
    add_figure(
        section,
        figure,
        f"QoI envelopes over {label} ({method} method; band: lower to upper "
        "bound, dashed: response at the interval midpoints; x: bounds flagged by the method's own "
        "checks).",
        dpi,
    )
    _interval_method_notes(section, ds, qois, sweep, method)
    return section


def _plot_interval_bounds(ax: Any, ds: xr.Dataset, name: str, sweep: str | None, label: str) -> None:
    """One QoI's bounds: a band over the sweep (with the nominal, branches and flags), or one bar."""
    _, unit, factor = display(name)
    bounds = ds[name]
    lower = bounds.sel(bound="lower").values * factor
    upper = bounds.sel(bound="upper").values * factor
    nominal = ds[f"{name}_nominal"].values * factor if f"{name}_nominal" in ds else None
    if sweep is not None and lower.ndim == 1:
        x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
        ax.fill_between(
            x, lower, upper, color=colormaps["cividis"](0.75), alpha=0.6, label=f"envelope over {label}"
        )
        ax.plot(x, lower, color="black", linewidth=1.0, linestyle="-")
        ax.plot(x, upper, color="black", linewidth=1.0, linestyle="-")
        if nominal is not None:
            ax.plot(x, nominal, color="black", linestyle="--", linewidth=1.0, label="nominal (midpoints)")
        _draw_branches(ax, ds, name, x, factor)
        _draw_coexisting(ax, ds, name, x, factor)
        flagged = _flags(ds, name)
        if flagged is not None and flagged.any():
            ax.plot(
                x[flagged],
                upper[flagged],
                linestyle="none",
                marker="x",
                color="black",
                markersize=6,
                label="flagged (non-smooth or surrogate error)",
            )
        ax.legend(fontsize=7, loc="best")
    else:
        ax.bar(
            [0],
            [float(np.ravel(upper)[0] - np.ravel(lower)[0])],
            bottom=[float(np.ravel(lower)[0])],
            color=colormaps["cividis"](0.75),
            edgecolor="black",
            width=0.4,
        )
        ax.set_xticks([])
    ax.set_ylabel(f"{display(name)[0]} [{unit}]")


def _interval_method_notes(section: Section, ds: xr.Dataset, qois: list[str], sweep: str | None,
                           method: Any) -> None:
    """The points the fallback recomputed, the runs the method took, and why bounds were flagged."""
    redone = _flags(ds, qois[0], FLAG_FALLBACK) if qois else None
    if redone is not None and redone.any() and sweep is not None:
        values = np.asarray(ds[sweep].values, dtype=float)
        section.caveats.append(
            f"the {ds.attrs.get('fallback', 'fallback')} fallback recomputed all QoIs at "
            f"{int(redone.sum())} of {redone.size} points: "
            + ", ".join(format_value(sweep, v) for v in values[redone][:12])
            + (", ..." if redone.sum() > 12 else "")
        )
    if "runs" in ds.attrs:
        section.facts.append(
            (
                "interval method",
                f"{method}, {int(ds.attrs['runs'])} runs including "
                f"{int(ds.attrs.get('fallback_runs', 0))} by the fallback",
            )
        )
    reasons = json_attr(ds["flag"], "flag_reasons", []) if "flag" in ds else []
    if reasons:
        section.tables.append(
            "<details><summary>Why bounds were flagged ("
            + str(len(reasons))
            + " entries)</summary>"
            + html_list(reasons)
            + "</details>"
        )


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
            f"{format_value(name, upper[widest])}) at {format_value(sweep, values[widest])}"
        )
        flagged = _flags(ds, name)
        if flagged is not None and flagged.any():
            fallback = str(ds.attrs.get("fallback", "none"))
            where = ", ".join(format_value(sweep, v) for v in values[flagged][:10])
            section.caveats.append(
                f"{title}: bounds flagged at {int(flagged.sum())} of {flagged.size} points ({where}"
                + (", ..." if flagged.sum() > 10 else "")
                + "): surrogate error above tolerance, "
                "non-smooth, non-monotone or non-finite response"
                + (
                    f"; recomputed there by the {fallback} fallback"
                    if fallback != "none"
                    else "; no fallback was run: treat these bands with care"
                )
            )
    else:
        section.findings.append(
            f"{title} in [{format_value(name, float(np.ravel(lower)[0]))}, "
            f"{format_value(name, float(np.ravel(upper)[0]))}] over {label}"
        )
    if "surrogate_error_relative" in ds and name in ds["qoi"].values:
        error = np.asarray(ds["surrogate_error_relative"].sel(qoi=name).values, dtype=float)
        if np.isfinite(error).any():
            section.caveats.append(
                f"{title}: largest estimated error of the bounds "
                f"{100 * float(np.nanmax(error)):.3g} % of the band width"
            )


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
    intervals = ", ".join(short_name(name) for name in json_attr(ds, "interval_parameters", {}))
    figure = new_figure(9.0, 2.8 * len(qois))
    axes = np.atleast_1d(figure.subplots(len(qois), 1, sharex=sweep is not None))
    for ax, name in zip(axes, qois):
        _, unit, factor = display(name)
        mean = ds[name].sel(statistic="mean") * factor
        low = ds[f"{name}_quantile"].isel(quantile=0).sel(bound="lower") * factor
        high = ds[f"{name}_quantile"].isel(quantile=-1).sel(bound="upper") * factor
        if sweep is not None:
            x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
            ax.fill_between(
                x,
                low.values,
                high.values,
                color=colormaps["cividis"](0.85),
                alpha=0.5,
                label=f"{100 * levels[0]:g}-{100 * levels[-1]:g} % quantiles, outer bounds",
            )
            ax.fill_between(
                x,
                mean.sel(bound="lower").values,
                mean.sel(bound="upper").values,
                color=colormaps["cividis"](0.35),
                alpha=0.8,
                label="mean: bounds over the intervals",
            )
            ax.legend(fontsize=7, loc="best")
            ax.set_ylabel(f"{display(name)[0]} [{unit}]")
        else:
            ax.bar(
                [0, 1],
                [float(high - low), float(mean.sel(bound="upper") - mean.sel(bound="lower"))],
                bottom=[float(low), float(mean.sel(bound="lower"))],
                color=colormaps["cividis"](0.6),
                edgecolor="black",
                width=0.5,
            )
            ax.set_xticks([0, 1], [f"{100 * levels[0]:g}-{100 * levels[-1]:g} % quantiles", "mean"])
            ax.set_ylabel(f"{display(name)[0]} [{unit}]")
        lower = np.atleast_1d(mean.sel(bound="lower").values) / factor
        upper = np.atleast_1d(mean.sel(bound="upper").values) / factor
        widest = int(np.nanargmax(upper - lower))
        where = "" if sweep is None else f" (widest at {format_value(sweep, float(ds[sweep].values[widest]))})"
        section.findings.append(
            f"{display(name)[0]}: the mean over the random parameters lies in "
            f"[{format_value(name, lower[widest])}, {format_value(name, upper[widest])}] over {intervals}{where}"
        )
    if sweep is not None:
        axes[-1].set_xlabel(axis_label(sweep))
    add_figure(
        section,
        figure,
        f"Probability box: Monte Carlo statistics over the random parameters, bounded "
        f"over the intervals ({intervals}); no distribution is assumed for the intervals.",
        dpi,
    )
    section.caveats.append(
        f"p-box from a scan of {ds.attrs.get('scan_points', '?')} points per interval "
        f"parameter with {ds.attrs.get('n_samples', '?')} random samples each (common random "
        "numbers); extremes between scan points can be missed"
    )
    return section


@renderer("monte_carlo")
def _render_monte_carlo(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    qois = _qois_of(ds)
    if qois and "bound" in ds[qois[0]].dims:
        return _render_pbox(ds, dpi, section, qois)
    sweep = _sweep_dim(ds, ("statistic", "quantile", "sample"))
    if not qois:
        return section
    figure = new_figure(9.0, 2.8 * len(qois))
    axes = np.atleast_1d(figure.subplots(len(qois), 1, sharex=sweep is not None))
    levels = np.asarray(ds["quantile"].values, dtype=float)
    for ax, name in zip(axes, qois):
        _, unit, factor = display(name)
        mean = ds[name].sel(statistic="mean").values * factor
        quantiles = ds[f"{name}_quantile"].values * factor
        if sweep is not None:
            x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
            ax.fill_between(
                x,
                quantiles[..., 0],
                quantiles[..., -1],
                color=colormaps["cividis"](0.75),
                alpha=0.6,
                label=f"{100 * levels[0]:g}-{100 * levels[-1]:g} % quantiles",
            )
            ax.plot(x, mean, color="black", linewidth=1.2, label="mean")
            if f"{name}_samples" in ds:
                samples = ds[f"{name}_samples"].transpose(sweep, "sample").values * factor
                ax.plot(
                    np.repeat(x, samples.shape[1]),
                    samples.ravel(),
                    linestyle="none",
                    marker=".",
                    markersize=1.5,
                    color="0.4",
                    label="samples",
                )
            ax.legend(fontsize=7, loc="best")
            peak = int(np.nanargmax(ds[name].sel(statistic="std").values))
            section.findings.append(
                f"{display(name)[0]}: mean from {format_value(name, np.nanmin(mean) / factor)} to "
                f"{format_value(name, np.nanmax(mean) / factor)}; largest spread (std "
                f"{format_value(name, float(ds[name].sel(statistic='std').values[peak]))}) at "
                f"{format_value(sweep, float(ds[sweep].values[peak]))}"
            )
        else:
            values = ds[f"{name}_samples"].values * factor if f"{name}_samples" in ds else None
            if values is not None:
                ax.hist(values[np.isfinite(values)], bins=20, color=colormaps["cividis"](0.6), edgecolor="black")
            ax.set_xlabel(f"{display(name)[0]} [{unit}]")
            ax.set_ylabel("count")
            section.findings.append(
                f"{display(name)[0]}: mean {format_value(name, float(mean.ravel()[0]) / factor)}, std "
                f"{format_value(name, float(ds[name].sel(statistic='std').values.ravel()[0]))}"
            )
        if sweep is not None:
            ax.set_ylabel(f"{display(name)[0]} [{unit}]")
    if sweep is not None:
        axes[-1].set_xlabel(axis_label(sweep))
    add_figure(
        section,
        figure,
        f"Monte Carlo: mean and quantile band of each QoI ({ds.attrs.get('n_samples', '?')} samples per point).",
        dpi,
    )
    caveat = _interval_treatment_caveat(ds, "Monte Carlo")
    if caveat:
        section.caveats.append(caveat)
    return section


@renderer("pce")
def _render_pce(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    qois = _qois_of(ds)
    if not qois:
        return section
    figure = new_figure(9.0, 3.2 * math.ceil(len(qois) / 2))
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
            f"validation error up to {100 * worst:.3g} % of the standard deviation"
        )
        if not np.isfinite(worst) or worst > 0.1:
            section.caveats.append(
                f"{display(name)[0]}: the polynomial surrogate misses the model by "
                f"{100 * worst:.3g} % of its spread at independent check points; its "
                "moments and Sobol indices are unreliable there (non-smooth response?)"
            )
    for ax in axes[len(qois) :]:
        ax.set_visible(False)
    add_figure(
        section,
        figure,
        "Polynomial chaos validation: surrogate against model at independent check points (all operating points).",
        dpi,
    )
    caveat = _interval_treatment_caveat(ds, "polynomial chaos")
    if caveat:
        section.caveats.append(caveat)
    return section


# ---------------------------------------------------------------------------- sobol


def _sobol_bars(ax: Any, indices: xr.DataArray, confidence: xr.DataArray | None, parameters: Sequence[str]) -> None:
    positions = np.arange(len(parameters))
    for offset, (index_name, hatch, shade) in enumerate((("S1", "", 0.35), ("ST", "//", 0.8))):
        values = indices.sel(index=index_name).transpose("param").values
        errors = confidence.sel(index=index_name).transpose("param").values if confidence is not None else None
        ax.bar(
            positions + (offset - 0.5) * 0.38,
            values,
            width=0.38,
            yerr=errors,
            capsize=3,
            color=colormaps["cividis"](shade),
            edgecolor="black",
            hatch=hatch,
            label="first order $S_1$" if index_name == "S1" else "total order $S_T$",
        )
    ax.set_xticks(positions, [short_name(p) for p in parameters], rotation=15, ha="right")
    ax.set_ylabel("Sobol index [-]")
    ax.axhline(0.0, color="black", linewidth=0.6)
    ax.legend(fontsize=7)


def _sobol_lines(ds: xr.Dataset, name: str, sweep: str, parameters: Sequence[str], level: float) -> Figure:
    indices = ds[name]
    confidence = ds.get(f"{name}_conf")
    figure = new_figure(9.0, 3.8)
    ax = figure.subplots()
    x = np.asarray(ds[sweep].values, dtype=float) * display(sweep)[2]
    cmap = colormaps["viridis"]
    for index, parameter in enumerate(parameters):
        total = indices.sel(index="ST", param=parameter).transpose(sweep).values
        colour = cmap(index / max(len(parameters) - 1, 1))
        ax.plot(
            x,
            total,
            linestyle=LINE_STYLES[index % len(LINE_STYLES)],
            marker=MARKERS[index % len(MARKERS)],
            markersize=4,
            color=colour,
            label=short_name(parameter),
        )
        if confidence is not None:
            half = confidence.sel(index="ST", param=parameter).transpose(sweep).values
            ax.fill_between(x, total - half, total + half, color=colour, alpha=0.15)
    ax.set_xlabel(axis_label(sweep))
    ax.set_ylabel("total-order Sobol index $S_T$ [-]")
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    ax.set_title(
        f"{display(name)[0]}: total-order Sobol indices (bands: {100 * level:g} % confidence intervals)", fontsize=9
    )
    return figure


def _sobol_findings(ds: xr.Dataset, name: str, sweep: str | None, parameters: Sequence[str]) -> list[str]:
    title = display(name)[0]
    selected = ds[name].sel(index="ST")
    totals = selected.transpose(sweep, "param").values if sweep else selected.transpose("param").values[None, :]
    defined = np.isfinite(totals).any(axis=1)
    dominant = np.where(defined, np.argmax(np.nan_to_num(totals, nan=-np.inf), axis=1), -1)
    values = np.asarray(ds[sweep].values, float) if sweep else np.empty(0)
    sentences = []
    for start, stop in equal_value_runs(dominant):
        where = "" if sweep is None else " " + range_text(sweep, values, start, stop)
        if dominant[start] < 0:
            sentences.append(f"{title}: indices undefined{where} (the QoI does not vary over the parameters)")
            continue
        ranking = np.argsort(-np.nan_to_num(totals[start], nan=-np.inf))
        sentences.append(
            f"{title}: {short_name(parameters[dominant[start]])} dominates{where} (S_T up to "
            f"{np.nanmax(totals[start : stop + 1, dominant[start]]):.2f}); ranking"
            + ("" if start == stop else " at the first point")
            + ": "
            + ", ".join(f"{short_name(parameters[i])} {totals[start, i]:.2f}" for i in ranking)
        )
    return sentences


@renderer("sobol")
def _render_sobol(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
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
            figure = new_figure(9.0, 3.4 * len(points))
            axes = np.atleast_1d(figure.subplots(len(points), 1, sharex=True))
            for ax, where in zip(axes, points):
                _sobol_bars(ax, indices.isel(where), None if confidence is None else confidence.isel(where), parameters)
                title = f"{display(name)[0]}: Sobol indices, {100 * level:g} % confidence intervals"
                if sweep is not None:  # then each point selects one value along it
                    title += f" at {format_value(sweep, float(ds[sweep].values[where[sweep]]))}"
                ax.set_title(title, fontsize=9)
            add_figure(
                section,
                figure,
                f"Sobol indices of {display(name)[0]} (bars: first and total "
                "order, whiskers: bootstrap confidence intervals).",
                dpi,
            )
        if sweep is not None and ds.sizes[sweep] >= 2:
            add_figure(
                section,
                _sobol_lines(ds, name, sweep, parameters, level),
                f"Total-order Sobol indices of {display(name)[0]} against {short_name(sweep)}.",
                dpi,
            )
        section.findings.extend(_sobol_findings(ds, name, sweep, parameters))
    treatment = str(ds.attrs.get("interval_treatment", ""))
    distributions = json_attr(ds, "distribution_assumed", {})
    if distributions:
        assumed = [short_name(k) for k, v in distributions.items() if str(v).startswith("uniform on interval")]
        given = [
            f"{short_name(k)} {v}" for k, v in distributions.items() if not str(v).startswith("uniform on interval")
        ]
        if assumed:
            section.caveats.append(
                "Sobol indices need distributions: the interval parameters "
                + ", ".join(assumed)
                + " are treated as uniform on their intervals, an "
                "assumption made for the sensitivity ranking only (an interval implies "
                "no distribution)"
            )
        if given:
            section.caveats.append("Sobol indices use the distributions " + "; ".join(given))
    elif treatment:
        section.caveats.append(f"Sobol indices: interval parameters {treatment}")
    held = json_attr(ds, "held_at_nominal", {})
    if held:
        section.caveats.append(
            "held at nominal values: " + ", ".join(f"{short_name(k)} = {format_value(k, v)}" for k, v in held.items())
        )
    widths = [
        float(np.nanmax(ds[f"{name}_conf"].sel(index="ST").values))
        for name in qois
        if f"{name}_conf" in ds and np.isfinite(ds[f"{name}_conf"].values).any()
    ]
    if widths and max(widths) > 0.1:
        section.caveats.append(
            f"confidence intervals of the total-order indices reach ±{max(widths):.2f} "
            f"with N = {ds.attrs.get('n_base', '?')} base samples: rankings closer than "
            "that are not resolved (increase samples)"
        )
    return section
