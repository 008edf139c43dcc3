"""One validated analysis of a study: :class:`AnalysisSpec`, built from its entry and checked against
the study's sweeps and uncertain parameters."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from ..common.errors import StudyError
from ..dynamics.stress_qois import STRESS_QOIS
from ..physics.rating import RatingSettings
from .analysis_schemas import (
    ANALYSIS_DEFAULTS,
    ANALYSIS_SCHEMAS,
    COMMON_ANALYSIS_KEYS,
    INTERVAL_TYPES,
    MAX_SIMULATE_RUNS,
    PROPAGATING_TYPES,
    REQUIRED_ANALYSIS_KEYS,
)
from .checkers import check_mapping, choice, expectation_error
from .parameters import UncertainParameter, ValueSpec, parse_operating_points
from .settings import SimulationSettings, parse_simulation_settings


@dataclass(frozen=True)
class AnalysisSpec:
    """One validated analysis of a study.

    Attributes
    ----------
    index : int
        Position in the study's ``analyses`` list (also its seed stream).
    type, name : str
        Analysis type and its (unique) name; results go to ``<name>.nc``.
    description : str
    options : Mapping
        Type-specific options with defaults filled in.
    operating_points : Mapping of str to ValueSpec
        Study operating points with this analysis's overrides merged in.
    simulation : SimulationSettings
        Study settings with this analysis's overrides merged in.
    raw : Mapping
        The analysis entry as written (for checkpoint keys).
    """

    index: int
    type: str
    name: str
    description: str
    options: Mapping[str, Any]
    operating_points: Mapping[str, ValueSpec]
    simulation: SimulationSettings
    raw: Mapping[str, Any]

    def __post_init__(self) -> None:
        object.__setattr__(self, "options", MappingProxyType(dict(self.options)))
        object.__setattr__(self, "operating_points", MappingProxyType(dict(self.operating_points)))

    @property
    def sweeps(self) -> dict[str, ValueSpec]:
        """Operating variables swept in this analysis, in order."""
        return {name: spec for name, spec in self.operating_points.items() if spec.sweep}

    @property
    def fixed(self) -> dict[str, float]:
        """Operating variables held at one value."""
        return {name: spec.value for name, spec in self.operating_points.items() if not spec.sweep}


def _check_axis(spec: AnalysisSpec, intervals: list[str], name: str, key: str, path: str) -> None:
    """An axis of a bifurcation or regime map must be swept or an uncertain interval parameter."""
    if name in spec.operating_points:
        if not spec.operating_points[name].sweep:
            raise StudyError(
                f"{path}.{key}: {name} is fixed in operating_points; expected a sweep "
                "(a list or {start, stop, num}) or an uncertain interval parameter"
            )
    elif name not in intervals:
        raise StudyError(
            f"{path}.{key}: {name} is neither swept in operating_points nor an "
            "uncertain interval parameter; expected one of "
            f"{', '.join(list(spec.sweeps) + intervals) or '(none defined)'}"
        )


def _check_bifurcation(
    spec: AnalysisSpec, intervals: list[str], path: str, envelope_names: list[str] | None = None
) -> None:
    options = spec.options
    _check_axis(spec, intervals, options["parameter"], "parameter", path)
    others = [name for name in spec.sweeps if name != options["parameter"]]
    if others:
        raise StudyError(
            f"{path}.operating_points.{others[0]}: a {spec.type} sweeps only its "
            f"parameter ({options['parameter']}); expected a single value"
        )
    allowed = intervals if envelope_names is None else envelope_names
    for name in options["envelope"]:
        if name not in allowed:
            kind = "interval parameter" if envelope_names is None else "parameter"
            raise StudyError(
                f"{path}.envelope: {name} is not an uncertain {kind}; "
                f"expected one of {', '.join(allowed) or '(none defined)'}"
            )
        if name == options["parameter"] or name in spec.operating_points:
            raise StudyError(
                f"{path}.envelope: {name} is also the swept parameter or fixed in "
                "operating_points; give it in one place"
            )


def _check_regime_map(spec: AnalysisSpec, intervals: list[str], path: str) -> None:
    options = spec.options
    if len(options["axes"]) != 2:
        raise StudyError(f"{path}.axes: expected exactly two variable names; got {len(options['axes'])}")
    for name in options["axes"]:
        _check_axis(spec, intervals, name, "axes", path)
    others = [name for name in spec.sweeps if name not in options["axes"]]
    if others:
        raise StudyError(
            f"{path}.operating_points.{others[0]}: a regime map sweeps only its axes "
            f"({', '.join(options['axes'])}); expected a single value"
        )


def _check_propagation(spec: AnalysisSpec, uncertain: Mapping[str, UncertainParameter], path: str) -> None:
    """The parameters and sample counts of an interval, Monte Carlo, PCE or Sobol analysis."""
    options = spec.options
    parameters = options["parameters"]
    for name in parameters:
        if name not in uncertain:
            raise StudyError(
                f"{path}.parameters: {name} is not an uncertain parameter; expected "
                f"one of {', '.join(uncertain) or '(none defined in uncertain)'}"
            )
        if name in spec.operating_points:
            raise StudyError(f"{path}.parameters: {name} is also given in operating_points; give it in one place")
    if spec.type in INTERVAL_TYPES:
        bad = [name for name in parameters if not uncertain[name].is_interval]
        if bad:
            raise StudyError(
                f"{path}.parameters: {bad[0]} has a distribution; {'an' if spec.type == 'interval' else 'a'} "
                f"{spec.type} analysis expects interval parameters"
            )
    if spec.type == "sobol":
        samples = options["samples"]
        if samples & (samples - 1):
            raise StudyError(f"{path}.samples: expected a power of 2 (Sobol' sequence balance); got {samples}")
    if spec.type == "monte_carlo" and options["intervals"] == "pbox":
        kinds = {uncertain[name].is_interval for name in parameters}
        if kinds != {True, False}:
            raise StudyError(
                f"{path}.intervals: 'pbox' bounds statistics over interval parameters of "
                "the random ones; expected both interval and distribution parameters "
                f"among parameters ({', '.join(parameters)})"
            )
    if spec.type == "monte_carlo" and options["sampling"] == "sobol" and options["samples"] & (options["samples"] - 1):
        raise StudyError(f"{path}.samples: expected a power of 2 with sampling 'sobol'; got {options['samples']}")
    if spec.type == "pce":
        if options["min_order"] > options["order"]:
            raise StudyError(
                f"{path}.min_order: expected at most order ({options['order']}); got {options['min_order']}"
            )
        needed = math.comb(len(parameters) + options["min_order"], options["min_order"]) + 2
        if options["samples"] and options["samples"] < needed:
            raise StudyError(
                f"{path}.samples: expected at least {needed} training samples for order "
                f"{options['min_order']} in {len(parameters)} parameter(s); "
                f"got {options['samples']}"
            )


def _check_rating(spec: AnalysisSpec, uncertain: Mapping[str, UncertainParameter], path: str) -> None:
    """A rating sweeps the pinion speed alone, at one drive torque; its service speeds lie inside the sweep and
    its rail condition inside the study's adhesion torque interval."""
    sweeps = spec.sweeps
    if "pinion_speed" not in sweeps:
        raise StudyError(
            f"{path}.operating_points.pinion_speed: a rating bounds safety factors against speed; "
            "expected a sweep (a list or {start, stop, num})"
        )
    others = [name for name in sweeps if name != "pinion_speed"]
    if others:
        raise StudyError(f"{path}.operating_points.{others[0]}: a rating sweeps only pinion_speed; expected one value")
    if "drive_torque" in spec.options["parameters"]:
        raise StudyError(f"{path}.parameters: drive_torque is the rating's load; expected it fixed, not bounded over")
    service = spec.options.get("service")
    if service:
        values = sweeps["pinion_speed"].values
        low, high = min(values), max(values)
        outside = [speed for speed in service["speeds"] if not low <= speed <= high]
        if outside:
            raise StudyError(
                f"{path}.service.speeds: {outside[0]:g} rpm is outside the study's speeds; "
                f"expected speeds in [{low:g}, {high:g}] rpm"
            )
        _check_rail(spec, uncertain, service, path)


def _check_rail(spec: AnalysisSpec, uncertain: Mapping[str, UncertainParameter], service, path: str) -> None:
    from .rating_service import rail_torques

    rail = rail_torques(service)
    if rail is None:
        return
    where = f"{path}.service.rail.adhesion_coefficient"
    if "adhesion_torque" not in spec.options["parameters"]:
        raise StudyError(f"{where}: a rail condition needs adhesion_torque among the rating's parameters")
    t2 = uncertain["adhesion_torque"]
    slack = 1e-9 * t2.upper
    outside = [value for value in rail[1] if not t2.lower - slack <= value <= t2.upper + slack]
    if outside:
        raise StudyError(
            f"{where}: T2 = {outside[0]:.6g} N m is outside the study's adhesion torque interval "
            f"[{t2.lower:.6g}, {t2.upper:.6g}] N m (T2 = mu Q g R_w with the service's axle_load and wheel_radius)"
        )


def _check_simulate(spec: AnalysisSpec, path: str) -> None:
    count = int(np.prod([len(s.values) for s in spec.sweeps.values()])) if spec.sweeps else 1
    if count > MAX_SIMULATE_RUNS:
        raise StudyError(
            f"{path}.operating_points: expected at most {MAX_SIMULATE_RUNS} runs "
            f"for a simulate analysis (each keeps full histories); the sweeps give {count}"
        )
    labels = spec.options["labels"]
    if labels and len(labels) != count:
        raise StudyError(f"{path}.labels: expected one label per run ({count}); got {len(labels)}")


def _check_runup(spec: AnalysisSpec, uncertain: Mapping[str, UncertainParameter], path: str) -> None:
    """A run-up's span (given, or the span of the study's speed sweep), single values elsewhere, intervals."""
    options = spec.options
    sweeps = spec.sweeps
    if "pinion_speed" not in options:
        raise StudyError(f"{path}.pinion_speed: missing; expected {{start, stop}} in rpm (the span of the ramp)")
    others = [name for name in sweeps if name != "pinion_speed"]
    if others:
        raise StudyError(
            f"{path}.operating_points.{others[0]}: a run-up sweeps the pinion speed along its ramp; expected a "
            "single value (or an interval under uncertain, bounded over with parameters)"
        )
    for name in options["parameters"]:
        if name not in uncertain or not uncertain[name].is_interval:
            raise StudyError(
                f"{path}.parameters: {name} is not an interval parameter; expected one of "
                f"{', '.join(n for n, p in uncertain.items() if p.is_interval) or '(no intervals under uncertain)'}"
            )
        if name == "pinion_speed":
            raise StudyError(f"{path}.parameters: pinion_speed is the ramp's; expected it out of parameters")


def _check_analysis_variables(spec: AnalysisSpec, uncertain: Mapping[str, UncertainParameter], path: str) -> None:
    """The analysis's options against the study's sweeps and uncertain parameters."""
    intervals = [name for name, parameter in uncertain.items() if parameter.is_interval]
    if spec.type == "bifurcation":
        _check_bifurcation(spec, intervals, path)
    elif spec.type == "continuation":
        # a distribution's bifurcation points are mapped at its quantiles
        _check_bifurcation(spec, intervals, path, list(uncertain))
    elif spec.type == "regime_map":
        _check_regime_map(spec, intervals, path)
    elif spec.type in PROPAGATING_TYPES:
        _check_propagation(spec, uncertain, path)
        if spec.type == "rating":
            _check_rating(spec, uncertain, path)
    elif spec.type == "simulate":
        _check_simulate(spec, path)
    elif spec.type == "runup":
        _check_runup(spec, uncertain, path)


def _with_stresses(
    kind: str, options: Mapping[str, Any], simulation: SimulationSettings, path: str
) -> SimulationSettings:
    """``simulation`` computing the tooth stresses where the analysis asks for a stress QoI (with its ``rating``
    inputs); a ``rating`` block without one is refused, as it would change nothing."""
    if kind in ("rating", "simulate"):
        # their own rating inputs: the rating's verdict, the simulated runs' stresses along the path
        return simulation
    if not any(name in STRESS_QOIS for name in options.get("qois", ())):
        if "rating" in options:
            raise StudyError(
                f"{path}.rating: only the tooth stress QoIs ({', '.join(STRESS_QOIS[:2])}, ...) take ISO 6336 "
                "inputs, and qois names none"
            )
        return simulation
    return dataclasses.replace(simulation, stresses=RatingSettings.from_mapping(options.get("rating")))


def parse_analysis(
    raw: Any,
    index: int,
    study_points: Mapping[str, ValueSpec],
    study_simulation: SimulationSettings,
    uncertain: Mapping[str, UncertainParameter],
) -> AnalysisSpec:
    """The analysis ``analyses[index]`` of a study as an :class:`AnalysisSpec`.

    Its keys are checked against the schema of its ``type``; its operating points and simulation settings
    are laid over the study's, and the parameters of a type that propagates uncertainty default to the
    study's uncertain ones it does not fix. Refusals are :class:`StudyError` naming the entry.
    """
    path = f"analyses[{index}]"
    if not isinstance(raw, Mapping):
        raise expectation_error(path, "a mapping with a 'type' key", raw)
    if "type" not in raw:
        raise StudyError(f"{path}.type: missing; expected one of {', '.join(ANALYSIS_SCHEMAS)}")
    kind: str = choice(*ANALYSIS_SCHEMAS)(raw["type"], f"{path}.type")
    schema = {**COMMON_ANALYSIS_KEYS, **ANALYSIS_SCHEMAS[kind]}
    values = check_mapping(raw, path, schema, required=REQUIRED_ANALYSIS_KEYS.get(kind, ()))
    options = dict(ANALYSIS_DEFAULTS[kind])
    options.update({key: value for key, value in values.items() if key not in COMMON_ANALYSIS_KEYS})
    if kind in PROPAGATING_TYPES and "parameters" not in options:
        overridden = parse_operating_points(raw.get("operating_points"), f"{path}.operating_points")
        options["parameters"] = tuple(
            name
            for name, parameter in uncertain.items()
            if name not in overridden and (parameter.is_interval or kind not in INTERVAL_TYPES)
        )
        if not options["parameters"]:
            raise StudyError(f"{path}.parameters: no uncertain parameters to propagate; define some under 'uncertain'")
    if kind == "runup" and "parameters" not in options:
        overridden = parse_operating_points(raw.get("operating_points"), f"{path}.operating_points")
        # every interval of the study, like the interval analyses; a run-up without intervals runs one case
        options["parameters"] = tuple(
            name for name, parameter in uncertain.items() if name not in overridden and parameter.is_interval
        )
    points = dict(study_points)
    points.update(parse_operating_points(raw.get("operating_points"), f"{path}.operating_points"))
    simulation = _with_stresses(
        kind, options, parse_simulation_settings(raw.get("simulation"), f"{path}.simulation", study_simulation), path
    )
    if kind == "runup" and "pinion_speed" not in options and "pinion_speed" in points and points["pinion_speed"].sweep:
        # without a span of its own, a run-up covers the study's speed sweep
        swept = np.asarray(points["pinion_speed"].values, dtype=float)
        options["pinion_speed"] = {"start": float(swept.min()), "stop": float(swept.max())}
    spec = AnalysisSpec(
        index=index,
        type=kind,
        name=values.get("name", kind),
        description=values.get("description", ""),
        options=options,
        operating_points=points,
        simulation=simulation,
        raw=dict(raw),
    )
    _check_analysis_variables(spec, uncertain, path)
    return spec
