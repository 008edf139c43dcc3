"""Life factors and the S-N curves they define (ISO 6336-2 and -3, method B, case-hardened steel).

A life factor is piecewise linear in log-log coordinates between knee points:
flat at its static value up to the first point, falling to 1 at the
endurance knee, then falling to 0.85 at 1e10 load cycles (ISO's default) or
staying at 1 (with optimum lubrication, material, manufacturing and
experience), flat beyond. For case-hardened steel:

- contact (Z_NT, pitting not permitted): 1.6 up to 1e5 cycles, 1 at 5e7, 0.85 (or 1) at 1e10;
- root (Y_NT): 2.5 up to 1e3 cycles, 1 at 3e6, 0.85 (or 1) at 1e10.

:class:`StressLifeCurve` is such a curve in stress: the permissible stress
sigma_G(N) against the number of load cycles, with its inverse (the cycles
to failure at a stress) for Miner's rule.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .settings import RatingMaterial

#: Knee points (cycles, life factor) of case-hardened steel; the last factor is 0.85 or 1 (see the module text).
CONTACT_KNEES = ((1e5, 1.6), (5e7, 1.0), (1e10, 0.85))
ROOT_KNEES = ((1e3, 2.5), (3e6, 1.0), (1e10, 0.85))


def _knees(knees: tuple[tuple[float, float], ...], material: RatingMaterial) -> tuple[tuple[float, float], ...]:
    last_cycles, last = knees[-1]
    return (*knees[:-1], (last_cycles, last if material.long_life_reduced else 1.0))


def _log_interp(cycles, points: tuple[tuple[float, float], ...]) -> np.ndarray:
    log_n = np.log10(np.asarray(points)[:, 0])
    log_y = np.log10(np.asarray(points)[:, 1])
    # np.interp holds the end values: flat before the first knee and after the last
    return 10.0 ** np.interp(np.log10(np.maximum(np.asarray(cycles, dtype=float), 1.0)), log_n, log_y)


def contact_life_factor(cycles, material: RatingMaterial | None = None):
    """Z_NT at a number of load cycles (ISO 6336-2, case-hardened steel, pitting not permitted).

    Examples
    --------
    >>> from uqgear.physics.rating import contact_life_factor
    >>> [round(float(contact_life_factor(n)), 3) for n in (1e4, 1e5, 1e6, 5e7, 1e10)]
    [1.6, 1.6, 1.344, 1.0, 0.85]
    """
    factor = _log_interp(cycles, _knees(CONTACT_KNEES, material or RatingMaterial()))
    return float(factor) if np.ndim(factor) == 0 else factor


def root_life_factor(cycles, material: RatingMaterial | None = None):
    """Y_NT at a number of load cycles (ISO 6336-3, case-hardened steel).

    Examples
    --------
    >>> from uqgear.physics.rating import RatingMaterial, root_life_factor
    >>> [round(float(root_life_factor(n)), 3) for n in (1e3, 1e5, 3e6, 1e10)]
    [2.5, 1.476, 1.0, 0.85]
    >>> round(float(root_life_factor(1e10, RatingMaterial(long_life_reduced=False))), 3)
    1.0
    """
    factor = _log_interp(cycles, _knees(ROOT_KNEES, material or RatingMaterial()))
    return float(factor) if np.ndim(factor) == 0 else factor


@dataclass(frozen=True)
class StressLifeCurve:
    """A permissible-stress S-N curve: stress at knee points, log-log linear between, flat outside.

    Parameters
    ----------
    cycles : tuple of float
        Knee points' load cycles, increasing.
    stress : tuple of float
        The permissible (limit) stress sigma_G at each knee point, Pa, not increasing.

    Examples
    --------
    Cycles to failure at a stress on the sloped part, and none below the last knee's stress:

    >>> from uqgear.physics.rating import StressLifeCurve
    >>> curve = StressLifeCurve(cycles=(1e3, 3e6, 1e10), stress=(2.5e9, 1.0e9, 0.85e9))
    >>> float(curve.strength(3e6)) / 1e9, round(float(curve.cycles_to_failure(1.0e9)))
    (1.0, 3000000)
    >>> float(curve.cycles_to_failure(0.8e9))
    inf
    """

    cycles: tuple[float, ...]
    stress: tuple[float, ...]

    def strength(self, cycles):
        """Permissible stress at a number of load cycles, Pa."""
        return _log_interp(cycles, tuple(zip(self.cycles, self.stress)))

    def cycles_to_failure(self, stress):
        """Load cycles to failure at a (peak) stress: the inverse of :meth:`strength`.

        Infinite at or below the stress of the last knee point (the curve is flat
        beyond it); 1 above the static stress (the first knee: failure in the
        first cycle).
        """
        stress = np.asarray(stress, dtype=float)
        log_n = np.log10(np.asarray(self.cycles))
        log_s = np.log10(np.asarray(self.stress))
        # interpolate log N against decreasing log stress (reversed to increasing for np.interp)
        with np.errstate(divide="ignore"):
            log_stress = np.log10(np.maximum(stress, 1e-300))
        result = 10.0 ** np.interp(log_stress, log_s[::-1], log_n[::-1])
        result = np.where(stress <= self.stress[-1], math.inf, result)
        result = np.where(stress > self.stress[0], 1.0, result)
        return float(result) if result.ndim == 0 else result


__all__ = ["CONTACT_KNEES", "ROOT_KNEES", "contact_life_factor", "root_life_factor", "StressLifeCurve"]
