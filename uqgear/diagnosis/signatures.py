"""The rig data's signature: frequency-locked lines and the candidate fits' starting values read off it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .allowances.interference import fixed_frequency_lines
from .case import RigCase
from .effects import signature_hints as family_hints
from .settings import DEFAULT_SETTINGS, DiagnosisSettings


def frequency_locked_lines(
    case: RigCase, *, channel: str = "te", settings: DiagnosisSettings = DEFAULT_SETTINGS
) -> list[dict[str, Any]]:
    """Spectral lines of a channel that keep their frequency, not their order, across runs.

    :func:`~.allowances.interference.fixed_frequency_lines` on the case's
    records (stick-slip, a fixed-frequency source), with the settings'
    ``interference_threshold`` and ``interference_runs``; empty without that
    channel.
    """
    if channel not in case.channels:
        return []
    index = case.channels.index(channel)
    return fixed_frequency_lines(
        np.asarray(case.rig[channel].values, dtype=float),
        case.noise_std[:, index],
        case.speeds,
        case.fs,
        case.processors[0].limit,
        usable=case.usable[:, index],
        threshold=settings.interference.interference_threshold,
        minimum_runs=settings.interference.interference_runs,
    )


def signature_hints(case: RigCase, locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """Starting values for the candidate fits read off the rig's features by every effect family.

    For the library: the run-out amplitude from the median 1x shaft line of
    the transmission error (the run-out enters the TE directly), the
    stick-slip frequency from the lowest frequency-locked line below 100 Hz
    (:meth:`~.effects.base.EffectFamily.hints`).
    """
    return family_hints(case.observed_features(), locked_lines)


__all__ = ["frequency_locked_lines", "signature_hints"]
