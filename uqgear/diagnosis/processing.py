"""The rig's feature processing for one run, built once and applied to records of the rig and of the model alike."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.fft
import scipy.linalg

from ..physics.design import Design
from ..rig import features as feature_module
from ..rig.features import feature_definitions
from ..rig.order_tracking import TrackerImage

#: Fewest low-band bins whose median :meth:`RunProcessor.band_floor` reads: the median of n
#: white-noise bins scatters by about 1.44 / sqrt(n) of the density (36 % at 16 bins).
MIN_FLOOR_BINS = 16


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
            design,
            n_harmonics=options["n_harmonics"],
            n_sidebands=options["n_sidebands"],
            n_shaft_orders=options["n_shaft_orders"],
            n_motor_lines=options["n_motor_lines"],
        )
        self.names = [definition.name for definition in self.definitions]
        self.columns = {name: index for index, name in enumerate(self.names)}
        self.line_columns = np.array([i for i, d in enumerate(self.definitions) if d.is_line], dtype=int)
        # each feature's frequency at this speed, Hz (NaN for features that are not lines)
        self.frequencies = np.array([d.order for d in self.definitions], dtype=float) * self.speed / 60.0
        line_orders = np.array([self.definitions[i].order for i in self.line_columns])
        self.limit = options["band_limit"]
        self.low_band = tuple(options["low_band"])
        self.taper = feature_module.analysis_window(options["window"], self.size)
        self.fit = feature_module.LineFit(line_orders * self.speed / 60.0, self.fs, self.size, self.limit, self.taper)
        # one column per fitted line (lines within a bin of each other share one fitted amplitude): sums of
        # line power count each line once
        _, first = np.unique(self.fit.groups, return_index=True)
        self.distinct_line_columns = self.line_columns[self.fit.inside[first]]
        # the other lines of a group read the first one's amplitude: the same spectral line under another name
        self.merged_columns = np.setdiff1d(self.line_columns[self.fit.inside], self.distinct_line_columns)
        frequencies = np.fft.rfftfreq(self.size, 1.0 / self.fs)
        self.excluded = feature_module.excluded_bins(
            frequencies,
            self.speed,
            design,
            line_orders,
            options["n_sidebands"],
            self.low_band,
            self.limit,
            self.fs / self.size,
        )
        self.line_noise = self._line_noise_scale()
        self._sideband_layout = _sideband_layout(self.columns, design, options)
        in_band = (frequencies >= self.low_band[0]) & (frequencies <= self.low_band[1])
        self._band_bins = np.flatnonzero(in_band)
        edge = (self._band_bins == 0) | ((self.size % 2 == 0) & (self._band_bins == self.size // 2))
        self._band_weights = np.where(edge, 1.0, 2.0)
        self._window_power = float(np.sum(self.taper**2))
        self.notch: tuple[float, ...] = ()

    def set_notch(self, frequencies: Sequence[float], half_width: int) -> None:
        """Leave the bins within ``half_width`` of each frequency (Hz) out of the low band, rig and model alike.

        For line interference (:mod:`uqgear.diagnosis.allowances.interference`). The rig's
        low band is then computed by :meth:`model_features`'s formula too.
        """
        resolution = self.fs / self.size
        keep = np.ones(self._band_bins.size, dtype=bool)
        for frequency in frequencies:
            keep &= np.abs(self._band_bins * resolution - frequency) > half_width * resolution + 1e-9
        self._band_bins = self._band_bins[keep]
        self._band_weights = self._band_weights[keep]
        self.notch = self.notch + tuple(float(f) for f in frequencies)

    def low_band_rms(self, records: np.ndarray) -> np.ndarray:
        """RMS of the low band (without notched bins) of records (R, N): the one-sided periodogram density summed."""
        return self._centred_low_band_rms(records - records.mean(axis=1, keepdims=True))

    def _band_density(self, centred: np.ndarray) -> np.ndarray:
        """One-sided periodogram density (scipy's 'density' scaling) of centred records at the low band's bins."""
        spectrum = scipy.fft.rfft(centred * self.taper, axis=1)  # scipy's takes half numpy's time here
        return np.abs(spectrum[:, self._band_bins]) ** 2 * (self._band_weights / (self.fs * self._window_power))

    def _centred_low_band_rms(self, centred: np.ndarray) -> np.ndarray:
        return np.sqrt(self._band_density(centred).sum(axis=1) * self.fs / self.size)

    def band_floor(self, records: np.ndarray) -> np.ndarray:
        """Std (R,) of white noise whose density is the median periodogram bin of the low band (without notches).

        The floor between the lines (``noise_std``) is read over the whole
        band, where the gears' shaft-order lines (every gear order with
        manufactured gears, accelerations rising with frequency) can fill most
        bins and raise it several times over the sensor's noise. The low
        band's own bins see that noise with few lines on them: a line or an
        oscillation in the band takes a few of its bins and leaves their
        median. NaN where the band has fewer than :data:`MIN_FLOOR_BINS` bins.

        Examples
        --------
        >>> import numpy as np
        >>> from uqgear.physics.design import load_design
        >>> from uqgear.diagnosis.case import FEATURE_OPTIONS
        >>> options = dict(FEATURE_OPTIONS, band_limit=8000.0)
        >>> processor = RunProcessor(load_design("locomotive"), 800.0, 20480.0, 20480, options)
        >>> noise = np.random.default_rng(0).standard_normal((16, 20480))  # unit white noise
        >>> round(float(processor.band_floor(noise).mean()), 1)
        1.0
        """
        records = np.atleast_2d(np.asarray(records, dtype=float))
        if self._band_bins.size < MIN_FLOOR_BINS:
            return np.full(records.shape[0], np.nan)
        density = self._band_density(records - records.mean(axis=1, keepdims=True))
        # a white-noise bin is exponentially distributed about the density, whose median is ln 2 times its mean
        return np.sqrt(np.median(density, axis=1) / math.log(2.0) * 0.5 * self.fs)

    def features(self, records: np.ndarray, *, lines: bool = True) -> np.ndarray:
        """Feature values (R, F) of records (R, N); NaN rows where a sample is NaN, NaN lines without ``lines``."""
        records = np.atleast_2d(np.asarray(records, dtype=float))
        out = np.full((records.shape[0], len(self.definitions)), np.nan)
        usable = ~np.isnan(records).any(axis=1)
        if usable.any():
            out[usable] = feature_module.block_features(
                records[usable],
                self.fit,
                self.excluded,
                self.fs,
                self.taper,
                self.low_band,
                self.columns,
                self.line_columns,
                len(self.definitions),
                lines=lines,
            )
            if self.notch:
                out[usable, self.columns["low_band_rms"]] = self.low_band_rms(records[usable])
        return out

    def model_features(self, records: np.ndarray, tracking: TrackerImage | None = None) -> np.ndarray:
        """Features (R, F) of noise-free model records (R, N) without NaN.

        The same line fit, low-band power, RMS and kurtosis as :meth:`features`;
        the noise floor and the crest factor, which describe noisy records,
        are left NaN (they are not compared), which saves most of the time.
        With ``tracking`` (the rig's record of this run was resampled on its
        own mesh lines) the rows are runs of C channels each, in the image's
        channel order, and their mesh sidebands are read as that tracking
        leaves them (:meth:`~uqgear.rig.order_tracking.TrackerImage.sidebands`).
        """
        records = np.atleast_2d(np.asarray(records, dtype=float))
        out = np.full((records.shape[0], len(self.definitions)), np.nan)
        if tracking is None:
            out[:, self.line_columns] = self.fit.amplitudes(records)
        else:
            out[:, self.line_columns] = np.abs(self._line_phasors(records, tracking))
        centred = records - records.mean(axis=1, keepdims=True)
        out[:, self.columns["low_band_rms"]] = self._centred_low_band_rms(centred)
        square = centred * centred
        mean_square = np.mean(square, axis=1)
        out[:, self.columns["rms"]] = np.sqrt(mean_square)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[:, self.columns["kurtosis"]] = np.where(
                mean_square > 0, np.mean(square * square, axis=1) / mean_square**2, np.nan
            )
        return out

    def model_phasors(self, records: np.ndarray) -> np.ndarray:
        """:meth:`features` (noise floor included) with each line's complex phasor in place of its amplitude (R, F).

        For model records with lines at every shaft order (pitch errors), whose
        forest of lines raises the noise floor a rig's records are read with.
        """
        records = np.atleast_2d(np.asarray(records, dtype=float))
        out = self.features(records, lines=False).astype(complex)
        out[:, self.line_columns] = self.fit.phasors(records)
        return out

    def model_line_phasors(self, records: np.ndarray) -> np.ndarray:
        """Each line's complex phasor (R, F) as in :meth:`model_phasors`, every other feature NaN.

        For tests that read the lines' phases alone (the sideband phase sums):
        the noise floor and spectral features :meth:`model_phasors` also
        computes cost about three times the line fit.
        """
        records = np.atleast_2d(np.asarray(records, dtype=float))
        out = np.full((records.shape[0], len(self.definitions)), np.nan, dtype=complex)
        out[:, self.line_columns] = self.fit.phasors(records)
        return out

    def _line_phasors(self, records: np.ndarray, tracking: TrackerImage) -> np.ndarray:
        """The line phasors (R, lines) of model records, their mesh sidebands as ``tracking`` leaves them."""
        phasors = self.fit.phasors(records)
        if self._sideband_layout is None:
            return phasors
        mesh_columns, plus_columns, minus_columns, offsets = self._sideband_layout
        n_channels = len(tracking.accelerations)
        full = np.full((records.shape[0], len(self.definitions)), np.nan, dtype=complex)
        full[:, self.line_columns] = phasors
        runs = full.reshape(-1, n_channels, len(self.definitions))
        mesh, plus, minus = runs[..., mesh_columns], runs[..., plus_columns], runs[..., minus_columns]
        plus, minus = tracking.sidebands(mesh, plus, minus, offsets)
        runs[..., plus_columns] = plus
        runs[..., minus_columns] = minus
        return runs.reshape(records.shape[0], -1)[:, self.line_columns]

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
        per_centre = np.sqrt(0.5 * (diagonal[1 : 1 + fit.n_centres] + diagonal[1 + fit.n_centres :]))
        line_scale = np.full(self.line_columns.size, np.nan)
        line_scale[fit.inside] = per_centre[fit.groups]
        scale[self.line_columns] = line_scale
        return scale


def _sideband_layout(
    columns: Mapping[str, int], design: Design, options: Mapping[str, Any]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The columns of each mesh harmonic (K,) and of its sidebands above and below (K, M), with their offsets (M,).

    Offsets are in pinion orders: the pinion's ``j`` and the gear's
    ``j z1 / z2``. None where the feature set has no mesh sidebands.
    """
    harmonics = range(1, int(options["n_harmonics"]) + 1)
    shafts = [(shaft, j) for shaft in ("pinion", "gear") for j in range(1, int(options["n_sidebands"]) + 1)]
    names = [f"mesh{k}" for k in harmonics]
    names += [f"mesh{k}_sb_{shaft}{sign}{j}" for k in harmonics for shaft, j in shafts for sign in "+-"]
    if not shafts or any(name not in columns for name in names):
        return None
    mesh = np.array([columns[f"mesh{k}"] for k in harmonics])
    plus = np.array([[columns[f"mesh{k}_sb_{shaft}+{j}"] for shaft, j in shafts] for k in harmonics])
    minus = np.array([[columns[f"mesh{k}_sb_{shaft}-{j}"] for shaft, j in shafts] for k in harmonics])
    ratio = design.z1 / design.z2
    offsets = np.array([j * (1.0 if shaft == "pinion" else ratio) for shaft, j in shafts])
    return mesh, plus, minus, offsets


__all__ = ["RunProcessor"]
