"""The fitted discrepancy: the posterior of beta and tau per group, its summary, and its record in ``posterior.nc``.

Given the residuals r_g of a group at a posterior draw and a (sigma, tau)
grid pair, beta is Gaussian with covariance C = (tau^-2 I + Phi^T D^-1
Phi)^-1 and mean C Phi^T D^-1 r (:mod:`~uqgear.calibration.discrepancy`).
Averaged over posterior draws and the grid posterior of (sigma, tau), that
mixture is summarised by its mean and covariance: a Gaussian that carries
the parameters' and the hyperparameters' uncertainty, not only the
conditional spread at one point. :class:`Discrepancy` draws from it at new
operating points; it is written to ``posterior.nc`` and read back by
:func:`read_discrepancy`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.special
import xarray as xr

from .discrepancy import BASIS_NAMES, DiscrepancyBasis, DiscrepancyLikelihood
from .errors import CalibrationError
from .harmonics import HARMONIC_CHANNELS
from .likelihood import Features

#: Units of the discrepancy (it adds to the natural log of a mesh-harmonic amplitude).
LOG_UNITS = "1 (natural log of the amplitude ratio)"
# Posterior draws the summary averages over (as many as the model-error summary's).
_SUMMARY_DRAWS = 400


@dataclass(frozen=True)
class Discrepancy:
    """A fitted discrepancy: the Gaussian of beta per (channel, harmonic) group and the basis it multiplies.

    Parameters
    ----------
    basis : DiscrepancyBasis
        The basis and its scaling.
    beta_mean : array (channel, harmonic, basis)
        Posterior mean of beta (NaN for a group without data).
    beta_covariance : array (channel, harmonic, basis, basis)
        Its posterior covariance.

    Examples
    --------
    A discrepancy of +0.1 in every group's constant, known exactly:

    >>> import numpy as np
    >>> mean = np.zeros((3, 1, 4)); mean[..., 0] = 0.1
    >>> fitted = Discrepancy(DiscrepancyBasis((1000.0, 3000.0), (5000.0, 7000.0)), mean, np.zeros((3, 1, 4, 4)))
    >>> draws = fitted.at([1500.0, 2500.0], [6000.0, 6000.0], 5, np.random.default_rng(0))
    >>> draws.dims, draws.shape, bool(np.allclose(draws, 0.1))
    (('draw', 'point', 'channel', 'harmonic'), (5, 2, 3, 1), True)
    """

    basis: DiscrepancyBasis
    beta_mean: np.ndarray
    beta_covariance: np.ndarray

    def mean_at(
        self, pinion_speed: Sequence[float] | np.ndarray, drive_torque: Sequence[float] | np.ndarray
    ) -> np.ndarray:
        """Posterior mean of delta (point, channel, harmonic) at operating points."""
        return np.einsum("np,chp->nch", self.basis.matrix(pinion_speed, drive_torque), self.beta_mean)

    def sd_at(
        self, pinion_speed: Sequence[float] | np.ndarray, drive_torque: Sequence[float] | np.ndarray
    ) -> np.ndarray:
        """Posterior standard deviation of delta (point, channel, harmonic) at operating points."""
        phi = self.basis.matrix(pinion_speed, drive_torque)
        variance = np.einsum("np,chpq,nq->nch", phi, self.beta_covariance, phi)
        return np.sqrt(np.maximum(variance, 0.0))

    def at_draws(
        self,
        beta: np.ndarray,
        pinion_speed: Sequence[float] | np.ndarray,
        drive_torque: Sequence[float] | np.ndarray,
    ) -> xr.DataArray:
        """delta at operating points for given draws of beta (draw, channel, harmonic, basis).

        With the draws of a posterior's ``discrepancy_beta`` (one per joint draw of the parameters) the
        discrepancy goes with the parameters it was drawn with (:func:`joint_beta_draws`), which :meth:`at`
        cannot do.

        Examples
        --------
        >>> import numpy as np
        >>> fitted = Discrepancy(DiscrepancyBasis((1000.0, 3000.0), (5000.0, 7000.0)), np.zeros((3, 1, 4)),
        ...                      np.zeros((3, 1, 4, 4)))
        >>> beta = np.zeros((2, 3, 1, 4)); beta[1, :, :, 1] = 0.1  # the second draw: a slope in speed
        >>> fitted.at_draws(beta, [1000.0, 3000.0], [6000.0, 6000.0]).sel(channel="te", harmonic=1).values.tolist()
        [[0.0, 0.0], [-0.1, 0.1]]
        """
        phi = self.basis.matrix(pinion_speed, drive_torque)
        return self._as_array(np.einsum("np,dchp->dnch", phi, np.asarray(beta, dtype=float)))

    @staticmethod
    def _as_array(delta: np.ndarray) -> xr.DataArray:
        n_channels, n_harmonics = delta.shape[2:]
        return xr.DataArray(
            delta,
            dims=("draw", "point", "channel", "harmonic"),
            coords={"channel": list(HARMONIC_CHANNELS)[:n_channels], "harmonic": np.arange(1, n_harmonics + 1)},
            attrs={"units": LOG_UNITS, "long_name": "model discrepancy of the log mesh-harmonic amplitude"},
        )

    def at(
        self,
        pinion_speed: Sequence[float] | np.ndarray,
        drive_torque: Sequence[float] | np.ndarray,
        draws: int,
        rng: np.random.Generator,
    ) -> xr.DataArray:
        """Draws of delta at operating points, to add to predicted log amplitudes.

        Parameters
        ----------
        pinion_speed, drive_torque : array-like (n,)
            Operating points (rpm, N m); outside the calibration campaign's
            range the quadratic extrapolates and grows quickly.
        draws : int
            Number of draws.
        rng : numpy.random.Generator
            Source of the draws.

        Returns
        -------
        xarray.DataArray
            (draw, point, channel, harmonic), log-amplitude units; NaN for a
            group the calibration had no data for.
        """
        phi = self.basis.matrix(pinion_speed, drive_torque)
        n_channels, n_harmonics, n_basis = self.beta_mean.shape
        # a symmetric square root (eigenvalues clipped at 0) tolerates a covariance that is PSD only up to rounding
        values, vectors = np.linalg.eigh(np.nan_to_num(self.beta_covariance))
        root = vectors * np.sqrt(np.maximum(values, 0.0))[..., None, :]
        normal = rng.standard_normal((draws, n_channels, n_harmonics, n_basis))
        beta = self.beta_mean[None] + np.einsum("chpq,dchq->dchp", root, normal)
        return self._as_array(np.einsum("np,dchp->dnch", phi, beta))


@dataclass(frozen=True)
class DiscrepancyFit:
    """The discrepancy's posterior from a finished fit: :class:`Discrepancy`, tau, and per-run values."""

    discrepancy: Discrepancy
    #: tau quantiles (channel, harmonic, 3): 5, 50, 95 % (NaN for a group without data).
    tau_quantiles: np.ndarray
    #: sigma (iid model error) posterior median (channel, harmonic).
    sigma_median: np.ndarray
    #: Variance of the emulated log features over posterior draws (op, channel, harmonic).
    parameter_variance: np.ndarray
    #: The tau grid's bounds.
    tau_range: tuple[float, float]


def _grid_quantiles(weights: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """5, 50 and 95 % quantiles of grid weights (..., grid) (the grid value where the cumulative weight passes)."""
    cumulative = np.cumsum(weights, axis=-1)
    found = [np.minimum((cumulative < q).sum(axis=-1), grid.size - 1) for q in (0.05, 0.5, 0.95)]
    return np.stack([grid[index] for index in found], axis=-1)


def fit_discrepancy(
    unit: np.ndarray, likelihood: DiscrepancyLikelihood, features: Features, basis: DiscrepancyBasis
) -> DiscrepancyFit:
    """The posterior of beta per group, averaged over unit-box posterior draws (M, n_dim) and the grids."""
    rng = np.random.default_rng(0)
    subset = unit[rng.choice(unit.shape[0], size=min(unit.shape[0], _SUMMARY_DRAWS), replace=False)]
    predicted = likelihood.emulate(subset)
    residual = features.log_observed[None] - predicted
    joint = likelihood.joint_terms(residual)  # (M, K, L, G)
    weights = np.exp(joint - scipy.special.logsumexp(joint, axis=(1, 2), keepdims=True)).transpose(0, 3, 1, 2)
    _, projected = likelihood.projections(residual)  # (G, M, K, p)
    covariance = likelihood.beta_covariance  # (G, K, L, p, p)
    count = subset.shape[0]
    mean_beta = np.zeros((covariance.shape[0], covariance.shape[-1]))
    second = np.zeros(covariance.shape[:1] + covariance.shape[-2:])
    for start in range(0, count, 64):  # blocks bound the (G, points, K, L, p) temporaries
        w, u = weights[start : start + 64], projected[:, start : start + 64]
        conditional = np.einsum("gklpq,gmkq->mgklp", covariance, u)
        mean_beta += np.einsum("mgkl,mgklp->gp", w, conditional)
        second += np.einsum("mgkl,gklpq->gpq", w, covariance)
        second += np.einsum("mgkl,mgklp,mgklq->gpq", w, conditional, conditional, optimize=True)
    mean_beta /= count
    beta_covariance = second / count - mean_beta[:, :, None] * mean_beta[:, None, :]
    n_op, n_channels, n_harmonics = likelihood.shape
    group_used = features.used.any(axis=0).reshape(-1)
    mean_beta[~group_used] = np.nan
    beta_covariance[~group_used] = np.nan
    tau_weights = weights.sum(axis=2).mean(axis=0)  # (G, L)
    sigma_weights = weights.sum(axis=3).mean(axis=0)  # (G, K)
    tau_q = np.where(group_used[:, None], _grid_quantiles(tau_weights, likelihood.tau), np.nan)
    sigma_q = np.where(group_used, _grid_quantiles(sigma_weights, features.model_error_grid)[:, 1], np.nan)
    shape = (n_channels, n_harmonics)
    return DiscrepancyFit(
        discrepancy=Discrepancy(
            basis, mean_beta.reshape(*shape, -1), beta_covariance.reshape(*shape, *covariance.shape[-2:])
        ),
        tau_quantiles=tau_q.reshape(*shape, 3),
        sigma_median=sigma_q.reshape(shape),
        parameter_variance=predicted.var(axis=0),
        tau_range=(float(likelihood.slab_tau[0]), float(likelihood.slab_tau[-1])),
    )


def joint_beta_draws(
    unit: np.ndarray, likelihood: DiscrepancyLikelihood, rng: np.random.Generator, block: int = 256
) -> np.ndarray:
    """One draw of beta per posterior draw, from its posterior given that draw's parameters: (M, G, p).

    For each unit-box draw (M, n_dim) and group, a (sigma, tau) grid pair is
    drawn from its posterior given the draw's residuals, then beta from
    N(C u, C) (C and u = Phi^T D^-1 r at that pair). Paired with the
    parameters they were drawn with, the draws are the joint posterior of the
    parameters and the discrepancy: a draw whose parameters put the emulated
    features high gets a discrepancy that takes them back towards the data. The
    summary Gaussian of :func:`fit_discrepancy` averages that dependence away;
    drawn apart from the parameters it counts their spread twice.
    """
    covariance = likelihood.beta_covariance  # (G, K, L, p, p)
    n_groups, n_sigma, n_tau, n_basis = covariance.shape[:3] + covariance.shape[-1:]
    # C = tau^2 M^-1: its root tau chol(M^-1) is zero, not singular, at tau = 0
    root = likelihood.tau[None, None, :, None, None] * np.linalg.cholesky(likelihood.unit_covariance)
    out = np.empty((unit.shape[0], n_groups, n_basis))
    groups = np.arange(n_groups)
    for start in range(0, unit.shape[0], block):  # blocks bound the (points, sigma, tau, group) temporaries
        chunk = unit[start : start + block]
        residual = likelihood.log_observed[None] - likelihood.emulate(chunk)
        joint = likelihood.joint_terms(residual).reshape(chunk.shape[0], n_sigma * n_tau, n_groups)
        weights = np.exp(joint - joint.max(axis=1, keepdims=True))
        cumulative = np.cumsum(weights, axis=1)
        pick = rng.uniform(size=(chunk.shape[0], 1, n_groups)) * cumulative[:, -1:, :]
        index = np.minimum((cumulative < pick).sum(axis=1), n_sigma * n_tau - 1)  # (m, G)
        k, at_tau = np.divmod(index, n_tau)
        _, projected = likelihood.projections(residual)  # (G, m, K, p)
        rows = np.arange(chunk.shape[0])[:, None]
        u = projected[groups[None], rows, k]  # (m, G, p)
        chosen = covariance[groups[None], k, at_tau]  # (m, G, p, p)
        normal = rng.standard_normal((chunk.shape[0], n_groups, n_basis))
        out[start : start + block] = np.einsum("mgpq,mgq->mgp", chosen, u) + np.einsum(
            "mgpq,mgq->mgp", root[groups[None], k, at_tau], normal
        )
    # a group without data has no discrepancy to carry
    out[:, ~likelihood.used.any(axis=0).reshape(-1)] = np.nan
    return out


def variance_components(
    fit: DiscrepancyFit, features: Features, loo_rms: np.ndarray, operating: Mapping[str, np.ndarray]
) -> dict[str, np.ndarray]:
    """Each feature's posterior-predictive variance (op, channel, harmonic) by source.

    ``discrepancy`` is the posterior variance of delta at the run (beta's
    posterior covariance, which carries tau's and the parameters'
    uncertainty); ``parameters`` the spread of the emulated feature over
    posterior draws; ``model_error`` the iid model error at its posterior
    median; ``noise`` and ``emulator`` those of the likelihood. What the
    discrepancy's mean shifts is not a variance: the summary gives it apart
    (``rms_mean``).
    """
    sd = fit.discrepancy.sd_at(operating["pinion_speed"], operating["drive_torque"])
    return {
        "parameters": fit.parameter_variance,
        "discrepancy": sd**2,
        "model_error": np.broadcast_to(fit.sigma_median[None] ** 2, features.used.shape),
        "noise": features.noise_variance,
        "emulator": loo_rms**2,
    }


def discrepancy_summary(
    fit: DiscrepancyFit, features: Features, loo_rms: np.ndarray, operating: Mapping[str, np.ndarray]
) -> dict[str, Any]:
    """The ``discrepancy`` entry of the summary: tau and delta per group, the variance shares per channel.

    ``share`` is the discrepancy's share of the posterior-predictive variance
    of each channel's features (:func:`variance_components`), ``rms_mean``
    the size of the shift its mean makes (log amplitude).
    """
    used = features.used
    components = variance_components(fit, features, loo_rms, operating)
    mean = fit.discrepancy.mean_at(operating["pinion_speed"], operating["drive_torque"])
    sd = fit.discrepancy.sd_at(operating["pinion_speed"], operating["drive_torque"])
    groups: dict[str, Any] = {}
    channels: dict[str, Any] = {}
    rms: dict[str, float] = {}  # root mean square of delta's posterior mean over the features used
    for c, channel in enumerate(HARMONIC_CHANNELS):
        for h in range(used.shape[2]):
            if used[:, c, h].any():
                q05, q50, q95 = (float(v) for v in fit.tau_quantiles[c, h])
                groups[f"{channel}_mesh{h + 1}"] = {
                    "tau": {"q05": q05, "q50": q50, "q95": q95},
                    "mean": [float(v) for v in mean[:, c, h]],
                    "sd": [float(v) for v in sd[:, c, h]],
                }
        if used[:, c].any():
            totals = {name: float(value[:, c][used[:, c]].sum()) for name, value in components.items()}
            whole = sum(totals.values())
            channels[channel] = {name: value / whole for name, value in totals.items()}
            rms[channel] = float(np.sqrt(np.mean(mean[:, c][used[:, c]] ** 2)))
    return {
        "groups": groups,
        "share": {channel: entry["discrepancy"] for channel, entry in channels.items()},
        "variance_shares": channels,
        "rms_mean": rms,
        "basis": list(BASIS_NAMES),
        "speed_range": list(fit.discrepancy.basis.speed_range),
        "torque_range": list(fit.discrepancy.basis.torque_range),
        "tau_range": list(fit.tau_range),
        "units": LOG_UNITS,
    }


def discrepancy_dataset(fit: DiscrepancyFit, operating: Mapping[str, np.ndarray]) -> xr.Dataset:
    """The variables of the discrepancy added to ``posterior.nc`` (what :func:`read_discrepancy` reads)."""
    fitted = fit.discrepancy
    mean = fitted.mean_at(operating["pinion_speed"], operating["drive_torque"])
    sd = fitted.sd_at(operating["pinion_speed"], operating["drive_torque"])
    groups = ("channel", "harmonic")
    data = {
        "discrepancy_beta_mean": (groups + ("basis",), fitted.beta_mean, {"units": LOG_UNITS}),
        "discrepancy_beta_covariance": (groups + ("basis", "basis_2"), fitted.beta_covariance, {"units": "1"}),
        "discrepancy_tau": (groups + ("quantile",), fit.tau_quantiles, {"units": LOG_UNITS}),
        "discrepancy_mean": (("op",) + groups, mean, {"units": LOG_UNITS}),
        "discrepancy_sd": (("op",) + groups, sd, {"units": LOG_UNITS}),
    }
    dataset = xr.Dataset(
        data,
        coords={
            "channel": list(HARMONIC_CHANNELS),
            "harmonic": np.arange(1, fitted.beta_mean.shape[1] + 1),
            "basis": list(BASIS_NAMES),
            "basis_2": list(BASIS_NAMES),
            "quantile": [0.05, 0.5, 0.95],
        },
    )
    dataset.attrs.update(
        discrepancy_speed_range=json.dumps(list(fitted.basis.speed_range)),
        discrepancy_speed_units="rpm",
        discrepancy_torque_range=json.dumps(list(fitted.basis.torque_range)),
        discrepancy_torque_units="N m",
        discrepancy_basis="phi = (1, s, t, s^2); s, t: pinion speed and drive torque scaled to [-1, 1] over the ranges",
    )
    return dataset


def read_discrepancy(posterior: xr.Dataset) -> Discrepancy:
    """The fitted discrepancy of a calibration's ``posterior.nc`` (a fit with ``discrepancy=True``).

    Raises
    ------
    CalibrationError
        The file holds no discrepancy.

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.calibration.discrepancy import DiscrepancyBasis
    >>> mean = np.zeros((3, 1, 4)); mean[..., 1] = 0.2
    >>> fit = DiscrepancyFit(Discrepancy(DiscrepancyBasis((1000.0, 3000.0), (6000.0, 6000.0)), mean,
    ...                      np.zeros((3, 1, 4, 4))), np.zeros((3, 1, 3)), np.zeros((3, 1)), np.zeros((1, 3, 1)),
    ...                      (0.005, 3.0))
    >>> saved = discrepancy_dataset(fit, {"pinion_speed": np.array([3000.0]), "drive_torque": np.array([6000.0])})
    >>> float(read_discrepancy(saved).mean_at([3000.0], [6000.0])[0, 0, 0])
    0.2
    """
    if "discrepancy_beta_mean" not in posterior:
        raise CalibrationError("posterior: no discrepancy (calibrated without discrepancy=True)")
    attrs = posterior.attrs
    speed_low, speed_high = (float(v) for v in json.loads(attrs["discrepancy_speed_range"]))
    torque_low, torque_high = (float(v) for v in json.loads(attrs["discrepancy_torque_range"]))
    basis = DiscrepancyBasis((speed_low, speed_high), (torque_low, torque_high))
    return Discrepancy(
        basis,
        posterior["discrepancy_beta_mean"].values.astype(float),
        posterior["discrepancy_beta_covariance"].values.astype(float),
    )


__all__ = [
    "Discrepancy",
    "DiscrepancyFit",
    "discrepancy_dataset",
    "discrepancy_summary",
    "fit_discrepancy",
    "joint_beta_draws",
    "read_discrepancy",
    "variance_components",
]
