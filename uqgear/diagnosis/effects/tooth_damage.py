"""Local tooth damage (a root crack, a spall): one tooth's pair stiffness reduced once per revolution."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ...physics.design import Design
from ...physics.effects import ToothDamage
from ..candidates import Candidate
from .base import EffectFamily


class ToothDamageFamily(EffectFamily):
    """A damaged tooth of the pinion or the gear (docs/model/unmodelled-effects.md section 6).

    Variants: one per gear, its depth fitted from a start grid spanning
    weak to strong damage. Which tooth does not change an amplitude
    spectrum, so tooth 0 stands for any in the fits, and a prediction draws
    the tooth among the gear's teeth (:meth:`open_choices`). Its response repeats over its
    gear's revolution. Hints: none on any channel (the start grid already
    spans weak to strong damage).
    """

    name = "tooth_damage"
    physics = ToothDamage
    strength = "depth"
    ladder = (0.005, 0.03, 0.35)

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        fitted = (self.strength_parameter("depth", 0.05, upper=0.9),)
        starts = self.grid(depth=(0.005, 0.05, 0.4))
        return [
            self.candidate(f"tooth_damage[{gear}]", (("gear", gear), ("tooth", 0.0)), fitted, starts, gear)
            for gear in ("pinion", "gear")
        ]

    def open_choices(self, values: Mapping[str, Any], design: Design) -> dict[str, tuple[float, ...]]:
        teeth = design.z1 if values.get("gear", "pinion") == "pinion" else design.z2
        return {"tooth": tuple(float(tooth) for tooth in range(int(teeth)))}

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        return {
            self.strength: strength,
            "gear": ("pinion", "gear")[int(rng.integers(2))],
            "tooth": float(rng.integers(0, 17)),
        }
