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
    CONTACT_RATIO,
    DAMP_IN_SEPARATION,
    ECC_KAPPA,
    ECC_OMEGA,
    ECC_PHASE,
    FRICTION,
    HALF_BACKLASH,
    INLINED,
    JIT_OPTIONS,
    MAX_PAIRS,
    N_PARAMS,
    NO_INVERSE,
    OMEGA_MESH,
    STE_PHASE,
    STIFFNESS_SCALE,
    TOOTH_FACTORS,
    Z1,
    Z2,
    _accelerations,
    _friction_arms,
    _friction_term,
    _interp_uniform,
    _mesh_position,
    _time_terms,
    coefficients,
    contact_region,
    dead_zone,
    divided,
    mesh_damping,
    modulated_scale,
    run_out_modulation,
    smooth_share,
    teeth_factor,
    tooth_factor,
)
from uqgear.physics._stepper import BISECTIONS, F_SINE, crossed_boundary, crossing_fraction, rk4_by, split_parts

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
        kp *= tooth_factor(tooth, p, fp, fg)
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
        f0 = teeth_factor(i0, j0, fp, fg)
        f1 = teeth_factor(i1, j1, fp, fg)
        f2 = teeth_factor(i2, j2, fp, fg)
        f3 = teeth_factor(i3, j3, fp, fg)
    return (
        (_teeth_offset(i0, j0, p), _teeth_offset(i1, j1, p), _teeth_offset(i2, j2, p), _teeth_offset(i3, j3, p)),
        (f0, f1, f2, f3),
    )


@nb.njit(**INLINED)
def _row_pair(i, table, sub, stage, n_pairs, p, offset, factor):
    """:func:`_pair` from a tabulated stage of :func:`~uqgear.physics._stepper.build_schedule`."""
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
    # the slots read here: the modulation takes scalars (run_out_modulation says why)
    scale = run_out_modulation(t, p[STIFFNESS_SCALE], p[ECC_KAPPA], p[ECC_OMEGA], p[ECC_PHASE])
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
def _slot(x, k, friction, offset, b, in_mesh):
    """(k f(x - e), friction term f(x - e), 1.0 if the slot is in mesh and in contact else 0.0) of a pair slot."""
    fx = dead_zone(x - offset, b)
    touching = 1.0 if (fx != 0.0) & in_mesh else 0.0
    return k * fx, friction * fx, touching


@nb.njit(**INLINED)
def _pair_sums(x, k, friction, offsets, n_pairs, b):
    """(sum k_i f(x - e_i), sum of the friction terms f(x - e_i), number of pairs in mesh and in contact) over
    the four pair slots in slot order (a slot beyond those in mesh has zero stiffness and friction: adding its
    zero product leaves a sum's bits as they are)."""
    k0, f0, t0 = _slot(x, k[0], friction[0], offsets[0], b, 0 < n_pairs)
    k1, f1, t1 = _slot(x, k[1], friction[1], offsets[1], b, 1 < n_pairs)
    k2, f2, t2 = _slot(x, k[2], friction[2], offsets[2], b, 2 < n_pairs)
    k3, f3, t3 = _slot(x, k[3], friction[3], offsets[3], b, 3 < n_pairs)
    elastic = 0.0 + k0
    elastic += k1
    elastic += k2
    elastic += k3
    sliding = 0.0 + f0
    sliding += f1
    sliding += f2
    sliding += f3
    return elastic, sliding, t0 + t1 + t2 + t3


@nb.njit(**INLINED)
def pair_derivative_by(s, terms, offsets, n_pairs, c, divide, inverse):
    """The per-pair right-hand side from a stage's terms (4-tuples of the pair slots' stiffness and friction
    term, drive, e''), the slots' pitch offsets and the pairs in mesh, with a quotient function
    (:func:`~uqgear.physics._rhs.state_derivative_by`): the one expression of both pair kernels.

    The model's accelerations (:func:`~uqgear.physics._rhs._accelerations` with k = sum k_i f(x - e_i),
    f(x) = 1 and the friction sum as the friction term: the products by 1.0 are exact) over
    :func:`_pair_sums`; the mesh damping off where no pair touches and the model has no damping in
    separation. Returns (ds/dt, F, exact).
    """
    k, friction, drive, ste_acc = terms
    elastic, sliding, touching = _pair_sums(s[2], k, friction, offsets, n_pairs, c[0])
    damping = mesh_damping(c, touching == 0.0)
    return _accelerations(s, elastic, sliding, drive, ste_acc, c, 1.0, damping, divide, inverse)


@nb.njit(**INLINED)
def _stage_of(terms):
    """A pair path's forcing 18-tuple as the stage terms and slot offsets of :func:`pair_derivative_by`."""
    stage = (
        (terms[PAIR_K], terms[PAIR_K + 1], terms[PAIR_K + 2], terms[PAIR_K + 3]),
        (terms[PAIR_FRICTION], terms[PAIR_FRICTION + 1], terms[PAIR_FRICTION + 2], terms[PAIR_FRICTION + 3]),
        terms[2],
        terms[4],
    )
    offsets = (terms[PAIR_OFFSET], terms[PAIR_OFFSET + 1], terms[PAIR_OFFSET + 2], terms[PAIR_OFFSET + 3])
    return stage, offsets


@nb.njit(**INLINED)
def derivative_pairs(s, terms, p):
    """:func:`~uqgear.physics._rhs.derivative` with one dead zone per pair: F = sum k_i f(x - e_i) + c_m* x'.

    The mesh damper acts on x' (every pair deflects at that rate); with
    ``damping_in_separation`` off it stops when no pair is in contact.
    ``terms``: the 18-tuple of :func:`forcing_pairs`.
    """
    stage, offsets = _stage_of(terms)
    d, force, _ = pair_derivative_by(s, stage, offsets, int(terms[PAIR_COUNT]), coefficients(p), divided, NO_INVERSE)
    return d, force


@nb.njit(**INLINED)
def side_derivative_pairs(s, terms, p, apart):
    """:func:`derivative_pairs` with the mesh damping of one side of a contact boundary, whatever x is: off where
    ``apart`` (no pair touching) and the model has no damping in separation, as
    :func:`~uqgear.physics._rhs.side_derivative` for the classical path. With damping in separation this is
    :func:`derivative_pairs`, bit for bit."""
    stage, offsets = _stage_of(terms)
    k, friction, drive, ste_acc = stage
    c = coefficients(p)
    elastic, sliding, _ = _pair_sums(s[2], k, friction, offsets, int(terms[PAIR_COUNT]), c[0])
    d, force, _ = _accelerations(
        s, elastic, sliding, drive, ste_acc, c, 1.0, mesh_damping(c, apart), divided, NO_INVERSE
    )
    return d, force


@nb.njit(**INLINED)
def _pairs_side_field(s, terms, context, divide):
    """:func:`side_derivative_pairs` as a field of :func:`~uqgear.physics._stepper.rk4_stages`: ``context``
    (parameters, apart)."""
    p, apart = context
    d, _ = side_derivative_pairs(s, terms, p, apart)
    return d, True


@nb.njit(**INLINED)
def pair_lane_field(s, terms, context, divide):
    """:func:`pair_derivative_by` as a field of :func:`~uqgear.physics._stepper.rk4_stages`: ``terms`` a stage's
    pair terms, ``context`` (pitch offsets of the pair slots, pairs in mesh, coefficients, inverse masses)."""
    offsets, n_pairs, c, inverse = context
    d, _, exact = pair_derivative_by(s, terms, offsets, n_pairs, c, divide, inverse)
    return d, exact


@nb.njit(**INLINED)
def _pairs_field(s, terms, p, divide):
    """:func:`derivative_pairs` as a field of :func:`~uqgear.physics._stepper.rk4_stages`."""
    d, _ = derivative_pairs(s, terms, p)
    return d, True


@nb.njit(**INLINED)
def _changes_contact(x, trial_x, terms, b):
    """Whether some pair in mesh changes its contact region from deflection ``x`` to ``trial_x``."""
    changed = False
    for i in range(int(terms[PAIR_COUNT])):
        offset = terms[PAIR_OFFSET + i]
        changed |= contact_region(x - offset, b) != contact_region(trial_x - offset, b)
    return changed


@nb.njit(**INLINED)
def _apart(x, terms, b):
    """Whether no pair in mesh touches at deflection ``x`` (``terms``: a pair path's forcing 18-tuple)."""
    touching = False
    for i in range(int(terms[PAIR_COUNT])):
        touching |= contact_region(x - terms[PAIR_OFFSET + i], b) != 0
    return not touching


@nb.njit(**INLINED)
def _first_crossing(field, s, d1, trial, end, h, context, split_level, terms):
    """(fraction of the step, boundary level) where the first pair changes its contact state ((2.0, nan) if none):
    the first crossing of the per-pair split (:func:`~uqgear.physics._stepper.split_parts`), on the Hermite
    interpolant of x from x' (s[5]) at the step's ends.

    A boundary a step was split at already (``split_level``) is not split at again: the first part ends
    on the interpolated crossing, a little short of or beyond its own, and the classical path
    (:func:`~uqgear.physics._stepper._split_at_contact`) splits a step once at the boundary it crosses. So
    both paths take the same steps where the pairs' offsets coincide.
    """
    p, _ = context
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
        theta = crossing_fraction(s[2], s[5], trial[2], trial[5], h, offset + level, BISECTIONS)
        if theta < first:
            first = theta
            first_level = offset + level
    return first, first_level


@nb.njit(**INLINED)
def _apart_after(part, before, trial, level, p, terms):
    """Whether no pair touches on the side a step split at boundary ``level`` enters: the side after the split of
    the per-pair path (:func:`~uqgear.physics._stepper.split_parts`). A pair that crosses that boundary over the
    step (from ``before`` to ``trial``) is in the region it enters, the others where ``part`` (ending on the split
    point) puts them."""
    b = p[HALF_BACKLASH]
    x = part[2]
    touching = False
    for i in range(int(terms[PAIR_COUNT])):
        offset = terms[PAIR_OFFSET + i]
        start = contact_region(before[2] - offset, b)
        after = contact_region(trial[2] - offset, b)
        region = contact_region(x - offset, b)
        if start != after:
            crossed, entered = crossed_boundary(start, after, b)
            if offset + crossed == level:
                region = entered
        touching |= region != 0
    return not touching


@nb.njit(**INLINED)
def scheduled_step_pairs(n, j, period, s, p, pair_k, period_k, fp, fg, schedule):
    """:func:`~uqgear.physics._stepper.classical_step` with per-pair deflections (same returns).

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
            start + offsets[sub],
            widths[sub],
            s,
            teeth,
            table,
            sub,
            pairs[sub],
            start + refs[sub],
            p,
            pair_k,
            period_k,
            fp,
            fg,
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
    of its mesh period, ``table``: its schedule's tabulated stages, ``t_ref``: its reference time): one RK4 step
    (one pair set), redone in parts at each pair's contact change.

    The classical path splits once, at |x| = b; here several pairs may change state within a step, so the
    remainder is checked again (at most ``2 MAX_PAIRS`` splits: each pair has two boundaries), each boundary
    once, by :func:`~uqgear.physics._stepper.split_parts` (:func:`_first_crossing`, :func:`_apart_after`).
    Each part runs on the mesh damping of its own side (:func:`side_derivative_pairs`), as the classical
    split does (:func:`~uqgear.physics._stepper._split_at_contact`): without damping in separation the
    damping force switches where the last pair leaves contact, and a stage on the other side's damping
    costs an error of the order of the step at every crossing. The crossing is then located on the step
    taken on the first side's damping throughout. With damping in separation both sides' damping is the
    same and the parts are the plain RK4 steps, bit for bit; a step that changes no pair's contact is the
    plain RK4 step on either model, as in the pair lanes.

    Returns (new state, first RK4 stage, mesh force at the start). The one-sample pair step, also
    what a pair lane's redone sub-step is (:mod:`uqgear.physics._pair_lanes`).
    """
    terms = _forcing_row_pairs(t, teeth, table, sub, 0, n_pairs, p)
    d1, force = derivative_pairs(s, terms, p)
    mid = _forcing_row_pairs(t + 0.5 * h, teeth, table, sub, 1, n_pairs, p)
    end = _forcing_row_pairs(t + h, teeth, table, sub, 2, n_pairs, p)
    trial = rk4_by(_pairs_field, s, h, d1, mid, end, p)
    b = p[HALF_BACKLASH]
    if not _changes_contact(s[2], trial[2], terms, b):
        return trial, d1, force
    apart = _apart(s[2], terms, b)
    if p[DAMP_IN_SEPARATION] == 0.0:
        trial = rk4_by(_pairs_side_field, s, h, d1, mid, end, (p, apart))
    new = split_parts(
        _pairs_side_field, forcing_pairs, _first_crossing, _apart_after, 2 * MAX_PAIRS, False, p, apart, t, h, s,
        d1, trial, end, terms, (t_ref, p, pair_k, period_k, fp, fg),
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
    "pair_derivative_by",
    "pair_lane_field",
    "scheduled_step_pairs",
    "substep_pairs",
    "pair_contact",
    "pair_offset",
    "pair_state",
]
