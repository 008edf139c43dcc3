"""Rig data files in the ``uqgear-rig/1`` format: read, validate, write.

One netCDF-4 file per campaign (docs/rig-data-format.md): dimensions ``op``
(steady runs) and ``time`` (samples per run); coordinates ``time`` (s),
``pinion_speed`` (rpm), ``drive_torque``, ``adhesion_torque_lower`` and
``adhesion_torque_upper`` (N m); at least one channel of ``te`` (m),
``acc_pinion`` and ``acc_gear`` (m s-2) over (op, time); global attributes
``conventions`` = ``uqgear-rig/1``, ``design`` (JSON of the design keys),
``title``, ``source`` and ``history``.

A file that does not follow the format is rejected with a
:class:`~uqgear.common.errors.RigDataError` naming the file and the variable or
attribute at fault. Missing samples are NaN: a run with any NaN in a channel is
unusable for that channel only (:func:`usable_runs`).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from ..common.errors import DesignError, RigDataError
from ..common.fileio import atomic_path
from ..physics.design import Design, design_from_json
from .features import SIGNAL_CHANNELS, sampling_rate
from .order_tracking import TACHOMETER_VARIABLE
from .ramp_format import (
    RAMP_CHANNELS,
    RAMP_COORDINATES,
    RAMP_DIMS,
    RAMP_TACHOMETER,
    RAMP_VARIABLES,
    has_ramps,
    validate_ramps,
)

#: Value of the ``conventions`` global attribute.
CONVENTIONS = "uqgear-rig/1"

#: Coordinates: name -> (dims, units, long name).
RIG_COORDINATES: dict[str, tuple[tuple[str, ...], str, str]] = {
    "time": (("time",), "s", "time from the start of each steady record"),
    "pinion_speed": (("op",), "rpm", "mean pinion speed"),
    "drive_torque": (("op",), "N m", "mean drive torque T1 on the pinion"),
    "adhesion_torque_lower": (("op",), "N m", "a-priori lower bound of the adhesion torque T2"),
    "adhesion_torque_upper": (("op",), "N m", "a-priori upper bound of the adhesion torque T2"),
}

#: Free-text global attributes.
TEXT_ATTRIBUTES: tuple[str, ...] = ("title", "source", "history")

# Spellings of the format's units that mean the same and are accepted on read
# (the Dataset returned by read_rig carries the canonical spelling).
_UNIT_SYNONYMS: dict[str, frozenset[str]] = {
    "s": frozenset({"s", "second", "seconds", "sec"}),
    "m": frozenset({"m", "metre", "meter", "metres", "meters"}),
    "m s-2": frozenset({"m s-2", "m/s^2", "m/s2", "m s^-2", "m.s-2", "m*s-2", "m s**-2", "m/s**2"}),
    "rpm": frozenset({"rpm", "min-1", "1/min", "r/min", "rev/min"}),
    "N m": frozenset({"N m", "N.m", "N*m", "Nm", "N·m", "m N"}),
}


def _units_match(found: object, expected: str) -> bool:
    return isinstance(found, str) and " ".join(found.split()) in _UNIT_SYNONYMS[expected]


def _check_units(where: str, name: str, attrs: Mapping, expected: str) -> None:
    if "units" not in attrs:
        raise RigDataError(f"{where}: {name}: missing 'units' attribute; expected {expected!r}")
    if not _units_match(attrs["units"], expected):
        raise RigDataError(f"{where}: {name}: expected units {expected!r}; got {attrs['units']!r}")


def validate_rig(ds: xr.Dataset, *, where: str = "rig data", design: Design | None = None) -> Design:
    """Check that a Dataset follows ``uqgear-rig/1``.

    Parameters
    ----------
    ds : xarray.Dataset
        The rig data, as read from a file or built by :func:`make_rig_dataset`.
    where : str
        Names the file in error messages.
    design : Design, optional
        A nominal design that replaces the file's (``--design``): the file's
        ``design`` attribute must still be a JSON object but is not validated
        as a design (it may hold one that uqgear would refuse), and the
        sampling-rate check uses this design's z1.

    Returns
    -------
    Design
        The nominal design: ``design`` if given, else the ``design`` attribute's.

    Raises
    ------
    RigDataError
        The first deviation from the format found, naming the variable or
        attribute and what was expected.
    """
    if not isinstance(ds, xr.Dataset):
        raise RigDataError(f"{where}: expected an xarray Dataset; got {type(ds).__name__}")
    conventions = ds.attrs.get("conventions")
    if conventions is None:
        raise RigDataError(f"{where}: conventions: missing global attribute; expected {CONVENTIONS!r}")
    if conventions != CONVENTIONS:
        raise RigDataError(f"{where}: conventions: expected {CONVENTIONS!r}; got {conventions!r}")
    for name in TEXT_ATTRIBUTES:
        if name not in ds.attrs:
            raise RigDataError(f"{where}: {name}: missing global attribute (free text)")
        if not isinstance(ds.attrs[name], str):
            raise RigDataError(f"{where}: {name}: expected a text attribute; got {type(ds.attrs[name]).__name__}")
    known = {"op", "time", *RAMP_DIMS}
    unknown_dims = sorted(set(map(str, ds.dims)) - known)
    if unknown_dims:
        raise RigDataError(
            f"{where}: {unknown_dims[0]}: unknown dimension; expected only op and time (and ramp, ramp_time)"
        )
    for name in map(str, ds.data_vars):
        # a coordinate stored as a data variable is reported by the coordinate checks
        known_names = (TACHOMETER_VARIABLE, *RAMP_VARIABLES, *RIG_COORDINATES, *RAMP_COORDINATES)
        if name not in SIGNAL_CHANNELS and name not in known_names:
            raise RigDataError(
                f"{where}: {name}: unknown data variable; expected channels "
                f"{', '.join(SIGNAL_CHANNELS)} (and optionally {TACHOMETER_VARIABLE}), or ramp records "
                f"{', '.join(RAMP_VARIABLES)}"
            )
    ramps = has_ramps(ds)
    # the steady part may be absent only where ramp records stand in for it
    steady = (
        not ramps
        or "op" in ds.dims
        or "time" in ds.dims
        or any(name in ds.variables for name in (*RIG_COORDINATES, *SIGNAL_CHANNELS, TACHOMETER_VARIABLE))
    )
    # (sampling rate, top speed, the time variable it applies to) of each kind of record
    rates: list[tuple[float, float, str]] = []
    if steady:
        rates.append((*_validate_steady(ds, where), "time"))
    if ramps:
        rates.append((*validate_ramps(ds, where, _check_units), "ramp_time"))

    text = ds.attrs.get("design")
    if text is None:
        raise RigDataError(f"{where}: design: missing global attribute (JSON object of the design keys)")
    if not isinstance(text, str):
        raise RigDataError(f"{where}: design: expected JSON text; got {type(text).__name__}")
    design = _nominal_design(text, where, design)

    for fs, fastest, name in rates:
        needed = 6.0 * design.z1 * fastest / 60.0
        if not fs > needed:
            raise RigDataError(
                f"{where}: {name}: sampling rate {fs:g} Hz does not resolve the third mesh harmonic at "
                f"{fastest:g} rpm; expected fs > 6 z1 n1_max/60 = {needed:g} Hz"
            )
    return design


def _validate_steady(ds: xr.Dataset, where: str) -> tuple[float, float]:
    """Check the steady runs (op x time) of a rig Dataset; return the sampling rate (Hz) and top speed (rpm)."""
    if ds.sizes.get("op", 0) < 1:
        raise RigDataError(
            f"{where}: op: the file holds no operating point; expected at least one run (or ramp records)"
        )
    if ds.sizes.get("time", 0) < 2:
        raise RigDataError(f"{where}: time: expected at least 2 samples per run; got {ds.sizes.get('time', 0)}")
    for name, (dims, units, _) in RIG_COORDINATES.items():
        if name not in ds.coords:
            where_found = " (found as a data variable)" if name in ds.data_vars else ""
            raise RigDataError(f"{where}: {name}: missing coordinate{where_found}; expected dims {dims} in {units}")
        variable = ds[name]
        if variable.dims != dims:
            raise RigDataError(f"{where}: {name}: expected dims {dims}; got {variable.dims}")
        _check_units(where, name, variable.attrs, units)
        if not np.issubdtype(variable.dtype, np.number):
            raise RigDataError(f"{where}: {name}: expected numbers; got dtype {variable.dtype}")
        if not np.all(np.isfinite(variable.values)):
            raise RigDataError(f"{where}: {name}: expected finite values; found NaN or inf")

    speed = ds["pinion_speed"].values
    if np.any(speed <= 0):
        index = int(np.argmax(speed <= 0))
        raise RigDataError(f"{where}: pinion_speed: expected speeds > 0 rpm; op {index} has {speed[index]:g}")
    lower = ds["adhesion_torque_lower"].values
    upper = ds["adhesion_torque_upper"].values
    if np.any(lower > upper):
        index = int(np.argmax(lower > upper))
        raise RigDataError(
            f"{where}: adhesion_torque_lower: expected <= adhesion_torque_upper; op {index} has "
            f"lower {lower[index]:g} N m > upper {upper[index]:g} N m"
        )
    _validate_steady_channels(ds, where)
    return sampling_rate(ds["time"].values, where=f"{where}: time"), float(speed.max())


def _validate_steady_channels(ds: xr.Dataset, where: str) -> None:
    channels = [str(name) for name in ds.data_vars if name not in (*RAMP_VARIABLES, *RAMP_COORDINATES)]
    if not channels:
        raise RigDataError(f"{where}: no data variable; expected at least one of {', '.join(SIGNAL_CHANNELS)}")
    if TACHOMETER_VARIABLE in channels:
        # optional instantaneous speed (a tachometer), used by the order tracking; not a measured channel
        channels.remove(TACHOMETER_VARIABLE)
        tachometer = ds[TACHOMETER_VARIABLE]
        if tachometer.dims != ("op", "time"):
            raise RigDataError(f"{where}: {TACHOMETER_VARIABLE}: expected dims ('op', 'time'); got {tachometer.dims}")
        _check_units(where, TACHOMETER_VARIABLE, tachometer.attrs, "rpm")
        if not channels:
            raise RigDataError(
                f"{where}: no channel variable besides {TACHOMETER_VARIABLE}; expected at least "
                f"one of {', '.join(SIGNAL_CHANNELS)}"
            )
    for name in channels:
        variable = ds[name]
        units = SIGNAL_CHANNELS[name][0]
        if variable.dims != ("op", "time"):
            raise RigDataError(f"{where}: {name}: expected dims ('op', 'time'); got {variable.dims}")
        if not np.issubdtype(variable.dtype, np.floating):
            raise RigDataError(
                f"{where}: {name}: expected floating-point samples (NaN where missing); got dtype {variable.dtype}"
            )
        _check_units(where, name, variable.attrs, units)
        long_name = variable.attrs.get("long_name")
        if not isinstance(long_name, str) or not long_name.strip():
            raise RigDataError(f"{where}: {name}: missing 'long_name' attribute (text)")
        if "noise_std" in variable.attrs:
            _check_noise_std(where, name, variable.attrs["noise_std"], units)
        if np.any(np.isinf(variable.values)):
            raise RigDataError(f"{where}: {name}: expected finite samples (NaN where missing); found inf")


def _check_noise_std(where: str, name: str, noise: object, units: str) -> None:
    if isinstance(noise, np.generic):
        noise = noise.item()
    if (
        isinstance(noise, bool)
        or not isinstance(noise, (int, float))
        or not math.isfinite(float(noise))
        or float(noise) < 0
    ):
        raise RigDataError(f"{where}: {name}: noise_std: expected a number >= 0 in {units}; got {noise!r}")


def _nominal_design(text: str, where: str, replacement: Design | None) -> Design:
    """The file's design, validated, or the replacement, with the file's copy only parsed."""
    if replacement is None:
        try:
            return design_from_json(text, where=f"{where}: design")
        except DesignError as exc:
            raise RigDataError(str(exc)) from None
    if not isinstance(replacement, Design):
        raise RigDataError(
            f"{where}: design: expected a uqgear Design to replace the file's; got {type(replacement).__name__}"
        )
    # replaced: the file's copy is not used, so it is held to the format (a JSON object) only
    try:
        values = json.loads(text)
    except (ValueError, RecursionError):
        values = None
    if not isinstance(values, dict):
        raise RigDataError(f"{where}: design: expected JSON text of an object of design keys")
    return replacement


def _canonical_units(ds: xr.Dataset) -> None:
    """Replace accepted unit spellings by the format's own, in place."""
    for name, (_, units, _) in {**RIG_COORDINATES, **RAMP_COORDINATES}.items():
        if name in ds.variables:
            ds[name].attrs["units"] = units
    for variable in map(str, ds.data_vars):
        if variable in (TACHOMETER_VARIABLE, RAMP_TACHOMETER):
            ds[variable].attrs["units"] = "rpm"
        else:
            ds[variable].attrs["units"] = SIGNAL_CHANNELS[RAMP_CHANNELS.get(variable, variable)][0]


def read_rig(path: str | os.PathLike[str], *, design: Design | None = None) -> xr.Dataset:
    """Read and validate a ``uqgear-rig/1`` file.

    Parameters
    ----------
    path : str or path-like
        The netCDF-4 file.
    design : Design, optional
        A nominal design that replaces the file's: the file's ``design``
        attribute is then not validated as a design (:func:`validate_rig`).

    Returns
    -------
    xarray.Dataset
        Loaded into memory (the file is closed); ``attrs["design"]`` stays JSON
        text, see :func:`rig_design`. Units carry the format's spelling.

    Raises
    ------
    RigDataError
        The file is missing, unreadable or does not follow the format; the
        message names the file and the variable or attribute.

    Examples
    --------
    The labelled healthy campaign shipped with the package: eight steady runs
    of 1 s at 20480 Hz:

    >>> import uqgear
    >>> rig = uqgear.read_rig(uqgear.example_rig_file("healthy"))
    >>> rig.attrs["conventions"], dict(rig.sizes)
    ('uqgear-rig/1', {'op': 8, 'time': 20480})
    >>> rig["pinion_speed"].values.tolist()
    [600.0, 800.0, 1250.0, 1700.0, 2200.0, 2800.0, 3400.0, 3800.0]
    >>> rig["te"].attrs["units"], float(1 / (rig["time"][1] - rig["time"][0]))
    ('m', 20480.0)
    >>> try:
    ...     uqgear.read_rig("missing/campaign.nc")
    ... except uqgear.RigDataError as error:
    ...     print(error)
    missing/campaign.nc: rig data file not found
    """
    path = Path(path)
    if not path.is_file():
        raise RigDataError(f"{path}: rig data file not found")
    try:
        ds = xr.load_dataset(path, engine="netcdf4", decode_times=False, decode_timedelta=False)
    except (OSError, ValueError, RuntimeError) as exc:
        raise RigDataError(f"{path}: not a readable netCDF-4 file ({exc})") from None
    validate_rig(ds, where=str(path), design=design)
    _canonical_units(ds)
    return ds


def rig_design(ds: xr.Dataset, *, where: str = "rig data") -> Design:
    """The nominal design stored in a rig Dataset's ``design`` attribute."""
    text = ds.attrs.get("design")
    if not isinstance(text, str):
        raise RigDataError(f"{where}: design: missing global attribute (JSON object of the design keys)")
    try:
        return design_from_json(text, where=f"{where}: design")
    except DesignError as exc:
        raise RigDataError(str(exc)) from None


def usable_runs(ds: xr.Dataset) -> xr.DataArray:
    """Which runs each channel can use: those without any NaN sample.

    Returns
    -------
    xarray.DataArray
        Booleans over (channel, op), with the op coordinates of ``ds``.
    """
    channels = [str(name) for name in ds.data_vars if name not in RAMP_VARIABLES]
    masks = [ds[name].notnull().all("time") for name in channels]
    usable = xr.concat(masks, dim="channel", coords="minimal").assign_coords(channel=channels)
    usable.attrs = {"long_name": "run has no missing (NaN) sample in the channel"}
    return usable.rename("usable_runs")


def _assembled(
    data_vars: Mapping[str, Any],
    coords: Mapping[str, Any],
    coordinate_table: Mapping[str, tuple[Any, str, str]],
    design: Design,
    texts: tuple[str, str, str],
    where: str,
) -> xr.Dataset:
    """A rig dataset from its variables: the global attributes (title, source, history), the units and long
    names of ``coordinate_table``'s coordinates, validated."""
    title, source, history = texts
    ds = xr.Dataset(
        data_vars,
        coords=coords,
        attrs={
            "conventions": CONVENTIONS,
            "design": design.to_json(),
            "title": title,
            "source": source,
            "history": history,
        },
    )
    for name, (_, units, long_name) in coordinate_table.items():
        ds[name].attrs.update(units=units, long_name=long_name)
    validate_rig(ds, where=where)
    return ds


def make_rig_dataset(
    *,
    time: ArrayLike,
    pinion_speed: ArrayLike,
    drive_torque: ArrayLike,
    adhesion_torque_lower: ArrayLike,
    adhesion_torque_upper: ArrayLike,
    channels: Mapping[str, ArrayLike],
    design: Design,
    title: str,
    source: str,
    history: str,
    noise_std: Mapping[str, float] | None = None,
) -> xr.Dataset:
    """Build a validated rig Dataset (channels stored as float32, as in the format's files).

    Parameters
    ----------
    time : array_like
        Sample instants in s, uniform spacing, shared by all runs.
    pinion_speed, drive_torque, adhesion_torque_lower, adhesion_torque_upper : array_like
        Per run: mean pinion speed (rpm), mean drive torque and the adhesion
        torque bounds (N m).
    channels : mapping
        Channel name (``te``, ``acc_pinion``, ``acc_gear``) -> samples over
        (op, time) in the format's units; NaN where missing.
    design : Design
        Nominal design of the gear pair, stored as JSON.
    title, source, history : str
        Free text.
    noise_std : mapping, optional
        Channel name -> sensor noise standard deviation in the channel's units.

    Returns
    -------
    xarray.Dataset

    Raises
    ------
    RigDataError
        A shape, unit-bearing value or channel name that the format rejects.
    """
    where = "new rig data"
    if not isinstance(design, Design):
        raise RigDataError(f"{where}: design: expected a uqgear Design; got {type(design).__name__}")
    per_run = {
        "pinion_speed": pinion_speed,
        "drive_torque": drive_torque,
        "adhesion_torque_lower": adhesion_torque_lower,
        "adhesion_torque_upper": adhesion_torque_upper,
    }
    arrays = {name: np.asarray(values, dtype=float) for name, values in per_run.items()}
    n_op = arrays["pinion_speed"].size
    for name, array in arrays.items():
        if array.ndim != 1 or array.size != n_op:
            raise RigDataError(
                f"{where}: {name}: expected one value per run ({n_op}, as pinion_speed); got shape {array.shape}"
            )
    time_values = np.asarray(time, dtype=float)
    if time_values.ndim != 1:
        raise RigDataError(f"{where}: time: expected a 1-D array of sample instants; got shape {time_values.shape}")
    noise_std = dict(noise_std or {})
    unknown = sorted(set(noise_std) - set(channels))
    if unknown:
        raise RigDataError(f"{where}: noise_std: {unknown[0]} is not one of the channels given ({', '.join(channels)})")
    data_vars = {}
    for name, values in channels.items():
        if name not in SIGNAL_CHANNELS:
            raise RigDataError(f"{where}: {name}: unknown channel; expected {', '.join(SIGNAL_CHANNELS)}")
        samples = np.asarray(values, dtype=np.float32)
        if samples.shape != (n_op, time_values.size):
            raise RigDataError(
                f"{where}: {name}: expected shape (op, time) = ({n_op}, {time_values.size}); got {samples.shape}"
            )
        units, long_name = SIGNAL_CHANNELS[name]
        attrs: dict[str, object] = {"units": units, "long_name": long_name}
        if name in noise_std:
            attrs["noise_std"] = noise_std[name]
        data_vars[name] = (("op", "time"), samples, attrs)
    coords = {"time": ("time", time_values)}
    coords.update({name: ("op", values) for name, values in arrays.items()})
    return _assembled(data_vars, coords, RIG_COORDINATES, design, (title, source, history), where)


def make_ramp_dataset(
    *,
    time: ArrayLike,
    pinion_speed_signal: ArrayLike,
    drive_torque: ArrayLike,
    adhesion_torque_lower: ArrayLike,
    adhesion_torque_upper: ArrayLike,
    channels: Mapping[str, ArrayLike],
    design: Design,
    title: str,
    source: str,
    history: str,
    noise_std: Mapping[str, float] | None = None,
) -> xr.Dataset:
    """Build a validated rig Dataset of run-up or coast-down records (dims ``ramp`` x ``ramp_time``).

    The arguments are those of :func:`make_rig_dataset` for ramps: ``time``
    is the ramp records' sample instants (stored as ``ramp_time``),
    ``pinion_speed_signal`` the tachometer (rpm, ramp x ramp_time), the
    torques one value per ramp, ``channels`` keyed by the steady names (``te``,
    ``acc_pinion``, ``acc_gear``; stored with the ``ramp_`` prefix). To hold
    steady runs too, merge with a steady Dataset:
    ``xarray.merge([steady, ramps], combine_attrs="override")``.

    Returns
    -------
    xarray.Dataset

    Raises
    ------
    RigDataError
        A shape, channel name or speed record that the format rejects.

    Examples
    --------
    >>> import numpy as np
    >>> import uqgear
    >>> from uqgear.rig.format import make_ramp_dataset
    >>> time = np.arange(20480) / 20480.0
    >>> speed = 1000.0 + 500.0 * time[None, :]
    >>> ramps = make_ramp_dataset(time=time, pinion_speed_signal=speed, drive_torque=[5000.0],
    ...                           adhesion_torque_lower=[0.0], adhesion_torque_upper=[5e4],
    ...                           channels={"te": np.zeros((1, time.size))}, design=uqgear.load_design("locomotive"),
    ...                           title="ramp", source="example", history="")
    >>> dict(ramps.sizes), sorted(ramps.data_vars)
    ({'ramp': 1, 'ramp_time': 20480}, ['ramp_pinion_speed_signal', 'ramp_te'])
    """
    where = "new rig data"
    if not isinstance(design, Design):
        raise RigDataError(f"{where}: design: expected a uqgear Design; got {type(design).__name__}")
    time_values = np.asarray(time, dtype=float)
    speed = np.asarray(pinion_speed_signal, dtype=float)
    if time_values.ndim != 1 or speed.ndim != 2 or speed.shape[1] != time_values.size:
        raise RigDataError(
            f"{where}: {RAMP_TACHOMETER}: expected shape (ramp, ramp_time) with ramp_time = {time_values.size} "
            f"samples; got {speed.shape}"
        )
    noise_std = dict(noise_std or {})
    data_vars: dict[str, tuple] = {
        RAMP_TACHOMETER: (RAMP_DIMS, speed, {"units": "rpm", "long_name": "pinion speed (tachometer)"})
    }
    for name, values in channels.items():
        if name not in SIGNAL_CHANNELS:
            raise RigDataError(f"{where}: {name}: unknown channel; expected {', '.join(SIGNAL_CHANNELS)}")
        samples = np.asarray(values, dtype=np.float32)
        if samples.shape != speed.shape:
            raise RigDataError(
                f"{where}: {name}: expected shape (ramp, ramp_time) = {speed.shape}; got {samples.shape}"
            )
        units, long_name = SIGNAL_CHANNELS[name]
        attrs: dict[str, object] = {"units": units, "long_name": long_name}
        if name in noise_std:
            attrs["noise_std"] = noise_std[name]
        data_vars[f"ramp_{name}"] = (RAMP_DIMS, samples, attrs)
    per_ramp = {
        "ramp_drive_torque": drive_torque,
        "ramp_adhesion_torque_lower": adhesion_torque_lower,
        "ramp_adhesion_torque_upper": adhesion_torque_upper,
    }
    coords: dict[str, tuple] = {"ramp_time": ("ramp_time", time_values)}
    for name, values in per_ramp.items():
        array = np.asarray(values, dtype=float)
        if array.shape != (speed.shape[0],):
            raise RigDataError(
                f"{where}: {name}: expected one value per ramp ({speed.shape[0]}); got shape {array.shape}"
            )
        coords[name] = ("ramp", array)
    return _assembled(data_vars, coords, RAMP_COORDINATES, design, (title, source, history), where)


def write_rig(path: str | os.PathLike[str], ds: xr.Dataset) -> Path:
    """Validate a rig Dataset and write it as a ``uqgear-rig/1`` file, atomically.

    The file appears complete or not at all: it is written under a temporary
    name in the target folder and renamed. Channels are stored as float32.

    Parameters
    ----------
    path : str or path-like
        Target file (``.nc``); its folder must exist.
    ds : xarray.Dataset
        Rig data, e.g. from :func:`make_rig_dataset` or :func:`read_rig`.

    Returns
    -------
    pathlib.Path
        The path written.

    Raises
    ------
    RigDataError
        The Dataset does not follow the format, or the folder does not exist.

    Examples
    --------
    A short virtual campaign written and read back: the channels come back
    as the float32 values stored:

    >>> import pathlib, tempfile
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> campaign = uqgear.simulate_campaign(design, {"pinion_speed": [1500.0], "drive_torque": [7000.0]},
    ...                                     duration=0.1, run_in=0.05, seed=7)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = uqgear.write_rig(pathlib.Path(folder) / "campaign.nc", campaign)
    ...     back = uqgear.read_rig(path)
    >>> back["te"].dtype.name, bool((back["te"] == campaign["te"].astype("float32")).all())
    ('float32', True)

    A Dataset that breaks the format is refused before anything is written:

    >>> wrong = campaign.copy()
    >>> wrong["te"] = wrong["te"].assign_attrs(units="mm")
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     try:
    ...         uqgear.write_rig(pathlib.Path(folder) / "wrong.nc", wrong)
    ...     except uqgear.RigDataError as error:
    ...         print(str(error).split(": ", 1)[1], list(pathlib.Path(folder).iterdir()))
    te: expected units 'm'; got 'mm' []
    """
    path = Path(path)
    validate_rig(ds, where=str(path))
    if not path.parent.is_dir():
        raise RigDataError(f"{path}: folder {path.parent} does not exist")
    # Encodings inherited from a file read earlier (chunking, source) must not leak into the new file.
    out = ds.drop_encoding()
    encoding: dict[str, dict[str, object]] = {
        str(name): {"dtype": "float32", "_FillValue": np.float32(np.nan)} for name in out.data_vars
    }
    encoding.update(
        {
            name: {"dtype": "float64", "_FillValue": None}
            for name in (*RIG_COORDINATES, *RAMP_COORDINATES)
            if name in out.variables
        }
    )
    with atomic_path(path) as temporary:
        out.to_netcdf(temporary, format="NETCDF4", engine="netcdf4", encoding=encoding)
    return path


__all__ = [
    "CONVENTIONS",
    "RIG_COORDINATES",
    "TEXT_ATTRIBUTES",
    "validate_rig",
    "read_rig",
    "rig_design",
    "usable_runs",
    "make_rig_dataset",
    "make_ramp_dataset",
    "write_rig",
]
