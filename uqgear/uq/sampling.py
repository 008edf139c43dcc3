"""Drawing points: the unit hypercube, grids, and samples of a parameter space.

Random and scrambled quasi-random points in [0, 1)^d come from
:func:`unit_hypercube`; :func:`sample_space` maps them (or a grid) onto the
parameters of a :class:`~uqgear.uq.parameter_space.ParameterSpace`, which is
what :meth:`ParameterSpace.sample` does.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from scipy.stats import qmc

from ..common.errors import ParameterSpaceError
from .checks import check_count
from .parameters import Distribution, Fixed, Interval
from .seeds import SeedLike, as_seed_sequence, child_seed, seed_attributes

#: Sampling methods understood by :meth:`ParameterSpace.sample`.
SAMPLING_METHODS: tuple[str, ...] = ("monte_carlo", "latin_hypercube", "sobol", "halton", "grid")

#: How :meth:`ParameterSpace.sample` may handle interval parameters.
INTERVAL_TREATMENTS: tuple[str, ...] = ("uniform", "exclude")

# Unit-hypercube points of exactly 0 or 1 map to +-inf for unbounded
# distributions; keep them a hair inside.
UNIT_EPSILON = 1e-12


def unit_hypercube(n: int, dimensions: int, method: str, seed_sequence: np.random.SeedSequence) -> np.ndarray:
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
            raise ParameterSpaceError(
                f"n: the 'sobol' sampling method needs a power of 2; got {n} (nearest: {2 ** int(round(math.log2(n)))})"
            )
        return qmc.Sobol(d=dimensions, scramble=True, rng=rng).random(n)
    if method == "halton":
        return qmc.Halton(d=dimensions, scramble=True, rng=rng).random(n)
    raise ParameterSpaceError(
        f"method: unknown sampling method {method!r}; expected one of {', '.join(SAMPLING_METHODS)}"
    )


def grid_columns(n: int, is_interval: Sequence[bool]) -> np.ndarray:
    dimensions = len(is_interval)
    if n**dimensions > 10_000_000:
        raise ParameterSpaceError(
            f"n: a grid of {n} points per parameter in {dimensions} dimensions has "
            f"{n**dimensions} points; expected at most 1e7"
        )
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


def sample_space(
    space: Any,
    n: int,
    method: str = "monte_carlo",
    *,
    seed: SeedLike | None = None,
    interval_treatment: str | None = None,
) -> xr.Dataset:
    """Samples of every parameter of ``space``: see :meth:`ParameterSpace.sample`."""
    if method not in SAMPLING_METHODS:
        raise ParameterSpaceError(
            f"method: unknown sampling method {method!r}; expected one of {', '.join(SAMPLING_METHODS)}"
        )
    n = check_count(n, "n")
    if interval_treatment is not None and interval_treatment not in INTERVAL_TREATMENTS:
        raise ParameterSpaceError(
            f"interval_treatment: expected None or one of {', '.join(INTERVAL_TREATMENTS)}; got {interval_treatment!r}"
        )
    intervals = space.interval_names
    if intervals and interval_treatment is None:
        raise ParameterSpaceError(
            f"interval parameter(s) {', '.join(intervals)}: an interval implies no distribution; pass "
            f"interval_treatment='uniform' to sample it uniformly anyway, 'exclude' to leave it out, "
            f"or use uqgear.uq.interval for interval analysis"
        )
    sampled = [name for name in space.uncertain_names if not (name in intervals and interval_treatment == "exclude")]
    seed_sequence = None
    if method != "grid":
        if seed is None:
            raise ParameterSpaceError(f"seed: the {method!r} sampling method is random; pass seed=")
        seed_sequence = as_seed_sequence(seed)
    if method == "grid":
        columns = grid_columns(n, [name in intervals for name in sampled])
    else:
        assert seed_sequence is not None  # set above for every method but grid
        columns = unit_hypercube(n, len(sampled), method, seed_sequence)
    size = columns.shape[0]
    data_vars = {}
    for name in space.names:
        parameter = space.parameters[name]
        if name in sampled:
            values = space.from_unit(name, columns[:, sampled.index(name)])
        elif isinstance(parameter, Fixed):
            values = np.full(size, parameter.value)
        else:
            continue
        kind = {Interval: "interval", Distribution: "distribution", Fixed: "fixed"}[type(parameter)]
        data_vars[name] = (
            "sample",
            values,
            {"units": parameter.units, "kind": kind, "description": parameter.describe()},
        )
    posterior = getattr(space, "posterior", None)
    if posterior is not None:
        # whole rows of the joint draws: the calibrated parameters keep their dependence
        if seed_sequence is None:
            rows = np.arange(size) % posterior.size
        else:
            rows = np.random.default_rng(child_seed(seed_sequence, 1)).integers(posterior.size, size=size)
        for name in posterior.names:
            data_vars[name] = (
                "sample",
                posterior.column(name)[rows],
                {"units": posterior.units.get(name, ""), "kind": "posterior", "description": posterior.source},
            )
    if not intervals:
        treatment = "none (no interval parameters)"
    elif interval_treatment == "uniform":
        treatment = (
            "uniform on the interval bounds (an assumption for sampling only: an interval implies no distribution)"
        )
    else:
        treatment = "excluded (interval parameters not sampled)"
    attrs = {
        "method": method,
        "interval_treatment": treatment,
        "parameter_space": space.to_json(),
        **seed_attributes(seed_sequence),
    }
    if method == "grid":
        attrs["grid_points_per_parameter"] = n
    return xr.Dataset(data_vars, coords={"sample": np.arange(size)}, attrs=attrs)
