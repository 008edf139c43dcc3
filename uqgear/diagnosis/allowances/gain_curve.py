"""A channel's gain over frequency (rig over model) as a robust Gaussian process in ln(frequency).

A transfer path acts on frequency, not order (a housing resonance is a peak
in Hz), so each channel's log gain is modelled as a smooth function of log
frequency: a Gaussian process with a constant mean, a squared-exponential
kernel and a white scatter term, hyperparameters by maximum marginal
likelihood, made robust (Student-t scatter, iteratively reweighted) so that
lines the model cannot produce at all lose their pull (docs/model/unmodelled-effects.md
section 6.1, step 3). Used by :mod:`.reference`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.optimize

# Bounds of the Gaussian process hyperparameters: length scale in ln(f) (the log gain of a
# resonance of damping 0.02 falls by half within about 0.04 of its peak; one decade is 2.3),
# amplitude and scatter in ln(gain). A shorter length would let the curve follow a single
# line that the model lacks (two lines a few hertz apart disagreeing is no transfer path).
_LENGTH_BOUNDS = (0.04, 3.0)
_AMPLITUDE_BOUNDS = (1e-3, 5.0)
_SCATTER_BOUNDS = (0.01, 2.0)
#: A correction read directly at one reference run has at least this relative uncertainty.
DIRECT_FLOOR = 0.03


@dataclass
class GainCurve:
    """One channel's log gain (rig over model) as a Gaussian process in ln(frequency).

    Attributes
    ----------
    x, y : ndarray
        Training points: ln(frequency / Hz) and ln(rig / model) of the lines.
    weights : ndarray
        Robustness weight of each point (1: a full member; small: a line the
        curve cannot follow, e.g. one the model does not produce at all).
    mean, amplitude, length, scatter : float
        Constant mean, kernel amplitude and length scale (in ln f), white scatter (in ln gain).
    """

    x: np.ndarray
    y: np.ndarray
    weights: np.ndarray
    mean: float
    amplitude: float
    length: float
    scatter: float
    _alpha: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    _factor: tuple | None = field(default=None, repr=False)

    @property
    def dropped(self) -> int:
        """Lines the curve effectively ignores (weight below :data:`_DROPPED_WEIGHT`)."""
        return int(np.sum(self.weights < _DROPPED_WEIGHT))

    @classmethod
    def flat(cls, mean: float = 0.0, scatter: float = DIRECT_FLOOR) -> GainCurve:
        """Too few lines to learn from: a constant gain, a small uncertainty."""
        return cls(np.zeros(0), np.zeros(0), np.zeros(0), mean, _AMPLITUDE_BOUNDS[0], 1.0, scatter)

    def _kernel(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        return _kernel(a, b, self.amplitude, self.length)

    def prepare(self) -> GainCurve:
        if self.x.size:
            matrix = self._kernel(self.x, self.x) + np.diag(self.scatter**2 / self.weights)
            self._factor = scipy.linalg.cho_factor(matrix, lower=True)
            self._alpha = scipy.linalg.cho_solve(self._factor, self.y - self.mean)
        return self

    def predict(self, frequencies: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Log gain and its predictive standard deviation (curve plus scatter) at ``frequencies`` (Hz)."""
        f = np.asarray(frequencies, dtype=float)
        x = np.log(np.maximum(f, 1e-3))
        if not self.x.size or self._factor is None:
            return np.full(f.shape, self.mean), np.full(f.shape, self.scatter)
        cross = self._kernel(x.ravel(), self.x)
        mean = self.mean + cross @ self._alpha
        variance = self.amplitude**2 - np.sum(cross * scipy.linalg.cho_solve(self._factor, cross.T).T, axis=1)
        spread = np.sqrt(np.maximum(variance, 0.0) + self.scatter**2)
        return mean.reshape(f.shape), spread.reshape(f.shape)


# Student-t degrees of freedom of the robust curve fit, and the weight below which a line counts as dropped.
_STUDENT_DOF = 4.0
_DROPPED_WEIGHT = 0.2
_ROBUST_ITERATIONS = 6


def _kernel(a: np.ndarray, b: np.ndarray, amplitude: float, length: float) -> np.ndarray:
    return amplitude**2 * np.exp(-0.5 * ((a[:, None] - b[None, :]) / length) ** 2)


def _negative_log_evidence(log_parameters: np.ndarray, x: np.ndarray, y: np.ndarray, weights: np.ndarray) -> float:
    amplitude, length, scatter = np.exp(log_parameters)
    matrix = _kernel(x, x, amplitude, length) + np.diag(scatter**2 / weights)
    try:
        factor = scipy.linalg.cho_factor(matrix, lower=True)
    except np.linalg.LinAlgError:
        return 1e12
    # the constant mean is profiled out (generalised least squares)
    ones = np.ones(x.size)
    solved_ones = scipy.linalg.cho_solve(factor, ones)
    mean = float(solved_ones @ y / (ones @ solved_ones))
    residual = y - mean
    return float(0.5 * residual @ scipy.linalg.cho_solve(factor, residual) + np.sum(np.log(np.diag(factor[0]))))


def fit_gain_curve(frequencies: np.ndarray, log_ratios: np.ndarray) -> GainCurve:
    """A channel's gain curve from lines' frequencies (Hz) and log ratios rig/model (module docstring, step 3).

    Robust: a Student-t scatter (4 degrees of freedom) by iteratively
    reweighted maximum marginal likelihood, each line weighted by its
    leave-one-out residual against the curve through the others, so that a
    line the model does not produce at all neither bends the curve nor
    inflates its scatter, while a resonance sampled by several lines keeps them.
    """
    x = np.log(np.asarray(frequencies, dtype=float))
    y = np.asarray(log_ratios, dtype=float)
    keep = np.isfinite(x) & np.isfinite(y)
    x, y = x[keep], y[keep]
    if x.size < 3:
        return GainCurve.flat(float(np.median(y)) if y.size else 0.0).prepare()
    bounds = [tuple(np.log(b)) for b in (_AMPLITUDE_BOUNDS, _LENGTH_BOUNDS, _SCATTER_BOUNDS)]
    weights = np.ones(x.size)
    spread = max(float(np.std(y)), 0.05)
    starts = [np.log([spread, length, 0.3 * spread]) for length in (0.06, 0.2, 0.8)]
    curve = None
    for _ in range(_ROBUST_ITERATIONS):
        best = min(
            (
                scipy.optimize.minimize(
                    _negative_log_evidence, start, args=(x, y, weights), method="L-BFGS-B", bounds=bounds
                )
                for start in starts
            ),
            key=lambda found: found.fun,
        )
        amplitude, length, scatter = (float(v) for v in np.exp(best.x))
        matrix = _kernel(x, x, amplitude, length) + np.diag(scatter**2 / weights)
        factor = scipy.linalg.cho_factor(matrix, lower=True)
        ones = np.ones(x.size)
        solved = scipy.linalg.cho_solve(factor, ones)
        mean = float(solved @ y / (ones @ solved))
        curve = GainCurve(x, y, weights.copy(), mean, amplitude, length, scatter).prepare()
        # leave-one-out residuals in closed form (alpha_i / [K^-1]_ii); their spread without the
        # point's own down-weighted noise, so that a far line cannot talk its weight back up
        inverse_diagonal = np.diag(scipy.linalg.cho_solve(factor, np.eye(x.size)))
        loo = curve._alpha / inverse_diagonal
        latent = np.maximum(1.0 / inverse_diagonal - scatter**2 / weights, 0.0)
        standardised = loo / np.sqrt(latent + scatter**2)
        updated = (_STUDENT_DOF + 1.0) / (_STUDENT_DOF + standardised**2)
        updated = np.clip(updated, 1e-3, 1.0)
        starts = [best.x] + starts[1:]
        if np.allclose(updated, weights, atol=0.02):
            break
        weights = updated
    assert curve is not None  # the loop runs at least once
    return curve


__all__ = ["GainCurve", "fit_gain_curve", "DIRECT_FLOOR"]
