"""Bounds of the responses over the interval box, their quality flags and the checks behind them.

:class:`Bounds` holds, per analysed sweep point and response, the band, the
model values actually seen, the estimated error and the flag bit mask with
its reasons. The checks shared by every interval method live here too: the
error relative to the band width, jumps between neighbouring nodes, regime
variables changing over the box and non-finite model values.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

#: Flag bits of the ``flag`` variable.
FLAG_VERTEX_EXCEEDED = 1
FLAG_SURROGATE_ERROR = 2
FLAG_NONSMOOTH = 4
FLAG_NONFINITE = 8
FLAG_FALLBACK = 16
FLAG_MEANINGS = (
    "vertex_bounds_exceeded_at_interior_check_points surrogate_error_large_relative_to_band "
    "nonsmooth_response nonfinite_model_output bounds_from_fallback_method"
)

# a step between neighbouring nodes is a jump when it is this many times the
# neighbouring steps (per unit length) and at least this fraction of the band
_JUMP_RATIO = 5.0
_JUMP_FRACTION = 0.2


@dataclass
class Bounds:
    """Bounds of every response at the analysed sweep points."""

    sweep_index: np.ndarray  # (S,) flat sweep point numbers
    lower: np.ndarray  # (S, R)
    upper: np.ndarray
    observed_lower: np.ndarray  # extremes of the model values actually seen
    observed_upper: np.ndarray
    error: np.ndarray  # estimated absolute error of the bounds (NaN: no estimate)
    flag: np.ndarray  # int bit mask
    reasons: dict[tuple[int, int], list[str]] = field(default_factory=dict)

    @classmethod
    def empty(cls, sweep_index: np.ndarray, responses: int) -> Bounds:
        shape = (len(sweep_index), responses)
        return cls(
            sweep_index,
            np.full(shape, np.nan),
            np.full(shape, np.nan),
            np.full(shape, np.inf),
            np.full(shape, -np.inf),
            np.full(shape, np.nan),
            np.zeros(shape, dtype=np.int64),
        )

    def add_reason(self, row: int, response: int, bit: int, text: str) -> None:
        self.flag[row, response] |= bit
        self.reasons.setdefault((int(self.sweep_index[row]), response), []).append(text)

    def observe(self, values: np.ndarray) -> None:
        """Widen the observed extremes with model values of shape (S, k, R)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            self.observed_lower = np.fmin(self.observed_lower, np.nanmin(values, axis=1))
            self.observed_upper = np.fmax(self.observed_upper, np.nanmax(values, axis=1))


def tensor_grid(axes: Sequence[np.ndarray]) -> np.ndarray:
    """Points (n, d) of the tensor grid of the 1-D ``axes``, last axis fastest."""
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([axis.ravel() for axis in mesh], axis=1)


def interior_check_points(count: int, dimensions: int) -> np.ndarray:
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


def relative_error(error: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """``error`` as a fraction of the band width (0 or inf for a constant response, NaN: no estimate)."""
    width = upper - lower
    scale = np.maximum(np.fmax(np.abs(lower), np.abs(upper)), 1e-300)
    with np.errstate(divide="ignore", invalid="ignore"):
        relative = error / width
        # a constant response: the error is zero up to rounding, or it is not
        constant = ~(width > 1e-12 * scale)
        relative = np.where(constant, np.where(error <= 1e-12 * scale, 0.0, np.inf), relative)
    return np.where(np.isnan(error), np.nan, relative)


def find_jumps(grid: np.ndarray, coordinates: np.ndarray, width: np.ndarray) -> np.ndarray:
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


def _regime_changes(regime: np.ndarray) -> list[list[int]]:
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


def flag_common_problems(
    bounds: Bounds, values: np.ndarray, regime: np.ndarray, regime_names: Sequence[str], names: Sequence[str]
) -> None:
    """Flag non-finite model values and regime variables that change over the interval box."""
    nonfinite = ~np.isfinite(values).all(axis=1)
    for s, r in zip(*np.nonzero(nonfinite)):
        count = int((~np.isfinite(values[s, :, r])).sum())
        bounds.add_reason(s, r, FLAG_NONFINITE, f"{names[r]}: {count} of {values.shape[1]} model values non-finite")
    for s, changed in enumerate(_regime_changes(regime)):
        if changed:
            which = ", ".join(regime_names[g] for g in changed)
            for r in range(values.shape[2]):
                bounds.add_reason(
                    s,
                    r,
                    FLAG_NONSMOOTH,
                    f"regime variable(s) {which} change over the interval box: response not smooth",
                )
