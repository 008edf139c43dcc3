"""Floquet multipliers of periodic orbits: stability, and the type of a loss of stability.

The multipliers of a period-n orbit are the eigenvalues of its monodromy matrix (the Jacobian of
the n-fold Poincare map at the orbit). The orbit is asymptotically stable when every multiplier
lies inside the unit circle. Along a branch, the unstable multipliers are counted by kind (real
above +1, real below -1, complex pairs), and a change of the counts between two points names the
bifurcation between them:

* a real multiplier through +1: a fold (limit point) when the branch turns back in the
  parameter there, else a branch point;
* a real multiplier through -1: a period doubling (flip);
* a complex pair through the unit circle: a Neimark-Sacker (torus) bifurcation.

A multiplier is taken as real when its imaginary part is below :data:`REAL_TOLERANCE` times its
modulus (a complex pair just after a collision on the real axis is still a pair).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Relative imaginary part below which a multiplier counts as real.
REAL_TOLERANCE = 1e-7
#: Margin on the unit circle: a multiplier counts as unstable above 1 + this modulus.
UNIT_CIRCLE_MARGIN = 1e-9

FOLD = "fold"
BRANCH_POINT = "branch_point"
PERIOD_DOUBLING = "period_doubling"
NEIMARK_SACKER = "neimark_sacker"
#: Types of a loss or gain of stability, as :func:`crossing_types` names them.
CROSSING_TYPES = (FOLD, BRANCH_POINT, PERIOD_DOUBLING, NEIMARK_SACKER)


def floquet_multipliers(monodromy: np.ndarray) -> np.ndarray:
    """The eigenvalues of a monodromy matrix, largest modulus first.

    Examples
    --------
    >>> import numpy as np
    >>> floquet_multipliers(np.diag([0.5, -2.0]))
    array([-2. +0.j,  0.5+0.j])
    """
    values = np.linalg.eigvals(np.asarray(monodromy, dtype=float)).astype(complex)
    order = np.lexsort((-values.imag, -values.real, -np.abs(values)))
    return values[order]


def is_real(multiplier: complex) -> bool:
    """Whether a multiplier counts as real (see :data:`REAL_TOLERANCE`)."""
    return abs(multiplier.imag) <= REAL_TOLERANCE * max(abs(multiplier), 1e-300)


@dataclass(frozen=True)
class UnstableCounts:
    """Multipliers outside the unit circle, by kind.

    Attributes
    ----------
    real_plus, real_minus : int
        Real multipliers above +1 and below -1.
    complex : int
        Complex multipliers (both of each pair counted).
    """

    real_plus: int
    real_minus: int
    complex: int

    @property
    def total(self) -> int:
        return self.real_plus + self.real_minus + self.complex


def unstable_counts(multipliers: np.ndarray) -> UnstableCounts:
    """Count the multipliers outside the unit circle by kind.

    Examples
    --------
    >>> unstable_counts(np.array([-1.2, 0.3 + 1.1j, 0.3 - 1.1j, 0.5]))
    UnstableCounts(real_plus=0, real_minus=1, complex=2)
    """
    plus = minus = pairs = 0
    for value in np.asarray(multipliers, dtype=complex):
        if abs(value) <= 1.0 + UNIT_CIRCLE_MARGIN:
            continue
        if is_real(value):
            if value.real > 0:
                plus += 1
            else:
                minus += 1
        else:
            pairs += 1
    return UnstableCounts(plus, minus, pairs)


def is_stable(multipliers: np.ndarray) -> bool:
    """Every multiplier inside the unit circle (asymptotic stability of the orbit)."""
    return bool(np.all(np.abs(np.asarray(multipliers)) <= 1.0 + UNIT_CIRCLE_MARGIN))


def crossing_types(before: UnstableCounts, after: UnstableCounts, turned: bool) -> list[str]:
    """The bifurcations between two points of a branch with these unstable counts.

    Parameters
    ----------
    before, after : UnstableCounts
        Counts at two neighbouring points.
    turned : bool
        Whether the branch turned back in the parameter between them (its tangent's parameter
        component changed sign).

    Returns
    -------
    list of str
        Among :data:`CROSSING_TYPES`; a fold is listed whenever ``turned``.

    Examples
    --------
    >>> crossing_types(UnstableCounts(0, 0, 0), UnstableCounts(0, 1, 0), turned=False)
    ['period_doubling']
    """
    found = []
    changed = after.total != before.total     # a collision on the real axis outside the circle changes no total
    if turned:
        found.append(FOLD)
    elif after.real_plus != before.real_plus and changed:
        found.append(BRANCH_POINT)
    if after.real_minus != before.real_minus and changed:
        found.append(PERIOD_DOUBLING)
    if after.complex != before.complex and changed:
        found.append(NEIMARK_SACKER)
    return found


def floquet_exponents(multipliers: np.ndarray, period: float) -> np.ndarray:
    """Floquet exponents log(mu) / T in 1/s (real part: growth rate of a perturbation).

    Examples
    --------
    >>> float(floquet_exponents(np.array([np.exp(-2.0)]), 1.0)[0].real)
    -2.0
    """
    return np.log(np.asarray(multipliers, dtype=complex)) / float(period)


__all__ = ["floquet_multipliers", "is_real", "UnstableCounts", "unstable_counts", "is_stable", "crossing_types",
           "floquet_exponents", "CROSSING_TYPES", "FOLD", "BRANCH_POINT", "PERIOD_DOUBLING", "NEIMARK_SACKER",
           "REAL_TOLERANCE", "UNIT_CIRCLE_MARGIN"]
