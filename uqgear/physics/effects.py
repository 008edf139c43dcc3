"""Unmodelled physical effects as model extensions (docs/model/unmodelled-effects.md section 6).

Each effect is a small object with validated parameters (settings in
``__init__``) and an ``apply(setup)`` that writes its terms into the slots
of a :class:`~uqgear.physics.model.ModelSetup`; the right-hand side and integrators
are shared, never forked. ``PARAMETERS`` gives each parameter's default,
bounds, unit and whether calibration may vary it.

Effects of the library: ``eccentricity``, ``tooth_damage``, ``friction``,
``torque_ripple``, ``adhesion_oscillation``, ``bearing_clearance``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from ..common.errors import UqgearError


class EffectError(UqgearError):
    """An effect name or parameter is not valid."""


@dataclass(frozen=True)
class EffectParameter:
    """Definition of one effect parameter."""

    default: float
    lower: float
    upper: float
    unit: str
    description: str
    calibrate: bool = True


class Effect:
    """Base class: validated parameters plus an ``apply`` writing kernel slots."""

    name: ClassVar[str] = ""
    PARAMETERS: ClassVar[dict[str, EffectParameter]] = {}
    CHOICES: ClassVar[dict[str, tuple[str, ...]]] = {}
    #: Whether the model under this effect still repeats every mesh period (Newton shooting and the
    #: calibration's harmonic kernel apply); an effect with a slower or unrelated period does not.
    mesh_periodic: ClassVar[bool] = False

    @property
    def repeat_shaft(self) -> str | None:
        """The shaft (``pinion`` or ``gear``) over whose revolution the effect repeats, or None.

        None where it repeats every mesh period or is locked to no shaft (a
        frequency in Hz). An average over a window that is not a whole number
        of that shaft's revolutions depends on where in the revolution the
        window lies.

        Examples
        --------
        >>> import uqgear
        >>> uqgear.make_effect("eccentricity", {"shaft": "gear"}).repeat_shaft
        'gear'
        >>> uqgear.make_effect("friction").repeat_shaft is None
        True
        """
        return None

    def __init__(self, values: Mapping[str, Any] | None = None) -> None:
        values = dict(values or {})
        unknown = sorted(set(values) - set(self.PARAMETERS) - set(self.CHOICES))
        if unknown:
            raise EffectError(
                f"{self.name}.{unknown[0]}: unknown parameter; expected one of "
                f"{', '.join(list(self.PARAMETERS) + list(self.CHOICES))}"
            )
        self.values: dict[str, Any] = {}
        for key, options in self.CHOICES.items():
            choice = values.get(key, options[0])
            if choice not in options:
                raise EffectError(f"{self.name}.{key}: expected one of {', '.join(options)}; got {choice!r}")
            self.values[key] = choice
        for key, spec in self.PARAMETERS.items():
            raw = values.get(key, spec.default)
            try:
                value = float(raw)
            except (TypeError, ValueError):
                raise EffectError(
                    f"{self.name}.{key}: expected a number in [{spec.lower:g}, {spec.upper:g}] {spec.unit}; got {raw!r}"
                ) from None
            if not math.isfinite(value) or not spec.lower <= value <= spec.upper:
                raise EffectError(
                    f"{self.name}.{key}: expected a value in [{spec.lower:g}, {spec.upper:g}] {spec.unit}; got {raw!r}"
                )
            self.values[key] = value

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({inner})"

    def with_values(self, **changes: Any) -> Effect:
        """A copy with some parameters changed (validated)."""
        return type(self)({**self.values, **changes})

    def turned(self, design: Any, pinion_teeth: int, seconds: float) -> Effect:
        """The same effect seen by a run whose shafts have turned on by ``pinion_teeth`` teeth of the pinion
        (and as many of the gear) and whose clock has run on by ``seconds``.

        A run that starts there gives the forcing the original run gives from that point on: a model of a
        stretch of a longer record starts where that stretch lies. Whole teeth keep the mesh phase. The
        default, for an effect locked to no shaft or clock (friction, a clearance), is the effect itself.

        Examples
        --------
        >>> import uqgear
        >>> design = uqgear.load_design("locomotive")
        >>> uqgear.make_effect("tooth_damage", {"gear": "gear", "tooth": 3}).turned(design, 5, 0.0)
        ToothDamage(gear='gear', tooth=99.0, depth=0.3)
        >>> uqgear.make_effect("friction").turned(design, 5, 1.0)
        Friction(coefficient=0.05)
        """
        return self

    def apply(self, setup) -> None:  # pragma: no cover - abstract
        raise NotImplementedError


def _wrapped(phase: float) -> float:
    """A phase in [-pi, pi), inside every effect's phase range."""
    return (phase + math.pi) % (2.0 * math.pi) - math.pi


class Eccentricity(Effect):
    """Shaft run-out: e_s sin(W_s t + phase) added to the STE, and mesh
    stiffness modulation k(t) (1 + kappa cos(W_s t + phase)), W_s the rotation
    rate of the eccentric shaft."""

    name = "eccentricity"
    CHOICES = {"shaft": ("pinion", "gear")}
    PARAMETERS = {
        "amplitude": EffectParameter(10e-6, 0.0, 2e-4, "m", "run-out amplitude e_s"),
        "phase": EffectParameter(0.0, -2 * math.pi, 2 * math.pi, "rad", "run-out phase"),
        "kappa": EffectParameter(0.0, 0.0, 0.5, "1", "relative mesh stiffness modulation"),
    }

    def apply(self, setup) -> None:
        rate = setup.pinion_rotation
        if self.values["shaft"] == "gear":
            rate *= setup.design.z1 / setup.design.z2
        setup.set_slot("ecc_amplitude", self.values["amplitude"])
        setup.set_slot("ecc_omega", rate)
        setup.set_slot("ecc_phase", self.values["phase"])
        setup.set_slot("ecc_kappa", self.values["kappa"])

    @property
    def repeat_shaft(self) -> str | None:
        return str(self.values["shaft"])

    def turned(self, design: Any, pinion_teeth: int, seconds: float) -> Effect:
        teeth = design.z1 if self.values["shaft"] == "pinion" else design.z2
        return self.with_values(phase=_wrapped(self.values["phase"] + 2.0 * math.pi * pinion_teeth / teeth))


class ToothDamage(Effect):
    """Local tooth damage: the single-pair stiffness of one tooth reduced by
    ``depth`` whenever that tooth is in mesh (once per revolution of its gear).
    Tooth numbers count from 0, tooth 0 being the one entering contact at t = 0."""

    name = "tooth_damage"
    CHOICES = {"gear": ("pinion", "gear")}
    PARAMETERS = {
        "tooth": EffectParameter(0.0, 0.0, 999.0, "1", "index of the damaged tooth", calibrate=False),
        "depth": EffectParameter(0.3, 0.0, 0.95, "1", "relative stiffness loss of that tooth's pair"),
    }

    def apply(self, setup) -> None:
        factors = setup.factor_pinion if self.values["gear"] == "pinion" else setup.factor_gear
        tooth = int(round(self.values["tooth"]))
        if tooth >= factors.size:
            raise EffectError(
                f"tooth_damage.tooth: expected 0..{factors.size - 1} for the {self.values['gear']}; got {tooth}"
            )
        factors[tooth] *= 1.0 - self.values["depth"]

    @property
    def repeat_shaft(self) -> str | None:
        return str(self.values["gear"])

    def turned(self, design: Any, pinion_teeth: int, seconds: float) -> Effect:
        # the tooth entering contact at the start is the one pinion_teeth teeth on
        teeth = design.z1 if self.values["gear"] == "pinion" else design.z2
        return self.with_values(tooth=float((int(round(self.values["tooth"])) - pinion_teeth) % teeth))


class Friction(Effect):
    """Tooth surface friction mu_f F_pair sign(sliding velocity), reversing at
    the pitch point, moment arms from the base-circle tangency points,
    entering the torsional equations only."""

    name = "friction"
    # it reverses at the pitch point once every mesh period
    mesh_periodic = True
    PARAMETERS = {"coefficient": EffectParameter(0.05, 0.0, 0.3, "1", "sliding friction coefficient mu_f")}

    def apply(self, setup) -> None:
        setup.set_slot("friction", self.values["coefficient"])


class TorqueRipple(Effect):
    """Traction motor torque ripple T1(t) = T1 (1 + r cos(6 p W1 t + phase));
    p from the design's ``motor_pole_pairs`` unless given."""

    name = "torque_ripple"
    PARAMETERS = {
        "amplitude": EffectParameter(0.05, 0.0, 0.5, "1", "relative ripple amplitude r"),
        "phase": EffectParameter(0.0, -2 * math.pi, 2 * math.pi, "rad", "ripple phase"),
        "pole_pairs": EffectParameter(
            0.0, 0.0, 24.0, "1", "motor pole pairs p (0: the design's motor_pole_pairs)", calibrate=False
        ),
    }

    def apply(self, setup) -> None:
        pole_pairs = int(round(self.values["pole_pairs"])) or setup.design.motor_pole_pairs
        if not pole_pairs:
            raise EffectError("torque_ripple.pole_pairs: the design has no motor_pole_pairs; expected pole_pairs >= 1")
        setup.set_slot("ripple_amplitude", self.values["amplitude"])
        setup.set_slot("ripple_omega", 6.0 * pole_pairs * setup.pinion_rotation)
        setup.set_slot("ripple_phase", self.values["phase"])

    @property
    def repeat_shaft(self) -> str | None:
        return "pinion"  # 6 p cycles per pinion revolution

    def turned(self, design: Any, pinion_teeth: int, seconds: float) -> Effect:
        pole_pairs = int(round(self.values["pole_pairs"])) or int(design.motor_pole_pairs or 0)
        turn = 6.0 * pole_pairs * 2.0 * math.pi * pinion_teeth / design.z1
        return self.with_values(phase=_wrapped(self.values["phase"] + turn))


class AdhesionOscillation(Effect):
    """Wheel/rail stick-slip: T2(t) = T2 (1 + a sin(2 pi f_s t + phase))."""

    name = "adhesion_oscillation"
    PARAMETERS = {
        "amplitude": EffectParameter(0.05, 0.0, 0.5, "1", "relative amplitude dT2/T2"),
        "frequency": EffectParameter(12.0, 0.5, 200.0, "Hz", "stick-slip frequency f_s"),
        "phase": EffectParameter(0.0, -2 * math.pi, 2 * math.pi, "rad", "phase"),
    }

    def turned(self, design: Any, pinion_teeth: int, seconds: float) -> Effect:
        turn = 2.0 * math.pi * self.values["frequency"] * seconds
        return self.with_values(phase=_wrapped(self.values["phase"] + turn))

    def apply(self, setup) -> None:
        setup.set_slot("adhesion_amplitude", self.values["amplitude"] * setup.slot("T2"))
        setup.set_slot("adhesion_omega", 2.0 * math.pi * self.values["frequency"])
        setup.set_slot("adhesion_phase", self.values["phase"])


class BearingClearance(Effect):
    """Radial bearing clearance: a dead zone of half-width c in the bearing force."""

    name = "bearing_clearance"
    # a state nonlinearity: it brings no period of its own
    mesh_periodic = True
    CHOICES = {"bearing": ("pinion", "gear", "both")}
    PARAMETERS = {"clearance": EffectParameter(10e-6, 0.0, 5e-4, "m", "half clearance c")}

    def apply(self, setup) -> None:
        if self.values["bearing"] in ("pinion", "both"):
            setup.set_slot("clearance1", self.values["clearance"])
        if self.values["bearing"] in ("gear", "both"):
            setup.set_slot("clearance2", self.values["clearance"])


#: The effect library by name.
EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls for cls in (Eccentricity, ToothDamage, Friction, TorqueRipple, AdhesionOscillation, BearingClearance)
}

#: The library's effects under which the model still repeats every mesh period (their ``mesh_periodic``),
#: in library order: friction reverses at the pitch point every mesh period; a bearing clearance is a state
#: nonlinearity.
MESH_PERIODIC_EFFECTS: tuple[str, ...] = tuple(name for name, cls in EFFECTS.items() if cls.mesh_periodic)


def make_effect(name: str, values: Mapping[str, Any] | None = None) -> Effect:
    """Build an effect of the library by name.

    Parameters
    ----------
    name : str
        One of :data:`EFFECTS` (``"eccentricity"``, ``"tooth_damage"``, ...).
    values : mapping, optional
        Parameters and choices of the effect; the defaults for the others.

    Returns
    -------
    Effect

    Raises
    ------
    EffectError
        An unknown effect or parameter, or a value outside its bounds.

    Examples
    --------
    A pinion tooth with 30 % stiffness loss widens the DTE range once per
    pinion revolution (42 kept periods: two revolutions of the 21 teeth):

    >>> import uqgear
    >>> damage = uqgear.make_effect("tooth_damage", {"depth": 0.3})
    >>> damage
    ToothDamage(gear='pinion', tooth=0.0, depth=0.3)
    >>> design = uqgear.load_design("locomotive")
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [2000.0]})
    >>> healthy = uqgear.simulate_batch(design, samples, n_periods=60, keep_periods=42)
    >>> damaged = uqgear.simulate_batch(design, samples, n_periods=60, keep_periods=42, effects=[damage])
    >>> print(f"DTE peak to peak {float(healthy['dte_peak_to_peak'][0]) * 1e6:.1f} um healthy, "
    ...       f"{float(damaged['dte_peak_to_peak'][0]) * 1e6:.1f} um damaged")
    DTE peak to peak 33.3 um healthy, 54.1 um damaged
    >>> try:
    ...     uqgear.make_effect("eccentricity", {"amplitude": -1e-5})
    ... except uqgear.UqgearError as error:
    ...     print(error)
    eccentricity.amplitude: expected a value in [0, 0.0002] m; got -1e-05
    """
    if name not in EFFECTS:
        raise EffectError(f"effect {name!r}: unknown; expected one of {', '.join(EFFECTS)}")
    return EFFECTS[name](values)


def parse_effect(text: str) -> Effect:
    """Parse ``NAME:param=value,param=value`` (the command-line form)."""
    name, _, rest = text.partition(":")
    values: dict[str, Any] = {}
    for item in filter(None, rest.split(",")):
        key, sep, raw = item.partition("=")
        if not sep:
            raise EffectError(f"effect {text!r}: expected NAME:param=value,...; got {item!r}")
        values[key.strip()] = raw.strip()
    return make_effect(name.strip(), values)


__all__ = [
    "Effect",
    "EffectParameter",
    "EffectError",
    "EFFECTS",
    "MESH_PERIODIC_EFFECTS",
    "make_effect",
    "parse_effect",
    "Eccentricity",
    "ToothDamage",
    "Friction",
    "TorqueRipple",
    "AdhesionOscillation",
    "BearingClearance",
]
