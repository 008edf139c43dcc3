"""Study report sections of the nonlinear dynamics: simulation panels, bifurcation diagrams and
regime maps."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from matplotlib import colormaps
from matplotlib.colors import BoundaryNorm, ListedColormap
from matplotlib.figure import Figure

from .coexistence_sections import coexistence_sentences, draw_sweep_starts, mark_coexistence
from .findings import regime_findings, separation_findings
from .page import figure_png, new_figure
from .presentation import (
    MARKERS,
    REGIME_CODES,
    REGIME_FIXED_COLOURS,
    REGIME_ORDER,
    axis_label,
    display,
    format_value,
    regime_legend,
    short_name,
)
from .sections import Section, add_figure, json_attr, renderer, section_from_attrs

#: Dynamic range of the DTE spectra drawn: floored this many dB below their peak.
SPECTRUM_RANGE_DB = 120.0
#: Smallest axis span of a Poincare map, relative to the magnitude of its values (and orbit size).
MIN_RELATIVE_SPAN = 1e-3


def _regime_order(labels: Sequence[str]) -> list[str]:
    def key(label: str) -> tuple[int, int, str]:
        if label.startswith("period-"):
            try:
                return (0, int(label.split("-", 1)[1]), label)
            except ValueError:
                return (0, 999, label)
        order = {name: index + 1 for index, name in enumerate(REGIME_ORDER)}
        return (order.get(label, len(REGIME_ORDER) + 1), 0, label)

    return sorted(set(labels), key=key)


def _regime_colours(labels: Sequence[str]) -> dict[str, Any]:
    # light for period-1 to dark for chaotic: the order reads in grey as well; uncertain and
    # undetermined are no point on that scale and keep colours of their own
    cmap = colormaps["cividis_r"]
    scaled = [label for label in labels if label not in REGIME_FIXED_COLOURS]
    count = max(len(scaled), 2)
    colours: dict[str, Any] = {label: cmap(0.08 + 0.84 * index / (count - 1)) for index, label in enumerate(scaled)}
    colours.update({label: REGIME_FIXED_COLOURS[label] for label in labels if label in REGIME_FIXED_COLOURS})
    return colours


def _is_dark(colour: Any) -> bool:
    from matplotlib.colors import to_rgb

    red, green, blue = to_rgb(colour)
    return 0.299 * red + 0.587 * green + 0.114 * blue < 0.5


def _regime_code(label: str) -> str:
    if label.startswith("period-n"):
        return "n"
    if label.startswith("period-"):
        return label.split("-", 1)[1]
    return REGIME_CODES.get(label, label[:1].upper())


def _plain_axis(ax: Any, axis: str, values: np.ndarray, reference: float = 0.0) -> None:
    """No offset or scientific multiplier on ``axis``; a span of at least ``MIN_RELATIVE_SPAN`` of the
    values' magnitude (or of ``reference``, e.g. the orbit size), so round-off (1e-13 on a period-1
    Poincare map) is not blown up into ticks."""
    ax.ticklabel_format(axis=axis, style="plain", useOffset=False)
    finite = np.asarray(values, dtype=float)
    finite = finite[np.isfinite(finite)]
    if finite.size == 0:
        return
    low, high = float(finite.min()), float(finite.max())
    magnitude = max(abs(low), abs(high), abs(float(reference)))
    minimum = MIN_RELATIVE_SPAN * magnitude if magnitude > 0.0 else 1.0
    if high - low < minimum:
        centre = 0.5 * (low + high)
        (ax.set_xlim if axis == "x" else ax.set_ylim)(centre - minimum, centre + minimum)


def _spectrum_floor(amplitude: np.ndarray) -> float:
    """Amplitude ``SPECTRUM_RANGE_DB`` below the spectrum's peak (0 for an all-zero spectrum)."""
    finite = amplitude[np.isfinite(amplitude)]
    peak = float(finite.max()) if finite.size else 0.0
    return peak * 10.0 ** (-SPECTRUM_RANGE_DB / 20.0) if peak > 0.0 else 0.0


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
    ax.plot(poincare_x, poincare_v, linestyle="none", marker="o", markersize=3, color="black", label="Poincaré points")
    ax.set_xlabel("DTE $x$ [µm]")
    ax.set_ylabel("DTE velocity $\\dot{x}$ [mm/s]")
    ax.set_title("phase plane", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    _plain_axis(ax, "x", x)
    _plain_axis(ax, "y", velocity)
    ax = axes[1, 0]
    ax.plot(poincare_x, poincare_v, linestyle="none", marker=".", markersize=4, color="black")
    ax.set_xlabel("$x_n$ [µm]")
    ax.set_ylabel("$\\dot{x}_n$ [mm/s]")
    ax.set_title("Poincaré map (once per mesh period)", fontsize=9)
    # a period-1 map is one point to round-off: no axis blown up to 1e-13 with an offset
    _plain_axis(ax, "x", poincare_x, reference=float(np.ptp(x)) if x.size else 0.0)
    _plain_axis(ax, "y", poincare_v, reference=float(np.ptp(velocity)) if velocity.size else 0.0)
    ax = axes[1, 1]
    amplitude = np.asarray(run["spectrum_x"].values) * 1e6
    if spectrum_axis == "frequency":
        abscissa = np.asarray(run["spectrum_frequency"].values)
        ax.set_xlabel("frequency [Hz]")
    else:
        abscissa = np.asarray(run["order"].values)
        ax.set_xlabel("order [multiples of pinion rotation]")
    floor = _spectrum_floor(amplitude)
    if floor > 0.0:
        # round-off lines far below the peak are floored, not drawn as content
        shown_amplitude = np.maximum(np.where(np.isfinite(amplitude), amplitude, floor), floor)
        ax.semilogy(abscissa, shown_amplitude, color="black", linewidth=0.8)
        ax.set_ylim(floor, 3.0 * float(np.max(shown_amplitude)))
    z1 = float(run.attrs.get("z1", np.nan))
    if np.isfinite(z1):
        mesh = z1 if spectrum_axis != "frequency" else float(run["mesh_frequency"].values)
        for harmonic in (1, 2, 3):
            ax.axvline(harmonic * mesh, color="0.55", linestyle=":", linewidth=0.8)
        ax.set_xlim(0, min(abscissa[-1], 4.2 * mesh))
    ax.set_ylabel("amplitude of $x$ [µm]")
    ax.set_title(f"DTE spectrum (dotted: mesh harmonics; {SPECTRUM_RANGE_DB:g} dB range)", fontsize=9)
    if title:
        figure.suptitle(title, fontsize=10)


def _run_title(run: xr.Dataset, swept: Sequence[str]) -> str:
    parts = [
        f"{short_name(name)} = {format_value(name, float(run[name].values))}"
        for name in ("pinion_speed", "drive_torque", "adhesion_torque", *swept)
        if name in run and run[name].ndim == 0 and name not in ("run",)
    ]
    if "mesh_stiffness_scale" in swept and "mesh_stiffness" in run:
        # the stiffness itself, not only the factor: mean of k(t) over the kept whole mesh periods
        parts.append(f"mean mesh stiffness {float(run['mesh_stiffness'].mean()) / 1e9:.3g} GN/m")
    parts = list(dict.fromkeys(parts))
    label = str(run["label"].values) if "label" in run else ""
    regime = str(run["regime"].values) if "regime" in run else ""
    text = ", ".join(parts)
    text += f": {regime}"
    if label and label != regime:
        text += f" (expected: {label})"
    return text


def simulation_figure_png(run: xr.Dataset, *, dpi: int = 110, spectrum_axis: str = "order") -> bytes:
    """PNG of the four panels of one run (:func:`uqgear.study.analyses.simulate_point` output)."""
    figure = new_figure(9.0, 6.6)
    _draw_simulation(figure, run, spectrum_axis, _run_title(run, ()))
    return figure_png(figure, dpi)


#: The stress peaks a simulated run's finding states.
_STRESS_PEAKS = (
    "root_stress_peak_pinion",
    "root_stress_peak_gear",
    "contact_stress_peak_pinion",
    "contact_stress_peak_gear",
)


@renderer("simulate")
def _render_simulate(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    swept = json_attr(ds, "swept", [])
    axis = str(ds.attrs.get("spectrum_axis", "order"))
    for index in range(ds.sizes.get("run", 0)):
        run = ds.isel(run=index)
        title = _run_title(run, swept)
        figure = new_figure(9.0, 6.6)
        _draw_simulation(figure, run, axis, title)
        add_figure(
            section,
            figure,
            title
            + ". "
            + str(run["regime_reason"].values)
            + f". Spectrum floored at {SPECTRUM_RANGE_DB:g} dB below its peak.",
            dpi,
        )
        label = str(run["label"].values) if "label" in run else ""
        regime = str(run["regime"].values)
        loads = ""
        if "peak_mesh_force" in run:
            loads = f"peak mesh force {float(run['peak_mesh_force'].values) / 1e3:.4g} kN"
            if "load_factor_rated" in run and np.isfinite(float(run["load_factor_rated"].values)):
                loads += f" ({float(run['load_factor_rated'].values):.3g} x the rated mesh force)"
            loads += ", "
        text = (
            f"{title}; {loads}RMS DTE {format_value('dte_rms', float(run['dte_rms'].values))}, dynamic load "
            f"factor {float(run['dynamic_load_factor'].values):.3g} (over the run's own F_T), teeth apart "
            f"{100 * float(run['fraction_separation'].values):.3g} % and in back-side contact "
            f"{100 * float(run['fraction_back_contact'].values):.3g} % of the time"
        )
        if "root_stress_peak_pinion" in run:
            peaks = {name: float(run[name].values) / 1e6 for name in _STRESS_PEAKS}
            text += (
                "; largest tooth root stress {root_stress_peak_pinion:.4g} MPa (pinion) and "
                "{root_stress_peak_gear:.4g} MPa (gear), flank contact stress {contact_stress_peak_pinion:.4g} / "
                "{contact_stress_peak_gear:.4g} MPa"
            ).format(**peaks)
        section.findings.append(text)
        if label and not _label_matches(label, regime):
            section.caveats.append(
                f"run {index} was listed as '{label}' in the study but is classified "
                f"'{regime}': the representative speeds need updating"
            )
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
    handles = [_patch(colours[label], regime_legend(label)) for label in order]
    ax.legend(handles=handles, fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    ax.set_xlabel(axis_label(sweep))


def _patch(colour: Any, label: str) -> Any:
    from matplotlib.patches import Patch

    return Patch(facecolor=colour, edgecolor="black", linewidth=0.4, label=label)


def _edges(values: np.ndarray) -> np.ndarray:
    if values.size == 1:
        return np.array([values[0] - 0.5, values[0] + 0.5])
    middle = 0.5 * (values[1:] + values[:-1])
    return np.concatenate([[values[0] - (middle[0] - values[0])], middle, [values[-1] + (values[-1] - middle[-1])]])


def _classification_caveat(ds: xr.Dataset) -> str:
    settings = json_attr(ds, "simulation_settings", {})
    keep = settings.get("keep_periods", "?")
    repeats = (
        "period-n only where the period repeats at least 10 times (n <= "
        + (f"{int(keep) // 10}" if isinstance(keep, int) else "kept/10")
        + "), quasi_periodic_or_long_period where it repeats fewer times"
    )
    if settings.get("lyapunov"):
        return (
            f"regimes classified from {keep} Poincaré points: period-n by repetition (0.1 % of the "
            f"orbit size), {repeats}; chaotic or quasi-periodic where the largest Lyapunov exponent "
            "(threshold 0.01 per mesh period) and the 0-1 test (K = 0.5) agree, uncertain where they "
            "disagree"
        )
    return (
        f"regimes classified from {keep} Poincaré points without a Lyapunov exponent ({repeats}): "
        "chaotic vs quasi-periodic rests on the 0-1 test, which converges slowly for quasi-periodic "
        "responses (set simulation.lyapunov: true to confirm)"
    )


def _half_backlash(ds: xr.Dataset, parameter: str) -> float | np.ndarray | None:
    """Half backlash b in m: one value, one per column when the backlash is swept, None if unknown."""
    if parameter == "backlash":
        return 0.5 * np.asarray(ds[parameter].values, dtype=float)
    if "backlash" in json_attr(ds, "envelope", []):
        return None
    for name, factor in (("half_backlash", 1.0), ("design_backlash", 0.5)):
        value = ds.attrs.get(name)
        if value is not None and np.isfinite(float(value)):
            return factor * float(value)
    return None


def _draw_contact_boundaries(ax: Any, values: np.ndarray, half_backlash: float | np.ndarray) -> list[Any]:
    """The contact boundaries x = +b (drive-side contact above) and x = -b (back-side contact below),
    dashed, with a legend of their own outside the axes (beside any legend already there)."""
    b = np.broadcast_to(np.asarray(half_backlash, dtype=float) * 1e6, values.shape)
    existing = ax.get_legend()
    lines = []
    for sign, text, style in (
        (1.0, "x = +b: drive-side contact above,\nteeth apart below", "--"),
        (-1.0, "x = -b: back-side contact\n(impact) below", ":"),
    ):
        if b.size > 1 and np.ptp(b) > 0:
            (line,) = ax.plot(values, sign * b, color="0.35", linestyle=style, linewidth=1.0, zorder=1, label=text)
        else:
            line = ax.axhline(
                sign * float(b.flat[0]), color="0.35", linestyle=style, linewidth=1.0, zorder=1, label=text
            )
        lines.append(line)
    ax.legend(
        handles=lines,
        fontsize=7,
        loc="lower left",
        bbox_to_anchor=(1.01, 0.0),
        borderaxespad=0,
        title=f"contact boundaries (b = {float(b.flat[-1]):.4g} µm)",
        title_fontsize=7,
    )
    if existing is not None:
        ax.add_artist(existing)
    return lines


def _geometric(values: np.ndarray) -> bool:
    """Positive values evenly spaced in log over more than a factor 5 (a ``spacing: log`` sweep)."""
    values = np.asarray(values, dtype=float)
    if values.size < 3 or np.any(values <= 0) or values.max() / values.min() < 5.0:
        return False
    steps = np.diff(np.log(values))
    return bool(np.allclose(steps, steps[0], rtol=1e-6))


def _mean_mesh_stiffness(ds: xr.Dataset) -> float | None:
    """Mean Ishikawa mesh stiffness k_mean (N/m, scale 1) of the design the result was run with."""
    from ..physics.design import DESIGN_KEYS, Design, load_design
    from ..physics.stiffness import mesh_stiffness

    try:
        values = {key: ds.attrs[f"design_{key}"] for key in DESIGN_KEYS}
        design = Design.from_mapping(values)
    except (KeyError, ValueError, TypeError):
        try:
            design = load_design(str(ds.attrs["design_name"]), json_attr(ds, "design_overrides", {}) or None)
        except (KeyError, ValueError, TypeError, OSError):
            return None
    return float(mesh_stiffness(design).attrs["k_mean"])


def _stiffness_axis(ax: Any, k_mean: float) -> None:
    """A top axis giving the mesh stiffness scale as the mean mesh stiffness s_k k_mean in GN/m."""
    per_unit = k_mean / 1e9
    secondary = ax.secondary_xaxis(
        "top", functions=(lambda scale: scale * per_unit, lambda stiffness: stiffness / per_unit)
    )
    secondary.set_xlabel("mean mesh stiffness $s_k k_{mean}$ [GN/m]", fontsize=8)
    secondary.tick_params(labelsize=7)


@renderer("bifurcation")
def _render_bifurcation(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    parameter = str(ds.attrs.get("parameter", next(iter(d for d in ds.dims if d != "period"))))
    envelope = json_attr(ds, "envelope", [])
    condition = envelope[0] if envelope else None
    scale = display(parameter)[2]
    figure = new_figure(9.0, 6.4 if condition else 5.4)
    top, bottom = figure.subplots(2, 1, height_ratios=(3, 1), sharex=True)
    values = np.asarray(ds[parameter].values, dtype=float)
    if condition:
        regime = _plot_envelope_points(top, ds, parameter, condition, values * scale)
    else:
        regime = _plot_poincare_points(top, ds, parameter, values * scale)
    if draw_sweep_starts(top, ds, parameter, condition, scale):
        top.set_title(
            top.get_title() + "\nwhere two or more responses coexist: blue ▲ up-sweep start, orange ▼ down-sweep start",
            fontsize=9,
        )
    top.set_ylabel("Poincaré points of DTE $x_n$ [µm]")
    half_backlash = _half_backlash(ds, parameter)
    if half_backlash is not None:
        _draw_contact_boundaries(top, values * scale, half_backlash)
    k_mean = _mean_mesh_stiffness(ds) if parameter == "mesh_stiffness_scale" else None
    if k_mean is not None:
        _stiffness_axis(top, k_mean)
    _regime_strip(bottom, regime, parameter, condition)
    if _geometric(values):
        _log_sweep_axis(bottom)
    add_figure(section, figure, _bifurcation_caption(parameter, condition, half_backlash, k_mean), dpi)
    if k_mean is not None:
        section.facts.append(("mean mesh stiffness at scale 1", f"{k_mean:.4g} N/m"))
    section.findings.extend(regime_findings(regime, parameter, condition))
    section.findings.extend(coexistence_sentences(ds, parameter, condition))
    section.caveats.append(_classification_caveat(ds))
    if condition:
        section.caveats.append(
            f"the envelope is the union over {ds.sizes[condition]} values of "
            f"{short_name(condition)} across its interval; regimes confined between "
            "these values can be missed"
        )
    return section


def _plot_envelope_points(top: Any, ds: xr.Dataset, parameter: str, condition: str, shown: np.ndarray) -> xr.DataArray:
    """Poincaré points per envelope member, one colour and marker each; the regimes over both axes."""
    points = ds["poincare_x"]
    others = [dim for dim in points.dims if dim not in (parameter, "period", condition)]
    if others:
        points = points.isel(dict.fromkeys(others, 0))
    condition_values = np.asarray(ds[condition].values, dtype=float)
    cmap = colormaps["cividis"]
    for index, level in enumerate(condition_values):
        column = points.sel({condition: level}).transpose(parameter, "period").values * 1e6
        colour = cmap(index / max(len(condition_values) - 1, 1))
        top.plot(
            np.repeat(shown, column.shape[1]),
            column.ravel(),
            linestyle="none",
            marker=MARKERS[index % len(MARKERS)],
            markersize=2.2,
            color=colour,
            alpha=0.8,
            label=f"{short_name(condition)} = {format_value(condition, level)}",
        )
    top.legend(
        fontsize=7,
        loc="upper left",
        bbox_to_anchor=(1.01, 1.0),
        borderaxespad=0,
        markerscale=2.5,
        title="envelope member",
        title_fontsize=7,
    )
    top.set_title(
        f"bifurcation envelope: union of Poincaré points over {short_name(condition)} "
        f"in [{format_value(condition, condition_values[0])}, "
        f"{format_value(condition, condition_values[-1])}]",
        fontsize=9,
    )
    return ds["regime"].transpose(parameter, condition, ...)


def _plot_poincare_points(top: Any, ds: xr.Dataset, parameter: str, shown: np.ndarray) -> xr.DataArray:
    """The Poincaré points of one bifurcation diagram; its regimes."""
    column = ds["poincare_x"].transpose(parameter, "period").values * 1e6
    top.plot(
        np.repeat(shown, column.shape[1]),
        column.ravel(),
        linestyle="none",
        marker=".",
        markersize=2.0,
        color="black",
    )
    top.set_title("bifurcation diagram: Poincaré points of the DTE", fontsize=9)
    return ds["regime"]


def _log_sweep_axis(ax: Any) -> None:
    """A log-spaced sweep (e.g. bearing stiffness over decades) on a log axis, columns evenly spread."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_xscale("log")
    ax.xaxis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(FuncFormatter(lambda value, _: f"{value:g}"))
    ax.xaxis.set_minor_formatter(NullFormatter())


def _bifurcation_caption(parameter: str, condition: str | None, half_backlash: float | np.ndarray | None,
                         k_mean: float | None) -> str:
    """The bifurcation figure's caption: what is drawn against what, and the lines added where known."""
    return (
        f"Bifurcation diagram against {short_name(parameter)}"
        + (f", over {short_name(condition)} (colour and marker)" if condition else "")
        + (
            "; dashed: the contact boundaries x = ±b (b the half backlash): points above +b in "
            "drive-side contact, between them teeth apart, below -b back-side impact"
            if half_backlash is not None
            else ""
        )
        + (
            f"; top axis: mean mesh stiffness (k_mean = {k_mean / 1e9:.4g} GN/m at scale 1)"
            if k_mean is not None
            else ""
        )
        + "; below: response regime per column."
    )


@renderer("regime_map")
def _render_regime_map(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    axes_names = json_attr(ds, "axes", list(ds["regime"].dims)[:2])
    first, second = axes_names[0], axes_names[1]
    regime = ds["regime"].transpose(first, second)
    figure = new_figure(9.0, 5.2)
    ax = figure.subplots()
    _regime_strip(ax, regime, first, second)
    mark_coexistence(ax, ds, first, second, (display(first)[2], display(second)[2]))
    labels = np.asarray(regime.values).astype(str)
    if labels.size <= 600:
        x_values = np.asarray(ds[first].values, dtype=float) * display(first)[2]
        y_values = np.asarray(ds[second].values, dtype=float) * display(second)[2]
        # the strip's colours (long periods possibly merged) decide the text colour
        shown = _collapse_periods(labels) if len(set(labels.ravel().tolist())) > 7 else labels
        colours = _regime_colours(_regime_order(shown.ravel().tolist()))
        for i, x_value in enumerate(x_values):
            for j, y_value in enumerate(y_values):
                if labels[i, j] == "period-1":
                    continue
                dark = _is_dark(colours[shown[i, j]])
                ax.text(
                    x_value,
                    y_value,
                    _regime_code(labels[i, j]),
                    ha="center",
                    va="center",
                    fontsize=6,
                    color="white" if dark else "black",
                )
    ax.set_title(
        f"response regime over {short_name(first)} x {short_name(second)} "
        "(cell code: period n, L quasi-periodic or long period, Q quasi-periodic, C chaotic, "
        "U uncertain; blank: period 1)",
        fontsize=9,
    )
    add_figure(section, figure, f"Regime map over {short_name(first)} and {short_name(second)}.", dpi)
    if "fraction_separation" in ds:
        figure = new_figure(9.0, 4.6)
        ax = figure.subplots()
        separation = ds["fraction_separation"].transpose(first, second).values * 100
        mesh = ax.pcolormesh(
            _edges(np.asarray(ds[first].values, float) * display(first)[2]),
            _edges(np.asarray(ds[second].values, float) * display(second)[2]),
            separation.T,
            cmap="viridis",
            shading="flat",
        )
        figure.colorbar(mesh, ax=ax, label="tooth separation [% of time]")
        ax.set_xlabel(axis_label(first))
        ax.set_ylabel(axis_label(second))
        ax.set_title("fraction of time with the teeth apart (contact loss)", fontsize=9)
        add_figure(section, figure, "Contact loss over the same grid.", dpi)
    section.findings.extend(regime_findings(regime, first, second))
    section.findings.extend(coexistence_sentences(ds, first, second))
    if "fraction_separation" in ds:
        # per end of the second axis (wet and dry rail): a range found at one T2 is never given to another
        section.findings.extend(separation_findings(ds["fraction_separation"], first, second))
    section.caveats.append(_classification_caveat(ds))
    return section
