"""What rig data taught the model, as study inputs: a calibrated posterior and diagnosed effects.

A study's ``uncertain.calibrated`` block names a posterior (a ``uqgear
calibrate`` output, or a ``calibrate`` analysis of the same study) whose joint
draws replace the calibrated parameters; its ``model.effects`` names the
effects a diagnosis found (a ``diagnosis.json``, a ``diagnose`` analysis of
the same study, or effects listed by family with their parameters). Both are
checked when the study is read, so that a wrong input is refused before
anything runs; one that comes from an analysis of the same study is resolved
when that analysis has run (:func:`resolve_inputs`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import xarray as xr

from ..calibration.discrepancy_results import Discrepancy, read_discrepancy
from ..common.errors import StudyError, UqgearError, shown
from ..diagnosis.named_effects import named_effects
from ..physics.design import Design
from ..physics.effect_draws import UncertainEffect
from ..physics.effects import EFFECTS
from ..uq.posterior import DEFAULT_DRAWS, PosteriorDraws, read_posterior
from .checkers import boolean, check_mapping, number, string

#: Analysis types that run no model of the study (they read rig data); the others use the inputs.
_RIG_ANALYSES = ("calibrate", "diagnose")


@dataclass(frozen=True)
class CalibratedInput:
    """A study's ``uncertain.calibrated`` block.

    Attributes
    ----------
    posterior : str or None
        The ``posterior.nc`` file (resolved), or None when ``analysis`` gives it.
    analysis : str or None
        A ``calibrate`` analysis of the same study.
    draws : int
        Joint draws kept (thinned without replacement, seeded by the study).
    allow_unconverged : bool
        Accept a posterior whose convergence checks failed (said in the report).
    names : tuple of str
        The calibrated parameters.
    """

    posterior: str | None
    analysis: str | None
    draws: int
    allow_unconverged: bool
    names: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class EffectsInput:
    """A study's ``model.effects``: a diagnosis file, a ``diagnose`` analysis, or effects listed."""

    source: str | None
    analysis: str | None
    listed: tuple[UncertainEffect, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {"source": self.source, "analysis": self.analysis, "listed": [e.to_dict() for e in self.listed]}


def _resolve(value: str, base_dir: Path | None) -> Path:
    candidate = Path(value)
    return candidate if candidate.is_absolute() or base_dir is None else base_dir / candidate


def _source_keys(raw: Mapping[str, Any], path: str, file_key: str) -> tuple[str | None, str | None]:
    given = [key for key in (file_key, "analysis") if raw.get(key) is not None]
    if len(given) != 1:
        raise StudyError(
            f"{path}: expected exactly one of {file_key} (a file) and analysis (NAME); got {given or 'neither'}"
        )
    return raw.get(file_key), raw.get("analysis")


def parse_calibrated(raw: Any, path: str, base_dir: Path | None, design: Design) -> CalibratedInput:
    """Check ``uncertain.calibrated``; a posterior file is read and checked here (converged, same design)."""
    entry = check_mapping(
        raw,
        path,
        {
            "posterior": string(),
            "analysis": string(),
            "draws": number("joint draws", 1, 100_000, integer=True),
            "allow_unconverged": boolean(),
        },
    )
    file, analysis = _source_keys(entry, path, "posterior")
    draws = int(entry.get("draws", DEFAULT_DRAWS))
    allow = bool(entry.get("allow_unconverged", False))
    if file is None:
        return CalibratedInput(None, analysis, draws, allow, ())
    location = _resolve(file, base_dir)
    try:
        posterior = PosteriorDraws.load(location)
        check_posterior(posterior, design, allow, f"{path}.posterior")
    except UqgearError as exc:
        message = str(exc)
        raise StudyError(message if message.startswith(path) else f"{path}.posterior: {message}") from None
    return CalibratedInput(str(location), None, draws, allow, posterior.names)


def check_posterior(posterior: PosteriorDraws, design: Design, allow_unconverged: bool, where: str) -> None:
    """Refuse an unconverged posterior (unless allowed) or one calibrated on another design."""
    if not posterior.converged and not allow_unconverged:
        raise StudyError(
            f"{where}: the posterior has not converged; expected a converged calibration "
            "(or allow_unconverged: true, which the report states)"
        )
    try:
        posterior.check_design(design.to_dict(), where=where)
    except UqgearError as exc:
        raise StudyError(str(exc)) from None


def parse_effects(raw: Any, path: str, base_dir: Path | None) -> EffectsInput:
    """Check ``model.effects``: a diagnosis file, ``{analysis: NAME}``, or ``{family: parameters}``."""
    if isinstance(raw, str):
        location = _resolve(raw, base_dir)
        try:
            named_effects(location, where=path)
        except UqgearError as exc:
            raise StudyError(str(exc) if str(exc).startswith(path) else f"{path}: {exc}") from None
        return EffectsInput(str(location), None)
    if isinstance(raw, Mapping) and set(raw) == {"analysis"}:
        return EffectsInput(None, string()(raw["analysis"], f"{path}.analysis"))
    if not isinstance(raw, Mapping) or not raw:
        raise StudyError(
            f"{path}: expected a diagnosis.json path, {{analysis: NAME}} of a diagnose analysis, or a mapping "
            f"of effect family to its parameters; got {shown(raw)}"
        )
    listed = []
    for family, values in raw.items():
        if family not in EFFECTS:
            raise StudyError(f"{path}.{family}: unknown effect; expected one of {', '.join(EFFECTS)} or analysis")
        values = dict(values or {})
        intervals = values.pop("intervals", {}) or {}
        choices = values.pop("choices", {}) or {}
        try:
            listed.append(UncertainEffect(family, values, intervals, choices))
        except UqgearError as exc:
            raise StudyError(f"{path}.{exc}") from None
    return EffectsInput(None, None, tuple(listed))


def check_order(
    analyses: Sequence[Any], calibrated: CalibratedInput | None, effects: EffectsInput | None
) -> None:
    """An input taken from an analysis needs that analysis, of the right type, before every model analysis."""
    names = [spec.name for spec in analyses]
    for source, kind, key in (
        (calibrated and calibrated.analysis, "calibrate", "uncertain.calibrated.analysis"),
        (effects and effects.analysis, "diagnose", "model.effects.analysis"),
    ):
        if not source:
            continue
        if source not in names or analyses[names.index(source)].type != kind:
            raise StudyError(f"{key}: {source!r} is not a {kind} analysis of the study; expected the name of one")
        position = names.index(source)
        late = [spec.name for spec in analyses[:position] if spec.type not in _RIG_ANALYSES]
        if kind == "diagnose":
            # a calibration conditions on the diagnosed effects: without them the effect's share of the gap
            # moves the calibrated parameters (a damaged tooth lowers the fitted mesh stiffness)
            late += [spec.name for spec in analyses[:position] if spec.type == "calibrate"]
        if late:
            raise StudyError(
                f"{key}: analysis {late[0]!r} runs before {source!r} and would not see its result; "
                f"expected {source!r} earlier in the list"
            )


def resolve_posterior(
    calibrated: CalibratedInput, design: Design, results: Mapping[str, xr.Dataset]
) -> tuple[PosteriorDraws, Discrepancy | None]:
    """The posterior's draws (all of them) and the model discrepancy its calibration learnt (None for an
    ordinary calibration), from its file, read once, or from the study's ``calibrate`` result."""
    if calibrated.posterior is not None:
        dataset = read_posterior(calibrated.posterior)
        posterior = PosteriorDraws.from_dataset(dataset, source=str(Path(calibrated.posterior)))
    else:
        assert calibrated.analysis is not None  # one of the two, checked when the study was read
        dataset = results[calibrated.analysis]
        calibrated_on = str(dataset.attrs.get("rig", ""))
        source = calibrated.analysis
        if calibrated_on:
            source = f"{Path(calibrated_on).name} (analysis {calibrated.analysis})"
        posterior = PosteriorDraws.from_dataset(dataset, source=source)
        check_posterior(posterior, design, calibrated.allow_unconverged, "uncertain.calibrated.analysis")
    discrepancy = read_discrepancy(dataset) if "discrepancy_beta_mean" in dataset else None
    return posterior, discrepancy


def resolve_effects(effects: EffectsInput, results: Mapping[str, xr.Dataset]) -> tuple[UncertainEffect, ...]:
    """The effects with their uncertainty from the diagnosis file, the study's ``diagnose`` result or the list."""
    if effects.listed:
        return effects.listed
    if effects.source is not None:
        return named_effects(effects.source, where="model.effects")
    assert effects.analysis is not None  # one of the three, checked when the study was read
    try:
        return named_effects(results[effects.analysis], where=f"model.effects (analysis {effects.analysis})")
    except UqgearError as exc:
        raise StudyError(str(exc)) from None


__all__ = [
    "CalibratedInput",
    "EffectsInput",
    "parse_calibrated",
    "parse_effects",
    "check_order",
    "check_posterior",
    "resolve_posterior",
    "resolve_effects",
]
