"""Study definitions: the YAML schema, its validation and loading.

A study says what to run: the design (with overrides), the operating points
and sweeps, the uncertain parameters, the analyses, the seed, the simulation
settings and the outputs. :func:`load_study` reads a YAML file and validates
it completely before anything runs; every problem raises
:class:`~uqgear.errors.StudyError` whose message starts with the key path and
says what was expected, e.g.::

    analyses[2].method: expected one of scan, vertex, chebyshev, optimize; got 'chebychev'

The reference of every key with its units is ``docs/study-reference.md``.

Adding an analysis type takes one entry in :data:`ANALYSIS_SCHEMAS` (its keys
and their checks) and one function registered in :mod:`uqgear.analyses`.

This module imports no physics beyond the design loader, so validating a
study is fast.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from .design import _DESIGN_KEYS, STANDARD_GRAVITY, Design, load_design
from .effects import EFFECTS
from .errors import StudyError, UqgearError
from .uncertainty import Distribution, Interval, ParameterSpace
from .yamlio import YAMLError, load_yaml

# ---------------------------------------------------------------------------- vocabulary

#: Operating variables a study may fix or sweep, with units and plausible ranges.
#: Design keys (bearing stiffness, backlash, ...) may be swept or made uncertain too.
OPERATING_VARIABLES: dict[str, tuple[str, float, float]] = {
    "pinion_speed": ("rpm", 0.0, 1e5),
    "drive_torque": ("N m", -1e7, 1e7),
    "adhesion_torque": ("N m", -1e7, 1e7),
    "mesh_stiffness_scale": ("1 (factor on the Ishikawa mesh stiffness)", 1e-3, 100.0),
}
#: Design keys that may vary between the runs of one batch (the tooth counts may not).
VARIABLE_DESIGN_KEYS: tuple[str, ...] = tuple(key for key in _DESIGN_KEYS if key not in ("z1", "z2"))
#: Every name an operating point, sweep or uncertain parameter may use.
VARIABLES: tuple[str, ...] = tuple(OPERATING_VARIABLES) + VARIABLE_DESIGN_KEYS

#: Scalar quantities of interest of a simulation run (see uqgear.integration.QOI_INFO).
QOIS: tuple[str, ...] = (
    "dte_mean", "dte_rms", "dte_peak_to_peak", "dynamic_load_factor", "acc_pinion_rms",
    "acc_gear_rms", "fraction_drive_contact", "fraction_separation", "fraction_back_contact",
    "largest_lyapunov",
)
DEFAULT_QOIS: tuple[str, ...] = ("dte_rms", "dynamic_load_factor", "fraction_separation")

INTERVAL_METHODS: tuple[str, ...] = ("scan", "vertex", "chebyshev", "optimize")
INTERVAL_FALLBACKS: tuple[str, ...] = ("scan", "optimize", "none")
SAMPLING_METHODS: tuple[str, ...] = ("monte_carlo", "latin_hypercube", "sobol", "halton")
#: Distributions by name: (required, optional) parameters, all in the parameter's units
#: except the lognormal's mu and sigma (of log(x - shift)) and the beta's alpha and beta.
#: They map onto :class:`uqgear.uncertainty.Distribution`.
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
_NAME_PATTERN = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")


def variable_unit(name: str) -> str:
    """Unit text of an operating variable or design key."""
    if name in OPERATING_VARIABLES:
        return OPERATING_VARIABLES[name][0]
    if name in _DESIGN_KEYS:
        return _DESIGN_KEYS[name][2]
    return ""


def variable_units_short(name: str) -> str:
    """A short unit for axis labels (``rpm``, ``N m``, ``N/m``, ``1``)."""
    unit = variable_unit(name)
    short = unit.split(" (")[0].split(",")[0].strip()
    if name in ("zeta1", "zeta2", "zeta_mesh", "poisson_ratio", "x1", "x2",
                "addendum_coefficient", "dedendum_coefficient"):
        return "1"
    return short or "1"


# ---------------------------------------------------------------------------- checkers

Checker = Callable[[Any, str], Any]


def _fail(path: str, expected: str, value: Any) -> StudyError:
    shown = repr(value)
    if len(shown) > 80:
        shown = shown[:77] + "..."
    return StudyError(f"{path}: expected {expected}; got {shown}")


def _type_name(value: Any) -> str:
    return "a mapping" if isinstance(value, Mapping) else (
        "a list" if isinstance(value, list) else repr(value))


def number(unit: str = "", lower: float | None = None, upper: float | None = None, *,
           integer: bool = False, lower_open: bool = False) -> Checker:
    """Checker of a finite number (optionally an integer) in a range."""
    kind = "an integer" if integer else "a number"
    if lower is not None and upper is not None:
        left = "(" if lower_open else "["
        expected = f"{kind} in {left}{lower:g}, {upper:g}]"
    elif lower is not None:
        expected = f"{kind} {'>' if lower_open else '>='} {lower:g}"
    else:
        expected = kind
    if unit:
        expected += f" {unit}"

    def check(value: Any, path: str) -> float | int:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise _fail(path, expected, value)
        if not math.isfinite(value):
            raise _fail(path, expected, value)
        if integer:
            if float(value) != int(value):
                raise _fail(path, expected, value)
            value = int(value)
        else:
            value = float(value)
        if lower is not None and (value < lower or (lower_open and value == lower)):
            raise _fail(path, expected, value)
        if upper is not None and value > upper:
            raise _fail(path, expected, value)
        return value

    check.expected = expected  # type: ignore[attr-defined]
    return check


def choice(*options: str) -> Checker:
    """Checker of one string among ``options``."""
    expected = f"one of {', '.join(options)}"

    def check(value: Any, path: str) -> str:
        if not isinstance(value, str) or value not in options:
            raise _fail(path, expected, value)
        return value

    return check


def boolean() -> Checker:
    """Checker of true/false."""
    def check(value: Any, path: str) -> bool:
        if not isinstance(value, bool):
            raise _fail(path, "true or false", value)
        return value

    return check


def string() -> Checker:
    """Checker of a string."""
    def check(value: Any, path: str) -> str:
        if not isinstance(value, str):
            raise _fail(path, "a string", value)
        return value

    return check


def identifier() -> Checker:
    """Checker of a name usable as a file name (letters, digits, _ and -)."""
    def check(value: Any, path: str) -> str:
        if not isinstance(value, str) or not _NAME_PATTERN.match(value):
            raise _fail(path, "a name of letters, digits, '_' and '-' starting with a letter", value)
        return value

    return check


def list_of(item: Checker, *, min_length: int = 1, unique: bool = False,
            what: str = "a list") -> Checker:
    """Checker of a list whose items pass ``item``; a single item is accepted as a list of one."""
    def check(value: Any, path: str) -> tuple:
        items = value if isinstance(value, list) else [value]
        if isinstance(value, (Mapping, tuple)) or value is None:
            raise _fail(path, what, value)
        checked = tuple(item(entry, f"{path}[{index}]") for index, entry in enumerate(items))
        if len(checked) < min_length:
            raise _fail(path, f"{what} of at least {min_length} item(s)", value)
        if unique and len(set(checked)) != len(checked):
            repeated = next(entry for entry in checked if checked.count(entry) > 1)
            raise StudyError(f"{path}: expected distinct entries; {repeated!r} is repeated")
        return checked

    return check


def check_mapping(value: Any, path: str, schema: Mapping[str, Checker], *,
                  required: Sequence[str] = ()) -> dict[str, Any]:
    """Validate a mapping against ``schema``: unknown keys, missing keys, each value."""
    where = path or "study"
    if not isinstance(value, Mapping):
        raise StudyError(f"{where}: expected a mapping with keys {', '.join(schema)}; got "
                         f"{_type_name(value)}")
    prefix = f"{path}." if path else ""
    for key in value:
        if not isinstance(key, str) or key not in schema:
            raise StudyError(f"{prefix}{key}: unknown key; expected one of {', '.join(schema)}")
    for key in required:
        if key not in value:
            raise StudyError(f"{prefix}{key}: missing (required)")
    return {key: schema[key](entry, f"{prefix}{key}") for key, entry in value.items()}


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
        spec = check_mapping(raw, path, {"start": element, "stop": element,
                                         "num": number("", 1, 10000, integer=True),
                                         "spacing": choice("linear", "log")},
                             required=("start", "stop", "num"))
        if spec.get("spacing") == "log":
            if spec["start"] <= 0 or spec["stop"] <= 0:
                raise StudyError(f"{path}: expected positive start and stop for log spacing; got "
                                 f"start {spec['start']:g}, stop {spec['stop']:g}")
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
        raise _fail(path, f"a number, a list of numbers or {{start, stop, num}} in {unit}", raw)
    if name in VARIABLE_DESIGN_KEYS:
        # the design's own plausibility ranges apply to swept design keys
        lower, upper, unit_text, _ = _DESIGN_KEYS[name]
        for value in result.values:
            if not lower <= value <= upper:
                raise StudyError(f"{path}: expected values in [{lower:g}, {upper:g}] {unit_text}; "
                                 f"got {value!r}")
    return result


def _operating_points(raw: Any, path: str) -> dict[str, ValueSpec]:
    if raw is None:
        return {}
    if not isinstance(raw, Mapping):
        raise _fail(path, f"a mapping of variable to value(s) (variables: {', '.join(OPERATING_VARIABLES)} "
                          "or a design key)", raw)
    result = {}
    for name, value in raw.items():
        if name not in VARIABLES:
            raise StudyError(f"{path}.{name}: unknown variable; expected one of "
                             f"{', '.join(OPERATING_VARIABLES)} or a design key "
                             f"({', '.join(VARIABLE_DESIGN_KEYS)})")
        result[name] = _value_spec(name, value, f"{path}.{name}")
    return result


# ---------------------------------------------------------------------------- uncertain parameters

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
        """The parameter as an :mod:`uqgear.uncertainty` object (units set)."""
        units = variable_units_short(self.name)
        if self.is_interval:
            return Interval(self.lower, self.upper, units=units)
        return Distribution(self.distribution, units=units, **dict(self.parameters))

    @property
    def nominal(self) -> float:
        """Value used where the parameter is not propagated: interval midpoint or distribution median."""
        if self.is_interval:
            return 0.5 * (self.lower + self.upper)
        return float(self.to_parameter().median())

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
        return {"name": self.name, "kind": self.kind, "lower": self.lower, "upper": self.upper,
                "distribution": self.distribution, "parameters": dict(self.parameters),
                "source": self.source}


def _bounds(raw: Any, path: str, element: Checker, unit: str) -> tuple[float, float]:
    if not isinstance(raw, list) or len(raw) != 2:
        raise _fail(path, f"[lower, upper] in {unit}", raw)
    lower, upper = element(raw[0], f"{path}[0]"), element(raw[1], f"{path}[1]")
    if not lower < upper:
        raise StudyError(f"{path}: expected lower < upper; got [{lower:g}, {upper:g}]")
    return lower, upper


def _uncertain_parameter(name: str, raw: Any, path: str, design: Design | None) -> UncertainParameter:
    unit = variable_unit(name)
    element = number(unit)
    if name == "adhesion_torque" and isinstance(raw, Mapping) and "interval" not in raw \
            and "distribution" not in raw:
        spec = check_mapping(raw, path, {
            "adhesion_coefficient": lambda v, p: _bounds(v, p, number("", 0.0, 1.5), "(adhesion coefficient mu)"),
            # plausible railway values: a load in tonnes or a diameter in mm is caught
            "axle_load": number("kg", 1000.0, 100_000.0),
            "wheel_radius": number("m", 0.2, 1.5),
        })
        operation = design.operation if design is not None else None
        mu = spec.get("adhesion_coefficient", operation.adhesion_coefficient if operation else (0.15, 0.33))
        axle_load = spec.get("axle_load", operation.axle_load if operation else 23000.0)
        wheel_radius = spec.get("wheel_radius", operation.wheel_radius if operation else 0.625)
        if mu[0] >= mu[1]:
            raise StudyError(f"{path}.adhesion_coefficient: expected lower < upper; got "
                             f"[{mu[0]:g}, {mu[1]:g}]")
        force = axle_load * STANDARD_GRAVITY
        return UncertainParameter(
            name, "interval", lower=mu[0] * force * wheel_radius, upper=mu[1] * force * wheel_radius,
            source=(f"T2 = mu Q R_w: mu in [{mu[0]:g}, {mu[1]:g}], axle load {axle_load:g} kg x "
                    f"g = {force:.6g} N, wheel radius {wheel_radius:g} m"))
    if not isinstance(raw, Mapping):
        raise _fail(path, "a mapping with 'interval: [lower, upper]' or 'distribution: NAME'"
                    + (" or adhesion_coefficient/axle_load/wheel_radius" if name == "adhesion_torque" else ""),
                    raw)
    if "interval" in raw:
        spec = check_mapping(raw, path, {"interval": lambda v, p: _bounds(v, p, element, unit)},
                             required=("interval",))
        lower, upper = spec["interval"]
        return UncertainParameter(name, "interval", lower=lower, upper=upper, source="given")
    if "distribution" in raw:
        distribution = raw["distribution"]
        choice(*DISTRIBUTIONS)(distribution, f"{path}.distribution")
        required, optional = DISTRIBUTIONS[distribution]
        schema: dict[str, Checker] = {"distribution": string()}
        schema.update({key: element for key in required + optional})
        spec = check_mapping(raw, path, schema, required=required)
        parameters = {key: value for key, value in spec.items() if key != "distribution"}
        try:
            built = Distribution(distribution, units=variable_units_short(name), **parameters)
            lower, upper = ParameterSpace({name: built}).bounds(name)
        except UqgearError as exc:
            raise StudyError(f"{path}: {exc}") from None
        return UncertainParameter(name, "distribution", lower=lower, upper=upper,
                                  distribution=distribution, parameters=dict(built.params))
    expected = "'interval: [lower, upper]' or 'distribution: NAME'"
    if name == "adhesion_torque":
        expected += " or adhesion_coefficient/axle_load/wheel_radius"
    raise StudyError(f"{path}: expected {expected}; got keys {', '.join(map(str, raw)) or 'none'}")


def _check_parameter_range(parameter: UncertainParameter, path: str) -> None:
    """Bounds of an uncertain design key or operating variable must be physically plausible."""
    if parameter.name in VARIABLE_DESIGN_KEYS:
        lower, upper, unit, _ = _DESIGN_KEYS[parameter.name]
    elif parameter.name in OPERATING_VARIABLES:
        unit, lower, upper = OPERATING_VARIABLES[parameter.name]
    else:  # pragma: no cover - names are checked before
        return
    if parameter.is_interval:
        if not (lower <= parameter.lower and parameter.upper <= upper):
            raise StudyError(f"{path}: expected bounds in [{lower:g}, {upper:g}] {unit}; "
                             f"got [{parameter.lower:g}, {parameter.upper:g}]")
        return
    # a distribution's tails may reach implausible values (a normal damping ratio below 0)
    # with negligible probability; its central 99.8 % must be plausible
    chaospy_distribution = parameter.to_parameter().to_chaospy()
    low, high = (float(chaospy_distribution.inv(q)) for q in (0.001, 0.999))
    if not (lower <= low and high <= upper):
        raise StudyError(f"{path}: expected a distribution whose 0.1 % to 99.9 % quantiles lie in "
                         f"[{lower:g}, {upper:g}] {unit}; got [{low:.6g}, {high:.6g}]")


# ---------------------------------------------------------------------------- simulation settings

@dataclass(frozen=True)
class SimulationSettings:
    """How each operating point is simulated (see :func:`uqgear.integration.simulate_batch`).

    Attributes
    ----------
    n_periods, keep_periods : int
        Mesh periods integrated, and kept at the end for QoIs and the
        Poincare section (the rest is the transient).
    lyapunov : bool
        Also estimate the largest Lyapunov exponent (about doubles the cost);
        it decides chaotic against quasi-periodic in classifications.
    steps_per_mode : int
        RK4 steps per period of the highest natural frequency.
    damping_in_separation : bool
        Mesh damping acts while the teeth are apart (the classical form).
    stiffness : {"ishikawa", "fourier"}
        Raw Ishikawa stiffness curve or its truncated Fourier series.
    """

    n_periods: int = 400
    keep_periods: int = 200
    lyapunov: bool = False
    steps_per_mode: int = 32
    damping_in_separation: bool = True
    stiffness: str = "ishikawa"

    def to_dict(self) -> dict[str, Any]:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}


_SIMULATION_SCHEMA: dict[str, Checker] = {
    "n_periods": number("mesh periods", 2, 1_000_000, integer=True),
    "keep_periods": number("mesh periods", 20, 1_000_000, integer=True),
    "lyapunov": boolean(),
    "steps_per_mode": number("steps", 8, 4096, integer=True),
    "damping_in_separation": boolean(),
    "stiffness": choice("ishikawa", "fourier"),
}


def _simulation(raw: Any, path: str, base: SimulationSettings) -> SimulationSettings:
    if raw is None:
        return base
    values = base.to_dict()
    values.update(check_mapping(raw, path, _SIMULATION_SCHEMA))
    settings = SimulationSettings(**values)
    if settings.keep_periods > settings.n_periods:
        raise StudyError(f"{path}.keep_periods: expected at most n_periods ({settings.n_periods}); "
                         f"got {settings.keep_periods}")
    return settings


# ---------------------------------------------------------------------------- analyses

def _qoi_list() -> Checker:
    return list_of(choice(*QOIS), unique=True, what="a list of QoI names")


def _variable_list() -> Checker:
    return list_of(choice(*VARIABLES), unique=True, what="a list of parameter names")


_COMMON_KEYS: dict[str, Checker] = {
    "type": string(),
    "name": identifier(),
    "description": string(),
    # merged over the study's operating_points and simulation
    "operating_points": lambda value, path: value,
    "simulation": lambda value, path: value,
}

#: Keys (with checks) of each analysis type, besides ``type``, ``name``,
#: ``description``, ``operating_points`` and ``simulation``.
ANALYSIS_SCHEMAS: dict[str, dict[str, Checker]] = {
    "simulate": {
        "samples_per_period": number("samples per mesh period", 8, 1024, integer=True),
        "method": choice("fast", "scipy"),
        "spectrum": choice("order", "frequency"),
        "labels": list_of(string(), what="a list of labels"),
    },
    "bifurcation": {
        "parameter": choice(*VARIABLES),
        "envelope": _variable_list(),
        "points": number("values across each interval", 2, 200, integer=True),
    },
    "regime_map": {
        "axes": list_of(choice(*VARIABLES), min_length=2, unique=True, what="a list of two variable names"),
        "points": number("values across each interval", 2, 200, integer=True),
    },
    "interval": {
        "parameters": _variable_list(),
        "method": choice(*INTERVAL_METHODS),
        "order": number("(Chebyshev series order)", 1, 20, integer=True),
        "points": number("(scan points per interval parameter)", 2, 1000, integer=True),
        "fallback": choice(*INTERVAL_FALLBACKS),
        "tolerance": number("(relative surrogate error accepted)", 0.0, 1.0, lower_open=True),
        "qois": _qoi_list(),
    },
    "monte_carlo": {
        "parameters": _variable_list(),
        "intervals": choice("uniform", "pbox"),
        "points": number("(scan points per interval parameter, p-box)", 2, 101, integer=True),
        "samples": number("samples", 2, 10_000_000, integer=True),
        "sampling": choice(*SAMPLING_METHODS),
        "quantiles": list_of(number("", 0.0, 1.0), unique=True, what="a list of probabilities"),
        "qois": _qoi_list(),
    },
    "pce": {
        "parameters": _variable_list(),
        "order": number("(highest total polynomial degree tried)", 1, 12, integer=True),
        "min_order": number("(lowest total polynomial degree tried)", 1, 12, integer=True),
        "samples": number("training samples", 2, 1_000_000, integer=True),
        "validation_samples": number("check samples", 2, 1_000_000, integer=True),
        "sampling": choice(*SAMPLING_METHODS),
        "qois": _qoi_list(),
    },
    "sobol": {
        "parameters": _variable_list(),
        "samples": number("base samples N (a power of 2)", 8, 1_048_576, integer=True),
        "second_order": boolean(),
        "confidence_level": number("", 0.5, 0.999),
        "bootstrap": number("resamples", 10, 100_000, integer=True),
        "qois": _qoi_list(),
    },
    "calibrate": {
        "rig": string(),
        "parameters": list_of(choice("mesh_stiffness_scale", "zeta_mesh", "backlash", "ste_amplitude", "k1", "k2",
                                     "k1_scale", "k2_scale", "zeta1", "zeta2", "m1", "m2"), unique=True),
    },
    "diagnose": {
        "rig": string(),
        "effects": list_of(choice(*EFFECTS), unique=True),
    },
}

#: Default option values per analysis type (applied after validation).
ANALYSIS_DEFAULTS: dict[str, dict[str, Any]] = {
    "simulate": {"samples_per_period": 64, "method": "fast", "spectrum": "order", "labels": ()},
    "bifurcation": {"envelope": (), "points": 5},
    "regime_map": {"points": 9},
    "interval": {"method": "chebyshev", "order": 6, "points": None, "fallback": "scan",
                 "tolerance": 0.02, "qois": DEFAULT_QOIS},
    "monte_carlo": {"intervals": "uniform", "points": 5, "samples": 256, "sampling": "latin_hypercube",
                    "quantiles": (0.05, 0.5, 0.95),
                    "qois": DEFAULT_QOIS},
    "pce": {"order": 3, "min_order": 1, "samples": 0, "validation_samples": 32, "sampling": "halton",
            "qois": DEFAULT_QOIS},
    "sobol": {"samples": 64, "second_order": False, "confidence_level": 0.95, "bootstrap": 200,
              "qois": DEFAULT_QOIS},
    "calibrate": {"parameters": ("mesh_stiffness_scale", "zeta_mesh", "backlash", "ste_amplitude", "k1", "k2")},
    "diagnose": {"effects": tuple(EFFECTS)},
}
_REQUIRED_KEYS: dict[str, tuple[str, ...]] = {"bifurcation": ("parameter",), "regime_map": ("axes",),
                                              "calibrate": ("rig",), "diagnose": ("rig",)}
#: Analysis types that read a rig data file (key ``rig``, relative to the study file).
RIG_TYPES: tuple[str, ...] = ("calibrate", "diagnose")
#: Analysis types that propagate uncertain parameters (``parameters`` key).
PROPAGATING_TYPES: tuple[str, ...] = ("interval", "monte_carlo", "pce", "sobol")
#: Cap on single simulate() runs in one ``simulate`` analysis (they keep full histories).
MAX_SIMULATE_RUNS = 64


@dataclass(frozen=True)
class AnalysisSpec:
    """One validated analysis of a study.

    Attributes
    ----------
    index : int
        Position in the study's ``analyses`` list (also its seed stream).
    type, name : str
        Analysis type and its (unique) name; results go to ``<name>.nc``.
    description : str
    options : Mapping
        Type-specific options with defaults filled in.
    operating_points : Mapping of str to ValueSpec
        Study operating points with this analysis's overrides merged in.
    simulation : SimulationSettings
        Study settings with this analysis's overrides merged in.
    raw : Mapping
        The analysis entry as written (for checkpoint keys).
    """

    index: int
    type: str
    name: str
    description: str
    options: Mapping[str, Any]
    operating_points: Mapping[str, ValueSpec]
    simulation: SimulationSettings
    raw: Mapping[str, Any]

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))
        object.__setattr__(self, "operating_points", MappingProxyType(dict(self.operating_points)))

    @property
    def sweeps(self) -> dict[str, ValueSpec]:
        """Operating variables swept in this analysis, in order."""
        return {name: spec for name, spec in self.operating_points.items() if spec.sweep}

    @property
    def fixed(self) -> dict[str, float]:
        """Operating variables held at one value."""
        return {name: spec.value for name, spec in self.operating_points.items() if not spec.sweep}


# ---------------------------------------------------------------------------- the study

@dataclass(frozen=True)
class Outputs:
    """What a run writes besides one netCDF file per analysis.

    Attributes
    ----------
    report : bool
        Write ``report.html``.
    dpi : int
        Resolution of the report's figures, dots per inch.
    """

    report: bool = True
    dpi: int = 110


@dataclass(frozen=True)
class Study:
    """A validated study (see :func:`load_study`)."""

    name: str
    description: str
    seed: int
    design: Design
    design_source: str
    design_overrides: Mapping[str, Any]
    operating_points: Mapping[str, ValueSpec]
    uncertain: Mapping[str, UncertainParameter]
    simulation: SimulationSettings
    analyses: tuple[AnalysisSpec, ...]
    outputs: Outputs
    chunk_size: int
    text: str
    path: str = ""

    def __post_init__(self) -> None:
        for name in ("design_overrides", "operating_points", "uncertain"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))

    def seed_sequences(self) -> list[np.random.SeedSequence]:
        """One independent SeedSequence per analysis, spawned from the study seed in list order."""
        return np.random.SeedSequence(self.seed).spawn(len(self.analyses))

    def analysis(self, name: str) -> AnalysisSpec:
        for spec in self.analyses:
            if spec.name == name:
                return spec
        raise StudyError(f"analysis {name!r}: not in the study; expected one of "
                         f"{', '.join(spec.name for spec in self.analyses)}")


def _resolve(path: str, base_dir: Path | None) -> Path:
    candidate = Path(path)
    return candidate if candidate.is_absolute() or base_dir is None else base_dir / candidate


def rig_path(study: "Study", spec: "AnalysisSpec") -> Path:
    """The rig file of a ``calibrate``/``diagnose`` analysis, relative to the study file's folder."""
    return _resolve(spec.options["rig"], Path(study.path).parent if study.path else None)


_TOP_LEVEL_KEYS = ("name", "description", "seed", "design", "operating_points", "uncertain",
                   "simulation", "analyses", "outputs", "execution")


def _design(raw: Any, base_dir: Path | None) -> tuple[Design, str, dict[str, Any]]:
    if raw is None:
        raw = "locomotive"
    if isinstance(raw, str):
        spec = {"name": raw}
    elif isinstance(raw, Mapping):
        spec = check_mapping(raw, "design", {"name": string(), "path": string(),
                                             "overrides": lambda v, p: v})
    else:
        raise _fail("design", "a bundled design name, or a mapping with name or path and overrides", raw)
    if ("name" in spec) == ("path" in spec):
        raise StudyError("design: expected exactly one of name (a bundled design or a file) and path")
    overrides = spec.get("overrides") or {}
    if not isinstance(overrides, Mapping):
        raise _fail("design.overrides", "a mapping of design keys to values", overrides)
    for key, value in overrides.items():
        if key not in _DESIGN_KEYS and key != "motor_pole_pairs":
            raise StudyError(f"design.overrides.{key}: unknown design key; expected one of "
                             f"{', '.join(_DESIGN_KEYS)}")
    source = spec.get("path", spec.get("name"))
    location: str | Path = source
    candidate = Path(source)
    if "path" in spec or candidate.suffix:
        if not candidate.is_absolute() and base_dir is not None:
            candidate = base_dir / candidate
        location = candidate
    try:
        design = load_design(location)
    except UqgearError as exc:
        raise StudyError(f"design: {exc}") from None
    try:
        design = design.replace(**dict(overrides)) if overrides else design
    except UqgearError as exc:
        raise StudyError(f"design.overrides.{exc}") from None
    return design, str(source), dict(overrides)


def _check_analysis_variables(spec: AnalysisSpec, uncertain: Mapping[str, UncertainParameter],
                              path: str) -> None:
    options = spec.options
    intervals = [name for name, parameter in uncertain.items() if parameter.is_interval]

    def axis_ok(name: str, key: str) -> None:
        if name in spec.operating_points:
            if not spec.operating_points[name].sweep:
                raise StudyError(f"{path}.{key}: {name} is fixed in operating_points; expected a sweep "
                                 "(a list or {start, stop, num}) or an uncertain interval parameter")
        elif name not in intervals:
            raise StudyError(f"{path}.{key}: {name} is neither swept in operating_points nor an "
                             "uncertain interval parameter; expected one of "
                             f"{', '.join(list(spec.sweeps) + intervals) or '(none defined)'}")

    if spec.type == "bifurcation":
        axis_ok(options["parameter"], "parameter")
        others = [name for name in spec.sweeps if name != options["parameter"]]
        if others:
            raise StudyError(f"{path}.operating_points.{others[0]}: a bifurcation sweeps only its "
                             f"parameter ({options['parameter']}); expected a single value")
        for name in options["envelope"]:
            if name not in intervals:
                raise StudyError(f"{path}.envelope: {name} is not an uncertain interval parameter; "
                                 f"expected one of {', '.join(intervals) or '(none defined)'}")
            if name == options["parameter"] or name in spec.operating_points:
                raise StudyError(f"{path}.envelope: {name} is also the swept parameter or fixed in "
                                 "operating_points; give it in one place")
    elif spec.type == "regime_map":
        if len(options["axes"]) != 2:
            raise StudyError(f"{path}.axes: expected exactly two variable names; got {len(options['axes'])}")
        for name in options["axes"]:
            axis_ok(name, "axes")
        others = [name for name in spec.sweeps if name not in options["axes"]]
        if others:
            raise StudyError(f"{path}.operating_points.{others[0]}: a regime map sweeps only its axes "
                             f"({', '.join(options['axes'])}); expected a single value")
    elif spec.type in PROPAGATING_TYPES:
        parameters = options["parameters"]
        for name in parameters:
            if name not in uncertain:
                raise StudyError(f"{path}.parameters: {name} is not an uncertain parameter; expected "
                                 f"one of {', '.join(uncertain) or '(none defined in uncertain)'}")
            if name in spec.operating_points:
                raise StudyError(f"{path}.parameters: {name} is also given in operating_points; "
                                 "give it in one place")
        if spec.type == "interval":
            bad = [name for name in parameters if not uncertain[name].is_interval]
            if bad:
                raise StudyError(f"{path}.parameters: {bad[0]} has a distribution; an interval "
                                 "analysis expects interval parameters")
        if spec.type == "sobol":
            samples = options["samples"]
            if samples & (samples - 1):
                raise StudyError(f"{path}.samples: expected a power of 2 (Sobol' sequence "
                                 f"balance); got {samples}")
        if spec.type == "monte_carlo" and options["intervals"] == "pbox":
            kinds = {uncertain[name].is_interval for name in parameters}
            if kinds != {True, False}:
                raise StudyError(f"{path}.intervals: 'pbox' bounds statistics over interval parameters of "
                                 "the random ones; expected both interval and distribution parameters "
                                 f"among parameters ({', '.join(parameters)})")
        if spec.type == "monte_carlo" and options["sampling"] == "sobol" \
                and options["samples"] & (options["samples"] - 1):
            raise StudyError(f"{path}.samples: expected a power of 2 with sampling 'sobol'; "
                             f"got {options['samples']}")
        if spec.type == "pce":
            if options["min_order"] > options["order"]:
                raise StudyError(f"{path}.min_order: expected at most order ({options['order']}); "
                                 f"got {options['min_order']}")
            needed = math.comb(len(parameters) + options["min_order"], options["min_order"]) + 2
            if options["samples"] and options["samples"] < needed:
                raise StudyError(f"{path}.samples: expected at least {needed} training samples for order "
                                 f"{options['min_order']} in {len(parameters)} parameter(s); "
                                 f"got {options['samples']}")
    elif spec.type == "simulate":
        count = int(np.prod([len(s.values) for s in spec.sweeps.values()])) if spec.sweeps else 1
        if count > MAX_SIMULATE_RUNS:
            raise StudyError(f"{path}.operating_points: expected at most {MAX_SIMULATE_RUNS} runs "
                             f"for a simulate analysis (each keeps full histories); the sweeps give {count}")
        labels = options["labels"]
        if labels and len(labels) != count:
            raise StudyError(f"{path}.labels: expected one label per run ({count}); got {len(labels)}")


def _analysis(raw: Any, index: int, study_points: Mapping[str, ValueSpec],
              study_simulation: SimulationSettings, uncertain: Mapping[str, UncertainParameter]) -> AnalysisSpec:
    path = f"analyses[{index}]"
    if not isinstance(raw, Mapping):
        raise _fail(path, "a mapping with a 'type' key", raw)
    if "type" not in raw:
        raise StudyError(f"{path}.type: missing; expected one of {', '.join(ANALYSIS_SCHEMAS)}")
    kind = choice(*ANALYSIS_SCHEMAS)(raw["type"], f"{path}.type")
    schema = {**_COMMON_KEYS, **ANALYSIS_SCHEMAS[kind]}
    values = check_mapping(raw, path, schema, required=_REQUIRED_KEYS.get(kind, ()))
    options = dict(ANALYSIS_DEFAULTS[kind])
    options.update({key: value for key, value in values.items() if key not in _COMMON_KEYS})
    if kind in PROPAGATING_TYPES and "parameters" not in options:
        overridden = _operating_points(raw.get("operating_points"), f"{path}.operating_points")
        options["parameters"] = tuple(
            name for name, parameter in uncertain.items()
            if name not in overridden and (parameter.is_interval or kind != "interval"))
        if not options["parameters"]:
            raise StudyError(f"{path}.parameters: no uncertain parameters to propagate; define some "
                             "under 'uncertain'")
    points = dict(study_points)
    points.update(_operating_points(raw.get("operating_points"), f"{path}.operating_points"))
    simulation = _simulation(raw.get("simulation"), f"{path}.simulation", study_simulation)
    spec = AnalysisSpec(index=index, type=kind, name=values.get("name", kind),
                        description=values.get("description", ""), options=options,
                        operating_points=points, simulation=simulation, raw=dict(raw))
    _check_analysis_variables(spec, uncertain, path)
    return spec


def study_from_mapping(raw: Any, *, text: str = "", path: str = "",
                       base_dir: str | Path | None = None) -> Study:
    """Validate a parsed study mapping and build a :class:`Study`.

    Parameters
    ----------
    raw : mapping
        The parsed YAML.
    text : str
        The YAML text (kept for provenance).
    path : str
        The study file, for messages and reports.
    base_dir : str or Path, optional
        Folder against which a relative design path is resolved.

    Raises
    ------
    StudyError
        The first problem found, with its key path.
    """
    if not isinstance(raw, Mapping):
        raise StudyError(f"study: expected a mapping with keys {', '.join(_TOP_LEVEL_KEYS)}; got "
                         f"{_type_name(raw)}")
    for key in raw:
        if key not in _TOP_LEVEL_KEYS:
            raise StudyError(f"{key}: unknown key; expected one of {', '.join(_TOP_LEVEL_KEYS)}")
    if "analyses" not in raw:
        raise StudyError("analyses: missing (required); expected a list of analyses")
    name = identifier()(raw.get("name", Path(path).stem if path else "study"), "name")
    description = string()(raw.get("description", ""), "description")
    seed = number("", 0, 2**63 - 1, integer=True)(raw.get("seed", 0), "seed")
    design, design_source, overrides = _design(raw.get("design"), Path(base_dir) if base_dir else None)
    points = _operating_points(raw.get("operating_points"), "operating_points")
    uncertain_raw = raw.get("uncertain") or {}
    if not isinstance(uncertain_raw, Mapping):
        raise _fail("uncertain", "a mapping of parameter name to its interval or distribution", uncertain_raw)
    uncertain = {}
    for key, entry in uncertain_raw.items():
        if key not in VARIABLES:
            raise StudyError(f"uncertain.{key}: unknown parameter; expected one of "
                             f"{', '.join(OPERATING_VARIABLES)} or a design key")
        if key in points:
            raise StudyError(f"uncertain.{key}: also given in operating_points; give a study-wide "
                             "value in one place (an analysis may fix it in its own operating_points)")
        parameter = _uncertain_parameter(key, entry, f"uncertain.{key}", design)
        _check_parameter_range(parameter, f"uncertain.{key}")
        uncertain[key] = parameter
    simulation = _simulation(raw.get("simulation"), "simulation", SimulationSettings())
    outputs_raw = check_mapping(raw.get("outputs") or {}, "outputs",
                                {"report": boolean(), "dpi": number("dots per inch", 50, 600, integer=True)})
    outputs = Outputs(**outputs_raw)
    execution = check_mapping(raw.get("execution") or {}, "execution",
                              {"chunk_size": number("samples per chunk", 1, 1_000_000, integer=True)})
    analyses_raw = raw["analyses"]
    if not isinstance(analyses_raw, list) or not analyses_raw:
        raise _fail("analyses", "a non-empty list of analyses", analyses_raw)
    analyses = tuple(_analysis(entry, index, points, simulation, uncertain)
                     for index, entry in enumerate(analyses_raw))
    names = [spec.name for spec in analyses]
    for index, spec in enumerate(analyses):
        if names.count(spec.name) > 1:
            raise StudyError(f"analyses[{index}].name: {spec.name!r} is used by more than one analysis; "
                             "expected unique names (give each a 'name')")
    for spec in analyses:
        if spec.type in RIG_TYPES:
            rig = _resolve(spec.options["rig"], Path(base_dir) if base_dir else None)
            if not rig.is_file():
                raise StudyError(f"analyses[{spec.index}].rig: file {rig} not found; expected a uqgear-rig/1 "
                                 "netCDF file (relative paths start at the study file's folder)")
    return Study(name=name, description=description, seed=seed, design=design,
                 design_source=design_source, design_overrides=overrides, operating_points=points,
                 uncertain=uncertain, simulation=simulation, analyses=analyses, outputs=outputs,
                 chunk_size=execution.get("chunk_size", 64), text=text, path=path)


def parse_study(text: str, *, path: str = "", base_dir: str | Path | None = None) -> Study:
    """Parse and validate study YAML text.

    Raises
    ------
    StudyError
        Not valid YAML, or the first schema violation (with its key path).
    """
    try:
        raw = load_yaml(text)
    except YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise StudyError(f"not valid YAML{where}: {problem}") from None
    if raw is None:
        raise StudyError("study: the file is empty; expected a mapping with 'analyses' and other keys")
    return study_from_mapping(raw, text=text, path=path, base_dir=base_dir)


def load_study(path: str | Path) -> Study:
    """Read and validate a study YAML file.

    Parameters
    ----------
    path : str or Path
        The study file. A relative design path in it is resolved against the
        file's folder.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        The file is missing or unreadable, not valid YAML, or breaks the
        schema; the message starts with the file name and the key path.
    """
    source = Path(path)
    if not source.is_file():
        raise StudyError(f"{source}: study file not found")
    try:
        content = source.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(f"{source}: cannot read the study file ({exc})") from None
    try:
        return parse_study(content, path=str(source), base_dir=source.parent)
    except StudyError as exc:
        raise StudyError(f"{source}: {exc}") from None


__all__ = [
    "Study", "AnalysisSpec", "ValueSpec", "UncertainParameter", "SimulationSettings", "Outputs",
    "load_study", "parse_study", "study_from_mapping", "ANALYSIS_SCHEMAS", "ANALYSIS_DEFAULTS",
    "INTERVAL_METHODS", "SAMPLING_METHODS", "DISTRIBUTIONS", "QOIS", "VARIABLES",
    "OPERATING_VARIABLES", "variable_unit", "variable_units_short", "rig_path", "RIG_TYPES",
]
