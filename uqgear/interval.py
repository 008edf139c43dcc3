"""Interval analysis: bounds of each QoI over the interval parameters.

An interval parameter (the adhesion torque T2 is the typical one) carries no
probability distribution, so the answer to "what does the uncertainty do" is a
band ``[lower, upper]`` of each quantity of interest, at every point of a
sweep (for example every pinion speed). Four methods:

``scan``
    A dense tensor grid over the interval box: the reference. Its own error is
    estimated by comparing with the bounds from every other grid point.
``vertex``
    The 2^d corners of the box. Exact only for monotone responses, so the
    method checks itself at interior points (the centre and a few more) and
    flags ``vertex bounds exceeded at interior check points: non-monotone
    response`` when any lies outside the corner bounds.
``chebyshev``
    The Chebyshev inclusion function of J. Wu, Z. Luo, Y. Zhang, N. Zhang and
    L. Chen, "Interval uncertain method for multibody mechanical systems using
    Chebyshev inclusion functions", Int. J. Numer. Meth. Engng (2013):
    a tensor Chebyshev series whose coefficients come from Gauss-Chebyshev
    quadrature at the roots of T_{order+1}, bounded by scanning the series
    densely (no further model runs). Its error is estimated at extra check
    points and from the size of the highest-order coefficients.
``optimize``
    Multi-start bounded minimisation and maximisation (scipy L-BFGS-B,
    finite-difference gradients) from the best points of a seeded screening
    sample.

Honesty: when a surrogate's estimated error is large compared with the band
width, or the response is seen to be non-smooth (a jump between neighbouring
nodes, a regime variable such as a contact-loss fraction changing over the
box), or the model returns non-finite values, the sweep point is flagged and,
unless ``fallback="none"``, its bounds are recomputed by ``scan`` or
``optimize``. Every reported band is at least as wide as the model values
actually seen. The ``flag`` variable is a bit mask (CF ``flag_masks``); the
reasons are in its ``flag_reasons`` attribute (JSON).

Model runs are batched: all nodes of all sweep points go to the model
function in one call (plus one for a fallback; the optimiser runs all its
local searches in lock-step, one call per iteration).

:func:`pbox` handles mixed interval and random parameters: for every interval
node it estimates the mean, standard deviation and quantiles of each QoI over
the random parameters (common random numbers at every node) and bounds these
statistics over the interval box, giving a probability box.
"""

from __future__ import annotations

import copy
import json
import threading
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr
from numpy.polynomial import chebyshev as cheb
from scipy.optimize import minimize

from .errors import ParameterSpaceError
from .uncertainty import (SAMPLING_METHODS, ModelFunction, ParameterSpace, SeedLike, Sweep, as_seed_sequence,
                          batch_samples, call_model, check_count, check_quantiles, child_seed, make_sweep,
                          seed_attributes, unit_hypercube)

#: Interval analysis methods.
METHODS: tuple[str, ...] = ("scan", "vertex", "chebyshev", "optimize")
#: What to do with a flagged sweep point.
FALLBACKS: tuple[str, ...] = ("scan", "optimize", "none")

#: Flag bits of the ``flag`` variable.
FLAG_VERTEX_EXCEEDED = 1
FLAG_SURROGATE_ERROR = 2
FLAG_NONSMOOTH = 4
FLAG_NONFINITE = 8
FLAG_FALLBACK = 16
FLAG_MEANINGS = ("vertex_bounds_exceeded_at_interior_check_points surrogate_error_large_relative_to_band "
                 "nonsmooth_response nonfinite_model_output bounds_from_fallback_method")
_NEEDS_FALLBACK = FLAG_VERTEX_EXCEEDED | FLAG_SURROGATE_ERROR | FLAG_NONSMOOTH | FLAG_NONFINITE

# default scan points per interval parameter, by number of parameters
_SCAN_POINTS = {1: 101, 2: 41, 3: 15, 4: 9}
# series values evaluated per (sweep point, QoI) when scanning a Chebyshev series
_DENSE_SERIES_POINTS = 200_000
# a step between neighbouring nodes is a jump when it is this many times the
# neighbouring steps (per unit length) and at least this fraction of the band
_JUMP_RATIO = 5.0
_JUMP_FRACTION = 0.2


# ---------------------------------------------------------------------------
# responses at (sweep point, unit-box point) rows
# ---------------------------------------------------------------------------

class _ModelResponses:
    """QoIs of the model at rows of (sweep point, point of the unit interval box)."""

    runs_per_row = 1

    def __init__(self, evaluate: ModelFunction, space: ParameterSpace, sweep: Sweep,
                 qoi: Sequence[str] | None, regime_variables: Sequence[str]) -> None:
        self._evaluate = evaluate
        self._space = space
        self._sweep = sweep
        self._point_values = sweep.point_values()
        self._qoi = None if qoi is None else list(qoi)
        self._regime = list(regime_variables)
        self.interval_names = list(space.interval_names)
        self.names: list[str] | None = None
        self.units: dict[str, str] = {}
        self.long_names: dict[str, str] = {}
        self.runs = np.zeros(sweep.size, dtype=np.int64)
        self.batch_calls = 0

    def batch(self, sweep_index: np.ndarray, unit_points: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, str]]:
        """Model inputs for the rows."""
        columns: dict[str, np.ndarray] = {}
        units: dict[str, str] = {}
        for name in self._space.names:
            if name in self._point_values:
                continue
            columns[name] = self._space.from_unit(name, unit_points[:, self.interval_names.index(name)]) \
                if name in self.interval_names else np.full(len(sweep_index), self._space.nominal(name))
            units[name] = self._space.units(name)
        for position, (name, values) in enumerate(self._point_values.items()):
            columns[name] = values[sweep_index]
            units[name] = self._sweep.attrs[position].get("units", "")
        return columns, units

    def __call__(self, sweep_index: np.ndarray, unit_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (rows x responses) and regime variables (rows x regime variables)."""
        columns, units = self.batch(sweep_index, unit_points)
        # with no QoI list, every per-sample output comes back and the regime variables are split off
        request = None if self._qoi is None else self._qoi + self._regime
        outputs = call_model(self._evaluate, batch_samples(columns, units), request)
        missing = [name for name in self._regime if name not in outputs]
        if missing:
            raise ParameterSpaceError(f"regime_variables: {', '.join(missing)} not returned by the model "
                                      f"function (it returned {', '.join(map(str, outputs.data_vars))})")
        if self.names is None:
            names = self._qoi if self._qoi is not None else [n for n in outputs.data_vars if n not in self._regime]
            if not names:
                raise ParameterSpaceError("qoi: the model function returned only regime variables")
            self.names = list(names)
            self.units = {name: outputs[name].attrs.get("units", "") for name in self.names}
            self.long_names = {name: outputs[name].attrs.get("long_name", name) for name in self.names}
        values = np.stack([outputs[name].values for name in self.names], axis=1)
        regime = (np.stack([outputs[name].values for name in self._regime], axis=1) if self._regime
                  else np.empty((len(sweep_index), 0)))
        np.add.at(self.runs, sweep_index, self.runs_per_row)
        self.batch_calls += 1
        return values, regime


class _PboxResponses(_ModelResponses):
    """Statistics over the random parameters at rows of (sweep point, interval point)."""

    def __init__(self, evaluate: ModelFunction, space: ParameterSpace, sweep: Sweep, qoi: Sequence[str] | None,
                 n_samples: int, sampling: str, quantiles: np.ndarray,
                 seed_sequence: np.random.SeedSequence) -> None:
        super().__init__(evaluate, space, sweep, qoi, ())
        self.runs_per_row = n_samples
        self.quantiles = quantiles
        self.random_names = list(space.random_names)
        unit = unit_hypercube(n_samples, len(self.random_names), sampling, seed_sequence)
        # common random numbers: the same random samples at every interval node,
        # so differences between nodes are not sampling noise
        self._random = {name: space.from_unit(name, unit[:, j]) for j, name in enumerate(self.random_names)}
        self.qoi_names: list[str] | None = None

    def __call__(self, sweep_index: np.ndarray, unit_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.runs_per_row
        columns, units = self.batch(sweep_index, unit_points)
        expanded = {name: np.repeat(values, n) for name, values in columns.items() if name not in self._random}
        for name, values in self._random.items():
            expanded[name] = np.tile(values, len(sweep_index))
            units[name] = self._space.units(name)
        outputs = call_model(self._evaluate, batch_samples(expanded, units), self._qoi)
        if self.qoi_names is None:
            self.qoi_names = list(outputs.data_vars)
            self.units = {name: outputs[name].attrs.get("units", "") for name in self.qoi_names}
            self.long_names = {name: outputs[name].attrs.get("long_name", name) for name in self.qoi_names}
            self.names = [f"{q}|{s}" for q in self.qoi_names
                          for s in ["mean", "std"] + [f"q{i}" for i in range(self.quantiles.size)]]
        values = np.stack([outputs[name].values.reshape(len(sweep_index), n) for name in self.qoi_names], axis=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            # a failed run makes the statistic of its node non-finite: flagged, never silently dropped
            mean = values.mean(axis=-1)
            std = values.std(axis=-1, ddof=1)
            quantile = np.moveaxis(np.quantile(values, self.quantiles, axis=-1), 0, -1)
        statistics = np.concatenate([mean[..., None], std[..., None], quantile], axis=-1)
        np.add.at(self.runs, sweep_index, n)
        self.batch_calls += 1
        return statistics.reshape(len(sweep_index), -1), np.empty((len(sweep_index), 0))


# ---------------------------------------------------------------------------
# bounds from node values
# ---------------------------------------------------------------------------

@dataclass
class _Bounds:
    """Bounds of every response at the analysed sweep points."""

    sweep_index: np.ndarray          # (S,) flat sweep point numbers
    lower: np.ndarray                # (S, R)
    upper: np.ndarray
    observed_lower: np.ndarray       # extremes of the model values actually seen
    observed_upper: np.ndarray
    error: np.ndarray                # estimated absolute error of the bounds (NaN: no estimate)
    flag: np.ndarray                 # int bit mask
    reasons: dict[tuple[int, int], list[str]] = field(default_factory=dict)

    @classmethod
    def empty(cls, sweep_index: np.ndarray, responses: int) -> "_Bounds":
        shape = (len(sweep_index), responses)
        return cls(sweep_index, np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.inf),
                   np.full(shape, -np.inf), np.full(shape, np.nan), np.zeros(shape, dtype=np.int64))

    def add_reason(self, row: int, response: int, bit: int, text: str) -> None:
        self.flag[row, response] |= bit
        self.reasons.setdefault((int(self.sweep_index[row]), response), []).append(text)

    def observe(self, values: np.ndarray) -> None:
        """Widen the observed extremes with model values of shape (S, k, R)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            self.observed_lower = np.fmin(self.observed_lower, np.nanmin(values, axis=1))
            self.observed_upper = np.fmax(self.observed_upper, np.nanmax(values, axis=1))


def _evaluate_nodes(responses: _ModelResponses, sweep_index: np.ndarray,
                    nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values (S, k, R) and regime variables (S, k, G) at every node of every sweep point."""
    rows_sweep = np.repeat(sweep_index, nodes.shape[0])
    rows_points = np.tile(nodes, (len(sweep_index), 1))
    values, regime = responses(rows_sweep, rows_points)
    return (values.reshape(len(sweep_index), nodes.shape[0], -1),
            regime.reshape(len(sweep_index), nodes.shape[0], -1))


def _tensor_grid(axes: Sequence[np.ndarray]) -> np.ndarray:
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([axis.ravel() for axis in mesh], axis=1)


def _check_points(count: int, dimensions: int) -> np.ndarray:
    """Deterministic, well spread interior points (Roberts' R-sequence).

    No randomness is needed for check points, and the sequence avoids the
    centre of the box and the Chebyshev nodes.
    """
    if count == 0:
        return np.empty((0, dimensions))
    phi = 2.0
    for _ in range(60):  # root of x**(d+1) = x + 1 by fixed-point iteration
        phi = (1.0 + phi) ** (1.0 / (dimensions + 1))
    alpha = (1.0 / phi) ** np.arange(1, dimensions + 1)
    index = np.arange(1, count + 1)[:, None]
    return np.mod(0.5 + index * alpha, 1.0)


def _relative(error: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    width = upper - lower
    scale = np.maximum(np.fmax(np.abs(lower), np.abs(upper)), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = error / width
        # a constant response: the error is zero up to rounding, or it is not
        constant = ~(width > 1e-12 * scale)
        relative = np.where(constant, np.where(error <= 1e-12 * scale, 0.0, np.inf), relative)
    return np.where(np.isnan(error), np.nan, relative)


def _jumps(grid: np.ndarray, coordinates: np.ndarray, width: np.ndarray) -> np.ndarray:
    """Which (sweep point, response) show a jump between neighbouring grid nodes.

    ``grid`` has shape (S, n, ..., n, R) with node coordinates ``coordinates``
    (ascending, same along every axis). A step counts as a jump when its slope
    is ``_JUMP_RATIO`` times the slopes of both neighbouring steps and the step
    is at least ``_JUMP_FRACTION`` of the band width; a smooth response has
    neighbouring slopes of similar size once the grid resolves it.
    """
    dimensions = grid.ndim - 2
    found = np.zeros((grid.shape[0], grid.shape[-1]), dtype=bool)
    if coordinates.size < 3:
        return found
    spacing = np.diff(coordinates)
    band = width.reshape(width.shape[0], *([1] * (dimensions - 1)), width.shape[1], 1)
    for axis in range(1, dimensions + 1):
        steps = np.moveaxis(np.diff(grid, axis=axis), axis, -1)  # (S, ..., R, n-1)
        slopes = np.abs(steps) / spacing
        padding = np.zeros(slopes.shape[:-1] + (1,))
        left = np.concatenate([padding, slopes[..., :-1]], axis=-1)
        right = np.concatenate([slopes[..., 1:], padding], axis=-1)
        big = np.abs(steps) >= _JUMP_FRACTION * band
        with np.errstate(invalid="ignore"):
            jump = big & (slopes > _JUMP_RATIO * np.fmax(left, right))
        found |= jump.reshape(jump.shape[0], -1, jump.shape[-2], jump.shape[-1]).any(axis=(1, 3))
    return found


def _regime_changes(regime: np.ndarray) -> list[list[str]]:
    """Per sweep point, the regime variables (by position) that change over the nodes."""
    changes = []
    for point in regime:
        changed = []
        for g in range(point.shape[1]):
            column = point[:, g]
            finite = column[np.isfinite(column)]
            if finite.size and finite.max() - finite.min() > 1e-12 * max(1.0, np.abs(finite).max()):
                changed.append(g)
        changes.append(changed)
    return changes


def _common_flags(bounds: _Bounds, values: np.ndarray, regime: np.ndarray, regime_names: Sequence[str],
                  names: Sequence[str]) -> None:
    nonfinite = ~np.isfinite(values).all(axis=1)
    for s, r in zip(*np.nonzero(nonfinite)):
        count = int((~np.isfinite(values[s, :, r])).sum())
        bounds.add_reason(s, r, FLAG_NONFINITE, f"{names[r]}: {count} of {values.shape[1]} model values "
                                                f"non-finite")
    for s, changed in enumerate(_regime_changes(regime)):
        if changed:
            which = ", ".join(regime_names[g] for g in changed)
            for r in range(values.shape[2]):
                bounds.add_reason(s, r, FLAG_NONSMOOTH, f"regime variable(s) {which} change over the interval "
                                                        f"box: response not smooth")


def _scan(responses: _ModelResponses, sweep_index: np.ndarray, dimensions: int, points: int,
          tolerance: float, regime_names: Sequence[str]) -> _Bounds:
    axis = np.linspace(0.0, 1.0, points)
    values, regime = _evaluate_nodes(responses, sweep_index, _tensor_grid([axis] * dimensions))
    names = responses.names
    bounds = _Bounds.empty(sweep_index, values.shape[2])
    bounds.observe(values)
    bounds.lower, bounds.upper = bounds.observed_lower.copy(), bounds.observed_upper.copy()
    grid = values.reshape(len(sweep_index), *([points] * dimensions), values.shape[2])
    if points >= 3 and points % 2 == 1:
        coarse = grid[(slice(None),) + (slice(None, None, 2),) * dimensions]
        coarse = coarse.reshape(len(sweep_index), -1, values.shape[2])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            bounds.error = np.fmax(np.abs(bounds.lower - np.nanmin(coarse, axis=1)),
                                   np.abs(bounds.upper - np.nanmax(coarse, axis=1)))
    bounds.error = np.fmax(bounds.error, _parabolic_refinement(grid))
    relative = _relative(bounds.error, bounds.lower, bounds.upper)
    for s, r in zip(*np.nonzero(relative > tolerance)):
        bounds.add_reason(s, r, FLAG_SURROGATE_ERROR,
                          f"{names[r]}: scan grid coarse: the bounds from every other grid point differ by "
                          f"{100 * relative[s, r]:.3g}% of the band width")
    for s, r in zip(*np.nonzero(_jumps(grid, axis, bounds.upper - bounds.lower))):
        bounds.add_reason(s, r, FLAG_NONSMOOTH, f"{names[r]}: jump between neighbouring scan points: "
                                                f"non-smooth response")
    _common_flags(bounds, values, regime, regime_names, names)
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


def _vertex(responses: _ModelResponses, sweep_index: np.ndarray, dimensions: int, check_points: int,
            regime_names: Sequence[str]) -> _Bounds:
    corners = _tensor_grid([np.array([0.0, 1.0])] * dimensions)
    checks = np.vstack([np.full((1, dimensions), 0.5), _check_points(check_points, dimensions)])
    values, regime = _evaluate_nodes(responses, sweep_index, np.vstack([corners, checks]))
    names = responses.names
    corner_values, check_values = values[:, :corners.shape[0]], values[:, corners.shape[0]:]
    bounds = _Bounds.empty(sweep_index, values.shape[2])
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
        bounds.add_reason(s, r, FLAG_VERTEX_EXCEEDED,
                          f"{names[r]}: vertex bounds exceeded at interior check points: non-monotone response "
                          f"(vertex band [{lower[s, r]:.6g}, {upper[s, r]:.6g}], check values "
                          f"[{check_lower[s, r]:.6g}, {check_upper[s, r]:.6g}])")
    _common_flags(bounds, values, regime, regime_names, names)
    return bounds


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
    chunk = max(1, 5_000_000 // per_axis ** dimensions)
    for start in range(0, coefficients.shape[0], chunk):
        values = coefficients[start:start + chunk]
        for axis in range(1, dimensions + 1):
            values = np.moveaxis(np.tensordot(vander, values, axes=([1], [axis])), 0, axis)
        flat = values.reshape(values.shape[0], -1)
        lower[start:start + chunk] = flat.min(axis=1)
        upper[start:start + chunk] = flat.max(axis=1)
    return lower, upper


def _chebyshev(responses: _ModelResponses, sweep_index: np.ndarray, dimensions: int, order: int,
               check_points: int, tolerance: float, regime_names: Sequence[str]) -> _Bounds:
    m = order + 1
    nodes_1d = chebyshev_nodes(m)
    nodes = _tensor_grid([(nodes_1d + 1.0) / 2.0] * dimensions)
    checks = _check_points(check_points, dimensions)
    values, regime = _evaluate_nodes(responses, sweep_index, np.vstack([nodes, checks]))
    names = responses.names
    count, responses_count = len(sweep_index), values.shape[2]
    node_values, check_values = values[:, :nodes.shape[0]], values[:, nodes.shape[0]:]
    bounds = _Bounds.empty(sweep_index, responses_count)
    bounds.observe(values)
    grid = node_values.reshape(count, *([m] * dimensions), responses_count)
    series = np.moveaxis(grid, -1, 1).reshape(count * responses_count, *([m] * dimensions))
    fittable = np.isfinite(series.reshape(series.shape[0], -1)).all(axis=1)
    coefficients = chebyshev_coefficients(np.where(fittable.reshape(-1, *([1] * dimensions)), series, 0.0),
                                          dimensions)
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
    relative = _relative(error, bounds.lower, bounds.upper)
    for s, r in zip(*np.nonzero(relative > tolerance)):
        bounds.add_reason(s, r, FLAG_SURROGATE_ERROR,
                          f"{names[r]}: Chebyshev surrogate error {error[s, r]:.3g} is {100 * relative[s, r]:.3g}% "
                          f"of the band width (tolerance {100 * tolerance:.3g}%)")
    for s, r in zip(*np.nonzero(_jumps(grid, nodes_1d, bounds.upper - bounds.lower))):
        bounds.add_reason(s, r, FLAG_NONSMOOTH, f"{names[r]}: jump between neighbouring Chebyshev nodes: "
                                                f"non-smooth response")
    _common_flags(bounds, values, regime, regime_names, names)
    return bounds


# ---------------------------------------------------------------------------
# multi-start optimisation, all local searches in lock-step
# ---------------------------------------------------------------------------

class _Aborted(Exception):
    """The batch evaluation failed; local searches stop."""


class _NonFinite(Exception):
    """The model returned a non-finite value; this local search stops."""


class _LockstepBatcher:
    """Collects the requests of all local searches and evaluates them in one call per round.

    Each local search runs scipy's optimiser in its own thread; its objective
    posts points and waits. When every live search is waiting, the collected
    points go to the model in one batch.
    """

    def __init__(self, workers: int) -> None:
        self._condition = threading.Condition()
        self._pending: dict[int, tuple[int, np.ndarray]] = {}
        self._results: dict[int, np.ndarray] = {}
        self._active = workers
        self._abort = False

    def request(self, worker: int, sweep_row: int, points: np.ndarray) -> np.ndarray:
        with self._condition:
            if self._abort:
                raise _Aborted
            self._pending[worker] = (sweep_row, points)
            self._condition.notify_all()
            self._condition.wait_for(lambda: worker in self._results or self._abort)
            if self._abort:
                raise _Aborted
            return self._results.pop(worker)

    def finish(self) -> None:
        with self._condition:
            self._active -= 1
            self._condition.notify_all()

    def serve(self, evaluate: Callable[[dict[int, tuple[int, np.ndarray]]], dict[int, np.ndarray]]) -> int:
        """Evaluate rounds until every search has finished; returns the number of rounds."""
        rounds = 0
        while True:
            with self._condition:
                self._condition.wait_for(lambda: len(self._pending) >= self._active)
                if self._active == 0:
                    return rounds
                requests = dict(self._pending)
                self._pending.clear()
            try:
                results = evaluate(requests)
            except BaseException:
                with self._condition:
                    self._abort = True
                    self._condition.notify_all()
                raise
            rounds += 1
            with self._condition:
                self._results.update(results)
                self._condition.notify_all()


def _optimize(responses: _ModelResponses, sweep_index: np.ndarray, dimensions: int,
              seed_sequence: np.random.SeedSequence, n_starts: int, screen_points: int,
              max_iterations: int, step: float, regime_names: Sequence[str]) -> _Bounds:
    screen = [np.full((1, dimensions), 0.5), unit_hypercube(screen_points, dimensions, "latin_hypercube",
                                                            seed_sequence)]
    if dimensions <= 6:
        screen.insert(0, _tensor_grid([np.array([0.0, 1.0])] * dimensions))
    screen_nodes = np.vstack(screen)
    values, regime = _evaluate_nodes(responses, sweep_index, screen_nodes)
    names = responses.names
    responses_count = values.shape[2]
    bounds = _Bounds.empty(sweep_index, responses_count)
    bounds.observe(values)
    _common_flags(bounds, values, regime, regime_names, names)
    nonfinite_seen = np.zeros(bounds.flag.shape, dtype=bool)
    lock = threading.Lock()

    searches = []
    for row in range(len(sweep_index)):
        for r in range(responses_count):
            for sign in (1.0, -1.0):
                objective = sign * values[row, :, r]
                order = [k for k in np.argsort(objective) if np.isfinite(objective[k])]
                for k in order[:n_starts]:
                    searches.append((row, r, sign, screen_nodes[k]))
    batcher = _LockstepBatcher(len(searches))
    failures: list[BaseException] = []

    def search(worker: int, row: int, r: int, sign: float, start: np.ndarray) -> None:
        def objective(x: np.ndarray) -> tuple[float, np.ndarray]:
            x = np.clip(x, 0.0, 1.0)
            steps = np.where(x + step <= 1.0, step, -step)
            points = np.vstack([x, x + np.diag(steps)])
            result = batcher.request(worker, row, points)[:, r]
            if not np.all(np.isfinite(result)):
                raise _NonFinite
            return sign * result[0], sign * (result[1:] - result[0]) / steps
        try:
            minimize(objective, start, jac=True, method="L-BFGS-B", bounds=[(0.0, 1.0)] * dimensions,
                     options={"maxiter": max_iterations, "maxfun": 2 * max_iterations})
        except _NonFinite:
            with lock:
                nonfinite_seen[row, r] = True
        except _Aborted:
            pass
        except BaseException as error:  # re-raised in the calling thread
            with lock:
                failures.append(error)
        finally:
            batcher.finish()

    def evaluate(requests: dict[int, tuple[int, np.ndarray]]) -> dict[int, np.ndarray]:
        workers = sorted(requests)  # the batch does not depend on thread timing
        rows = np.concatenate([np.full(len(requests[w][1]), requests[w][0]) for w in workers])
        points = np.vstack([requests[w][1] for w in workers])
        found, _ = responses(sweep_index[rows], points)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            for row in np.unique(rows):
                chosen = found[rows == row]
                bounds.observed_lower[row] = np.fmin(bounds.observed_lower[row], np.nanmin(chosen, axis=0))
                bounds.observed_upper[row] = np.fmax(bounds.observed_upper[row], np.nanmax(chosen, axis=0))
        results, position = {}, 0
        for w in workers:
            size = len(requests[w][1])
            results[w] = found[position:position + size]
            position += size
        return results

    threads = [threading.Thread(target=search, args=(i, *spec), daemon=True) for i, spec in enumerate(searches)]
    for thread in threads:
        thread.start()
    try:
        batcher.serve(evaluate)
    finally:
        for thread in threads:
            thread.join()
    if failures:
        raise failures[0]
    for row, r in zip(*np.nonzero(nonfinite_seen & ~(bounds.flag & FLAG_NONFINITE).astype(bool))):
        bounds.add_reason(row, r, FLAG_NONFINITE, f"{names[r]}: non-finite model value met by a local search")
    bounds.lower, bounds.upper = bounds.observed_lower.copy(), bounds.observed_upper.copy()
    return bounds


# ---------------------------------------------------------------------------
# the analysis
# ---------------------------------------------------------------------------

class IntervalAnalysis:
    """Bounds of each QoI over the interval parameters, at every sweep point.

    Parameters
    ----------
    method : {"scan", "vertex", "chebyshev", "optimize"}
        See the module documentation.
    order : int
        Chebyshev series order per interval parameter ((order + 1)^d nodes).
    scan_points : int, optional
        Grid points per interval parameter for ``scan`` (and the scan
        fallback); default 101, 41, 15, 9, 5 for 1, 2, 3, 4, more parameters.
    check_points : int
        Extra interior points at which ``chebyshev`` and ``vertex`` check
        themselves (``vertex`` always checks the centre as well).
    tolerance : float
        Largest acceptable estimated error of a surrogate's bounds, as a
        fraction of the band width; beyond it the point is flagged.
    fallback : {"scan", "optimize", "none"}
        How flagged sweep points of ``vertex`` and ``chebyshev`` are redone.
    n_starts : int
        Local searches per QoI, sweep point and direction (``optimize``).
    screen_points : int, optional
        Seeded Latin-hypercube points (plus corners and centre) evaluated
        before the local searches; default 20 d.
    max_iterations : int
        L-BFGS-B iterations per local search.
    finite_difference_step : float
        Step of the finite-difference gradients, as a fraction of each
        interval's width.
    regime_variables : sequence of str
        Model outputs that reveal a change of regime (e.g. a contact-loss
        fraction); if one changes over the box, the response is flagged as
        non-smooth. They are not bounded.
    qoi : sequence of str, optional
        QoIs to bound; default every per-sample output.
    seed : SeedSequence or int, optional
        Needed by ``optimize`` (as method or fallback) and by :func:`pbox`.

    Attributes
    ----------
    result_ : xarray.Dataset
        After :meth:`fit`: for each QoI a variable with dims
        ``(*sweep, "bound")``; ``runs`` (model runs per sweep point),
        ``surrogate_error_relative`` and ``flag`` with dims ``("qoi", *sweep)``
        and ``<qoi>_surrogate_error`` (absolute, in the QoI's units).
    """

    def __init__(self, method: str = "chebyshev", *, order: int = 6, scan_points: int | None = None,
                 check_points: int = 4, tolerance: float = 0.02, fallback: str = "scan", n_starts: int = 2,
                 screen_points: int | None = None, max_iterations: int = 40,
                 finite_difference_step: float = 1e-6, regime_variables: Sequence[str] = (),
                 qoi: Sequence[str] | None = None, seed: SeedLike | None = None) -> None:
        if method not in METHODS:
            raise ParameterSpaceError(f"method: unknown interval method {method!r}; expected one of "
                                      f"{', '.join(METHODS)}")
        if fallback not in FALLBACKS:
            raise ParameterSpaceError(f"fallback: expected one of {', '.join(FALLBACKS)}; got {fallback!r}")
        self.method = method
        self.order = check_count(order, "order", 1, 64)
        self.scan_points = None if scan_points is None else check_count(scan_points, "scan_points", 2)
        self.check_points = check_count(check_points, "check_points", 0)
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0 < tolerance < 1:
            raise ParameterSpaceError(f"tolerance: expected a fraction of the band width in (0, 1); "
                                      f"got {tolerance!r}")
        self.tolerance = float(tolerance)
        self.fallback = fallback
        self.n_starts = check_count(n_starts, "n_starts", 1)
        self.screen_points = None if screen_points is None else check_count(screen_points, "screen_points", 1)
        self.max_iterations = check_count(max_iterations, "max_iterations", 1)
        if (isinstance(finite_difference_step, bool) or not isinstance(finite_difference_step, (int, float))
                or not 0 < finite_difference_step < 0.1):
            raise ParameterSpaceError(f"finite_difference_step: expected a number in (0, 0.1); "
                                      f"got {finite_difference_step!r}")
        self.finite_difference_step = float(finite_difference_step)
        if isinstance(regime_variables, str):
            regime_variables = [regime_variables]
        self.regime_variables = list(regime_variables)
        self.qoi = None if qoi is None else ([qoi] if isinstance(qoi, str) else list(qoi))
        overlap = set(self.regime_variables) & set(self.qoi or ())
        if overlap:
            raise ParameterSpaceError(f"regime_variables: {', '.join(sorted(overlap))} also listed as qoi")
        needs_seed = method == "optimize" or (fallback == "optimize" and method in ("vertex", "chebyshev"))
        if seed is None and needs_seed:
            raise ParameterSpaceError("seed: the optimize method draws seeded starting points; pass seed=")
        self.seed_sequence = None if seed is None else as_seed_sequence(seed)

    # -- public ---------------------------------------------------------------------

    def fit(self, evaluate: ModelFunction, space: ParameterSpace,
            sweep: Mapping[str, Any] | None = None) -> "IntervalAnalysis":
        """Bound every QoI over the interval parameters of ``space`` at every sweep point.

        Parameters
        ----------
        evaluate : callable
            The model function.
        space : ParameterSpace
            At least one interval parameter; fixed parameters are passed on;
            random parameters are refused (use :func:`pbox`).
        sweep : mapping of str to 1-D values, optional
            Deterministic variables (e.g. ``{"pinion_speed": speeds}``).

        Returns
        -------
        IntervalAnalysis
            ``self`` with ``result_`` set.
        """
        intervals = self._check_space(space)
        if space.random_names:
            raise ParameterSpaceError(f"space: {', '.join(space.random_names)} have distributions; interval "
                                      f"analysis bounds over intervals only: fix them, or use pbox() for "
                                      f"bounds on statistics")
        sweep_spec = make_sweep(sweep, space)
        responses = _ModelResponses(evaluate, space, sweep_spec, self.qoi, self.regime_variables)
        bounds = self._bound(responses, sweep_spec, len(intervals))
        names = responses.names
        coords = self._coords(sweep_spec, names)
        data_vars = {}
        shape = sweep_spec.shape
        for r, name in enumerate(names):
            band = np.stack([bounds.lower[:, r], bounds.upper[:, r]], axis=-1).reshape(*shape, 2)
            data_vars[name] = ((*sweep_spec.names, "bound"), band,
                               {"units": responses.units[name],
                                "long_name": f"bounds of {responses.long_names[name]} over the interval parameters"})
            data_vars[f"{name}_surrogate_error"] = (sweep_spec.names, bounds.error[:, r].reshape(shape),
                                                    {"units": responses.units[name],
                                                     "long_name": f"estimated error of the bounds of {name} "
                                                                  f"(NaN: no estimate)"})
        data_vars.update(self._diagnostics(bounds, responses, sweep_spec, names,
                                           [[r] for r in range(len(names))]))
        self.result_ = xr.Dataset(data_vars, coords=coords,
                                  attrs=self._attrs(space, responses, "interval_analysis"))
        return self

    # -- internals ------------------------------------------------------------------

    def _check_space(self, space: ParameterSpace) -> list[str]:
        if not isinstance(space, ParameterSpace):
            raise ParameterSpaceError(f"space: expected a ParameterSpace; got {type(space).__name__}")
        intervals = list(space.interval_names)
        if not intervals:
            raise ParameterSpaceError("space: interval analysis needs at least one Interval parameter; "
                                      f"the space has {', '.join(space.names)}")
        if self.method == "vertex" and len(intervals) > 16:
            raise ParameterSpaceError(f"method: vertex with {len(intervals)} intervals needs "
                                      f"2^{len(intervals)} runs; expected at most 16 intervals")
        return intervals

    def _scan_points(self, dimensions: int) -> int:
        return self.scan_points or _SCAN_POINTS.get(dimensions, 5)

    def _run_method(self, method: str, responses: _ModelResponses, sweep_index: np.ndarray,
                    dimensions: int) -> _Bounds:
        regime = [] if isinstance(responses, _PboxResponses) else self.regime_variables
        if method == "scan":
            return _scan(responses, sweep_index, dimensions, self._scan_points(dimensions), self.tolerance, regime)
        if method == "vertex":
            return _vertex(responses, sweep_index, dimensions, self.check_points, regime)
        if method == "chebyshev":
            return _chebyshev(responses, sweep_index, dimensions, self.order, self.check_points, self.tolerance,
                              regime)
        screen = self.screen_points or 20 * dimensions
        return _optimize(responses, sweep_index, dimensions,
                         child_seed(self.seed_sequence, 1 if method == self.method else 2),
                         self.n_starts, screen, self.max_iterations, self.finite_difference_step, regime)

    def _bound(self, responses: _ModelResponses, sweep: Sweep, dimensions: int) -> _Bounds:
        everything = np.arange(sweep.size)
        nodes = {"scan": self._scan_points(dimensions) ** dimensions, "vertex": 2 ** dimensions,
                 "chebyshev": (self.order + 1) ** dimensions}
        if nodes.get(self.method, 0) > 1_000_000:
            raise ParameterSpaceError(f"{'order' if self.method == 'chebyshev' else 'scan_points'}: "
                                      f"{nodes[self.method]} nodes per sweep point in {dimensions} dimensions; "
                                      f"expected at most 1e6")
        bounds = self._run_method(self.method, responses, everything, dimensions)
        self.fallback_runs_ = 0
        if self.method in ("scan", "optimize") or self.fallback == "none":
            return bounds
        redo = np.nonzero((bounds.flag & _NEEDS_FALLBACK).any(axis=1))[0]
        if redo.size == 0:
            return bounds
        runs_before = responses.runs.sum()
        again = self._run_method(self.fallback, responses, bounds.sweep_index[redo], dimensions)
        self.fallback_runs_ = int(responses.runs.sum() - runs_before)
        for position, row in enumerate(redo):
            bounds.observed_lower[row] = np.fmin(bounds.observed_lower[row], again.observed_lower[position])
            bounds.observed_upper[row] = np.fmax(bounds.observed_upper[row], again.observed_upper[position])
            bounds.lower[row] = np.fmin(again.lower[position], bounds.observed_lower[row])
            bounds.upper[row] = np.fmax(again.upper[position], bounds.observed_upper[row])
            bounds.error[row] = again.error[position]
            for r in range(bounds.flag.shape[1]):
                bounds.flag[row, r] |= again.flag[position, r]
                for text in again.reasons.get((int(bounds.sweep_index[row]), r), []):
                    if text not in bounds.reasons.get((int(bounds.sweep_index[row]), r), []):
                        bounds.add_reason(row, r, 0, f"{self.fallback} fallback: {text}")
                bounds.add_reason(row, r, FLAG_FALLBACK, f"bounds from the {self.fallback} fallback")
        return bounds

    def _coords(self, sweep: Sweep, names: Sequence[str]) -> dict[str, Any]:
        coords: dict[str, Any] = dict(sweep.coords())
        coords["bound"] = ("bound", ["lower", "upper"])
        coords["qoi"] = ("qoi", list(names))
        return coords

    def _diagnostics(self, bounds: _Bounds, responses: _ModelResponses, sweep: Sweep, qoi_names: Sequence[str],
                     groups: Sequence[Sequence[int]]) -> dict[str, Any]:
        shape = sweep.shape
        relative = _relative(bounds.error, bounds.lower, bounds.upper)
        flags = np.zeros((len(qoi_names), bounds.flag.shape[0]), dtype=np.int8)
        errors = np.full((len(qoi_names), bounds.flag.shape[0]), np.nan)
        reasons = []
        for q, group in enumerate(groups):
            for r in group:
                flags[q] |= bounds.flag[:, r].astype(np.int8)
                errors[q] = np.fmax(errors[q], relative[:, r])
            for row in range(bounds.flag.shape[0]):
                texts = [t for r in group for t in bounds.reasons.get((int(bounds.sweep_index[row]), r), [])]
                if texts:
                    where = f"at {sweep.label(int(bounds.sweep_index[row]))}: " if sweep.names else ""
                    reasons.append(where + "; ".join(dict.fromkeys(texts)))
        return {
            "runs": (sweep.names, responses.runs.reshape(shape),
                     {"units": "1", "long_name": "model runs spent per sweep point"}),
            "surrogate_error_relative": (("qoi", *sweep.names), errors.reshape(len(qoi_names), *shape),
                                         {"units": "1", "long_name": "estimated error of the bounds relative to "
                                                                     "the band width (NaN: no estimate)"}),
            "flag": (("qoi", *sweep.names), flags.reshape(len(qoi_names), *shape),
                     {"units": "1", "long_name": "quality flags of the bounds (bit mask, 0: none)",
                      "flag_masks": np.array([FLAG_VERTEX_EXCEEDED, FLAG_SURROGATE_ERROR, FLAG_NONSMOOTH,
                                              FLAG_NONFINITE, FLAG_FALLBACK], dtype=np.int8),
                      "flag_meanings": FLAG_MEANINGS,
                      "flag_reasons": json.dumps(reasons)}),
        }

    def _attrs(self, space: ParameterSpace, responses: _ModelResponses, kind: str) -> dict[str, Any]:
        attrs: dict[str, Any] = {
            "analysis": kind,
            "method": self.method,
            "interval_parameters": json.dumps({name: [space[name].lower, space[name].upper, space[name].units]
                                               for name in space.interval_names}),
            "parameter_space": space.to_json(),
            "tolerance": self.tolerance,
            "fallback": self.fallback if self.method in ("vertex", "chebyshev") else "none",
            "fallback_runs": int(getattr(self, "fallback_runs_", 0)),
            "runs": int(responses.runs.sum()),
            "batch_calls": int(responses.batch_calls),
            "units": json.dumps(responses.units),
            **seed_attributes(self.seed_sequence),
        }
        if self.method == "chebyshev":
            attrs.update(order=self.order, check_points=self.check_points,
                         reference="Wu, Luo, Zhang, Zhang, Chen (2013) Int J Numer Meth Eng: Chebyshev "
                                   "inclusion function at Gauss-Chebyshev nodes, bounds by dense scan of the series")
        if self.method == "vertex":
            attrs.update(check_points=self.check_points + 1)
        if self.method == "scan" or self.fallback == "scan":
            attrs.update(scan_points=self._scan_points(len(space.interval_names)))
        if self.method == "optimize" or self.fallback == "optimize":
            attrs.update(n_starts=self.n_starts, max_iterations=self.max_iterations,
                         finite_difference_step=self.finite_difference_step)
        if self.regime_variables:
            attrs.update(regime_variables=json.dumps(self.regime_variables))
        return attrs


def response_envelope(evaluate: ModelFunction, space: ParameterSpace, sweep: Mapping[str, Any], *,
                      method: str = "chebyshev", order: int = 6, scan_points: int | None = None,
                      check_points: int = 4, tolerance: float = 0.02, fallback: str = "scan",
                      qoi: Sequence[str] | None = None, seed: SeedLike | None = None) -> xr.Dataset:
    """Band of each QoI over the interval parameters along a sweep axis.

    A shorthand for ``IntervalAnalysis(method, ...).fit(evaluate, space,
    sweep).result_``; see :class:`IntervalAnalysis` for the parameters.
    """
    if not sweep:
        raise ParameterSpaceError("sweep: a response envelope needs a sweep, e.g. {'pinion_speed': speeds}")
    analysis = IntervalAnalysis(method, order=order, scan_points=scan_points, check_points=check_points,
                                tolerance=tolerance, fallback=fallback, qoi=qoi, seed=seed)
    return analysis.fit(evaluate, space, sweep).result_


def pbox(evaluate: ModelFunction, space: ParameterSpace, *, n_samples: int, seed: SeedLike,
         sweep: Mapping[str, Any] | None = None, quantiles: Sequence[float] = (0.05, 0.5, 0.95),
         sampling: str = "latin_hypercube", qoi: Sequence[str] | None = None,
         analysis: IntervalAnalysis | None = None) -> xr.Dataset:
    """Bounds on statistics over interval parameters: a probability box.

    For every interval node the model runs the same ``n_samples`` random
    samples of the random parameters (common random numbers); the mean,
    standard deviation and quantiles of each QoI over them are then bounded
    over the interval box with ``analysis`` (default: ``scan``). The bounds of
    the quantiles at many levels are the bounds of the quantile function,
    i.e. the p-box of the QoI.

    Parameters
    ----------
    evaluate : callable
        The model function.
    space : ParameterSpace
        At least one interval and one random parameter.
    n_samples : int
        Random samples per interval node.
    seed : SeedSequence or int
        Source of the random samples.
    sweep : mapping of str to 1-D values, optional
        Deterministic variables.
    quantiles : sequence of float
        Quantile levels.
    sampling : str
        Sampling of the random parameters (see ``SAMPLING_METHODS``, not grid).
    qoi : sequence of str, optional
        QoIs (default: every per-sample output).
    analysis : IntervalAnalysis, optional
        How to bound the statistics over the intervals (method, order, ...).

    Returns
    -------
    xarray.Dataset
        For each QoI ``q``: ``q`` with dims ``(*sweep, "statistic", "bound")``
        (statistic: mean, std) and ``q_quantile`` with dims
        ``(*sweep, "quantile", "bound")``; plus ``runs``, ``flag`` and
        ``surrogate_error_relative`` as for :class:`IntervalAnalysis`
        (the largest over a QoI's statistics).
    """
    analysis = analysis if analysis is not None else IntervalAnalysis("scan")
    if not isinstance(analysis, IntervalAnalysis):
        raise ParameterSpaceError(f"analysis: expected an IntervalAnalysis; got {type(analysis).__name__}")
    intervals = analysis._check_space(space)
    if not space.random_names:
        raise ParameterSpaceError("space: a p-box needs at least one random (Distribution) parameter; "
                                  "use IntervalAnalysis for intervals alone")
    if analysis.regime_variables:
        raise ParameterSpaceError("analysis: regime_variables are not used by pbox(); leave them out")
    n_samples = check_count(n_samples, "n_samples", 2)
    if sampling not in SAMPLING_METHODS or sampling == "grid":
        raise ParameterSpaceError(f"sampling: expected one of monte_carlo, latin_hypercube, sobol, halton; "
                                  f"got {sampling!r}")
    levels = check_quantiles(quantiles)
    seed_sequence = as_seed_sequence(seed)
    sweep_spec = make_sweep(sweep, space)
    responses = _PboxResponses(evaluate, space, sweep_spec, None if qoi is None else list(qoi), n_samples,
                               sampling, levels, child_seed(seed_sequence, 0))
    if analysis.seed_sequence is None:
        analysis = copy.copy(analysis)  # leave the caller's object as it was
        analysis.seed_sequence = child_seed(seed_sequence, 1)
    bounds = analysis._bound(responses, sweep_spec, len(intervals))
    qoi_names = responses.qoi_names
    per_qoi = 2 + levels.size
    shape = sweep_spec.shape
    coords = analysis._coords(sweep_spec, qoi_names)
    coords.update(statistic=("statistic", ["mean", "std"]), quantile=("quantile", levels, {"units": "1"}))
    data_vars = {}
    for q, name in enumerate(qoi_names):
        columns = slice(q * per_qoi, (q + 1) * per_qoi)
        lower, upper = bounds.lower[:, columns], bounds.upper[:, columns]
        band = np.stack([lower, upper], axis=-1).reshape(*shape, per_qoi, 2)
        units = responses.units[name]
        data_vars[name] = ((*sweep_spec.names, "statistic", "bound"), band[..., :2, :],
                           {"units": units, "long_name": f"bounds over the interval parameters of the mean and "
                                                         f"standard deviation of {name} over the random ones"})
        data_vars[f"{name}_quantile"] = ((*sweep_spec.names, "quantile", "bound"), band[..., 2:, :],
                                         {"units": units, "long_name": f"bounds of the quantiles of {name} "
                                                                       f"(p-box)"})
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            error = np.nanmax(np.where(np.isnan(bounds.error[:, columns]), -np.inf, bounds.error[:, columns]),
                              axis=1)
        data_vars[f"{name}_surrogate_error"] = (sweep_spec.names, np.where(np.isinf(error) & (error < 0), np.nan,
                                                                           error).reshape(shape),
                                                {"units": units, "long_name": f"largest estimated error of the "
                                                                              f"bounds of the statistics of {name}"})
    groups = [list(range(q * per_qoi, (q + 1) * per_qoi)) for q in range(len(qoi_names))]
    readable = {}
    for q, name in enumerate(qoi_names):
        labels = ["mean", "std"] + [f"quantile {level:g}" for level in levels]
        for k, label in enumerate(labels):
            readable[q * per_qoi + k] = f"{name} {label}"
    for key, texts in bounds.reasons.items():
        bounds.reasons[key] = [text.replace(responses.names[key[1]], readable[key[1]], 1) for text in texts]
    data_vars.update(analysis._diagnostics(bounds, responses, sweep_spec, qoi_names, groups))
    attrs = analysis._attrs(space, responses, "pbox")
    attrs.update(n_samples=n_samples, sampling=sampling, random_parameters=json.dumps({name: space[name].describe() for name in space.random_names}),
                 random_numbers="common random numbers: the same random samples at every interval node",
                 **{f"pbox_{k}": v for k, v in seed_attributes(seed_sequence).items()})
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)
