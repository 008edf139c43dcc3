"""Wheel/rail adhesion oscillation (stick-slip): the adhesion torque modulated at a frequency of its own."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...physics.design import Design
from ...physics.effects import AdhesionOscillation
from ..candidates import Candidate
from .base import EffectFamily


def _has_te(observed: Mapping[str, np.ndarray]) -> bool:
    """Whether the campaign has a TE with a usable run (a finite TE feature)."""
    return any(key.startswith("te:") and bool(np.isfinite(values).any()) for key, values in observed.items())


class AdhesionOscillationFamily(EffectFamily):
    """Stick-slip of the wheel on the rail (docs/model/unmodelled-effects.md section 6).

    One variant, its amplitude and frequency fitted; the frequency starts
    at a line at a fixed frequency between 1 and 100 Hz, else at 8 and
    30 Hz. Hint order: the TE first, its lowest frequency-locked line (the
    TE sees the torsional oscillation directly); only a campaign without a
    usable TE reads the accelerometers, their strongest steady line (the
    housings carry a faint image of the oscillation, the only one such a
    campaign has). Its phase relative to the record start
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
        """The stick-slip frequency from a line at a fixed frequency between 1 and 100 Hz, Hz.

        The TE's lowest line (lines naming channel ``te``, or none) where
        the campaign has a TE; else the accelerometers' strongest (their
        lines come strongest first: :func:`~uqgear.diagnosis.signatures.steady_modulation_lines`).

        Examples
        --------
        >>> from uqgear.diagnosis.effects import effect_family
        >>> family = effect_family("adhesion_oscillation")
        >>> lines = [{"frequency": 50.0, "channel": "te"}, {"frequency": 17.0, "channel": "acc_gear"},
        ...          {"frequency": 3.0, "channel": "acc_pinion"}]
        >>> family.hints({"te:mesh1": np.ones(3)}, lines)
        {'adhesion_frequency': 50.0}
        >>> family.hints({"acc_gear:mesh1": np.ones(3)}, lines[1:])
        {'adhesion_frequency': 17.0}
        """
        band = [line for line in locked_lines if 1.0 <= line["frequency"] <= 100.0]
        torsional = [line["frequency"] for line in band if line.get("channel", "te") == "te"]
        if torsional:
            return {"adhesion_frequency": float(min(torsional))}
        if _has_te(observed):
            # the TE sees a torsional line far better than the housings: where it has none, none is read
            return {}
        housings = [line["frequency"] for line in band]
        return {"adhesion_frequency": float(housings[0])} if housings else {}

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        return {self.strength: strength, "frequency": float(rng.uniform(6.0, 30.0)), "phase": phase}
