"""Bounds of QoIs over interval parameters and over the coexisting steady responses at each point.

Where a gear holds two responses at one operating point, the QoI is no function of the inputs: its
interval bounds are the largest and smallest value over the interval box *and* over the
attractors found there. The model (a multi-start model, :class:`uqgear.study.coexistence.
MultiStartModel`) returns per sample ``<qoi>_max`` / ``<qoi>_min`` over its attractors with the
start that reached each (``<qoi>_max_start``, ``<qoi>_min_start``) and ``attractor_count``.
:func:`scan_over_attractors` evaluates it on a tensor grid over the interval parameters at every
sweep point, in one batch call, and keeps for each bound the grid node and the start that gave it.
A scan, not a surrogate: a response that jumps between attractors is exactly the non-smooth case
a polynomial inclusion would bound falsely tight.
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from .parameter_space import ParameterSpace
from .parameters import Fixed, Interval
from .sweeps import ModelFunction, Sweep, batch_samples, make_sweep


def scan_over_attractors(
    evaluate: ModelFunction, space: ParameterSpace, sweep: Mapping[str, Any] | None, qois: Sequence[str], points: int
) -> xr.Dataset:
    """Bound each QoI over the interval parameters of ``space`` and the attractors, at every sweep point.

    Parameters
    ----------
    evaluate : callable
        A multi-start model (module docstring).
    space : ParameterSpace
        Interval and fixed parameters only.
    sweep : mapping
        Deterministic sweep (e.g. ``{"pinion_speed": speeds}``).
    qois : sequence of str
    points : int
        Grid points per interval parameter (both ends included).

    Returns
    -------
    xarray.Dataset
        ``<qoi>`` on (sweep dims, ``bound``) as :class:`~uqgear.uq.interval.IntervalAnalysis` gives it;
        ``<qoi>_start`` (the start whose attractor gave each bound), ``<qoi>_attractors`` (how many
        attractors that point held) and ``<qoi>_at_<parameter>`` (where in the box); ``attractor_count``
        (the most attractors at any node) and ``coexisting`` (any node with more than one).
    """
    if space.random_names:
        raise ParameterSpaceError(
            f"space: {', '.join(space.random_names)} have distributions; bounds over "
            "attractors take interval parameters only"
        )
    names = list(space.interval_names)
    if not names:
        raise ParameterSpaceError("space: expected at least one interval parameter")
    sweep_spec = make_sweep(sweep, space)
    intervals = {name: cast(Interval, space[name]) for name in names}  # interval_names: each an Interval
    axes = [np.linspace(intervals[name].lower, intervals[name].upper, int(points)) for name in names]
    nodes = np.array(list(itertools.product(*axes)), dtype=float).reshape(-1, len(names))
    n_nodes, n_points = nodes.shape[0], sweep_spec.size
    result = evaluate(_grid_samples(space, names, nodes, sweep_spec))
    shape = (*sweep_spec.shape, 2)
    dims = (*sweep_spec.names, "bound")
    data: dict[str, Any] = {}
    for qoi in qois:
        picked = _pick_bounds(result, qoi, nodes, n_points)
        attrs = dict(result[f"{qoi}_max"].attrs)
        data[qoi] = (
            dims,
            picked.band.reshape(shape),
            {
                "units": attrs.get("units", ""),
                "long_name": f"bounds of {qoi} over the interval parameters and the coexisting responses",
            },
        )
        data[f"{qoi}_start"] = (
            dims,
            picked.starts.astype(str).reshape(shape),
            {"long_name": f"start whose attractor gives each bound of {qoi}"},
        )
        data[f"{qoi}_attractors"] = (
            dims,
            picked.held.reshape(shape),
            {"units": "1", "long_name": "attractors at the point giving each bound"},
        )
        for column, name in enumerate(names):
            data[f"{qoi}_at_{name}"] = (
                dims,
                picked.where[:, :, column].reshape(shape),
                {"units": space.units(name), "long_name": f"{name} giving each bound"},
            )
    data.update(_coexistence_variables(result, sweep_spec, n_points, n_nodes))
    coords: dict[str, Any] = {**sweep_spec.coords(), "bound": ("bound", ["lower", "upper"])}
    return xr.Dataset(
        data,
        coords=coords,
        attrs={
            "analysis": "scan_over_attractors",
            "interval_parameters": json.dumps(
                {name: [bound.lower, bound.upper, bound.units] for name, bound in intervals.items()}
            ),
            "grid_points": int(points),
        },
    )


def _grid_samples(space: ParameterSpace, names: Sequence[str], nodes: np.ndarray, sweep_spec: Sweep) -> xr.Dataset:
    """Every grid node at every sweep point, as one batch (nodes fastest), with the fixed parameters."""
    # random parameters are refused by the caller: the others are Fixed
    fixed = {name: float(cast(Fixed, space[name]).value) for name in space.names if name not in names}
    n_nodes, n_points = nodes.shape[0], sweep_spec.size
    flat: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    for column, name in enumerate(names):
        flat[name] = np.tile(nodes[:, column], n_points)
        units[name] = space.units(name)
    for name, value in fixed.items():
        flat[name] = np.full(n_nodes * n_points, value)
        units[name] = space.units(name)
    for name, values in sweep_spec.point_values().items():
        flat[name] = np.repeat(values, n_nodes)
        units[name] = sweep_spec.attrs[sweep_spec.names.index(name)].get("units", "")
    return batch_samples(flat, units)


@dataclass(frozen=True)
class _PickedBounds:
    """Lower and upper bound of one QoI per sweep point (rows) and bound (columns), with where each lies.

    Attributes
    ----------
    band : numpy.ndarray
        The bounds, shape (points, 2).
    starts : numpy.ndarray
        The start whose attractor gave each bound (object array of str).
    held : numpy.ndarray
        How many attractors the grid node giving each bound held.
    where : numpy.ndarray
        The grid node giving each bound, shape (points, 2, parameters).
    """

    band: np.ndarray
    starts: np.ndarray
    held: np.ndarray
    where: np.ndarray


def _pick_bounds(result: xr.Dataset, qoi: str, nodes: np.ndarray, n_points: int) -> _PickedBounds:
    """The smallest minimum and largest maximum of ``qoi`` over the grid nodes at each sweep point."""
    n_nodes = nodes.shape[0]
    band = np.empty((n_points, 2))
    starts = np.empty((n_points, 2), dtype=object)
    where = np.empty((n_points, 2, nodes.shape[1]))
    held = np.empty((n_points, 2), dtype=np.int64)
    for column, (bound, pick) in enumerate((("min", np.nanargmin), ("max", np.nanargmax))):
        values = np.asarray(result[f"{qoi}_{bound}"].values, dtype=float).reshape(n_points, n_nodes)
        labels = np.asarray(result[f"{qoi}_{bound}_start"].values).astype(str).reshape(n_points, n_nodes)
        counts = np.asarray(result["attractor_count"].values).reshape(n_points, n_nodes)
        for row in range(n_points):
            node = int(pick(values[row])) if np.isfinite(values[row]).any() else 0
            band[row, column] = values[row, node]
            starts[row, column] = labels[row, node]
            held[row, column] = counts[row, node]
            where[row, column] = nodes[node]
    return _PickedBounds(band, starts, held, where)


def _coexistence_variables(result: xr.Dataset, sweep_spec: Sweep, n_points: int, n_nodes: int) -> dict[str, Any]:
    """Per sweep point: the most attractors at any grid node, whether responses coexist, the grid's runs."""
    counts = np.asarray(result["attractor_count"].values).reshape(n_points, n_nodes)
    return {
        "attractor_count": (
            sweep_spec.names,
            counts.max(axis=1).reshape(sweep_spec.shape),
            {"units": "1", "long_name": "most attractors at any point of the box"},
        ),
        "coexisting": (
            sweep_spec.names,
            (counts.max(axis=1) > 1).reshape(sweep_spec.shape),
            {"long_name": "responses coexist somewhere in the box"},
        ),
        "runs": (
            sweep_spec.names,
            np.full(sweep_spec.shape, n_nodes),
            {"units": "1", "long_name": "grid points per sweep point (each run from several starts)"},
        ),
    }


__all__ = ["scan_over_attractors"]
