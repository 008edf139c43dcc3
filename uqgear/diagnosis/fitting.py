"""Robust least-squares fits of the nominal model and of the nominal model plus candidate effects."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.optimize
import scipy.stats
import xarray as xr

from .candidates import Candidate, nominal_parameters
from .case import RigCase
from .errors import DiagnosisError
from .fit_problem import LOSS_SCALE, FitProblem, robust_cost, robust_weights
from .settings import DEFAULT_SETTINGS

# Every this many Jacobians of a fit is a finite-difference one, the others secant updates.
_SECANT_REFRESH = 2


class SecantJacobian:
    """The solver's Jacobian: finite differences where a fit starts, Broyden's rank-one updates after.

    A finite-difference Jacobian costs a simulation per free global
    parameter and run, several times a residual evaluation; the solver asks
    for one at every accepted point. Between accepted points the residuals
    already simulated give the secant (Broyden 1965) update for free. Its
    entries that are structurally zero (a run's rows in another run's T2
    column, the prior rows) stay zero; every :data:`_SECANT_REFRESH`-th
    call is a fresh finite-difference Jacobian. The fit's final Jacobian
    (intervals, held-out predictions) is always a finite-difference one.
    """

    def __init__(self, problem: FitProblem, free: np.ndarray, expand: Callable[[np.ndarray], np.ndarray]) -> None:
        self.problem, self.free, self.expand = problem, free, expand
        self.calls = 0
        self.point: np.ndarray | None = None
        self.values: np.ndarray | None = None
        self.matrix: np.ndarray | None = None
        self.zero: np.ndarray | None = None

    def __call__(self, u: np.ndarray) -> np.ndarray:
        v = self.expand(u)
        values = self.problem.residuals(v)  # simulated already: the solver evaluated it there
        step = None if self.point is None else u - self.point
        if self.matrix is None or step is None or self.calls % _SECANT_REFRESH == 0 or not step @ step > 0.0:
            matrix = self.problem.jacobian(v, self.free)
            if self.zero is None:
                self.zero = matrix == 0.0
        else:
            assert self.values is not None and step is not None  # set with the matrix by the call before
            matrix = self.matrix + np.outer(values - self.values - self.matrix @ step, step / (step @ step))
            matrix[self.zero] = 0.0
        self.calls += 1
        self.point, self.values, self.matrix = np.array(u, dtype=float), values, matrix
        return matrix


@dataclass(frozen=True)
class FitResult:
    """A fitted model: optimum, residuals and Jacobian there, cost and bookkeeping.

    ``free`` marks the entries of the optimiser vector that were fitted (the
    others stayed at their starting values); ``jacobian`` has one column per
    free entry, in order.
    """

    problem: FitProblem
    vector: np.ndarray
    free: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    z: np.ndarray
    scale: np.ndarray
    model: np.ndarray
    periodic: np.ndarray
    cost: float
    evaluations: int
    seconds: float
    converged: bool
    message: str

    @property
    def values(self) -> dict[str, float]:
        return self.problem.values(self.vector)

    @property
    def positions(self) -> np.ndarray:
        """Each run's T2 as a position in its interval (0 lower end, 1 upper end): the vector after the globals."""
        return self.vector[self.problem.n_global :]

    @property
    def adhesion_torques(self) -> np.ndarray:
        return self.problem.adhesion_torques(self.vector)

    def after(self, earlier: FitResult) -> FitResult:
        """This fit, counting the evaluations and time of the earlier fit it started from."""
        return replace(self, evaluations=self.evaluations + earlier.evaluations, seconds=self.seconds + earlier.seconds)


def start_costs(problem: FitProblem, starts: Sequence[np.ndarray], *, rows: np.ndarray | None = None) -> np.ndarray:
    """The robust (Cauchy) cost of each starting vector over ``rows`` (default all), simulated in one batch."""
    model, _ = problem.model_features(list(starts))
    selected = slice(None) if rows is None else np.asarray(rows, dtype=bool)
    costs = []
    for index, v in enumerate(starts):
        z, _ = problem.discrepancy(model[index])
        costs.append(robust_cost(problem.residual_vector(z, v)[selected]))
    return np.asarray(costs)


def fit(
    problem: FitProblem,
    starts: Sequence[np.ndarray],
    *,
    free: np.ndarray | None = None,
    max_evaluations: int = 30,
    loss: str = "cauchy",
    rows: np.ndarray | None = None,
    tolerance: float = 1e-4,
) -> FitResult:
    """Robust least-squares fit from the best of several starting vectors.

    All starts are simulated in one batch; the one with the lowest robust
    cost is refined with scipy's trust-region reflective least squares
    (bounds, Cauchy loss), the Jacobian from batched finite differences.

    Parameters
    ----------
    problem : FitProblem
    starts : sequence of ndarray
        Full optimiser vectors.
    free : ndarray of bool, optional
        Entries to fit (default all); the T2 positions are free all together or not at all.
    max_evaluations : int
        Cost evaluations allowed to the least-squares solver.
    loss : {"cauchy", "soft_l1"}
        Robust loss of the solver (the result's cost is always the Cauchy one).
    rows : ndarray of bool, optional
        Residual rows the solver sees (default all); the result holds all rows.
    tolerance : float
        Relative tolerance on the cost and the step (scipy's ftol and xtol).
    """
    started = time.perf_counter()
    first = problem.evaluations
    free = np.ones(problem.size, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    selected = slice(None) if rows is None else np.asarray(rows, dtype=bool)
    base = np.asarray(starts[int(np.argmin(start_costs(problem, starts, rows=rows)))], dtype=float)

    def expand(u: np.ndarray) -> np.ndarray:
        v = base.copy()
        v[free] = u
        return v

    secant = SecantJacobian(problem, free, expand)
    result = scipy.optimize.least_squares(
        lambda u: problem.residuals(expand(u))[selected],
        base[free],
        jac=lambda u: secant(u)[selected],
        bounds=(problem.lower[free], problem.upper[free]),
        method="trf",
        loss=loss,
        f_scale=LOSS_SCALE,
        x_scale=1.0,
        max_nfev=max_evaluations,
        xtol=tolerance,
        ftol=tolerance,
        gtol=1e-8,
    )
    v = np.clip(expand(result.x), problem.lower, problem.upper)
    model, periodic = problem.model_features([v])
    z, scale = problem.discrepancy(model[0])
    residuals = problem.residual_vector(z, v)
    jacobian = problem.jacobian(v, free)
    return FitResult(
        problem=problem,
        vector=v,
        free=free,
        residuals=residuals,
        jacobian=jacobian,
        z=z,
        scale=scale,
        model=model[0],
        periodic=periodic[0],
        cost=robust_cost(residuals),
        evaluations=problem.evaluations - first,
        seconds=time.perf_counter() - started,
        converged=bool(result.status > 0),
        message=str(result.message),
    )


#: Standard normal quantile of the two-sided 90 % parameter intervals.
Z90 = float(scipy.stats.norm.ppf(0.95))


def parameter_intervals(result: FitResult, names: Sequence[str] | None = None) -> dict[str, tuple[float, float]]:
    """90 % intervals of fitted global parameters from the Laplace approximation at the optimum.

    The covariance in optimiser units is the inverse of the Gauss-Newton
    Hessian of the robust cost, J^T W J (W the Cauchy loss' IRLS weights, J
    the fit's Jacobian in all its free entries, T2 positions included, so
    that their uncertainty widens the global parameters'); each interval is
    the optimiser value +- 1.645 standard deviations, kept inside the bounds
    and mapped to natural units (a log-scale parameter gets a multiplicative
    interval). A parameter the fit held fixed has no interval.

    Parameters
    ----------
    result : FitResult
    names : sequence of str, optional
        Parameter names (default: every free global parameter).
    """
    problem = result.problem
    free_index = np.flatnonzero(result.free)
    if result.jacobian.shape[1] != free_index.size:
        return {}
    weights = robust_weights(result.residuals)
    hessian = result.jacobian.T @ (weights[:, None] * result.jacobian)
    covariance = np.linalg.pinv(hessian)
    wanted = None if names is None else set(names)
    intervals = {}
    for column, index in enumerate(free_index):
        if index >= problem.n_global:
            continue
        spec = problem.specs[index]
        if wanted is not None and spec.name not in wanted:
            continue
        spread = Z90 * math.sqrt(max(float(covariance[column, column]), 0.0))
        low = max(float(result.vector[index]) - spread, float(problem.lower[index]))
        high = min(float(result.vector[index]) + spread, float(problem.upper[index]))
        intervals[spec.name] = (spec.from_optimiser(low), spec.from_optimiser(high))
    return intervals


# Positions in its interval at which each run's T2 is tried by :func:`profile_adhesion`.
_T2_GRID = np.linspace(0.0, 1.0, 9)


def profile_adhesion(problem: FitProblem, vector: np.ndarray, ops: Sequence[int] | None = None) -> np.ndarray:
    """Each run's T2 set to the best of a grid over its interval, other parameters fixed.

    T2 moves a run across regimes (contact loss, quasi-periodic motion near
    the mesh resonance), where a feature can change tenfold within a kN m
    and be flat elsewhere: a local fit started on the wrong branch never
    finds the right one. Each run depends on its own T2 only, so all runs'
    grids are one batch; the run's Cauchy cost on its fitted features picks
    the position. Returns the updated vector.
    """
    case = problem.case
    ops = list(range(case.n_op)) if ops is None else list(ops)
    vectors = []
    for position in _T2_GRID:
        shifted = np.array(vector, dtype=float)
        shifted[problem.n_global + np.array(ops, dtype=int)] = position
        vectors.append(shifted)
    model, _ = problem.model_features(vectors, [ops] * len(vectors))
    z, _ = problem.discrepancy(model)
    result = np.array(vector, dtype=float)
    for op in ops:
        costs = [
            robust_cost(np.where(np.isfinite(z[k, op]), z[k, op], 0.0)[problem.mask[op]]) for k in range(_T2_GRID.size)
        ]
        result[problem.n_global + op] = _T2_GRID[int(np.argmin(costs))]
    return result


def fit_nominal(
    case: RigCase,
    *,
    max_evaluations: int = DEFAULT_SETTINGS.nominal.nominal_evaluations,
    start: Mapping[str, float] | None = None,
    positions: np.ndarray | None = None,
) -> FitResult:
    """Fit the nominal model (no effect).

    From the design's values and T2 mid-interval, two stages: a soft-L1
    fit to the mesh harmonics alone (what the nominal model class produces,
    a nearly convex problem from there), then the Cauchy fit to all fitted
    features (the redescending loss alone can stall far from the optimum).
    From a calibration (``start``: parameter values, ``positions``: each
    run's T2 position in its interval) only the second stage runs. Before
    the second stage every run's T2 is profiled on a grid (:func:`profile_adhesion`).
    """
    problem = FitProblem(case, None)
    if start is not None:
        begin = problem.vector(start, 0.5 if positions is None else positions)
        return fit(problem, [profile_adhesion(problem, begin), begin], max_evaluations=max_evaluations, tolerance=1e-3)
    families = np.broadcast_to(np.array(case.layout.families), problem.mask.shape)[problem.mask]
    rows = np.concatenate([families == "mesh_harmonic", np.ones(problem.prior_index.size, dtype=bool)])
    first = fit(
        problem, [problem.vector({}, 0.5)], max_evaluations=max_evaluations, loss="soft_l1", rows=rows, tolerance=1e-3
    )
    second = fit(
        problem,
        [profile_adhesion(problem, first.vector), first.vector],
        max_evaluations=max_evaluations,
        tolerance=1e-3,
    )
    return second.after(first)


def fit_candidate(
    case: RigCase,
    candidate: Candidate,
    base: FitResult,
    *,
    full: bool,
    max_evaluations: int = 20,
    start: FitResult | None = None,
    earlier: FitResult | None = None,
) -> FitResult:
    """Fit a base model plus one more effect, warm-started from the base fit and the candidate's signature grid.

    The base is the nominal fit, or (forward selection) a fit of the nominal
    model with effects already named: their structure stays, the new
    candidate acts together with them in every simulation.

    Parameters
    ----------
    case : RigCase
    candidate : Candidate
        The effect added; not an effect of the base (:func:`~.candidates.check_combination`).
    base : FitResult
        The base fit (its parameters and T2 positions are the start).
    full : bool
        Fit all parameters (nominal, the base's effects, the new one's, T2);
        otherwise only the new effect's (the screening fit).
    max_evaluations : int
        Cost evaluations allowed to the least-squares solver.
    start : FitResult, optional
        A screening fit of the same candidate to start from instead of the grid.
    earlier : FitResult, optional
        A full fit of the same candidate against another nominal fit (one in
        a local optimum, since refitted): a start of the full fit too. Where
        it is the best start, the fit refines it with the Cauchy loss alone:
        its soft-L1 stage ran when it was fitted. Screenings ignore it.
    """
    # the base's own model error (its effects' pitch-error allowance) until the new fit gets its own
    problem = FitProblem(case, (*base.problem.candidates, candidate), model_error=base.problem.own_model_error)
    positions = base.positions
    if start is not None:
        starts = [problem.vector(start.values, start.positions)]
    else:
        starts = [problem.vector({**base.values, **point}, positions) for point in candidate.starts]
    free = np.ones(problem.size, dtype=bool)
    if full:
        # As for the nominal fit: the redescending loss alone can leave a few features of one run
        # (a sensitive quasi-periodic one) as "outliers" far from the optimum; a soft-L1 stage
        # first, then the Cauchy fit from the better (in Cauchy cost) of its result and the start.
        # An effect that changes every run (clearance in both bearings) drags the nominal fit far
        # from the truth; the effects' values on the design's own parameters are a start too.
        effect_only = {name: value for name, value in problem.values(starts[0]).items() if "." in name}
        centred = [
            problem.vector(values, positions)
            for values in (effect_only, *({**effect_only, **point} for point in candidate.starts))
        ]
        starts = [profile_adhesion(problem, starts[0]), profile_adhesion(problem, centred[0]), *starts, *centred[1:]]
        if earlier is not None:
            again = problem.vector(earlier.values, earlier.positions)
            if start_costs(problem, [again, *starts]).argmin() == 0:
                return fit(problem, [again], free=free, max_evaluations=max_evaluations, tolerance=1e-3)
        first = fit(problem, starts, free=free, max_evaluations=max_evaluations, loss="soft_l1", tolerance=1e-3)
        second = fit(problem, [first.vector, *starts], free=free, max_evaluations=max_evaluations, tolerance=1e-3)
        return second.after(first)
    n_base = base.problem.n_global
    free[:] = False
    free[n_base : problem.n_global] = True
    result = fit(problem, starts, free=free, max_evaluations=max_evaluations)
    # Held-out predictions must leave each run out of the base's parameters too, as the base
    # model's do: leave_one_out needs the Jacobian in all parameters. The base fit's columns
    # stand in for its parameters and T2 (exact for a small effect; a strong one is refitted in
    # full anyway).
    if base.jacobian.shape[1] == n_base + case.n_op and base.jacobian.shape[0] == result.jacobian.shape[0]:
        jacobian = np.concatenate([base.jacobian[:, :n_base], result.jacobian, base.jacobian[:, n_base:]], axis=1)
    else:
        jacobian = problem.jacobian(result.vector, np.ones(problem.size, dtype=bool))
    return replace(result, jacobian=jacobian, free=np.ones(problem.size, dtype=bool))


def calibration_start(posterior: xr.Dataset, case: RigCase) -> tuple[dict[str, float], np.ndarray | None]:
    """Starting values for the nominal fit from a calibration posterior (``posterior.nc`` of ``uqgear calibrate``).

    Posterior medians of the parameters the diagnosis fits (and of the
    backlash, which it keeps fixed: returned under ``backlash``), and each
    run's T2 median as a position in its interval when the posterior has
    one T2 per run of this campaign.

    Raises
    ------
    DiagnosisError
        Not a Dataset, or it holds none of the nominal parameters.
    """
    if not isinstance(posterior, xr.Dataset):
        raise DiagnosisError(
            f"calibration: expected a posterior Dataset (posterior.nc of uqgear calibrate); "
            f"got {type(posterior).__name__}"
        )
    names = [spec.name for spec in nominal_parameters(case.design)] + ["backlash"]
    start = {name: float(posterior[name].median()) for name in names if name in posterior.data_vars}
    if not start:
        raise DiagnosisError(f"calibration: the posterior has none of the parameters {', '.join(names)}")
    positions = None
    if "adhesion_torque" in posterior.data_vars and posterior["adhesion_torque"].sizes.get("op") == case.n_op:
        other = [dim for dim in posterior["adhesion_torque"].dims if dim != "op"]
        median = np.asarray(posterior["adhesion_torque"].median(dim=other).values, dtype=float)
        width = np.maximum(case.adhesion_upper - case.adhesion_lower, 1e-12)
        positions = np.clip((median - case.adhesion_lower) / width, 0.0, 1.0)
    return start, positions


__all__ = [
    "SecantJacobian",
    "FitResult",
    "start_costs",
    "fit",
    "Z90",
    "parameter_intervals",
    "profile_adhesion",
    "fit_nominal",
    "fit_candidate",
    "calibration_start",
]
