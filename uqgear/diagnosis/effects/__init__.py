"""The effects a diagnosis can name, as plug-ins: one module per effect family and a registry built from them.

Each family (:class:`~.base.EffectFamily`) holds what the diagnosis and the
virtual rig need of it: its physics slot, its fitted parameters with their
bounds, its start grid and the signature hints it reads, its screening
variants, its strength ladder for virtual-rig campaigns, and the hooks the
rules ask instead of naming an effect (``run_out``: whether its fits read as
a shaft run-out; ``proportional``: parameters a change scoring tries in
proportion to its strength; ``look_alike`` and ``separated_by``: the sensor
artefact that reads as it on one channel alone and the measurements that
would tell the two apart), whose defaults suit most families. Adding an effect
takes a physics :class:`~uqgear.physics.effects.Effect` subclass, a family
module and one line in :data:`~.registry.LIBRARY` (or :func:`register_effect`
at run time).

Examples
--------
>>> from uqgear.diagnosis.effects import effect_family, effect_names
>>> effect_names()[:2]
('eccentricity', 'tooth_damage')
>>> [c.label for c in effect_family("friction").variants(None, {})]
['friction']
"""

from __future__ import annotations

from .adhesion_oscillation import AdhesionOscillationFamily
from .base import START_PHASES, EffectFamily, RunOut
from .bearing_clearance import BearingClearanceFamily
from .eccentricity import EccentricityFamily
from .friction import FrictionFamily
from .registry import (
    LIBRARY,
    candidates_for,
    check_effects,
    effect_family,
    effect_names,
    hooks_of,
    register_effect,
    run_out_family,
    signature_hints,
    unregister_effect,
)
from .tooth_damage import ToothDamageFamily
from .torque_ripple import TorqueRippleFamily

__all__ = [
    "EffectFamily",
    "RunOut",
    "LIBRARY",
    "START_PHASES",
    "register_effect",
    "unregister_effect",
    "effect_names",
    "effect_family",
    "candidates_for",
    "signature_hints",
    "check_effects",
    "run_out_family",
    "hooks_of",
    "EccentricityFamily",
    "ToothDamageFamily",
    "FrictionFamily",
    "TorqueRippleFamily",
    "AdhesionOscillationFamily",
    "BearingClearanceFamily",
]
