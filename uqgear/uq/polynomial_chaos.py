"""Polynomial chaos: regression expansions with the order chosen by leave-one-out error.

Moments, quantiles and Sobol indices of each QoI come from the fitted
expansion (:class:`PolynomialChaos`); interval parameters are treated as
uniform on their bounds here, and the result attributes say so.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Hashable, Mapping, Sequence
from typing import Any

import chaospy
import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from .checks import check_count, check_quantiles, finite_number
from .parameter_space import ParameterSpace
from .sampling import SAMPLING_METHODS, UNIT_EPSILON, unit_hypercube
from .seeds import SeedLike, as_seed_sequence, child_seed, seed_attributes
from .sweeps import ModelFunction, evaluate_on_sweep, make_sweep


def total_degree_indices(dimensions: int, order: int) -> np.ndarray:
    """Multi-indices of total degree <= ``order``, sorted by degree (graded).

    Returns
    -------
    numpy.ndarray
        Shape ``(terms, dimensions)``; the first row is all zeros, and the
        indices of degree <= p form a prefix for every p.
    """
    indices = np.asarray(
        chaospy.glexindex(start=0, stop=order + 1, dimensions=dimensions, graded=True, reverse=True), dtype=int
    ).reshape(-1, dimensions)
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

    Examples
    --------
    y = x1^2 + x2 with x1 normal(1, 0.1) and x2 uniform on [0, 1] is a
    polynomial of degree 2: the expansion recovers it exactly, with mean
    1 + 0.1^2 + 0.5 = 1.51 and variance (4 0.1^2 + 2 0.1^4) + 1/12:

    >>> import xarray as xr
    >>> import uqgear
    >>> def quadratic(samples):
    ...     return xr.Dataset({"y": ("sample", (samples["x1"] ** 2 + samples["x2"]).values)})
    >>> space = uqgear.ParameterSpace({"x1": uqgear.Distribution("normal", mu=1.0, sigma=0.1),
    ...                                "x2": uqgear.Distribution("uniform", lower=0.0, upper=1.0)})
    >>> pce = uqgear.PolynomialChaos(max_order=3, surrogate_samples=2000, seed=2).fit(quadratic, space)
    >>> int(pce.result_["y_order"])
    2
    >>> pce.result_["y"].sel(statistic=["mean", "variance"]).round(5).values
    array([1.51   , 0.12353])
    >>> round(1 + 0.1**2 + 0.5, 5), round(4 * 0.1**2 + 2 * 0.1**4 + 1 / 12, 5)
    (1.51, 0.12353)
    >>> pce.result_["y_sobol"].sel(index="S1").round(3).values     # (1/12) / 0.12353 for x2
    array([0.325, 0.675])
    """

    def __init__(
        self,
        max_order: int = 6,
        *,
        min_order: int = 1,
        n_samples: int | None = None,
        oversampling: float = 2.0,
        sampling: str = "halton",
        quantiles: Sequence[float] = (0.05, 0.5, 0.95),
        surrogate_samples: int = 20_000,
        qoi: Sequence[str] | None = None,
        seed: SeedLike | None = None,
    ) -> None:
        self.max_order = check_count(max_order, "max_order", 1, 30)
        self.min_order = check_count(min_order, "min_order", 0, 30)
        if self.min_order > self.max_order:
            raise ParameterSpaceError(f"min_order: expected <= max_order={self.max_order}; got {min_order!r}")
        self.n_samples = None if n_samples is None else check_count(n_samples, "n_samples", 2)
        self.oversampling = finite_number(oversampling, "oversampling", "a number >= 1")
        if self.oversampling < 1:
            raise ParameterSpaceError(f"oversampling: expected a number >= 1; got {oversampling!r}")
        if sampling not in SAMPLING_METHODS or sampling == "grid":
            raise ParameterSpaceError(
                f"sampling: expected one of monte_carlo, latin_hypercube, sobol, halton; got {sampling!r}"
            )
        self.sampling = sampling
        self.quantiles = check_quantiles(quantiles)
        self.surrogate_samples = check_count(surrogate_samples, "surrogate_samples", 10)
        self.qoi = None if qoi is None else list(qoi)
        if seed is None:
            raise ParameterSpaceError("seed: PolynomialChaos draws random samples; pass seed=")
        self.seed_sequence = as_seed_sequence(seed)

    # -- public ----------------------------------------------------------------------

    def fit(
        self, evaluate: ModelFunction, space: ParameterSpace, sweep: Mapping[str, Any] | None = None
    ) -> PolynomialChaos:
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
        names = _uncertain_names(space)
        sweep_spec = make_sweep(sweep, space)
        n = self.n_samples or int(math.ceil(self.oversampling * number_of_terms(len(names), self.max_order)))
        if self.sampling == "sobol":
            n = 1 << (n - 1).bit_length()
        samples = space.sample(n, self.sampling, seed=child_seed(self.seed_sequence, 0), interval_treatment="uniform")
        outputs = evaluate_on_sweep(evaluate, samples, sweep_spec, qoi=self.qoi)
        return self.fit_samples(samples, outputs, space)

    def fit_samples(self, samples: xr.Dataset, outputs: xr.Dataset, space: ParameterSpace) -> PolynomialChaos:
        """Fit expansions to given samples and outputs (dims ``(*sweep, "sample")``)."""
        names = _uncertain_names(space)
        _check_training_data(names, samples, outputs, self.min_order)
        n = samples.sizes["sample"]
        self._names = names
        self._maps = [space.standardized(name) for name in names]
        self._univariate = [chaospy.generate_expansion(self.max_order, dist, normed=True) for dist, _, _ in self._maps]
        self._indices = total_degree_indices(len(names), self.max_order)
        design = self._basis(self._standard_coordinates(samples))

        qoi_names = [name for name, v in outputs.data_vars.items() if v.dims and v.dims[-1] == "sample"]
        if not qoi_names:
            raise ParameterSpaceError("outputs: no variable ends with the dimension 'sample'")
        sweep_dims = outputs[qoi_names[0]].dims[:-1]
        sweep_shape = tuple(outputs.sizes[d] for d in sweep_dims)
        columns = np.stack(
            [outputs[name].transpose(*sweep_dims, "sample").values.reshape(-1, n) for name in qoi_names]
        )  # (qoi, sweep point, sample)
        orders = np.arange(self.min_order, self.max_order + 1)
        loo, coefficients, chosen, used = _fit_orders(design, columns, orders, len(names))
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
            data_vars[name] = (
                (*self._sweep_dims, "sample"),
                values.reshape(*self._sweep_shape, n),
                dict(self.outputs_[name].attrs),
            )
        coords: dict[Hashable, Any] = {
            d: self.outputs_.coords[d] for d in self._sweep_dims if d in self.outputs_.coords
        }
        coords["sample"] = samples["sample"].values
        return xr.Dataset(data_vars, coords=coords, attrs={"method": "polynomial_chaos_surrogate"})

    # -- internals ------------------------------------------------------------------

    def _standard_coordinates(self, samples: xr.Dataset) -> np.ndarray:
        columns = []
        for name, (_, location, scale) in zip(self._names, self._maps):
            columns.append((np.asarray(samples[name].values, dtype=float) - location) / scale)
        return np.stack(columns, axis=1)

    def _basis(self, standard: np.ndarray) -> np.ndarray:
        """Design matrix (samples x terms) of the orthonormal product basis."""
        univariate = [
            np.atleast_2d(np.asarray(poly(standard[:, j]), dtype=float)) for j, poly in enumerate(self._univariate)
        ]
        design = np.ones((standard.shape[0], self._indices.shape[0]))
        for j, values in enumerate(univariate):
            design *= values[self._indices[:, j]].T
        return design

    def _result(
        self,
        outputs: xr.Dataset,
        orders: np.ndarray,
        loo: np.ndarray,
        chosen: np.ndarray,
        used: np.ndarray,
        space: ParameterSpace,
    ) -> xr.Dataset:
        mean, variance, first, total = _variance_decomposition(self._coefficients, self._indices)
        quantile_values = _surrogate_quantiles(
            self._basis,
            [dist for dist, _, _ in self._maps],
            self._coefficients,
            self.quantiles,
            self.surrogate_samples,
            child_seed(self.seed_sequence, 1),
        )

        sweep_dims, shape = self._sweep_dims, self._sweep_shape
        coords = _result_coords(outputs, sweep_dims, self.quantiles, self._names, orders)
        data_vars: dict[Hashable, Any] = {}
        for q, name in enumerate(self._qoi_names):
            moments = np.stack([mean[q], np.sqrt(variance[q]), variance[q]], axis=-1)
            sobol = np.stack([first[q], total[q]], axis=-1)
            data_vars.update(
                _qoi_variables(
                    name,
                    outputs[name].attrs.get("units", ""),
                    sweep_dims,
                    moments.reshape(*shape, 3),
                    quantile_values[q].reshape(*shape, -1),
                    sobol.reshape(*shape, len(self._names), 2),
                    loo[q].reshape(*shape, orders.size),
                    chosen[q].reshape(shape),
                    used[q].reshape(shape),
                    self.surrogate_samples,
                )
            )
        return xr.Dataset(data_vars, coords=coords, attrs=_result_attributes(self, self._names, space, shape))


def _surrogate_quantiles(
    basis: Callable[[np.ndarray], np.ndarray],
    distributions: Sequence[Any],
    coefficients: np.ndarray,
    quantiles: np.ndarray,
    surrogate_samples: int,
    seed: np.random.SeedSequence,
) -> np.ndarray:
    """Quantiles (qoi, sweep point, quantile) of the expansions over seeded samples of the standard inputs."""
    unit = unit_hypercube(surrogate_samples, len(distributions), "monte_carlo", seed)
    unit = np.clip(unit, UNIT_EPSILON, 1 - UNIT_EPSILON)
    standard = np.stack([np.asarray(dist.inv(unit[:, j]), dtype=float) for j, dist in enumerate(distributions)], axis=1)
    flat = coefficients.reshape(-1, coefficients.shape[-1])
    values = np.empty((flat.shape[0], standard.shape[0]))
    chunk = 8192  # bound the design-matrix memory: chunk x terms floats
    for start in range(0, standard.shape[0], chunk):
        design = basis(standard[start : start + chunk])
        values[:, start : start + chunk] = flat @ design.T
    result = np.quantile(values, quantiles, axis=1).T  # (qoi*sweep, quantile)
    return result.reshape(*coefficients.shape[:2], quantiles.size)


def _result_coords(
    outputs: xr.Dataset,
    sweep_dims: tuple[Hashable, ...],
    quantiles: np.ndarray,
    names: Sequence[str],
    orders: np.ndarray,
) -> dict[Hashable, Any]:
    """The result's coordinates: the sweep's, the statistics, quantile levels, parameters, indices and orders."""
    coords: dict[Hashable, Any] = {d: outputs.coords[d] for d in sweep_dims if d in outputs.coords}
    coords.update(
        statistic=("statistic", ["mean", "std", "variance"]),
        quantile=("quantile", quantiles, {"units": "1"}),
        param=("param", list(names)),
        index=("index", ["S1", "ST"]),
        order=("order", orders.astype(np.int64)),
    )
    return coords


def _qoi_variables(
    name: Hashable,
    units: str,
    sweep_dims: tuple[Hashable, ...],
    moments: np.ndarray,
    quantiles: np.ndarray,
    sobol: np.ndarray,
    loo: np.ndarray,
    chosen: np.ndarray,
    used: np.ndarray,
    surrogate_samples: int,
) -> dict[Hashable, Any]:
    """The result's variables of QoI ``name``: moments, quantiles, Sobol indices and the fit's diagnostics."""
    return {
        name: (
            (*sweep_dims, "statistic"),
            moments,
            {
                "units": units,
                "variance_units": f"({units})^2" if units else "",
                "long_name": f"PCE moments of {name}",
            },
        ),
        f"{name}_quantile": (
            (*sweep_dims, "quantile"),
            quantiles,
            {
                "units": units,
                "long_name": f"PCE quantiles of {name}",
                "method": f"empirical quantiles of {surrogate_samples} surrogate samples",
            },
        ),
        f"{name}_sobol": (
            (*sweep_dims, "param", "index"),
            sobol,
            {"units": "1", "long_name": f"PCE Sobol indices of {name}"},
        ),
        f"{name}_loo_error": (
            (*sweep_dims, "order"),
            loo,
            {
                "units": "1",
                "long_name": "relative leave-one-out error: mean "
                "squared LOO residual / sample variance (NaN: too few samples)",
            },
        ),
        f"{name}_order": (
            sweep_dims,
            chosen,
            {"units": "1", "long_name": "order chosen by minimal LOO error (-1: no usable order)"},
        ),
        f"{name}_samples_used": (
            sweep_dims,
            used,
            {"units": "1", "long_name": "finite model outputs used"},
        ),
    }


def _result_attributes(
    pce: PolynomialChaos, names: Sequence[str], space: ParameterSpace, shape: tuple[int, ...]
) -> dict[str, Any]:
    """The result's attributes: the method, the distributions it took, its settings and seed."""
    distributions = {
        name: ("uniform on " + space[name].describe() if name in space.interval_names else space[name].describe())
        for name in names
    }
    attrs = {
        "method": "polynomial_chaos_regression",
        "interval_treatment": (
            "interval parameters treated as uniform on their bounds for the PCE "
            "(an assumption: an interval implies no distribution)"
            if space.interval_names
            else "none (no interval parameters)"
        ),
        "distributions": json.dumps(distributions),
        "basis": "orthonormal polynomials of each standardized input (chaospy.generate_expansion), "
        "total-degree truncation",
        "regression": "ordinary least squares; order chosen by minimal leave-one-out error",
        "sobol_method": "from the coefficients of the orthonormal expansion (Sudret 2008), "
        "equal to chaospy.Sens_m / Sens_t",
        "min_order": pce.min_order,
        "max_order": pce.max_order,
        "n_samples": int(pce.samples_.sizes["sample"]),
        "sampling": pce.sampling,
        "runs": int(pce.samples_.sizes["sample"]) * int(np.prod(shape, dtype=int)),
        "surrogate_samples": pce.surrogate_samples,
        "parameter_space": space.to_json(),
        **seed_attributes(pce.seed_sequence),
    }
    return attrs


def _uncertain_names(space: ParameterSpace) -> list[str]:
    """The parameters an expansion is built on: the interval and random ones of ``space``."""
    if not isinstance(space, ParameterSpace):
        raise ParameterSpaceError(f"space: expected a ParameterSpace; got {type(space).__name__}")
    names = list(space.uncertain_names)
    if not names:
        raise ParameterSpaceError("space: polynomial chaos needs at least one interval or random parameter")
    return names


def _variance_decomposition(
    coefficients: np.ndarray, indices: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Mean, variance and first-order and total Sobol indices from orthonormal-expansion coefficients.

    ``coefficients`` has shape (qoi, sweep point, terms) on the multi-indices
    ``indices`` (terms x parameters, the constant term first); the indices
    come out with shape (qoi, sweep point, parameter).
    """
    variance_terms = coefficients[..., 1:] ** 2
    variance = variance_terms.sum(axis=-1)
    mean = coefficients[..., 0]
    active = indices[1:] > 0
    only = active & (active.sum(axis=1, keepdims=True) == 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        first = np.einsum("qst,td->qsd", variance_terms, only.astype(float)) / variance[..., None]
        total = np.einsum("qst,td->qsd", variance_terms, active.astype(float)) / variance[..., None]
    return mean, variance, first, total


def _check_training_data(names: list[str], samples: xr.Dataset, outputs: xr.Dataset, min_order: int) -> None:
    """Check that ``samples`` and ``outputs`` can train an expansion of ``min_order`` in ``names``."""
    if not isinstance(samples, xr.Dataset) or "sample" not in samples.dims:
        raise ParameterSpaceError("samples: expected an xarray.Dataset with dimension 'sample'")
    if not isinstance(outputs, xr.Dataset) or outputs.sizes.get("sample") != samples.sizes["sample"]:
        raise ParameterSpaceError(
            f"outputs: expected an xarray.Dataset with dimension 'sample' of length {samples.sizes['sample']}"
        )
    missing = [name for name in names if name not in samples]
    if missing:
        raise ParameterSpaceError(f"samples: missing parameter(s) {', '.join(missing)}")
    n = samples.sizes["sample"]
    terms_needed = number_of_terms(len(names), min_order) + 2
    if n < terms_needed:
        raise ParameterSpaceError(
            f"n_samples: {n} samples cannot fit order {min_order} in "
            f"{len(names)} parameters ({terms_needed - 2} terms); expected at least "
            f"{terms_needed}"
        )


def _fit_orders(
    design: np.ndarray, columns: np.ndarray, orders: np.ndarray, dimensions: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fit every order to every (QoI, sweep point) column and keep the one of least LOO error.

    Parameters
    ----------
    design : numpy.ndarray
        Design matrix (samples x terms) of the basis at the highest order.
    columns : numpy.ndarray
        Model outputs, shape (qoi, sweep point, sample); non-finite ones are left out.
    orders : numpy.ndarray
        Orders tried, ascending.
    dimensions : int
        Number of uncertain parameters.

    Returns
    -------
    (loo, coefficients, chosen, used)
        Relative LOO error per order (NaN: too few samples), coefficients of
        the chosen order (zero-padded), the chosen order (-1: none usable) and
        the finite outputs used.
    """
    terms_by_order = np.array([number_of_terms(dimensions, int(order)) for order in orders])
    loo = np.full(columns.shape[:2] + (orders.size,), np.nan)
    coefficients = np.zeros(columns.shape[:2] + (design.shape[1],))
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
                factorizations[key] = np.linalg.qr(design[finite][:, : terms_by_order[usable[-1]]])
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
    return loo, coefficients, chosen, used


def _fit_with_loo(q_factor: np.ndarray, r_factor: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares coefficients and the relative leave-one-out error.

    For ordinary least squares the LOO residual is ``r_i / (1 - h_i)`` with
    ``h_i`` the diagonal of the hat matrix, so no refit is needed.
    """
    leverage = np.sum(q_factor**2, axis=1)
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
        return coefficients, (0.0 if loo_mean_square <= 1e-28 * max(float(np.mean(y**2)), 1e-300) else np.inf)
    return coefficients, loo_mean_square / variance
