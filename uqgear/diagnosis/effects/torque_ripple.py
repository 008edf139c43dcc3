"""Traction motor torque ripple: the drive torque modulated at six times the motor's electrical frequency."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...physics.design import Design
from ...physics.effects import TorqueRipple
from ..candidates import Candidate
from .base import START_PHASES, EffectFamily


class TorqueRippleFamily(EffectFamily):
    """Torque ripple of the traction motor (docs/model/unmodelled-effects.md section 6).

    One variant, its amplitude and phase fitted; none for a design without
    ``motor_pole_pairs`` (its frequency is unknown). Its response repeats
    over a pinion revolution (the rotor turns with the pinion). Hints: none
    on any channel (its frequency follows from the design, its amplitude
    starts from a fixed grid).
    """

    name = "torque_ripple"
    physics = TorqueRipple
    strength = "amplitude"
    ladder = (0.003, 0.01, 0.06)

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        if design.motor_pole_pairs is None:
            return []
        fitted = (self.strength_parameter("amplitude", 0.01, upper=0.3), self.parameter("phase", 1.0, 0.0, 2.0 * np.pi))
        starts = self.grid(amplitude=(0.003, 0.05), phase=START_PHASES)
        return [self.candidate("torque_ripple", (), fitted, starts, "pinion")]

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        return {self.strength: strength, "phase": phase}
