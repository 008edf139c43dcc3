"""Interval analysis: bounds of each QoI over the interval parameters.

An interval parameter (the adhesion torque T2 is the typical one) carries no
probability distribution, so the answer to "what does the uncertainty do" is a
band ``[lower, upper]`` of each quantity of interest, at every point of a
sweep (for example every pinion speed). Four methods:

``scan``
    A dense tensor grid over the interval box: the reference. Its own error is
    estimated by comparing with the bounds from every other grid point.
``vertex``
    The 2^d corners of the box. Exact only for monotone responses, so the
    method checks itself at interior points (the centre and a few more) and
    flags ``vertex bounds exceeded at interior check points: non-monotone
    response`` when any lies outside the corner bounds.
``chebyshev``
    The Chebyshev inclusion function of J. Wu, Z. Luo, Y. Zhang, N. Zhang and
    L. Chen, "Interval uncertain method for multibody mechanical systems using
    Chebyshev inclusion functions", Int. J. Numer. Meth. Engng (2013):
    a tensor Chebyshev series whose coefficients come from Gauss-Chebyshev
    quadrature at the roots of T_{order+1}, bounded by scanning the series
    densely (no further model runs). Its error is estimated at extra check
    points and from the size of the highest-order coefficients.
``optimize``
    Multi-start bounded minimisation and maximisation (scipy L-BFGS-B,
    finite-difference gradients) from the best points of a seeded screening
    sample.

Honesty: when a surrogate's estimated error is large compared with the band
width, or the response is seen to be non-smooth (a jump between neighbouring
nodes, a regime variable such as a contact-loss fraction changing over the
box), or the model returns non-finite values, the sweep point is flagged and,
unless ``fallback="none"``, its bounds are recomputed by ``scan`` or
``optimize``. Every reported band is at least as wide as the model values
actually seen. The ``flag`` variable is a bit mask (CF ``flag_masks``); the
reasons are in its ``flag_reasons`` attribute (JSON).

Model runs are batched: all nodes of all sweep points go to the model
function in one call (plus one for a fallback; the optimiser runs all its
local searches in lock-step, one call per iteration).

:func:`uqgear.uq.pbox.pbox` bounds statistics over the interval box when
random parameters are present as well.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from typing import Any, cast

import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from .chebyshev import chebyshev_bounds
from .checks import check_count
from .interval_bounds import (
    FLAG_FALLBACK,
    FLAG_MEANINGS,
    FLAG_NONFINITE,
    FLAG_NONSMOOTH,
    FLAG_SURROGATE_ERROR,
    FLAG_VERTEX_EXCEEDED,
    Bounds,
    relative_error,
)
from .interval_optimize import optimize_bounds
from .interval_responses import ModelResponses, PboxResponses
from .interval_scan import scan_bounds, vertex_bounds
from .parameter_space import ParameterSpace
from .parameters import Interval
from .seeds import SeedLike, as_seed_sequence, child_seed, seed_attributes
from .sweeps import ModelFunction, Sweep, make_sweep

#: Interval analysis methods.
METHODS: tuple[str, ...] = ("scan", "vertex", "chebyshev", "optimize")
#: What to do with a flagged sweep point.
FALLBACKS: tuple[str, ...] = ("scan", "optimize", "none")

_NEEDS_FALLBACK = FLAG_VERTEX_EXCEEDED | FLAG_SURROGATE_ERROR | FLAG_NONSMOOTH | FLAG_NONFINITE

# default scan points per interval parameter, by number of parameters
_SCAN_POINTS = {1: 101, 2: 41, 3: 15, 4: 9}


class IntervalAnalysis:
    """Bounds of each QoI over the interval parameters, at every sweep point.

    Parameters
    ----------
    method : {"scan", "vertex", "chebyshev", "optimize"}
        See the module documentation.
    order : int
        Chebyshev series order per interval parameter ((order + 1)^d nodes).
    scan_points : int, optional
        Grid points per interval parameter for ``scan`` (and the scan
        fallback); default 101, 41, 15, 9, 5 for 1, 2, 3, 4, more parameters.
    check_points : int
        Extra interior points at which ``chebyshev`` and ``vertex`` check
        themselves (``vertex`` always checks the centre as well).
    tolerance : float
        Largest acceptable estimated error of a surrogate's bounds, as a
        fraction of the band width; beyond it the point is flagged.
    fallback : {"scan", "optimize", "none"}
        How flagged sweep points of ``vertex`` and ``chebyshev`` are redone.
    n_starts : int
        Local searches per QoI, sweep point and direction (``optimize``).
    screen_points : int, optional
        Seeded Latin-hypercube points (plus corners and centre) evaluated
        before the local searches; default 20 d.
    max_iterations : int
        L-BFGS-B iterations per local search.
    finite_difference_step : float
        Step of the finite-difference gradients, as a fraction of each
        interval's width.
    regime_variables : sequence of str
        Model outputs that reveal a change of regime (e.g. a contact-loss
        fraction); if one changes over the box, the response is flagged as
        non-smooth. They are not bounded.
    qoi : sequence of str, optional
        QoIs to bound; default every per-sample output.
    seed : SeedSequence or int, optional
        Needed by ``optimize`` (as method or fallback) and by :func:`pbox`.

    Attributes
    ----------
    result_ : xarray.Dataset
        After :meth:`fit`: for each QoI a variable with dims
        ``(*sweep, "bound")``; ``runs`` (model runs per sweep point),
        ``surrogate_error_relative`` and ``flag`` with dims ``("qoi", *sweep)``
        and ``<qoi>_surrogate_error`` (absolute, in the QoI's units).

    Examples
    --------
    A model is any function from a ``sample`` Dataset to a Dataset of
    outputs. (a - 0.3)^2 on [0, 1] has its minimum inside the interval: the
    vertex method misses it and flags the point, a Chebyshev surrogate finds it:

    >>> import xarray as xr
    >>> import uqgear
    >>> def bowl(samples):
    ...     return xr.Dataset({"y": ("sample", ((samples["a"] - 0.3) ** 2).values)})
    >>> space = uqgear.ParameterSpace({"a": uqgear.Interval(0.0, 1.0)})
    >>> vertex = uqgear.IntervalAnalysis("vertex", fallback="none").fit(bowl, space).result_
    >>> int(vertex["flag"][0]) & 1          # vertex bounds exceeded at an interior check point
    1
    >>> chebyshev = uqgear.IntervalAnalysis("chebyshev", order=4).fit(bowl, space).result_
    >>> chebyshev["y"].round(6).values, int(chebyshev["flag"][0]), int(chebyshev["runs"])
    (array([0.  , 0.49]), 0, 9)

    The gear model's DTE RMS at 2000 rpm over the adhesion torque interval;
    it grows with T2, so its bounds are the runs at the interval's ends:

    >>> design = uqgear.load_design("locomotive")
    >>> lower, upper = design.operation.adhesion_torque_bounds()
    >>> model = uqgear.BatchEvaluator(design, fixed={"pinion_speed": 2000.0}, n_periods=60, keep_periods=20)
    >>> space = uqgear.ParameterSpace({"adhesion_torque": uqgear.Interval(lower, upper)})
    >>> band = uqgear.IntervalAnalysis("vertex", qoi=["dte_rms"]).fit(model, space).result_
    >>> (band["dte_rms"] * 1e6).round(2).values
    array([ 6.25, 13.07])
    >>> ends = model(uqgear.samples_from_mapping({"adhesion_torque": [lower, upper]}))
    >>> bool((ends["dte_rms"].values == band["dte_rms"].values).all())
    True
    """

    def __init__(
        self,
        method: str = "chebyshev",
        *,
        order: int = 6,
        scan_points: int | None = None,
        check_points: int = 4,
        tolerance: float = 0.02,
        fallback: str = "scan",
        n_starts: int = 2,
        screen_points: int | None = None,
        max_iterations: int = 40,
        finite_difference_step: float = 1e-6,
        regime_variables: Sequence[str] = (),
        qoi: Sequence[str] | None = None,
        seed: SeedLike | None = None,
    ) -> None:
        if method not in METHODS:
            raise ParameterSpaceError(
                f"method: unknown interval method {method!r}; expected one of {', '.join(METHODS)}"
            )
        if fallback not in FALLBACKS:
            raise ParameterSpaceError(f"fallback: expected one of {', '.join(FALLBACKS)}; got {fallback!r}")
        self.method = method
        self.order = check_count(order, "order", 1, 64)
        self.scan_points = None if scan_points is None else check_count(scan_points, "scan_points", 2)
        self.check_points = check_count(check_points, "check_points", 0)
        if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0 < tolerance < 1:
            raise ParameterSpaceError(f"tolerance: expected a fraction of the band width in (0, 1); got {tolerance!r}")
        self.tolerance = float(tolerance)
        self.fallback = fallback
        self.n_starts = check_count(n_starts, "n_starts", 1)
        self.screen_points = None if screen_points is None else check_count(screen_points, "screen_points", 1)
        self.max_iterations = check_count(max_iterations, "max_iterations", 1)
        if (
            isinstance(finite_difference_step, bool)
            or not isinstance(finite_difference_step, (int, float))
            or not 0 < finite_difference_step < 0.1
        ):
            raise ParameterSpaceError(
                f"finite_difference_step: expected a number in (0, 0.1); got {finite_difference_step!r}"
            )
        self.finite_difference_step = float(finite_difference_step)
        if isinstance(regime_variables, str):
            regime_variables = [regime_variables]
        self.regime_variables = list(regime_variables)
        self.qoi = None if qoi is None else ([qoi] if isinstance(qoi, str) else list(qoi))
        overlap = set(self.regime_variables) & set(self.qoi or ())
        if overlap:
            raise ParameterSpaceError(f"regime_variables: {', '.join(sorted(overlap))} also listed as qoi")
        needs_seed = method == "optimize" or (fallback == "optimize" and method in ("vertex", "chebyshev"))
        if seed is None and needs_seed:
            raise ParameterSpaceError("seed: the optimize method draws seeded starting points; pass seed=")
        self.seed_sequence = None if seed is None else as_seed_sequence(seed)

    # -- public ---------------------------------------------------------------------

    def fit(
        self, evaluate: ModelFunction, space: ParameterSpace, sweep: Mapping[str, Any] | None = None
    ) -> IntervalAnalysis:
        """Bound every QoI over the interval parameters of ``space`` at every sweep point.

        Parameters
        ----------
        evaluate : callable
            The model function.
        space : ParameterSpace
            At least one interval parameter; fixed parameters are passed on;
            random parameters are refused (use :func:`pbox`).
        sweep : mapping of str to 1-D values, optional
            Deterministic variables (e.g. ``{"pinion_speed": speeds}``).

        Returns
        -------
        IntervalAnalysis
            ``self`` with ``result_`` set.
        """
        intervals = self._check_space(space)
        if space.random_names:
            raise ParameterSpaceError(
                f"space: {', '.join(space.random_names)} have distributions; interval "
                f"analysis bounds over intervals only: fix them, or use pbox() for "
                f"bounds on statistics"
            )
        sweep_spec = make_sweep(sweep, space)
        responses = ModelResponses(evaluate, space, sweep_spec, self.qoi, self.regime_variables)
        bounds = self._bound(responses, sweep_spec, len(intervals))
        names = responses.names
        assert names is not None  # set by the model's first call, which every bounding method makes
        coords = self._coords(sweep_spec, names)
        data_vars = _band_variables(bounds, responses, sweep_spec)
        data_vars.update(bound_diagnostics(bounds, responses, sweep_spec, names, [[r] for r in range(len(names))]))
        self.result_ = xr.Dataset(data_vars, coords=coords, attrs=self._attrs(space, responses, "interval_analysis"))
        return self

    # -- internals ------------------------------------------------------------------

    def _check_space(self, space: ParameterSpace) -> list[str]:
        return _interval_names(space, self.method)

    def _scan_points(self, dimensions: int) -> int:
        return self.scan_points or _SCAN_POINTS.get(dimensions, 5)

    def _run_method(self, method: str, responses: ModelResponses, sweep_index: np.ndarray, dimensions: int) -> Bounds:
        regime = [] if isinstance(responses, PboxResponses) else self.regime_variables
        if method == "scan":
            return scan_bounds(
                responses, sweep_index, dimensions, self._scan_points(dimensions), self.tolerance, regime
            )
        if method == "vertex":
            return vertex_bounds(responses, sweep_index, dimensions, self.check_points, regime)
        if method == "chebyshev":
            return chebyshev_bounds(
                responses, sweep_index, dimensions, self.order, self.check_points, self.tolerance, regime
            )
        screen = self.screen_points or 20 * dimensions
        assert self.seed_sequence is not None  # __init__ refuses no seed where optimize runs
        return optimize_bounds(
            responses,
            sweep_index,
            dimensions,
            child_seed(self.seed_sequence, 1 if method == self.method else 2),
            self.n_starts,
            screen,
            self.max_iterations,
            self.finite_difference_step,
            regime,
        )

    def _bound(self, responses: ModelResponses, sweep: Sweep, dimensions: int) -> Bounds:
        everything = np.arange(sweep.size)
        nodes = {
            "scan": self._scan_points(dimensions) ** dimensions,
            "vertex": 2**dimensions,
            "chebyshev": (self.order + 1) ** dimensions,
        }
        if nodes.get(self.method, 0) > 1_000_000:
            raise ParameterSpaceError(
                f"{'order' if self.method == 'chebyshev' else 'scan_points'}: "
                f"{nodes[self.method]} nodes per sweep point in {dimensions} dimensions; "
                f"expected at most 1e6"
            )
        bounds = self._run_method(self.method, responses, everything, dimensions)
        self.fallback_runs_ = 0
        if self.method in ("scan", "optimize") or self.fallback == "none":
            return bounds
        redo = np.nonzero((bounds.flag & _NEEDS_FALLBACK).any(axis=1))[0]
        if redo.size == 0:
            return bounds
        runs_before = responses.runs.sum()
        again = self._run_method(self.fallback, responses, bounds.sweep_index[redo], dimensions)
        self.fallback_runs_ = int(responses.runs.sum() - runs_before)
        _merge_fallback(bounds, again, redo, self.fallback)
        return bounds

    def _coords(self, sweep: Sweep, names: Sequence[str]) -> dict[str, Any]:
        coords: dict[str, Any] = dict(sweep.coords())
        coords["bound"] = ("bound", ["lower", "upper"])
        coords["qoi"] = ("qoi", list(names))
        return coords

    def _attrs(self, space: ParameterSpace, responses: ModelResponses, kind: str) -> dict[str, Any]:
        return _result_attributes(self, space, responses, kind)


def _interval_names(space: ParameterSpace, method: str) -> list[str]:
    """The interval parameters of ``space``, checked as bounds over them by ``method`` need them."""
    if not isinstance(space, ParameterSpace):
        raise ParameterSpaceError(f"space: expected a ParameterSpace; got {type(space).__name__}")
    intervals = list(space.interval_names)
    if not intervals:
        raise ParameterSpaceError(
            "space: interval analysis needs at least one Interval parameter; "
            f"the space has {', '.join(space.names)}"
        )
    if method == "vertex" and len(intervals) > 16:
        raise ParameterSpaceError(
            f"method: vertex with {len(intervals)} intervals needs "
            f"2^{len(intervals)} runs; expected at most 16 intervals"
        )
    return intervals


def _result_attributes(
    analysis: IntervalAnalysis, space: ParameterSpace, responses: ModelResponses, kind: str
) -> dict[str, Any]:
    """The result's attributes: the analysis ``kind``, the method and the settings it used, runs and seed."""
    attrs: dict[str, Any] = {
        "analysis": kind,
        "method": analysis.method,
        "interval_parameters": json.dumps(
            {name: [bound.lower, bound.upper, bound.units] for name, bound in _intervals(space).items()}
        ),
        "parameter_space": space.to_json(),
        "tolerance": analysis.tolerance,
        "fallback": analysis.fallback if analysis.method in ("vertex", "chebyshev") else "none",
        "fallback_runs": int(getattr(analysis, "fallback_runs_", 0)),
        "runs": int(responses.runs.sum()),
        "batch_calls": int(responses.batch_calls),
        "units": json.dumps(responses.units),
        **seed_attributes(analysis.seed_sequence),
    }
    if analysis.method == "chebyshev":
        attrs.update(
            order=analysis.order,
            check_points=analysis.check_points,
            reference="Wu, Luo, Zhang, Zhang, Chen (2013) Int J Numer Meth Eng: Chebyshev "
            "inclusion function at Gauss-Chebyshev nodes, bounds by dense scan of the series",
        )
    if analysis.method == "vertex":
        attrs.update(check_points=analysis.check_points + 1)
    if analysis.method == "scan" or analysis.fallback == "scan":
        attrs.update(scan_points=analysis._scan_points(len(space.interval_names)))
    if analysis.method == "optimize" or analysis.fallback == "optimize":
        attrs.update(
            n_starts=analysis.n_starts,
            max_iterations=analysis.max_iterations,
            finite_difference_step=analysis.finite_difference_step,
        )
    if analysis.regime_variables:
        attrs.update(regime_variables=json.dumps(analysis.regime_variables))
    return attrs


def _intervals(space: ParameterSpace) -> dict[str, Interval]:
    """The interval parameters of ``space`` by name."""
    return {name: cast(Interval, space[name]) for name in space.interval_names}


def _band_variables(bounds: Bounds, responses: ModelResponses, sweep: Sweep) -> dict[str, Any]:
    """Per QoI: the band (dims ``(*sweep, "bound")``) and the estimated error of its bounds."""
    data_vars = {}
    shape = sweep.shape
    assert responses.names is not None  # set by the model's first call, which every bounding method makes
    for r, name in enumerate(responses.names):
        band = np.stack([bounds.lower[:, r], bounds.upper[:, r]], axis=-1).reshape(*shape, 2)
        data_vars[name] = (
            (*sweep.names, "bound"),
            band,
            {
                "units": responses.units[name],
                "long_name": f"bounds of {responses.long_names[name]} over the interval parameters",
            },
        )
        data_vars[f"{name}_surrogate_error"] = (
            sweep.names,
            bounds.error[:, r].reshape(shape),
            {
                "units": responses.units[name],
                "long_name": f"estimated error of the bounds of {name} (NaN: no estimate)",
            },
        )
    return data_vars


def _merge_fallback(bounds: Bounds, again: Bounds, redo: np.ndarray, fallback: str) -> None:
    """Put the bounds ``again`` from the ``fallback`` method at the rows ``redo`` of ``bounds``.

    The observed extremes of both runs are kept, the error and flags come
    from the fallback, and every reason is kept and marked as the fallback's.
    """
    for position, row in enumerate(redo):
        bounds.observed_lower[row] = np.fmin(bounds.observed_lower[row], again.observed_lower[position])
        bounds.observed_upper[row] = np.fmax(bounds.observed_upper[row], again.observed_upper[position])
        bounds.lower[row] = np.fmin(again.lower[position], bounds.observed_lower[row])
        bounds.upper[row] = np.fmax(again.upper[position], bounds.observed_upper[row])
        bounds.error[row] = again.error[position]
        for r in range(bounds.flag.shape[1]):
            bounds.flag[row, r] |= again.flag[position, r]
            for text in again.reasons.get((int(bounds.sweep_index[row]), r), []):
                if text not in bounds.reasons.get((int(bounds.sweep_index[row]), r), []):
                    bounds.add_reason(row, r, 0, f"{fallback} fallback: {text}")
            bounds.add_reason(row, r, FLAG_FALLBACK, f"bounds from the {fallback} fallback")


def bound_diagnostics(
    bounds: Bounds, responses: ModelResponses, sweep: Sweep, qoi_names: Sequence[str], groups: Sequence[Sequence[int]]
) -> dict[str, Any]:
    """Runs per sweep point, and per QoI (the responses ``groups[q]``) the relative error and the flags.

    The flags carry their reasons (``flag_reasons``, JSON), labelled by sweep point.
    """
    shape = sweep.shape
    relative = relative_error(bounds.error, bounds.lower, bounds.upper)
    flags = np.zeros((len(qoi_names), bounds.flag.shape[0]), dtype=np.int8)
    errors = np.full((len(qoi_names), bounds.flag.shape[0]), np.nan)
    reasons = []
    for q, group in enumerate(groups):
        for r in group:
            flags[q] |= bounds.flag[:, r].astype(np.int8)
            errors[q] = np.fmax(errors[q], relative[:, r])
        for row in range(bounds.flag.shape[0]):
            texts = [t for r in group for t in bounds.reasons.get((int(bounds.sweep_index[row]), r), [])]
            if texts:
                where = f"at {sweep.label(int(bounds.sweep_index[row]))}: " if sweep.names else ""
                reasons.append(where + "; ".join(dict.fromkeys(texts)))
    return {
        "runs": (
            sweep.names,
            responses.runs.reshape(shape),
            {"units": "1", "long_name": "model runs spent per sweep point"},
        ),
        "surrogate_error_relative": (
            ("qoi", *sweep.names),
            errors.reshape(len(qoi_names), *shape),
            {"units": "1", "long_name": "estimated error of the bounds relative to the band width (NaN: no estimate)"},
        ),
        "flag": (
            ("qoi", *sweep.names),
            flags.reshape(len(qoi_names), *shape),
            {
                "units": "1",
                "long_name": "quality flags of the bounds (bit mask, 0: none)",
                "flag_masks": np.array(
                    [FLAG_VERTEX_EXCEEDED, FLAG_SURROGATE_ERROR, FLAG_NONSMOOTH, FLAG_NONFINITE, FLAG_FALLBACK],
                    dtype=np.int8,
                ),
                "flag_meanings": FLAG_MEANINGS,
                "flag_reasons": json.dumps(reasons),
            },
        ),
    }
