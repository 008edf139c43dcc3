"""Analysis types of a study: the keys each takes with their checks, and their defaults.

Adding an analysis type takes one entry in :data:`ANALYSIS_SCHEMAS` (its keys
and their checks) and one function registered in :mod:`uqgear.study.analyses`.
"""

from __future__ import annotations

from typing import Any

from ..common.errors import StudyError
from ..dynamics.stress_qois import STRESS_QOIS
from ..physics.effects import EFFECTS
from .checkers import Checker, boolean, check_mapping, choice, class_range, identifier, list_of, number, string
from .variables import VARIABLES

#: Scalar quantities of interest of a simulation run (see uqgear.physics.integration.QOI_INFO).
QOIS: tuple[str, ...] = (
    "dte_mean",
    "dte_rms",
    "dte_peak_to_peak",
    "dynamic_load_factor",
    "peak_mesh_force",
    "load_factor_rated",
    "acc_pinion_rms",
    "acc_gear_rms",
    "fraction_drive_contact",
    "fraction_separation",
    "fraction_back_contact",
    "largest_lyapunov",
)
DEFAULT_QOIS: tuple[str, ...] = ("dte_rms", "dynamic_load_factor", "fraction_separation")
#: QoIs of the analyses that bound or sample any QoI: :data:`QOIS` and the tooth stresses
#: (uqgear.dynamics.stress_qois.STRESS_QOI_INFO), which take a ``rating`` block of ISO 6336 inputs.
RUN_QOIS: tuple[str, ...] = QOIS + STRESS_QOIS

INTERVAL_METHODS: tuple[str, ...] = ("scan", "vertex", "chebyshev", "optimize")
INTERVAL_FALLBACKS: tuple[str, ...] = ("scan", "optimize", "none")
SAMPLING_METHODS: tuple[str, ...] = ("monte_carlo", "latin_hypercube", "sobol", "halton")
#: Which response the statistics of a sample see where several coexist (``response`` of monte_carlo, pce, sobol).
RESPONSES: tuple[str, ...] = ("worst", "rest")


def diagnosis_settings(value: Any, path: str) -> dict[str, Any]:
    """Checker of a ``diagnose`` analysis's ``settings``: documented thresholds of the diagnosis by name."""
    from ..common.errors import StudyError, shown
    from ..diagnosis import DiagnosisError, DiagnosisSettings

    if not isinstance(value, dict):
        raise StudyError(f"{path}: expected a mapping of diagnosis settings to values; got {shown(value)}")
    try:
        DiagnosisSettings.from_mapping(value, where=path, keys=DiagnosisSettings.study_keys())
    except DiagnosisError as exc:
        raise StudyError(str(exc)) from None
    return dict(value)


def rating_settings(value: Any, path: str) -> dict[str, Any]:
    """Checker of a ``rating`` analysis's ``rating``: material data and the ISO 6336 inputs, validated by key."""
    from ..common.errors import StudyError
    from ..physics.rating import RatingError, RatingSettings

    try:
        RatingSettings.from_mapping(value, where=f"{path}.")
    except RatingError as exc:
        raise StudyError(str(exc)) from None
    # kept as written (JSON-able, part of the analysis key); the analysis builds the settings from it
    return dict(value)


def service_profile(value: Any, path: str) -> dict[str, Any]:
    """Checker of a ``rating`` analysis's ``service``: a bundled profile or a speed distribution or mission, with
    its duration and rail condition (:func:`uqgear.study.rating_service.check_service`)."""
    from .rating_service import check_service

    return check_service(value, path)


def runup_speeds(value: Any, path: str) -> dict[str, float]:
    """Checker of a ``runup`` analysis's ``pinion_speed``: ``{start, stop}`` in rpm, two different speeds."""
    speed = number("rpm", 0.0, None, lower_open=True)
    speeds = check_mapping(value, path, {"start": speed, "stop": speed}, required=("start", "stop"))
    if speeds["start"] == speeds["stop"]:
        raise StudyError(f"{path}: expected two different speeds for start and stop; got {speeds['start']:g} rpm twice")
    return speeds


def _qoi_list(names: tuple[str, ...] = QOIS) -> Checker:
    return list_of(choice(*names), unique=True, what="a list of QoI names")


#: The keys of an analysis that takes the tooth stress QoIs.
_STRESS_KEYS: dict[str, Checker] = {"qois": _qoi_list(RUN_QOIS), "rating": rating_settings}


def _variable_list() -> Checker:
    return list_of(choice(*VARIABLES), unique=True, what="a list of parameter names")


#: Keys every analysis entry may have, whatever its type, and the check of each.
COMMON_ANALYSIS_KEYS: dict[str, Checker] = {
    "type": string(),
    "name": identifier(),
    "description": string(),
    # merged over the study's operating_points and simulation
    "operating_points": lambda value, path: value,
    "simulation": lambda value, path: value,
}

#: The interval method's keys, shared by the analyses that bound over interval parameters with it.
_INTERVAL_METHOD_KEYS: dict[str, Checker] = {
    "parameters": _variable_list(),
    "method": choice(*INTERVAL_METHODS),
    "order": number("(Chebyshev series order)", 1, 20, integer=True),
    "points": number("(scan points per interval parameter)", 2, 1000, integer=True),
    "fallback": choice(*INTERVAL_FALLBACKS),
    "tolerance": number("(relative surrogate error accepted)", 0.0, 1.0, lower_open=True),
}

#: Keys (with checks) of each analysis type, besides ``type``, ``name``,
#: ``description``, ``operating_points`` and ``simulation``.
ANALYSIS_SCHEMAS: dict[str, dict[str, Checker]] = {
    "simulate": {
        "samples_per_period": number("samples per mesh period", 8, 1024, integer=True),
        "method": choice("fast", "scipy"),
        "spectrum": choice("order", "frequency"),
        "labels": list_of(string(), what="a list of labels"),
        # ISO 6336 inputs of the tooth stresses along the path of contact
        "rating": rating_settings,
    },
    "bifurcation": {
        "parameter": choice(*VARIABLES),
        "envelope": _variable_list(),
        "points": number("values across each interval", 2, 200, integer=True),
    },
    "regime_map": {
        "axes": list_of(choice(*VARIABLES), min_length=2, unique=True, what="a list of two variable names"),
        "points": number("values across each interval", 2, 200, integer=True),
    },
    "interval": {**_INTERVAL_METHOD_KEYS, **_STRESS_KEYS},
    "monte_carlo": {
        "parameters": _variable_list(),
        "intervals": choice("uniform", "pbox"),
        "points": number("(scan points per interval parameter, p-box)", 2, 101, integer=True),
        "samples": number("samples", 2, 10_000_000, integer=True),
        "sampling": choice(*SAMPLING_METHODS),
        "quantiles": list_of(number("", 0.0, 1.0), unique=True, what="a list of probabilities"),
        **_STRESS_KEYS,
        "response": choice(*RESPONSES),
    },
    "pce": {
        "parameters": _variable_list(),
        "order": number("(highest total polynomial degree tried)", 1, 12, integer=True),
        "min_order": number("(lowest total polynomial degree tried)", 1, 12, integer=True),
        "samples": number("training samples", 2, 1_000_000, integer=True),
        "validation_samples": number("check samples", 2, 1_000_000, integer=True),
        "sampling": choice(*SAMPLING_METHODS),
        **_STRESS_KEYS,
        "response": choice(*RESPONSES),
    },
    "sobol": {
        "parameters": _variable_list(),
        "samples": number("base samples N (a power of 2)", 8, 1_048_576, integer=True),
        "second_order": boolean(),
        "confidence_level": number("", 0.5, 0.999),
        "bootstrap": number("resamples", 10, 100_000, integer=True),
        **_STRESS_KEYS,
        "response": choice(*RESPONSES),
    },
    "calibrate": {
        "rig": string(),
        "parameters": list_of(
            choice(
                "mesh_stiffness_scale",
                "zeta_mesh",
                "backlash",
                "ste_amplitude",
                "k1",
                "k2",
                "k1_scale",
                "k2_scale",
                "zeta1",
                "zeta2",
                "m1",
                "m2",
            ),
            unique=True,
        ),
        # ISO 1328-1 classes of the rig's gears, for the pitch-error correction (none: read from the sidebands)
        "pitch_classes": class_range(1, 11),
        # a model-discrepancy term per channel and harmonic (uqgear calibrate --discrepancy)
        "discrepancy": boolean(),
    },
    "diagnose": {
        "rig": string(),
        "effects": list_of(choice(*EFFECTS), unique=True),
        # a healthy campaign of the same rig and test plan (uqgear diagnose --reference)
        "reference": string(),
        # ISO 1328-1 classes of the rig's gears: what their pitch errors do is model error (none: perfect gears)
        "pitch_classes": class_range(1, 11),
        # the documented decision thresholds of uqgear.diagnosis.DiagnosisSettings
        "settings": diagnosis_settings,
    },
    "prediction": {
        "parameters": _variable_list(),
        "method": choice("scan", "vertex"),
        "points": number("(nodes per interval parameter)", 2, 101, integer=True),
        "draws": number("(draws of the study's distributions without a posterior)", 1, 100_000, integer=True),
        "quantiles": list_of(number("", 0.0, 1.0), unique=True, what="a list of probabilities"),
        **_STRESS_KEYS,
    },
    "continuation": {
        "parameter": choice(*VARIABLES),
        "envelope": _variable_list(),
        "points": number("values across each interval", 2, 50, integer=True),
        "max_period": number("(longest period followed at period doublings)", 1, 64, integer=True),
        "compare_sweeps": boolean(),
    },
    "runup": {
        "direction": choice("up", "down", "both"),
        # {start, stop} in rpm: the span run up and coasted down
        "pinion_speed": runup_speeds,
        "rate": number("rpm/s", 0.0, None, lower_open=True),
        "parameters": _variable_list(),
        "points": number("(values across each interval parameter)", 2, 21, integer=True),
        "speed_bins": number("(speed bins along the ramp)", 2, 2000, integer=True),
        "sample_rate": number("Hz", 1000.0, 500_000.0),
        "orders": list_of(number("(pinion orders)", 0.0, None, lower_open=True), unique=True, what="a list of orders"),
        "jump_threshold": number("(relative step of the binned peak that is a jump)", 0.0, 10.0, lower_open=True),
        "jump_bin": number("rpm (bins the jumps are located to)", 0.0, None, lower_open=True),
        "folds": boolean(),
        "max_period": number("(longest period followed for the folds)", 1, 16, integer=True),
        "compare_rates": list_of(number("rpm/s", 0.0, None, lower_open=True), unique=True, what="a list of rates"),
    },
    "rating": {
        **_INTERVAL_METHOD_KEYS,
        # material data and the other ISO 6336 inputs (uqgear.physics.rating.RatingSettings keys)
        "rating": rating_settings,
        # the service the fatigue damage is summed over (illustrative default: see RATING_SERVICE)
        "service": service_profile,
        # T2 values per speed the stress histories run at, evenly across the T2 interval, its ends included
        "history_points": number("(T2 values per speed of the damage histories)", 2, 33, integer=True),
    },
}

#: The interval method's defaults (:data:`_INTERVAL_METHOD_KEYS`).
_INTERVAL_METHOD_DEFAULTS: dict[str, Any] = {
    "method": "chebyshev",
    "order": 6,
    "points": None,
    "fallback": "scan",
    "tolerance": 0.02,
}

#: Default option values per analysis type (applied after validation).
ANALYSIS_DEFAULTS: dict[str, dict[str, Any]] = {
    "simulate": {"samples_per_period": 64, "method": "fast", "spectrum": "order", "labels": ()},
    "bifurcation": {"envelope": (), "points": 5},
    "continuation": {"envelope": (), "points": 2, "max_period": 8, "compare_sweeps": True},
    "regime_map": {"points": 9},
    "interval": {**_INTERVAL_METHOD_DEFAULTS, "qois": DEFAULT_QOIS},
    "rating": {**_INTERVAL_METHOD_DEFAULTS, "history_points": 3},
    "monte_carlo": {
        "intervals": "uniform",
        "points": 5,
        "samples": 256,
        "sampling": "latin_hypercube",
        "quantiles": (0.05, 0.5, 0.95),
        "qois": DEFAULT_QOIS,
        "response": "worst",
    },
    "pce": {
        "order": 3,
        "min_order": 1,
        "samples": 0,
        "validation_samples": 32,
        "sampling": "halton",
        "qois": DEFAULT_QOIS,
        "response": "worst",
    },
    "sobol": {
        "samples": 64,
        "second_order": False,
        "confidence_level": 0.95,
        "bootstrap": 200,
        "qois": DEFAULT_QOIS,
        "response": "worst",
    },
    "calibrate": {
        "parameters": ("mesh_stiffness_scale", "zeta_mesh", "backlash", "ste_amplitude", "k1", "k2"),
        "pitch_classes": (6.0, 8.0),
        "discrepancy": False,
    },
    "diagnose": {"effects": tuple(EFFECTS), "reference": None, "pitch_classes": (6.0, 8.0)},
    "runup": {
        "direction": "both",
        "rate": 100.0,
        "points": 3,
        "speed_bins": 40,
        "sample_rate": 20480.0,
        "orders": (),
        "jump_threshold": 0.15,
        "jump_bin": None,
        "folds": True,
        "max_period": 1,
        "compare_rates": (),
    },
    "prediction": {
        "method": "scan",
        "points": 7,
        "draws": 64,
        "quantiles": (0.05, 0.5, 0.95),
        "qois": ("peak_mesh_force", "dynamic_load_factor", "dte_rms"),
    },
}
#: Keys an analysis entry of a type must have.
REQUIRED_ANALYSIS_KEYS: dict[str, tuple[str, ...]] = {
    "bifurcation": ("parameter",),
    "continuation": ("parameter",),
    "regime_map": ("axes",),
    "calibrate": ("rig",),
    "diagnose": ("rig",),
}
#: Analysis types that read a rig data file (key ``rig``, relative to the study file).
RIG_TYPES: tuple[str, ...] = ("calibrate", "diagnose")
#: Analysis types that propagate uncertain parameters (``parameters`` key).
PROPAGATING_TYPES: tuple[str, ...] = ("interval", "monte_carlo", "pce", "sobol", "prediction", "rating")
#: Analysis types that bound over interval parameters (their ``parameters`` are intervals).
INTERVAL_TYPES: tuple[str, ...] = ("interval", "prediction", "rating")
#: Cap on single simulate() runs in one ``simulate`` analysis (they keep full histories).
MAX_SIMULATE_RUNS = 64
