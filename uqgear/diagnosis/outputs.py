"""What a diagnosis hands back as a record: the JSON-ready summary of ``diagnosis.json`` (data: :mod:`.dataset`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .case import RigCase
from .gap_maps import line_signal_to_noise
from .result import DiagnosisResult
from .scoring import GAP_METRIC
from .settings import DEFAULT_SETTINGS, DiagnosisSettings


def summary(result: DiagnosisResult, *, source: str, seed_text: str, timings: Mapping[str, float]) -> dict[str, Any]:
    """The JSON summary of a diagnosis (``diagnosis.json``).

    ``ambiguity`` is there only where the verdict is ``inconclusive`` between
    an effect the other channels cannot see and one channel's own artefact:
    both candidates, the channel, the effect's reach on the others and what
    would separate the two (:meth:`~.decision.Ambiguity.summary`).
    """
    case, settings = result.case, result.settings
    best = result.best
    named = best if best is not None and best.effect == result.verdict else None
    chosen = named if named is not None else best
    gap = {
        "metric": GAP_METRIC,
        "baseline": result.nominal_gap,
        "with_effect": chosen.gap_with_effect if chosen is not None else None,
        "effect": chosen.effect if chosen is not None else None,
        "effect_named": named is not None,
        "shrink_fraction": chosen.shrink_fraction if chosen is not None else None,
        "shrink_interval": list(chosen.shrink_interval) if chosen is not None else None,
        "evaluated_on": _evaluated_on(case),
        "noise_threshold": settings.verdict.noise_gap,
        "baseline_interval": [float(v) for v in result.nominal_gap_interval],
    }
    decision = result.decision
    content = {
        "verdict": result.verdict,
        "reason": result.reason,
        "borderline": [dict(entry) for entry in decision.borderline],
        "partial": decision.partial,
        "one_channel_gap": decision.one_channel or None,
        "effects": [chosen.summary() for chosen in result.selected],
        "remaining_gap": _remaining_gap(result),
        "forward_selection": [selection.summary() for selection in result.rounds],
        "gap": gap,
        "where": result.where,
        "families": result.families,
        "frequency_locked_lines": result.locked_lines,
        "ranking": result.ranking(),
        "nominal": {
            "parameters": result.nominal.values,
            "adhesion_torque": [float(v) for v in result.nominal.adhesion_torques],
            "periodic_runs": [bool(v) for v in result.nominal.periodic],
            "converged": result.nominal.converged,
        },
        "thresholds": _thresholds(settings),
        "model_error": case.model_error,
        "pitch_errors": result.pitch_errors.summary() if result.pitch_errors is not None else None,
        "cannot_tell": result.cannot_tell(),
        "sideband_phases": [evidence.summary() for evidence in result.modulation],
        "line_interference": case.interference.summary(),
        "effects_considered": list(result.effects),
        "rig": {
            "source": source,
            "title": str(case.rig.attrs.get("title", "")),
            "n_op": case.n_op,
            "channels": list(case.channels),
            "speed": case.speed,
        },
        "seed": seed_text,
        "timing_s": dict(timings),
    }
    if decision.ambiguity is not None:
        # only where the verdict is inconclusive between an effect and a sensor's artefact
        content["ambiguity"] = decision.ambiguity.summary()
    if settings.changed():
        content["settings"] = settings.changed()
    return content


def _thresholds(settings: DiagnosisSettings, *, signal: bool = False) -> dict[str, float]:
    """The verdict's thresholds as ``diagnosis.json`` reports them."""
    thresholds = {
        "score": settings.verdict.score_threshold,
        "shrink_fraction": settings.verdict.shrink_threshold,
        "nominal_gap": settings.verdict.noise_gap,
        "partial_shrink": settings.verdict.partial_shrink,
    }
    if signal:
        thresholds["signal_snr"] = settings.features.signal_snr
    return thresholds


def _remaining_gap(result: DiagnosisResult) -> dict[str, Any]:
    """The held-out gap the final model leaves (the nominal model when no effect is named), and where it lies.

    ``unexplained`` when it is above the noise threshold; ``where`` lists
    the features (channel, feature, family, runs beyond 3 sigma) and
    ``families`` the channel x feature family cells above noise with their
    per-run (operating point) values, both from the final model's held-out
    discrepancies.
    """
    value, noise_gap = result.remaining_gap, result.settings.verdict.noise_gap
    return {
        "value": value,
        "interval": [float(v) for v in result.remaining_interval],
        "unexplained": bool(math.isfinite(value) and value > noise_gap),
        "model": ["nominal"] + [chosen.entry.label for chosen in result.selected],
        "where": result.remaining_where,
        "families": [row for row in result.remaining_families if row["score"] > noise_gap],
    }


def _evaluated_on(case: RigCase) -> dict[str, Any]:
    return {
        "scheme": "leave-one-operating-point-out: each run predicted by the models fitted without it",
        "ops": list(range(case.n_op)),
        "pinion_speed": [float(v) for v in case.speeds],
        "drive_torque": [float(v) for v in case.drive_torques],
    }


def _strongest_lines(case: RigCase) -> list[float | None]:
    """Per run: the strongest line's amplitude in noise spreads (None where nothing could be measured)."""
    ratio = line_signal_to_noise(case)
    return [float(np.nanmax(ratio[op])) if np.isfinite(ratio[op]).any() else None for op in range(case.n_op)]


def inconclusive_summary(
    case: RigCase,
    reason: str,
    *,
    source: str,
    effects: Sequence[str],
    seed_text: str,
    timings: Mapping[str, float],
    settings: DiagnosisSettings = DEFAULT_SETTINGS,
) -> dict[str, Any]:
    """The JSON summary of a diagnosis whose data cannot decide (verdict ``inconclusive``, nothing fitted).

    The same keys as :func:`summary`; what was not computed is None or empty
    (``nominal`` is None: no model was fitted to noise), and ``signal`` gives
    the strongest line of each run in noise spreads against the threshold.
    """
    gap = {
        "metric": GAP_METRIC,
        "baseline": None,
        "with_effect": None,
        "effect": None,
        "effect_named": False,
        "shrink_fraction": None,
        "shrink_interval": None,
        "evaluated_on": _evaluated_on(case),
        "noise_threshold": settings.verdict.noise_gap,
        "baseline_interval": None,
    }
    content = {
        "verdict": "inconclusive",
        "reason": reason,
        "borderline": [],
        "partial": False,
        "effects": [],
        "remaining_gap": None,
        "forward_selection": [],
        "gap": gap,
        "where": [],
        "families": [],
        "frequency_locked_lines": [],
        "ranking": [],
        "nominal": None,
        "signal": {"strongest_line_snr": _strongest_lines(case), "threshold": settings.features.signal_snr},
        "thresholds": _thresholds(settings, signal=True),
        "model_error": case.model_error,
        "pitch_errors": None,
        "cannot_tell": [],
        "sideband_phases": [],
        "line_interference": case.interference.summary(),
        "effects_considered": list(effects),
        "rig": {
            "source": source,
            "title": str(case.rig.attrs.get("title", "")),
            "n_op": case.n_op,
            "channels": list(case.channels),
            "speed": case.speed,
        },
        "seed": seed_text,
        "timing_s": dict(timings),
    }
    if settings.changed():
        content["settings"] = settings.changed()
    return content


def json_clean(value: Any) -> Any:
    """Replace non-finite floats by None (JSON has no NaN)."""
    if isinstance(value, float) or isinstance(value, np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: json_clean(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_clean(item) for item in value]
    return value


__all__ = ["summary", "inconclusive_summary", "json_clean"]
