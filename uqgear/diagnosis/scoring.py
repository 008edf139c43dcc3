"""Held-out scoring: leave-one-run-out predictions, the gap metric, its bootstrap, candidate scores."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.stats

from .discrepancy import robust_log_density
from .fitting import FitProblem, FitResult, parameter_intervals, profile_adhesion, robust_weights

# ---------------------------------------------------------------------------------------------- held-out runs

@dataclass
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
    t2_column: dict[int, int] = {int(index) - problem.n_global: column
                                 for column, index in enumerate(free_index) if index >= problem.n_global}
    vectors, covariances = _newton_steps(result, free_index, global_columns, rows_of, t2_column)
    held_model = _held_out_model(problem, vectors, profile=bool(t2_column))
    z, inflated_scale = _held_out_discrepancy(result, held_model, vectors, covariances, global_columns, rows_of,
                                              t2_column)
    log_density = np.where(np.isfinite(z), robust_log_density(np.nan_to_num(z), np.nan_to_num(inflated_scale, nan=1.0)),
                           np.nan)
    return HeldOut(z=z, scale=inflated_scale, log_density=log_density, vectors=vectors, model=held_model)


def _newton_steps(result: FitResult, free_index: np.ndarray, global_columns: np.ndarray, rows_of: np.ndarray,
                  t2_column: Mapping[int, int]) -> tuple[np.ndarray, list[np.ndarray]]:
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
        at_bound = _pressed_to_bound(result.vector[free_index[keep]], reduced_gradient,
                                     problem.lower[free_index[keep]], problem.upper[free_index[keep]])
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
        worst = np.nanmax(np.abs(np.where(np.isfinite(z_first[..., harmonic]), z_first[..., harmonic], 0.0)),
                          axis=(1, 2))
        for op in np.flatnonzero(worst > _PROFILE_Z):
            vectors[op] = profile_adhesion(problem, vectors[op], [int(op)])
            model, _ = problem.model_features([vectors[op]], [[int(op)]])
            held_model[op] = model[0, op]
    return held_model


def _held_out_discrepancy(result: FitResult, held_model: np.ndarray, vectors: np.ndarray,
                          covariances: Sequence[np.ndarray], global_columns: np.ndarray, rows_of: np.ndarray,
                          t2_column: Mapping[int, int]) -> tuple[np.ndarray, np.ndarray]:
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
            curvature = float(np.sum(w * slope ** 2))
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


# ---------------------------------------------------------------------------------------------- gap metric

GAP_METRIC = "excess_rms_standardised_discrepancy_capped_at_10"
# Each feature's squared discrepancy counts at most this much, so that a few
# features thousands of sigmas off do not decide alone how far a gap shrank.
_GAP_CAP = 10.0
# E[min(z^2, cap^2)] for z ~ N(0, 1): the noise level the gap is measured from.
_GAP_NOISE_LEVEL = float(1.0 - 2.0 * (_GAP_CAP * scipy.stats.norm.pdf(_GAP_CAP) + scipy.stats.norm.sf(_GAP_CAP))
                         + 2.0 * _GAP_CAP ** 2 * scipy.stats.norm.sf(_GAP_CAP))


def capped_squares(z: np.ndarray) -> np.ndarray:
    """min(z^2, cap^2) (NaN stays NaN)."""
    return np.minimum(np.asarray(z, dtype=float) ** 2, _GAP_CAP ** 2)


def gap_metric(z: np.ndarray) -> float:
    """The gap: RMS standardised discrepancy in excess of noise.

    sqrt(max(mean(min(z^2, 10^2)) - E_noise, 0)): 0 when the features scatter
    about the model as noise and model error allow; in units of that scatter
    otherwise, each feature counting at most 10 sigma. NaN entries are ignored.
    """
    values = capped_squares(z)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return math.nan
    return excess_over_noise(float(np.mean(values)))


def excess_over_noise(mean_square: float) -> float:
    """The gap of features with this mean capped square: sqrt(max(mean_square - E_noise, 0))."""
    return math.sqrt(max(mean_square - _GAP_NOISE_LEVEL, 0.0))


def _per_run_squares(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per run (axis 0): the sum of capped squares and the count of finite entries."""
    n_op = z.shape[0]
    squares = np.array([np.nansum(capped_squares(z[op])) for op in range(n_op)])
    counts = np.array([np.sum(np.isfinite(z[op])) for op in range(n_op)])
    return squares, counts


def shrink_fraction(before: float, after: float) -> float:
    """1 - after/before (0 when there is no gap to shrink; negative when it grew)."""
    if not before > 0:
        return 0.0
    return 1.0 - after / before


def bootstrap_shrink(z_before: np.ndarray, z_after: np.ndarray, rng: np.random.Generator,
                     n_resamples: int = 400) -> tuple[float, float, float]:
    """Shrink fraction and its 5 % and 95 % bootstrap quantiles, resampling runs.

    The quantiles are over the resamples that hold a gap to shrink (the
    central resample does whenever the result is not 0).

    Parameters
    ----------
    z_before, z_after : ndarray (n_op, ...)
        Held-out standardised discrepancies of the nominal model and the
        model with the effect.
    """
    before = np.asarray(z_before, dtype=float)
    after = np.asarray(z_after, dtype=float)
    n_op = before.shape[0]
    # per-run sums of squares and counts make each resample cheap
    squares_before, counts = _per_run_squares(before)
    squares_after, _ = _per_run_squares(after)

    def shrink_of(index: np.ndarray) -> float:
        count = counts[index].sum()
        if count == 0:
            return math.nan
        gap_before = excess_over_noise(squares_before[index].sum() / count)
        gap_after = excess_over_noise(squares_after[index].sum() / count)
        # a resample that left out every run carrying the gap has nothing to shrink: the
        # fraction is undefined there, not 0 (a gap confined to one run would otherwise get a
        # lower bound of 0 from the third of resamples that miss that run)
        return shrink_fraction(gap_before, gap_after) if gap_before > 0 else math.nan

    central = shrink_of(np.arange(n_op))
    if not math.isfinite(central):
        return 0.0, 0.0, 0.0
    samples = np.array([shrink_of(rng.integers(0, n_op, n_op)) for _ in range(n_resamples)])
    samples = samples[np.isfinite(samples)]
    return central, float(np.quantile(samples, 0.05)), float(np.quantile(samples, 0.95))


def bootstrap_gap(z: np.ndarray, rng: np.random.Generator, n_resamples: int = 400) -> tuple[float, float]:
    """5 % and 95 % bootstrap quantiles of :func:`gap_metric`, resampling runs (axis 0)."""
    values = np.asarray(z, dtype=float)
    n_op = values.shape[0]
    squares, counts = _per_run_squares(values)
    gaps = []
    for _ in range(n_resamples):
        index = rng.integers(0, n_op, n_op)
        count = counts[index].sum()
        if count:
            gaps.append(excess_over_noise(squares[index].sum() / count))
    if not gaps:
        return math.nan, math.nan
    return float(np.quantile(gaps, 0.05)), float(np.quantile(gaps, 0.95))


# ---------------------------------------------------------------------------------------------- candidate scores

@dataclass
class CandidateScore:
    """Held-out scores of one candidate effect (its best variant)."""

    effect: str
    label: str
    fit: FitResult
    held: HeldOut
    stage: str
    delta_log_density: float
    standard_error: float
    penalty: float
    score: float
    gap: float
    shrink: float
    shrink_low: float
    shrink_high: float
    # robust cost of the nominal model at this fit's nominal parameters and T2 minus the fit's own:
    # what the effect itself adds (set by run_diagnosis; a screening fit shares the nominal's)
    effect_gain: float = math.inf
    # an eccentricity fit's robust cost with its mesh-stiffness modulation (kappa) off minus its own:
    # evidence that pitch errors, which make a run-out but no modulation, cannot give (None: not measured)
    modulation_gain: float | None = None

    def figures(self) -> dict[str, Any]:
        """The figures the verdict reads and the ranking reports (``modulation_gain`` where it was measured)."""
        figures: dict[str, Any] = {
            "effect": self.effect, "score": self.score, "standard_error": self.standard_error,
            "shrink_fraction": self.shrink, "shrink_interval": [self.shrink_low, self.shrink_high],
            "gap_with_effect": self.gap, "effect_gain": self.effect_gain}
        if self.modulation_gain is not None:
            figures["modulation_gain"] = self.modulation_gain
        return figures

    def parameters(self) -> dict[str, object]:
        """Fitted parameters of this candidate's effect (natural units) and its fixed choices.

        Only the new candidate's: in a fit on top of named effects theirs are reported with them.
        """
        candidate = self.fit.problem.candidate
        values: dict[str, object] = {key: value for key, value in candidate.choices}
        fitted = self.fit.values
        values.update({spec.name.split(".", 1)[1]: float(fitted[spec.name]) for spec in candidate.fitted})
        return values

    def parameter_intervals(self) -> dict[str, list[float]]:
        """90 % Laplace intervals of this candidate's fitted parameters (:func:`~.fitting.parameter_intervals`)."""
        candidate = self.fit.problem.candidate
        intervals = parameter_intervals(self.fit, [spec.name for spec in candidate.fitted])
        return {name.split(".", 1)[1]: [low, high] for name, (low, high) in intervals.items()}


def score_candidate(fit_result: FitResult, held: HeldOut, nominal_held: HeldOut, stage: str,
                    rng: np.random.Generator) -> CandidateScore:
    """Held-out log-density gain over the base model, its standard error, penalty and gap shrink.

    The base is the nominal model, or in forward selection the model with
    the effects already named (``nominal_held`` is then its held-out
    predictions): the gain, the penalty (the new effect's parameters only)
    and the shrink are the new effect's on top of it.
    """
    candidate = fit_result.problem.candidate
    difference = held.log_density - nominal_held.log_density
    per_run = np.array([np.nansum(difference[op]) for op in range(difference.shape[0])])
    n_runs = per_run.size
    delta = float(per_run.sum())
    standard_error = float(math.sqrt(n_runs) * per_run.std(ddof=1)) if n_runs > 1 else math.inf
    n_features = int(np.isfinite(held.z).sum())
    penalty = 0.5 * len(candidate.fitted) * math.log(max(n_features, 2))
    gap = gap_metric(held.z)
    shrink, low, high = bootstrap_shrink(nominal_held.z, held.z, rng)
    return CandidateScore(effect=candidate.effect, label=candidate.label, fit=fit_result, held=held, stage=stage,
                          delta_log_density=delta, standard_error=standard_error, penalty=penalty,
                          score=delta - penalty, gap=gap, shrink=shrink, shrink_low=low, shrink_high=high)

