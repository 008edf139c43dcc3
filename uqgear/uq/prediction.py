"""Posterior-predictive bounds: for each joint draw, a QoI's bounds over the interval parameters, and their quantiles.

A :class:`PosteriorPrediction` takes a :class:`~uqgear.uq.parameter_space.ParameterSpace`
whose calibrated parameters are a posterior's joint draws (``space.posterior``),
beside interval parameters (T2) and fixed inputs. Each draw runs at the nodes
of the intervals at every sweep point, in one batch; per draw and sweep point
the lower and upper bound of each QoI over the nodes are taken (over every
steady response the model reports: ``<qoi>_min`` and ``<qoi>_max`` where it
gives them), and the result holds the quantiles of each bound over the draws.
The space's distributions are drawn once per draw; diagnosed effects with
intervals (:class:`~uqgear.physics.effect_draws.UncertainEffect`) are drawn
once per draw and passed as sample variables ``family.parameter`` (the model
must carry those effects). Without a posterior the draws are ``draws`` samples
of the distributions.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import ParameterSpaceError
from ..dynamics.stress_qois import RUN_QOI_INFO, STRESS_QOIS
from ..physics.effect_draws import UncertainEffect, draw_effect_sets
from .checks import check_count
from .parameter_space import ParameterSpace
from .parameters import Distribution, Fixed, Interval
from .seeds import SeedLike, as_seed_sequence, child_seed
from .sweeps import Sweep, evaluate_on_sweep, make_sweep

#: QoIs a prediction reports when not told.
DEFAULT_QOIS = ("peak_mesh_force", "dynamic_load_factor", "dte_rms")


def _rows(space: ParameterSpace, draws: int, effects: Sequence[UncertainEffect], seed: np.random.SeedSequence) -> dict:
    """Per draw: the posterior's rows, the distributions drawn, the effect parameters drawn."""
    posterior = space.posterior
    random = space.random_names
    size = posterior.size if posterior is not None else (draws if random or any(e.intervals for e in effects) else 1)
    rows: dict[str, np.ndarray] = {} if posterior is None else {n: posterior.column(n) for n in posterior.names}
    rng = np.random.default_rng(child_seed(seed, 0))
    unit = rng.uniform(1e-12, 1.0 - 1e-12, (size, len(random)))
    for column, name in enumerate(random):
        rows[name] = space.from_unit(name, unit[:, column])
    if any(effect.intervals for effect in effects):
        if len({effect.name for effect in effects}) != len(effects):
            raise ParameterSpaceError("effects: two effects of one family cannot both be drawn per sample")
        drawn = draw_effect_sets(effects, size, child_seed(seed, 1))
        for position, effect in enumerate(effects):
            for key in sorted(effect.intervals):
                rows[f"{effect.name}.{key}"] = np.array([one[position].values[key] for one in drawn])
    return rows


class PosteriorPrediction:
    """Quantiles over joint draws of each QoI's bounds over the interval parameters.

    Parameters
    ----------
    qoi : sequence of str
        QoIs (:data:`~uqgear.dynamics.stress_qois.RUN_QOI_INFO`: the kernels' and the tooth stresses,
        these from a model that gives them, :class:`~uqgear.dynamics.stress_qois.StressEvaluator`).
    quantiles : sequence of float
        Quantiles over the draws.
    points : int
        Nodes per interval parameter, end to end (``method="scan"``).
    method : {"scan", "vertex"}
        ``vertex``: the two ends of each interval.
    draws : int
        Samples of the space's distributions where it has no posterior.
    effects : sequence of UncertainEffect
        Effects whose parameters are drawn per draw (the model carries them).
    seed : SeedSequence or int
        Source of the distribution and effect draws.
    discrepancy : callable, optional
        ``discrepancy(points, draws, rng) -> array (draw, sweep point)``: per draw and operating point
        (``points``: name -> values per sweep point, fixed inputs included) the factor on the dynamic part
        of the response that the calibration's model discrepancy gives (:data:`DYNAMIC_PARTS` says which
        part of each QoI it scales; the other QoIs are left as the model gives them).

    Examples
    --------
    The bound of the RMS DTE over the T2 interval under a posterior of mesh
    stiffness and damping, at two speeds (short runs):

    >>> import numpy as np, xarray as xr
    >>> import uqgear
    >>> rows = np.random.default_rng(0).normal([1.0, 0.05], [0.02, 0.004], size=(2, 20, 2))
    >>> posterior = xr.Dataset({"mesh_stiffness_scale": (("chain", "draw"), rows[..., 0]),
    ...                         "zeta_mesh": (("chain", "draw"), rows[..., 1])}, attrs={"converged": 1})
    >>> space = uqgear.ParameterSpace.from_posterior(posterior, {"adhesion_torque": [25e3, 40e3]}, draws=8, seed=1)
    >>> model = uqgear.BatchEvaluator(uqgear.load_design("locomotive"), fixed={"drive_torque": 7000.0},
    ...                               n_periods=60, keep_periods=20)
    >>> prediction = uqgear.PosteriorPrediction(["dte_rms"], points=3).fit(
    ...     model, space, {"pinion_speed": [1500.0, 3000.0]})
    >>> band = prediction.result_["dte_rms"]
    >>> band.dims, prediction.model_runs_
    (('bound', 'quantile', 'pinion_speed'), 48)
    >>> bool((band.sel(bound="upper") >= band.sel(bound="lower")).all())
    True
    """

    def __init__(
        self,
        qoi: Sequence[str] = DEFAULT_QOIS,
        *,
        quantiles: Sequence[float] = (0.05, 0.5, 0.95),
        points: int = 7,
        method: str = "scan",
        draws: int = 64,
        effects: Sequence[UncertainEffect] = (),
        seed: SeedLike = 0,
        discrepancy: Any = None,
    ) -> None:
        unknown = [name for name in qoi if name not in RUN_QOI_INFO]
        if unknown or not qoi:
            raise ParameterSpaceError(f"qoi: expected names of RUN_QOI_INFO; got {unknown or list(qoi)}")
        if method not in ("scan", "vertex"):
            raise ParameterSpaceError(f"method: expected 'scan' or 'vertex'; got {method!r}")
        quantile_values = np.asarray(quantiles, dtype=float)
        if quantile_values.size == 0 or not np.all((quantile_values >= 0) & (quantile_values <= 1)):
            raise ParameterSpaceError(f"quantiles: expected probabilities in [0, 1]; got {list(quantiles)}")
        self.qoi = tuple(qoi)
        self.quantiles = tuple(float(q) for q in np.sort(quantile_values))
        self.points = check_count(points, "points")
        self.method = method
        self.draws = check_count(draws, "draws")
        self.effects = tuple(effects)
        self.seed = seed
        self.discrepancy = discrepancy

    def _nodes(self, space: ParameterSpace) -> np.ndarray:
        count = 2 if self.method == "vertex" else self.points
        axes = [np.linspace(*space.bounds(name), count) for name in space.interval_names]
        if not axes:
            return np.zeros((1, 0))
        return np.array(list(itertools.product(*axes)), dtype=float).reshape(-1, len(axes))

    def fit(
        self, evaluate: Any, space: ParameterSpace, sweep: Mapping[str, Any] | None = None
    ) -> PosteriorPrediction:
        """Run every draw at every interval node and sweep point; ``result_`` holds the quantiles of the bounds.

        Parameters
        ----------
        evaluate : callable
            The model ``samples -> Dataset`` (a :class:`~uqgear.physics.integration.BatchEvaluator`, a study's model).
        space : ParameterSpace
            Interval, random and fixed parameters, and optionally a posterior.
        sweep : mapping of str to 1-D values, optional
            Operating points (e.g. ``{"pinion_speed": speeds}``).
        """
        sweep_spec = make_sweep(sweep, space)
        rows = _rows(space, self.draws, self.effects, as_seed_sequence(self.seed))
        size = len(next(iter(rows.values()))) if rows else 1
        nodes = self._nodes(space)
        samples = self._samples(space, rows, size, nodes)
        outputs = evaluate_on_sweep(evaluate, samples, sweep_spec)
        self.rows_, self.nodes_, self.model_runs_ = rows, nodes, int(outputs.attrs["runs"])
        self.factors_ = None
        if self.discrepancy is not None:
            points = dict(sweep_spec.point_values())
            for name in space.fixed_names:
                points.setdefault(name, np.full(sweep_spec.size, cast_fixed(space[name])))
            rng = np.random.default_rng(child_seed(as_seed_sequence(self.seed), 2))
            self.factors_ = np.asarray(self.discrepancy(points, size, rng), dtype=float)  # (draw, sweep point)
            outputs = with_discrepancy(outputs, self.factors_, sweep_spec.shape, nodes.shape[0])
        self.result_ = self._result(outputs, sweep_spec, size, nodes, space.interval_names)
        return self

    def _samples(
        self, space: ParameterSpace, rows: Mapping[str, np.ndarray], size: int, nodes: np.ndarray
    ) -> xr.Dataset:
        """Samples in the order (draw, node)."""
        data = {name: np.repeat(np.asarray(values, dtype=float), nodes.shape[0]) for name, values in rows.items()}
        for column, name in enumerate(space.interval_names):
            data[name] = np.tile(nodes[:, column], size)
        for name in space.fixed_names:
            data[name] = np.full(size * nodes.shape[0], cast_fixed(space[name]))
        return xr.Dataset({name: ("sample", values) for name, values in data.items()})

    def _result(
        self, outputs: xr.Dataset, sweep: Sweep, size: int, nodes: np.ndarray, names: Sequence[str]
    ) -> xr.Dataset:
        quantiles = np.asarray(self.quantiles)
        shape = (*sweep.shape, size, nodes.shape[0])
        dims = list(sweep.names)
        result = xr.Dataset(coords={"bound": ["lower", "upper"], "quantile": quantiles, "draw": np.arange(size)})
        result = result.assign_coords(sweep.coords())
        for qoi in self.qoi:
            if qoi not in outputs and f"{qoi}_max" not in outputs:
                given = ", ".join(map(str, outputs.data_vars))
                raise ParameterSpaceError(f"qoi: {qoi!r} is not among the model's outputs ({given})")
            high = outputs[f"{qoi}_max"] if f"{qoi}_max" in outputs else outputs[qoi]
            low = outputs[f"{qoi}_min"] if f"{qoi}_min" in outputs else outputs[qoi]
            high_values = np.asarray(high.values, dtype=float).reshape(shape)
            low_values = np.asarray(low.values, dtype=float).reshape(shape)
            upper, lower = np.nanmax(high_values, axis=-1), np.nanmin(low_values, axis=-1)  # (*sweep, draw)
            stacked = np.stack([lower, upper])  # (bound, *sweep, draw)
            units, meaning = RUN_QOI_INFO[qoi]
            result[qoi] = (
                ("bound", "quantile", *dims),
                np.moveaxis(np.nanquantile(stacked, quantiles, axis=-1), 0, 1),
                {"units": units, "long_name": f"quantiles over the draws of the bounds of {meaning}"},
            )
            result[f"{qoi}_draws"] = (("draw", "bound", *dims), np.moveaxis(stacked, -1, 0), {"units": units})
            worst = np.argmax(np.where(np.isnan(high_values), -np.inf, high_values), axis=-1)  # (*sweep, draw)
            flat = worst.reshape(-1, size)
            most = np.array([np.bincount(row, minlength=nodes.shape[0]).argmax() for row in flat])
            for column, name in enumerate(names):
                result[f"{qoi}_worst_{name}"] = (
                    tuple(dims),
                    nodes[most, column].reshape(sweep.shape),
                    {"long_name": f"{name} giving the upper bound most often"},
                )
        return result


#: What the discrepancy's factor scales in each QoI: the part above the static response (the mesh force above its
#: mean, the load factors above 1; the DTE's RMS about its mean and its peak to peak whole) and the tooth stresses
#: with the load (:func:`scale_dynamic_part`); the rest are left alone.
DYNAMIC_PARTS = (
    "peak_mesh_force",
    "dynamic_load_factor",
    "load_factor_rated",
    "dte_rms",
    "dte_peak_to_peak",
    *STRESS_QOIS,
)


def _load_ratio(outputs: xr.Dataset, suffix: str, factor: np.ndarray) -> np.ndarray:
    """The peak mesh force with its dynamic part scaled by ``factor``, over the peak as the model gives it."""
    peak = np.asarray(outputs[f"peak_mesh_force{suffix}"].values, dtype=float)
    static = np.asarray(outputs["static_mesh_force"].values, dtype=float)
    return (static + (peak - static) * factor) / peak


def scale_dynamic_part(
    name: str, suffix: str, values: np.ndarray, outputs: xr.Dataset, factor: np.ndarray
) -> np.ndarray:
    """One QoI (``name`` + ``suffix``, e.g. ``_max``) with its dynamic part multiplied by ``factor``.

    The mesh force and the load factors have their part above the static load scaled, the DTE's RMS and peak to
    peak are scaled whole. A tooth stress follows the tooth load the mesh force carries: the root stress in
    proportion to it (ISO 6336-3: sigma_F = F_t Y_F Y_S ... / (b m_n)), the flank stress as its square root
    (Hertz, ISO 6336-2); both take the ratio of the scaled peak mesh force to the peak (of the same response:
    ``suffix``).

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.uq.prediction import scale_dynamic_part
    >>> outputs = xr.Dataset({"peak_mesh_force": ("sample", [150e3]), "static_mesh_force": ("sample", [100e3])})
    >>> factor = np.array([2.0])
    >>> float(scale_dynamic_part("peak_mesh_force", "", np.array([150e3]), outputs, factor)[0])
    200000.0
    >>> float(scale_dynamic_part("root_stress_peak_pinion", "", np.array([300e6]), outputs, factor)[0]) / 1e6
    400.0
    >>> round(float(scale_dynamic_part("contact_stress_peak_gear", "", np.array([1e9]), outputs, factor)[0]) / 1e6, 1)
    1154.7
    """
    if name == "peak_mesh_force":
        static = np.asarray(outputs["static_mesh_force"].values, dtype=float)
        return static + (values - static) * factor
    if name == "dynamic_load_factor":
        return 1.0 + (values - 1.0) * factor
    if name == "load_factor_rated":
        # the peak's dynamic part scaled, over the same rated force: the ratio of the scaled peak to the peak
        return values * _load_ratio(outputs, suffix, factor)
    if name.startswith("root_stress_"):
        return values * _load_ratio(outputs, suffix, factor)
    if name.startswith("contact_stress_"):
        return values * np.sqrt(_load_ratio(outputs, suffix, factor))
    # the RMS about the mean and the peak to peak of the DTE are its dynamic part already
    return values * factor


def with_discrepancy(outputs: xr.Dataset, factors: np.ndarray, sweep_shape: tuple[int, ...], nodes: int) -> xr.Dataset:
    """The model's outputs (*sweep, sample = draw x node) with each run's dynamic part scaled by its draw's factor."""
    size = factors.shape[0]
    # (draw, sweep point) -> (*sweep, draw x node), the layout of the outputs
    factor = np.repeat(factors.T.reshape(*sweep_shape, size), nodes, axis=-1)
    scaled = outputs.copy()
    for name in map(str, outputs.data_vars):
        base = name.removesuffix("_max").removesuffix("_min").removesuffix("_rest")
        if base in DYNAMIC_PARTS and outputs[name].shape == factor.shape:
            values = np.asarray(outputs[name].values, dtype=float)
            changed = scale_dynamic_part(base, name[len(base):], values, outputs, factor)
            scaled[name] = (outputs[name].dims, changed, outputs[name].attrs)
    return scaled


def cast_fixed(parameter: Interval | Distribution | Fixed) -> float:
    """A fixed parameter's value."""
    if not isinstance(parameter, Fixed):
        raise ParameterSpaceError(f"{parameter!r}: expected a fixed parameter")
    return float(parameter.value)


__all__ = ["PosteriorPrediction", "DEFAULT_QOIS", "DYNAMIC_PARTS", "scale_dynamic_part", "with_discrepancy"]
