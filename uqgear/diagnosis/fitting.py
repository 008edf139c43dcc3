"""Robust least-squares fits of the nominal model and of the nominal model plus candidate effects."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import xarray as xr

from .candidates import Candidate, ParameterSpec, check_combination, combined_periodicity, nominal_parameters
from .case import RigCase, RunTask
from .discrepancy import standardised_discrepancy
from .errors import DiagnosisError

# Feature kinds the fits use (RMS and kurtosis enter the gap map only).
_FITTED_KINDS = ("line", "band")
# Robust (Cauchy) loss of the fits: quadratic to about this |z|, then logarithmic.
_LOSS_SCALE = 3.0
# Finite-difference step in optimiser units (prior standard deviations or effect units).
_DIFFERENCE_STEP = 0.02
# Every this many Jacobians of a fit is a finite-difference one, the others secant updates.
_SECANT_REFRESH = 2


class FitProblem:
    """Nominal model plus any number of candidate effects, as a function of an optimiser vector.

    The vector holds the global parameters (nominal ones, then each
    candidate's, in order) in optimiser units (:class:`ParameterSpec`), then
    the position of each run's T2 inside its interval (0 at the lower, 1 at
    the upper bound). All candidates act together in every simulation; the
    last one is the *new* candidate a fit adds to the others (its ``base``,
    fixed in structure, their parameters fitted or held), the one a score
    is about.

    Parameters
    ----------
    case : RigCase
    candidates : Candidate or sequence of Candidate or None
        The effects of the model (None or empty: the nominal model); each
        library effect at most once (:func:`~.candidates.check_combination`).
    model_error : mapping, optional
        This model's own model error (e.g. with the pitch-error allowance
        of its own effects, :func:`~.manufacturing.allowance_for_fit`);
        default the case's.
    """

    def __init__(self, case: RigCase, candidates: Candidate | Sequence[Candidate] | None, *,
                 model_error: Mapping[str, float] | None = None) -> None:
        self.case = case
        self.own_model_error = model_error
        if candidates is None:
            candidates = ()
        elif isinstance(candidates, Candidate):
            candidates = (candidates,)
        self.candidates: tuple[Candidate, ...] = check_combination(candidates)
        self.specs: list[ParameterSpec] = nominal_parameters(case.design)
        for candidate in self.candidates:
            self.specs += list(candidate.fitted)
        self.n_global = len(self.specs)
        # where the new candidate's parameters start: the base's (nominal and earlier effects) end there
        self.n_base_global = self.n_global - (len(self.candidate.fitted) if self.candidate else 0)
        self.size = self.n_global + case.n_op
        # RMS and kurtosis sum up everything, also what the model class cannot produce; fitted to
        # them the nominal parameters would trade mesh-harmonic accuracy for the unmodelled part.
        fitted_kind = np.array([kind in _FITTED_KINDS for kind in case.layout.kinds])
        self.mask = case.mask() & fitted_kind
        self.periodicity = combined_periodicity([c.periodicity for c in self.candidates], case.design)
        lower = [spec.bounds()[0] for spec in self.specs] + [0.0] * case.n_op
        upper = [spec.bounds()[1] for spec in self.specs] + [1.0] * case.n_op
        self.lower = np.array(lower)
        self.upper = np.array(upper)
        self.prior_index = np.array([i for i, spec in enumerate(self.specs) if spec.prior], dtype=int)
        self._cache: dict[tuple, tuple[np.ndarray, bool]] = {}
        self.evaluations = 0

    @property
    def candidate(self) -> Candidate | None:
        """The new candidate (the last one), or None for the nominal model."""
        return self.candidates[-1] if self.candidates else None

    @property
    def base(self) -> tuple[Candidate, ...]:
        """The candidates the new one is added to."""
        return self.candidates[:-1]

    # -- vectors
    def vector(self, values: Mapping[str, float], t2_position: Sequence[float] | float = 0.5) -> np.ndarray:
        """Optimiser vector from natural values (missing globals at their centres)."""
        v = np.zeros(self.size)
        for i, spec in enumerate(self.specs):
            if spec.name in values:
                v[i] = spec.to_optimiser(float(values[spec.name]))
        v[self.n_global:] = np.broadcast_to(np.asarray(t2_position, dtype=float), (self.case.n_op,))
        return np.clip(v, self.lower, self.upper)

    def values(self, v: np.ndarray) -> dict[str, float]:
        """Natural values of the global parameters."""
        return {spec.name: spec.from_optimiser(float(v[i])) for i, spec in enumerate(self.specs)}

    def adhesion_torques(self, v: np.ndarray) -> np.ndarray:
        position = np.clip(v[self.n_global:], 0.0, 1.0)
        return self.case.adhesion_lower + position * (self.case.adhesion_upper - self.case.adhesion_lower)

    # -- model features
    def run_task(self, v: np.ndarray, op: int) -> "RunTask":
        """The simulation of run ``op`` at optimiser vector ``v``."""
        values = self.values(v)
        design = self.case.design.replace(zeta_mesh=values["zeta_mesh"], ste_amplitude=values["ste_amplitude"],
                                          k1=values["k1"], k2=values["k2"])
        effects = tuple(candidate.make(values) for candidate in self.candidates)
        return RunTask(op, design, values["mesh_stiffness_scale"], float(self.adhesion_torques(v)[op]), effects,
                       self.periodicity)

    def model_features(self, vectors: Sequence[np.ndarray], ops: Sequence[Sequence[int]] | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free model features (V, n_op, n_channel, all features), NaN for runs not asked.

        Returns the features and whether each run's response was periodic
        (V, n_op). Runs already simulated for the same parameters come from a
        cache; the others are simulated together (in worker processes when
        the case has them).
        """
        case = self.case
        n_all = case.observed_all.shape[-1]
        out = np.full((len(vectors), case.n_op, len(case.channels), n_all), np.nan)
        periodic = np.zeros((len(vectors), case.n_op), dtype=bool)
        tasks: list[RunTask] = []
        where: list[tuple[int, int, tuple]] = []
        for index, v in enumerate(vectors):
            for op in (range(case.n_op) if ops is None else ops[index]):
                key = (op, float(v[self.n_global + op]), *np.round(v[:self.n_global], 12))
                if key in self._cache:
                    out[index, op], periodic[index, op] = self._cache[key]
                    continue
                tasks.append(self.run_task(v, op))
                where.append((index, op, key))
        for (index, op, key), (values, is_periodic) in zip(where, case.execute(tasks)):
            self.evaluations += 1
            out[index, op], periodic[index, op] = values, is_periodic
            self._cache[key] = (values, is_periodic)
        return out, periodic

    @property
    def model_error(self) -> Mapping[str, float]:
        """The model error the discrepancies are standardised with: this model's own, else the case's."""
        return self.case.model_error if self.own_model_error is None else self.own_model_error

    def discrepancy(self, model_all: np.ndarray, model_error: Mapping[str, float] | None = None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """Standardised discrepancies and scales (..., n_op, n_channel, F) of model features.

        ``model_error`` replaces :attr:`model_error` (e.g. to judge a base model by a richer one's error).
        """
        case = self.case
        return standardised_discrepancy(case.observed, model_all[..., case.layout.columns], case.noise_std,
                                        case.noise, case.layout,
                                        self.model_error if model_error is None else model_error)

    def residual_vector(self, z: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Feature residuals (masked) followed by the prior residuals."""
        values = np.where(np.isfinite(z), z, 0.0)[self.mask]
        return np.concatenate([values, v[self.prior_index]])

    def residuals(self, v: np.ndarray) -> np.ndarray:
        model, _ = self.model_features([v])
        z, _ = self.discrepancy(model[0])
        return self.residual_vector(z, v)

    def jacobian(self, v: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Forward-difference Jacobian of :meth:`residuals` in the ``free`` entries of ``v``.

        All perturbations are simulated in one batch. Each run depends only
        on its own T2, so one perturbation of all T2 positions at once gives
        every run's T2 column (the positions are free all together or not at all).
        """
        free_index = np.flatnonzero(free)
        global_index = free_index[free_index < self.n_global]
        t2_free = bool(np.any(free_index >= self.n_global))
        vectors = [v]
        steps = []
        for i in global_index:
            step = _DIFFERENCE_STEP if v[i] + _DIFFERENCE_STEP <= self.upper[i] else -_DIFFERENCE_STEP
            shifted = v.copy()
            shifted[i] += step
            vectors.append(shifted)
            steps.append(step)
        if t2_free:
            t2_step = np.where(v[self.n_global:] + _DIFFERENCE_STEP <= 1.0, _DIFFERENCE_STEP, -_DIFFERENCE_STEP)
            shifted = v.copy()
            shifted[self.n_global:] += t2_step
            vectors.append(shifted)
        model, _ = self.model_features(vectors)
        z, _ = self.discrepancy(model)
        base = self.residual_vector(z[0], v)
        columns = {}
        for k, (i, step) in enumerate(zip(global_index, steps), start=1):
            columns[int(i)] = (self.residual_vector(z[k], vectors[k]) - base) / step
        if t2_free:
            change = self.residual_vector(z[-1], vectors[-1]) - base
            rows_of = self.op_of_row()
            for op in range(self.case.n_op):
                column = np.zeros(base.size)
                rows = rows_of == op
                column[rows] = change[rows] / t2_step[op]
                columns[self.n_global + op] = column
        return np.stack([columns[int(i)] for i in free_index], axis=1)

    def op_of_row(self) -> np.ndarray:
        """Run index of each residual row (-1 for priors)."""
        shape = self.mask.shape
        ops = np.broadcast_to(np.arange(shape[0])[:, None, None], shape)[self.mask]
        return np.concatenate([ops, np.full(self.prior_index.size, -1)])


def robust_cost(residuals: np.ndarray) -> float:
    """The fits' objective: the Cauchy loss 0.5 c^2 sum log(1 + (r/c)^2), c = :data:`_LOSS_SCALE`.

    A redescending loss: a feature far beyond what the model class can
    produce (an unmodelled line thousands of sigmas high) loses its pull on
    the parameters instead of bending them towards it through tiny slopes.
    """
    s = (np.asarray(residuals) / _LOSS_SCALE) ** 2
    return float(0.5 * _LOSS_SCALE ** 2 * np.sum(np.log1p(s)))


def robust_weights(residuals: np.ndarray) -> np.ndarray:
    """IRLS weights of the Cauchy loss: 1 / (1 + (r/c)^2)."""
    return 1.0 / (1.0 + (np.asarray(residuals) / _LOSS_SCALE) ** 2)


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
        values = self.problem.residuals(v)          # simulated already: the solver evaluated it there
        step = None if self.point is None else u - self.point
        if self.matrix is None or self.calls % _SECANT_REFRESH == 0 or not step @ step > 0.0:
            matrix = self.problem.jacobian(v, self.free)
            if self.zero is None:
                self.zero = matrix == 0.0
        else:
            matrix = self.matrix + np.outer(values - self.values - self.matrix @ step, step / (step @ step))
            matrix[self.zero] = 0.0
        self.calls += 1
        self.point, self.values, self.matrix = np.array(u, dtype=float), values, matrix
        return matrix


@dataclass
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
    def adhesion_torques(self) -> np.ndarray:
        return self.problem.adhesion_torques(self.vector)

    def after(self, earlier: "FitResult") -> "FitResult":
        """This fit, counting the evaluations and time of the earlier fit it started from."""
        self.evaluations += earlier.evaluations
        self.seconds += earlier.seconds
        return self


def fit(problem: FitProblem, starts: Sequence[np.ndarray], *, free: np.ndarray | None = None,
        max_evaluations: int = 30, loss: str = "cauchy", rows: np.ndarray | None = None,
        tolerance: float = 1e-4) -> FitResult:
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
    model, _ = problem.model_features(list(starts))
    selected = slice(None) if rows is None else np.asarray(rows, dtype=bool)
    costs = []
    for index, v in enumerate(starts):
        z, _ = problem.discrepancy(model[index])
        costs.append(robust_cost(problem.residual_vector(z, v)[selected]))
    base = np.asarray(starts[int(np.argmin(costs))], dtype=float)

    def expand(u: np.ndarray) -> np.ndarray:
        v = base.copy()
        v[free] = u
        return v

    jacobian = SecantJacobian(problem, free, expand)
    result = scipy.optimize.least_squares(lambda u: problem.residuals(expand(u))[selected], base[free],
                                          jac=lambda u: jacobian(u)[selected],
                                          bounds=(problem.lower[free], problem.upper[free]), method="trf",
                                          loss=loss, f_scale=_LOSS_SCALE, x_scale=1.0, max_nfev=max_evaluations,
                                          xtol=tolerance, ftol=tolerance, gtol=1e-8)
    v = np.clip(expand(result.x), problem.lower, problem.upper)
    model, periodic = problem.model_features([v])
    z, scale = problem.discrepancy(model[0])
    residuals = problem.residual_vector(z, v)
    jacobian = problem.jacobian(v, free)
    return FitResult(problem=problem, vector=v, free=free, residuals=residuals, jacobian=jacobian, z=z, scale=scale,
                     model=model[0], periodic=periodic[0], cost=robust_cost(residuals),
                     evaluations=problem.evaluations - first, seconds=time.perf_counter() - started,
                     converged=bool(result.status > 0), message=str(result.message))


# Standard normal quantile of the two-sided 90 % parameter intervals.
_Z90 = 1.6448536269514722


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
        spread = _Z90 * math.sqrt(max(float(covariance[column, column]), 0.0))
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
        costs = [robust_cost(np.where(np.isfinite(z[k, op]), z[k, op], 0.0)[problem.mask[op]])
                 for k in range(_T2_GRID.size)]
        result[problem.n_global + op] = _T2_GRID[int(np.argmin(costs))]
    return result


def fit_nominal(case: RigCase, *, max_evaluations: int = 30, start: Mapping[str, float] | None = None,
                positions: np.ndarray | None = None) -> FitResult:
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
        return fit(problem, [profile_adhesion(problem, begin), begin], max_evaluations=max_evaluations,
                   tolerance=1e-3)
    families = np.broadcast_to(np.array(case.layout.families), problem.mask.shape)[problem.mask]
    rows = np.concatenate([families == "mesh_harmonic", np.ones(problem.prior_index.size, dtype=bool)])
    first = fit(problem, [problem.vector({}, 0.5)], max_evaluations=max_evaluations, loss="soft_l1", rows=rows,
                tolerance=1e-3)
    second = fit(problem, [profile_adhesion(problem, first.vector), first.vector], max_evaluations=max_evaluations,
                 tolerance=1e-3)
    return second.after(first)


def fit_candidate(case: RigCase, candidate: Candidate, base: FitResult, *, full: bool,
                  max_evaluations: int = 20, start: FitResult | None = None) -> FitResult:
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
    """
    # the base's own model error (its effects' pitch-error allowance) until the new fit gets its own
    problem = FitProblem(case, (*base.problem.candidates, candidate), model_error=base.problem.own_model_error)
    positions = base.vector[base.problem.n_global:]
    if start is not None:
        starts = [problem.vector(start.values, start.vector[start.problem.n_global:])]
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
        centred = [problem.vector(values, positions) for values in
                   (effect_only, *({**effect_only, **point} for point in candidate.starts))]
        starts = [profile_adhesion(problem, starts[0]), profile_adhesion(problem, centred[0]), *starts, *centred[1:]]
        first = fit(problem, starts, free=free, max_evaluations=max_evaluations, loss="soft_l1", tolerance=1e-3)
        second = fit(problem, [first.vector, *starts], free=free, max_evaluations=max_evaluations, tolerance=1e-3)
        return second.after(first)
    n_base = base.problem.n_global
    free[:] = False
    free[n_base:problem.n_global] = True
    result = fit(problem, starts, free=free, max_evaluations=max_evaluations)
    # Held-out predictions must leave each run out of the base's parameters too, as the base
    # model's do: leave_one_out needs the Jacobian in all parameters. The base fit's columns
    # stand in for its parameters and T2 (exact for a small effect; a strong one is refitted in
    # full anyway).
    if base.jacobian.shape[1] == n_base + case.n_op and base.jacobian.shape[0] == result.jacobian.shape[0]:
        result.jacobian = np.concatenate([base.jacobian[:, :n_base], result.jacobian, base.jacobian[:, n_base:]],
                                         axis=1)
    else:
        result.jacobian = problem.jacobian(result.vector, np.ones(problem.size, dtype=bool))
    result.free = np.ones(problem.size, dtype=bool)
    return result


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
        raise DiagnosisError(f"calibration: expected a posterior Dataset (posterior.nc of uqgear calibrate); "
                             f"got {type(posterior).__name__}")
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
