"""Checks of the settings that :class:`~uqgear.calibration.estimator.Calibration` takes."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..physics.design import Design
from ..physics.pitch_errors import check_classes
from ..uq.seeds import as_seed_sequence
from .errors import CalibrationError
from .harmonics import HARMONIC_CHANNELS
from .priors import PARAMETER_ALIASES


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
