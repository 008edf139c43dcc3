"""The fitted parameters: the nominal model's, with priors from the design, and the candidate effects' variants.

The variants of each effect family come from its plug-in
(:mod:`uqgear.diagnosis.effects`); here are the parameter transform, the
nominal model's priors and what a model with several effects repeats over.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from ..physics.design import Design, design_key_bounds
from ..physics.effects import Effect
from .errors import DiagnosisError
from .simulation import MAX_STIFFNESS_SCALE, PERIODICITIES


@dataclass(frozen=True)
class ParameterSpec:
    """A fitted parameter: transform, prior, bounds and the optimiser's unit.

    The optimiser works with ``v = (g(x) - g(centre)) / unit`` where ``g`` is
    the identity or the logarithm; with a prior (normal in g) the unit is its
    standard deviation, so the prior's residual is ``v`` itself.

    Natural values always lie in ``[lower, upper]``: :meth:`from_optimiser`
    clips, because the round trip through the transform is not exact
    (``0.03 exp(log(10))`` is ``0.30000000000000004``) and the values go to
    constructors that validate them as strictly as a user's input (an
    effect's parameters, the design keys).
    """

    name: str
    log: bool
    centre: float
    unit: float
    lower: float
    upper: float
    prior: bool

    def to_optimiser(self, value: float) -> float:
        value = min(max(value, self.lower), self.upper)
        g = math.log(value / self.centre) if self.log else value - self.centre
        return g / self.unit

    def from_optimiser(self, v: float) -> float:
        g = v * self.unit
        value = self.centre * math.exp(g) if self.log else self.centre + g
        # an optimiser, a finite-difference step or a Newton step may sit on (or a rounding past)
        # a bound: the natural value is held inside, never handed on one ulp outside
        return min(max(value, self.lower), self.upper)

    def bounds(self) -> tuple[float, float]:
        return self.to_optimiser(self.lower), self.to_optimiser(self.upper)


# Floors of the log-scale centres: a design may give an undamped mesh or no STE, but a log
# transform needs a positive centre (the fit then starts at the floor).
_ZETA_MESH_FLOOR = 1e-3
_STE_FLOOR = 1e-7


def _design_spec(name: str, centre: float, unit: float, lower: float, upper: float) -> ParameterSpec:
    """A nominal parameter that is a design key, its bounds inside what the design validation accepts.

    Without the intersection a design near the edge of a key's plausible
    range (k1 = 1e13 N/m, an STE of 0.4 mm) would let the fit propose a value
    the design refuses, minutes into the work.
    """
    valid_lower, valid_upper = design_key_bounds(name)
    lower, upper = max(lower, valid_lower), min(upper, valid_upper)
    centre = min(max(centre, lower), upper)
    return ParameterSpec(name, True, centre, unit, lower, upper, True)


def nominal_parameters(design: Design) -> list[ParameterSpec]:
    """The nominal model's calibration parameters with priors from the design.

    Mesh stiffness scale (log-normal, 15 %), mesh damping ratio (50 %), STE
    amplitude (40 %), bearing stiffnesses (25 %), bounded at about three
    standard deviations and inside the design keys' plausible ranges.
    """
    zeta = max(design.zeta_mesh, _ZETA_MESH_FLOOR)
    ste = max(design.ste_amplitude, _STE_FLOOR)
    return [
        ParameterSpec("mesh_stiffness_scale", True, 1.0, 0.15, 0.6, MAX_STIFFNESS_SCALE, True),
        _design_spec("zeta_mesh", zeta, 0.5, zeta / 5.0, min(zeta * 5.0, 0.9)),
        _design_spec("ste_amplitude", ste, 0.4, ste / 3.0, ste * 3.0),
        _design_spec("k1", design.k1, 0.25, design.k1 / 2.0, design.k1 * 2.0),
        _design_spec("k2", design.k2, 0.25, design.k2 / 2.0, design.k2 * 2.0),
    ]


@dataclass(frozen=True)
class Candidate:
    """One way of adding a library effect: fixed choices, fitted parameters, periodicity.

    Attributes
    ----------
    effect : str
        Library name.
    label : str
        Unique label (effect and choices), e.g. ``eccentricity[gear]``.
    choices : tuple of (str, object)
        Fixed settings (shaft, gear, bearing, tooth, phases that amplitude
        features cannot see).
    fitted : tuple of ParameterSpec
        Effect parameters fitted (named ``EFFECT.PARAM``).
    starts : tuple of dict
        Starting values tried before the fit (signature grid).
    periodicity : str
        One of :data:`PERIODICITIES`.
    physics : type of Effect
        The model extension that simulates it (its family's physics slot).
    """

    effect: str
    label: str
    choices: tuple[tuple[str, object], ...]
    fitted: tuple[ParameterSpec, ...]
    starts: tuple[dict[str, float], ...]
    periodicity: str
    physics: type[Effect] = field(default=Effect, compare=False, repr=False)

    def make(self, values: Mapping[str, float]) -> Effect:
        """The effect with fitted values ``{EFFECT.PARAM: value}`` and the fixed choices."""
        settings: dict[str, object] = dict(self.choices)
        settings.update({spec.name.split(".", 1)[1]: values[spec.name] for spec in self.fitted})
        return self.physics(settings)


def combined_periodicity(periodicities: Sequence[str], design: Design | None = None) -> str:
    """The period over which the steady response of several effects together repeats.

    The coarser common period of the effects': a mesh-periodic effect
    (friction, a clearance) repeats within any shaft revolution, so it adds
    nothing to a pinion's or a gear's period; a pinion and a gear effect
    together repeat only over the hunting-tooth period (lcm(z1, z2) mesh
    periods), which is not one of :data:`~.simulation.PERIODICITIES`: the
    response is then simulated over the whole record (``free``), unless z1
    divides z2, when one gear revolution is a whole number of pinion
    revolutions. Anything with a frequency of its own (``free``) stays free.

    Parameters
    ----------
    periodicities : sequence of str
        One of :data:`~.simulation.PERIODICITIES` per effect (none: the nominal model, ``mesh``).
    design : Design, optional
        For the tooth numbers (without it a pinion and a gear effect give ``free``).

    Raises
    ------
    DiagnosisError
        An unknown periodicity.
    """
    kinds = set()
    for periodicity in periodicities:
        if periodicity not in PERIODICITIES:
            raise DiagnosisError(f"periodicity: expected one of {', '.join(PERIODICITIES)}; got {periodicity!r}")
        if periodicity != "mesh":
            kinds.add(periodicity)
    if not kinds:
        return "mesh"
    if len(kinds) == 1:
        return kinds.pop()
    if kinds == {"pinion", "gear"} and design is not None and design.z2 % design.z1 == 0:
        return "gear"
    return "free"


def check_combination(candidates: Sequence[Candidate]) -> tuple[Candidate, ...]:
    """The candidates of one model, checked: each effect at most once.

    Two variants of one effect (eccentricity of the pinion and of the gear)
    would share their fitted parameters' names, and an effect named twice
    would only soak up noise: forward selection never proposes it.

    Raises
    ------
    DiagnosisError
        An effect that appears twice, named with its labels.
    """
    chosen = tuple(candidates)
    seen: dict[str, str] = {}
    for candidate in chosen:
        if candidate.effect in seen:
            raise DiagnosisError(
                f"effects: {candidate.effect!r} appears twice in one model ({seen[candidate.effect]} "
                f"and {candidate.label}); each effect enters a model at most once"
            )
        seen[candidate.effect] = candidate.label
    return chosen
