"""Material data and rating inputs of an ISO 6336 rating, validated key by key.

:class:`RatingMaterial` holds what ISO 6336-5 gives for a material grade
(endurance limits, the S-N curve family); :class:`RatingSettings` the other
inputs of a rating that the gear design does not carry (load factors, surface
roughness, lubricant, accuracy grade, the basic rack's root fillet, required
safety factors). Both are frozen; :meth:`RatingSettings.from_mapping` refuses
a missing, unknown or out-of-range key with a :class:`RatingError` naming it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

from ...common.errors import UqgearError, shown


class RatingError(UqgearError):
    """A rating input (material data, load factor, roughness, ...) is missing or out of range.

    Examples
    --------
    >>> from uqgear.physics.rating import RatingError, RatingSettings
    >>> issubclass(RatingError, ValueError)
    True
    >>> try:
    ...     RatingSettings.from_mapping({"material": {"sigma_Hlim": 15e6}})
    ... except RatingError as error:
    ...     print(error)
    rating.material.sigma_Hlim: expected a value in [2e+08, 2.5e+09] Pa (SI: 1500 MPa is 1.5e9); got 15000000.0
    """


#: Material families whose S-N curves (knee points, static factors) ISO 6336-2/-3 tabulate here.
HARDENINGS = ("case_hardened",)

# key -> (lower, upper, unit and hint); generous plausibility limits that catch a value in MPa meant as Pa
_MATERIAL_KEYS: dict[str, tuple[float, float, str]] = {
    "sigma_Hlim": (2e8, 2.5e9, "Pa (SI: 1500 MPa is 1.5e9)"),
    "sigma_Flim": (1e8, 1.2e9, "Pa (SI: 500 MPa is 5e8)"),
}
_SETTINGS_KEYS: dict[str, tuple[float, float, str]] = {
    "application_factor": (1.0, 3.0, "K_A, -"),
    "face_load_factor": (1.0, 3.0, "K_Hbeta, -"),
    "transverse_load_factor": (1.0, 3.0, "K_Halpha = K_Falpha, -"),
    "flank_roughness": (0.1, 50.0, "R_z of the flanks, um"),
    "root_roughness": (0.1, 50.0, "R_z of the root fillet, um"),
    "viscosity_40": (10.0, 3000.0, "lubricant kinematic viscosity at 40 C, mm^2/s"),
    "accuracy_grade": (1, 11, "ISO 1328-1 flank tolerance class, integer"),
    "rack_fillet_coefficient": (0.1, 0.5, "root fillet radius of the basic rack, multiple of the module"),
    "minimum_safety_contact": (0.5, 3.0, "required S_Hmin, -"),
    "minimum_safety_root": (0.5, 4.0, "required S_Fmin, -"),
    "density": (1000.0, 20000.0, "kg/m^3"),
}


def _number(key: str, value: Any, bounds: tuple[float, float, str], where: str) -> float:
    lower, upper, unit = bounds
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise RatingError(f"{where}{key}: expected a number in [{lower:g}, {upper:g}] {unit}; got {shown(value)}")
    if not lower <= value <= upper:
        raise RatingError(f"{where}{key}: expected a value in [{lower:g}, {upper:g}] {unit}; got {shown(value)}")
    return float(value)


@dataclass(frozen=True)
class RatingMaterial:
    """Material data of both gears (ISO 6336-5): endurance limits and the S-N curve family.

    Parameters
    ----------
    sigma_Hlim : float
        Allowable stress number for contact, Pa (case-hardened steel, quality MQ: 1500 MPa).
    sigma_Flim : float
        Nominal stress number for bending, Pa (case-hardened steel, quality MQ: 500 MPa).
    hardening : str
        One of :data:`HARDENINGS`; selects the life-factor curves of ISO 6336-2/-3.
    long_life_reduced : bool
        Beyond the knee the life factors fall to 0.85 at 1e10 cycles (True, ISO's default)
        or stay at 1 (False: "optimum lubrication, material, manufacturing and experience").

    Examples
    --------
    >>> from uqgear.physics.rating import RatingMaterial
    >>> material = RatingMaterial()
    >>> material.sigma_Hlim / 1e6, material.sigma_Flim / 1e6, material.hardening
    (1500.0, 500.0, 'case_hardened')
    """

    sigma_Hlim: float = 1500e6
    sigma_Flim: float = 500e6
    hardening: str = "case_hardened"
    long_life_reduced: bool = True

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], *, where: str = "rating.material.") -> RatingMaterial:
        """Validate a mapping of material keys; absent keys keep the case-hardened defaults."""
        if not isinstance(values, Mapping):
            raise RatingError(f"{where.rstrip('.')}: expected a mapping of material keys; got {shown(values)}")
        known = (*_MATERIAL_KEYS, "hardening", "long_life_reduced")
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise RatingError(f"{where}{unknown[0]}: unknown key; expected one of {', '.join(known)}")
        checked: dict[str, Any] = {
            key: _number(key, values[key], bounds, where) for key, bounds in _MATERIAL_KEYS.items() if key in values
        }
        if "hardening" in values:
            if values["hardening"] not in HARDENINGS:
                raise RatingError(
                    f"{where}hardening: expected one of {', '.join(HARDENINGS)}; got {shown(values['hardening'])}"
                )
            checked["hardening"] = values["hardening"]
        if "long_life_reduced" in values:
            if not isinstance(values["long_life_reduced"], bool):
                raise RatingError(
                    f"{where}long_life_reduced: expected true or false; got {shown(values['long_life_reduced'])}"
                )
            checked["long_life_reduced"] = values["long_life_reduced"]
        return cls(**checked)


@dataclass(frozen=True)
class RatingSettings:
    """The inputs of an ISO 6336 rating that a gear design does not carry.

    Parameters
    ----------
    material : RatingMaterial
        The same material for pinion and gear.
    application_factor : float
        K_A. 1 where the load (T2 here) is carried explicitly.
    face_load_factor : float
        K_Hbeta (given, not computed); K_Fbeta is taken equal to it.
    transverse_load_factor : float
        K_Halpha = K_Falpha (1 for spur gears of good accuracy at high line load).
    flank_roughness, root_roughness : float
        Mean peak-to-valley roughness R_z, um (ground flanks about 3 um, root 10 um).
    viscosity_40 : float
        Lubricant kinematic viscosity at 40 C, mm^2/s (Z_L).
    accuracy_grade : int
        ISO 1328-1 tolerance class: base pitch and profile deviations of the dynamic factor.
    rack_fillet_coefficient : float
        Root fillet radius of the basic rack rho_fP / m (ISO 53 profile A: 0.38).
    minimum_safety_contact, minimum_safety_root : float
        Required S_Hmin and S_Fmin (traction gears commonly 1.0 to 1.2 and 1.4).
    density : float
        Steel density, kg/m^3 (the reduced mass of ISO's solid-blank formula).

    Examples
    --------
    >>> from uqgear.physics.rating import RatingSettings
    >>> settings = RatingSettings.from_mapping({"face_load_factor": 1.15, "material": {"sigma_Flim": 430e6}})
    >>> settings.face_load_factor, settings.material.sigma_Flim, settings.minimum_safety_root
    (1.15, 430000000.0, 1.4)
    >>> try:
    ...     RatingSettings.from_mapping({"face_load_factor": 0.8})
    ... except ValueError as error:
    ...     print(error)
    rating.face_load_factor: expected a value in [1, 3] K_Hbeta, -; got 0.8
    """

    material: RatingMaterial = field(default_factory=RatingMaterial)
    application_factor: float = 1.0
    face_load_factor: float = 1.1
    transverse_load_factor: float = 1.0
    flank_roughness: float = 3.0
    root_roughness: float = 10.0
    viscosity_40: float = 220.0
    accuracy_grade: int = 6
    rack_fillet_coefficient: float = 0.38
    minimum_safety_contact: float = 1.0
    minimum_safety_root: float = 1.4
    density: float = 7830.0

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any] | None, *, where: str = "rating.") -> RatingSettings:
        """Validate a mapping of rating keys (a study's ``rating`` block); absent keys keep their defaults."""
        if values is None:
            return cls()
        if not isinstance(values, Mapping):
            raise RatingError(f"{where.rstrip('.')}: expected a mapping of rating keys; got {shown(values)}")
        known = [item.name for item in fields(cls)]
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise RatingError(f"{where}{unknown[0]}: unknown key; expected one of {', '.join(known)}")
        checked: dict[str, Any] = {}
        for key, bounds in _SETTINGS_KEYS.items():
            if key in values:
                checked[key] = _number(key, values[key], bounds, where)
        if "accuracy_grade" in checked:
            if checked["accuracy_grade"] != int(checked["accuracy_grade"]):
                raise RatingError(
                    f"{where}accuracy_grade: expected an integer in [1, 11]; got {values['accuracy_grade']!r}"
                )
            checked["accuracy_grade"] = int(checked["accuracy_grade"])
        if "material" in values:
            checked["material"] = RatingMaterial.from_mapping(values["material"], where=f"{where}material.")
        return cls(**checked)


__all__ = ["RatingError", "RatingMaterial", "RatingSettings", "HARDENINGS"]
