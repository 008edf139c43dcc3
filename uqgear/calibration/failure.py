"""Why a calibration is not a result: named causes instead of a blanket "did not converge".

A posterior can fail for reasons that have nothing to do with the sampler:
the model cannot reproduce the features (posterior-predictive misfit), the
data push parameters against their prior bounds, or the model-error terms
climb to their cap to absorb a misfit. Each is read off the finished fit and
named with its numbers; the chain statistics are named as the cause only
when they are what failed and nothing else is.

With the discrepancy term (:mod:`~uqgear.calibration.discrepancy`) an iid
model error at its cap is not a cause when the discrepancy explains the
misfit, that is when the predictive check with the discrepancy included
passes; a discrepancy scale tau at the cap of its own grid is.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

# A posterior median within this fraction of the prior width from a bound
# "sits at" the bound.
_AT_BOUND = 0.03
# A model-error median within this fraction of the cap has "hit" it.
_AT_CAP = 0.9
_WORST_SHOWN = 3


def parameters_at_bounds(parameters: Mapping[str, Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Global parameters whose posterior median sits at a prior bound."""
    found = []
    for name, entry in parameters.items():
        lower, upper = entry["prior"]
        width = upper - lower
        for side, bound in (("lower", lower), ("upper", upper)):
            if width > 0 and abs(entry["q50"] - bound) <= _AT_BOUND * width:
                found.append({"parameter": name, "bound": side, "value": float(bound), "median": entry["q50"]})
    return found


def model_errors_at_cap(model_error: Mapping[str, Mapping[str, float]], cap: float) -> list[dict[str, Any]]:
    """Model-error groups whose posterior median reached the cap of their grid."""
    return [
        {"group": group, "median": entry["q50"], "cap": cap}
        for group, entry in model_error.items()
        if entry["q50"] >= _AT_CAP * cap
    ]


def worst_misfits(predictive: xr.Dataset) -> list[dict[str, Any]]:
    """The features farthest from the posterior-predictive median (in total sigma, with the discrepancy if fitted)."""
    name = "z_discrepancy" if "z_discrepancy" in predictive else "z_total"
    if name not in predictive:
        return []
    z = np.abs(predictive[name].values)
    order = np.argsort(np.where(np.isfinite(z), z, -1.0), axis=None)[::-1][:_WORST_SHOWN]
    rows = []
    for flat in order:
        op, channel, harmonic = np.unravel_index(flat, z.shape)
        if not np.isfinite(z[op, channel, harmonic]):
            break
        rows.append(
            {
                "op": int(op),
                "pinion_speed": float(predictive["pinion_speed"].values[op]),
                "feature": f"{predictive['channel'].values[channel]} mesh{predictive['harmonic'].values[harmonic]}",
                "z": float(predictive[name].values[op, channel, harmonic]),
                "relative_difference": float(predictive["relative_difference"].values[op, channel, harmonic]),
            }
        )
    return rows


def failure_causes(
    *,
    diagnostics: Mapping[str, Any],
    summary: Mapping[str, Any],
    predictive_check: Mapping[str, Any],
    predictive: xr.Dataset,
    model_error_cap: float,
    discrepancy_cap: float | None = None,
) -> dict[str, Any]:
    """What is wrong with a fit, each cause with its numbers.

    ``discrepancy_cap`` (the upper bound of tau) is given for a fit with the
    discrepancy term: its ``summary`` has a ``discrepancy`` entry and its
    predictive check includes the discrepancy (module docstring).

    Returns
    -------
    dict
        ``causes`` (list of {"kind", "text", ...}; kinds ``predictive_misfit``,
        ``parameter_at_bound``, ``model_error_at_cap``, ``discrepancy_at_cap``,
        ``sampler``) and ``message``: one sentence naming them, "" when nothing
        is wrong.
    """
    causes: list[dict[str, Any]] = []
    if predictive_check.get("passed") is False:
        misfits = worst_misfits(predictive)
        worst = "; ".join(
            f"{m['feature']} at {m['pinion_speed']:g} rpm off by {100 * m['relative_difference']:+.0f} % "
            f"({m['z']:+.1f} sigma)"
            for m in misfits
        )
        causes.append(
            {
                "kind": "predictive_misfit",
                "misfits": misfits,
                "text": (
                    f"the model does not reproduce the features: "
                    f"{100 * predictive_check['fraction_within_2_sigma']:.0f} % within 2 sigma "
                    f"(90 % needed), median difference "
                    f"{100 * predictive_check['median_abs_relative_difference']:.0f} %"
                    + (f"; worst {worst}" if worst else "")
                ),
            }
        )
    at_bounds = parameters_at_bounds(summary.get("parameters", {}))
    if at_bounds:
        causes.append(
            {
                "kind": "parameter_at_bound",
                "parameters": at_bounds,
                "text": "parameters pile against their prior bounds: "
                + ", ".join(
                    f"{b['parameter']} median {b['median']:.4g} at its {b['bound']} bound {b['value']:.4g}"
                    for b in at_bounds
                ),
            }
        )
    capped = model_errors_at_cap(summary.get("model_error", {}), model_error_cap)
    if discrepancy_cap is not None:
        if predictive_check.get("passed") is True:
            capped = []  # the discrepancy explains what the iid error could not
        causes.extend(_discrepancy_at_cap(summary.get("discrepancy", {}), discrepancy_cap))
    if capped:
        causes.append(
            {
                "kind": "model_error_at_cap",
                "groups": capped,
                "text": "the model-error terms reach their cap {:.2g} to absorb a misfit: {}".format(
                    model_error_cap, ", ".join(g["group"] for g in capped)
                ),
            }
        )
    reasons = [str(reason) for reason in diagnostics.get("reasons", [])]
    if reasons:
        causes.append(
            {"kind": "sampler", "reasons": reasons, "text": "the sampler did not converge: " + "; ".join(reasons)}
        )
    if not causes:
        return {"causes": [], "message": ""}
    physical = [cause for cause in causes if cause["kind"] != "sampler"]
    if physical:
        message = (
            "the model does not fit these data, so the estimates are not a result: "
            + "; ".join(cause["text"] for cause in physical)
            + ". An effect the model lacks, or a record it cannot read (check the speed estimate), "
            "is the likely cause: run `uqgear diagnose` on the same file"
        )
        if reasons:
            message += "; the chain statistics also fail (" + "; ".join(reasons) + ")"
    else:
        message = "the sampler did not converge, so the estimates are not a result: " + "; ".join(reasons)
    return {"causes": causes, "message": message}


def _discrepancy_at_cap(discrepancy: Mapping[str, Any], cap: float) -> list[dict[str, Any]]:
    """The cause ``discrepancy_at_cap`` (none or one): groups whose tau median reached the cap of its grid."""
    groups = [
        {"group": group, "median": entry["tau"]["q50"], "cap": cap}
        for group, entry in discrepancy.get("groups", {}).items()
        if entry["tau"]["q50"] >= _AT_CAP * cap
    ]
    if not groups:
        return []
    text = "the discrepancy terms reach their cap {:.2g}: {}".format(cap, ", ".join(g["group"] for g in groups))
    return [{"kind": "discrepancy_at_cap", "groups": groups, "text": text}]


__all__ = ["parameters_at_bounds", "model_errors_at_cap", "worst_misfits", "failure_causes"]
