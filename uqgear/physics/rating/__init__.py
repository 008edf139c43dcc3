"""ISO 6336 load capacity of spur gears (method B), as pure functions of a design.

``settings`` (material data and the rating's inputs, validated) ->
``root`` (critical section, Y_F and Y_S, ISO 6336-3) and ``contact``
(Z_H, Z_E, Z_eps, Z_B, Z_D, ISO 6336-2) -> ``life`` (the life factors
Z_NT, Y_NT and the S-N curves they define) -> ``dynamic`` (ISO 6336-1
method B's K_v with its resonance speed and speed ranges) -> ``static``
(nominal and actual stresses, permissible stresses and safety factors).

May import :mod:`uqgear.common` and the rest of :mod:`uqgear.physics` only; no file output.
"""

from __future__ import annotations

from .contact import ContactFactors, contact_factors, elasticity_factor
from .dynamic import (
    MAIN_RESONANCE_END,
    SPEED_RANGES,
    SUPERCRITICAL_START,
    DynamicFactorModel,
    dynamic_factor_model,
    solid_blank_reduced_mass,
)
from .life import CONTACT_KNEES, ROOT_KNEES, StressLifeCurve, contact_life_factor, root_life_factor
from .root import LOADS, RootSection, root_section
from .settings import HARDENINGS, RatingError, RatingMaterial, RatingSettings
from .static import (
    SLIP_LAYER_CASE_HARDENED,
    Y_ST,
    StaticRating,
    lubricant_factors,
    root_strength_factors,
    static_rating,
)

__all__ = [
    "RatingError",
    "RatingMaterial",
    "RatingSettings",
    "HARDENINGS",
    "RootSection",
    "root_section",
    "LOADS",
    "ContactFactors",
    "contact_factors",
    "elasticity_factor",
    "CONTACT_KNEES",
    "ROOT_KNEES",
    "contact_life_factor",
    "root_life_factor",
    "StressLifeCurve",
    "DynamicFactorModel",
    "dynamic_factor_model",
    "solid_blank_reduced_mass",
    "SPEED_RANGES",
    "MAIN_RESONANCE_END",
    "SUPERCRITICAL_START",
    "StaticRating",
    "static_rating",
    "lubricant_factors",
    "root_strength_factors",
    "Y_ST",
    "SLIP_LAYER_CASE_HARDENED",
]
