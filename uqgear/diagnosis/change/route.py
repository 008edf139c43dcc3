"""The differential diagnosis against a healthy reference: what changed, where, and which effect explains it.

Run by :class:`~uqgear.diagnosis.Diagnosis` when a reference campaign is
given (``reference_route="change"``, the default): step 1 judges the change
on condition-monitoring features (:mod:`.detection`); with no significant
change the verdict is ``none`` and no model is simulated; otherwise every
candidate effect is scored on the change it predicts (:mod:`.scoring`) and
the rules of the ``reference`` case name the best when it explains at least
``change_share`` of the change, else the change is ``unexplained`` with where
it lies (:mod:`uqgear.diagnosis.verdict.reference`;
docs/model/unmodelled-effects.md section 6.1).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from ...common.steps import StepLog
from ...physics.design import Design
from ..decision import Decision
from ..settings import DiagnosisSettings
from ..verdict.reference import decide_change
from ..verdict.rules import verdict_rules
from .detection import ChangeTest, judge_change, read_campaign
from .features import FEATURES
from .scoring import ChangeModel, ChangeScore, explained_where, score_change

_DB = 10.0 / np.log(10.0)


@dataclass(frozen=True)
class ChangeOutcome:
    """What the differential diagnosis found: the change test, the scores, the decision and its record."""

    test: ChangeTest
    scores: list[ChangeScore]
    decision: Decision
    summary: dict[str, Any]
    timings: dict[str, float] = field(default_factory=dict)


def _score_entry(score: ChangeScore, test: ChangeTest, settings: DiagnosisSettings) -> dict[str, Any]:
    entry = score.summary()
    entry["share_by_channel"] = explained_where(test, score, settings)
    return entry


def diagnose_change(
    rig: xr.Dataset,
    reference: xr.Dataset,
    design: Design,
    effects: Sequence[str],
    *,
    settings: DiagnosisSettings,
    gears: str,
    reference_source: str,
    steps: StepLog,
    workers: int = 1,
) -> ChangeOutcome:
    """Judge the change since the reference and, where there is one, score the effects on it."""
    timings: dict[str, float] = {}
    channels = tuple(name for name in ("te", "acc_pinion", "acc_gear") if name in rig.data_vars)
    started = time.perf_counter()
    with steps.step("read the condition-monitoring features of the reference and the test campaign"):
        reference_features = read_campaign(reference, design, channels)
        test_features = read_campaign(rig, design, channels)
    with steps.step("judge the change since the reference") as found:
        test = judge_change(reference_features, test_features, settings=settings, gears=gears)
        share = settings.change.replaced_line_floor if gears == "replaced" else settings.change.same_line_floor
        model = ChangeModel(design, rig, test_features, test.judged, share)
        allowance = model.load_allowance(settings.change.load_allowance)
        test = judge_change(reference_features, test_features, settings=settings, gears=gears, load_allowance=allowance)
        found.update(changed=test.changed)
    timings["change_test"] = time.perf_counter() - started
    scores: list[ChangeScore] = []
    if test.changed and effects:
        started = time.perf_counter()
        with steps.step("score the candidate effects on the change they predict") as found:
            scores = score_change(
                test,
                test_features,
                rig,
                design,
                effects,
                settings=settings,
                model=model,
                reference=reference,
                workers=workers,
            )
            found.update(best=scores[0].label if scores else None)
        timings["change_scoring"] = time.perf_counter() - started
    decision = decide_change(test, scores, verdict_rules(settings, "reference"))
    best = scores[0] if scores and decision.verdict == scores[0].effect else None
    summary = {
        "route": "change",
        "reference": reference_source,
        "gears": gears,
        "test": test.summary(),
        "named": None if best is None else _score_entry(best, test, settings),
        "ranking": [_score_entry(score, test, settings) for score in scores],
        "thresholds": {
            "change_z": settings.change.change_z,
            "change_allowance_db": settings.change.change_allowance_db,
            "replaced_allowance_db": list(settings.change.replaced_allowance_db) if gears == "replaced" else None,
            "change_share": settings.change.change_share,
            "change_margin": settings.change.change_margin,
        },
        "timing_s": dict(timings),
    }
    return ChangeOutcome(test, scores, decision, summary, timings)


def change_dataset(outcome: ChangeOutcome) -> dict[str, Any]:
    """Variables for ``diagnosis.nc``: the change, its threshold and (with a named effect) the predicted change."""
    test = outcome.test
    dims = ("op", "channel", "cm_feature")
    data = {
        "change": (dims, test.change * _DB, {"long_name": "change since the reference", "units": "dB"}),
        "change_threshold": (dims, test.threshold * _DB, {"long_name": "change threshold", "units": "dB"}),
    }
    coords = {
        "cm_feature": ("cm_feature", [name.label for name in FEATURES]),
        "cm_family": ("cm_feature", [name.family for name in FEATURES]),
    }
    return {"data": data, "coords": coords}


__all__ = ["ChangeOutcome", "change_dataset", "diagnose_change"]
