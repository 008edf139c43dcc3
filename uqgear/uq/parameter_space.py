"""The parameter space: named interval, random and fixed parameters.

A :class:`ParameterSpace` names the parameters of an analysis, maps the unit
hypercube onto them, gives their nominal values and bounds, derives
sub-spaces, and draws samples (:mod:`uqgear.uq.sampling`).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from types import MappingProxyType
from typing import Any

import chaospy
import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from .parameters import Distribution, Fixed, Interval, Parameter, parse_parameter
from .posterior import DEFAULT_DRAWS, PosteriorDraws, PosteriorError
from .sampling import UNIT_EPSILON, sample_space
from .seeds import SeedLike


class _ParameterView:
    """The named parameters of a space, read-only: names by kind, units, nominal values, bounds.

    And the maps from the unit hypercube and to standard distributions that
    sampling and the expansions build on. :class:`ParameterSpace` is the
    public face.
    """

    _parameters: Mapping[str, Parameter]

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
            raise ParameterSpaceError(
                f"parameter {name!r}: not in the parameter space; known: {', '.join(self.names)}"
            ) from None

    def __contains__(self, name: object) -> bool:
        return name in self._parameters

    def __len__(self) -> int:
        return len(self._parameters)

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

    # -- bounds and maps -------------------------------------------------------------

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
            clipped = np.clip(unit_values, UNIT_EPSILON, 1.0 - UNIT_EPSILON)
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


class ParameterSpace(_ParameterView):
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

    Examples
    --------
    The specifications of a study file, from the rail adhesion to a fixed
    torque; the adhesion torque interval is mu Q g R_w at both bounds of mu:

    >>> import uqgear
    >>> space = uqgear.ParameterSpace({
    ...     "adhesion_torque": {"adhesion_coefficient": [0.15, 0.33], "axle_load": 23000, "wheel_radius": 0.625},
    ...     "mesh_stiffness_scale": [0.9, 1.1],
    ...     "ste_amplitude": {"distribution": "uniform", "lower": 10e-6, "upper": 20e-6},
    ...     "drive_torque": 7000.0})
    >>> space.interval_names, space.random_names, space.fixed_names
    (('adhesion_torque', 'mesh_stiffness_scale'), ('ste_amplitude',), ('drive_torque',))
    >>> space.describe()["adhesion_torque"]
    'interval [21145.6, 46520.3] N m'
    >>> space.nominal("mesh_stiffness_scale")        # an interval's midpoint
    1.0
    >>> try:
    ...     uqgear.ParameterSpace({"mesh_stiffness_scale": [1.1, 0.9]})
    ... except uqgear.ParameterSpaceError as error:
    ...     print(error)
    mesh_stiffness_scale: interval: inverted interval, expected lower < upper; got lower=1.1 > upper=0.9
    """

    def __init__(self, parameters: Mapping[str, Parameter | Any], *, posterior: PosteriorDraws | None = None) -> None:
        if not isinstance(parameters, Mapping) or not (parameters or posterior is not None):
            raise ParameterSpaceError(
                f"parameter space: expected a non-empty mapping of parameter names to "
                f"Interval/Distribution/Fixed; got {parameters!r}"
            )
        parsed: dict[str, Parameter] = {}
        for name, spec in parameters.items():
            if not isinstance(name, str) or not name.isidentifier():
                raise ParameterSpaceError(f"parameter name {name!r}: expected an identifier such as 'adhesion_torque'")
            parsed[name] = parse_parameter(name, spec)
        if posterior is not None:
            if not isinstance(posterior, PosteriorDraws):
                raise ParameterSpaceError(f"posterior: expected PosteriorDraws; got {type(posterior).__name__}")
            both = [name for name in posterior.names if name in parsed]
            if both:
                raise ParameterSpaceError(
                    f"{both[0]}: given both by the posterior ({posterior.source or 'its draws'}) and as a "
                    "parameter; expected it in one place"
                )
        self._parameters = MappingProxyType(parsed)
        self._posterior = posterior

    @classmethod
    def from_posterior(
        cls,
        calibration: Any,
        parameters: Mapping[str, Parameter | Any] | None = None,
        *,
        draws: int | None = DEFAULT_DRAWS,
        seed: SeedLike = 0,
        allow_unconverged: bool = False,
    ) -> ParameterSpace:
        """A space whose calibrated parameters are a posterior's joint draws, beside other parameters.

        Parameters
        ----------
        calibration : Calibration, xarray.Dataset or PosteriorDraws
            A fitted :class:`~uqgear.calibration.Calibration`, its posterior
            Dataset (``posterior.nc``) or draws already read.
        parameters : mapping, optional
            Further parameters as for :class:`ParameterSpace` (the adhesion
            torque interval, ...); none may be a calibrated one.
        draws : int or None
            Draws kept (thinned without replacement, seeded); None keeps all.
        seed : SeedSequence or int
            Seed of the thinning.
        allow_unconverged : bool
            Accept a posterior whose convergence checks failed.

        Raises
        ------
        PosteriorError
            Not converged (unless allowed), or unreadable.
        ParameterSpaceError
            A parameter given both ways.

        Examples
        --------
        >>> import numpy as np, xarray as xr
        >>> import uqgear
        >>> rows = np.random.default_rng(0).normal([1.0, 0.05], [0.01, 0.002], size=(4, 100, 2))
        >>> posterior = xr.Dataset({"mesh_stiffness_scale": (("chain", "draw"), rows[..., 0]),
        ...                         "zeta_mesh": (("chain", "draw"), rows[..., 1])}, attrs={"converged": 1})
        >>> space = uqgear.ParameterSpace.from_posterior(
        ...     posterior, {"adhesion_torque": [21e3, 46e3]}, draws=32, seed=3)
        >>> space.interval_names, space.posterior_names, space.posterior.size
        (('adhesion_torque',), ('mesh_stiffness_scale', 'zeta_mesh'), 32)
        >>> samples = space.sample(4, seed=1, interval_treatment="uniform")
        >>> sorted(samples.data_vars)
        ['adhesion_torque', 'mesh_stiffness_scale', 'zeta_mesh']
        """
        posterior = (
            calibration if isinstance(calibration, PosteriorDraws) else PosteriorDraws.from_calibration(calibration)
        )
        if not posterior.converged and not allow_unconverged:
            raise PosteriorError(
                f"{posterior.source or 'posterior'}: the posterior has not converged; expected a converged "
                "calibration (or allow_unconverged=True, stated with every result)"
            )
        if draws is not None:
            posterior = posterior.thin(draws, seed)
        return cls(dict(parameters or {}), posterior=posterior)

    @property
    def posterior(self) -> PosteriorDraws | None:
        """The joint draws of the calibrated parameters, or None."""
        return self._posterior

    @property
    def posterior_names(self) -> tuple[str, ...]:
        """Names of the calibrated parameters (columns of :attr:`posterior`)."""
        return () if self._posterior is None else self._posterior.names

    def __repr__(self) -> str:
        inner = ", ".join(f"{name!r}: {parameter!r}" for name, parameter in self._parameters.items())
        return f"ParameterSpace({{{inner}}})"

    def __reduce__(self) -> tuple[Any, ...]:
        return (_rebuild, (dict(self._parameters), self._posterior))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, ParameterSpace):
            return NotImplemented
        same_posterior = (self._posterior is None and other._posterior is None) or (
            self._posterior is not None
            and other._posterior is not None
            and self._posterior.names == other._posterior.names
            and np.array_equal(self._posterior.values, other._posterior.values)
        )
        return dict(self._parameters) == dict(other._parameters) and same_posterior

    # -- derived spaces -------------------------------------------------------------

    def select(self, names: Iterable[str]) -> ParameterSpace:
        """Sub-space with the parameters ``names`` (in that order)."""
        names = list(names)
        return ParameterSpace({name: self[name] for name in names})

    def fix(self, values: Mapping[str, float]) -> ParameterSpace:
        """Copy with the parameters in ``values`` turned into :class:`Fixed` ones."""
        parameters = dict(self._parameters)
        for name, value in values.items():
            parameters[name] = Fixed(value, units=self[name].units)
        return ParameterSpace(parameters, posterior=self._posterior)

    def with_nominal(self, keep: Iterable[str]) -> ParameterSpace:
        """Copy where every uncertain parameter not in ``keep`` is fixed at its nominal value."""
        keep = set(keep)
        return self.fix({name: self.nominal(name) for name in self.uncertain_names if name not in keep})

    # -- sampling -------------------------------------------------------------------

    def sample(
        self,
        n: int,
        method: str = "monte_carlo",
        *,
        seed: SeedLike | None = None,
        interval_treatment: str | None = None,
    ) -> xr.Dataset:
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
        return sample_space(self, n, method, seed=seed, interval_treatment=interval_treatment)


def _rebuild(parameters: dict[str, Parameter], posterior: PosteriorDraws | None) -> ParameterSpace:
    """Unpickle a space (keyword-only ``posterior``)."""
    return ParameterSpace(parameters, posterior=posterior)
