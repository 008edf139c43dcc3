"""Rack generation of a spur tooth: the undercut flank, and whether a mating tip clears it.

docs/model/geometry.md section 3. A tooth is cut by its basic rack rolling on the
reference circle r (the rack's datum lies ``x m`` outside it). The rack's
straight flank ends ``h_a* m`` below the datum, that is ``u = (h_a* - x) m``
inside the rolling line, in a corner; its tip fillet lies in the clearance
below that and only shapes the root below ``r_c = r - u``, so it is not
modelled. With ``l = r sin(alpha) - u / sin(alpha)`` (the distance of the
corner's point on the line of action from the base-circle tangency point),
``l >= 0`` leaves the whole involute above ``sqrt(r_b^2 + l^2)``; ``l < 0``
means the corner passes beyond the tangency point and its path relative to the
tooth (a trochoid) cuts into the involute near the base circle: the undercut.
The involute then starts where the trochoid crosses it (the form radius r_Ff),
and below that the flank is the trochoid, narrower than the involute would be.

Angles here are half angular tooth thicknesses: a point at polar angle beta
from the tooth's centre line lies in the tooth if ``|beta| < B(rho)``.
Functions take plain numbers so that :mod:`.geometry` can call them while it
builds a :class:`~uqgear.physics.geometry.ToothGeometry`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.optimize import brentq, minimize_scalar


def _involute(angle: float | np.ndarray) -> float | np.ndarray:
    return np.tan(angle) - angle


@dataclass(frozen=True)
class RackCorner:
    """The corner of the generating rack that ends its straight flank, seen from the tooth.

    Attributes
    ----------
    pitch_radius, base_radius : float
        r and r_b of the tooth being cut, m.
    pressure_angle : float
        alpha, rad.
    depth : float
        u = (h_a* - x) m: depth of the corner inside the rolling line, m.
    half_angle_pitch : float
        Half the angular tooth thickness at r, rad (docs/model/geometry.md section 3).
    """

    pitch_radius: float
    base_radius: float
    pressure_angle: float
    depth: float
    half_angle_pitch: float

    @property
    def lowest_radius(self) -> float:
        """r_c = r - u: the radius the corner reaches at its deepest, m."""
        return self.pitch_radius - self.depth

    @property
    def offset(self) -> float:
        """Distance of the corner from the tooth's centre line along the rack, ``r psi + u tan(alpha)``, m."""
        return self.pitch_radius * self.half_angle_pitch + self.depth * math.tan(self.pressure_angle)

    @property
    def limit(self) -> float:
        """l = r sin(alpha) - u / sin(alpha); negative when the tooth is undercut, m."""
        return self.pitch_radius * math.sin(self.pressure_angle) - self.depth / math.sin(self.pressure_angle)

    def involute_half_angle(self, radius: float | np.ndarray) -> float | np.ndarray:
        """Half angle of the involute flank at ``radius`` (>= r_b), rad."""
        ratio = np.clip(self.base_radius / np.asarray(radius, dtype=float), -1.0, 1.0)
        return self.half_angle_pitch + _involute(self.pressure_angle) - _involute(np.arccos(ratio))

    def trochoid_half_angle(self, radius: float | np.ndarray) -> float | np.ndarray:
        """Half angle of the corner's trochoid at ``radius`` (>= r_c), rad.

        The corner passes each radius twice, approaching its deepest point
        and leaving it; the smaller angle (the one nearer the tooth's centre
        line) is the one that bounds the tooth.
        """
        r_c = self.lowest_radius
        # t: the corner's position along the rolling line, measured from its deepest point
        t = np.sqrt(np.maximum(np.asarray(radius, dtype=float) ** 2 - r_c**2, 0.0))
        approach = -np.arctan2(t, r_c) + (t + self.offset) / self.pitch_radius
        leave = np.arctan2(t, r_c) - (t - self.offset) / self.pitch_radius
        return np.minimum(approach, leave)

    def tooth_half_angle(self, radius: float | np.ndarray) -> np.ndarray:
        """Half angle B(rho) of the generated tooth: involute, trochoid below r_Ff, the corner's
        angle at its deepest below r_c (the unmodelled tip fillet taken as straight below it), rad."""
        rho = np.asarray(radius, dtype=float)
        corner = np.where(
            rho >= self.lowest_radius,
            self.trochoid_half_angle(np.maximum(rho, self.lowest_radius)),
            self.offset / self.pitch_radius,
        )
        involute = np.where(
            rho >= self.base_radius, self.involute_half_angle(np.maximum(rho, self.base_radius)), np.inf
        )
        return np.minimum(corner, involute)


@dataclass(frozen=True)
class Undercut:
    """Where an undercut tooth's involute starts and how thin its undercut root is.

    Attributes
    ----------
    form_radius : float
        r_Ff: where the corner's trochoid crosses the involute, m; the
        involute flank runs from here to the tip. ``nan`` when the trochoid
        does not leave the involute below the tip circle (no involute left).
    neck_thickness : float
        Chordal thickness of the narrowest section of the undercut flank
        between the base circle and r_Ff, m.
    """

    form_radius: float
    neck_thickness: float


@lru_cache(maxsize=512)
def undercut(corner: RackCorner, tip_radius: float) -> Undercut | None:
    """The undercut of a tooth generated by ``corner`` (None when ``l >= 0``: not undercut).

    The crossing is solved in the roll length ``s = sqrt(rho^2 - r_b^2)``,
    which is well scaled even for a marginal undercut (there r_Ff exceeds
    r_b by well under a micrometre, while s_Ff is about ``-l/2``). Results are
    cached: the geometry of a design is computed again for every model built
    from it, and fits change only its non-geometric keys.

    Parameters
    ----------
    corner : RackCorner
    tip_radius : float
        r_a of the tooth, m: the crossing is searched below it.
    """
    if corner.limit >= 0.0:
        return None
    r_b = corner.base_radius

    def gaps(roll: float | np.ndarray) -> np.ndarray:
        radius = np.sqrt(r_b * r_b + np.asarray(roll, dtype=float) ** 2)
        return np.asarray(corner.trochoid_half_angle(radius) - corner.involute_half_angle(radius))

    def gap(roll: float) -> float:
        return float(gaps(roll))

    top = math.sqrt(max(tip_radius**2 - r_b**2, 0.0))
    if top <= 0.0 or gap(top) < 0.0:
        return Undercut(form_radius=float("nan"), neck_thickness=float("nan"))
    # first sign change on a geometric grid starting well below |l|, where the crossing is
    rolls = np.geomspace(min(1e-3 * -corner.limit, 1e-3 * top), top, 400)
    values = gaps(rolls)
    if values[0] >= 0.0:
        roll_form = float(rolls[0])  # crossing closer to the base circle than 1e-3 |l|: take that bound
    else:
        index = int(np.argmax(values >= 0.0))
        roll_form = brentq(gap, float(rolls[index - 1]), float(rolls[index]), xtol=1e-15, rtol=1e-14)
    form_radius = math.sqrt(r_b * r_b + roll_form * roll_form)
    return Undercut(form_radius=form_radius, neck_thickness=_neck(corner, form_radius))


def _neck(corner: RackCorner, form_radius: float) -> float:
    """Least chordal thickness of the undercut flank between the base and form circles, m.

    Below the base circle Ishikawa's tooth keeps the base-circle thickness
    whether or not the tooth is undercut (the convention of
    :meth:`~uqgear.physics.geometry.ToothGeometry.chordal_thickness`); the
    pocket the corner cuts above it is what the undercut takes away. So the
    neck tends to the base-circle thickness as the undercut vanishes, and the
    stiffness is continuous at the least shift.
    """

    def chord(radius: float) -> float:
        return float(2.0 * radius * np.sin(corner.tooth_half_angle(radius)))

    low = corner.base_radius
    radii = np.linspace(low, form_radius, 257)
    chords = 2.0 * radii * np.sin(corner.tooth_half_angle(radii))
    best = int(np.argmin(chords))
    lower, upper = float(radii[max(best - 1, 0)]), float(radii[min(best + 1, len(radii) - 1)])
    if upper > lower:
        refined = minimize_scalar(chord, bounds=(lower, upper), method="bounded", options={"xatol": 1e-12})
        return min(float(chords[best]), float(refined.fun))
    return float(chords[best])


@lru_cache(maxsize=256)
def tip_penetration(
    corner: RackCorner,
    teeth: int,
    root_radius: float,
    tip_radius: float,
    *,
    mate_teeth: int,
    mate_tip_radius: float,
    mate_tip_half_angle: float,
    centre_distance: float,
    n_angles: int = 4001,
    n_tip_points: int = 9,
) -> float:
    """How deep the mating gear's tip land cuts into the generated tooth while the pair meshes, m.

    The pair is placed with zero backlash (the working pressure angle makes
    it so): at rotation 0 a tooth of the gear under test points at the mating
    centre and sits centred in a tooth space of the mate. Both turn about
    their centres with their working pitch circles rolling; the mate's tip
    land (``n_tip_points`` points from corner to corner, on the teeth within
    three pitches of the mesh) is followed through ``n_angles`` positions over
    +-2.5 pitches of the gear under test, and each point that lies inside its
    tip circle is compared with the tooth profile B(rho) of
    :meth:`RackCorner.tooth_half_angle` (inside the root circle counts as
    inside the tooth).

    Returns
    -------
    float
        The largest penetration as an arc length at its radius, m (<= 0:
        the tip stays clear; a tip sliding along the involute gives about 0).

    Results are cached (a design is validated again whenever a fit changes
    one of its non-geometric keys).
    """
    pitch = 2.0 * math.pi / teeth
    theta = np.linspace(-2.5 * pitch, 2.5 * pitch, n_angles)[:, None]
    centres = (2 * np.arange(-3, 3) + 1) * math.pi / mate_teeth
    spread = mate_tip_half_angle * np.linspace(-1.0, 1.0, n_tip_points)
    gamma = (centres[:, None] + spread[None, :]).ravel()[None, :]
    # fixed frame: gear under test at the origin turning by +theta (counter-clockwise), the mate at
    # (0, a_w) turning the other way by theta z / z_mate (the working pitch circles roll, whatever
    # their radii); gamma is measured on the mate from its direction to the origin. Then rotate back
    # into the frame of the gear under test.
    mate_angle = gamma - theta * teeth / mate_teeth
    fixed = 1j * centre_distance - 1j * mate_tip_radius * np.exp(1j * mate_angle)
    local = fixed * np.exp(-1j * theta)
    radius = np.abs(local)
    beta = np.arctan2(local.real, local.imag)
    beta = np.abs((beta + 0.5 * pitch) % pitch - 0.5 * pitch)  # from the nearest tooth's centre line
    inside = radius <= tip_radius
    if not np.any(inside):
        return -math.inf
    rho, angle = radius[inside], beta[inside]
    bound = np.where(rho < root_radius, 0.5 * pitch, corner.tooth_half_angle(rho))
    return float(np.max(rho * (bound - angle)))


__all__ = ["RackCorner", "Undercut", "undercut", "tip_penetration"]
