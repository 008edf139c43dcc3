"""Study definitions: the YAML schema, its validation and loading.

A study says what to run: the design (with overrides), the operating points
and sweeps, the uncertain parameters, the analyses, the seed, the simulation
settings and the outputs. :func:`load_study` reads a YAML file and validates
it completely before anything runs; every problem raises
:class:`~uqgear.common.errors.StudyError` whose message starts with the key path and
says what was expected, e.g.::

    analyses[2].method: expected one of scan, vertex, chebyshev, optimize; got 'chebychev'

The reference of every key with its units is ``docs/study-reference.md``.

The parts live in their own modules: :mod:`~uqgear.study.checkers`,
:mod:`~uqgear.study.variables`, :mod:`~uqgear.study.parameters`,
:mod:`~uqgear.study.settings`, :mod:`~uqgear.study.analysis_schemas` (adding an
analysis type starts there) and :mod:`~uqgear.study.analysis_specs`; this
module holds the :class:`Study` and reads it.

This module imports no physics beyond the design loader, so validating a
study is fast.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from ..common.errors import StudyError, UqgearError
from ..common.resources import bundled_by_name, bundled_names
from ..common.yamlio import YAMLError, load_yaml
from ..physics.design import DESIGN_KEYS, Design, load_design
from .analysis_schemas import RIG_TYPES
from .analysis_specs import AnalysisSpec, parse_analysis
from .checkers import boolean, check_mapping, expectation_error, identifier, number, string, value_kind
from .limits import DPI
from .model_inputs import CalibratedInput, EffectsInput, check_order, parse_calibrated, parse_effects
from .parameters import (
    UncertainParameter,
    ValueSpec,
    check_parameter_range,
    parse_operating_points,
    parse_uncertain_parameter,
)
from .settings import GUIDED_STARTS, SimulationSettings, parse_simulation_settings
from .variables import OPERATING_VARIABLES, VARIABLES


@dataclass(frozen=True)
class Outputs:
    """What a run writes besides one netCDF file per analysis.

    Attributes
    ----------
    report : bool
        Write ``report.html``.
    dpi : int
        Resolution of the report's figures, dots per inch.
    """

    report: bool = True
    dpi: int = 110


@dataclass(frozen=True)
class Study:
    """A validated study (see :func:`load_study`)."""

    name: str
    description: str
    seed: int
    design: Design
    design_source: str
    design_overrides: Mapping[str, Any]
    operating_points: Mapping[str, ValueSpec]
    uncertain: Mapping[str, UncertainParameter]
    simulation: SimulationSettings
    analyses: tuple[AnalysisSpec, ...]
    outputs: Outputs
    chunk_size: int
    text: str
    path: str = ""
    calibrated: CalibratedInput | None = None
    effects: EffectsInput | None = None

    def __post_init__(self) -> None:
        for name in ("design_overrides", "operating_points", "uncertain"):
            object.__setattr__(self, name, MappingProxyType(dict(getattr(self, name))))

    def seed_sequences(self) -> list[np.random.SeedSequence]:
        """One independent SeedSequence per analysis, spawned from the study seed in list order."""
        return np.random.SeedSequence(self.seed).spawn(len(self.analyses))

    def analysis(self, name: str) -> AnalysisSpec:
        for spec in self.analyses:
            if spec.name == name:
                return spec
        raise StudyError(
            f"analysis {name!r}: not in the study; expected one of {', '.join(spec.name for spec in self.analyses)}"
        )


def _resolve(path: str, base_dir: Path | None) -> Path:
    candidate = Path(path)
    return candidate if candidate.is_absolute() or base_dir is None else base_dir / candidate


def _resolve_rig(value: str, base_dir: Path | None) -> Path:
    """A rig file relative to the study's folder, or a bundled campaign named without a suffix."""
    candidate = _resolve(value, base_dir)
    return bundled_by_name("rig", value, candidate) or candidate


def rig_path(study: Study, spec: AnalysisSpec) -> Path:
    """The rig file of a ``calibrate``/``diagnose`` analysis.

    A path is relative to the study file's folder; a bare name such as
    ``healthy`` with no such file there is the bundled campaign of that name
    (``uqgear examples`` lists them).
    """
    return _resolve_rig(spec.options["rig"], Path(study.path).parent if study.path else None)


def reference_path(study: Study, spec: AnalysisSpec) -> Path | None:
    """The healthy reference campaign of a ``diagnose`` analysis (key ``reference``), resolved like ``rig``; or None."""
    value = spec.options.get("reference")
    if value is None:
        return None
    return _resolve_rig(value, Path(study.path).parent if study.path else None)


_TOP_LEVEL_KEYS = (
    "name",
    "description",
    "seed",
    "design",
    "operating_points",
    "uncertain",
    "simulation",
    "analyses",
    "outputs",
    "execution",
    "model",
)


def _design(raw: Any, base_dir: Path | None) -> tuple[Design, str, dict[str, Any]]:
    if raw is None:
        raw = "locomotive"
    spec: Mapping[str, Any]
    if isinstance(raw, str):
        spec = {"name": raw}
    elif isinstance(raw, Mapping):
        spec = check_mapping(raw, "design", {"name": string(), "path": string(), "overrides": lambda v, p: v})
    else:
        raise expectation_error("design", "a bundled design name, or a mapping with name or path and overrides", raw)
    if ("name" in spec) == ("path" in spec):
        raise StudyError("design: expected exactly one of name (a bundled design or a file) and path")
    overrides = spec.get("overrides") or {}
    if not isinstance(overrides, Mapping):
        raise expectation_error("design.overrides", "a mapping of design keys to values", overrides)
    for key in overrides:
        if key not in DESIGN_KEYS and key != "motor_pole_pairs":
            raise StudyError(f"design.overrides.{key}: unknown design key; expected one of {', '.join(DESIGN_KEYS)}")
    source = spec["path"] if "path" in spec else spec["name"]  # exactly one of them, checked above
    location: str | Path = source
    candidate = Path(source)
    if "path" in spec or candidate.suffix:
        if not candidate.is_absolute() and base_dir is not None:
            candidate = base_dir / candidate
        location = candidate
    try:
        design = load_design(location)
    except UqgearError as exc:
        raise StudyError(f"design: {exc}") from None
    try:
        design = design.replace(**dict(overrides)) if overrides else design
    except UqgearError as exc:
        raise StudyError(f"design.overrides.{exc}") from None
    return design, str(source), dict(overrides)


def _model(raw: Any, base_dir: Path | None) -> EffectsInput | None:
    """The study's ``model`` section: the effects added to every run."""
    if raw is None:
        return None
    entry = check_mapping(raw, "model", {"effects": lambda value, path: value})
    return parse_effects(entry["effects"], "model.effects", base_dir) if "effects" in entry else None


def _calibrated_names(
    calibrated: CalibratedInput | None, analyses: tuple[AnalysisSpec, ...], uncertain: Mapping[str, Any]
) -> CalibratedInput | None:
    """Fill in the names a ``calibrate`` analysis calibrates, and refuse a parameter given both ways."""
    if calibrated is None:
        return None
    if calibrated.analysis is not None:
        source = next((spec for spec in analyses if spec.name == calibrated.analysis), None)
        if source is not None:
            calibrated = dataclasses.replace(calibrated, names=tuple(source.options.get("parameters", ())))
    both = [name for name in calibrated.names if name in uncertain]
    if both:
        raise StudyError(
            f"uncertain.{both[0]}: also calibrated (uncertain.calibrated); expected each parameter in one place"
        )
    return calibrated


def _uncertain(uncertain_raw: Mapping[str, Any], points: Mapping[str, Any], design: Design) -> dict[str, Any]:
    """The study-wide uncertain parameters (``calibrated`` read apart), each a known variable not fixed in
    ``operating_points``."""
    uncertain = {}
    for key, entry in uncertain_raw.items():
        if key == "calibrated":
            continue
        if key not in VARIABLES:
            raise StudyError(
                f"uncertain.{key}: unknown parameter; expected one of {', '.join(OPERATING_VARIABLES)} or a design key"
            )
        if key in points:
            raise StudyError(
                f"uncertain.{key}: also given in operating_points; give a study-wide "
                "value in one place (an analysis may fix it in its own operating_points)"
            )
        parameter = parse_uncertain_parameter(key, entry, f"uncertain.{key}", design)
        check_parameter_range(parameter, f"uncertain.{key}")
        uncertain[key] = parameter
    return uncertain


def _analyses(analyses_raw: Any, points: Mapping[str, Any], simulation: SimulationSettings,
              uncertain: Mapping[str, Any]) -> tuple[AnalysisSpec, ...]:
    """The analyses, a non-empty list with unique names."""
    if not isinstance(analyses_raw, list) or not analyses_raw:
        raise expectation_error("analyses", "a non-empty list of analyses", analyses_raw)
    analyses = tuple(
        parse_analysis(entry, index, points, simulation, uncertain) for index, entry in enumerate(analyses_raw)
    )
    names = [spec.name for spec in analyses]
    for index, spec in enumerate(analyses):
        if names.count(spec.name) > 1:
            raise StudyError(
                f"analyses[{index}].name: {spec.name!r} is used by more than one analysis; "
                "expected unique names (give each a 'name')"
            )
    return analyses


def _check_analysis_inputs(spec: AnalysisSpec, design: Design, base_dir: Path | None) -> None:
    """A run-up's span inside the design's speed range; a rig analysis's rig (and reference) files present."""
    if spec.type == "runup":
        _check_runup_span(spec, design)
    if spec.type in RIG_TYPES:
        rig = _resolve_rig(spec.options["rig"], base_dir)
        if not rig.is_file():
            raise StudyError(
                f"analyses[{spec.index}].rig: file {rig} not found; expected a uqgear-rig/1 "
                "netCDF file (relative paths start at the study file's folder) or a bundled "
                f"campaign ({', '.join(bundled_names('rig'))})"
            )
        reference = spec.options.get("reference")
        if reference is not None:
            found = _resolve_rig(reference, base_dir)
            if not found.is_file():
                raise StudyError(
                    f"analyses[{spec.index}].reference: file {found} not found; expected a "
                    "uqgear-rig/1 netCDF file of the same rig with a healthy gearbox (relative "
                    "paths start at the study file's folder) or a bundled campaign "
                    f"({', '.join(bundled_names('rig'))})"
                )


def study_from_mapping(raw: Any, *, text: str = "", path: str = "", base_dir: str | Path | None = None) -> Study:
    """Validate a parsed study mapping and build a :class:`Study`.

    Parameters
    ----------
    raw : mapping
        The parsed YAML.
    text : str
        The YAML text (kept for provenance).
    path : str
        The study file, for messages and reports.
    base_dir : str or Path, optional
        Folder against which a relative design path is resolved.

    Raises
    ------
    StudyError
        The first problem found, with its key path.
    """
    if not isinstance(raw, Mapping):
        raise StudyError(f"study: expected a mapping with keys {', '.join(_TOP_LEVEL_KEYS)}; got {value_kind(raw)}")
    for key in raw:
        if key not in _TOP_LEVEL_KEYS:
            raise StudyError(f"{key}: unknown key; expected one of {', '.join(_TOP_LEVEL_KEYS)}")
    if "analyses" not in raw:
        raise StudyError("analyses: missing (required); expected a list of analyses")
    name = identifier()(raw.get("name", Path(path).stem if path else "study"), "name")
    description = string()(raw.get("description", ""), "description")
    seed = number("", 0, 2**63 - 1, integer=True)(raw.get("seed", 0), "seed")
    design, design_source, overrides = _design(raw.get("design"), Path(base_dir) if base_dir else None)
    points = parse_operating_points(raw.get("operating_points"), "operating_points")
    uncertain_raw = raw.get("uncertain") or {}
    if not isinstance(uncertain_raw, Mapping):
        raise expectation_error(
            "uncertain", "a mapping of parameter name to its interval or distribution", uncertain_raw
        )
    base = Path(base_dir) if base_dir else None
    calibrated = (
        parse_calibrated(uncertain_raw["calibrated"], "uncertain.calibrated", base, design)
        if "calibrated" in uncertain_raw
        else None
    )
    uncertain = _uncertain(uncertain_raw, points, design)
    simulation = parse_simulation_settings(
        raw.get("simulation"), "simulation", SimulationSettings(starts=GUIDED_STARTS)
    )
    outputs_raw = check_mapping(raw.get("outputs") or {}, "outputs", {"report": boolean(), "dpi": DPI})
    outputs = Outputs(**outputs_raw)
    execution = check_mapping(
        raw.get("execution") or {}, "execution", {"chunk_size": number("samples per chunk", 1, 1_000_000, integer=True)}
    )
    analyses = _analyses(raw["analyses"], points, simulation, uncertain)
    effects = _model(raw.get("model"), base)
    calibrated = _calibrated_names(calibrated, analyses, uncertain)
    check_order(analyses, calibrated, effects)
    for spec in analyses:
        _check_analysis_inputs(spec, design, base)
    return Study(
        name=name,
        description=description,
        seed=seed,
        design=design,
        design_source=design_source,
        design_overrides=overrides,
        operating_points=points,
        uncertain=uncertain,
        simulation=simulation,
        analyses=analyses,
        outputs=outputs,
        chunk_size=execution.get("chunk_size", 64),
        text=text,
        path=path,
        calibrated=calibrated,
        effects=effects,
    )


def _check_runup_span(spec: AnalysisSpec, design: Design) -> None:
    """A run-up's span inside the design's speed range (``operation.pinion_speed_sweep``)."""
    low, high = design.operation.pinion_speed_sweep
    span = spec.options["pinion_speed"]
    for key in ("start", "stop"):
        if not low <= float(span[key]) <= high:
            raise StudyError(
                f"analyses[{spec.index}].pinion_speed.{key}: expected a speed in the design's range "
                f"[{low:g}, {high:g}] rpm (operation.pinion_speed_sweep); got {float(span[key]):g}"
            )


def parse_study(text: str, *, path: str = "", base_dir: str | Path | None = None) -> Study:
    """Parse and validate study YAML text.

    Parameters
    ----------
    text : str
        The study, as in a study file (docs/study-reference.md).
    path : str
        Where the text comes from, for messages and provenance.
    base_dir : str or Path, optional
        Folder that relative design and rig paths start from.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        Not valid YAML, or the first schema violation (with its key path).

    Examples
    --------
    >>> import uqgear
    >>> study = uqgear.parse_study('''
    ... name: t2_band
    ... design: {name: locomotive}
    ... operating_points: {pinion_speed: [1000, 2000], drive_torque: 7000}
    ... uncertain:
    ...   adhesion_torque: {adhesion_coefficient: [0.15, 0.33], axle_load: 23000, wheel_radius: 0.625}
    ... analyses:
    ...   - {type: interval, name: band, parameters: [adhesion_torque], method: vertex}
    ... ''')
    >>> study.name, [(analysis.type, analysis.name) for analysis in study.analyses]
    ('t2_band', [('interval', 'band')])
    >>> study.operating_points["pinion_speed"].values
    (1000.0, 2000.0)
    >>> try:
    ...     uqgear.parse_study("{name: t, analyses: [{type: interval, method: guess}]}")
    ... except uqgear.StudyError as error:
    ...     print(error)
    analyses[0].method: expected one of scan, vertex, chebyshev, optimize; got 'guess'
    """
    try:
        raw = load_yaml(text)
    except YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise StudyError(f"not valid YAML{where}: {problem}") from None
    if raw is None:
        raise StudyError("study: the file is empty; expected a mapping with 'analyses' and other keys")
    return study_from_mapping(raw, text=text, path=path, base_dir=base_dir)


def load_study(path: str | Path) -> Study:
    """Read and validate a study YAML file.

    Parameters
    ----------
    path : str or Path
        The study file, or the name of a bundled study (``"smoke"``) when no
        such file exists. A relative design or rig path in it is resolved
        against the file's folder.

    Returns
    -------
    Study

    Raises
    ------
    StudyError
        The file is missing or unreadable, not valid YAML, or breaks the
        schema; the message starts with the file name and the key path.

    Examples
    --------
    A bundled study by name, and a study file of one's own:

    >>> import pathlib, tempfile
    >>> import uqgear
    >>> smoke = uqgear.load_study("smoke")
    >>> smoke.name, smoke.seed, len(smoke.analyses)
    ('smoke', 20240601, 12)
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     path = pathlib.Path(folder) / "short.yaml"
    ...     _ = path.write_text(smoke.text.replace("n_periods: 100", "n_periods: 60"))
    ...     short = uqgear.load_study(path)
    >>> short.simulation.n_periods, smoke.simulation.n_periods
    (60, 100)
    >>> try:
    ...     uqgear.load_study("no_such_study.yaml")
    ... except uqgear.StudyError as error:
    ...     print(str(error).split(" (")[0])
    no_such_study.yaml: study file not found
    """
    source = Path(path)
    # a name is only ever typed text: a path object never names a bundled study
    source = (bundled_by_name("study", path, source) if isinstance(path, str) else None) or source
    if source.is_dir():
        raise StudyError(f"{source}: is a folder; expected a study YAML file")
    if not source.is_file():
        bundled = ", ".join(bundled_names("study"))
        raise StudyError(f"{source}: study file not found (bundled studies, runnable by name: {bundled})")
    try:
        content = source.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise StudyError(f"{source}: cannot read the study file ({exc})") from None
    try:
        return parse_study(content, path=str(source), base_dir=source.parent)
    except StudyError as exc:
        raise StudyError(f"{source}: {exc}") from None


__all__ = ["Study", "Outputs", "load_study", "parse_study", "study_from_mapping", "rig_path", "reference_path"]
