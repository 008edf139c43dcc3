"""Wheel/rail adhesion oscillation (stick-slip): the adhesion torque modulated at a frequency of its own."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...physics.design import Design
from ...physics.effects import AdhesionOscillation
from ..candidates import Candidate
from .base import EffectFamily

#: Steady lines of the accelerometers the frequency starts at, the strongest of distinct frequency. A
#: speed wander modulates the mesh line's frequency: sidebands at multiples of the wander's frequency,
#: the same in Hz in every run, with an index of modulation that grows with the mesh frequency, so
#: they may pass the steady-line test (+-0.5 % at 1.3 Hz: a line at 4 Hz with twice the power over the
#: floor of a 0.5 % oscillation's line), and more than one where the wander is larger. Each start
#: costs one batch of simulations; the fit refines the least costly.
HOUSING_STARTS = 4


def _hint_keys() -> tuple[str, ...]:
    """The hints' keys, the preferred start first: ``adhesion_frequency``, ``adhesion_frequency_2``, ..."""
    return ("adhesion_frequency", *(f"adhesion_frequency_{rank}" for rank in range(2, HOUSING_STARTS + 1)))


def _has_te(observed: Mapping[str, np.ndarray]) -> bool:
    """Whether the campaign has a TE with a usable run (a finite TE feature)."""
    return any(key.startswith("te:") and bool(np.isfinite(values).any()) for key, values in observed.items())


class AdhesionOscillationFamily(EffectFamily):
    """Stick-slip of the wheel on the rail (docs/model/unmodelled-effects.md section 6).

    One variant, its amplitude and frequency fitted; the frequency starts
    at the lines at a fixed frequency between 1 and 100 Hz, else at 8 and
    30 Hz. Hint order: the TE first, its lowest frequency-locked line (the
    TE sees the torsional oscillation directly); only a campaign without a
    usable TE reads the accelerometers, their :data:`HOUSING_STARTS`
    strongest steady lines of distinct frequency, strongest first (the
    housings carry a faint image of the oscillation, the only one such a
    campaign has, but a wandering speed puts the mesh line's own frequency
    modulation there too, at multiples of the wander's frequency, and it
    may outshine a weak oscillation's; the fit keeps the start of least
    cost). Its phase relative to the record start changes no amplitude
    spectrum and is fixed. Its response never repeats over a shaft period
    (simulated over the whole record).
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
        read = [hints[key] for key in _hint_keys() if hints.get(key)]
        frequencies = tuple(read) if read else (8.0, 30.0)
        starts = self.grid(amplitude=(0.003, 0.03), frequency=frequencies)
        return [self.candidate("adhesion_oscillation", (("phase", 0.0),), fitted, starts, "free")]

    def hints(self, observed: Mapping[str, np.ndarray], locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
        """The stick-slip frequency from the lines at a fixed frequency between 1 and 100 Hz, Hz.

        The TE's lowest line (lines naming channel ``te``, or none) where
        the campaign has a TE, as ``adhesion_frequency``; else the
        accelerometers' :data:`HOUSING_STARTS` strongest lines of distinct
        frequency (their lines come strongest first:
        :func:`~uqgear.diagnosis.signatures.steady_modulation_lines`; a
        line within 1 Hz of a stronger one, the same line on the other
        housing, is not counted again), as ``adhesion_frequency``,
        ``adhesion_frequency_2``, ...

        Examples
        --------
        >>> from uqgear.diagnosis.effects import effect_family
        >>> family = effect_family("adhesion_oscillation")
        >>> lines = [{"frequency": 50.0, "channel": "te"}, {"frequency": 4.0, "channel": "acc_gear"},
        ...          {"frequency": 4.0, "channel": "acc_pinion"}, {"frequency": 17.0, "channel": "acc_gear"}]
        >>> family.hints({"te:mesh1": np.ones(3)}, lines)
        {'adhesion_frequency': 50.0}
        >>> family.hints({"acc_gear:mesh1": np.ones(3)}, lines[1:])
        {'adhesion_frequency': 4.0, 'adhesion_frequency_2': 17.0}
        """
        band = [line for line in locked_lines if 1.0 <= line["frequency"] <= 100.0]
        torsional = [line["frequency"] for line in band if line.get("channel", "te") == "te"]
        if torsional:
            return {"adhesion_frequency": float(min(torsional))}
        if _has_te(observed):
            # the TE sees a torsional line far better than the housings: where it has none, none is read
            return {}
        distinct: list[float] = []
        for line in band:
            if all(abs(line["frequency"] - kept) > 1.0 for kept in distinct):
                distinct.append(float(line["frequency"]))
        return dict(zip(_hint_keys(), distinct))

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        return {self.strength: strength, "frequency": float(rng.uniform(6.0, 30.0)), "phase": phase}
