"""Whether a rig campaign carries signal that an analysis can use, checked before any work starts.

A file can follow the ``uqgear-rig/1`` format and still hold nothing to
analyse: every record missing (NaN) or constant (a dead sensor writes
zeros), records too short to hold one revolution of the pinion, fewer
operating points than the analysis needs, or torques the model does not
take. :func:`check_usable_signal` refuses such a campaign with one line
naming the variable and what was expected, before minutes of fitting; the
diagnosis and the calibration call it right after reading the file.

A campaign that passes can still be uninformative (every line at the noise
floor): that is for the analysis to judge from its features (the diagnosis
then gives the verdict ``inconclusive``).
"""

from __future__ import annotations

import math

import numpy as np
import xarray as xr

from ..common.errors import RigDataError
from .sampling import SIGNAL_CHANNELS, sampling_rate


def record_states(ds: xr.Dataset) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per channel: which records are missing (any NaN sample) and which are constant (no variation).

    Parameters
    ----------
    ds : xarray.Dataset
        A rig Dataset that follows the format (:func:`~uqgear.rig.format.validate_rig`).

    Returns
    -------
    dict
        Channel name -> ``(missing, constant)``, boolean arrays over ``op``.
        A missing record is unusable for its channel (docs/rig-data-format.md);
        a constant one (all zero, or a sensor stuck at one value) carries no signal.
    """
    states = {}
    for name in SIGNAL_CHANNELS:
        if name not in ds.data_vars:
            continue
        values = np.asarray(ds[name].values, dtype=float)
        missing = np.isnan(values).any(axis=1)
        with np.errstate(invalid="ignore"):
            spread = np.where(missing, 0.0, np.ptp(np.where(np.isnan(values), 0.0, values), axis=1))
        states[name] = (missing, ~missing & (spread == 0.0))
    return states


def _describe_dead(states: dict[str, tuple[np.ndarray, np.ndarray]], ds: xr.Dataset) -> str:
    """What records without signal are: missing, all zero, constant, or a mixture."""
    if all(missing.all() for missing, _ in states.values()):
        return "missing (NaN)"
    if any(missing.any() for missing, _ in states.values()):
        return "missing (NaN) or constant (no variation)"
    if all(not np.any(np.asarray(ds[name].values)) for name in states):
        return "all zero"
    return "constant (a sensor stuck at one value)"


def check_usable_signal(
    ds: xr.Dataset,
    *,
    where: str = "rig data",
    min_operating_points: int = 1,
    purpose: str = "the analysis",
    why: str = "",
) -> np.ndarray:
    """Refuse a campaign without usable signal; return the operating points that carry some.

    Checked in this order, each failure one :class:`RigDataError` naming the
    variable and what was expected:

    1. at least ``min_operating_points`` operating points in the file;
    2. drive torque and the adhesion-torque bounds >= 0 (the model's convention);
    3. records at least one pinion revolution long at the slowest operating
       point (shaft-order lines and sidebands need one revolution to exist);
    4. at least one channel record that is neither missing (any NaN) nor
       constant (all zero) in at least ``min_operating_points`` operating points.

    Parameters
    ----------
    ds : xarray.Dataset
        A rig Dataset that follows the format (validated).
    where : str
        Names the file in messages.
    min_operating_points : int
        Operating points with signal that the analysis needs.
    purpose : str
        The analysis, for messages (``"the diagnosis"``).
    why : str
        Why it needs that many, for messages (optional).

    Returns
    -------
    numpy.ndarray
        Indices of the operating points with at least one usable channel record.

    Raises
    ------
    RigDataError
        The first of the conditions above that fails.
    """
    because = f" ({why})" if why else ""
    n_op = int(ds.sizes.get("op", 0))
    if n_op < 1:
        raise RigDataError(
            f"{where}: op: the campaign holds no operating point; {purpose} needs at least "
            f"{max(min_operating_points, 1)}{because}"
        )
    if n_op < min_operating_points:
        raise RigDataError(
            f"{where}: op: the campaign holds {n_op} operating point{'s' if n_op != 1 else ''}; "
            f"{purpose} needs at least {min_operating_points}{because}"
        )
    for name in ("drive_torque", "adhesion_torque_lower"):
        values = np.asarray(ds[name].values, dtype=float)
        if np.any(values < 0):
            index = int(np.argmax(values < 0))
            raise RigDataError(
                f"{where}: {name}: expected torques >= 0 N m (the model's sign convention: T1 drives "
                f"the pinion, T2 brakes the wheelset); op {index} has {values[index]:g}"
            )

    speed = np.asarray(ds["pinion_speed"].values, dtype=float)
    fs = sampling_rate(ds["time"].values, where=f"{where}: time")
    size = int(ds.sizes["time"])
    slowest = int(np.argmin(speed))
    revolution = 60.0 / float(speed[slowest])
    duration = size / fs
    if duration < revolution * (1.0 - 1e-9):
        raise RigDataError(
            f"{where}: time: records of {size} samples at {fs:g} Hz last {duration:.4g} s, shorter "
            f"than one pinion revolution at the slowest operating point (op {slowest}, "
            f"{speed[slowest]:g} rpm: {revolution:.4g} s); expected records of at least "
            f"{math.ceil(revolution * fs)} samples"
        )

    states = record_states(ds)
    channels = ", ".join(states)
    usable = np.zeros(n_op, dtype=bool)
    for missing, constant in states.values():
        usable |= ~missing & ~constant
    if not usable.any():
        raise RigDataError(
            f"{where}: {channels}: no usable signal: every record of every channel is "
            f"{_describe_dead(states, ds)}; expected records that vary in at least "
            f"{max(min_operating_points, 1)} operating point{'s' if min_operating_points > 1 else ''}"
        )
    count = int(usable.sum())
    if count < min_operating_points:
        kept = ", ".join(f"op {op} at {speed[op]:g} rpm" for op in np.flatnonzero(usable))
        raise RigDataError(
            f"{where}: {channels}: only {count} of {n_op} operating points carry usable signal "
            f"({kept}); {purpose} needs at least {min_operating_points}{because}; the records of "
            f"the others are missing (NaN) or constant in every channel"
        )
    return np.flatnonzero(usable)


__all__ = ["record_states", "check_usable_signal"]
