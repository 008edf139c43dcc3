"""Interval bounds from model values on grids: the ``scan`` and ``vertex`` methods.

``scan`` bounds each response by a dense tensor grid over the interval box
and estimates its own error (every other grid point, and a parabola through
the extreme node); ``vertex`` takes the corners and checks them at interior
points, flagging a non-monotone response.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numpy as np

from .interval_bounds import (
    FLAG_NONSMOOTH,
    FLAG_SURROGATE_ERROR,
    FLAG_VERTEX_EXCEEDED,
    Bounds,
    find_jumps,
    flag_common_problems,
    interior_check_points,
    relative_error,
    tensor_grid,
)
from .interval_responses import ModelResponses, evaluate_nodes


def scan_bounds(
    responses: ModelResponses,
    sweep_index: np.ndarray,
    dimensions: int,
    points: int,
    tolerance: float,
    regime_names: Sequence[str],
) -> Bounds:
    """The ``scan`` method: bounds from a tensor grid of ``points`` per axis, with an error estimate."""
    axis = np.linspace(0.0, 1.0, points)
    values, regime = evaluate_nodes(responses, sweep_index, tensor_grid([axis] * dimensions))
    names = responses.names
    assert names is not None  # set by the model's first call, which every bounding method makes
    bounds = Bounds.empty(sweep_index, values.shape[2])
    bounds.observe(values)
    bounds.lower, bounds.upper = bounds.observed_lower.copy(), bounds.observed_upper.copy()
    grid = values.reshape(len(sweep_index), *([points] * dimensions), values.shape[2])
    if points >= 3 and points % 2 == 1:
        coarse = grid[(slice(None),) + (slice(None, None, 2),) * dimensions]
        coarse = coarse.reshape(len(sweep_index), -1, values.shape[2])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            bounds.error = np.fmax(
                np.abs(bounds.lower - np.nanmin(coarse, axis=1)), np.abs(bounds.upper - np.nanmax(coarse, axis=1))
            )
    bounds.error = np.fmax(bounds.error, _parabolic_refinement(grid))
    relative = relative_error(bounds.error, bounds.lower, bounds.upper)
    for s, r in zip(*np.nonzero(relative > tolerance)):
        bounds.add_reason(
            s,
            r,
            FLAG_SURROGATE_ERROR,
            f"{names[r]}: scan grid coarse: the bounds from every other grid point differ by "
            f"{100 * relative[s, r]:.3g}% of the band width",
        )
    for s, r in zip(*np.nonzero(find_jumps(grid, axis, bounds.upper - bounds.lower))):
        bounds.add_reason(
            s, r, FLAG_NONSMOOTH, f"{names[r]}: jump between neighbouring scan points: non-smooth response"
        )
    flag_common_problems(bounds, values, regime, regime_names, names)
    return bounds


def _parabolic_refinement(grid: np.ndarray) -> np.ndarray:
    """How far a parabola through the extreme grid node and its neighbours overshoots it.

    Along each axis where the extreme node of a scan is interior and a local
    extremum, the vertex of the parabola through it and its two neighbours
    estimates how much the true extreme lies beyond the grid value.
    Returns (S, R), the larger of the estimates for the minimum and maximum.
    """
    count, responses = grid.shape[0], grid.shape[-1]
    dimensions = grid.ndim - 2
    shape = grid.shape[1:-1]
    flat = grid.reshape(count, -1, responses)
    estimate = np.zeros((count, responses))
    if not np.all(np.isfinite(flat)):
        return np.full((count, responses), np.nan)
    for pick in (np.argmin, np.argmax):
        position = np.unravel_index(pick(flat, axis=1), shape)  # d arrays of (S, R)
        for axis in range(dimensions):
            index = [p.copy() for p in position]
            centre = index[axis]
            interior = (centre > 0) & (centre < shape[axis] - 1)
            values = []
            for offset in (-1, 0, 1):
                index[axis] = np.clip(centre + offset, 0, shape[axis] - 1)
                flat_index = np.ravel_multi_index(tuple(index), shape)
                values.append(np.take_along_axis(flat, flat_index[:, None, :], axis=1)[:, 0, :])
            before, middle, after = values
            curvature = before - 2.0 * middle + after
            with np.errstate(divide="ignore", invalid="ignore"):
                overshoot = np.abs((after - before) ** 2 / (8.0 * curvature))
            # only a strict local extremum: a plateau beside a jump is no parabola
            strict = (middle - before) * (middle - after) > 0
            overshoot = np.where(interior & strict & np.isfinite(overshoot), overshoot, 0.0)
            estimate = np.fmax(estimate, overshoot)
    return estimate


def vertex_bounds(
    responses: ModelResponses, sweep_index: np.ndarray, dimensions: int, check_points: int, regime_names: Sequence[str]
) -> Bounds:
    """The ``vertex`` method: bounds from the corners, checked at the centre and ``check_points`` more."""
    corners = tensor_grid([np.array([0.0, 1.0])] * dimensions)
    checks = np.vstack([np.full((1, dimensions), 0.5), interior_check_points(check_points, dimensions)])
    values, regime = evaluate_nodes(responses, sweep_index, np.vstack([corners, checks]))
    names = responses.names
    assert names is not None  # set by the model's first call, which every bounding method makes
    corner_values, check_values = values[:, : corners.shape[0]], values[:, corners.shape[0] :]
    bounds = Bounds.empty(sweep_index, values.shape[2])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        lower, upper = np.nanmin(corner_values, axis=1), np.nanmax(corner_values, axis=1)
        check_lower, check_upper = np.nanmin(check_values, axis=1), np.nanmax(check_values, axis=1)
    scale = np.fmax(np.fmax(np.abs(lower), np.abs(upper)), 1e-300)
    exceed = np.fmax(np.fmax(lower - check_lower, check_upper - upper), 0.0)
    bounds.error = exceed
    bounds.observe(values)
    # report at least every value seen; a flagged point is refined by the fallback
    bounds.lower, bounds.upper = bounds.observed_lower.copy(), bounds.observed_upper.copy()
    for s, r in zip(*np.nonzero(exceed > 1e-9 * scale)):
        bounds.add_reason(
            s,
            r,
            FLAG_VERTEX_EXCEEDED,
            f"{names[r]}: vertex bounds exceeded at interior check points: non-monotone response "
            f"(vertex band [{lower[s, r]:.6g}, {upper[s, r]:.6g}], check values "
            f"[{check_lower[s, r]:.6g}, {check_upper[s, r]:.6g}])",
        )
    flag_common_problems(bounds, values, regime, regime_names, names)
    return bounds
