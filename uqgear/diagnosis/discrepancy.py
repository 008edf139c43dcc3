"""Predictive distribution of rig features given model features: sensor noise, model error, discrepancies.

A feature of the rig is the model's value plus sensor noise plus model
error: Rice-distributed line amplitudes, band powers with the noise power
added. :func:`standardised_discrepancy` maps each feature to a standard
normal discrepancy and :func:`robust_log_density` scores it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.special
import scipy.stats

from ..rig.features import FEATURE_FAMILIES
from .errors import DiagnosisError
from .processing import RunProcessor

# Features compared with the model. The noise floor and the crest factor (a
# maximum, driven by single noise samples) describe the record, not the gear.
_COMPARED_EXCLUDED = ("noise_std", "crest_factor")

#: Feature kinds with their own predictive distribution.
FEATURE_KINDS = ("line", "band", "rms", "kurtosis")

# Rice distributions with b = nu/sigma above this are normal to within 1e-4 in z.
_RICE_NORMAL_ABOVE = 40.0
# Robust predictive density: a small share of outliers spread evenly over +-100 sigma, a floor
# that a feature far off costs whatever its distance (about 10 nats beyond 4.6 sigma).
_OUTLIER_SHARE = 0.01
_OUTLIER_WIDTH = 100.0


def feature_kind(name: str, family: str) -> str:
    """Kind of a feature for its predictive distribution (see :data:`FEATURE_KINDS`)."""
    if name == "low_band_rms":
        return "band"
    if name == "rms":
        return "rms"
    if name == "kurtosis":
        return "kurtosis"
    if family in FEATURE_FAMILIES and family not in ("low_frequency", "broadband"):
        return "line"
    raise DiagnosisError(f"feature {name!r}: no predictive distribution for family {family!r}")


@dataclass(frozen=True)
class NoiseModel:
    """What sensor noise adds to each feature, for unit noise standard deviation.

    Attributes
    ----------
    line_scale : ndarray (F,)
        Per-quadrature standard deviation of line amplitudes (NaN for other features).
    band_power : ndarray (2,)
        Mean and standard deviation of the low-band mean square.
    total_power : ndarray (2,)
        Mean and standard deviation of the record's mean square.
    kurtosis_spread : float
        Standard deviation of the kurtosis of white noise records.
    """

    line_scale: np.ndarray
    band_power: np.ndarray
    total_power: np.ndarray
    kurtosis_spread: float


def noise_model(processor: RunProcessor, rng: np.random.Generator, n_records: int = 16) -> NoiseModel:
    """Noise contributions of a run's processing: lines exactly, band powers by Monte Carlo."""
    noise = rng.standard_normal((n_records, processor.size))
    values = processor.features(noise)
    band = values[:, processor.columns["low_band_rms"]] ** 2
    total = values[:, processor.columns["rms"]] ** 2
    return NoiseModel(
        line_scale=processor.line_noise,
        band_power=np.array([band.mean(), band.std(ddof=1)]),
        total_power=np.array([total.mean(), total.std(ddof=1)]),
        kurtosis_spread=float(values[:, processor.columns["kurtosis"]].std(ddof=1)),
    )


def _rice_moments(nu: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of a Rice(nu, sigma) amplitude (stable for all nu/sigma)."""
    b2 = 0.25 * (nu / sigma) ** 2
    laguerre = (1.0 + 2.0 * b2) * scipy.special.ive(0, b2) + 2.0 * b2 * scipy.special.ive(1, b2)
    mean = sigma * math.sqrt(math.pi / 2.0) * laguerre
    variance = np.maximum(2.0 * sigma**2 + nu**2 - mean**2, 1e-300)
    return mean, np.sqrt(variance)


def _line_discrepancy(observed: np.ndarray, nu: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """Standard normal quantile of the Rice CDF at the observation (normal limit for large nu/sigma)."""
    z = np.full(observed.shape, np.nan)
    b = nu / sigma
    ok = np.isfinite(observed) & np.isfinite(b)
    normal = ok & (b > _RICE_NORMAL_ABOVE)
    mean, spread = _rice_moments(nu[normal], sigma[normal])
    z[normal] = (observed[normal] - mean) / spread
    rice = ok & ~normal
    if rice.any():
        x = observed[rice] / sigma[rice]
        upper = scipy.stats.rice.sf(x, b[rice])
        lower = scipy.stats.rice.cdf(x, b[rice])
        values = np.where(upper < 0.5, scipy.stats.norm.isf(upper), scipy.stats.norm.ppf(lower))
        # beyond double precision in the tail: the moment form keeps the ordering
        extreme = ~np.isfinite(values)
        if extreme.any():
            mean, spread = _rice_moments(nu[rice][extreme], sigma[rice][extreme])
            values[extreme] = (observed[rice][extreme] - mean) / spread
        z[rice] = values
    return z


@dataclass(frozen=True)
class FeatureLayout:
    """Names, families and kinds of the compared features, in order."""

    names: tuple[str, ...]
    families: tuple[str, ...]
    kinds: tuple[str, ...]
    columns: np.ndarray  # positions in the processor's feature vector

    @classmethod
    def from_processor(cls, processor: RunProcessor) -> FeatureLayout:
        chosen = [i for i, d in enumerate(processor.definitions) if d.name not in _COMPARED_EXCLUDED]
        names = tuple(processor.definitions[i].name for i in chosen)
        families = tuple(processor.definitions[i].family for i in chosen)
        kinds = tuple(feature_kind(n, f) for n, f in zip(names, families))
        return cls(names, families, kinds, np.array(chosen, dtype=int))


def absolute_model_error(model_error: Mapping[str, Any], kind: str) -> Any:
    """Absolute model error of a feature kind (:class:`~.case.FeatureModelError`; 0 where none is held)."""
    return getattr(model_error, "absolute", {}).get(kind, 0.0)


def _noisy_kurtosis(kurtosis: np.ndarray, signal_power: np.ndarray, noise_power: np.ndarray) -> np.ndarray:
    """Kurtosis of a signal of this kurtosis and mean square plus independent Gaussian noise of this power."""
    return (kurtosis * signal_power**2 + 6.0 * signal_power * noise_power + 3.0 * noise_power**2) / np.maximum(
        (signal_power + noise_power) ** 2, 1e-300
    )


def standardised_discrepancy(
    observed: np.ndarray,
    model: np.ndarray,
    noise_std: np.ndarray,
    noise: Sequence[NoiseModel],
    layout: FeatureLayout,
    model_error: Mapping[str, float],
    *,
    band_noise_std: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Standardised discrepancies and predictive scales of rig features against model features.

    Parameters
    ----------
    observed : ndarray (..., n_op, n_channel, F)
        Rig features in ``layout`` order.
    model : ndarray (..., n_op, n_channel, F)
        Noise-free model features, same layout (broadcast against ``observed``).
    noise_std : ndarray (n_op, n_channel)
        The rig's white-noise standard deviation per run and channel.
    noise : sequence of NoiseModel
        Per run (unit noise).
    layout : FeatureLayout
    model_error : mapping
        Relative model error per feature kind (a
        :class:`~uqgear.diagnosis.case.FeatureModelError` may add absolute
        model error, :func:`absolute_model_error`).
    band_noise_std : ndarray (n_op, n_channel), optional
        The white noise of the low band, where it is read apart from
        ``noise_std`` (:attr:`~uqgear.diagnosis.case.RigCase.band_noise_std`);
        default ``noise_std``.

    Returns
    -------
    z : ndarray
        N(0, 1) where the model, noise and model error describe the rig.
    scale : ndarray
        Predictive scale of each feature relative to its noise-only scale
        (>= 1; model error widens it), for predictive densities.
    """
    observed, model = np.broadcast_arrays(np.asarray(observed, float), np.asarray(model, float))
    z = np.full(observed.shape, np.nan)
    scale = np.full(observed.shape, np.nan)
    kinds = np.array(layout.kinds)
    sigma_noise = np.asarray(noise_std, dtype=float)[..., None]  # (n_op, n_channel, 1)
    sigma_band = sigma_noise if band_noise_std is None else np.asarray(band_noise_std, dtype=float)[..., None]
    line_sigma = line_noise_sigma(noise_std, noise, layout)
    band = np.stack([n.band_power for n in noise])[:, None, :]  # (n_op, 1, 2)
    total = np.stack([n.total_power for n in noise])[:, None, :]
    kurt_spread = np.array([n.kurtosis_spread for n in noise])[:, None]

    line = kinds == "line"
    if line.any():
        nu = np.abs(model[..., line])
        sigma = np.sqrt(
            line_sigma[..., line] ** 2
            + (model_error["line"] * nu) ** 2
            + absolute_model_error(model_error, "line") ** 2
        )
        sigma = np.maximum(sigma, 1e-300)
        z[..., line] = _line_discrepancy(observed[..., line], nu, sigma)
        scale[..., line] = sigma / np.maximum(line_sigma[..., line], 1e-300)
    for kind, moments, sigma_kind in (("band", band, sigma_band), ("rms", total, sigma_noise)):
        chosen = kinds == kind
        if not chosen.any():
            continue
        model_power = model[..., chosen] ** 2
        noise_power = sigma_kind**2 * moments[..., 0:1]
        # noise power scatter, model error, and the signal-noise cross term
        relative_scatter = moments[..., 1:2] / moments[..., 0:1]
        spread = np.sqrt(
            (sigma_kind**2 * moments[..., 1:2]) ** 2
            + (2.0 * model_error[kind] * model_power) ** 2
            + 2.0 * model_power * noise_power * relative_scatter**2
            + absolute_model_error(model_error, kind) ** 2
        )
        spread = np.maximum(spread, 1e-300)
        z[..., chosen] = (observed[..., chosen] ** 2 - model_power - noise_power) / spread
        scale[..., chosen] = spread / np.maximum(sigma_kind**2 * moments[..., 1:2], 1e-300)
    chosen = kinds == "kurtosis"
    if chosen.any():
        index = layout.names.index("rms")
        power = model[..., index : index + 1] ** 2
        noise_power = sigma_noise**2 * total[..., 0:1]
        kurt = model[..., chosen]
        predicted = _noisy_kurtosis(kurt, power, noise_power)
        spread = np.sqrt(
            (model_error["kurtosis"] * predicted) ** 2
            + kurt_spread[..., None] ** 2
            + absolute_model_error(model_error, "kurtosis") ** 2
        )
        z[..., chosen] = (observed[..., chosen] - predicted) / spread
        scale[..., chosen] = spread / np.maximum(kurt_spread[..., None], 1e-300)
    return z, scale


def line_noise_sigma(noise_std: np.ndarray, noise: Sequence[NoiseModel], layout: FeatureLayout) -> np.ndarray:
    """Per-quadrature noise spread of each compared line (n_op, n_channel, F; NaN for features not lines):
    each record's noise std times the line's scale in its run's noise model."""
    line_scale = np.stack([n.line_scale[layout.columns] for n in noise])[:, None, :]  # (n_op, 1, F)
    return np.asarray(noise_std, dtype=float)[..., None] * line_scale


def expected_rig_features(
    model: np.ndarray,
    noise_std: np.ndarray,
    noise: Sequence[NoiseModel],
    layout: FeatureLayout,
    *,
    band_noise_std: np.ndarray | None = None,
) -> np.ndarray:
    """What a rig records on average for noise-free model features (..., n_op, n_channel, F).

    Line amplitudes: the Rice mean about the model's amplitude; band and
    broadband RMS: the noise power added (the band's with ``band_noise_std``
    where given, as in :func:`standardised_discrepancy`); kurtosis: that of
    signal plus Gaussian noise. Used to judge how visible a model difference is.
    """
    model = np.asarray(model, dtype=float)
    out = np.full(model.shape, np.nan)
    kinds = np.array(layout.kinds)
    sigma_noise = np.asarray(noise_std, dtype=float)[..., None]
    sigma_band = sigma_noise if band_noise_std is None else np.asarray(band_noise_std, dtype=float)[..., None]
    band = np.stack([n.band_power[0] for n in noise])[:, None, None]
    total = np.stack([n.total_power[0] for n in noise])[:, None, None]
    line = kinds == "line"
    sigma = np.broadcast_to(
        np.maximum(line_noise_sigma(noise_std, noise, layout)[..., line], 1e-300), model[..., line].shape
    )
    out[..., line] = _rice_moments(np.abs(model[..., line]), sigma)[0]
    for kind, power, sigma_kind in (("band", band, sigma_band), ("rms", total, sigma_noise)):
        chosen = kinds == kind
        out[..., chosen] = np.sqrt(model[..., chosen] ** 2 + sigma_kind**2 * power)
    chosen = kinds == "kurtosis"
    if chosen.any():
        index = layout.names.index("rms")
        signal_power = model[..., index : index + 1] ** 2
        noise_power = sigma_noise**2 * total
        out[..., chosen] = _noisy_kurtosis(model[..., chosen], signal_power, noise_power)
    return out


def robust_log_density(z: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Log predictive density of features from their standardised discrepancies.

    A normal density in z mixed with a small share of outliers spread evenly
    over a wide range: a feature the model cannot reach costs a bounded
    number of nats, however far off, so neither a single model-error outlier
    nor a partial approach to a hopeless feature can drive a verdict.
    Densities are per unit of the noise-only scale: ``scale`` is the
    predictive scale relative to it (model error and parameter uncertainty
    widen it), so a vaguer prediction pays for it near the data while the
    floor stays the same for every model.
    """
    z = np.asarray(z, dtype=float)
    normal = (
        math.log1p(-_OUTLIER_SHARE)
        - 0.5 * z**2
        - 0.5 * math.log(2.0 * math.pi)
        - np.log(np.asarray(scale, dtype=float))
    )
    floor = math.log(_OUTLIER_SHARE / (2.0 * _OUTLIER_WIDTH))
    return np.logaddexp(normal, floor)
