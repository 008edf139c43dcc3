"""Blind tests of the differential diagnosis on the foreign virtual rig (:mod:`uqgear.rig.foreign_rig`).

Every campaign pairs a healthy reference campaign of the foreign rig with a
test campaign of it, each with its own noise and record starts:

- ``healthy_same``: the reference's gears again (expected ``none``);
- ``healthy_replaced``: another gear set of the same grade, diagnosed with
  ``reference_gears="replaced"`` (expected ``none``);
- one per library effect (``n_per_effect`` each): the reference's gears with
  the effect at the strong level of its ladder, its choices (shaft, gear,
  bearing) and phases drawn; bearing clearances on the foreign rig's own
  light-load bearing check (:func:`uqgear.rig.foreign_modes.bearing_check_plan`:
  its mesh fundamental through its own bearing-dominated modes), the others on
  the service plan (expected: the effect, with its shaft, gear or bearing);
- last, with bearing clearances, ``healthy_bearing_check``: the reference's
  gears again on that plan (expected ``none``), each plan having its own
  healthy reference campaign.

A campaign is *exactly right* when the verdict is the expected one and a
named effect's choice (shaft, gear or bearing) is the true one.

A withheld effect is also judged for how *visible* it is to the change test
(:func:`change_visibility`): the test campaign is simulated again without
noise, with and without the effect, and the change between the two is read
against the thresholds the diagnosis drew from healthy variation. Below 1 the
effect moves no feature beyond what two healthy campaigns of the rig differ
by, and ``none`` is all the data can support; the suite's
``exactly_right_visible`` counts ``none`` as right there, as the library
suite's ``accuracy_detectable`` does for an effect the data cannot show.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np

from ..diagnosis import Diagnosis
from ..diagnosis.change import ChangeTest, read_campaign
from ..diagnosis.effects import effect_family, effect_names
from ..diagnosis.inputs import check_workers
from ..physics.design import Design, load_design
from ..physics.effects import Effect
from ..rig.foreign_modes import bearing_check_plan
from ..rig.foreign_rig import draw_gears, simulate_foreign_campaign
from ..rig.virtual_rig import adhesion_torque_bounds
from ..uq.seeds import as_seed_sequence, child_seed
from .campaigns import operating_points_of

#: Quality grade (ISO 1328-1) of the foreign rig's gears.
FOREIGN_GRADE = 6.0


def _operating_points(plan: str, design: Design, n_ops: int) -> dict[str, np.ndarray]:
    if plan == "bearing_check":
        # the rig's own bearing modes place its bearing check, as a test engineer's run-up would
        ops = bearing_check_plan(design)
        size = ops.sizes["op"]
        index = np.unique(np.round(np.linspace(0, size - 1, min(n_ops, size))).astype(int))
        return {str(name): np.asarray(ops[name].values)[index] for name in ops.data_vars}
    table = dict(operating_points_of(plan, design, n_ops))
    if "adhesion_torque_lower" not in table:
        lower, upper = adhesion_torque_bounds(design, table["drive_torque"])
        table.update(adhesion_torque_lower=lower, adhesion_torque_upper=upper)
    return table


def _as_points(table: dict[str, np.ndarray]) -> Any:
    import xarray as xr

    return xr.Dataset({name: ("op", np.asarray(values, dtype=float)) for name, values in table.items()})


def foreign_campaign_plan(effects: Sequence[str], n_per_effect: int) -> list[tuple[str, str | None]]:
    """The suite's campaigns: (identifier, effect or None for a healthy test)."""
    plan: list[tuple[str, str | None]] = [("healthy_same", None), ("healthy_replaced", None)]
    for name in effects:
        plan += [(f"{name}-{k}", name) for k in range(n_per_effect)]
    if any(effect_family(name).plan != "service" for name in effects):
        plan.append(("healthy_bearing_check", None))
    return plan


def _plan_of(identifier: str, name: str | None) -> str:
    if identifier == "healthy_bearing_check":
        return "bearing_check"
    return "service" if name is None else effect_family(name).plan


def run_foreign_suite(
    *,
    seed: int = 1,
    n_per_effect: int = 1,
    effects: Sequence[str] | None = None,
    n_ops: int = 8,
    duration: float = 1.0,
    workers: int | None = None,
    design: Design | None = None,
) -> dict[str, Any]:
    """Run the foreign-rig suite; returns the JSON-ready record (campaigns, verdicts, shares, times, scores).

    Examples
    --------
    >>> from uqgear.validation.foreign_suite import run_foreign_suite
    >>> run_foreign_suite(seed=1, effects=[], n_ops=3, duration=0.2)["exactly_right"]  # doctest: +SKIP
    1.0
    """
    # a bad worker count is refused before any campaign is simulated, not after the first
    workers = check_workers(workers)
    names = list(effect_names()) if effects is None else list(effects)
    nominal = design if design is not None else load_design("locomotive")
    sequence = as_seed_sequence(seed)
    gears_seed, replaced_seed, campaign_seed = (child_seed(sequence, index) for index in range(3))
    gears = draw_gears(nominal, FOREIGN_GRADE, gears_seed)
    replaced = draw_gears(nominal, FOREIGN_GRADE, replaced_seed)
    references: dict[str, Any] = {}
    entries = []
    for index, (identifier, name) in enumerate(foreign_campaign_plan(names, n_per_effect)):
        run_seed = child_seed(campaign_seed, index)
        reference_seed, test_seed, effect_seed = (child_seed(run_seed, k) for k in range(3))
        plan = _plan_of(identifier, name)
        table = _operating_points(plan, nominal, n_ops)
        if plan not in references:
            references[plan] = simulate_foreign_campaign(
                nominal,
                _as_points(table),
                gears=gears,
                seed=child_seed(sequence, 10 + len(references)),
                duration=duration,
                title=f"foreign rig healthy reference ({plan})",
            )
        effects_in = []
        truth: dict[str, Any] = {}
        if name is not None:
            family = effect_family(name)
            rng = np.random.default_rng(effect_seed)
            truth = family.campaign_values(family.ladder[2], float(rng.uniform(0.0, 2.0 * math.pi)), rng)
            effects_in = [family.make(truth)]
        # the test campaign's set-up: the noisy campaign diagnosed and the clean ones of its visibility alike
        campaign = partial(
            simulate_foreign_campaign,
            nominal,
            _as_points(table),
            gears=replaced if identifier == "healthy_replaced" else gears,
            seed=test_seed,
            duration=duration,
        )
        rig = campaign(effects=effects_in, title=f"foreign rig campaign {identifier}")
        started = time.perf_counter()
        diagnosis = Diagnosis(
            seed=reference_seed,
            workers=workers,
            reference_gears="replaced" if identifier == "healthy_replaced" else "same",
        ).fit(rig, reference=references[plan])
        seconds = time.perf_counter() - started
        visibility = None
        if name is not None:
            # an internal invariant: a diagnosis against a reference has its change test
            assert diagnosis.change_ is not None
            visibility = change_visibility(diagnosis.change_.test, nominal, campaign, effects_in)
        entries.append(_judged(identifier, name, truth, diagnosis.summary_, seconds, visibility))
    return {"suite": "foreign", "seed": seed, "n_ops": n_ops, "duration_s": duration, **_scored(entries)}


def _scored(entries: list[dict[str, Any]]) -> dict[str, Any]:
    """The suite's campaigns and its scores over them (exactly right, where visible, healthy tests)."""
    right = [entry["exactly_right"] for entry in entries]
    right_visible = [entry["right_where_visible"] for entry in entries]
    effect_entries = [entry for entry in entries if entry["truth"] is not None]
    healthy = [entry for entry in entries if entry["truth"] is None]
    return {
        "campaigns": entries,
        "exactly_right": float(np.mean(right)) if right else math.nan,
        "effects_exactly_right": float(np.mean([e["exactly_right"] for e in effect_entries]))
        if effect_entries
        else math.nan,
        "exactly_right_visible": float(np.mean(right_visible)) if right_visible else math.nan,
        "effects_visible": int(sum(bool(entry["visible"]) for entry in effect_entries)),
        "healthy_none": all(entry["verdict"] == "none" for entry in healthy),
        "false_effect_on_healthy": any(entry["verdict"] not in ("none", "unexplained") for entry in healthy),
    }


def change_visibility(
    test: ChangeTest, design: Design, campaign: Callable[..., Any], effects: Sequence[Effect]
) -> float:
    """How visible withheld effects are to a change test: their largest noise-free change over its threshold.

    The test campaign is simulated again without noise (``campaign``: its
    set-up, so the same gears, seed and record starts), without and with
    ``effects``; the change
    between the two, floored as the test floors its own, is divided by the
    thresholds ``test`` drew from healthy variation, on its judged runs.
    Below 1 the effects move no feature beyond what two healthy campaigns
    of the rig differ by.

    Parameters
    ----------
    test : ChangeTest
        The diagnosis's change test (``Diagnosis.change_.test``).
    design : Design
        The design the features are read with.
    campaign : callable
        The test campaign's :func:`~uqgear.rig.foreign_rig.simulate_foreign_campaign`
        with all but ``effects`` and ``relative_noise`` given (a :func:`functools.partial`).
    effects : sequence of Effect
        The withheld effects.

    Returns
    -------
    float
        The largest ratio; 0 for no effect.
    """
    clean = [
        read_campaign(campaign(effects=list(chosen), relative_noise=0.0), design, test.channels)
        for chosen in ((), effects)
    ]
    return float(np.max(test.ratio_of(test.change_between(clean[0], clean[1]))))


def _judged(
    identifier: str,
    name: str | None,
    truth: dict[str, Any],
    content: dict[str, Any],
    seconds: float,
    visibility: float | None = None,
) -> dict[str, Any]:
    """One campaign's record: what was true, what was said, whether exactly right (and where visible)."""
    verdict = content["verdict"]
    change = content.get("change") or {}
    named = change.get("named")
    expected = "none" if name is None else name
    right = verdict == expected
    if right and name is not None and named is not None:
        # the effect's choices (a shaft, a gear, a bearing) must match for a campaign to be exactly right
        right = all(named["parameters"].get(key) == truth.get(key) for key in effect_family(name).physics.CHOICES)
    largest = (change.get("test") or {}).get("largest") or {}
    visible = None if visibility is None else bool(visibility >= 1.0)
    return {
        "campaign": identifier,
        "truth": None if name is None else {"effect": name, **truth},
        "verdict": verdict,
        "named": named,
        "best": (change.get("ranking") or [None])[0],
        "largest_change_db": largest.get("change_db"),
        "largest_threshold_db": largest.get("threshold_db"),
        "exactly_right": bool(right),
        "visibility": visibility,
        "visible": visible,
        # an effect no feature shows beyond healthy variation is right as `none`: nothing else is supported
        "right_where_visible": bool(right or (visible is False and verdict == "none")),
        "seconds": seconds,
        "timing_s": content.get("timing_s"),
    }


__all__ = ["FOREIGN_GRADE", "change_visibility", "foreign_campaign_plan", "run_foreign_suite"]
