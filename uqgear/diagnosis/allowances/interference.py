"""Lines at fixed frequencies that reach the accelerometers but not the gears: line interference.

Mains pickup (50 or 60 Hz and their harmonics) on an accelerometer's cable
is a line whose frequency stays put while the speed changes, on that
sensor only. In the low band (2-80 Hz) it adds its power to the
``low_band_rms`` feature, which the model cannot produce at any parameter,
so it would read as an unexplained gap. A line at a fixed frequency can
also be the gear's own (an adhesion oscillation, stick slip): then the
transmission error, which measures the gears' relative motion and is the
most sensitive channel at low frequencies, carries it too. So a line is
taken as interference where it stands at the same frequency (not the same
order) in most runs of an accelerometer channel and the TE shows no such
line; its bins are then left out of the low band of every record, the
rig's and the model's alike (docs/model/unmodelled-effects.md section 6.5; the campaign that
shows it is in docs/validation/diagnosis.md). Without a TE channel nothing
is left out.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import scipy.signal

from ..settings import DEFAULT_SETTINGS

#: Bins on each side of an interference line left out of the band (the Hann main lobe spans +-2).
NOTCH_HALF_WIDTH = 2
#: Channels that carry the gears' own motion (a line there is not interference).
GEAR_CHANNEL = "te"


@dataclass(frozen=True)
class LineInterference:
    """The interference lines found on a campaign's accelerometers (the ``line_interference`` allowance).

    Each line: ``frequency`` (Hz), ``channel``, ``ops`` (runs) and
    ``amplitude``; their bins are left out of the low band of every record.
    """

    lines: list[dict[str, Any]]
    #: Its entry in ``diagnosis.json``.
    key: ClassVar[str] = "line_interference"

    @property
    def applied(self) -> bool:
        """Whether any line was left out."""
        return bool(self.lines)

    @property
    def frequencies(self) -> list[float]:
        """The distinct frequencies left out, Hz, ascending."""
        return sorted({line["frequency"] for line in self.lines})

    def summary(self) -> list[dict[str, Any]]:
        """JSON-ready: the lines."""
        return self.lines


def amplitude_spectrum(record: np.ndarray, taper: np.ndarray) -> np.ndarray:
    """One-sided amplitude spectrum of a record (mean removed, tapered), channel units."""
    record = np.asarray(record, dtype=float)
    return np.abs(np.fft.rfft((record - record.mean()) * taper)) * (2.0 / taper.sum())


def fixed_frequency_lines(
    records: np.ndarray,
    noise_std: np.ndarray,
    speeds: np.ndarray,
    fs: float,
    limit: float,
    *,
    usable: np.ndarray | None = None,
    threshold: float = DEFAULT_SETTINGS.interference.interference_threshold,
    minimum_runs: int = DEFAULT_SETTINGS.interference.interference_runs,
) -> list[dict[str, Any]]:
    """Spectral lines of one channel that keep their frequency, not their order, across runs.

    Peaks of each run's amplitude spectrum more than ``threshold`` times a
    line's noise scale above zero are grouped by frequency (within 1.5
    bins); a group met in at least ``minimum_runs`` runs (and half of them)
    whose orders differ by more than half an order is frequency-locked,
    unlike every order-locked line, which moves with the speed.

    Parameters
    ----------
    records : ndarray (n_op, N)
        The channel's records.
    noise_std : ndarray (n_op,)
        The records' white-noise standard deviations.
    speeds : ndarray (n_op,)
        Pinion speeds, rpm.
    fs : float
        Sampling rate, Hz.
    limit : float
        Highest frequency searched, Hz.
    usable : ndarray of bool (n_op,), optional
        Runs to search (default all).

    Returns
    -------
    list of dict
        ``frequency`` (Hz), ``ops`` (run indices), ``amplitude`` (median, channel units).
    """
    n_op, size = records.shape
    usable = np.ones(n_op, dtype=bool) if usable is None else np.asarray(usable, dtype=bool)
    resolution = fs / size
    taper = scipy.signal.get_window("hann", size)
    frequency = np.fft.rfftfreq(size, 1.0 / fs)
    inside = frequency <= limit
    peaks: list[tuple[float, int, float]] = []
    for op in range(n_op):
        if not usable[op] or not math.isfinite(noise_std[op]) or np.isnan(records[op]).any():
            continue
        amplitude = amplitude_spectrum(records[op], taper)
        line_scale = noise_std[op] * math.sqrt(2.0 * np.sum(taper**2)) / taper.sum()
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
    needed = max(minimum_runs, int(math.ceil(0.5 * n_op)))
    for group in groups:
        ops = sorted({op for _, op, _ in group})
        if len(ops) < needed:
            continue
        centre = float(np.median([f for f, _, _ in group]))
        orders = centre / (np.asarray(speeds, dtype=float)[ops] / 60.0)
        if np.ptp(orders) <= 0.5:
            continue
        lines.append({"frequency": centre, "ops": ops, "amplitude": float(np.median([a for _, _, a in group]))})
    return lines


def interference_lines(
    records: Mapping[str, np.ndarray],
    noise_std: Mapping[str, np.ndarray],
    usable: Mapping[str, np.ndarray],
    speeds: np.ndarray,
    fs: float,
    band: tuple[float, float],
    channels: Sequence[str],
    *,
    threshold: float = DEFAULT_SETTINGS.interference.interference_threshold,
    minimum_runs: int = DEFAULT_SETTINGS.interference.interference_runs,
) -> LineInterference:
    """Fixed-frequency lines inside ``band`` on a channel other than the TE, absent from the TE (module docstring).

    ``threshold`` and ``minimum_runs`` as in :func:`fixed_frequency_lines`.

    Returns
    -------
    LineInterference
        ``frequency`` (Hz), ``channel``, ``ops`` and ``amplitude`` of each line; none without a TE channel.
    """
    if GEAR_CHANNEL not in channels:
        return LineInterference([])
    size = records[GEAR_CHANNEL].shape[1]
    resolution = fs / size
    upper = band[1] + (NOTCH_HALF_WIDTH + 1) * resolution
    gear_lines = fixed_frequency_lines(
        records[GEAR_CHANNEL],
        noise_std[GEAR_CHANNEL],
        speeds,
        fs,
        upper,
        usable=usable[GEAR_CHANNEL],
        threshold=threshold,
        minimum_runs=minimum_runs,
    )
    found = []
    for channel in channels:
        if channel == GEAR_CHANNEL:
            continue
        for line in fixed_frequency_lines(
            records[channel],
            noise_std[channel],
            speeds,
            fs,
            upper,
            usable=usable[channel],
            threshold=threshold,
            minimum_runs=minimum_runs,
        ):
            if not band[0] - NOTCH_HALF_WIDTH * resolution <= line["frequency"] <= upper:
                continue
            if any(abs(line["frequency"] - other["frequency"]) <= 1.5 * resolution for other in gear_lines):
                continue
            found.append({**line, "channel": channel})
    return LineInterference(found)


__all__ = [
    "LineInterference",
    "NOTCH_HALF_WIDTH",
    "GEAR_CHANNEL",
    "amplitude_spectrum",
    "fixed_frequency_lines",
    "interference_lines",
]
