"""Monte Carlo statistics of model outputs: moments, extremes and quantiles over samples."""

from __future__ import annotations

import warnings
from collections.abc import Hashable, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from .checks import check_quantiles

MONTE_CARLO_STATISTICS: tuple[str, ...] = ("mean", "std", "mean_standard_error", "min", "max")


def monte_carlo_statistics(
    outputs: xr.Dataset, *, quantiles: Sequence[float] = (0.05, 0.5, 0.95), dim: str = "sample"
) -> xr.Dataset:
    """Mean, standard deviation, extremes and quantiles of each QoI over ``dim``.

    Non-finite values (failed runs) are left out and counted.

    Parameters
    ----------
    outputs : xarray.Dataset
        QoIs with dimension ``dim`` (other dims, e.g. a sweep, are kept).
    quantiles : sequence of float
        Quantile levels in [0, 1].
    dim : str
        The sample dimension.

    Returns
    -------
    xarray.Dataset
        For each QoI ``q``: ``q`` with dims ``(..., "statistic")`` (mean, std
        with ddof=1, standard error of the mean, min, max), ``q_quantile`` with
        dims ``(..., "quantile")`` and ``q_count`` (finite samples used).
    """
    if not isinstance(outputs, xr.Dataset):
        raise ParameterSpaceError(f"outputs: expected an xarray.Dataset; got {type(outputs).__name__}")
    levels = check_quantiles(quantiles)
    names = [name for name, variable in outputs.data_vars.items() if dim in variable.dims]
    if not names:
        raise ParameterSpaceError(
            f"outputs: no variable has the dimension {dim!r}; "
            f"variables: {', '.join(map(str, outputs.data_vars)) or 'none'}"
        )
    data_vars = {}
    coords: dict[Hashable, Any] = {
        name: outputs.coords[name] for name in outputs.coords if dim not in outputs.coords[name].dims
    }
    for name in names:
        variable = outputs[name].transpose(..., dim)
        values = np.asarray(variable.values, dtype=float)
        other_dims = variable.dims[:-1]
        units = variable.attrs.get("units", "")
        finite = np.isfinite(values)
        count = finite.sum(axis=-1)
        masked = np.where(finite, values, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(masked, axis=-1)
            std = np.nanstd(masked, axis=-1, ddof=1)
            stats = np.stack(
                [
                    mean,
                    std,
                    std / np.sqrt(np.maximum(count, 1)),
                    np.nanmin(masked, axis=-1),
                    np.nanmax(masked, axis=-1),
                ],
                axis=-1,
            )
            quantile_values = np.moveaxis(np.nanquantile(masked, levels, axis=-1), 0, -1)
        data_vars[name] = (
            (*other_dims, "statistic"),
            stats,
            {"units": units, "long_name": f"Monte Carlo statistics of {name}"},
        )
        data_vars[f"{name}_quantile"] = (
            (*other_dims, "quantile"),
            quantile_values,
            {"units": units, "long_name": f"empirical quantiles of {name}"},
        )
        data_vars[f"{name}_count"] = (
            other_dims,
            count.astype(np.int64),
            {"units": "1", "long_name": f"finite samples of {name} used"},
        )
    coords["statistic"] = ("statistic", list(MONTE_CARLO_STATISTICS))
    coords["quantile"] = ("quantile", levels, {"units": "1"})
    attrs = {"method": "monte_carlo_statistics", "std_ddof": 1, "n_samples": int(outputs.sizes[dim])}
    for key in ("seed_entropy", "seed_spawn_key", "interval_treatment", "parameter_space"):
        if key in outputs.attrs:
            attrs[key] = outputs.attrs[key]
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)
