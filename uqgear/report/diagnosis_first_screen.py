"""The first line of a diagnosis report: the verdict, how sure it is, where the evidence is, what to do next.

A fleet engineer reads one line per campaign. :func:`at_a_glance` writes it
from ``diagnosis.json``: the verdict; ``sure`` or ``borderline`` (a deciding
figure whose 90 % interval holds its threshold, named); the channels and
operating points (pinion speeds) that carry the evidence (the held-out
features beyond 3 sigma, or the named effects' channels); and the next step:
inspect the named part, record a healthy reference of the same rig (an
unexplained gap, a gap on one channel alone), record more runs (borderline,
inconclusive), the measurements that would tell two explanations apart (an
effect too weak for the other channels to see and one channel's own
artefact: ``ambiguity``), or nothing (healthy).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from .finding import Finding

# what to inspect for each library effect (a named effect's shaft or gear is added where the fit has one)
_INSPECT = {
    "eccentricity": "measure the run-out of the {where} shaft",
    "tooth_damage": "inspect the teeth of the {where} for a crack or spall",
    "friction": "check the lubrication (oil level, grade, temperature)",
    "torque_ripple": "check the traction motor's converter and its torque ripple",
    "adhesion_oscillation": "check the wheel-rail adhesion control (stick-slip)",
    "bearing_clearance": "measure the clearance of the {where} bearing",
}


def _speeds(content: Mapping[str, Any], ops: Sequence[int]) -> str:
    """The pinion speeds of some runs, e.g. ``600 and 800 rpm`` (run numbers where no speed is known)."""
    table = (content.get("rig") or {}).get("speed") or []
    values = []
    for op in sorted({int(op) for op in ops}):
        row = table[op] if op < len(table) else {}
        rpm = row.get("stated_rpm") if isinstance(row, Mapping) else None
        values.append(f"{rpm:.0f}" if isinstance(rpm, (int, float)) else f"run {op}")
    if not values:
        return ""
    joined = values[0] if len(values) == 1 else ", ".join(values[:-1]) + " and " + values[-1]
    return joined + (" rpm" if all(value[0].isdigit() for value in values) else "")


def _evidence(content: Mapping[str, Any]) -> tuple[list[str], list[int]]:
    """Channels and runs that carry the evidence: where the held-out gap lies, strongest first."""
    where = list(content.get("where") or [])
    if content.get("effects"):
        remaining = (content.get("remaining_gap") or {}).get("where")
        # with an effect named, the evidence is where the nominal model missed (what the effect explains)
        where = where or list(remaining or [])
    channels = list(dict.fromkeys(str(entry["channel"]) for entry in where))
    ops: list[int] = []
    for entry in where[:6]:
        ops += [int(op) for op in entry.get("ops", [])]
    return channels, sorted(set(ops))


def _ambiguous(ambiguity: Mapping[str, Any]) -> tuple[str, str]:
    """The two explanations an ambiguous verdict names, and the measurements that would separate them."""
    names = [str(entry.get("description") or entry.get("name")) for entry in ambiguity.get("candidates") or []]
    between = " and ".join(names) + f" on {ambiguity.get('channel')}"
    # each sentence says the measurement, then after a colon why it separates them: the first screen keeps the first
    measurements = [str(sentence).split(": ")[0] for sentence in ambiguity.get("separated_by") or []]
    joined = "; or ".join(measurements)
    return between, f"tell the two apart with {joined}" if measurements else "record more runs"


def _next_step(content: Mapping[str, Any], verdict: str, borderline: bool) -> str:
    if verdict == "inconclusive" and content.get("ambiguity"):
        return _ambiguous(content["ambiguity"])[1]
    if verdict == "inconclusive":
        return "record more runs with the gear under load (no line stands above the noise floor)"
    if content.get("one_channel_gap"):
        channel = content["one_channel_gap"]
        return (
            f"check the {channel} sensor and its mounting (a gap on {channel} alone is that sensor's own as far "
            "as the data tell), then record a healthy reference"
        )
    if verdict == "unexplained":
        return (
            "record a healthy reference campaign of the same rig and diagnose against it (uqgear diagnose "
            "--reference), then record more runs if the gap stays"
        )
    if verdict == "none":
        return "record more runs before acting" if borderline else "nothing to do: the gear behaves as modelled"
    steps = []
    for entry in content.get("effects") or [{"effect": verdict}]:
        values = entry.get("parameters") or {}
        where = values.get("shaft") or values.get("gear") or values.get("bearing") or ""
        template = _INSPECT.get(str(entry.get("effect")), "inspect for {effect}")
        # without a fitted shaft or gear the sentence names none
        steps.append(" ".join(template.format(where=where, effect=entry.get("effect")).split()))
    text = "; ".join(steps)
    if borderline:
        text = "record more runs to confirm, then " + text
    return text


def at_a_glance(content: Mapping[str, Any]) -> Finding:
    r"""The report's first line: verdict, certainty, evidence (channels, speeds) and the next step.

    Examples
    --------
    >>> content = {"verdict": "none", "borderline": [{"figure": "nominal_gap", "value": 0.52, "threshold": 0.5,
    ...            "interval": [0.0, 0.83]}], "where": [{"channel": "acc_gear", "ops": [0, 1]}],
    ...            "rig": {"speed": [{"stated_rpm": 630.0}, {"stated_rpm": 840.0}]}}
    >>> print(at_a_glance(content).text.replace("; ", ";\n"))
    At a glance: none (borderline: nominal gap 0.52 against 0.5, 90 % interval 0 to 0.83);
    evidence on acc_gear at 630 and 840 rpm;
    next: record more runs before acting.
    """
    verdict = str(content.get("verdict", "?"))
    effects = [str(entry["effect"]) for entry in content.get("effects") or []]
    named = " + ".join(effects) if len(effects) > 1 else verdict
    if content.get("partial"):
        named += " (partial: part of the gap remains)"
    if verdict == "inconclusive" and content.get("ambiguity"):
        named += " between " + _ambiguous(content["ambiguity"])[0] + ", which these data cannot tell apart"
    figures = list(content.get("borderline") or [])
    if figures:
        first = figures[0]
        low, high = first.get("interval", [None, None])
        certainty = (
            f"borderline: {str(first['figure']).replace('_', ' ')} {first['value']:.2g} against "
            f"{float(first['threshold']):g}, 90 % interval {low:.2g} to {high:.2g}"
        )
        if len(figures) > 1:
            certainty += f", and {len(figures) - 1} more figure{'s' if len(figures) > 2 else ''}"
    else:
        certainty = "sure: no deciding figure is near its threshold"
    channels, ops = _evidence(content)
    if verdict == "none" and not figures:
        channels, ops = [], []
        evidence = "the held-out gap is within noise"
    elif channels:
        evidence = f"evidence on {', '.join(channels)}" + (f" at {_speeds(content, ops)}" if ops else "")
    elif verdict == "none":
        evidence = "no held-out feature beyond 3 sigma"
    else:
        evidence = "no single feature beyond 3 sigma (the evidence is spread over many)"
    step = _next_step(content, verdict, bool(figures))
    facts = {
        "verdict": verdict,
        "effects": effects,
        "borderline": [f.get("figure") for f in figures],
        "channels": channels,
        "ops": ops,
        "next": step,
    }
    return Finding(f"At a glance: {named} ({certainty}); {evidence}; next: {step}.", facts, "at_a_glance")


__all__ = ["at_a_glance"]
