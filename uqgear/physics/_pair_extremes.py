"""Extremes of the tooth-pair loads over a run's kept grid steps, for the tooth-stress QoIs (compiled).

A tooth's root stress is a constant of its gear times the load ``P`` of its pair, and its flank stress
is a constant times ``sqrt(P+ / rho(s))`` while the contact point ``s`` lies on that gear's
dedendum (docs/model/rating.md section 10.6, :mod:`uqgear.dynamics.tooth_loads`). The peaks and
amplitudes of both stresses of both gears therefore follow from four extremes over the kept grid
steps and the pairs in mesh that touch (slots ``E_*``): the largest and the smallest pair load and,
per gear, the largest ``P+ / rho``. The batch kernels keep them where asked
(:class:`~uqgear.physics._batch_record.QoiBatch`'s ``stresses``) at the start of each kept grid step,
where they take their other QoIs: :func:`add_pair_extremes`.

Each pair's load is that of :func:`uqgear.dynamics.tooth_loads.pair_loads`: its elastic force
``k_i f(x - e_i)`` plus its share ``k_i / sum_j k_j`` (over the pairs that touch) of the mesh
damping force ``c_m x'``. The pair stiffness ``k_i`` and offset ``e_i`` are those the pair path
steps with (:func:`~uqgear.physics._pairs._forcing_row_pairs` from the run's tabulated stages and the
period's :func:`~uqgear.physics._pairs._tooth_terms`): the Ishikawa pair table or its share of a smooth one,
the tooth factors, the stiffness scale and the run-out's modulation, written once for every path.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from uqgear.physics._pairs import PAIR_K, PAIR_OFFSET, _forcing_row_pairs
from uqgear.physics._rhs import (
    BASE_PITCH,
    CM,
    HALF_BACKLASH,
    INLINED,
    LOA_LENGTH,
    PATH_START,
    PITCH_POSITION,
    dead_zone,
)

# slots of a run's extremes: largest and smallest pair load (N), largest P+ / rho on the pinion's
# and on the gear's dedendum (N/m)
E_LOAD_MAX, E_LOAD_MIN, E_FLANK_PINION, E_FLANK_GEAR = range(4)
N_EXTREMES = 4
#: Tolerance of the dedendum test at the pitch point, base pitches (:mod:`uqgear.dynamics.tooth_loads` applies it too).
PITCH_TOLERANCE = 1e-12


#: The extremes of a run before its first kept grid step: no load seen (the flank terms are >= 0).
NO_EXTREMES = (-np.inf, np.inf, 0.0, 0.0)


@nb.njit(**INLINED)
def _pair_load(elastic, k, touching_k, damping):
    """A touching pair's load: its elastic force and its stiffness share of the mesh damping force."""
    return elastic + (k / touching_k) * damping


@nb.njit(**INLINED)
def _add_pair(extremes, load, position, geometry):
    """``extremes`` (a 4-tuple, slots ``E_*``) with one touching pair's load at ``position`` base pitches on the
    path of contact; ``geometry``: (path start, base pitch, length of the line of action, pitch point)."""
    high, low, pinion_flank, gear_flank = extremes
    start, base_pitch, length, pitch = geometry
    high = load if load > high else high  # noqa: FURB136
    low = load if load < low else low  # noqa: FURB136
    pinion = start + base_pitch * position
    gear = length - pinion
    # P+ / rho: a pair at a negative load adds nothing to the flank terms (which start at 0)
    flank = max(load, 0.0) / (pinion * gear / (pinion + gear))
    if position <= pitch + PITCH_TOLERANCE:
        pinion_flank = flank if flank > pinion_flank else pinion_flank  # noqa: FURB136
    if position >= pitch - PITCH_TOLERANCE:
        gear_flank = flank if flank > gear_flank else gear_flank  # noqa: FURB136
    return high, low, pinion_flank, gear_flank


@nb.njit(**INLINED)
def add_pair_extremes(extremes, x, x_velocity, t, u, teeth, table, sub, n_pairs, p):
    """``extremes`` (a 4-tuple, slots ``E_*``) with the pair loads at state (``x``, ``x_velocity``), time ``t`` and
    mesh phase ``u`` (base pitches; sub-step ``sub`` of the run's tabulated stages ``table`` starts there, with
    ``n_pairs`` in mesh); ``teeth``: :func:`~uqgear.physics._pairs._tooth_terms` of the mesh period.

    Inlined, on tuples: what the pair forcing computes beyond the pairs' stiffness (the time terms,
    friction) is then dropped by the compiler, and no array is passed by a call or counted in a
    branch on every kept grid step (docs/validation/performance.md, "Compile time and inlining").
    """
    # the slots read first, outside any branch
    b = p[HALF_BACKLASH]
    damping = p[CM] * x_velocity
    geometry = (p[PATH_START], p[BASE_PITCH], p[LOA_LENGTH], p[PITCH_POSITION])
    terms = _forcing_row_pairs(t, teeth, table, sub, 0, n_pairs, p)
    k0, k1, k2, k3 = terms[PAIR_K], terms[PAIR_K + 1], terms[PAIR_K + 2], terms[PAIR_K + 3]
    # a slot beyond the pairs in mesh has zero stiffness: no elastic force, not touching
    e0 = k0 * dead_zone(x - terms[PAIR_OFFSET], b)
    e1 = k1 * dead_zone(x - terms[PAIR_OFFSET + 1], b)
    e2 = k2 * dead_zone(x - terms[PAIR_OFFSET + 2], b)
    e3 = k3 * dead_zone(x - terms[PAIR_OFFSET + 3], b)
    touching_k = 0.0
    touching_k += k0 if e0 != 0.0 else 0.0
    touching_k += k1 if e1 != 0.0 else 0.0
    touching_k += k2 if e2 != 0.0 else 0.0
    touching_k += k3 if e3 != 0.0 else 0.0
    if e0 != 0.0:
        extremes = _add_pair(extremes, _pair_load(e0, k0, touching_k, damping), u, geometry)
    if e1 != 0.0:
        extremes = _add_pair(extremes, _pair_load(e1, k1, touching_k, damping), u + 1.0, geometry)
    if e2 != 0.0:
        extremes = _add_pair(extremes, _pair_load(e2, k2, touching_k, damping), u + 2.0, geometry)
    if e3 != 0.0:
        extremes = _add_pair(extremes, _pair_load(e3, k3, touching_k, damping), u + 3.0, geometry)
    return extremes


__all__ = ["E_LOAD_MAX", "E_LOAD_MIN", "E_FLANK_PINION", "E_FLANK_GEAR", "N_EXTREMES", "NO_EXTREMES",
           "add_pair_extremes"]
