"""Running the analyses of a study: one function per analysis type, results as Datasets.

Each analysis type of :data:`uqgear.study.ANALYSIS_SCHEMAS` has a function
here, registered with :func:`register`, that takes an :class:`AnalysisContext`
(the validated study, the analysis's options, its seed and the runner) and
returns an :class:`xarray.Dataset` with named dims and units. Adding a type is
one schema entry in :mod:`uqgear.study.analysis_schemas` and one function here (plus, for its
figures, a renderer in one of the ``uqgear.report.*_sections`` modules).

All model runs go through :func:`evaluate_batch`, a picklable model function
``samples -> results`` executed by a :class:`uqgear.uq.runner.Runner`: in-process
(all local cores), or on a dask scheduler, chunked and checkpointed so a
killed run resumes. :func:`uqgear.study.running.run_analyses` runs every
analysis of a study and writes one ``<name>.nc`` per analysis with provenance.

Randomness: one :class:`numpy.random.SeedSequence` per study (the ``seed``
key), one child per analysis in list order (:meth:`Study.seed_sequences`),
and children of that per stage. Same seed, same numbers.
"""

from __future__ import annotations

import dataclasses
import functools
import json
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np
import xarray as xr

import uqgear.dynamics as dynamics

from ..common.progress import progress
from ..dynamics.attractors import final_variables
from ..dynamics.stress_qois import RUN_QOI_INFO, StressEvaluator
from ..physics.design import Design
from ..physics.effect_draws import UncertainEffect
from ..physics.integration import BatchEvaluator
from ..physics.rating import RatingSettings
from ..uq.monte_carlo import monte_carlo_statistics
from ..uq.parameter_space import ParameterSpace
from ..uq.parameters import Fixed
from ..uq.polynomial_chaos import PolynomialChaos
from ..uq.posterior import PosteriorDraws
from ..uq.runner import Runner
from ..uq.seeds import child_seed
from ..uq.sweeps import evaluate_on_sweep
from .analysis_specs import AnalysisSpec
from .coexistence import MultiStartModel, interval_over_attractors, multi_start_model
from .guided_starts import GuidedStartModel, guided_start_model, widen_over_attractors
from .model_runs import RememberedRuns, RunnerModel
from .point_run import simulate_point
from .schema import Study
from .settings import SimulationSettings
from .variables import variable_units_short

#: Attribute holding the hash of an analysis's inputs (reuse on resume).
ANALYSIS_KEY_ATTR = "analysis_key"

AnalysisFunction = Callable[["AnalysisContext"], xr.Dataset]
#: Analysis type -> function computing its result.
ANALYSES: dict[str, AnalysisFunction] = {}


def register(kind: str) -> Callable[[AnalysisFunction], AnalysisFunction]:
    """Decorator registering the function of an analysis type."""

    def decorate(function: AnalysisFunction) -> AnalysisFunction:
        ANALYSES[kind] = function
        return function

    return decorate


# ---------------------------------------------------------------------------- the model


def evaluate_batch(
    samples: xr.Dataset,
    *,
    design: Design,
    simulation: SimulationSettings,
    threads: int | None = None,
    classify: bool = False,
    classify_seed: np.random.SeedSequence | None = None,
    poincare: bool = True,
    final_state: bool = False,
) -> xr.Dataset:
    """The gear model as a batch function: samples in, QoIs and Poincare points out.

    Module-level (picklable) so that a dask worker can run it. The model call
    is :class:`~uqgear.physics.integration.BatchEvaluator`'s; this adds what
    studies need: the study's simulation settings, classification and
    dropping the Poincare points.

    Parameters
    ----------
    samples : xarray.Dataset
        Dim ``sample``; variables ``pinion_speed`` (rpm), ``drive_torque``,
        ``adhesion_torque`` (N m), ``mesh_stiffness_scale`` and design keys.
    design : Design
        The base design.
    simulation : SimulationSettings
        Periods integrated and kept, Lyapunov exponent, integrator settings.
    threads : int, optional
        Threads of the batch integrator (default: all cores).
    classify : bool
        Also classify each response (``regime``, ``response_period``,
        ``zero_one_k``, ``distinct_points``).
    classify_seed : SeedSequence, optional
        Seed of the 0-1 test frequencies (the same for every chunk).
    poincare : bool
        Keep the Poincare points (``period`` dim); analyses of scalar QoIs
        drop them, which keeps checkpoints small.
    final_state : bool
        Also return each run's final state as ``final_<state>`` (what a sweep carries on, the layout of
        :class:`~uqgear.dynamics.attractors.StartedEvaluator`).

    Returns
    -------
    xarray.Dataset
        The :func:`~uqgear.physics.integration.simulate_batch` outputs (dims
        ``sample``, ``period``), input variables as coordinates.
    """
    options = simulation.batch_options(threads)
    model = (
        BatchEvaluator(design, **options, final_state=final_state)
        if simulation.stresses is None
        else StressEvaluator(design, rating=simulation.stresses, **options, final_state=final_state)
    )
    result = model(samples)
    if final_state:
        result = final_variables(result)
    if classify:
        seed = classify_seed if classify_seed is not None else 0
        classes = dynamics.classify_batch(result, seed=seed)
        result = result.merge(classes, compat="override")
    if not poincare:
        result = result.drop_dims("period")
    return result


# ---------------------------------------------------------------------------- context


@dataclass
class AnalysisContext:
    """Everything an analysis function needs.

    Attributes
    ----------
    study : Study
    spec : AnalysisSpec
        The analysis (type, options, merged operating points and settings).
    seed : numpy.random.SeedSequence
        This analysis's seed (a child of the study seed).
    runner : Runner
        Executes model batches.
    resume : bool
        Reuse checkpoints.
    threads : int, optional
        Threads for in-process batch integration.
    notes : list of str
        Remarks an analysis wants in its result (attribute ``notes``).
    posterior : PosteriorDraws, optional
        The study's calibrated posterior (``uncertain.calibrated``), thinned to
        its ``draws``; analyses that do not propagate it take its medians.
    effects : tuple of UncertainEffect
        The study's diagnosed effects (``model.effects``) with their
        uncertainty; every run carries them at their fitted values
        (``spec.simulation.effects``), a prediction samples them.
    discrepancy : Discrepancy, optional
        The model discrepancy the calibration learnt (a calibration with
        ``discrepancy: true``); a prediction carries it.
    """

    study: Study
    spec: AnalysisSpec
    seed: np.random.SeedSequence
    runner: Runner
    resume: bool = False
    threads: int | None = None
    notes: list[str] = field(default_factory=list)
    posterior: PosteriorDraws | None = None
    effects: tuple[UncertainEffect, ...] = ()
    discrepancy: Any = None

    @property
    def design(self) -> Design:
        return self.study.design

    @property
    def options(self) -> Mapping[str, Any]:
        return self.spec.options

    def stage_seed(self, stage: int) -> np.random.SeedSequence:
        """Seed of one stage of this analysis (sampling, validation, bootstrap, ...)."""
        return child_seed(self.seed, stage)

    def model(
        self, *, classify: bool = False, lyapunov: bool | None = None, poincare: bool = True
    ) -> RunnerModel | MultiStartModel | GuidedStartModel:
        """The gear model for this analysis, evaluated through the runner.

        ``poincare=False`` drops the Poincare points from the outputs (scalar
        QoIs only). With ``simulation.starts`` every point is run from several
        starts (:class:`~uqgear.study.coexistence.MultiStartModel`); with guided
        starts (the default) only the points inside the coexistence windows
        (:class:`~uqgear.study.guided_starts.GuidedStartModel`).
        """
        simulation = self.spec.simulation
        if lyapunov is not None and lyapunov != simulation.lyapunov:
            simulation = dataclasses.replace(simulation, lyapunov=lyapunov)
        if simulation.starts is not None and not simulation.starts.guided:
            return multi_start_model(self, simulation, poincare)
        if simulation.starts is not None:
            # the rest runs keep their Poincare points: the window points' rest runs are grouped from them
            # and their final states: the sweeps start and enter the window stretches from them
            rest = self.rest_model(
                dataclasses.replace(simulation, starts=None), classify=classify, poincare=True, final_state=True
            )
            return guided_start_model(self, simulation, rest, poincare)
        return self.rest_model(simulation, classify=classify, poincare=poincare)

    def rest_model(
        self,
        simulation: SimulationSettings,
        *,
        classify: bool = False,
        poincare: bool = True,
        final_state: bool = False,
    ) -> RunnerModel:
        """The model with every point run from rest (what a study without starts runs); ``final_state`` adds each
        run's final state (:func:`evaluate_batch`)."""
        function = functools.partial(
            evaluate_batch,
            design=self.design,
            simulation=simulation,
            threads=self.threads,
            classify=classify,
            classify_seed=self.stage_seed(99) if classify else None,
            poincare=poincare,
            final_state=final_state,
        )
        # the runner's checkpoint hash covers the samples and the function name, not the
        # partial's arguments: the key carries them
        key = json.dumps(
            {
                "analysis": self.spec.name,
                "design": self.design.to_dict(),
                "simulation": simulation.to_dict(),
                "classify": classify,
                "poincare": poincare,
                "seed": [str(self.seed.entropy), list(self.seed.spawn_key)],
                # only then: the keys of existing checkpoints stay as they were
                **({"final_state": True} if final_state else {}),
            },
            sort_keys=True,
        )
        return RunnerModel(self.runner, function, key, self.resume)

    def fixed_values(self, exclude: Sequence[str] = ()) -> dict[str, float]:
        """Values of every input not varied by the analysis.

        Fixed operating points, then uncertain parameters not in ``exclude``
        at their nominal value (interval midpoint, distribution median; a
        calibrated parameter at its posterior median), then
        the drive torque (the design's rated torque) and the adhesion torque
        (the value balancing the drive torque, T1 z2 / z1) if still unset.
        """
        values = dict(self.spec.fixed)
        for name, parameter in self.study.uncertain.items():
            if name not in exclude and name not in values and name not in self.spec.sweeps:
                values[name] = parameter.nominal
        if self.posterior is not None:
            for name in self.posterior.names:
                if name not in exclude and name not in values and name not in self.spec.sweeps:
                    values[name] = self.posterior.median(name)
        for name in exclude:
            values.pop(name, None)
        if "drive_torque" not in values and "drive_torque" not in exclude and "drive_torque" not in self.spec.sweeps:
            values["drive_torque"] = self.design.operation.drive_torque
        if (
            "adhesion_torque" not in values
            and "adhesion_torque" not in exclude
            and "adhesion_torque" not in self.spec.sweeps
        ):
            drive = values.get("drive_torque", self.design.operation.drive_torque)
            values["adhesion_torque"] = drive * self.design.z2 / self.design.z1
        return values

    def axis_values(self, name: str) -> np.ndarray:
        """Values along a grid axis: an operating sweep, or ``points`` across an interval."""
        if name in self.spec.sweeps:
            return np.asarray(self.spec.sweeps[name].values, dtype=float)
        parameter = self.study.uncertain[name]
        return np.linspace(parameter.lower, parameter.upper, int(self.options["points"]))

    def parameter_space(self, names: Sequence[str], fixed: Mapping[str, float]) -> ParameterSpace:
        """Space of the propagated parameters plus the fixed inputs (as Fixed)."""
        parameters: dict[str, Any] = {name: self.study.uncertain[name].to_parameter() for name in names}
        for name, value in fixed.items():
            parameters[name] = Fixed(value, units=variable_units_short(name))
        return ParameterSpace(parameters)

    def sweep(self) -> dict[str, xr.DataArray]:
        """The operating sweeps as DataArrays with units (the uncertainty layer's sweep)."""
        return {
            name: xr.DataArray(np.asarray(spec.values), dims=name, attrs={"units": variable_units_short(name)})
            for name, spec in self.spec.sweeps.items()
        }


# ---------------------------------------------------------------------------- helpers


def _coordinate(name: str, values: Sequence[float]) -> tuple[str, np.ndarray, dict[str, str]]:
    return (
        name,
        np.asarray(values, dtype=float),
        {"units": variable_units_short(name), "long_name": name.replace("_", " ")},
    )


def _grid_samples(axes: Mapping[str, np.ndarray], fixed: Mapping[str, float]) -> xr.Dataset:
    """Samples of the Cartesian product of ``axes`` (C order) plus fixed values."""
    mesh = np.meshgrid(*axes.values(), indexing="ij")
    n = mesh[0].size
    data = {name: ("sample", grid.ravel()) for name, grid in zip(axes, mesh)}
    data.update({name: ("sample", np.full(n, float(value))) for name, value in fixed.items()})
    return xr.Dataset(data)


def _grid_run(context: AnalysisContext, axes: Mapping[str, np.ndarray], *, lyapunov: bool | None = None) -> xr.Dataset:
    """Run and classify the model on a grid; dims are the axes (in order) and ``period``."""
    fixed = context.fixed_values(exclude=list(axes))
    model = context.model(lyapunov=lyapunov)
    gridded = dynamics.sweep_grid(context.design, axes, fixed=fixed, seed=context.stage_seed(99), evaluate=model)
    for name in axes:
        gridded[name].attrs.update({"units": variable_units_short(name), "long_name": name.replace("_", " ")})
    gridded.attrs.update(model_runs=int(model.runs), fixed_inputs=json.dumps(fixed))
    return gridded


# ---------------------------------------------------------------------------- analyses


def quick_run(
    design: Design,
    pinion_speed: float,
    drive_torque: float,
    adhesion_torque: float,
    *,
    n_periods: int = 400,
    keep_periods: int = 200,
    samples_per_period: int = 64,
) -> xr.Dataset:
    """One operating point, classified with the help of its Lyapunov exponent (``uqgear simulate``).

    Returns the Dataset of :func:`simulate_point`, with the QoIs, the regime
    and its reason also as attributes.
    """
    simulation = SimulationSettings(n_periods=n_periods, keep_periods=keep_periods, lyapunov=True)
    point = {
        "pinion_speed": float(pinion_speed),
        "drive_torque": float(drive_torque),
        "adhesion_torque": float(adhesion_torque),
    }
    samples = xr.Dataset({name: ("sample", [value]) for name, value in point.items()})
    batch = evaluate_batch(samples, design=design, simulation=simulation)
    run = simulate_point(
        design,
        point,
        simulation=simulation,
        samples_per_period=samples_per_period,
        largest_lyapunov=float(batch["largest_lyapunov"].values[0]),
    )
    for name, variable in run.data_vars.items():
        if variable.ndim == 0:
            value = variable.values.item()
            run.attrs[name] = value if isinstance(value, str) else float(value)
    run.attrs["design_name"] = design.name
    return run


@register("simulate")
def simulate_analysis(context: AnalysisContext) -> xr.Dataset:
    """Full time histories at each operating point, with Poincare points, spectra and regime.

    Output dims: ``run`` (the operating points, with one coordinate per swept
    variable), ``mesh_cycle`` (time in mesh periods), ``period`` (Poincare
    section) and ``order`` (DTE spectrum against multiples of the pinion
    rotation; ``spectrum_frequency`` gives each bin in Hz).
    """
    spec = context.spec
    options = context.options
    sweeps = {name: np.asarray(s.values) for name, s in spec.sweeps.items()}
    fixed = context.fixed_values(exclude=list(sweeps))
    grid = (
        _grid_samples(sweeps, fixed)
        if sweeps
        else xr.Dataset({name: ("sample", [float(value)]) for name, value in fixed.items()})
    )
    points = [{name: float(grid[name].values[i]) for name in grid.data_vars} for i in range(grid.sizes["sample"])]
    # Lyapunov exponents from a batch run of the same points decide chaotic vs quasi-periodic
    model = context.model(classify=False, lyapunov=True)
    batch = model(grid)
    # the panels start from rest: with several starts, the rest start's exponent
    exponent = batch["largest_lyapunov_rest" if "largest_lyapunov_rest" in batch else "largest_lyapunov"].values
    labels = list(options["labels"]) or [""] * len(points)
    runs = [
        simulate_point(
            context.design,
            point,
            simulation=spec.simulation,
            samples_per_period=options["samples_per_period"],
            method=options["method"],
            largest_lyapunov=float(exponent[index]),
            seed=context.stage_seed(0),
            label=labels[index],
            rating=RatingSettings.from_mapping(options.get("rating")),
        )
        for index, point in enumerate(progress(points, desc=f"{spec.name}: simulate", unit="run"))
    ]
    # the runs share sample counts, periods and spectrum bins (same settings), so they stack
    result = xr.concat(
        runs, dim="run", coords="minimal", compat="override", join="override", combine_attrs="drop_conflicts"
    )
    result = result.assign_coords(run=("run", np.arange(len(points)), {"units": "1"}))
    if "attractor_count" in batch:
        # every steady response the point holds, besides the panels' one from rest
        result = result.merge(
            batch[[name for name in cast(Iterable[str], batch.data_vars) if name.startswith("attractor_")]]
            .rename({"sample": "run"})
            .drop_vars(list(batch.coords), errors="ignore")
        )
    result.attrs.update(
        model_runs=len(points) + int(model.runs),
        swept=json.dumps(list(sweeps)),
        fixed_inputs=json.dumps(fixed),
        spectrum_axis=options["spectrum"],
        classification="period from the Poincare sequence; chaotic vs quasi-periodic by "
        "the largest Lyapunov exponent of a batch run of the same point",
    )
    return result


@register("bifurcation")
def bifurcation_analysis(context: AnalysisContext) -> xr.Dataset:
    """Poincare points and regime against one parameter, optionally over interval parameters.

    Output dims: the swept parameter, one dim per ``envelope`` parameter
    (``points`` values across its interval) and ``period``. The bifurcation
    envelope at a parameter value is the union of its Poincare points over
    the envelope dims; every point keeps the envelope values that made it.
    """
    options = context.options
    axes = {options["parameter"]: context.axis_values(options["parameter"])}
    for name in options["envelope"]:
        axes[name] = context.axis_values(name)
    result = _grid_run(context, axes, lyapunov=context.spec.simulation.lyapunov)
    result.attrs.update(parameter=options["parameter"], envelope=json.dumps(list(options["envelope"])))
    return result


@register("regime_map")
def regime_map_analysis(context: AnalysisContext) -> xr.Dataset:
    """Response regime on the grid of two variables (e.g. pinion speed x adhesion torque)."""
    axes = {name: context.axis_values(name) for name in context.options["axes"]}
    result = _grid_run(context, axes, lyapunov=context.spec.simulation.lyapunov)
    result.attrs.update(axes=json.dumps(list(axes)))
    return result


#: What the statistics of a sample see where several steady responses coexist, by the ``response`` key.
RESPONSE_TREATMENT = {
    "worst": "the worst response at each sample (the attractor with the largest peak mesh force; a response that "
    "jumps between attractors is a discontinuous function of the inputs, taken as it is)",
    "rest": "the response reached from rest at each sample (as a start from standstill reaches it); every sample "
    "runs from rest only",
}


def _statistics_model(context: AnalysisContext) -> RunnerModel | MultiStartModel | GuidedStartModel:
    """The model of a statistics analysis (monte_carlo, pce, sobol) by its ``response`` key: the worst response
    over the starts the study sets, or the response from rest alone."""
    simulation = context.spec.simulation
    if context.options["response"] == "rest" or simulation.starts is None:
        return context.rest_model(dataclasses.replace(simulation, starts=None), poincare=False)
    return context.model(poincare=False)


def _response_attrs(context: AnalysisContext) -> dict[str, str]:
    """The ``response`` attributes of a statistics analysis's result (said in the report's facts)."""
    response = str(context.options["response"])
    if context.spec.simulation.starts is None:
        return {"response": "rest", "response_treatment": "every sample runs from rest (simulation.starts: false)"}
    return {"response": response, "response_treatment": RESPONSE_TREATMENT[response]}


@register("monte_carlo")
def monte_carlo_analysis(context: AnalysisContext) -> xr.Dataset:
    """Monte Carlo statistics of the QoIs at every operating point.

    With ``intervals: uniform`` (default) interval parameters among
    ``parameters`` are sampled uniformly on their bounds (an assumption
    stated in ``interval_treatment``). With ``intervals: pbox`` the random
    parameters are sampled at every node of a scan over the intervals and
    the statistics are bounded over the intervals: a probability box
    (:func:`uqgear.uq.interval.pbox`); every statistic then has a ``bound`` dim.
    """
    options = context.options
    names = list(options["parameters"])
    fixed = context.fixed_values(exclude=names)
    space = context.parameter_space(names, fixed)
    model = _statistics_model(context)
    if options["intervals"] == "pbox":
        from ..uq.interval import IntervalAnalysis
        from ..uq.pbox import pbox

        result = pbox(
            model,
            space,
            n_samples=options["samples"],
            seed=context.stage_seed(0),
            sweep=context.sweep(),
            quantiles=options["quantiles"],
            sampling=options["sampling"],
            qoi=list(options["qois"]),
            analysis=IntervalAnalysis("scan", scan_points=options["points"]),
        )
        result.attrs.update(
            **_response_attrs(context),
            model_runs=int(model.runs),
            parameters=json.dumps(names),
            fixed_inputs=json.dumps(fixed),
            interval_treatment="p-box: statistics bounded over "
            "the interval parameters (no distribution assumed for them)",
        )
        return result
    samples = space.sample(
        options["samples"], options["sampling"], seed=context.stage_seed(0), interval_treatment="uniform"
    )
    outputs = evaluate_on_sweep(model, samples, context.sweep(), qoi=list(options["qois"]))
    statistics = monte_carlo_statistics(outputs, quantiles=options["quantiles"])
    for name in options["qois"]:
        statistics[f"{name}_samples"] = outputs[name]
    for name in names:
        statistics[f"input_{name}"] = (
            "sample",
            samples[name].values,
            {"units": variable_units_short(name), "long_name": f"sampled {name}"},
        )
    statistics.attrs.update(samples.attrs)
    statistics.attrs.update(
        **_response_attrs(context),
        model_runs=int(model.runs),
        parameters=json.dumps(names),
        fixed_inputs=json.dumps(fixed),
    )
    return statistics


@register("pce")
def pce_analysis(context: AnalysisContext) -> xr.Dataset:
    """Polynomial chaos surrogate per operating point, with an independent validation error.

    The order is chosen by leave-one-out error; ``validation_samples`` fresh
    model runs (another seed stream) measure the surrogate's error, reported
    per QoI as ``<qoi>_validation_error`` (RMS error / standard deviation of
    the model outputs).
    """
    options = context.options
    names = list(options["parameters"])
    fixed = context.fixed_values(exclude=names)
    space = context.parameter_space(names, fixed)
    model = _statistics_model(context)
    chaos = PolynomialChaos(
        max_order=options["order"],
        min_order=options["min_order"],
        n_samples=options["samples"] or None,
        sampling=options["sampling"],
        qoi=list(options["qois"]),
        seed=context.stage_seed(0),
    )
    chaos.fit(model, space, context.sweep())
    result = chaos.result_.copy()
    check_samples = space.sample(
        options["validation_samples"], "monte_carlo", seed=context.stage_seed(1), interval_treatment="uniform"
    )
    truth = evaluate_on_sweep(model, check_samples, context.sweep(), qoi=list(options["qois"]))
    predicted = chaos.predict(check_samples)
    for name in options["qois"]:
        model_values = truth[name].rename({"sample": "check"})
        surrogate_values = predicted[name].rename({"sample": "check"}).transpose(*model_values.dims)
        error = np.sqrt(((surrogate_values - model_values) ** 2).mean("check"))
        spread = model_values.std("check")
        relative = (error / spread.where(spread > 0)).fillna(0.0).where(np.isfinite(error))
        result[f"{name}_validation_error"] = relative.assign_attrs(
            units="1", long_name=f"RMS surrogate error at independent check points / std of {name}"
        )
        result[f"{name}_validation_model"] = model_values.drop_vars("check", errors="ignore").assign_attrs(
            units=RUN_QOI_INFO[name][0], long_name=f"{name} from the model at the check points"
        )
        result[f"{name}_validation_surrogate"] = surrogate_values.drop_vars("check", errors="ignore").assign_attrs(
            units=RUN_QOI_INFO[name][0], long_name=f"{name} from the surrogate at the check points"
        )
    result.attrs.update(
        **_response_attrs(context),
        model_runs=int(model.runs),
        parameters=json.dumps(names),
        fixed_inputs=json.dumps(fixed),
        validation_samples=options["validation_samples"],
    )
    return result


@register("interval")
def interval_analysis(context: AnalysisContext) -> xr.Dataset:
    """Bounds of each QoI over the interval parameters at every operating point.

    Runs :class:`uqgear.uq.interval.IntervalAnalysis` (scan, vertex, Chebyshev
    inclusion or optimisation) with its own checks: where a surrogate's
    estimated error is large or the response is non-smooth (contact-loss
    fractions that are not QoIs serve as regime indicators) the point is
    flagged and recomputed by the fallback. Adds ``<qoi>_nominal``, the
    response at the interval midpoints, for reference.
    """
    return interval_bounds(context)


def interval_bounds(context: AnalysisContext, guided: GuidedStartModel | None = None) -> xr.Dataset:
    """:func:`interval_analysis` with ``guided``, the guided model to run (default: a new one where the study's
    starts are guided), for a caller that reads its attractors afterwards."""
    from ..uq.interval import IntervalAnalysis

    options = context.options
    names = list(options["parameters"])
    qois = list(options["qois"])
    fixed = context.fixed_values(exclude=names)
    starts = context.spec.simulation.starts
    if starts is not None and not starts.guided:
        return interval_over_attractors(context, names, qois, fixed)
    space = context.parameter_space(names, fixed)
    regime_variables = [name for name in ("fraction_separation", "fraction_back_contact") if name not in qois]
    if starts is not None:
        # the bounds from rest run through the guided model's rest runs, remembered: where its window points are
        # scan nodes the widening below meets them again and runs only their extra starts
        guided = guided if guided is not None else cast(GuidedStartModel, context.model(poincare=False))
        guided.rest = RememberedRuns(guided.rest)
        model: Any = guided.rest
    else:
        guided = None
        model = context.rest_model(dataclasses.replace(context.spec.simulation, starts=None), poincare=False)
    analysis = IntervalAnalysis(
        options["method"],
        order=options["order"],
        scan_points=options["points"],
        tolerance=options["tolerance"],
        fallback=options["fallback"],
        regime_variables=regime_variables,
        qoi=qois,
        seed=context.stage_seed(0),
    )
    result = analysis.fit(model, space, context.sweep()).result_.copy()
    midpoint = {**fixed, **{name: context.study.uncertain[name].nominal for name in names}}
    one = xr.Dataset({name: ("sample", [float(value)]) for name, value in midpoint.items()})
    nominal = evaluate_on_sweep(model, one, context.sweep(), qoi=qois).isel(sample=0, drop=True)
    for name in qois:
        result[f"{name}_nominal"] = nominal[name].assign_attrs(
            units=RUN_QOI_INFO[name][0], long_name=f"{name} at the interval midpoints"
        )
    result.attrs.update(model_runs=int(model.runs), parameters=json.dumps(names), fixed_inputs=json.dumps(fixed))
    if guided is not None:
        result = widen_over_attractors(context, result, names, qois, fixed, model=guided)
    return result


@register("sobol")
def sobol_analysis(context: AnalysisContext) -> xr.Dataset:
    """First- and total-order Sobol indices (SALib) of each QoI at every operating point.

    Interval parameters are treated as uniform on their bounds for this
    purpose (attribute ``distribution_assumed``; the report says so).
    """
    from ..uq.sensitivity import SobolAnalysis

    options = context.options
    names = list(options["parameters"])
    fixed = context.fixed_values(exclude=names)
    space = context.parameter_space(names, fixed)
    model = _statistics_model(context)
    analysis = SobolAnalysis(
        options["samples"],
        second_order=options["second_order"],
        parameters=names,
        num_resamples=options["bootstrap"],
        conf_level=options["confidence_level"],
        qoi=list(options["qois"]),
        seed=context.stage_seed(0),
    )
    result = analysis.fit(model, space, context.sweep()).result_.copy()
    result.attrs.update(
        **_response_attrs(context),
        model_runs=int(model.runs),
        parameters=json.dumps(names),
        fixed_inputs=json.dumps(fixed),
    )
    return result


@register("calibrate")
def calibrate_analysis(context: AnalysisContext) -> xr.Dataset:
    """Bayesian calibration (emcee) of the study's design against a rig file.

    The result holds the posterior draws (dims ``chain``, ``draw``; per-run
    ``adhesion_torque`` adds ``op``) and, in attribute ``calibration``, the
    content of ``calibration.json`` (estimates, diagnostics, predictive check).
    A posterior that has not converged is stored with ``converged = 0`` and
    no estimates. With ``discrepancy: true`` the fitted discrepancy's
    variables (``discrepancy_*``) come with the draws. With the study's
    diagnosed effects (``model.effects``) the model calibrated carries them at
    their fitted values, so the parameters do not absorb the effects' share of
    the gap (``calibration`` lists them).
    """
    from ..calibration import Calibration
    from .schema import rig_path

    names = list(context.options["parameters"])
    calibration = Calibration(
        parameters=names,
        design=context.design,
        seed=context.stage_seed(0),
        threads=context.threads,
        pitch_classes=context.options["pitch_classes"],
        discrepancy=context.options["discrepancy"],
        effects=tuple(effect.central() for effect in context.effects),
    ).fit(rig_path(context.study, context.spec))
    result = calibration.posterior_.copy()
    summary = calibration.to_dict()
    result.attrs.update(
        calibration=json.dumps(summary, default=float),
        converged=int(bool(summary["converged"])),
        parameters=json.dumps(names),
        rig=str(summary["rig"]),
    )
    return result


@register("diagnose")
def diagnose_analysis(context: AnalysisContext) -> xr.Dataset:
    """Sim-to-real gap diagnosis of the study's design against a rig file.

    The result is the Dataset of ``uqgear diagnose``'s ``diagnosis.nc`` (gap
    maps over ``op`` x ``channel`` x ``family``, candidate scores, held-out
    spectra) with the content of its ``diagnosis.json`` (verdict, gap and
    shrink, where, ranking) in attribute ``diagnosis``. With ``reference``
    (a healthy campaign of the same rig, ``uqgear diagnose --reference``) its
    learned transfer correction is carried over and recorded there. Its
    ``settings`` (the documented decision thresholds of
    :class:`~uqgear.diagnosis.DiagnosisSettings`) replace the defaults.
    """
    from ..diagnosis import Diagnosis, DiagnosisSettings
    from .schema import reference_path, rig_path

    effects = list(context.options["effects"])
    rig = rig_path(context.study, context.spec)
    reference = reference_path(context.study, context.spec)
    settings = DiagnosisSettings.from_mapping(
        context.options.get("settings"), where=f"analyses[{context.spec.index}].settings"
    )
    diagnosis = Diagnosis(
        effects=effects,
        settings=settings,
        design=context.design,
        seed=context.stage_seed(0),
        workers=context.threads,
        pitch_classes=context.options["pitch_classes"],
    ).fit(rig, reference=reference)
    content, result = diagnosis.to_dict(), diagnosis.result_.copy()
    result.attrs.update(
        diagnosis=json.dumps(content, default=float),
        verdict=str(content["verdict"]),
        effects=json.dumps(effects),
        rig=str(rig),
    )
    if reference is not None:
        result.attrs["reference"] = str(reference)
    return result


__all__ = ["ANALYSES", "register", "evaluate_batch", "quick_run", "RunnerModel", "AnalysisContext", "ANALYSIS_KEY_ATTR"]
