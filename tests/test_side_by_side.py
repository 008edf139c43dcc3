"""Fits side by side: the numbers of one fit after the other, bit for bit, and a failure reported in its own step."""

from __future__ import annotations

import json
import threading
import time
from typing import Any

import pytest

from uqgear import Diagnosis, example_rig_file, read_rig
from uqgear.common.errors import InternalError
from uqgear.diagnosis import fitting, screening, side_by_side

EFFECTS = ["eccentricity", "tooth_damage", "friction"]
# none of these explains a run-out: the gap stays unexplained and every extra full fit runs
UNEXPLAINED = ["friction", "torque_ripple", "bearing_clearance"]


@pytest.fixture(scope="module")
def rig():
    return read_rig(example_rig_file("eccentricity")).isel(op=[2, 4, 6], time=slice(0, 5120))


def _without_times(value: Any) -> Any:
    """A diagnosis record without its wall-clock figures (everything else must agree bit for bit)."""
    if isinstance(value, dict):
        return {key: _without_times(item) for key, item in value.items() if key not in ("seconds", "timing_s")}
    if isinstance(value, list):
        return [_without_times(item) for item in value]
    return value


def _record(
    rig, monkeypatch, at_once: int, intervals: list[tuple[float, float]], effects: list[str]
) -> tuple[str, list[str]]:
    monkeypatch.setattr(side_by_side, "FITS_AT_ONCE", at_once)
    original = fitting.fit_candidate

    def timed(*args: Any, **kwargs: Any) -> Any:
        started = time.perf_counter()
        try:
            return original(*args, **kwargs)
        finally:
            intervals.append((started, time.perf_counter()))

    monkeypatch.setattr(screening, "fit_candidate", timed)
    diagnosis = Diagnosis(effects=effects, workers=2, seed=4).fit(rig)
    steps = [record["step"] for record in diagnosis.steps_.finished]
    return json.dumps(_without_times(diagnosis.to_dict()), sort_keys=True, default=str), steps


def _overlapping(intervals: list[tuple[float, float]]) -> bool:
    ordered = sorted(intervals)
    return any(later[0] < earlier[1] for earlier, later in zip(ordered, ordered[1:]))


@pytest.mark.parametrize("effects", [EFFECTS, UNEXPLAINED], ids=["named", "unexplained"])
def test_fits_side_by_side_give_the_numbers_of_one_after_the_other(rig, monkeypatch, effects):
    alone: list[tuple[float, float]] = []
    together: list[tuple[float, float]] = []
    one_after_the_other, steps_alone = _record(rig, monkeypatch, 1, alone, effects)
    side_by_side_record, steps = _record(rig, monkeypatch, 2, together, effects)
    assert side_by_side_record == one_after_the_other
    assert steps == steps_alone
    if effects is UNEXPLAINED:
        # the leader's full fit and three extra ones, two of them computed side by side
        assert json.loads(side_by_side_record)["verdict"] == "unexplained"
        assert sum(step.endswith(" in full") for step in steps) == 4
    # the screening fits did run side by side in the second diagnosis, and one at a time in the first
    assert _overlapping(together) and not _overlapping(alone)


def test_a_fit_that_fails_side_by_side_names_its_own_step(rig, monkeypatch):
    original = fitting.fit_candidate

    def failing(case, candidate, *args: Any, **kwargs: Any) -> Any:
        if candidate.label == "tooth_damage[gear]" and threading.current_thread().name.startswith("uqgear-fit"):
            raise RuntimeError("a numerical failure")
        return original(case, candidate, *args, **kwargs)

    monkeypatch.setattr(screening, "fit_candidate", failing)
    with pytest.raises(InternalError) as caught:
        Diagnosis(effects=EFFECTS, workers=2, seed=4).fit(rig)
    assert caught.value.step == "screen tooth_damage[gear]"
    screened = [record["step"] for record in caught.value.finished if record["step"].startswith("screen ")]
    # the variants listed before it were taken up, in order; none after it
    assert screened == ["screen eccentricity[pinion]", "screen eccentricity[gear]", "screen tooth_damage[pinion]"]
