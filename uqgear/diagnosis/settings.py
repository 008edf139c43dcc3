"""Every decision threshold and budget of the diagnosis in one frozen settings object.

Each field of :class:`DiagnosisSettings` carries its unit, the rule it
serves in one sentence and the section of docs/model.md that explains it
(its evidence is in docs/validation/diagnosis.md). The defaults are the
values the validation record was measured with. Fields marked ``study``
are the documented decision thresholds a study's ``diagnose`` analysis may
set under ``settings:``; the others (budgets, numerical gates) are set from
Python.

Examples
--------
>>> from uqgear.diagnosis import DiagnosisSettings
>>> settings = DiagnosisSettings(score_threshold=15.0)
>>> settings.score_threshold, settings.shrink_threshold
(15.0, 0.5)
>>> DiagnosisSettings.describe("score_threshold")["unit"]
'nat'
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from .errors import DiagnosisError


def _setting(default: Any, unit: str, rule: str, docs: str, *, lower: float = -math.inf, upper: float = math.inf,
             integer: bool = False, study: bool = False) -> Any:
    """A settings field with its unit, rule, docs section, valid range and whether a study may set it."""
    metadata = {"unit": unit, "rule": rule, "docs": docs, "lower": lower, "upper": upper, "integer": integer,
                "study": study}
    if isinstance(default, (dict, MappingProxyType)):
        frozen = MappingProxyType(dict(default))
        return field(default_factory=lambda: frozen, metadata=metadata)
    return field(default=default, metadata=metadata)


_VERDICT = "docs/model.md section 6, step 5"
_SELECTION = "docs/model.md section 6.2"
_COST = "docs/model.md section 6.2.1"
_PITCH = "docs/model.md section 6.4"
_PHASES = "docs/model.md section 6.4 (sideband phases)"
_REFERENCE = "docs/model.md section 6.1"
_INTERFERENCE = "docs/model.md section 6.5"
_FEATURES = "docs/model.md section 6, step 2"


@dataclass(frozen=True)
class DiagnosisSettings:
    """The thresholds and budgets of a diagnosis (each field: unit, rule, docs section; :meth:`describe`).

    Settings are checked when made: a value outside its range raises
    :class:`~uqgear.diagnosis.DiagnosisError` naming the field.
    """

    # ---- the verdict (step 5)
    score_threshold: float = _setting(
        10.0, "nat", "a candidate is named only when its held-out log predictive density gain over the model "
        "without it, after a penalty of 0.5 log n per parameter, reaches this", _VERDICT, lower=0.0, study=True)
    shrink_threshold: float = _setting(
        0.5, "1", "a named candidate must shrink the held-out gap by this fraction, or leave a gap within noise",
        _VERDICT, lower=0.0, upper=1.0, study=True)
    noise_gap: float = _setting(
        0.5, "noise spreads", "a held-out gap (excess RMS standardised discrepancy) at most this is within noise",
        _VERDICT, lower=0.0, study=True)
    effect_gain_threshold: float = _setting(
        5.0, "nat", "a candidate's fit must be worse by at least this robust cost with its effect switched off, "
        "or its score belongs to the nominal parameters it refitted", _VERDICT, lower=0.0, study=True)
    partial_shrink: float = _setting(
        0.2, "1", "a candidate that meets the score and gain rules but not the shrink rule is named with an "
        "unexplained remainder when the lower end of its 90 % shrink interval reaches this", _VERDICT,
        lower=0.0, upper=1.0, study=True)
    score_quantile: float = _setting(
        1.645, "standard errors", "a score's 90 % lower bound lies this many standard errors below it (the "
        "normal 95 % quantile)", _PITCH, lower=0.0)
    signal_snr: float = _setting(
        5.0, "noise spreads", "a rig line counts as signal at this amplitude over its per-quadrature noise spread "
        "(white noise reaches it in one line of 270,000)", _FEATURES, lower=0.0, study=True)
    min_informative_runs: int = _setting(
        2, "runs", "a campaign is diagnosed only when this many runs show a line above the noise floor (one "
        "to fit, one held out)", _FEATURES, lower=2, integer=True)
    # ---- which candidates are fitted in full, and how many effects a set holds (steps 3 and 6)
    promoted: int = _setting(
        2, "candidates", "at most this many effects are promoted from the screening fit to a full fit",
        _SELECTION, lower=1, integer=True)
    runner_up_share: float = _setting(
        0.25, "1", "a runner-up is promoted when its screening score is at least this share of the leader's",
        _SELECTION, lower=0.0, upper=1.0)
    extra_full_fits: int = _setting(
        3, "fits", "while the gap stays unexplained, up to this many further variants are fitted in full, best "
        "screened first", _SELECTION, lower=0, integer=True)
    max_effects: int = _setting(
        3, "effects", "forward selection names at most this many effects together", _SELECTION, lower=1,
        integer=True, study=True)
    nominal_refits: int = _setting(
        2, "refits", "the nominal fit is restarted from a candidate's fit at most this many times", _SELECTION,
        lower=0, integer=True)
    nominal_margin: float = _setting(
        5.0, "nat", "a candidate's nominal parameters must beat the nominal fit's robust cost by this much to "
        "show that the nominal fit stopped in a local optimum", _SELECTION, lower=0.0)
    nominal_evaluations: int = _setting(
        30, "cost evaluations", "budget of each stage of the nominal fit and of its refits", _COST, lower=1,
        integer=True)
    screening_evaluations: int = _setting(
        6, "cost evaluations", "budget of a screening fit (the new effect's parameters only)", _COST, lower=1,
        integer=True)
    full_fit_evaluations: int = _setting(
        12, "cost evaluations", "budget of each stage of a full fit and of its refit with its own pitch-error "
        "allowance", _COST, lower=1, integer=True)
    bootstrap_resamples: int = _setting(
        400, "resamples", "runs are resampled this many times for the intervals of a shrink and of a gap",
        _VERDICT, lower=10, integer=True)
    # ---- the pitch-error allowance (step 3)
    pitch_draws: int = _setting(
        12, "draws", "pitch-error draws whose changes to each feature give the allowance", _PITCH, lower=2,
        integer=True)
    min_sideband_snr: float = _setting(
        3.0, "noise spreads", "a rig sideband counts as visible this far above the nominal fit", _PITCH, lower=0.0)
    min_visible_fraction: float = _setting(
        0.2, "1", "the allowance applies only where this share of each shaft's sidebands of every order 1 to 3 is "
        "visible on both shafts (pitch errors light every order of both)", _PITCH, lower=0.0, upper=1.0,
        study=True)
    run_out_quantile: float = _setting(
        0.95, "1", "an eccentricity whose run-out stays below this quantile of what the stated classes' pitch "
        "errors make as a first-order run-out is not named for its run-out", _PITCH, lower=0.5, upper=1.0)
    order_factor_quantiles: tuple[float, ...] = _setting(
        (0.01, 0.99), "1", "each (gear, order) group's share of the allowance is scaled to the rig's own gears within "
        "these quantiles of what gears of the stated classes give that group", _PITCH, lower=0.0, upper=1.0)
    large_run_out_share: float = _setting(
        0.9, "1", "a gear whose first order reads larger than this share of the stated classes' gears is "
        "reported as a run-out the lines cannot tell from its own errors", _PITCH, lower=0.5, upper=1.0,
        study=True)
    # ---- an eccentric shaft named by its sidebands' phases (step 6)
    phase_evidence_threshold: float = _setting(
        200.0, "nat", "the sideband phase sums name an eccentric shaft at this log ratio over pitch errors alone "
        "(without the run that favours it most)", _PHASES, lower=0.0, study=True)
    min_sideband_orders: float = _setting(
        0.5, "pinion orders", "a shaft's phase sums are tested only where its first sidebands lie this far from "
        "their carrier (nearer, the line fit cannot hold them apart from the shaft's other orders)", _PHASES,
        lower=0.0)
    modulation_kappas: tuple[float, ...] = _setting(
        (0.01, 0.03), "1", "mesh stiffness modulations the eccentric-shaft hypothesis is tried at", _PHASES)
    phase_draws_per_point: int = _setting(
        4, "draws", "pitch-error draws simulated at each point of the fitted model's parameter spread",
        _PHASES, lower=1, integer=True)
    # ---- a healthy reference and line interference (step 1)
    speed_tolerance: float = _setting(
        0.01, "1", "a test run matches a reference run within this relative pinion speed", _REFERENCE,
        lower=0.0, upper=1.0)
    torque_tolerance: float = _setting(
        0.05, "1", "a test run matches a reference run within this relative drive torque", _REFERENCE,
        lower=0.0, upper=1.0)
    interference_threshold: float = _setting(
        8.0, "noise spreads", "a fixed-frequency peak counts as a line at this height", _INTERFERENCE, lower=0.0)
    interference_runs: int = _setting(
        3, "runs", "a fixed-frequency line must be met in at least this many runs (and half of them)",
        _INTERFERENCE, lower=1, integer=True)
    # ---- the predictive distribution (step 2)
    model_error: Mapping[str, float] = _setting(
        {"line": 0.03, "band": 0.05, "rms": 0.03, "kurtosis": 0.05}, "1",
        "relative model error (standard deviation) of each feature kind: lines, band powers, RMS, kurtosis",
        _FEATURES)
    # ---- where the gap lies (reported, not decided)
    where_z: float = _setting(
        3.0, "noise spreads", "a held-out feature this far off counts as a gap in the list of where it lies",
        _VERDICT, lower=0.0)

    def __post_init__(self) -> None:
        for spec in dataclasses.fields(self):
            _check(spec, getattr(self, spec.name))
        if not isinstance(self.model_error, MappingProxyType):
            object.__setattr__(self, "model_error", MappingProxyType(dict(self.model_error)))

    @classmethod
    def describe(cls, name: str | None = None) -> Any:
        """Unit, rule, docs section, default and whether a study may set it: of one field, or of all by name."""
        table = {spec.name: {"default": _default(spec), **{key: spec.metadata[key] for key in
                                                              ("unit", "rule", "docs", "study")}}
                 for spec in dataclasses.fields(cls)}
        if name is None:
            return table
        if name not in table:
            raise DiagnosisError(f"settings.{name}: unknown setting; expected one of {', '.join(table)}")
        return table[name]

    @classmethod
    def study_keys(cls) -> tuple[str, ...]:
        """The settings a study's ``diagnose`` analysis may set (the documented decision thresholds)."""
        return tuple(spec.name for spec in dataclasses.fields(cls) if spec.metadata["study"])

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any] | None, *, where: str = "settings",
                     keys: tuple[str, ...] | None = None) -> "DiagnosisSettings":
        """Settings from a mapping of field names (``keys``: the names allowed, default all)."""
        allowed = tuple(spec.name for spec in dataclasses.fields(cls)) if keys is None else keys
        values = dict(values or {})
        unknown = sorted(set(values) - set(allowed))
        if unknown:
            raise DiagnosisError(f"{where}.{unknown[0]}: unknown setting; expected one of {', '.join(allowed)}")
        try:
            return cls(**values)
        except DiagnosisError as exc:
            raise DiagnosisError(f"{where}.{str(exc).removeprefix('settings.')}") from None

    def changed(self) -> dict[str, Any]:
        """The settings that differ from the defaults, JSON-ready."""
        return {spec.name: _json_ready(getattr(self, spec.name)) for spec in dataclasses.fields(self)
                if getattr(self, spec.name) != _default(spec)}


def _default(spec: dataclasses.Field) -> Any:
    return spec.default_factory() if spec.default is dataclasses.MISSING else spec.default  # type: ignore[misc]


def _json_ready(value: Any) -> Any:
    if isinstance(value, Mapping):
        return dict(value)
    if isinstance(value, tuple):
        return list(value)
    return value


def _check(spec: dataclasses.Field, value: Any) -> None:
    """Refuse a setting outside its type or range, naming it."""
    meta = spec.metadata
    name = f"settings.{spec.name}"
    if spec.name == "model_error":
        _check_model_error(value)
        return
    values = value if isinstance(value, tuple) else (value,)
    if isinstance(_default(spec), tuple) and not (isinstance(value, tuple) and value):
        raise DiagnosisError(f"{name}: expected a non-empty tuple of numbers; got {value!r}")
    for item in values:
        numeric = isinstance(item, (int, float)) and not isinstance(item, bool)
        if not numeric or not math.isfinite(item) or (meta["integer"] and not isinstance(item, int)):
            kind = "an integer" if meta["integer"] else "a number"
            raise DiagnosisError(f"{name}: expected {kind} ({meta['unit']}); got {item!r}")
        if not meta["lower"] <= item <= meta["upper"]:
            raise DiagnosisError(f"{name}: expected a value in [{meta['lower']:g}, {meta['upper']:g}] "
                                 f"({meta['unit']}); got {item!r}")


def _check_model_error(value: Any) -> None:
    kinds = ("line", "band", "rms", "kurtosis")
    if not isinstance(value, Mapping):
        raise DiagnosisError(f"settings.model_error: expected a mapping of feature kind to relative error; "
                             f"got {value!r}")
    unknown = sorted(set(value) - set(kinds))
    if unknown:
        raise DiagnosisError(f"model_error.{unknown[0]}: unknown feature kind; expected {', '.join(kinds)}")
    missing = [kind for kind in kinds if kind not in value]
    if missing:
        raise DiagnosisError(f"model_error.{missing[0]}: missing; expected a relative error for each of "
                             f"{', '.join(kinds)}")
    for key, item in value.items():
        if isinstance(item, bool) or not isinstance(item, (int, float)) or not 0.0 <= item < 1.0:
            raise DiagnosisError(f"model_error.{key}: expected a relative error in [0, 1); got {item!r}")


#: The settings the validation record was measured with (every default).
DEFAULT_SETTINGS = DiagnosisSettings()


__all__ = ["DiagnosisSettings", "DEFAULT_SETTINGS"]
