"""Sim-to-real gap diagnosis: where the model and the rig disagree, which
unmodelled effect causes it, and how far the gap shrinks once it is added.

Pipeline (issue 6, model.md section 6):

1. **Features.** The rig's records are reduced to the features of
   :mod:`uqgear.features` (mesh harmonics, sideband families per shaft, shaft
   and motor lines, a low-frequency band, RMS, kurtosis). The model's records
   go through *the same* processing: each run is simulated (steady state after
   a run-in), band-limited like the rig's anti-alias filter, resampled onto
   the rig's time grid and fed to the same window-weighted line fit. A steady
   response that repeats over a mesh period, a pinion or a gear revolution is
   simulated over that period only and tiled (exact for a periodic
   response); anything else over the full record.
2. **Predictive distribution.** A feature of the rig is the model's value plus
   sensor noise plus model error. A line amplitude is Rice distributed about
   the model's amplitude with a per-quadrature spread from the record's white
   noise floor (exact for the weighted least-squares fit) and a relative
   model error; band powers add the noise power. The *standardised
   discrepancy* of a feature is its probability integral transform mapped to
   a standard normal, so it is N(0, 1) where the model is right, also for
   lines at the noise floor (censoring is built in).
3. **Fit.** The nominal model (mesh stiffness scale, mesh damping ratio, STE
   amplitude, bearing stiffnesses; T2 of each run inside its interval) is fitted by
   robust least squares on the standardised discrepancies with priors from
   the nominal design (a Laplace approximation of its posterior): soft-L1 on
   the mesh harmonics first, each run's T2 profiled on a grid (T2 can move a
   run across a regime boundary), then a Cauchy loss on all line and band
   features so that what the model class cannot produce loses its pull.
   Every candidate effect is screened with its own parameters on top of the
   nominal fit, from a start grid read off the data's signature (run-out
   from the 1x TE line, stick-slip frequency from frequency-locked lines);
   the best is refitted with all parameters. A calibration posterior
   (``uqgear calibrate``) can give the nominal fit's start.
4. **Held-out scoring.** Leave-one-operating-point-out predictions (one Newton
   step from the full fit without that run, the held-out run's T2 profiled,
   the prediction itself re-simulated) give the gap map on held-out runs, a
   robust predictive density per candidate and the gap metric before and
   after adding the effect.
5. **Verdict.** ``none`` when the nominal model is within noise on held-out
   runs; otherwise the best candidate when it clearly beats the nominal
   model (predictive density gain beyond a penalty per extra parameter, a
   gap that shrinks by at least half); otherwise ``unexplained``.

This module does no plotting; :func:`diagnose` writes ``diagnosis.json``,
``diagnosis.nc`` and, through :mod:`uqgear.diagnosis_report`, ``report.html``.
"""

from __future__ import annotations

import json
import math
import multiprocessing
import os
import resource
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.signal
import scipy.special
import scipy.stats
import xarray as xr

from . import features as feature_module
from .design import Design
from .effects import EFFECTS, Effect, make_effect
from .errors import RigDataError, UqgearError
from .features import FEATURE_FAMILIES, SIGNAL_CHANNELS, feature_definitions
from .fileio import write_text_atomic
from .integration import _HISTORY_COLUMNS, _integrate_fast, steps_per_period
from .model import build_model
from .results import json_default, load_result, save_result
from .uncertainty import as_seed_sequence
from .virtual_rig import frequency_filter

#: Effects of the library that the diagnosis can name.
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
#: Possible verdicts.
VERDICTS: tuple[str, ...] = EFFECT_NAMES + ("none", "unexplained")

# Features compared with the model. The noise floor and the crest factor (a
# maximum, driven by single noise samples) describe the record, not the gear.
_COMPARED_EXCLUDED = ("noise_std", "crest_factor")

# Relative model error (standard deviation) by feature kind: line amplitudes,
# band powers (as amplitudes), the broadband RMS and kurtosis. With their true
# parameters and effect the model reproduces the reference campaigns' lines to
# well under 1 % (a few per cent for lines near the noise floor); 3 % leaves
# room for an independent rig without hiding a friction-sized change.
DEFAULT_MODEL_ERROR: dict[str, float] = {"line": 0.03, "band": 0.05, "rms": 0.03, "kurtosis": 0.05}

# Run-in simulated before the kept window: about 9 time constants of the
# slowest decay (about 17 ms on the reference design: a transient falls by 2e-5).
_RUN_IN = 0.15
# Guard on each side of a non-periodic window, so that the band-limiting
# filter's wrap-around stays outside the record.
_GUARD = 0.025
# Highest mesh-stiffness scale for which the step count is fixed in advance,
# so that finite-difference neighbours integrate on the same grid.
_MAX_STIFFNESS_SCALE = 1.5


class DiagnosisError(UqgearError):
    """A diagnosis or blind-test input is not valid (unknown effect, bad option)."""


# ---------------------------------------------------------------------------------------------- feature processing


class RunProcessor:
    """The rig's feature processing for one run (speed, sampling rate, record length), built once.

    Wraps the line fit and the spectral estimates of :mod:`uqgear.features`
    so that model records of many parameter sets go through exactly the
    processing that produced the rig's features, without rebuilding the
    least-squares basis for every record.

    Parameters
    ----------
    design : Design
    speed : float
        Pinion speed, rpm.
    fs : float
        Sampling rate, Hz.
    size : int
        Samples per record.
    options : mapping
        ``n_harmonics``, ``n_sidebands``, ``n_shaft_orders``, ``n_motor_lines``,
        ``low_band``, ``band_limit`` and ``window`` as in
        :func:`uqgear.features.extract_features`.
    """

    def __init__(self, design: Design, speed: float, fs: float, size: int, options: Mapping[str, Any]) -> None:
        self.speed = float(speed)
        self.fs = float(fs)
        self.size = int(size)
        self.definitions = feature_definitions(
            design, n_harmonics=options["n_harmonics"], n_sidebands=options["n_sidebands"],
            n_shaft_orders=options["n_shaft_orders"], n_motor_lines=options["n_motor_lines"])
        self.names = [definition.name for definition in self.definitions]
        self.columns = {name: index for index, name in enumerate(self.names)}
        self.line_columns = np.array([i for i, d in enumerate(self.definitions) if d.is_line], dtype=int)
        line_orders = np.array([self.definitions[i].order for i in self.line_columns])
        self.limit = options["band_limit"]
        self.low_band = tuple(options["low_band"])
        self.taper = feature_module._window(options["window"], self.size)
        self.fit = feature_module._LineFit(line_orders * self.speed / 60.0, self.fs, self.size, self.limit, self.taper)
        frequencies = np.fft.rfftfreq(self.size, 1.0 / self.fs)
        self.excluded = feature_module._excluded_bins(frequencies, self.speed, design, line_orders,
                                                      options["n_sidebands"], self.low_band, self.limit,
                                                      self.fs / self.size)
        self.line_noise = self._line_noise_scale()
        in_band = (frequencies >= self.low_band[0]) & (frequencies <= self.low_band[1])
        self._band_bins = np.flatnonzero(in_band)
        edge = (self._band_bins == 0) | ((self.size % 2 == 0) & (self._band_bins == self.size // 2))
        self._band_weights = np.where(edge, 1.0, 2.0)
        self._window_power = float(np.sum(self.taper ** 2))

    def features(self, records: np.ndarray) -> np.ndarray:
        """Feature values (R, F) of records (R, N); rows with a NaN sample are NaN."""
        records = np.atleast_2d(np.asarray(records, dtype=float))
        out = np.full((records.shape[0], len(self.definitions)), np.nan)
        usable = ~np.isnan(records).any(axis=1)
        if usable.any():
            out[usable] = feature_module._block_features(
                records[usable], self.fit, self.excluded, self.fs, self.taper, self.low_band, self.columns,
                self.line_columns, len(self.definitions))
        return out

    def model_features(self, records: np.ndarray) -> np.ndarray:
        """Features (R, F) of noise-free model records (R, N) without NaN.

        The same line fit, low-band power, RMS and kurtosis as :meth:`features`;
        the noise floor and the crest factor, which describe noisy records,
        are left NaN (they are not compared), which saves most of the time.
        """
        records = np.atleast_2d(np.asarray(records, dtype=float))
        out = np.full((records.shape[0], len(self.definitions)), np.nan)
        out[:, self.line_columns] = self.fit.amplitudes(records)
        centred = records - records.mean(axis=1, keepdims=True)
        spectrum = np.fft.rfft(centred * self.taper, axis=1)
        # one-sided periodogram density (scipy's 'density' scaling), summed over the band
        density = np.abs(spectrum[:, self._band_bins]) ** 2 * (self._band_weights / (self.fs * self._window_power))
        out[:, self.columns["low_band_rms"]] = np.sqrt(density.sum(axis=1) * self.fs / self.size)
        mean_square = np.mean(centred ** 2, axis=1)
        out[:, self.columns["rms"]] = np.sqrt(mean_square)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[:, self.columns["kurtosis"]] = np.where(mean_square > 0,
                                                        np.mean(centred ** 4, axis=1) / mean_square ** 2, np.nan)
        return out

    def _line_noise_scale(self) -> np.ndarray:
        """Per-quadrature standard deviation of each line's fitted amplitude for unit white noise.

        The weighted least-squares coefficients are G^-1 (B w)^T x with
        G = (B w)^T B, so their covariance for white noise of unit variance
        is G^-1 (B w)^T (B w) G^-1; a line's two quadratures share the mean of
        their variances (NaN for lines outside the band).
        """
        scale = np.full(len(self.definitions), np.nan)
        fit = self.fit
        if not fit.n_centres:
            return scale
        inverse_gram = scipy.linalg.cho_solve(fit.factor, np.eye(fit.weighted.shape[1]))
        covariance = inverse_gram @ (fit.weighted.T @ fit.weighted) @ inverse_gram
        diagonal = np.diag(covariance)
        per_centre = np.sqrt(0.5 * (diagonal[1:1 + fit.n_centres] + diagonal[1 + fit.n_centres:]))
        line_scale = np.full(self.line_columns.size, np.nan)
        line_scale[fit.inside] = per_centre[fit.groups]
        scale[self.line_columns] = line_scale
        return scale



# ---------------------------------------------------------------------------------------------- model records

#: How the steady response of a model with an effect repeats: over a mesh
#: period, a pinion or a gear revolution, or not at all (simulated in full).
PERIODICITIES = ("mesh", "pinion", "gear", "free")


@dataclass
class SimulatedRun:
    """Model records of one run on the rig's time grid, and how they were obtained."""

    records: dict[str, np.ndarray]
    periodic: bool
    window: str


class CampaignSimulator:
    """Model records of a campaign's runs on the rig's time grid.

    Each run is integrated from static equilibrium over a run-in, then over
    one period of its steady response (a mesh period, a pinion or a gear
    revolution, by the effects present), which is tiled over the record; a
    run whose state does not return after that period (a quasi-periodic or
    chaotic response, or an effect at a frequency of its own) is simulated
    over the whole record instead. Displacements are band-limited like the
    rig's anti-alias filter and accelerations taken as their second
    derivative in the frequency domain (sampling y'' directly would alias
    the jumps of the mesh stiffness), then resampled onto the rig's grid.

    Parameters
    ----------
    design : Design
        Nominal design.
    speeds, drive_torques : array_like
        Per run: pinion speed (rpm) and drive torque (N m).
    fs : float
        Rig sampling rate, Hz.
    size : int
        Samples per rig record.
    channels : sequence of str
        Rig channels to produce.
    steps_per_mode : int
        RK4 steps per period of the fastest mode.
    """

    def __init__(self, design: Design, speeds: Sequence[float], drive_torques: Sequence[float], fs: float,
                 size: int, channels: Sequence[str], steps_per_mode: int = 24) -> None:
        self.design = design
        self.speeds = np.asarray(speeds, dtype=float)
        self.drive_torques = np.asarray(drive_torques, dtype=float)
        self.fs = float(fs)
        self.size = int(size)
        self.duration = self.size / self.fs
        self.channels = tuple(channels)
        self.steps_per_mode = int(steps_per_mode)
        self.passband = self.fs / 2.56
        self.stopband = self.fs / 2.0
        self.rig_time = np.arange(self.size) / self.fs
        stiff = design.replace(k1=min(design.k1 * 2.0, 1e13), k2=min(design.k2 * 2.0, 1e13))
        self.samples_per_period = []
        for speed, torque in zip(self.speeds, self.drive_torques):
            # every neighbour of a fit integrates on the same grid: the steps of the stiffest model,
            # kept every step or (at twice the stop band and more) every other step
            steps = steps_per_period(build_model(stiff, speed, torque, torque * design.z2 / design.z1,
                                                 mesh_stiffness_scale=_MAX_STIFFNESS_SCALE), self.steps_per_mode)
            steps += steps % 2
            mesh_frequency = design.z1 * speed / 60.0
            half = steps // 2
            self.samples_per_period.append(half if half * mesh_frequency >= 2.2 * self.stopband else steps)

    def mesh_frequency(self, op: int) -> float:
        return self.design.z1 * self.speeds[op] / 60.0

    def window_periods(self, periodicity: str, op: int) -> int:
        """Mesh periods in one period of the steady response."""
        if periodicity == "mesh":
            return 2
        if periodicity == "pinion":
            return self.design.z1
        if periodicity == "gear":
            return self.design.z2
        return int(math.ceil((self.duration + 2 * _GUARD) * self.mesh_frequency(op))) + 1

    def run(self, op: int, design: Design, mesh_stiffness_scale: float, adhesion_torque: float,
            effects: Sequence[Effect], periodicity: str) -> SimulatedRun:
        """Model records of run ``op`` (dict channel -> (N,) array on the rig grid).

        ``periodicity`` is the expected period of the steady response; a run
        found not to repeat over it is simulated in full.
        """
        if periodicity not in PERIODICITIES:
            raise DiagnosisError(f"periodicity: expected one of {', '.join(PERIODICITIES)}; got {periodicity!r}")
        if periodicity != "free":
            result = self._periodic(op, design, mesh_stiffness_scale, adhesion_torque, effects, periodicity)
            if result is not None:
                return result
        return self._free(op, design, mesh_stiffness_scale, adhesion_torque, effects)

    def _simulate(self, op: int, design: Design, scale: float, adhesion_torque: float, effects: Sequence[Effect],
                  n_periods: int, keep_periods: int) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """Displacements and TE over the kept periods, and the state at each kept period start.

        Calls the fast integrator directly: the full :func:`uqgear.simulate`
        Dataset (a dozen histories with attributes) costs as much as the
        integration of a short periodic window.
        """
        setup = build_model(design, float(self.speeds[op]), float(self.drive_torques[op]), float(adhesion_torque),
                            mesh_stiffness_scale=float(scale), effects=effects)
        history, poincare, _ = _integrate_fast(setup, n_periods, keep_periods, self.samples_per_period[op],
                                               self.steps_per_mode, setup.static_state())
        columns = {name: index for index, name in enumerate(_HISTORY_COLUMNS)}
        signals = {"y1": history[:, columns["y1"]], "y2": history[:, columns["y2"]], "x": history[:, columns["x"]],
                   "te": history[:, columns["x"]] - history[:, columns["y1"]] + history[:, columns["y2"]]
                   + history[:, columns["ste"]]}
        return signals, poincare

    def _periodic(self, op: int, design: Design, scale: float, adhesion_torque: float, effects: Sequence[Effect],
                  periodicity: str) -> SimulatedRun | None:
        f_mesh = self.mesh_frequency(op)
        window = self.window_periods(periodicity, op)
        # a run-in of whole windows puts the kept window's start at the response's phase 0
        run_in = int(math.ceil(_RUN_IN * f_mesh))
        signals, poincare = self._simulate(op, design, scale, adhesion_torque, effects, run_in + window + 1,
                                           window + 1)
        per_period = self.samples_per_period[op]
        kept = window * per_period
        # the state one window later must be where it started, else the response is not periodic
        spread = np.array([np.ptp(signals[name][:kept]) for name in ("y1", "y2", "x")])
        change = np.abs(poincare[window, :3] - poincare[0, :3])
        if np.any(change > 1e-3 * np.maximum(spread, 1e-12)):
            return None
        period = window / f_mesh
        rate = per_period * f_mesh
        # upsampled grid fine enough for linear interpolation of the band-limited signal
        factor = max(1, int(math.ceil(4.0 * self.fs / rate)))
        grid = np.arange(kept * factor) * (period / (kept * factor))
        records = {}
        for channel in self.channels:
            raw, order = self._raw(signals, channel)
            spectrum = np.fft.rfft(raw[:kept] - raw[:kept].mean())
            spectrum *= frequency_filter(kept, rate, self.passband, self.stopband, order)
            fine = np.fft.irfft(spectrum, n=kept * factor) * factor
            records[channel] = np.interp(self.rig_time, grid, fine, period=period)
        return SimulatedRun(records, True, periodicity)

    def _free(self, op: int, design: Design, scale: float, adhesion_torque: float,
              effects: Sequence[Effect]) -> SimulatedRun:
        f_mesh = self.mesh_frequency(op)
        window = self.window_periods("free", op)
        run_in = int(math.ceil(_RUN_IN * f_mesh))
        signals, _ = self._simulate(op, design, scale, adhesion_torque, effects, run_in + window, window)
        rate = self.samples_per_period[op] * f_mesh
        size = signals["te"].size
        time = np.arange(size) / rate
        taper = np.ones(size)
        edge = 0.6 * _GUARD
        left, right = time < edge, time > time[-1] - edge
        taper[left] = 0.5 * (1.0 - np.cos(np.pi * time[left] / edge))
        taper[right] = 0.5 * (1.0 - np.cos(np.pi * (time[-1] - time[right]) / edge))
        factor = max(1, int(math.ceil(4.0 * self.fs / rate)))
        grid = np.arange(size * factor) / (rate * factor)
        records = {}
        for channel in self.channels:
            raw, order = self._raw(signals, channel)
            centred = (raw - raw.mean()) * taper
            spectrum = np.fft.rfft(centred) * frequency_filter(size, rate, self.passband, self.stopband, order)
            fine = np.fft.irfft(spectrum, n=size * factor) * factor
            records[channel] = np.interp(self.rig_time + _GUARD, grid, fine)
        return SimulatedRun(records, False, "free")

    @staticmethod
    def _raw(signals: Mapping[str, np.ndarray], channel: str) -> tuple[np.ndarray, int]:
        if channel == "te":
            return signals["te"], 0
        return signals["y1" if channel == "acc_pinion" else "y2"], 2


# ---------------------------------------------------------------------------------------------- discrepancies

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
    return NoiseModel(line_scale=processor.line_noise, band_power=np.array([band.mean(), band.std(ddof=1)]),
                      total_power=np.array([total.mean(), total.std(ddof=1)]),
                      kurtosis_spread=float(values[:, processor.columns["kurtosis"]].std(ddof=1)))


def _rice_moments(nu: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation of a Rice(nu, sigma) amplitude (stable for all nu/sigma)."""
    b2 = 0.25 * (nu / sigma) ** 2
    laguerre = (1.0 + 2.0 * b2) * scipy.special.ive(0, b2) + 2.0 * b2 * scipy.special.ive(1, b2)
    mean = sigma * math.sqrt(math.pi / 2.0) * laguerre
    variance = np.maximum(2.0 * sigma ** 2 + nu ** 2 - mean ** 2, 1e-300)
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
    columns: np.ndarray     # positions in the processor's feature vector

    @classmethod
    def from_processor(cls, processor: RunProcessor) -> "FeatureLayout":
        chosen = [i for i, d in enumerate(processor.definitions) if d.name not in _COMPARED_EXCLUDED]
        names = tuple(processor.definitions[i].name for i in chosen)
        families = tuple(processor.definitions[i].family for i in chosen)
        kinds = tuple(feature_kind(n, f) for n, f in zip(names, families))
        return cls(names, families, kinds, np.array(chosen, dtype=int))


def standardised_discrepancy(observed: np.ndarray, model: np.ndarray, noise_std: np.ndarray,
                             noise: Sequence[NoiseModel], layout: FeatureLayout,
                             model_error: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
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
        Relative model error per feature kind.

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
    sigma_noise = np.asarray(noise_std, dtype=float)[..., None]            # (n_op, n_channel, 1)
    line_scale = np.stack([n.line_scale[layout.columns] for n in noise])[:, None, :]   # (n_op, 1, F)
    band = np.stack([n.band_power for n in noise])[:, None, :]             # (n_op, 1, 2)
    total = np.stack([n.total_power for n in noise])[:, None, :]
    kurt_spread = np.array([n.kurtosis_spread for n in noise])[:, None]

    line = kinds == "line"
    if line.any():
        nu = np.abs(model[..., line])
        sigma = np.sqrt((sigma_noise * line_scale[..., line]) ** 2 + (model_error["line"] * nu) ** 2)
        sigma = np.maximum(sigma, 1e-300)
        z[..., line] = _line_discrepancy(observed[..., line], nu, sigma)
        scale[..., line] = sigma / np.maximum(sigma_noise * line_scale[..., line], 1e-300)
    for kind, moments in (("band", band), ("rms", total)):
        chosen = kinds == kind
        if not chosen.any():
            continue
        model_power = model[..., chosen] ** 2
        noise_power = sigma_noise ** 2 * moments[..., 0:1]
        # noise power scatter, model error, and the signal-noise cross term
        relative_scatter = moments[..., 1:2] / moments[..., 0:1]
        spread = np.sqrt((sigma_noise ** 2 * moments[..., 1:2]) ** 2 + (2.0 * model_error[kind] * model_power) ** 2
                         + 2.0 * model_power * noise_power * relative_scatter ** 2)
        spread = np.maximum(spread, 1e-300)
        z[..., chosen] = (observed[..., chosen] ** 2 - model_power - noise_power) / spread
        scale[..., chosen] = spread / np.maximum(sigma_noise ** 2 * moments[..., 1:2], 1e-300)
    chosen = kinds == "kurtosis"
    if chosen.any():
        index = layout.names.index("rms")
        power = model[..., index:index + 1] ** 2
        noise_power = sigma_noise ** 2 * total[..., 0:1]
        kurt = model[..., chosen]
        predicted = (kurt * power ** 2 + 6.0 * power * noise_power + 3.0 * noise_power ** 2) / \
            np.maximum((power + noise_power) ** 2, 1e-300)
        spread = np.sqrt((model_error["kurtosis"] * predicted) ** 2 + kurt_spread[..., None] ** 2)
        z[..., chosen] = (observed[..., chosen] - predicted) / spread
        scale[..., chosen] = spread / np.maximum(kurt_spread[..., None], 1e-300)
    return z, scale


def expected_rig_features(model: np.ndarray, noise_std: np.ndarray, noise: Sequence[NoiseModel],
                          layout: FeatureLayout) -> np.ndarray:
    """What a rig records on average for noise-free model features (..., n_op, n_channel, F).

    Line amplitudes: the Rice mean about the model's amplitude; band and
    broadband RMS: the noise power added; kurtosis: that of signal plus
    Gaussian noise. Used to judge how visible a model difference is.
    """
    model = np.asarray(model, dtype=float)
    out = np.full(model.shape, np.nan)
    kinds = np.array(layout.kinds)
    sigma_noise = np.asarray(noise_std, dtype=float)[..., None]
    line_scale = np.stack([n.line_scale[layout.columns] for n in noise])[:, None, :]
    band = np.stack([n.band_power[0] for n in noise])[:, None, None]
    total = np.stack([n.total_power[0] for n in noise])[:, None, None]
    line = kinds == "line"
    sigma = np.broadcast_to(np.maximum(sigma_noise * line_scale[..., line], 1e-300), model[..., line].shape)
    out[..., line] = _rice_moments(np.abs(model[..., line]), sigma)[0]
    for kind, power in (("band", band), ("rms", total)):
        chosen = kinds == kind
        out[..., chosen] = np.sqrt(model[..., chosen] ** 2 + sigma_noise ** 2 * power)
    chosen = kinds == "kurtosis"
    if chosen.any():
        index = layout.names.index("rms")
        signal_power = model[..., index:index + 1] ** 2
        noise_power = sigma_noise ** 2 * total
        out[..., chosen] = ((model[..., chosen] * signal_power ** 2 + 6.0 * signal_power * noise_power
                             + 3.0 * noise_power ** 2) / np.maximum((signal_power + noise_power) ** 2, 1e-300))
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
    normal = (math.log1p(-_OUTLIER_SHARE) - 0.5 * z ** 2 - 0.5 * math.log(2.0 * math.pi)
              - np.log(np.asarray(scale, dtype=float)))
    floor = math.log(_OUTLIER_SHARE / (2.0 * _OUTLIER_WIDTH))
    return np.logaddexp(normal, floor)


# ---------------------------------------------------------------------------------------------- parameters

@dataclass(frozen=True)
class ParameterSpec:
    """A fitted parameter: transform, prior, bounds and the optimiser's unit.

    The optimiser works with ``v = (g(x) - g(centre)) / unit`` where ``g`` is
    the identity or the logarithm; with a prior (normal in g) the unit is its
    standard deviation, so the prior's residual is ``v`` itself.
    """

    name: str
    log: bool
    centre: float
    unit: float
    lower: float
    upper: float
    prior: bool

    def to_optimiser(self, value: float) -> float:
        value = min(max(value, self.lower), self.upper)
        g = math.log(value / self.centre) if self.log else value - self.centre
        return g / self.unit

    def from_optimiser(self, v: float) -> float:
        g = v * self.unit
        return self.centre * math.exp(g) if self.log else self.centre + g

    def bounds(self) -> tuple[float, float]:
        return self.to_optimiser(self.lower), self.to_optimiser(self.upper)


def nominal_parameters(design: Design) -> list[ParameterSpec]:
    """The nominal model's calibration parameters with priors from the design.

    Mesh stiffness scale (log-normal, 15 %), mesh damping ratio (50 %), STE
    amplitude (40 %), bearing stiffnesses (25 %), bounded at about three
    standard deviations.
    """
    return [
        ParameterSpec("mesh_stiffness_scale", True, 1.0, 0.15, 0.6, _MAX_STIFFNESS_SCALE, True),
        ParameterSpec("zeta_mesh", True, design.zeta_mesh, 0.5, design.zeta_mesh / 5.0,
                      min(design.zeta_mesh * 5.0, 0.9), True),
        ParameterSpec("ste_amplitude", True, max(design.ste_amplitude, 1e-7), 0.4,
                      max(design.ste_amplitude, 1e-7) / 3.0, max(design.ste_amplitude, 1e-7) * 3.0, True),
        ParameterSpec("k1", True, design.k1, 0.25, design.k1 / 2.0, design.k1 * 2.0, True),
        ParameterSpec("k2", True, design.k2, 0.25, design.k2 / 2.0, design.k2 * 2.0, True),
    ]


@dataclass(frozen=True)
class Candidate:
    """One way of adding a library effect: fixed choices, fitted parameters, periodicity.

    Attributes
    ----------
    effect : str
        Library name.
    label : str
        Unique label (effect and choices), e.g. ``eccentricity[gear]``.
    choices : tuple of (str, object)
        Fixed settings (shaft, gear, bearing, tooth, phases that amplitude
        features cannot see).
    fitted : tuple of ParameterSpec
        Effect parameters fitted (named ``EFFECT.PARAM``).
    starts : tuple of dict
        Starting values tried before the fit (signature grid).
    periodicity : str
        One of :data:`PERIODICITIES`.
    """

    effect: str
    label: str
    choices: tuple[tuple[str, object], ...]
    fitted: tuple[ParameterSpec, ...]
    starts: tuple[dict[str, float], ...]
    periodicity: str

    def make(self, values: Mapping[str, float]) -> Effect:
        """The effect with fitted values ``{EFFECT.PARAM: value}`` and the fixed choices."""
        settings: dict[str, object] = dict(self.choices)
        settings.update({spec.name.split(".", 1)[1]: values[spec.name] for spec in self.fitted})
        return make_effect(self.effect, settings)


def _effect_spec(effect: str, parameter: str, unit: float, lower: float | None = None,
                 upper: float | None = None) -> ParameterSpec:
    definition = EFFECTS[effect].PARAMETERS[parameter]
    low = definition.lower if lower is None else lower
    high = definition.upper if upper is None else upper
    return ParameterSpec(f"{effect}.{parameter}", False, 0.0, unit, low, high, False)


def _strength_spec(effect: str, parameter: str, centre: float, upper: float | None = None) -> ParameterSpec:
    """An effect's strength (amplitude, depth, coefficient) on a log scale.

    Differences and steps are then relative: an effect near the detection
    limit is fitted as well as a strong one (a fixed step would dwarf a
    weak amplitude). The lower bound, a millionth of ``centre``, stands for
    "absent".
    """
    definition = EFFECTS[effect].PARAMETERS[parameter]
    high = definition.upper if upper is None else upper
    return ParameterSpec(f"{effect}.{parameter}", True, centre, 1.0, centre * 1e-6, high, False)


def _grid(**axes: Sequence[float]) -> tuple[dict[str, float], ...]:
    keys = list(axes)
    points: list[dict[str, float]] = [{}]
    for key in keys:
        points = [{**point, key: float(value)} for point in points for value in axes[key]]
    return tuple(points)


def candidates_for(effect: str, design: Design, *, hints: Mapping[str, float] | None = None) -> list[Candidate]:
    """The candidate variants of one library effect for a design.

    Tooth numbers and phases relative to the record start do not change
    amplitude spectra, so tooth 0 and the adhesion phase 0 are fixed; the
    eccentricity and ripple phases (relative to the mesh) are fitted.

    Parameters
    ----------
    effect : str
        Library name.
    design : Design
    hints : mapping, optional
        Starting values read off the data's signature:
        ``eccentricity_pinion`` and ``eccentricity_gear`` (run-out amplitude,
        m, from the 1x shaft line of the transmission error) and
        ``adhesion_frequency`` (Hz, a low-frequency line common to the runs).
    """
    hints = dict(hints or {})
    if effect not in EFFECTS:
        raise DiagnosisError(f"effects: {effect!r} is not a library effect; expected one of {', '.join(EFFECTS)}")
    two_pi = 2.0 * math.pi
    phases = (0.5 * math.pi, 1.5 * math.pi)
    if effect == "eccentricity":
        fitted = (_strength_spec(effect, "amplitude", 1e-6, upper=1e-4),
                  _effect_spec(effect, "phase", 1.0, 0.0, two_pi), _strength_spec(effect, "kappa", 1e-3, upper=0.3))
        variants = []
        for shaft in ("pinion", "gear"):
            amplitude = float(np.clip(hints.get(f"eccentricity_{shaft}", 5e-6), 1e-9, 5e-5))
            # no modulation, or as much as the public campaign per metre of run-out (0.03 at 12 um)
            starts = _grid(**{"eccentricity.amplitude": (amplitude,), "eccentricity.phase": phases,
                              "eccentricity.kappa": (1e-9, min(2500.0 * amplitude, 0.1))})
            variants.append(Candidate(effect, f"eccentricity[{shaft}]", (("shaft", shaft),), fitted, starts,
                                      "pinion" if shaft == "pinion" else "gear"))
        return variants
    if effect == "tooth_damage":
        fitted = (_strength_spec(effect, "depth", 0.05, upper=0.9),)
        starts = _grid(**{"tooth_damage.depth": (0.005, 0.05, 0.4)})
        return [Candidate(effect, f"tooth_damage[{gear}]", (("gear", gear), ("tooth", 0.0)), fitted, starts,
                          "pinion" if gear == "pinion" else "gear") for gear in ("pinion", "gear")]
    if effect == "friction":
        fitted = (_strength_spec(effect, "coefficient", 0.03),)
        return [Candidate(effect, "friction", (), fitted, _grid(**{"friction.coefficient": (0.03, 0.1)}),
                          "mesh")]
    if effect == "torque_ripple":
        if design.motor_pole_pairs is None:
            return []
        fitted = (_strength_spec(effect, "amplitude", 0.01, upper=0.3), _effect_spec(effect, "phase", 1.0, 0.0, two_pi))
        starts = _grid(**{"torque_ripple.amplitude": (0.003, 0.05), "torque_ripple.phase": phases})
        return [Candidate(effect, "torque_ripple", (), fitted, starts, "pinion")]
    if effect == "adhesion_oscillation":
        fitted = (_strength_spec(effect, "amplitude", 0.01, upper=0.3),
                  _effect_spec(effect, "frequency", 2.0, 1.0, 100.0))
        frequencies = (hints["adhesion_frequency"],) if hints.get("adhesion_frequency") else (8.0, 30.0)
        starts = _grid(**{"adhesion_oscillation.amplitude": (0.003, 0.03), "adhesion_oscillation.frequency": frequencies})
        return [Candidate(effect, "adhesion_oscillation", (("phase", 0.0),), fitted, starts, "free")]
    fitted = (_strength_spec(effect, "clearance", 2e-5),)
    starts = _grid(**{"bearing_clearance.clearance": (1e-6, 1e-5, 1e-4)})
    return [Candidate(effect, f"bearing_clearance[{bearing}]", (("bearing", bearing),), fitted, starts, "mesh")
            for bearing in ("pinion", "gear", "both")]


# ---------------------------------------------------------------------------------------------- the rig case

#: Options of the feature processing (as :func:`uqgear.features.extract_features`).
FEATURE_OPTIONS: dict[str, Any] = {"n_harmonics": 3, "n_sidebands": 3, "n_shaft_orders": 3, "n_motor_lines": 2,
                                   "low_band": (2.0, 80.0), "window": "hann"}


@dataclass
class RigCase:
    """A rig campaign prepared for diagnosis: features, noise, processing and simulator."""

    rig: xr.Dataset
    design: Design
    channels: tuple[str, ...]
    speeds: np.ndarray
    drive_torques: np.ndarray
    adhesion_lower: np.ndarray
    adhesion_upper: np.ndarray
    fs: float
    size: int
    processors: list[RunProcessor]
    layout: FeatureLayout
    observed: np.ndarray          # (n_op, n_channel, F) compared features
    observed_all: np.ndarray      # (n_op, n_channel, all features)
    noise_std: np.ndarray         # (n_op, n_channel)
    noise: list[NoiseModel]
    usable: np.ndarray            # (n_op, n_channel)
    simulator: CampaignSimulator
    model_error: dict[str, float]
    executor: "RunExecutor | None" = None

    @property
    def n_op(self) -> int:
        return int(self.speeds.size)

    def mask(self) -> np.ndarray:
        """Features that enter the comparison: usable runs and finite rig features."""
        return np.isfinite(self.observed) & self.usable[..., None]

    def execute(self, tasks: Sequence["RunTask"]) -> list[tuple[np.ndarray, bool]]:
        """Simulate and reduce runs (through the executor when one is attached)."""
        if self.executor is not None:
            return self.executor.map(tasks)
        return [execute_run(self, task) for task in tasks]


def prepare_case(rig: xr.Dataset, design: Design, *, seed: np.random.SeedSequence,
                 model_error: Mapping[str, float] | None = None, steps_per_mode: int = 24) -> RigCase:
    """Features, noise models, processors and simulator of a validated rig Dataset."""
    errors = dict(DEFAULT_MODEL_ERROR)
    if model_error is not None:
        unknown = sorted(set(model_error) - set(errors))
        if unknown:
            raise DiagnosisError(f"model_error.{unknown[0]}: unknown feature kind; expected {', '.join(errors)}")
        for key, value in model_error.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value < 1.0:
                raise DiagnosisError(f"model_error.{key}: expected a relative error in [0, 1); got {value!r}")
            errors[key] = float(value)
    channels = tuple(name for name in SIGNAL_CHANNELS if name in rig.data_vars)
    fs = feature_module.sampling_rate(rig["time"].values, where="rig data: time")
    size = int(rig.sizes["time"])
    options = dict(FEATURE_OPTIONS, band_limit=feature_module.DEFAULT_BAND_FRACTION * fs)
    speeds = np.asarray(rig["pinion_speed"].values, dtype=float)
    processors: list[RunProcessor] = []
    cache: dict[float, RunProcessor] = {}
    for speed in speeds:
        if float(speed) not in cache:
            cache[float(speed)] = RunProcessor(design, float(speed), fs, size, options)
        processors.append(cache[float(speed)])
    layout = FeatureLayout.from_processor(processors[0])
    observed_all = np.stack([np.stack([processors[op].features(np.asarray(rig[channel].values[op], dtype=float)[None])[0]
                                       for channel in channels]) for op in range(speeds.size)])
    noise_column = processors[0].columns["noise_std"]
    noise_std = observed_all[..., noise_column]
    usable = np.isfinite(observed_all).any(axis=-1) & np.isfinite(noise_std) & (noise_std > 0)
    rng = np.random.default_rng(seed)
    noise_by_speed = {speed: noise_model(processor, rng) for speed, processor in cache.items()}
    noise = [noise_by_speed[float(speed)] for speed in speeds]
    simulator = CampaignSimulator(design, speeds, rig["drive_torque"].values, fs, size, channels, steps_per_mode)
    return RigCase(rig=rig, design=design, channels=channels, speeds=speeds,
                   drive_torques=np.asarray(rig["drive_torque"].values, dtype=float),
                   adhesion_lower=np.asarray(rig["adhesion_torque_lower"].values, dtype=float),
                   adhesion_upper=np.asarray(rig["adhesion_torque_upper"].values, dtype=float),
                   fs=fs, size=size, processors=processors, layout=layout,
                   observed=observed_all[..., layout.columns], observed_all=observed_all, noise_std=noise_std,
                   noise=noise, usable=usable, simulator=simulator, model_error=errors)


@dataclass(frozen=True)
class RunTask:
    """One run to simulate and reduce to features: all a worker process needs besides the case."""

    op: int
    design: Design
    mesh_stiffness_scale: float
    adhesion_torque: float
    effects: tuple[Effect, ...]
    periodicity: str


def execute_run(case: RigCase, task: RunTask) -> tuple[np.ndarray, bool]:
    """Simulate a run and reduce its records with the rig's processing: (n_channel, all features), periodic."""
    run = case.simulator.run(task.op, task.design, task.mesh_stiffness_scale, task.adhesion_torque, task.effects,
                             task.periodicity)
    stacked = np.stack([run.records[channel] for channel in case.channels])
    return case.processors[task.op].model_features(stacked), run.periodic


# The case a forked worker process inherits from its parent (set just before
# the pool is created): the processors hold large least-squares bases that
# are cheaper to share by fork than to pickle.
_INHERITED_CASE: RigCase | None = None


def _worker_execute(task: RunTask) -> tuple[np.ndarray, bool]:
    assert _INHERITED_CASE is not None, "worker started without a case"  # internal invariant, not user input
    return execute_run(_INHERITED_CASE, task)


class RunExecutor:
    """Runs :class:`RunTask` lists sequentially or over forked worker processes.

    Parameters
    ----------
    case : RigCase
    workers : int
        Worker processes (1: in this process). Needs the ``fork`` start
        method; elsewhere runs stay in this process.
    """

    def __init__(self, case: RigCase, workers: int = 1) -> None:
        global _INHERITED_CASE
        self.case = case
        self.pool = None
        if workers > 1 and "fork" in multiprocessing.get_all_start_methods():
            _INHERITED_CASE = case
            try:
                self.pool = multiprocessing.get_context("fork").Pool(workers)
            finally:
                _INHERITED_CASE = None
        self.workers = workers if self.pool is not None else 1

    def map(self, tasks: Sequence[RunTask]) -> list[tuple[np.ndarray, bool]]:
        if self.pool is None or len(tasks) < 2:
            return [execute_run(self.case, task) for task in tasks]
        chunk = max(1, len(tasks) // (4 * self.workers))
        return self.pool.map(_worker_execute, tasks, chunksize=chunk)

    def close(self) -> None:
        if self.pool is not None:
            self.pool.close()
            self.pool.join()
            self.pool = None


# ---------------------------------------------------------------------------------------------- fitting

# Feature kinds the fits use (RMS and kurtosis enter the gap map only).
_FITTED_KINDS = ("line", "band")
# Robust (Cauchy) loss of the fits: quadratic to about this |z|, then logarithmic.
_LOSS_SCALE = 3.0
# Finite-difference step in optimiser units (prior standard deviations or effect units).
_DIFFERENCE_STEP = 0.02


class FitProblem:
    """Nominal model plus at most one candidate effect, as a function of an optimiser vector.

    The vector holds the global parameters (nominal ones, then the effect's)
    in optimiser units (:class:`ParameterSpec`), then the position of each
    run's T2 inside its interval (0 at the lower, 1 at the upper bound).
    """

    def __init__(self, case: RigCase, candidate: Candidate | None) -> None:
        self.case = case
        self.candidate = candidate
        self.specs: list[ParameterSpec] = nominal_parameters(case.design) + list(candidate.fitted if candidate else [])
        self.n_global = len(self.specs)
        self.size = self.n_global + case.n_op
        # RMS and kurtosis sum up everything, also what the model class cannot produce; fitted to
        # them the nominal parameters would trade mesh-harmonic accuracy for the unmodelled part.
        fitted_kind = np.array([kind in _FITTED_KINDS for kind in case.layout.kinds])
        self.mask = case.mask() & fitted_kind
        self.periodicity = candidate.periodicity if candidate else "mesh"
        lower = [spec.bounds()[0] for spec in self.specs] + [0.0] * case.n_op
        upper = [spec.bounds()[1] for spec in self.specs] + [1.0] * case.n_op
        self.lower = np.array(lower)
        self.upper = np.array(upper)
        self.prior_index = np.array([i for i, spec in enumerate(self.specs) if spec.prior], dtype=int)
        self._cache: dict[tuple, tuple[np.ndarray, bool]] = {}
        self.evaluations = 0

    # -- vectors
    def vector(self, values: Mapping[str, float], t2_position: Sequence[float] | float = 0.5) -> np.ndarray:
        """Optimiser vector from natural values (missing globals at their centres)."""
        v = np.zeros(self.size)
        for i, spec in enumerate(self.specs):
            if spec.name in values:
                v[i] = spec.to_optimiser(float(values[spec.name]))
        v[self.n_global:] = np.broadcast_to(np.asarray(t2_position, dtype=float), (self.case.n_op,))
        return np.clip(v, self.lower, self.upper)

    def values(self, v: np.ndarray) -> dict[str, float]:
        """Natural values of the global parameters."""
        return {spec.name: spec.from_optimiser(float(v[i])) for i, spec in enumerate(self.specs)}

    def adhesion_torques(self, v: np.ndarray) -> np.ndarray:
        position = np.clip(v[self.n_global:], 0.0, 1.0)
        return self.case.adhesion_lower + position * (self.case.adhesion_upper - self.case.adhesion_lower)

    # -- model features
    def run_task(self, v: np.ndarray, op: int) -> "RunTask":
        """The simulation of run ``op`` at optimiser vector ``v``."""
        values = self.values(v)
        design = self.case.design.replace(zeta_mesh=values["zeta_mesh"], ste_amplitude=values["ste_amplitude"],
                                          k1=values["k1"], k2=values["k2"])
        effects = (self.candidate.make(values),) if self.candidate else ()
        return RunTask(op, design, values["mesh_stiffness_scale"], float(self.adhesion_torques(v)[op]), effects,
                       self.periodicity)

    def model_features(self, vectors: Sequence[np.ndarray], ops: Sequence[Sequence[int]] | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free model features (V, n_op, n_channel, all features), NaN for runs not asked.

        Returns the features and whether each run's response was periodic
        (V, n_op). Runs already simulated for the same parameters come from a
        cache; the others are simulated together (in worker processes when
        the case has them).
        """
        case = self.case
        n_all = case.observed_all.shape[-1]
        out = np.full((len(vectors), case.n_op, len(case.channels), n_all), np.nan)
        periodic = np.zeros((len(vectors), case.n_op), dtype=bool)
        tasks: list[RunTask] = []
        where: list[tuple[int, int, tuple]] = []
        for index, v in enumerate(vectors):
            for op in (range(case.n_op) if ops is None else ops[index]):
                key = (op, float(v[self.n_global + op]), *np.round(v[:self.n_global], 12))
                if key in self._cache:
                    out[index, op], periodic[index, op] = self._cache[key]
                    continue
                tasks.append(self.run_task(v, op))
                where.append((index, op, key))
        for (index, op, key), (values, is_periodic) in zip(where, case.execute(tasks)):
            self.evaluations += 1
            out[index, op], periodic[index, op] = values, is_periodic
            self._cache[key] = (values, is_periodic)
        return out, periodic

    def discrepancy(self, model_all: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Standardised discrepancies and scales (..., n_op, n_channel, F) of model features."""
        case = self.case
        return standardised_discrepancy(case.observed, model_all[..., case.layout.columns], case.noise_std,
                                        case.noise, case.layout, case.model_error)

    def residual_vector(self, z: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Feature residuals (masked) followed by the prior residuals."""
        values = np.where(np.isfinite(z), z, 0.0)[self.mask]
        return np.concatenate([values, v[self.prior_index]])

    def residuals(self, v: np.ndarray) -> np.ndarray:
        model, _ = self.model_features([v])
        z, _ = self.discrepancy(model[0])
        return self.residual_vector(z, v)

    def jacobian(self, v: np.ndarray, free: np.ndarray) -> np.ndarray:
        """Forward-difference Jacobian of :meth:`residuals` in the ``free`` entries of ``v``.

        All perturbations are simulated in one batch. Each run depends only
        on its own T2, so one perturbation of all T2 positions at once gives
        every run's T2 column (the positions are free all together or not at all).
        """
        free_index = np.flatnonzero(free)
        global_index = free_index[free_index < self.n_global]
        t2_free = bool(np.any(free_index >= self.n_global))
        vectors = [v]
        steps = []
        for i in global_index:
            step = _DIFFERENCE_STEP if v[i] + _DIFFERENCE_STEP <= self.upper[i] else -_DIFFERENCE_STEP
            shifted = v.copy()
            shifted[i] += step
            vectors.append(shifted)
            steps.append(step)
        if t2_free:
            t2_step = np.where(v[self.n_global:] + _DIFFERENCE_STEP <= 1.0, _DIFFERENCE_STEP, -_DIFFERENCE_STEP)
            shifted = v.copy()
            shifted[self.n_global:] += t2_step
            vectors.append(shifted)
        model, _ = self.model_features(vectors)
        z, _ = self.discrepancy(model)
        base = self.residual_vector(z[0], v)
        columns = {}
        for k, (i, step) in enumerate(zip(global_index, steps), start=1):
            columns[int(i)] = (self.residual_vector(z[k], vectors[k]) - base) / step
        if t2_free:
            change = self.residual_vector(z[-1], vectors[-1]) - base
            rows_of = self.op_of_row()
            for op in range(self.case.n_op):
                column = np.zeros(base.size)
                rows = rows_of == op
                column[rows] = change[rows] / t2_step[op]
                columns[self.n_global + op] = column
        return np.stack([columns[int(i)] for i in free_index], axis=1)

    def op_of_row(self) -> np.ndarray:
        """Run index of each residual row (-1 for priors)."""
        shape = self.mask.shape
        ops = np.broadcast_to(np.arange(shape[0])[:, None, None], shape)[self.mask]
        return np.concatenate([ops, np.full(self.prior_index.size, -1)])


def robust_cost(residuals: np.ndarray) -> float:
    """The fits' objective: the Cauchy loss 0.5 c^2 sum log(1 + (r/c)^2), c = :data:`_LOSS_SCALE`.

    A redescending loss: a feature far beyond what the model class can
    produce (an unmodelled line thousands of sigmas high) loses its pull on
    the parameters instead of bending them towards it through tiny slopes.
    """
    s = (np.asarray(residuals) / _LOSS_SCALE) ** 2
    return float(0.5 * _LOSS_SCALE ** 2 * np.sum(np.log1p(s)))


def robust_weights(residuals: np.ndarray) -> np.ndarray:
    """IRLS weights of the Cauchy loss: 1 / (1 + (r/c)^2)."""
    return 1.0 / (1.0 + (np.asarray(residuals) / _LOSS_SCALE) ** 2)


@dataclass
class FitResult:
    """A fitted model: optimum, residuals and Jacobian there, cost and bookkeeping.

    ``free`` marks the entries of the optimiser vector that were fitted (the
    others stayed at their starting values); ``jacobian`` has one column per
    free entry, in order.
    """

    problem: FitProblem
    vector: np.ndarray
    free: np.ndarray
    residuals: np.ndarray
    jacobian: np.ndarray
    z: np.ndarray
    scale: np.ndarray
    model: np.ndarray
    periodic: np.ndarray
    cost: float
    evaluations: int
    seconds: float
    converged: bool
    message: str

    @property
    def values(self) -> dict[str, float]:
        return self.problem.values(self.vector)

    @property
    def adhesion_torques(self) -> np.ndarray:
        return self.problem.adhesion_torques(self.vector)


def fit(problem: FitProblem, starts: Sequence[np.ndarray], *, free: np.ndarray | None = None,
        max_evaluations: int = 30, loss: str = "cauchy", rows: np.ndarray | None = None,
        tolerance: float = 1e-4) -> FitResult:
    """Robust least-squares fit from the best of several starting vectors.

    All starts are simulated in one batch; the one with the lowest robust
    cost is refined with scipy's trust-region reflective least squares
    (bounds, Cauchy loss), the Jacobian from batched finite differences.

    Parameters
    ----------
    problem : FitProblem
    starts : sequence of ndarray
        Full optimiser vectors.
    free : ndarray of bool, optional
        Entries to fit (default all); the T2 positions are free all together or not at all.
    max_evaluations : int
        Cost evaluations allowed to the least-squares solver.
    loss : {"cauchy", "soft_l1"}
        Robust loss of the solver (the result's cost is always the Cauchy one).
    rows : ndarray of bool, optional
        Residual rows the solver sees (default all); the result holds all rows.
    tolerance : float
        Relative tolerance on the cost and the step (scipy's ftol and xtol).
    """
    started = time.perf_counter()
    first = problem.evaluations
    free = np.ones(problem.size, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    model, _ = problem.model_features(list(starts))
    selected = slice(None) if rows is None else np.asarray(rows, dtype=bool)
    costs = []
    for index, v in enumerate(starts):
        z, _ = problem.discrepancy(model[index])
        costs.append(robust_cost(problem.residual_vector(z, v)[selected]))
    base = np.asarray(starts[int(np.argmin(costs))], dtype=float)

    def expand(u: np.ndarray) -> np.ndarray:
        v = base.copy()
        v[free] = u
        return v

    result = scipy.optimize.least_squares(lambda u: problem.residuals(expand(u))[selected], base[free],
                                          jac=lambda u: problem.jacobian(expand(u), free)[selected],
                                          bounds=(problem.lower[free], problem.upper[free]), method="trf",
                                          loss=loss, f_scale=_LOSS_SCALE, x_scale=1.0, max_nfev=max_evaluations,
                                          xtol=tolerance, ftol=tolerance, gtol=1e-8)
    v = np.clip(expand(result.x), problem.lower, problem.upper)
    model, periodic = problem.model_features([v])
    z, scale = problem.discrepancy(model[0])
    residuals = problem.residual_vector(z, v)
    jacobian = problem.jacobian(v, free)
    return FitResult(problem=problem, vector=v, free=free, residuals=residuals, jacobian=jacobian, z=z, scale=scale,
                     model=model[0], periodic=periodic[0], cost=robust_cost(residuals),
                     evaluations=problem.evaluations - first, seconds=time.perf_counter() - started,
                     converged=bool(result.status > 0), message=str(result.message))


# ---------------------------------------------------------------------------------------------- held-out runs

@dataclass
class HeldOut:
    """Leave-one-run-out predictions of a fitted model.

    Attributes
    ----------
    z : ndarray (n_op, n_channel, F)
        Standardised discrepancy of each run's features predicted by the
        model fitted without that run (parameter uncertainty included).
    scale : ndarray
        Predictive scales, same shape.
    log_density : ndarray
        Robust log predictive density of each feature (NaN outside the mask).
    vectors : ndarray (n_op, size)
        Parameter vectors fitted without each run (its T2 profiled on it).
    model : ndarray (n_op, n_channel, all features)
        The held-out model features.
    """

    z: np.ndarray
    scale: np.ndarray
    log_density: np.ndarray
    vectors: np.ndarray
    model: np.ndarray


# A held-out run whose mesh harmonics are this many sigmas off gets its T2 profiled on the grid.
_PROFILE_Z = 5.0
# Largest change of any parameter (optimiser units) in a leave-one-run-out step.
_LOO_STEP_LIMIT = 1.0


def _pressed_to_bound(values: np.ndarray, gradient: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Parameters at a bound whose descent direction points out of the box."""
    span = np.maximum(upper - lower, 1e-12)
    at_lower = (values - lower) <= 1e-6 * span
    at_upper = (upper - values) <= 1e-6 * span
    return (at_lower & (gradient > 0)) | (at_upper & (gradient < 0))


def leave_one_out(result: FitResult) -> HeldOut:
    """Leave-one-operating-point-out predictions from a full fit.

    The fit without run o is one Gauss-Newton step from the full optimum
    with run o's rows removed (robust weights kept, run o's T2 dropped: no
    other run informs it); run o is then re-simulated with those parameters,
    its T2 profiled on its own features (a linearised one-parameter fit
    inside its interval, when the T2 positions were fitted), and the fitted
    global parameters' remaining uncertainty widens the predictive scale.
    """
    problem = result.problem
    case = problem.case
    r = result.residuals
    jac = result.jacobian
    free_index = np.flatnonzero(result.free)
    global_columns = np.flatnonzero(free_index < problem.n_global)
    weights = robust_weights(r)
    hessian = jac.T @ (weights[:, None] * jac)
    gradient = jac.T @ (weights * r)
    rows_of = problem.op_of_row()
    vectors = np.empty((case.n_op, problem.size))
    covariances = []
    t2_column: dict[int, int] = {int(index) - problem.n_global: column
                                 for column, index in enumerate(free_index) if index >= problem.n_global}
    for op in range(case.n_op):
        rows = rows_of == op
        keep = np.array([c for c in range(free_index.size) if t2_column.get(op) != c], dtype=int)
        j_op = jac[rows][:, keep]
        reduced = hessian[np.ix_(keep, keep)] - j_op.T @ (weights[rows, None] * j_op)
        reduced_gradient = gradient[keep] - j_op.T @ (weights[rows] * r[rows])
        reduced += np.eye(keep.size) * 1e-9 * max(np.trace(reduced) / max(keep.size, 1), 1e-12)
        # parameters held at a bound by the data stay there (active set); the rest take one
        # Newton step, limited to one optimiser unit: dropping one run is a small perturbation
        at_bound = _pressed_to_bound(result.vector[free_index[keep]], reduced_gradient,
                                     problem.lower[free_index[keep]], problem.upper[free_index[keep]])
        inverse = np.zeros_like(reduced)
        moving = np.flatnonzero(~at_bound)
        if moving.size:
            inverse[np.ix_(moving, moving)] = np.linalg.pinv(reduced[np.ix_(moving, moving)])
        step = np.clip(-inverse @ reduced_gradient, -_LOO_STEP_LIMIT, _LOO_STEP_LIMIT)
        v = result.vector.copy()
        v[free_index[keep]] += step
        vectors[op] = np.clip(v, problem.lower, problem.upper)
        position = {column: k for k, column in enumerate(keep)}
        chosen = [position[c] for c in global_columns]
        covariances.append(inverse[np.ix_(chosen, chosen)])
    model, _ = problem.model_features(list(vectors), [[op] for op in range(case.n_op)])
    held_model = np.stack([model[op, op] for op in range(case.n_op)])
    if t2_column:
        # a run predicted far off on its mesh harmonics may sit on the wrong side of a regime
        # change in T2: its T2 is then profiled on the grid before the linear refinement
        z_first, _ = problem.discrepancy(held_model)
        harmonic = np.array(case.layout.families) == "mesh_harmonic"
        worst = np.nanmax(np.abs(np.where(np.isfinite(z_first[..., harmonic]), z_first[..., harmonic], 0.0)),
                          axis=(1, 2))
        for op in np.flatnonzero(worst > _PROFILE_Z):
            vectors[op] = profile_adhesion(problem, vectors[op], [int(op)])
            model, _ = problem.model_features([vectors[op]], [[int(op)]])
            held_model[op] = model[0, op]
    z_raw, scale = problem.discrepancy(held_model)
    z = np.full_like(z_raw, np.nan)
    inflated_scale = np.full_like(scale, np.nan)
    compared = case.mask()
    for op in range(case.n_op):
        fitted_rows = problem.mask[op][compared[op]]
        residual = np.where(np.isfinite(z_raw[op]), z_raw[op], 0.0)[compared[op]]
        rows = rows_of == op
        slope_fitted = jac[rows][:, t2_column[op]] if op in t2_column else None
        if slope_fitted is not None:
            # profile this run's T2 on its own fitted features (linearised, inside its interval)
            slope = np.zeros(residual.size)
            slope[fitted_rows] = slope_fitted
            w = robust_weights(residual) * fitted_rows
            curvature = float(np.sum(w * slope ** 2))
            if curvature > 0:
                position = vectors[op, problem.n_global + op]
                shift = -float(np.sum(w * slope * residual)) / curvature
                shift = float(np.clip(position + shift, 0.0, 1.0) - position)
                residual = residual + slope * shift
                vectors[op, problem.n_global + op] = position + shift
        variance = np.zeros(residual.size)
        if global_columns.size:
            j_global = np.zeros((residual.size, global_columns.size))
            j_global[fitted_rows] = jac[rows][:, global_columns]
            variance = np.maximum(np.einsum("ij,jk,ik->i", j_global, covariances[op], j_global), 0.0)
        values = np.full(compared[op].shape, np.nan)
        values[compared[op]] = residual / np.sqrt(1.0 + variance)
        z[op] = values
        widened = np.full(compared[op].shape, np.nan)
        widened[compared[op]] = scale[op][compared[op]] * np.sqrt(1.0 + variance)
        inflated_scale[op] = widened
    log_density = np.where(np.isfinite(z), robust_log_density(np.nan_to_num(z), np.nan_to_num(inflated_scale, nan=1.0)),
                           np.nan)
    return HeldOut(z=z, scale=inflated_scale, log_density=log_density, vectors=vectors, model=held_model)


# ---------------------------------------------------------------------------------------------- gap metric

GAP_METRIC = "excess_rms_standardised_discrepancy_capped_at_10"
# Each feature's squared discrepancy counts at most this much, so that a few
# features thousands of sigmas off do not decide alone how far a gap shrank.
_GAP_CAP = 10.0
# E[min(z^2, cap^2)] for z ~ N(0, 1): the noise level the gap is measured from.
_GAP_NOISE_LEVEL = float(1.0 - 2.0 * (_GAP_CAP * scipy.stats.norm.pdf(_GAP_CAP) + scipy.stats.norm.sf(_GAP_CAP))
                         + 2.0 * _GAP_CAP ** 2 * scipy.stats.norm.sf(_GAP_CAP))


def capped_squares(z: np.ndarray) -> np.ndarray:
    """min(z^2, cap^2) (NaN stays NaN)."""
    return np.minimum(np.asarray(z, dtype=float) ** 2, _GAP_CAP ** 2)


def gap_metric(z: np.ndarray) -> float:
    """The gap: RMS standardised discrepancy in excess of noise.

    sqrt(max(mean(min(z^2, 10^2)) - E_noise, 0)): 0 when the features scatter
    about the model as noise and model error allow; in units of that scatter
    otherwise, each feature counting at most 10 sigma. NaN entries are ignored.
    """
    values = capped_squares(z)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return math.nan
    return math.sqrt(max(float(np.mean(values)) - _GAP_NOISE_LEVEL, 0.0))


def shrink_fraction(before: float, after: float) -> float:
    """1 - after/before (0 when there is no gap to shrink; negative when it grew)."""
    if not before > 0:
        return 0.0
    return 1.0 - after / before


def bootstrap_shrink(z_before: np.ndarray, z_after: np.ndarray, rng: np.random.Generator,
                     n_resamples: int = 400) -> tuple[float, float, float]:
    """Shrink fraction and its 5 % and 95 % bootstrap quantiles, resampling runs.

    The quantiles are over the resamples that hold a gap to shrink (the
    central resample does whenever the result is not 0).

    Parameters
    ----------
    z_before, z_after : ndarray (n_op, ...)
        Held-out standardised discrepancies of the nominal model and the
        model with the effect.
    """
    before = np.asarray(z_before, dtype=float)
    after = np.asarray(z_after, dtype=float)
    n_op = before.shape[0]
    # per-run sums of squares and counts make each resample cheap
    squares_before = np.array([np.nansum(capped_squares(before[op])) for op in range(n_op)])
    squares_after = np.array([np.nansum(capped_squares(after[op])) for op in range(n_op)])
    counts = np.array([np.sum(np.isfinite(before[op])) for op in range(n_op)])

    def shrink_of(index: np.ndarray) -> float:
        count = counts[index].sum()
        if count == 0:
            return math.nan
        gap_before = math.sqrt(max(squares_before[index].sum() / count - _GAP_NOISE_LEVEL, 0.0))
        gap_after = math.sqrt(max(squares_after[index].sum() / count - _GAP_NOISE_LEVEL, 0.0))
        # a resample that left out every run carrying the gap has nothing to shrink: the
        # fraction is undefined there, not 0 (a gap confined to one run would otherwise get a
        # lower bound of 0 from the third of resamples that miss that run)
        return shrink_fraction(gap_before, gap_after) if gap_before > 0 else math.nan

    central = shrink_of(np.arange(n_op))
    if not math.isfinite(central):
        return 0.0, 0.0, 0.0
    samples = np.array([shrink_of(rng.integers(0, n_op, n_op)) for _ in range(n_resamples)])
    samples = samples[np.isfinite(samples)]
    return central, float(np.quantile(samples, 0.05)), float(np.quantile(samples, 0.95))


def bootstrap_gap(z: np.ndarray, rng: np.random.Generator, n_resamples: int = 400) -> tuple[float, float]:
    """5 % and 95 % bootstrap quantiles of :func:`gap_metric`, resampling runs (axis 0)."""
    values = np.asarray(z, dtype=float)
    n_op = values.shape[0]
    squares = np.array([np.nansum(capped_squares(values[op])) for op in range(n_op)])
    counts = np.array([np.sum(np.isfinite(values[op])) for op in range(n_op)])
    gaps = []
    for _ in range(n_resamples):
        index = rng.integers(0, n_op, n_op)
        count = counts[index].sum()
        if count:
            gaps.append(math.sqrt(max(squares[index].sum() / count - _GAP_NOISE_LEVEL, 0.0)))
    if not gaps:
        return math.nan, math.nan
    return float(np.quantile(gaps, 0.05)), float(np.quantile(gaps, 0.95))


# Positions in its interval at which each run's T2 is tried by :func:`profile_adhesion`.
_T2_GRID = np.linspace(0.0, 1.0, 9)


def profile_adhesion(problem: FitProblem, vector: np.ndarray, ops: Sequence[int] | None = None) -> np.ndarray:
    """Each run's T2 set to the best of a grid over its interval, other parameters fixed.

    T2 moves a run across regimes (contact loss, quasi-periodic motion near
    the mesh resonance), where a feature can change tenfold within a kN m
    and be flat elsewhere: a local fit started on the wrong branch never
    finds the right one. Each run depends on its own T2 only, so all runs'
    grids are one batch; the run's Cauchy cost on its fitted features picks
    the position. Returns the updated vector.
    """
    case = problem.case
    ops = list(range(case.n_op)) if ops is None else list(ops)
    vectors = []
    for position in _T2_GRID:
        shifted = np.array(vector, dtype=float)
        shifted[problem.n_global + np.array(ops, dtype=int)] = position
        vectors.append(shifted)
    model, _ = problem.model_features(vectors, [ops] * len(vectors))
    z, _ = problem.discrepancy(model)
    result = np.array(vector, dtype=float)
    for op in ops:
        costs = [robust_cost(np.where(np.isfinite(z[k, op]), z[k, op], 0.0)[problem.mask[op]])
                 for k in range(_T2_GRID.size)]
        result[problem.n_global + op] = _T2_GRID[int(np.argmin(costs))]
    return result


def fit_nominal(case: RigCase, *, max_evaluations: int = 30, start: Mapping[str, float] | None = None,
                positions: np.ndarray | None = None) -> FitResult:
    """Fit the nominal model (no effect).

    From the design's values and T2 mid-interval, two stages: a soft-L1
    fit to the mesh harmonics alone (what the nominal model class produces,
    a nearly convex problem from there), then the Cauchy fit to all fitted
    features (the redescending loss alone can stall far from the optimum).
    From a calibration (``start``: parameter values, ``positions``: each
    run's T2 position in its interval) only the second stage runs. Before
    the second stage every run's T2 is profiled on a grid (:func:`profile_adhesion`).
    """
    problem = FitProblem(case, None)
    if start is not None:
        begin = problem.vector(start, 0.5 if positions is None else positions)
        return fit(problem, [profile_adhesion(problem, begin), begin], max_evaluations=max_evaluations,
                   tolerance=1e-3)
    families = np.broadcast_to(np.array(case.layout.families), problem.mask.shape)[problem.mask]
    rows = np.concatenate([families == "mesh_harmonic", np.ones(problem.prior_index.size, dtype=bool)])
    first = fit(problem, [problem.vector({}, 0.5)], max_evaluations=max_evaluations, loss="soft_l1", rows=rows,
                tolerance=1e-3)
    second = fit(problem, [profile_adhesion(problem, first.vector), first.vector], max_evaluations=max_evaluations,
                 tolerance=1e-3)
    second.evaluations += first.evaluations
    second.seconds += first.seconds
    return second


def fit_candidate(case: RigCase, candidate: Candidate, nominal: FitResult, *, full: bool,
                  max_evaluations: int = 20, start: FitResult | None = None) -> FitResult:
    """Fit nominal + one effect, warm-started from the nominal fit and the candidate's signature grid.

    Parameters
    ----------
    case : RigCase
    candidate : Candidate
    nominal : FitResult
        The nominal fit (its parameters and T2 positions are the start).
    full : bool
        Fit all parameters; otherwise only the effect's (the screening fit).
    max_evaluations : int
        Cost evaluations allowed to the least-squares solver.
    start : FitResult, optional
        A screening fit of the same candidate to start from instead of the grid.
    """
    problem = FitProblem(case, candidate)
    positions = nominal.vector[nominal.problem.n_global:]
    if start is not None:
        starts = [problem.vector(start.values, start.vector[start.problem.n_global:])]
    else:
        starts = [problem.vector({**nominal.values, **point}, positions) for point in candidate.starts]
    free = np.ones(problem.size, dtype=bool)
    if full:
        # As for the nominal fit: the redescending loss alone can leave a few features of one run
        # (a sensitive quasi-periodic one) as "outliers" far from the optimum; a soft-L1 stage
        # first, then the Cauchy fit from the better (in Cauchy cost) of its result and the start.
        # An effect that changes every run (clearance in both bearings) drags the nominal fit far
        # from the truth; the effect's values on the design's own parameters are a start too.
        effect_only = {name: value for name, value in problem.values(starts[0]).items() if "." in name}
        centred = [problem.vector(values, positions) for values in (effect_only, *candidate.starts)]
        starts = [profile_adhesion(problem, starts[0]), profile_adhesion(problem, centred[0]), *starts, *centred[1:]]
        first = fit(problem, starts, free=free, max_evaluations=max_evaluations, loss="soft_l1", tolerance=1e-3)
        second = fit(problem, [first.vector, *starts], free=free, max_evaluations=max_evaluations, tolerance=1e-3)
        second.evaluations += first.evaluations
        second.seconds += first.seconds
        return second
    free[:] = False
    free[len(nominal_parameters(case.design)):problem.n_global] = True
    result = fit(problem, starts, free=free, max_evaluations=max_evaluations)
    # Held-out predictions must leave each run out of the nominal parameters too, as the
    # nominal model's do: leave_one_out needs the Jacobian in all parameters. The nominal
    # fit's columns stand in for the nominal parameters and T2 (exact for a small effect;
    # a strong one is refitted in full anyway).
    n_nominal = len(nominal_parameters(case.design))
    if nominal.jacobian.shape[1] == n_nominal + case.n_op and nominal.jacobian.shape[0] == result.jacobian.shape[0]:
        result.jacobian = np.concatenate([nominal.jacobian[:, :n_nominal], result.jacobian,
                                          nominal.jacobian[:, n_nominal:]], axis=1)
    else:
        result.jacobian = problem.jacobian(result.vector, np.ones(problem.size, dtype=bool))
    result.free = np.ones(problem.size, dtype=bool)
    return result


# ---------------------------------------------------------------------------------------------- signatures

def frequency_locked_lines(case: RigCase, *, channel: str = "te", threshold: float = 8.0,
                           minimum_runs: int = 3) -> list[dict[str, Any]]:
    """Spectral lines that keep their frequency, not their order, across runs.

    Peaks of each run's amplitude spectrum more than ``threshold`` times a
    line's noise scale above zero are grouped by frequency (within 1.5
    bins); a group met in at least ``minimum_runs`` runs (and half of them)
    whose orders differ by more than half an order is frequency-locked
    (stick-slip, a fixed-frequency source), unlike every order-locked line,
    which moves with the speed.

    Returns
    -------
    list of dict
        ``frequency`` (Hz), ``ops`` (run indices), ``amplitude`` (median, channel units).
    """
    if channel not in case.channels:
        return []
    channel_index = case.channels.index(channel)
    resolution = case.fs / case.size
    taper = scipy.signal.get_window("hann", case.size)
    peaks: list[tuple[float, int, float]] = []
    for op in range(case.n_op):
        if not case.usable[op, channel_index]:
            continue
        record = np.asarray(case.rig[channel].values[op], dtype=float)
        amplitude = np.abs(np.fft.rfft((record - record.mean()) * taper)) * (2.0 / taper.sum())
        frequency = np.fft.rfftfreq(case.size, 1.0 / case.fs)
        line_scale = case.noise_std[op, channel_index] * math.sqrt(2.0 * np.sum(taper ** 2)) / taper.sum()
        inside = frequency <= case.processors[op].limit
        index, _ = scipy.signal.find_peaks(np.where(inside, amplitude, 0.0), height=threshold * line_scale)
        strongest = index[np.argsort(amplitude[index])[::-1][:60]]
        peaks.extend((float(frequency[i]), op, float(amplitude[i])) for i in strongest if frequency[i] > resolution)
    peaks.sort()
    groups: list[list[tuple[float, int, float]]] = []
    for peak in peaks:
        if groups and peak[0] - groups[-1][-1][0] <= 1.5 * resolution:
            groups[-1].append(peak)
        else:
            groups.append([peak])
    lines = []
    needed = max(minimum_runs, int(math.ceil(0.5 * case.n_op)))
    for group in groups:
        ops = sorted({op for _, op, _ in group})
        if len(ops) < needed:
            continue
        frequency = float(np.median([f for f, _, _ in group]))
        orders = frequency / (case.speeds[ops] / 60.0)
        if np.ptp(orders) <= 0.5:
            continue
        lines.append({"frequency": frequency, "ops": ops,
                      "amplitude": float(np.median([a for _, _, a in group]))})
    return lines


def signature_hints(case: RigCase, locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """Starting values for the candidate fits read off the rig's features.

    The run-out amplitude from the median 1x shaft line of the transmission
    error (the run-out enters the TE directly); the stick-slip frequency
    from the lowest frequency-locked line below 100 Hz.
    """
    hints: dict[str, float] = {}
    if "te" in case.channels:
        te = case.channels.index("te")
        for shaft in ("pinion", "gear"):
            name = f"shaft_{shaft}1"
            if name in case.layout.names:
                values = case.observed[:, te, case.layout.names.index(name)]
                values = values[np.isfinite(values)]
                if values.size:
                    hints[f"eccentricity_{shaft}"] = float(np.median(values))
    low = [line["frequency"] for line in locked_lines if 1.0 <= line["frequency"] <= 100.0]
    if low:
        hints["adhesion_frequency"] = float(min(low))
    return hints


# ---------------------------------------------------------------------------------------------- scoring and verdict

#: A candidate must gain this much held-out log predictive density (nats, after the penalty) to be named.
SCORE_THRESHOLD = 10.0
#: ... and shrink the held-out gap by at least this fraction.
SHRINK_THRESHOLD = 0.5
#: The nominal model is within noise when its held-out gap is below this (and no candidate is named).
NOISE_GAP_THRESHOLD = 0.5
#: A named effect must itself improve its fit's robust cost by at least this much (about nats).
EFFECT_GAIN_THRESHOLD = 5.0
#: An effect that clears the score and gain rules but not the shrink rule is still named, with an
#: unexplained remainder, when the lower end of its shrink interval reaches this fraction.
PARTIAL_SHRINK_THRESHOLD = 0.2
# A held-out feature this many sigmas off counts as a gap in the "where" list.
_WHERE_Z = 3.0


@dataclass
class CandidateScore:
    """Held-out scores of one candidate effect (its best variant)."""

    effect: str
    label: str
    fit: FitResult
    held: HeldOut
    stage: str
    delta_log_density: float
    standard_error: float
    penalty: float
    score: float
    gap: float
    shrink: float
    shrink_low: float
    shrink_high: float
    # robust cost of the nominal model at this fit's nominal parameters and T2 minus the fit's own:
    # what the effect itself adds (set by run_diagnosis; a screening fit shares the nominal's)
    effect_gain: float = math.inf

    def parameters(self) -> dict[str, object]:
        """Fitted effect parameters (natural units) and the fixed choices."""
        values: dict[str, object] = {key: value for key, value in self.fit.problem.candidate.choices}
        values.update({name.split(".", 1)[1]: float(value) for name, value in self.fit.values.items() if "." in name})
        return values


def score_candidate(fit_result: FitResult, held: HeldOut, nominal_held: HeldOut, stage: str,
                    rng: np.random.Generator) -> CandidateScore:
    """Held-out log-density gain over the nominal model, its standard error, penalty and gap shrink."""
    candidate = fit_result.problem.candidate
    difference = held.log_density - nominal_held.log_density
    per_run = np.array([np.nansum(difference[op]) for op in range(difference.shape[0])])
    n_runs = per_run.size
    delta = float(per_run.sum())
    standard_error = float(math.sqrt(n_runs) * per_run.std(ddof=1)) if n_runs > 1 else math.inf
    n_features = int(np.isfinite(held.z).sum())
    penalty = 0.5 * len(candidate.fitted) * math.log(max(n_features, 2))
    gap = gap_metric(held.z)
    shrink, low, high = bootstrap_shrink(nominal_held.z, held.z, rng)
    return CandidateScore(effect=candidate.effect, label=candidate.label, fit=fit_result, held=held, stage=stage,
                          delta_log_density=delta, standard_error=standard_error, penalty=penalty,
                          score=delta - penalty, gap=gap, shrink=shrink, shrink_low=low, shrink_high=high)


@dataclass(frozen=True)
class Decision:
    """A verdict with the figures that decided it.

    Attributes
    ----------
    verdict, reason : str
        As :func:`decide_verdict` returns them.
    partial : bool
        The named effect explains only part of the gap: what remains
        (``remaining_gap``) is significant and unexplained.
    remaining_gap : float or None
        Held-out gap with the named effect (``None`` when none is named).
    borderline : tuple of dict
        Deciding figures that lie within their own spread of their threshold
        (``figure``, ``value``, ``threshold``, ``interval``): a rerun on
        another campaign of the same rig could go the other way.
    """

    verdict: str
    reason: str
    partial: bool = False
    remaining_gap: float | None = None
    borderline: tuple[dict[str, Any], ...] = ()


def _straddles(interval: Sequence[float] | None, threshold: float) -> bool:
    if interval is None or len(interval) != 2 or not all(math.isfinite(float(v)) for v in interval):
        return False
    return float(interval[0]) < threshold <= float(interval[1])


def _borderline_figures(nominal_gap: float, nominal_gap_interval: Sequence[float] | None,
                        best: Mapping[str, Any] | None, *, score_threshold: float, shrink_threshold: float,
                        noise_gap: float) -> tuple[dict[str, Any], ...]:
    figures = []
    if _straddles(nominal_gap_interval, noise_gap):
        figures.append({"figure": "nominal_gap", "value": nominal_gap, "threshold": noise_gap,
                        "interval": [float(v) for v in nominal_gap_interval]})
    if best is not None:
        error = float(best.get("standard_error", math.nan))
        if math.isfinite(error):
            score_interval = [best["score"] - 1.645 * error, best["score"] + 1.645 * error]
            if _straddles(score_interval, score_threshold):
                figures.append({"figure": "score", "value": float(best["score"]), "threshold": score_threshold,
                                "interval": score_interval})
        if _straddles(best.get("shrink_interval"), shrink_threshold):
            figures.append({"figure": "shrink_fraction", "value": float(best["shrink_fraction"]),
                            "threshold": shrink_threshold,
                            "interval": [float(v) for v in best["shrink_interval"]]})
        if _straddles(best.get("gap_interval"), noise_gap):
            figures.append({"figure": "gap_with_effect", "value": float(best["gap_with_effect"]),
                            "threshold": noise_gap, "interval": [float(v) for v in best["gap_interval"]]})
    return tuple(figures)


def decide(nominal_gap: float, ranking: Sequence[Mapping[str, Any]], *,
           nominal_gap_interval: Sequence[float] | None = None,
           score_threshold: float = SCORE_THRESHOLD, shrink_threshold: float = SHRINK_THRESHOLD,
           noise_gap: float = NOISE_GAP_THRESHOLD, effect_gain_threshold: float = EFFECT_GAIN_THRESHOLD,
           partial_shrink: float = PARTIAL_SHRINK_THRESHOLD) -> Decision:
    """The verdict from the held-out gap of the nominal model and the ranked candidates.

    Parameters
    ----------
    nominal_gap : float
        Held-out gap of the nominal model (:func:`gap_metric`).
    ranking : sequence of mapping
        Candidates best first, each with ``effect``, ``score`` (held-out log
        density gain over the nominal model minus the parameter penalty),
        ``shrink_fraction``, ``shrink_interval`` ([5 %, 95 %]) and optionally
        ``gap_with_effect`` (its held-out gap), ``gap_interval``,
        ``standard_error`` (of the score) and ``effect_gain`` (how much worse
        its fit is with the effect switched off, robust cost).
    nominal_gap_interval : pair of float, optional
        Bootstrap interval of the nominal gap (:func:`bootstrap_gap`).
    score_threshold, shrink_threshold, noise_gap : float
        A candidate is named when its score reaches the threshold, the lower
        end of its shrink interval is positive, and it explains the gap:
        shrinks it by ``shrink_threshold`` or leaves no significant gap
        (held-out gap with the effect at most ``noise_gap``; a nominal gap
        just above noise cannot shrink by half and still be significant).
        The nominal model is within noise when its gap is at most ``noise_gap``.
    effect_gain_threshold : float
        A candidate whose fit is as good with its effect off (``effect_gain``
        below this) owes its score to the nominal parameters it refitted, not
        to the effect, and is never named.
    partial_shrink : float
        A candidate that passes the score and gain rules but explains only
        part of the gap is named with an unexplained remainder (``partial``)
        when the lower end of its shrink interval reaches this fraction;
        below it the verdict is ``unexplained``.

    Returns
    -------
    Decision
    """
    best = ranking[0] if ranking else None
    borderline = _borderline_figures(nominal_gap, nominal_gap_interval, best, score_threshold=score_threshold,
                                     shrink_threshold=shrink_threshold, noise_gap=noise_gap)
    if best is not None:
        remaining = float(best.get("gap_with_effect", math.inf))
        explains = best["shrink_fraction"] >= shrink_threshold or remaining <= noise_gap
        carried = float(best.get("effect_gain", math.inf)) >= effect_gain_threshold
        evidence = best["score"] >= score_threshold and carried
        if evidence and explains and best["shrink_interval"][0] > 0.0:
            within = (f"; what remains ({remaining:.2f}) is within noise"
                      if best["shrink_fraction"] < shrink_threshold else "")
            return Decision(str(best["effect"]), (
                f"{best['effect']} gains {best['score']:.1f} nats of held-out predictive density over the "
                f"nominal model after its parameter penalty and shrinks the held-out gap by "
                f"{100 * best['shrink_fraction']:.0f} % (90 % interval {100 * best['shrink_interval'][0]:.0f} "
                f"to {100 * best['shrink_interval'][1]:.0f} %){within}"),
                remaining_gap=remaining, borderline=borderline)
        if evidence and not explains and best["shrink_interval"][0] >= partial_shrink:
            return Decision(str(best["effect"]), (
                f"{best['effect']} gains {best['score']:.1f} nats of held-out predictive density and shrinks "
                f"the held-out gap by {100 * best['shrink_fraction']:.0f} % (90 % interval "
                f"{100 * best['shrink_interval'][0]:.0f} to {100 * best['shrink_interval'][1]:.0f} %), but a "
                f"gap of {remaining:.2f} (above {noise_gap:g}) remains unexplained"),
                partial=True, remaining_gap=remaining, borderline=borderline)
    if not math.isfinite(nominal_gap) or nominal_gap <= noise_gap:
        return Decision("none", f"the nominal model's held-out gap {nominal_gap:.2f} is within noise "
                                f"(threshold {noise_gap:g}) and no candidate is clearly better",
                        borderline=borderline)
    detail = ""
    if best is not None:
        detail = (f"; the best candidate, {best['effect']}, scores {best['score']:.1f} nats and shrinks it by "
                  f"{100 * best['shrink_fraction']:.0f} % (needed: {score_threshold:g} nats, and a shrink of "
                  f"{100 * shrink_threshold:.0f} % or a remaining gap within noise)")
    return Decision("unexplained", f"the nominal model's held-out gap is {nominal_gap:.2f} "
                                   f"(above {noise_gap:g}){detail}", borderline=borderline)


def decide_verdict(nominal_gap: float, ranking: Sequence[Mapping[str, Any]], **thresholds: float) -> tuple[str, str]:
    """``(verdict, reason)`` of :func:`decide` (same arguments)."""
    decision = decide(nominal_gap, ranking, **thresholds)
    return decision.verdict, decision.reason


def where_gap(z: np.ndarray, case: RigCase, *, limit: int = 12) -> list[dict[str, Any]]:
    """The features carrying a held-out gap: RMS z over runs, runs beyond 3 sigma, strongest first."""
    entries = []
    for c, channel in enumerate(case.channels):
        for f, name in enumerate(case.layout.names):
            values = z[:, c, f]
            finite = np.isfinite(values)
            if not finite.any():
                continue
            score = float(np.sqrt(np.mean(values[finite] ** 2)))
            ops = [int(op) for op in np.flatnonzero(finite & (np.abs(np.nan_to_num(values)) > _WHERE_Z))]
            if score > _WHERE_Z / 1.5 and ops:
                entries.append({"channel": channel, "feature": name, "family": case.layout.families[f],
                                "ops": ops, "score": score})
    entries.sort(key=lambda entry: -entry["score"])
    return entries[:limit]


def _shaft_lines_in_band(z: np.ndarray, case: RigCase, channel: int) -> bool:
    """Whether shaft-order lines inside the low band carry a gap (> 3 sigma) in some run."""
    low, high = case.processors[0].low_band
    for f, family in enumerate(case.layout.families):
        if not family.startswith("shaft_"):
            continue
        order = case.processors[0].definitions[case.layout.columns[f]].order
        frequency = order * case.speeds / 60.0
        inside = (frequency >= low) & (frequency <= high)
        if np.any(inside & (np.abs(np.nan_to_num(z[:, channel, f])) > _WHERE_Z)):
            return True
    return False


def family_character(z: np.ndarray, case: RigCase, locked_lines: Sequence[Mapping[str, Any]]
                     ) -> list[dict[str, Any]]:
    """Per channel and feature family: held-out gap and its character.

    ``order-locked`` for a gap on lines at orders of the shafts or the mesh;
    ``frequency-locked`` for the low-frequency band when lines keep their
    frequency across runs; ``load-dependent`` / ``speed-dependent`` when the
    per-run discrepancy follows the drive torque / speed (|Spearman| >= 0.7).
    """
    rows = []
    families = np.array(case.layout.families)
    for c, channel in enumerate(case.channels):
        for family in FEATURE_FAMILIES:
            chosen = families == family
            if not chosen.any():
                continue
            values = z[:, c, chosen]
            finite = np.isfinite(values)
            if not finite.any():
                continue
            score = math.sqrt(max(float(np.mean(capped_squares(values[finite]))) - _GAP_NOISE_LEVEL, 0.0))
            per_run = np.array([np.sqrt(np.nanmean(capped_squares(values[op]))) if finite[op].any() else np.nan
                                for op in range(case.n_op)])
            character = []
            if score > NOISE_GAP_THRESHOLD:
                if family not in ("low_frequency", "broadband"):
                    character.append("order-locked")
                elif family == "low_frequency":
                    low = [line for line in locked_lines if line["frequency"] <= case.processors[0].low_band[1]]
                    if low:
                        character.append("frequency-locked")
                    elif _shaft_lines_in_band(z, case, c):
                        character.append("order-locked (shaft lines in the band)")
                    else:
                        character.append("not order-locked")
                ok = np.isfinite(per_run)
                if ok.sum() >= 4 and np.ptp(per_run[ok]) > 0:
                    for label, driver in (("load-dependent", case.drive_torques), ("speed-dependent", case.speeds)):
                        if np.ptp(driver[ok]) > 0:
                            rho = scipy.stats.spearmanr(per_run[ok], driver[ok]).statistic
                            if np.isfinite(rho) and abs(rho) >= 0.7:
                                character.append(label)
            rows.append({"channel": channel, "family": family, "score": score,
                         "per_run": [None if not np.isfinite(v) else float(v) for v in per_run],
                         "character": character})
    return rows


# ---------------------------------------------------------------------------------------------- orchestration

#: Candidates promoted from the screening fit (effect parameters only) to a full fit.
PROMOTED = 2


@dataclass
class DiagnosisResult:
    """Everything a diagnosis found (see :func:`run_diagnosis`)."""

    case: RigCase
    nominal: FitResult
    nominal_held: HeldOut
    scores: list[CandidateScore]          # best variant per effect, ranked best first
    all_scores: list[CandidateScore]      # every variant and stage
    verdict: str
    reason: str
    nominal_gap: float
    where: list[dict[str, Any]]
    families: list[dict[str, Any]]
    locked_lines: list[dict[str, Any]]
    hints: dict[str, float]
    effects: tuple[str, ...]
    timings: dict[str, float]
    decision: Decision | None = None
    nominal_gap_interval: tuple[float, float] = (math.nan, math.nan)

    @property
    def best(self) -> CandidateScore | None:
        return self.scores[0] if self.scores else None

    def ranking(self) -> list[dict[str, Any]]:
        """JSON-ready ranking, best first."""
        return [{"effect": s.effect, "variant": s.label, "score": s.score, "delta_log_density": s.delta_log_density,
                 "standard_error": s.standard_error, "penalty": s.penalty, "shrink_fraction": s.shrink,
                 "shrink_interval": [s.shrink_low, s.shrink_high], "gap_with_effect": s.gap,
                 "effect_gain": s.effect_gain, "parameters": s.parameters(), "fit": s.stage} for s in self.scores]


def _check_effects(effects: Sequence[str] | None) -> tuple[str, ...]:
    if effects is None:
        return EFFECT_NAMES
    if isinstance(effects, str):
        effects = [effects]
    chosen = []
    for name in effects:
        if not isinstance(name, str) or name not in EFFECTS:
            raise DiagnosisError(f"effects: {name!r} is not a library effect; expected one or more of "
                                 f"{', '.join(EFFECT_NAMES)}")
        if name not in chosen:
            chosen.append(name)
    if not chosen:
        raise DiagnosisError(f"effects: expected at least one of {', '.join(EFFECT_NAMES)}; got none")
    return tuple(chosen)


def calibration_start(posterior: xr.Dataset, case: RigCase) -> tuple[dict[str, float], np.ndarray | None]:
    """Starting values for the nominal fit from a calibration posterior (``posterior.nc`` of ``uqgear calibrate``).

    Posterior medians of the parameters the diagnosis fits (and of the
    backlash, which it keeps fixed: returned under ``backlash``), and each
    run's T2 median as a position in its interval when the posterior has
    one T2 per run of this campaign.

    Raises
    ------
    DiagnosisError
        Not a Dataset, or it holds none of the nominal parameters.
    """
    if not isinstance(posterior, xr.Dataset):
        raise DiagnosisError(f"calibration: expected a posterior Dataset (posterior.nc of uqgear calibrate); "
                             f"got {type(posterior).__name__}")
    names = [spec.name for spec in nominal_parameters(case.design)] + ["backlash"]
    start = {name: float(posterior[name].median()) for name in names if name in posterior.data_vars}
    if not start:
        raise DiagnosisError(f"calibration: the posterior has none of the parameters {', '.join(names)}")
    positions = None
    if "adhesion_torque" in posterior.data_vars and posterior["adhesion_torque"].sizes.get("op") == case.n_op:
        other = [dim for dim in posterior["adhesion_torque"].dims if dim != "op"]
        median = np.asarray(posterior["adhesion_torque"].median(dim=other).values, dtype=float)
        width = np.maximum(case.adhesion_upper - case.adhesion_lower, 1e-12)
        positions = np.clip((median - case.adhesion_lower) / width, 0.0, 1.0)
    return start, positions


def load_calibration(calibration: str | os.PathLike[str] | xr.Dataset) -> xr.Dataset:
    """A calibration posterior from a Dataset, a ``posterior.nc`` file or the folder holding it."""
    if isinstance(calibration, xr.Dataset):
        return calibration
    if not isinstance(calibration, (str, os.PathLike)):
        raise DiagnosisError(f"calibration: expected a posterior.nc path, its folder or a Dataset; "
                             f"got {type(calibration).__name__}")
    path = Path(calibration)
    if path.is_dir():
        path = path / "posterior.nc"
    if not path.is_file():
        raise DiagnosisError(f"calibration: {path}: no such file (expected posterior.nc of uqgear calibrate)")

    return load_result(path)


# Full fits beyond the promoted ones while the gap stays unexplained (each costs about a screening).
_EXTRA_FULL_FITS = 3
# The nominal fit is restarted from a candidate's fit at most this many times.
_NOMINAL_REFITS = 2
# A candidate's nominal parameters must beat the nominal fit's robust cost by this much (about
# nats) to count as evidence that the nominal fit stopped in a local optimum.
_NOMINAL_MARGIN = 5.0


def effect_off_costs(nominal: FitResult, fits: Sequence[FitResult]) -> tuple[list[np.ndarray], list[float]]:
    """The nominal model at each fit's nominal parameters and T2 (its effect off): vectors and robust costs."""
    problem = nominal.problem
    starts = [problem.vector({key: value for key, value in candidate.values.items() if "." not in key},
                             candidate.vector[candidate.problem.n_global:]) for candidate in fits]
    if not starts:
        return [], []
    model, _ = problem.model_features(starts)
    return starts, [robust_cost(problem.residual_vector(problem.discrepancy(model[index])[0], v))
                    for index, v in enumerate(starts)]


def improved_nominal(nominal: FitResult, fits: Sequence[FitResult], *,
                     margin: float = _NOMINAL_MARGIN) -> FitResult | None:
    """A better nominal fit found through the candidates' full fits, or None.

    Every candidate contains the nominal model (its effect at strength 0).
    A full candidate fit refits the nominal parameters and T2 too; if the
    nominal model alone, at those values, fits the data better than the
    nominal fit did, the nominal fit had stopped in a local optimum (light
    loads, with contact loss near the bearing modes, have several), and a
    candidate would otherwise be credited with what is only the better
    optimum. The nominal model is then refitted from the best such point.
    """
    problem = nominal.problem
    starts, costs = effect_off_costs(nominal, fits)
    if not starts:
        return None
    best = int(np.argmin(costs))
    if costs[best] >= nominal.cost - margin:
        return None
    refit = fit(problem, [starts[best]], max_evaluations=30, tolerance=1e-3)
    refit.evaluations += nominal.evaluations
    refit.seconds += nominal.seconds
    return refit if refit.cost < nominal.cost - margin else None


def _score_candidates(case: RigCase, nominal: FitResult, nominal_held: HeldOut, nominal_gap: float,
                      effect_names: Sequence[str], hints: Mapping[str, float], rng: np.random.Generator,
                      promoted: int, timings: dict[str, float]
                      ) -> tuple[dict[str, CandidateScore], list[CandidateScore]]:
    """Screen every candidate against the nominal fit, fit the best ones in full; best score per effect."""
    clock = time.perf_counter()
    screened: list[CandidateScore] = []
    for name in effect_names:
        for candidate in candidates_for(name, case.design, hints=hints):
            result = fit_candidate(case, candidate, nominal, full=False, max_evaluations=6)
            screened.append(score_candidate(result, leave_one_out(result), nominal_held, "screening", rng))
    timings["screening"] += time.perf_counter() - clock

    clock = time.perf_counter()
    best_per_effect: dict[str, CandidateScore] = {}
    for entry in screened:
        if entry.effect not in best_per_effect or entry.score > best_per_effect[entry.effect].score:
            best_per_effect[entry.effect] = entry
    order = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
    all_scores = list(screened)
    # the runner-up is refitted too unless the screening already puts it far behind
    chosen = [entry for rank, entry in enumerate(order[:promoted])
              if rank == 0 or (entry.score > 0 and entry.score >= 0.25 * order[0].score)]

    def fit_in_full(entries: Sequence[CandidateScore]) -> None:
        for entry in entries:
            candidate = entry.fit.problem.candidate
            result = fit_candidate(case, candidate, nominal, full=True, max_evaluations=12, start=entry.fit)
            full = score_candidate(result, leave_one_out(result), nominal_held, "full", rng)
            all_scores.append(full)
            if full.score > best_per_effect[entry.effect].score:
                best_per_effect[entry.effect] = full

    fit_in_full(chosen)
    # An effect that changes the response only in a few runs (a bearing clearance where a bearing
    # unloads) cannot be screened with the nominal parameters held where the nominal model put
    # them to absorb that change: before a gap is called unexplained the next candidate variants
    # get a full fit, best screened first, until one explains it.
    remaining = sorted((entry for entry in screened if not any(entry is done for done in chosen)),
                       key=lambda entry: -entry.score)
    for entry in remaining[:_EXTRA_FULL_FITS]:
        if decide_verdict(nominal_gap, _ranking_of(best_per_effect))[0] != "unexplained":
            break
        fit_in_full([entry])
    full_fits = [entry for entry in all_scores if entry.stage == "full"]
    for entry, cost in zip(full_fits, effect_off_costs(nominal, [entry.fit for entry in full_fits])[1]):
        entry.effect_gain = cost - entry.fit.cost
    for entry in screened:
        entry.effect_gain = nominal.cost - entry.fit.cost
    timings["full_fits"] += time.perf_counter() - clock
    return best_per_effect, all_scores


def _ranking_of(best_per_effect: Mapping[str, CandidateScore]) -> list[dict[str, Any]]:
    """What :func:`decide_verdict` needs of the best variant of each effect, best first."""
    scores = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
    return [{"effect": s.effect, "score": s.score, "standard_error": s.standard_error,
             "shrink_fraction": s.shrink, "shrink_interval": [s.shrink_low, s.shrink_high],
             "gap_with_effect": s.gap, "effect_gain": s.effect_gain} for s in scores]


def run_diagnosis(case: RigCase, *, effects: Sequence[str] | None = None, seed: np.random.SeedSequence,
                  promoted: int = PROMOTED, calibration: xr.Dataset | None = None) -> DiagnosisResult:
    """Fit the nominal model and every candidate, score them on held-out runs, decide.

    Candidates are screened with their own parameters only (the nominal
    parameters and T2 stay at the nominal fit); the best effect, and up to
    ``promoted`` - 1 runners-up within a quarter of its score, are then
    fitted in full (all parameters), warm-started from the screening fit,
    and keep whichever fit scores better on held-out runs; while that leaves
    a significant gap unexplained, up to three more variants are fitted in
    full, best screened first, before the verdict says so. If a full fit
    shows that the nominal fit stopped in a local optimum
    (:func:`improved_nominal`), the nominal model is refitted from there and
    the candidates are scored again against it.

    Parameters
    ----------
    case : RigCase
        The prepared campaign (:func:`prepare_case`), optionally with an executor attached.
    effects : sequence of str, optional
        Candidate effects (default all six).
    seed : SeedSequence
        Seeds the bootstrap of the shrink fractions.
    promoted : int
        At most this many effects get a full fit.
    calibration : xarray.Dataset, optional
        A calibration posterior; the nominal fit starts from its medians.

    Returns
    -------
    DiagnosisResult
    """
    effect_names = _check_effects(effects)
    rng = np.random.default_rng(seed)
    timings: dict[str, float] = {"nominal_fit": 0.0, "screening": 0.0, "full_fits": 0.0}
    clock = time.perf_counter()
    if calibration is not None:
        start, positions = calibration_start(calibration, case)
        if "backlash" in start:
            case.design = case.design.replace(backlash=start.pop("backlash"))
        nominal = fit_nominal(case, start=start, positions=positions)
    else:
        nominal = fit_nominal(case)
    timings["nominal_fit"] += time.perf_counter() - clock
    locked = frequency_locked_lines(case)
    hints = signature_hints(case, locked)
    for attempt in range(_NOMINAL_REFITS + 1):
        clock = time.perf_counter()
        nominal_held = leave_one_out(nominal)
        nominal_gap = gap_metric(nominal_held.z)
        timings["nominal_fit"] += time.perf_counter() - clock
        best_per_effect, all_scores = _score_candidates(case, nominal, nominal_held, nominal_gap, effect_names,
                                                        hints, rng, promoted, timings)
        if attempt == _NOMINAL_REFITS:
            break
        clock = time.perf_counter()
        better = improved_nominal(nominal, [entry.fit for entry in all_scores if entry.stage == "full"])
        timings["nominal_fit"] += time.perf_counter() - clock
        if better is None:
            break
        # the candidates were scored against a nominal fit stuck in a local optimum: score them again
        nominal = better
    scores = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
    ranking = _ranking_of(best_per_effect)
    # drawn after the shrink bootstraps, so their numbers do not depend on this
    nominal_interval = bootstrap_gap(nominal_held.z, rng)
    if scores:
        ranking[0]["gap_interval"] = list(bootstrap_gap(scores[0].held.z, rng))
    decision = decide(nominal_gap, ranking, nominal_gap_interval=nominal_interval)
    verdict, reason = decision.verdict, decision.reason
    where = where_gap(nominal_held.z, case)
    families = family_character(nominal_held.z, case, locked)
    return DiagnosisResult(case=case, nominal=nominal, nominal_held=nominal_held, scores=scores,
                           all_scores=all_scores, verdict=verdict, reason=reason, nominal_gap=nominal_gap,
                           where=where, families=families, locked_lines=locked, hints=hints,
                           effects=effect_names, timings=timings, decision=decision,
                           nominal_gap_interval=nominal_interval)


# ---------------------------------------------------------------------------------------------- outputs

def _held_spectra(result: DiagnosisResult, ops: Sequence[int]) -> xr.Dataset:
    """Amplitude spectra of the rig and of the held-out predictions (nominal, best effect) for some runs."""
    case = result.case
    best = result.best
    sources = ["rig", "nominal"] + (["with_effect"] if best is not None else [])
    taper = scipy.signal.get_window("hann", case.size)
    frequency = np.fft.rfftfreq(case.size, 1.0 / case.fs)
    top = min(case.processors[0].limit, 3.6 * case.design.z1 * float(case.speeds[list(ops)].max()) / 60.0)
    keep = frequency <= top
    values = np.full((len(ops), len(sources), len(case.channels), int(keep.sum())), np.nan)

    def spectrum(record: np.ndarray) -> np.ndarray:
        record = np.asarray(record, dtype=float)
        return (np.abs(np.fft.rfft((record - record.mean()) * taper)) * (2.0 / taper.sum()))[keep]

    for i, op in enumerate(ops):
        for c, channel in enumerate(case.channels):
            if case.usable[op, c]:
                values[i, 0, c] = spectrum(case.rig[channel].values[op])
        fits = [(1, result.nominal.problem, result.nominal_held.vectors[op])]
        if best is not None:
            fits.append((2, best.fit.problem, best.held.vectors[op]))
        for source, problem, vector in fits:
            task = problem.run_task(vector, op)
            run = case.simulator.run(task.op, task.design, task.mesh_stiffness_scale, task.adhesion_torque,
                                     task.effects, task.periodicity)
            for c, channel in enumerate(case.channels):
                values[i, source, c] = spectrum(run.records[channel])
    # mean amplitude of the rig's white noise in a bin: s sqrt(pi/2), s its per-quadrature spread
    floor = (case.noise_std[list(ops)] * math.sqrt(2.0 * np.sum(taper ** 2)) / taper.sum()
             * math.sqrt(math.pi / 2.0))
    return xr.Dataset(
        {"amplitude_spectrum": (("spectrum_op", "source", "channel", "frequency"), values,
                                {"long_name": "amplitude spectrum (Hann window), held-out prediction for the models",
                                 "units": "channel units"}),
         "spectrum_noise_floor": (("spectrum_op", "channel"), floor,
                                  {"long_name": "mean amplitude of the rig's white noise in one bin",
                                   "units": "channel units"})},
        coords={"spectrum_op": ("spectrum_op", np.asarray(ops, dtype=int), {"long_name": "run index"}),
                "source": ("source", sources), "channel": ("channel", list(case.channels)),
                "frequency": ("frequency", frequency[keep], {"units": "Hz"})})


def _family_map(z: np.ndarray, case: RigCase) -> np.ndarray:
    """Excess RMS (capped) standardised discrepancy per run, channel and feature family."""
    families = np.array(case.layout.families)
    out = np.full((case.n_op, len(case.channels), len(FEATURE_FAMILIES)), np.nan)
    for k, family in enumerate(FEATURE_FAMILIES):
        chosen = families == family
        if not chosen.any():
            continue
        squares = capped_squares(z[:, :, chosen])
        with np.errstate(invalid="ignore"):
            mean = np.nanmean(np.where(np.isfinite(squares), squares, np.nan), axis=-1)
        out[:, :, k] = np.sqrt(np.maximum(mean - _GAP_NOISE_LEVEL, 0.0))
    return out


def result_dataset(result: DiagnosisResult, spectra: xr.Dataset | None = None) -> xr.Dataset:
    """The gap maps and scores as a Dataset (written to ``diagnosis.nc``)."""
    case = result.case
    layout = case.layout
    best = result.best
    dims = ("op", "channel", "feature")
    data: dict[str, Any] = {
        "observed": (dims, case.observed, {"long_name": "rig features", "units": "channel units"}),
        "nominal_model": (dims, result.nominal.model[..., layout.columns],
                          {"long_name": "nominal model features (fitted to all runs)", "units": "channel units"}),
        "nominal_heldout_model": (dims, result.nominal_held.model[..., layout.columns],
                                  {"long_name": "nominal model features, run left out of the fit",
                                   "units": "channel units"}),
        "z_nominal": (dims, result.nominal.z, {"long_name": "standardised discrepancy, nominal fit", "units": "1"}),
        "z_nominal_heldout": (dims, result.nominal_held.z,
                              {"long_name": "standardised discrepancy on held-out runs, nominal model", "units": "1"}),
        "gap_map_nominal": (("op", "channel", "family"), _family_map(result.nominal_held.z, case),
                            {"long_name": "excess RMS standardised discrepancy (capped at 10) per feature family, "
                                          "held-out runs, nominal model", "units": "1"}),
        "noise_std": (("op", "channel"), case.noise_std, {"long_name": "white-noise level of the rig records",
                                                          "units": "channel units"}),
        "nominal_adhesion_torque": (("op",), result.nominal.adhesion_torques,
                                    {"long_name": "adhesion torque T2 of the nominal fit", "units": "N m"}),
        "nominal_periodic": (("op",), result.nominal.periodic.astype(np.int8),
                             {"long_name": "nominal model's steady response repeats (1) or not (0)", "units": "1"}),
    }
    if best is not None:
        data["with_effect_heldout_model"] = (dims, best.held.model[..., layout.columns],
                                             {"long_name": f"model with {best.label}, run left out of the fit",
                                              "units": "channel units"})
        data["z_with_effect_heldout"] = (dims, best.held.z, {
            "long_name": f"standardised discrepancy on held-out runs, model with {best.label}", "units": "1"})
        data["gap_map_with_effect"] = (("op", "channel", "family"), _family_map(best.held.z, case), {
            "long_name": f"excess RMS standardised discrepancy per feature family, held-out runs, with {best.label}",
            "units": "1"})
    scores = result.scores
    data.update({
        "score": (("candidate",), [s.score for s in scores],
                  {"long_name": "held-out log predictive density gain over nominal minus penalty", "units": "nat"}),
        "delta_log_density": (("candidate",), [s.delta_log_density for s in scores],
                              {"long_name": "held-out log predictive density gain over nominal", "units": "nat"}),
        "delta_log_density_se": (("candidate",), [s.standard_error for s in scores],
                                 {"long_name": "standard error of the gain (over runs)", "units": "nat"}),
        "gap_with_effect": (("candidate",), [s.gap for s in scores],
                            {"long_name": "held-out gap with the effect", "units": "1"}),
        "shrink_fraction": (("candidate",), [s.shrink for s in scores],
                            {"long_name": "1 - gap with effect / nominal gap, held-out runs", "units": "1"}),
        "shrink_fraction_bounds": (("candidate", "bound"), [[s.shrink_low, s.shrink_high] for s in scores],
                                   {"long_name": "5 % and 95 % bootstrap quantiles (runs resampled)",
                                    "units": "1"}),
    })
    coords = {
        "op": ("op", np.arange(case.n_op)),
        "pinion_speed": ("op", case.speeds, {"units": "rpm"}),
        "drive_torque": ("op", case.drive_torques, {"units": "N m"}),
        "channel": ("channel", list(case.channels)),
        "feature": ("feature", list(layout.names)),
        "feature_family": ("feature", list(layout.families)),
        "feature_kind": ("feature", list(layout.kinds)),
        "family": ("family", list(FEATURE_FAMILIES)),
        "candidate": ("candidate", [s.label for s in scores]),
        "candidate_effect": ("candidate", [s.effect for s in scores]),
        "bound": ("bound", ["q05", "q95"]),
    }
    ds = xr.Dataset(data, coords=coords)
    if spectra is not None:
        ds = ds.merge(spectra)
    ds.attrs.update(title="uqgear sim-to-real gap diagnosis", verdict=result.verdict, reason=result.reason,
                    gap_metric=GAP_METRIC, nominal_gap=result.nominal_gap,
                    model_error=json.dumps(case.model_error), effects_considered=json.dumps(list(result.effects)),
                    nominal_parameters=json.dumps(result.nominal.values))
    return ds


def summary(result: DiagnosisResult, *, source: str, seed_text: str, timings: Mapping[str, float]) -> dict[str, Any]:
    """The JSON summary of a diagnosis (``diagnosis.json``)."""
    case = result.case
    best = result.best
    named = best if best is not None and best.effect == result.verdict else None
    chosen = named if named is not None else best
    gap = {
        "metric": GAP_METRIC,
        "baseline": result.nominal_gap,
        "with_effect": chosen.gap if chosen is not None else None,
        "effect": chosen.effect if chosen is not None else None,
        "effect_named": named is not None,
        "shrink_fraction": chosen.shrink if chosen is not None else None,
        "shrink_interval": [chosen.shrink_low, chosen.shrink_high] if chosen is not None else None,
        "evaluated_on": {
            "scheme": "leave-one-operating-point-out: each run predicted by the models fitted without it",
            "ops": list(range(case.n_op)),
            "pinion_speed": [float(v) for v in case.speeds],
            "drive_torque": [float(v) for v in case.drive_torques],
        },
        "noise_threshold": NOISE_GAP_THRESHOLD,
        "baseline_interval": [float(v) for v in result.nominal_gap_interval],
    }
    decision = result.decision or Decision(result.verdict, result.reason)
    return {
        "verdict": result.verdict,
        "reason": result.reason,
        "borderline": [dict(entry) for entry in decision.borderline],
        "partial": decision.partial,
        "remaining_gap": ({"value": decision.remaining_gap, "unexplained": True, "where": result.where}
                          if decision.partial else None),
        "gap": gap,
        "where": result.where,
        "families": result.families,
        "frequency_locked_lines": result.locked_lines,
        "ranking": result.ranking(),
        "nominal": {"parameters": result.nominal.values,
                    "adhesion_torque": [float(v) for v in result.nominal.adhesion_torques],
                    "periodic_runs": [bool(v) for v in result.nominal.periodic],
                    "converged": result.nominal.converged},
        "thresholds": {"score": SCORE_THRESHOLD, "shrink_fraction": SHRINK_THRESHOLD,
                       "nominal_gap": NOISE_GAP_THRESHOLD, "partial_shrink": PARTIAL_SHRINK_THRESHOLD},
        "model_error": case.model_error,
        "effects_considered": list(result.effects),
        "rig": {"source": source, "title": str(case.rig.attrs.get("title", "")), "n_op": case.n_op,
                "channels": list(case.channels)},
        "seed": seed_text,
        "timing_s": dict(timings),
    }


def _json_clean(value: Any) -> Any:
    """Replace non-finite floats by None (JSON has no NaN)."""
    if isinstance(value, float) or isinstance(value, np.floating):
        return float(value) if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _json_clean(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_clean(item) for item in value]
    return value


def _cpu_seconds() -> float:
    """CPU time of this process and of its finished worker processes, s."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def _as_seed(seed: int | np.random.SeedSequence) -> np.random.SeedSequence:
    return as_seed_sequence(seed, error=DiagnosisError)


def load_rig_input(rig: str | os.PathLike[str] | xr.Dataset) -> tuple[xr.Dataset, str]:
    """A validated rig Dataset from a path or a Dataset, and a text naming its source."""
    from .rig import read_rig, validate_rig

    if isinstance(rig, xr.Dataset):
        validate_rig(rig, where="rig data")
        return rig, str(rig.attrs.get("title", "rig Dataset"))
    if isinstance(rig, (str, os.PathLike)):
        return read_rig(rig), str(rig)
    raise RigDataError(f"rig: expected a uqgear-rig/1 file path or an xarray Dataset; got {type(rig).__name__}")


def _resolve_design(design: Design | str | os.PathLike[str] | None, rig: xr.Dataset) -> Design:
    from .design import load_design
    from .rig import rig_design

    if design is None:
        return rig_design(rig)
    if isinstance(design, Design):
        return design
    if isinstance(design, (str, os.PathLike)):
        return load_design(str(design))
    raise DiagnosisError(f"design: expected a Design, a design file or name, or None (the rig file's design); "
                         f"got {type(design).__name__}")


def diagnosis_result(rig: str | os.PathLike[str] | xr.Dataset, *,
                     design: Design | str | os.PathLike[str] | None = None, effects: Sequence[str] | None = None,
                     seed: int | np.random.SeedSequence = 0, workers: int | None = None,
                     calibration: str | os.PathLike[str] | xr.Dataset | None = None
                     ) -> tuple[dict[str, Any], xr.Dataset]:
    """Diagnose the sim-to-real gap of a rig campaign without writing anything.

    Parameters are those of :func:`diagnose` (less the output options).

    Returns
    -------
    (content, maps) : tuple of dict and xarray.Dataset
        The content of ``diagnosis.json`` and the Dataset of ``diagnosis.nc``
        (gap maps over op x channel x family, scores, held-out spectra).
    """
    content, maps, _ = _diagnosis(rig, design=design, effects=effects, seed=seed, workers=workers,
                                  calibration=calibration)
    return content, maps


def _diagnosis(rig, *, design, effects, seed, workers, calibration) -> tuple[dict[str, Any], xr.Dataset, Design]:
    started = time.perf_counter()
    cpu_started = _cpu_seconds()
    effect_names = _check_effects(effects)
    seed_sequence = _as_seed(seed)
    workers = _check_workers(workers)
    dataset, source = load_rig_input(rig)
    nominal_design = _resolve_design(design, dataset)
    posterior = load_calibration(calibration) if calibration is not None else None
    noise_seed, run_seed = seed_sequence.spawn(2)
    case = prepare_case(dataset, nominal_design, seed=noise_seed)
    case.executor = RunExecutor(case, workers)
    try:
        result = run_diagnosis(case, effects=effect_names, seed=run_seed, calibration=posterior)
        worst = np.argsort([-np.nansum(capped_squares(result.nominal_held.z[op])) for op in range(case.n_op)])
        spectra = _held_spectra(result, sorted(int(op) for op in worst[:2]))
    finally:
        case.executor.close()
        case.executor = None
    timings = dict(result.timings, total_wall=time.perf_counter() - started,
                   total_cpu=_cpu_seconds() - cpu_started, workers=float(workers))
    content = _json_clean(summary(result, source=source, seed_text=str(seed_sequence.entropy), timings=timings))
    content["nominal"]["start"] = "calibration posterior medians" if posterior is not None else "design values"
    maps = result_dataset(result, spectra)
    maps.attrs["verdict"] = content["verdict"]
    return content, maps, nominal_design


def default_workers() -> int:
    """Worker processes by default: one per two CPUs.

    A worker's own numpy (BLAS) calls already keep about two cores busy: on
    2 CPUs one process diagnoses a campaign about 13 % faster than two.
    """
    return max(1, (os.cpu_count() or 1) // 2)


def _check_workers(workers: int | None) -> int:
    if workers is None:
        return default_workers()
    if isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1:
        raise DiagnosisError(f"workers: expected an integer >= 1; got {workers!r}")
    return int(workers)


def diagnose(rig: str | os.PathLike[str] | xr.Dataset, out_dir: str | os.PathLike[str], *,
             design: Design | str | os.PathLike[str] | None = None, effects: Sequence[str] | None = None,
             seed: int | np.random.SeedSequence = 0, workers: int | None = None,
             calibration: str | os.PathLike[str] | xr.Dataset | None = None, report: bool = True) -> dict[str, Any]:
    """Diagnose the sim-to-real gap of a rig campaign and write the results.

    Parameters
    ----------
    rig : path or xarray.Dataset
        A ``uqgear-rig/1`` file or Dataset.
    out_dir : path
        Output folder (created if missing): ``diagnosis.json``,
        ``diagnosis.nc`` (gap maps, scores, spectra) and ``report.html``,
        each written atomically.
    design : Design, design file or name, optional
        The nominal design; by default the rig file's ``design`` attribute.
    effects : sequence of str, optional
        Candidate effects (default: all six of the library).
    seed : int or SeedSequence
        Seeds the noise calibration and the bootstrap.
    workers : int, optional
        Worker processes for the simulations (default: one per two CPUs, :func:`default_workers`).
    calibration : path or xarray.Dataset, optional
        A calibration of this campaign (``posterior.nc`` of ``uqgear
        calibrate``, or its folder): the nominal fit starts from its posterior
        medians (backlash included) instead of the design's values.
    report : bool
        Write ``report.html``.

    Returns
    -------
    dict
        The content of ``diagnosis.json``: ``verdict``, ``gap``, ``where``,
        ``ranking`` and more.

    Raises
    ------
    RigDataError
        The rig file or Dataset does not follow the format.
    DiagnosisError
        An unknown effect, a bad seed, design or worker count.
    """
    # the cheap checks first: a bad option or folder fails before minutes of fitting
    _check_effects(effects)
    _as_seed(seed)
    _check_workers(workers)
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DiagnosisError(f"out_dir: cannot create {out} ({exc})") from None
    content, maps, nominal_design = _diagnosis(rig, design=design, effects=effects, seed=seed, workers=workers,
                                               calibration=calibration)
    save_result(maps, out / "diagnosis.nc", seed=_as_seed(seed), design=nominal_design)
    write_text_atomic(out / "diagnosis.json", json.dumps(content, indent=2, default=json_default))
    if report:
        from .diagnosis_report import write_diagnosis_report

        write_diagnosis_report(content, maps, out / "report.html")
    return content
