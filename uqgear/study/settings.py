"""How each operating point of a study is simulated: :class:`SimulationSettings` and their checks."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..common.errors import StudyError, UqgearError
from ..dynamics.attractors import MultiStart
from ..physics.rating import RatingMaterial, RatingSettings
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
    starts : MultiStart, optional
        Start every point from several states and report every steady response found
        (:mod:`uqgear.dynamics.attractors`); None (default): from rest only, as always.
    effects : tuple of Effect
        Effects added to the model in every run (a study's ``model.effects``: the
        effects a diagnosis named, at their fitted values).
    stresses : RatingSettings, optional
        Also compute the tooth stress QoIs of every run with these ISO 6336 inputs
        (:mod:`uqgear.dynamics.stress_qois`); set where an analysis asks for a stress QoI.
    """

    n_periods: int = 400
    keep_periods: int = 200
    lyapunov: bool = False
    steps_per_mode: int = 32
    damping_in_separation: bool = True
    stiffness: str = "ishikawa"
    starts: MultiStart | None = None
    effects: tuple[Any, ...] = ()
    stresses: RatingSettings | None = None

    def __post_init__(self) -> None:
        if isinstance(self.starts, Mapping):
            object.__setattr__(self, "starts", MultiStart.from_mapping(self.starts))
        if isinstance(self.stresses, Mapping):
            # the plain values of to_dict, field for field
            values = dict(self.stresses)
            values["material"] = RatingMaterial(**values["material"])
            object.__setattr__(self, "stresses", RatingSettings(**values))

    def batch_options(self, threads: int | None = None) -> dict[str, Any]:
        """Keyword arguments of :func:`~uqgear.physics.integration.simulate_batch` (and
        :class:`~uqgear.physics.integration.BatchEvaluator`) for these settings.

        Examples
        --------
        >>> SimulationSettings(n_periods=600).batch_options(threads=2)["n_periods"]
        600
        """
        return {
            "n_periods": self.n_periods,
            "keep_periods": self.keep_periods,
            "lyapunov": self.lyapunov,
            "damping_in_separation": self.damping_in_separation,
            "stiffness": self.stiffness,
            "steps_per_mode": self.steps_per_mode,
            "threads": threads,
            "effects": self.effects,
        }

    def to_dict(self) -> dict[str, Any]:
        """The settings as plain values; ``starts`` only when set, so the keys of results run from rest
        only (checkpoints, resumed studies) stay what they were."""
        optional = ("starts", "effects", "stresses")
        values = {key: getattr(self, key) for key in self.__dataclass_fields__ if key not in optional}
        if self.starts is not None:
            values["starts"] = self.starts.to_dict()
        if self.stresses is not None:
            values["stresses"] = dataclasses.asdict(self.stresses)
        if self.effects:
            values["effects"] = [repr(effect) for effect in self.effects]
        return values


#: The starts of a study that does not say: extra starts only inside the coexistence windows.
GUIDED_STARTS = MultiStart(guided=True, seeded=1, nodes=9)


def _starts(value: Any, path: str) -> MultiStart | None:
    """``guided`` (the default: extra starts inside the coexistence windows only), ``true`` (every start at every
    point), ``false``/none (rest only) or a mapping of :class:`MultiStart` keys."""
    if value is None or value is False or value == "none":
        return None
    if value is True:
        return MultiStart()
    if value == "guided":
        return GUIDED_STARTS
    if not isinstance(value, Mapping):
        raise StudyError(
            f"{path}: expected guided, true, false or a mapping with keys "
            f"{', '.join(MultiStart.__dataclass_fields__)}; got {value!r}"
        )
    try:
        return MultiStart.from_mapping(value, where=path)
    except (UqgearError, TypeError) as error:
        raise StudyError(str(error)) from None


#: The keys of a ``simulation`` entry and the check of each.
SIMULATION_SCHEMA: dict[str, Checker] = {
    "n_periods": number("mesh periods", 2, 1_000_000, integer=True),
    "keep_periods": number("mesh periods", 20, 1_000_000, integer=True),
    "lyapunov": boolean(),
    "steps_per_mode": number("steps", 8, 4096, integer=True),
    "damping_in_separation": boolean(),
    "stiffness": choice("ishikawa", "fourier"),
    "starts": _starts,
}


def parse_simulation_settings(raw: Any, path: str, base: SimulationSettings) -> SimulationSettings:
    """The ``simulation`` entry at ``path`` laid over ``base`` (the study's settings, or the defaults).

    Keys are those of :data:`SIMULATION_SCHEMA`; ``None`` gives ``base`` itself. Refusals are
    :class:`StudyError` naming the entry.
    """
    if raw is None:
        return base
    values = base.to_dict()
    values.update(check_mapping(raw, path, SIMULATION_SCHEMA))
    settings = SimulationSettings(**values)
    check_kept_within(settings.n_periods, settings.keep_periods, "n_periods", f"{path}.keep_periods")
    return settings


def check_kept_within(total: int, kept: int, total_name: str, kept_name: str) -> None:
    """Refuse keeping more mesh periods than are integrated; the message names both values."""
    if kept > total:
        raise StudyError(f"{kept_name}: expected at most {total_name} ({total}); got {kept}")
