"""The first screen of a differential diagnosis against a healthy reference (``uqgear diagnose --reference``).

:func:`change_findings` states what changed since the reference, where, and
which effect explains what share of the change; :func:`change_page_parts`
renders the ``change`` entry of ``diagnosis.json`` (the change test, the
effects' shares of the change by channel, the runs not judged, the stages'
times). It works on the JSON content only, so the diagnosis report calls it
without importing the diagnosis.
"""

from __future__ import annotations

import html
import math
from collections.abc import Mapping, Sequence
from typing import Any

from .finding import Finding


def _text(value: Any, digits: int = 3) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-"
    if isinstance(value, float):
        return f"{value:.{digits}g}"
    return html.escape(str(value))


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in headers)
    body = "".join("<tr>" + "".join(f"<td>{_text(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def _where(entry: Mapping[str, Any]) -> str:
    shaft = f" of the {entry['shaft']}" if entry.get("shaft") else ""
    speeds = ", ".join(f"{speed:g}" for speed in entry["speeds_rpm"])
    return (
        f"{entry['channel']} {str(entry['family']).replace('_', ' ')}{shaft} {entry['direction']} "
        f"{abs(entry['largest_db']):.1f} dB ({entry['kind']}; at {speeds} rpm)"
    )


def change_findings(content: Mapping[str, Any]) -> list[Finding]:
    """What changed since the reference, where, and which effect explains what share of it."""
    change = content["change"]
    test = change["test"]
    verdict = str(content.get("verdict", "?"))
    findings = []
    largest = test.get("largest") or {}
    if not test["changed"]:
        findings.append(
            Finding(
                f"Verdict none: nothing changed since the reference beyond what two healthy campaigns of this rig "
                f"differ by; the largest change, {largest.get('channel')} {largest.get('feature')} at "
                f"{largest.get('speed_rpm', float('nan')):g} rpm, is {largest.get('change_db', float('nan')):+.1f} dB "
                f"against a threshold of {largest.get('threshold_db', float('nan')):.1f} dB.",
                {"verdict": verdict, "largest": dict(largest)},
                "verdict",
            )
        )
    else:
        where = test["where"]
        findings.append(
            Finding(
                f"Changed since the reference: {'; '.join(_where(entry) for entry in where[:3])}"
                + (f"; {len(where)} groups of features in all" if len(where) > 3 else "")
                + ".",
                {"where": [dict(entry) for entry in where[:3]], "count": len(where)},
                "where",
            )
        )
        named = change.get("named")
        ranking = change.get("ranking") or []
        if named is not None:
            channels = ", ".join(f"{channel} {share:.0%}" for channel, share in named["share_by_channel"].items())
            parameters = ", ".join(f"{key}={_text(value, 3)}" for key, value in named["parameters"].items())
            findings.append(
                Finding(
                    f"Verdict {verdict}: {named['variant']} ({parameters}) explains {named['share']:.0%} of the change "
                    f"({channels}).",
                    {"verdict": verdict, "named": dict(named)},
                    "verdict",
                )
            )
        else:
            best = ranking[0] if ranking else None
            text = "Verdict unexplained: no effect of the library predicts the change"
            if best is not None:
                text += f" (the best, {best['variant']}, explains {best['share']:.0%})"
            findings.append(Finding(text + ".", {"verdict": verdict}, "verdict"))
    inconclusive = test.get("inconclusive_runs") or []
    if inconclusive:
        findings.append(
            Finding(
                f"Not judged ({len(inconclusive)} runs outside the reference's range, inconclusive there): "
                + "; ".join(f"run {entry['op']}: {entry['reason']}" for entry in inconclusive[:3])
                + ".",
                {"inconclusive_runs": list(inconclusive)},
                "coverage",
            )
        )
    return findings


def change_page_parts(content: Mapping[str, Any]) -> list[str]:
    """The sections of a differential diagnosis's report after its first screen."""
    change = content["change"]
    test = change["test"]
    parts = [
        f'<p class="note">reference: {html.escape(str(change["reference"]))} ({change["gears"]} gears); '
        f"{test['judged_runs']} runs judged, {test['features_changed']} of {test['features_compared']} "
        "features changed.</p>",
        "<h2>Where: the changed features</h2>",
    ]
    if test["where"]:
        parts.append(
            _table(
                [
                    "channel",
                    "family",
                    "shaft",
                    "kind",
                    "direction",
                    "largest change (dB)",
                    "over its threshold",
                    "runs",
                ],
                [
                    [
                        w["channel"],
                        w["family"],
                        w["shaft"] or "-",
                        w["kind"],
                        w["direction"],
                        w["largest_db"],
                        w["largest_ratio"],
                        ", ".join(map(str, w["ops"])),
                    ]
                    for w in test["where"]
                ],
            )
        )
    else:
        parts.append("<p>No feature changed beyond its threshold.</p>")
    if change.get("ranking"):
        parts.append("<h2>Which: the effects' shares of the change</h2>")
        channels = list(change["ranking"][0]["share_by_channel"])
        parts.append(
            _table(
                ["effect", "variant", "share of the change", *[f"share on {c}" for c in channels], "parameters"],
                [
                    [
                        r["effect"],
                        r["variant"],
                        r["share"],
                        *[r["share_by_channel"][c] for c in channels],
                        ", ".join(f"{k}={_text(v, 4)}" for k, v in r["parameters"].items()),
                    ]
                    for r in change["ranking"]
                ],
            )
        )
        thresholds = change["thresholds"]
        parts.append(
            f'<p class="note">An effect is named when it explains at least '
            f"{thresholds['change_share']:.0%} of the change (docs/model/unmodelled-effects.md section 6.1).</p>"
        )
    timing = content.get("timing_s") or {}
    stages = ", ".join(
        f"{key.replace('_', ' ')} {value:.1f} s"
        for key, value in timing.items()
        if key not in ("workers",) and isinstance(value, (int, float))
    )
    parts.append(f'<p class="note">Stages: {html.escape(stages)}.</p>')
    return parts


__all__ = ["change_findings", "change_page_parts"]
