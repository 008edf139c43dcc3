"""Bifurcation diagrams and regime maps: parameter grids run as one batch and classified."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
import xarray as xr

from ..common.errors import UqgearError
from ._checks import Seed
from .regimes import classify_batch


def _check_values(name: str, values: Any) -> np.ndarray:
    array = np.asarray(values, dtype=float) if not isinstance(values, str) else np.array([])
    if array.ndim != 1 or array.size == 0:
        raise UqgearError(f"{name}: expected a non-empty 1-D sequence of numbers; got {values!r}")
    if not np.all(np.isfinite(array)):
        raise UqgearError(f"{name}: expected finite numbers; got {values!r}")
    return array


def _check_fixed(fixed: Mapping[str, float] | None, swept: Sequence[str]) -> dict[str, float]:
    if fixed is None:
        return {}
    if not isinstance(fixed, Mapping):
        raise UqgearError(f"fixed: expected a mapping of variable name to value; got {fixed!r}")
    result = {}
    for key, value in fixed.items():
        if key in swept:
            raise UqgearError(f"fixed: {key!r} is also swept; give it either as swept or as fixed")
        try:
            result[str(key)] = float(value)
        except (TypeError, ValueError):
            raise UqgearError(f"fixed: {key}: expected a number; got {value!r}") from None
    return result


def _run_and_classify(
    design: Any,
    samples: xr.Dataset,
    n_periods: int,
    keep_periods: int,
    lyapunov: bool,
    max_period: int | None,
    rtol: float,
    seed: Seed,
    evaluate: Callable[[xr.Dataset], xr.Dataset] | None = None,
) -> xr.Dataset:
    if evaluate is not None:
        result = evaluate(samples)
    else:
        # Imported here: the integrators are a heavier module (numba kernels) and
        # the analysis functions must stay importable and testable on their own.
        from ..physics.design import load_design
        from ..physics.integration import simulate_batch

        result = simulate_batch(
            load_design(design), samples, n_periods=n_periods, keep_periods=keep_periods, lyapunov=bool(lyapunov)
        )
    classes = classify_batch(result, max_period=max_period, rtol=rtol, seed=seed)
    return result.merge(classes, compat="override")


def bifurcation(
    design: Any,
    parameter: str,
    values: Sequence[float],
    *,
    fixed: Mapping[str, float] | None = None,
    n_periods: int = 400,
    keep_periods: int = 200,
    lyapunov: bool = True,
    max_period: int | None = None,
    rtol: float = 1e-3,
    seed: Seed = 0,
) -> xr.Dataset:
    """Bifurcation diagram: Poincare values and regime against one parameter.

    Builds one ``samples`` Dataset (the swept ``parameter`` plus the ``fixed``
    values) and runs :func:`uqgear.physics.integration.simulate_batch` once.

    Parameters
    ----------
    design : Design, str or mapping
        The gear design, anything :func:`uqgear.physics.design.load_design` accepts.
    parameter : str
        A simulate_batch sample variable: ``pinion_speed``, ``drive_torque``,
        ``adhesion_torque``, a design key or ``mesh_stiffness_scale``.
    values : sequence of float
        Values of the parameter (one column of the diagram each).
    fixed : mapping, optional
        Other sample variables held at one value (e.g. ``{"pinion_speed": 3000.0}``).
    n_periods, keep_periods : int
        Mesh periods simulated and kept for the Poincare section.
    lyapunov : bool
        Also estimate the largest Lyapunov exponent (doubles the cost) and
        let it decide chaotic against quasi-periodic. On by default: with a
        few hundred kept periods the 0-1 test alone mistakes slowly
        converging quasi-periodic responses for chaos (module docstring).
    max_period, rtol, seed
        Classification, see :func:`classify_batch`.

    Returns
    -------
    xarray.Dataset
        Dims (``parameter``, ``period``): ``poincare_x`` and the other
        simulate_batch outputs, plus ``regime``, ``response_period``,
        ``zero_one_k`` and ``distinct_points``.
    """
    if not isinstance(parameter, str) or not parameter or parameter in ("sample", "period"):
        raise UqgearError(
            f"parameter: expected the name of a sample variable such as 'pinion_speed'; got {parameter!r}"
        )
    return sweep_grid(
        design,
        {parameter: values},
        fixed=fixed,
        n_periods=n_periods,
        keep_periods=keep_periods,
        lyapunov=lyapunov,
        max_period=max_period,
        rtol=rtol,
        seed=seed,
    )


def sweep_grid(
    design: Any,
    parameters: Mapping[str, Sequence[float] | np.ndarray],
    *,
    fixed: Mapping[str, float] | None = None,
    n_periods: int = 400,
    keep_periods: int = 200,
    lyapunov: bool = True,
    max_period: int | None = None,
    rtol: float = 1e-3,
    seed: Seed = 0,
    evaluate: Callable[[xr.Dataset], xr.Dataset] | None = None,
) -> xr.Dataset:
    """Regime map over the full grid of several parameters (e.g. speed x adhesion torque).

    Parameters
    ----------
    design : Design, str or mapping
        The gear design, anything :func:`uqgear.physics.design.load_design` accepts.
    parameters : mapping of str to sequence of float
        Swept sample variables and their values; the grid is their Cartesian
        product, run as one simulate_batch call.
    fixed, n_periods, keep_periods, lyapunov, max_period, rtol, seed
        As in :func:`bifurcation`.
    evaluate : callable, optional
        The model as ``evaluate(samples) -> Dataset`` (e.g. a batch evaluator
        run through a :class:`~uqgear.uq.runner.Runner`); its own settings then
        replace ``n_periods``, ``keep_periods`` and ``lyapunov``. Default:
        :func:`~uqgear.physics.integration.simulate_batch` in-process.

    Returns
    -------
    xarray.Dataset
        One dim per swept parameter (in the given order) plus ``period``,
        with the variables of :func:`bifurcation`.
    """
    if not isinstance(parameters, Mapping) or not parameters:
        raise UqgearError(f"parameters: expected a mapping of sample variable name to values; got {parameters!r}")
    names = [str(name) for name in parameters]
    for name in names:
        if not name or name in ("sample", "period"):
            raise UqgearError(f"parameters: expected sample variable names such as 'pinion_speed'; got {name!r}")
    axes = [_check_values(name, parameters[name]) for name in names]
    for name, axis in zip(names, axes):
        if np.unique(axis).size != axis.size:
            raise UqgearError(f"{name}: expected distinct values; got repeated values in {axis.tolist()}")
    constants = _check_fixed(fixed, names)
    index = pd.MultiIndex.from_product(axes, names=names)
    n_samples = len(index)
    data = {name: ("sample", index.get_level_values(name).to_numpy(dtype=float)) for name in names}
    data.update({name: ("sample", np.full(n_samples, value)) for name, value in constants.items()})
    samples = xr.Dataset(data)
    result = _run_and_classify(design, samples, n_periods, keep_periods, lyapunov, max_period, rtol, seed, evaluate)
    result = result.drop_vars([name for name in names if name in result.variables])
    if "sample" in result.variables:
        result = result.drop_vars("sample")
    if len(names) == 1:
        return result.assign_coords({names[0]: ("sample", axes[0])}).swap_dims({"sample": names[0]})
    coords = xr.Coordinates.from_pandas_multiindex(index, "sample")
    return result.assign_coords(coords).unstack("sample").transpose(*names, ...)
