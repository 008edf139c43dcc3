"""Results of a fitted calibration: the posterior Dataset, the summary and the JSON content."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.special
import xarray as xr

from .harmonics import HARMONIC_CHANNELS
from .likelihood import Features, StageLikelihood
from .priors import PRIOR_RULES, parameter_units


def summarise(values: np.ndarray) -> dict[str, float]:
    """Mean, standard deviation and 5/50/95 % quantiles of draws."""
    q05, q50, q95 = np.quantile(values, [0.05, 0.5, 0.95])
    return {
        "mean": float(np.mean(values)),
        "sd": float(np.std(values)),
        "q05": float(q05),
        "q50": float(q50),
        "q95": float(q95),
    }


def posterior_dataset(
    physical: np.ndarray,
    log_likelihood: np.ndarray,
    *,
    parameters: Sequence[str],
    bounds: Mapping[str, tuple[float, float]],
    operating: Mapping[str, np.ndarray],
    converged: bool,
) -> xr.Dataset:
    """The posterior draws (``posterior_``) from kept physical draws (draw, chain, dim)."""
    n_global, n_op = len(parameters), len(operating["pinion_speed"])
    draws = np.transpose(physical, (1, 0, 2))  # (chain, draw, dim)
    data: dict[str, tuple[Any, ...]] = {}
    for index, name in enumerate(parameters):
        data[name] = (
            ("chain", "draw"),
            draws[:, :, index],
            {
                "units": parameter_units(name),
                "long_name": PRIOR_RULES[name].long_name if name in PRIOR_RULES else name,
                "prior": "uniform",
                "prior_lower": bounds[name][0],
                "prior_upper": bounds[name][1],
            },
        )
    data["adhesion_torque"] = (
        ("chain", "draw", "op"),
        draws[:, :, n_global:],
        {"units": "N m", "long_name": "adhesion torque T2 of each run", "prior": "uniform on the file's interval"},
    )
    data["log_likelihood"] = (
        ("chain", "draw"),
        log_likelihood.T,
        {"units": "1", "long_name": "log likelihood (emulated, model error integrated out)"},
    )
    coords: dict[str, Any] = {
        "chain": np.arange(draws.shape[0]),
        "draw": np.arange(draws.shape[1]),
        "op": np.arange(n_op),
    }
    for name, values in operating.items():
        coords[name] = ("op", values, {"units": "rpm" if name == "pinion_speed" else "N m"})
    posterior = xr.Dataset(data, coords=coords)
    posterior.attrs.update(converged=int(converged), parameters=json.dumps(list(parameters)))
    return posterior


def posterior_summary(
    physical: np.ndarray,
    *,
    parameters: Sequence[str],
    bounds: Mapping[str, tuple[float, float]],
    operating: Mapping[str, np.ndarray],
    likelihood: StageLikelihood,
    features: Features,
) -> dict[str, Any]:
    """The summary (``summary_``) of kept physical draws (draw, chain, dim)."""
    n_global, n_op = len(parameters), len(operating["pinion_speed"])
    flat = physical.reshape(-1, likelihood.n_dim)
    summary: dict[str, Any] = {"parameters": {}, "adhesion_torque": []}
    for index, name in enumerate(parameters):
        summary["parameters"][name] = summarise(flat[:, index]) | {
            "units": parameter_units(name),
            "prior": list(bounds[name]),
        }
    for op in range(n_op):
        summary["adhesion_torque"].append(
            {
                "op": op,
                "pinion_speed": float(operating["pinion_speed"][op]),
                "units": "N m",
                "prior": [float(operating["adhesion_torque_lower"][op]), float(operating["adhesion_torque_upper"][op])],
            }
            | summarise(flat[:, n_global + op])
        )
    summary["model_error"] = model_error_summary(likelihood.to_unit(flat), likelihood, features)
    return summary


def model_error_summary(unit: np.ndarray, likelihood: StageLikelihood, features: Features) -> dict[str, Any]:
    """Posterior of the relative model error per (channel, harmonic) group, over the sigma grid."""
    rng = np.random.default_rng(0)
    subset = unit[rng.choice(unit.shape[0], size=min(unit.shape[0], 400), replace=False)]
    terms = likelihood.group_terms(features.log_observed[None] - likelihood.emulate(subset))
    weights = np.exp(terms - scipy.special.logsumexp(terms, axis=1, keepdims=True)).mean(axis=0)
    used, grid = features.used, features.model_error_grid
    result = {}
    for c, channel in enumerate(HARMONIC_CHANNELS):
        for h in range(used.shape[2]):
            if not used[:, c, h].any():
                continue
            cumulative = np.cumsum(weights[:, c, h])
            quantile = {
                q: float(grid[min(int(np.searchsorted(cumulative, q)), cumulative.size - 1)]) for q in (0.05, 0.5, 0.95)
            }
            result[f"{channel}_mesh{h + 1}"] = {
                "q05": quantile[0.05],
                "q50": quantile[0.5],
                "q95": quantile[0.95],
                "n_features": int(used[:, c, h].sum()),
            }
    return result


def result_content(
    *,
    rig: str,
    converged: bool,
    design: Mapping[str, Any],
    diagnostics: dict[str, Any],
    summary: dict[str, Any],
    predictive_check: dict[str, Any],
    emulator: dict[str, Any],
    timing: dict[str, Any],
    settings: dict[str, Any],
    speed: list[dict[str, Any]],
    failure: Mapping[str, Any],
) -> dict[str, Any]:
    """The content of ``calibration.json``: estimates only if converged.

    ``failure`` is :func:`uqgear.calibration.failure.failure_causes` of the
    fit: an unconverged fit carries its ``message`` and ``causes`` (the
    sampler named only when the chain statistics are all that failed); a
    converged one lists what it still shows (a predictive misfit, a
    parameter at a prior bound, capped model-error terms) under ``warnings``.

    ``speed`` is the per-operating-point speed estimate of the order tracking
    (:func:`uqgear.rig.order_tracking.speed_summary`).
    """
    estimates = {"parameters": summary["parameters"], "adhesion_torque": summary["adhesion_torque"]}
    result: dict[str, Any] = {
        "rig": rig,
        "converged": converged,
        "design": design,
        "diagnostics": diagnostics,
        "model_error": summary["model_error"],
        "predictive_check": predictive_check,
        "emulator": emulator,
        "timing": timing,
        "settings": settings,
        "speed": speed,
    }
    if "discrepancy" in summary:
        result["discrepancy"] = summary["discrepancy"]
    causes = failure["causes"]
    if converged:
        result.update(estimates)
        # a converged fit may still misfit, lean on a bound or on its model-error terms: say so, keep the result
        result["warnings"] = [cause["text"] for cause in causes]
    else:
        result.update(
            parameters=None,
            adhesion_torque=None,
            unconverged_estimates=estimates,
            message=failure["message"],
            causes=causes,
        )
    return result
