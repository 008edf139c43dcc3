"""The rig data's signature: frequency-locked lines and the candidate fits' starting values read off it."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.signal

from .case import RigCase


def amplitude_spectrum(record: np.ndarray, taper: np.ndarray) -> np.ndarray:
    """One-sided amplitude spectrum of a record (mean removed, tapered), channel units."""
    record = np.asarray(record, dtype=float)
    return np.abs(np.fft.rfft((record - record.mean()) * taper)) * (2.0 / taper.sum())


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
        amplitude = amplitude_spectrum(case.rig[channel].values[op], taper)
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

