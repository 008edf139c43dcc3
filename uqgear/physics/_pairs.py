"""Compiled per-pair mesh force for pitch errors (docs/model/equations.md section 2.6).

With per-tooth pitch offsets each tooth pair in mesh has its own deflection
``x - e_i`` (``e_i = e_pinion[i] + e_gear[j]`` for the pair of pinion tooth i
and gear tooth j), its own backlash dead zone and its own contact state, so
the mesh force is ``sum_i k_i f(x - e_i) + c_m x'`` instead of ``k f(x) + c_m x'``.
That sum is not the classical product even with every offset zero (floating
point does not distribute), so the kernels take this path only when some
offset is not zero (slot ``PITCH_ERRORS``) and are unchanged, bit for bit,
otherwise.

The forcing of a pair path is an 18-tuple: the five terms of
:func:`~uqgear.physics._rhs.forcing` (total k, total friction term,
relative drive acceleration, e, e''), the number of pairs in mesh, then per
pair slot (``MAX_PAIRS`` of them, zeros beyond the pairs in mesh) its
stiffness, its friction term and its offset. Steps are split where any
pair's deflection crosses its contact boundary ``+-b``, as the classical path
splits at ``|x| = b``.

Built on the helpers of :mod:`uqgear.physics._rhs`; :mod:`uqgear.physics._kernels`
chooses between this path and the classical one.
"""

from __future__ import annotations

import math

import numba as nb

from uqgear.physics._rhs import (
    C1,
    C2,
    CLEARANCE1,
    CLEARANCE2,
    CM,
    CONTACT_RATIO,
    DAMP_IN_SEPARATION,
    F_SINE,
    FRICTION,
    HALF_BACKLASH,
    INLINED,
    JIT_OPTIONS,
    K1,
    K2,
    M1,
    M2,
    MAX_PAIRS,
    ME,
    N_PARAMS,
    OMEGA_MESH,
    STE_PHASE,
    TOOTH_FACTORS,
    Z1,
    Z2,
    _crossing_fraction,
    _friction_arms,
    _friction_term,
    _interp_uniform,
    _mesh_position,
    _shifted,
    _time_terms,
    contact_region,
    crossed_boundary,
    dead_zone,
    modulated_scale,
    rk4_combine,
    smooth_share,
)

# positions in the forcing tuple of a pair path
PAIR_COUNT = 5
PAIR_K = 6
PAIR_FRICTION = PAIR_K + MAX_PAIRS
PAIR_OFFSET = PAIR_FRICTION + MAX_PAIRS
N_PAIR_TERMS = PAIR_OFFSET + MAX_PAIRS


@nb.njit(**INLINED)
def pair_offset(tooth, p):
    """e_pinion + e_gear (m) of the pair brought into mesh by meshing number ``tooth``.

    Tooth numbers as for the tooth factors: meshing n pairs pinion tooth
    n mod z1 with gear tooth n mod z2, tooth 0 of each entering at t = 0.
    """
    return _teeth_offset(tooth % int(p[Z1]), tooth % int(p[Z2]), p)


@nb.njit(**INLINED)
def _teeth_offset(pinion_tooth, gear_tooth, p):
    """e_pinion + e_gear (m) of pinion tooth ``pinion_tooth`` meshing with gear tooth ``gear_tooth``."""
    return p[N_PARAMS + pinion_tooth] + p[N_PARAMS + int(p[Z1]) + gear_tooth]


@nb.njit(**INLINED)
def _pair(i, n_ref, u_ref, u, eps, ratio, p, pair_k, fp, fg):
    """(k_i, pinion arm, gear arm, e_i) of pair ``i``, unscaled; zeros when it is not in mesh."""
    if not u_ref + i < eps:
        return 0.0, 0.0, 0.0, 0.0
    kp = _interp_uniform(pair_k, u + i, eps) * ratio
    tooth = int(n_ref) - i
    if p[TOOTH_FACTORS] != 0.0:
        kp *= fp[tooth % int(p[Z1])] * fg[tooth % int(p[Z2])]
    pinion = 0.0
    gear = 0.0
    if p[FRICTION] != 0.0:
        pinion, gear = _friction_arms(kp, u + i, u_ref + i, p)
    return kp, pinion, gear, pair_offset(tooth, p)


@nb.njit(**INLINED)
def _pack(count, a, b, c, d, scale, drive, ste, ste_acc, p):
    """The 18-tuple forcing from four (k, arms, e) pair tuples, with the stiffness scale applied."""
    k0, k1, k2, k3 = a[0] * scale, b[0] * scale, c[0] * scale, d[0] * scale
    f0 = _friction_term(a[1] * scale, a[2] * scale, p)
    f1 = _friction_term(b[1] * scale, b[2] * scale, p)
    f2 = _friction_term(c[1] * scale, c[2] * scale, p)
    f3 = _friction_term(d[1] * scale, d[2] * scale, p)
    return (
        k0 + k1 + k2 + k3,
        f0 + f1 + f2 + f3,
        drive,
        ste,
        ste_acc,
        float(count),
        k0,
        k1,
        k2,
        k3,
        f0,
        f1,
        f2,
        f3,
        a[3],
        b[3],
        c[3],
        d[3],
    )


@nb.njit(**JIT_OPTIONS)
def forcing_pairs(t, t_ref, p, pair_k, period_k, fp, fg):
    """Pair-resolved forcing at any time ``t`` (pairs in mesh as at ``t_ref``); see the module doc.

    With a smooth period table (``fourier`` or ``constant`` stiffness) each
    pair takes its share of the smooth curve
    (:func:`~uqgear.physics._rhs.smooth_share`).
    """
    n_ref, u_ref, u = _mesh_position(t, t_ref, p)
    eps = p[CONTACT_RATIO]
    count = 0
    while u_ref + count < eps:
        if count >= MAX_PAIRS:
            raise ValueError("more tooth pairs in contact than the pair path holds")
        count += 1
    ratio, _ = smooth_share(t, u_ref, u, p, pair_k, period_k)
    scale = modulated_scale(t, p)
    drive, ste, ste_acc = _time_terms(t, math.sin(p[OMEGA_MESH] * t + p[STE_PHASE]), p)
    return _pack(
        count,
        _pair(0, n_ref, u_ref, u, eps, ratio, p, pair_k, fp, fg),
        _pair(1, n_ref, u_ref, u, eps, ratio, p, pair_k, fp, fg),
        _pair(2, n_ref, u_ref, u, eps, ratio, p, pair_k, fp, fg),
        _pair(3, n_ref, u_ref, u, eps, ratio, p, pair_k, fp, fg),
        scale,
        drive,
        ste,
        ste_acc,
        p,
    )


@nb.njit(**INLINED)
def _earlier(remainder, back, count):
    """``(m - back) % count`` given ``remainder = m % count`` (``back >= 0``), without a division."""
    earlier = remainder - back
    while earlier < 0:
        earlier += count
    return earlier


@nb.njit(**INLINED)
def _tooth_terms(n, p, fp, fg):
    """(offset, tooth factor) of the pairs brought into mesh by meshing numbers n, n - 1, n - 2 and n - 3.

    They depend on the meshing number only: a step computes them once for
    the three stages of each of its sub-steps, from one integer remainder
    per gear (remainders are the dearest operations of a pair's forcing;
    the teeth of the earlier pairs follow by subtraction).
    """
    z1 = int(p[Z1])
    z2 = int(p[Z2])
    i0 = n % z1
    j0 = n % z2
    i1, i2, i3 = _earlier(i0, 1, z1), _earlier(i0, 2, z1), _earlier(i0, 3, z1)
    j1, j2, j3 = _earlier(j0, 1, z2), _earlier(j0, 2, z2), _earlier(j0, 3, z2)
    f0 = f1 = f2 = f3 = 1.0
    if p[TOOTH_FACTORS] != 0.0:
        f0 = fp[i0] * fg[j0]
        f1 = fp[i1] * fg[j1]
        f2 = fp[i2] * fg[j2]
        f3 = fp[i3] * fg[j3]
    return (
        (_teeth_offset(i0, j0, p), _teeth_offset(i1, j1, p), _teeth_offset(i2, j2, p), _teeth_offset(i3, j3, p)),
        (f0, f1, f2, f3),
    )


@nb.njit(**INLINED)
def _row_pair(i, table, sub, stage, n_pairs, p, offset, factor):
    """:func:`_pair` from a tabulated stage of :func:`~uqgear.physics._rhs.build_schedule`."""
    if i >= n_pairs:
        return 0.0, 0.0, 0.0, 0.0
    kp = table[sub, stage, 4 + 3 * i]
    pinion = table[sub, stage, 5 + 3 * i]
    gear = table[sub, stage, 6 + 3 * i]
    if p[TOOTH_FACTORS] != 0.0:
        kp *= factor
        pinion *= factor
        gear *= factor
    return kp, pinion, gear, offset


@nb.njit(**INLINED)
def _forcing_row_pairs(t, teeth, table, sub, stage, n_pairs, p):
    """:func:`forcing_pairs` at absolute time ``t`` from a tabulated stage (``teeth``: :func:`_tooth_terms`)."""
    # the table's pair fields are each pair's share of the mesh stiffness already (smooth_share)
    scale = modulated_scale(t, p)
    drive, ste, ste_acc = _time_terms(t, table[sub, stage, F_SINE], p)
    offsets, factors = teeth
    return _pack(
        n_pairs,
        _row_pair(0, table, sub, stage, n_pairs, p, offsets[0], factors[0]),
        _row_pair(1, table, sub, stage, n_pairs, p, offsets[1], factors[1]),
        _row_pair(2, table, sub, stage, n_pairs, p, offsets[2], factors[2]),
        _row_pair(3, table, sub, stage, n_pairs, p, offsets[3], factors[3]),
        scale,
        drive,
        ste,
        ste_acc,
        p,
    )


@nb.njit(**INLINED)
def derivative_pairs(s, terms, p):
    """:func:`~uqgear.physics._rhs.derivative` with one dead zone per pair: F = sum k_i f(x - e_i) + c_m* x'.

    The mesh damper acts on x' (every pair deflects at that rate); with
    ``damping_in_separation`` off it stops when no pair is in contact.
    """
    x = s[2]
    vx = s[5]
    b = p[HALF_BACKLASH]
    elastic = 0.0
    friction = 0.0
    touching = False
    for i in range(int(terms[PAIR_COUNT])):
        fx = dead_zone(x - terms[PAIR_OFFSET + i], b)
        if fx != 0.0:
            touching = True
        elastic += terms[PAIR_K + i] * fx
        friction += terms[PAIR_FRICTION + i] * fx
    damping = p[CM]
    if p[DAMP_IN_SEPARATION] == 0.0 and not touching:
        damping = 0.0
    force = elastic + damping * vx
    bearing1 = p[K1] * dead_zone(s[0], p[CLEARANCE1])
    bearing2 = p[K2] * dead_zone(s[1], p[CLEARANCE2])
    a1 = (-p[C1] * s[3] - bearing1 - force) / p[M1]
    a2 = (-p[C2] * s[4] - bearing2 + force) / p[M2]
    relative = terms[2] - force / p[ME] - friction
    return (s[3], s[4], vx, a1, a2, a1 - a2 + relative - terms[4]), force


@nb.njit(**INLINED)
def _rk4_pairs(s, h, d1, mid, end, p):
    """:func:`~uqgear.physics._rhs._rk4` with the pair-resolved derivative."""
    d2, _ = derivative_pairs(_shifted(s, 0.5 * h, d1), mid, p)
    d3, _ = derivative_pairs(_shifted(s, 0.5 * h, d2), mid, p)
    d4, _ = derivative_pairs(_shifted(s, h, d3), end, p)
    return rk4_combine(s, h, d1, d2, d3, d4)


@nb.njit(**INLINED)
def _first_crossing(s, trial, h, terms, p, split_level):
    """(fraction of the step, boundary level) where the first pair changes its contact state ((2.0, nan) if none).

    A boundary a step was split at already (``split_level``) is not split at again: the first part ends
    on the interpolated crossing, a little short of or beyond its own, and the classical path
    (:func:`~uqgear.physics._rhs._split_at_contact`) splits a step once at the boundary it crosses. So
    both paths take the same steps where the pairs' offsets coincide.
    """
    b = p[HALF_BACKLASH]
    first = 2.0
    first_level = math.nan
    for i in range(int(terms[PAIR_COUNT])):
        offset = terms[PAIR_OFFSET + i]
        before = contact_region(s[2] - offset, b)
        after = contact_region(trial[2] - offset, b)
        if before == after:
            continue
        level, _ = crossed_boundary(before, after, b)
        if offset + level == split_level:
            continue
        theta = _crossing_fraction(s[2], s[5], trial[2], trial[5], h, offset + level)
        if theta < first:
            first = theta
            first_level = offset + level
    return first, first_level


@nb.njit(**INLINED)
def _step_pairs(t, h, s, d1, mid, end, terms, t_ref, p, pair_k, period_k, fp, fg):
    """One RK4 step over [t, t+h] (one pair set), redone in parts at each pair's contact change.

    The classical path splits once, at |x| = b; here several pairs may change
    state within a step, so the remainder is checked again (at most
    ``2 MAX_PAIRS`` splits: each pair has two boundaries), each boundary once.
    """
    trial = _rk4_pairs(s, h, d1, mid, end, p)
    split_level = math.nan
    for _ in range(2 * MAX_PAIRS):
        theta, split_level = _first_crossing(s, trial, h, terms, p, split_level)
        if not 1e-9 < theta < 1.0 - 1e-9:
            return trial
        h_a = theta * h
        middle = forcing_pairs(t + h_a, t_ref, p, pair_k, period_k, fp, fg)
        s = _rk4_pairs(s, h_a, d1, forcing_pairs(t + 0.5 * h_a, t_ref, p, pair_k, period_k, fp, fg), middle, p)
        t += h_a
        h -= h_a
        d1, _ = derivative_pairs(s, middle, p)
        trial = _rk4_pairs(
            s,
            h,
            d1,
            forcing_pairs(t + 0.5 * h, t_ref, p, pair_k, period_k, fp, fg),
            forcing_pairs(t + h, t_ref, p, pair_k, period_k, fp, fg),
            p,
        )
    return trial


@nb.njit(**INLINED)
def scheduled_step_pairs(n, j, period, s, p, pair_k, period_k, fp, fg, schedule):
    """:func:`~uqgear.physics._rhs.classical_step` with per-pair deflections (same returns).

    Inlined into the kernels, with the parts of its step, as the classical
    step is: a plain call on every grid step pays the reference counts of
    the arrays it is passed (``INLINED`` in :mod:`uqgear.physics._rhs`).
    """
    first_sub, offsets, widths, refs, pairs, table = schedule
    start = n * period
    force = 0.0
    a1 = 0.0
    a2 = 0.0
    teeth = _tooth_terms(n, p, fp, fg)
    for sub in range(first_sub[j], first_sub[j + 1]):
        new, d1, f = substep_pairs(
            start + offsets[sub], widths[sub], s, teeth, table, sub, pairs[sub], start + refs[sub], p, pair_k,
            period_k, fp, fg,
        )
        if sub == first_sub[j]:
            force = f
            a1 = d1[3]
            a2 = d1[4]
        s = new
    return s, force, a1, a2


@nb.njit(**INLINED)
def substep_pairs(t, h, s, teeth, table, sub, n_pairs, t_ref, p, pair_k, period_k, fp, fg):
    """Sub-step ``sub`` of :func:`scheduled_step_pairs` over [t, t+h] from ``s`` (``teeth``: :func:`_tooth_terms`
    of its mesh period, ``table``: its schedule's tabulated stages, ``t_ref``: its reference time).

    Returns (new state, first RK4 stage, mesh force at the start). The one-sample pair step, also
    what a pair lane's redone sub-step is (:mod:`uqgear.physics._pair_lanes`).
    """
    terms = _forcing_row_pairs(t, teeth, table, sub, 0, n_pairs, p)
    d1, force = derivative_pairs(s, terms, p)
    new = _step_pairs(
        t,
        h,
        s,
        d1,
        _forcing_row_pairs(t + 0.5 * h, teeth, table, sub, 1, n_pairs, p),
        _forcing_row_pairs(t + h, teeth, table, sub, 2, n_pairs, p),
        terms,
        t_ref,
        p,
        pair_k,
        period_k,
        fp,
        fg,
    )
    return new, d1, force


@nb.njit(**INLINED)
def pair_contact(x, n, n_pairs, p):
    """Contact state with pitch errors: 1 if some pair in mesh is in drive-side contact (x - e_i > b),
    else -1 if some pair touches on the back side (x - e_i < -b), else 0."""
    b = p[HALF_BACKLASH]
    z1 = int(p[Z1])
    z2 = int(p[Z2])
    pinion = n % z1
    gear = n % z2
    state = 0
    for i in range(n_pairs):
        region = contact_region(x - _teeth_offset(_earlier(pinion, i, z1), _earlier(gear, i, z2), p), b)
        if region == 1:
            return 1
        if region == -1:
            state = -1
    return state


@nb.njit(**JIT_OPTIONS)
def pair_state(t_ref, p):
    """(meshing number of the newest pair, number of pairs in mesh) at time ``t_ref``."""
    n_ref, u_ref, _ = _mesh_position(t_ref, t_ref, p)
    count = 0
    while u_ref + count < p[CONTACT_RATIO]:
        count += 1
    return int(n_ref), count


__all__ = [
    "forcing_pairs",
    "derivative_pairs",
    "scheduled_step_pairs",
    "substep_pairs",
    "pair_contact",
    "pair_offset",
    "pair_state",
]
