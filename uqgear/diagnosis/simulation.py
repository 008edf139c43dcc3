"""Model records of a campaign's runs on the rig's time grid, and the rig's feature processing for them.

:class:`CampaignSimulator` integrates the model for each run (steady state
after a run-in, one period tiled when the response repeats) and band-limits
and resamples it like the rig's acquisition; :class:`RunProcessor` reduces
records of either source with exactly the rig's feature processing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg

from ..physics.design import Design, design_key_bounds
from ..physics.effects import Effect
from ..physics.integration import _HISTORY_COLUMNS, _integrate_fast, steps_per_period
from ..physics.model import build_model
from ..rig import features as feature_module
from ..rig.features import feature_definitions
from ..rig.virtual_rig import frequency_filter
from .errors import DiagnosisError

# Run-in simulated before the kept window: about 9 time constants of the
# slowest decay (about 17 ms on the reference design: a transient falls by 2e-5).
_RUN_IN = 0.15
# Guard on each side of a non-periodic window, so that the band-limiting
# filter's wrap-around stays outside the record.
_GUARD = 0.025
# Highest mesh-stiffness scale for which the step count is fixed in advance,
# so that finite-difference neighbours integrate on the same grid.
_MAX_STIFFNESS_SCALE = 1.5


# ---------------------------------------------------------------------------------------------- feature processing


class RunProcessor:
    """The rig's feature processing for one run (speed, sampling rate, record length), built once.

    Wraps the line fit and the spectral estimates of :mod:`uqgear.rig.features`
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
        :func:`uqgear.rig.features.extract_features`.
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
        # the stiffest bearings a fit may propose (candidates.nominal_parameters), inside the design's range
        stiff = design.replace(k1=min(design.k1 * 2.0, design_key_bounds("k1")[1]),
                               k2=min(design.k2 * 2.0, design_key_bounds("k2")[1]))
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

