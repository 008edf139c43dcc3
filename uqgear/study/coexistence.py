"""The gear model of a study run from several starts per point (``simulation.starts``).

With ``starts`` set, every analysis that runs the model gets :class:`MultiStartModel` in place of the
single-start batch model (:meth:`uqgear.study.analyses.AnalysisContext.model`). It runs each point
from rest, from the neighbouring points' final states in an up- and a down-sweep along the pinion
speed, and from seeded random states (:mod:`uqgear.dynamics.attractors`), groups the steady
responses into attractors and returns, per point:

* every QoI of the **worst attractor** (the largest peak mesh force) under its plain name, with its
  Poincare points as ``poincare_x`` / ``poincare_x_velocity``: statistics, Sobol indices,
  surrogates, headline loads and the regime classification all see the response that loads the
  gear most;
* ``<qoi>_max`` and ``<qoi>_min`` over the attractors with ``<qoi>_max_start`` /
  ``<qoi>_min_start`` (the first start that reached it) and ``_attractor`` (its index), and
  ``<qoi>_rest`` (the rest start's value);
* ``attractor_count`` and per attractor (dim ``attractor``) its peak mesh force, separation
  fraction, regime, share of starts and starts;
* the Poincare points of the rest, up- and down-sweep starts (``poincare_x_rest``, ``_up``,
  ``_down``) for bifurcation diagrams that show coexistence.

:func:`interval_over_attractors` bounds QoIs over interval parameters and attractors (a scan: a
response that jumps between attractors is the non-smooth case surrogates cannot bound).
"""

from __future__ import annotations

import functools
import json
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast

import numpy as np
import xarray as xr

from ..dynamics.attractors import ATTRACTOR_QOIS, MultiStart, MultiStartSearch, StartedEvaluator
from ..dynamics.stress_qois import RUN_QOI_INFO
from ..physics.design import Design
from ..uq.attractor_bounds import scan_over_attractors
from .model_runs import RunnerModel
from .settings import SimulationSettings
from .variables import variable_units_short

#: QoIs reported per attractor along dim ``attractor``.
PER_ATTRACTOR = ("peak_mesh_force", "fraction_separation", "fraction_back_contact", "dte_rms")


def evaluate_started(
    samples: xr.Dataset, *, design: Design, simulation: SimulationSettings, threads: int | None, classify_seed: Any
) -> xr.Dataset:
    """One batch with start states (``initial_<state>``), as :class:`StartedEvaluator`; module-level so that a
    dask worker can run it."""
    return StartedEvaluator(design, simulation.batch_options(threads), classify_seed, stresses=simulation.stresses)(
        samples
    )


class MultiStartModel:
    """The model ``samples -> results`` with every point run from several starts (module docstring).

    Parameters
    ----------
    inner : callable
        The started batch model (a :class:`~uqgear.study.analyses.RunnerModel` of
        :func:`evaluate_started`).
    design : Design
    settings : MultiStart
    seed : SeedSequence
        Seed of the random starts (the same for every call).
    poincare : bool
        Keep Poincare points.
    """

    def __init__(self, inner: Any, design: Design, settings: MultiStart, seed: Any, poincare: bool = True) -> None:
        self.inner = inner
        self.design = design
        self.settings = settings
        self.seed = seed
        self.poincare = poincare

    @property
    def runs(self) -> int:
        """Model runs made so far."""
        return int(self.inner.runs)

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        search = MultiStartSearch(self.settings, self.seed).fit(self.inner, samples, self.design)
        return summarise(search, samples, poincare=self.poincare)

    def attractor_starts(self, samples: xr.Dataset) -> list[list[tuple[str, np.ndarray]]]:
        """Each sample's attractors as (first start, its state; NaN: from rest), from a search run now."""
        return attractor_starts(MultiStartSearch(self.settings, self.seed).fit(self.inner, samples, self.design))


def attractor_starts(search: MultiStartSearch) -> list[list[tuple[str, np.ndarray]]]:
    """Each sample's attractors as (first start, the state it began from; NaN: from rest), in attractor order."""
    first = np.asarray(search.attractors_["first_start"].values).astype(str)
    return [
        [(label, np.array(search.start_states_[label][row], dtype=float)) for label in labels if label != ""]
        for row, labels in enumerate(first)
    ]


def summarise(search: MultiStartSearch, samples: xr.Dataset, poincare: bool = True) -> xr.Dataset:
    """Per-sample outputs of a multi-start search (the layout of the module docstring)."""
    runs, attractors = search.runs_, search.attractors_
    n = samples.sizes["sample"]
    rows = np.arange(n)
    peak = np.where(np.isfinite(attractors["peak_mesh_force"].values), attractors["peak_mesh_force"].values, -np.inf)
    worst = np.argmax(peak, axis=1)
    labels = [str(label) for label in runs["start"].values]
    first = [labels.index(str(attractors["first_start"].values[i, worst[i]])) for i in range(n)]
    out = xr.Dataset(
        coords={
            name: ("sample", samples[name].values)
            for name in cast(Iterable[str], samples.data_vars)  # sample variables are named by strings
            if samples[name].dims == ("sample",) and not name.startswith("initial_")
        }
    )
    # every variable is gathered first and merged once: a merge per variable costs more than the rest of the call
    data: dict[str, Any] = {}
    for name in [*RUN_QOI_INFO, "static_mesh_force", "mesh_frequency", "steps_per_period"]:
        if name not in runs:
            continue
        values = runs[name].transpose("sample", "start").values
        data[name] = ("sample", values[rows, first], dict(runs[name].attrs))
        data[f"{name}_rest"] = ("sample", values[:, 0], {**runs[name].attrs, "long_name": f"{name} from rest"})
    for name in ATTRACTOR_QOIS:
        if name not in attractors:
            continue
        values = np.where(np.isfinite(attractors[name].values), attractors[name].values, np.nan)
        for bound, pick in (("max", np.nanargmax), ("min", np.nanargmin)):
            # every sample holds at least its rest run's attractor: no row is all NaN
            index = pick(values, axis=1).astype(np.int64)
            data[f"{name}_{bound}"] = (
                "sample",
                values[rows, index],
                {"units": RUN_QOI_INFO[name][0], "long_name": f"{bound} over attractors of {name}"},
            )
            data[f"{name}_{bound}_attractor"] = ("sample", index, {"long_name": f"attractor giving {name}_{bound}"})
            data[f"{name}_{bound}_start"] = (
                "sample",
                attractors["first_start"].values[rows, index].astype(str),
                {"long_name": f"first start that reached the attractor of {name}_{bound}"},
            )
    data["attractor_count"] = attractors["attractor_count"]
    for name in PER_ATTRACTOR:
        if name in attractors:
            data[f"attractor_{name}"] = attractors[name]
    for name in ("regime", "share", "starts", "first_start"):
        data[f"attractor_{name}"] = attractors[name]
    data["worst_attractor_start"] = (
        "sample",
        np.array([labels[j] for j in first], dtype=str),
        {"long_name": "first start of the attractor with the largest peak mesh force"},
    )
    if poincare:
        for name in ("poincare_x", "poincare_x_velocity"):
            values = runs[name].transpose("sample", "start", "period").values
            data[name] = (("sample", "period"), values[rows, first], dict(runs[name].attrs))
        for start in ("rest", "up", "down"):
            if start in labels:
                data[f"poincare_x_{start}"] = (
                    ("sample", "period"),
                    runs["poincare_x"].sel(start=start).transpose("sample", "period").values,
                    {"units": "m", "long_name": f"Poincare points of the DTE, {start} start"},
                )
    out = out.assign(data)
    if poincare:
        out = out.assign_coords(period=runs["period"].values)
    out.attrs.update(starts=json.dumps(search.settings.to_dict()), model_runs_per_point=search.model_runs_ / max(n, 1))
    return out


def started_model(context: Any, simulation: SimulationSettings) -> RunnerModel:
    """The batch model with start states of an analysis (an :class:`~uqgear.study.analyses.AnalysisContext`),
    through the analysis's runner, checkpointed under a key of its own."""
    function = functools.partial(
        evaluate_started,
        design=context.design,
        simulation=simulation,
        threads=context.threads,
        classify_seed=context.stage_seed(99),
    )
    key = json.dumps(
        {
            "analysis": context.spec.name,
            "design": context.design.to_dict(),
            "started": True,
            "simulation": simulation.to_dict(),
            "seed": [str(context.seed.entropy), list(context.seed.spawn_key)],
        },
        sort_keys=True,
    )
    return RunnerModel(context.runner, function, key, context.resume)


def multi_start_model(context: Any, simulation: SimulationSettings, poincare: bool) -> MultiStartModel:
    """The multi-start model of an analysis (``simulation.starts`` set)."""
    assert simulation.starts is not None  # the caller's condition
    return MultiStartModel(
        started_model(context, simulation), context.design, simulation.starts, context.stage_seed(98), poincare
    )


def interval_over_attractors(
    context: Any, names: Sequence[str], qois: Sequence[str], fixed: Mapping[str, float]
) -> xr.Dataset:
    """Bounds of each QoI over the interval parameters ``names`` and the attractors, at every operating point."""
    space = context.parameter_space(names, fixed)
    model = context.model(poincare=False)
    points = int(context.options["points"] or 9)
    result = scan_over_attractors(model, space, context.sweep(), qois, points)
    for name in names:
        if name in result.coords:
            result[name].attrs.setdefault("units", variable_units_short(name))
    result.attrs.update(
        model_runs=int(model.runs),
        parameters=json.dumps(list(names)),
        fixed_inputs=json.dumps(dict(fixed)),
        method="scan over attractors",
        scan_points=points,
    )
    return result


__all__ = [
    "attractor_starts",
    "MultiStartModel",
    "multi_start_model",
    "started_model",
    "evaluate_started",
    "summarise",
    "interval_over_attractors",
    "PER_ATTRACTOR",
]
