"""Variance-based (Sobol) sensitivity indices with SALib.

The steps are kept apart, SALib style, and joined by xarray Datasets:

1. :meth:`SobolAnalysis.sample` draws the Saltelli design
   (``SALib.sample.sobol.sample``, a scrambled Sobol sequence) in the unit
   hypercube and maps it to the parameters;
2. the model runs on the samples (any way the caller likes; :meth:`fit` does
   it with one batch call over all sweep points);
3. :meth:`SobolAnalysis.analyze` computes first-order and total indices
   (optionally second-order) with bootstrap confidence intervals
   (``SALib.analyze.sobol.analyze``).

Variance-based indices need a probability distribution for every analysed
input. Interval parameters have none, so here they are treated as uniform on
their bounds; the ``distribution_assumed`` attribute of every output says so.
Random parameters are mapped through their inverse cumulative distribution
function, so the design stays a valid Saltelli design for independent inputs.
For Sobol indices from a polynomial chaos expansion see
:class:`uqgear.uq.polynomial_chaos.PolynomialChaos`.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Hashable, Mapping, Sequence
from typing import Any, cast

import numpy as np
import xarray as xr
from SALib.analyze import sobol as salib_analyze
from SALib.sample import sobol as salib_sample

from ..common.errors import ParameterSpaceError
from .checks import check_count
from .parameter_space import ParameterSpace
from .seeds import SeedLike, as_seed_sequence, child_seed, seed_attributes
from .sweeps import ModelFunction, evaluate_on_sweep, make_sweep

#: Index names of the ``index`` dimension.
SOBOL_INDICES: tuple[str, ...] = ("S1", "ST")
# bootstrap estimates of tiny samples are meaningless
_MINIMUM_BASE = 8


class SobolAnalysis:
    """Saltelli/Sobol sensitivity analysis through SALib.

    Parameters
    ----------
    n_base : int
        Base sample size N of the Saltelli design, a power of 2 (>= 8). The
        model runs ``N (D + 2)`` times, or ``N (2 D + 2)`` with second-order
        indices, for D analysed parameters (per sweep point).
    second_order : bool
        Also compute second-order indices.
    parameters : sequence of str, optional
        Parameters to analyse (default: every interval and random parameter).
        The other uncertain parameters are held at their nominal values
        (interval midpoint, distribution median), as recorded in the
        ``held_at_nominal`` attribute.
    num_resamples : int
        Bootstrap resamples for the confidence intervals.
    conf_level : float
        Confidence level of the intervals, in (0, 1).
    qoi : sequence of str, optional
        QoIs to analyse (default: every per-sample output of the model).
    seed : SeedSequence or int
        Source of the scrambling of the Sobol sequence and of the bootstrap.

    Attributes
    ----------
    result_, samples_, outputs_ : xarray.Dataset
        Set by :meth:`fit`.

    Examples
    --------
    For y = x1 + 2 x2 with x1, x2 uniform on [0, 1] (intervals are taken as
    uniform), the variances are 1/12 and 4/12: S1 = 0.2 and 0.8, and with no
    interaction the total indices equal them:

    >>> import xarray as xr
    >>> import uqgear
    >>> def linear(samples):
    ...     return xr.Dataset({"y": ("sample", (samples["x1"] + 2 * samples["x2"]).values)})
    >>> space = uqgear.ParameterSpace({"x1": uqgear.Interval(0.0, 1.0), "x2": uqgear.Interval(0.0, 1.0)})
    >>> sobol = uqgear.SobolAnalysis(n_base=256, seed=1).fit(linear, space)
    >>> sobol.result_["y"].round(2).to_pandas()
    index   S1   ST
    param
    x1     0.2  0.2
    x2     0.8  0.8
    >>> int(sobol.result_.attrs["runs"]) == 256 * (2 + 2)
    True
    """

    def __init__(
        self,
        n_base: int = 1024,
        *,
        second_order: bool = False,
        parameters: Sequence[str] | None = None,
        num_resamples: int = 100,
        conf_level: float = 0.95,
        qoi: Sequence[str] | None = None,
        seed: SeedLike | None = None,
    ) -> None:
        n_base = check_count(n_base, "n_base", _MINIMUM_BASE)
        if n_base & (n_base - 1):
            lower = 1 << (n_base.bit_length() - 1)
            raise ParameterSpaceError(
                f"n_base: the Sobol sequence needs a power of 2; got {n_base} (try {lower} or {2 * lower})"
            )
        self.n_base = n_base
        if not isinstance(second_order, (bool, np.bool_)):
            raise ParameterSpaceError(f"second_order: expected True or False; got {second_order!r}")
        self.second_order = bool(second_order)
        if parameters is not None and (isinstance(parameters, str) or not isinstance(parameters, Sequence)):
            raise ParameterSpaceError(f"parameters: expected a list of parameter names; got {parameters!r}")
        self.parameters = None if parameters is None else list(parameters)
        self.num_resamples = check_count(num_resamples, "num_resamples", 2)
        if isinstance(conf_level, bool) or not isinstance(conf_level, (int, float)) or not 0 < conf_level < 1:
            raise ParameterSpaceError(f"conf_level: expected a number in (0, 1); got {conf_level!r}")
        self.conf_level = float(conf_level)
        self.qoi = None if qoi is None else ([qoi] if isinstance(qoi, str) else list(qoi))
        if seed is None:
            raise ParameterSpaceError(
                "seed: the Sobol design is scrambled and the confidence intervals are bootstrapped; pass seed="
            )
        self.seed_sequence = as_seed_sequence(seed)

    # -- steps ----------------------------------------------------------------------

    def sample(self, space: ParameterSpace) -> xr.Dataset:
        """Draw the Saltelli design.

        Parameters
        ----------
        space : ParameterSpace
            The parameters; fixed ones are passed on unchanged.

        Returns
        -------
        xarray.Dataset
            Dimension ``sample`` of length ``N (D + 2)`` (or ``N (2 D + 2)``),
            one variable per parameter; the attributes carry what
            :meth:`analyze` needs.
        """
        names = self._parameter_names(space)
        held = {name: space.nominal(name) for name in space.uncertain_names if name not in names}
        analysed_space = space.fix(held)
        problem = _unit_problem(names)
        rng = np.random.default_rng(child_seed(self.seed_sequence, 0))
        with warnings.catch_warnings():
            # SALib warns about sample sizes; ours are checked to be powers of 2
            warnings.simplefilter("ignore", UserWarning)
            unit = salib_sample.sample(
                problem, self.n_base, calc_second_order=self.second_order, scramble=True, seed=rng
            )
        data_vars = {}
        for name in space.names:
            if name in names:
                values = analysed_space.from_unit(name, unit[:, names.index(name)])
            else:
                values = np.full(unit.shape[0], analysed_space.nominal(name))
            data_vars[name] = ("sample", values, {"units": space.units(name), "description": space[name].describe()})
        attrs = {
            "method": "saltelli_sobol_design (SALib.sample.sobol.sample, scrambled)",
            "n_base": self.n_base,
            "second_order": int(self.second_order),
            "sobol_parameters": json.dumps(names),
            "distribution_assumed": _assumed_distributions(space, names),
            "held_at_nominal": json.dumps(held),
            "parameter_space": space.to_json(),
            **seed_attributes(self.seed_sequence),
        }
        return xr.Dataset(data_vars, coords={"sample": np.arange(unit.shape[0])}, attrs=attrs)

    def analyze(self, samples: xr.Dataset, outputs: xr.Dataset) -> xr.Dataset:
        """Sobol indices with bootstrap confidence intervals.

        Parameters
        ----------
        samples : xarray.Dataset
            As returned by :meth:`sample`.
        outputs : xarray.Dataset
            Model outputs with dims ``(*sweep, "sample")`` (the sample
            dimension last or not; other dims are kept).

        Returns
        -------
        xarray.Dataset
            For each QoI ``q``: ``q`` and ``q_conf`` with dims
            ``(*sweep, "param", "index")`` (index: S1, ST; ``q_conf`` is the
            half-width of the ``conf_level`` interval); with second-order
            indices also ``q_S2`` and ``q_S2_conf`` with dims
            ``(*sweep, "param", "param_2")``. A QoI that does not vary, or
            has non-finite values, gets NaN indices (counted in
            ``nonfinite_outputs``).
        """
        if not isinstance(samples, xr.Dataset) or "sobol_parameters" not in samples.attrs:
            raise ParameterSpaceError(
                "samples: expected the Dataset returned by SobolAnalysis.sample (attribute sobol_parameters missing)"
            )
        names = json.loads(samples.attrs["sobol_parameters"])
        second_order = bool(samples.attrs["second_order"])
        if second_order != self.second_order:
            raise ParameterSpaceError(
                f"second_order: the samples were drawn with second_order={second_order}, "
                f"this analysis has second_order={self.second_order}"
            )
        size = samples.sizes["sample"]
        if not isinstance(outputs, xr.Dataset) or outputs.sizes.get("sample") != size:
            raise ParameterSpaceError(
                f"outputs: expected an xarray.Dataset with dimension 'sample' of length "
                f"{size} (one value per Saltelli sample)"
            )
        qoi_names = _qoi_names(outputs, self.qoi)
        problem = _unit_problem(names)
        bootstrap_seed = int(child_seed(self.seed_sequence, 1).generate_state(1, np.uint32)[0]) % (2**31 - 1) + 1
        data_vars: dict[str, Any] = {}
        nonfinite: dict[str, int] = {}
        for name in qoi_names:
            variables, bad = _qoi_indices(
                name,
                outputs[name],
                problem,
                names,
                second_order=second_order,
                num_resamples=self.num_resamples,
                conf_level=self.conf_level,
                seed=bootstrap_seed,
            )
            data_vars.update(variables)
            if bad:
                nonfinite[name] = bad
        coords = _result_coords(outputs, names, second_order)
        attrs = _result_attributes(samples, self, bootstrap_seed, int(np.prod(list(outputs[qoi_names[0]].shape))))
        attrs.update(nonfinite_outputs=json.dumps(nonfinite))
        return xr.Dataset(data_vars, coords=coords, attrs=attrs)

    def fit(
        self, evaluate: ModelFunction, space: ParameterSpace, sweep: Mapping[str, Any] | None = None
    ) -> SobolAnalysis:
        """Sample, run the model once on all samples at all sweep points, analyse.

        Parameters
        ----------
        evaluate : callable
            The model function.
        space : ParameterSpace
            The parameters.
        sweep : mapping of str to 1-D values, optional
            Deterministic variables; the indices are computed at every sweep
            point (e.g. index against pinion speed).

        Returns
        -------
        SobolAnalysis
            ``self`` with ``result_``, ``samples_`` and ``outputs_`` set.
        """
        sweep_spec = make_sweep(sweep, space)
        self.samples_ = self.sample(space)
        self.outputs_ = evaluate_on_sweep(evaluate, self.samples_, sweep_spec, qoi=self.qoi)
        self.result_ = self.analyze(self.samples_, self.outputs_)
        return self

    # -- internals ------------------------------------------------------------------

    def _parameter_names(self, space: ParameterSpace) -> list[str]:
        return _parameter_names(space, self.parameters, self.second_order)


def _parameter_names(space: ParameterSpace, parameters: Sequence[str] | None, second_order: bool) -> list[str]:
    """The analysed parameters: ``parameters`` (default every uncertain one of ``space``), checked."""
    if not isinstance(space, ParameterSpace):
        raise ParameterSpaceError(f"space: expected a ParameterSpace; got {type(space).__name__}")
    uncertain = list(space.uncertain_names)
    names = list(parameters) if parameters is not None else uncertain
    for name in names:
        if name not in uncertain:
            raise ParameterSpaceError(
                f"parameters: {name!r} is not an interval or random parameter of the "
                f"space; expected some of {', '.join(uncertain) or '(none)'}"
            )
    if len(set(names)) != len(names):
        raise ParameterSpaceError(f"parameters: duplicate names in {names}")
    if not names:
        raise ParameterSpaceError("space: Sobol analysis needs at least one interval or random parameter")
    if second_order and len(names) < 2:
        raise ParameterSpaceError("second_order: needs at least two analysed parameters")
    return names


def _qoi_names(outputs: xr.Dataset, qoi: Sequence[str] | None) -> list[str]:
    """The QoIs analysed: ``qoi``, checked against the outputs, or every numeric output with a sample dim."""
    # the model's outputs are named by strings
    qoi_names = [
        name
        for name, variable in cast(Mapping[str, xr.DataArray], outputs.data_vars).items()
        if "sample" in variable.dims and np.issubdtype(variable.dtype, np.number)
    ]
    if qoi is not None:
        missing = [name for name in qoi if name not in qoi_names]
        if missing:
            raise ParameterSpaceError(f"qoi: {', '.join(missing)} not among the outputs ({', '.join(qoi_names)})")
        qoi_names = list(qoi)
    if not qoi_names:
        raise ParameterSpaceError("outputs: no numeric variable with dimension 'sample'")
    return qoi_names


def _result_coords(outputs: xr.Dataset, names: Sequence[str], second_order: bool) -> dict[Hashable, Any]:
    """The result's coordinates: the outputs' other than the samples', the parameters and the indices."""
    coords: dict[Hashable, Any] = {
        dim: outputs.coords[dim] for dim in outputs.coords if "sample" not in outputs.coords[dim].dims
    }
    coords.update(param=("param", list(names)), index=("index", list(SOBOL_INDICES)))
    if second_order:
        coords["param_2"] = ("param_2", list(names))
    return coords


def _result_attributes(samples: xr.Dataset, analysis: SobolAnalysis, bootstrap_seed: int, runs: int) -> dict[str, Any]:
    """The result's attributes: the design's (taken from ``samples``), the method and the bootstrap's settings."""
    attrs = {
        key: samples.attrs[key]
        for key in (
            "n_base",
            "second_order",
            "distribution_assumed",
            "held_at_nominal",
            "parameter_space",
            "seed_entropy",
            "seed_spawn_key",
        )
        if key in samples.attrs
    }
    attrs.update(
        method="sobol (SALib.analyze.sobol.analyze, Saltelli 2010 / Jansen estimators)",
        num_resamples=analysis.num_resamples,
        conf_level=analysis.conf_level,
        bootstrap_seed=bootstrap_seed,
        runs=runs,
    )
    return attrs


def _unit_problem(names: Sequence[str]) -> dict[str, Any]:
    """SALib's problem over the analysed parameters."""
    # SALib works in the unit hypercube; the inverse CDFs map to the parameters
    return {"num_vars": len(names), "names": list(names), "bounds": [[0.0, 1.0]] * len(names)}


def _assumed_distributions(space: ParameterSpace, names: Sequence[str]) -> str:
    """JSON of the distribution each analysed parameter is taken to have (``distribution_assumed``)."""
    assumed = {}
    for name in names:
        if name in space.interval_names:
            assumed[name] = (
                f"uniform on {space[name].describe()} (assumed for variance-based sensitivity "
                f"only: an interval implies no distribution)"
            )
        else:
            assumed[name] = space[name].describe()
    return json.dumps(assumed)


def _qoi_indices(
    name: str,
    output: xr.DataArray,
    problem: Mapping[str, Any],
    names: Sequence[str],
    *,
    second_order: bool,
    num_resamples: int,
    conf_level: float,
    seed: int,
) -> tuple[dict[str, Any], int]:
    """The index variables of one QoI (:meth:`SobolAnalysis.analyze`), and how many of its sample columns
    had non-finite values (their indices are NaN)."""
    variable = output.transpose(..., "sample")
    other_dims = variable.dims[:-1]
    shape = variable.shape[:-1]
    columns = np.asarray(variable.values, dtype=float).reshape(-1, variable.shape[-1])
    first_total = np.full((columns.shape[0], len(names), 2), np.nan)
    confidence = np.full_like(first_total, np.nan)
    second = np.full((columns.shape[0], len(names), len(names)), np.nan)
    second_confidence = np.full_like(second, np.nan)
    bad = 0
    for row, y in enumerate(columns):
        if not np.all(np.isfinite(y)):
            bad += 1
            continue
        if np.ptp(y) == 0.0:
            continue  # variance zero: the indices are undefined
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            indices = salib_analyze.analyze(
                problem,
                y,
                calc_second_order=second_order,
                num_resamples=num_resamples,
                conf_level=conf_level,
                print_to_console=False,
                seed=seed,
            )
        first_total[row] = np.stack([indices["S1"], indices["ST"]], axis=-1)
        confidence[row] = np.stack([indices["S1_conf"], indices["ST_conf"]], axis=-1)
        if second_order:
            second[row] = indices["S2"]
            second_confidence[row] = indices["S2_conf"]
    units_note = {"units": "1"}
    data_vars: dict[str, Any] = {}
    data_vars[name] = (
        (*other_dims, "param", "index"),
        first_total.reshape(*shape, len(names), 2),
        {**units_note, "long_name": f"Sobol indices of {name}"},
    )
    data_vars[f"{name}_conf"] = (
        (*other_dims, "param", "index"),
        confidence.reshape(*shape, len(names), 2),
        {**units_note, "long_name": f"half-width of the {conf_level:g} bootstrap confidence interval"},
    )
    if second_order:
        data_vars[f"{name}_S2"] = (
            (*other_dims, "param", "param_2"),
            second.reshape(*shape, len(names), len(names)),
            {**units_note, "long_name": f"second-order Sobol indices of {name} (upper triangle)"},
        )
        data_vars[f"{name}_S2_conf"] = (
            (*other_dims, "param", "param_2"),
            second_confidence.reshape(*shape, len(names), len(names)),
            {**units_note, "long_name": "half-width of the bootstrap confidence interval"},
        )
    return data_vars, bad
