"""The 0-1 test for chaos (Gottwald and Melbourne) on a series of Poincare points.

K near 0 for a regular series, near 1 for a chaotic one; the regime labels
(:mod:`uqgear.dynamics.regimes`) require it to agree with the largest Lyapunov
exponent before a response is called chaotic.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import UqgearError
from ._checks import Seed

#: Fewest Poincare points the 0-1 test accepts: n_cut = N/10 must give a
#: correlation over at least two lags.
MIN_ZERO_ONE_POINTS = 20


def seed_generator(seed: Seed) -> np.random.Generator:
    if isinstance(seed, np.random.SeedSequence):
        return np.random.default_rng(seed)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UqgearError(f"seed: expected a non-negative integer or a numpy.random.SeedSequence; got {seed!r}")
    return np.random.default_rng(np.random.SeedSequence(int(seed)))


def zero_one_frequencies(seed: Seed, n_c: Any) -> np.ndarray:
    if isinstance(n_c, bool) or not isinstance(n_c, (int, np.integer)) or n_c < 1:
        raise UqgearError(f"n_c: expected an integer >= 1; got {n_c!r}")
    # (pi/5, 4pi/5) keeps c away from the resonances c = 0 and c = pi
    # (Gottwald & Melbourne 2009, section 3).
    return seed_generator(seed).uniform(math.pi / 5.0, 4.0 * math.pi / 5.0, int(n_c))


def zero_one_median(series: np.ndarray, frequencies: np.ndarray, constant_tolerance: float = 0.0) -> float:
    n_points = series.size
    spread = np.ptp(series)
    magnitude = np.max(np.abs(series))
    if spread <= max(1e-12 * magnitude, constant_tolerance) or spread == 0.0:
        # A constant sequence (period 1 to round-off, or to the periodicity
        # tolerance) is regular; the statistic itself would see the residual
        # noise and, like any noise, report K near 1.
        return 0.0
    phi = series / spread
    mean = np.mean(phi)
    n_cut = n_points // 10
    lags = np.arange(1, n_cut + 1)
    j = np.arange(1, n_points + 1)
    angles = np.outer(frequencies, j)
    p = np.cumsum(phi * np.cos(angles), axis=1)
    q = np.cumsum(phi * np.sin(angles), axis=1)
    msd = np.empty((frequencies.size, n_cut))
    for index, lag in enumerate(lags):
        msd[:, index] = np.mean((p[:, lag:] - p[:, :-lag]) ** 2 + (q[:, lag:] - q[:, :-lag]) ** 2, axis=1)
    # Modified mean-square displacement D_c(n) = M_c(n) - V_osc(c, n): the
    # oscillatory term of a non-zero mean is removed before correlating.
    oscillation = mean**2 * (1.0 - np.cos(np.outer(frequencies, lags))) / (1.0 - np.cos(frequencies))[:, None]
    displacement = msd - oscillation
    centred_lags = lags - lags.mean()
    centred = displacement - displacement.mean(axis=1, keepdims=True)
    norms = np.sqrt(np.sum(centred**2, axis=1) * np.sum(centred_lags**2))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = np.where(norms > 0.0, centred @ centred_lags / norms, 0.0)
    return float(np.median(correlation))


def zero_one_test(series: Any, seed: Seed = 0, n_c: int = 100) -> float:
    """Gottwald-Melbourne 0-1 test for chaos, correlation method.

    Follows Gottwald & Melbourne, "On the implementation of the 0-1 test for
    chaos", SIAM J. Appl. Dyn. Syst. 8 (2009) 129-145: for each of ``n_c``
    frequencies ``c`` drawn uniformly in (pi/5, 4 pi/5), the translation
    variables ``p_c(n) = sum_j phi_j cos(j c)``, ``q_c(n) = sum_j phi_j sin(j c)``
    give the modified mean-square displacement ``D_c(n)`` for ``n <= N/10``;
    ``K_c`` is the correlation coefficient of ``D_c(n)`` with ``n``, and the
    result is the median of ``K_c`` over ``c`` (which suppresses the isolated
    resonant ``c`` at which a regular series gives a spuriously large ``K_c``).

    Parameters
    ----------
    series : array_like, shape (N,)
        A discrete-time observable, e.g. the Poincare sequence of ``x``
        (not an oversampled time history). ``N >= 20``; a few hundred or more
        sharpen the result.
    seed : int or numpy.random.SeedSequence
        Seeds the draw of the frequencies ``c``.
    n_c : int
        Number of frequencies ``c``.

    Returns
    -------
    float
        Median ``K``: near 0 for regular (periodic, quasi-periodic) dynamics,
        near 1 for chaotic dynamics (and for noise). A sequence constant to
        round-off gives exactly 0.
    """
    array = np.asarray(series.values if isinstance(series, xr.DataArray) else series, dtype=float)
    if array.ndim != 1:
        raise UqgearError(f"series: expected a 1-D sequence; got an array of shape {array.shape}")
    if array.size < MIN_ZERO_ONE_POINTS:
        raise UqgearError(
            f"series: the 0-1 test needs at least {MIN_ZERO_ONE_POINTS} values "
            f"(keep more Poincare periods); got {array.size}"
        )
    if not np.all(np.isfinite(array)):
        raise UqgearError("series: expected finite values; got NaN or infinity")
    return zero_one_median(array, zero_one_frequencies(seed, n_c))


# ----------------------------------------------------------------------------
# classification
# ----------------------------------------------------------------------------
