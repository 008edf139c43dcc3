"""The static ISO 6336 rating of a spur pair: nominal and actual stresses, permissible stresses, safety factors.

Tooth root (ISO 6336-3 method B):
``sigma_F0 = F_t / (b m) Y_F Y_S Y_beta Y_B Y_DT`` with Y_beta = Y_B = Y_DT = 1
(spur gears, solid rims, eps_alpha < 2.05) and Y_eps = 1 (the load at the outer
point of single pair contact); ``sigma_F = sigma_F0 K_A K_v K_Fbeta K_Falpha``
with K_Fbeta = K_Hbeta^N_F.
Flank (ISO 6336-2): ``sigma_H0 = Z_H Z_E Z_eps Z_beta sqrt(F_t / (d_1 b) (u + 1) / u)``,
``sigma_H = Z_B|Z_D sigma_H0 sqrt(K_A K_v K_Hbeta K_Halpha)``.
Permissible stresses follow the S-N curves of :mod:`.life`: at the static
point the life factor alone (Z_NT = 1.6, or Y_NT = 2.5 with the static
Y_deltarelT = 0.44 Y_S + 0.12), at the endurance knee and beyond the
long-life factors Z_L, Z_v, Z_R, Z_W = Z_X = 1 (both gears case-hardened)
and Y_ST = 2, Y_deltarelT, Y_RrelT, Y_X; log-log linear between.
Safety factors S_H = sigma_HG / sigma_H, S_F = sigma_FG / sigma_F.
Stresses in Pa; the dynamic factor is ISO's K_v unless one is given (the
simulated peak mesh force over the static one, for example).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..geometry import PairGeometry, pair_geometry
from .contact import ContactFactors, contact_factors
from .dynamic import dynamic_factor_model
from .life import CONTACT_KNEES, ROOT_KNEES, StressLifeCurve
from .root import RootSection, root_section
from .settings import RatingSettings

#: ISO 6336-3's stress correction factor of the reference test gear (sigma_Flim is for Y_ST = 2).
Y_ST = 2.0
#: Slip-layer thickness rho' of case-hardened steel (ISO 6336-3 method B), m.
SLIP_LAYER_CASE_HARDENED = 0.003e-3


def lubricant_factors(settings: RatingSettings, pitch_line_velocity: float, reduced_radius: float):
    """Z_L, Z_v and Z_R of ISO 6336-2 method B (velocity in m/s, reduced radius of curvature in m)."""
    sigma = settings.material.sigma_Hlim / 1e6
    c_zl = 0.83 if sigma < 850.0 else (0.91 if sigma > 1200.0 else sigma / 4375.0 + 0.6357)
    z_l = c_zl + 4.0 * (1.0 - c_zl) / (1.2 + 134.0 / settings.viscosity_40) ** 2
    c_zv = c_zl + 0.02
    z_v = c_zv + 2.0 * (1.0 - c_zv) / math.sqrt(0.8 + 32.0 / max(pitch_line_velocity, 1e-6))
    c_zr = 0.15 if sigma < 850.0 else (0.08 if sigma > 1200.0 else 0.32 - 0.0002 * sigma)
    r_z10 = settings.flank_roughness * (10.0 / (reduced_radius * 1e3)) ** (1.0 / 3.0)
    z_r = (3.0 / r_z10) ** c_zr
    return z_l, z_v, z_r


def root_strength_factors(settings: RatingSettings, section: RootSection, module: float):
    """Y_deltarelT (static, long life), Y_RrelT and Y_X (long life) of ISO 6336-3 method B, case-hardened."""
    static_notch = 0.44 * section.stress_correction + 0.12
    chi = (1.0 + 2.0 * section.notch_parameter) / 5.0e-3  # relative stress gradient, 1/m
    chi_t = (1.0 + 2.0 * 2.5) / 5.0e-3
    notch = (1.0 + math.sqrt(SLIP_LAYER_CASE_HARDENED * chi)) / (1.0 + math.sqrt(SLIP_LAYER_CASE_HARDENED * chi_t))
    rz = settings.root_roughness
    roughness = 1.12 if rz < 1.0 else 1.674 - 0.529 * (rz + 1.0) ** 0.1
    m_mm = module * 1e3
    size = 1.0 if m_mm <= 5.0 else (0.8 if m_mm >= 25.0 else 1.05 - 0.01 * m_mm)
    return static_notch, notch, roughness, size


@dataclass(frozen=True)
class StaticRating:
    """ISO 6336 rating of a spur pair at one operating point; tuples are (pinion, gear).

    Attributes
    ----------
    tangential_force : float
        F_t at the reference circle, N.
    dynamic_factor : float
        K_v used (ISO's, or the one given).
    root : tuple of RootSection
        Y_F, Y_S and the critical section of each gear.
    contact : ContactFactors
    root_stress_nominal, root_stress : tuple of float
        sigma_F0 and sigma_F, Pa.
    contact_stress_nominal : float
        sigma_H0, Pa (the same for both gears).
    contact_stress : tuple of float
        sigma_H, Pa.
    contact_curve, root_curve : tuple of StressLifeCurve
        The permissible-stress S-N curves of each gear, in the pinion's (gear's) own load cycles.
    cycles : tuple of float or None
        Load cycles of each gear the safety factors are for (None: at the endurance knee).
    contact_strength, root_strength : tuple of float
        sigma_HG and sigma_FG at those cycles, Pa.
    safety_contact, safety_root : tuple of float
        S_H and S_F.
    lubricant : tuple of float
        Z_L, Z_v, Z_R.
    """

    tangential_force: float
    dynamic_factor: float
    root: tuple[RootSection, RootSection]
    contact: ContactFactors
    root_stress_nominal: tuple[float, float]
    root_stress: tuple[float, float]
    contact_stress_nominal: float
    contact_stress: tuple[float, float]
    contact_curve: tuple[StressLifeCurve, StressLifeCurve]
    root_curve: tuple[StressLifeCurve, StressLifeCurve]
    cycles: tuple[float, float] | None
    contact_strength: tuple[float, float]
    root_strength: tuple[float, float]
    safety_contact: tuple[float, float]
    safety_root: tuple[float, float]
    lubricant: tuple[float, float, float]


def _curve(knees, static: float, endurance: float, reduced: bool) -> StressLifeCurve:
    (n_static, _), (n_knee, _), (n_long, long_factor) = knees
    return StressLifeCurve(
        cycles=(n_static, n_knee, n_long), stress=(static, endurance, endurance * (long_factor if reduced else 1.0))
    )


def static_rating(
    design,
    drive_torque: float,
    pinion_speed: float,
    settings: RatingSettings | None = None,
    *,
    dynamic_factor: float | None = None,
    cycles: float | None = None,
) -> StaticRating:
    """Rate a design's spur pair by ISO 6336 (method B) at a drive torque and pinion speed.

    Parameters
    ----------
    design : Design
    drive_torque : float
        Torque on the pinion, N m (> 0).
    pinion_speed : float
        rpm (> 0): the dynamic factor and Z_v.
    settings : RatingSettings, optional
        Material and the other rating inputs (defaults: case-hardened steel, K_A = 1, K_Hbeta = 1.1).
    dynamic_factor : float, optional
        K_v to use instead of ISO 6336-1 method B's.
    cycles : float, optional
        Load cycles of the pinion for the safety factors (the gear's are ``cycles / u``);
        None rates at the endurance knee (Z_NT = Y_NT = 1).

    Returns
    -------
    StaticRating

    Examples
    --------
    The locomotive gear at its continuous rating, with K_v = 1 (the nominal stresses times the load factors):

    >>> import uqgear
    >>> from uqgear.physics.rating import static_rating
    >>> rating = static_rating(uqgear.load_design("locomotive"), 7000.0, 1000.0, dynamic_factor=1.0)
    >>> round(rating.contact_stress_nominal / 1e6, 1), [round(s / 1e6, 1) for s in rating.root_stress_nominal]
    (815.5, [171.9, 181.4])
    >>> [round(s, 2) for s in rating.safety_contact], [round(s, 2) for s in rating.safety_root]
    ([1.8, 1.84], [5.14, 4.88])
    """
    settings = settings or RatingSettings()
    if not (math.isfinite(drive_torque) and drive_torque > 0.0):
        raise ValueError(f"drive_torque: expected a finite torque > 0 N m; got {drive_torque!r}")
    if not (math.isfinite(pinion_speed) and pinion_speed > 0.0):
        raise ValueError(f"pinion_speed: expected a finite speed > 0 rpm; got {pinion_speed!r}")
    geometry = pair_geometry(design)
    force = drive_torque / geometry.pinion.pitch_radius
    k_v = (
        dynamic_factor
        if dynamic_factor is not None
        else float(dynamic_factor_model(design, drive_torque, settings).factor(pinion_speed))
    )
    sections, root_nominal, root_actual = _root_stresses(design, geometry, settings, force, k_v)
    factors, contact_nominal, contact_actual = _contact_stresses(design, geometry, settings, force, k_v)
    lubricant, contact_curve, root_curves = _strength_curves(design, geometry, settings, sections, pinion_speed)
    per_gear = None if cycles is None else (float(cycles), float(cycles) / (design.z2 / design.z1))
    contact_strength = tuple(
        contact_curve.stress[1] if per_gear is None else float(contact_curve.strength(n))
        for n in (per_gear or (0.0, 0.0))
    )
    root_strength = tuple(
        curve.stress[1] if per_gear is None else float(curve.strength(n))
        for curve, n in zip(root_curves, per_gear or (0.0, 0.0))
    )
    return StaticRating(
        tangential_force=force,
        dynamic_factor=k_v,
        root=sections,
        contact=factors,
        root_stress_nominal=root_nominal,
        root_stress=root_actual,
        contact_stress_nominal=contact_nominal,
        contact_stress=contact_actual,
        contact_curve=(contact_curve, contact_curve),
        root_curve=root_curves,
        cycles=per_gear,
        contact_strength=(contact_strength[0], contact_strength[1]),
        root_strength=(root_strength[0], root_strength[1]),
        safety_contact=(contact_strength[0] / contact_actual[0], contact_strength[1] / contact_actual[1]),
        safety_root=(root_strength[0] / root_actual[0], root_strength[1] / root_actual[1]),
        lubricant=lubricant,
    )


def _root_stresses(
    design, geometry: PairGeometry, settings: RatingSettings, force: float, k_v: float
) -> tuple[tuple[RootSection, RootSection], tuple[float, float], tuple[float, float]]:
    """Each gear's critical root section, nominal root stress sigma_F0 and root stress sigma_F (ISO 6336-3)."""
    b, m = design.face_width, design.module
    k_a, k_hb, k_alpha = settings.application_factor, settings.face_load_factor, settings.transverse_load_factor
    depth = (design.addendum_coefficient + design.dedendum_coefficient) * m
    ratio = b / depth
    k_fb = k_hb ** (ratio**2 / (1.0 + ratio + ratio**2))
    pinion, gear = (
        root_section(design, name, rack_fillet_coefficient=settings.rack_fillet_coefficient, geometry=geometry)
        for name in ("pinion", "gear")
    )
    nominal = (
        force / (b * m) * pinion.form_factor * pinion.stress_correction,
        force / (b * m) * gear.form_factor * gear.stress_correction,
    )
    actual = (nominal[0] * k_a * k_v * k_fb * k_alpha, nominal[1] * k_a * k_v * k_fb * k_alpha)
    return (pinion, gear), nominal, actual


def _contact_stresses(
    design, geometry: PairGeometry, settings: RatingSettings, force: float, k_v: float
) -> tuple[ContactFactors, float, tuple[float, float]]:
    """The contact factors, the nominal contact stress sigma_H0 and each gear's sigma_H (ISO 6336-2)."""
    b, u = design.face_width, design.z2 / design.z1
    d_1 = 2.0 * geometry.pinion.pitch_radius
    k_a, k_hb, k_alpha = settings.application_factor, settings.face_load_factor, settings.transverse_load_factor
    factors = contact_factors(design, geometry)
    nominal = (
        factors.zone
        * factors.elasticity
        * factors.contact_ratio
        * factors.helix
        * math.sqrt(force / (d_1 * b) * (u + 1.0) / u)
    )
    load = math.sqrt(k_a * k_v * k_hb * k_alpha)
    return factors, nominal, (factors.single_pair_pinion * nominal * load, factors.single_pair_gear * nominal * load)


def _strength_curves(
    design, geometry: PairGeometry, settings: RatingSettings, sections: tuple[RootSection, ...], pinion_speed: float
) -> tuple[tuple[float, float, float], StressLifeCurve, tuple[StressLifeCurve, StressLifeCurve]]:
    """The lubricant factors (Z_L, Z_v, Z_R), the flank's S-N curve and each gear's root S-N curve."""
    d_1 = 2.0 * geometry.pinion.pitch_radius
    velocity = math.pi * d_1 * pinion_speed / 60.0
    radii = [
        tooth.base_radius * math.tan(geometry.working_pressure_angle) for tooth in (geometry.pinion, geometry.gear)
    ]
    lubricant = lubricant_factors(settings, velocity, radii[0] * radii[1] / (radii[0] + radii[1]))
    material = settings.material
    reduced = material.long_life_reduced
    h_static = material.sigma_Hlim * CONTACT_KNEES[0][1]
    h_endurance = material.sigma_Hlim * lubricant[0] * lubricant[1] * lubricant[2]
    contact_curve = _curve(CONTACT_KNEES, h_static, h_endurance, reduced)
    root_curves = []
    for section in sections:
        static_notch, notch, roughness, size = root_strength_factors(settings, section, design.module)
        f_static = material.sigma_Flim * Y_ST * ROOT_KNEES[0][1] * static_notch
        f_endurance = material.sigma_Flim * Y_ST * notch * roughness * size
        root_curves.append(_curve(ROOT_KNEES, f_static, f_endurance, reduced))
    return lubricant, contact_curve, (root_curves[0], root_curves[1])


__all__ = [
    "StaticRating",
    "static_rating",
    "lubricant_factors",
    "root_strength_factors",
    "Y_ST",
    "SLIP_LAYER_CASE_HARDENED",
]
