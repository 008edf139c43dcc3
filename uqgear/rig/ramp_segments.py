"""A ramp segment read alike from the rig's record and from the model: the speed it swept and its cleaning.

A segment of a run-up or coast-down (:mod:`uqgear.rig.ramp_records`) is
not a steady run: the mesh harmonics' response changes along the speeds
it sweeps (a resonance passage, the history the gear brings into it), and
a segment too short to resolve the gear-order lines reads that change as
leakage into them. A steady model run at the segment's mean speed has
neither (on virtual run-ups at 200 rpm/s its gear-order lines read up to
several times the channel's largest line off the segment's at 850 rpm).
The model is therefore read through the segment itself
(:class:`SegmentProfile`): driven through the speed the segment's
tachometer swept, from :data:`SEGMENT_LEAD` s before it, recorded like the
rig's segment, cleaned by :class:`SegmentCleaner` as the rig's segment was
and order-tracked with the model's own angle.

:class:`SegmentCleaner` is the segment cleaning both records get: each
mesh harmonic's linear-in-time change of amplitude and phase (fitted at
the tachometer's pinion angle jointly with every line of the feature set)
is taken out, and from the TE its mean and straight-line trend (the
quasi-static deflection following the speed). Left in, the carrier's
change leaks into the lines nearest the mesh harmonics.

This module does no file I/O and runs no model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from ..physics.design import Design
from ..physics.effects import Effect
from ..physics.speed_profile import SpeedProfile
from .features import feature_definitions
from .order_tracking import TACHOMETER_VARIABLE, integrated_angle
from .sampling import DEFAULT_BAND_FRACTION, sampling_rate

#: Time (s) the model is driven through the ramp before a segment's first sample: the gear's response
#: at a speed depends on the speeds before it; 0.15 s is about 8 time constants of the slowest linear
#: decay of the reference design (18 ms), over which the model's start onto the ramp has died away. A
#: ramp record leaves out as much at its ends (:data:`uqgear.rig.ramp_records.RAMP_SETTLING`).
SEGMENT_LEAD = 0.15

#: Time (s) the model is driven past a segment's last sample: the band-limiting's tapered edge and its
#: filter's ringing stay outside the segment (the guard of a steady model run's whole record).
SEGMENT_GUARD = 0.025

#: Name of the operating points' coordinate telling where each came from (``ramp <index>`` for a segment).
OP_SOURCE = "op_source"
#: Names of the coordinates saying where a segment starts on its ramp: the pinion angle (rad) turned and the
#: time (s) since the ramp record's first sample (NaN for a steady run).
SEGMENT_ANGLE = "segment_angle"
SEGMENT_TIME = "segment_time"
#: The coordinates on ``op`` that say where an operating point came from, not what it ran at.
SOURCE_COORDINATES = (OP_SOURCE, SEGMENT_ANGLE, SEGMENT_TIME)


@dataclass(frozen=True)
class SegmentProfile:
    """The speed a ramp segment swept, as the model is driven through it.

    The segment's tachometer fitted by a quadratic in time (a ramp, its
    curvature, a slow wander over the segment), continued over the lead
    before it and the guard after it; where the quadratic would turn back
    there (a wander's curvature continued past the segment), by the straight
    line fitted to the tachometer, which keeps the ramp's direction.

    Parameters
    ----------
    coefficients : tuple of float
        Quadratic in time from the segment's centre (:func:`numpy.polyval` order), rpm.
    size : int
        Samples in the segment.
    fs : float
        Sampling rate, Hz.
    start_angle, start_time : float
        Where the segment starts on its ramp: the pinion angle turned (rad) and the time (s) since the
        ramp record's first sample. A model of the segment turns the effects locked to a shaft or a clock
        on by as much (:meth:`uqgear.physics.effects.Effect.turned`), so that one effect phase holds for
        every segment of a ramp.

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.rig.ramp_segments import SegmentProfile
    >>> fs = 20480.0
    >>> time = np.arange(4096) / fs
    >>> segment = SegmentProfile.from_tachometer(1000.0 + 200.0 * time, fs)
    >>> round(segment.mean_speed, 3), round(float(segment.speed_at(np.array([0.0]))[0]), 3)
    (1019.995, 1000.0)
    >>> profile = segment.profile(lead=0.15, guard=0.025)
    >>> round(profile.duration, 4), round(float(profile.speed(0.15)), 3)
    (0.375, 1000.0)
    """

    coefficients: tuple[float, float, float]
    size: int
    fs: float
    start_angle: float = 0.0
    start_time: float = 0.0

    @classmethod
    def from_tachometer(
        cls,
        speed: np.ndarray,
        fs: float,
        reach: tuple[float, float] = (SEGMENT_LEAD, SEGMENT_GUARD),
        start: tuple[float, float] = (0.0, 0.0),
    ) -> SegmentProfile:
        """The profile of a segment whose tachometer (rpm, one per sample at ``fs`` Hz) reads ``speed``.

        ``reach``: the time (s) before and after the segment the profile is continued over, where it
        must keep the ramp's direction; ``start``: the segment's start angle (rad) and time (s) on its ramp.
        """
        speed = np.asarray(speed, dtype=float)
        duration = speed.size / fs
        centred = np.arange(speed.size) / fs - 0.5 * duration
        a, b, c = np.polyfit(centred, speed, 2)
        # the quadratic's slope b + 2 a t is monotone in t: it keeps its sign over the reach if it does at both ends
        ends = b + 2.0 * a * np.array([-0.5 * duration - reach[0], 0.5 * duration + reach[1]])
        if not (np.all(ends > 0.0) or np.all(ends < 0.0)):
            b, c = np.polyfit(centred, speed, 1)
            a = 0.0
        return cls((float(a), float(b), float(c)), int(speed.size), float(fs), float(start[0]), float(start[1]))

    @property
    def duration(self) -> float:
        """The segment's length, s."""
        return self.size / self.fs

    @property
    def mean_speed(self) -> float:
        """Mean of the fitted speed over the segment's samples, rpm."""
        return float(np.mean(self.speed_at(np.arange(self.size) / self.fs)))

    def speed_at(self, time: np.ndarray) -> np.ndarray:
        """Fitted speed (rpm) at ``time`` s from the segment's first sample."""
        return np.polyval(self.coefficients, np.asarray(time, dtype=float) - 0.5 * self.duration)

    def turned_effects(
        self, design: Design, effects: Sequence[Effect], profile: SpeedProfile, lead: float
    ) -> tuple[Effect, ...]:
        """``effects`` as a run driven through ``profile`` (:meth:`profile` from ``lead`` s before the segment)
        must take them.

        That run's shafts start at angle 0 and its clock at 0; the effects are turned on by the whole pinion
        teeth nearest to where the segment starts on its ramp less the angle the run turns over the lead,
        and by the ramp's time at the run's start, so that every segment of a ramp sees one effect phase
        (whole teeth keep the mesh phase: the rest, under half a tooth, is left).
        """
        lead_angle = float(profile.angle(lead))
        teeth = int(round((self.start_angle - lead_angle) * design.z1 / (2.0 * math.pi)))
        return tuple(effect.turned(design, teeth, self.start_time - lead) for effect in effects)

    def profile(self, lead: float, guard: float) -> SpeedProfile:
        """The model's speed profile: t = 0 ``lead`` s before the segment, to ``guard`` s after it."""
        return SpeedProfile.from_function(lambda t: self.speed_at(t - lead), lead + self.duration + guard)


def segment_profiles(dataset: xr.Dataset, tracked: Sequence[bool] | None = None) -> tuple[SegmentProfile | None, ...]:
    """Per operating point, the profile of its ramp segment, or None for a steady run.

    An operating point is a ramp segment where ``op_source`` says so and its
    tachometer (``pinion_speed_signal``) is finite and positive; with
    ``tracked`` (the order tracking's flag per run), only where its record was
    resampled to uniform angle, as the model's is then.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.rig.ramp_segments import segment_profiles
    >>> fs, size = 20480.0, 2048
    >>> ramp = 1500.0 + 300.0 * np.arange(size) / fs
    >>> ops = xr.Dataset({"pinion_speed_signal": (("op", "time"), np.stack([np.full(size, 2000.0), ramp]))},
    ...                  coords={"time": np.arange(size) / fs, "op_source": ("op", ["steady", "ramp 0"])})
    >>> [profile is None for profile in segment_profiles(ops)]
    [True, False]
    """
    if OP_SOURCE not in dataset.coords or TACHOMETER_VARIABLE not in dataset.data_vars:
        return (None,) * int(dataset.sizes.get("op", 0))
    fs = sampling_rate(dataset["time"].values, where="time")
    speeds = np.asarray(dataset[TACHOMETER_VARIABLE].values, dtype=float)
    size = speeds.shape[0]
    angles, times = (
        np.asarray(dataset[name].values, dtype=float) if name in dataset.coords else np.zeros(size)
        for name in (SEGMENT_ANGLE, SEGMENT_TIME)
    )
    profiles: list[SegmentProfile | None] = []
    for op, source in enumerate(dataset[OP_SOURCE].values):
        speed = speeds[op]
        usable = str(source).startswith("ramp") and bool(np.all(np.isfinite(speed)) and np.all(speed > 0))
        if tracked is not None:
            usable = usable and bool(tracked[op])
        start = (float(np.nan_to_num(angles[op])), float(np.nan_to_num(times[op])))
        profiles.append(SegmentProfile.from_tachometer(speed, fs, start=start) if usable else None)
    return tuple(profiles)


def line_orders(design: Design, fs: float, top_speed: float) -> tuple[np.ndarray, np.ndarray]:
    """Orders of the feature set's lines and of its mesh harmonics within the usable band at the top speed."""
    definitions = [d for d in feature_definitions(design) if d.is_line]
    limit = DEFAULT_BAND_FRACTION * fs * 60.0 / top_speed
    lines = np.array(sorted({d.order for d in definitions if d.order < limit}))
    carriers = np.array(sorted({d.order for d in definitions if d.family == "mesh_harmonic" and d.order < limit}))
    return lines, carriers


class SegmentCleaner:
    """The cleaning of one segment's records (module docstring), built once for its tachometer.

    One least-squares fit per record at the pinion angle integrated from
    ``speed``: every line of the feature set within the band at the segment's
    top speed (constant amplitude), a constant, a straight line, and ``t cos``,
    ``t sin`` of each mesh harmonic (t from the segment's centre); the last part
    is the drift taken out. The fit's pseudo-inverse depends on the speed alone,
    so the model's many records of one segment share it.

    Parameters
    ----------
    speed : array (N,)
        The segment's pinion speed, rpm, one per sample.
    fs : float
        Sampling rate, Hz.
    design : Design
        Gives the lines' orders.

    Examples
    --------
    >>> import numpy as np
    >>> import uqgear
    >>> from uqgear.rig.ramp_segments import SegmentCleaner
    >>> design, fs = uqgear.load_design("locomotive"), 20480.0
    >>> time = np.arange(4096) / fs
    >>> speed = 1500.0 + 300.0 * time
    >>> angle = 2 * np.pi * np.cumsum(speed / 60.0) / fs
    >>> te = (1.0 + 5.0 * (time - time.mean())) * np.cos(21 * angle) + 3.0 * time
    >>> cleaned = SegmentCleaner(speed, fs, design).clean(te, "te")
    >>> bool(np.std(cleaned - np.cos(21 * angle)) < 0.05 * np.std(te))
    True
    """

    def __init__(self, speed: np.ndarray, fs: float, design: Design) -> None:
        speed = np.asarray(speed, dtype=float)
        size = speed.size
        lines, carriers = line_orders(design, fs, float(np.max(speed)))
        angle = integrated_angle(speed, fs)
        centred = (np.arange(size) - 0.5 * (size - 1)) / size
        phases = np.concatenate([lines, carriers])[None, :] * angle[:, None]
        constant = np.concatenate([np.cos(phases[:, : lines.size]), np.sin(phases[:, : lines.size])], axis=1)
        trend = centred[:, None] * np.concatenate(
            [np.cos(phases[:, lines.size :]), np.sin(phases[:, lines.size :])], axis=1
        )
        basis = np.concatenate([np.ones((size, 1)), centred[:, None], constant, trend], axis=1)
        # one thread: a decomposition of a few thousand rows by ~100 columns gains nothing from BLAS threads,
        # which spin on the cores another process works on
        with threadpool_limits(1):
            self._trend_rows = np.linalg.pinv(basis)[-trend.shape[1] :]
        self._trend = trend
        # the order tracking divides accelerations by (speed / mean speed)^2 (a response that follows the
        # angle): the drift is fitted on what it will see
        self._acceleration_scale = (speed / speed.mean()) ** 2
        self._time = np.arange(size) - 0.5 * (size - 1)

    def drift(self, record: np.ndarray) -> np.ndarray:
        """The linear-in-time change of the mesh harmonics in ``record`` (N,)."""
        return self._trend @ (self._trend_rows @ record)

    def clean(self, record: np.ndarray, channel: str) -> np.ndarray:
        """``record`` (N,) of ``channel`` less its carriers' drift (and, for the TE, its mean and trend)."""
        record = np.asarray(record, dtype=float)
        if not np.all(np.isfinite(record)):
            return record
        if channel != "te":
            scale = self._acceleration_scale
            return record - scale * self.drift(record / scale)
        values = record - self.drift(record)
        # encoders have no absolute zero: each steady record is stored without its mean; a segment also
        # without its straight-line trend, the quasi-static deflection changing with the speed it sweeps
        slope = values @ self._time / float(self._time @ self._time)
        return values - values.mean() - slope * self._time


__all__ = [
    "OP_SOURCE",
    "SEGMENT_ANGLE",
    "SEGMENT_GUARD",
    "SEGMENT_LEAD",
    "SEGMENT_TIME",
    "SOURCE_COORDINATES",
    "SegmentCleaner",
    "SegmentProfile",
    "line_orders",
    "segment_profiles",
]
