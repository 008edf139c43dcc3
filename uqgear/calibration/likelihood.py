"""The likelihood: the rig campaign's features with their noise, the parameter box, and the emulated log likelihood.

The observed features of each run and their sensor noise, the box of the
sampled vector (global parameters, then each run's T2), and the Gaussian
likelihood of the log features on one stage's emulators with the relative
model error of each (channel, harmonic) group integrated out on a grid (the
variances are described in :mod:`uqgear.calibration`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..physics.design import Design
from .emulator import JointEmulator, PolynomialEmulator
from .errors import CalibrationError
from .harmonics import HARMONIC_CHANNELS, observed_harmonics

#: Operating-point variables of the rig file that the calibration uses.
OPERATING_VARIABLES = ("pinion_speed", "drive_torque", "adhesion_torque_lower", "adhesion_torque_upper")


@dataclass
class Features:
    """Observed features of a rig campaign and their place in the likelihood.

    All arrays are over (op, channel, harmonic), the channels those of
    :data:`HARMONIC_CHANNELS`.
    """

    #: :func:`observed_harmonics` of the campaign.
    observed: xr.Dataset
    #: Whether each feature enters the likelihood.
    used: np.ndarray
    #: Log observed amplitude (0 where not used).
    log_observed: np.ndarray
    #: Sensor-noise variance of the log amplitude (1 where not used).
    noise_variance: np.ndarray
    #: Grid of the relative model error (log-uniform prior).
    model_error_grid: np.ndarray


def observed_features(
    rig: xr.Dataset,
    design: Design,
    *,
    channels: Sequence[str],
    n_harmonics: int,
    min_snr: float,
    model_error_range: tuple[float, float],
) -> Features:
    """The features of ``rig`` that enter the likelihood.

    Raises
    ------
    CalibrationError
        No feature with a signal-to-noise ratio of at least ``min_snr``.
    """
    observed = observed_harmonics(rig, design, channels=channels, n_harmonics=n_harmonics)
    amplitude = observed["amplitude"].values
    noise = observed["amplitude_std"].values
    with np.errstate(divide="ignore", invalid="ignore"):
        snr = amplitude / noise
        log_amplitude = np.log(amplitude)
    channel_used = np.array([name in channels for name in HARMONIC_CHANNELS])
    used = np.isfinite(log_amplitude) & np.isfinite(snr) & (snr >= min_snr) & channel_used[None, :, None]
    if not used.any():
        raise CalibrationError(
            f"rig data: no mesh-harmonic feature with signal-to-noise ratio >= "
            f"{min_snr:g} in channels {', '.join(channels)}"
        )
    return Features(
        observed=observed,
        used=used,
        log_observed=np.where(used, log_amplitude, 0.0),
        noise_variance=np.where(used, (noise / np.where(used, amplitude, 1.0)) ** 2, 1.0),
        model_error_grid=np.geomspace(model_error_range[0], model_error_range[1], 32),
    )


def operating_points(rig: xr.Dataset) -> dict[str, np.ndarray]:
    """Speed, drive torque and a-priori adhesion-torque interval of each run."""
    return {name: rig[name].values.astype(float) for name in OPERATING_VARIABLES}


def prior_box(
    bounds: Mapping[str, tuple[float, float]], parameters: Sequence[str], operating: Mapping[str, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper prior bounds of the sampled vector: the global parameters, then each run's T2."""
    lower = np.array([bounds[name][0] for name in parameters] + list(operating["adhesion_torque_lower"]))
    upper = np.array([bounds[name][1] for name in parameters] + list(operating["adhesion_torque_upper"]))
    # a run with a fixed T2 (lower == upper) still gets a tiny box so the emulator input is defined
    degenerate = upper - lower <= 1e-9 * np.maximum(np.abs(upper), 1.0)
    upper = np.where(degenerate, lower * (1 + 1e-9) + 1e-9, upper)
    return lower, upper


class StageLikelihood:
    """Log likelihood on one stage's emulators, at points of the stage box scaled to [0, 1].

    Parameters
    ----------
    box_lower, box_upper : array (n_dim,)
        The stage's box (global parameters, then each run's T2).
    emulators : sequence of PolynomialEmulator
        One per run, fitted on the box scaled to [-1, 1].
    loo : array (op, features)
        Leave-one-out RMS error of each run's emulator features.
    features : Features
        The observed features.
    n_global : int
        Number of global parameters.
    """

    def __init__(
        self,
        box_lower: np.ndarray,
        box_upper: np.ndarray,
        emulators: Sequence[PolynomialEmulator],
        loo: np.ndarray,
        features: Features,
        n_global: int,
    ) -> None:
        self.box_lower, self.box_upper = box_lower.copy(), box_upper.copy()
        self.n_dim = self.box_lower.size
        self._emulators, self._loo, self._n_global = tuple(emulators), loo, n_global
        self.emulator = JointEmulator(emulators, n_global)
        self.log_observed = features.log_observed
        n_op = len(emulators)
        self.shape = (n_op, len(HARMONIC_CHANNELS), features.used.shape[2])
        loo_variance = loo.reshape(self.shape) ** 2
        #: Leave-one-out RMS error of the emulated log features (op, channel, harmonic).
        self.loo_rms = np.sqrt(loo_variance)
        variance = np.where(features.used, features.noise_variance + loo_variance, 1.0)
        total = variance[None] + features.model_error_grid[:, None, None, None] ** 2  # (K, op, C, H)
        used = features.used[None]
        self.inverse_total = np.where(used, 1.0 / total, 0.0)
        self.log_normaliser = np.where(used, -0.5 * np.log(2.0 * np.pi * total), 0.0).sum(axis=1)  # (K, C, H)

    def with_features(self, features: Features) -> StageLikelihood:
        """The likelihood of other observed features (a corrected copy) on the same box and emulators."""
        return StageLikelihood(self.box_lower, self.box_upper, self._emulators, self._loo, features, self._n_global)

    def to_physical(self, unit: np.ndarray) -> np.ndarray:
        """Physical values of unit-box points, inside the box.

        ``lower + 1 * (upper - lower)`` can round one ulp past ``upper``; the
        values go to the model as design keys, validated like a user's input,
        so they are clipped to the box (which lies inside the design's ranges).
        """
        return np.clip(self.box_lower + unit * (self.box_upper - self.box_lower), self.box_lower, self.box_upper)

    def to_unit(self, physical: np.ndarray) -> np.ndarray:
        """Unit-box coordinates of physical points."""
        return (physical - self.box_lower) / (self.box_upper - self.box_lower)

    def emulate(self, unit: np.ndarray) -> np.ndarray:
        """Emulated log features (M, n_op, channel, harmonic) at stage-box unit points (M, n_dim)."""
        z = 2.0 * np.atleast_2d(unit) - 1.0
        return self.emulator.predict(z).reshape(z.shape[0], *self.shape)

    def group_terms(self, residual: np.ndarray) -> np.ndarray:
        """Log likelihood per (point, model-error grid value, channel, harmonic), summed over runs."""
        count = residual.shape[0]
        n_op = self.shape[0]
        squares = (residual**2).reshape(count, n_op, -1)
        inverse = self.inverse_total.reshape(self.inverse_total.shape[0], n_op, -1)
        # sum over runs for each (grid value, feature group)
        weighted = np.matmul(squares.transpose(2, 0, 1), inverse.transpose(2, 1, 0))  # (g, M, K)
        return self.log_normaliser[None] - 0.5 * weighted.transpose(1, 2, 0).reshape(
            count, inverse.shape[0], *residual.shape[2:]
        )

    def group_log_likelihood(self, residual: np.ndarray) -> np.ndarray:
        """Log likelihood per (point, channel, harmonic) group, the model error integrated out on its
        log-uniform prior (equal weights on a log-spaced grid)."""
        terms = self.group_terms(residual)
        peak = terms.max(axis=1)
        return peak + np.log(np.exp(terms - peak[:, None]).mean(axis=1))

    def log_likelihood(self, unit: np.ndarray) -> np.ndarray:
        """Log likelihood at unit-box points (M, n_dim); -inf outside the box."""
        unit = np.atleast_2d(unit)
        result = np.full(unit.shape[0], -np.inf)
        inside = np.all((unit >= 0.0) & (unit <= 1.0), axis=1)
        if inside.any():
            predicted = self.emulate(unit[inside])
            residual = self.log_observed[None] - predicted
            result[inside] = self.group_log_likelihood(residual).sum(axis=(1, 2))
        return result
