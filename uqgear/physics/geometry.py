"""Involute spur-gear geometry with profile shift.

Radii, working pressure angle and centre distance, the path of contact along
the line of action, contact ratio, and tooth thickness at any radius. Lengths
are in metres; the path-of-contact coordinate ``s`` is the distance along the
line of action from the pinion's base-circle tangency point T1.

Tip radii follow ``r_a = m (z/2 + h_a* + x)`` without tip shortening (the
reference design has x1 + x2 = 0, where none is needed). The root form radius
is where the straight flank of the generating rack (height ``h_a* m`` above
the rack's datum, the fillet lying in the clearance) stops generating the
involute.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from ..common.errors import DesignError


def involute(angle: float | np.ndarray) -> float | np.ndarray:
    """The involute function inv(a) = tan(a) - a."""
    return np.tan(angle) - angle


@dataclass(frozen=True)
class ToothGeometry:
    """Geometry of one gear of the pair (all lengths in m).

    Attributes
    ----------
    teeth, shift : int, float
        Number of teeth z and profile shift coefficient x.
    pitch_radius, base_radius, tip_radius, root_radius : float
        Reference, base, tip and root circle radii.
    form_radius : float
        Root form radius (start of the generated involute); ``nan`` if undercut.
    effective_root_radius : float
        r_ff: the larger of the base and root form radii (Ishikawa's transition
        from rectangle to trapezoid).
    half_angle_pitch : float
        Half the angular tooth thickness at the reference circle, rad.
    """

    teeth: int
    shift: float
    module: float
    pressure_angle: float
    pitch_radius: float
    base_radius: float
    tip_radius: float
    root_radius: float
    form_radius: float
    effective_root_radius: float
    half_angle_pitch: float

    def half_angle(self, radius: float | np.ndarray) -> float | np.ndarray:
        """Half the angular tooth thickness at ``radius`` (clamped to the base circle below it)."""
        radius = np.maximum(radius, self.base_radius)
        alpha_r = np.arccos(np.clip(self.base_radius / radius, -1.0, 1.0))
        return self.half_angle_pitch + involute(self.pressure_angle) - involute(alpha_r)

    def chordal_thickness(self, radius: float | np.ndarray) -> float | np.ndarray:
        """Chordal tooth thickness at ``radius`` (at the base circle below it), m."""
        return 2.0 * np.maximum(radius, self.base_radius) * np.sin(self.half_angle(radius))

    def arc_thickness(self, radius: float | np.ndarray) -> float | np.ndarray:
        """Arc tooth thickness at ``radius`` (at the base circle below it), m."""
        return 2.0 * np.maximum(radius, self.base_radius) * self.half_angle(radius)

    def load_angle(self, radius: float | np.ndarray) -> float | np.ndarray:
        """Load angle w_x at a contact radius: between the line of action and
        the normal to the tooth centre line, rad."""
        alpha_r = np.arccos(np.clip(self.base_radius / radius, -1.0, 1.0))
        return alpha_r - self.half_angle(radius)


@dataclass(frozen=True)
class PairGeometry:
    """Geometry of the meshing pair.

    Attributes
    ----------
    pinion, gear : ToothGeometry
    working_pressure_angle : float
        alpha_w, rad.
    centre_distance : float
        Working centre distance a_w, m.
    base_pitch : float
        p_b = pi m cos(alpha), m.
    line_of_action_length : float
        Distance T1-T2 between the base-circle tangency points, m.
    contact_start, contact_end, pitch_point : float
        Path coordinates s of the start of contact A (gear tip), end of contact
        E (pinion tip) and pitch point C, measured from T1, m.
    contact_ratio : float
        Transverse contact ratio eps = (s_E - s_A) / p_b.
    """

    pinion: ToothGeometry
    gear: ToothGeometry
    working_pressure_angle: float
    centre_distance: float
    base_pitch: float
    line_of_action_length: float
    contact_start: float
    contact_end: float
    pitch_point: float
    contact_ratio: float

    def contact_radii(self, s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pinion and gear contact radii at path coordinate(s) ``s``."""
        s = np.asarray(s, dtype=float)
        r1 = np.sqrt(self.pinion.base_radius ** 2 + s ** 2)
        r2 = np.sqrt(self.gear.base_radius ** 2 + (self.line_of_action_length - s) ** 2)
        return r1, r2

    @property
    def double_contact_fraction(self) -> float:
        """Fraction of a mesh period with two pairs in contact (eps - floor(eps))."""
        return self.contact_ratio - math.floor(self.contact_ratio)


def _tooth(teeth: int, shift: float, module: float, alpha: float,
           addendum: float, dedendum: float) -> ToothGeometry:
    pitch_radius = 0.5 * module * teeth
    base_radius = pitch_radius * math.cos(alpha)
    tip_radius = module * (0.5 * teeth + addendum + shift)
    root_radius = module * (0.5 * teeth - dedendum + shift)
    # Generating-rack limit point: its straight flank ends h_a* m - x m below the
    # pitch line; beyond the base-circle tangency this is where the involute starts.
    limit = pitch_radius * math.sin(alpha) - (addendum - shift) * module / math.sin(alpha)
    form_radius = math.hypot(base_radius, limit) if limit >= 0.0 else float("nan")
    effective = max(base_radius, form_radius) if limit >= 0.0 else base_radius
    half_angle_pitch = (0.5 * math.pi + 2.0 * shift * math.tan(alpha)) / teeth
    return ToothGeometry(teeth=teeth, shift=shift, module=module, pressure_angle=alpha,
                         pitch_radius=pitch_radius, base_radius=base_radius,
                         tip_radius=tip_radius, root_radius=root_radius,
                         form_radius=form_radius, effective_root_radius=effective,
                         half_angle_pitch=half_angle_pitch)


def pair_geometry(design) -> PairGeometry:
    """Compute the involute geometry of a design's gear pair (no validation).

    Parameters
    ----------
    design : Design

    Returns
    -------
    PairGeometry
    """
    alpha = math.radians(design.pressure_angle)
    pinion = _tooth(design.z1, design.x1, design.module, alpha,
                    design.addendum_coefficient, design.dedendum_coefficient)
    gear = _tooth(design.z2, design.x2, design.module, alpha,
                  design.addendum_coefficient, design.dedendum_coefficient)
    target = involute(alpha) + 2.0 * math.tan(alpha) * (design.x1 + design.x2) / (design.z1 + design.z2)
    if abs(design.x1 + design.x2) < 1e-12:
        alpha_w = alpha
    else:
        alpha_w = brentq(lambda a: involute(a) - target, 1e-3, 1.5)
    centre_distance = (pinion.pitch_radius + gear.pitch_radius) * math.cos(alpha) / math.cos(alpha_w)
    loa = centre_distance * math.sin(alpha_w)
    s_end = math.sqrt(max(pinion.tip_radius ** 2 - pinion.base_radius ** 2, 0.0))
    s_start = loa - math.sqrt(max(gear.tip_radius ** 2 - gear.base_radius ** 2, 0.0))
    base_pitch = math.pi * design.module * math.cos(alpha)
    return PairGeometry(pinion=pinion, gear=gear, working_pressure_angle=alpha_w,
                        centre_distance=centre_distance, base_pitch=base_pitch,
                        line_of_action_length=loa, contact_start=s_start, contact_end=s_end,
                        pitch_point=pinion.base_radius * math.tan(alpha_w),
                        contact_ratio=(s_end - s_start) / base_pitch)


def check_geometry(design, where: str = "") -> PairGeometry:
    """Compute the geometry and reject pairs that cannot work.

    Raises
    ------
    DesignError
        Undercut teeth (too few teeth for the profile shift), pointed tips,
        involute interference, or a contact ratio below 1.
    """
    geometry = pair_geometry(design)
    for label, tooth, shift_key in (("pinion", geometry.pinion, "x1"), ("gear", geometry.gear, "x2")):
        teeth_key = "z1" if label == "pinion" else "z2"
        if math.isnan(tooth.form_radius):
            alpha = math.radians(design.pressure_angle)
            x_min = design.addendum_coefficient - 0.5 * tooth.teeth * math.sin(alpha) ** 2
            raise DesignError(f"{where}{shift_key}: the {label} ({teeth_key}={tooth.teeth}) is undercut; "
                              f"expected a profile shift of at least {x_min:.3f}; got {tooth.shift:g}")
        tip_half = float(tooth.half_angle(tooth.tip_radius))
        if tip_half <= 0.0:
            raise DesignError(f"{where}{shift_key}: the {label} teeth are pointed at the tip; "
                              f"expected a smaller profile shift or addendum; got {tooth.shift:g}")
        if tooth.root_radius <= 0.0:
            raise DesignError(f"{where}{teeth_key}: the {label} root radius is not positive; "
                              f"expected more teeth or a smaller dedendum")
    if geometry.contact_start < 0.0:
        raise DesignError(f"{where}z1: contact starts below the pinion base circle (interference); "
                          f"expected more pinion teeth or a larger x1")
    r1_start, _ = geometry.contact_radii(geometry.contact_start)
    if r1_start < geometry.pinion.form_radius - 1e-9:
        raise DesignError(f"{where}x1: the gear tip reaches below the pinion's root form circle "
                          f"(involute interference); expected a larger x1 or a smaller x2")
    _, r2_end = geometry.contact_radii(geometry.contact_end)
    if r2_end < geometry.gear.form_radius - 1e-9:
        raise DesignError(f"{where}x2: the pinion tip reaches below the gear's root form circle "
                          f"(involute interference); expected a larger x2 or a smaller x1")
    if geometry.contact_ratio < 1.0:
        raise DesignError(f"{where}addendum_coefficient: contact ratio {geometry.contact_ratio:.3f} is "
                          f"below 1; expected >= 1 (larger addendum or pressure angle change)")
    return geometry


__all__ = ["involute", "ToothGeometry", "PairGeometry", "pair_geometry", "check_geometry"]
