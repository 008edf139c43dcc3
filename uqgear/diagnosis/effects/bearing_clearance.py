"""Bearing clearance: a dead zone in the bearing force, felt only where a bearing unloads."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ...physics.design import Design
from ...physics.effects import BearingClearance
from ..candidates import Candidate
from .base import EffectFamily


class BearingClearanceFamily(EffectFamily):
    """Radial clearance in the pinion bearing, the gear bearing or both (docs/model/unmodelled-effects.md section 6).

    Variants: one per bearing choice, the half clearance fitted from a
    start grid over three decades. A clearance has no signature while the
    bearings stay loaded (the dead zone is never entered), so its
    virtual-rig campaigns follow the light-load bearing check plan, where a
    bearing unloads. Its response repeats every mesh period. Hints: none
    on any channel.
    """

    name = "bearing_clearance"
    physics = BearingClearance
    strength = "clearance"
    # the signature saturates once the clearance exceeds the excursion past unloading (a few um)
    ladder = (5e-7, 3e-6, 5e-5)
    plan = "bearing_check"

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        fitted = (self.strength_parameter("clearance", 2e-5),)
        starts = self.grid(clearance=(1e-6, 1e-5, 1e-4))
        return [
            self.candidate(f"bearing_clearance[{bearing}]", (("bearing", bearing),), fitted, starts, "mesh")
            for bearing in ("pinion", "gear", "both")
        ]

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        return {self.strength: strength, "bearing": ("pinion", "gear", "both")[int(rng.integers(3))]}
