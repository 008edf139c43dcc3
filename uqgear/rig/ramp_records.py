"""Run-up and coast-down records cut into steady-format operating points (speed bins).

A ramp record (docs/rig-data-format.md, "Run-up and coast-down records") is
cut into segments of one common length centred at evenly spaced speeds of its
tachometer. Each segment becomes an operating point of the steady format: its
channel samples on ``time``, the mean of its tachometer as ``pinion_speed``,
the tachometer itself as ``pinion_speed_signal`` (so that
:func:`~uqgear.rig.order_tracking.track_orders` resamples it to uniform angle
at its mean speed, as it does for a wandering steady run), and the ramp's
torques. Every analysis that reads steady runs then reads ramps unchanged.

Segment length, one for all segments of a campaign:

* at least :data:`MIN_REVOLUTIONS` pinion revolutions at each segment's speed:
  shaft-order lines and sidebands need whole revolutions, and two leave the
  order tracking an angle range to resample over;
* short enough that the speed changes within a segment by at most
  ``max_speed_change`` (default :data:`MAX_SPEED_CHANGE`, 5 %) of the
  segment's mean speed: after resampling to uniform angle the mesh orders are
  sharp lines, but their amplitude is the response averaged over the speeds
  the segment swept, and the model predicts it at one speed; near a resonance
  of damping ratio zeta the response changes by half over about 2 zeta of
  speed (10-20 % for the gear mesh), so a 5 % sweep keeps the averaging well
  inside that;
* segments of one ramp do not overlap (each sample counts once, as in separate
  steady runs).

Segments per ramp: by default the ramps of a campaign share
:data:`DEFAULT_SEGMENTS` (8) operating points, ``8 // ramps`` each (at least
one), and take turns along the speeds they sweep: ramp ``r`` of ``R`` takes
every ``R``-th of ``segments x R`` evenly spaced speeds, starting at the
``r``-th, so that a run-up and a coast-down over one span give 8 distinct
speeds, as one ramp or a steady 8-point campaign does. The reason is the
calibration's cost: it samples one adhesion torque per operating point and
evaluates every point's emulator at every step, so its time grows about as
points x (parameters + points); a second ramp over the same speeds adds the
same speed dependence again, and the 8 points already resolve the mesh
resonance as a steady campaign does. ``segments`` given cuts each ramp into
that many segments over its own span.

Where the campaign holds steady runs too, the segments take the steady
records' length (so that all operating points share ``time``), and a ramp too
fast for that length is refused; with ramps alone the length is the longest
that meets the three rules (or ``segment_duration`` where given, checked
against them). Ramp and steady records must then share the sampling rate.

Each segment is taken without two parts of the response that change with
the speed it sweeps and that a steady run does not have: the straight-line
trend of ``te`` (the quasi-static deflection follows the speed) and a
linear-in-time change of each mesh harmonic's amplitude and phase, fitted at
the tachometer's pinion angle jointly with every line of the feature set;
left in, it leaks into the lines nearest the mesh harmonics (the gear-order
sidebands of a segment of one or two gear revolutions).

The operating points carry the coordinate ``op_source``: ``steady`` or
``ramp <index>``, reported by the calibration and the diagnosis with the
per-point speed. This module does no file I/O.
"""

from __future__ import annotations

import json
import math

import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from ..common.errors import RigDataError
from ..physics.design import Design
from .features import feature_definitions
from .format import RIG_COORDINATES, rig_design
from .order_tracking import TACHOMETER_VARIABLE
from .ramp_format import RAMP_CHANNELS, RAMP_COORDINATES, RAMP_TACHOMETER, RAMP_VARIABLES, has_ramps
from .sampling import DEFAULT_BAND_FRACTION, SIGNAL_CHANNELS, sampling_rate

#: Operating points the ramps of a campaign share by default (segments per ramp: this // ramps, at least 1).
DEFAULT_SEGMENTS = 8

#: Largest speed change within a segment, as a fraction of its mean speed.
MAX_SPEED_CHANGE = 0.05

#: Fewest pinion revolutions in a segment at its mean speed.
MIN_REVOLUTIONS = 2.0

#: Gear revolutions a ramp segment holds at least for its gear-order lines to compare with steady runs:
#: on virtual run-ups, segments of 0.6 gear revolutions (200 rpm/s at 820 rpm) read those lines 20-70 % of the
#: channel's largest line off steady runs at their speeds and left healthy gears ``unexplained``; 1.9
#: revolutions (60 rpm/s) read them within 4 % and were diagnosed right (docs/validation/blind-tests.md,
#: "Run-up suite").
RESOLVED_GEAR_REVOLUTIONS = 2.0

#: Name of the operating points' coordinate telling where each came from.
OP_SOURCE = "op_source"


def _starts(speed: np.ndarray, segments: int, size: int, turn: tuple[int, int] = (0, 1)) -> np.ndarray:
    """First sample of each segment of ``size`` samples centred at evenly spaced speeds of a ramp.

    ``turn`` = (r, R): the ramp takes every R-th of ``segments x R`` evenly
    spaced speeds, from the r-th in rising speed (ramps taking turns).
    """
    half = size // 2
    last_centre = speed.size - size + half
    # a monotone envelope of the tachometer places each target speed once, whatever the noise
    rising = speed[-1] >= speed[0]
    envelope = np.maximum.accumulate(speed) if rising else -np.minimum.accumulate(speed)
    offset, stride = turn
    if stride == 1:
        targets = np.linspace(envelope[half], envelope[last_centre], segments)
    else:
        # the turns are counted in rising speed, whichever way the ramp goes
        ends = sorted((abs(envelope[half]), abs(envelope[last_centre])))
        speeds = np.linspace(ends[0], ends[1], segments * stride)[offset::stride]
        targets = speeds if rising else np.sort(-speeds)
    centres = np.clip(np.searchsorted(envelope, targets, side="left"), half, last_centre)
    return np.asarray(centres - half, dtype=int)


def _segment_speeds(speed: np.ndarray, starts: np.ndarray, size: int, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Mean speed (rpm) and speed change over the segment from a straight-line fit (rpm) of each segment."""
    index = starts[:, None] + np.arange(size)[None, :]
    pieces = speed[index]
    time = (np.arange(size) - 0.5 * (size - 1)) / fs
    slope = pieces @ time / float(time @ time)
    return pieces.mean(axis=1), np.abs(slope) * size / fs


def _violation(
    speeds: np.ndarray, segments: int, size: int, fs: float, max_speed_change: float, stride: int = 1
) -> tuple[int, str] | None:
    """The first ramp and rule a segment length breaks, or None where it meets all three."""
    if segments * size > speeds.shape[1]:
        return 0, f"{segments} segments of {size} samples do not fit in a ramp of {speeds.shape[1]} samples"
    for ramp, speed in enumerate(speeds):
        starts = _starts(speed, segments, size, (ramp % stride, stride))
        if segments > 1 and np.any(np.diff(starts) < size):
            return ramp, f"segments of {size / fs:g} s overlap (the ramp is too short or too fast for {segments})"
        mean, change = _segment_speeds(speed, starts, size, fs)
        worst = int(np.argmax(change / mean))
        if change[worst] > max_speed_change * mean[worst]:
            return ramp, (
                f"a segment of {size / fs:g} s changes speed by {change[worst] / mean[worst]:.1%} at "
                f"{mean[worst]:.0f} rpm; expected at most {max_speed_change:.0%}"
            )
        slowest = int(np.argmin(mean))
        if size / fs < MIN_REVOLUTIONS * 60.0 / mean[slowest]:
            return ramp, (
                f"a segment of {size / fs:g} s holds fewer than {MIN_REVOLUTIONS:g} pinion revolutions at "
                f"{mean[slowest]:.0f} rpm"
            )
    return None


def _longest_size(
    speeds: np.ndarray, segments: int, fs: float, max_speed_change: float, where: str, stride: int = 1
) -> int:
    """The longest segment (samples) that meets the rules in every ramp, by bisection."""
    low = max(4, int(math.ceil(MIN_REVOLUTIONS * 60.0 / float(speeds.min()) * fs)))
    high = speeds.shape[1] // segments
    if high < low:
        raise RigDataError(
            f"{where}: {RAMP_TACHOMETER}: the ramps of {speeds.shape[1]} samples are too short for {segments} "
            f"segments of at least {MIN_REVOLUTIONS:g} pinion revolutions"
        )
    broken = _violation(speeds, segments, low, fs, max_speed_change, stride)
    if broken is not None:
        raise RigDataError(
            f"{where}: {RAMP_TACHOMETER}: ramp {broken[0]}: no segment length meets the rules for {segments} "
            f"segments: {broken[1]}"
        )
    # a longer segment sweeps more speed and leaves less room between centres: feasibility is monotone
    while high - low > 1:
        middle = (low + high) // 2
        if _violation(speeds, segments, middle, fs, max_speed_change, stride) is None:
            low = middle
        else:
            high = middle
    return high if _violation(speeds, segments, high, fs, max_speed_change, stride) is None else low


def _truth_per_op(attrs: dict, ramps: np.ndarray) -> dict:
    """The attributes with a virtual rig's per-ramp true adhesion torque carried to the operating points.

    ``true_parameters`` (JSON) may hold ``ramp_adhesion_torque`` (one per
    ramp) beside the steady runs' ``adhesion_torque``; the segments' values
    follow the steady runs' in ``adhesion_torque``, as their operating points do.
    """
    attrs = dict(attrs)
    text = attrs.get("true_parameters")
    if not isinstance(text, str):
        return attrs
    truth = json.loads(text)
    if not isinstance(truth, dict) or "ramp_adhesion_torque" not in truth:
        return attrs
    per_ramp = truth.pop("ramp_adhesion_torque")
    truth["adhesion_torque"] = list(truth.get("adhesion_torque", [])) + [per_ramp[ramp] for ramp in ramps]
    attrs["true_parameters"] = json.dumps(truth)
    return attrs


def points_truth(ds: xr.Dataset, sources: list[str]) -> dict | None:
    """A virtual rig's true parameters per operating point, without cutting the ramps again.

    Parameters
    ----------
    ds : xarray.Dataset
        A validated campaign, as read (ramp records not cut).
    sources : list of str
        ``op_source`` of each operating point the campaign was read as
        (``steady`` or ``ramp <index>``), in order.

    Returns
    -------
    dict or None
        The ``true_parameters`` attribute (JSON) as :func:`steady_campaign`
        carries it to the operating points; None where the file has none.

    Examples
    --------
    >>> import xarray as xr
    >>> points_truth(xr.Dataset(attrs={"true_parameters": '{"zeta_mesh": 0.044}'}), ["steady"])
    {'zeta_mesh': 0.044}
    """
    ramps = np.array([int(source.split()[1]) for source in sources if source.startswith("ramp")], dtype=int)
    attrs = _truth_per_op(ds.attrs, ramps) if has_ramps(ds) else dict(ds.attrs)
    text = attrs.get("true_parameters")
    return json.loads(text) if isinstance(text, str) else None


def _line_orders(design: Design, fs: float, top_speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Orders of the feature set's lines and of its mesh harmonics within the usable band at the top speed."""
    definitions = [d for d in feature_definitions(design) if d.is_line]
    limit = DEFAULT_BAND_FRACTION * fs * 60.0 / top_speed
    lines = np.array(sorted({d.order for d in definitions if d.order < limit}))
    carriers = np.array(sorted({d.order for d in definitions if d.family == "mesh_harmonic" and d.order < limit}))
    return lines, carriers


def _carrier_drift(
    records: np.ndarray, tachometer: np.ndarray, fs: float, lines: np.ndarray, carriers: np.ndarray
) -> np.ndarray:
    """The part of each record (R, N) that is a linear-in-time amplitude change of the carrier lines.

    Per record: one least-squares fit at the pinion angle integrated from the
    tachometer of every line of the feature set (``lines``, orders, constant
    amplitude) and of ``t cos``, ``t sin`` of the ``carriers`` (mesh
    harmonics; t from the segment's centre); the latter part is returned.
    """
    drift = np.zeros_like(records)
    size = records.shape[1]
    centred = (np.arange(size) - 0.5 * (size - 1)) / size
    # one thread: a fit of a few thousand samples on ~100 columns gains nothing from BLAS threads, which spin on
    # the cores another process works on (measured on 2 busy cores: 0.6 s a fit threaded, 0.04 s on one thread)
    with threadpool_limits(1):
        for row, (record, speed) in enumerate(zip(records, tachometer)):
            if np.all(np.isfinite(record)):
                drift[row] = _drift_fit(record, speed, fs, lines, carriers, centred)
    return drift


def _drift_fit(
    record: np.ndarray, speed: np.ndarray, fs: float, lines: np.ndarray, carriers: np.ndarray, centred: np.ndarray
) -> np.ndarray:
    """The linear-in-time carrier part of one record (:func:`_carrier_drift`)."""
    size = record.size
    rate = 2.0 * math.pi * speed / 60.0
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) / fs)])
    phases = np.concatenate([lines, carriers])[None, :] * angle[:, None]
    constant = np.concatenate([np.cos(phases[:, : lines.size]), np.sin(phases[:, : lines.size])], axis=1)
    trend = centred[:, None] * np.concatenate([np.cos(phases[:, lines.size :]), np.sin(phases[:, lines.size :])], 1)
    basis = np.concatenate([np.ones((size, 1)), centred[:, None], constant, trend], axis=1)
    coefficients = np.linalg.lstsq(basis, record, rcond=None)[0]
    return trend @ coefficients[-trend.shape[1] :]


def _segment_dataset(
    ds: xr.Dataset, size: int, segments: tuple[int, int], fs: float, speeds: np.ndarray, design: Design
) -> xr.Dataset:
    """The ramps' segments (``segments`` = (per ramp, stride of the turns)) as steady-format operating points."""
    count, stride = segments
    starts = np.concatenate([_starts(speed, count, size, (ramp % stride, stride)) for ramp, speed in enumerate(speeds)])
    ramps = np.repeat(np.arange(speeds.shape[0]), count)
    index = starts[:, None] + np.arange(size)[None, :]
    tachometer = speeds[ramps[:, None], index]
    data_vars: dict[str, tuple] = {}
    lines = _line_orders(design, fs, float(speeds.max()))
    for ramp_name, name in RAMP_CHANNELS.items():
        if ramp_name not in ds.data_vars:
            continue
        values = np.asarray(ds[ramp_name].values, dtype=float)[ramps[:, None], index]
        # the order tracking divides accelerations by (speed / mean speed)^2 (a response that follows the angle):
        # the drift is taken out of what it will see
        scale = (tachometer / tachometer.mean(axis=1, keepdims=True)) ** 2 if name != "te" else 1.0
        values = values - scale * _carrier_drift(values / scale, tachometer, fs, *lines)
        if name == "te":
            # encoders have no absolute zero: each steady record is stored without its mean; a segment also
            # without its straight-line trend, the quasi-static deflection changing with the speed it sweeps
            time = np.arange(size) - 0.5 * (size - 1)
            slope = values @ time / float(time @ time)
            values = values - values.mean(axis=1, keepdims=True) - slope[:, None] * time[None, :]
        attrs = dict(ds[ramp_name].attrs)
        attrs["units"], attrs["long_name"] = SIGNAL_CHANNELS[name]
        data_vars[name] = (("op", "time"), values.astype(np.float32), attrs)
    data_vars[TACHOMETER_VARIABLE] = (
        ("op", "time"),
        tachometer.astype(np.float32),
        {"units": "rpm", "long_name": "pinion speed (tachometer)"},
    )
    coords: dict[str, tuple] = {
        "time": ("time", np.arange(size) / fs),
        "pinion_speed": ("op", tachometer.mean(axis=1)),
        OP_SOURCE: ("op", np.array([f"ramp {ramp}" for ramp in ramps], dtype=object)),
    }
    for name in ("drive_torque", "adhesion_torque_lower", "adhesion_torque_upper"):
        coords[name] = ("op", np.asarray(ds[f"ramp_{name}"].values, dtype=float)[ramps])
    out = xr.Dataset(data_vars, coords=coords, attrs=_truth_per_op(ds.attrs, ramps))
    for name, (_, units, long_name) in RIG_COORDINATES.items():
        out[name].attrs.update(units=units, long_name=long_name)
    out[OP_SOURCE].attrs["long_name"] = "record the operating point comes from: steady, or a ramp's segment"
    return out


def ramp_operating_points(
    ds: xr.Dataset,
    *,
    segments: int | None = None,
    segment_duration: float | None = None,
    max_speed_change: float = MAX_SPEED_CHANGE,
    design: Design | None = None,
    where: str = "rig data",
) -> xr.Dataset:
    """Cut a campaign's ramp records into segments, each a steady-format operating point.

    Parameters
    ----------
    ds : xarray.Dataset
        A validated ``uqgear-rig/1`` Dataset with ramp records
        (:func:`~uqgear.rig.format.validate_rig`).
    segments : int, optional
        Segments per ramp, centred at evenly spaced speeds of its tachometer
        between the lowest and highest a whole segment fits around. Default:
        the ramps share :data:`DEFAULT_SEGMENTS` operating points and take
        turns along the speeds (module docstring).
    segment_duration : float, optional
        Segment length in s; default the longest that meets the rules (module
        docstring). Checked against them.
    max_speed_change : float
        Largest speed change within a segment, a fraction of its mean speed.
    design : Design, optional
        Gives the orders of the lines (default: the file's ``design``).
    where : str
        Names the file in error messages.

    Returns
    -------
    xarray.Dataset
        Operating points on ``op`` x ``time`` (the segments of each ramp, ramp by
        ramp, in the ramp's speed order) with the steady format's coordinates,
        the channels, ``pinion_speed_signal`` and ``op_source`` (``ramp <index>``).

    Raises
    ------
    RigDataError
        No ramp records, or no segment length meeting the rules; the message
        names the variable and the ramp.

    Examples
    --------
    A 4 s run-up from 1000 to 2000 rpm in eight segments:

    >>> import numpy as np
    >>> import uqgear
    >>> from uqgear.rig.format import make_ramp_dataset
    >>> from uqgear.rig.ramp_records import ramp_operating_points
    >>> time = np.arange(4 * 20480) / 20480.0
    >>> ramps = make_ramp_dataset(time=time, pinion_speed_signal=1000.0 + 250.0 * time[None, :],
    ...                           drive_torque=[5000.0], adhesion_torque_lower=[0.0], adhesion_torque_upper=[5e4],
    ...                           channels={"te": np.sin(2 * np.pi * 50 * time)[None, :]},
    ...                           design=uqgear.load_design("locomotive"), title="run-up", source="example", history="")
    >>> ops = ramp_operating_points(ramps)
    >>> ops.sizes["op"], round(ops.sizes["time"] / 20480, 3)
    (8, 0.205)
    >>> np.round(ops["pinion_speed"].values).tolist()
    [1026.0, 1161.0, 1297.0, 1432.0, 1568.0, 1703.0, 1839.0, 1974.0]
    """
    if not has_ramps(ds) or RAMP_TACHOMETER not in ds.data_vars:
        raise RigDataError(f"{where}: {RAMP_TACHOMETER}: no ramp records to cut into operating points")
    if segments is not None and (
        isinstance(segments, bool) or not isinstance(segments, (int, np.integer)) or segments < 1
    ):
        raise RigDataError(f"{where}: segments: expected a whole number >= 1 of segments per ramp; got {segments!r}")
    if not (isinstance(max_speed_change, (int, float)) and 0 < max_speed_change < 1):
        raise RigDataError(f"{where}: max_speed_change: expected a fraction in (0, 1); got {max_speed_change!r}")
    fs = sampling_rate(ds["ramp_time"].values, where=f"{where}: ramp_time")
    speeds = np.asarray(ds[RAMP_TACHOMETER].values, dtype=float)
    # by default the ramps share the points and take turns along the speeds; given, each ramp over its own span
    stride = speeds.shape[0] if segments is None else 1
    count = max(1, DEFAULT_SEGMENTS // stride) if segments is None else int(segments)
    if segment_duration is None:
        size = _longest_size(speeds, count, fs, max_speed_change, where, stride)
    else:
        if not (isinstance(segment_duration, (int, float)) and segment_duration > 0):
            raise RigDataError(f"{where}: segment_duration: expected a duration > 0 s; got {segment_duration!r}")
        size = int(round(segment_duration * fs))
        broken = _violation(speeds, count, size, fs, max_speed_change, stride)
        if broken is not None:
            raise RigDataError(f"{where}: {RAMP_TACHOMETER}: ramp {broken[0]}: {broken[1]}")
    return _segment_dataset(ds, size, (count, stride), fs, speeds, design if design is not None else rig_design(ds))


def steady_campaign(
    ds: xr.Dataset,
    *,
    segments: int | None = None,
    max_speed_change: float = MAX_SPEED_CHANGE,
    design: Design | None = None,
    where: str = "rig data",
) -> xr.Dataset:
    """A validated campaign with its ramp records cut into operating points beside its steady runs.

    A campaign without ramp records is returned as it is. With ramps alone it
    becomes :func:`ramp_operating_points` of them; with steady runs too, the
    segments take the steady records' length and follow the steady runs on
    ``op``, and ``op_source`` tells them apart (``steady`` or ``ramp <index>``).
    A steady run without a tachometer gets a row of NaN in
    ``pinion_speed_signal``: the order tracking then reads its angle from the
    signals, as before.

    Raises
    ------
    RigDataError
        A ramp that cannot be cut by the rules (module docstring), or ramp and
        steady records at different sampling rates.

    Examples
    --------
    >>> import uqgear
    >>> rig = uqgear.read_rig(uqgear.example_rig_file("healthy"))
    >>> steady_campaign(rig) is rig
    True
    """
    if not has_ramps(ds):
        return ds
    steady = "op" in ds.dims
    duration = None
    if steady:
        fs = sampling_rate(ds["time"].values, where=f"{where}: time")
        ramp_fs = sampling_rate(ds["ramp_time"].values, where=f"{where}: ramp_time")
        if abs(fs - ramp_fs) > 1e-6 * fs:
            raise RigDataError(
                f"{where}: ramp_time: sampling rate {ramp_fs:g} Hz differs from the steady records' {fs:g} Hz; "
                "expected one rate (or the ramps in a file of their own)"
            )
        duration = ds.sizes["time"] / fs
    ramps = ramp_operating_points(
        ds, segments=segments, segment_duration=duration, max_speed_change=max_speed_change, design=design, where=where
    )
    if not steady:
        return ramps
    drop = [name for name in (*RAMP_VARIABLES, *RAMP_COORDINATES) if name in ds.variables]
    runs = ds.drop_vars(drop).assign_coords({OP_SOURCE: ("op", np.full(ds.sizes["op"], "steady", dtype=object))})
    if TACHOMETER_VARIABLE not in runs.data_vars:
        runs[TACHOMETER_VARIABLE] = (
            ("op", "time"),
            np.full((runs.sizes["op"], runs.sizes["time"]), np.nan, dtype=np.float32),
            dict(ramps[TACHOMETER_VARIABLE].attrs),
        )
    ramps = ramps.assign_coords(time=runs["time"].values)
    combined = xr.concat(
        [runs, ramps],
        dim="op",
        data_vars="all",
        coords="minimal",
        compat="override",
        join="exact",
        combine_attrs="override",
    )
    # the segments' attributes carry the truth of both kinds of record (virtual rig), the rest as the file's
    combined.attrs = ramps.attrs
    return combined


def segment_notes(dataset: xr.Dataset, design: Design) -> list[str]:
    """What a campaign cut from ramps cannot show: segments too short for the gear's lines.

    A segment of a ramp holds at least :data:`MIN_REVOLUTIONS` of the pinion, but the gear turns z2 / z1
    times slower; below :data:`RESOLVED_GEAR_REVOLUTIONS` the gear-order lines (the gear's shaft orders and
    the gear sidebands of the mesh harmonics) are not resolved. The note names the shortest segment and the
    ramp rate at that speed that would give the segments enough gear revolutions (at most
    :data:`MAX_SPEED_CHANGE` speed change a segment). Steady runs get no note.

    Parameters
    ----------
    dataset : xarray.Dataset
        A campaign as :func:`steady_campaign` reads it (coordinate ``op_source``).
    design : Design
        Its design (the tooth numbers).

    Returns
    -------
    list of str
        One sentence, or none where every ramp segment holds enough gear revolutions.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.physics.design import load_design
    >>> from uqgear.rig.ramp_records import segment_notes
    >>> fs, size = 20480.0, 4198  # segments of 0.205 s, as 200 rpm/s cuts them at 821 rpm
    >>> campaign = xr.Dataset(coords={"time": np.arange(size) / fs, "pinion_speed": ("op", [821.0, 3779.0]),
    ...                               "op_source": ("op", ["ramp 0", "ramp 1"])})
    >>> print(segment_notes(campaign, load_design("locomotive"))[0])  # doctest: +NORMALIZE_WHITESPACE
    the ramp segments hold as few as 0.58 gear revolutions (operating point 0, 821 rpm, ramp 0): the gear-order
    lines are not resolved there and can read far off the model's steady runs, so a gear effect or a healthy
    gear may be judged wrongly; a ramp at most 58 rpm/s at 821 rpm gives its segments 2 gear revolutions
    """
    if OP_SOURCE not in dataset.coords or "time" not in dataset.coords:
        return []
    sources = [str(source) for source in dataset[OP_SOURCE].values]
    ramps = [op for op, source in enumerate(sources) if source.startswith("ramp")]
    if not ramps:
        return []
    duration = dataset.sizes["time"] / sampling_rate(np.asarray(dataset["time"].values), where="time")
    speeds = np.asarray(dataset["pinion_speed"].values, dtype=float)
    ratio = design.z1 / design.z2
    revolutions = {op: duration * speeds[op] / 60.0 * ratio for op in ramps}
    shortest = min(revolutions, key=revolutions.__getitem__)
    if revolutions[shortest] >= RESOLVED_GEAR_REVOLUTIONS:
        return []
    speed = speeds[shortest]
    # RESOLVED_GEAR_REVOLUTIONS gear revolutions with at most MAX_SPEED_CHANGE of speed change in the segment
    rate = MAX_SPEED_CHANGE * speed * speed * ratio / (60.0 * RESOLVED_GEAR_REVOLUTIONS)
    return [
        f"the ramp segments hold as few as {revolutions[shortest]:.2f} gear revolutions (operating point "
        f"{shortest}, {speed:.0f} rpm, {sources[shortest]}): the gear-order lines are not resolved there and can "
        "read far off the model's steady runs, so a gear effect or a healthy gear may be judged wrongly; a ramp at "
        f"most {rate:.0f} rpm/s at {speed:.0f} rpm gives its segments {RESOLVED_GEAR_REVOLUTIONS:g} gear revolutions"
    ]


__all__ = [
    "DEFAULT_SEGMENTS",
    "RESOLVED_GEAR_REVOLUTIONS",
    "segment_notes",
    "MAX_SPEED_CHANGE",
    "MIN_REVOLUTIONS",
    "OP_SOURCE",
    "ramp_operating_points",
    "steady_campaign",
]
