"""Time stepping of the fast path, compiled with numba: RK4 stages, contact splits, one mesh period tabulated.

Classical RK4 on a uniform grid of ``N`` steps per mesh period, so Poincare
samples fall on grid points. Two kinds of non-smoothness are located instead
of stepped over:

* mesh-stiffness jumps (a pair enters at mesh phase 0, leaves at frac(eps);
  the friction force reverses at the pitch point) happen at known phases: a
  step containing one is split there, and the set of pairs in contact is
  taken from the sub-step's midpoint (``t_ref``), so each sub-step sees a
  smooth stiffness;
* contact boundaries |x| = b depend on the state: when a step changes the
  contact region, the crossing is located on the step's cubic Hermite
  interpolant (one bisection, :func:`crossing_fraction`) and the step is
  redone in two parts.

Every integrator of the package takes its RK4 step from :func:`rk4_by_weighted`
(the stages of :func:`rk4_stages`, combined), given its right-hand side from
:mod:`uqgear.physics._rhs` as a compiled function, and its contact split from
:func:`split_parts`, the one control flow of a split, given the path's rules as
compiled functions (:func:`split_step` splits once at the one boundary; the
per-pair path splits at each pair's boundaries in turn; the variational pass
keeps its own split, which carries its matrix through the parts). These helpers
are inlined into kernels in other files: a cached kernel is keyed on the
contents of every compiled module of the package (:mod:`uqgear.physics._cache`),
so editing this one recompiles them all.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from uqgear.physics._rhs import (
    CONTACT_RATIO,
    ECC_KAPPA,
    ECC_OMEGA,
    ECC_PHASE,
    HALF_BACKLASH,
    INLINED,
    JIT_OPTIONS,
    MAX_PAIRS,
    NO_INVERSE,
    OMEGA_MESH,
    STE_PHASE,
    STIFFNESS_SCALE,
    TOOTH_FACTORS,
    TWO_PI,
    USE_PERIOD_TABLE,
    _friction_arms,
    _friction_term,
    _interp_uniform,
    _mesh_position,
    _time_terms,
    coefficients,
    contact_region,
    derivative,
    divided,
    forcing,
    run_out_modulation,
    side_derivative,
    state_derivative_by,
    table_stiffness,
    tooth_factor,
)


@nb.njit(**INLINED)
def _shifted(s, h, d):
    return (s[0] + h * d[0], s[1] + h * d[1], s[2] + h * d[2], s[3] + h * d[3], s[4] + h * d[4], s[5] + h * d[5])


@nb.njit(**INLINED)
def rk4_combine_weighted(s, w, d1, d2, d3, d4):
    """The classical RK4 update of ``s`` from its four stage derivatives, with the weight w = h / 6 given."""
    return (
        s[0] + w * (d1[0] + 2.0 * d2[0] + 2.0 * d3[0] + d4[0]),
        s[1] + w * (d1[1] + 2.0 * d2[1] + 2.0 * d3[1] + d4[1]),
        s[2] + w * (d1[2] + 2.0 * d2[2] + 2.0 * d3[2] + d4[2]),
        s[3] + w * (d1[3] + 2.0 * d2[3] + 2.0 * d3[3] + d4[3]),
        s[4] + w * (d1[4] + 2.0 * d2[4] + 2.0 * d3[4] + d4[4]),
        s[5] + w * (d1[5] + 2.0 * d2[5] + 2.0 * d3[5] + d4[5]),
    )


@nb.njit(**INLINED)
def rk4_combine(s, h, d1, d2, d3, d4):
    """The classical RK4 update of ``s`` over ``h`` from its four stage derivatives."""
    return rk4_combine_weighted(s, h / 6.0, d1, d2, d3, d4)


@nb.njit(**INLINED)
def rk4_stages(field, divide, s, h, d1, mid, end, context):
    """The later stage derivatives d2, d3, d4 of the classical RK4 step from ``s`` over ``h`` given its first
    stage ``d1``: the one stage sequence of every integrator of the package.

    ``field(state, terms, context, divide)`` is the right-hand side, returning (ds/dt, whether its
    quotients are exact); ``mid`` and ``end`` are its forcing terms at the step's midpoint and end;
    ``divide`` the quotient function (:func:`state_derivative_by`). Each caller passes its own field
    (classical, one side's damping, per pair, lanes, the variational pass), specialised and inlined at
    compile time. Returns (d2, d3, d4, whether every quotient of these stages is exact).
    """
    d2, exact2 = field(_shifted(s, 0.5 * h, d1), mid, context, divide)
    d3, exact3 = field(_shifted(s, 0.5 * h, d2), mid, context, divide)
    d4, exact4 = field(_shifted(s, h, d3), end, context, divide)
    return d2, d3, d4, exact2 & exact3 & exact4


@nb.njit(**INLINED)
def _classical_field(s, terms, p, divide):
    """:func:`derivative` as a field of :func:`rk4_stages` (``terms`` from :func:`forcing`)."""
    d, _ = derivative(s, terms, p)
    return d, True


@nb.njit(**INLINED)
def _table_field(s, terms, context, divide):
    """:func:`state_derivative_by` as a field of :func:`rk4_stages`: ``terms`` a forcing 4-tuple (k, friction
    term, drive, e''), ``context`` (:func:`coefficients`, the inverse masses ``divide`` reads)."""
    c, inverse = context
    d, _, exact = state_derivative_by(s, terms[0], terms[1], terms[2], terms[3], c, divide, inverse)
    return d, exact


@nb.njit(**INLINED)
def _side_field(s, terms, context, divide):
    """:func:`side_derivative` as a field of :func:`rk4_stages`: ``context`` (:func:`coefficients`, region)."""
    c, region = context
    d, _ = side_derivative(s, terms[0], terms[1], terms[2], terms[4], c, region)
    return d, True


@nb.njit(**INLINED)
def rk4_by_weighted(field, divide, s, h, w, d1, mid, end, context):
    """One classical RK4 step from ``s`` over ``h`` with first stage ``d1``, the weight w = h / 6 given: the
    stages of :func:`rk4_stages` with ``field`` and ``context``, combined. The one RK4 step of every
    integrator of the package. Returns (new state, whether every quotient of the later stages is exact)."""
    d2, d3, d4, exact = rk4_stages(field, divide, s, h, d1, mid, end, context)
    return rk4_combine_weighted(s, w, d1, d2, d3, d4), exact


@nb.njit(**INLINED)
def rk4_by(field, s, h, d1, mid, end, context):
    """:func:`rk4_by_weighted` with IEEE divisions and w = h / 6: the new state. (The same two calls, not a
    call of it: each level of inlined helpers is one more optimisation of the inlined body at compile
    time.)"""
    d2, d3, d4, _ = rk4_stages(field, divided, s, h, d1, mid, end, context)
    return rk4_combine_weighted(s, h / 6.0, d1, d2, d3, d4)


@nb.njit(**INLINED)
def _rk4(s, h, d1, mid, end, p):
    """One classical RK4 step from ``s`` with first stage ``d1`` and the forcing at the midpoint and end."""
    return rk4_by(_classical_field, s, h, d1, mid, end, p)


@nb.njit(**INLINED)
def rk4_step_weighted(s, h, w, d1, mid, end, c, divide, inverse):
    """:func:`_rk4` from forcing 4-tuples (k, friction term, drive, e''), :func:`coefficients`, w = h / 6 and a
    quotient function (:func:`state_derivative_by`). Returns (new state, whether every quotient is exact)."""
    return rk4_by_weighted(_table_field, divide, s, h, w, d1, mid, end, (c, inverse))


@nb.njit(**INLINED)
def rk4_step(s, h, d1, mid, end, c):
    """:func:`_rk4` from forcing 4-tuples (k, friction term, drive, e'') and :func:`coefficients`."""
    new, _ = rk4_step_weighted(s, h, h / 6.0, d1, mid, end, c, divided, NO_INVERSE)
    return new


#: A contact crossing closer than this fraction of a step to either end is not split at: the parts
#: would be too short to gain anything over the unsplit step.
SPLIT_MARGIN = 1e-9


@nb.njit(**INLINED)
def splits_step(theta):
    """Whether a step is split at the crossing fraction ``theta`` (:data:`SPLIT_MARGIN`)."""
    return SPLIT_MARGIN < theta < 1.0 - SPLIT_MARGIN


#: Bisection steps of a contact crossing on a step's Hermite interpolant: 2^-40 of a step, far below
#: the step's own error.
BISECTIONS = 40


@nb.njit(**JIT_OPTIONS)
def crossing_fraction(x0, v0, x1, v1, h, level, iterations):
    """Fraction of a step where the cubic Hermite interpolant of x reaches ``level``, by ``iterations``
    bisection steps: the one bisection of every split step (the fast path's, the per-pair path's and
    the variational pass's)."""
    lo = 0.0
    hi = 1.0
    g_lo = x0 - level
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        s = mid
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = s**3 - 2 * s**2 + s
        h01 = -2 * s**3 + 3 * s**2
        h11 = s**3 - s**2
        value = h00 * x0 + h10 * h * v0 + h01 * x1 + h11 * h * v1 - level
        if (value > 0.0) == (g_lo > 0.0):
            lo = mid
            g_lo = value
        else:
            hi = mid
    return 0.5 * (lo + hi)


@nb.njit(**INLINED)
def _rk4_side(s, h, d1, mid, end, p, region):
    """:func:`_rk4` with the later stages on the mesh damping of contact region ``region`` (:func:`side_derivative`)."""
    return rk4_by(_side_field, s, h, d1, mid, end, (coefficients(p), region))


@nb.njit(**INLINED)
def crossed_boundary(before, after, b):
    """(boundary level, region entered) of a step from contact region ``before`` to ``after``.

    The level is that of the boundary next to the side the step leaves; the region entered is the
    one just beyond it (a step from one contact side to the other enters separation first).
    """
    if before == 1 or (before == 0 and after == -1):
        level = b if before == 1 else -b
    else:
        level = -b if before == -1 else b
    entered = 0 if before != 0 else (1 if level > 0.0 else -1)
    return level, entered


# inlined by numba (its IR copied into the caller) rather than by LLVM: each path calls it once, and its loop is
# then compiled in the caller alone, not also as a function of its own (the one-run and pair kernels compile
# as fast as with the loop written in each path); numba's inliner takes no star argument, hence ``model``
# as a tuple
@nb.njit(**JIT_OPTIONS, inline="always")
def split_parts(field, forcing_at, first_crossing, side_after, splits, same_end, fc, side, t, h, s, d1, trial, end,
                rules, model):
    """``trial`` (the step from ``s`` over [t, t+h] on the mesh damping of contact side ``side``), redone in
    parts at its contact crossings, at most ``splits`` of them: the one control flow of every contact split
    of the fast path (one boundary, :func:`split_step`; several pairs, each with its own boundaries,
    :func:`uqgear.physics._pairs.substep_pairs`).

    ``field(state, terms, (fc, side), divide)`` is the right-hand side with the mesh damping of
    contact side ``side`` whatever x is, ``forcing_at(time, *model)`` its forcing terms at any time
    (``model`` a tuple), ``d1`` the field at ``s`` and ``end`` the forcing at the end of ``trial``.
    The path's rules, given as compiled functions and specialised at compile time:

    * ``first_crossing(field, s, d1, trial, end, h, (fc, side), done, rules)``: (fraction of the step,
      boundary level) of the first crossing on the step's cubic Hermite interpolant, not at the
      boundary ``done`` split at already (NaN before the first split); a fraction outside
      :func:`splits_step` ends the splitting;
    * ``side_after(part, s, trial, level, fc, rules)``: the contact side the step enters at the
      split at ``level`` (``part`` ends on the split point, ``trial`` is the step split).

    The remaining step [t, t+h] after a split ends where the step ends: where ``same_end`` is true its
    forcing there is ``end``, else it is computed again at t + h (a flag, not a function: one compiled
    function less per path, and a constant the compiler folds).

    Each part runs on the mesh damping of its own side, the remainder from the field at the split
    point on the side it enters. The variational pass (:func:`uqgear.physics._variational._substep`)
    keeps its own split: it carries the 6 x 6 matrix Phi through every stage of each part in place
    (restored from a copy when the step is redone), applies the saltation matrix's jump in the mesh
    damping between the parts, adds the derivative of the split point's position
    (:func:`uqgear.physics._variational._crossing_sensitivity`, two more two-part steps from the
    unsplit step's rows of Phi), locates its crossing more finely and records each part's extremes;
    this driver carries the state alone.
    """
    level = math.nan
    for _ in range(splits):
        theta, level = first_crossing(field, s, d1, trial, end, h, (fc, side), level, rules)
        if not splits_step(theta):
            return trial
        h_a = theta * h
        middle = forcing_at(t + h_a, *model)
        part = rk4_by(field, s, h_a, d1, forcing_at(t + 0.5 * h_a, *model), middle, (fc, side))
        side = side_after(part, s, trial, level, fc, rules)
        s = part
        t += h_a
        h -= h_a
        d1, _ = field(s, middle, (fc, side), divided)
        if not same_end:
            end = forcing_at(t + h, *model)
        trial = rk4_by(field, s, h, d1, forcing_at(t + 0.5 * h, *model), end, (fc, side))
    return trial


@nb.njit(**INLINED)
def _boundary_crossing(field, s, d1, trial, end, h, context, done, rules):
    """The first crossing of :func:`split_step`: at the boundary level ``rules`` gives, on the Hermite
    interpolant of x from its slopes at the step's ends (the field's: x' in time, dx/dtau in warped time)."""
    level = rules[0]
    d_end, _ = field(trial, end, context, divided)
    return crossing_fraction(s[2], d1[2], trial[2], d_end[2], h, level, BISECTIONS), level


@nb.njit(**INLINED)
def _entered_region(part, s, trial, level, c, rules):
    """The side after the split of :func:`split_step`: the region entered, which ``rules`` gives."""
    return rules[1]


@nb.njit(**INLINED)
def split_step(field, forcing_at, c, t, h, s, d1, trial, *model):
    """``trial`` (the step from ``s`` over [t, t+h]), redone in two parts where it changes the
    contact region, split where the cubic Hermite interpolant of x crosses the boundary: the
    contact split of every integrator with one contact boundary, one split by :func:`split_parts`
    (the per-pair path splits at each pair's boundaries in turn, :func:`uqgear.physics._pairs.substep_pairs`).

    ``field(state, terms, (c, region), divide)`` is the right-hand side with the mesh damping of
    contact region ``region`` whatever x is (:func:`_side_field`; in warped time
    :func:`uqgear.physics._runup_kernels.warped_field`), ``forcing_at(time, *model)`` its forcing
    terms at any time (:func:`forcing`), ``c`` the :func:`coefficients` and ``d1`` the field at
    ``s``. Each part is integrated with the mesh damping of its own side of the boundary, the
    second from the field at the split point on the side the step enters. Without damping in
    separation the damping force switches at the boundary, and a stage evaluated with the other
    side's damping costs an error of the order of the step at every crossing (first-order
    convergence); the crossing is then also located on the step taken with the first side's
    damping throughout, not on ``trial``, whose later stages mix the two sides. With damping in
    separation the vector field is continuous there and both sides' damping is the same: the
    parts are the plain RK4 steps, bit for bit. The boundary and the region entered are those of
    ``trial`` as given.
    """
    b = c[0]
    before = contact_region(s[2], b)
    after = contact_region(trial[2], b)
    if before == after:
        return trial
    level, entered = crossed_boundary(before, after, b)
    end = forcing_at(t + h, *model)
    if c[2] == 0.0:
        trial = rk4_by(field, s, h, d1, forcing_at(t + 0.5 * h, *model), end, (c, before))
    return split_parts(
        field, forcing_at, _boundary_crossing, _entered_region, 1, True, c, before, t, h, s, d1, trial, end,
        (level, entered), model,
    )


@nb.njit(**JIT_OPTIONS)
def _split_at_contact(t, h, s, d1, trial, t_ref, p, pair_k, period_k, fp, fg):
    """:func:`split_step` of the constant-speed path: ``trial``, the step from ``s`` over [t, t+h] with first
    stage ``d1``, redone in two parts where it changes the contact region (pairs in mesh as at ``t_ref``)."""
    return split_step(_side_field, forcing, coefficients(p), t, h, s, d1, trial, t_ref, p, pair_k, period_k, fp, fg)


# ---------------------------------------------------------------- one mesh period tabulated
# fields of a tabulated stage: healthy k, friction arm sums, sin(omega t + STE phase), then
# per pair in contact its healthy stiffness and friction arms (for tooth factors); with a smooth
# table, k is the table's and each pair's fields are its share of it (smooth_share)
(F_K, F_ARM_PINION, F_ARM_GEAR, F_SINE) = range(4)
N_FIELDS = 4 + 3 * MAX_PAIRS


@nb.njit(**JIT_OPTIONS)
def _tabulate_stage(t, t_ref, p, pair_k, period_k, row):
    """The mesh-periodic forcing at local time ``t`` (first mesh period) into ``row``; returns the pair count."""
    _, u_ref, u = _mesh_position(t, t_ref, p)
    eps = p[CONTACT_RATIO]
    k = 0.0
    arm_pinion = 0.0
    arm_gear = 0.0
    i = 0
    while u_ref + i < eps:
        if i >= MAX_PAIRS:
            raise ValueError("more tooth pairs in contact than a schedule holds")
        kp = _interp_uniform(pair_k, u + i, eps)
        pinion, gear = _friction_arms(kp, u + i, u_ref + i, p)
        row[4 + 3 * i] = kp
        row[5 + 3 * i] = pinion
        row[6 + 3 * i] = gear
        k += kp
        arm_pinion += pinion
        arm_gear += gear
        i += 1
    if p[USE_PERIOD_TABLE] != 0.0:
        # the smooth curve, each pair its share of it (smooth_share's rule, r = k(t) / the pairs' sum, from the
        # sum just taken): what tooth factors and friction act on
        smooth = table_stiffness(t, p, period_k)
        ratio = smooth / k
        k = smooth
        arm_pinion = 0.0
        arm_gear = 0.0
        for j in range(i):
            row[4 + 3 * j] *= ratio
            row[5 + 3 * j] *= ratio
            row[6 + 3 * j] *= ratio
            arm_pinion += row[5 + 3 * j]
            arm_gear += row[6 + 3 * j]
    row[F_K] = k
    row[F_ARM_PINION] = arm_pinion
    row[F_ARM_GEAR] = arm_gear
    row[F_SINE] = math.sin(p[OMEGA_MESH] * t + p[STE_PHASE])
    return i


@nb.njit(**JIT_OPTIONS)
def build_schedule(p, pair_k, period_k, breakpoints, steps_per_period):
    """Sub-steps of one mesh period and their forcing at RK4's three stage times.

    Everything in the forcing that repeats every mesh period (pair
    stiffnesses, friction arms, the STE phase) is evaluated here once per
    run instead of three times per step; the effect slots that do not repeat
    (run-out, tooth factors, torque ripple, adhesion oscillation) are applied
    on top in :func:`_forcing_row`. Grid step ``j`` of any period is made of
    sub-steps ``first_sub[j]`` to ``first_sub[j + 1] - 1`` (split at the
    stiffness breakpoints exactly as the generic stepping would).

    Returns
    -------
    first_sub, offsets, widths, refs, pairs, table
        ``offsets``/``widths``/``refs``: sub-step start, length and reference
        time (its midpoint) within the period; ``pairs``: pairs in contact;
        ``table``: (sub-step, stage, field) forcing values.
    """
    period = TWO_PI / p[OMEGA_MESH]
    h = period / steps_per_period
    capacity = steps_per_period * (breakpoints.size + 1)
    offsets = np.empty(capacity)
    widths = np.empty(capacity)
    refs = np.empty(capacity)
    pairs = np.empty(capacity, dtype=np.int64)
    table = np.zeros((capacity, 3, N_FIELDS))
    first_sub = np.empty(steps_per_period + 1, dtype=np.int64)
    du = p[OMEGA_MESH] * h / TWO_PI
    count = 0
    for j in range(steps_per_period):
        first_sub[j] = count
        t_now = j * h
        end = (j + 1) * h
        cycles0 = p[OMEGA_MESH] * t_now / TWO_PI
        base = math.floor(cycles0 + 1e-9)
        u0 = cycles0 - base
        for bp in breakpoints:
            if u0 + 1e-12 < bp < u0 + du - 1e-12:
                t_break = (base + bp) * TWO_PI / p[OMEGA_MESH]
                count = _add_substep(t_now, t_break, count, p, pair_k, period_k, offsets, widths, refs, pairs, table)
                t_now = t_break
        count = _add_substep(t_now, end, count, p, pair_k, period_k, offsets, widths, refs, pairs, table)
    first_sub[steps_per_period] = count
    return first_sub, offsets, widths, refs, pairs, table


@nb.njit(**JIT_OPTIONS)
def _add_substep(start, end, count, p, pair_k, period_k, offsets, widths, refs, pairs, table):
    t_ref = 0.5 * (start + end)
    offsets[count] = start
    widths[count] = end - start
    refs[count] = t_ref
    pairs[count] = _tabulate_stage(start, t_ref, p, pair_k, period_k, table[count, 0])
    _tabulate_stage(0.5 * (start + end), t_ref, p, pair_k, period_k, table[count, 1])
    _tabulate_stage(end, t_ref, p, pair_k, period_k, table[count, 2])
    return count + 1


@nb.njit(**INLINED)
def _forcing_row(t, n, table, sub, stage, n_pairs, p, factor_pinion, factor_gear):
    """:func:`forcing` at absolute time ``t`` in mesh period ``n`` from a tabulated stage."""
    k = table[sub, stage, F_K]
    arm_pinion = table[sub, stage, F_ARM_PINION]
    arm_gear = table[sub, stage, F_ARM_GEAR]
    if p[TOOTH_FACTORS] != 0.0:
        for i in range(n_pairs):
            extra = tooth_extra(n - i, p, factor_pinion, factor_gear)
            k += table[sub, stage, 4 + 3 * i] * extra
            arm_pinion += table[sub, stage, 5 + 3 * i] * extra
            arm_gear += table[sub, stage, 6 + 3 * i] * extra
    return scaled_forcing(t, k, arm_pinion, arm_gear, table[sub, stage, F_SINE], p)


@nb.njit(**INLINED)
def tooth_extra(tooth, p, factor_pinion, factor_gear):
    """The tooth factors' change of pair stiffness, f_pinion f_gear - 1, of the pair entering in period ``tooth``."""
    return tooth_factor(tooth, p, factor_pinion, factor_gear) - 1.0


@nb.njit(**INLINED)
def scaled_forcing(t, k, arm_pinion, arm_gear, sine, p):
    """:func:`forcing` at ``t`` from the pair sums ``k`` and friction arms (tooth factors applied) and
    sin(omega t + STE phase): the stiffness scale, the run-out's modulation and the time terms."""
    # the slots read here: the modulation takes scalars (run_out_modulation says why)
    scale = run_out_modulation(t, p[STIFFNESS_SCALE], p[ECC_KAPPA], p[ECC_OMEGA], p[ECC_PHASE])
    drive, ste, ste_acc = _time_terms(t, sine, p)
    return k * scale, _friction_term(arm_pinion * scale, arm_gear * scale, p), drive, ste, ste_acc


@nb.njit(**INLINED)
def classical_step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule):
    """Advance the state tuple ``s`` over grid step ``j`` of mesh period ``n`` (no pitch errors).

    ``schedule`` comes from :func:`build_schedule`: the step is split at the
    stiffness breakpoints, and each sub-step, which sees one smooth
    stiffness branch, is split once more where it crosses a contact
    boundary.

    Returns
    -------
    state, force, a1, a2
        The new state tuple, and the mesh force and accelerations of y1, y2
        at the step's start (first RK4 stage).
    """
    first_sub, offsets, widths, refs, pairs, table = schedule
    start = n * period
    force = 0.0
    a1 = 0.0
    a2 = 0.0
    for sub in range(first_sub[j], first_sub[j + 1]):
        t = start + offsets[sub]
        h = widths[sub]
        n_pairs = pairs[sub]
        d1, f = derivative(s, _forcing_row(t, n, table, sub, 0, n_pairs, p, fp, fg), p)
        if sub == first_sub[j]:
            force = f
            a1 = d1[3]
            a2 = d1[4]
        trial = _rk4(
            s,
            h,
            d1,
            _forcing_row(t + 0.5 * h, n, table, sub, 1, n_pairs, p, fp, fg),
            _forcing_row(t + h, n, table, sub, 2, n_pairs, p, fp, fg),
            p,
        )
        if contact_region(s[2], p[HALF_BACKLASH]) == contact_region(trial[2], p[HALF_BACKLASH]):
            s = trial
        else:
            s = _split_at_contact(t, h, s, d1, trial, start + refs[sub], p, pair_k, period_k, fp, fg)
    return s, force, a1, a2


@nb.njit(**INLINED)
def mesh_contact(x, n, n_pairs, p):
    """Contact state (1 drive, 0 apart, -1 back side) of the mesh as a whole: from x alone.

    The signature of :func:`uqgear.physics._pairs.pair_contact`, so that a
    kernel takes either as its contact function.
    """
    return contact_region(x, p[HALF_BACKLASH])
