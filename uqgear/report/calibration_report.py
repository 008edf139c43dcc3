"""Self-contained HTML report of a calibration (``report.html`` of ``uqgear calibrate``).

One file, figures embedded as base64 PNG (matplotlib's Agg canvas, no
pyplot), nothing fetched from the network. It holds the verdict (converged or
not, with the reasons), the posterior summary against the priors (and
against known true values when the rig file is synthetic), the convergence
diagnostics, the model-error levels, the posterior predictive check, and
figures: a corner plot of the global parameters, walker traces, and the
posterior predictive of the mesh-harmonic amplitudes against the data per
operating point.
"""

from __future__ import annotations

import html
import os
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import numpy as np
from matplotlib.figure import Figure

from ..common.errors import UqgearError
from ..common.fileio import write_text_atomic
from .calibration_discrepancy import discrepancy_finding, discrepancy_section
from .finding import HEADLINE_STYLE, Finding, headline_html
from .page import figure_html, figure_png, html_page, new_figure


class Calibration(Protocol):
    """What the report reads of a fitted :class:`uqgear.calibration.Calibration`.

    The report sits below the calibration in the package's layers, so it
    names the attributes it uses instead of importing the class (read-only: the report only reads them).
    """

    @property
    def parameters(self) -> Sequence[str]: ...

    @property
    def posterior_(self) -> Any: ...

    @property
    def predictive_(self) -> Any: ...

    @property
    def predictive_check_(self) -> Any: ...

    @property
    def summary_(self) -> Mapping[str, Any]: ...

    @property
    def converged_(self) -> bool: ...

    @property
    def diagnostics_(self) -> Mapping[str, Any]: ...

    @property
    def timing_(self) -> Mapping[str, Any]: ...

    @property
    def emulator_(self) -> Any: ...

    def to_dict(self) -> dict[str, Any]: ...


# parameter -> (label, unit shown, factor from SI)
_DISPLAY: dict[str, tuple[str, str, float]] = {
    "mesh_stiffness_scale": ("mesh stiffness scale", "1", 1.0),
    "zeta_mesh": ("mesh damping ratio", "1", 1.0),
    "backlash": ("backlash 2b", "mm", 1e3),
    "ste_amplitude": ("STE amplitude e_r", "µm", 1e6),
    "k1": ("k1", "GN/m", 1e-9),
    "k2": ("k2", "GN/m", 1e-9),
    "adhesion_torque": ("T2", "kN m", 1e-3),
}
_CHANNEL_UNITS = {"te": "m", "acc_pinion": "m s-2", "acc_gear": "m s-2"}

_STYLE = """
body { font-family: sans-serif; margin: 2em auto; max-width: 1150px; color: #222; }
table { border-collapse: collapse; margin: 0.6em 0; font-size: 0.92em; }
th, td { border: 1px solid #bbb; padding: 0.25em 0.55em; text-align: right; }
th { background: #eee; } td.text { text-align: left; }
.ok { color: #1a6b1a; font-weight: bold; } .bad { color: #a01010; font-weight: bold; }
figure { margin: 1em 0; } figure img { max-width: 100%; } figcaption { font-size: 0.9em; color: #444; }
"""


def _display(name: str) -> tuple[str, str, float]:
    return _DISPLAY.get(name, (name, "SI", 1.0))


#: A parameter whose 90 % credible interval spans at least this share of its (uniform) prior range
#: counts as not identifiable: its posterior is close to its prior (a flat posterior spans 90 %).
NOT_IDENTIFIABLE_SHARE = 0.5


def calibration_findings(content: Mapping[str, Any]) -> list[Finding]:
    """The headline statements of a calibration, from its JSON content (``calibration.json``).

    Converged or not and why; each parameter's median and 90 % interval in engineering units (only
    if converged: an unconverged posterior gives no estimates); the parameters the data do not
    identify (90 % interval spanning at least ``NOT_IDENTIFIABLE_SHARE`` of the prior range); the
    share of predicted features within 2 sigma of the data.
    """
    converged = bool(content.get("converged"))
    findings = [_convergence_finding(content, converged)]
    findings += _warnings_findings(content)
    findings += _speed_findings(content)
    findings += _pitch_error_findings(content)
    estimates = content.get("parameters") if converged else None
    if estimates:
        findings += [_estimates_finding(estimates), _identifiability_finding(estimates)]
    if content.get("discrepancy"):
        findings.append(discrepancy_finding(content["discrepancy"]))
    findings += _predictive_check_findings(content)
    return findings


def _convergence_finding(content: Mapping[str, Any], converged: bool) -> Finding:
    """Whether the sampler converged, with its diagnostics or the reasons it did not."""
    diagnostics = content.get("diagnostics") or {}
    numbers = {
        key: float(diagnostics[key])
        for key in ("tau_max", "rhat_max", "ess_min", "acceptance_mean")
        if key in diagnostics
    }
    if converged:
        text = (
            "The sampler converged"
            + (
                f": largest autocorrelation time {numbers['tau_max']:.0f} steps, "
                f"largest split R-hat {numbers['rhat_max']:.3f}, smallest effective "
                f"sample size {numbers['ess_min']:.0f}"
                if {"tau_max", "rhat_max", "ess_min"} <= set(numbers)
                else ""
            )
            + "."
        )
    else:
        reasons = [str(r) for r in diagnostics.get("reasons", [])]
        message = str(content.get("message") or "")
        text = (
            ("NOT converged: " + message)
            if message
            else ("NOT converged, so the estimates are not a result" + (": " + "; ".join(reasons) if reasons else ""))
        ) + "."
    return Finding(
        text, {"converged": converged, "reasons": list(diagnostics.get("reasons", [])), **numbers}, "convergence"
    )


def _warnings_findings(content: Mapping[str, Any]) -> list[Finding]:
    """The assumptions the result leans on (none: no finding)."""
    warnings = [str(w) for w in content.get("warnings") or []]
    if not warnings:
        return []
    return [Finding("Caution, the result leans on: " + "; ".join(warnings) + ".", {"warnings": warnings}, "warnings")]


def _speed_findings(content: Mapping[str, Any]) -> list[Finding]:
    """The widest speed wander within a record and the runs resampled to uniform pinion angle."""
    speed_rows = [row for row in content.get("speed") or [] if row.get("wander") is not None]
    if not speed_rows:
        return []
    widest = max(speed_rows, key=lambda row: row["wander"])
    tracked = [row["op"] for row in speed_rows if row.get("order_tracked")]
    return [
        Finding(
            f"Pinion speed within a record wandered by up to +-{100 * widest['wander']:.2f} % (run {widest['op']}, "
            f"{widest['mean_rpm']:.0f} rpm); "
            + (
                f"runs {', '.join(map(str, tracked))} were resampled to uniform pinion angle (order tracking) "
                "before their features were read."
                if tracked
                else "no run needed order tracking."
            ),
            {"max_wander": widest["wander"], "order_tracked_runs": tracked},
            "speed",
        )
    ]


def _pitch_error_findings(content: Mapping[str, Any]) -> list[Finding]:
    """What the pitch-error correction of the observed harmonics did, or why it was not applied."""
    pitch = content.get("pitch_errors")
    if not pitch:
        return []
    if pitch.get("applied"):
        text = (
            f"Pitch errors: the observed mesh harmonics were corrected for random pitch errors "
            f"({pitch['reason']}; {pitch['draws']} model draws, largest change "
            f"{100 * pitch['max_abs_log_shift']:.1f} %, median {100 * pitch['median_abs_log_shift']:.2f} %, "
            f"spread between draws up to {100 * pitch['max_draw_spread']:.1f} %, added to the variance)."
        )
    else:
        text = f"Pitch errors: no correction ({pitch['reason']})."
    return [
        Finding(
            text,
            {key: pitch.get(key) for key in ("applied", "scale_to_class_7", "classes", "max_abs_log_shift")},
            "pitch_errors",
        )
    ]


def _estimates_finding(estimates: Mapping[str, Any]) -> Finding:
    """Each parameter's median and 90 % credible interval in engineering units."""
    parts, facts = [], {}
    for name, entry in estimates.items():
        label, unit, factor = _display(name)
        shown = "" if unit in ("1", "SI") else f" {unit}"
        parts.append(
            f"{label} {entry['q50'] * factor:.4g}{shown} [{entry['q05'] * factor:.4g}, {entry['q95'] * factor:.4g}]"
        )
        facts[name] = {
            "q05": float(entry["q05"]),
            "q50": float(entry["q50"]),
            "q95": float(entry["q95"]),
            "factor": factor,
            "unit": unit,
        }
    return Finding(
        "Estimates, median [90 % credible interval]: " + "; ".join(parts) + ".",
        {"parameters": facts},
        "estimates",
    )


def _identifiability_finding(estimates: Mapping[str, Any]) -> Finding:
    """The parameters whose 90 % interval spans at least ``NOT_IDENTIFIABLE_SHARE`` of their prior range."""
    shares = {
        name: (float(entry["q95"]) - float(entry["q05"])) / (float(entry["prior"][1]) - float(entry["prior"][0]))
        for name, entry in estimates.items()
    }
    weak = [name for name, share in shares.items() if share >= NOT_IDENTIFIABLE_SHARE]
    if weak:
        text = (
            "Not identifiable from these data (posterior close to its prior): "
            + "; ".join(
                f"{_display(name)[0]} (90 % interval spans {100 * shares[name]:.0f} % of the prior range)"
                for name in weak
            )
            + "."
        )
    else:
        text = (
            f"Every parameter is identified: the 90 % intervals span at most "
            f"{100 * max(shares.values()):.0f} % of their prior ranges."
        )
    return Finding(
        text,
        {"shares": shares, "not_identifiable": weak, "threshold": NOT_IDENTIFIABLE_SHARE},
        "identifiability",
    )


def _predictive_check_findings(content: Mapping[str, Any]) -> list[Finding]:
    """The share of predicted features within 2 sigma of the data (no check recorded: no finding)."""
    check = content.get("predictive_check") or {}
    if "fraction_within_2_sigma" not in check:
        return []
    share = float(check["fraction_within_2_sigma"])
    text = (
        f"Posterior predictive check with the real model {'passed' if check.get('passed') else 'FAILED'}: "
        f"{100 * share:.0f} % of the {int(check.get('features_used', 0))} features within 2 sigma "
        f"(noise and model error) of the data, largest |z| {float(check.get('max_abs_z', np.nan)):.3g}."
    )
    return [
        Finding(
            text,
            {
                "fraction_within_2_sigma": share,
                "passed": bool(check.get("passed")),
                "features_used": int(check.get("features_used", 0)),
                "max_abs_z": float(check.get("max_abs_z", np.nan)),
            },
            "predictive_check",
        )
    ]


def _figure_html(figure: Figure, caption: str, dpi: int) -> str:
    return figure_html(figure_png(figure, dpi), caption)


def _table(rows: Sequence[Sequence[Any]], header: Sequence[str]) -> str:
    def cell(value: Any) -> str:
        if isinstance(value, float):
            return f"<td>{value:.5g}</td>"
        if isinstance(value, bool):
            return f'<td class="{"ok" if value else "bad"}">{"yes" if value else "no"}</td>'
        return f'<td class="text">{html.escape(str(value))}</td>'

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(cell(v) for v in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def corner_figure(calibration: Calibration, truth: Mapping[str, Any] | None = None) -> Figure:
    """Pairwise marginals of the global parameters (2-D histograms) with 1-D histograms on the diagonal."""
    names = list(calibration.parameters)
    draws = {name: calibration.posterior_[name].values.ravel() * _display(name)[2] for name in names}
    n = len(names)
    size = max(1.7 * n, 4.0)
    figure = new_figure(size, size)
    axes = figure.subplots(n, n, squeeze=False)
    for row, y_name in enumerate(names):
        for column, x_name in enumerate(names):
            axis = axes[row][column]
            if column > row:
                axis.set_visible(False)
                continue
            x = draws[x_name]
            if row == column:
                axis.hist(x, bins=40, color="0.45", histtype="stepfilled")
                axis.set_yticks([])
                for q in np.quantile(x, [0.05, 0.5, 0.95]):
                    axis.axvline(q, color="k", linestyle=":" if q != np.median(x) else "-", linewidth=0.8)
            else:
                axis.hist2d(x, draws[y_name], bins=40, cmap="cividis")
            if truth and x_name in truth:
                axis.axvline(float(truth[x_name]) * _display(x_name)[2], color="#d62728", linestyle="--", linewidth=1.0)
            if truth and y_name in truth and row != column:
                axis.axhline(float(truth[y_name]) * _display(y_name)[2], color="#d62728", linestyle="--", linewidth=1.0)
            label_x, unit_x, _ = _display(x_name)
            label_y, unit_y, _ = _display(y_name)
            if row == n - 1:
                axis.set_xlabel(f"{label_x} [{unit_x}]", fontsize=8)
            else:
                axis.set_xticklabels([])
            if column == 0 and row != 0:
                axis.set_ylabel(f"{label_y} [{unit_y}]", fontsize=8)
            elif column != row:
                axis.set_yticklabels([])
            axis.tick_params(labelsize=7)
    return figure


def trace_figure(calibration: Calibration, walkers: int = 12) -> Figure:
    """Traces of the stored (burnt-in, thinned) draws of the global parameters for some walkers."""
    names = list(calibration.parameters)
    figure = new_figure(9.0, 1.6 * len(names) + 0.6)
    axes = figure.subplots(len(names), 1, squeeze=False, sharex=True)
    chains = calibration.posterior_.sizes["chain"]
    chosen = np.linspace(0, chains - 1, min(walkers, chains)).astype(int)
    for axis, name in zip(axes[:, 0], names):
        label, unit, factor = _display(name)
        values = calibration.posterior_[name].values[chosen] * factor
        for trace in values:
            axis.plot(trace, linewidth=0.6, alpha=0.8)
        axis.set_ylabel(f"{label}\n[{unit}]", fontsize=8)
        axis.tick_params(labelsize=7)
    axes[-1, 0].set_xlabel("stored draw (after burn-in and thinning)")
    return figure


def predictive_figure(calibration: Calibration) -> Figure:
    """Observed mesh-harmonic amplitudes against the posterior predictive of the real model, per channel."""
    predictive = calibration.predictive_
    channels = [str(c) for c in predictive["channel"].values]
    harmonics = [int(h) for h in predictive["harmonic"].values]
    speed = predictive["pinion_speed"].values
    figure = new_figure(11.0, 3.4 * len(channels))
    axes = figure.subplots(len(channels), 2, squeeze=False)
    markers = ("o", "s", "^", "D", "v", "P")
    for row, channel in enumerate(channels):
        axis, z_axis = axes[row]
        for index, harmonic in enumerate(harmonics):
            marker = markers[index % len(markers)]
            observed = predictive["observed"].sel(channel=channel, harmonic=harmonic).values
            used = predictive["used"].sel(channel=channel, harmonic=harmonic).values
            offset = (index - 1) * 0.012 * (speed.max() - speed.min() + 1.0)
            axis.plot(
                speed + offset,
                observed,
                marker=marker,
                linestyle="none",
                color="k",
                markersize=7,
                markerfacecolor="none",
                label=f"data mesh{harmonic}",
            )
            if "predicted_median" in predictive:
                median = predictive["predicted_median"].sel(channel=channel, harmonic=harmonic).values
                low = predictive["predicted_q05"].sel(channel=channel, harmonic=harmonic).values
                high = predictive["predicted_q95"].sel(channel=channel, harmonic=harmonic).values
                axis.errorbar(
                    speed + offset,
                    median,
                    yerr=[median - low, high - median],
                    marker=marker,
                    linestyle="none",
                    color="#1f77b4",
                    markersize=3,
                    capsize=2,
                    label=f"model mesh{harmonic} (median, 5-95 %)",
                )
                z = predictive["z_total"].sel(channel=channel, harmonic=harmonic).values
                z_axis.plot(speed[used], z[used], marker=marker, linestyle="-", linewidth=0.6, label=f"mesh{harmonic}")
        axis.set_yscale("log")
        axis.set_ylabel(f"{channel} amplitude [{_CHANNEL_UNITS.get(channel, '')}]")
        axis.set_xlabel("pinion speed [rpm]")
        axis.legend(fontsize=7, ncol=2)
        z_axis.axhspan(-2, 2, color="0.9")
        z_axis.axhline(0, color="0.5", linewidth=0.6)
        z_axis.set_ylabel("(data - model) / sigma [1]")
        z_axis.set_xlabel("pinion speed [rpm]")
        z_axis.set_title(f"{channel}: standardised residual (noise + model error)", fontsize=9)
        z_axis.legend(fontsize=7)
    return figure


def _truth_rows(truth: Mapping[str, Any] | None, name: str, q05: float, q95: float) -> list[Any]:
    if not truth or name not in truth:
        return ["", ""]
    value = float(truth[name])
    return [value, bool(q05 <= value <= q95)]


def calibration_report_html(calibration: Calibration, *, truth: Mapping[str, Any] | None = None, dpi: int = 100) -> str:
    """The report as one HTML document (see the module docstring)."""
    if not hasattr(calibration, "posterior_"):
        raise UqgearError("calibration report: the calibration is not fitted; call fit(rig) first")
    content = calibration.to_dict()
    summary = calibration.summary_
    parts = _overview_section(calibration, content)
    parts += _posterior_section(calibration, summary, truth, dpi)
    parts += _convergence_section(calibration, dpi)
    parts += _predictive_section(calibration, dpi)
    parts += _model_error_section(summary)
    if "discrepancy" in summary:
        parts.extend(discrepancy_section(summary["discrepancy"], _table))
    parts += _emulator_section(calibration)
    return html_page("uqgear calibration report", _STYLE + HEADLINE_STYLE, parts)


def _overview_section(calibration: Calibration, content: Mapping[str, Any]) -> list[str]:
    """Title, headline, verdict, design notes and the table of the run (data, model runs, times)."""
    verdict = (
        '<p class="ok">Converged: the posterior below is a result.</p>'
        if calibration.converged_
        else '<p class="bad">NOT converged: the estimates below are not a result.</p>'
        + "<ul>"
        + "".join(f"<li>{html.escape(r)}</li>" for r in calibration.diagnostics_["reasons"])
        + "</ul>"
    )
    # what the model did with the design's geometry (an undercut tooth is modelled, not refused)
    design_notes = "".join(
        f'<p class="note"><b>Design:</b> {html.escape(str(note))}.</p>' for note in content.get("design_notes") or []
    )
    return [
        "<h1>uqgear calibration report</h1>",
        headline_html(calibration_findings(content), "Details, figures and diagnostics below."),
        verdict,
        design_notes,
        _table(
            [
                ("rig data", content["rig"]),
                ("model runs", str(calibration.timing_["model_runs"])),
                ("wall time", f"{calibration.timing_['wall_s']:.1f} s"),
                ("CPU time", f"{calibration.timing_['cpu_s']:.1f} s"),
                ("report created", datetime.now(UTC).isoformat(timespec="seconds")),
            ],
            ("item", "value"),
        ),
    ]


def _posterior_section(
    calibration: Calibration, summary: Mapping[str, Any], truth: Mapping[str, Any] | None, dpi: int
) -> list[str]:
    """The global parameters against their priors, the latent T2 per run, and the corner plot."""
    parts = ["<h2>Posterior of the global parameters</h2>"]
    rows = []
    for name, entry in summary["parameters"].items():
        rows.append(
            [
                name,
                entry["units"],
                f"[{entry['prior'][0]:.4g}, {entry['prior'][1]:.4g}]",
                entry["mean"],
                entry["sd"],
                entry["q05"],
                entry["q50"],
                entry["q95"],
                *_truth_rows(truth, name, entry["q05"], entry["q95"]),
            ]
        )
    parts.append(
        _table(
            rows,
            ("parameter", "units", "prior (uniform)", "mean", "sd", "q05", "q50", "q95", "true", "true in 90 % CI"),
        )
    )
    parts.append("<h2>Adhesion torque per run (latent)</h2>")
    true_t2 = (truth or {}).get("adhesion_torque")
    rows = []
    for entry in summary["adhesion_torque"]:
        op = entry["op"]
        true_value = float(true_t2[op]) if true_t2 is not None else None
        rows.append(
            [
                op,
                entry["pinion_speed"],
                f"[{entry['prior'][0]:.0f}, {entry['prior'][1]:.0f}]",
                entry["mean"],
                entry["q05"],
                entry["q50"],
                entry["q95"],
                true_value if true_value is not None else "",
                bool(entry["q05"] <= true_value <= entry["q95"]) if true_value is not None else "",
            ]
        )
    parts.append(
        _table(
            rows, ("op", "pinion speed [rpm]", "prior [N m]", "mean", "q05", "q50", "q95", "true", "true in 90 % CI")
        )
    )
    parts.append(
        _figure_html(
            corner_figure(calibration, truth),
            "Corner plot of the global parameters (dotted: 5 and 95 % quantiles; dashed red: true values where known)",
            dpi,
        )
    )
    return parts


#: The sampler's diagnostics shown in the report, in order.
_DIAGNOSTIC_KEYS = (
    "converged",
    "n_walkers",
    "n_steps",
    "burn_in",
    "thin",
    "steps_after_burn_in",
    "tau_max",
    "rhat_max",
    "ess_min",
    "acceptance_mean",
    "acceptance_min",
    "acceptance_max",
)


def _convergence_section(calibration: Calibration, dpi: int) -> list[str]:
    """The sampler's diagnostics, overall and per parameter, and the walker traces."""
    diagnostics = calibration.diagnostics_
    return [
        "<h2>Convergence diagnostics</h2>",
        _table([(key, diagnostics[key]) for key in _DIAGNOSTIC_KEYS], ("diagnostic", "value")),
        _table(
            [(name, entry["tau"], entry["ess"], entry["rhat"]) for name, entry in diagnostics["parameters"].items()],
            ("parameter", "autocorrelation time [steps]", "effective sample size", "split R-hat"),
        ),
        _figure_html(trace_figure(calibration), "Walker traces of the stored draws", dpi),
    ]


def _predictive_section(calibration: Calibration, dpi: int) -> list[str]:
    """The posterior predictive check with the real model, and its figure where predictions were kept."""
    check = calibration.predictive_check_
    parts = [
        "<h2>Posterior predictive check (real model)</h2>",
        _table([(key, value) for key, value in check.items()], ("item", "value")),
    ]
    if "predicted_median" in calibration.predictive_:
        parts.append(
            _figure_html(
                predictive_figure(calibration),
                "Mesh-harmonic amplitudes: data (black) and the real model at posterior draws "
                "(blue: median and 5-95 %); right: residuals in units of the noise plus the "
                "posterior model error (grey band: +-2)",
                dpi,
            )
        )
    return parts


def _model_error_section(summary: Mapping[str, Any]) -> list[str]:
    """The relative model error per channel and harmonic."""
    return [
        "<h2>Model error (relative, per channel and harmonic)</h2>",
        _table(
            [
                (group, entry["q05"], entry["q50"], entry["q95"], entry["n_features"])
                for group, entry in summary["model_error"].items()
            ],
            ("group", "q05", "q50", "q95", "features"),
        ),
    ]


def _emulator_section(calibration: Calibration) -> list[str]:
    """The emulator's stages: leave-one-out errors, acceptance, truncation of the posterior."""
    return [
        "<h2>Emulator stages</h2>",
        _table(
            [
                (
                    stage["stage"],
                    stage["loo_rms_median"],
                    stage["loo_rms_max"],
                    stage["acceptance"],
                    bool(stage["truncated"]),
                )
                for stage in calibration.emulator_["stages"]
            ],
            ("stage", "LOO error median [log]", "LOO error max [log]", "acceptance", "posterior truncated"),
        ),
    ]


def write_calibration_report(
    calibration: Calibration, path: str | os.PathLike[str], *, truth: Mapping[str, Any] | None = None, dpi: int = 100
) -> Path:
    """Write the HTML report of a fitted calibration atomically.

    Parameters
    ----------
    calibration : Calibration
        Fitted.
    path : path
        Target file (its folder must exist).
    truth : mapping, optional
        Known true values (parameter names and ``adhesion_torque`` per run).
    dpi : int
        Figure resolution.

    Returns
    -------
    pathlib.Path
    """
    target = Path(path)
    if not target.parent.is_dir():
        raise UqgearError(f"{target}: folder {target.parent} does not exist")
    return write_text_atomic(target, calibration_report_html(calibration, truth=truth, dpi=dpi))


__all__ = [
    "write_calibration_report",
    "calibration_report_html",
    "calibration_findings",
    "corner_figure",
    "trace_figure",
    "predictive_figure",
]
