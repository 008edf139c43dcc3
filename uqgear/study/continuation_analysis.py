"""The ``continuation`` analysis: periodic-orbit branches and their bifurcations, over uncertain parameters.

For every combination of ``points`` values across each ``envelope`` parameter (an interval: from end
to end, by default both ends, wet and dry rail for T2; a distribution: its 5 % to 95 % quantiles)
the period-1 branch is followed over the range of ``parameter`` (the span of its sweep, or its interval) with :class:`~uqgear.dynamics.continuation.Continuation`, switching
onto doubled branches at period doublings up to ``max_period``. The result stacks the cases along dim
``case`` (:func:`~uqgear.dynamics.branches.stack_cases`): each bifurcation point of each case, so
the interval of a bifurcation point over T2 is the spread of its location over the cases.

With ``compare_sweeps`` (default) the same cases are also swept by brute force at the sweep's values,
from rest, and up and down with each run starting from its neighbour's final state
(:class:`~uqgear.dynamics.attractors.MultiStartSearch` without random starts): ``sweep_<qoi>`` and
``sweep_poincare_x`` on (``case``, ``start``, ``sweep_value``), the points the report draws the
branches over.
"""

from __future__ import annotations

import itertools
import json
import time
from typing import Any

import numpy as np
import xarray as xr

from ..dynamics.attractors import MultiStart, MultiStartSearch
from ..dynamics.branches import stack_cases
from ..dynamics.continuation import Continuation, ContinuationSettings
from ..dynamics.shooting import ShootingSettings
from .analyses import register
from .coexistence import started_model
from .variables import variable_units_short

#: Quantile range at which a distribution in ``envelope`` is continued (``points`` values across it).
QUANTILES = (0.05, 0.95)
#: Brute-force sweep QoIs kept for the comparison.
SWEEP_QOIS = ("peak_mesh_force", "fraction_separation", "fraction_back_contact", "dte_peak_to_peak")


def _envelope_values(context: Any, name: str) -> np.ndarray:
    """``points`` values across an interval, or at the quantiles 5 % to 95 % of a distribution."""
    parameter = context.study.uncertain[name]
    if parameter.is_interval:
        return context.axis_values(name)
    levels = np.linspace(QUANTILES[0], QUANTILES[1], int(context.options["points"]))
    return np.asarray(parameter.to_parameter().to_chaospy().inv(levels), dtype=float)


def _cases(context: Any) -> tuple[list[dict[str, float]], dict[str, list[float]]]:
    names = list(context.options["envelope"])
    grids = [_envelope_values(context, name) for name in names]
    cases = [dict(zip(names, map(float, combination))) for combination in itertools.product(*grids)] or [{}]
    return cases, {name: [case[name] for case in cases] for name in names}


def _sweeps(context: Any, parameter: str, values: np.ndarray, fixed: dict[str, float],
            cases: list[dict[str, float]]) -> xr.Dataset:
    """Brute-force sweeps of every case from rest, up and down (each run from its neighbour's end)."""
    model = started_model(context, context.spec.simulation)
    data: dict[str, np.ndarray] = {parameter: np.tile(values, len(cases))}
    for name in cases[0]:
        data[name] = np.repeat([case[name] for case in cases], values.size)
    for name, value in fixed.items():
        data[name] = np.full(values.size * len(cases), float(value))
    samples = xr.Dataset({name: ("sample", column) for name, column in data.items()})
    search = MultiStartSearch(MultiStart(sweeps=True, seeded=0, sweep_variable=parameter)).fit(
        model, samples, context.design)
    runs = search.runs_
    shape = (len(cases), values.size)
    out = xr.Dataset(coords={"start": ("start", [str(s) for s in runs["start"].values]),
                             "sweep_value": ("sweep_value", values, {"units": variable_units_short(parameter),
                                                                     "long_name": f"{parameter} of the sweeps"})})
    for name in SWEEP_QOIS:
        array = runs[name].transpose("start", "sample").values.reshape(runs.sizes["start"], *shape)
        out[f"sweep_{name}"] = (("case", "start", "sweep_value"), np.moveaxis(array, 0, 1), dict(runs[name].attrs))
    regime = runs["regime"].transpose("start", "sample").values.astype(str).reshape(runs.sizes["start"], *shape)
    out["sweep_regime"] = (("case", "start", "sweep_value"), np.moveaxis(regime, 0, 1),
                           {"long_name": "regime of the sweep run"})
    points = runs["poincare_x"].transpose("start", "sample", "period").values
    points = points.reshape(runs.sizes["start"], *shape, points.shape[-1])
    out["sweep_poincare_x"] = (("case", "start", "sweep_value", "period"), np.moveaxis(points, 0, 1),
                               {"units": "m", "long_name": "Poincare points of the DTE in the sweeps"})
    out.attrs["sweep_runs"] = int(search.model_runs_)
    return out


@register("continuation")
def continuation_analysis(context: Any) -> xr.Dataset:
    """Branches of periodic orbits in one parameter, their bifurcations, at each envelope case.

    Output dims: ``case`` (the envelope values, as ``case_<name>``), ``branch``, ``point``,
    ``bifurcation``, ``state``, ``multiplier`` (:mod:`uqgear.dynamics.branches`), and with
    ``compare_sweeps`` ``start`` (rest, up, down), ``sweep_value`` and ``period``.
    """
    options = context.options
    parameter = options["parameter"]
    envelope = list(options["envelope"])
    values = np.asarray(context.axis_values(parameter), dtype=float)
    fixed = context.fixed_values(exclude=[parameter, *envelope])
    simulation = context.spec.simulation
    settings = ContinuationSettings(max_period=int(options["max_period"]),
                                    shooting=ShootingSettings(steps_per_mode=simulation.steps_per_mode))
    cases, case_values = _cases(context)
    began = time.perf_counter()
    fitted = [Continuation(parameter, float(values.min()), float(values.max()), settings=settings,
                           damping_in_separation=simulation.damping_in_separation, stiffness=simulation.stiffness)
              .fit(context.design, {**fixed, **case}) for case in cases]
    seconds = time.perf_counter() - began
    result = stack_cases([fit.result_ for fit in fitted], case_values)
    result.attrs.update(parameter=parameter, parameter_units=variable_units_short(parameter),
                        envelope=json.dumps(envelope), fixed_inputs=json.dumps(fixed),
                        location_tolerance=float(fitted[0].tolerance_), half_backlash=context.design.half_backlash,
                        continuation_seconds=float(seconds),
                        orbit_passes=int(sum(fit.orbit_passes_ for fit in fitted)),
                        folds_dropped=int(sum(fit.folds_dropped_ for fit in fitted)),
                        model_runs=0, steps_per_mode=simulation.steps_per_mode)
    if options["compare_sweeps"]:
        began = time.perf_counter()
        sweeps = _sweeps(context, parameter, np.sort(values), fixed, cases)
        result = result.merge(sweeps)
        result.attrs.update(model_runs=int(sweeps.attrs["sweep_runs"]),
                            sweep_seconds=float(time.perf_counter() - began))
    return result


__all__ = ["continuation_analysis", "SWEEP_QOIS"]
