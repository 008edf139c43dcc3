"""Run-up and coast-down records in the ``uqgear-rig/1`` format: names, units and checks.

A campaign file may hold, beside (or instead of) its steady runs on ``op`` x
``time``, records taken while the speed ramps (docs/rig-data-format.md,
"Run-up and coast-down records"): dimensions ``ramp`` (records) and
``ramp_time`` (samples per record), coordinates ``ramp_time`` (s),
``ramp_drive_torque``, ``ramp_adhesion_torque_lower`` and
``ramp_adhesion_torque_upper`` (N m, per record), channels ``ramp_te``,
``ramp_acc_pinion`` and ``ramp_acc_gear`` (any subset, at least one) and the
speed reference ``ramp_pinion_speed_signal`` (rpm, a tachometer), which is
required: a ramp has no single speed, so without it the record cannot be placed
on the speed axis.

The names repeat the steady ones with a ``ramp_`` prefix so that the two kinds
of record can share one file without sharing a dimension (their lengths and
their meaning differ). This module does no file I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping

import numpy as np
import xarray as xr

from ..common.errors import RigDataError
from .sampling import SIGNAL_CHANNELS, sampling_rate

#: Dimensions of the ramp records: records, samples per record.
RAMP_DIMS: tuple[str, str] = ("ramp", "ramp_time")

#: Coordinates of the ramp records: name -> (dims, units, long name).
RAMP_COORDINATES: dict[str, tuple[tuple[str, ...], str, str]] = {
    "ramp_time": (("ramp_time",), "s", "time from the start of each run-up or coast-down record"),
    "ramp_drive_torque": (("ramp",), "N m", "mean drive torque T1 on the pinion during the ramp"),
    "ramp_adhesion_torque_lower": (("ramp",), "N m", "a-priori lower bound of the adhesion torque T2"),
    "ramp_adhesion_torque_upper": (("ramp",), "N m", "a-priori upper bound of the adhesion torque T2"),
}

#: Ramp channel name -> the steady channel it becomes in an operating point.
RAMP_CHANNELS: dict[str, str] = {f"ramp_{name}": name for name in SIGNAL_CHANNELS}

#: The required speed reference of a ramp record (rpm, a tachometer).
RAMP_TACHOMETER = "ramp_pinion_speed_signal"

#: Every data variable a ramp record may carry.
RAMP_VARIABLES: tuple[str, ...] = (*RAMP_CHANNELS, RAMP_TACHOMETER)

#: Largest step back against the ramp's direction, as a fraction of its speed span: a tachometer's noise and
#: a drive's wander step back a little; more than this and two stretches of the record hold the same speed.
MAX_REVERSAL = 0.05


def has_ramps(ds: xr.Dataset) -> bool:
    """Whether a Dataset holds ramp records (a ramp dimension or variable)."""
    return any(dim in ds.dims for dim in RAMP_DIMS) or any(
        name in ds.variables for name in (*RAMP_VARIABLES, *RAMP_COORDINATES)
    )


def _check_coordinates(ds: xr.Dataset, where: str, check_units: Callable[[str, str, Mapping, str], None]) -> None:
    for name, (dims, units, _) in RAMP_COORDINATES.items():
        if name not in ds.coords:
            found = " (found as a data variable)" if name in ds.data_vars else ""
            raise RigDataError(f"{where}: {name}: missing coordinate{found}; expected dims {dims} in {units}")
        variable = ds[name]
        if variable.dims != dims:
            raise RigDataError(f"{where}: {name}: expected dims {dims}; got {variable.dims}")
        check_units(where, name, variable.attrs, units)
        if not np.issubdtype(variable.dtype, np.number) or not np.all(np.isfinite(variable.values)):
            raise RigDataError(f"{where}: {name}: expected finite numbers; found {variable.dtype} or NaN/inf")
    lower = ds["ramp_adhesion_torque_lower"].values
    upper = ds["ramp_adhesion_torque_upper"].values
    if np.any(lower > upper):
        index = int(np.argmax(lower > upper))
        raise RigDataError(
            f"{where}: ramp_adhesion_torque_lower: expected <= ramp_adhesion_torque_upper; ramp {index} has "
            f"lower {lower[index]:g} N m > upper {upper[index]:g} N m"
        )


def _check_channels(ds: xr.Dataset, where: str, check_units: Callable[[str, str, Mapping, str], None]) -> None:
    channels = [name for name in RAMP_CHANNELS if name in ds.data_vars]
    if not channels:
        raise RigDataError(
            f"{where}: ramp: no ramp channel; expected at least one of {', '.join(RAMP_CHANNELS)} over {RAMP_DIMS}"
        )
    for name in channels:
        variable = ds[name]
        if variable.dims != RAMP_DIMS:
            raise RigDataError(f"{where}: {name}: expected dims {RAMP_DIMS}; got {variable.dims}")
        if not np.issubdtype(variable.dtype, np.floating):
            raise RigDataError(
                f"{where}: {name}: expected floating-point samples (NaN where missing); got {variable.dtype}"
            )
        check_units(where, name, variable.attrs, SIGNAL_CHANNELS[RAMP_CHANNELS[name]][0])
        long_name = variable.attrs.get("long_name")
        if not isinstance(long_name, str) or not long_name.strip():
            raise RigDataError(f"{where}: {name}: missing 'long_name' attribute (text)")
        if np.any(np.isinf(variable.values)):
            raise RigDataError(f"{where}: {name}: expected finite samples (NaN where missing); found inf")


def reversal(speed: np.ndarray) -> tuple[float, int]:
    """Largest step back of a speed record against its direction, as a fraction of its span, and where.

    The direction is that of the record's end against its start (a run-up
    rises, a coast-down falls); the step back at a sample is how far the
    speed lies below the highest speed reached so far (a run-up) or above the
    lowest (a coast-down).

    Examples
    --------
    >>> import numpy as np
    >>> reversal(np.array([100.0, 200.0, 300.0, 400.0]))
    (0.0, 0)
    >>> reversal(np.array([100.0, 300.0, 200.0, 500.0]))
    (0.25, 2)
    """
    sign = 1.0 if speed[-1] >= speed[0] else -1.0
    oriented = sign * speed
    back = np.maximum.accumulate(oriented) - oriented
    span = float(np.ptp(speed))
    index = int(np.argmax(back))
    return (float(back[index]) / span if span > 0 else 0.0), index


def _check_tachometer(ds: xr.Dataset, where: str, check_units: Callable[[str, str, Mapping, str], None]) -> float:
    """Check the ramp records' speed reference; return the top speed in rpm."""
    if RAMP_TACHOMETER not in ds.data_vars:
        raise RigDataError(
            f"{where}: {RAMP_TACHOMETER}: missing; a run-up or coast-down record needs its speed reference "
            f"(a tachometer, rpm over {RAMP_DIMS}) to be placed on the speed axis"
        )
    tachometer = ds[RAMP_TACHOMETER]
    if tachometer.dims != RAMP_DIMS:
        raise RigDataError(f"{where}: {RAMP_TACHOMETER}: expected dims {RAMP_DIMS}; got {tachometer.dims}")
    check_units(where, RAMP_TACHOMETER, tachometer.attrs, "rpm")
    values = np.asarray(tachometer.values, dtype=float)
    if not np.all(np.isfinite(values)):
        ramp = int(np.argmax(~np.isfinite(values).all(axis=1)))
        raise RigDataError(f"{where}: {RAMP_TACHOMETER}: ramp {ramp} has NaN or inf; expected a speed at every sample")
    if np.any(values <= 0):
        ramp = int(np.argmax((values <= 0).any(axis=1)))
        raise RigDataError(
            f"{where}: {RAMP_TACHOMETER}: ramp {ramp} reaches {values[ramp].min():g} rpm; expected speeds > 0"
        )
    for ramp, speed in enumerate(values):
        if np.ptp(speed) == 0:
            raise RigDataError(
                f"{where}: {RAMP_TACHOMETER}: ramp {ramp} holds one constant speed; expected a run-up or "
                "coast-down (store a constant-speed record as a steady run on op)"
            )
        back, index = reversal(speed)
        if back > MAX_REVERSAL:
            raise RigDataError(
                f"{where}: {RAMP_TACHOMETER}: ramp {ramp} reverses at sample {index} by {back:.0%} of its speed span; "
                f"expected a run-up or a coast-down that steps back by at most {MAX_REVERSAL:.0%}"
            )
    return float(values.max())


def validate_ramps(
    ds: xr.Dataset, where: str, check_units: Callable[[str, str, Mapping, str], None]
) -> tuple[float, float]:
    """Check the ramp records of a rig Dataset; return their sampling rate (Hz) and top speed (rpm).

    ``check_units(where, name, attrs, expected)`` is the format's unit check.
    The sampling rate against the design is checked by the caller.

    Raises
    ------
    RigDataError
        The first deviation found, naming the file and the variable.
    """
    if ds.sizes.get("ramp", 0) < 1:
        raise RigDataError(f"{where}: ramp: the ramp variables hold no record; expected at least one")
    if ds.sizes.get("ramp_time", 0) < 2:
        raise RigDataError(
            f"{where}: ramp_time: expected at least 2 samples per ramp; got {ds.sizes.get('ramp_time', 0)}"
        )
    _check_coordinates(ds, where, check_units)
    _check_channels(ds, where, check_units)
    top = _check_tachometer(ds, where, check_units)
    return sampling_rate(ds["ramp_time"].values, where=f"{where}: ramp_time"), top


__all__ = [
    "RAMP_DIMS",
    "RAMP_COORDINATES",
    "RAMP_CHANNELS",
    "RAMP_TACHOMETER",
    "RAMP_VARIABLES",
    "MAX_REVERSAL",
    "has_ramps",
    "reversal",
    "validate_ramps",
]
