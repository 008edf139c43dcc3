"""Gear designs: the nominal description of a gear pair and its operation.

A design holds the keys of docs/rig-data-format.md (SI units, pressure angle in
degrees). Designs are read from YAML files with a ``design`` mapping and an
optional ``operation`` mapping (rated drive torque, axle load, wheel radius,
adhesion-coefficient bounds) and validated key by key: a missing or unknown
key, or a value outside physical plausibility, raises :class:`DesignError`
naming the key and the expected range.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..common.errors import DesignError, shown
from ..common.resources import bundled_by_name, bundled_names
from ..common.yamlio import YAMLError, load_yaml
from .design_parts import DesignParts, ToothPairDesign

#: Standard gravity used to turn an axle load in kg into a normal force.
STANDARD_GRAVITY = 9.80665

# key -> (lower, upper, unit/explanation, integer?)
# Ranges are generous physical plausibility limits, chosen so that a value in
# the wrong unit (a module of 9 meant as mm, a face width in mm) is caught.
_DESIGN_KEYS: dict[str, tuple[float, float, str, bool]] = {
    "z1": (6, 400, "teeth", True),
    "z2": (6, 1000, "teeth", True),
    "module": (2e-4, 0.05, "m (SI metres: a 9 mm module is 0.009)", False),
    "pressure_angle": (10.0, 35.0, "deg", False),
    "x1": (-1.0, 1.5, "profile shift coefficient", False),
    "x2": (-1.0, 1.5, "profile shift coefficient", False),
    "addendum_coefficient": (0.5, 1.6, "multiple of the module", False),
    "dedendum_coefficient": (0.6, 2.0, "multiple of the module", False),
    "face_width": (1e-3, 1.5, "m", False),
    "youngs_modulus": (1e9, 1e12, "Pa", False),
    "poisson_ratio": (0.0, 0.5, "-", False),
    "m1": (1e-3, 1e5, "kg", False),
    "m2": (1e-3, 1e5, "kg", False),
    "I1": (1e-7, 1e5, "kg m^2", False),
    "I2": (1e-7, 1e5, "kg m^2", False),
    "k1": (1e5, 1e13, "N/m", False),
    "k2": (1e5, 1e13, "N/m", False),
    "zeta1": (0.0, 1.0, "damping ratio", False),
    "zeta2": (0.0, 1.0, "damping ratio", False),
    "zeta_mesh": (0.0, 1.0, "damping ratio", False),
    "backlash": (0.0, 5e-3, "m, total backlash 2b", False),
    "ste_amplitude": (0.0, 5e-4, "m", False),
}
_OPTIONAL_DESIGN_KEYS: dict[str, tuple[float, float, str, bool]] = {
    "motor_pole_pairs": (1, 24, "pole pairs of the traction motor", True)
}

_OPERATION_KEYS: dict[str, tuple[float, float, str]] = {
    "drive_torque": (0.0, 1e7, "N m"),
    "axle_load": (1.0, 1e6, "kg"),
    "wheel_radius": (0.05, 5.0, "m"),
}

#: The keys every design must have (docs/rig-data-format.md), in canonical order.
DESIGN_KEYS: tuple[str, ...] = tuple(_DESIGN_KEYS)
#: Keys a design may have in addition.
OPTIONAL_DESIGN_KEYS: tuple[str, ...] = tuple(_OPTIONAL_DESIGN_KEYS)
_ALL_DESIGN_KEYS = {**_DESIGN_KEYS, **_OPTIONAL_DESIGN_KEYS}


def design_key_bounds(key: str) -> tuple[float, float]:
    """The plausible range ``(lower, upper)`` that :meth:`Design.from_mapping` accepts for a design key.

    Lets a fit or a sampler keep its internal proposals inside what the
    validation accepts (geometry checks such as undercut come on top).

    Raises
    ------
    DesignError
        ``key`` is not a design key.
    """
    if key not in _ALL_DESIGN_KEYS:
        raise _unknown_key(key, "")
    lower, upper, _, _ = _ALL_DESIGN_KEYS[key]
    return float(lower), float(upper)


def design_key_unit(key: str) -> str:
    """The unit (or what the value is) of a design key, as messages and axis labels give it.

    Raises
    ------
    DesignError
        ``key`` is not a design key.

    Examples
    --------
    >>> from uqgear.physics.design import design_key_unit
    >>> design_key_unit("pressure_angle"), design_key_unit("z1")
    ('deg', 'teeth')
    """
    if key not in _ALL_DESIGN_KEYS:
        raise _unknown_key(key, "")
    return _ALL_DESIGN_KEYS[key][2]


def _unknown_key(key: str, where: str) -> DesignError:
    expected = ", ".join(DESIGN_KEYS + OPTIONAL_DESIGN_KEYS)
    return DesignError(f"{where}{key}: unknown design key; expected one of {expected}")


def _missing_key(key: str, where: str) -> DesignError:
    return DesignError(f"{where}{key}: missing design key (expected {_DESIGN_KEYS[key][2]})")


def _check_key(key: str, value: Any, where: str) -> float | int:
    """A design key's value as :meth:`Design.from_mapping` takes it (the key known, the value not None)."""
    lower, upper, unit, integer = _ALL_DESIGN_KEYS[key]
    return _check_number(key, value, lower, upper, unit, integer, where)


def _check_tip_clearance(addendum: float, dedendum: float, where: str) -> None:
    if dedendum <= addendum:
        raise DesignError(
            f"{where}dedendum_coefficient: expected more than addendum_coefficient "
            f"({addendum:g}) to leave tip clearance; got {dedendum:g}"
        )


def _check_number(
    key: str, value: Any, lower: float, upper: float, unit: str, integer: bool, where: str
) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DesignError(f"{where}{key}: expected a number in [{lower:g}, {upper:g}] {unit}; got {shown(value)}")
    if integer:
        if float(value) != int(value):
            raise DesignError(f"{where}{key}: expected an integer in [{lower:g}, {upper:g}] {unit}; got {shown(value)}")
        value = int(value)
    if not math.isfinite(value) or not lower <= value <= upper:
        raise DesignError(f"{where}{key}: expected a value in [{lower:g}, {upper:g}] {unit}; got {shown(value)}")
    return value if integer else float(value)


@dataclass(frozen=True)
class Operation:
    """Operating conditions that come with a design.

    Parameters
    ----------
    drive_torque : float
        Rated drive torque T1 on the pinion, N m.
    axle_load : float
        Wheelset axle load, kg (the normal force is ``axle_load * g``).
    wheel_radius : float
        Wheel rolling radius R_w, m.
    adhesion_coefficient : tuple of float
        Bounds (lower, upper) of the wheel/rail adhesion coefficient mu.
    pinion_speed_service, pinion_speed_sweep : tuple of float
        Pinion speed ranges in rpm: in service and for dynamic sweeps.

    Examples
    --------
    The adhesion torque interval is T2 = mu Q g R_w at the two bounds of mu:

    >>> import uqgear
    >>> operation = uqgear.load_design("locomotive").operation
    >>> operation.axle_load, operation.wheel_radius, operation.adhesion_coefficient
    (23000.0, 0.625, (0.15, 0.33))
    >>> lower, upper = operation.adhesion_torque_bounds()
    >>> round(lower), round(upper), round(0.33 * 23000.0 * 9.80665 * 0.625)
    (21146, 46520, 46520)
    """

    drive_torque: float = 7000.0
    axle_load: float = 23000.0
    wheel_radius: float = 0.625
    adhesion_coefficient: tuple[float, float] = (0.15, 0.33)
    pinion_speed_service: tuple[float, float] = (0.0, 4000.0)
    pinion_speed_sweep: tuple[float, float] = (200.0, 6000.0)

    def adhesion_torque_bounds(self) -> tuple[float, float]:
        """Interval of the adhesion torque T2 = mu Q R_w in N m."""
        normal_force = self.axle_load * STANDARD_GRAVITY
        lower, upper = self.adhesion_coefficient
        return (lower * normal_force * self.wheel_radius, upper * normal_force * self.wheel_radius)


@dataclass(frozen=True)
class Design(DesignParts):
    """Nominal design of a spur gear pair (keys and units of docs/rig-data-format.md).

    Use :func:`load_design` or :meth:`from_mapping` to build one with
    validation; :meth:`replace` returns a validated copy with some keys changed.
    The parts the derived design reads (:attr:`tooth_pair`, :attr:`mesh_design`,
    :attr:`modal_design`; :mod:`uqgear.physics.design_parts`) are the keys
    its geometry, stiffness tables and modes are cached under.

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> design.z1, design.z2, round(design.z2 / design.z1, 3)
    (21, 101, 4.81)
    >>> wider = design.replace(face_width=0.15)      # a validated copy; the original is unchanged
    >>> wider.face_width, design.face_width
    (0.15, 0.125)
    >>> try:
    ...     design.replace(face_width=-0.1)
    ... except uqgear.DesignError as error:
    ...     print(error)
    face_width: expected a value in [0.001, 1.5] m; got -0.1
    """

    z1: int
    z2: int
    module: float
    pressure_angle: float
    x1: float
    x2: float
    addendum_coefficient: float
    dedendum_coefficient: float
    face_width: float
    youngs_modulus: float
    poisson_ratio: float
    m1: float
    m2: float
    I1: float
    I2: float
    k1: float
    k2: float
    zeta1: float
    zeta2: float
    zeta_mesh: float
    backlash: float
    ste_amplitude: float
    motor_pole_pairs: int | None = None
    name: str = "custom"
    operation: Operation = field(default_factory=Operation)

    @classmethod
    def from_mapping(
        cls, values: Mapping[str, Any], *, name: str = "custom", operation: Operation | None = None, where: str = ""
    ) -> Design:
        """Validate a mapping of design keys and build a design.

        Parameters
        ----------
        values : mapping
            Design keys of docs/rig-data-format.md (SI units).
        name : str
            A label for reports.
        operation : Operation, optional
            Operating conditions; defaults to those of the reference design.
        where : str
            Prefix for error messages (a file name or key path).

        Raises
        ------
        DesignError
            A key is missing, unknown, or outside its plausible range, or the
            pair cannot mesh (pointed teeth, interference, contact ratio < 1;
            :func:`~uqgear.physics.geometry.check_geometry`).

        Warns
        -----
        UndercutWarning
            A tooth is undercut: modelled from its form circle, not refused.
        """
        if not isinstance(values, Mapping):
            raise DesignError(f"{where}design: expected a mapping of design keys; got {type(values).__name__}")
        unknown = sorted(set(values) - set(_ALL_DESIGN_KEYS))
        if unknown:
            raise _unknown_key(unknown[0], where)
        # an empty YAML value reads as None: as missing as an absent key
        missing = [key for key in _DESIGN_KEYS if values.get(key) is None]
        if missing:
            raise _missing_key(missing[0], where)
        checked: dict[str, Any] = {
            key: _check_key(key, values[key], where) for key in _ALL_DESIGN_KEYS if values.get(key) is not None
        }
        _check_tip_clearance(checked["addendum_coefficient"], checked["dedendum_coefficient"], where)
        design = cls(**checked, name=name, operation=operation or Operation())
        # Geometry-level checks (interference, contact ratio; an undercut warns) need the
        # involute geometry; importing here avoids a module cycle.
        from .geometry import check_geometry

        check_geometry(design, where=where)
        return design

    def replace(self, **changes: Any) -> Design:
        """Return a validated copy with some design keys changed.

        The changed keys are checked as :meth:`from_mapping` checks them, and
        the pair's geometry again when one of its keys changed; the other
        keys are this design's, validated when it was built. A fit builds a
        copy for every model run (thousands a diagnosis), so the copy costs
        the keys that change, not a whole validation.
        """
        unknown = sorted(set(changes) - set(_ALL_DESIGN_KEYS))
        if unknown:
            raise _unknown_key(unknown[0], "")
        missing = [key for key, value in changes.items() if value is None and key in _DESIGN_KEYS]
        if missing:
            raise _missing_key(missing[0], "")
        checked: dict[str, Any] = {
            key: None if value is None else _check_key(key, value, "") for key, value in changes.items()
        }
        design = dataclasses.replace(self, **checked)
        _check_tip_clearance(design.addendum_coefficient, design.dedendum_coefficient, "")
        # importing here avoids a module cycle, as in from_mapping
        from .geometry import check_geometry

        if any(key in ToothPairDesign.keys() for key in changes):
            check_geometry(design)
        return design

    def to_dict(self) -> dict[str, Any]:
        """The design keys (docs/rig-data-format.md), without name and operation."""
        values = {key: getattr(self, key) for key in DESIGN_KEYS}
        if self.motor_pole_pairs is not None:
            values["motor_pole_pairs"] = self.motor_pole_pairs
        return values

    def to_json(self) -> str:
        """The design keys as a JSON object (the rig format's ``design`` attribute)."""
        return json.dumps(self.to_dict())

    @property
    def gear_ratio(self) -> float:
        """Speed ratio z2 / z1."""
        return self.z2 / self.z1

    @property
    def half_backlash(self) -> float:
        """Half backlash b in m."""
        return 0.5 * self.backlash


def _parse_operation(raw: Any, where: str) -> Operation:
    if raw is None:
        return Operation()
    if not isinstance(raw, Mapping):
        raise DesignError(f"{where}operation: expected a mapping; got {type(raw).__name__}")
    known = set(_OPERATION_KEYS) | {"adhesion_coefficient", "pinion_speed_service", "pinion_speed_sweep"}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise DesignError(f"{where}operation.{unknown[0]}: unknown key; expected one of {', '.join(sorted(known))}")
    values: dict[str, Any] = {}
    for key, (lower, upper, unit) in _OPERATION_KEYS.items():
        if key in raw:
            values[key] = _check_number(key, raw[key], lower, upper, unit, False, f"{where}operation.")
    for key, lower, upper, unit in (
        ("adhesion_coefficient", 0.0, 1.5, "-"),
        ("pinion_speed_service", 0.0, 1e5, "rpm"),
        ("pinion_speed_sweep", 0.0, 1e5, "rpm"),
    ):
        if key not in raw:
            continue
        pair = raw[key]
        if not isinstance(pair, (list, tuple)) or len(pair) != 2:
            raise DesignError(f"{where}operation.{key}: expected [lower, upper] in {unit}; got {pair!r}")
        low = _check_number(key, pair[0], lower, upper, unit, False, f"{where}operation.")
        high = _check_number(key, pair[1], lower, upper, unit, False, f"{where}operation.")
        if high < low:
            raise DesignError(f"{where}operation.{key}: expected lower <= upper; got [{low:g}, {high:g}]")
        values[key] = (low, high)
    return Operation(**values)


def bundled_designs() -> list[str]:
    """Names of the designs shipped with the package (``uqgear/data/designs``).

    Examples
    --------
    >>> import warnings
    >>> import uqgear
    >>> uqgear.bundled_designs()
    ['locomotive', 'pair_17_38']
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("ignore", uqgear.UndercutWarning)   # the 17-tooth pinion is undercut
    ...     [(design.z1, design.z2) for design in map(uqgear.load_design, uqgear.bundled_designs())]
    [(21, 101), (17, 38)]
    """
    return list(bundled_names("design"))


def load_design(
    name_or_path: str | os.PathLike[str] | Design | Mapping[str, Any] = "locomotive",
    overrides: Mapping[str, Any] | None = None,
) -> Design:
    """Load and validate a gear design.

    Parameters
    ----------
    name_or_path : str, Path, Design or mapping
        A bundled design name (see :func:`bundled_designs`), the path of a YAML
        design file, an existing :class:`Design`, or a mapping of design keys.
    overrides : mapping, optional
        Design keys to change after loading (validated like the file).

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        Unknown name, unreadable file, or a key that fails validation. The
        message names the file and the key.

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> design.name, design.module, design.backlash
    ('locomotive', 0.009, 0.0003)
    >>> damped = uqgear.load_design("locomotive", overrides={"zeta_mesh": 0.08})
    >>> damped.zeta_mesh, damped.z1
    (0.08, 21)
    >>> uqgear.load_design(damped) is damped            # a Design passes through
    True
    >>> try:
    ...     uqgear.load_design("locomotive", overrides={"backlash": -1e-4})
    ... except uqgear.DesignError as error:
    ...     print(error)
    backlash: expected a value in [0, 0.005] m, total backlash 2b; got -0.0001
    """
    if isinstance(name_or_path, Design):
        design = name_or_path
    elif isinstance(name_or_path, Mapping):
        raw = dict(name_or_path)
        if "design" in raw:
            design = Design.from_mapping(
                raw["design"], name=str(raw.get("name", "custom")), operation=_parse_operation(raw.get("operation"), "")
            )
        else:
            design = Design.from_mapping(raw)
    else:
        path = Path(name_or_path)
        path = bundled_by_name("design", str(name_or_path), path) or path
        if not path.suffix and not path.exists():
            raise DesignError(
                f"design {str(name_or_path)[:80]!r}: not a bundled design "
                f"({', '.join(bundled_designs())}) nor an existing file"
            )
        if not path.is_file():
            raise DesignError(f"{path}: design file not found")
        try:
            raw = load_yaml(path.read_text())
        except YAMLError as exc:
            raise DesignError(f"{path}: not valid YAML ({str(exc).splitlines()[0]})") from None
        where = f"{path}: "
        if not isinstance(raw, Mapping) or "design" not in raw:
            raise DesignError(f"{where}expected a mapping with a 'design' key holding the design keys")
        unknown = sorted(set(raw) - {"name", "description", "design", "operation"})
        if unknown:
            raise DesignError(
                f"{where}{unknown[0]}: unknown top-level key; expected name, description, design, operation"
            )
        design = Design.from_mapping(
            raw["design"],
            name=str(raw.get("name", path.stem)),
            operation=_parse_operation(raw.get("operation"), where),
            where=where,
        )
    if overrides:
        design = design.replace(**dict(overrides))
    return design


def design_from_json(text: str, *, where: str = "design") -> Design:
    """Build a design from the JSON object of a rig file's ``design`` attribute."""
    try:
        values = json.loads(text)
    except (TypeError, json.JSONDecodeError) as exc:
        raise DesignError(f"{where}: not a JSON object ({shown(str(exc), 120)})") from None
    except RecursionError:
        raise DesignError(
            f"{where}: not a design: the JSON is nested too deeply; expected one flat object of design keys"
        ) from None
    if not isinstance(values, dict):
        raise DesignError(f"{where}: expected a JSON object of design keys; got {shown(values)}")
    return Design.from_mapping(values, name="rig", where=f"{where}.")


__all__ = [
    "Design",
    "Operation",
    "load_design",
    "bundled_designs",
    "design_from_json",
    "DESIGN_KEYS",
    "OPTIONAL_DESIGN_KEYS",
    "STANDARD_GRAVITY",
    "design_key_bounds",
    "design_key_unit",
]
