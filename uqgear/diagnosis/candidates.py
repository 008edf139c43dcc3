"""The fitted parameters: the nominal model's, with priors from the design, and each candidate effect's."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..physics.design import Design, design_key_bounds
from ..physics.effects import EFFECTS, Effect, make_effect
from .errors import DiagnosisError
from .simulation import _MAX_STIFFNESS_SCALE, PERIODICITIES


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
        ParameterSpec("mesh_stiffness_scale", True, 1.0, 0.15, 0.6, _MAX_STIFFNESS_SCALE, True),
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
    """

    effect: str
    label: str
    choices: tuple[tuple[str, object], ...]
    fitted: tuple[ParameterSpec, ...]
    starts: tuple[dict[str, float], ...]
    periodicity: str

    def make(self, values: Mapping[str, float]) -> Effect:
        """The effect with fitted values ``{EFFECT.PARAM: value}`` and the fixed choices."""
        settings: dict[str, object] = dict(self.choices)
        settings.update({spec.name.split(".", 1)[1]: values[spec.name] for spec in self.fitted})
        return make_effect(self.effect, settings)


def _effect_spec(effect: str, parameter: str, unit: float, lower: float | None = None,
                 upper: float | None = None) -> ParameterSpec:
    definition = EFFECTS[effect].PARAMETERS[parameter]
    # the search range never reaches past what the effect itself accepts
    low = definition.lower if lower is None else max(lower, definition.lower)
    high = definition.upper if upper is None else min(upper, definition.upper)
    return ParameterSpec(f"{effect}.{parameter}", False, 0.0, unit, low, high, False)


def _strength_spec(effect: str, parameter: str, centre: float, upper: float | None = None) -> ParameterSpec:
    """An effect's strength (amplitude, depth, coefficient) on a log scale.

    Differences and steps are then relative: an effect near the detection
    limit is fitted as well as a strong one (a fixed step would dwarf a
    weak amplitude). The lower bound, a millionth of ``centre``, stands for
    "absent".
    """
    definition = EFFECTS[effect].PARAMETERS[parameter]
    high = definition.upper if upper is None else min(upper, definition.upper)
    return ParameterSpec(f"{effect}.{parameter}", True, centre, 1.0, max(centre * 1e-6, definition.lower), high,
                         False)


def _grid(**axes: Sequence[float]) -> tuple[dict[str, float], ...]:
    keys = list(axes)
    points: list[dict[str, float]] = [{}]
    for key in keys:
        points = [{**point, key: float(value)} for point in points for value in axes[key]]
    return tuple(points)


def candidates_for(effect: str, design: Design, *, hints: Mapping[str, float] | None = None) -> list[Candidate]:
    """The candidate variants of one library effect for a design.

    Tooth numbers and phases relative to the record start do not change
    amplitude spectra, so tooth 0 and the adhesion phase 0 are fixed; the
    eccentricity and ripple phases (relative to the mesh) are fitted.

    Parameters
    ----------
    effect : str
        Library name.
    design : Design
    hints : mapping, optional
        Starting values read off the data's signature:
        ``eccentricity_pinion`` and ``eccentricity_gear`` (run-out amplitude,
        m, from the 1x shaft line of the transmission error) and
        ``adhesion_frequency`` (Hz, a low-frequency line common to the runs).
    """
    hints = dict(hints or {})
    if effect not in EFFECTS:
        raise DiagnosisError(f"effects: {effect!r} is not a library effect; expected one of {', '.join(EFFECTS)}")
    two_pi = 2.0 * math.pi
    phases = (0.5 * math.pi, 1.5 * math.pi)
    if effect == "eccentricity":
        fitted = (_strength_spec(effect, "amplitude", 1e-6, upper=1e-4),
                  _effect_spec(effect, "phase", 1.0, 0.0, two_pi), _strength_spec(effect, "kappa", 1e-3, upper=0.3))
        variants = []
        for shaft in ("pinion", "gear"):
            amplitude = float(np.clip(hints.get(f"eccentricity_{shaft}", 5e-6), 1e-9, 5e-5))
            # no modulation, or as much as the public campaign per metre of run-out (0.03 at 12 um)
            starts = _grid(**{"eccentricity.amplitude": (amplitude,), "eccentricity.phase": phases,
                              "eccentricity.kappa": (1e-9, min(2500.0 * amplitude, 0.1))})
            variants.append(Candidate(effect, f"eccentricity[{shaft}]", (("shaft", shaft),), fitted, starts,
                                      "pinion" if shaft == "pinion" else "gear"))
        return variants
    if effect == "tooth_damage":
        fitted = (_strength_spec(effect, "depth", 0.05, upper=0.9),)
        starts = _grid(**{"tooth_damage.depth": (0.005, 0.05, 0.4)})
        return [Candidate(effect, f"tooth_damage[{gear}]", (("gear", gear), ("tooth", 0.0)), fitted, starts,
                          "pinion" if gear == "pinion" else "gear") for gear in ("pinion", "gear")]
    if effect == "friction":
        fitted = (_strength_spec(effect, "coefficient", 0.03),)
        return [Candidate(effect, "friction", (), fitted, _grid(**{"friction.coefficient": (0.03, 0.1)}),
                          "mesh")]
    if effect == "torque_ripple":
        if design.motor_pole_pairs is None:
            return []
        fitted = (_strength_spec(effect, "amplitude", 0.01, upper=0.3), _effect_spec(effect, "phase", 1.0, 0.0, two_pi))
        starts = _grid(**{"torque_ripple.amplitude": (0.003, 0.05), "torque_ripple.phase": phases})
        return [Candidate(effect, "torque_ripple", (), fitted, starts, "pinion")]
    if effect == "adhesion_oscillation":
        fitted = (_strength_spec(effect, "amplitude", 0.01, upper=0.3),
                  _effect_spec(effect, "frequency", 2.0, 1.0, 100.0))
        frequencies = (hints["adhesion_frequency"],) if hints.get("adhesion_frequency") else (8.0, 30.0)
        starts = _grid(**{"adhesion_oscillation.amplitude": (0.003, 0.03), "adhesion_oscillation.frequency": frequencies})
        return [Candidate(effect, "adhesion_oscillation", (("phase", 0.0),), fitted, starts, "free")]
    fitted = (_strength_spec(effect, "clearance", 2e-5),)
    starts = _grid(**{"bearing_clearance.clearance": (1e-6, 1e-5, 1e-4)})
    return [Candidate(effect, f"bearing_clearance[{bearing}]", (("bearing", bearing),), fitted, starts, "mesh")
            for bearing in ("pinion", "gear", "both")]



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
            raise DiagnosisError(f"effects: {candidate.effect!r} appears twice in one model ({seen[candidate.effect]} "
                                 f"and {candidate.label}); each effect enters a model at most once")
        seen[candidate.effect] = candidate.label
    return chosen
