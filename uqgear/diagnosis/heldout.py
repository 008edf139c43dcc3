"""Leave-one-operating-point-out predictions of a fitted model: the held-out runs every score is taken on."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .discrepancy import robust_log_density
from .fit_problem import FitProblem, robust_weights
from .fitting import FitResult, profile_adhesion


@dataclass(frozen=True)
class HeldOut:
    """Leave-one-run-out predictions of a fitted model.

    Attributes
    ----------
    z : ndarray (n_op, n_channel, F)
        Standardised discrepancy of each run's features predicted by the
        model fitted without that run (parameter uncertainty included).
    scale : ndarray
        Predictive scales, same shape.
    log_density : ndarray
        Robust log predictive density of each feature (NaN outside the mask).
    vectors : ndarray (n_op, size)
        Parameter vectors fitted without each run (its T2 profiled on it).
    model : ndarray (n_op, n_channel, all features)
        The held-out model features.
    """

    z: np.ndarray
    scale: np.ndarray
    log_density: np.ndarray
    vectors: np.ndarray
    model: np.ndarray


# A held-out run whose mesh harmonics are this many sigmas off gets its T2 profiled on the grid.
_PROFILE_Z = 5.0
# Largest change of any parameter (optimiser units) in a leave-one-run-out step.
_LOO_STEP_LIMIT = 1.0


def _pressed_to_bound(values: np.ndarray, gradient: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Parameters at a bound whose descent direction points out of the box."""
    span = np.maximum(upper - lower, 1e-12)
    at_lower = (values - lower) <= 1e-6 * span
    at_upper = (upper - values) <= 1e-6 * span
    return (at_lower & (gradient > 0)) | (at_upper & (gradient < 0))


def leave_one_out(result: FitResult) -> HeldOut:
    """Leave-one-operating-point-out predictions from a full fit.

    The fit without run o is one Gauss-Newton step from the full optimum
    with run o's rows removed (robust weights kept, run o's T2 dropped: no
    other run informs it); run o is then re-simulated with those parameters,
    its T2 profiled on its own features (a linearised one-parameter fit
    inside its interval, when the T2 positions were fitted), and the fitted
    global parameters' remaining uncertainty widens the predictive scale.
    """
    problem = result.problem
    free_index = np.flatnonzero(result.free)
    global_columns = np.flatnonzero(free_index < problem.n_global)
    rows_of = problem.op_of_row()
    # column of each run's T2 position in the Jacobian (runs whose T2 was fitted)
    t2_column: dict[int, int] = {
        int(index) - problem.n_global: column for column, index in enumerate(free_index) if index >= problem.n_global
    }
    vectors, covariances = _newton_steps(result, free_index, global_columns, rows_of, t2_column)
    held_model = _held_out_model(problem, vectors, profile=bool(t2_column))
    z, inflated_scale = _held_out_discrepancy(
        result, held_model, vectors, covariances, global_columns, rows_of, t2_column
    )
    log_density = np.where(
        np.isfinite(z), robust_log_density(np.nan_to_num(z), np.nan_to_num(inflated_scale, nan=1.0)), np.nan
    )
    return HeldOut(z=z, scale=inflated_scale, log_density=log_density, vectors=vectors, model=held_model)


def _newton_steps(
    result: FitResult,
    free_index: np.ndarray,
    global_columns: np.ndarray,
    rows_of: np.ndarray,
    t2_column: Mapping[int, int],
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Parameter vectors fitted without each run (one Newton step), and their global parameters' covariances."""
    problem = result.problem
    case = problem.case
    r = result.residuals
    jac = result.jacobian
    weights = robust_weights(r)
    hessian = jac.T @ (weights[:, None] * jac)
    gradient = jac.T @ (weights * r)
    vectors = np.empty((case.n_op, problem.size))
    covariances = []
    for op in range(case.n_op):
        rows = rows_of == op
        keep = np.array([c for c in range(free_index.size) if t2_column.get(op) != c], dtype=int)
        j_op = jac[rows][:, keep]
        reduced = hessian[np.ix_(keep, keep)] - j_op.T @ (weights[rows, None] * j_op)
        reduced_gradient = gradient[keep] - j_op.T @ (weights[rows] * r[rows])
        reduced += np.eye(keep.size) * 1e-9 * max(np.trace(reduced) / max(keep.size, 1), 1e-12)
        # parameters held at a bound by the data stay there (active set); the rest take one
        # Newton step, limited to one optimiser unit: dropping one run is a small perturbation
        at_bound = _pressed_to_bound(
            result.vector[free_index[keep]],
            reduced_gradient,
            problem.lower[free_index[keep]],
            problem.upper[free_index[keep]],
        )
        inverse = np.zeros_like(reduced)
        moving = np.flatnonzero(~at_bound)
        if moving.size:
            inverse[np.ix_(moving, moving)] = np.linalg.pinv(reduced[np.ix_(moving, moving)])
        step = np.clip(-inverse @ reduced_gradient, -_LOO_STEP_LIMIT, _LOO_STEP_LIMIT)
        v = result.vector.copy()
        v[free_index[keep]] += step
        vectors[op] = np.clip(v, problem.lower, problem.upper)
        position = {column: k for k, column in enumerate(keep)}
        chosen = [position[c] for c in global_columns]
        covariances.append(inverse[np.ix_(chosen, chosen)])
    return vectors, covariances


def _held_out_model(problem: FitProblem, vectors: np.ndarray, *, profile: bool) -> np.ndarray:
    """Model features (n_op, n_channel, all features) of each run at its held-out vector.

    With ``profile`` (the T2 positions were fitted), a run far off on its
    mesh harmonics gets its T2 profiled on the grid first (``vectors`` is
    updated in place).
    """
    case = problem.case
    model, _ = problem.model_features(list(vectors), [[op] for op in range(case.n_op)])
    held_model = np.stack([model[op, op] for op in range(case.n_op)])
    if profile:
        # a run predicted far off on its mesh harmonics may sit on the wrong side of a regime
        # change in T2: its T2 is then profiled on the grid before the linear refinement
        z_first, _ = problem.discrepancy(held_model)
        harmonic = np.array(case.layout.families) == "mesh_harmonic"
        worst = np.nanmax(
            np.abs(np.where(np.isfinite(z_first[..., harmonic]), z_first[..., harmonic], 0.0)), axis=(1, 2)
        )
        for op in np.flatnonzero(worst > _PROFILE_Z):
            vectors[op] = profile_adhesion(problem, vectors[op], [int(op)])
            model, _ = problem.model_features([vectors[op]], [[int(op)]])
            held_model[op] = model[0, op]
    return held_model


def _held_out_discrepancy(
    result: FitResult,
    held_model: np.ndarray,
    vectors: np.ndarray,
    covariances: Sequence[np.ndarray],
    global_columns: np.ndarray,
    rows_of: np.ndarray,
    t2_column: Mapping[int, int],
) -> tuple[np.ndarray, np.ndarray]:
    """Held-out standardised discrepancies and predictive scales, each run's T2 refined linearly.

    Each run's T2 is profiled on its own fitted features (a linearised
    one-parameter fit inside its interval; ``vectors`` is updated in place)
    and the remaining uncertainty of the global parameters widens the scale.
    """
    problem = result.problem
    case = problem.case
    jac = result.jacobian
    z_raw, scale = problem.discrepancy(held_model)
    z = np.full_like(z_raw, np.nan)
    inflated_scale = np.full_like(scale, np.nan)
    compared = case.mask()
    for op in range(case.n_op):
        fitted_rows = problem.mask[op][compared[op]]
        residual = np.where(np.isfinite(z_raw[op]), z_raw[op], 0.0)[compared[op]]
        rows = rows_of == op
        slope_fitted = jac[rows][:, t2_column[op]] if op in t2_column else None
        if slope_fitted is not None:
            # profile this run's T2 on its own fitted features (linearised, inside its interval)
            slope = np.zeros(residual.size)
            slope[fitted_rows] = slope_fitted
            w = robust_weights(residual) * fitted_rows
            curvature = float(np.sum(w * slope**2))
            if curvature > 0:
                position = vectors[op, problem.n_global + op]
                shift = -float(np.sum(w * slope * residual)) / curvature
                shift = float(np.clip(position + shift, 0.0, 1.0) - position)
                residual = residual + slope * shift
                vectors[op, problem.n_global + op] = position + shift
        variance = np.zeros(residual.size)
        if global_columns.size:
            j_global = np.zeros((residual.size, global_columns.size))
            j_global[fitted_rows] = jac[rows][:, global_columns]
            variance = np.maximum(np.einsum("ij,jk,ik->i", j_global, covariances[op], j_global), 0.0)
        values = np.full(compared[op].shape, np.nan)
        values[compared[op]] = residual / np.sqrt(1.0 + variance)
        z[op] = values
        widened = np.full(compared[op].shape, np.nan)
        widened[compared[op]] = scale[op][compared[op]] * np.sqrt(1.0 + variance)
        inflated_scale[op] = widened
    return z, inflated_scale


__all__ = ["HeldOut", "leave_one_out"]
