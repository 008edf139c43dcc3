"""The fitted attributes and records of a differential diagnosis (``diagnosis.json``, ``diagnosis.nc``)."""

from __future__ import annotations

import os
import time
from typing import Any

import xarray as xr

from ..case import prepare_case
from ..dataset import inconclusive_dataset
from ..inputs import ReferenceInput, read_inputs
from ..outputs import inconclusive_summary, json_clean
from .route import change_dataset, diagnose_change


def _cpu_seconds() -> float:
    import resource

    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def conclude_change(
    diagnosis: Any,
    rig: str | os.PathLike[str] | xr.Dataset,
    reference: ReferenceInput | None,
    started: float,
    cpu_started: float,
) -> Any:
    """Run the differential route for a :class:`~uqgear.diagnosis.Diagnosis` and set its fitted attributes.

    The inputs are read and checked first (the reference must cover at
    least one test run; its runs need not match the test's). ``outcome_``
    and ``nominal_`` are None (no model is fitted to either campaign);
    ``change_`` holds the change test and the scores.
    """
    from ...common.steps import StepLog

    settings = diagnosis.settings
    inputs = read_inputs(
        rig,
        reference,
        design=diagnosis.design,
        calibration=diagnosis.calibration,
        settings=settings,
        match_points=False,
    )
    diagnosis.design_, diagnosis.steps_ = inputs.design, StepLog()
    steps = diagnosis.steps_
    assert inputs.reference is not None  # internal invariant: the route runs only with a reference
    with steps.step("extract the rig features"):
        case = prepare_case(inputs.rig, inputs.design, seed=diagnosis.seeds.noise, settings=settings)
    outcome = diagnose_change(
        inputs.rig,
        inputs.reference,
        inputs.design,
        diagnosis.effects,
        settings=settings,
        gears=diagnosis.reference_gears,
        reference_source=inputs.reference_source,
        steps=steps,
        workers=diagnosis.workers,
    )
    with steps.step("summarise the results"):
        timings = dict(outcome.timings, order_tracking=case.tracking_s)
        timings.update(
            total_wall=time.perf_counter() - started,
            total_cpu=_cpu_seconds() - cpu_started,
            workers=float(diagnosis.workers),
        )
        content = inconclusive_summary(
            case,
            outcome.decision.reason,
            source=inputs.source,
            effects=diagnosis.effects,
            seed_text=str(diagnosis.seed.entropy),
            timings=timings,
            settings=settings,
        )
        content["verdict"] = outcome.decision.verdict
        content["reason"] = outcome.decision.reason
        content["change"] = outcome.summary
        if outcome.summary["named"] is not None:
            content["effects"] = [_named_effect(outcome.summary["named"])]
        content["reference"] = {"file": inputs.reference_source, "route": "change"}
        content = json_clean(content)
        maps = inconclusive_dataset(case, outcome.decision.reason, diagnosis.effects)
        extra = change_dataset(outcome)
        maps = maps.assign_coords(dict(extra["coords"]))
        maps = maps.assign(dict(extra["data"]))
        maps.attrs.update(
            verdict=outcome.decision.verdict, reason=outcome.decision.reason, reference=str(inputs.reference_source)
        )
    from ...physics.geometry import geometry_notes

    content["design_notes"] = geometry_notes(inputs.design)
    diagnosis.outcome_, diagnosis.case_, diagnosis.nominal_ = None, case, None
    diagnosis.features_ = case
    diagnosis.change_ = outcome
    diagnosis.ranking_, diagnosis.effects_ = [], []
    diagnosis.decision_ = outcome.decision
    diagnosis.remaining_gap_ = float("nan")
    diagnosis.summary_, diagnosis.result_ = content, maps
    return diagnosis


def _named_effect(named: dict[str, Any]) -> dict[str, Any]:
    """The named effect's entry of ``diagnosis.json``'s ``effects``: its variant, parameters and share of the change."""
    return {key: named[key] for key in ("effect", "variant", "parameters", "share")}


__all__ = ["conclude_change"]
