"""Fatigue of a stress history: rainflow cycle counting and Miner's rule on an ISO S-N curve.

Cycles are counted by the ``rainflow`` package (ASTM E1049-85 four-point
counting, half cycles of the residue kept as halves). Each cycle is scored
by its peak, ``mean + range / 2``: ISO 6336's permissible stresses are peak
stresses of the tooth's pulsating load cycles (a tooth root is loaded from
zero to its peak once per revolution), so a cycle from 0 to sigma counts as
one load cycle at sigma. Miner's rule sums ``count / N(peak)`` with ``N`` the
cycles to failure on a :class:`~uqgear.physics.rating.StressLifeCurve`.

A steady response repeats: the damage of its kept section (``duration``
seconds) scaled to the service time is the damage over the service.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import rainflow

from ..physics.rating import StressLifeCurve


@dataclass(frozen=True)
class RainflowCount:
    """The cycles of a history (ASTM E1049-85 rainflow counting).

    Attributes
    ----------
    ranges, means : ndarray
        Range and mean of each cycle (units of the history).
    counts : ndarray
        1 for a full cycle, 0.5 for a half cycle.
    """

    ranges: np.ndarray
    means: np.ndarray
    counts: np.ndarray

    @property
    def peaks(self) -> np.ndarray:
        """The largest value of each cycle, ``mean + range / 2``."""
        return self.means + 0.5 * self.ranges

    def histogram(self) -> dict[float, float]:
        """Cycles per range, summed over equal ranges (the form ASTM E1049 tabulates)."""
        table: dict[float, float] = {}
        for value, count in zip(self.ranges.tolist(), self.counts.tolist()):
            table[value] = table.get(value, 0.0) + count
        return dict(sorted(table.items()))


def _turning_points(values: np.ndarray) -> np.ndarray:
    """The first and last values and every local extremum between, plateaus reduced to one value."""
    if values.size < 3:
        return values
    kept = np.concatenate(([True], np.diff(values) != 0.0))
    values = values[kept]
    if values.size < 3:
        return values
    slope = np.sign(np.diff(values))
    turning = np.concatenate(([True], slope[1:] != slope[:-1], [True]))
    return values[turning]


def rainflow_count(history) -> RainflowCount:
    """Count the cycles of a history by rainflow (ASTM E1049-85).

    Parameters
    ----------
    history : array_like
        A 1-D sequence of finite values (a stress history, Pa).

    Returns
    -------
    RainflowCount

    Examples
    --------
    The example history of ASTM E1049-85 (its figure of rainflow counting):

    >>> from uqgear.dynamics.fatigue import rainflow_count
    >>> rainflow_count([-2, 1, -3, 5, -1, 3, -4, 4, -2]).histogram()
    {3.0: 0.5, 4.0: 1.5, 6.0: 0.5, 8.0: 1.0, 9.0: 0.5}
    """
    values = np.asarray(history, dtype=float)
    if values.ndim != 1 or not np.all(np.isfinite(values)):
        raise ValueError(f"history: expected a 1-D sequence of finite values; got shape {values.shape}")
    # counting depends on the turning points alone: hand the package those (its reversal search is a Python loop)
    values = _turning_points(values)
    cycles = list(rainflow.extract_cycles(values)) if values.size >= 2 else []
    if not cycles:
        empty = np.zeros(0)
        return RainflowCount(ranges=empty, means=empty.copy(), counts=empty.copy())
    table = np.asarray([cycle[:3] for cycle in cycles], dtype=float)
    return RainflowCount(ranges=table[:, 0], means=table[:, 1], counts=table[:, 2])


def miner_damage(history_or_count, curve: StressLifeCurve, *, repetitions: float = 1.0) -> float:
    """Miner's damage sum of a stress history (or its rainflow count) on an S-N curve.

    Parameters
    ----------
    history_or_count : array_like or RainflowCount
        Stress history in Pa, or its count.
    curve : StressLifeCurve
        The permissible stress against load cycles (of the tooth the history belongs to).
    repetitions : float
        How many times the history repeats (a steady section over a service time).

    Returns
    -------
    float
        sum of count / N(peak) over the cycles, times ``repetitions`` (1 is failure).

    Examples
    --------
    A constant-amplitude pulsating history: n cycles from 0 to sigma give n / N(sigma):

    >>> import numpy as np
    >>> from uqgear.dynamics.fatigue import miner_damage
    >>> from uqgear.physics.rating import StressLifeCurve
    >>> curve = StressLifeCurve(cycles=(1e3, 3e6, 1e10), stress=(2.5e9, 1.0e9, 0.85e9))
    >>> history = np.append(np.tile([0.0, 1.2e9], 1000), 0.0)     # 1000 cycles, closed at zero
    >>> damage = miner_damage(history, curve, repetitions=100.0)
    >>> round(damage / (100.0 * 1000 / curve.cycles_to_failure(1.2e9)), 12)
    1.0
    """
    count = history_or_count if isinstance(history_or_count, RainflowCount) else rainflow_count(history_or_count)
    if not (math.isfinite(repetitions) and repetitions >= 0.0):
        raise ValueError(f"repetitions: expected a finite number >= 0; got {repetitions!r}")
    if count.counts.size == 0:
        return 0.0
    life = np.asarray(curve.cycles_to_failure(count.peaks), dtype=float)
    return float(repetitions * np.sum(count.counts / life))


def damage_rate(history, duration: float, curve: StressLifeCurve) -> float:
    """Miner damage per second of a steady, repeating stress history that lasts ``duration`` seconds."""
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"duration: expected a time > 0 s; got {duration!r}")
    return miner_damage(history, curve) / duration


def engagement_damage(stress, curve: StressLifeCurve) -> float:
    """Miner damage per load cycle of a tooth, from the stress of its engagements (one a row).

    The rows, each a tooth's stress over one engagement (unloaded, zero, outside it), are
    counted as one history that starts and ends unloaded, and the damage divided by the rows:
    a tooth meets one engagement per revolution, so this is its damage per revolution.

    Parameters
    ----------
    stress : array_like
        (engagements, samples) stress, Pa.
    curve : StressLifeCurve

    Returns
    -------
    float

    Examples
    --------
    Engagements loading the tooth from zero to sigma and back are ISO's pulsating cycles, 1 / N(sigma) each:

    >>> import numpy as np
    >>> from uqgear.dynamics.fatigue import engagement_damage
    >>> from uqgear.physics.rating import StressLifeCurve
    >>> curve = StressLifeCurve(cycles=(1e3, 3e6, 1e10), stress=(2.5e9, 1.0e9, 0.85e9))
    >>> pulse = np.array([0.3, 1.0, 0.6, 0.0]) * 1.2e9
    >>> round(engagement_damage(np.tile(pulse, (5, 1)), curve) * curve.cycles_to_failure(1.2e9), 12)
    1.0
    """
    table = np.asarray(stress, dtype=float)
    if table.ndim != 2 or table.shape[0] == 0:
        raise ValueError(f"stress: expected (engagements, samples); got shape {table.shape}")
    history = np.concatenate(([0.0], table.ravel(), [0.0]))
    return miner_damage(history, curve) / table.shape[0]


__all__ = ["RainflowCount", "rainflow_count", "miner_damage", "damage_rate", "engagement_damage"]
