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
  steady runs);
* no segment reaches into the first or last :data:`RAMP_SETTLING` s of a ramp
  record: a record may begin or end where the ramp starts or stops, and the
  jump of the angular acceleration there sets the gear ringing, which neither a
  steady run nor the model's reading of a segment holds.

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
that meets the rules (or ``segment_duration`` where given, checked
against them). Ramp and steady records must then share the sampling rate.

Each segment is cleaned by :class:`~uqgear.rig.ramp_segments.SegmentCleaner`
(without the straight-line trend of ``te`` and the linear-in-time change of
each mesh harmonic); the diagnosis reads its model of a segment through the
same cleaning (:mod:`uqgear.rig.ramp_segments`).

The operating points carry the coordinate ``op_source``: ``steady`` or
``ramp <index>``, reported by the calibration and the diagnosis with the
per-point speed. This module does no file I/O.
"""

from __future__ import annotations

import json
import math

import numpy as np
import xarray as xr

from ..common.errors import RigDataError
from ..physics.design import Design
from .format import RIG_COORDINATES, rig_design
from .order_tracking import TACHOMETER_VARIABLE, integrated_angle
from .ramp_format import RAMP_CHANNELS, RAMP_COORDINATES, RAMP_TACHOMETER, RAMP_VARIABLES, has_ramps
from .ramp_segments import OP_SOURCE, SEGMENT_ANGLE, SEGMENT_LEAD, SEGMENT_TIME, SegmentCleaner
from .sampling import SIGNAL_CHANNELS, sampling_rate

#: Operating points the ramps of a campaign share by default (segments per ramp: this // ramps, at least 1).
DEFAULT_SEGMENTS = 8

#: Largest speed change within a segment, as a fraction of its mean speed.
MAX_SPEED_CHANGE = 0.05

#: Fewest pinion revolutions in a segment at its mean speed.
MIN_REVOLUTIONS = 2.0

#: Gear revolutions a ramp segment holds at least for its gear-order lines to be resolved: below, the lines
#: a gear effect puts there depend on where in the gear's turn the segment lies, which the model of a
#: segment (:mod:`uqgear.rig.ramp_segments`) follows along one ramp but not from one ramp record to
#: another (each starts at an angle of its own), nor to which tooth is damaged (the fits take tooth 0).
RESOLVED_GEAR_REVOLUTIONS = 2.0

#: Time (s) left out at either end of a ramp record. A record may begin or end where the ramp starts or
#: stops: the angular acceleration jumps there and sets the gear ringing, which neither a steady run nor the
#: model's reading of a segment (:data:`uqgear.rig.ramp_segments.SEGMENT_LEAD`: the same time of ramp
#: before the segment) holds. 0.15 s is about 8 time constants of the slowest linear decay of the reference
#: design (18 ms).
RAMP_SETTLING = SEGMENT_LEAD



def _starts(
    speed: np.ndarray, segments: int, size: int, turn: tuple[int, int] = (0, 1), margin: int = 0
) -> np.ndarray:
    """First sample of each segment of ``size`` samples centred at evenly spaced speeds of a ramp.

    ``turn`` = (r, R): the ramp takes every R-th of ``segments x R`` evenly
    spaced speeds, from the r-th in rising speed (ramps taking turns). No
    segment reaches into the first or last ``margin`` samples.
    """
    half = size // 2
    first_centre = margin + half
    last_centre = speed.size - margin - size + half
    # a monotone envelope of the tachometer places each target speed once, whatever the noise
    rising = speed[-1] >= speed[0]
    envelope = np.maximum.accumulate(speed) if rising else -np.minimum.accumulate(speed)
    offset, stride = turn
    if stride == 1:
        targets = np.linspace(envelope[first_centre], envelope[last_centre], segments)
    else:
        # the turns are counted in rising speed, whichever way the ramp goes
        ends = sorted((abs(envelope[first_centre]), abs(envelope[last_centre])))
        speeds = np.linspace(ends[0], ends[1], segments * stride)[offset::stride]
        targets = speeds if rising else np.sort(-speeds)
    centres = np.clip(np.searchsorted(envelope, targets, side="left"), first_centre, last_centre)
    return np.asarray(centres - half, dtype=int)


def settling_samples(fs: float) -> int:
    """Samples left out at either end of a ramp record sampled at ``fs`` Hz (:data:`RAMP_SETTLING`)."""
    return int(math.ceil(RAMP_SETTLING * fs))


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
    """The first ramp and rule a segment length breaks, or None where it meets them all."""
    margin = settling_samples(fs)
    if segments * size > speeds.shape[1] - 2 * margin:
        return 0, (
            f"{segments} segments of {size} samples do not fit in a ramp of {speeds.shape[1]} samples less "
            f"{RAMP_SETTLING:g} s at either end"
        )
    for ramp, speed in enumerate(speeds):
        starts = _starts(speed, segments, size, (ramp % stride, stride), margin)
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
    high = (speeds.shape[1] - 2 * settling_samples(fs)) // segments
    if high < low:
        raise RigDataError(
            f"{where}: {RAMP_TACHOMETER}: the ramps of {speeds.shape[1]} samples are too short for {segments} "
            f"segments of at least {MIN_REVOLUTIONS:g} pinion revolutions and {RAMP_SETTLING:g} s left out at "
            "either end"
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


def _segment_dataset(
    ds: xr.Dataset, size: int, segments: tuple[int, int], fs: float, speeds: np.ndarray, design: Design
) -> xr.Dataset:
    """The ramps' segments (``segments`` = (per ramp, stride of the turns)) as steady-format operating points."""
    count, stride = segments
    margin = settling_samples(fs)
    starts = np.concatenate(
        [_starts(speed, count, size, (ramp % stride, stride), margin) for ramp, speed in enumerate(speeds)]
    )
    ramps = np.repeat(np.arange(speeds.shape[0]), count)
    index = starts[:, None] + np.arange(size)[None, :]
    tachometer = speeds[ramps[:, None], index]
    data_vars: dict[str, tuple] = {}
    cleaners = [SegmentCleaner(row, fs, design) for row in tachometer]
    for ramp_name, name in RAMP_CHANNELS.items():
        if ramp_name not in ds.data_vars:
            continue
        cut = np.asarray(ds[ramp_name].values, dtype=float)[ramps[:, None], index]
        values = np.stack([cleaner.clean(row, name) for cleaner, row in zip(cleaners, cut)])
        attrs = dict(ds[ramp_name].attrs)
        attrs["units"], attrs["long_name"] = SIGNAL_CHANNELS[name]
        data_vars[name] = (("op", "time"), values.astype(np.float32), attrs)
    data_vars[TACHOMETER_VARIABLE] = (
        ("op", "time"),
        tachometer.astype(np.float32),
        {"units": "rpm", "long_name": "pinion speed (tachometer)"},
    )
    # where each segment starts on its ramp: the pinion angle turned (as the order tracking integrates the
    # tachometer) and the time since the ramp record's first sample
    turned = [integrated_angle(row, fs) for row in speeds]
    coords: dict[str, tuple] = {
        "time": ("time", np.arange(size) / fs),
        "pinion_speed": ("op", tachometer.mean(axis=1)),
        OP_SOURCE: ("op", np.array([f"ramp {ramp}" for ramp in ramps], dtype=object)),
        SEGMENT_ANGLE: ("op", np.array([turned[ramp][start] for ramp, start in zip(ramps, starts)])),
        SEGMENT_TIME: ("op", starts / fs),
    }
    for name in ("drive_torque", "adhesion_torque_lower", "adhesion_torque_upper"):
        coords[name] = ("op", np.asarray(ds[f"ramp_{name}"].values, dtype=float)[ramps])
    out = xr.Dataset(data_vars, coords=coords, attrs=_truth_per_op(ds.attrs, ramps))
    for name, (_, units, long_name) in RIG_COORDINATES.items():
        out[name].attrs.update(units=units, long_name=long_name)
    out[OP_SOURCE].attrs["long_name"] = "record the operating point comes from: steady, or a ramp's segment"
    out[SEGMENT_ANGLE].attrs.update(units="rad", long_name="pinion angle at the segment's start from its ramp's")
    out[SEGMENT_TIME].attrs.update(units="s", long_name="time of the segment's start from its ramp's")
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
    A 4 s run-up from 1000 to 2000 rpm in eight segments (none within 0.15 s of either end):

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
    (8, 0.213)
    >>> np.round(ops["pinion_speed"].values).tolist()
    [1064.0, 1189.0, 1313.0, 1438.0, 1562.0, 1687.0, 1811.0, 1936.0]
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
    runs = ds.drop_vars(drop).assign_coords(
        {
            OP_SOURCE: ("op", np.full(ds.sizes["op"], "steady", dtype=object)),
            SEGMENT_ANGLE: ("op", np.full(ds.sizes["op"], np.nan)),
            SEGMENT_TIME: ("op", np.full(ds.sizes["op"], np.nan)),
        }
    )
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
    the gear sidebands of the mesh harmonics) are not resolved, and a gear effect's share of them depends on
    the gear's angle over the segment. The note names the shortest segment and the
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
    lines are not resolved there, and what a gear effect puts into them depends on where in the gear's turn the
    segment lies, which the model follows along one ramp but not from one ramp record to another, nor to the
    damaged tooth, so a gear effect may be judged wrongly; a ramp at most 58 rpm/s at 821 rpm gives its segments
    2 gear revolutions
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
        f"{shortest}, {speed:.0f} rpm, {sources[shortest]}): the gear-order lines are not resolved there, and what "
        "a gear effect puts into them depends on where in the gear's turn the segment lies, which the model follows "
        "along one ramp but not from one ramp record to another, nor to the damaged tooth, so a gear effect may be "
        f"judged wrongly; a ramp at most {rate:.0f} rpm/s at {speed:.0f} rpm gives its segments "
        f"{RESOLVED_GEAR_REVOLUTIONS:g} gear revolutions"
    ]


__all__ = [
    "DEFAULT_SEGMENTS",
    "RESOLVED_GEAR_REVOLUTIONS",
    "segment_notes",
    "MAX_SPEED_CHANGE",
    "MIN_REVOLUTIONS",
    "RAMP_SETTLING",
    "OP_SOURCE",
    "ramp_operating_points",
    "steady_campaign",
]
