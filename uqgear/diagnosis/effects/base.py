"""What the diagnosis and the virtual rig need of an effect family, and the helpers its module builds it with.

An effect family (:class:`EffectFamily`) names its physics slot (the
:class:`~uqgear.physics.effects.Effect` subclass that writes its terms into
the model set-up), the screening variants a diagnosis fits (fixed choices,
fitted parameters with their bounds, start grids read off the rig's
signature, the period the response repeats over), the signature hints it
reads, the strength ladder and random draws a virtual-rig campaign of it
uses, and the hooks through which the rules ask about it: whether a fit
of it reads as a shaft run-out (:class:`RunOut`), which parameters a
change scoring tries in proportion to its strength, which sensor artefact
reads as it on one channel alone and what measurement would tell the two
apart.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...physics.design import Design
from ...physics.effects import Effect
from ..candidates import Candidate, ParameterSpec

#: Starting phases of a phase the amplitude features cannot see but a fit must place (a quarter turn
#: either side of zero: the cost is symmetric about the true phase, so two starts find its branch).
START_PHASES: tuple[float, float] = (0.5 * math.pi, 1.5 * math.pi)


@dataclass(frozen=True)
class RunOut:
    """How a family's fit reads as a shaft run-out, which the gears' own first-order pitch errors also make.

    A family with one is held to the rules on run-outs: its fitted run-out is
    checked against what the gears' stated classes make (the run-out check),
    the fit is measured with its modulation off (what pitch errors do not
    make), the mesh lines' sideband phases can name it on a shaft, and a gear
    whose first-order errors read large is reported as not told apart from it
    (docs/model/unmodelled-effects.md section 6.4).

    Attributes
    ----------
    amplitude : str
        The parameter holding the run-out, m.
    phase : str
        The parameter holding the run-out's phase, rad.
    shaft : str
        The choice naming the shaft (``pinion`` or ``gear``).
    modulation : str
        The parameter that pitch errors cannot make (a mesh-stiffness modulation); its lower bound is "absent".

    Examples
    --------
    >>> from uqgear.diagnosis.effects import effect_family
    >>> effect_family("eccentricity").run_out
    RunOut(amplitude='amplitude', phase='phase', shaft='shaft', modulation='kappa')
    >>> effect_family("friction").run_out is None
    True
    """

    amplitude: str
    phase: str
    shaft: str
    modulation: str


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
        the mesh, and evidence on one channel alone is that sensor's own;
        :mod:`uqgear.diagnosis.verdict.cross_channel`).
    run_out : RunOut or None
        How a fit of it reads as a shaft run-out the gears' pitch errors also make (default None: it
        does not, and the rules on run-outs leave it alone).
    proportional : mapping of str to float
        Parameters the change scoring also tries in proportion to the strength along its ladder, with
        their factor per unit of strength (default none: each parameter at its start values only).
    look_alike, separated_by : methods
        The sensor artefact that reads as it on one channel alone, and the measurements that would tell
        the two apart (defaults: none known; records at a higher load and speed).
    """

    name: ClassVar[str]
    physics: ClassVar[type[Effect]]
    strength: ClassVar[str]
    ladder: ClassVar[tuple[float, float, float]]
    plan: ClassVar[str] = "service"
    one_channel: ClassVar[str] = ""
    run_out: ClassVar[RunOut | None] = None
    proportional: ClassVar[Mapping[str, float]] = {}

    def variants(self, design: Design, hints: Mapping[str, float]) -> list[Candidate]:
        """The screening variants of this family for a design, their start grids from the signature ``hints``."""
        raise NotImplementedError

    def hints(self, observed: Mapping[str, np.ndarray], locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
        """Starting values read off the rig's signature (none by default).

        ``observed`` maps ``CHANNEL:FEATURE`` names to the rig's values over
        runs (the compared features) of every channel the campaign has;
        ``locked_lines`` are the lines at a fixed frequency of every channel,
        each naming its ``channel`` (a line naming none is the TE's): the
        TE's frequency-locked lines first, then the accelerometers' steady
        modulations of the mesh line, strongest first
        (:func:`uqgear.diagnosis.signatures.every_channel_locked_lines`). A
        family that reads hints states in its docstring which channel it
        prefers; a campaign may lack the TE (no encoders).
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

    def look_alike(self, channel: str) -> str:
        """A sensor artefact that reads as this effect on ``channel`` alone, in words (default ``""``: none known).

        The verdict names it beside the effect where the other channels
        cannot see the effect as fitted (:mod:`uqgear.diagnosis.verdict.cross_channel`);
        without one it names the channel's own artefacts in general.
        """
        return ""

    def separated_by(self) -> tuple[str, ...]:
        """Measurements that would show this effect on the channels that cannot see it yet, as sentences.

        The verdict states them where the effect and one channel's own
        artefact explain the data alike (:mod:`uqgear.diagnosis.verdict.cross_channel`).

        Examples
        --------
        >>> from uqgear.diagnosis.effects import hooks_of
        >>> hooks_of("friction").separated_by()
        ('records at a higher load and speed, where a stronger friction would reach the other channels too',)
        """
        return (f"records at a higher load and speed, where a stronger {self.name} would reach the other channels too",)

    def run_out_shaft(self, values: Mapping[str, Any]) -> str | None:
        """The shaft whose run-out a fit with ``values`` (its choices and parameters) reads, or None (no run-out).

        Examples
        --------
        >>> from uqgear.diagnosis.effects import effect_family
        >>> effect_family("eccentricity").run_out_shaft({"shaft": "gear", "amplitude": 5e-6})
        'gear'
        >>> effect_family("tooth_damage").run_out_shaft({"gear": "pinion"}) is None
        True
        """
        return None if self.run_out is None else str(values.get(self.run_out.shaft))

    def open_choices(self, values: Mapping[str, Any], design: Design) -> dict[str, tuple[float, ...]]:
        """Parameters a fit with ``values`` leaves open, with the values each can take (default: none).

        A prediction with the named effect draws each of them at random
        (:class:`~uqgear.physics.effect_draws.UncertainEffect`'s ``choices``)
        instead of holding the placeholder the fit used.

        Examples
        --------
        >>> import uqgear
        >>> from uqgear.diagnosis.effects import hooks_of
        >>> design = uqgear.load_design("locomotive")
        >>> hooks_of("eccentricity").open_choices({"shaft": "pinion"}, design)
        {}
        >>> len(hooks_of("tooth_damage").open_choices({"gear": "pinion"}, design)["tooth"])
        21
        """
        return {}

    def parameter_name(self, parameter: str) -> str:
        """A parameter's name as fits and starts key it, ``FAMILY.PARAMETER``.

        Examples
        --------
        >>> from uqgear.diagnosis.effects import effect_family
        >>> family = effect_family("eccentricity")
        >>> family.parameter_name(family.run_out.modulation)
        'eccentricity.kappa'
        """
        return f"{self.name}.{parameter}"

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


__all__ = ["EffectFamily", "RunOut", "START_PHASES"]
