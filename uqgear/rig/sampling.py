"""Sampling facts shared by every reader of rig records: channels, sampling rate, usable band.

This module does no file I/O and no plotting.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ..common.errors import RigDataError, StudyError

#: Measured channels of the rig format: name -> (units, long name).
SIGNAL_CHANNELS: dict[str, tuple[str, str]] = {
    "te": ("m", "transmission error along the line of action (encoders, mean removed)"),
    "acc_pinion": ("m s-2", "pinion bearing-housing acceleration along the line of action"),
    "acc_gear": ("m s-2", "gear bearing-housing acceleration along the line of action"),
}

#: Usable bandwidth as a fraction of the sampling rate when none is given: the
#: customary fs/2.56 of anti-aliased acquisition (8 kHz at 20480 Hz).
DEFAULT_BAND_FRACTION = 1.0 / 2.56


def sampling_rate(time: ArrayLike, *, where: str = "time") -> float:
    """Sampling rate of a uniformly spaced time axis, Hz.

    Parameters
    ----------
    time : array_like
        Sample instants in s (at least two, increasing, uniform spacing).
    where : str
        Prefix naming the file or variable in error messages.

    Raises
    ------
    RigDataError
        Fewer than two samples, non-finite, non-increasing or non-uniform.
    """
    values = np.asarray(time, dtype=float)
    if values.ndim != 1 or values.size < 2:
        raise RigDataError(f"{where}: expected a 1-D time axis of at least 2 samples; got shape {values.shape}")
    if not np.all(np.isfinite(values)):
        raise RigDataError(f"{where}: expected finite sample instants; found NaN or inf")
    steps = np.diff(values)
    step = float(np.median(steps))
    if step <= 0:
        raise RigDataError(f"{where}: expected increasing sample instants; got a median step of {step:g} s")
    worst = int(np.argmax(np.abs(steps - step)))
    # Instants stored as float64 k/fs deviate from uniform by rounding only.
    if abs(steps[worst] - step) > 1e-6 * step:
        raise RigDataError(
            f"{where}: expected uniform spacing 1/fs; step {worst} is {steps[worst]:.9g} s "
            f"against a median of {step:.9g} s"
        )
    # The end-to-end span is less affected by rounding than any single step.
    return (values.size - 1) / (values[-1] - values[0])


def band_limit_of(band_limit: float | None, fs: float) -> float:
    """Highest usable frequency (Hz): ``band_limit`` checked against fs, or fs/2.56 when None."""
    if band_limit is None:
        return DEFAULT_BAND_FRACTION * fs
    if isinstance(band_limit, bool) or not isinstance(band_limit, (int, float)) or not 0 < band_limit <= 0.5 * fs:
        raise StudyError(f"band_limit: expected a frequency in (0, fs/2 = {0.5 * fs:g}] Hz; got {band_limit!r}")
    return float(band_limit)


__all__ = ["SIGNAL_CHANNELS", "DEFAULT_BAND_FRACTION", "sampling_rate", "band_limit_of"]
