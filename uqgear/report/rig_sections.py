"""Study report sections of analyses on rig data: calibration and gap diagnosis."""

from __future__ import annotations

import html
import math

import numpy as np
import xarray as xr

from .diagnosis_report import gap_map_plot, spectra_plot
from .page import figure_png, new_figure
from .presentation import axis_label
from .sections import ReportFigure, Section, add_figure, json_attr, renderer, section_from_attrs


@renderer("diagnose")
def _render_diagnose(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    content = json_attr(ds, "diagnosis", {})
    verdict = str(content.get("verdict", ds.attrs.get("verdict", "?")))
    gap = content.get("gap", {})
    section.facts.append(("rig file", str(ds.attrs.get("rig", (content.get("rig") or {}).get("source", "")))))
    section.facts.append(("verdict", verdict))
    if gap and gap.get("baseline") is not None:
        section.facts.append(("held-out gap, nominal model", f"{float(gap['baseline']):.3g}"))
        if gap.get("effect"):
            interval = gap.get("shrink_interval") or [math.nan, math.nan]
            section.facts.append((f"held-out gap with {gap['effect']}", f"{float(gap['with_effect']):.3g}"))
            section.facts.append(
                (
                    "shrink fraction (90 % interval)",
                    f"{100 * float(gap['shrink_fraction']):.0f} % ({100 * float(interval[0]):.0f} "
                    f"to {100 * float(interval[1]):.0f} %)",
                )
            )
        section.facts.append(("evaluated on", str((gap.get("evaluated_on") or {}).get("scheme", ""))))
    if content.get("reason"):
        section.findings.append(f"verdict {verdict}: {content['reason']}")
    where = content.get("where") or []
    if where:
        section.findings.append(
            "the nominal model misses most at "
            + "; ".join(
                f"{entry['channel']} {entry['feature']} (runs {', '.join(map(str, entry['ops']))}, "
                f"RMS z {float(entry['score']):.1f})"
                for entry in where[:4]
            )
        )
    ranking = content.get("ranking") or []
    if ranking:

        def parameters(entry: dict) -> str:
            values = (entry.get("parameters") or {}).items()
            return ", ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in values)

        rows = "".join(
            f"<tr><td>{html.escape(str(entry['effect']))}</td><td>{float(entry['score']):.1f}</td>"
            f"<td>{100 * float(entry['shrink_fraction']):.0f} %</td>"
            f"<td>{html.escape(parameters(entry))}</td></tr>"
            for entry in ranking
        )
        section.tables.append(
            "<table><tr><th>candidate effect</th><th>score (nats)</th><th>shrink</th>"
            f"<th>fitted parameters</th></tr>{rows}</table>"
        )
    if "gap_map_nominal" in ds:
        figure = gap_map_plot(ds, "gap_map_nominal", "nominal model, held-out runs")
        section.figures.append(
            ReportFigure(
                "Gap map of the nominal model on held-out runs (channel / feature family x run).",
                figure_png(figure, dpi),
            )
        )
    if "gap_map_with_effect" in ds:
        figure = gap_map_plot(ds, "gap_map_with_effect", f"with {ds['candidate'].values[0]}, held-out runs")
        section.figures.append(
            ReportFigure("The same map with the best candidate effect added.", figure_png(figure, dpi))
        )
    if "amplitude_spectrum" in ds:
        section.figures.append(
            ReportFigure(
                "Held-out spectra of the two runs with the largest nominal gap: rig, "
                "nominal model and model with the effect.",
                figure_png(spectra_plot(ds), dpi),
            )
        )
    if verdict == "unexplained":
        section.caveats.append("a significant gap remains that no candidate effect of the library removes")
    elif verdict == "inconclusive" and content.get("ambiguity"):
        section.caveats.append("an effect and one sensor's own artefact fit the data alike: no verdict on either")
    elif verdict == "inconclusive":
        section.caveats.append("the data cannot decide between a healthy gear and an effect: no verdict on either")
    return section


@renderer("calibrate")
def _render_calibrate(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    summary = json_attr(ds, "calibration", {})
    converged = bool(summary.get("converged"))
    estimates = (
        summary.get("parameters") if converged else (summary.get("unconverged_estimates") or {}).get("parameters", {})
    )
    rows = "".join(
        f"<tr><td>{html.escape(name)}</td><td>{values['q50']:.6g}</td><td>{values['q05']:.6g}</td>"
        f"<td>{values['q95']:.6g}</td></tr>"
        for name, values in (estimates or {}).items()
    )
    section.tables.append(f"<table><tr><th>parameter</th><th>median</th><th>5 %</th><th>95 %</th></tr>{rows}</table>")
    diagnostics = summary.get("diagnostics", {})
    section.facts.append(("rig file", str(summary.get("rig", ds.attrs.get("rig", "")))))
    section.facts.append(("converged", "yes" if converged else "NO: estimates are not a result"))
    for key, label in (
        ("tau_max", "largest integrated autocorrelation time (steps)"),
        ("rhat_max", "largest split R-hat"),
        ("ess_min", "smallest effective sample size"),
        ("acceptance_mean", "mean acceptance fraction"),
    ):
        if key in diagnostics:
            section.facts.append((label, f"{float(diagnostics[key]):.4g}"))
    names = [str(name) for name in ds.data_vars if set(ds[name].dims) == {"chain", "draw"}]
    if names:
        figure = new_figure(9.0, 1.9 * ((len(names) + 2) // 3))
        axes = np.atleast_1d(figure.subplots((len(names) + 2) // 3, 3)).ravel()
        for ax, name in zip(axes, names):
            ax.hist(ds[name].values.ravel(), bins=40, color="0.35")
            ax.set_xlabel(axis_label(name), fontsize=8)
            ax.tick_params(labelsize=7)
        for ax in axes[len(names) :]:
            ax.set_visible(False)
        add_figure(section, figure, "Posterior marginals of the calibrated parameters.", dpi)
    check = summary.get("predictive_check") or {}
    if "fraction_within_2_sigma" in check:
        verdict = "passed" if check.get("passed") else "FAILED: the model does not explain these data"
        section.findings.append(
            f"posterior predictive check with the real model {verdict}: "
            f"{100 * float(check['fraction_within_2_sigma']):.0f} % of the features within "
            f"2 sigma (noise and model error), largest |z| {float(check['max_abs_z']):.3g}"
        )
    if not converged:
        section.caveats.append("the sampler did not converge: the estimates shown are not a result")
    return section
