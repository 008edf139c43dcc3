"""Operating points (fixed values and sweeps) and uncertain parameters (intervals, distributions)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from ..common.errors import StudyError, UqgearError, shown
from ..physics.design import STANDARD_GRAVITY, Design, design_key_bounds
from ..uq.parameter_space import ParameterSpace
from ..uq.parameters import Distribution, Interval
from .checkers import Checker, check_mapping, choice, expectation_error, list_of, number, string
from .variables import OPERATING_VARIABLES, VARIABLE_DESIGN_KEYS, VARIABLES, variable_unit, variable_units_short

# ---------------------------------------------------------------------------- value specs


@dataclass(frozen=True)
class ValueSpec:
    """A fixed value or a sweep of an operating variable.

    Attributes
    ----------
    name : str
        The variable (``pinion_speed``, ``k1``, ...).
    values : tuple of float
        The value(s), in the variable's units.
    sweep : bool
        True for a list or a ``{start, stop, num}`` range (a sweep axis),
        False for a scalar.
    """

    name: str
    values: tuple[float, ...]
    sweep: bool

    @property
    def value(self) -> float:
        """The value of a fixed (non-sweep) variable."""
        return self.values[0]


def _value_spec(name: str, raw: Any, path: str) -> ValueSpec:
    unit, lower, upper = OPERATING_VARIABLES.get(name, (variable_unit(name), None, None))
    element = number(unit, lower, upper, lower_open=name == "pinion_speed")
    if isinstance(raw, Mapping):
        spec = check_mapping(
            raw,
            path,
            {
                "start": element,
                "stop": element,
                "num": number("", 1, 10000, integer=True),
                "spacing": choice("linear", "log"),
            },
            required=("start", "stop", "num"),
        )
        if spec.get("spacing") == "log":
            if spec["start"] <= 0 or spec["stop"] <= 0:
                raise StudyError(
                    f"{path}: expected positive start and stop for log spacing; got "
                    f"start {spec['start']:g}, stop {spec['stop']:g}"
                )
            values = np.geomspace(spec["start"], spec["stop"], spec["num"])
        else:
            values = np.linspace(spec["start"], spec["stop"], spec["num"])
        result = ValueSpec(name, tuple(float(v) for v in values), True)
    elif isinstance(raw, list):
        values = list_of(element, unique=True, what="a list of values")(raw, path)
        result = ValueSpec(name, tuple(values), True)
    elif isinstance(raw, (int, float)) and not isinstance(raw, bool):
        result = ValueSpec(name, (element(raw, path),), False)
    else:
        raise expectation_error(path, f"a number, a list of numbers or {{start, stop, num}} in {unit}", raw)
    if name in VARIABLE_DESIGN_KEYS:
        # the design's own plausibility ranges apply to swept design keys
        lower, upper = design_key_bounds(name)
        unit_text = variable_unit(name)
        for value in result.values:
            if not lower <= value <= upper:
                raise StudyError(f"{path}: expected values in [{lower:g}, {upper:g}] {unit_text}; got {shown(value)}")
    return result


def parse_operating_points(raw: Any, path: str) -> dict[str, ValueSpec]:
    """The ``operating_points`` entry at ``path`` as one :class:`ValueSpec` per variable (empty where absent).

    A variable is an operating variable or a batch-variable design key, given as a number, a list of
    numbers or ``{start, stop, num}``; a swept design key must stay inside the design's plausible range.
    Refusals are :class:`StudyError` naming the entry.
    """
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise expectation_error(
            path,
            f"a mapping of variable to value(s) (variables: {', '.join(OPERATING_VARIABLES)} or a design key)",
            raw,
        )
    result = {}
    for name, value in raw.items():
        if name not in VARIABLES:
            raise StudyError(
                f"{path}.{name}: unknown variable; expected one of "
                f"{', '.join(OPERATING_VARIABLES)} or a design key "
                f"({', '.join(VARIABLE_DESIGN_KEYS)})"
            )
        result[name] = _value_spec(name, value, f"{path}.{name}")
    return result


# ---------------------------------------------------------------------------- uncertain parameters

#: Distributions by name: (required, optional) parameters, all in the parameter's units
#: except the lognormal's mu and sigma (of log(x - shift)) and the beta's alpha and beta.
#: They map onto :class:`uqgear.uq.parameters.Distribution`.
DISTRIBUTIONS: dict[str, tuple[tuple[str, ...], tuple[str, ...]]] = {
    "uniform": (("lower", "upper"), ()),
    "normal": (("mu", "sigma"), ()),
    "truncnormal": (("mu", "sigma", "lower", "upper"), ()),
    "lognormal": (("mu", "sigma"), ("shift",)),
    "triangle": (("lower", "mode", "upper"), ()),
    "beta": (("alpha", "beta"), ("lower", "upper")),
    "gamma": (("shape", "scale"), ("shift",)),
    "exponential": (("scale",), ("shift",)),
}


@dataclass(frozen=True)
class UncertainParameter:
    """An uncertain parameter: an interval or a probability distribution.

    Attributes
    ----------
    name : str
        The variable (``adhesion_torque``, ``mesh_stiffness_scale``, a design key).
    kind : {"interval", "distribution"}
    lower, upper : float
        Interval bounds; for a distribution the bounds of its support when
        finite, else NaN.
    distribution : str
        Distribution name (``uniform``, ``normal``, ...); "" for an interval.
    parameters : Mapping
        Distribution parameters by name.
    source : str
        How the interval was obtained (e.g. adhesion coefficient x axle load
        x g x wheel radius), for reports.
    """

    name: str
    kind: str
    lower: float = math.nan
    upper: float = math.nan
    distribution: str = ""
    parameters: Mapping[str, float] = field(default_factory=dict)
    source: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "parameters", MappingProxyType(dict(self.parameters)))

    @property
    def is_interval(self) -> bool:
        return self.kind == "interval"

    def to_parameter(self) -> Interval | Distribution:
        """The parameter as an :mod:`uqgear.uq.parameters` object (units set)."""
        units = variable_units_short(self.name)
        if self.is_interval:
            return Interval(self.lower, self.upper, units=units)
        return Distribution(self.distribution, units=units, **dict(self.parameters))

    @property
    def nominal(self) -> float:
        """Value used where the parameter is not propagated: interval midpoint or distribution median."""
        if self.is_interval:
            return 0.5 * (self.lower + self.upper)
        distribution = self.to_parameter()
        assert isinstance(distribution, Distribution)  # not an interval
        return float(distribution.median())

    def describe(self) -> str:
        """One line for reports, with units."""
        unit = variable_units_short(self.name)
        if self.is_interval:
            text = f"interval [{self.lower:.6g}, {self.upper:.6g}] {unit}"
        else:
            args = ", ".join(f"{key}={value:.6g}" for key, value in self.parameters.items())
            text = f"{self.distribution}({args}) {unit}"
        return text + (f" ({self.source})" if self.source else "")

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "kind": self.kind,
            "lower": self.lower,
            "upper": self.upper,
            "distribution": self.distribution,
            "parameters": dict(self.parameters),
            "source": self.source,
        }


def _bounds(raw: Any, path: str, element: Checker, unit: str) -> tuple[float, float]:
    if not isinstance(raw, list) or len(raw) != 2:
        raise expectation_error(path, f"[lower, upper] in {unit}", raw)
    lower, upper = element(raw[0], f"{path}[0]"), element(raw[1], f"{path}[1]")
    if not lower < upper:
        raise StudyError(f"{path}: expected lower < upper; got [{lower:g}, {upper:g}]")
    return lower, upper


def parse_uncertain_parameter(name: str, raw: Any, path: str, design: Design | None) -> UncertainParameter:
    """The uncertain parameter ``name`` from its entry at ``path``: an interval or a distribution.

    The adhesion torque may instead be given by the adhesion coefficient range, the axle load and the wheel
    radius, with the ``design``'s operation filling what the entry leaves out. Refusals are
    :class:`StudyError` naming the entry.
    """
    unit = variable_unit(name)
    element = number(unit)
    if name == "adhesion_torque" and isinstance(raw, Mapping) and "interval" not in raw and "distribution" not in raw:
        spec = check_mapping(
            raw,
            path,
            {
                "adhesion_coefficient": lambda v, p: _bounds(v, p, number("", 0.0, 1.5), "(adhesion coefficient mu)"),
                # plausible railway values: a load in tonnes or a diameter in mm is caught
                "axle_load": number("kg", 1000.0, 100_000.0),
                "wheel_radius": number("m", 0.2, 1.5),
            },
        )
        operation = design.operation if design is not None else None
        mu = spec.get("adhesion_coefficient", operation.adhesion_coefficient if operation else (0.15, 0.33))
        axle_load = spec.get("axle_load", operation.axle_load if operation else 23000.0)
        wheel_radius = spec.get("wheel_radius", operation.wheel_radius if operation else 0.625)
        if mu[0] >= mu[1]:
            raise StudyError(f"{path}.adhesion_coefficient: expected lower < upper; got [{mu[0]:g}, {mu[1]:g}]")
        force = axle_load * STANDARD_GRAVITY
        return UncertainParameter(
            name,
            "interval",
            lower=mu[0] * force * wheel_radius,
            upper=mu[1] * force * wheel_radius,
            source=(
                f"T2 = mu Q R_w: mu in [{mu[0]:g}, {mu[1]:g}], axle load {axle_load:g} kg x "
                f"g = {force:.6g} N, wheel radius {wheel_radius:g} m"
            ),
        )
    if not isinstance(raw, Mapping):
        raise expectation_error(
            path,
            "a mapping with 'interval: [lower, upper]' or 'distribution: NAME'"
            + (" or adhesion_coefficient/axle_load/wheel_radius" if name == "adhesion_torque" else ""),
            raw,
        )
    if "interval" in raw:
        spec = check_mapping(raw, path, {"interval": lambda v, p: _bounds(v, p, element, unit)}, required=("interval",))
        lower, upper = spec["interval"]
        return UncertainParameter(name, "interval", lower=lower, upper=upper, source="given")
    if "distribution" in raw:
        distribution = raw["distribution"]
        choice(*DISTRIBUTIONS)(distribution, f"{path}.distribution")
        required, optional = DISTRIBUTIONS[distribution]
        schema: dict[str, Checker] = {"distribution": string()}
        schema.update(dict.fromkeys(required + optional, element))
        spec = check_mapping(raw, path, schema, required=required)
        parameters = {key: value for key, value in spec.items() if key != "distribution"}
        try:
            built = Distribution(distribution, units=variable_units_short(name), **parameters)
            lower, upper = ParameterSpace({name: built}).bounds(name)
        except UqgearError as exc:
            raise StudyError(f"{path}: {exc}") from None
        return UncertainParameter(
            name, "distribution", lower=lower, upper=upper, distribution=distribution, parameters=dict(built.params)
        )
    expected = "'interval: [lower, upper]' or 'distribution: NAME'"
    if name == "adhesion_torque":
        expected += " or adhesion_coefficient/axle_load/wheel_radius"
    raise StudyError(f"{path}: expected {expected}; got keys {', '.join(map(str, raw)) or 'none'}")


def check_parameter_range(parameter: UncertainParameter, path: str) -> None:
    """Bounds of an uncertain design key or operating variable must be physically plausible."""
    if parameter.name in VARIABLE_DESIGN_KEYS:
        lower, upper = design_key_bounds(parameter.name)
        unit = variable_unit(parameter.name)
    elif parameter.name in OPERATING_VARIABLES:
        unit, lower, upper = OPERATING_VARIABLES[parameter.name]
    else:  # pragma: no cover - names are checked before
        return
    if parameter.is_interval:
        if not (lower <= parameter.lower and parameter.upper <= upper):
            raise StudyError(
                f"{path}: expected bounds in [{lower:g}, {upper:g}] {unit}; "
                f"got [{parameter.lower:g}, {parameter.upper:g}]"
            )
        return
    # a distribution's tails may reach implausible values (a normal damping ratio below 0)
    # with negligible probability; its central 99.8 % must be plausible
    distribution = parameter.to_parameter()
    assert isinstance(distribution, Distribution)  # not an interval
    chaospy_distribution = distribution.to_chaospy()
    low, high = (float(chaospy_distribution.inv(q)) for q in (0.001, 0.999))
    if not (lower <= low and high <= upper):
        raise StudyError(
            f"{path}: expected a distribution whose 0.1 % to 99.9 % quantiles lie in "
            f"[{lower:g}, {upper:g}] {unit}; got [{low:.6g}, {high:.6g}]"
        )
