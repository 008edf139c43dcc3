"""Uncertain parameters, sampling, Monte Carlo statistics and polynomial chaos.

Three kinds of parameter make up a :class:`ParameterSpace`:

* :class:`Interval` -- known only to lie between two bounds. No probability
  distribution is implied (the wheel/rail adhesion torque T2 is the typical
  case). Methods that need a distribution (Monte Carlo sampling, polynomial
  chaos, Sobol indices) treat an interval as uniform on its bounds only when
  told to, and record that in the output attributes (``interval_treatment``).
* :class:`Distribution` -- a random parameter with a named distribution,
  mapped onto :mod:`chaospy`.
* :class:`Fixed` -- a known value, passed to the model unchanged.

Everything here works against a *model function*::

    evaluate(samples: xarray.Dataset) -> xarray.Dataset

``samples`` has the dimension ``sample`` and one float variable per parameter
name; the result has the dimension ``sample`` and one variable per quantity of
interest (QoI). :func:`evaluate_on_sweep` runs such a function for every point
of a sweep (for example every pinion speed) in *one* batch call, because the
gear model's batch simulator runs a batch in parallel.

All randomness comes from one :class:`numpy.random.SeedSequence` given by the
caller; its entropy is written to the ``seed_entropy`` attribute of every
result so that a run can be repeated.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Union

import chaospy
import numpy as np
import xarray as xr
from scipy.stats import qmc

from .design import STANDARD_GRAVITY
from .errors import ExecutionError, ParameterSpaceError

#: Sampling methods understood by :meth:`ParameterSpace.sample`.
SAMPLING_METHODS: tuple[str, ...] = ("monte_carlo", "latin_hypercube", "sobol", "halton", "grid")

#: How :meth:`ParameterSpace.sample` may handle interval parameters.
INTERVAL_TREATMENTS: tuple[str, ...] = ("uniform", "exclude")

#: A model function: samples (dim ``sample``) in, QoIs (dim ``sample``) out.
ModelFunction = Callable[[xr.Dataset], xr.Dataset]

#: A seed: a SeedSequence or an integer entropy for one.
SeedLike = Union[np.random.SeedSequence, int]

# Unit-hypercube points of exactly 0 or 1 map to +-inf for unbounded
# distributions; keep them a hair inside.
_UNIT_EPSILON = 1e-12


# ---------------------------------------------------------------------------
# seeds
# ---------------------------------------------------------------------------

def as_seed_sequence(seed: SeedLike, *, setting: str = "seed",
                     error: type[ValueError] | None = None) -> np.random.SeedSequence:
    """Turn ``seed`` into a :class:`numpy.random.SeedSequence`.

    Parameters
    ----------
    seed : SeedSequence or int
        A seed sequence (used as is) or a non-negative integer entropy.
    setting : str
        Name of the setting, used in the error message.
    error : type, optional
        The error class to raise (the calling module's own; default
        :class:`ParameterSpaceError`).

    Returns
    -------
    numpy.random.SeedSequence

    Raises
    ------
    ParameterSpaceError (or ``error``)
        If ``seed`` is neither a SeedSequence nor a non-negative integer.
    """
    if isinstance(seed, np.random.SeedSequence):
        return seed
    if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0:
        return np.random.SeedSequence(int(seed))
    raise (error or ParameterSpaceError)(
        f"{setting}: expected a non-negative integer or a numpy SeedSequence; got {seed!r}")


def child_seed(seed_sequence: np.random.SeedSequence, index: int) -> np.random.SeedSequence:
    """Return the ``index``-th child of ``seed_sequence`` without changing its state.

    :meth:`SeedSequence.spawn` counts the children it has handed out, so
    calling it twice on the same object gives different streams; deriving the
    child from the spawn key keeps "same seed, same numbers" true however
    often an analysis is run.
    """
    return np.random.SeedSequence(entropy=seed_sequence.entropy,
                                  spawn_key=tuple(seed_sequence.spawn_key) + (int(index),),
                                  pool_size=seed_sequence.pool_size)


def seed_attributes(seed_sequence: np.random.SeedSequence | None) -> dict[str, str]:
    """NetCDF-safe attributes describing a seed (entropy may exceed 64 bits, so strings)."""
    if seed_sequence is None:
        return {"seed_entropy": "none (deterministic)", "seed_spawn_key": ""}
    return {"seed_entropy": str(seed_sequence.entropy),
            "seed_spawn_key": json.dumps([int(k) for k in seed_sequence.spawn_key])}


# ---------------------------------------------------------------------------
# number checks
# ---------------------------------------------------------------------------

def _finite_number(value: Any, where: str, expected: str = "a finite number") -> float:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ParameterSpaceError(f"{where}: expected {expected}; got {value!r}")
    value = float(value)
    if not math.isfinite(value):
        raise ParameterSpaceError(f"{where}: expected {expected}; got {value!r}")
    return value


def check_count(value: Any, setting: str, minimum: int = 1, maximum: int | None = None) -> int:
    """Check that a count setting is an integer in ``[minimum, maximum]``.

    Raises
    ------
    ParameterSpaceError
        Naming ``setting`` and the expected range.
    """
    upper_text = "" if maximum is None else f" and <= {maximum}"
    if (isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer))
            or value < minimum or (maximum is not None and value > maximum)):
        raise ParameterSpaceError(f"{setting}: expected an integer >= {minimum}{upper_text}; got {value!r}")
    return int(value)


def check_quantiles(quantiles: Iterable[float], setting: str = "quantiles") -> np.ndarray:
    """Check quantile levels: a non-empty 1-D sequence of numbers in [0, 1]."""
    try:
        levels = np.asarray(list(quantiles), dtype=float)
    except (TypeError, ValueError):
        raise ParameterSpaceError(f"{setting}: expected a sequence of numbers in [0, 1]; "
                                  f"got {quantiles!r}") from None
    if levels.ndim != 1 or levels.size == 0 or not np.all(np.isfinite(levels)) \
            or np.any(levels < 0) or np.any(levels > 1):
        raise ParameterSpaceError(f"{setting}: expected a sequence of numbers in [0, 1]; got {quantiles!r}")
    return levels


# ---------------------------------------------------------------------------
# parameter kinds
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Interval:
    """A parameter known only to lie in ``[lower, upper]``; no distribution implied.

    Parameters
    ----------
    lower, upper : float
        Bounds, ``lower < upper`` (use :class:`Fixed` for a known value).
    units : str
        Units of the parameter, e.g. ``"N m"``.

    Raises
    ------
    ParameterSpaceError
        If a bound is not a finite number or the interval is inverted or empty.
    """

    lower: float
    upper: float
    units: str = ""

    def __post_init__(self) -> None:
        lower, upper = _check_interval_bounds(self.lower, self.upper, f"Interval({self.lower!r}, {self.upper!r})")
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)
        if not isinstance(self.units, str):
            raise ParameterSpaceError(f"Interval units: expected a string; got {self.units!r}")

    @classmethod
    def from_adhesion(cls, mu_lower: float, mu_upper: float, axle_load_kg: float,
                      wheel_radius: float) -> "Interval":
        """Adhesion torque interval T2 = mu Q R_w from adhesion-coefficient bounds.

        Parameters
        ----------
        mu_lower, mu_upper : float
            Bounds of the wheel/rail adhesion coefficient mu (wet to dry rail).
        axle_load_kg : float
            Wheelset axle load in kg; the normal force is Q = axle_load * g.
        wheel_radius : float
            Wheel rolling radius R_w in m.

        Returns
        -------
        Interval
            T2 bounds in N m.
        """
        where = "adhesion_coefficient"
        mu_lower = _finite_number(mu_lower, f"{where} lower bound", "a number in [0, 1.5]")
        mu_upper = _finite_number(mu_upper, f"{where} upper bound", "a number in [0, 1.5]")
        for label, mu in (("lower", mu_lower), ("upper", mu_upper)):
            if not 0.0 <= mu <= 1.5:
                raise ParameterSpaceError(f"{where} {label} bound: expected a number in [0, 1.5]; got {mu!r}")
        _check_interval_bounds(mu_lower, mu_upper, where)
        axle_load_kg = _finite_number(axle_load_kg, "axle_load", "a positive mass in kg")
        wheel_radius = _finite_number(wheel_radius, "wheel_radius", "a positive radius in m")
        if axle_load_kg <= 0:
            raise ParameterSpaceError(f"axle_load: expected a positive mass in kg; got {axle_load_kg!r}")
        if wheel_radius <= 0:
            raise ParameterSpaceError(f"wheel_radius: expected a positive radius in m; got {wheel_radius!r}")
        lever = axle_load_kg * STANDARD_GRAVITY * wheel_radius
        return cls(mu_lower * lever, mu_upper * lever, "N m")

    @property
    def width(self) -> float:
        """Width ``upper - lower``."""
        return self.upper - self.lower

    @property
    def midpoint(self) -> float:
        """Centre of the interval."""
        return 0.5 * (self.lower + self.upper)

    def describe(self) -> str:
        """One-line description for attributes and messages."""
        return f"interval [{self.lower:.6g}, {self.upper:.6g}] {self.units}".rstrip()

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping accepted by :class:`ParameterSpace`."""
        return {"interval": [self.lower, self.upper], "units": self.units}


def _check_interval_bounds(lower: Any, upper: Any, where: str) -> tuple[float, float]:
    lower = _finite_number(lower, f"{where} lower bound")
    upper = _finite_number(upper, f"{where} upper bound")
    if lower > upper:
        raise ParameterSpaceError(f"{where}: inverted interval, expected lower < upper; "
                                  f"got lower={lower!r} > upper={upper!r}")
    if lower == upper:
        raise ParameterSpaceError(f"{where}: empty interval (lower == upper == {lower!r}); "
                                  f"use a fixed value for a known parameter")
    return lower, upper


@dataclass(frozen=True)
class Fixed:
    """A parameter with a known value, passed to the model unchanged."""

    value: float
    units: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", _finite_number(self.value, f"Fixed({self.value!r})"))
        if not isinstance(self.units, str):
            raise ParameterSpaceError(f"Fixed units: expected a string; got {self.units!r}")

    def describe(self) -> str:
        """One-line description for attributes and messages."""
        return f"fixed {self.value:.6g} {self.units}".rstrip()

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping accepted by :class:`ParameterSpace`."""
        return {"fixed": self.value, "units": self.units}


@dataclass(frozen=True)
class _DistributionKind:
    """How one named distribution maps onto chaospy."""

    required: tuple[str, ...]
    optional: Mapping[str, float]
    check: Callable[[Mapping[str, float]], str | None]
    build: Callable[[Mapping[str, float]], Any]
    # (standard chaospy distribution, location, scale) with x = location + scale * z
    standardize: Callable[[Mapping[str, float]], tuple[Any, float, float]]


def _positive(*names: str) -> Callable[[Mapping[str, float]], str | None]:
    def check(params: Mapping[str, float]) -> str | None:
        for name in names:
            if params[name] <= 0:
                return f"{name} must be > 0; got {params[name]!r}"
        return None
    return check


def _ordered(*names: str, strict_pairs: tuple[tuple[str, str], ...] = ()) -> Callable[[Mapping[str, float]], str | None]:
    def check(params: Mapping[str, float]) -> str | None:
        values = [params[name] for name in names]
        if any(a > b for a, b in zip(values, values[1:])):
            return f"expected {' <= '.join(names)}; got " + ", ".join(f"{n}={params[n]!r}" for n in names)
        for first, second in strict_pairs:
            if not params[first] < params[second]:
                return f"expected {first} < {second}; got {first}={params[first]!r}, {second}={params[second]!r}"
        return None
    return check


def _both(*checks: Callable[[Mapping[str, float]], str | None]) -> Callable[[Mapping[str, float]], str | None]:
    def check(params: Mapping[str, float]) -> str | None:
        for one in checks:
            problem = one(params)
            if problem:
                return problem
        return None
    return check


def _half(params: Mapping[str, float]) -> tuple[float, float]:
    return 0.5 * (params["lower"] + params["upper"]), 0.5 * (params["upper"] - params["lower"])


_DISTRIBUTIONS: dict[str, _DistributionKind] = {
    "normal": _DistributionKind(
        ("mu", "sigma"), {}, _positive("sigma"),
        lambda p: chaospy.Normal(p["mu"], p["sigma"]),
        lambda p: (chaospy.Normal(0.0, 1.0), p["mu"], p["sigma"])),
    "uniform": _DistributionKind(
        ("lower", "upper"), {}, _ordered("lower", "upper", strict_pairs=(("lower", "upper"),)),
        lambda p: chaospy.Uniform(p["lower"], p["upper"]),
        lambda p: (chaospy.Uniform(-1.0, 1.0), *_half(p))),
    # log(x - shift) ~ normal(mu, sigma); the median of x - shift is exp(mu)
    "lognormal": _DistributionKind(
        ("mu", "sigma"), {"shift": 0.0}, _positive("sigma"),
        lambda p: chaospy.LogNormal(p["mu"], p["sigma"], p["shift"]),
        lambda p: (chaospy.LogNormal(0.0, p["sigma"]), p["shift"], math.exp(p["mu"]))),
    "beta": _DistributionKind(
        ("alpha", "beta"), {"lower": 0.0, "upper": 1.0},
        _both(_positive("alpha", "beta"), _ordered("lower", "upper", strict_pairs=(("lower", "upper"),))),
        lambda p: chaospy.Beta(p["alpha"], p["beta"], p["lower"], p["upper"]),
        lambda p: (chaospy.Beta(p["alpha"], p["beta"], -1.0, 1.0), *_half(p))),
    "truncnormal": _DistributionKind(
        ("mu", "sigma", "lower", "upper"), {},
        _both(_positive("sigma"), _ordered("lower", "upper", strict_pairs=(("lower", "upper"),))),
        lambda p: chaospy.TruncNormal(p["lower"], p["upper"], p["mu"], p["sigma"]),
        lambda p: (chaospy.TruncNormal((p["lower"] - p["mu"]) / p["sigma"],
                                       (p["upper"] - p["mu"]) / p["sigma"], 0.0, 1.0),
                   p["mu"], p["sigma"])),
    "triangle": _DistributionKind(
        ("lower", "mode", "upper"), {},
        _ordered("lower", "mode", "upper", strict_pairs=(("lower", "upper"),)),
        lambda p: chaospy.Triangle(p["lower"], p["mode"], p["upper"]),
        lambda p: (chaospy.Triangle(-1.0, (2 * p["mode"] - p["lower"] - p["upper"]) / (p["upper"] - p["lower"]),
                                    1.0), *_half(p))),
    "gamma": _DistributionKind(
        ("shape", "scale"), {"shift": 0.0}, _positive("shape", "scale"),
        lambda p: chaospy.Gamma(p["shape"], p["scale"], p["shift"]),
        lambda p: (chaospy.Gamma(p["shape"], 1.0, 0.0), p["shift"], p["scale"])),
    "exponential": _DistributionKind(
        ("scale",), {"shift": 0.0}, _positive("scale"),
        lambda p: chaospy.Exponential(p["scale"], p["shift"]),
        lambda p: (chaospy.Exponential(1.0, 0.0), p["shift"], p["scale"])),
}

#: Names accepted by :class:`Distribution`.
DISTRIBUTION_NAMES: tuple[str, ...] = tuple(_DISTRIBUTIONS)


def _signature_text(name: str) -> str:
    kind = _DISTRIBUTIONS[name]
    parts = list(kind.required) + [f"{key}={value:g}" for key, value in kind.optional.items()]
    return f"{name}({', '.join(parts)})"


class Distribution:
    """A random parameter with a named distribution (mapped onto chaospy).

    Parameters
    ----------
    name : str
        One of :data:`DISTRIBUTION_NAMES`:
        ``normal(mu, sigma)``, ``uniform(lower, upper)``,
        ``lognormal(mu, sigma, shift=0)`` (log(x - shift) is normal(mu, sigma)),
        ``beta(alpha, beta, lower=0, upper=1)``,
        ``truncnormal(mu, sigma, lower, upper)``,
        ``triangle(lower, mode, upper)``, ``gamma(shape, scale, shift=0)``,
        ``exponential(scale, shift=0)``.
    units : str
        Units of the parameter.
    **params : float
        The distribution's parameters, checked against the list above.

    Raises
    ------
    ParameterSpaceError
        For an unknown name (the message lists the known ones), a missing or
        unknown parameter, or an invalid value (sigma <= 0, lower >= upper, ...).
    """

    __slots__ = ("_name", "_params", "_units")

    def __init__(self, name: str, *, units: str = "", **params: float) -> None:
        if not isinstance(name, str) or name.lower() not in _DISTRIBUTIONS:
            raise ParameterSpaceError(f"distribution {name!r}: unknown; expected one of "
                                      f"{', '.join(DISTRIBUTION_NAMES)}")
        name = name.lower()
        kind = _DISTRIBUTIONS[name]
        where = f"distribution {_signature_text(name)}"
        unknown = sorted(set(params) - set(kind.required) - set(kind.optional))
        if unknown:
            raise ParameterSpaceError(f"{where}: unknown parameter(s) {', '.join(unknown)}")
        missing = [key for key in kind.required if key not in params]
        if missing:
            raise ParameterSpaceError(f"{where}: missing parameter(s) {', '.join(missing)}")
        values = dict(kind.optional)
        for key, value in params.items():
            values[key] = _finite_number(value, f"{where}: {key}")
        problem = kind.check(values)
        if problem:
            raise ParameterSpaceError(f"{where}: {problem}")
        if not isinstance(units, str):
            raise ParameterSpaceError(f"{where}: units: expected a string; got {units!r}")
        self._name = name
        self._params = MappingProxyType(values)
        self._units = units

    @property
    def name(self) -> str:
        """Distribution name (lower case)."""
        return self._name

    @property
    def params(self) -> Mapping[str, float]:
        """Read-only mapping of the distribution's parameters, defaults filled in."""
        return self._params

    @property
    def units(self) -> str:
        """Units of the parameter."""
        return self._units

    def to_chaospy(self) -> Any:
        """The chaospy distribution in physical units."""
        return _DISTRIBUTIONS[self._name].build(self._params)

    def standardized(self) -> tuple[Any, float, float]:
        """A standard chaospy distribution and the affine map to physical units.

        Returns
        -------
        (distribution, location, scale)
            ``x = location + scale * z`` with ``z`` drawn from ``distribution``.
            Polynomials in ``z`` are well conditioned even when ``x`` is of
            order 1e4 (a torque in N m).
        """
        return _DISTRIBUTIONS[self._name].standardize(self._params)

    def median(self) -> float:
        """Median of the distribution."""
        return float(self.to_chaospy().inv(0.5))

    def describe(self) -> str:
        """One-line description for attributes and messages."""
        params = ", ".join(f"{key}={value:.6g}" for key, value in self._params.items())
        return f"{self._name}({params}) {self._units}".rstrip()

    def to_dict(self) -> dict[str, Any]:
        """Plain mapping accepted by :class:`ParameterSpace`."""
        return {"distribution": self._name, **dict(self._params), "units": self._units}

    def __reduce__(self) -> tuple[Any, ...]:
        # read-only mapping proxies do not pickle; rebuild (and re-check) from plain values
        return (_rebuild_distribution, (self._name, self._units, dict(self._params)))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Distribution):
            return NotImplemented
        return (self._name, dict(self._params), self._units) == (other._name, dict(other._params), other._units)

    def __hash__(self) -> int:
        return hash((self._name, tuple(sorted(self._params.items())), self._units))

    def __repr__(self) -> str:
        params = ", ".join(f"{key}={value!r}" for key, value in self._params.items())
        units = f", units={self._units!r}" if self._units else ""
        return f"Distribution({self._name!r}{units}, {params})"


def _rebuild_distribution(name: str, units: str, params: dict[str, float]) -> Distribution:
    return Distribution(name, units=units, **params)


Parameter = Union[Interval, Distribution, Fixed]

_SPEC_KEYS = {
    "interval": ("interval", "units"),
    "adhesion_coefficient": ("adhesion_coefficient", "axle_load", "wheel_radius"),
    "distribution": None,  # plus the distribution's own parameters
    "fixed": ("fixed", "units"),
}


def _parse_parameter(name: str, spec: Any) -> Parameter:
    """Build a parameter from an object or a plain specification (study files)."""
    if isinstance(spec, (Interval, Distribution, Fixed)):
        return spec
    try:
        if isinstance(spec, (bool, np.bool_)):
            raise ParameterSpaceError(f"{name}: expected a number, [lower, upper] or a mapping; got {spec!r}")
        if isinstance(spec, (int, float, np.integer, np.floating)):
            return Fixed(spec)
        if isinstance(spec, Sequence) and not isinstance(spec, str):
            if len(spec) != 2:
                raise ParameterSpaceError(f"expected [lower, upper]; got {list(spec)!r}")
            return Interval(*_check_interval_bounds(spec[0], spec[1], "interval"))
        if isinstance(spec, Mapping):
            return _parse_parameter_mapping(spec)
    except ParameterSpaceError as error:
        raise ParameterSpaceError(f"{name}: {error}") from None
    raise ParameterSpaceError(f"{name}: expected Interval, Distribution, Fixed, a number, [lower, upper] "
                              f"or a mapping with one of the keys {', '.join(_SPEC_KEYS)}; got {spec!r}")


def _parse_parameter_mapping(spec: Mapping[str, Any]) -> Parameter:
    kinds = [key for key in _SPEC_KEYS if key in spec]
    if len(kinds) != 1:
        raise ParameterSpaceError(f"expected exactly one of the keys {', '.join(_SPEC_KEYS)}; "
                                  f"got keys {', '.join(map(str, spec)) or 'none'}")
    kind = kinds[0]
    units = spec.get("units", "")
    if kind == "distribution":
        params = {key: value for key, value in spec.items() if key not in ("distribution", "units")}
        return Distribution(spec["distribution"], units=units, **params)
    unknown = sorted(set(map(str, spec)) - set(_SPEC_KEYS[kind]))
    if unknown:
        raise ParameterSpaceError(f"unknown key(s) {', '.join(unknown)} for a {kind} parameter; "
                                  f"expected {', '.join(_SPEC_KEYS[kind])}")
    if kind == "interval":
        bounds = spec["interval"]
        if isinstance(bounds, str) or not isinstance(bounds, Sequence) or len(bounds) != 2:
            raise ParameterSpaceError(f"interval: expected [lower, upper]; got {bounds!r}")
        return Interval(*_check_interval_bounds(bounds[0], bounds[1], "interval"), units=units)
    if kind == "adhesion_coefficient":
        bounds = spec["adhesion_coefficient"]
        if isinstance(bounds, str) or not isinstance(bounds, Sequence) or len(bounds) != 2:
            raise ParameterSpaceError(f"adhesion_coefficient: expected [mu_lower, mu_upper]; got {bounds!r}")
        for key in ("axle_load", "wheel_radius"):
            if key not in spec:
                raise ParameterSpaceError(f"adhesion_coefficient needs {key} as well")
        return Interval.from_adhesion(bounds[0], bounds[1], spec["axle_load"], spec["wheel_radius"])
    return Fixed(spec["fixed"], units=units)


class ParameterSpace:
    """Named uncertain and fixed parameters.

    Parameters
    ----------
    parameters : mapping of str to parameter
        Each value is an :class:`Interval`, :class:`Distribution` or
        :class:`Fixed`, or a plain specification as found in a study file:
        a number (fixed), ``[lower, upper]`` (interval), or a mapping with
        one of the keys ``interval`` (``{"interval": [lo, hi], "units": ...}``),
        ``adhesion_coefficient`` (``{"adhesion_coefficient": [mu_lo, mu_hi],
        "axle_load": kg, "wheel_radius": m}``, giving the adhesion torque
        interval), ``distribution`` (``{"distribution": "normal", "mu": ...,
        "sigma": ...}``) or ``fixed``.

    Raises
    ------
    ParameterSpaceError
        Naming the parameter whose specification is wrong.
    """

    def __init__(self, parameters: Mapping[str, Parameter | Any]) -> None:
        if not isinstance(parameters, Mapping) or not parameters:
            raise ParameterSpaceError(f"parameter space: expected a non-empty mapping of parameter names to "
                                      f"Interval/Distribution/Fixed; got {parameters!r}")
        parsed: dict[str, Parameter] = {}
        for name, spec in parameters.items():
            if not isinstance(name, str) or not name.isidentifier():
                raise ParameterSpaceError(f"parameter name {name!r}: expected an identifier such as "
                                          f"'adhesion_torque'")
            parsed[name] = _parse_parameter(name, spec)
        self._parameters = MappingProxyType(parsed)

    # -- inspection -----------------------------------------------------------------

    @property
    def parameters(self) -> Mapping[str, Parameter]:
        """Read-only mapping of name to parameter, in definition order."""
        return self._parameters

    @property
    def names(self) -> tuple[str, ...]:
        """All parameter names."""
        return tuple(self._parameters)

    @property
    def interval_names(self) -> tuple[str, ...]:
        """Names of the interval parameters."""
        return tuple(n for n, p in self._parameters.items() if isinstance(p, Interval))

    @property
    def random_names(self) -> tuple[str, ...]:
        """Names of the parameters with a distribution."""
        return tuple(n for n, p in self._parameters.items() if isinstance(p, Distribution))

    @property
    def fixed_names(self) -> tuple[str, ...]:
        """Names of the fixed parameters."""
        return tuple(n for n, p in self._parameters.items() if isinstance(p, Fixed))

    @property
    def uncertain_names(self) -> tuple[str, ...]:
        """Names of the interval and random parameters, in definition order."""
        return tuple(n for n, p in self._parameters.items() if not isinstance(p, Fixed))

    def __getitem__(self, name: str) -> Parameter:
        try:
            return self._parameters[name]
        except KeyError:
            raise ParameterSpaceError(f"parameter {name!r}: not in the parameter space; "
                                      f"known: {', '.join(self.names)}") from None

    def __contains__(self, name: object) -> bool:
        return name in self._parameters

    def __len__(self) -> int:
        return len(self._parameters)

    def __repr__(self) -> str:
        inner = ", ".join(f"{name!r}: {parameter!r}" for name, parameter in self._parameters.items())
        return f"ParameterSpace({{{inner}}})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (ParameterSpace, (dict(self._parameters),))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ParameterSpace):
            return NotImplemented
        return dict(self._parameters) == dict(other._parameters)

    def units(self, name: str) -> str:
        """Units of parameter ``name``."""
        return self[name].units

    def nominal(self, name: str) -> float:
        """Nominal value: interval midpoint, distribution median or the fixed value."""
        parameter = self[name]
        if isinstance(parameter, Interval):
            return parameter.midpoint
        if isinstance(parameter, Distribution):
            return parameter.median()
        return parameter.value

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """Plain mapping (JSON-able) that rebuilds the space via ``ParameterSpace(...)``."""
        return {name: parameter.to_dict() for name, parameter in self._parameters.items()}

    def to_json(self) -> str:
        """JSON text of :meth:`to_dict` (for netCDF attributes)."""
        return json.dumps(self.to_dict(), sort_keys=False)

    def describe(self) -> dict[str, str]:
        """Name to one-line description."""
        return {name: parameter.describe() for name, parameter in self._parameters.items()}

    # -- derived spaces -------------------------------------------------------------

    def select(self, names: Iterable[str]) -> "ParameterSpace":
        """Sub-space with the parameters ``names`` (in that order)."""
        names = list(names)
        return ParameterSpace({name: self[name] for name in names})

    def fix(self, values: Mapping[str, float]) -> "ParameterSpace":
        """Copy with the parameters in ``values`` turned into :class:`Fixed` ones."""
        parameters = dict(self._parameters)
        for name, value in values.items():
            parameters[name] = Fixed(value, units=self[name].units)
        return ParameterSpace(parameters)

    def with_nominal(self, keep: Iterable[str]) -> "ParameterSpace":
        """Copy where every uncertain parameter not in ``keep`` is fixed at its nominal value."""
        keep = set(keep)
        return self.fix({name: self.nominal(name) for name in self.uncertain_names if name not in keep})

    def bounds(self, name: str) -> tuple[float, float]:
        """Bounds of an interval; for a distribution the support as chaospy reports it.

        chaospy cuts unbounded distributions numerically (a normal at about
        +-8.2 standard deviations), so the values are finite.
        """
        parameter = self[name]
        if isinstance(parameter, Interval):
            return parameter.lower, parameter.upper
        if isinstance(parameter, Distribution):
            distribution = parameter.to_chaospy()
            return float(np.atleast_1d(distribution.lower)[0]), float(np.atleast_1d(distribution.upper)[0])
        return parameter.value, parameter.value

    # -- mapping from the unit hypercube -------------------------------------------

    def from_unit(self, name: str, unit_values: np.ndarray) -> np.ndarray:
        """Map values in [0, 1] to parameter ``name``.

        Intervals map linearly onto their bounds (a uniform treatment, used
        only where the caller asked for one); distributions through their
        inverse cumulative distribution function.
        """
        parameter = self[name]
        unit_values = np.asarray(unit_values, dtype=float)
        if isinstance(parameter, Interval):
            return parameter.lower + unit_values * parameter.width
        if isinstance(parameter, Distribution):
            clipped = np.clip(unit_values, _UNIT_EPSILON, 1.0 - _UNIT_EPSILON)
            return np.asarray(parameter.to_chaospy().inv(clipped.ravel()), dtype=float).reshape(unit_values.shape)
        return np.full(unit_values.shape, parameter.value)

    def standardized(self, name: str) -> tuple[Any, float, float]:
        """Standard chaospy distribution and affine map ``x = location + scale z``.

        Intervals are treated as uniform on their bounds here (for PCE and
        Sobol indices only).
        """
        parameter = self[name]
        if isinstance(parameter, Interval):
            return chaospy.Uniform(-1.0, 1.0), parameter.midpoint, 0.5 * parameter.width
        if isinstance(parameter, Distribution):
            return parameter.standardized()
        raise ParameterSpaceError(f"parameter {name!r}: fixed parameters have no distribution")

    # -- sampling -------------------------------------------------------------------

    def sample(self, n: int, method: str = "monte_carlo", *, seed: SeedLike | None = None,
               interval_treatment: str | None = None) -> xr.Dataset:
        """Draw samples of all parameters.

        Parameters
        ----------
        n : int
            Number of samples; for ``method="grid"`` the number of points per
            uncertain parameter (``n ** d`` samples in all). ``"sobol"``
            needs a power of 2 (its balance properties hold only then).
        method : str
            One of :data:`SAMPLING_METHODS`. Quasi-random methods are scrambled
            and seeded. ``"grid"`` puts interval points on the bounds and
            equally spaced between, distribution points at the probability
            levels ``(i + 0.5) / n``.
        seed : SeedSequence or int
            Required for every method except ``"grid"``.
        interval_treatment : {None, "uniform", "exclude"}
            What to do with interval parameters: ``"uniform"`` samples them
            uniformly on their bounds (an assumption, recorded in the
            ``interval_treatment`` attribute); ``"exclude"`` leaves them out
            of the samples (e.g. to cross them with interval nodes later).
            ``None`` (default) refuses to sample a space with intervals,
            because an interval implies no distribution.

        Returns
        -------
        xarray.Dataset
            Dimension ``sample``; one variable per parameter (fixed ones
            constant) with ``units`` and ``kind`` attributes.

        Raises
        ------
        ParameterSpaceError
            For a bad ``n``, ``method``, ``seed`` or ``interval_treatment``.
        """
        if method not in SAMPLING_METHODS:
            raise ParameterSpaceError(f"method: unknown sampling method {method!r}; expected one of "
                                      f"{', '.join(SAMPLING_METHODS)}")
        n = check_count(n, "n")
        if interval_treatment is not None and interval_treatment not in INTERVAL_TREATMENTS:
            raise ParameterSpaceError(f"interval_treatment: expected None or one of "
                                      f"{', '.join(INTERVAL_TREATMENTS)}; got {interval_treatment!r}")
        intervals = self.interval_names
        if intervals and interval_treatment is None:
            raise ParameterSpaceError(
                f"interval parameter(s) {', '.join(intervals)}: an interval implies no distribution; pass "
                f"interval_treatment='uniform' to sample it uniformly anyway, 'exclude' to leave it out, "
                f"or use uqgear.interval for interval analysis")
        sampled = [name for name in self.uncertain_names
                   if not (name in intervals and interval_treatment == "exclude")]
        seed_sequence = None
        if method != "grid":
            if seed is None:
                raise ParameterSpaceError(f"seed: the {method!r} sampling method is random; pass seed=")
            seed_sequence = as_seed_sequence(seed)
        if method == "grid":
            columns = _grid_columns(n, [name in intervals for name in sampled])
        else:
            columns = unit_hypercube(n, len(sampled), method, seed_sequence)
        size = columns.shape[0]
        data_vars = {}
        for name in self.names:
            parameter = self._parameters[name]
            if name in sampled:
                values = self.from_unit(name, columns[:, sampled.index(name)])
            elif isinstance(parameter, Fixed):
                values = np.full(size, parameter.value)
            else:
                continue
            kind = {Interval: "interval", Distribution: "distribution", Fixed: "fixed"}[type(parameter)]
            data_vars[name] = ("sample", values, {"units": parameter.units, "kind": kind,
                                                  "description": parameter.describe()})
        if not intervals:
            treatment = "none (no interval parameters)"
        elif interval_treatment == "uniform":
            treatment = ("uniform on the interval bounds (an assumption for sampling only: "
                         "an interval implies no distribution)")
        else:
            treatment = "excluded (interval parameters not sampled)"
        attrs = {"method": method, "interval_treatment": treatment,
                 "parameter_space": self.to_json(), **seed_attributes(seed_sequence)}
        if method == "grid":
            attrs["grid_points_per_parameter"] = n
        return xr.Dataset(data_vars, coords={"sample": np.arange(size)}, attrs=attrs)


def unit_hypercube(n: int, dimensions: int, method: str,
                   seed_sequence: np.random.SeedSequence) -> np.ndarray:
    """``n`` points in [0, 1)^dimensions by a random or scrambled quasi-random method.

    Parameters
    ----------
    n, dimensions : int
        Number of points and of dimensions.
    method : {"monte_carlo", "latin_hypercube", "sobol", "halton"}
        ``"sobol"`` needs ``n`` a power of 2.
    seed_sequence : numpy.random.SeedSequence
        Source of all randomness (scrambling included).

    Returns
    -------
    numpy.ndarray
        Shape ``(n, dimensions)``.
    """
    if dimensions == 0:
        return np.empty((n, 0))
    rng = np.random.default_rng(seed_sequence)
    if method == "monte_carlo":
        return rng.random((n, dimensions))
    if method == "latin_hypercube":
        return qmc.LatinHypercube(d=dimensions, rng=rng).random(n)
    if method == "sobol":
        if n & (n - 1):
            raise ParameterSpaceError(f"n: the 'sobol' sampling method needs a power of 2; got {n} "
                                      f"(nearest: {2 ** int(round(math.log2(n)))})")
        return qmc.Sobol(d=dimensions, scramble=True, rng=rng).random(n)
    if method == "halton":
        return qmc.Halton(d=dimensions, scramble=True, rng=rng).random(n)
    raise ParameterSpaceError(f"method: unknown sampling method {method!r}; expected one of "
                              f"{', '.join(SAMPLING_METHODS)}")


def _grid_columns(n: int, is_interval: Sequence[bool]) -> np.ndarray:
    dimensions = len(is_interval)
    if n ** dimensions > 10_000_000:
        raise ParameterSpaceError(f"n: a grid of {n} points per parameter in {dimensions} dimensions has "
                                  f"{n ** dimensions} points; expected at most 1e7")
    axes = []
    for interval in is_interval:
        if interval:
            axes.append(np.linspace(0.0, 1.0, n) if n > 1 else np.array([0.5]))
        else:
            axes.append((np.arange(n) + 0.5) / n)
    if dimensions == 0:
        return np.empty((1, 0))
    mesh = np.meshgrid(*axes, indexing="ij")
    return np.stack([axis.ravel() for axis in mesh], axis=1)


# ---------------------------------------------------------------------------
# running the model
# ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Sweep:
    """Cartesian sweep of one or more deterministic variables (e.g. pinion speed)."""

    names: tuple[str, ...]
    values: tuple[np.ndarray, ...]
    attrs: tuple[dict[str, Any], ...]

    @property
    def shape(self) -> tuple[int, ...]:
        """Number of values along each sweep variable."""
        return tuple(len(v) for v in self.values)

    @property
    def size(self) -> int:
        """Number of sweep points (1 for no sweep)."""
        return int(np.prod(self.shape, dtype=int))

    def point_values(self) -> dict[str, np.ndarray]:
        """Per sweep point (flattened, C order) the value of each sweep variable."""
        if not self.names:
            return {}
        mesh = np.meshgrid(*self.values, indexing="ij")
        return {name: grid.ravel() for name, grid in zip(self.names, mesh)}

    def coords(self) -> dict[str, tuple[str, np.ndarray, dict[str, Any]]]:
        """xarray coordinates of the sweep."""
        return {name: (name, values, attrs) for name, values, attrs in zip(self.names, self.values, self.attrs)}

    def label(self, index: int) -> str:
        """Human-readable label of flat sweep point ``index``."""
        if not self.names:
            return "(no sweep)"
        position = np.unravel_index(index, self.shape)
        return ", ".join(f"{name}={values[i]:.6g}" for name, values, i in zip(self.names, self.values, position))


def make_sweep(sweep: Mapping[str, Any] | None, space: ParameterSpace | None = None) -> Sweep:
    """Validate a sweep mapping ``{name: 1-D values}``.

    An :class:`xarray.DataArray` keeps its attributes (e.g. ``units``). A
    sweep variable may override a fixed parameter of ``space`` but not an
    uncertain one.
    """
    if sweep is None:
        return Sweep((), (), ())
    if not isinstance(sweep, Mapping):
        raise ParameterSpaceError(f"sweep: expected a mapping of name to 1-D values; got {sweep!r}")
    names, values, attrs = [], [], []
    for name, raw in sweep.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise ParameterSpaceError(f"sweep: expected identifier names; got {name!r}")
        if space is not None and name in space.uncertain_names:
            raise ParameterSpaceError(f"sweep {name}: {name} is an uncertain parameter of the space; "
                                      f"a sweep variable must be deterministic")
        units = ""
        if isinstance(raw, xr.DataArray):
            extra = dict(raw.attrs)
            raw = raw.values
        else:
            extra = {}
        if space is not None and name in space and not extra.get("units"):
            units = space.units(name)
        try:
            array = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            raise ParameterSpaceError(f"sweep {name}: expected 1-D numbers; got {raw!r}") from None
        if array.ndim != 1 or array.size == 0 or not np.all(np.isfinite(array)):
            raise ParameterSpaceError(f"sweep {name}: expected a non-empty 1-D sequence of finite numbers; "
                                      f"got {raw!r}")
        if len(np.unique(array)) != array.size:
            raise ParameterSpaceError(f"sweep {name}: values must be distinct")
        if units and "units" not in extra:
            extra["units"] = units
        names.append(name)
        values.append(array)
        attrs.append(extra)
    return Sweep(tuple(names), tuple(values), tuple(attrs))


def call_model(evaluate: ModelFunction, batch: xr.Dataset,
               qoi: Sequence[str] | None = None) -> xr.Dataset:
    """Run ``evaluate`` on ``batch`` once and check what comes back.

    Parameters
    ----------
    evaluate : callable
        The model function.
    batch : xarray.Dataset
        Inputs with dimension ``sample``.
    qoi : sequence of str, optional
        Output variables to keep; by default every numeric variable whose only
        dimension is ``sample``.

    Returns
    -------
    xarray.Dataset
        The selected QoIs as float arrays with dimension ``sample``.

    Raises
    ------
    ExecutionError
        If the model returns something else than a Dataset with the same
        number of samples, or a requested QoI is missing or not per-sample.
    """
    size = batch.sizes["sample"]
    result = evaluate(batch)
    if not isinstance(result, xr.Dataset):
        raise ExecutionError(f"model function: expected an xarray.Dataset with dimension 'sample'; "
                             f"got {type(result).__name__}")
    if result.sizes.get("sample") != size:
        raise ExecutionError(f"model function: expected dimension 'sample' of length {size}; "
                             f"got dims {dict(result.sizes)}")
    if qoi is None:
        names = [name for name, variable in result.data_vars.items()
                 if variable.dims == ("sample",) and np.issubdtype(variable.dtype, np.number)]
        if not names:
            raise ExecutionError("model function: returned no numeric variable with dimension ('sample',)")
    else:
        names = list(qoi)
        for name in names:
            if name not in result.data_vars:
                raise ExecutionError(f"qoi {name!r}: not returned by the model function; it returned "
                                     f"{', '.join(map(str, result.data_vars)) or 'nothing'}")
            variable = result[name]
            if variable.dims != ("sample",) or not np.issubdtype(variable.dtype, np.number):
                raise ExecutionError(f"qoi {name!r}: expected a numeric variable with dims ('sample',); "
                                     f"got dims {variable.dims}, dtype {variable.dtype}")
    selected = xr.Dataset({name: ("sample", np.asarray(result[name].values, dtype=float),
                                  dict(result[name].attrs)) for name in names},
                          coords={"sample": np.arange(size)})
    return selected


def batch_samples(samples: Mapping[str, np.ndarray], units: Mapping[str, str]) -> xr.Dataset:
    """Dataset (dimension ``sample``) from flat arrays of equal length."""
    data_vars = {name: ("sample", np.asarray(values, dtype=float), {"units": units.get(name, "")})
                 for name, values in samples.items()}
    size = len(next(iter(samples.values()))) if samples else 0
    return xr.Dataset(data_vars, coords={"sample": np.arange(size)})


def evaluate_on_sweep(evaluate: ModelFunction, samples: xr.Dataset,
                      sweep: Mapping[str, Any] | Sweep | None = None, *,
                      qoi: Sequence[str] | None = None) -> xr.Dataset:
    """Evaluate the model on every sample at every sweep point, in one batch call.

    Parameters
    ----------
    evaluate : callable
        The model function.
    samples : xarray.Dataset
        Parameter samples (dimension ``sample``).
    sweep : mapping of str to 1-D values, optional
        Deterministic variables swept on a cartesian grid; each sample is run
        at every sweep point.
    qoi : sequence of str, optional
        QoIs to keep (default: all per-sample numeric outputs).

    Returns
    -------
    xarray.Dataset
        The QoIs with dims ``(*sweep names, "sample")``.
    """
    if not isinstance(samples, xr.Dataset) or "sample" not in samples.dims:
        raise ParameterSpaceError("samples: expected an xarray.Dataset with dimension 'sample'")
    sweep = sweep if isinstance(sweep, Sweep) else make_sweep(sweep)
    n = samples.sizes["sample"]
    point_values = sweep.point_values()
    flat: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    for name, variable in samples.data_vars.items():
        if name in point_values or variable.dims != ("sample",):
            continue
        flat[name] = np.tile(np.asarray(variable.values, dtype=float), sweep.size)
        units[name] = variable.attrs.get("units", "")
    for name, values in point_values.items():
        flat[name] = np.repeat(values, n)
        units[name] = sweep.attrs[sweep.names.index(name)].get("units", "")
    outputs = call_model(evaluate, batch_samples(flat, units), qoi)
    data_vars = {name: ((*sweep.names, "sample"), variable.values.reshape(*sweep.shape, n), variable.attrs)
                 for name, variable in outputs.data_vars.items()}
    return xr.Dataset(data_vars, coords={**sweep.coords(), "sample": samples["sample"].values},
                      attrs={"runs": sweep.size * n})


# ---------------------------------------------------------------------------
# Monte Carlo statistics
# ---------------------------------------------------------------------------

MONTE_CARLO_STATISTICS: tuple[str, ...] = ("mean", "std", "mean_standard_error", "min", "max")


def monte_carlo_statistics(outputs: xr.Dataset, *, quantiles: Sequence[float] = (0.05, 0.5, 0.95),
                           dim: str = "sample") -> xr.Dataset:
    """Mean, standard deviation, extremes and quantiles of each QoI over ``dim``.

    Non-finite values (failed runs) are left out and counted.

    Parameters
    ----------
    outputs : xarray.Dataset
        QoIs with dimension ``dim`` (other dims, e.g. a sweep, are kept).
    quantiles : sequence of float
        Quantile levels in [0, 1].
    dim : str
        The sample dimension.

    Returns
    -------
    xarray.Dataset
        For each QoI ``q``: ``q`` with dims ``(..., "statistic")`` (mean, std
        with ddof=1, standard error of the mean, min, max), ``q_quantile`` with
        dims ``(..., "quantile")`` and ``q_count`` (finite samples used).
    """
    if not isinstance(outputs, xr.Dataset):
        raise ParameterSpaceError(f"outputs: expected an xarray.Dataset; got {type(outputs).__name__}")
    levels = check_quantiles(quantiles)
    names = [name for name, variable in outputs.data_vars.items() if dim in variable.dims]
    if not names:
        raise ParameterSpaceError(f"outputs: no variable has the dimension {dim!r}; "
                                  f"variables: {', '.join(map(str, outputs.data_vars)) or 'none'}")
    data_vars = {}
    coords = {name: outputs.coords[name] for name in outputs.coords if dim not in outputs.coords[name].dims}
    for name in names:
        variable = outputs[name].transpose(..., dim)
        values = np.asarray(variable.values, dtype=float)
        other_dims = variable.dims[:-1]
        units = variable.attrs.get("units", "")
        finite = np.isfinite(values)
        count = finite.sum(axis=-1)
        masked = np.where(finite, values, np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            mean = np.nanmean(masked, axis=-1)
            std = np.nanstd(masked, axis=-1, ddof=1)
            stats = np.stack([mean, std, std / np.sqrt(np.maximum(count, 1)),
                              np.nanmin(masked, axis=-1), np.nanmax(masked, axis=-1)], axis=-1)
            quantile_values = np.moveaxis(np.nanquantile(masked, levels, axis=-1), 0, -1)
        data_vars[name] = ((*other_dims, "statistic"), stats,
                           {"units": units, "long_name": f"Monte Carlo statistics of {name}"})
        data_vars[f"{name}_quantile"] = ((*other_dims, "quantile"), quantile_values,
                                         {"units": units, "long_name": f"empirical quantiles of {name}"})
        data_vars[f"{name}_count"] = (other_dims, count.astype(np.int64),
                                      {"units": "1", "long_name": f"finite samples of {name} used"})
    coords["statistic"] = ("statistic", list(MONTE_CARLO_STATISTICS))
    coords["quantile"] = ("quantile", levels, {"units": "1"})
    attrs = {"method": "monte_carlo_statistics", "std_ddof": 1,
             "n_samples": int(outputs.sizes[dim])}
    for key in ("seed_entropy", "seed_spawn_key", "interval_treatment", "parameter_space"):
        if key in outputs.attrs:
            attrs[key] = outputs.attrs[key]
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)


# ---------------------------------------------------------------------------
# polynomial chaos
# ---------------------------------------------------------------------------

def total_degree_indices(dimensions: int, order: int) -> np.ndarray:
    """Multi-indices of total degree <= ``order``, sorted by degree (graded).

    Returns
    -------
    numpy.ndarray
        Shape ``(terms, dimensions)``; the first row is all zeros, and the
        indices of degree <= p form a prefix for every p.
    """
    indices = np.asarray(chaospy.glexindex(start=0, stop=order + 1, dimensions=dimensions,
                                           graded=True, reverse=True), dtype=int).reshape(-1, dimensions)
    degree = indices.sum(axis=1)
    return indices[np.argsort(degree, kind="stable")]


def number_of_terms(dimensions: int, order: int) -> int:
    """Number of total-degree polynomial terms: C(d + p, p)."""
    return math.comb(dimensions + order, order)


class PolynomialChaos:
    """Regression polynomial chaos expansion with order chosen by leave-one-out error.

    The expansion is built on the orthonormal polynomials of each parameter's
    standardized distribution (chaospy three-term recurrence), with total
    degree truncation. Interval parameters are treated as uniform on their
    bounds (an assumption: an interval implies no distribution); the result
    attributes say so. The model is run once, on ``n_samples`` quasi-random
    samples (times the sweep points). Every order from ``min_order`` to
    ``max_order`` is fitted by least squares; the relative leave-one-out
    error (closed form from the hat matrix) picks the order.

    Parameters
    ----------
    max_order : int
        Highest total degree tried.
    min_order : int
        Lowest total degree tried.
    n_samples : int, optional
        Model runs per sweep point. Default: ``oversampling`` times the number
        of terms at ``max_order``.
    oversampling : float
        Ratio of samples to terms when ``n_samples`` is not given.
    sampling : str
        Sampling method (see :data:`SAMPLING_METHODS`, not ``"grid"``).
    quantiles : sequence of float
        Quantile levels estimated by sampling the surrogate.
    surrogate_samples : int
        Samples of the surrogate used for the quantiles.
    qoi : sequence of str, optional
        QoIs to expand (default: all per-sample outputs of the model).
    seed : SeedSequence or int
        Source of all randomness (training samples, surrogate samples).

    Attributes
    ----------
    result_ : xarray.Dataset
        For each QoI ``q``: ``q`` (dims ``(*sweep, "statistic")``: mean,
        std, variance), ``q_quantile`` (``(*sweep, "quantile")``),
        ``q_sobol`` (``(*sweep, "param", "index")``, index = S1, ST),
        ``q_loo_error`` (``(*sweep, "order")``, NaN where an order has too
        many terms for the samples) and ``q_order`` (chosen order).
    samples_, outputs_ : xarray.Dataset
        The training samples and model outputs.
    """

    def __init__(self, max_order: int = 6, *, min_order: int = 1, n_samples: int | None = None,
                 oversampling: float = 2.0, sampling: str = "halton",
                 quantiles: Sequence[float] = (0.05, 0.5, 0.95), surrogate_samples: int = 20_000,
                 qoi: Sequence[str] | None = None, seed: SeedLike | None = None) -> None:
        self.max_order = check_count(max_order, "max_order", 1, 30)
        self.min_order = check_count(min_order, "min_order", 0, 30)
        if self.min_order > self.max_order:
            raise ParameterSpaceError(f"min_order: expected <= max_order={self.max_order}; got {min_order!r}")
        self.n_samples = None if n_samples is None else check_count(n_samples, "n_samples", 2)
        self.oversampling = _finite_number(oversampling, "oversampling", "a number >= 1")
        if self.oversampling < 1:
            raise ParameterSpaceError(f"oversampling: expected a number >= 1; got {oversampling!r}")
        if sampling not in SAMPLING_METHODS or sampling == "grid":
            raise ParameterSpaceError(f"sampling: expected one of monte_carlo, latin_hypercube, sobol, halton; "
                                      f"got {sampling!r}")
        self.sampling = sampling
        self.quantiles = check_quantiles(quantiles)
        self.surrogate_samples = check_count(surrogate_samples, "surrogate_samples", 10)
        self.qoi = None if qoi is None else list(qoi)
        if seed is None:
            raise ParameterSpaceError("seed: PolynomialChaos draws random samples; pass seed=")
        self.seed_sequence = as_seed_sequence(seed)

    # -- public ----------------------------------------------------------------------

    def fit(self, evaluate: ModelFunction, space: ParameterSpace,
            sweep: Mapping[str, Any] | None = None) -> "PolynomialChaos":
        """Sample, run the model once (all sweep points in one batch) and fit.

        Parameters
        ----------
        evaluate : callable
            The model function.
        space : ParameterSpace
            At least one interval or random parameter.
        sweep : mapping of str to 1-D values, optional
            A separate expansion is fitted at every sweep point.

        Returns
        -------
        PolynomialChaos
            ``self``, with ``result_``, ``samples_`` and ``outputs_`` set.
        """
        names = self._check_space(space)
        sweep_spec = make_sweep(sweep, space)
        n = self.n_samples or int(math.ceil(self.oversampling * number_of_terms(len(names), self.max_order)))
        if self.sampling == "sobol":
            n = 1 << (n - 1).bit_length()
        samples = space.sample(n, self.sampling, seed=child_seed(self.seed_sequence, 0),
                               interval_treatment="uniform")
        outputs = evaluate_on_sweep(evaluate, samples, sweep_spec, qoi=self.qoi)
        return self.fit_samples(samples, outputs, space)

    def fit_samples(self, samples: xr.Dataset, outputs: xr.Dataset, space: ParameterSpace) -> "PolynomialChaos":
        """Fit expansions to given samples and outputs (dims ``(*sweep, "sample")``)."""
        names = self._check_space(space)
        if not isinstance(samples, xr.Dataset) or "sample" not in samples.dims:
            raise ParameterSpaceError("samples: expected an xarray.Dataset with dimension 'sample'")
        if not isinstance(outputs, xr.Dataset) or outputs.sizes.get("sample") != samples.sizes["sample"]:
            raise ParameterSpaceError(f"outputs: expected an xarray.Dataset with dimension 'sample' of length "
                                      f"{samples.sizes['sample']}")
        missing = [name for name in names if name not in samples]
        if missing:
            raise ParameterSpaceError(f"samples: missing parameter(s) {', '.join(missing)}")
        n = samples.sizes["sample"]
        terms_needed = number_of_terms(len(names), self.min_order) + 2
        if n < terms_needed:
            raise ParameterSpaceError(f"n_samples: {n} samples cannot fit order {self.min_order} in "
                                      f"{len(names)} parameters ({terms_needed - 2} terms); expected at least "
                                      f"{terms_needed}")
        self._names = names
        self._maps = [space.standardized(name) for name in names]
        self._univariate = [chaospy.generate_expansion(self.max_order, dist, normed=True)
                            for dist, _, _ in self._maps]
        self._indices = total_degree_indices(len(names), self.max_order)
        design = self._basis(self._standard_coordinates(samples))

        qoi_names = [name for name, v in outputs.data_vars.items() if v.dims and v.dims[-1] == "sample"]
        if not qoi_names:
            raise ParameterSpaceError("outputs: no variable ends with the dimension 'sample'")
        sweep_dims = outputs[qoi_names[0]].dims[:-1]
        sweep_shape = tuple(outputs.sizes[d] for d in sweep_dims)
        columns = np.stack([outputs[name].transpose(*sweep_dims, "sample").values.reshape(-1, n)
                            for name in qoi_names])  # (qoi, sweep point, sample)
        orders = np.arange(self.min_order, self.max_order + 1)
        terms_by_order = np.array([number_of_terms(len(names), int(order)) for order in orders])
        loo = np.full(columns.shape[:2] + (orders.size,), np.nan)
        coefficients = np.zeros(columns.shape[:2] + (self._indices.shape[0],))
        chosen = np.zeros(columns.shape[:2], dtype=np.int64)
        used = np.zeros(columns.shape[:2], dtype=np.int64)
        # Orders are nested (graded indices), so one QR of the largest usable
        # design matrix gives the factors of every lower order by slicing.
        factorizations: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
        for q in range(columns.shape[0]):
            for s in range(columns.shape[1]):
                y = columns[q, s]
                finite = np.isfinite(y)
                count = int(finite.sum())
                used[q, s] = count
                usable = [k for k, terms in enumerate(terms_by_order) if terms + 2 <= count]
                chosen[q, s] = -1
                if not usable:
                    coefficients[q, s, :] = np.nan
                    continue
                key = np.packbits(finite).tobytes()
                if key not in factorizations:
                    factorizations[key] = np.linalg.qr(design[finite][:, :terms_by_order[usable[-1]]])
                q_factor, r_factor = factorizations[key]
                best = np.inf
                for k in usable:
                    terms = int(terms_by_order[k])
                    coef, error = _fit_with_loo(q_factor[:, :terms], r_factor[:terms, :terms], y[finite])
                    loo[q, s, k] = error
                    if error < best:
                        best = error
                        coefficients[q, s, :] = 0.0
                        coefficients[q, s, :terms] = coef
                        chosen[q, s] = int(orders[k])
        self._coefficients = coefficients
        self._qoi_names = qoi_names
        self._sweep_dims = sweep_dims
        self._sweep_shape = sweep_shape
        self.samples_ = samples
        self.outputs_ = outputs
        self.result_ = self._result(outputs, orders, loo, chosen, used, space)
        return self

    def predict(self, samples: xr.Dataset) -> xr.Dataset:
        """Evaluate the fitted surrogates on ``samples``.

        Returns
        -------
        xarray.Dataset
            Each QoI with dims ``(*sweep, "sample")``.
        """
        if not hasattr(self, "_coefficients"):
            raise ParameterSpaceError("PolynomialChaos.predict: call fit() first")
        missing = [name for name in self._names if name not in samples]
        if missing:
            raise ParameterSpaceError(f"samples: missing parameter(s) {', '.join(missing)}")
        design = self._basis(self._standard_coordinates(samples))
        n = samples.sizes["sample"]
        data_vars = {}
        for q, name in enumerate(self._qoi_names):
            values = self._coefficients[q] @ design.T  # (sweep point, sample)
            data_vars[name] = ((*self._sweep_dims, "sample"), values.reshape(*self._sweep_shape, n),
                               dict(self.outputs_[name].attrs))
        coords = {d: self.outputs_.coords[d] for d in self._sweep_dims if d in self.outputs_.coords}
        coords["sample"] = samples["sample"].values
        return xr.Dataset(data_vars, coords=coords, attrs={"method": "polynomial_chaos_surrogate"})

    # -- internals ------------------------------------------------------------------

    def _check_space(self, space: ParameterSpace) -> list[str]:
        if not isinstance(space, ParameterSpace):
            raise ParameterSpaceError(f"space: expected a ParameterSpace; got {type(space).__name__}")
        names = list(space.uncertain_names)
        if not names:
            raise ParameterSpaceError("space: polynomial chaos needs at least one interval or random parameter")
        return names

    def _standard_coordinates(self, samples: xr.Dataset) -> np.ndarray:
        columns = []
        for name, (_, location, scale) in zip(self._names, self._maps):
            columns.append((np.asarray(samples[name].values, dtype=float) - location) / scale)
        return np.stack(columns, axis=1)

    def _basis(self, standard: np.ndarray) -> np.ndarray:
        """Design matrix (samples x terms) of the orthonormal product basis."""
        univariate = [np.atleast_2d(np.asarray(poly(standard[:, j]), dtype=float))
                      for j, poly in enumerate(self._univariate)]
        design = np.ones((standard.shape[0], self._indices.shape[0]))
        for j, values in enumerate(univariate):
            design *= values[self._indices[:, j]].T
        return design

    def _result(self, outputs: xr.Dataset, orders: np.ndarray, loo: np.ndarray, chosen: np.ndarray,
                used: np.ndarray, space: ParameterSpace) -> xr.Dataset:
        coefficients = self._coefficients
        variance_terms = coefficients[..., 1:] ** 2
        variance = variance_terms.sum(axis=-1)
        mean = coefficients[..., 0]
        indices = self._indices[1:]
        active = indices > 0
        only = active & (active.sum(axis=1, keepdims=True) == 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            first = np.einsum("qst,td->qsd", variance_terms, only.astype(float)) / variance[..., None]
            total = np.einsum("qst,td->qsd", variance_terms, active.astype(float)) / variance[..., None]
        quantile_values = self._surrogate_quantiles()

        sweep_dims, shape = self._sweep_dims, self._sweep_shape
        coords: dict[str, Any] = {d: outputs.coords[d] for d in sweep_dims if d in outputs.coords}
        coords.update(statistic=("statistic", ["mean", "std", "variance"]),
                      quantile=("quantile", self.quantiles, {"units": "1"}),
                      param=("param", list(self._names)), index=("index", ["S1", "ST"]),
                      order=("order", orders.astype(np.int64)))
        data_vars = {}
        for q, name in enumerate(self._qoi_names):
            units = outputs[name].attrs.get("units", "")
            moments = np.stack([mean[q], np.sqrt(variance[q]), variance[q]], axis=-1)
            data_vars[name] = ((*sweep_dims, "statistic"), moments.reshape(*shape, 3),
                               {"units": units, "variance_units": f"({units})^2" if units else "",
                                "long_name": f"PCE moments of {name}"})
            data_vars[f"{name}_quantile"] = ((*sweep_dims, "quantile"),
                                             quantile_values[q].reshape(*shape, -1),
                                             {"units": units, "long_name": f"PCE quantiles of {name}",
                                              "method": f"empirical quantiles of {self.surrogate_samples} "
                                                        f"surrogate samples"})
            sobol = np.stack([first[q], total[q]], axis=-1)
            data_vars[f"{name}_sobol"] = ((*sweep_dims, "param", "index"),
                                          sobol.reshape(*shape, len(self._names), 2),
                                          {"units": "1", "long_name": f"PCE Sobol indices of {name}"})
            data_vars[f"{name}_loo_error"] = ((*sweep_dims, "order"), loo[q].reshape(*shape, orders.size),
                                              {"units": "1", "long_name": "relative leave-one-out error: mean "
                                               "squared LOO residual / sample variance (NaN: too few samples)"})
            data_vars[f"{name}_order"] = (sweep_dims, chosen[q].reshape(shape),
                                          {"units": "1", "long_name": "order chosen by minimal LOO error "
                                                                      "(-1: no usable order)"})
            data_vars[f"{name}_samples_used"] = (sweep_dims, used[q].reshape(shape),
                                                 {"units": "1", "long_name": "finite model outputs used"})
        distributions = {name: ("uniform on " + space[name].describe() if name in space.interval_names
                                else space[name].describe()) for name in self._names}
        attrs = {
            "method": "polynomial_chaos_regression",
            "interval_treatment": ("interval parameters treated as uniform on their bounds for the PCE "
                                   "(an assumption: an interval implies no distribution)"
                                   if space.interval_names else "none (no interval parameters)"),
            "distributions": json.dumps(distributions),
            "basis": "orthonormal polynomials of each standardized input (chaospy.generate_expansion), "
                     "total-degree truncation",
            "regression": "ordinary least squares; order chosen by minimal leave-one-out error",
            "sobol_method": "from the coefficients of the orthonormal expansion (Sudret 2008), "
                            "equal to chaospy.Sens_m / Sens_t",
            "min_order": self.min_order, "max_order": self.max_order,
            "n_samples": int(self.samples_.sizes["sample"]), "sampling": self.sampling,
            "runs": int(self.samples_.sizes["sample"]) * int(np.prod(shape, dtype=int)),
            "surrogate_samples": self.surrogate_samples,
            "parameter_space": space.to_json(),
            **seed_attributes(self.seed_sequence),
        }
        return xr.Dataset(data_vars, coords=coords, attrs=attrs)

    def _surrogate_quantiles(self) -> np.ndarray:
        rng_seed = child_seed(self.seed_sequence, 1)
        unit = unit_hypercube(self.surrogate_samples, len(self._names), "monte_carlo", rng_seed)
        unit = np.clip(unit, _UNIT_EPSILON, 1 - _UNIT_EPSILON)
        standard = np.stack([np.asarray(dist.inv(unit[:, j]), dtype=float)
                             for j, (dist, _, _) in enumerate(self._maps)], axis=1)
        coefficients = self._coefficients.reshape(-1, self._indices.shape[0])
        values = np.empty((coefficients.shape[0], standard.shape[0]))
        chunk = 8192  # bound the design-matrix memory: chunk x terms floats
        for start in range(0, standard.shape[0], chunk):
            design = self._basis(standard[start:start + chunk])
            values[:, start:start + chunk] = coefficients @ design.T
        result = np.quantile(values, self.quantiles, axis=1).T  # (qoi*sweep, quantile)
        return result.reshape(*self._coefficients.shape[:2], self.quantiles.size)


def _fit_with_loo(q_factor: np.ndarray, r_factor: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares coefficients and the relative leave-one-out error.

    For ordinary least squares the LOO residual is ``r_i / (1 - h_i)`` with
    ``h_i`` the diagonal of the hat matrix, so no refit is needed.
    """
    leverage = np.sum(q_factor ** 2, axis=1)
    try:
        coefficients = np.linalg.solve(r_factor, q_factor.T @ y)
    except np.linalg.LinAlgError:
        return np.full(r_factor.shape[0], np.nan), np.inf
    residual = y - q_factor @ (q_factor.T @ y)
    # leverage 1 means the point is interpolated exactly: its LOO residual is unbounded
    denominator = np.maximum(1.0 - leverage, 1e-12)
    loo_mean_square = float(np.mean((residual / denominator) ** 2))
    variance = float(np.var(y))
    if variance == 0.0:
        return coefficients, (0.0 if loo_mean_square <= 1e-28 * max(float(np.mean(y ** 2)), 1e-300)
                              else np.inf)
    return coefficients, loo_mean_square / variance
