"""Flank contact factors of ISO 6336-2 for external spur gears.

Zone factor Z_H, elasticity factor Z_E, contact-ratio factor Z_eps and the
single pair tooth contact factors Z_B (pinion) and Z_D (gear), which carry
the nominal contact stress at the pitch point to the inner point of single
pair contact of each gear. The helix factor Z_beta is 1 for spur gears.
Z_E is in sqrt(Pa) (ISO tables give sqrt(N/mm^2): 189.8 for steel on steel
is 1.898e5 sqrt(Pa)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..geometry import PairGeometry, pair_geometry


@dataclass(frozen=True)
class ContactFactors:
    """Contact factors of a spur pair (ISO 6336-2).

    Attributes
    ----------
    zone : float
        Z_H.
    elasticity : float
        Z_E, sqrt(Pa).
    contact_ratio : float
        Z_eps = sqrt((4 - eps_alpha) / 3).
    single_pair_pinion, single_pair_gear : float
        Z_B and Z_D (at least 1).
    helix : float
        Z_beta (1: spur).
    """

    zone: float
    elasticity: float
    contact_ratio: float
    single_pair_pinion: float
    single_pair_gear: float
    helix: float = 1.0


def elasticity_factor(youngs_modulus: float, poisson_ratio: float) -> float:
    """Z_E of two gears of one material, sqrt(Pa).

    Examples
    --------
    >>> from uqgear.physics.rating import elasticity_factor
    >>> round(elasticity_factor(206e9, 0.3) / 1e3, 1)          # sqrt(N/mm^2), as ISO's tables give it
    189.8
    """
    return math.sqrt(1.0 / (math.pi * 2.0 * (1.0 - poisson_ratio**2) / youngs_modulus))


def contact_factors(design, geometry: PairGeometry | None = None) -> ContactFactors:
    """Z_H, Z_E, Z_eps, Z_B and Z_D of a design's spur pair (ISO 6336-2).

    Parameters
    ----------
    design : Design
    geometry : PairGeometry, optional

    Returns
    -------
    ContactFactors

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.physics.rating import contact_factors
    >>> factors = contact_factors(uqgear.load_design("locomotive"))
    >>> round(factors.zone, 4), round(factors.contact_ratio, 4), round(factors.single_pair_pinion, 4)
    (2.4946, 0.885, 1.0187)
    >>> factors.single_pair_gear                      # M_2 < 1: the gear's inner point is no worse than C
    1.0
    """
    geometry = geometry or pair_geometry(design)
    alpha, alpha_w = math.radians(design.pressure_angle), geometry.working_pressure_angle
    zone = math.sqrt(2.0 * math.cos(alpha_w) / (math.cos(alpha) ** 2 * math.sin(alpha_w)))
    eps = geometry.contact_ratio
    pinion, gear = geometry.pinion, geometry.gear

    def roll(tooth) -> float:
        # sqrt(d_a^2 / d_b^2 - 1): the tip's roll angle
        return math.sqrt((tooth.tip_radius / tooth.base_radius) ** 2 - 1.0)

    m_1 = math.tan(alpha_w) / math.sqrt(
        (roll(pinion) - 2.0 * math.pi / pinion.teeth) * (roll(gear) - (eps - 1.0) * 2.0 * math.pi / gear.teeth)
    )
    m_2 = math.tan(alpha_w) / math.sqrt(
        (roll(gear) - 2.0 * math.pi / gear.teeth) * (roll(pinion) - (eps - 1.0) * 2.0 * math.pi / pinion.teeth)
    )
    return ContactFactors(
        zone=zone,
        elasticity=elasticity_factor(design.youngs_modulus, design.poisson_ratio),
        contact_ratio=math.sqrt((4.0 - eps) / 3.0),
        single_pair_pinion=max(1.0, m_1),
        single_pair_gear=max(1.0, m_2),
    )


__all__ = ["ContactFactors", "contact_factors", "elasticity_factor"]
