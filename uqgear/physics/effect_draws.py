"""Effects with uncertain parameters: a fitted effect, its intervals, and draws of it.

A diagnosis reports each effect it names with its fitted parameters and
their 90 % intervals. An :class:`UncertainEffect` carries both; a prediction
takes the fitted effect (:meth:`UncertainEffect.central`) or draws of it
(:func:`draw_effect_sets`). A draw of a parameter follows a split normal
whose median is the fitted value and whose 5 % and 95 % quantiles are the
interval's ends: the diagnosis' intervals are Laplace intervals kept inside
the parameter's bounds, so they can be lopsided around the fit, and a split
normal keeps both sides; draws are then clipped into the effect's bounds.

A parameter the data leave open among a few values (which tooth is damaged:
an amplitude spectrum is the same for every tooth) is listed with those
values in ``choices``; each draw takes one of them at random. It matters
wherever a quantity is taken over a window that is not a whole number of
revolutions: the damaged tooth then meets the mesh once more or once less in
it, depending on which tooth it is.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .effects import EFFECTS, Effect, EffectError, make_effect

#: z of the 95 % quantile of the standard normal (an interval's ends are its 5 % and 95 % quantiles).
Z95 = 1.6448536269514722


@dataclass(frozen=True)
class UncertainEffect:
    """An effect of the library with fitted parameters and their 90 % intervals.

    Parameters
    ----------
    name : str
        The effect (one of :data:`~uqgear.physics.effects.EFFECTS`).
    values : mapping
        Its fitted parameters and choices (``shaft``, ``gear``, ...).
    intervals : mapping of str to (float, float)
        90 % interval of each uncertain parameter; the others are held at
        their fitted value.
    choices : mapping of str to sequence of float
        Values a parameter the data leave open can take, equally likely
        (each draw takes one; :meth:`central` keeps the fitted value).

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.physics.effect_draws import UncertainEffect, draw_effect_sets
    >>> run_out = UncertainEffect("eccentricity", {"shaft": "pinion", "amplitude": 12e-6, "kappa": 0.03},
    ...                           {"amplitude": (11.8e-6, 12.2e-6)})
    >>> run_out.central()
    Eccentricity(shaft='pinion', amplitude=1.2e-05, phase=0.0, kappa=0.03)
    >>> sets = draw_effect_sets([run_out], 3, seed=0)
    >>> [round(effects[0].values["amplitude"] * 1e6, 2) for effects in sets]
    [12.02, 11.98, 12.08]

    A damaged pinion tooth whose place the data do not tell:

    >>> damage = UncertainEffect("tooth_damage", {"gear": "pinion", "depth": 0.3},
    ...                          {"depth": (0.28, 0.32)}, choices={"tooth": range(21)})
    >>> teeth = {int(effects[0].values["tooth"]) for effects in draw_effect_sets([damage], 200, seed=0)}
    >>> sorted(teeth) == list(range(21))
    True
    """

    name: str
    values: Mapping[str, Any]
    intervals: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    choices: Mapping[str, tuple[float, ...]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in EFFECTS:
            raise EffectError(f"effect {self.name!r}: unknown; expected one of {', '.join(EFFECTS)}")
        object.__setattr__(self, "values", dict(self.values))
        intervals = {}
        for key, bounds in self._mapping("intervals", "[low, high]").items():
            if key not in EFFECTS[self.name].PARAMETERS:
                raise EffectError(f"{self.name}.{key}: an interval for an unknown parameter")
            try:
                low, high = (float(v) for v in bounds)
            except (TypeError, ValueError):
                raise EffectError(f"{self.name}.{key}: expected an interval [low, high]; got {bounds!r}") from None
            if not low <= high:
                raise EffectError(f"{self.name}.{key}: expected an interval with low <= high; got [{low}, {high}]")
            intervals[key] = (low, high)
        object.__setattr__(self, "intervals", intervals)
        object.__setattr__(self, "choices", self._checked_choices(self._mapping("choices", "[values]")))
        self.central()  # validates the fitted values against the effect's bounds

    def _mapping(self, name: str, each: str) -> dict[str, Any]:
        """The field ``name`` as a dict, or an error naming it (a study's YAML can give it any shape)."""
        raw = getattr(self, name)
        if not isinstance(raw, Mapping):
            raise EffectError(f"{self.name}.{name}: expected a mapping of parameter to {each}; got {raw!r}")
        return dict(raw)

    def _checked_choices(self, choices: Mapping[str, Any]) -> dict[str, tuple[float, ...]]:
        checked = {}
        for key, values in choices.items():
            if key not in EFFECTS[self.name].PARAMETERS:
                raise EffectError(f"{self.name}.{key}: choices for an unknown parameter")
            if key in self.intervals:
                raise EffectError(f"{self.name}.{key}: given both an interval and choices; expected one of them")
            try:
                options = tuple(float(v) for v in values)
            except (TypeError, ValueError):
                raise EffectError(
                    f"{self.name}.{key}: expected a list of values to choose from; got {values!r}"
                ) from None
            if not options:
                raise EffectError(f"{self.name}.{key}: expected at least one value to choose from; got none")
            for option in options:  # each must make a valid effect
                make_effect(self.name, {**self.values, key: option})
            checked[key] = options
        return checked

    def central(self) -> Effect:
        """The effect at its fitted parameters."""
        return make_effect(self.name, self.values)

    def draw(self, rng: np.random.Generator) -> Effect:
        """One draw: each uncertain parameter from its split normal, clipped into the effect's bounds."""
        values = dict(self.values)
        specs = EFFECTS[self.name].PARAMETERS
        for key in sorted(self.intervals):
            low, high = self.intervals[key]
            fitted = float(values.get(key, specs[key].default))
            z = rng.standard_normal()
            side = (high - fitted) if z > 0 else (fitted - low)
            values[key] = float(np.clip(fitted + z * max(side, 0.0) / Z95, specs[key].lower, specs[key].upper))
        # after the intervals: an effect without choices takes its intervals' draws alone from the stream
        for key in sorted(self.choices):
            options = self.choices[key]
            values[key] = options[int(rng.integers(len(options)))]
        return make_effect(self.name, values)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"effect", "parameters", "parameter_intervals"}`` and, where the data leave a parameter
        open, ``"parameter_choices"`` (a diagnosis' layout)."""
        out: dict[str, Any] = {
            "effect": self.name,
            "parameters": dict(self.values),
            "parameter_intervals": {key: list(bounds) for key, bounds in self.intervals.items()},
        }
        if self.choices:
            out["parameter_choices"] = {key: list(options) for key, options in self.choices.items()}
        return out


def draw_effect_sets(effects: Sequence[UncertainEffect], n: int, seed: Any) -> list[tuple[Effect, ...]]:
    """``n`` independent draws of a set of uncertain effects (one tuple of effects per draw).

    Parameters
    ----------
    effects : sequence of UncertainEffect
    n : int
        Number of draws.
    seed : SeedSequence or int
        Source of the draws (same seed, same effects).
    """
    rng = np.random.default_rng(seed)
    return [tuple(effect.draw(rng) for effect in effects) for _ in range(int(n))]


def as_effect(item: Any) -> Effect:
    """An :class:`Effect` from an effect, an :class:`UncertainEffect` (its fitted value) or a diagnosed effect.

    A diagnosed effect is anything with a ``to_effect()`` method (what a
    fitted :class:`~uqgear.diagnosis.Diagnosis` lists in ``effects_``).
    """
    if isinstance(item, Effect):
        return item
    if isinstance(item, UncertainEffect):
        return item.central()
    convert = getattr(item, "to_effect", None)
    if callable(convert):
        effect = convert()
        if isinstance(effect, Effect):
            return effect
    raise EffectError(
        f"effects: expected effects of the library (make_effect), or a diagnosis' effects_; got {type(item).__name__}"
    )


__all__ = ["UncertainEffect", "draw_effect_sets", "as_effect", "Z95"]
