"""Views and scalar summaries of one simulated response: phase plane, Poincare section,
contact-state fractions and the response quantities of interest."""

from __future__ import annotations

import math
from typing import cast

import numpy as np
import xarray as xr

from ..common.errors import UqgearError
from ._checks import require_number_attr, require_variables

_CONTACT_STATES = {"fraction_drive_contact": 1, "fraction_separation": 0, "fraction_back_contact": -1}
_CONTACT_LONG_NAMES = {
    "fraction_drive_contact": "fraction of time in drive-side contact (x > b)",
    "fraction_separation": "fraction of time with the teeth apart (|x| <= b)",
    "fraction_back_contact": "fraction of time in back-side contact (x < -b)",
}


def phase_plane(ds: xr.Dataset, variable: str = "x") -> xr.Dataset:
    """Displacement and velocity histories of one coordinate, for a phase portrait.

    Parameters
    ----------
    ds : xarray.Dataset
        A simulate() result.
    variable : str
        ``x``, ``y1`` or ``y2``; its velocity is ``<variable>_velocity``.

    Returns
    -------
    xarray.Dataset
        ``displacement`` (m) and ``velocity`` (m s-1) over ``time``.
    """
    if not isinstance(variable, str):
        raise UqgearError(f"variable: expected a variable name such as 'x'; got {variable!r}")
    velocity_name = f"{variable}_velocity"
    require_variables(ds, [variable, velocity_name], "phase_plane")
    displacement = ds[variable].copy()
    velocity = ds[velocity_name].copy()
    displacement.attrs = {"units": ds[variable].attrs.get("units", "m"), "long_name": f"{variable} displacement"}
    velocity.attrs = {"units": ds[velocity_name].attrs.get("units", "m s-1"), "long_name": f"{variable} velocity"}
    return xr.Dataset({"displacement": displacement, "velocity": velocity}, attrs={"variable": variable})


def poincare_section(ds: xr.Dataset) -> xr.Dataset:
    """The Poincare section (state once per mesh period) of a simulate() result.

    Returns
    -------
    xarray.Dataset
        The ``poincare_*`` variables over the ``period`` dim, with the run's
        attrs.
    """
    if not isinstance(ds, xr.Dataset):
        raise UqgearError(f"poincare_section: expected an xarray Dataset; got {type(ds).__name__}")
    names = [name for name in ds.data_vars if str(name).startswith("poincare_")]
    if not names:
        raise UqgearError(
            "poincare_section: the Dataset has no poincare_* variables (expected poincare_x, poincare_x_velocity, ...)"
        )
    return ds[names].copy()


def contact_fractions(ds: xr.Dataset) -> xr.Dataset:
    """Fractions of time in each contact state, from the ``contact`` history.

    Returns
    -------
    xarray.Dataset
        ``fraction_drive_contact`` (``contact == 1``), ``fraction_separation``
        (0) and ``fraction_back_contact`` (-1), averaged over ``time`` (other
        dims kept); they add up to 1.
    """
    require_variables(ds, ["contact"], "contact_fractions")
    contact = ds["contact"]
    if "time" not in contact.dims:
        raise UqgearError(f"contact_fractions: 'contact' should have a 'time' dim; it has {contact.dims}")
    if contact.sizes["time"] == 0:
        raise UqgearError("contact_fractions: 'contact' has no time samples")
    values = np.unique(contact.values)
    unexpected = sorted(set(values.tolist()) - {-1, 0, 1})
    if unexpected:
        raise UqgearError(f"contact_fractions: 'contact' should hold only -1, 0 and 1; got {unexpected[:5]}")
    return xr.Dataset(
        {
            name: (contact == state)
            .mean("time")
            .astype(float)
            .assign_attrs(units="1", long_name=_CONTACT_LONG_NAMES[name])
            for name, state in _CONTACT_STATES.items()
        }
    )


def _sqrt(values: xr.DataArray) -> xr.DataArray:
    """np.sqrt of a DataArray, which stays a DataArray (NumPy's stubs type the result as an ndarray)."""
    return cast(xr.DataArray, np.sqrt(values))


def response_qois(ds: xr.Dataset) -> xr.Dataset:
    """Scalar quantities of interest of a simulate() run.

    Named and defined like the QoIs of ``simulate_batch``, reduced over
    ``time`` (other dims kept):

    * ``dte_mean``: mean of ``x``, m;
    * ``dte_rms``: RMS of ``x - mean(x)``, m;
    * ``dte_peak_to_peak``: ``max(x) - min(x)``, m;
    * ``dynamic_load_factor``: peak mesh force in the loading direction over
      the run's own static mesh force, ``max(F sign(F_T)) / |F_T|``
      (``max(F) / F_T`` for a driving load); F_T is set by this run's T1 and
      T2, so the factor moves with T2 even where the peak force does not;
    * ``peak_mesh_force``: ``max(F)`` over the kept section, N (the load a
      designer sizes against);
    * ``load_factor_rated``: ``peak_mesh_force`` over the design's rated mesh
      force ``T1_rated / r_b1`` (attribute ``rated_mesh_force`` of the run;
      NaN when the run does not give it), 1;
    * ``acc_pinion_rms``, ``acc_gear_rms``: RMS of ``y1_acceleration`` and
      ``y2_acceleration`` (their mean is zero in a steady state), m s-2;
    * the three contact fractions of :func:`contact_fractions`.
    """
    require_variables(ds, ["x", "mesh_force", "y1_acceleration", "y2_acceleration", "contact"], "response_qois")
    if "time" not in ds["x"].dims:
        raise UqgearError(f"response_qois: 'x' should have a 'time' dim; it has {ds['x'].dims}")
    static_force = require_number_attr(ds, "static_mesh_force", "response_qois")
    if static_force == 0.0 or not math.isfinite(static_force):
        raise UqgearError(
            f"response_qois: attribute static_mesh_force should be a non-zero number "
            f"(a loaded mesh); got {static_force!r}"
        )
    rated_force = float(ds.attrs.get("rated_mesh_force", math.nan))
    if not (math.isfinite(rated_force) and rated_force > 0.0):
        rated_force = math.nan
    peak_force = ds["mesh_force"].max("time")
    x = ds["x"]
    mean = x.mean("time")
    qois = {
        "dte_mean": mean.assign_attrs(units="m", long_name="mean dynamic transmission error x"),
        "dte_rms": _sqrt(((x - mean) ** 2).mean("time")).assign_attrs(
            units="m", long_name="RMS of the dynamic transmission error about its mean"
        ),
        "dte_peak_to_peak": (x.max("time") - x.min("time")).assign_attrs(
            units="m", long_name="peak-to-peak dynamic transmission error"
        ),
        "dynamic_load_factor": (
            (ds["mesh_force"] * math.copysign(1.0, static_force)).max("time") / abs(static_force)
        ).assign_attrs(units="1", long_name="peak mesh force over the run's own static mesh force F_T (moves with T2)"),
        "peak_mesh_force": peak_force.assign_attrs(units="N", long_name="largest mesh force F in the kept section"),
        "load_factor_rated": (peak_force / rated_force).assign_attrs(
            units="1", long_name="peak mesh force over the rated mesh force T1_rated / r_b1"
        ),
        "acc_pinion_rms": _sqrt((ds["y1_acceleration"] ** 2).mean("time")).assign_attrs(
            units="m s-2", long_name="RMS pinion acceleration along the line of action"
        ),
        "acc_gear_rms": _sqrt((ds["y2_acceleration"] ** 2).mean("time")).assign_attrs(
            units="m s-2", long_name="RMS gear acceleration along the line of action"
        ),
    }
    result = xr.Dataset(qois)
    return result.merge(contact_fractions(ds))
