"""What the diagnosis and the virtual rig need of an effect family, and the helpers its module builds it with.

An effect family (:class:`EffectFamily`) names its physics slot (the
:class:`~uqgear.physics.effects.Effect` subclass that writes its terms into
the model set-up), the screening variants a diagnosis fits (fixed choices,
fitted parameters with their bounds, start grids read off the rig's
signature, the period the response repeats over), the signature hints it
reads and the strength ladder and random draws a virtual-rig campaign of
it uses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from ...physics.design import Design
from ...physics.effects import Effect
from ..candidates import Candidate, ParameterSpec

#: Starting phases of a phase the amplitude features cannot see but a fit must place (a quarter turn
#: either side of zero: the cost is symmetric about the true phase, so two starts find its branch).
START_PHASES: tuple[float, float] = (0.5 * math.pi, 1.5 * math.pi)


class EffectFamily:
    """One effect family of the library, as the diagnosis screens and fits it and the virtual rig makes it.

    Subclasses set the class attributes and :meth:`variants`; the rest has
    defaults. Register an instance with :func:`uqgear.diagnosis.effects.register_effect`.

    Attributes
    ----------
    name : str
        Library name (the verdict names it).
    physics : type of Effect
        Its physics slot: the model extension every simulation of it switches on.
    strength : str
        The parameter that sets its size.
    ladder : (float, float, float)
        Weak (near detectability), medium and strong values of ``strength`` for virtual-rig campaigns.
    plan : str
        The test plan where it shows (``service``, or ``bearing_check`` where a bearing must unload).
    one_channel : str
        Why its signature may lie on one channel alone (empty: it shows on every channel that sees
        the mesh, and evidence on one channel alone is that sensor's own; :mod:`uqgear.diagnosis.consistency`).
    """

    name: ClassVar[str]
    physics: ClassVar[type[Effect]]
    strength: ClassVar[str]
    ladder: ClassVar[tuple[float, float, float]]
    plan: ClassVar[str] = "service"
    one_channel: ClassVar[str] = ""

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        """The screening variants of this family for a design, their start grids from the signature ``hints``."""
        raise NotImplementedError

    def hints(self, observed: Mapping[str, np.ndarray], locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
        """Starting values read off the rig's signature (none by default).

        ``observed`` maps ``CHANNEL:FEATURE`` names to the rig's values over
        runs (the compared features); ``locked_lines`` are the transmission
        error's frequency-locked lines.
        """
        return {}

    def campaign_values(self, strength: float, phase: float, rng: np.random.Generator) -> dict[str, object]:
        """The effect's values in a virtual-rig campaign at ``strength``: its other parameters drawn from ``rng``.

        ``phase`` is drawn for every family before this is called (uniform in [0, 2 pi)).
        """
        return {self.strength: strength}

    def make(self, values: Mapping[str, Any] | None = None) -> Effect:
        """The physics effect with ``values`` (validated by it)."""
        return self.physics(values)

    # ---- helpers for the variants

    def candidate(
        self,
        label: str,
        choices: Sequence[tuple[str, object]],
        fitted: Sequence[ParameterSpec],
        starts: Sequence[dict[str, float]],
        periodicity: str,
    ) -> Candidate:
        """One screening variant of this family."""
        return Candidate(self.name, label, tuple(choices), tuple(fitted), tuple(starts), periodicity, self.physics)

    def parameter(
        self, parameter: str, unit: float, lower: float | None = None, upper: float | None = None
    ) -> ParameterSpec:
        """A fitted parameter on a linear scale (a phase, a frequency), inside what the effect accepts."""
        definition = self.physics.PARAMETERS[parameter]
        # the search range never reaches past what the effect itself accepts
        low = definition.lower if lower is None else max(lower, definition.lower)
        high = definition.upper if upper is None else min(upper, definition.upper)
        return ParameterSpec(f"{self.name}.{parameter}", False, 0.0, unit, low, high, False)

    def strength_parameter(self, parameter: str, centre: float, upper: float | None = None) -> ParameterSpec:
        """The effect's strength (amplitude, depth, coefficient) on a log scale.

        Differences and steps are then relative: an effect near the
        detection limit is fitted as well as a strong one (a fixed step
        would dwarf a weak amplitude). The lower bound, a millionth of
        ``centre``, stands for "absent".
        """
        definition = self.physics.PARAMETERS[parameter]
        high = definition.upper if upper is None else min(upper, definition.upper)
        return ParameterSpec(
            f"{self.name}.{parameter}", True, centre, 1.0, max(centre * 1e-6, definition.lower), high, False
        )

    def grid(self, **axes: Sequence[float]) -> tuple[dict[str, float], ...]:
        """Every combination of the start values, keyed ``FAMILY.PARAMETER``."""
        points: list[dict[str, float]] = [{}]
        for key, values in axes.items():
            points = [{**point, f"{self.name}.{key}": float(value)} for point in points for value in values]
        return tuple(points)


__all__ = ["EffectFamily", "START_PHASES"]
