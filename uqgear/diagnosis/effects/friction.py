"""Tooth surface friction: a sliding force that reverses at the pitch point."""

from __future__ import annotations

from collections.abc import Mapping

from ...physics.design import Design
from ...physics.effects import Friction
from ..candidates import Candidate
from .base import EffectFamily


class FrictionFamily(EffectFamily):
    """Sliding friction on the tooth flanks (docs/model/unmodelled-effects.md section 6).

    One variant, its coefficient fitted from two starts; its response
    repeats every mesh period. Hints: none on any channel.
    """

    name = "friction"
    physics = Friction
    strength = "coefficient"
    ladder = (0.05, 0.08, 0.12)

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        fitted = (self.strength_parameter("coefficient", 0.03),)
        return [self.candidate("friction", (), fitted, self.grid(coefficient=(0.03, 0.1)), "mesh")]
