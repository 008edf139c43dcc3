"""The settings that :class:`~uqgear.calibration.estimator.Calibration` takes: their checks and their record."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..physics.design import Design
from ..physics.effects import Effect
from ..physics.pitch_errors import check_classes
from ..uq.seeds import as_seed_sequence
from .discrepancy import DEFAULT_DISCREPANCY_RANGE
from .errors import CalibrationError
from .harmonics import HARMONIC_CHANNELS
from .pitch_correction import DEFAULT_CLASSES
from .priors import DEFAULT_PARAMETERS, PARAMETER_ALIASES, resolve_parameters


def as_seed(seed: np.random.SeedSequence | int | None) -> np.random.SeedSequence:
    """The seed as a SeedSequence (fresh entropy for None)."""
    return np.random.SeedSequence() if seed is None else as_seed_sequence(seed, error=CalibrationError)


def check_design(design: object) -> Design | None:
    """None, or ``design`` if it is a uqgear Design."""
    if design is not None and not isinstance(design, Design):
        raise CalibrationError(f"design: expected a uqgear Design; got {type(design).__name__}")
    return design


def check_bool(name: str, value: object) -> bool:
    """``value`` as a bool, if it is true or false."""
    if not isinstance(value, (bool, np.bool_)):
        raise CalibrationError(f"{name}: expected true or false; got {value!r}")
    return bool(value)


def check_int(name: str, value: object, lowest: int) -> int:
    """``value`` as an int, if it is an integer >= ``lowest``."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lowest:
        raise CalibrationError(f"{name}: expected an integer >= {lowest}; got {value!r}")
    return int(value)


def check_float(name: str, value: object, lower: float, upper: float, unit: str = "") -> float:
    """``value`` as a float, if it is a number in [lower, upper]."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not lower <= float(value) <= upper
    ):
        raise CalibrationError(f"{name}: expected a number in [{lower:g}, {upper:g}]{unit}; got {value!r}")
    return float(value)


def check_priors(priors: Mapping[str, Sequence[float]] | None, parameters: Sequence[str]) -> dict[str, Sequence[float]]:
    """The prior bounds given, if each is of a calibrated parameter (aliases allowed)."""
    priors = dict(priors or {})
    for name in priors:
        if PARAMETER_ALIASES.get(name, name) not in parameters:
            raise CalibrationError(f"priors.{name}: not among the calibrated parameters ({', '.join(parameters)})")
    return priors


def check_channels(channels: Sequence[str]) -> tuple[str, ...]:
    """The channels, if at least one and each a rig channel of :data:`HARMONIC_CHANNELS`."""
    channels = list(channels)
    for name in channels:
        if name not in HARMONIC_CHANNELS:
            raise CalibrationError(f"channels: {name!r} is not a rig channel; expected {', '.join(HARMONIC_CHANNELS)}")
    if not channels:
        raise CalibrationError("channels: expected at least one channel")
    return tuple(channels)


def check_model_error_range(
    model_error_range: tuple[float, float], name: str = "model_error_range"
) -> tuple[float, float]:
    """The bounds of a relative error's log-uniform prior (``name`` says which), if 0 < lower < upper."""
    try:
        low, high = (float(v) for v in model_error_range)
    except (TypeError, ValueError):
        raise CalibrationError(f"{name}: expected (lower, upper) relative errors; got {model_error_range!r}") from None
    if not 0 < low < high:
        raise CalibrationError(f"{name}: expected 0 < lower < upper (relative); got {model_error_range!r}")
    return low, high


def check_n_training(n_training: int) -> int:
    """Model runs per operating point and stage, if a power of 2 (Sobol design) of at least 16."""
    value = check_int("n_training", n_training, 16)
    if value & (value - 1):
        raise CalibrationError(f"n_training: expected a power of 2 (Sobol design); got {n_training!r}")
    return value


def check_pitch_classes(classes: object) -> tuple[float, float] | None:
    """None, or (lowest, highest) ISO 1328-1 flank tolerance classes within 1..11."""
    return check_classes(classes, error=CalibrationError)


class CalibrationSettings:
    """The settings of a :class:`~uqgear.calibration.Calibration`, checked, and their record.

    The parameters are those of :class:`~uqgear.calibration.Calibration`,
    whose docstring describes each; a bad one raises :class:`CalibrationError`
    naming it.

    Examples
    --------
    >>> from uqgear.calibration.settings import CalibrationSettings
    >>> record = CalibrationSettings(["zeta_mesh"], n_harmonics=2, seed=4).settings()
    >>> record["parameters"], record["n_harmonics"], record["seed_entropy"]
    (['zeta_mesh'], 2, '4')
    """

    def __init__(
        self,
        parameters: Sequence[str] = DEFAULT_PARAMETERS,
        *,
        design: Design | None = None,
        priors: Mapping[str, Sequence[float]] | None = None,
        channels: Sequence[str] = HARMONIC_CHANNELS,
        n_harmonics: int = 3,
        min_snr: float = 5.0,
        model_error_range: tuple[float, float] = (0.01, 0.5),
        effects: Sequence[Effect] = (),
        n_training: int = 256,
        emulator_degree: int = 3,
        max_stages: int = 5,
        n_walkers: int | None = None,
        stage_steps: int = 1500,
        chunk_steps: int = 2000,
        max_steps: int = 30000,
        autocorr_factor: float = 50.0,
        rhat_threshold: float = 1.01,
        min_ess: float = 400.0,
        predictive_draws: int = 16,
        transient: float = 0.2,
        window: float = 0.1,
        seed: np.random.SeedSequence | int | None = None,
        threads: int | None = None,
        pitch_correction: bool = True,
        pitch_draws: int = 4,
        pitch_classes: tuple[float, float] | None = DEFAULT_CLASSES,
        discrepancy: bool = False,
        discrepancy_range: tuple[float, float] = DEFAULT_DISCREPANCY_RANGE,
    ) -> None:
        self.parameters = resolve_parameters(parameters)
        self.design = check_design(design)
        self.priors = check_priors(priors, self.parameters)
        self.channels = check_channels(channels)
        self.n_harmonics = check_int("n_harmonics", n_harmonics, 1)
        self.min_snr = check_float("min_snr", min_snr, 0.0, 1e6)
        self.model_error_range = check_model_error_range(model_error_range)
        self.effects = tuple(effects)
        self.n_training = check_n_training(n_training)
        self.emulator_degree = check_int("emulator_degree", emulator_degree, 1)
        self.max_stages = check_int("max_stages", max_stages, 1)
        self.n_walkers = None if n_walkers is None else check_int("n_walkers", n_walkers, 4)
        self.stage_steps = check_int("stage_steps", stage_steps, 100)
        self.chunk_steps = check_int("chunk_steps", chunk_steps, 100)
        self.max_steps = check_int("max_steps", max_steps, self.chunk_steps)
        self.autocorr_factor = check_float("autocorr_factor", autocorr_factor, 1.0, 1e4)
        self.rhat_threshold = check_float("rhat_threshold", rhat_threshold, 1.0, 10.0)
        self.min_ess = check_float("min_ess", min_ess, 1.0, 1e9)
        self.predictive_draws = check_int("predictive_draws", predictive_draws, 0)
        self.transient = check_float("transient", transient, 0.0, 100.0, " s")
        self.window = check_float("window", window, 0.0, 100.0, " s")
        self.seed = as_seed(seed)
        self.threads = None if threads is None else check_int("threads", threads, 1)
        self.pitch_correction = check_bool("pitch_correction", pitch_correction)
        self.pitch_draws = check_int("pitch_draws", pitch_draws, 2)
        self.pitch_classes = check_pitch_classes(pitch_classes)
        self.discrepancy = check_bool("discrepancy", discrepancy)
        self.discrepancy_range = check_model_error_range(discrepancy_range, "discrepancy_range")

    # ------------------------------------------------------------------ settings record

    def settings(self) -> dict[str, Any]:
        """The settings as a JSON-ready mapping."""
        return {
            "parameters": list(self.parameters),
            "priors": {k: list(v) for k, v in self.priors.items()},
            "channels": list(self.channels),
            "n_harmonics": self.n_harmonics,
            "min_snr": self.min_snr,
            "model_error_range": list(self.model_error_range),
            "effects": [{"name": e.name, "values": dict(e.values)} for e in self.effects],
            "n_training": self.n_training,
            "emulator_degree": self.emulator_degree,
            "max_stages": self.max_stages,
            "n_walkers": self.n_walkers,
            "stage_steps": self.stage_steps,
            "chunk_steps": self.chunk_steps,
            "max_steps": self.max_steps,
            "autocorr_factor": self.autocorr_factor,
            "rhat_threshold": self.rhat_threshold,
            "min_ess": self.min_ess,
            "predictive_draws": self.predictive_draws,
            "transient": self.transient,
            "window": self.window,
            "pitch_correction": self.pitch_correction,
            "pitch_draws": self.pitch_draws,
            "pitch_classes": None if self.pitch_classes is None else list(self.pitch_classes),
            "discrepancy": self.discrepancy,
            "discrepancy_range": list(self.discrepancy_range),
            "seed_entropy": str(self.seed.entropy),
        }
