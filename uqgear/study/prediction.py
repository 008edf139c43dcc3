"""The ``prediction`` analysis: the calibrated model's band over the interval parameters, and how far rig data
narrowed it.

For each joint draw of the calibrated parameters (``uncertain.calibrated``,
thinned and seeded) the model runs at every operating point and at the nodes
of the interval parameters (``parameters``, by default every interval of the
study: T2 on wet to dry rail), carrying the diagnosed effects of
``model.effects`` (one draw of their parameters per posterior draw). Per draw
and operating point the bounds of each QoI over the interval nodes are taken,
over every steady response the guided starts find (the worst and best
attractor); the result holds the quantiles over the draws of each bound. The
same runs from the calibration's prior (its uniform box, the design's
tolerances before the rig data) give ``<qoi>_prior``, so that the report says
how far the rig data narrowed the worst case.

Without a calibrated posterior the draws come from the study's distributions
(the analysis's ``draws``) and there is no ``_prior``. Operating points
outside the speeds and loads of the rig campaign are flagged
(``extrapolated``), not hidden.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..calibration.priors import prior_bounds
from ..physics.effect_draws import draw_effect_sets
from ..physics.effects import Effect
from ..physics.integration import QOI_INFO
from ..uq.parameters import Distribution
from .analyses import AnalysisContext, register
from .variables import variable_units_short


@dataclasses.dataclass(frozen=True)
class DrawSet:
    """Rows of the propagated inputs: one value per draw for each name, and the effects of each draw."""

    label: str
    rows: Mapping[str, np.ndarray]
    effects: tuple[tuple[Effect, ...], ...] | None

    @property
    def size(self) -> int:
        return len(next(iter(self.rows.values()))) if self.rows else 1


@dataclasses.dataclass(frozen=True)
class DrawBounds:
    """Per draw and operating point: the lower and upper bound of each QoI over the interval nodes."""

    lower: Mapping[str, np.ndarray]  # qoi -> (draw, point)
    upper: Mapping[str, np.ndarray]
    worst_node: Mapping[str, np.ndarray]  # qoi -> (draw, point) index of the node giving the upper bound
    runs: int


def _interval_nodes(context: AnalysisContext, names: Sequence[str]) -> np.ndarray:
    """Nodes over the interval parameters: ``points`` per parameter end to end (``vertex``: the two ends)."""
    options = context.options
    count = 2 if options["method"] == "vertex" else int(options["points"])
    axes = []
    for name in names:
        parameter = context.study.uncertain[name]
        axes.append(np.linspace(parameter.lower, parameter.upper, count))
    return np.array(list(itertools.product(*axes)), dtype=float).reshape(-1, len(names))


def _distribution_rows(context: AnalysisContext, names: Sequence[str], size: int) -> dict[str, np.ndarray]:
    """The study's distributions not bounded over, sampled once (the same rows for posterior and prior)."""
    rng = np.random.default_rng(context.stage_seed(2))
    rows = {}
    for name, parameter in context.study.uncertain.items():
        if name in names or name in context.spec.sweeps:
            continue
        spec = parameter.to_parameter()
        if isinstance(spec, Distribution):
            rows[name] = np.asarray(spec.to_chaospy().inv(rng.uniform(1e-12, 1 - 1e-12, size)), dtype=float)
    return rows


def draw_sets(context: AnalysisContext, names: Sequence[str]) -> tuple[DrawSet, DrawSet | None]:
    """The posterior's draws (or the study's distributions) and, with a posterior, the prior's."""
    posterior = context.posterior
    size = posterior.size if posterior is not None else int(context.options["draws"])
    shared = _distribution_rows(context, names, size)
    if posterior is None and not shared and not any(e.intervals for e in context.effects):
        size = 1
        shared = {}
    effects = None
    if any(effect.intervals for effect in context.effects):
        drawn = draw_effect_sets(context.effects, size, context.stage_seed(3))
        if len({effect.name for effect in context.effects}) == len(context.effects):
            # each draw's effect parameters as sample variables (``family.parameter``): all draws in one batch
            for position, effect in enumerate(context.effects):
                for key in sorted(effect.intervals):
                    shared[f"{effect.name}.{key}"] = np.array([one[position].values[key] for one in drawn])
        else:
            effects = tuple(drawn)
    if posterior is None:
        return DrawSet("study", shared, effects), None
    calibrated = {name: posterior.column(name) for name in posterior.names}
    rng = np.random.default_rng(context.stage_seed(1))
    box = prior_bounds(context.design, posterior.names)
    prior = {name: rng.uniform(*box[name], size) for name in posterior.names}
    return DrawSet("posterior", {**calibrated, **shared}, effects), DrawSet("prior", {**prior, **shared}, effects)


def _sweep_points(context: AnalysisContext) -> tuple[dict[str, np.ndarray], tuple[int, ...]]:
    sweeps = context.sweep()
    if not sweeps:
        return {}, ()
    mesh = np.meshgrid(*(array.values for array in sweeps.values()), indexing="ij")
    return {name: grid.ravel() for name, grid in zip(sweeps, mesh)}, mesh[0].shape


def _samples(
    draws: DrawSet, rows: Sequence[int], nodes: np.ndarray, names: Sequence[str], points: Mapping[str, np.ndarray],
    fixed: Mapping[str, float],
) -> xr.Dataset:
    """Samples in the order (draw, node, point)."""
    n_points = len(next(iter(points.values()))) if points else 1
    n_nodes = nodes.shape[0]
    count = len(rows) * n_nodes * n_points
    data: dict[str, Any] = {}
    for name, values in draws.rows.items():
        data[name] = np.repeat(np.asarray(values)[list(rows)], n_nodes * n_points)
    for column, name in enumerate(names):
        data[name] = np.tile(np.repeat(nodes[:, column], n_points), len(rows))
    for name, values in points.items():
        data[name] = np.tile(values, len(rows) * n_nodes)
    for name, value in fixed.items():
        if name not in data:
            data[name] = np.full(count, float(value))
    return xr.Dataset({name: ("sample", values) for name, values in data.items()})


def _bounds_of(result: xr.Dataset, qoi: str, shape: tuple[int, int, int]) -> tuple[np.ndarray, ...]:
    """(lower, upper, node of the upper) per (draw, point), over the nodes and every attractor found."""
    high = result[f"{qoi}_max"] if f"{qoi}_max" in result else result[qoi]
    low = result[f"{qoi}_min"] if f"{qoi}_min" in result else result[qoi]
    high_values = np.asarray(high.values, dtype=float).reshape(shape)
    low_values = np.asarray(low.values, dtype=float).reshape(shape)
    filled = np.where(np.isnan(high_values), -np.inf, high_values)
    return np.nanmin(low_values, axis=1), np.nanmax(high_values, axis=1), np.argmax(filled, axis=1)


def run_draws(
    context: AnalysisContext, draws: DrawSet, nodes: np.ndarray, names: Sequence[str], qois: Sequence[str]
) -> DrawBounds:
    """Run every draw at every node and operating point; keep the bounds over the nodes per draw."""
    points, _ = _sweep_points(context)
    n_points = len(next(iter(points.values()))) if points else 1
    fixed = context.fixed_values(exclude=[*names, *draws.rows])
    # draws whose effects differ run as batches of their own; otherwise all draws are one batch
    groups = [[row] for row in range(draws.size)] if draws.effects is not None else [list(range(draws.size))]
    lower = {qoi: np.empty((draws.size, n_points)) for qoi in qois}
    upper = {qoi: np.empty((draws.size, n_points)) for qoi in qois}
    worst = {qoi: np.empty((draws.size, n_points), dtype=np.int64) for qoi in qois}
    runs = 0
    for rows in groups:
        run_context = context
        if draws.effects is not None:
            simulation = dataclasses.replace(context.spec.simulation, effects=draws.effects[rows[0]])
            run_context = dataclasses.replace(context, spec=dataclasses.replace(context.spec, simulation=simulation))
        model = run_context.model(poincare=False)
        result = model(_samples(draws, rows, nodes, names, points, fixed))
        runs += int(model.runs)
        for qoi in qois:
            low, high, node = _bounds_of(result, qoi, (len(rows), nodes.shape[0], n_points))
            lower[qoi][rows], upper[qoi][rows], worst[qoi][rows] = low, high, node
    return DrawBounds(lower, upper, worst, runs)


def _quantile_array(bounds: DrawBounds, qoi: str, quantiles: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    stacked = np.stack([bounds.lower[qoi], bounds.upper[qoi]])  # (bound, draw, point)
    values = np.nanquantile(stacked, quantiles, axis=1)  # (quantile, bound, point)
    return np.moveaxis(values, 0, 1).reshape((2, quantiles.size, *shape))


def _extrapolated(context: AnalysisContext, points: Mapping[str, np.ndarray], count: int) -> tuple[np.ndarray, dict]:
    """Operating points outside the campaign's speeds and loads (and the campaign's range)."""
    flags = np.zeros(count, dtype=bool)
    campaign = dict(context.posterior.campaign) if context.posterior is not None else {}
    fixed = context.fixed_values()
    for name, (low, high) in campaign.items():
        if name == "adhesion_torque":
            continue  # an interval parameter: its range is said in the attributes
        values = points.get(name, np.full(count, fixed.get(name, np.nan)))
        span = max(high - low, abs(high)) * 1e-9
        flags |= (values < low - span) | (values > high + span)
    return flags, campaign


def _narrowing(draws: DrawSet, prior: DrawSet | None, names: Sequence[str]) -> dict[str, float]:
    """Width of each calibrated parameter's 90 % interval after the rig data, as a share of the prior's."""
    if prior is None:
        return {}
    share = {}
    for name in names:
        after = np.subtract(*np.quantile(draws.rows[name], [0.95, 0.05]))
        before = np.subtract(*np.quantile(prior.rows[name], [0.95, 0.05]))
        share[name] = float(after / before) if before > 0 else float("nan")
    return dict(sorted(share.items(), key=lambda item: item[1]))


@register("prediction")
def prediction_analysis(context: AnalysisContext) -> xr.Dataset:
    """Posterior-predictive quantiles of each QoI's bounds over the interval parameters (see the module)."""
    options = context.options
    names = list(options["parameters"])
    qois = list(options["qois"])
    quantiles = np.asarray(options["quantiles"], dtype=float)
    nodes = _interval_nodes(context, names)
    draws, prior = draw_sets(context, names)
    points, shape = _sweep_points(context)
    sweep_dims = list(context.sweep())
    count = int(np.prod(shape)) if shape else 1
    found = {"": run_draws(context, draws, nodes, names, qois)}
    if prior is not None:
        found["_prior"] = run_draws(context, prior, nodes, names, qois)
    coords: dict[str, Any] = {"bound": ["lower", "upper"], "quantile": quantiles, "draw": np.arange(draws.size)}
    coords.update(context.sweep())
    result = xr.Dataset(coords=coords)
    for suffix, bounds in found.items():
        for qoi in qois:
            units, meaning = QOI_INFO[qoi]
            label = "prior (the design's tolerances)" if suffix else draws.label
            result[f"{qoi}{suffix}"] = (
                ("bound", "quantile", *sweep_dims),
                _quantile_array(bounds, qoi, quantiles, shape),
                {"units": units, "long_name": f"quantiles over the {label} draws of the bounds of {meaning}"},
            )
            per_draw = np.stack([bounds.lower[qoi], bounds.upper[qoi]], axis=1).reshape((draws.size, 2, *shape))
            result[f"{qoi}{suffix}_draws"] = (("draw", "bound", *sweep_dims), per_draw, {"units": units})
    for qoi in qois:
        node = found[""].worst_node[qoi]
        for column, name in enumerate(names):
            at = np.asarray([np.bincount(node[:, i], minlength=nodes.shape[0]).argmax() for i in range(count)])
            result[f"{qoi}_worst_{name}"] = (
                tuple(sweep_dims),
                nodes[at, column].reshape(shape),
                {"units": variable_units_short(name), "long_name": f"{name} giving the upper bound most often"},
            )
    flags, campaign = _extrapolated(context, points, count)
    result["extrapolated"] = (tuple(sweep_dims), flags.reshape(shape), {"long_name": "outside the rig campaign"})
    for label, drawn in (("posterior", draws), ("prior", prior)):
        if drawn is None or context.posterior is None:
            continue
        for name in context.posterior.names:
            result[f"{label}_{name}"] = ("draw", np.asarray(drawn.rows[name]), {"units": variable_units_short(name)})
    result.attrs.update(_attributes(context, names, nodes, draws, prior, campaign, found))
    return result


def _attributes(
    context: AnalysisContext,
    names: Sequence[str],
    nodes: np.ndarray,
    draws: DrawSet,
    prior: DrawSet | None,
    campaign: Mapping[str, tuple[float, float]],
    found: Mapping[str, DrawBounds],
) -> dict[str, Any]:
    posterior = context.posterior
    return {
        "parameters": json.dumps(list(names)),
        "interval_nodes": int(nodes.shape[0]),
        "draws": int(draws.size),
        "draws_from": draws.label,
        "calibrated_parameters": json.dumps(list(posterior.names) if posterior is not None else []),
        "posterior_source": posterior.source if posterior is not None else "",
        "posterior_converged": int(posterior.converged) if posterior is not None else 1,
        "narrowing": json.dumps(_narrowing(draws, prior, posterior.names if posterior is not None else ())),
        "campaign_range": json.dumps(campaign),
        "effects": json.dumps([effect.to_dict() for effect in context.effects], default=float),
        "effects_sampled": int(draws.effects is not None or any("." in name for name in draws.rows)),
        "fixed_inputs": json.dumps(context.fixed_values(exclude=[*names, *draws.rows])),
        "model_runs": int(sum(bounds.runs for bounds in found.values())),
    }


__all__ = ["prediction_analysis", "draw_sets", "run_draws", "DrawSet", "DrawBounds"]
