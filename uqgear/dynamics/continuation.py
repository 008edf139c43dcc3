"""Pseudo-arclength continuation of periodic orbits in one model parameter, through folds.

A branch of period-n orbits is the curve of (s, lambda) with P^n(s; lambda) = s, s the state at mesh
phase 0 and lambda the parameter (pinion speed, a torque, the mesh stiffness scale, a design key
such as k1). :class:`Continuation` follows it by predictor-corrector steps in scaled coordinates
(state by :meth:`~uqgear.physics.model.ModelSetup.state_scale` at the first point, parameter by the
span of the range, so the range is one unit): predict along the unit tangent, correct by Newton on

    P^n(s; lambda) - s = 0,    t . ((s, lambda) - predicted) = 0,

with the monodromy as the state Jacobian and a forward difference for the parameter column. The
arclength condition lets the corrector pass folds, where the parameter turns back and a fixed-
parameter Newton fails; stable and unstable stretches are followed alike. Steps grow after easy
corrections and shrink after hard ones or when the tangent turns by more than ``max_turn``.

Between neighbouring points the Floquet multipliers, the tangent and the orbit's smallest DTE are
compared, and each change is located and typed (:mod:`uqgear.dynamics.bifurcations`). At a period
doubling the doubled orbit is a branch of P^{2n} leaving the point along the flip eigenvector, in
the direction orthogonal to the period-n branch's tangent; it is followed too (branch switching),
up to ``max_period``. A period-2n branch that merges back into its period-n parent (the two halves
of the orbit meet) ends there.

The RK4 grid has the fast integrator's steps per mesh period at each parameter value; within one
corrector solve it is held fixed, so the map Newton solves is smooth.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from ..common.errors import UqgearError
from ..physics.design import Design
from ..physics.integration import BATCH_DESIGN_KEYS
from .bifurcations import Bifurcation, BranchPoint, detect, locate
from .branches import Branch, branches_dataset
from .floquet import BRANCH_POINT, FOLD, PERIOD_DOUBLING, floquet_multipliers
from .shooting import PoincareMap, ShootingError, ShootingSettings, newton_orbit, orbit_qois, setup_at

#: Parameter step of the forward difference for dP/dlambda, in scaled units (range = 1).
PARAMETER_DIFFERENCE = 1e-6
#: Leaps over a kink of the discrete map a branch may take before it is ended there.
MAX_LEAPS = 5
#: Mesh periods integrated before shooting again when the first orbit is not found from the start state.
RELAXATION_PERIODS = (200, 1000)
#: A doubled branch ends where the distance between its orbit's halves falls below this fraction of
#: its largest value at a fold or branch point: it merges back into its parent there (the distance
#: grows like the square root of the parameter's distance from the merge, so a fold located within
#: 1 % of the bubble's width from it is at about a tenth of the largest distance).
MERGE_FRACTION = 0.3
#: ... or at any point below this fraction (the corrector slid onto the parent orbit at the merge).
COLLAPSE_FRACTION = 0.01
#: Largest Newton update of a correction in scaled units; a larger one fails the step.
MAX_CORRECTION = 0.25


@dataclass(frozen=True)
class ContinuationSettings:
    """How a branch is followed.

    Attributes
    ----------
    step, min_step, max_step : float
        First, smallest and largest arclength step in scaled units (the parameter range is 1).
    max_turn : float
        Largest angle (rad) between neighbouring tangents; a step turning more is retried shorter.
    max_points : int
        Points per branch before it is cut.
    tolerance : float, optional
        Location tolerance of bifurcations in the parameter's units; default 1e-5 of the range.
    max_period : int
        Follow period-doubled branches up to this period (1: no branch switching).
    min_fold_width : float, optional
        Two neighbouring folds of a branch closer than this in the parameter (default 1e-3 of the
        range) are not reported: the discrete map has small kinks where a contact crossing moves
        across an integration sub-step, and a branch running almost straight across the parameter
        (next to a nearly degenerate period doubling) folds back and forth on them within a
        fraction of an rpm. The count dropped is in the result's ``folds_dropped``.
    corrector_iterations : int
        Newton iterations of one correction before the step is halved.
    shooting : ShootingSettings
        Newton tolerance and RK4 steps per mode.
    """

    step: float = 0.005
    min_step: float = 1e-6
    max_step: float = 0.02
    max_turn: float = 0.3
    max_points: int = 3000
    tolerance: float | None = None
    max_period: int = 8
    min_fold_width: float | None = None
    corrector_iterations: int = 8
    shooting: ShootingSettings = field(default_factory=ShootingSettings)


class _Tracer:
    """The predictor-corrector machinery for one design, fixed inputs and parameter."""

    def __init__(
        self,
        design: Design,
        parameter: str,
        fixed: Mapping[str, float],
        bounds: tuple[float, float],
        settings: ContinuationSettings,
        model: Mapping[str, Any],
    ) -> None:
        # the fixed design keys are applied once: a set-up per corrector step would replace them every time
        keys = {name: float(value) for name, value in fixed.items() if name in BATCH_DESIGN_KEYS and name != parameter}
        self.design = design.replace(**keys) if keys else design
        self.parameter = parameter
        self.fixed = {name: value for name, value in fixed.items() if name not in keys}
        self.low, self.high = min(bounds), max(bounds)
        self.span = self.high - self.low
        self.settings, self.model = settings, dict(model)
        self.scale = self.setup(bounds[0]).state_scale()
        self.passes = 0
        self.iterations = 0

    def setup(self, value: float) -> Any:
        return setup_at(self.design, {**self.fixed, self.parameter: float(value)}, **self.model)

    def mapping(self, value: float, steps: int | None = None) -> PoincareMap:
        return PoincareMap(self.setup(value), steps=steps, steps_per_mode=self.settings.shooting.steps_per_mode)

    def _evaluate(self, x: np.ndarray, period: int, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """Scaled residual, state Jacobian, parameter column and measures at scaled point ``x``."""
        value = self.low + x[6] * self.span
        state = x[:6] * self.scale
        base = self.mapping(value, steps)
        result = base(state, period)
        shifted = self.mapping(value + PARAMETER_DIFFERENCE * self.span, steps)(state, period, with_matrix=False)
        self.passes += 2 * period
        residual = (result.state - state) / self.scale
        jacobian = result.monodromy * self.scale[None, :] / self.scale[:, None] - np.eye(6)
        column = (shifted.state - result.state) / self.scale / PARAMETER_DIFFERENCE
        return (
            residual,
            jacobian,
            column,
            {"monodromy": result.monodromy, "measures": result.measures, "setup": base.setup},
        )

    def scaled(self, point: BranchPoint) -> np.ndarray:
        return np.concatenate([point.state / self.scale, [(point.parameter - self.low) / self.span]])

    def correct(
        self, predicted: np.ndarray, tangent: np.ndarray, period: int, previous_tangent: np.ndarray
    ) -> BranchPoint | None:
        """Newton on the extended system from ``predicted``; the corrected point with its tangent, or None.

        The iterations taken are left in ``iterations`` (for the step control).
        """
        x = predicted.copy()
        steps = self.mapping(self.low + x[6] * self.span).steps
        tolerance = self.settings.shooting.tolerance
        for iteration in range(self.settings.corrector_iterations + 1):
            residual, jacobian, column, extra = self._evaluate(x, period, steps)
            if not np.all(np.isfinite(residual)):
                return None
            constraint = float(tangent @ (x - predicted))
            if np.linalg.norm(residual) < tolerance and abs(constraint) < tolerance:
                self.iterations = iteration
                return self._point(x, jacobian, column, extra, previous_tangent)
            extended = np.zeros((7, 7))
            extended[:6, :6], extended[:6, 6], extended[6] = jacobian, column, tangent
            try:
                update = np.linalg.solve(extended, -np.concatenate([residual, [constraint]]))
            except np.linalg.LinAlgError:
                return None
            # a corrector that runs away is a failed step (the step control retries shorter)
            if not np.linalg.norm(update) < MAX_CORRECTION or not -0.5 < x[6] + update[6] < 1.5:
                return None
            x = x + update
        return None

    def _point(
        self, x: np.ndarray, jacobian: np.ndarray, column: np.ndarray, extra: dict, previous_tangent: np.ndarray
    ) -> BranchPoint:
        bordered = np.zeros((7, 7))
        bordered[:6, :6], bordered[:6, 6], bordered[6] = jacobian, column, previous_tangent
        tangent = np.linalg.solve(bordered, np.eye(7)[6])
        tangent /= np.linalg.norm(tangent)
        if tangent @ previous_tangent < 0:
            tangent = -tangent
        return BranchPoint(
            parameter=float(self.low + x[6] * self.span),
            state=x[:6] * self.scale,
            tangent=tangent,
            multipliers=floquet_multipliers(extra["monodromy"]),
            monodromy=extra["monodromy"],
            qois=orbit_qois(extra["measures"], extra["setup"]),
        )

    def first_point(self, value: float, guess: np.ndarray, period: int, direction: float) -> BranchPoint:
        """The orbit at a fixed parameter value by plain shooting, as a branch point heading ``direction``."""
        mapping = self.mapping(value)
        orbit = newton_orbit(mapping, guess, period, self.settings.shooting, self.scale)
        for transient in RELAXATION_PERIODS:
            if orbit is not None:
                break
            # a start far from the orbit: let the transient decay first, then shoot again
            guess = mapping(guess, transient, with_matrix=False).state
            orbit = newton_orbit(mapping, guess, period, self.settings.shooting, self.scale)
        self.passes += mapping.passes
        if orbit is None:
            raise ShootingError(
                f"{self.parameter} = {value:g}: no period-{period} orbit found from the start state; "
                "give initial_state on or near the orbit"
            )
        x = np.concatenate([orbit.state / self.scale, [(value - self.low) / self.span]])
        residual, jacobian, column, extra = self._evaluate(x, period, mapping.steps)
        heading = np.zeros(7)
        heading[6] = direction
        return self._point(x, jacobian, column, extra, heading)

    def inside(self, point: BranchPoint) -> bool:
        margin = 1e-9 * self.span
        return self.low - margin <= point.parameter <= self.high + margin

    def iterates(self, point: BranchPoint, period: int) -> np.ndarray:
        """The DTE at the start of each mesh period of a period-n orbit (its n Poincare points)."""
        values = [point.state[2]]
        state = point.state
        if period > 1:
            mapping = self.mapping(point.parameter)
            for _ in range(period - 1):
                state = mapping(state, 1, with_matrix=False).state
                values.append(state[2])
        self.passes += period - 1
        return np.array(values)

    def half_distance(self, point: BranchPoint, period: int) -> float:
        """Scaled distance between a period-2n orbit's state and its image after n periods (0: period n)."""
        if period % 2:
            return math.inf
        half = self.mapping(point.parameter)(point.state, period // 2, with_matrix=False).state
        self.passes += period // 2
        return float(np.linalg.norm((half - point.state) / self.scale))


class Continuation:
    """Follow the periodic orbits of the gear model in one parameter, with their bifurcations.

    Parameters
    ----------
    parameter : str
        ``pinion_speed``, ``drive_torque``, ``adhesion_torque``, ``mesh_stiffness_scale`` or a
        design key (``k1``, ``k2``, ``zeta_mesh``, ``backlash``, ...).
    start, stop : float
        The range; the branch starts at ``start`` and is followed towards ``stop``.
    settings : ContinuationSettings, optional
    damping_in_separation, stiffness, effects
        The model, as in :func:`uqgear.simulate` (effects must keep the model mesh-periodic).

    Attributes
    ----------
    branches_ : list of Branch
        The period-1 branch first, then the branches switched onto at period doublings.
    bifurcations_ : list of Bifurcation
        Every located bifurcation, in the order found.
    result_ : xarray.Dataset
        Branches and bifurcation table (:func:`uqgear.dynamics.branches.branches_dataset`).
    orbit_passes_ : int
        Mesh periods integrated in total (a cost measure; a pass with the monodromy counts once).

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> fit = Continuation("pinion_speed", 3500.0, 3800.0).fit(design, {"adhesion_torque": 21150.0})
    >>> sorted({b.kind for b in fit.bifurcations_})[:2]
    ['fold', 'grazing_separation']
    """

    def __init__(
        self,
        parameter: str = "pinion_speed",
        start: float = 200.0,
        stop: float = 6000.0,
        *,
        settings: ContinuationSettings | None = None,
        damping_in_separation: bool = True,
        stiffness: str = "ishikawa",
        effects: Sequence[Any] = (),
    ) -> None:
        self.parameter = parameter
        self.start = start
        self.stop = stop
        self.settings = settings or ContinuationSettings()
        self.damping_in_separation = damping_in_separation
        self.stiffness = stiffness
        self.effects = tuple(effects)

    def _check(self, fixed: Mapping[str, float]) -> tuple[float, float]:
        try:
            start, stop = float(self.start), float(self.stop)
        except (TypeError, ValueError):
            raise UqgearError(f"start, stop: expected numbers; got {self.start!r}, {self.stop!r}") from None
        if not (math.isfinite(start) and math.isfinite(stop)) or start == stop:
            raise UqgearError(f"start, stop: expected two different finite values; got {start!r}, {stop!r}")
        if self.parameter in fixed:
            raise UqgearError(f"fixed: {self.parameter!r} is the continuation parameter; leave it out of fixed")
        return start, stop

    def fit(
        self, design: Design, fixed: Mapping[str, float] | None = None, *, initial_state: np.ndarray | None = None
    ) -> Continuation:
        """Follow the period-1 branch from ``start`` to ``stop`` and every doubled branch off it.

        Parameters
        ----------
        design : Design
        fixed : mapping, optional
            The other inputs (``drive_torque``, ``adhesion_torque``, ...; ``pinion_speed`` unless it is
            the parameter).
        initial_state : array of 6, optional
            A state on or near the period-1 orbit at ``start``; the static equilibrium by default.
        """
        fixed = dict(fixed or {})
        start, stop = self._check(fixed)
        if self.parameter != "pinion_speed" and "pinion_speed" not in fixed:
            raise UqgearError(
                "fixed: pinion_speed missing; the orbit needs a speed when another parameter is continued"
            )
        began = self._began = time.perf_counter()
        tracer = _Tracer(
            design,
            self.parameter,
            fixed,
            (start, stop),
            self.settings,
            {"damping_in_separation": self.damping_in_separation, "stiffness": self.stiffness, "effects": self.effects},
        )
        tolerance = self.settings.tolerance if self.settings.tolerance is not None else 1e-5 * tracer.span
        width = self.settings.min_fold_width if self.settings.min_fold_width is not None else 1e-3 * tracer.span
        self.folds_dropped_ = 0
        guess = tracer.setup(start).static_state() if initial_state is None else np.asarray(initial_state, float)
        first = tracer.first_point(start, guess, 1, math.copysign(1.0, stop - start))
        branches: list[Branch] = []
        bifurcations: list[Bifurcation] = []
        queue: list[tuple[Branch, BranchPoint, np.ndarray | None, list[float]]] = [
            (Branch(1, [first]), first, None, [])
        ]
        while queue:
            branch, point, heading, parent_doublings = queue.pop(0)
            if any(
                other.period == branch.period and abs(other.merged_at - point.parameter) < 10 * tolerance
                for other in branches
            ):
                continue  # reached already from its other end
            index = len(branches)
            branches.append(branch)
            found = self._trace(tracer, branch, index, point, heading, tolerance, parent_doublings)
            found, dropped = _drop_fold_pairs(found, width, point.parameter if heading is not None else None)
            self.folds_dropped_ += dropped
            doublings = [b.parameter for b in found if b.kind == PERIOD_DOUBLING]
            for bifurcation in found:
                bifurcations.append(bifurcation)
                if bifurcation.kind == PERIOD_DOUBLING and 2 * branch.period <= self.settings.max_period:
                    switched = self._switch(tracer, bifurcation)
                    if switched is not None:
                        doubled = Branch(2 * branch.period, [], parent=index, origin=len(bifurcations) - 1)
                        queue.append((doubled, *switched, doublings))
        for branch in branches:
            for point in branch.points:
                point.poincare_x = tracer.iterates(point, branch.period)
        self.branches_ = branches
        self.bifurcations_ = bifurcations
        self.tolerance_ = tolerance
        self.orbit_passes_ = tracer.passes
        self.seconds_ = time.perf_counter() - began
        self.result_ = branches_dataset(
            branches,
            bifurcations,
            parameter=self.parameter,
            design=design,
            fixed=fixed,
            tolerance=tolerance,
            attrs=self._attrs(tracer),
        )
        return self

    def _attrs(self, tracer: _Tracer) -> dict[str, Any]:
        return {
            "start": float(self.start),
            "stop": float(self.stop),
            "orbit_passes": int(tracer.passes),
            "run_time_s": float(time.perf_counter() - self._began),
            "damping_in_separation": int(self.damping_in_separation),
            "stiffness": self.stiffness,
            "effects": "; ".join(repr(e) for e in self.effects) or "none",
            "steps_per_mode": self.settings.shooting.steps_per_mode,
            "newton_tolerance": self.settings.shooting.tolerance,
            "max_period": self.settings.max_period,
            "folds_dropped": int(self.folds_dropped_),
        }

    def _trace(
        self,
        tracer: _Tracer,
        branch: Branch,
        index: int,
        point: BranchPoint,
        heading: np.ndarray | None,
        tolerance: float,
        parent_doublings: Sequence[float] = (),
    ) -> list[Bifurcation]:
        """Follow ``branch`` from ``point`` (or, for a switched branch, from the bifurcation along ``heading``).

        ``parent_doublings``: the period doublings of a switched branch's parent, where it can merge back.
        """
        settings = self.settings
        period = branch.period
        step = settings.step
        found: list[Bifurcation] = []
        current = point
        x = tracer.scaled(current)
        tangent = current.tangent if heading is None else heading
        if heading is not None:
            current = None  # type: ignore[assignment]
        widest = 0.0  # largest distance between the halves of a doubled orbit so far
        leaps = 0
        while len(branch.points) < settings.max_points:
            predicted = x + step * tangent
            new = tracer.correct(predicted, tangent, period, tangent)
            if new is None or (current is not None and new.tangent @ current.tangent < math.cos(settings.max_turn)):
                step *= 0.5
                if step >= settings.min_step:
                    continue
                # stuck at a kink of the discrete map (a contact crossing appearing at a grid point, say):
                # leap over it once with the first step size, the turn not checked
                leap = (
                    tracer.correct(x + settings.step * tangent, tangent, period, tangent) if leaps < MAX_LEAPS else None
                )
                if leap is None or current is None:
                    branch.end = "corrector failed" if new is None else "branch turns too sharply"
                    break
                leaps += 1
                new, step = leap, settings.step
            if current is None:
                # the first point of a switched branch: no bifurcation test against the doubling point
                widest = tracer.half_distance(new, period)
                branch.points.append(new)
                current, x, tangent = new, tracer.scaled(new), new.tangent
                continue
            new.arclength = current.arclength + step
            located, merged = _bifurcations_on_step(tracer, branch, index, (current, x, tangent), new, step,
                                                    tolerance, widest)
            found += located
            if merged:
                break
            if period % 2 == 0:
                distance = tracer.half_distance(new, period)
                if distance < COLLAPSE_FRACTION * widest:
                    # the corrector slid onto the parent orbit (a period-2n solution too) across the merge,
                    # which is the parent's period doubling nearest to here
                    branch.merged_at = min(
                        parent_doublings, key=lambda v: abs(v - new.parameter), default=new.parameter
                    )
                    branch.end = f"merges into the period-{period // 2} branch at {branch.merged_at:.6g}"
                    break
                widest = max(widest, distance)
            branch.points.append(new)
            if not tracer.inside(new):
                branch.end = "leaves the range"
                break
            current, x, tangent = new, tracer.scaled(new), new.tangent
            # grow after an easy correction, shrink after a hard one
            if tracer.iterations <= 3:
                step = min(step * 1.5, settings.max_step)
            elif tracer.iterations >= 6:
                step = max(step * 0.7, settings.min_step)
        else:
            branch.end = "point limit reached"
        return found

    def _switch(self, tracer: _Tracer, bifurcation: Bifurcation) -> tuple[BranchPoint, np.ndarray] | None:
        """The start of the doubled branch at a period doubling: the point and the heading off it."""
        point = bifurcation.point
        values, vectors = np.linalg.eig(point.monodromy)
        flip = int(np.argmin(np.abs(values + 1.0)))
        direction = np.real(vectors[:, flip]) / tracer.scale
        direction /= np.linalg.norm(direction)
        heading = np.concatenate([direction, [0.0]])
        heading -= (heading @ point.tangent) * point.tangent
        norm = np.linalg.norm(heading)
        if norm < 1e-8:
            return None
        return replace(point, tangent=heading / norm), heading / norm


def _bifurcations_on_step(
    tracer: _Tracer,
    branch: Branch,
    index: int,
    start: tuple[BranchPoint, np.ndarray, np.ndarray],
    new: BranchPoint,
    step: float,
    tolerance: float,
    widest: float,
) -> tuple[list[Bifurcation], bool]:
    """The bifurcations located on the step from ``start`` (point, scaled point, tangent) to ``new``.

    A fold or branch point where a doubled orbit's halves meet (closer than ``MERGE_FRACTION`` of the
    ``widest`` distance so far) ends the branch: it merges into its parent, and the second value is True.
    """
    current, x, tangent = start
    period = branch.period
    found: list[Bifurcation] = []
    for kind, test in detect(current, new):
        start_x, start_tangent = x.copy(), tangent.copy()

        def corrected(s: float, start_x: np.ndarray = start_x, t: np.ndarray = start_tangent) -> Any:
            return tracer.correct(start_x + s * t, t, period, t)

        located = locate(kind, test, current, new, step, corrected, tolerance, tracer.span, index)
        if (
            kind in (FOLD, BRANCH_POINT)
            and period % 2 == 0
            and tracer.half_distance(located.point, period) < MERGE_FRACTION * widest
        ):
            # a doubled orbit's two halves meet: the parent's period doubling, reached from this side
            branch.merged_at = located.parameter
            branch.end = f"merges into the period-{period // 2} branch at {located.parameter:.6g}"
            return found, True
        found.append(located)
    return found, False


def _drop_fold_pairs(
    found: list[Bifurcation], width: float, origin: float | None = None
) -> tuple[list[Bifurcation], int]:
    """Drop pairs of neighbouring folds of one branch closer than ``width`` (see ``min_fold_width``), and
    on a switched branch a fold closer than that to the period doubling it starts from."""
    kept = list(found)
    dropped = 0
    changed = True
    while changed:
        changed = False
        folds = [i for i, b in enumerate(kept) if b.kind == FOLD]
        if folds and origin is not None and abs(kept[folds[0]].parameter - origin) < width:
            del kept[folds[0]]
            dropped += 1
            changed = True
            continue
        for a, b in zip(folds, folds[1:]):
            if abs(kept[a].parameter - kept[b].parameter) < width:
                del kept[b], kept[a]
                dropped += 2
                changed = True
                break
    return kept, dropped


__all__ = ["Continuation", "ContinuationSettings", "Branch", "PARAMETER_DIFFERENCE"]
