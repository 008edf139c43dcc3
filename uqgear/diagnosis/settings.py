"""Every decision threshold and budget of the diagnosis, grouped by the step each serves.

:class:`DiagnosisSettings` holds the values, one frozen group per step of the
diagnosis in the order it takes them (:data:`GROUPS`: ``reference``,
``change``, ``interference``, ``features``, ``predictive``, ``nominal``,
``screening``, ``pitch``, ``verdict``, ``selection``, ``phases``); a setting
keeps its own name inside its group (``settings.verdict.score_threshold``)
and may be given by that name alone. :data:`SETTINGS` states for
each its unit, the rule it serves in one sentence and the section of
docs/model/ that explains it (its evidence is in
docs/validation/diagnosis.md), with its valid range
(:meth:`DiagnosisSettings.describe` reads both). The defaults are the values
the validation record was measured with. Settings marked ``study`` are the
documented decision thresholds a study's ``diagnose`` analysis may set under
``settings:``; the others (budgets, numerical gates) are set from Python.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

from .errors import DiagnosisError

_VERDICT = "docs/model/unmodelled-effects.md section 6, step 5"
_SELECTION = "docs/model/unmodelled-effects.md section 6.2"
_COST = "docs/model/unmodelled-effects.md section 6.2.1"
_PITCH = "docs/model/unmodelled-effects.md section 6.4"
_PHASES = "docs/model/unmodelled-effects.md section 6.4 (sideband phases)"
_REFERENCE = "docs/model/unmodelled-effects.md section 6.1"
_INTERFERENCE = "docs/model/unmodelled-effects.md section 6.5"
_FEATURES = "docs/model/unmodelled-effects.md section 6, step 2"
_CHANGE = "docs/model/unmodelled-effects.md section 6.1 (what changed)"
_CONSISTENCY = "docs/model/unmodelled-effects.md section 6, step 5 (cross-channel consistency)"

# Relative model error (standard deviation) by feature kind: with their true parameters and effect the model
# reproduces the reference campaigns' lines to well under 1 % (a few per cent for lines near the noise floor);
# 3 % leaves room for an independent rig without hiding a friction-sized change.
_MODEL_ERROR = {"line": 0.03, "band": 0.05, "rms": 0.03, "kurtosis": 0.05}


@dataclass(frozen=True)
class Setting:
    """What a setting of :class:`DiagnosisSettings` is: unit, rule, docs section, range, whether a study sets it."""

    unit: str
    rule: str
    docs: str
    lower: float = -math.inf
    upper: float = math.inf
    integer: bool = False
    study: bool = False


GROUPS: dict[str, tuple[str, ...]] = {
    "reference": ("speed_tolerance", "torque_tolerance"),
    "change": ("change_z", "change_allowance_db", "replaced_allowance_db", "same_line_floor", "replaced_line_floor",
               "change_share", "change_margin", "load_allowance", "change_model_error"),
    "interference": ("interference_threshold", "interference_runs"),
    "features": ("signal_snr", "min_informative_runs"),
    "predictive": ("model_error",),
    "nominal": ("nominal_refits", "nominal_margin", "nominal_evaluations"),
    "screening": ("promoted", "runner_up_share", "extra_full_fits", "screening_evaluations", "full_fit_evaluations"),
    "pitch": ("pitch_draws", "min_sideband_snr", "min_visible_fraction", "run_out_quantile",
              "order_factor_quantiles", "large_run_out_share"),
    "verdict": ("score_threshold", "shrink_threshold", "noise_gap", "effect_gain_threshold", "partial_shrink",
                "score_quantile", "cross_channel_gain", "bootstrap_resamples", "where_z"),
    "selection": ("max_effects",),
    "phases": ("phase_evidence_threshold", "min_sideband_orders", "modulation_kappas", "phase_draws_per_point"),
}
"""The settings of each step, in the order the diagnosis takes them (docs/model/unmodelled-effects.md section 6)."""


class _Group:
    """Checks a group's settings when made: a value outside its range raises naming it."""

    def __post_init__(self) -> None:
        for spec in dataclasses.fields(self):  # type: ignore[arg-type]
            _check(spec.name, SETTINGS[spec.name], getattr(self, spec.name))


@dataclass(frozen=True)
class ReferenceSettings(_Group):
    """How a test run is matched to a run of a healthy reference (section 6.1).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import ReferenceSettings
    >>> ReferenceSettings().speed_tolerance
    0.01
    """

    speed_tolerance: float = 0.01
    torque_tolerance: float = 0.05


@dataclass(frozen=True)
class ChangeSettings(_Group):
    """What changed since a healthy reference, and which effect explains it (section 6.1).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import ChangeSettings
    >>> ChangeSettings(change_z=4.0).change_z
    4.0
    """

    change_z: float = 5.0
    change_allowance_db: float = 1.0
    replaced_allowance_db: tuple[float, ...] = (3.0, 2.0, 8.0, 8.0, 6.0, 8.0, 3.0)
    same_line_floor: float = 0.003
    replaced_line_floor: float = 0.05
    change_share: float = 0.2
    change_margin: float = 0.1
    load_allowance: float = 0.5
    change_model_error: float = 0.5


@dataclass(frozen=True)
class InterferenceSettings(_Group):
    """Fixed-frequency line interference on the accelerometers (step 1, section 6.5).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import InterferenceSettings
    >>> InterferenceSettings().interference_runs
    3
    """

    interference_threshold: float = 8.0
    interference_runs: int = 3


@dataclass(frozen=True)
class FeatureSettings(_Group):
    """When the rig's features can decide at all (step 1).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import FeatureSettings
    >>> FeatureSettings().signal_snr
    5.0
    """

    signal_snr: float = 5.0
    min_informative_runs: int = 2


@dataclass(frozen=True)
class PredictiveSettings(_Group):
    """The model error of the predictive distribution (step 2).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import PredictiveSettings
    >>> PredictiveSettings().model_error["line"]
    0.03
    """

    model_error: Mapping[str, float] = field(default_factory=lambda: MappingProxyType(dict(_MODEL_ERROR)))

    def __post_init__(self) -> None:
        super().__post_init__()
        if not isinstance(self.model_error, MappingProxyType):
            object.__setattr__(self, "model_error", MappingProxyType(dict(self.model_error)))


@dataclass(frozen=True)
class NominalSettings(_Group):
    """The nominal fit and its restarts from a candidate's fit (step 3).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import NominalSettings
    >>> NominalSettings().nominal_refits
    2
    """

    nominal_refits: int = 2
    nominal_margin: float = 5.0
    nominal_evaluations: int = 30


@dataclass(frozen=True)
class ScreeningSettings(_Group):
    """The screening fits and which candidates are fitted in full (step 3, section 6.2).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import ScreeningSettings
    >>> ScreeningSettings().promoted
    2
    """

    promoted: int = 2
    runner_up_share: float = 0.25
    extra_full_fits: int = 3
    screening_evaluations: int = 6
    full_fit_evaluations: int = 12


@dataclass(frozen=True)
class PitchSettings(_Group):
    """The pitch-error allowance (step 3, section 6.4).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import PitchSettings
    >>> PitchSettings().pitch_draws
    12
    """

    pitch_draws: int = 12
    min_sideband_snr: float = 3.0
    min_visible_fraction: float = 0.2
    run_out_quantile: float = 0.95
    order_factor_quantiles: tuple[float, ...] = (0.01, 0.99)
    large_run_out_share: float = 0.9


@dataclass(frozen=True)
class VerdictSettings(_Group):
    """The held-out scores' rules that name an effect, and where the gap lies (steps 4 and 5).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import VerdictSettings
    >>> VerdictSettings(score_threshold=20.0).score_threshold
    20.0
    """

    score_threshold: float = 10.0
    shrink_threshold: float = 0.5
    noise_gap: float = 0.5
    effect_gain_threshold: float = 5.0
    partial_shrink: float = 0.2
    score_quantile: float = 1.645
    cross_channel_gain: float = 5.0
    bootstrap_resamples: int = 400
    where_z: float = 3.0


@dataclass(frozen=True)
class SelectionSettings(_Group):
    """How many effects forward selection names together (step 6, section 6.2).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import SelectionSettings
    >>> SelectionSettings().max_effects
    3
    """

    max_effects: int = 3


@dataclass(frozen=True)
class PhaseSettings(_Group):
    """An eccentric shaft named by its sidebands' phases (step 6, section 6.4).

    Examples
    --------
    >>> from uqgear.diagnosis.settings import PhaseSettings
    >>> PhaseSettings().modulation_kappas
    (0.01, 0.03)
    """

    phase_evidence_threshold: float = 200.0
    min_sideband_orders: float = 0.5
    modulation_kappas: tuple[float, ...] = (0.01, 0.03)
    phase_draws_per_point: int = 4


#: The class of each group of :data:`GROUPS`.
GROUP_TYPES: dict[str, type[Any]] = {
    "reference": ReferenceSettings,
    "change": ChangeSettings,
    "interference": InterferenceSettings,
    "features": FeatureSettings,
    "predictive": PredictiveSettings,
    "nominal": NominalSettings,
    "screening": ScreeningSettings,
    "pitch": PitchSettings,
    "verdict": VerdictSettings,
    "selection": SelectionSettings,
    "phases": PhaseSettings,
}

#: The group each setting belongs to.
GROUP_OF: dict[str, str] = {name: group for group, names in GROUPS.items() for name in names}


@dataclass(frozen=True, init=False)
class DiagnosisSettings:
    """The thresholds and budgets of a diagnosis, one group per step (units, rules, docs sections: :data:`SETTINGS`).

    A group is given whole (``verdict=VerdictSettings(...)``) or a setting by
    its own name (``score_threshold=20.0``), which goes to its group.
    Settings are checked when made: a value outside its range raises
    :class:`~uqgear.diagnosis.DiagnosisError` naming it.

    Examples
    --------
    >>> import dataclasses
    >>> import uqgear
    >>> settings = uqgear.DiagnosisSettings(score_threshold=20.0)
    >>> settings.verdict.score_threshold, settings.changed()
    (20.0, {'score_threshold': 20.0})
    >>> uqgear.DiagnosisSettings.describe("score_threshold")["unit"]
    'nat'
    >>> try:
    ...     dataclasses.replace(settings, max_effects=0)
    ... except uqgear.UqgearError as error:
    ...     print(type(error).__name__, "-", error)
    DiagnosisError - settings.max_effects: expected a value in [1, inf] (effects); got 0
    """

    reference: ReferenceSettings
    change: ChangeSettings
    interference: InterferenceSettings
    features: FeatureSettings
    predictive: PredictiveSettings
    nominal: NominalSettings
    screening: ScreeningSettings
    pitch: PitchSettings
    verdict: VerdictSettings
    selection: SelectionSettings
    phases: PhaseSettings

    def __init__(self, **values: Any) -> None:
        unknown = sorted(set(values) - set(GROUPS) - set(GROUP_OF))
        if unknown:
            raise DiagnosisError(f"settings.{unknown[0]}: unknown setting")
        for group, kind in GROUP_TYPES.items():
            given = values.get(group, None)
            if given is not None and not isinstance(given, kind):
                raise DiagnosisError(f"settings.{group}: expected a {kind.__name__}; got {type(given).__name__}")
            flat = {name: values[name] for name in GROUPS[group] if name in values}
            if given is None:
                given = kind(**flat)
            elif flat:
                given = dataclasses.replace(given, **flat)
            object.__setattr__(self, group, given)

    def value(self, name: str) -> Any:
        """One setting by its own name, from its group.

        Examples
        --------
        >>> from uqgear.diagnosis.settings import DEFAULT_SETTINGS
        >>> DEFAULT_SETTINGS.value("max_effects")
        3
        """
        if name not in GROUP_OF:
            raise DiagnosisError(f"settings.{name}: unknown setting; expected one of {', '.join(SETTINGS)}")
        return getattr(getattr(self, GROUP_OF[name]), name)

    @classmethod
    def describe(cls, name: str | None = None) -> Any:
        """Unit, rule, docs section, group, default and whether a study may set it: of one setting, or of all."""
        defaults = cls()
        table = {
            key: {
                "default": _json_ready(defaults.value(key)),
                "unit": setting.unit,
                "rule": setting.rule,
                "docs": setting.docs,
                "group": GROUP_OF[key],
                "study": setting.study,
            }
            for key, setting in SETTINGS.items()
        }
        if name is None:
            return table
        if name not in table:
            raise DiagnosisError(f"settings.{name}: unknown setting; expected one of {', '.join(table)}")
        return table[name]

    @classmethod
    def study_keys(cls) -> tuple[str, ...]:
        """The settings a study's ``diagnose`` analysis may set (the documented decision thresholds)."""
        return tuple(name for name, setting in SETTINGS.items() if setting.study)

    @classmethod
    def from_mapping(
        cls, values: Mapping[str, Any] | None, *, where: str = "settings", keys: tuple[str, ...] | None = None
    ) -> DiagnosisSettings:
        """Settings from a mapping of setting names, flat or by group (``keys``: the names allowed, default all).

        A group's name holds a mapping of its settings (``verdict: {score_threshold: 12}``); a setting's own
        name at the top level goes to its group.

        Examples
        --------
        >>> from uqgear.diagnosis.settings import DiagnosisSettings
        >>> flat = DiagnosisSettings.from_mapping({"score_threshold": 12.0})
        >>> nested = DiagnosisSettings.from_mapping({"verdict": {"score_threshold": 12.0}})
        >>> flat == nested, nested.verdict.score_threshold
        (True, 12.0)
        """
        allowed = tuple(SETTINGS) if keys is None else keys
        flat: dict[str, Any] = {}
        for key, value in dict(values or {}).items():
            if key in GROUPS and key not in allowed:
                if not isinstance(value, Mapping):
                    raise DiagnosisError(f"{where}.{key}: expected a mapping of its settings; got {value!r}")
                for name, item in value.items():
                    if name not in GROUPS[key] or name not in allowed:
                        expected = ", ".join(n for n in GROUPS[key] if n in allowed) or "none"
                        raise DiagnosisError(f"{where}.{key}.{name}: unknown setting; expected one of {expected}")
                    if name in flat:
                        raise DiagnosisError(f"{where}.{key}.{name}: set twice (also as {name})")
                    flat[name] = item
                continue
            if key not in allowed:
                raise DiagnosisError(f"{where}.{key}: unknown setting; expected one of {', '.join(allowed)}")
            if key in flat:
                raise DiagnosisError(f"{where}.{key}: set twice (also under {GROUP_OF[key]})")
            flat[key] = value
        try:
            return cls(**flat)
        except DiagnosisError as exc:
            raise DiagnosisError(f"{where}.{str(exc).removeprefix('settings.')}") from None

    def changed(self) -> dict[str, Any]:
        """The settings that differ from the defaults, JSON-ready, by their own names."""
        defaults = DiagnosisSettings()
        return {
            name: _json_ready(self.value(name))
            for name in SETTINGS
            if self.value(name) != defaults.value(name)
        }


#: Each setting's unit, the rule it serves, the docs section that explains it, its valid range, and whether a
#: study's ``diagnose`` analysis may set it.
SETTINGS: dict[str, Setting] = {
    # ---- the verdict (step 5)
    "score_threshold": Setting(
        "nat",
        "a candidate is named only when its held-out log predictive density gain over the model without it, after a "
        "penalty of 0.5 log n per parameter, reaches this",
        _VERDICT,
        lower=0.0,
        study=True,
    ),
    "shrink_threshold": Setting(
        "1",
        "a named candidate must shrink the held-out gap by this fraction, or leave a gap within noise",
        _VERDICT,
        lower=0.0,
        upper=1.0,
        study=True,
    ),
    "noise_gap": Setting(
        "noise spreads",
        "a held-out gap (excess RMS standardised discrepancy) at most this is within noise",
        _VERDICT,
        lower=0.0,
        study=True,
    ),
    "effect_gain_threshold": Setting(
        "nat",
        "a candidate's fit must be worse by at least this robust cost with its effect switched off, or its score "
        "belongs to the nominal parameters it refitted",
        _VERDICT,
        lower=0.0,
        study=True,
    ),
    "cross_channel_gain": Setting(
        "nat",
        "an effect is named only where the channels other than the one it gains most on gain at least this much "
        "held-out density together (score_threshold where the rig's gap is on that channel alone: a gear effect "
        "shows on every channel that sees the mesh; one channel alone is that sensor's own), and not where it "
        "loses this much on a channel the model without it fits",
        _CONSISTENCY,
        lower=0.0,
        study=True,
    ),
    "partial_shrink": Setting(
        "1",
        "a candidate that meets the score and gain rules but not the shrink rule is named with an unexplained "
        "remainder when the lower end of its 90 % shrink interval reaches this",
        _VERDICT,
        lower=0.0,
        upper=1.0,
        study=True,
    ),
    "score_quantile": Setting(
        "standard errors",
        "a score's 90 % lower bound lies this many standard errors below it (the normal 95 % quantile)",
        _PITCH,
        lower=0.0,
    ),
    "signal_snr": Setting(
        "noise spreads",
        "a rig line counts as signal at this amplitude over its per-quadrature noise spread (white noise reaches it in "
        "one line of 270,000)",
        _FEATURES,
        lower=0.0,
        study=True,
    ),
    "min_informative_runs": Setting(
        "runs",
        "a campaign is diagnosed only when this many runs show a line above the noise floor (one to fit, one held out)",
        _FEATURES,
        lower=2,
        integer=True,
    ),
    # ---- which candidates are fitted in full, and how many effects a set holds (steps 3 and 6)
    "promoted": Setting(
        "candidates",
        "at most this many effects are promoted from the screening fit to a full fit",
        _SELECTION,
        lower=1,
        integer=True,
    ),
    "runner_up_share": Setting(
        "1",
        "a runner-up is promoted when its screening score is at least this share of the leader's",
        _SELECTION,
        lower=0.0,
        upper=1.0,
    ),
    "extra_full_fits": Setting(
        "fits",
        "while the gap stays unexplained, up to this many further variants are fitted in full, best screened first "
        "(after the set the gap's strongest candidate leads, where it leads one, has failed)",
        _SELECTION,
        lower=0,
        integer=True,
    ),
    "max_effects": Setting(
        "effects",
        "forward selection names at most this many effects together",
        _SELECTION,
        lower=1,
        integer=True,
        study=True,
    ),
    "nominal_refits": Setting(
        "refits",
        "the nominal fit is restarted from a candidate's fit at most this many times",
        _SELECTION,
        lower=0,
        integer=True,
    ),
    "nominal_margin": Setting(
        "nat",
        "a candidate's nominal parameters must beat the nominal fit's robust cost by this much to show that the "
        "nominal fit stopped in a local optimum",
        _SELECTION,
        lower=0.0,
    ),
    "nominal_evaluations": Setting(
        "cost evaluations", "budget of each stage of the nominal fit and of its refits", _COST, lower=1, integer=True
    ),
    "screening_evaluations": Setting(
        "cost evaluations", "budget of a screening fit (the new effect's parameters only)", _COST, lower=1, integer=True
    ),
    "full_fit_evaluations": Setting(
        "cost evaluations",
        "budget of each stage of a full fit and of its refit with its own pitch-error allowance",
        _COST,
        lower=1,
        integer=True,
    ),
    "bootstrap_resamples": Setting(
        "resamples",
        "runs are resampled this many times for the intervals of a shrink and of a gap",
        _VERDICT,
        lower=10,
        integer=True,
    ),
    # ---- the pitch-error allowance (step 3)
    "pitch_draws": Setting(
        "draws", "pitch-error draws whose changes to each feature give the allowance", _PITCH, lower=2, integer=True
    ),
    "min_sideband_snr": Setting(
        "noise spreads", "a rig sideband counts as visible this far above the nominal fit", _PITCH, lower=0.0
    ),
    "min_visible_fraction": Setting(
        "1",
        "the allowance applies only where this share of each shaft's sidebands of every order 1 to 3 is visible on "
        "both shafts (pitch errors light every order of both)",
        _PITCH,
        lower=0.0,
        upper=1.0,
        study=True,
    ),
    "run_out_quantile": Setting(
        "1",
        "an eccentricity whose run-out stays below this quantile of what the stated classes' pitch errors make as a "
        "first-order run-out is not named for its run-out",
        _PITCH,
        lower=0.5,
        upper=1.0,
    ),
    "order_factor_quantiles": Setting(
        "1",
        "each (gear, order) group's share of the allowance is scaled to the rig's own gears within these quantiles of "
        "what gears of the stated classes give that group",
        _PITCH,
        lower=0.0,
        upper=1.0,
    ),
    "large_run_out_share": Setting(
        "1",
        "a gear whose first order reads larger than this share of the stated classes' gears is reported as a run-out "
        "the lines cannot tell from its own errors",
        _PITCH,
        lower=0.5,
        upper=1.0,
        study=True,
    ),
    # ---- an eccentric shaft named by its sidebands' phases (step 6)
    "phase_evidence_threshold": Setting(
        "nat",
        "the sideband phase sums name an eccentric shaft at this log ratio over pitch errors alone (without the run "
        "that favours it most)",
        _PHASES,
        lower=0.0,
        study=True,
    ),
    "min_sideband_orders": Setting(
        "pinion orders",
        "a shaft's phase sums are tested only where its first sidebands lie this far from their carrier (nearer, the "
        "line fit cannot hold them apart from the shaft's other orders)",
        _PHASES,
        lower=0.0,
    ),
    "modulation_kappas": Setting("1", "mesh stiffness modulations the eccentric-shaft hypothesis is tried at", _PHASES),
    "phase_draws_per_point": Setting(
        "draws",
        "pitch-error draws simulated at each point of the fitted model's parameter spread",
        _PHASES,
        lower=1,
        integer=True,
    ),
    # ---- a healthy reference and line interference (step 1)
    "speed_tolerance": Setting(
        "1", "a test run matches a reference run within this relative pinion speed", _REFERENCE, lower=0.0, upper=1.0
    ),
    "torque_tolerance": Setting(
        "1", "a test run matches a reference run within this relative drive torque", _REFERENCE, lower=0.0, upper=1.0
    ),
    "interference_threshold": Setting(
        "noise spreads", "a fixed-frequency peak counts as a line at this height", _INTERFERENCE, lower=0.0
    ),
    "interference_runs": Setting(
        "runs",
        "a fixed-frequency line must be met in at least this many runs (and half of them)",
        _INTERFERENCE,
        lower=1,
        integer=True,
    ),
    # ---- what changed since a healthy reference (step 1 with a reference)
    "change_z": Setting("noise spreads", "a feature changed when it moved by more than this many spreads of two "
                        "healthy records (halves of each record, carrying in speed) plus its allowances", _CHANGE,
                        lower=0.0, study=True),
    "change_allowance_db": Setting("dB", "run-to-run allowance added to every feature's change threshold", _CHANGE,
                                   lower=0.0, study=True),
    "replaced_allowance_db": Setting("dB", "a replaced gear set's spread added per family (rms, kurtosis, mesh "
                                     "harmonics, shaft lines, sidebands, TSA residual rms and kurtosis)", _CHANGE,
                                     lower=0.0),
    "same_line_floor": Setting("1", "line and band powers compare above this share of the channel's RMS (same "
                               "gears)", _CHANGE, lower=0.0, upper=1.0),
    "replaced_line_floor": Setting("1", "line and band powers compare above this share of the channel's RMS "
                                   "(replaced gears)", _CHANGE, lower=0.0, upper=1.0),
    "change_share": Setting("1", "an effect is named when it explains at least this share of the change",
                            _CHANGE, lower=0.0, upper=1.0, study=True),
    "change_margin": Setting("1", "and at least this much more than the next variant", _CHANGE, lower=0.0,
                             upper=1.0, study=True),
    "load_allowance": Setting("1", "share of the model's change over a run's stated T2 interval a healthy "
                              "campaign may differ by", _CHANGE, lower=0.0),
    "change_model_error": Setting("1", "relative error of the model's predicted change of a feature", _CHANGE,
                                  lower=0.0),
    # ---- the predictive distribution (step 2)
    "model_error": Setting(
        "1",
        "relative model error (standard deviation) of each feature kind: lines, band powers, RMS, kurtosis",
        _FEATURES,
    ),
    # ---- where the gap lies (reported, not decided)
    "where_z": Setting(
        "noise spreads",
        "a held-out feature this far off counts as a gap in the list of where it lies",
        _VERDICT,
        lower=0.0,
    ),
}


def _json_ready(value: Any) -> Any:
    if isinstance(value, Mapping):
        return dict(value)
    if isinstance(value, tuple):
        return list(value)
    return value


def _field_defaults() -> dict[str, Any]:
    """The defaults as the groups declare them (a tuple setting stays a tuple)."""
    return {spec.name: spec.default for kind in GROUP_TYPES.values() for spec in dataclasses.fields(kind)}


def _check(name: str, setting: Setting, value: Any) -> None:
    """Refuse a setting outside its type or range, naming it."""
    where = f"settings.{name}"
    if name == "model_error":
        _check_model_error(value)
        return
    if isinstance(_field_defaults().get(name), tuple) and not (isinstance(value, tuple) and value):
        raise DiagnosisError(f"{where}: expected a non-empty tuple of numbers; got {value!r}")
    for item in value if isinstance(value, tuple) else (value,):
        numeric = isinstance(item, (int, float)) and not isinstance(item, bool)
        if not numeric or not math.isfinite(item) or (setting.integer and not isinstance(item, int)):
            kind = "an integer" if setting.integer else "a number"
            raise DiagnosisError(f"{where}: expected {kind} ({setting.unit}); got {item!r}")
        if not setting.lower <= item <= setting.upper:
            raise DiagnosisError(
                f"{where}: expected a value in [{setting.lower:g}, {setting.upper:g}] ({setting.unit}); got {item!r}"
            )


def _check_model_error(value: Any) -> None:
    kinds = tuple(_MODEL_ERROR)
    if not isinstance(value, Mapping):
        raise DiagnosisError(
            f"settings.model_error: expected a mapping of feature kind to relative error; got {value!r}"
        )
    unknown = sorted(set(value) - set(kinds))
    if unknown:
        raise DiagnosisError(f"model_error.{unknown[0]}: unknown feature kind; expected {', '.join(kinds)}")
    missing = [kind for kind in kinds if kind not in value]
    if missing:
        raise DiagnosisError(
            f"model_error.{missing[0]}: missing; expected a relative error for each of {', '.join(kinds)}"
        )
    for key, item in value.items():
        if isinstance(item, bool) or not isinstance(item, (int, float)) or not 0.0 <= item < 1.0:
            raise DiagnosisError(f"model_error.{key}: expected a relative error in [0, 1); got {item!r}")


#: The settings the validation record was measured with (every default).
DEFAULT_SETTINGS = DiagnosisSettings()


__all__ = [
    "DiagnosisSettings", "Setting", "SETTINGS", "DEFAULT_SETTINGS", "GROUPS", "GROUP_OF", "GROUP_TYPES",
    "ReferenceSettings", "ChangeSettings", "InterferenceSettings", "FeatureSettings", "PredictiveSettings",
    "NominalSettings", "ScreeningSettings", "PitchSettings", "VerdictSettings", "SelectionSettings", "PhaseSettings",
]
