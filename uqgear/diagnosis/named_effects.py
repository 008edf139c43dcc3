"""The effects a diagnosis names, read back as model inputs with their uncertainty.

A diagnosis ends in the effects it names, each with fitted parameters and
their 90 % intervals (``diagnosis.json``'s ``effects``). :func:`named_effects`
reads them from a fitted :class:`~uqgear.diagnosis.Diagnosis`, from the
content of ``diagnosis.json``, from the file itself, or from the
``diagnosis.nc`` of a ``diagnose`` analysis, and returns them as
:class:`~uqgear.physics.effect_draws.UncertainEffect` objects that a
prediction samples and a :class:`~uqgear.physics.integration.BatchEvaluator`
takes.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import xarray as xr

from ..common.errors import UqgearError
from ..physics.effect_draws import UncertainEffect
from .errors import DiagnosisError


def _content_of_file(path: Path) -> Mapping[str, Any]:
    if not path.is_file():
        raise DiagnosisError(
            f"{path}: diagnosis file not found; expected the diagnosis.json (or .nc) of uqgear diagnose"
        )
    try:
        if path.suffix == ".nc":
            with xr.open_dataset(path) as opened:
                text = opened.attrs.get("diagnosis")
            if text is None and (path.parent / "diagnosis.json").is_file():
                text = (path.parent / "diagnosis.json").read_text()
            if text is None:
                raise DiagnosisError(f"{path}: holds no diagnosis record; expected the diagnosis.nc of uqgear diagnose")
            return dict(json.loads(text))
        return dict(json.loads(path.read_text()))
    except (OSError, ValueError) as exc:
        if isinstance(exc, UqgearError):
            raise
        raise DiagnosisError(f"{path}: cannot read the diagnosis ({exc})") from None


def named_effects(source: Any, *, where: str = "") -> tuple[UncertainEffect, ...]:
    """The effects a diagnosis names, with their fitted parameters and 90 % intervals.

    Parameters
    ----------
    source : Diagnosis, mapping, Dataset or path
        A fitted :class:`~uqgear.diagnosis.Diagnosis`; the content of
        ``diagnosis.json``; a ``diagnose`` analysis's Dataset; or the path of
        ``diagnosis.json`` / ``diagnosis.nc``.
    where : str
        Names the input in messages (a study key, a file).

    Returns
    -------
    tuple of UncertainEffect
        In the order the diagnosis named them.

    Raises
    ------
    DiagnosisError
        The source is unreadable, or names no effect (its verdict is
        ``nominal``, ``unexplained`` or ``inconclusive``).

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.diagnosis.named_effects import named_effects
    >>> record = {"verdict": "tooth_damage", "effects": [{"effect": "tooth_damage",
    ...           "parameters": {"gear": "pinion", "tooth": 3.0, "depth": 0.42},
    ...           "parameter_intervals": {"depth": [0.38, 0.46]}}]}
    >>> [effect.central() for effect in named_effects(record)]
    [ToothDamage(gear='pinion', tooth=3.0, depth=0.42)]
    >>> try:
    ...     named_effects({"verdict": "unexplained", "effects": []}, where="model.effects")
    ... except uqgear.UqgearError as error:
    ...     print(error)
    model.effects: the diagnosis names no effect (verdict: unexplained); expected one that names at least one
    """
    if hasattr(source, "effects_") and not isinstance(source, Mapping):
        effects = tuple(selected.to_uncertain() for selected in source.effects_)
        verdict = getattr(getattr(source, "decision_", None), "verdict", "?")
        label = where or "diagnosis"
    else:
        if isinstance(source, xr.Dataset):
            content: Mapping[str, Any] = json.loads(source.attrs.get("diagnosis", "{}"))
        elif isinstance(source, Mapping):
            content = source
        elif isinstance(source, (str, os.PathLike)):
            content = _content_of_file(Path(source))
        else:
            raise DiagnosisError(
                f"{where or 'effects'}: expected a Diagnosis, its diagnosis.json (or its content) or a diagnosis.nc; "
                f"got {type(source).__name__}"
            )
        label = where or str(source if isinstance(source, (str, os.PathLike)) else "diagnosis")
        verdict = content.get("verdict", "?")
        entries = content.get("effects") or []
        try:
            effects = tuple(
                UncertainEffect(
                    entry["effect"],
                    entry.get("parameters", {}),
                    entry.get("parameter_intervals", {}),
                    entry.get("parameter_choices", {}),
                )
                for entry in entries
            )
        except (KeyError, TypeError) as exc:
            raise DiagnosisError(f"{label}: an effect of the diagnosis is malformed ({exc})") from None
        except UqgearError as exc:
            raise DiagnosisError(f"{label}: {exc}") from None
    if not effects:
        raise DiagnosisError(
            f"{label}: the diagnosis names no effect (verdict: {verdict}); expected one that names at least one"
        )
    return effects


__all__ = ["named_effects"]
