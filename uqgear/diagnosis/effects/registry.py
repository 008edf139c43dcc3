"""The registry of effect families: the library's, and any registered at run time."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ...physics.design import Design
from ..candidates import Candidate
from ..errors import DiagnosisError
from .adhesion_oscillation import AdhesionOscillationFamily
from .base import EffectFamily
from .bearing_clearance import BearingClearanceFamily
from .eccentricity import EccentricityFamily
from .friction import FrictionFamily
from .tooth_damage import ToothDamageFamily
from .torque_ripple import TorqueRippleFamily

#: The library's families, in the order a diagnosis screens them (and ranks ties).
LIBRARY: tuple[EffectFamily, ...] = (
    EccentricityFamily(),
    ToothDamageFamily(),
    FrictionFamily(),
    TorqueRippleFamily(),
    AdhesionOscillationFamily(),
    BearingClearanceFamily(),
)

_REGISTRY: dict[str, EffectFamily] = {family.name: family for family in LIBRARY}
# the hooks' answers for a name with no family
_DEFAULTS = EffectFamily()


def register_effect(family: EffectFamily) -> EffectFamily:
    """Add an effect family to the ones a diagnosis can name (after the library's); returns it.

    Raises
    ------
    DiagnosisError
        A family of that name is already registered.
    """
    if not getattr(family, "name", None) or not isinstance(family.name, str):
        raise DiagnosisError(f"effects: {family!r} has no name; expected an EffectFamily with a name")
    if family.name in _REGISTRY:
        raise DiagnosisError(f"effects: {family.name!r} is already registered")
    _REGISTRY[family.name] = family
    return family


def unregister_effect(name: str) -> None:
    """Remove a family added with :func:`register_effect` (the library's stay)."""
    if any(family.name == name for family in LIBRARY):
        raise DiagnosisError(f"effects: {name!r} is a library effect and stays registered")
    _REGISTRY.pop(name, None)


def effect_names() -> tuple[str, ...]:
    """The registered effect families' names, library first."""
    return tuple(_REGISTRY)


def effect_family(name: str) -> EffectFamily:
    """The registered family of that name.

    Raises
    ------
    DiagnosisError
        No such family.
    """
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise DiagnosisError(
            f"effects: {name!r} is not a library effect; expected one of {', '.join(_REGISTRY)}"
        ) from None


def run_out_family(effects: Sequence[str] | None = None) -> EffectFamily | None:
    """The first registered family whose fits read as a shaft run-out (its ``run_out`` hook), or None.

    Parameters
    ----------
    effects : sequence of str, optional
        Only among these names (a diagnosis's candidates); default: every registered family.

    Examples
    --------
    >>> from uqgear.diagnosis.effects import run_out_family
    >>> run_out_family().name
    'eccentricity'
    >>> run_out_family(["friction", "tooth_damage"]) is None
    True
    """
    for family in _REGISTRY.values():
        if family.run_out is not None and (effects is None or family.name in effects):
            return family
    return None


def hooks_of(name: str) -> EffectFamily:
    """The family that answers the rules' questions about an effect: the registered one, or the defaults.

    A name no family is registered under (a score built by hand, a family
    unregistered since) gets the base :class:`~.base.EffectFamily`'s
    answers: no run-out, nothing in proportion.

    Examples
    --------
    >>> from uqgear.diagnosis.effects import hooks_of
    >>> hooks_of("eccentricity").run_out.modulation
    'kappa'
    >>> hooks_of("no_such_effect").run_out is None
    True
    """
    return _REGISTRY.get(name, _DEFAULTS)


def candidates_for(effect: str, design: Design, *, hints: Mapping[str, float] | None = None) -> list[Candidate]:
    """The screening variants of one registered effect for a design (its family's :meth:`~.base.EffectFamily.variants`).

    ``hints`` are starting values read off the rig's signature
    (:func:`signature_hints`): ``eccentricity_pinion`` and ``eccentricity_gear``
    (run-out, m; ``eccentricity_SHAFT_sidebands`` where read off the housings'
    sidebands), ``adhesion_frequency`` (Hz; without a TE also
    ``adhesion_frequency_2`` to ``_4``, weaker lines).
    """
    return effect_family(effect).variants(design, dict(hints or {}))


def signature_hints(observed: Mapping[str, np.ndarray], locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """Every registered family's starting values read off the rig's features, in registry order.

    ``observed`` holds every channel's features and ``locked_lines`` every
    channel's lines at a fixed frequency, each naming its ``channel``
    (:meth:`~.base.EffectFamily.hints`).
    """
    hints: dict[str, float] = {}
    for family in _REGISTRY.values():
        hints.update(family.hints(observed, locked_lines))
    return hints


def check_effects(effects: Sequence[str] | str | None) -> tuple[str, ...]:
    """Validated candidate effects: registered names, each once (default: every registered family).

    Raises
    ------
    DiagnosisError
        An unknown name, or none at all.
    """
    if effects is None:
        return effect_names()
    if isinstance(effects, str):
        effects = [effects]
    chosen: list[str] = []
    for name in effects:
        if not isinstance(name, str) or name not in _REGISTRY:
            raise DiagnosisError(
                f"effects: {name!r} is not a library effect; expected one or more of {', '.join(_REGISTRY)}"
            )
        if name not in chosen:
            chosen.append(name)
    if not chosen:
        raise DiagnosisError(f"effects: expected at least one of {', '.join(_REGISTRY)}; got none")
    return tuple(chosen)


__all__ = [
    "LIBRARY",
    "register_effect",
    "unregister_effect",
    "effect_names",
    "effect_family",
    "candidates_for",
    "signature_hints",
    "check_effects",
    "run_out_family",
    "hooks_of",
]
