"""Branches of periodic orbits and their bifurcations as one xarray Dataset (storable in netCDF).

Layout (dims ``branch``, ``point``, ``state``, ``multiplier``, ``bifurcation``):

* per branch point, padded with NaN beyond a branch's ``branch_points``: ``parameter``,
  ``orbit_state`` (the state at mesh phase 0), ``multiplier_real`` / ``multiplier_imag`` (Floquet
  multipliers, largest modulus first; netCDF has no complex type), ``spectral_radius``,
  ``stable`` (1 stable, 0 unstable, -1 no point), ``arclength`` and the orbit QoIs
  (``peak_mesh_force``, ``fraction_separation``, ``x_min``, ...);
* per branch: ``branch_period`` (n of the period-n orbits), ``branch_parent`` and
  ``branch_origin`` (the branch and bifurcation it was switched from, -1 for the first),
  ``branch_points`` and ``branch_end`` (why it stops);
* the bifurcation table: ``bifurcation_type``, ``bifurcation_branch``, ``bifurcation_parameter``
  with ``bifurcation_tolerance`` (the location is within it), ``bifurcation_side`` (+1: the new
  condition holds above the point), stability before and after, ``bifurcation_sweep`` (for a
  fold of a stable stretch, the sweep direction that jumps there: ``up`` at a parameter maximum,
  ``down`` at a minimum), the orbit's state, multipliers and QoIs there.

:func:`bifurcation_table` reads the table back as a pandas DataFrame.
"""

from __future__ import annotations

import json
import math
from collections.abc import Hashable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import pandas as pd
import xarray as xr

from ..physics.design import Design
from ..physics.integration import QOI_INFO, STATE_NAMES
from .bifurcations import Bifurcation, BranchPoint
from .floquet import FOLD


@dataclass
class Branch:
    """A followed branch: its points in order, its period and where it came from.

    Attributes
    ----------
    period : int
        n of its period-n orbits.
    points : list of BranchPoint
    parent, origin : int
        The branch and the bifurcation (indices) it was switched from; -1 for the first branch.
    end : str
        Why it ends.
    merged_at : float
        Where a doubled branch merges back into its parent (NaN otherwise).
    """

    period: int
    points: list[BranchPoint]
    parent: int = -1
    origin: int = -1
    end: str = ""
    merged_at: float = math.nan


#: Orbit QoIs stored per branch point (see :func:`uqgear.dynamics.shooting.orbit_qois`).
BRANCH_QOIS: dict[str, tuple[str, str]] = {
    **{
        name: QOI_INFO[name]
        for name in (
            "peak_mesh_force",
            "dynamic_load_factor",
            "load_factor_rated",
            "dte_rms",
            "dte_peak_to_peak",
            "fraction_separation",
            "fraction_back_contact",
        )
    },
    "x_min": ("m", "smallest DTE over the orbit (on the step interpolants)"),
    "x_max": ("m", "largest DTE over the orbit (grid points)"),
    "separation_margin": ("m", "x_min - b: negative where the teeth separate"),
    "back_side_margin": ("m", "x_min + b: negative where back-side contact (impact) occurs"),
}
#: Units of the parameters a branch can be followed in (design keys not listed are given as '1').
PARAMETER_UNITS = {
    "pinion_speed": "rpm",
    "drive_torque": "N m",
    "adhesion_torque": "N m",
    "mesh_stiffness_scale": "1",
    "k1": "N m-1",
    "k2": "N m-1",
    "backlash": "m",
    "ste_amplitude": "m",
    "m1": "kg",
    "m2": "kg",
    "I1": "kg m2",
    "I2": "kg m2",
}


def _padded(
    branches: Sequence[Branch], width: int, read: Any, shape: tuple[int, ...] = (), fill: float = np.nan
) -> np.ndarray:
    out = np.full((len(branches), width, *shape), fill)
    for i, branch in enumerate(branches):
        for j, point in enumerate(branch.points):
            out[i, j] = read(point)
    return out


def _sweep(bifurcation: Bifurcation) -> str:
    """For a fold ending a stable stretch: the sweep direction that jumps there."""
    if bifurcation.kind != FOLD or not (bifurcation.stable_before or bifurcation.stable_after):
        return ""
    return "up" if bifurcation.side > 0 else "down"


def branches_dataset(
    branches: Sequence[Branch],
    bifurcations: Sequence[Bifurcation],
    *,
    parameter: str,
    design: Design,
    fixed: Mapping[str, float],
    tolerance: float,
    attrs: Mapping[str, Any] | None = None,
) -> xr.Dataset:
    """The Dataset of followed branches and their bifurcation table (layout in the module docstring)."""
    width = max((len(branch.points) for branch in branches), default=0)
    units = PARAMETER_UNITS.get(parameter, "1")
    data = _point_variables(branches, width, parameter, units)
    phases = max((branch.period for branch in branches), default=1)  # Poincare points of the longest orbit
    data.update(_branch_variables(branches))
    data.update(_table(branches, bifurcations, units))
    coords = {
        "branch": ("branch", np.arange(len(branches))),
        "point": ("point", np.arange(width)),
        "state": ("state", list(STATE_NAMES)),
        "multiplier": ("multiplier", np.arange(6)),
        "bifurcation": ("bifurcation", np.arange(len(bifurcations))),
        "phase": ("phase", np.arange(phases)),
    }
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(
        {
            "parameter": parameter,
            "parameter_units": units,
            "location_tolerance": float(tolerance),
            "fixed_inputs": json.dumps({k: float(v) for k, v in fixed.items()}),
            "design_name": design.name,
            "half_backlash": float(design.half_backlash),
            **dict(attrs or {}),
        }
    )
    return ds


def _point_variables(branches: Sequence[Branch], width: int, parameter: str, units: str) -> dict[str, Any]:
    """Per branch point, padded beyond a branch's points: parameter, orbit, multipliers, stability, QoIs."""
    data: dict[str, Any] = {
        "parameter": (
            ("branch", "point"),
            _padded(branches, width, lambda p: p.parameter),
            {"units": units, "long_name": parameter.replace("_", " ")},
        ),
        "orbit_state": (
            ("branch", "point", "state"),
            _padded(branches, width, lambda p: p.state, (6,)),
            {"units": "m, m, m, m s-1, m s-1, m s-1", "long_name": "orbit state at mesh phase 0"},
        ),
        "multiplier_real": (
            ("branch", "point", "multiplier"),
            _padded(branches, width, lambda p: p.multipliers.real, (6,)),
            {"units": "1", "long_name": "Floquet multiplier, real part"},
        ),
        "multiplier_imag": (
            ("branch", "point", "multiplier"),
            _padded(branches, width, lambda p: p.multipliers.imag, (6,)),
            {"units": "1", "long_name": "Floquet multiplier, imaginary part"},
        ),
        "spectral_radius": (
            ("branch", "point"),
            _padded(branches, width, lambda p: np.abs(p.multipliers).max()),
            {"units": "1", "long_name": "largest Floquet multiplier modulus (stable below 1)"},
        ),
        "stable": (
            ("branch", "point"),
            _padded(branches, width, lambda p: int(p.stable), fill=-1).astype(np.int8),
            {"long_name": "orbit stable: 1 yes, 0 no, -1 no point"},
        ),
        "arclength": (
            ("branch", "point"),
            _padded(branches, width, lambda p: p.arclength),
            {"units": "1", "long_name": "scaled arclength along the branch"},
        ),
    }
    for name, (unit, long_name) in BRANCH_QOIS.items():
        data[name] = (
            ("branch", "point"),
            _padded(branches, width, lambda p, name=name: p.qois[name]),
            {"units": unit, "long_name": long_name},
        )
    phases = max((branch.period for branch in branches), default=1)
    data["orbit_poincare_x"] = (
        ("branch", "point", "phase"),
        _padded(
            branches,
            width,
            lambda p: np.pad(p.poincare_x, (0, phases - p.poincare_x.size), constant_values=np.nan),
            (phases,),
        ),
        {"units": "m", "long_name": "DTE of the orbit at each mesh-period start (its Poincare points)"},
    )
    return data


def _branch_variables(branches: Sequence[Branch]) -> dict[str, Any]:
    """Per branch: its period, where it was switched from, its points and why it ends."""
    return {
        "branch_period": (
            "branch",
            np.array([b.period for b in branches], dtype=np.int64),
            {"units": "1", "long_name": "n of the branch's period-n orbits"},
        ),
        "branch_parent": (
            "branch",
            np.array([b.parent for b in branches], dtype=np.int64),
            {"long_name": "branch switched from (-1: none)"},
        ),
        "branch_origin": (
            "branch",
            np.array([b.origin for b in branches], dtype=np.int64),
            {"long_name": "bifurcation switched at (-1: none)"},
        ),
        "branch_points": (
            "branch",
            np.array([len(b.points) for b in branches], dtype=np.int64),
            {"units": "1", "long_name": "points on the branch"},
        ),
        "branch_end": (
            "branch",
            np.array([b.end for b in branches], dtype=str),
            {"long_name": "why the branch ends"},
        ),
    }


def _table(branches: Sequence[Branch], bifurcations: Sequence[Bifurcation], units: str) -> dict[str, Any]:
    """The bifurcation table: type, branch, location with its tolerance, side, stability, sweep, orbit there."""
    table: dict[str, Any] = {
        "bifurcation_type": (
            "bifurcation",
            np.array([b.kind for b in bifurcations], dtype=str),
            {
                "long_name": "fold, period_doubling, neimark_sacker, branch_point, grazing_separation "
                "or grazing_back_side"
            },
        ),
        "bifurcation_branch": (
            "bifurcation",
            np.array([b.branch for b in bifurcations], dtype=np.int64),
            {"long_name": "branch it lies on"},
        ),
        "bifurcation_period": (
            "bifurcation",
            np.array([branches[b.branch].period for b in bifurcations], dtype=np.int64),
            {"units": "1", "long_name": "branch period n"},
        ),
        "bifurcation_parameter": (
            "bifurcation",
            np.array([b.parameter for b in bifurcations], dtype=float),
            {"units": units, "long_name": "location"},
        ),
        "bifurcation_tolerance": (
            "bifurcation",
            np.array([b.tolerance for b in bifurcations], dtype=float),
            {"units": units, "long_name": "the location is within this"},
        ),
        "bifurcation_side": (
            "bifurcation",
            np.array([b.side for b in bifurcations], dtype=np.int64),
            {
                "long_name": "+1: the new condition (separation, instability, no branch past a fold) "
                "holds above the location, -1 below"
            },
        ),
        "bifurcation_stable_before": (
            "bifurcation",
            np.array([b.stable_before for b in bifurcations], dtype=np.int8),
            {"long_name": "branch stable before it (direction of travel)"},
        ),
        "bifurcation_stable_after": (
            "bifurcation",
            np.array([b.stable_after for b in bifurcations], dtype=np.int8),
            {"long_name": "branch stable after it (direction of travel)"},
        ),
        "bifurcation_arclength": (
            "bifurcation",
            np.array([b.arclength for b in bifurcations], dtype=float),
            {"units": "1", "long_name": "scaled arclength along its branch"},
        ),
        "bifurcation_sweep": (
            "bifurcation",
            np.array([_sweep(b) for b in bifurcations], dtype=str),
            {"long_name": "fold of a stable stretch: the sweep direction that jumps there"},
        ),
    }
    table.update(_orbit_at_bifurcations(bifurcations))
    return table


def _orbit_at_bifurcations(bifurcations: Sequence[Bifurcation]) -> dict[str, Any]:
    """The orbit at each bifurcation: its state, Floquet multipliers and QoIs."""
    n = len(bifurcations)
    multipliers = np.array([b.point.multipliers for b in bifurcations]).reshape(n, 6)
    table: dict[str, Any] = {
        "bifurcation_state": (
            ("bifurcation", "state"),
            np.array([b.point.state for b in bifurcations]).reshape(n, 6),
            {"units": "m, m, m, m s-1, m s-1, m s-1", "long_name": "orbit state there"},
        ),
        "bifurcation_multiplier_real": (
            ("bifurcation", "multiplier"),
            multipliers.real,
            {"units": "1", "long_name": "Floquet multipliers there, real part"},
        ),
        "bifurcation_multiplier_imag": (
            ("bifurcation", "multiplier"),
            multipliers.imag,
            {"units": "1", "long_name": "Floquet multipliers there, imaginary part"},
        ),
    }
    for name in ("peak_mesh_force", "fraction_separation", "fraction_back_contact"):
        unit, long_name = BRANCH_QOIS[name]
        table[f"bifurcation_{name}"] = (
            "bifurcation",
            np.array([b.point.qois[name] for b in bifurcations], dtype=float),
            {"units": unit, "long_name": long_name},
        )
    return table


def _fill(dtype: np.dtype) -> Any:
    if np.issubdtype(dtype, np.floating):
        return np.nan
    if np.issubdtype(dtype, np.integer):
        return -1
    return ""


def stack_cases(datasets: Sequence[xr.Dataset], values: Mapping[str, Sequence[float]]) -> xr.Dataset:
    """Branch Datasets of several cases (e.g. both ends of the T2 interval) along a new dim ``case``.

    ``branch``, ``point`` and ``bifurcation`` are padded to the largest case (NaN, -1 or '');
    ``values`` gives each case's inputs, stored as ``case_<name>``.
    """
    sizes = {dim: max(ds.sizes.get(dim, 0) for ds in datasets) for dim in ("branch", "point", "bifurcation", "phase")}
    padded = []
    for ds in datasets:
        variables = {}
        for name, variable in ds.data_vars.items():
            widths = [(0, sizes[dim] - ds.sizes[dim]) if dim in sizes else (0, 0) for dim in variable.dims]
            array = np.asarray(variable.values)
            if array.dtype.kind in "US":
                array = array.astype(object)
            array = np.pad(array, widths, constant_values=_fill(variable.dtype)) if array.ndim else array
            if variable.dtype.kind in "US":
                array = array.astype(str)
            variables[name] = (variable.dims, array, dict(variable.attrs))
        coords: dict[Hashable, Any] = {dim: (dim, np.arange(size)) for dim, size in sizes.items()}
        coords.update({name: ds[name] for name in ("state", "multiplier") if name in ds.coords})
        padded.append(xr.Dataset(variables, coords=coords))
    stacked = xr.concat(padded, dim="case", combine_attrs="drop_conflicts")
    stacked = stacked.assign_coords(case=np.arange(len(datasets)))
    for name, column in values.items():
        stacked[f"case_{name}"] = (
            "case",
            np.asarray(column, dtype=float),
            {"units": PARAMETER_UNITS.get(name, "1"), "long_name": f"{name} of the case"},
        )
    return stacked


def bifurcation_table(ds: xr.Dataset) -> pd.DataFrame:
    """The bifurcation table of a branches Dataset as a DataFrame (one row per bifurcation).

    Examples
    --------
    >>> import xarray as xr
    >>> empty = xr.Dataset({"bifurcation_type": ("bifurcation", [])})
    >>> len(bifurcation_table(empty))
    0
    """
    # the table's variables are named by strings
    columns = {
        name.removeprefix("bifurcation_"): ds[name].values
        for name in cast(Iterable[str], ds.data_vars)
        if name.startswith("bifurcation_") and ds[name].dims == ("bifurcation",)
    }
    return pd.DataFrame(columns)


__all__ = ["Branch", "branches_dataset", "stack_cases", "bifurcation_table", "BRANCH_QOIS", "PARAMETER_UNITS"]
