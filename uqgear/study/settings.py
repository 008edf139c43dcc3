"""How each operating point of a study is simulated: :class:`SimulationSettings` and their checks."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from ..common.errors import StudyError
from .checkers import Checker, boolean, check_mapping, choice, number


@dataclass(frozen=True)
class SimulationSettings:
    """How each operating point is simulated (see :func:`uqgear.physics.integration.simulate_batch`).

    Attributes
    ----------
    n_periods, keep_periods : int
        Mesh periods integrated, and kept at the end for QoIs and the
        Poincare section (the rest is the transient).
    lyapunov : bool
        Also estimate the largest Lyapunov exponent (about doubles the cost);
        it decides chaotic against quasi-periodic in classifications.
    steps_per_mode : int
        RK4 steps per period of the highest natural frequency.
    damping_in_separation : bool
        Mesh damping acts while the teeth are apart (the classical form).
    stiffness : {"ishikawa", "fourier"}
        Raw Ishikawa stiffness curve or its truncated Fourier series.
    """

    n_periods: int = 400
    keep_periods: int = 200
    lyapunov: bool = False
    steps_per_mode: int = 32
    damping_in_separation: bool = True
    stiffness: str = "ishikawa"

    def to_dict(self) -> dict[str, Any]:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}


_SIMULATION_SCHEMA: dict[str, Checker] = {
    "n_periods": number("mesh periods", 2, 1_000_000, integer=True),
    "keep_periods": number("mesh periods", 20, 1_000_000, integer=True),
    "lyapunov": boolean(),
    "steps_per_mode": number("steps", 8, 4096, integer=True),
    "damping_in_separation": boolean(),
    "stiffness": choice("ishikawa", "fourier"),
}


def _simulation(raw: Any, path: str, base: SimulationSettings) -> SimulationSettings:
    if raw is None:
        return base
    values = base.to_dict()
    values.update(check_mapping(raw, path, _SIMULATION_SCHEMA))
    settings = SimulationSettings(**values)
    check_kept_within(settings.n_periods, settings.keep_periods, "n_periods", f"{path}.keep_periods")
    return settings


def check_kept_within(total: int, kept: int, total_name: str, kept_name: str) -> None:
    """Refuse keeping more mesh periods than are integrated; the message names both values."""
    if kept > total:
        raise StudyError(f"{kept_name}: expected at most {total_name} ({total}); got {kept}")
