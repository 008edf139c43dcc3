"""Running a model function on samples, at every point of a sweep, in one batch call.

A *model function* is::

    evaluate(samples: xarray.Dataset) -> xarray.Dataset

``samples`` has the dimension ``sample`` and one float variable per parameter
name; the result has the dimension ``sample`` and one variable per quantity of
interest (QoI). :func:`evaluate_on_sweep` runs such a function for every point
of a sweep (for example every pinion speed) in *one* batch call, because the
gear model's batch simulator runs a batch in parallel.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
import xarray as xr

from ..common.errors import ExecutionError, ParameterSpaceError
from .parameter_space import ParameterSpace

#: A model function: samples (dim ``sample``) in, QoIs (dim ``sample``) out.
ModelFunction = Callable[[xr.Dataset], xr.Dataset]


@dataclass(frozen=True)
class Sweep:
    """Cartesian sweep of one or more deterministic variables (e.g. pinion speed)."""

    names: tuple[str, ...]
    values: tuple[np.ndarray, ...]
    attrs: tuple[dict[str, Any], ...]

    @property
    def shape(self) -> tuple[int, ...]:
        """Number of values along each sweep variable."""
        return tuple(len(v) for v in self.values)

    @property
    def size(self) -> int:
        """Number of sweep points (1 for no sweep)."""
        return int(np.prod(self.shape, dtype=int))

    def point_values(self) -> dict[str, np.ndarray]:
        """Per sweep point (flattened, C order) the value of each sweep variable."""
        if not self.names:
            return {}
        mesh = np.meshgrid(*self.values, indexing="ij")
        return {name: grid.ravel() for name, grid in zip(self.names, mesh)}

    def coords(self) -> dict[str, tuple[str, np.ndarray, dict[str, Any]]]:
        """xarray coordinates of the sweep."""
        return {name: (name, values, attrs) for name, values, attrs in zip(self.names, self.values, self.attrs)}

    def label(self, index: int) -> str:
        """Human-readable label of flat sweep point ``index``."""
        if not self.names:
            return "(no sweep)"
        position = np.unravel_index(index, self.shape)
        return ", ".join(f"{name}={values[i]:.6g}" for name, values, i in zip(self.names, self.values, position))


def make_sweep(sweep: Mapping[str, Any] | None, space: ParameterSpace | None = None) -> Sweep:
    """Validate a sweep mapping ``{name: 1-D values}``.

    An :class:`xarray.DataArray` keeps its attributes (e.g. ``units``). A
    sweep variable may override a fixed parameter of ``space`` but not an
    uncertain one.
    """
    if sweep is None:
        return Sweep((), (), ())
    if not isinstance(sweep, Mapping):
        raise ParameterSpaceError(f"sweep: expected a mapping of name to 1-D values; got {sweep!r}")
    names, values, attrs = [], [], []
    for name, raw in sweep.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise ParameterSpaceError(f"sweep: expected identifier names; got {name!r}")
        if space is not None and name in space.uncertain_names:
            raise ParameterSpaceError(
                f"sweep {name}: {name} is an uncertain parameter of the space; a sweep variable must be deterministic"
            )
        units = ""
        if isinstance(raw, xr.DataArray):
            extra = dict(raw.attrs)
            raw = raw.values
        else:
            extra = {}
        if space is not None and name in space and not extra.get("units"):
            units = space.units(name)
        try:
            array = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            raise ParameterSpaceError(f"sweep {name}: expected 1-D numbers; got {raw!r}") from None
        if array.ndim != 1 or array.size == 0 or not np.all(np.isfinite(array)):
            raise ParameterSpaceError(f"sweep {name}: expected a non-empty 1-D sequence of finite numbers; got {raw!r}")
        if len(np.unique(array)) != array.size:
            raise ParameterSpaceError(f"sweep {name}: values must be distinct")
        if units and "units" not in extra:
            extra["units"] = units
        names.append(name)
        values.append(array)
        attrs.append(extra)
    return Sweep(tuple(names), tuple(values), tuple(attrs))


def call_model(evaluate: ModelFunction, batch: xr.Dataset, qoi: Sequence[str] | None = None) -> xr.Dataset:
    """Run ``evaluate`` on ``batch`` once and check what comes back.

    Parameters
    ----------
    evaluate : callable
        The model function.
    batch : xarray.Dataset
        Inputs with dimension ``sample``.
    qoi : sequence of str, optional
        Output variables to keep; by default every numeric variable whose only
        dimension is ``sample``.

    Returns
    -------
    xarray.Dataset
        The selected QoIs as float arrays with dimension ``sample``.

    Raises
    ------
    ExecutionError
        If the model returns something else than a Dataset with the same
        number of samples, or a requested QoI is missing or not per-sample.
    """
    size = batch.sizes["sample"]
    result = evaluate(batch)
    if not isinstance(result, xr.Dataset):
        raise ExecutionError(
            f"model function: expected an xarray.Dataset with dimension 'sample'; got {type(result).__name__}"
        )
    if result.sizes.get("sample") != size:
        raise ExecutionError(
            f"model function: expected dimension 'sample' of length {size}; got dims {dict(result.sizes)}"
        )
    if qoi is None:
        names = [
            name
            for name, variable in result.data_vars.items()
            if variable.dims == ("sample",) and np.issubdtype(variable.dtype, np.number)
        ]
        if not names:
            raise ExecutionError("model function: returned no numeric variable with dimension ('sample',)")
    else:
        names = list(qoi)
        for name in names:
            if name not in result.data_vars:
                raise ExecutionError(
                    f"qoi {name!r}: not returned by the model function; it returned "
                    f"{', '.join(map(str, result.data_vars)) or 'nothing'}"
                )
            variable = result[name]
            if variable.dims != ("sample",) or not np.issubdtype(variable.dtype, np.number):
                raise ExecutionError(
                    f"qoi {name!r}: expected a numeric variable with dims ('sample',); "
                    f"got dims {variable.dims}, dtype {variable.dtype}"
                )
    selected = xr.Dataset(
        {name: ("sample", np.asarray(result[name].values, dtype=float), dict(result[name].attrs)) for name in names},
        coords={"sample": np.arange(size)},
    )
    return selected


def batch_samples(samples: Mapping[str, np.ndarray], units: Mapping[str, str]) -> xr.Dataset:
    """Dataset (dimension ``sample``) from flat arrays of equal length."""
    data_vars = {
        name: ("sample", np.asarray(values, dtype=float), {"units": units.get(name, "")})
        for name, values in samples.items()
    }
    size = len(next(iter(samples.values()))) if samples else 0
    return xr.Dataset(data_vars, coords={"sample": np.arange(size)})


def evaluate_on_sweep(
    evaluate: ModelFunction,
    samples: xr.Dataset,
    sweep: Mapping[str, Any] | Sweep | None = None,
    *,
    qoi: Sequence[str] | None = None,
) -> xr.Dataset:
    """Evaluate the model on every sample at every sweep point, in one batch call.

    Parameters
    ----------
    evaluate : callable
        The model function.
    samples : xarray.Dataset
        Parameter samples (dimension ``sample``).
    sweep : mapping of str to 1-D values, optional
        Deterministic variables swept on a cartesian grid; each sample is run
        at every sweep point.
    qoi : sequence of str, optional
        QoIs to keep (default: all per-sample numeric outputs).

    Returns
    -------
    xarray.Dataset
        The QoIs with dims ``(*sweep names, "sample")``.
    """
    if not isinstance(samples, xr.Dataset) or "sample" not in samples.dims:
        raise ParameterSpaceError("samples: expected an xarray.Dataset with dimension 'sample'")
    sweep = sweep if isinstance(sweep, Sweep) else make_sweep(sweep)
    n = samples.sizes["sample"]
    point_values = sweep.point_values()
    flat: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    # sample variables are named by strings (model inputs)
    for name, variable in cast(Mapping[str, xr.DataArray], samples.data_vars).items():
        if name in point_values or variable.dims != ("sample",):
            continue
        flat[name] = np.tile(np.asarray(variable.values, dtype=float), sweep.size)
        units[name] = variable.attrs.get("units", "")
    for name, values in point_values.items():
        flat[name] = np.repeat(values, n)
        units[name] = sweep.attrs[sweep.names.index(name)].get("units", "")
    outputs = call_model(evaluate, batch_samples(flat, units), qoi)
    data_vars = {
        name: ((*sweep.names, "sample"), variable.values.reshape(*sweep.shape, n), variable.attrs)
        for name, variable in outputs.data_vars.items()
    }
    return xr.Dataset(
        data_vars, coords={**sweep.coords(), "sample": samples["sample"].values}, attrs={"runs": sweep.size * n}
    )
