"""Bifurcations of periodic-orbit branches: detected between two branch points, located by bisection.

Between two neighbouring points of a branch (:mod:`uqgear.dynamics.continuation`) a bifurcation
shows as a change of a discrete test quantity:

* **fold** (limit point, the jump of a sweep): the parameter component of the branch tangent
  changes sign. At a parameter maximum a sweep upwards falls off the branch (jumps), at a
  minimum a sweep downwards does;
* **period doubling**: the number of real multipliers below -1 changes;
* **Neimark-Sacker**: the number of complex multipliers outside the unit circle changes;
* **branch point**: a real multiplier passes +1 without a fold;
* **grazing**: the orbit's smallest DTE crosses a contact boundary: x = +b (the teeth begin to
  separate, ``grazing_separation``) or x = -b (back-side impact begins, ``grazing_back_side``).
  The smallest DTE is taken on the cubic Hermite interpolant of every integration step.

Each is located by bisection in arclength from the earlier point, every trial point corrected
onto the branch, until the bracket is narrower than the stated tolerance in the parameter (for a
fold, until the arclength bracket's effect on the parameter, which is quadratic there, is).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .floquet import (BRANCH_POINT, FOLD, NEIMARK_SACKER, PERIOD_DOUBLING, UnstableCounts, crossing_types,
                      unstable_counts)

GRAZING_SEPARATION = "grazing_separation"
GRAZING_BACK_SIDE = "grazing_back_side"
#: Every bifurcation type a branch reports.
BIFURCATION_TYPES = (FOLD, PERIOD_DOUBLING, NEIMARK_SACKER, BRANCH_POINT, GRAZING_SEPARATION, GRAZING_BACK_SIDE)
#: Bisection steps before a location gives up narrowing its bracket.
MAX_BISECTIONS = 40


@dataclass
class BranchPoint:
    """One corrected point of a branch.

    Attributes
    ----------
    parameter : float
        The continuation parameter's value.
    state : ndarray (6,)
        The orbit's state at mesh phase 0.
    tangent : ndarray (7,)
        Unit tangent of the branch in scaled coordinates (state, parameter), in the direction of
        travel.
    multipliers : ndarray of complex
        Floquet multipliers, largest modulus first.
    monodromy : ndarray (6, 6)
    qois : dict
        Orbit QoIs (:func:`uqgear.dynamics.shooting.orbit_qois`).
    arclength : float
        Scaled arclength from the branch's first point.
    poincare_x : ndarray
        The DTE at the start of each of the orbit's n mesh periods (filled in when the branch is
        stored).
    """

    parameter: float
    state: np.ndarray
    tangent: np.ndarray
    multipliers: np.ndarray
    monodromy: np.ndarray
    qois: dict[str, float]
    arclength: float = 0.0
    poincare_x: np.ndarray = field(default_factory=lambda: np.empty(0))

    @property
    def counts(self) -> UnstableCounts:
        return unstable_counts(self.multipliers)

    @property
    def stable(self) -> bool:
        return self.counts.total == 0


@dataclass
class Bifurcation:
    """A located bifurcation.

    Attributes
    ----------
    kind : str
        One of :data:`BIFURCATION_TYPES`.
    branch : int
        Index of the branch it lies on.
    point : BranchPoint
        The branch point closest to it (the bracket end on the far side for all but folds).
    parameter : float
        Its location in the parameter.
    tolerance : float
        Half-width of the final bracket in the parameter (the location is within this).
    side : int
        +1 where the new condition (separation, instability, the branch's absence past a fold) holds
        above ``parameter``, -1 below it.
    stable_before, stable_after : bool
        Stability of the branch on either side, in the direction of travel.
    """

    kind: str
    branch: int
    point: BranchPoint
    parameter: float
    tolerance: float
    side: int
    stable_before: bool
    stable_after: bool
    arclength: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)


#: The orbit QoI whose sign change marks each grazing (the lowest DTE against +b and -b).
GRAZING_MARGINS = {"grazing_separation": "separation_margin", "grazing_back_side": "back_side_margin"}


def _grazing_sign(point: BranchPoint, margin: str) -> bool:
    return bool(point.qois[margin] < 0.0)


def detect(before: BranchPoint, after: BranchPoint) -> list[tuple[str, Callable]]:
    """The bifurcations between two neighbouring points, each with its discrete test function."""
    turned = bool(np.sign(before.tangent[-1]) != np.sign(after.tangent[-1]) and before.tangent[-1] != 0.0)
    found: list[tuple[str, Callable]] = []
    for kind in crossing_types(before.counts, after.counts, turned):
        found.append((kind, _TESTS[kind]))
    for kind, margin in GRAZING_MARGINS.items():
        if _grazing_sign(before, margin) != _grazing_sign(after, margin):
            found.append((kind, lambda point, margin=margin: _grazing_sign(point, margin)))
    return found


_TESTS: dict[str, Callable[[BranchPoint], Any]] = {
    FOLD: lambda point: bool(point.tangent[-1] > 0.0),
    PERIOD_DOUBLING: lambda point: point.counts.real_minus,
    NEIMARK_SACKER: lambda point: point.counts.complex,
    BRANCH_POINT: lambda point: point.counts.real_plus,
}


def locate(kind: str, test: Callable[[BranchPoint], Any], before: BranchPoint, after: BranchPoint, step: float,
           correct: Callable[[float], BranchPoint | None], tolerance: float, parameter_scale: float,
           branch: int) -> Bifurcation:
    """Bisect in arclength between ``before`` and ``after`` (``step`` apart) for the change of ``test``.

    ``correct(s)`` returns the branch point at arclength ``s`` from ``before`` (predicted along its
    tangent and corrected), or None where the corrector fails (the bracket then stops narrowing).
    """
    reference = test(before)
    low, high = 0.0, step
    low_point, high_point = before, after
    for _ in range(MAX_BISECTIONS):
        if _narrow_enough(kind, low_point, high_point, high - low, tolerance, parameter_scale):
            break
        middle = 0.5 * (low + high)
        point = correct(middle)
        if point is None:
            break
        if test(point) == reference:
            low, low_point = middle, point
        else:
            high, high_point = middle, point
    if kind == FOLD:
        # the parameter is extremal inside the bracket: the bracket end further out
        outer = max((low_point, high_point), key=lambda p: p.parameter * np.sign(before.tangent[-1]))
        location, near = outer.parameter, outer
        width = abs(high_point.parameter - low_point.parameter) + 0.5 * (high - low) ** 2 * parameter_scale
        side = int(np.sign(before.tangent[-1]))
    else:
        location, near = 0.5 * (low_point.parameter + high_point.parameter), high_point
        width = 0.5 * abs(high_point.parameter - low_point.parameter)
        travel = np.sign(high_point.parameter - low_point.parameter) or np.sign(before.tangent[-1]) or 1.0
        # the new condition (separation, contact on the back side, one more unstable multiplier) holds
        # on the far side in the direction of travel when the test grew across the point
        side = int(travel if test(after) > reference else -travel)
    return Bifurcation(kind=kind, branch=branch, point=near, parameter=float(location), tolerance=float(width),
                       side=side, stable_before=before.stable, stable_after=after.stable,
                       arclength=before.arclength + 0.5 * (low + high))


def _narrow_enough(kind: str, low: BranchPoint, high: BranchPoint, width: float, tolerance: float,
                   parameter_scale: float) -> bool:
    if kind == FOLD:
        # near a fold the parameter moves with the square of the arclength
        return abs(high.parameter - low.parameter) < tolerance and 0.5 * width ** 2 * parameter_scale < tolerance
    return abs(high.parameter - low.parameter) < 2.0 * tolerance


__all__ = ["BranchPoint", "Bifurcation", "detect", "locate", "BIFURCATION_TYPES", "GRAZING_SEPARATION",
           "GRAZING_BACK_SIDE", "MAX_BISECTIONS"]
