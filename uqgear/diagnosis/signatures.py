"""The rig data's signature: frequency-locked lines and the candidate fits' starting values read off it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.ndimage
import scipy.signal

from .allowances.interference import fixed_frequency_lines
from .case import RigCase
from .effects import signature_hints as family_hints
from .settings import DEFAULT_SETTINGS, DiagnosisSettings


def frequency_locked_lines(
    case: RigCase, *, channel: str = "te", settings: DiagnosisSettings = DEFAULT_SETTINGS
) -> list[dict[str, Any]]:
    """Spectral lines of a channel that keep their frequency, not their order, across runs.

    :func:`~.allowances.interference.fixed_frequency_lines` on the case's
    records (stick-slip, a fixed-frequency source), with the settings'
    ``interference_threshold`` and ``interference_runs``; empty without that
    channel.
    """
    if channel not in case.channels:
        return []
    index = case.channels.index(channel)
    return fixed_frequency_lines(
        np.asarray(case.rig[channel].values, dtype=float),
        case.noise_std[:, index],
        case.speeds,
        case.fs,
        case.processors[0].limit,
        usable=case.usable[:, index],
        threshold=settings.interference.interference_threshold,
        minimum_runs=settings.interference.interference_runs,
    )


#: Band of modulation frequencies searched on the accelerometers, Hz (the stick-slip band).
STEADY_BAND: tuple[float, float] = (1.0, 100.0)
#: Bins on either side of a bin whose median power is its run's local floor.
STEADY_FLOOR_BINS = 20
#: Bins on either side of the mesh line's peak left out (the taper's main lobe, the speed's wander).
STEADY_MESH_BINS = 3
#: Height of a steady modulation: the median over runs of its two sidebands' mean power over the local floor.
#: Noise alone gives a bin a power over the floor that is exponential with mean 1 / ln 2 (the floor is a
#: median); the mean of two such exceeds 6 with probability 0.2 %, and the median of 8 runs needs 4 of
#: them to: far fewer than one offset in a million. A floor that is not flat (a neighbouring line, a
#: resonance's skirt) raises the noise's ratios, hence the margin.
STEADY_POWER = 6.0


def steady_modulation_lines(
    case: RigCase, *, band: tuple[float, float] = STEADY_BAND, threshold: float = STEADY_POWER
) -> list[dict[str, Any]]:
    """Modulations of the mesh line at one frequency in every run, read on each accelerometer, strongest first.

    A torque oscillation far below the bearing modes barely moves a housing
    by itself, but it modulates the mesh force: the housings carry it as a
    pair of sidebands of the mesh line at its frequency, the same in Hz in
    every run, while a shaft's sidebands lie at its speed and move with it.
    Per accelerometer and offset of ``band``: each usable run's power at the
    mesh line's peak plus and minus the offset over its local floor (the
    median power of the neighbouring bins), the mean of the two sides, then
    the median over the runs; a local maximum above ``threshold`` is a
    line. Empty without accelerometers or with fewer than three usable runs.

    Returns
    -------
    list of dict
        ``frequency`` (the offset, Hz), ``ops`` (the runs searched),
        ``amplitude`` (the median power over the floor) and ``channel``,
        strongest first.
    """
    lines: list[dict[str, Any]] = []
    for c, channel in enumerate(case.channels):
        ops = [op for op in range(case.speeds.size) if case.usable[op, c]]
        records = np.asarray(case.rig[channel].values, dtype=float)
        ops = [op for op in ops if np.isfinite(records[op]).all()]
        if channel == "te" or len(ops) < 3:
            continue
        resolution = case.fs / records.shape[1]
        offsets = np.arange(max(round(band[0] / resolution), STEADY_MESH_BINS + 1), round(band[1] / resolution) + 1)
        ratios = [_sideband_power(records[op], case.design.z1 * case.speeds[op] / 60.0 / resolution, offsets)
                  for op in ops]
        median = np.median(ratios, axis=0)
        peaks, _ = scipy.signal.find_peaks(np.concatenate(([0.0], median, [0.0])), height=threshold)
        lines.extend(
            {"frequency": float(offsets[i - 1] * resolution), "ops": ops, "amplitude": float(median[i - 1]),
             "channel": channel}
            for i in peaks
        )
    return sorted(lines, key=lambda line: -line["amplitude"])


def _sideband_power(record: np.ndarray, mesh_bin: float, offsets: np.ndarray) -> np.ndarray:
    """Mean power of the mesh line's two sidebands at ``offsets`` (bins) over the local floor."""
    power = np.abs(np.fft.rfft((record - record.mean()) * np.hanning(record.size))) ** 2
    # the mesh line's peak, where the speed's wander has put it
    near = np.arange(max(int(mesh_bin * 0.99), 1), min(int(mesh_bin * 1.01) + 2, power.size))
    peak = int(near[np.argmax(power[near])])
    floor = scipy.ndimage.median_filter(power, size=2 * STEADY_FLOOR_BINS + 1, mode="nearest")
    ratio = power / np.maximum(floor, np.finfo(float).tiny)
    upper = np.clip(peak + offsets, 0, power.size - 1)
    lower = np.clip(peak - offsets, 0, power.size - 1)
    return np.asarray(0.5 * (ratio[upper] + ratio[lower]))


def every_channel_locked_lines(
    case: RigCase, *, settings: DiagnosisSettings = DEFAULT_SETTINGS
) -> list[dict[str, Any]]:
    """The lines at a fixed frequency of every channel of the case, each naming its ``channel``, the TE's first.

    What the effect families read their hints off
    (:meth:`~.effects.base.EffectFamily.hints`): the TE's frequency-locked
    lines (those of :func:`frequency_locked_lines`), then the accelerometers'
    steady modulations of the mesh line (:func:`steady_modulation_lines`),
    so that a campaign without encoders still shows a torsional oscillation
    where the housings carry it.
    """
    te = [{**line, "channel": "te"} for line in frequency_locked_lines(case, settings=settings)]
    return te + steady_modulation_lines(case)


def signature_hints(case: RigCase, locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """Starting values for the candidate fits read off the rig's features by every effect family.

    ``locked_lines`` are frequency-locked lines, each naming its
    ``channel`` (:func:`every_channel_locked_lines`; a line naming none is
    the TE's). For the library: the run-out amplitude from the median 1x
    shaft line of the transmission error (the run-out enters the TE
    directly), the stick-slip frequency from the lowest frequency-locked line
    below 100 Hz of the TE, or on a campaign without a TE the accelerometers'
    strongest steady modulation (:meth:`~.effects.base.EffectFamily.hints`).
    """
    return family_hints(case.observed_features(), locked_lines)


__all__ = ["frequency_locked_lines", "every_channel_locked_lines", "signature_hints"]
