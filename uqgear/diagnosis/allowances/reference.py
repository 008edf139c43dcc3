"""A healthy reference campaign from the same rig: learn what the model lacks there, carry it to a test campaign.

A real rig carries structure the gear model lacks: transfer paths between
the gear body and a sensor (a housing resonance on the accelerometer path,
the accelerometer's own response), extra modes, its own TE definition. A
campaign recorded on the same rig while the gearbox was known to be good
shows that structure against the fitted nominal model; a diagnosis of a
later campaign with it (``uqgear diagnose TEST.nc --reference HEALTHY.nc``)
then names what changed between the two instead of the rig's own structure.

Method (docs/model/unmodelled-effects.md section 6.1):

1. **Compatibility** (:mod:`.compatibility`). Both campaigns must state the
   same design and channels and every test operating point needs a
   reference point at the same speed and torque; otherwise
   :class:`~uqgear.diagnosis.DiagnosisError` names the file and what differs.
2. **Reference fit.** The reference is prepared like any campaign
   (:func:`~uqgear.diagnosis.case.prepare_case`) and the nominal model fitted
   to it (:func:`~uqgear.diagnosis.fitting.fit_nominal`).
3. **What the model lacks.** For every line that stands clear of the noise
   in the reference (amplitude at least :data:`MIN_LINE_SNR` per-quadrature
   noise spreads, in rig and model) the log ratio rig/model is a sample of
   the channel's transfer correction at the line's frequency; a gain curve
   over frequency (:mod:`.gain_curve`) is fitted to them per channel. Its
   predictive spread (curve uncertainty plus the scatter) is the
   correction's uncertainty. Band power, RMS and kurtosis are not line
   spectra: their correction is read directly at the matched reference run
   (the RMS after the model's lines are taken through the curve one by one,
   :func:`~uqgear.diagnosis.execution.transferred_rms`).
4. **Carried to the test campaign.** The test campaign's model features are
   multiplied by the gain at their frequencies (the observed features and
   the noise floor stay as recorded, so the Rice statistics of the lines
   stay exact) and the correction's relative uncertainty widens their
   model error (:class:`~uqgear.diagnosis.case.FeatureModelError`):
   :meth:`ReferenceCorrection.apply` returns the corrected case. Fits,
   held-out scoring and the verdict then run unchanged on it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np
import xarray as xr

from ...physics.design import Design
from ..case import FeatureModelError, RigCase, prepare_case
from ..execution import RunExecutor, transferred_rms
from ..fitting import fit_nominal
from ..settings import DEFAULT_SETTINGS
from .compatibility import match_operating_points
from .gain_curve import DIRECT_FLOOR, GainCurve, fit_gain_curve

#: A line enters the learned correction when rig and model both stand this many per-quadrature noise spreads up.
MIN_LINE_SNR = 5.0
# Frequencies of the gain curve stored in diagnosis.json (per channel).
_CURVE_POINTS = 120
# The local noise floor at a line is the median of the free periodogram bins within this
# relative distance of it (at least _LOCAL_MIN_HZ): narrower than a resonance of damping 0.05
# (half-power half-width 5 %), wide enough for a median of about a hundred bins at 1 Hz.
# Where fewer than _LOCAL_MIN_BINS free bins lie that near (shaft lines inside the excluded low
# band), the nearest _LOCAL_MIN_BINS free bins are taken instead.
_LOCAL_WIDTH = 0.03
_LOCAL_MIN_HZ = 50.0
_LOCAL_MIN_BINS = 20


# ---------------------------------------------------------------------------------------------- compatibility


@dataclass(frozen=True)
class ReferenceCorrection:
    """What a healthy reference campaign shows against the fitted nominal model (see the module docstring).

    Attributes
    ----------
    source : str
        The reference file (or a Dataset's title).
    rig : xarray.Dataset
        The reference campaign (validated).
    channels : tuple of str
    curves : dict
        Per channel, its :class:`GainCurve`.
    direct : dict
        Per feature kind (``band``, ``rms``, ``kurtosis``), (n_ref_op, n_channel) log
        corrections read at each reference run (NaN: none).
    summary : dict
        The reference fit and what was learned, JSON-ready (``reference`` of ``diagnosis.json``).
    """

    source: str
    rig: xr.Dataset
    channels: tuple[str, ...]
    curves: dict[str, GainCurve]
    direct: dict[str, np.ndarray]
    summary: dict[str, Any]

    #: Its entry in ``diagnosis.json``.
    key: ClassVar[str] = "reference"

    @property
    def applied(self) -> bool:
        """A learned correction is always carried over."""
        return True

    def apply(self, case: RigCase, matched: np.ndarray) -> tuple[RigCase, dict[str, Any]]:
        """The test campaign with the correction on it, and the JSON-ready record of what was applied.

        The new case's model features are multiplied by ``transfer``, its
        observed lines divided by their noise colour, and its model error is
        a :class:`FeatureModelError` widened by the correction's relative
        uncertainty; ``case`` itself is not changed.
        """
        line_gain, spread = line_gains(case, self.curves)
        gain = line_gain.copy()
        processor_kinds = _kinds_of_all(case)
        for op in range(case.n_op):
            for c, channel in enumerate(case.channels):
                curve = self.curves.get(channel)
                reference_channel = self.channels.index(channel)
                for kind, values in self.direct.items():
                    value = values[matched[op], reference_channel]
                    if not math.isfinite(value):
                        continue
                    columns = np.flatnonzero(processor_kinds == kind)
                    gain[op, c, columns] = math.exp(value)
                    scatter = curve.scatter if curve is not None else DIRECT_FLOOR
                    spread[op, c, columns] = max(scatter, DIRECT_FLOOR)
        # the test records' own noise colour: lines and their model are both divided by it, so that the
        # white-noise level of the record is the right noise for them (Rice statistics stay exact)
        colour = noise_colour(case)
        observed_all = case.observed_all / colour
        compared = gain[..., case.layout.columns]
        widened = spread[..., case.layout.columns]
        kinds = np.array(case.layout.kinds)
        # a log-gain spread s is a relative error of about s on an amplitude
        model_error = FeatureModelError(
            case.model_error, {kind: widened[..., kinds == kind] for kind in set(case.layout.kinds)}
        )
        # the RMS through the path line by line (transferred_rms), then scaled by its direct correction
        corrected = replace(
            case,
            observed_all=observed_all,
            observed=observed_all[..., case.layout.columns],
            transfer=gain / colour,
            line_gain=line_gain,
            model_error=model_error,
        )
        line = kinds == "line"
        usable = np.isfinite(corrected.observed[..., line])
        return corrected, {
            "noise_colour_range": [float(np.min(colour)), float(np.max(colour))],
            "gain_range": [
                float(np.nanmin(compared[..., line][usable])) if usable.any() else None,
                float(np.nanmax(compared[..., line][usable])) if usable.any() else None,
            ],
            "largest_added_relative_error": float(np.max(widened)) if widened.size else 0.0,
        }


def _kinds_of_all(case: RigCase) -> np.ndarray:
    """Feature kind of every processor column (``""`` for features not compared)."""
    kinds = np.full(case.observed_all.shape[-1], "", dtype=object)
    kinds[case.layout.columns] = case.layout.kinds
    return kinds


def noise_colour(case: RigCase) -> np.ndarray:
    """Local noise floor at each line over the record's white-noise level, as amplitudes (n_op, n_channel, all).

    The diagnosis takes a record's noise as white at the level of its median
    spectral floor. A transfer path colours the noise that enters before it
    (a resonance raises the floor around it, a roll-off lowers it), so a line
    at the noise floor near a resonance would look several noise spreads
    high. The ratio is the square root of the median of the free
    periodogram bins near the line over the median of all free bins (the
    bins the noise estimate uses), or of the nearest free bins where too
    few lie near the line (a shaft line inside the low band, which the noise
    estimate leaves out and where a resonance's floor can be far above the
    median; docs/model/unmodelled-effects.md section 6.1, step 4); 1 for features that are not
    lines.
    """
    colour = np.ones(case.observed_all.shape)
    for op in range(case.n_op):
        processor = case.processors[op]
        fit = processor.fit
        frequencies = np.fft.rfftfreq(processor.size, 1.0 / processor.fs)
        kept = ~processor.excluded
        centres = processor.frequencies
        lines = np.flatnonzero(np.isfinite(centres))
        free = np.flatnonzero(kept)
        windows = []
        for i in lines:
            width = max(_LOCAL_WIDTH * centres[i], _LOCAL_MIN_HZ)
            window = kept & (np.abs(frequencies - centres[i]) <= width)
            if window.sum() < _LOCAL_MIN_BINS and free.size >= _LOCAL_MIN_BINS:
                nearest = free[np.argsort(np.abs(frequencies[free] - centres[i]), kind="stable")[:_LOCAL_MIN_BINS]]
                window = np.zeros_like(kept)
                window[nearest] = True
            windows.append(window)
        for c, channel in enumerate(case.channels):
            record = np.asarray(case.rig[channel].values[op], dtype=float)
            if not case.usable[op, c] or np.isnan(record).any() or not fit.n_centres:
                continue
            # the fitted lines taken out first: a strong line's window leakage is no noise for the fit
            coefficients = fit.coefficients(record[None])[:, 0]
            residual = record * processor.taper - fit.weighted @ coefficients
            density = np.abs(np.fft.rfft(residual)) ** 2
            overall = float(np.median(density[kept])) if kept.any() else 0.0
            if overall <= 0:
                continue
            for i, window in zip(lines, windows):
                if window.sum() >= _LOCAL_MIN_BINS:
                    colour[op, c, i] = math.sqrt(float(np.median(density[window])) / overall)
    return colour


def _line_points(case: RigCase, model_all: np.ndarray, colour: np.ndarray) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per channel the (frequency, log ratio) of lines clear of the noise in rig and model."""
    points: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    kinds = np.array(case.layout.kinds)
    line = kinds == "line"
    columns = case.layout.columns[line]
    for c, channel in enumerate(case.channels):
        frequencies, ratios = [], []
        for op in range(case.n_op):
            if not case.usable[op, c]:
                continue
            processor = case.processors[op]
            scale = case.noise_std[op, c] * case.noise[op].line_scale[columns] * colour[op, c, columns]
            observed = case.observed_all[op, c, columns]
            model = np.abs(model_all[op, c, columns])
            line_frequencies = processor.frequencies[columns]
            with np.errstate(divide="ignore", invalid="ignore"):
                clear = (observed >= MIN_LINE_SNR * scale) & (model >= MIN_LINE_SNR * scale) & (scale > 0)
                # the Rice mean's bias is removed to first order: E|A + n|^2 = A^2 + 2 sigma^2
                rig = np.sqrt(np.maximum(observed**2 - 2.0 * scale**2, 0.25 * observed**2))
                ratio = np.log(rig / model)
            # lines merged with an earlier one (within a bin) report that line: count each frequency once
            chosen = np.flatnonzero(clear & np.isfinite(ratio))
            seen: set[float] = set()
            for i in chosen:
                f = round(float(line_frequencies[i]), 6)
                if f in seen:
                    continue
                seen.add(f)
                frequencies.append(f)
                ratios.append(float(ratio[i]))
        points[channel] = (np.array(frequencies), np.array(ratios))
    return points


def line_gains(case: RigCase, curves: dict[str, GainCurve]) -> tuple[np.ndarray, np.ndarray]:
    """Each channel's learned gain and its log-gain spread at every line of every run (n_op, n_channel, all).

    1 and 0 for features that are not lines and for channels without a curve.
    """
    gain = np.ones((case.n_op, len(case.channels), case.observed_all.shape[-1]))
    spread = np.zeros_like(gain)
    for op in range(case.n_op):
        frequencies = case.processors[op].frequencies
        lines = np.isfinite(frequencies)
        for c, channel in enumerate(case.channels):
            curve = curves.get(channel)
            if curve is not None and lines.any():
                mean, sd = curve.predict(frequencies[lines])
                gain[op, c, lines] = np.exp(mean)
                spread[op, c, lines] = sd
    return gain, spread


def _direct_corrections(case: RigCase, model_all: np.ndarray, line_gain: np.ndarray) -> dict[str, np.ndarray]:
    """Log corrections of band power, RMS and kurtosis read at each reference run (n_op, n_channel).

    The RMS correction is read against the model's RMS taken through the
    learned line gains (:func:`~uqgear.diagnosis.execution.transferred_rms`), as
    it is applied to the test campaign's model.
    """
    names = case.processors[0].names
    out = {kind: np.full((case.n_op, len(case.channels)), np.nan) for kind in ("band", "rms", "kurtosis")}
    for op in range(case.n_op):
        noise = case.noise[op]
        for c in range(len(case.channels)):
            if not case.usable[op, c]:
                continue
            through_path = {
                "low_band_rms": model_all[op, c, names.index("low_band_rms")],
                "rms": float(transferred_rms(model_all[op, c], line_gain[op, c], case.processors[op])),
            }
            for kind, name, power in (("band", "low_band_rms", noise.band_power), ("rms", "rms", noise.total_power)):
                observed = case.observed_all[op, c, names.index(name)]
                model = through_path[name]
                sigma2 = case.noise_std_for(kind)[op, c] ** 2
                signal = observed**2 - sigma2 * power[0]
                # only where the signal stands clear of the noise power's own scatter
                if np.isfinite(signal) and model > 0 and signal > MIN_LINE_SNR * sigma2 * power[1]:
                    out[kind][op, c] = 0.5 * math.log(signal / model**2)
            rms_model = through_path["rms"]
            kurtosis_model = model_all[op, c, names.index("kurtosis")]
            observed = case.observed_all[op, c, names.index("kurtosis")]
            if math.isfinite(out["rms"][op, c]) and kurtosis_model > 0 and np.isfinite(observed):
                signal_power = (rms_model * math.exp(out["rms"][op, c])) ** 2
                noise_power = case.noise_std[op, c] ** 2 * noise.total_power[0]
                # the noise-free kurtosis that, with this noise, gives what the rig recorded (the inverse
                # of discrepancy._noisy_kurtosis)
                kurtosis = (
                    observed * (signal_power + noise_power) ** 2
                    - 6.0 * signal_power * noise_power
                    - 3.0 * noise_power**2
                ) / signal_power**2
                if kurtosis > 0:
                    out["kurtosis"][op, c] = math.log(kurtosis / kurtosis_model)
    return out


def learn_reference(
    rig: xr.Dataset, design: Design, *, source: str, seed: np.random.SeedSequence, workers: int = 1
) -> ReferenceCorrection:
    """Fit the nominal model to a healthy reference campaign and learn each channel's transfer correction.

    Parameters
    ----------
    rig : xarray.Dataset
        The reference campaign, validated (:func:`uqgear.diagnosis.inputs.load_rig_input`).
    design : Design
        The nominal design (the same as the test campaign's).
    source : str
        Names the reference in messages and in the summary.
    seed : SeedSequence
        Seeds the reference's noise calibration.
    workers : int
        Worker processes for the reference fit's simulations.

    Returns
    -------
    ReferenceCorrection
    """
    started = time.perf_counter()
    prepared = prepare_case(rig, design, seed=seed)
    executor = RunExecutor(prepared, workers)
    try:
        nominal = fit_nominal(prepared.with_executor(executor))
    finally:
        executor.close()
    case = prepared
    model_all = nominal.model
    points = _line_points(case, model_all, noise_colour(case))
    curves = {channel: fit_gain_curve(*points[channel]) for channel in case.channels}
    direct = _direct_corrections(case, model_all, line_gains(case, curves)[0])
    channels_summary = {}
    for channel in case.channels:
        curve = curves[channel]
        frequencies, ratios = points[channel]
        if frequencies.size:
            grid = np.geomspace(max(1.0, 0.8 * frequencies.min()), 1.25 * frequencies.max(), _CURVE_POINTS)
        else:
            grid = np.geomspace(10.0, 0.5 * case.fs, _CURVE_POINTS)
        mean, sd = curve.predict(grid)
        peak = int(np.argmax(np.abs(mean)))
        channels_summary[channel] = {
            "lines": int(frequencies.size),
            "lines_dropped": curve.dropped,
            "mean_log_gain": curve.mean,
            "amplitude": curve.amplitude,
            "length_scale_ln_f": curve.length,
            "scatter": curve.scatter,
            "largest_gain": {
                "frequency": float(grid[peak]),
                "gain": float(np.exp(mean[peak])),
                "interval_2sd": [float(np.exp(mean[peak] - 2 * sd[peak])), float(np.exp(mean[peak] + 2 * sd[peak]))],
            },
            "points": {"frequency": frequencies.tolist(), "log_ratio": ratios.tolist()},
            "curve": {
                "frequency": grid.tolist(),
                "gain": np.exp(mean).tolist(),
                "low": np.exp(mean - 2 * sd).tolist(),
                "high": np.exp(mean + 2 * sd).tolist(),
            },
        }
    summary = {
        "file": source,
        "method": "per-channel log gain rig/model as a Gaussian process in ln(frequency) over lines clear of "
        "the noise; band power, RMS and kurtosis read at the matched reference run",
        "nominal_fit": {
            "parameters": nominal.values,
            "adhesion_torque": list(map(float, nominal.adhesion_torques)),
            "cost": nominal.cost,
            "converged": bool(nominal.converged),
        },
        "operating_points": {"pinion_speed": case.speeds.tolist(), "drive_torque": case.drive_torques.tolist()},
        "channels": channels_summary,
        "direct": {kind: values.tolist() for kind, values in direct.items()},
        "seconds": time.perf_counter() - started,
    }
    return ReferenceCorrection(
        source=source, rig=rig, channels=case.channels, curves=curves, direct=direct, summary=summary
    )


def attach_reference(
    case: RigCase,
    correction: ReferenceCorrection,
    test: xr.Dataset,
    *,
    speed_tolerance: float = DEFAULT_SETTINGS.reference.speed_tolerance,
    torque_tolerance: float = DEFAULT_SETTINGS.reference.torque_tolerance,
) -> tuple[RigCase, dict[str, Any]]:
    """The test campaign corrected by a learned reference (its runs matched to the reference's), and the
    ``reference`` summary of ``diagnosis.json``."""
    matched = match_operating_points(
        test,
        correction.rig,
        where=correction.source,
        speed_tolerance=speed_tolerance,
        torque_tolerance=torque_tolerance,
    )
    corrected, applied = correction.apply(case, matched)
    summary = dict(correction.summary)
    summary["matched_operating_points"] = [
        {
            "op": op,
            "reference_op": int(ref),
            "pinion_speed": float(test["pinion_speed"].values[op]),
            "reference_pinion_speed": float(correction.rig["pinion_speed"].values[ref]),
            "drive_torque": float(test["drive_torque"].values[op]),
            "reference_drive_torque": float(correction.rig["drive_torque"].values[ref]),
        }
        for op, ref in enumerate(matched)
    ]
    summary["applied"] = applied
    return corrected, summary


__all__ = ["MIN_LINE_SNR", "ReferenceCorrection", "noise_colour", "line_gains", "learn_reference", "attach_reference"]
