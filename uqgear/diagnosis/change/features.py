"""The model-free condition-monitoring features a change since a healthy reference is judged on.

Per record (one channel of one run): the RMS and kurtosis of the record;
per shaft, its time-synchronous average (TSA, the record resampled onto the
shaft's angle and averaged over whole revolutions), read as the first three
mesh harmonics, the shaft-order lines 1 and 2, the energy of the sidebands
+-1 to +-3 shaft orders about every mesh harmonic in the pass band, and the
TSA residual (the TSA less its mesh harmonics, their first sidebands and the
shaft orders 1 and 2) by its RMS and kurtosis. Every feature is a natural
logarithm of a power (or of a kurtosis), so that a change is a ratio and
campaigns of different levels compare alike.

Each feature carries the white noise of the record it was read from (the
median periodogram bin): line and band powers add their noise power, RMS and
kurtosis mix with Gaussian noise in closed form. The same function reads a
noiseless model record when given the rig record's noise, so that a model's
predicted change at the noise floor is as small as the rig would show it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: The shafts whose revolutions the TSA averages over.
SHAFTS = ("pinion", "gear")
#: Shaft-order lines read per shaft.
SHAFT_ORDERS = (1, 2)
#: Mesh harmonics read as lines (from the pinion's TSA).
MESH_HARMONICS = (1, 2, 3)
#: Sidebands about each mesh harmonic summed in the sideband energy, shaft orders either side.
SIDEBAND_ORDERS = (1, 2, 3)
#: Highest frequency of a mesh harmonic whose sidebands count, as a share of the sampling rate (the rig's
#: anti-alias pass band, fs / 2.56).
PASS_BAND = 1.0 / 2.56


@dataclass(frozen=True)
class FeatureName:
    """One condition-monitoring feature: its family, the shaft it belongs to ('' for a record's), its label."""

    family: str
    shaft: str
    label: str


def feature_names() -> tuple[FeatureName, ...]:
    """Every feature read per record, in a fixed order."""
    names = [FeatureName("rms", "", "rms"), FeatureName("kurtosis", "", "kurtosis")]
    names += [FeatureName("mesh_harmonic", "", f"mesh_h{h}") for h in MESH_HARMONICS]
    for shaft in SHAFTS:
        names += [FeatureName("shaft_line", shaft, f"{shaft}_order{k}") for k in SHAFT_ORDERS]
        names += [
            FeatureName("sideband_energy", shaft, f"{shaft}_sidebands"),
            FeatureName("tsa_residual_rms", shaft, f"{shaft}_residual_rms"),
            FeatureName("tsa_residual_kurtosis", shaft, f"{shaft}_residual_kurtosis"),
        ]
    return tuple(names)


FEATURES = feature_names()
FAMILIES = tuple(dict.fromkeys(name.family for name in FEATURES))


def noise_variance(record: np.ndarray) -> float:
    """White noise variance of a record from its median periodogram bin (robust to lines and resonances)."""
    centred = record - record.mean()
    power = np.abs(np.fft.rfft(centred)[1:]) ** 2
    # the median of an exponential variable is ln 2 times its mean; E|X_k|^2 = N sigma^2
    return float(np.median(power) / (centred.size * math.log(2.0)))


def _mixed_kurtosis(m2: float, m4: float, noise: float) -> float:
    """Kurtosis of a zero-mean signal with moments m2, m4 plus independent Gaussian noise of variance ``noise``."""
    return (m4 + 6.0 * m2 * noise + 3.0 * noise * noise) / max((m2 + noise) ** 2, 1e-300)


def _shaft_average(record: np.ndarray, fs: float, shaft_hz: float, teeth: int) -> tuple[np.ndarray, int]:
    """The TSA of ``record`` over whole revolutions of a shaft at ``shaft_hz`` (samples per revolution a multiple
    of ``teeth``, as dense as the record), and the number of revolutions averaged."""
    per_rev = teeth * max(2, int(math.ceil(fs / shaft_hz / teeth)))
    revolutions = int(math.floor(record.size / fs * shaft_hz))
    if revolutions < 1:
        return np.zeros(per_rev), 0
    angle_times = np.arange(revolutions * per_rev) / (per_rev * shaft_hz)
    resampled = np.interp(angle_times, np.arange(record.size) / fs, record)
    return resampled.reshape(revolutions, per_rev).mean(axis=0), revolutions


def _shaft_features(
    record: np.ndarray, fs: float, shaft_hz: float, teeth: int, noise: float, mesh_lines: bool
) -> list[float]:
    """One shaft's lines, sideband energy and TSA residual RMS and kurtosis (ln), and the mesh harmonics when asked."""
    tsa, revolutions = _shaft_average(record, fs, shaft_hz, teeth)
    if revolutions < 1:
        # not one revolution of this shaft in the record: nothing to average
        return [math.nan] * ((len(MESH_HARMONICS) if mesh_lines else 0) + len(SHAFT_ORDERS) + 3)
    size = tsa.size
    spectrum = np.fft.rfft(tsa - tsa.mean())
    amplitude2 = (2.0 * np.abs(spectrum) / size) ** 2
    # noise of one TSA order's squared amplitude: the record's noise averaged over the revolutions
    floor = 4.0 * noise / (size * max(revolutions, 1))
    top = min(spectrum.size - 1, int(PASS_BAND * fs / shaft_hz))
    values: list[float] = []
    if mesh_lines:
        values += [
            math.log(amplitude2[h * teeth] + floor) if h * teeth <= top else math.log(floor) for h in MESH_HARMONICS
        ]
    values += [math.log(amplitude2[k] + floor) for k in SHAFT_ORDERS]
    carriers = [h * teeth for h in range(1, top // teeth + 1)]
    sidebands = [c + s * j for c in carriers for j in SIDEBAND_ORDERS for s in (-1, 1) if 0 < c + s * j <= top]
    values.append(math.log(float(amplitude2[sidebands].sum()) + floor * max(len(sidebands), 1)))
    # the residual: the TSA less the meshing (harmonics and first sidebands) and the shaft lines, in the pass band
    keep = np.ones(spectrum.size, dtype=bool)
    keep[0] = False
    keep[top + 1 :] = False
    for c in carriers:
        keep[max(c - 1, 0) : c + 2] = False
    keep[list(SHAFT_ORDERS)] = False
    residual = np.fft.irfft(np.where(keep, spectrum, 0.0), n=size)
    tsa_noise = noise / max(revolutions, 1) * keep.sum() / max(spectrum.size - 1, 1)
    m2 = float(np.mean(residual**2))
    m4 = float(np.mean(residual**4))
    values.append(math.log(m2 + tsa_noise + 1e-300))
    values.append(math.log(_mixed_kurtosis(m2, m4, tsa_noise)))
    return values


def record_features(
    record: np.ndarray, fs: float, pinion_hz: float, z1: int, z2: int, *, noise: float | None = None
) -> np.ndarray:
    """The features of one record (in the order of :data:`FEATURES`).

    ``noise`` is the white noise variance the features carry: None reads it
    off the record (a rig record); a model record is given its rig record's.
    """
    record = np.asarray(record, dtype=float)
    record = record - record.mean()
    own = noise is None
    noise_var = noise_variance(record) if noise is None else float(noise)
    m2 = float(np.mean(record**2))
    m4 = float(np.mean(record**4))
    # a rig record holds its noise already; a model record gets it mixed in
    added = 0.0 if own else noise_var
    values = [math.log(m2 + added + 1e-300), math.log(_mixed_kurtosis(m2, m4, added))]
    values += _shaft_features(record, fs, pinion_hz, z1, noise_var, True)
    values += _shaft_features(record, fs, pinion_hz * z1 / z2, z2, noise_var, False)
    return np.array(values)


def campaign_features(
    records: Sequence[np.ndarray],
    fs: float,
    pinion_hz: Sequence[float] | np.ndarray,
    z1: int,
    z2: int,
    *,
    noise: Sequence[float] | np.ndarray | None = None,
) -> np.ndarray:
    """Features of a channel's records over runs, (n_op, n_feature)."""
    return np.stack(
        [
            record_features(records[op], fs, pinion_hz[op], z1, z2, noise=None if noise is None else noise[op])
            for op in range(len(records))
        ]
    )


__all__ = [
    "FEATURES",
    "FAMILIES",
    "FeatureName",
    "SHAFTS",
    "campaign_features",
    "feature_names",
    "noise_variance",
    "record_features",
]
