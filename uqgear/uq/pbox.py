"""Shorthands on interval analysis: response envelopes along a sweep and probability boxes.

:func:`response_envelope` is the band of each QoI over the interval
parameters along a sweep axis. :func:`pbox` handles mixed interval and random
parameters: for every interval node it estimates the mean, standard deviation
and quantiles of each QoI over the random parameters (common random numbers
at every node) and bounds these statistics over the interval box, giving a
probability box.
"""

from __future__ import annotations

import copy
import json
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from .checks import check_count, check_quantiles
from .interval import IntervalAnalysis, bound_diagnostics
from .interval_bounds import Bounds
from .interval_responses import PboxResponses
from .parameter_space import ParameterSpace
from .sampling import SAMPLING_METHODS
from .seeds import SeedLike, as_seed_sequence, child_seed, seed_attributes
from .sweeps import ModelFunction, Sweep, make_sweep


def response_envelope(
    evaluate: ModelFunction,
    space: ParameterSpace,
    sweep: Mapping[str, Any],
    *,
    method: str = "chebyshev",
    order: int = 6,
    scan_points: int | None = None,
    check_points: int = 4,
    tolerance: float = 0.02,
    fallback: str = "scan",
    qoi: Sequence[str] | None = None,
    seed: SeedLike | None = None,
) -> xr.Dataset:
    """Band of each QoI over the interval parameters along a sweep axis.

    A shorthand for ``IntervalAnalysis(method, ...).fit(evaluate, space,
    sweep).result_``; see :class:`IntervalAnalysis` for the parameters.

    Examples
    --------
    The band of the DTE RMS over the adhesion torque interval at three
    pinion speeds (short runs):

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> lower, upper = design.operation.adhesion_torque_bounds()
    >>> space = uqgear.ParameterSpace({"adhesion_torque": uqgear.Interval(lower, upper)})
    >>> model = uqgear.BatchEvaluator(design, n_periods=60, keep_periods=20)
    >>> band = uqgear.response_envelope(model, space, {"pinion_speed": [1000.0, 2000.0, 3000.0]},
    ...                                 method="vertex", qoi=["dte_rms"])
    >>> band["dte_rms"].dims
    ('pinion_speed', 'bound')
    >>> (band["dte_rms"] * 1e6).round(2).values
    array([[ 4.81,  9.61],
           [ 6.25, 13.07],
           [ 2.58,  5.08]])
    >>> bool((band["dte_rms"].sel(bound="lower") < band["dte_rms"].sel(bound="upper")).all())
    True
    """
    if not sweep:
        raise ParameterSpaceError("sweep: a response envelope needs a sweep, e.g. {'pinion_speed': speeds}")
    analysis = IntervalAnalysis(
        method,
        order=order,
        scan_points=scan_points,
        check_points=check_points,
        tolerance=tolerance,
        fallback=fallback,
        qoi=qoi,
        seed=seed,
    )
    return analysis.fit(evaluate, space, sweep).result_


def pbox(
    evaluate: ModelFunction,
    space: ParameterSpace,
    *,
    n_samples: int,
    seed: SeedLike,
    sweep: Mapping[str, Any] | None = None,
    quantiles: Sequence[float] = (0.05, 0.5, 0.95),
    sampling: str = "latin_hypercube",
    qoi: Sequence[str] | None = None,
    analysis: IntervalAnalysis | None = None,
) -> xr.Dataset:
    """Bounds on statistics over interval parameters: a probability box.

    For every interval node the model runs the same ``n_samples`` random
    samples of the random parameters (common random numbers); the mean,
    standard deviation and quantiles of each QoI over them are then bounded
    over the interval box with ``analysis`` (default: ``scan``). The bounds of
    the quantiles at many levels are the bounds of the quantile function,
    i.e. the p-box of the QoI.

    Parameters
    ----------
    evaluate : callable
        The model function.
    space : ParameterSpace
        At least one interval and one random parameter.
    n_samples : int
        Random samples per interval node.
    seed : SeedSequence or int
        Source of the random samples.
    sweep : mapping of str to 1-D values, optional
        Deterministic variables.
    quantiles : sequence of float
        Quantile levels.
    sampling : str
        Sampling of the random parameters (see ``SAMPLING_METHODS``, not grid).
    qoi : sequence of str, optional
        QoIs (default: every per-sample output).
    analysis : IntervalAnalysis, optional
        How to bound the statistics over the intervals (method, order, ...).

    Returns
    -------
    xarray.Dataset
        For each QoI ``q``: ``q`` with dims ``(*sweep, "statistic", "bound")``
        (statistic: mean, std) and ``q_quantile`` with dims
        ``(*sweep, "quantile", "bound")``; plus ``runs``, ``flag`` and
        ``surrogate_error_relative`` as for :class:`IntervalAnalysis`
        (the largest over a QoI's statistics).

    Examples
    --------
    y = a + z with a in [0, 1] and z standard normal: every statistic's
    band is that of z shifted by the interval (the mean by 0 to 1, the
    standard deviation unchanged), and the 5 % quantile lies near -1.645 + a:

    >>> import xarray as xr
    >>> import uqgear
    >>> def shifted(samples):
    ...     return xr.Dataset({"y": ("sample", (samples["a"] + samples["z"]).values)})
    >>> space = uqgear.ParameterSpace({"a": uqgear.Interval(0.0, 1.0),
    ...                                "z": uqgear.Distribution("normal", mu=0.0, sigma=1.0)})
    >>> box = uqgear.pbox(shifted, space, n_samples=64, seed=3)
    >>> box["y"].sel(statistic="mean").round(3).values, box["y"].sel(statistic="std").round(3).values
    (array([0.002, 1.002]), array([0.989, 0.989]))
    >>> width = box["y_quantile"].sel(bound="upper") - box["y_quantile"].sel(bound="lower")
    >>> width.round(9).values                    # common random numbers: each quantile moves by a's width
    array([1., 1., 1.])
    >>> box["y_quantile"].sel(quantile=0.05).round(2).values
    array([-1.54, -0.54])
    """
    analysis = analysis if analysis is not None else IntervalAnalysis("scan")
    if not isinstance(analysis, IntervalAnalysis):
        raise ParameterSpaceError(f"analysis: expected an IntervalAnalysis; got {type(analysis).__name__}")
    intervals = analysis._check_space(space)
    if not space.random_names:
        raise ParameterSpaceError(
            "space: a p-box needs at least one random (Distribution) parameter; "
            "use IntervalAnalysis for intervals alone"
        )
    if analysis.regime_variables:
        raise ParameterSpaceError("analysis: regime_variables are not used by pbox(); leave them out")
    n_samples = check_count(n_samples, "n_samples", 2)
    if sampling not in SAMPLING_METHODS or sampling == "grid":
        raise ParameterSpaceError(
            f"sampling: expected one of monte_carlo, latin_hypercube, sobol, halton; got {sampling!r}"
        )
    levels = check_quantiles(quantiles)
    seed_sequence = as_seed_sequence(seed)
    sweep_spec = make_sweep(sweep, space)
    responses = PboxResponses(
        evaluate,
        space,
        sweep_spec,
        None if qoi is None else list(qoi),
        n_samples,
        sampling,
        levels,
        child_seed(seed_sequence, 0),
    )
    if analysis.seed_sequence is None:
        analysis = copy.copy(analysis)  # leave the caller's object as it was
        analysis.seed_sequence = child_seed(seed_sequence, 1)
    bounds = analysis._bound(responses, sweep_spec, len(intervals))
    qoi_names = responses.qoi_names
    assert qoi_names is not None  # set by the model's first call, which every bounding method makes
    per_qoi = 2 + levels.size
    coords = analysis._coords(sweep_spec, qoi_names)
    coords.update(statistic=("statistic", ["mean", "std"]), quantile=("quantile", levels, {"units": "1"}))
    data_vars = _statistic_variables(bounds, responses, sweep_spec, levels)
    groups = [list(range(q * per_qoi, (q + 1) * per_qoi)) for q in range(len(qoi_names))]
    _relabel_reasons(bounds, responses, levels)
    data_vars.update(bound_diagnostics(bounds, responses, sweep_spec, qoi_names, groups))
    attrs = analysis._attrs(space, responses, "pbox")
    attrs.update(
        n_samples=n_samples,
        sampling=sampling,
        random_parameters=json.dumps({name: space[name].describe() for name in space.random_names}),
        random_numbers="common random numbers: the same random samples at every interval node",
        **{f"pbox_{k}": v for k, v in seed_attributes(seed_sequence).items()},
    )
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)


def _statistic_variables(bounds: Bounds, responses: PboxResponses, sweep: Sweep, levels: np.ndarray) -> dict[str, Any]:
    """Per QoI: bounds of its mean and std, of its quantiles (the p-box) and their largest error."""
    qoi_names = responses.qoi_names
    assert qoi_names is not None  # set by the model's first call, which every bounding method makes
    per_qoi = 2 + levels.size
    shape = sweep.shape
    data_vars = {}
    for q, name in enumerate(qoi_names):
        columns = slice(q * per_qoi, (q + 1) * per_qoi)
        lower, upper = bounds.lower[:, columns], bounds.upper[:, columns]
        band = np.stack([lower, upper], axis=-1).reshape(*shape, per_qoi, 2)
        units = responses.units[name]
        data_vars[name] = (
            (*sweep.names, "statistic", "bound"),
            band[..., :2, :],
            {
                "units": units,
                "long_name": f"bounds over the interval parameters of the mean and "
                f"standard deviation of {name} over the random ones",
            },
        )
        data_vars[f"{name}_quantile"] = (
            (*sweep.names, "quantile", "bound"),
            band[..., 2:, :],
            {"units": units, "long_name": f"bounds of the quantiles of {name} (p-box)"},
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            error = np.nanmax(np.where(np.isnan(bounds.error[:, columns]), -np.inf, bounds.error[:, columns]), axis=1)
        data_vars[f"{name}_surrogate_error"] = (
            sweep.names,
            np.where(np.isinf(error) & (error < 0), np.nan, error).reshape(shape),
            {"units": units, "long_name": f"largest estimated error of the bounds of the statistics of {name}"},
        )
    return data_vars


def _relabel_reasons(bounds: Bounds, responses: PboxResponses, levels: np.ndarray) -> None:
    """Name the statistic in each flag reason (``dte_rms quantile 0.95``, not ``dte_rms|q2``)."""
    qoi_names = responses.qoi_names
    assert qoi_names is not None  # set by the model's first call, which every bounding method makes
    per_qoi = 2 + levels.size
    readable = {}
    for q, name in enumerate(qoi_names):
        labels = ["mean", "std"] + [f"quantile {level:g}" for level in levels]
        for k, label in enumerate(labels):
            readable[q * per_qoi + k] = f"{name} {label}"
    names = responses.names
    assert names is not None  # set by the model's first call, which every bounding method makes
    for key, texts in bounds.reasons.items():
        bounds.reasons[key] = [text.replace(names[key[1]], readable[key[1]], 1) for text in texts]
