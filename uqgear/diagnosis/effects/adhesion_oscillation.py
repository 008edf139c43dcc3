"""Wheel/rail adhesion oscillation (stick-slip): the adhesion torque modulated at a frequency of its own."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...physics.design import Design
from ...physics.effects import AdhesionOscillation
from ..candidates import Candidate
from .base import EffectFamily


class AdhesionOscillationFamily(EffectFamily):
    """Stick-slip of the wheel on the rail (docs/model/unmodelled-effects.md section 6).

    One variant, its amplitude and frequency fitted; the frequency starts
    at the lowest frequency-locked line of the TE below 100 Hz where there
    is one, else at 8 and 30 Hz. Its phase relative to the record start
    changes no amplitude spectrum and is fixed. Its response never repeats
    over a shaft period (simulated over the whole record).
    """

    name = "adhesion_oscillation"
    physics = AdhesionOscillation
    strength = "amplitude"
    ladder = (0.003, 0.01, 0.05)
    # at 1-100 Hz, far below the bearing modes, a torque oscillation turns the gears against each other
    # (the TE) while the housings barely accelerate: its evidence may lie on the TE alone
    one_channel = "a torque oscillation far below the bearing modes moves the TE, not the housings"

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        fitted = (self.strength_parameter("amplitude", 0.01, upper=0.3), self.parameter("frequency", 2.0, 1.0, 100.0))
        frequencies = (hints["adhesion_frequency"],) if hints.get("adhesion_frequency") else (8.0, 30.0)
        starts = self.grid(amplitude=(0.003, 0.03), frequency=frequencies)
        return [self.candidate("adhesion_oscillation", (("phase", 0.0),), fitted, starts, "free")]

    def hints(self, observed: Mapping[str, np.ndarray], locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
        """The stick-slip frequency: the lowest frequency-locked line between 1 and 100 Hz, Hz."""
        low = [line["frequency"] for line in locked_lines if 1.0 <= line["frequency"] <= 100.0]
        return {"adhesion_frequency": float(min(low))} if low else {}

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        return {self.strength: strength, "frequency": float(rng.uniform(6.0, 30.0)), "phase": phase}
