"""Posterior predictive check: the real model rerun at posterior draws, compared with the data and the emulator."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from .harmonics import HARMONIC_CHANNELS
from .likelihood import Features, StageLikelihood

#: How the check is passed.
CRITERION = (
    "posterior-predictive median of the real model within 2 sigma (sensor noise + "
    "posterior median model error) for >= 90 % of the features used, and within 4 sigma "
    "for all"
)
#: How the check is passed with the discrepancy term.
DISCREPANCY_CRITERION = (
    "posterior-predictive median of the real model plus the discrepancy's posterior mean within 2 sigma "
    "(sensor noise + posterior median model error + the discrepancy's posterior variance) for >= 90 % of the "
    "features used, and within 4 sigma for all"
)

_DIMS = ("op", "channel", "harmonic")


def median_model_error(model_error: Mapping[str, Mapping[str, float]], n_harmonics: int) -> np.ndarray:
    """Posterior median relative model error per (channel, harmonic); NaN for groups not used."""
    sigma_model = np.zeros((len(HARMONIC_CHANNELS), n_harmonics))
    for c, channel in enumerate(HARMONIC_CHANNELS):
        for h in range(n_harmonics):
            entry = model_error.get(f"{channel}_mesh{h + 1}")
            sigma_model[c, h] = entry["q50"] if entry else np.nan
    return sigma_model


def predictive_check(
    posterior: xr.Dataset,
    rng: np.random.Generator,
    *,
    parameters: Sequence[str],
    draws: int,
    features: Features,
    likelihood: StageLikelihood,
    model_error: Mapping[str, Mapping[str, float]],
    pinion_speed: np.ndarray,
    run_model: Callable[[list[np.ndarray]], np.ndarray],
    discrepancy: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[xr.Dataset, dict[str, Any]]:
    """The posterior predictive check (``predictive_``) and its summary (``predictive_check_``).

    ``draws`` posterior draws, chosen with ``rng``, are rerun with the real
    model (``run_model``: physical points per run -> log features (op, M,
    channel, harmonic)).

    With ``discrepancy`` (the discrepancy's posterior mean and standard
    deviation at each run, (op, channel, harmonic) each) the check is passed
    on ``z_discrepancy``: the data against the model plus the discrepancy's
    mean, in sigma that include its variance; ``z_total`` (without it) is
    kept, and the spread of the real model over the draws
    (``parameter_log_std``) shows the parameters' uncertainty apart from the
    discrepancy's (``discrepancy_log_std``).
    """
    n_global = len(parameters)
    n_op, _, n_harmonics = features.used.shape
    stacked = np.concatenate(
        [posterior[name].values.reshape(-1, 1) for name in parameters]
        + [posterior["adhesion_torque"].values.reshape(-1, n_op)],
        axis=1,
    )
    count = min(draws, stacked.shape[0])
    sigma_model = median_model_error(model_error, n_harmonics)
    used = features.used
    data: dict[str, Any] = {
        "observed": (_DIMS, features.observed["amplitude"].values),
        "used": (_DIMS, used),
        "noise_log_std": (_DIMS, np.where(used, np.sqrt(features.noise_variance), np.nan)),
        "model_error_log_std": (("channel", "harmonic"), sigma_model),
    }
    if count == 0:
        return xr.Dataset(data), {"draws": 0}
    chosen = stacked[rng.choice(stacked.shape[0], size=count, replace=False)]
    points = [chosen[:, list(range(n_global)) + [n_global + op]] for op in range(n_op)]
    real = run_model(points).transpose(1, 0, 2, 3)
    emulated = likelihood.emulate(likelihood.to_unit(chosen))
    median = np.median(real, axis=0)
    total_std = np.sqrt(features.noise_variance + sigma_model[None] ** 2)
    z_total = (features.log_observed - median) / total_std
    z_noise = (features.log_observed - median) / np.sqrt(features.noise_variance)
    emulator_error = emulated - real
    relative = np.exp(features.log_observed - median) - 1.0
    z_discrepancy = None
    if discrepancy is not None:
        delta_mean, delta_sd = discrepancy
        z_discrepancy = (features.log_observed - median - delta_mean) / np.sqrt(total_std**2 + delta_sd**2)
        data.update(
            {
                "z_discrepancy": (_DIMS, np.where(used, z_discrepancy, np.nan)),
                "discrepancy_mean": (_DIMS, delta_mean),
                "discrepancy_log_std": (_DIMS, delta_sd),
                "parameter_log_std": (_DIMS, np.std(real, axis=0)),
            }
        )
    data.update(
        {
            "predicted_median": (_DIMS, np.exp(median)),
            "predicted_q05": (_DIMS, np.exp(np.quantile(real, 0.05, axis=0))),
            "predicted_q95": (_DIMS, np.exp(np.quantile(real, 0.95, axis=0))),
            "z_total": (_DIMS, np.where(used, z_total, np.nan)),
            "z_noise": (_DIMS, np.where(used, z_noise, np.nan)),
            "relative_difference": (_DIMS, np.where(used, relative, np.nan)),
            "emulator_error_rms": (_DIMS, np.sqrt(np.mean(emulator_error**2, axis=0))),
            "emulator_loo_rms": (_DIMS, likelihood.loo_rms),
        }
    )
    predictive = xr.Dataset(
        data,
        coords={
            "channel": list(HARMONIC_CHANNELS),
            "harmonic": np.arange(1, n_harmonics + 1),
            "pinion_speed": ("op", pinion_speed),
        },
    )
    check = _check_summary(count, used, z_total, z_noise, relative, emulator_error, likelihood.loo_rms)
    if z_discrepancy is not None:
        check = _with_discrepancy(check, used, z_discrepancy)
    return predictive, check


def _with_discrepancy(check: dict[str, Any], used: np.ndarray, z_discrepancy: np.ndarray) -> dict[str, Any]:
    """The check passed on the z-scores with the discrepancy, those without it kept under their own names."""
    used_z = np.abs(z_discrepancy[used])
    within = float(np.mean(used_z <= 2.0))
    return check | {
        "fraction_within_2_sigma_without_discrepancy": check["fraction_within_2_sigma"],
        "max_abs_z_without_discrepancy": check["max_abs_z"],
        "passed_without_discrepancy": check["passed"],
        "fraction_within_2_sigma": within,
        "max_abs_z": float(used_z.max()),
        "passed": bool(within >= 0.9 and used_z.max() <= 4.0),
        "criterion": DISCREPANCY_CRITERION,
    }


def _check_summary(
    count: int,
    used: np.ndarray,
    z_total: np.ndarray,
    z_noise: np.ndarray,
    relative: np.ndarray,
    emulator_error: np.ndarray,
    loo_rms: np.ndarray,
) -> dict[str, Any]:
    """Summary of the check: how many features lie within 2 sigma, the largest misfits, the emulator error."""
    used_z = np.abs(z_total[used])
    used_noise = np.abs(z_noise[used])
    emulator_ratio = float(np.sqrt(np.mean(emulator_error[:, used] ** 2)) / np.sqrt(np.mean(loo_rms[used] ** 2)))
    within = float(np.mean(used_z <= 2.0))
    return {
        "draws": int(count),
        "features_used": int(used.sum()),
        "fraction_within_2_sigma": within,
        "max_abs_z": float(used_z.max()),
        "fraction_within_2_noise_sigma": float(np.mean(used_noise <= 2.0)),
        "median_abs_relative_difference": float(np.median(np.abs(relative[used]))),
        "max_abs_relative_difference": float(np.max(np.abs(relative[used]))),
        "emulator_error_over_loo": emulator_ratio,
        "passed": bool(within >= 0.9 and used_z.max() <= 4.0),
        "criterion": CRITERION,
    }
