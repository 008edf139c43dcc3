"""Self-contained HTML reports of a gap diagnosis and of a blind test.

Figures are drawn with matplotlib's Agg backend and embedded as base64 PNG,
so a report is one file that opens anywhere. Files are written atomically.
"""

from __future__ import annotations

import html
import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from matplotlib.ticker import LogLocator, NullLocator

from ..common.fileio import write_text_atomic
from .change_section import change_findings, change_page_parts
from .diagnosis_first_screen import at_a_glance
from .finding import HEADLINE_STYLE, Finding, headline_html
from .page import figure_png, figure_pngs, html_page, img_tag, new_figure
from .reference_section import reference_section_html

_STYLE = """
body { font-family: sans-serif; margin: 2em; max-width: 1200px; color: #222; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; margin-top: 1.6em; }
table { border-collapse: collapse; margin: 0.8em 0; font-size: 0.9em; }
th, td { border: 1px solid #bbb; padding: 3px 8px; text-align: right; }
th { background: #eee; } td.text, th.text { text-align: left; }
.verdict { font-size: 1.3em; font-weight: bold; padding: 0.4em 0.8em; background: #f3f3d8; display: inline-block; }
.note { color: #555; font-size: 0.9em; }
img { max-width: 100%; }
"""


def _figure_html(figure, alt: str) -> str:
    return img_tag(figure_png(figure, 90, tight=True), alt)


def _number(value: Any, digits: int = 3) -> str:
    if value is None:
        return "-"
    if isinstance(value, (float, np.floating)):
        if not math.isfinite(value):
            return "-"
        return f"{value:.{digits}g}"
    return html.escape(str(value))


def _write_atomic(path: Path, text: str) -> Path:
    return write_text_atomic(path, text)


def gap_map_plot(ds: xr.Dataset, variable: str, title: str):
    """Figure of a gap map (op x channel x family) of a diagnosis Dataset."""
    values = ds[variable].values               # (op, channel, family)
    n_op, n_channel, n_family = values.shape
    matrix = values.transpose(1, 2, 0).reshape(n_channel * n_family, n_op)
    labels = [f"{c} / {f}" for c in ds["channel"].values for f in ds["family"].values]
    figure = new_figure(1.0 + 0.7 * n_op, 0.28 * len(labels) + 1.2, layout=None)
    axis = figure.subplots()
    shown = np.log10(1.0 + np.nan_to_num(matrix, nan=0.0))
    # one scale for every map: the capped gap cannot exceed sqrt(99)
    image = axis.imshow(shown, aspect="auto", cmap="magma_r", vmin=0.0, vmax=math.log10(1.0 + math.sqrt(99.0)))
    axis.set_yticks(range(len(labels)), labels, fontsize=7)
    speeds = ds["pinion_speed"].values
    axis.set_xticks(range(n_op), [f"{i}\n{s:.0f}" for i, s in enumerate(speeds)], fontsize=7)
    axis.set_xlabel("held-out run (index / pinion speed, rpm)")
    axis.set_title(title, fontsize=9)
    bar = figure.colorbar(image, ax=axis)
    bar.set_label("log10(1 + excess RMS z)")
    return figure


def spectra_plot(ds: xr.Dataset):
    """Before/after: per held-out run, a row rig vs nominal model and a row rig vs model with the effect."""
    spectra = ds["amplitude_spectrum"]
    ops = spectra["spectrum_op"].values
    channels = spectra["channel"].values
    models = [str(source) for source in spectra["source"].values if source != "rig"]
    rows = [(op, model) for op in ops for model in models]
    figure = new_figure(4.2 * len(channels), 2.4 * len(rows), layout=None)
    axes = figure.subplots(len(rows), len(channels), squeeze=False)
    colours = {"nominal": "tab:blue", "with_effect": "tab:red"}
    frequency = spectra["frequency"].values
    for i, (op, model) in enumerate(rows):
        for c, channel in enumerate(channels):
            axis = axes[i, c]
            floor = float(ds["spectrum_noise_floor"].sel(spectrum_op=op, channel=channel))
            predicted = spectra.sel(spectrum_op=op, source=model, channel=channel).values
            measured = spectra.sel(spectrum_op=op, source="rig", channel=channel).values
            if np.any(np.isfinite(measured)):
                axis.semilogy(frequency, measured, lw=0.7, color="0.6", label="rig")
            if np.any(np.isfinite(predicted)):
                # the models are noise-free: shown as the rig would record them
                axis.semilogy(frequency, np.sqrt(predicted ** 2 + floor ** 2), lw=0.7, color=colours.get(model, "k"),
                              alpha=0.85, label=model.replace("_", " ") + " (held out)")
            both = np.concatenate([predicted, measured])
            both = both[np.isfinite(both) & (both > 0)]
            if both.size and floor > 0:
                axis.set_ylim(floor / 5.0, both.max() * 3.0)
            speed = float(ds["pinion_speed"].values[int(op)])
            axis.set_title(f"run {int(op)} ({speed:.0f} rpm), {channel}: rig vs {model.replace('_', ' ')}",
                           fontsize=8)
            axis.set_xlabel("frequency (Hz)", fontsize=7)
            axis.tick_params(labelsize=7)
            # a few labelled decades and no minor ticks: laying out the default tick labels of a dozen
            # log axes took most of a diagnosis report's time (5 s of 6, measured)
            axis.yaxis.set_major_locator(LogLocator(numticks=4))
            axis.yaxis.set_minor_locator(NullLocator())
            if c == 0:
                axis.legend(fontsize=7, loc="upper right")
    figure.tight_layout()
    return figure


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]], text_columns: Sequence[int] = (0,)) -> str:
    head = "".join(f'<th class="{"text" if i in text_columns else ""}">{html.escape(h)}</th>'
                   for i, h in enumerate(headers))
    body = []
    for row in rows:
        cells = "".join(f'<td class="{"text" if i in text_columns else ""}">{_number(v)}</td>'
                        for i, v in enumerate(row))
        body.append(f"<tr>{cells}</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def _decision_notes(content: Mapping[str, Any]) -> list[str]:
    """Paragraphs for a partial explanation and for figures that decided on a knife edge."""
    notes = []
    remaining = content.get("remaining_gap")
    if content.get("partial") and remaining:
        notes.append(f'<p class="note"><b>Partial explanation:</b> {html.escape(content["verdict"])} accounts '
                     f'for part of the gap; a held-out gap of {remaining["value"]:.2f} remains unexplained '
                     '(where: see the table of held-out discrepancies below).</p>')
    for entry in content.get("borderline", []):
        low, high = entry["interval"]
        notes.append(f'<p class="note"><b>Borderline:</b> {html.escape(_figure_name(entry))} = {entry["value"]:.3g} '
                     f'against a threshold of {entry["threshold"]:g}; its 90 % interval {low:.3g} to {high:.3g} '
                     'contains the threshold, so another campaign of the same rig could be decided the other '
                     'way.</p>')
    return notes


def _figure_name(entry: Mapping[str, Any]) -> str:
    """A borderline figure's name, with the effect it belongs to when forward selection added that effect."""
    return f"{entry['figure']} of {entry['effect']} (added on top)" if entry.get("effect") else str(entry["figure"])


def _design_notes(content: Mapping[str, Any]) -> list[str]:
    """Paragraphs saying what the model did with the design's geometry (an undercut tooth is modelled, not refused)."""
    return [f'<p class="note"><b>Design:</b> {html.escape(str(note))}.</p>'
            for note in content.get("design_notes") or []]


def _rig_notes(content: Mapping[str, Any]) -> list[str]:
    """Paragraphs saying what the campaign cannot show (ramp segments too short for the gear's lines)."""
    return [f'<p class="note"><b>Rig data:</b> {html.escape(str(note))}.</p>'
            for note in content.get("rig_notes") or []]


def _percent(value: Any) -> str:
    return "-" if value is None or not math.isfinite(float(value)) else f"{100 * float(value):.0f} %"


def _figure(value: Any, digits: int = 3, fixed: bool = False) -> str:
    """A number as plain text (no HTML escaping: the headline escapes its sentences itself); ``fixed``:
    ``digits`` decimals."""
    if value is None or not math.isfinite(float(value)):
        return "-"
    if fixed:
        return f"{float(value):.{digits}f}"
    return f"{float(value):.0f}" if abs(float(value)) >= 10 ** digits else f"{float(value):.{digits}g}"


def diagnosis_findings(content: Mapping[str, Any]) -> list[Finding]:
    """The headline statements of a diagnosis, from its JSON summary (``diagnosis.json``).

    The verdict in one sentence; the held-out gap before and after the effect with the shrink and its
    90 % interval; where the nominal model misses; the ``partial`` and ``borderline`` flags.
    """
    if not content:
        return []
    if content.get("change"):
        return [*change_findings(content), *_rig_findings(content)]
    verdict = str(content.get("verdict", "?"))
    gap = content.get("gap") or {}
    # the line a fleet engineer reads first: verdict, certainty, evidence, next step
    findings = [at_a_glance(content), _verdict_finding(content, verdict)]
    findings += _gap_findings(gap)
    findings.append(_where_finding(content, verdict, gap))
    findings += _effect_set_findings(content, verdict)
    findings += _borderline_findings(content)
    findings += [Finding(f"Cannot tell: {entry['reason']}.",
                         {key: entry.get(key) for key in ("effect", "shaft", "run_out_m",
                                                          "share_of_class_gears_below", "classes")},
                         "cannot_tell") for entry in content.get("cannot_tell") or []]
    return [*findings, *_rig_findings(content)]


def _verdict_finding(content: Mapping[str, Any], verdict: str) -> Finding:
    """The verdict in one sentence, with the reason the diagnosis gives."""
    reason = str(content.get("reason", "")).rstrip(".")
    if verdict == "none":
        text = "Verdict none: the nominal model reproduces the rig within noise, no effect is needed"
    elif verdict == "unexplained":
        text = "Verdict unexplained: a significant gap remains that no candidate effect of the library removes"
    elif verdict == "inconclusive" and content.get("ambiguity"):
        ambiguity = content["ambiguity"]
        names = [str(entry.get("description") or entry.get("name")) for entry in ambiguity.get("candidates") or []]
        text = (f"Verdict inconclusive: {' and '.join(names)} explain the gap on {ambiguity.get('channel')} "
                "alike, and these data cannot tell them apart, so neither is claimed")
    elif verdict == "inconclusive":
        # never read as "healthy": the data did not allow a comparison at all
        text = ("Verdict inconclusive: the data cannot decide whether the gear is healthy or carries an effect, "
                "so neither is claimed")
    else:
        effects = [entry["effect"] for entry in content.get("effects") or []]
        if len(effects) > 1:
            text = (f"Verdict {verdict} with {' and '.join(effects[1:])}: adding these {len(effects)} effects "
                    "together to the model explains " + ("part of " if content.get("partial") else "")
                    + f"the gap between model and rig, {verdict} the largest share")
        else:
            text = (f"Verdict {verdict}: adding {verdict} to the model explains "
                    + ("part of " if content.get("partial") else "") + "the gap between model and rig")
    return Finding(text + (f"; {reason}." if reason else "."),
                   {"verdict": verdict, "partial": bool(content.get("partial"))}, "verdict")


def _gap_findings(gap: Mapping[str, Any]) -> list[Finding]:
    """The held-out gap of the nominal model, and with the effect, with the shrink and its 90 % interval."""
    if not gap:
        return []
    if gap.get("baseline") is None:
        return [Finding("Held-out gap not measured: no feature could be compared with the model on "
                        "held-out runs.", {"baseline": None}, "gap")]

    def gap_value(value: Any) -> str:
        return _figure(value, 2, fixed=True)

    facts = {key: gap.get(key) for key in ("baseline", "baseline_interval", "with_effect", "effect",
                                           "effect_named", "shrink_fraction", "shrink_interval",
                                           "noise_threshold")}
    text = ("Held-out gap (RMS standardised discrepancy in excess of noise) of the nominal model "
            + gap_value(gap.get("baseline")))
    if gap.get("baseline_interval"):
        low, high = gap["baseline_interval"]
        text += f" (90 % interval {gap_value(low)} to {gap_value(high)})"
    baseline, noise = gap.get("baseline"), gap.get("noise_threshold")
    # a candidate's gap is worth quoting where it was named or where there is a gap to shrink
    worth = gap.get("effect_named") or (baseline is not None and noise is not None and baseline >= noise)
    if gap.get("effect") and gap.get("with_effect") is not None and worth:
        low, high = gap.get("shrink_interval") or [None, None]
        named = "" if gap.get("effect_named", True) else " (best candidate, not named)"
        text += (f"; with {gap['effect']}{named} {gap_value(gap['with_effect'])}: a shrink of "
                 f"{_percent(gap.get('shrink_fraction'))} (90 % interval {_percent(low)} to {_percent(high)})")
    return [Finding(text + f"; within noise below {_figure(noise)}.", facts, "gap")]


def _where_finding(content: Mapping[str, Any], verdict: str, gap: Mapping[str, Any]) -> Finding:
    """The features where the nominal model misses most on held-out runs."""
    where = content.get("where") or []
    n_op = int((content.get("rig") or {}).get("n_op", 0))
    if verdict == "inconclusive" and gap.get("baseline") is None:
        text = "No held-out comparison was made: the nominal model was not fitted to data that cannot decide."
    elif where:
        of = f" of {n_op}" if n_op else ""
        shown = "; ".join(f"{w['channel']} {w['feature']} ({str(w['family']).replace('_', ' ')} family, beyond "
                          f"3 sigma at {len(w['ops'])}{of} runs, RMS z {_figure(w['score'])})" for w in where[:3])
        text = (f"The nominal model misses most at {shown}"
                + (f"; {len(where)} features beyond 3 sigma in all" if len(where) > 3 else "") + ".")
    else:
        text = "No held-out feature of the nominal model is beyond 3 sigma."
    return Finding(text, {"where": [dict(w) for w in where[:3]], "count": len(where)}, "where")


def _effect_set_findings(content: Mapping[str, Any], verdict: str) -> list[Finding]:
    """Each effect's share of the shrink (several named) and the gap left unexplained (a partial verdict)."""
    findings = []
    effects = content.get("effects") or []
    if len(effects) > 1:
        shares = "; ".join(f"{entry['effect']} ({entry['variant']}) {_percent(entry['shrink_share'])}"
                           for entry in effects)
        findings.append(Finding(f"Effects named by forward selection, each with its share of the held-out gap "
                                f"shrink: {shares}.",
                                {"effects": [{key: entry.get(key) for key in ("effect", "variant", "shrink_share")}
                                             for entry in effects]}, "effects"))
    if content.get("partial"):
        remaining = (content.get("remaining_gap") or {}).get("value")
        after = " + ".join(entry["effect"] for entry in effects) if effects else verdict
        findings.append(Finding(f"Partial explanation: a held-out gap of {_figure(remaining, 2, fixed=True)} "
                                f"remains unexplained after {after}.",
                                {"partial": True, "remaining_gap": remaining}, "partial"))
    return findings


def _borderline_findings(content: Mapping[str, Any]) -> list[Finding]:
    """The deciding figures whose 90 % interval holds their threshold, or that there are none."""
    findings = []
    for entry in content.get("borderline") or []:
        low, high = entry["interval"]
        findings.append(Finding(
            f"Borderline: {_figure_name(entry)} = {_figure(entry['value'])} against a threshold of "
            f"{float(entry['threshold']):g}; its 90 % interval {_figure(low)} to {_figure(high)} contains the "
            "threshold, so another campaign of the same rig could be decided the other way.",
            {key: entry.get(key) for key in ("figure", "value", "threshold", "interval")}, "borderline"))
    if not content.get("borderline"):
        findings.append(Finding("No borderline figure: none of the figures that decided the verdict has its "
                                "threshold inside its 90 % interval.", {"borderline": []}, "borderline"))
    return findings


def _rig_findings(content: Mapping[str, Any]) -> list[Finding]:
    """What the campaign cannot show, on the first screen: a verdict read from it carries that caveat."""
    return [Finding(f"Rig data: {note}.", {"rig_note": note}, "rig") for note in content.get("rig_notes") or []]


def _parameter_text(entry: Mapping[str, Any]) -> str:
    """Fitted parameters of a named effect with their 90 % intervals where the fit gave them; a parameter the
    data leave open is said to be open (the fit's value is a placeholder there)."""
    intervals = entry.get("parameter_intervals") or {}
    choices = entry.get("parameter_choices") or {}
    texts = []
    for key, value in (entry.get("parameters") or {}).items():
        if key in choices:
            texts.append(f"{key} not identified (any of {len(choices[key])})")
            continue
        text = f"{key}={_number(value, 4)}"
        if key in intervals and intervals[key] is not None and None not in intervals[key]:
            low, high = intervals[key]
            text += f" [{_number(low, 3)}, {_number(high, 3)}]"
        texts.append(text)
    return ", ".join(texts)


def _effect_set_html(content: Mapping[str, Any], figures: Mapping[str, str]) -> list[str]:
    """The named effects in the order forward selection added them, and the gap that remains, with where."""
    effects = content.get("effects") or []
    remaining = content.get("remaining_gap")
    parts = []
    if effects:
        parts += ["<h2>The named effects (forward selection)</h2>",
                  _table(["order", "effect", "variant", "score on top (nats)", "gap before", "gap after",
                          "share of the shrink", "fit", "parameters [90 % interval]"],
                         [[k + 1, e["effect"], e["variant"], e["score"], e["gap_before"], e["gap_after"],
                           _percent(e["shrink_share"]), e["fit"], _parameter_text(e)]
                          for k, e in enumerate(effects)], (1, 2, 6, 7, 8)),
                  '<p class="note">Each effect after the first was screened and fitted with the earlier ones '
                  'present in the simulation, scored on held-out runs against the model with the earlier ones, '
                  'and added by the same rule as the first (score beyond its penalty, its own gain, a shrink of '
                  'the remaining gap). Share: the gap shrink it brought as a fraction of the nominal model\'s '
                  'gap. Parameter intervals: Laplace approximation at the fit.</p>']
    for selection in content.get("forward_selection") or []:
        if selection.get("added") is None and selection.get("candidates"):
            best = selection["candidates"][0]
            parts.append(f'<p class="note">On top of {html.escape(" + ".join(selection["base"]))} no further effect '
                         f'was added: the best, {html.escape(best["variant"])}, scores {_number(best["score"])} nats '
                         f'and shrinks the remaining gap of {_number(selection["gap_before"])} by '
                         f'{_percent(best["shrink_fraction"])}.</p>')
        elif selection.get("added") is None and selection.get("reason"):
            parts.append(f'<p class="note">On top of {html.escape(" + ".join(selection["base"]))} no further effect '
                         f'was tried: {html.escape(selection["reason"])}.</p>')
    if remaining and effects:
        parts.append(f'<h2>What remains: held-out gap {_number(remaining["value"])} with '
                     f'{html.escape(" + ".join(e["effect"] for e in effects))}</h2>')
        if "gap_map_final" in figures:
            parts.append(figures["gap_map_final"])
        if remaining.get("where"):
            parts.append(_table(["channel", "feature", "family", "runs beyond 3 sigma", "RMS z"],
                                [[w["channel"], w["feature"], w["family"], ", ".join(map(str, w["ops"])), w["score"]]
                                 for w in remaining["where"]], (0, 1, 2, 3)))
        else:
            parts.append("<p>No held-out feature of the final model is beyond 3 sigma.</p>")
    return parts


def _diagnosis_figures(content: Mapping[str, Any], ds: xr.Dataset) -> dict[str, str]:
    """The report's figures as ``<img>`` elements, drawn side by side (:func:`~.page.figure_pngs`)."""
    makers: dict[str, tuple[Any, str]] = {}
    # the spectra, the dearest, first: the gap maps share the other process
    if "amplitude_spectrum" in ds:
        makers["spectra"] = (lambda: spectra_plot(ds), "held-out spectra")
    if "gap_map_nominal" in ds:
        title = "nominal model, held-out runs"
        makers["gap_map_nominal"] = (lambda: gap_map_plot(ds, "gap_map_nominal", title), title)
    if "gap_map_with_effect" in ds:
        effect_title = f"with {ds['candidate'].values[0]}, held-out runs"
        makers["gap_map_with_effect"] = (lambda: gap_map_plot(ds, "gap_map_with_effect", effect_title),
                                         effect_title)
    if "gap_map_final" in ds and content.get("remaining_gap") and content.get("effects"):
        final_title = "model with all named effects, held-out runs"
        makers["gap_map_final"] = (lambda: gap_map_plot(ds, "gap_map_final", final_title), final_title)
    pngs = figure_pngs([make for make, _ in makers.values()], 90, tight=True)
    return {key: img_tag(png, alt) for (key, (_, alt)), png in zip(makers.items(), pngs)}


def _pitch_error_notes(content: Mapping[str, Any]) -> list[str]:
    """What the pitch-error allowance did, and the eccentricities a mesh-stiffness modulation let be named."""
    pitch = content.get("pitch_errors")
    if not pitch:
        return []
    if not pitch["applied"]:
        return [f"<p class=\"note\">Pitch errors: no allowance ({html.escape(pitch['reason'])}).</p>"]
    parts = [f"<p>Pitch errors: {html.escape(pitch['reason'])}. What {pitch['draws']} random draws do to each "
             "feature is model error of the nominal model; no effect is named for what such errors can do.</p>"]
    factors = pitch.get("order_factors") or {}
    if factors:
        rows = [[gear, order, entry["factor"], f"{entry['low']:.3g} to {entry['high']:.3g}",
                 1e6 * entry["amplitude_m"],
                 f"{1e6 * entry['amplitude_range_m'][0]:.2g} to {1e6 * entry['amplitude_range_m'][1]:.3g}",
                 _percent(entry.get("share_of_class_gears_below"))]
                for gear, orders in factors.items() for order, entry in orders.items()]
        parts += ['<p class="note">The rig\'s gears are one draw, the same in every run: each gear\'s share of '
                  "the allowance at each shaft order (its shaft line and the sidebands of that order) is scaled "
                  "to what the rig shows, within the range gears of the stated classes give (1 % to 99 %). As "
                  "read by the nominal fit; |E_j| is the gear's tooth positions' j-th Fourier coefficient along "
                  "the line of action (at order 1 its run-out, which an eccentricity within that range cannot "
                  "be told from):</p>",
                  _table(["gear", "shaft order", "factor on the allowance's power", "range", "|E_j| um",
                          "range um", "class gears below"], rows, (0, 1, 3, 5, 6))]
    modulated = [r for r in content.get("ranking", []) if r.get("modulation_gain") is not None]
    if modulated:
        parts.append('<p class="note">Pitch errors make a run-out but no mesh-stiffness modulation: an '
                     "eccentricity within their run-out is named only where its fit is clearly worse with its "
                     "modulation off (by at least the effect-gain threshold); here "
                     + ", ".join(f"{html.escape(r['variant'])} {r['modulation_gain']:.1f} nats" for r in modulated)
                     + ".</p>")
    phases = content.get("sideband_phases") or []
    if phases:
        parts.append('<p class="note">An eccentric shaft also modulates the mesh stiffness, which pitch errors do '
                     "not: the phase sums of each tested shaft's first sidebands around the mesh harmonics, scored "
                     "with an eccentricity of the run-out read (at the best of the modulations tried) against the "
                     "gears' pitch errors alone; an eccentricity is named from them at a log ratio of "
                     f"{phases[0]['threshold']:g} nats: "
                     + "; ".join(f"{html.escape(entry['shaft'])} {entry['log_ratio']:.0f} nats over "
                                 f"{entry['n_sums']} sums (kappa {entry['kappa']:g}, "
                                 f"{'named' if entry['named'] else 'not named'})" for entry in phases)
                     + ".</p>")
    return parts


def diagnosis_report_html(content: Mapping[str, Any], ds: xr.Dataset) -> str:
    """HTML text of a diagnosis report from its JSON summary and Dataset."""
    if content.get("change"):
        # against a healthy reference: what changed, where, which effect explains what share of it
        return html_page(f"uqgear diagnosis: {content['verdict']}", _STYLE + HEADLINE_STYLE, [
            "<h1>What changed since the healthy reference</h1>",
            headline_html(diagnosis_findings(content), "Details below."),
            f'<p class="verdict">verdict: {html.escape(content["verdict"])}</p>',
            f'<p>{html.escape(content["reason"])}.</p>', *change_page_parts(content)])
    figures = _diagnosis_figures(content, ds)
    parts = [*_verdict_parts(content), *_held_out_gap_parts(content), *_effect_set_html(content, figures)]
    parts += _where_parts(content, ds, figures)
    parts += _pitch_error_notes(content)
    parts += _ranking_parts(content)
    if "amplitude_spectrum" in ds:
        parts.append("<h2>Spectra on held-out runs: rig, nominal model, model with the effect</h2>"
                     "<p class=\"note\">The two runs with the largest nominal gap, each predicted by the models "
                     "fitted without it; model spectra include the rig's noise floor.</p>")
        parts.append(figures["spectra"])
    parts += _nominal_fit_parts(content)
    parts += reference_section_html(content)
    return html_page(f"uqgear diagnosis: {content['verdict']}", _STYLE + HEADLINE_STYLE, parts)


def _verdict_parts(content: Mapping[str, Any]) -> list[str]:
    """Title, headline, the rig, the verdict with its reason and the notes on decision, design and rig."""
    return ["<h1>Sim-to-real gap diagnosis</h1>",
            headline_html(diagnosis_findings(content), "Details, maps and the candidate ranking below."),
            f'<p class="note">rig: {html.escape(str(content["rig"]["source"]))} '
            f'({html.escape(content["rig"]["title"])}), {content["rig"]["n_op"]} runs, channels '
            f'{", ".join(content["rig"]["channels"])}</p>',
            f'<p class="verdict">verdict: {html.escape(content["verdict"])}</p>',
            f'<p>{html.escape(content["reason"])}.</p>',
            *_decision_notes(content),
            *_design_notes(content),
            *_rig_notes(content)]


def _held_out_gap_parts(content: Mapping[str, Any]) -> list[str]:
    """How far: the gap on held-out runs of the nominal model and with the effect."""
    gap = content["gap"]
    return ["<h2>How far: the gap on held-out runs</h2>",
            _table(["metric", "nominal model", "with effect", "effect", "shrink fraction", "90 % interval"],
                   [[gap["metric"], gap["baseline"], gap["with_effect"], gap["effect"], gap["shrink_fraction"],
                     "-" if gap["shrink_interval"] is None else
                     f"{gap['shrink_interval'][0]:.2f} to {gap['shrink_interval'][1]:.2f}"]], (0, 3, 5)),
            f'<p class="note">{html.escape(gap["evaluated_on"]["scheme"])}. The gap is the RMS standardised '
            f'discrepancy in excess of noise (each feature capped at 10 sigma); the nominal model is within '
            f'noise below {gap["noise_threshold"]}.</p>']


def _where_parts(content: Mapping[str, Any], ds: xr.Dataset, figures: Mapping[str, str]) -> list[str]:
    """Where: gap maps, the signal per run, the features and families that miss, fixed lines."""
    parts = []
    if "gap_map_nominal" in ds:
        parts += ["<h2>Where: gap map of the nominal model (held-out runs)</h2>",
                  figures["gap_map_nominal"]]
    signal = content.get("signal")
    if signal:
        parts += ["<h2>Signal: the strongest line of each run</h2>",
                  _table(["run", "strongest line (noise spreads)", "needed"],
                         [[op, value, signal["threshold"]] for op, value in enumerate(signal["strongest_line_snr"])])]
    if "gap_map_with_effect" in ds:
        parts.append(figures["gap_map_with_effect"])
    if content["where"]:
        parts.append(_table(["channel", "feature", "family", "runs beyond 3 sigma", "RMS z"],
                            [[w["channel"], w["feature"], w["family"], ", ".join(map(str, w["ops"])), w["score"]]
                             for w in content["where"]], (0, 1, 2, 3)))
    families = [f for f in content["families"] if f["character"]]
    if families:
        parts.append(_table(["channel", "family", "excess RMS z", "character"],
                            [[f["channel"], f["family"], f["score"], ", ".join(f["character"])] for f in families],
                            (0, 1, 3)))
    if content["frequency_locked_lines"]:
        parts.append("<p>Lines at a fixed frequency across runs (not order-locked): " + ", ".join(
            f"{line['frequency']:.1f} Hz (runs {', '.join(map(str, line['ops']))})"
            for line in content["frequency_locked_lines"]) + ".</p>")
    if content.get("line_interference"):
        parts.append("<p>Line interference (a fixed line on an accelerometer that the TE lacks), left out of the "
                     "low band: " + ", ".join(f"{line['frequency']:.1f} Hz on {html.escape(line['channel'])}"
                                              for line in content["line_interference"]) + ".</p>")
    return parts


def _ranking_parts(content: Mapping[str, Any]) -> list[str]:
    """Which: the candidate effects ranked by held-out score, with the naming rule."""
    return ["<h2>Which: candidate effects ranked</h2>",
            _table(
                ["effect", "variant", "score (nats)", "gain (nats)", "s.e.", "penalty", "gap with effect", "shrink",
                 "shrink 5 %", "shrink 95 %", "fit", "parameters"],
                [[r["effect"], r["variant"], r["score"], r["delta_log_density"], r["standard_error"], r["penalty"],
                  r["gap_with_effect"], r["shrink_fraction"], r["shrink_interval"][0], r["shrink_interval"][1],
                  r["fit"], ", ".join(f"{k}={_number(v, 4)}" for k, v in r["parameters"].items())]
                 for r in content["ranking"]],
                (0, 1, 10, 11)),
            '<p class="note">Score: held-out log predictive density gain over the nominal model minus '
            f'0.5 log(n) per effect parameter; an effect is named at a score of '
            f'{content["thresholds"]["score"]:g} or more with a shrink of at least '
            f'{content["thresholds"]["shrink_fraction"]:g}.</p>']


def _nominal_fit_parts(content: Mapping[str, Any]) -> list[str]:
    """The nominal model's fitted parameters, T2 per run, periodicity, model error and time."""
    nominal = content["nominal"]
    parts = ["<h2>Nominal fit</h2>"]
    if nominal is None:
        parts.append("<p>Not fitted: the data cannot decide (see the verdict).</p>")
    else:
        parts.append(_table(["parameter", "value"], [[k, v] for k, v in nominal["parameters"].items()]))
        parts.append(f'<p class="note">T2 per run (kN m): '
                     f'{", ".join(f"{v / 1e3:.2f}" for v in nominal["adhesion_torque"])}; '
                     f'periodic steady response: {", ".join("yes" if p else "no" for p in nominal["periodic_runs"])}; '
                     f'model error (relative): {html.escape(json.dumps(content["model_error"]))}; '
                     f'time: {content["timing_s"].get("total_wall", float("nan")):.0f} s.</p>')
    return parts


def write_diagnosis_report(content: Mapping[str, Any], ds: xr.Dataset, path: str | os.PathLike[str]) -> Path:
    """Write the diagnosis report (self-contained HTML) atomically."""
    return _write_atomic(Path(path), diagnosis_report_html(content, ds))


def blindtest_report_html(content: Mapping[str, Any]) -> str:
    """HTML text of a blind-test report from its JSON summary."""
    labels = content["labels"]
    matrix = np.array(content["confusion"]["counts"], dtype=float)
    figure = new_figure(1.2 + 0.75 * matrix.shape[1], 1.0 + 0.55 * matrix.shape[0], layout=None)
    axis = figure.subplots()
    axis.imshow(matrix, cmap="Blues")
    axis.set_xticks(range(matrix.shape[1]), content["confusion"]["verdicts"], rotation=45, ha="right", fontsize=7)
    axis.set_yticks(range(matrix.shape[0]), labels, fontsize=7)
    for i in range(matrix.shape[0]):
        for j in range(matrix.shape[1]):
            if matrix[i, j]:
                axis.text(j, i, f"{int(matrix[i, j])}", ha="center", va="center", fontsize=8)
    axis.set_xlabel("verdict")
    axis.set_ylabel("true effect")
    axis.set_title("blind test: confusion matrix", fontsize=9)
    parts = ["<h1>Blind test of the gap diagnosis</h1>",
             f"<p>{content['n_campaigns']} campaigns; accuracy {100 * content['accuracy']:.1f} % "
             f"(counting 'none' as right for effects below detectability: "
             f"{100 * content['accuracy_detectable']:.1f} %); effects named on healthy controls: "
             f"{content['false_alarms']}; median shrink when identified: "
             f"{_number(content['shrink']['median'])}.</p>",
             '<p class="note">Test plans: "service" is the public campaigns\' 8 service points; '
             '"bearing_check" a light-load run (T1 1.5 kN m) through the two bearing-dominated modes, where a '
             'bearing unloads. Bearing-clearance campaigns follow the bearing check (a clearance cannot show '
             'at service loads), the other effects the service plan; healthy controls alternate both.</p>',
             _figure_html(figure, "confusion matrix"),
             "<h2>Detection threshold per effect</h2>",
             _table(["effect", "parameter", "detected at or above", "missed at or below", "note"],
                    [[t["effect"], t["parameter"], t["detected_from"], t["missed_up_to"], t["note"]]
                     for t in content["thresholds"]], (0, 1, 4)),
             *_effect_set_scores_html(content),
             "<h2>Campaigns</h2>",
             _table(["id", "truth", "strength", "design", "plan", "oracle gap", "verdict", "effects named",
                     "cannot tell", "sideband phases, nats", "shrink", "seconds"],
                    [[c["id"], " + ".join(c.get("truth_effects") or [c["truth"]]), c["strength"], c["design"],
                      c.get("plan", "service"), c["oracle_gap"], c["verdict"],
                      " + ".join(c.get("effects_named") or []) or "-", " + ".join(c.get("cannot_tell") or []) or "-",
                      ", ".join(f"{shaft} {value:.0f}" for shaft, value in
                                (c.get("sideband_phase_log_ratios") or {}).items()) or "-",
                      c["shrink_fraction"], c["seconds"]]
                     for c in content["campaigns"]],
                    (0, 1, 3, 4, 6, 7, 8, 9))]
    return html_page("uqgear blind test", _STYLE, parts)


def _effect_set_scores_html(content: Mapping[str, Any]) -> list[str]:
    """Per-effect precision and recall of the named effect sets, and how often a set was exactly right."""
    sets = content.get("effect_sets")
    if not sets:
        return []
    return ["<h2>Effect sets: precision and recall per effect</h2>",
            f"<p>Named set exactly the true set: {_percent(sets['set_exact'])} of the campaigns"
            + (f" ({_percent(sets['set_exact_multi_effect'])} of the {sets['n_multi_effect']} with several effects)"
               if sets.get("n_multi_effect") else "")
            + (f"; healthy controls with an effect named: {sets['controls_with_an_effect_named']} of "
               f"{sets['n_controls']}" if sets.get("n_controls") is not None else "") + ".</p>",
            *([f"<p>Against the effects the data can tell (each effect's visibility next to the others "
               f"beyond the noise-gap threshold, by the diagnosis's own model error, pitch-error allowance "
               f"included): "
               f"{_percent(sets['set_exact_identifiable'])} exactly right; effects too faint to tell: "
               f"{sets['effects_not_identifiable']}.</p>"] if "set_exact_identifiable" in sets else []),
            *([f"<p>Effects missed: {sets['effects_missed']}, of which reported as a run-out the lines cannot "
               f"tell from the gears' own pitch errors: {sets['effects_missed_reported_cannot_tell']}; healthy "
               f"controls with such a report: {sets['controls_with_cannot_tell']} of {sets['n_controls']} (one "
               f"gear in ten of the stated classes has a first-order error that large).</p>"]
              if "effects_missed_reported_cannot_tell" in sets else []),
            _table(["effect", "acting", "named", "named and acting", "precision", "recall",
                    "median shrink share"],
                   [[r["effect"], r["acting"], r["named"], r["correct"], r["precision"], r["recall"],
                     r.get("shrink_share_median")] for r in sets["per_effect"]])]


def write_blindtest_report(content: Mapping[str, Any], path: str | os.PathLike[str]) -> Path:
    """Write the blind-test report (self-contained HTML) atomically."""
    return _write_atomic(Path(path), blindtest_report_html(content))


__all__ = ["diagnosis_report_html", "diagnosis_findings", "write_diagnosis_report", "blindtest_report_html",
           "write_blindtest_report"]
