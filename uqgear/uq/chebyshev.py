"""Chebyshev inclusion functions: interval bounds from a tensor Chebyshev series.

After J. Wu, Z. Luo, Y. Zhang, N. Zhang and L. Chen, "Interval uncertain
method for multibody mechanical systems using Chebyshev inclusion
functions", Int. J. Numer. Meth. Engng (2013): the coefficients come from
Gauss-Chebyshev quadrature at the roots of T_{order+1}, the bounds from a
dense scan of the series, and the error estimate from extra check points and
the size of the highest-order coefficients (:func:`chebyshev_bounds`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np
from numpy.polynomial import chebyshev as cheb

from .interval_bounds import (
    FLAG_NONSMOOTH,
    FLAG_SURROGATE_ERROR,
    Bounds,
    find_jumps,
    flag_common_problems,
    interior_check_points,
    relative_error,
    tensor_grid,
)
from .interval_responses import ModelResponses, evaluate_nodes

# series values evaluated per (sweep point, QoI) when scanning a Chebyshev series
_DENSE_SERIES_POINTS = 200_000


def chebyshev_coefficients(node_values: np.ndarray, dimensions: int) -> np.ndarray:
    """Tensor Chebyshev coefficients from values at Gauss-Chebyshev nodes.

    Parameters
    ----------
    node_values : numpy.ndarray
        Shape ``(..., m, ..., m)`` (the last ``dimensions`` axes), values at the
        nodes ``x_j = -cos(pi (j + 1/2) / m)`` (ascending roots of T_m).
    dimensions : int
        Number of node axes.

    Returns
    -------
    numpy.ndarray
        Coefficients ``c[k1, ..., kd]`` of ``sum c T_k1(x1) ... T_kd(xd)``
        by the discrete orthogonality of T_k at the roots of T_m (Gauss-Chebyshev
        quadrature), the same shape as ``node_values``.
    """
    m = node_values.shape[-1]
    nodes = chebyshev_nodes(m)
    transform = (2.0 / m) * cheb.chebvander(nodes, m - 1).T
    transform[0] *= 0.5
    coefficients = node_values
    for axis in range(node_values.ndim - dimensions, node_values.ndim):
        coefficients = np.moveaxis(np.tensordot(transform, coefficients, axes=([1], [axis])), 0, axis)
    return coefficients


def chebyshev_nodes(count: int) -> np.ndarray:
    """Ascending roots of the Chebyshev polynomial T_count in [-1, 1]."""
    return -np.cos(np.pi * (np.arange(count) + 0.5) / count)


def _series_at(coefficients: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Series (coefficients shape (Z, m, ..., m)) at scattered points (n, d) -> (Z, n)."""
    dimensions = points.shape[1]
    letters = "abcdefghijklm"[:dimensions]
    vanders = [cheb.chebvander(points[:, a], coefficients.shape[-1] - 1) for a in range(dimensions)]
    subscripts = f"z{letters}," + ",".join(f"n{letter}" for letter in letters) + "->zn"
    return np.einsum(subscripts, coefficients, *vanders, optimize=True)


def _series_extremes(coefficients: np.ndarray, dimensions: int) -> tuple[np.ndarray, np.ndarray]:
    """Minimum and maximum of each series (Z, m, ..., m) on a dense tensor grid of [-1, 1]^d."""
    per_axis = max(int(_DENSE_SERIES_POINTS ** (1.0 / dimensions)), 4 * coefficients.shape[-1])
    grid = np.linspace(-1.0, 1.0, per_axis)
    vander = cheb.chebvander(grid, coefficients.shape[-1] - 1)
    lower = np.empty(coefficients.shape[0])
    upper = np.empty(coefficients.shape[0])
    chunk = max(1, 5_000_000 // per_axis**dimensions)
    for start in range(0, coefficients.shape[0], chunk):
        values = coefficients[start : start + chunk]
        for axis in range(1, dimensions + 1):
            values = np.moveaxis(np.tensordot(vander, values, axes=([1], [axis])), 0, axis)
        flat = values.reshape(values.shape[0], -1)
        lower[start : start + chunk] = flat.min(axis=1)
        upper[start : start + chunk] = flat.max(axis=1)
    return lower, upper


def chebyshev_bounds(
    responses: ModelResponses,
    sweep_index: np.ndarray,
    dimensions: int,
    order: int,
    check_points: int,
    tolerance: float,
    regime_names: Sequence[str],
) -> Bounds:
    """The ``chebyshev`` method: bounds of a tensor series of ``order`` per axis, with an error estimate."""
    m = order + 1
    nodes_1d = chebyshev_nodes(m)
    nodes = tensor_grid([(nodes_1d + 1.0) / 2.0] * dimensions)
    checks = interior_check_points(check_points, dimensions)
    values, regime = evaluate_nodes(responses, sweep_index, np.vstack([nodes, checks]))
    names = responses.names
    assert names is not None  # set by the model's first call, which every bounding method makes
    count, responses_count = len(sweep_index), values.shape[2]
    node_values, check_values = values[:, : nodes.shape[0]], values[:, nodes.shape[0] :]
    bounds = Bounds.empty(sweep_index, responses_count)
    bounds.observe(values)
    grid = node_values.reshape(count, *([m] * dimensions), responses_count)
    series = np.moveaxis(grid, -1, 1).reshape(count * responses_count, *([m] * dimensions))
    fittable = np.isfinite(series.reshape(series.shape[0], -1)).all(axis=1)
    coefficients = chebyshev_coefficients(np.where(fittable.reshape(-1, *([1] * dimensions)), series, 0.0), dimensions)
    series_lower, series_upper = _series_extremes(coefficients, dimensions)
    # truncation estimate: the coefficients of the two highest orders in any
    # variable (two, because an odd or even response has every other one zero)
    top = np.zeros([m] * dimensions, dtype=bool)
    for axis in range(dimensions):
        index = [slice(None)] * dimensions
        index[axis] = slice(max(m - 2, 1), m)
        top[tuple(index)] = True
    tail = np.abs(coefficients[:, top]).sum(axis=1)
    if checks.shape[0]:
        predicted = _series_at(coefficients, 2.0 * checks - 1.0)  # (Z, n)
        actual = np.moveaxis(check_values, -1, 1).reshape(count * responses_count, -1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            check_error = np.nanmax(np.abs(predicted - actual), axis=1)
    else:
        check_error = np.zeros(count * responses_count)
    error = np.where(fittable, np.fmax(check_error, tail), np.inf).reshape(count, responses_count)
    bounds.error = error
    series_lower = np.where(fittable, series_lower, np.nan).reshape(count, responses_count)
    series_upper = np.where(fittable, series_upper, np.nan).reshape(count, responses_count)
    bounds.lower = np.fmin(series_lower, bounds.observed_lower)
    bounds.upper = np.fmax(series_upper, bounds.observed_upper)
    relative = relative_error(error, bounds.lower, bounds.upper)
    for s, r in zip(*np.nonzero(relative > tolerance)):
        bounds.add_reason(
            s,
            r,
            FLAG_SURROGATE_ERROR,
            f"{names[r]}: Chebyshev surrogate error {error[s, r]:.3g} is {100 * relative[s, r]:.3g}% "
            f"of the band width (tolerance {100 * tolerance:.3g}%)",
        )
    for s, r in zip(*np.nonzero(find_jumps(grid, nodes_1d, bounds.upper - bounds.lower))):
        bounds.add_reason(
            s, r, FLAG_NONSMOOTH, f"{names[r]}: jump between neighbouring Chebyshev nodes: non-smooth response"
        )
    flag_common_problems(bounds, values, regime, regime_names, names)
    return bounds
