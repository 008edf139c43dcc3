"""The three kinds of uncertain parameter and their plain specifications.

* :class:`Interval` -- known only to lie between two bounds. No probability
  distribution is implied (the wheel/rail adhesion torque T2 is the typical
  case, built from adhesion-coefficient bounds by
  :meth:`Interval.from_adhesion`). Methods that need a distribution (Monte
  Carlo sampling, polynomial chaos, Sobol indices) treat an interval as
  uniform on its bounds only when told to, and record that in the output
  attributes (``interval_treatment``).
* :class:`Distribution` -- a random parameter with a named distribution,
  mapped onto :mod:`chaospy`.
* :class:`Fixed` -- a known value, passed to the model unchanged.

:func:`parse_parameter` builds one from the plain specification of a study
file; :class:`uqgear.uq.parameter_space.ParameterSpace` names them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, cast

import chaospy
import numpy as np

from ..common.errors import ParameterSpaceError
from ..physics.design import STANDARD_GRAVITY
from .checks import finite_number


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

    Examples
    --------
    >>> import uqgear
    >>> stiffness = uqgear.Interval(0.9, 1.1)
    >>> round(stiffness.width, 12), stiffness.midpoint
    (0.2, 1.0)

    The adhesion torque T2 = mu Q g R_w for an adhesion coefficient in
    [0.15, 0.33], an axle load of 23 t and a wheel radius of 0.625 m:

    >>> adhesion = uqgear.Interval.from_adhesion(0.15, 0.33, 23000.0, 0.625)
    >>> adhesion.describe()
    'interval [21145.6, 46520.3] N m'
    >>> round(adhesion.upper / adhesion.lower, 6), round(0.33 / 0.15, 6)
    (2.2, 2.2)
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
    def from_adhesion(cls, mu_lower: float, mu_upper: float, axle_load_kg: float, wheel_radius: float) -> Interval:
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
        mu_lower = finite_number(mu_lower, f"{where} lower bound", "a number in [0, 1.5]")
        mu_upper = finite_number(mu_upper, f"{where} upper bound", "a number in [0, 1.5]")
        for label, mu in (("lower", mu_lower), ("upper", mu_upper)):
            if not 0.0 <= mu <= 1.5:
                raise ParameterSpaceError(f"{where} {label} bound: expected a number in [0, 1.5]; got {mu!r}")
        _check_interval_bounds(mu_lower, mu_upper, where)
        axle_load_kg = finite_number(axle_load_kg, "axle_load", "a positive mass in kg")
        wheel_radius = finite_number(wheel_radius, "wheel_radius", "a positive radius in m")
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
    lower = finite_number(lower, f"{where} lower bound")
    upper = finite_number(upper, f"{where} upper bound")
    if lower > upper:
        raise ParameterSpaceError(
            f"{where}: inverted interval, expected lower < upper; got lower={lower!r} > upper={upper!r}"
        )
    if lower == upper:
        raise ParameterSpaceError(
            f"{where}: empty interval (lower == upper == {lower!r}); use a fixed value for a known parameter"
        )
    return lower, upper


@dataclass(frozen=True)
class Fixed:
    """A parameter with a known value, passed to the model unchanged.

    Parameters
    ----------
    value : float
        The value (finite).
    units : str
        Units of the parameter.

    Examples
    --------
    >>> import uqgear
    >>> torque = uqgear.Fixed(7000.0, units="N m")
    >>> torque.describe(), torque.to_dict()
    ('fixed 7000 N m', {'fixed': 7000.0, 'units': 'N m'})
    >>> space = uqgear.ParameterSpace({"drive_torque": torque, "adhesion_torque": uqgear.Interval(21e3, 46e3)})
    >>> space.fixed_names, space.uncertain_names
    (('drive_torque',), ('adhesion_torque',))
    >>> try:
    ...     uqgear.Fixed(float("nan"))
    ... except uqgear.ParameterSpaceError as error:
    ...     print(type(error).__name__)
    ParameterSpaceError
    """

    value: float
    units: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "value", finite_number(self.value, f"Fixed({self.value!r})"))
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


def _ordered(
    *names: str, strict_pairs: tuple[tuple[str, str], ...] = ()
) -> Callable[[Mapping[str, float]], str | None]:
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
        ("mu", "sigma"),
        {},
        _positive("sigma"),
        lambda p: chaospy.Normal(p["mu"], p["sigma"]),
        lambda p: (chaospy.Normal(0.0, 1.0), p["mu"], p["sigma"]),
    ),
    "uniform": _DistributionKind(
        ("lower", "upper"),
        {},
        _ordered("lower", "upper", strict_pairs=(("lower", "upper"),)),
        lambda p: chaospy.Uniform(p["lower"], p["upper"]),
        lambda p: (chaospy.Uniform(-1.0, 1.0), *_half(p)),
    ),
    # log(x - shift) ~ normal(mu, sigma); the median of x - shift is exp(mu)
    "lognormal": _DistributionKind(
        ("mu", "sigma"),
        {"shift": 0.0},
        _positive("sigma"),
        lambda p: chaospy.LogNormal(p["mu"], p["sigma"], p["shift"]),
        lambda p: (chaospy.LogNormal(0.0, p["sigma"]), p["shift"], math.exp(p["mu"])),
    ),
    "beta": _DistributionKind(
        ("alpha", "beta"),
        {"lower": 0.0, "upper": 1.0},
        _both(_positive("alpha", "beta"), _ordered("lower", "upper", strict_pairs=(("lower", "upper"),))),
        lambda p: chaospy.Beta(p["alpha"], p["beta"], p["lower"], p["upper"]),
        lambda p: (chaospy.Beta(p["alpha"], p["beta"], -1.0, 1.0), *_half(p)),
    ),
    "truncnormal": _DistributionKind(
        ("mu", "sigma", "lower", "upper"),
        {},
        _both(_positive("sigma"), _ordered("lower", "upper", strict_pairs=(("lower", "upper"),))),
        lambda p: chaospy.TruncNormal(p["lower"], p["upper"], p["mu"], p["sigma"]),
        lambda p: (
            chaospy.TruncNormal((p["lower"] - p["mu"]) / p["sigma"], (p["upper"] - p["mu"]) / p["sigma"], 0.0, 1.0),
            p["mu"],
            p["sigma"],
        ),
    ),
    "triangle": _DistributionKind(
        ("lower", "mode", "upper"),
        {},
        _ordered("lower", "mode", "upper", strict_pairs=(("lower", "upper"),)),
        lambda p: chaospy.Triangle(p["lower"], p["mode"], p["upper"]),
        lambda p: (
            chaospy.Triangle(-1.0, (2 * p["mode"] - p["lower"] - p["upper"]) / (p["upper"] - p["lower"]), 1.0),
            *_half(p),
        ),
    ),
    "gamma": _DistributionKind(
        ("shape", "scale"),
        {"shift": 0.0},
        _positive("shape", "scale"),
        lambda p: chaospy.Gamma(p["shape"], p["scale"], p["shift"]),
        lambda p: (chaospy.Gamma(p["shape"], 1.0, 0.0), p["shift"], p["scale"]),
    ),
    "exponential": _DistributionKind(
        ("scale",),
        {"shift": 0.0},
        _positive("scale"),
        lambda p: chaospy.Exponential(p["scale"], p["shift"]),
        lambda p: (chaospy.Exponential(1.0, 0.0), p["shift"], p["scale"]),
    ),
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

    Examples
    --------
    >>> import uqgear
    >>> scale = uqgear.Distribution("normal", mu=1.0, sigma=0.05)
    >>> scale, scale.median()
    (Distribution('normal', mu=1.0, sigma=0.05), 1.0)

    It maps onto chaospy; the 97.5 % quantile of a normal is mu + 1.96 sigma:

    >>> round(float(scale.to_chaospy().inv(0.975)), 4), round(1.0 + 1.959964 * 0.05, 4)
    (1.098, 1.098)
    >>> try:
    ...     uqgear.Distribution("normal", mu=1.0, sigma=-0.05)
    ... except uqgear.ParameterSpaceError as error:
    ...     print(error)
    distribution normal(mu, sigma): sigma must be > 0; got -0.05
    """

    __slots__ = ("_name", "_params", "_units")

    def __init__(self, name: str, *, units: str = "", **params: float) -> None:
        if not isinstance(name, str) or name.lower() not in _DISTRIBUTIONS:
            raise ParameterSpaceError(
                f"distribution {name!r}: unknown; expected one of {', '.join(DISTRIBUTION_NAMES)}"
            )
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
            values[key] = finite_number(value, f"{where}: {key}")
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


Parameter = Interval | Distribution | Fixed

_SPEC_KEYS = {
    "interval": ("interval", "units"),
    "adhesion_coefficient": ("adhesion_coefficient", "axle_load", "wheel_radius"),
    "distribution": None,  # plus the distribution's own parameters
    "fixed": ("fixed", "units"),
}


def parse_parameter(name: str, spec: Any) -> Parameter:
    """Build a parameter from an object or a plain specification (study files)."""
    if isinstance(spec, (Interval, Distribution, Fixed)):
        return spec
    try:
        if isinstance(spec, (bool, np.bool_)):
            raise ParameterSpaceError(f"{name}: expected a number, [lower, upper] or a mapping; got {spec!r}")
        if isinstance(spec, (int, float, np.integer, np.floating)):
            return Fixed(cast(float, spec))  # a NumPy number too: Fixed converts it
        if isinstance(spec, Sequence) and not isinstance(spec, str):
            if len(spec) != 2:
                raise ParameterSpaceError(f"expected [lower, upper]; got {list(spec)!r}")
            return Interval(*_check_interval_bounds(spec[0], spec[1], "interval"))
        if isinstance(spec, Mapping):
            return _parse_parameter_mapping(spec)
    except ParameterSpaceError as error:
        raise ParameterSpaceError(f"{name}: {error}") from None
    raise ParameterSpaceError(
        f"{name}: expected Interval, Distribution, Fixed, a number, [lower, upper] "
        f"or a mapping with one of the keys {', '.join(_SPEC_KEYS)}; got {spec!r}"
    )


def _parse_parameter_mapping(spec: Mapping[str, Any]) -> Parameter:
    kinds = [key for key in _SPEC_KEYS if key in spec]
    if len(kinds) != 1:
        raise ParameterSpaceError(
            f"expected exactly one of the keys {', '.join(_SPEC_KEYS)}; got keys {', '.join(map(str, spec)) or 'none'}"
        )
    kind = kinds[0]
    units = spec.get("units", "")
    if kind == "distribution":
        params = {key: value for key, value in spec.items() if key not in ("distribution", "units")}
        return Distribution(spec["distribution"], units=units, **params)
    keys = _SPEC_KEYS[kind]
    assert keys is not None  # only a distribution has open keys, handled above
    unknown = sorted(set(map(str, spec)) - set(keys))
    if unknown:
        raise ParameterSpaceError(
            f"unknown key(s) {', '.join(unknown)} for a {kind} parameter; expected {', '.join(keys)}"
        )
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
