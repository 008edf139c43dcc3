"""What a diagnosis hands back as a record: the JSON-ready summary of ``diagnosis.json`` (data: :mod:`.dataset`)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..physics.design import Design
from .case import RigCase
from .decision import Decision
from .gap_maps import line_signal_to_noise
from .result import DiagnosisResult
from .scoring import GAP_METRIC
from .settings import DEFAULT_SETTINGS, DiagnosisSettings

#: The keys of ``diagnosis.json`` in their order; a record holds those its route fills.
_ORDER = (
    "verdict", "reason", "borderline", "partial", "one_channel_gap", "effects", "remaining_gap",
    "forward_selection", "gap", "where", "families", "frequency_locked_lines", "ranking", "nominal", "signal",
    "thresholds", "model_error", "pitch_errors", "cannot_tell", "sideband_phases", "line_interference",
    "effects_considered", "rig", "seed", "timing_s", "ambiguity", "settings",
)


def summary(
    case: RigCase,
    decision: Decision,
    *,
    source: str,
    effects: Sequence[str],
    seed_text: str,
    timings: Mapping[str, float],
    settings: DiagnosisSettings = DEFAULT_SETTINGS,
    result: DiagnosisResult | None = None,
    named: Sequence[Mapping[str, Any]] = (),
) -> dict[str, Any]:
    """The JSON summary of a diagnosis (``diagnosis.json``), its verdict and reason those of ``decision``.

    With ``result`` (the diagnosis fitted the model: ``case``, ``effects``
    and ``settings`` are then the result's) the record holds what the fits
    found. Without, nothing was fitted (data that cannot decide, or a
    differential diagnosis): the same keys, what was not computed None or
    empty (``nominal`` is None), ``effects`` the ``named`` entries, and
    ``signal`` gives the strongest line of each run in noise spreads against
    the threshold.

    ``ambiguity`` is there only where the verdict is ``inconclusive`` between
    an effect the other channels cannot see and one channel's own artefact:
    both candidates, the channel, the effect's reach on the others and what
    would separate the two (:meth:`~.decision.Ambiguity.summary`).

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.diagnosis.case import prepare_case
    >>> from uqgear.diagnosis.inputs import resolve_design
    >>> from uqgear.diagnosis.outputs import summary
    >>> rig = uqgear.read_rig(uqgear.example_rig_file("healthy")).isel(op=[2, 4, 6], time=slice(0, 5120))
    >>> case = prepare_case(rig, resolve_design(None, rig), seed=0)
    >>> record = summary(case, uqgear.diagnosis.Decision("inconclusive", "no line above noise"), source="rig.nc",
    ...                  effects=["eccentricity"], seed_text="0", timings={})
    >>> record["verdict"], record["nominal"], record["rig"]["n_op"]
    ('inconclusive', None, 3)
    """
    parts = {
        "verdict": decision.verdict,
        "reason": decision.reason,
        "borderline": [dict(entry) for entry in decision.borderline],
        "partial": decision.partial,
        "model_error": case.model_error,
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
    parts.update(_fitted_parts(result) if result is not None else _unfitted_parts(case, settings, named))
    if decision.ambiguity is not None:
        # only where the verdict is inconclusive between an effect and a sensor's artefact
        parts["ambiguity"] = decision.ambiguity.summary()
    if settings.changed():
        parts["settings"] = settings.changed()
    return {key: parts[key] for key in _ORDER if key in parts}


def _fitted_parts(result: DiagnosisResult) -> dict[str, Any]:
    """The parts of the record that the fits of a diagnosis found."""
    case, settings, decision = result.case, result.settings, result.decision
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
    return {
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
        "pitch_errors": result.pitch_errors.summary() if result.pitch_errors is not None else None,
        "cannot_tell": result.cannot_tell(),
        "sideband_phases": [evidence.summary() for evidence in result.modulation],
    }


def _unfitted_parts(
    case: RigCase, settings: DiagnosisSettings, named: Sequence[Mapping[str, Any]]
) -> dict[str, Any]:
    """The parts of the record of a diagnosis that fitted no model: empty, with the runs' signal."""
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
    return {
        "effects": [dict(entry) for entry in named],
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
        "pitch_errors": None,
        "cannot_tell": [],
        "sideband_phases": [],
    }


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


def completed(
    content: dict[str, Any],
    maps: xr.Dataset,
    design: Design,
    reference: Mapping[str, Any] | None = None,
    rig: xr.Dataset | None = None,
) -> dict[str, Any]:
    """The record with a reference's summary (and its fit's time, where one was fitted) and the design's and rig's
    notes.

    ``reference`` is the reference's summary (``file``, and ``seconds`` when
    a model was fitted to it); ``maps`` (``diagnosis.nc``) names its file.
    ``design_notes`` says what the model did with the design's geometry (an
    undercut tooth); ``rig_notes`` what the campaign ``rig`` (as the diagnosis read it) cannot show (ramp
    segments too short for the gear's lines, :func:`uqgear.rig.ramp_records.segment_notes`).
    """
    from ..physics.geometry import geometry_notes
    from ..rig.ramp_records import segment_notes

    if reference is not None:
        content["reference"] = json_clean(dict(reference))
        maps.attrs["reference"] = str(reference["file"])
        if "seconds" in reference and isinstance(content.get("timing_s"), dict):
            content["timing_s"]["reference_fit"] = reference["seconds"]
    content["design_notes"] = geometry_notes(design)
    content["rig_notes"] = segment_notes(rig, design) if rig is not None else []
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


__all__ = ["completed", "json_clean", "summary"]
