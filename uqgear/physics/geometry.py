"""Involute spur-gear geometry with profile shift.

Radii, working pressure angle and centre distance, the path of contact along
the line of action, contact ratio, and tooth thickness at any radius. Lengths
are in metres; the path-of-contact coordinate ``s`` is the distance along the
line of action from the pinion's base-circle tangency point T1.

Tip radii follow ``r_a = m (z/2 + h_a* + x)`` without tip shortening (the
reference design has x1 + x2 = 0, where none is needed). The root form radius
is where the straight flank of the generating rack (height ``h_a* m`` above
the rack's datum, the fillet lying in the clearance) stops generating the
involute; on an undercut tooth it is where the rack corner's trochoid crosses
the involute (:mod:`.generation`), and the path of contact starts (ends) no
lower than the form circle of the pinion (gear).

:func:`check_geometry` refuses only pairs that cannot mesh and warns
(:class:`~uqgear.common.errors.UndercutWarning`) about undercut teeth, which
are modelled (docs/model/geometry.md section 3, "Undercut" and "Rejected designs").
"""

from __future__ import annotations

import functools
import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from ..common.errors import DesignError, UndercutWarning
from .design_parts import ToothPairDesign
from .generation import RackCorner, tip_penetration, undercut


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
        Root form radius r_Ff (start of the generated involute). On an
        undercut tooth, where the rack corner's trochoid crosses the involute
        (``nan`` if it crosses above the tip: no involute left).
    effective_root_radius : float
        r_ff: the larger of the base and root form radii (Ishikawa's transition
        from rectangle to trapezoid).
    half_angle_pitch : float
        Half the angular tooth thickness at the reference circle, rad.
    undercut : bool
        The generating rack's corner cut into the involute (``l < 0``).
    neck_thickness : float or None
        Undercut teeth: chordal thickness of the narrowest section of the
        undercut flank above the base circle, m (the Ishikawa rectangle's
        thickness); None otherwise.
    rack_corner : RackCorner or None
        The generating rack's corner as seen from this tooth (profile below
        the form circle, :mod:`.generation`).
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
    undercut: bool = False
    neck_thickness: float | None = None
    rack_corner: RackCorner | None = field(default=None, repr=False, compare=False)

    @property
    def form_roll(self) -> float:
        """Roll length ``sqrt(r_Ff^2 - r_b^2)`` of the form circle along the line of action, m."""
        return math.sqrt(max(self.form_radius**2 - self.base_radius**2, 0.0))

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
        Path coordinates s of the start of contact A (gear tip, or the
        pinion's form circle where an undercut pinion's involute starts
        higher), end of contact E (pinion tip, or an undercut gear's form
        circle) and pitch point C, measured from T1, m.
    contact_ratio : float
        Transverse contact ratio eps = (s_E - s_A) / p_b.
    tip_contact_start, tip_contact_end : float
        Where the tip circles cross the line of action (gear tip, pinion
        tip), m: the contact limits the standard formula uses; they differ
        from ``contact_start``/``contact_end`` only where an undercut tooth's
        form circle limits the contact.
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
    tip_contact_start: float = math.nan
    tip_contact_end: float = math.nan

    def contact_radii(self, s: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pinion and gear contact radii at path coordinate(s) ``s``."""
        s = np.asarray(s, dtype=float)
        r1 = np.sqrt(self.pinion.base_radius**2 + s**2)
        r2 = np.sqrt(self.gear.base_radius**2 + (self.line_of_action_length - s) ** 2)
        return r1, r2

    @property
    def double_contact_fraction(self) -> float:
        """Fraction of a mesh period with two pairs in contact (eps - floor(eps))."""
        return self.contact_ratio - math.floor(self.contact_ratio)


def _tooth(teeth: int, shift: float, module: float, alpha: float, addendum: float, dedendum: float) -> ToothGeometry:
    pitch_radius = 0.5 * module * teeth
    base_radius = pitch_radius * math.cos(alpha)
    tip_radius = module * (0.5 * teeth + addendum + shift)
    root_radius = module * (0.5 * teeth - dedendum + shift)
    half_angle_pitch = (0.5 * math.pi + 2.0 * shift * math.tan(alpha)) / teeth
    # Generating-rack limit point: its straight flank ends h_a* m - x m below the
    # pitch line; beyond the base-circle tangency this is where the involute starts.
    corner = RackCorner(
        pitch_radius=pitch_radius,
        base_radius=base_radius,
        pressure_angle=alpha,
        depth=(addendum - shift) * module,
        half_angle_pitch=half_angle_pitch,
    )
    limit = pitch_radius * math.sin(alpha) - (addendum - shift) * module / math.sin(alpha)
    neck: float | None = None
    if limit >= 0.0:
        form_radius = math.hypot(base_radius, limit)
        effective = max(base_radius, form_radius)
    else:
        # the corner passed beyond the tangency point and cut the involute's foot away
        cut = undercut(corner, tip_radius)
        assert cut is not None  # limit < 0 is the corner's limit < 0, where undercut finds the cut
        form_radius = cut.form_radius
        effective = form_radius if math.isfinite(form_radius) else base_radius
        neck = cut.neck_thickness
    return ToothGeometry(
        teeth=teeth,
        shift=shift,
        module=module,
        pressure_angle=alpha,
        pitch_radius=pitch_radius,
        base_radius=base_radius,
        tip_radius=tip_radius,
        root_radius=root_radius,
        form_radius=form_radius,
        effective_root_radius=effective,
        half_angle_pitch=half_angle_pitch,
        undercut=limit < 0.0,
        neck_thickness=neck,
        rack_corner=corner,
    )


#: Design keys the pair geometry depends on (the fields of :class:`~uqgear.physics.design_parts.ToothPairDesign`).
PAIR_GEOMETRY_KEYS = ToothPairDesign.keys()


def pair_geometry(design) -> PairGeometry:
    """Compute the involute geometry of a design's gear pair (no validation).

    Cached on the design's :class:`~uqgear.physics.design_parts.ToothPairDesign`,
    the fields the geometry reads and nothing else: a batch of ten thousand
    runs of one design computes it once, not twice a run; the result is
    frozen, so sharing it is safe.

    Parameters
    ----------
    design : Design or ToothPairDesign
        Any object with the tooth pair's fields.

    Returns
    -------
    PairGeometry
    """
    return _pair_geometry(ToothPairDesign.of(design))


@functools.lru_cache(maxsize=256)
def _pair_geometry(design: ToothPairDesign) -> PairGeometry:
    alpha = math.radians(design.pressure_angle)
    pinion = _tooth(
        design.z1, design.x1, design.module, alpha, design.addendum_coefficient, design.dedendum_coefficient
    )
    gear = _tooth(design.z2, design.x2, design.module, alpha, design.addendum_coefficient, design.dedendum_coefficient)
    target = involute(alpha) + 2.0 * math.tan(alpha) * (design.x1 + design.x2) / (design.z1 + design.z2)
    if abs(design.x1 + design.x2) < 1e-12:
        alpha_w = alpha
    else:
        alpha_w = brentq(lambda a: involute(a) - target, 1e-3, 1.5)
    centre_distance = (pinion.pitch_radius + gear.pitch_radius) * math.cos(alpha) / math.cos(alpha_w)
    loa = centre_distance * math.sin(alpha_w)
    tip_end = math.sqrt(max(pinion.tip_radius**2 - pinion.base_radius**2, 0.0))
    tip_start = loa - math.sqrt(max(gear.tip_radius**2 - gear.base_radius**2, 0.0))
    s_start, s_end = tip_start, tip_end
    # An undercut tooth has no flank below its form circle: a mating tip that reaches lower
    # passes through the undercut pocket, and contact begins (ends) where the involute does.
    # A tooth that is not undercut keeps the tip points (reaching below its form circle is
    # fillet interference, refused by check_geometry).
    if pinion.undercut and math.isfinite(pinion.form_radius):
        s_start = max(tip_start, pinion.form_roll)
    if gear.undercut and math.isfinite(gear.form_radius):
        s_end = min(tip_end, loa - gear.form_roll)
    base_pitch = math.pi * design.module * math.cos(alpha)
    return PairGeometry(
        pinion=pinion,
        gear=gear,
        working_pressure_angle=alpha_w,
        centre_distance=centre_distance,
        base_pitch=base_pitch,
        line_of_action_length=loa,
        contact_start=s_start,
        contact_end=s_end,
        pitch_point=pinion.base_radius * math.tan(alpha_w),
        contact_ratio=(s_end - s_start) / base_pitch,
        tip_contact_start=tip_start,
        tip_contact_end=tip_end,
    )


#: How far (a fraction of the module) a mating tip may reach into an undercut flank before the pair
#: is refused: far below tooth deflection under load and manufacturing tolerance, far above round-off.
TIP_PENETRATION_TOLERANCE = 1e-4


def least_shift(design, teeth: int) -> float:
    """Least profile shift coefficient that avoids undercut, ``h_a* - (z/2) sin^2(alpha)``.

    Parameters
    ----------
    design : Design
    teeth : int
        Number of teeth of the gear in question.
    """
    return design.addendum_coefficient - 0.5 * teeth * math.sin(math.radians(design.pressure_angle)) ** 2


def _sides(geometry: PairGeometry):
    """Per gear of the pair: label, tooth, mate, shift key, teeth key, and whether its form circle limits contact."""
    return (
        ("pinion", geometry.pinion, geometry.gear, "x1", "z1", geometry.contact_start > geometry.tip_contact_start),
        ("gear", geometry.gear, geometry.pinion, "x2", "z2", geometry.contact_end < geometry.tip_contact_end),
    )


def geometry_notes(design, geometry: PairGeometry | None = None) -> list[str]:
    """What the model does with a design's undercut teeth, one line per undercut tooth.

    The text of the :class:`~uqgear.common.errors.UndercutWarning` that
    :func:`check_geometry` emits, for reports and JSON summaries (empty for a
    design without undercut, such as the bundled one).

    Parameters
    ----------
    design : Design
    geometry : PairGeometry, optional
        Its geometry, if already computed.

    Returns
    -------
    list of str
    """
    geometry = geometry or pair_geometry(design)
    notes = []
    for label, tooth, _, shift_key, teeth_key, limits in _sides(geometry):
        if not tooth.undercut or not math.isfinite(tooth.form_radius):
            continue
        involute_chord = float(tooth.chordal_thickness(tooth.form_radius))
        tip_ratio = (geometry.tip_contact_end - geometry.tip_contact_start) / geometry.base_pitch
        contact = (
            f"contact ratio {geometry.contact_ratio:.3f}, limited by this form circle "
            f"(the tip circles alone give {tip_ratio:.3f})"
            if limits
            else f"contact ratio {geometry.contact_ratio:.3f} (the mating tip stays above the form circle)"
        )
        notes.append(
            f"{shift_key}: the {label} ({teeth_key}={tooth.teeth}, {shift_key}={tooth.shift:g}) is undercut "
            f"(none from {shift_key} = {least_shift(design, tooth.teeth):.3f}); "
            f"modelled from its form circle: the involute starts at r_Ff = {tooth.form_radius * 1e3:.4f} mm, "
            f"{(tooth.form_radius - tooth.base_radius) * 1e6:.3g} um above the base circle, the undercut "
            f"root section is {tooth.neck_thickness * 1e3:.3f} mm thick (the involute's at r_Ff "
            f"{involute_chord * 1e3:.3f} mm); {contact}"
        )
    return notes


def _refuse_tip_cut(geometry: PairGeometry, design, where: str, side) -> None:
    """Refuse a pair whose mating tip, reaching below an undercut tooth's form circle, cuts its flank."""
    label, tooth, mate, shift_key, teeth_key, _ = side
    depth = tip_penetration(
        tooth.rack_corner,
        tooth.teeth,
        tooth.root_radius,
        tooth.tip_radius,
        mate_teeth=mate.teeth,
        mate_tip_radius=mate.tip_radius,
        mate_tip_half_angle=float(mate.half_angle(mate.tip_radius)),
        centre_distance=geometry.centre_distance,
    )
    if depth > TIP_PENETRATION_TOLERANCE * design.module:
        other_key = "x2" if shift_key == "x1" else "x1"
        mate_label = "gear" if label == "pinion" else "pinion"
        raise DesignError(
            f"{where}{shift_key}: the {mate_label} tip would cut {depth * 1e6:.3g} um into the "
            f"{label}'s undercut flank below its form circle (interference); expected a larger "
            f"{shift_key} (no undercut from {least_shift(design, tooth.teeth):.3f}) or a smaller "
            f"{other_key}; got {tooth.shift:g}"
        )


def check_geometry(design, where: str = "") -> PairGeometry:
    """Compute the geometry, refuse pairs that cannot mesh, warn about undercut teeth.

    What is refused and why is docs/model/geometry.md section 3 ("Rejected designs").
    An undercut tooth is modelled from its form circle and reported with an
    :class:`~uqgear.common.errors.UndercutWarning` (text of
    :func:`geometry_notes`).

    Parameters
    ----------
    design : Design
    where : str
        Prefix for messages (a file name or key path).

    Returns
    -------
    PairGeometry

    Raises
    ------
    DesignError
        Naming the key to change: a tooth undercut up to its tip (no involute
        left), pointed tips, a root circle at or below the centre, no tip
        clearance, a mating tip below a form circle that is not undercut
        (fillet interference) or cutting into an undercut flank, or a contact
        ratio below 1.
    """
    geometry = pair_geometry(design)
    sides = _sides(geometry)
    for label, tooth, _, shift_key, teeth_key, _ in sides:
        if tooth.undercut and not math.isfinite(tooth.form_radius):
            raise DesignError(
                f"{where}{shift_key}: the {label} ({teeth_key}={tooth.teeth}) is undercut up to its "
                f"tip circle, no involute flank is left; expected a profile shift of at least "
                f"{least_shift(design, tooth.teeth):.3f}; got {tooth.shift:g}"
            )
        tip_half = float(tooth.half_angle(tooth.tip_radius))
        if tip_half <= 0.0:
            raise DesignError(
                f"{where}{shift_key}: the {label} teeth are pointed at the tip; "
                f"expected a smaller profile shift or addendum; got {tooth.shift:g}"
            )
        if tooth.root_radius <= 0.0:
            raise DesignError(
                f"{where}{teeth_key}: the {label} root radius is not positive; "
                f"expected more teeth or a smaller dedendum"
            )
    # Without tip shortening the two tip clearances are equal:
    # a_w - m (z1 + z2)/2 - m (x1 + x2) + m (h_f* - h_a*).
    clearance = geometry.centre_distance - geometry.gear.tip_radius - geometry.pinion.root_radius
    if clearance <= 0.0:
        needed = design.dedendum_coefficient - clearance / design.module
        raise DesignError(
            f"{where}dedendum_coefficient: no tip clearance ({clearance * 1e3:.3g} mm), the tips "
            f"would strike the mating roots (shift sum x1 + x2 = {design.x1 + design.x2:g}, no tip "
            f"shortening is modelled); expected more than {needed:.3f} or a smaller shift sum; "
            f"got {design.dedendum_coefficient:g}"
        )
    pinion_side, gear_side = sides
    if not geometry.pinion.undercut:
        if geometry.tip_contact_start < 0.0:
            raise DesignError(
                f"{where}z1: contact starts below the pinion base circle (interference); "
                f"expected more pinion teeth or a larger x1"
            )
        r1_start, _ = geometry.contact_radii(geometry.contact_start)
        if r1_start < geometry.pinion.form_radius - 1e-9:
            raise DesignError(
                f"{where}x1: the gear tip reaches below the pinion's root form circle "
                f"(involute interference); expected a larger x1 or a smaller x2"
            )
    elif geometry.tip_contact_start < geometry.pinion.form_roll:
        _refuse_tip_cut(geometry, design, where, pinion_side)
    if not geometry.gear.undercut:
        _, r2_end = geometry.contact_radii(geometry.contact_end)
        if r2_end < geometry.gear.form_radius - 1e-9:
            raise DesignError(
                f"{where}x2: the pinion tip reaches below the gear's root form circle "
                f"(involute interference); expected a larger x2 or a smaller x1"
            )
    elif geometry.tip_contact_end > geometry.line_of_action_length - geometry.gear.form_roll:
        _refuse_tip_cut(geometry, design, where, gear_side)
    if geometry.contact_ratio < 1.0:
        limiting = [side for side in sides if side[5]]
        if limiting:
            label, tooth, _, shift_key, _, _ = limiting[0]
            raise DesignError(
                f"{where}{shift_key}: contact ratio {geometry.contact_ratio:.3f} is below 1: the "
                f"undercut {label}'s involute starts too high (form radius "
                f"{tooth.form_radius * 1e3:.4g} mm); expected >= 1 (a larger {shift_key}, no undercut "
                f"from {least_shift(design, tooth.teeth):.3f}); got {tooth.shift:g}"
            )
        raise DesignError(
            f"{where}addendum_coefficient: contact ratio {geometry.contact_ratio:.3f} is "
            f"below 1; expected >= 1 (larger addendum or pressure angle change)"
        )
    for note in geometry_notes(design, geometry):
        # the text names the gear, its teeth and shift but not `where`: one design read from several
        # places in one command (a rig file, its copy in memory) warns once, not once per place
        warnings.warn(note, UndercutWarning, stacklevel=2)
    return geometry


__all__ = [
    "involute",
    "ToothGeometry",
    "PairGeometry",
    "pair_geometry",
    "check_geometry",
    "geometry_notes",
    "least_shift",
    "TIP_PENETRATION_TOLERANCE",
]
