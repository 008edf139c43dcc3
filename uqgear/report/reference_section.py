"""The report section on a healthy reference campaign (``uqgear diagnose --reference``).

:func:`reference_section_html` renders the ``reference`` entry of
``diagnosis.json`` (:mod:`uqgear.diagnosis.allowances.reference`): the reference file
and its nominal fit, per channel the learned gain over frequency with its
2-sigma band and the lines it rests on, and the matched operating points.
It works on the JSON content only, so the diagnosis report can call it
(``parts += reference_section_html(content)``) without importing the diagnosis.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .page import figure_png, img_tag, new_figure


def _number(value: Any, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if isinstance(value, (float, np.floating)):
        return f"{value:.{digits}g}"
    return html.escape(str(value))


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{_number(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def reference_gain_plot(reference: Mapping[str, Any]):
    """Figure: per channel the learned gain rig/model over frequency, its 2-sigma band and the lines used."""
    channels = reference["channels"]
    figure = new_figure(7.5, 2.2 * max(1, len(channels)), layout="constrained")
    axes = figure.subplots(max(1, len(channels)), 1, squeeze=False)[:, 0]
    for axis, (channel, entry) in zip(axes, channels.items()):
        curve = entry["curve"]
        frequency = np.asarray(curve["frequency"], dtype=float)
        axis.fill_between(frequency, curve["low"], curve["high"], color="tab:blue", alpha=0.2, lw=0,
                          label="2-sigma band")
        axis.plot(frequency, curve["gain"], color="tab:blue", label="learned gain")
        points = entry["points"]
        if points["frequency"]:
            axis.plot(points["frequency"], np.exp(points["log_ratio"]), "k.", ms=4, label="lines (rig / model)")
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_ylabel(f"{channel}\ngain")
        axis.grid(True, which="both", alpha=0.3)
    axes[-1].set_xlabel("frequency (Hz)")
    axes[0].legend(loc="best", fontsize="small")
    return figure


def reference_section_html(content: Mapping[str, Any]) -> list[str]:
    """HTML parts of the reference section of a diagnosis report; empty without a reference.

    Parameters
    ----------
    content : mapping
        The content of ``diagnosis.json``.

    Returns
    -------
    list of str
        Heading, note, gain figure and tables, to append to the report's parts.
    """
    reference = content.get("reference")
    if not reference:
        return []
    fit = reference.get("nominal_fit", {})
    parts = ["<h2>Reference: what the healthy campaign of this rig shows against the model</h2>",
             f'<p class="note">reference campaign {html.escape(str(reference["file"]))}: the nominal model '
             f'fitted to it (robust cost {_number(fit.get("cost"))}); per channel the gain rig/model of its '
             'lines as a smooth function of frequency (the transfer path), carried to this campaign: its model '
             'features are multiplied by the gain and their model error widened by its uncertainty.</p>']
    if reference.get("channels"):
        parts.append(img_tag(figure_png(reference_gain_plot(reference), 90, tight=True),
                             "learned gain per channel"))
        parts.append(_table(
            ["channel", "lines", "down-weighted", "largest gain", "at (Hz)", "2-sigma interval", "scatter (ln)"],
            [[channel, entry["lines"], entry["lines_dropped"], entry["largest_gain"]["gain"],
              entry["largest_gain"]["frequency"],
              "{:.3g} to {:.3g}".format(*entry["largest_gain"]["interval_2sd"]), entry["scatter"]]
             for channel, entry in reference["channels"].items()]))
    parameters = fit.get("parameters") or {}
    if parameters:
        parts.append(_table(["reference fit: " + name for name in parameters], [list(parameters.values())]))
    matched = reference.get("matched_operating_points") or []
    if matched:
        parts.append(_table(["run", "reference run", "speed (rpm)", "reference speed", "T1 (N m)",
                             "reference T1"],
                            [[m["op"], m["reference_op"], m["pinion_speed"], m["reference_pinion_speed"],
                              m["drive_torque"], m["reference_drive_torque"]] for m in matched]))
    return parts


__all__ = ["reference_section_html", "reference_gain_plot"]
