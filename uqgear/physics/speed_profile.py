"""A prescribed pinion speed against time: the input of a run-up or coast-down simulation.

The profile is held as a piecewise polynomial of the speed in time
(:class:`scipy.interpolate.PPoly`), so its angular acceleration and the pinion
angle (the integral of the speed) are exact polynomials too: a linear ramp's
angle is the closed-form quadratic, a sampled profile's the antiderivative of
its interpolant.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline, PchipInterpolator, PPoly

from ..common.errors import OperatingPointError

if TYPE_CHECKING:
    from .design import Design

#: rad/s per rpm.
RPM = 2.0 * math.pi / 60.0
#: Interpolations of a sampled profile.
INTERPOLATIONS = ("pchip", "linear")


class SpeedProfileError(OperatingPointError):
    """A speed profile is not a positive, finite, monotone run-up or coast-down.

    Examples
    --------
    >>> import uqgear
    >>> try:
    ...     uqgear.SpeedProfile.samples([0.0, 1.0, 2.0], [1500.0, 2500.0, 2000.0])
    ... except uqgear.SpeedProfileError as error:
    ...     print(error)
    speed profile: expected a monotone run-up or coast-down; the speed reverses at t = 1 s (2500 rpm)
    """


def _finite_array(name: str, values: object) -> np.ndarray:
    try:
        array = np.asarray(values, dtype=float).ravel()
    except (TypeError, ValueError):
        raise SpeedProfileError(f"{name}: expected numbers; got {values!r}") from None
    if not np.all(np.isfinite(array)):
        raise SpeedProfileError(f"{name}: expected finite values; got non-finite entries")
    return array


@dataclass(frozen=True)
class SpeedProfile:
    """Pinion speed (rpm) against time (s) on [0, ``duration``], a piecewise polynomial.

    Build one with :meth:`linear`, :meth:`constant`, :meth:`samples` or
    :meth:`from_function`. Every speed is finite and > 0, and the speed never
    reverses its trend: a profile is a run-up, a coast-down or constant.

    Attributes
    ----------
    knots : ndarray
        Breakpoints in time, s (from 0 to the duration).
    coefficients : ndarray
        Polynomial coefficients of the speed on each piece, rpm s^-j
        (:class:`scipy.interpolate.PPoly` layout: highest power first).
    kind : str
        How it was built ("linear", "constant", "pchip", "samples-linear", "function").

    Examples
    --------
    A ramp 1500 -> 2500 rpm in 0.5 s: the angle is the closed-form integral,
    (1500 t + 1000 t^2) rpm s turned into radians:

    >>> import uqgear
    >>> ramp = uqgear.SpeedProfile.linear(1500.0, 2500.0, 0.5)
    >>> ramp.direction, float(ramp.speed(0.25)), round(float(ramp.acceleration(0.1)), 3)
    ('up', 2000.0, 209.44)
    >>> round(float(ramp.angle(0.5)), 6), round((1500 * 0.5 + 1000 * 0.25) * 2 * 3.141592653589793 / 60, 6)
    (104.719755, 104.719755)
    """

    knots: np.ndarray
    coefficients: np.ndarray
    kind: str

    def __post_init__(self) -> None:
        check_profile(self)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def linear(
        cls,
        start_rpm: float,
        stop_rpm: float | None = None,
        duration_s: float | None = None,
        *,
        rate_rpm_per_s: float | None = None,
    ) -> SpeedProfile:
        """A linear ramp from ``start_rpm`` to ``stop_rpm`` over ``duration_s``, or at ``rate_rpm_per_s``.

        Give two of ``stop_rpm``, ``duration_s`` and ``rate_rpm_per_s``.

        Examples
        --------
        >>> import uqgear
        >>> uqgear.SpeedProfile.linear(2500.0, 1500.0, rate_rpm_per_s=-2000.0).duration
        0.5
        """
        start = float(start_rpm)
        given = sum(value is not None for value in (stop_rpm, duration_s, rate_rpm_per_s))
        if given != 2:
            raise SpeedProfileError(
                "SpeedProfile.linear: expected two of stop_rpm, duration_s, rate_rpm_per_s; "
                f"got stop_rpm={stop_rpm!r}, duration_s={duration_s!r}, rate_rpm_per_s={rate_rpm_per_s!r}"
            )
        if duration_s is None:
            assert stop_rpm is not None and rate_rpm_per_s is not None
            if rate_rpm_per_s == 0.0 or (float(stop_rpm) - start) / rate_rpm_per_s <= 0.0:
                raise SpeedProfileError(
                    f"rate_rpm_per_s: expected a rate that takes {start:g} rpm to {stop_rpm:g} rpm; "
                    f"got {rate_rpm_per_s!r}"
                )
            duration_s = (float(stop_rpm) - start) / float(rate_rpm_per_s)
        duration = _duration(duration_s)
        if stop_rpm is None:
            assert rate_rpm_per_s is not None
            stop_rpm = start + float(rate_rpm_per_s) * duration
        stop = float(stop_rpm)
        coefficients = np.array([[(stop - start) / duration], [start]])
        return cls(np.array([0.0, duration]), coefficients, "linear")

    @classmethod
    def constant(cls, rpm: float, duration_s: float) -> SpeedProfile:
        """A constant speed ``rpm`` for ``duration_s`` seconds.

        Examples
        --------
        >>> import uqgear
        >>> round(float(uqgear.SpeedProfile.constant(2000.0, 0.1).angle(0.1)), 9)  # 2000 rpm for 0.1 s, rad
        20.943951024
        """
        duration = _duration(duration_s)
        return cls(np.array([0.0, duration]), np.array([[float(rpm)]]), "constant")

    @classmethod
    def samples(cls, times_s: object, speeds_rpm: object, interpolation: str = "pchip") -> SpeedProfile:
        """Speeds at strictly increasing times, interpolated ("pchip": shape-preserving cubic, or "linear").

        The first time is the profile's t = 0 (times are shifted to start there).

        Examples
        --------
        >>> import uqgear
        >>> profile = uqgear.SpeedProfile.samples([1.0, 2.0, 3.0], [1000.0, 1500.0, 3000.0])
        >>> profile.duration, float(profile.speed(1.0)), profile.direction
        (2.0, 1500.0, 'up')
        """
        times = _finite_array("times_s", times_s)
        speeds = _finite_array("speeds_rpm", speeds_rpm)
        if times.size != speeds.size or times.size < 2:
            raise SpeedProfileError(
                f"times_s, speeds_rpm: expected equal lengths of at least 2; got {times.size} and {speeds.size}"
            )
        steps = np.diff(times)
        if np.any(steps <= 0.0):
            bad = int(np.argmax(steps <= 0.0))
            raise SpeedProfileError(
                f"times_s: expected strictly increasing times; got {times[bad]:g} s followed by {times[bad + 1]:g} s"
            )
        _check_speeds(speeds, times)
        times = times - times[0]
        if interpolation == "pchip":
            poly: PPoly = PchipInterpolator(times, speeds)
        elif interpolation == "linear":
            poly = PPoly(np.vstack([np.diff(speeds) / np.diff(times), speeds[:-1]]), times)
        else:
            raise SpeedProfileError(
                f"interpolation: expected one of {', '.join(INTERPOLATIONS)}; got {interpolation!r}"
            )
        kind = "pchip" if interpolation == "pchip" else "samples-linear"
        return cls(np.asarray(poly.x, dtype=float), np.asarray(poly.c, dtype=float), kind)

    @classmethod
    def from_function(
        cls, function: Callable[[np.ndarray], np.ndarray], duration_s: float, resolution_s: float = 1e-3
    ) -> SpeedProfile:
        """A callable speed(t) in rpm on [0, ``duration_s``], held as the cubic spline through its values
        every ``resolution_s`` seconds (the angle is that spline's exact integral).

        Examples
        --------
        >>> import numpy as np, uqgear
        >>> profile = uqgear.SpeedProfile.from_function(lambda t: 1500.0 + 4000.0 * t**2, 0.5)
        >>> round(float(profile.speed(0.3)), 6)
        1860.0
        """
        duration = _duration(duration_s)
        count = max(int(math.ceil(duration / float(resolution_s))), 3) + 1
        times = np.linspace(0.0, duration, count)
        speeds = _finite_array("function", function(times))
        if speeds.size != times.size:
            raise SpeedProfileError(f"function: expected one speed per time ({times.size}); got {speeds.size}")
        _check_speeds(speeds, times)
        poly = CubicSpline(times, speeds)
        return cls(np.asarray(poly.x, dtype=float), np.asarray(poly.c, dtype=float), "function")

    # ------------------------------------------------------------------ evaluation
    @functools.cached_property
    def _poly(self) -> PPoly:
        return PPoly(self.coefficients, self.knots, extrapolate=False)

    @functools.cached_property
    def _angle_poly(self) -> PPoly:
        return self._poly.antiderivative()

    @property
    def duration(self) -> float:
        """Length of the profile, s."""
        return float(self.knots[-1] - self.knots[0])

    @property
    def start_speed(self) -> float:
        """Speed at t = 0, rpm."""
        return float(self.speed(0.0))

    @property
    def stop_speed(self) -> float:
        """Speed at the end, rpm."""
        return float(self.speed(self.duration))

    @property
    def direction(self) -> str:
        """The profile's trend: "up" (run-up), "down" (coast-down) or "constant"."""
        start, stop = self.start_speed, self.stop_speed
        return "up" if stop > start else ("down" if stop < start else "constant")

    def speed_range(self) -> tuple[float, float]:
        """(lowest, highest) speed in rpm (at the ends: the profile is monotone)."""
        return min(self.start_speed, self.stop_speed), max(self.start_speed, self.stop_speed)

    def _times(self, t: object) -> np.ndarray:
        times = np.asarray(t, dtype=float)
        slack = 1e-9 * max(self.duration, 1.0)
        if np.any(~np.isfinite(times)) or np.any(times < -slack) or np.any(times > self.duration + slack):
            raise SpeedProfileError(f"t: expected times in [0, {self.duration:g}] s (the profile's span)")
        return np.clip(times, 0.0, self.duration)

    def speed(self, t: object) -> np.ndarray:
        """Pinion speed n1(t), rpm."""
        return self._poly(self._times(t))

    def acceleration(self, t: object) -> np.ndarray:
        """Pinion angular acceleration d(omega1)/dt, rad s-2."""
        return self._poly(self._times(t), 1) * RPM

    def angular_speed(self, t: object) -> np.ndarray:
        """Pinion angular speed omega1(t), rad s-1."""
        return self.speed(t) * RPM

    def angle(self, t: object) -> np.ndarray:
        """Pinion angle theta1(t) = integral of omega1 from 0 to t, rad (exact for the piecewise polynomial)."""
        return self._angle_poly(self._times(t)) * RPM

    def time_at_angle(self, angle: object) -> np.ndarray:
        """The time t at which the pinion has turned ``angle`` rad (the inverse of :meth:`angle`, by Newton
        steps from an interpolated start; the angle grows strictly since the speed is > 0)."""
        target = np.asarray(angle, dtype=float)
        grid = np.linspace(0.0, self.duration, 4097)
        t = np.interp(target, self.angle(grid), grid)
        for _ in range(50):
            correction = (self.angle(t) - target) / self.angular_speed(t)
            t = np.clip(t - correction, 0.0, self.duration)
            if np.all(np.abs(correction) <= 1e-15 * max(self.duration, 1.0)):
                break
        return t


def _duration(duration_s: object) -> float:
    try:
        duration = float(duration_s)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise SpeedProfileError(f"duration_s: expected a number of seconds; got {duration_s!r}") from None
    if not math.isfinite(duration) or duration <= 0.0:
        raise SpeedProfileError(f"duration_s: expected a finite duration > 0 s; got {duration_s!r}")
    return duration


def _check_speeds(speeds: np.ndarray, times: np.ndarray) -> None:
    if np.any(speeds <= 0.0):
        bad = int(np.argmax(speeds <= 0.0))
        raise SpeedProfileError(
            f"speeds_rpm: expected speeds > 0 rpm (no standstill or reversal); got {speeds[bad]:g} rpm at t = "
            f"{times[bad]:g} s"
        )
    # changes below round-off of the largest speed count as flat
    change = np.diff(speeds)
    signs = np.where(np.abs(change) > 1e-12 * np.max(speeds), np.sign(change), 0.0)
    steps = signs[signs != 0.0]
    if steps.size and np.any(steps != steps[0]):
        turn = int(np.argmax(signs == -steps[0]))
        raise SpeedProfileError(
            "speed profile: expected a monotone run-up or coast-down; the speed reverses at "
            f"t = {times[turn]:g} s ({speeds[turn]:g} rpm)"
        )


def check_profile(profile: SpeedProfile) -> None:
    """Refuse a profile whose speed is not finite and > 0 everywhere, or whose trend reverses.

    The speed is checked at the knots and on a fine grid inside each piece
    (a cubic piece can overshoot between its knots).
    """
    knots = _finite_array("knots", profile.knots)
    coefficients = np.asarray(profile.coefficients, dtype=float)
    if knots.size < 2 or np.any(np.diff(knots) <= 0.0) or knots[0] != 0.0:
        raise SpeedProfileError("knots: expected strictly increasing times from 0 s")
    if coefficients.ndim != 2 or coefficients.shape[1] != knots.size - 1 or not np.all(np.isfinite(coefficients)):
        raise SpeedProfileError(f"coefficients: expected finite values of shape (degree + 1, {knots.size - 1})")
    poly = PPoly(coefficients, knots, extrapolate=False)
    fine = np.unique(np.concatenate([np.linspace(a, b, 33) for a, b in zip(knots[:-1], knots[1:])]))
    _check_speeds(poly(fine), fine)


def torque_driven_profile(
    design: Design,
    speeds_rpm: object,
    torques_nm: object,
    start_rpm: float,
    duration_s: float,
    *,
    wheel_torque: float = 0.0,
    mass: float | None = None,
    resolution_s: float = 1e-3,
) -> SpeedProfile:
    """The pinion speed that a drive torque-speed curve gives the train: J omega1' = T1(n1) - T_w / i.

    The curve T1(n1) is the PCHIP through (``speeds_rpm``, ``torques_nm``); the
    reflected inertia on the pinion is J = I1 + (I2 + m R_w^2) / i^2 (i = z2 / z1,
    R_w the wheel radius, m the train mass per driven axle, the design's
    ``axle_load`` by default); ``wheel_torque`` (N m at the wheel) resists. The
    speed is integrated (DOP853) and held as the PCHIP of its values every
    ``resolution_s`` seconds. The speed must stay within the curve and not reverse.

    Examples
    --------
    A flat 7000 N m curve accelerates at the constant rate T1 / J:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> profile = uqgear.torque_driven_profile(design, [0.0, 6000.0], [7000.0, 7000.0], 1500.0, 2.0)
    >>> ratio = design.z2 / design.z1
    >>> inertia = design.I1 + (design.I2 + 23000.0 * 0.625**2) / ratio**2
    >>> rate = 7000.0 / inertia * 60 / (2 * 3.141592653589793)            # rpm per second
    >>> round(float(profile.stop_speed), 3) == round(1500.0 + 2.0 * rate, 3), profile.direction
    (True, 'up')
    """
    speeds = _finite_array("speeds_rpm", speeds_rpm)
    torques = _finite_array("torques_nm", torques_nm)
    if speeds.size != torques.size or speeds.size < 2 or np.any(np.diff(speeds) <= 0.0):
        raise SpeedProfileError("speeds_rpm, torques_nm: expected equal lengths of at least 2, speeds increasing")
    start = float(start_rpm)
    if not speeds[0] <= start <= speeds[-1]:
        raise SpeedProfileError(
            f"start_rpm: expected a speed in the curve's [{speeds[0]:g}, {speeds[-1]:g}] rpm; got {start!r}"
        )
    duration = _duration(duration_s)
    curve = PchipInterpolator(speeds, torques, extrapolate=False)
    ratio = design.z2 / design.z1
    carried = design.operation.axle_load if mass is None else float(mass)
    inertia = design.I1 + (design.I2 + carried * design.operation.wheel_radius**2) / ratio**2
    resisting = float(wheel_torque) / ratio

    def accelerate(t: float, w: np.ndarray) -> np.ndarray:
        return (curve(min(max(w[0] / RPM, speeds[0]), speeds[-1])) - resisting) / inertia * np.ones(1)

    def leaves(t: float, w: np.ndarray) -> float:
        return (w[0] / RPM - speeds[0]) * (speeds[-1] - w[0] / RPM)

    leaves.terminal = True  # type: ignore[attr-defined]
    count = max(int(math.ceil(duration / float(resolution_s))), 3) + 1
    grid = np.linspace(0.0, duration, count)
    solution = solve_ivp(
        accelerate,
        (0.0, duration),
        [start * RPM],
        method="DOP853",
        t_eval=grid,
        rtol=1e-10,
        atol=1e-9,
        events=leaves if speeds[0] < start < speeds[-1] else None,
    )
    if solution.status != 0:
        raise SpeedProfileError(
            f"torques_nm: the speed leaves the curve's [{speeds[0]:g}, {speeds[-1]:g}] rpm at t = {solution.t[-1]:g} s"
        )
    return SpeedProfile.samples(grid, solution.y[0] / RPM)


__all__ = ["SpeedProfile", "torque_driven_profile", "SpeedProfileError", "check_profile", "RPM", "INTERPOLATIONS"]
