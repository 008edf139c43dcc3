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

A calibration with a model discrepancy (``discrepancy: true``) carries it: each posterior draw gets a draw
of the discrepancy of the DTE's first mesh harmonic at each operating point, and the dynamic part of each
response (the mesh force above its mean, the load factors above 1, the DTE about its mean) is scaled by
exp(delta) (:data:`~uqgear.uq.prediction.DYNAMIC_PARTS`); the prior's runs, the design's tolerances before
the rig data, carry none.

Without a calibrated posterior the draws come from the study's distributions
(the analysis's ``draws``) and there is no ``_prior``. Operating points
outside the speeds and loads of the rig campaign are flagged
(``extrapolated``), not hidden.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..calibration.priors import prior_bounds
from ..uq.parameter_space import ParameterSpace
from ..uq.posterior import PosteriorDraws
from ..uq.prediction import PosteriorPrediction
from ..uq.sweeps import make_sweep
from .analyses import AnalysisContext, register
from .variables import variable_units_short


def _prior_draws(context: AnalysisContext) -> PosteriorDraws | None:
    """The calibrated parameters drawn from the calibration's uniform prior box, as many as the posterior's."""
    posterior = context.posterior
    if posterior is None:
        return None
    rng = np.random.default_rng(context.stage_seed(1))
    box = prior_bounds(context.design, posterior.names)
    values = np.stack([rng.uniform(*box[name], posterior.size) for name in posterior.names], axis=1)
    return dataclasses.replace(posterior, values=values, source="the calibration's prior", discrepancy_beta=None)


#: The feature whose discrepancy a prediction carries: the first mesh harmonic of the transmission error, the
#: channel that measures the DTE itself (the accelerometers see it through the housing's transfer path).
DISCREPANCY_FEATURE = ("te", 1)


@dataclasses.dataclass(frozen=True)
class DiscrepancyFactors:
    """Per draw and operating point, exp(delta) of the calibration's discrepancy on the DTE's first mesh harmonic.

    The discrepancy says by how much (in log amplitude) the rig's DTE at the mesh frequency differs from the
    model's at an operating point; the prediction scales the dynamic part of each response by that factor (the
    mesh force's part above its mean follows the DTE's dynamic part in a linear mesh). ``beta``: the posterior's
    discrepancy coefficients drawn with each of its draws (``PosteriorDraws.discrepancy_beta``), so that each
    draw carries the discrepancy that goes with its parameters; without them (a posterior written before they
    were kept) delta is drawn apart from the parameters (:meth:`Discrepancy.at
    <uqgear.calibration.discrepancy_results.Discrepancy.at>`).
    """

    discrepancy: Any
    drive_torque: float
    beta: np.ndarray | None = None

    def __call__(self, points: Mapping[str, np.ndarray], draws: int, rng: np.random.Generator) -> np.ndarray:
        speed = np.asarray(points["pinion_speed"], dtype=float)
        torque = np.asarray(points.get("drive_torque", np.full(speed.size, self.drive_torque)), dtype=float)
        if self.beta is None:
            delta = self.discrepancy.at(speed, torque, draws, rng).sel(channel=DISCREPANCY_FEATURE[0])
        elif self.beta.shape[0] != draws:
            # the coefficients are rows of the posterior the draws come from: a mismatch is a bug, not a fallback
            raise RuntimeError(f"internal: {self.beta.shape[0]} discrepancy draws for {draws} posterior draws")
        else:
            delta = self.discrepancy.at_draws(self.beta, speed, torque).sel(channel=DISCREPANCY_FEATURE[0])
        values = np.asarray(delta.sel(harmonic=DISCREPANCY_FEATURE[1]).values, dtype=float)  # (draw, point)
        return np.exp(np.nan_to_num(values))


def _run(
    context: AnalysisContext, names: Sequence[str], posterior: PosteriorDraws | None, discrepancy: Any = None
) -> PosteriorPrediction:
    """One prediction: the draws (posterior or prior) x interval nodes x operating points in one batch."""
    options = context.options
    random = [
        name
        for name, parameter in context.study.uncertain.items()
        if not parameter.is_interval and name not in names and name not in context.spec.sweeps
    ]
    exclude = [*names, *random, *(posterior.names if posterior is not None else ())]
    space = context.parameter_space([*names, *random], context.fixed_values(exclude=exclude))
    space = ParameterSpace(space.parameters, posterior=posterior)
    prediction = PosteriorPrediction(
        options["qois"],
        quantiles=options["quantiles"],
        points=options["points"],
        method=options["method"],
        draws=options["draws"],
        effects=context.effects,
        # the same seed for posterior and prior: the same distribution and effect draws, so the two differ by
        # the calibrated parameters alone
        seed=context.stage_seed(2),
        discrepancy=discrepancy,
    )
    return prediction.fit(context.model(poincare=False), space, context.sweep())


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


@register("prediction")
def prediction_analysis(context: AnalysisContext) -> xr.Dataset:
    """Posterior-predictive quantiles of each QoI's bounds over the interval parameters (see the module)."""
    names = list(context.options["parameters"])
    carried = None
    if context.discrepancy is not None:
        beta = context.posterior.discrepancy_beta if context.posterior is not None else None
        torque = float(context.fixed_values().get("drive_torque", np.nan))
        carried = DiscrepancyFactors(context.discrepancy, torque, beta)
    found = _run(context, names, context.posterior, carried)
    result = found.result_.copy()
    prior = _prior_draws(context)
    before = _run(context, names, prior) if prior is not None else None
    if before is not None:
        for name in context.options["qois"]:
            result[f"{name}_prior"] = before.result_[name].assign_attrs(
                long_name=f"{before.result_[name].attrs['long_name']}, the calibrated parameters from their prior"
            )
            result[f"{name}_prior_draws"] = before.result_[f"{name}_draws"]
    for name in [name for name in result.data_vars if "_worst_" in str(name)]:
        result[name].attrs["units"] = variable_units_short(str(name).rsplit("_worst_", 1)[1])
    sweep = make_sweep(context.sweep())
    points, shape, count = sweep.point_values(), sweep.shape, sweep.size
    flags, campaign = _extrapolated(context, points, count)
    sweep_dims = list(context.sweep())
    result["extrapolated"] = (tuple(sweep_dims), flags.reshape(shape), {"long_name": "outside the rig campaign"})
    for label, prediction in (("posterior", found), ("prior", before)):
        if prediction is None or context.posterior is None:
            continue
        for name in context.posterior.names:
            result[f"{label}_{name}"] = ("draw", prediction.rows_[name], {"units": variable_units_short(name)})
    runs = found.model_runs_ + (before.model_runs_ if before is not None else 0)
    result.attrs.update(_attributes(context, names, found, before, campaign, runs))
    return result


def _narrowing(found: PosteriorPrediction, prior: PosteriorPrediction | None, names: Sequence[str]) -> dict[str, float]:
    """Width of each calibrated parameter's 90 % interval after the rig data, as a share of the prior's."""
    if prior is None:
        return {}
    share = {}
    for name in names:
        after = np.subtract(*np.quantile(found.rows_[name], [0.95, 0.05]))
        before = np.subtract(*np.quantile(prior.rows_[name], [0.95, 0.05]))
        share[name] = float(after / before) if before > 0 else float("nan")
    return dict(sorted(share.items(), key=lambda item: item[1]))


def _attributes(
    context: AnalysisContext,
    names: Sequence[str],
    found: PosteriorPrediction,
    prior: PosteriorPrediction | None,
    campaign: Mapping[str, tuple[float, float]],
    runs: int,
) -> dict[str, Any]:
    posterior = context.posterior
    calibrated = list(posterior.names) if posterior is not None else []
    drawn = [*found.rows_]
    return {
        "parameters": json.dumps(list(names)),
        "interval_nodes": int(found.nodes_.shape[0]),
        "draws": int(found.result_.sizes["draw"]),
        "draws_from": "posterior" if posterior is not None else "study",
        "calibrated_parameters": json.dumps(calibrated),
        "posterior_source": posterior.source if posterior is not None else "",
        "posterior_converged": int(posterior.converged) if posterior is not None else 1,
        "narrowing": json.dumps(_narrowing(found, prior, calibrated)),
        "campaign_range": json.dumps(campaign),
        "effects": json.dumps([effect.to_dict() for effect in context.effects], default=float),
        "effects_sampled": int(any("." in name for name in drawn)),
        "discrepancy": int(found.factors_ is not None),
        "discrepancy_feature": f"{DISCREPANCY_FEATURE[0]} mesh harmonic {DISCREPANCY_FEATURE[1]}",
        "fixed_inputs": json.dumps(context.fixed_values(exclude=[*names, *drawn])),
        "model_runs": int(runs),
    }


__all__ = ["prediction_analysis"]
