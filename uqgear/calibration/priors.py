"""Calibration parameters: their names, aliases, units and uniform priors.

Global parameters (selectable; the names are those of the design keys, in SI
units, plus ``mesh_stiffness_scale``) have uniform priors around the nominal
design of the rig file:

=======================  ==========================================  ==============
parameter                prior (uniform)                             units
=======================  ==========================================  ==============
``mesh_stiffness_scale`` [0.7, 1.3]                                  1
``zeta_mesh``            [0.01, 0.15]                                1
``backlash``             nominal x [0.7, 1.3]                        m
``ste_amplitude``        nominal x [0.5, 1.5]                        m
``k1``, ``k2``           nominal x [0.6, 1.5]                        N m-1
any other design key     nominal x [0.7, 1.3] (or ``priors``)        its units
=======================  ==========================================  ==============

``k1_scale``/``k2_scale`` are accepted as aliases of ``k1``/``k2``.

Every prior lies inside what the design validation accepts for its key: a
default prior is cut to the key's plausible range (``k1`` of a design at
1e13 N/m gets [6e12, 1e13]), a prior given outside it is refused before any
work starts, and so is a prior box at whose corners the design stops being a
working gear pair (a profile shift that makes the teeth pointed or the tips
interfere). The sampler's proposals never leave the box, so no model run of a
calibration can be refused for its parameters.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from itertools import product

from ..common.errors import DesignError
from ..physics.design import Design, design_key_bounds
from ..physics.integration import BATCH_DESIGN_KEYS
from .errors import CalibrationError


@dataclass(frozen=True)
class PriorRule:
    """Default uniform prior of a parameter: absolute bounds or a range relative to nominal."""

    lower: float
    upper: float
    relative: bool
    units: str
    long_name: str


#: Default priors of the calibration parameters.
PRIOR_RULES: dict[str, PriorRule] = {
    "mesh_stiffness_scale": PriorRule(0.7, 1.3, False, "1", "factor on the nominal Ishikawa mesh stiffness"),
    "zeta_mesh": PriorRule(0.01, 0.15, False, "1", "mesh damping ratio"),
    "backlash": PriorRule(0.7, 1.3, True, "m", "total backlash 2b"),
    "ste_amplitude": PriorRule(0.5, 1.5, True, "m", "static transmission error amplitude e_r"),
    "k1": PriorRule(0.6, 1.5, True, "N m-1", "pinion bearing stiffness"),
    "k2": PriorRule(0.6, 1.5, True, "N m-1", "gear bearing stiffness"),
}
#: Prior of design keys without their own rule: nominal x [0.7, 1.3].
OTHER_KEY_RULE = (0.7, 1.3)
#: Parameters calibrated by default.
DEFAULT_PARAMETERS: tuple[str, ...] = tuple(PRIOR_RULES)
#: Accepted aliases of parameter names.
PARAMETER_ALIASES: dict[str, str] = {"k1_scale": "k1", "k2_scale": "k2"}

_DESIGN_UNITS = {
    "module": "m",
    "face_width": "m",
    "youngs_modulus": "Pa",
    "m1": "kg",
    "m2": "kg",
    "I1": "kg m2",
    "I2": "kg m2",
    "k1": "N m-1",
    "k2": "N m-1",
    "backlash": "m",
    "ste_amplitude": "m",
    "pressure_angle": "deg",
}


def resolve_parameters(parameters: Sequence[str]) -> tuple[str, ...]:
    """Check calibration parameter names and resolve aliases.

    Raises
    ------
    CalibrationError
        Unknown or repeated name, or an empty selection.
    """
    if isinstance(parameters, str) or not isinstance(parameters, Sequence):
        raise CalibrationError(f"parameters: expected a list of names; got {parameters!r}")
    known = ["mesh_stiffness_scale", *BATCH_DESIGN_KEYS]
    resolved: list[str] = []
    for name in parameters:
        canonical = PARAMETER_ALIASES.get(name, name)
        if canonical not in known:
            raise CalibrationError(
                f"parameters: {name!r} is not a calibration parameter; expected "
                f"mesh_stiffness_scale or a design key ({', '.join(BATCH_DESIGN_KEYS)}), "
                f"aliases {', '.join(PARAMETER_ALIASES)}"
            )
        if canonical in resolved:
            raise CalibrationError(f"parameters: {name!r} given twice (as {canonical})")
        resolved.append(canonical)
    if not resolved:
        raise CalibrationError("parameters: expected at least one parameter to calibrate")
    return tuple(resolved)


def prior_bounds(
    design: Design, parameters: Sequence[str], priors: Mapping[str, Sequence[float]] | None = None
) -> dict[str, tuple[float, float]]:
    """Uniform prior bounds of each parameter (see the module docstring for the defaults).

    Parameters
    ----------
    design : Design
        Nominal design (relative priors scale its values).
    parameters : sequence of str
        Parameter names (resolved).
    priors : mapping, optional
        Name -> (lower, upper) absolute bounds replacing the default.

    Raises
    ------
    CalibrationError
        A prior for a parameter not calibrated, or bounds not lower < upper.
    """
    priors = dict(priors or {})
    priors = {PARAMETER_ALIASES.get(name, name): value for name, value in priors.items()}
    unknown = sorted(set(priors) - set(parameters))
    if unknown:
        raise CalibrationError(f"priors.{unknown[0]}: not among the calibrated parameters ({', '.join(parameters)})")
    bounds: dict[str, tuple[float, float]] = {}
    for name in parameters:
        if name in priors:
            value = priors[name]
            try:
                lower, upper = (float(v) for v in value)
            except (TypeError, ValueError):
                raise CalibrationError(f"priors.{name}: expected [lower, upper]; got {value!r}") from None
        else:
            rule = PRIOR_RULES.get(name)
            if rule is None:
                nominal = float(getattr(design, name))
                lower, upper = nominal * OTHER_KEY_RULE[0], nominal * OTHER_KEY_RULE[1]
            elif rule.relative:
                nominal = float(getattr(design, name))
                lower, upper = nominal * rule.lower, nominal * rule.upper
            else:
                lower, upper = rule.lower, rule.upper
            # a negative nominal (a negative profile shift) turns a relative range around
            lower, upper = min(lower, upper), max(lower, upper)
            if name != "mesh_stiffness_scale":
                # a default prior is cut to what the design accepts; one given is checked below
                valid_lower, valid_upper = design_key_bounds(name)
                lower, upper = max(lower, valid_lower), min(upper, valid_upper)
        if not (math.isfinite(lower) and math.isfinite(upper) and lower < upper):
            raise CalibrationError(
                f"priors.{name}: expected finite bounds with lower < upper; got [{lower!r}, {upper!r}]"
            )
        if name == "mesh_stiffness_scale" and lower <= 0:
            raise CalibrationError(f"priors.{name}: expected a positive lower bound; got {lower!r}")
        if name != "mesh_stiffness_scale":
            valid_lower, valid_upper = design_key_bounds(name)
            if lower < valid_lower or upper > valid_upper:
                raise CalibrationError(
                    f"priors.{name}: expected bounds within [{valid_lower:g}, {valid_upper:g}] "
                    f"{parameter_units(name)} (the design's plausible range); "
                    f"got [{lower!r}, {upper!r}]"
                )
        bounds[name] = (lower, upper)
    _check_prior_designs(design, bounds)
    return bounds


# Up to this many design keys in a prior box, every corner is checked; beyond, the end of each
# key's range with the others at their nominal values (2^12 corners would take a second).
_MAX_CORNER_KEYS = 10


def _check_prior_designs(design: Design, bounds: Mapping[str, tuple[float, float]]) -> None:
    """Refuse a prior box in which the design stops being a working gear pair.

    The keys' ranges are checked above; what is left are the geometry checks
    (interference, pointed teeth, contact ratio, tip clearance), which depend on
    several keys at once. They are checked at the end of each key's range
    (naming that key) and at the corners of the box, where a geometric limit
    is reached first.
    """
    keys = [name for name in bounds if name != "mesh_stiffness_scale"]
    if not keys:
        return

    def refused(changes: Mapping[str, float]) -> str | None:
        try:
            design.replace(**changes)
        except DesignError as exc:
            return str(exc)
        return None

    for name in keys:
        for value in bounds[name]:
            problem = refused({name: value})
            if problem is not None:
                raise CalibrationError(
                    f"priors.{name}: the design at {name} = {value:g} is not a working gear "
                    f"pair ({problem}); expected a prior inside the range the design accepts"
                )
    if len(keys) > _MAX_CORNER_KEYS:
        return
    for corner in product(*(bounds[name] for name in keys)):
        changes = dict(zip(keys, corner))
        problem = refused(changes)
        if problem is not None:
            shown = ", ".join(f"{name} = {value:g}" for name, value in changes.items())
            raise CalibrationError(
                f"priors: the design at the corner {shown} of the prior box is not a working "
                f"gear pair ({problem}); expected priors inside the range the design accepts"
            )


def parameter_units(name: str) -> str:
    """Units of a calibration parameter."""
    if name in PRIOR_RULES:
        return PRIOR_RULES[name].units
    return _DESIGN_UNITS.get(name, "1")
