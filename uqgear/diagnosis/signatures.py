"""The rig data's signature: frequency-locked lines and the candidate fits' starting values read off it."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .case import RigCase
from .interference import MIN_RUNS, PEAK_THRESHOLD, fixed_frequency_lines


def frequency_locked_lines(case: RigCase, *, channel: str = "te", threshold: float = PEAK_THRESHOLD,
                           minimum_runs: int = MIN_RUNS) -> list[dict[str, Any]]:
    """Spectral lines of a channel that keep their frequency, not their order, across runs.

    :func:`~.interference.fixed_frequency_lines` on the case's records
    (stick-slip, a fixed-frequency source); empty without that channel.
    """
    if channel not in case.channels:
        return []
    index = case.channels.index(channel)
    return fixed_frequency_lines(np.asarray(case.rig[channel].values, dtype=float), case.noise_std[:, index],
                                 case.speeds, case.fs, case.processors[0].limit, usable=case.usable[:, index],
                                 threshold=threshold, minimum_runs=minimum_runs)


def signature_hints(case: RigCase, locked_lines: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """Starting values for the candidate fits read off the rig's features.

    The run-out amplitude from the median 1x shaft line of the transmission
    error (the run-out enters the TE directly); the stick-slip frequency
    from the lowest frequency-locked line below 100 Hz.
    """
    hints: dict[str, float] = {}
    if "te" in case.channels:
        te = case.channels.index("te")
        for shaft in ("pinion", "gear"):
            name = f"shaft_{shaft}1"
            if name in case.layout.names:
                values = case.observed[:, te, case.layout.names.index(name)]
                values = values[np.isfinite(values)]
                if values.size:
                    hints[f"eccentricity_{shaft}"] = float(np.median(values))
    low = [line["frequency"] for line in locked_lines if 1.0 <= line["frequency"] <= 100.0]
    if low:
        hints["adhesion_frequency"] = float(min(low))
    return hints

