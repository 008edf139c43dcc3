"""Compiled kernels of the speed-varying (run-up, coast-down) model: the forcing at the pinion angle.

The mesh-periodic forcing is evaluated at the warped time
tau(t) = z1 theta1(t) / Omega_ref (docs/model/run-up.md section 11.1): the mesh phase, the
pairs in contact, the Ishikawa stiffness, the STE, the run-out and the torque
ripple follow the pinion angle, and the STE's acceleration takes the chain
rule e'' = e_tautau tau'^2 + e_tau tau''. The adhesion oscillation keeps its
own clock, physical time t.

The fast path steps in tau, not in t: a uniform grid of ``steps_per_period``
steps per mesh period puts the stiffness breakpoints on the same sub-steps as
the constant-speed schedule (:func:`uqgear.physics._stepper.build_schedule`),
and the state's derivative in tau is its time derivative over tau'. The
physical time at a given tau comes from knots once per mesh period (t, tau',
tau''), cubic Hermite in between. Outputs at uniform physical times are the
step's cubic Hermite interpolant in tau, with the right-hand side evaluated
there.

These helpers inline the ones of :mod:`uqgear.physics._rhs` and
:mod:`uqgear.physics._stepper`: the accelerations, the time terms at the
angle's clock, the RK4 step (:func:`~uqgear.physics._stepper.rk4_by`) and the
contact split (:func:`~uqgear.physics._stepper.split_step`) are the
constant-speed model's, given the warped field and forcing; the module is one of the compiled modules of
:mod:`uqgear.physics._cache`, so a cached kernel follows their edits.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from uqgear.physics._rhs import (
    ECC_KAPPA,
    ECC_OMEGA,
    ECC_PHASE,
    HALF_BACKLASH,
    INLINED,
    JIT_OPTIONS,
    NO_INVERSE,
    OMEGA_MESH,
    STE_PHASE,
    STIFFNESS_SCALE,
    TOOTH_FACTORS,
    _accelerations,
    _friction_term,
    coefficients,
    contact_region,
    dead_zone,
    divided,
    drive_acceleration,
    mesh_damping,
    mesh_ste,
    mesh_terms,
    run_out_modulation,
    state_derivative_by,
    ste_terms,
)
from uqgear.physics._stepper import F_ARM_GEAR, F_ARM_PINION, F_K, F_SINE, rk4_by, split_step, tooth_extra

#: Region code of :func:`warped_field` for "the mesh damping from x itself".
FROM_X = 2


@nb.njit(**INLINED)
def warp(tau, n, period, knot_t, knot_rate, knot_accel):
    """(t, tau', tau'') at warped time ``tau`` in mesh period ``n`` from the period's knots.

    t(tau) is the cubic Hermite with the knots' dt/dtau = 1 / tau' (exact to
    the ramp's fourth derivative over one mesh period); tau' its derivative's
    inverse; tau'' linear between the knots.
    """
    u = (tau - n * period) / period
    t0 = knot_t[n]
    t1 = knot_t[n + 1]
    m0 = period / knot_rate[n]
    m1 = period / knot_rate[n + 1]
    u2 = u * u
    u3 = u2 * u
    t = (2 * u3 - 3 * u2 + 1) * t0 + (u3 - 2 * u2 + u) * m0 + (-2 * u3 + 3 * u2) * t1 + (u3 - u2) * m1
    slope = (
        (6 * u2 - 6 * u) * t0 + (3 * u2 - 4 * u + 1) * m0 + (-6 * u2 + 6 * u) * t1 + (3 * u2 - 2 * u) * m1
    ) / period
    accel = knot_accel[n] * (1.0 - u) + knot_accel[n + 1] * u
    return t, 1.0 / slope, accel


@nb.njit(**INLINED)
def chain_rule(ste_tau, ste_tautau, rate, accel):
    """e'' = e_tautau tau'^2 + e_tau tau'' (the one expression of the STE's acceleration)."""
    return ste_tautau * (rate * rate) + ste_tau * accel


@nb.njit(**INLINED)
def time_part(tau, t, rate, accel, sine, cosine, p):
    """(relative drive acceleration, e, e'') of the angle-driven model.

    ``sine``/``cosine`` of Omega_ref tau + STE phase. Torque ripple and run-out
    follow the shaft angles (tau); the adhesion oscillation its own clock (t): the constant-speed
    model's time terms (:func:`~uqgear.physics._rhs.drive_acceleration`,
    :func:`~uqgear.physics._rhs.ste_terms`) at the angle's clock, with
    e'' = e_tautau tau'^2 + e_tau tau'' (chain rule).
    """
    ste, ste_tau, ste_tautau = ste_terms(tau, sine, cosine, p)
    return drive_acceleration(tau, t, p), ste, chain_rule(ste_tau, ste_tautau, rate, accel)


@nb.njit(**INLINED)
def _terms(tau, t, rate, accel, sine, cosine, k, arm_pinion, arm_gear, p):
    """Forcing 6-tuple (k, friction term, drive, e'', 1 / tau', e) from scaled pair sums."""
    drive, ste, ste_acc = time_part(tau, t, rate, accel, sine, cosine, p)
    return (k, _friction_term(arm_pinion, arm_gear, p), drive, ste_acc, 1.0 / rate, ste)


@nb.njit(**INLINED)
def warped_forcing(tau, tau_ref, n, period, warps, p, pair_k, period_k, fp, fg):
    """Forcing 6-tuple at any warped time ``tau`` in mesh period ``n``, pairs those at ``tau_ref``."""
    knot_t, knot_rate, knot_accel = warps
    k, arm_pinion, arm_gear = mesh_terms(tau, tau_ref, p, pair_k, period_k, fp, fg)
    t, rate, accel = warp(tau, n, period, knot_t, knot_rate, knot_accel)
    angle = p[OMEGA_MESH] * tau + p[STE_PHASE]
    return _terms(tau, t, rate, accel, math.sin(angle), math.cos(angle), k, arm_pinion, arm_gear, p)


@nb.njit(**INLINED)
def table_forcing(tau, local, n, period, warps, table, sub, stage, n_pairs, p, fp, fg):
    """:func:`warped_forcing` from a tabulated stage (``local``: tau within the period)."""
    knot_t, knot_rate, knot_accel = warps
    t, rate, accel = warp(tau, n, period, knot_t, knot_rate, knot_accel)
    cosine = math.cos(p[OMEGA_MESH] * local + p[STE_PHASE])
    return table_terms(tau, n, t, rate, accel, cosine, table, sub, stage, n_pairs, p, fp, fg)


@nb.njit(**INLINED)
def table_terms(tau, n, t, rate, accel, cosine, table, sub, stage, n_pairs, p, fp, fg):
    """:func:`table_forcing` given the clock (t, tau', tau'') at ``tau`` (:func:`warp`: the same for every
    run through the profile) and cos(Omega_ref local + STE phase) (the same every mesh period)."""
    k = table[sub, stage, F_K]
    arm_pinion = table[sub, stage, F_ARM_PINION]
    arm_gear = table[sub, stage, F_ARM_GEAR]
    if p[TOOTH_FACTORS] != 0.0:
        for i in range(n_pairs):
            extra = tooth_extra(n - i, p, fp, fg)
            k += table[sub, stage, 4 + 3 * i] * extra
            arm_pinion += table[sub, stage, 5 + 3 * i] * extra
            arm_gear += table[sub, stage, 6 + 3 * i] * extra
    scale = run_out_modulation(tau, p[STIFFNESS_SCALE], p[ECC_KAPPA], p[ECC_OMEGA], p[ECC_PHASE])
    sine = table[sub, stage, F_SINE]
    return _terms(tau, t, rate, accel, sine, cosine, k * scale, arm_pinion * scale, arm_gear * scale, p)


@nb.njit(**INLINED)
def warped_field(s, terms, context, divide):
    """ds/dtau = (ds/dt) / tau' as a field of :func:`rk4_stages`; ``context`` (coefficients, region):
    region 1, 0, -1 takes that side's mesh damping, :data:`FROM_X` the damping x itself implies."""
    c, region = context
    fx = dead_zone(s[2], c[0])
    apart = (fx == 0.0) if region == FROM_X else (region == 0)
    d, _, exact = _accelerations(
        s, terms[0], terms[1], terms[2], terms[3], c, fx, mesh_damping(c, apart), divide, NO_INVERSE
    )
    w = terms[4]
    return (d[0] * w, d[1] * w, d[2] * w, d[3] * w, d[4] * w, d[5] * w), exact


@nb.njit(**INLINED)
def lane_field(s, terms, context, divide):
    """:func:`warped_field` with the mesh damping x implies, as a field of :func:`rk4_stages` for the
    lanes: ``context`` (coefficients, the inverse masses ``divide`` reads), ``terms`` (k, friction
    term, drive, e'', 1 / tau')."""
    c, inverse = context
    d, _, exact = state_derivative_by(s, terms[0], terms[1], terms[2], terms[3], c, divide, inverse)
    w = terms[4]
    return (d[0] * w, d[1] * w, d[2] * w, d[3] * w, d[4] * w, d[5] * w), exact


@nb.njit(**INLINED)
def _rk4(s, h, d1, mid, end, c, region):
    """One RK4 step in warped time (:func:`~uqgear.physics._stepper.rk4_by` with :func:`warped_field`)."""
    return rk4_by(warped_field, s, h, d1, mid, end, (c, region))


@nb.njit(**JIT_OPTIONS)
def split_at_contact(tau, h, s, d1, trial, tau_ref, n, period, warps, p, pair_k, period_k, fp, fg):
    """``trial`` redone in two parts where it changes the contact region: the constant-speed path's
    :func:`~uqgear.physics._stepper.split_step`, in warped time (:func:`warped_field`, :func:`warped_forcing`)."""
    return split_step(
        warped_field, warped_forcing, coefficients(p), tau, h, s, d1, trial, tau_ref, n, period, warps, p, pair_k,
        period_k, fp, fg,
    )


@nb.njit(**INLINED)
def _hermite(s0, d0, s1, d1, h, u):
    """Cubic Hermite of the state tuple over a step of length ``h`` at fraction ``u``."""
    u2 = u * u
    u3 = u2 * u
    a = 2 * u3 - 3 * u2 + 1
    bh = (u3 - 2 * u2 + u) * h
    c = -2 * u3 + 3 * u2
    dh = (u3 - u2) * h
    return (
        a * s0[0] + bh * d0[0] + c * s1[0] + dh * d1[0],
        a * s0[1] + bh * d0[1] + c * s1[1] + dh * d1[1],
        a * s0[2] + bh * d0[2] + c * s1[2] + dh * d1[2],
        a * s0[3] + bh * d0[3] + c * s1[3] + dh * d1[3],
        a * s0[4] + bh * d0[4] + c * s1[4] + dh * d1[4],
        a * s0[5] + bh * d0[5] + c * s1[5] + dh * d1[5],
    )


@nb.njit(**INLINED)
def record_row(s, terms, p, row):
    """One history row (y1, y2, x, v1, v2, vx, a1, a2, F, k, e, contact) in physical time."""
    c = coefficients(p)
    fx = dead_zone(s[2], c[0])
    d, force, _ = _accelerations(
        s, terms[0], terms[1], terms[2], terms[3], c, fx, mesh_damping(c, fx == 0.0), divided, NO_INVERSE
    )
    for j in range(6):
        row[j] = s[j]
    row[6] = d[3]
    row[7] = d[4]
    row[8] = force
    row[9] = terms[0]
    row[10] = terms[5]
    row[11] = contact_region(s[2], p[HALF_BACKLASH])


@nb.njit(**JIT_OPTIONS)
def runup_rhs(tau, tau_ref, t, rate, accel, state, p, pair_k, period_k, fp, fg, row):
    """The physical-time right-hand side at (t, tau(t)) given tau' and tau'' (the scipy reference's):
    writes a history row into ``row`` (its derivative in row[3:6], row[6:8] the accelerations)."""
    k, arm_pinion, arm_gear = mesh_terms(tau, tau_ref, p, pair_k, period_k, fp, fg)
    angle = p[OMEGA_MESH] * tau + p[STE_PHASE]
    terms = _terms(tau, t, rate, accel, math.sin(angle), math.cos(angle), k, arm_pinion, arm_gear, p)
    s = (state[0], state[1], state[2], state[3], state[4], state[5])
    record_row(s, terms, p, row)
    c = coefficients(p)
    fx = dead_zone(s[2], c[0])
    d, _, _ = _accelerations(
        s, terms[0], terms[1], terms[2], terms[3], c, fx, mesh_damping(c, fx == 0.0), divided, NO_INVERSE
    )
    return d


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_runup(state0, p, pair_k, period_k, fp, fg, schedule, period, first, stop, warps, out_tau, o, history):
    """Integrate a run in warped time over mesh periods ``first`` to ``stop - 1`` from ``state0``, recording
    ``history`` rows at the warped times ``out_tau`` from index ``o`` on (increasing, within the span).

    ``schedule`` from :func:`uqgear.physics._stepper.build_schedule` at the reference speed (its steps
    per period hold for these periods); ``warps`` = (knot t, knot tau', knot tau''), one knot per mesh
    period start. Returns (final state as an array, index of the next output).
    """
    first_sub, offsets, widths, refs, pairs, table = schedule
    s = (state0[0], state0[1], state0[2], state0[3], state0[4], state0[5])
    c = coefficients(p)
    b = p[HALF_BACKLASH]
    steps = first_sub.size - 1
    n_out = out_tau.size
    for n in range(first, stop):
        start = n * period
        for j in range(steps):
            for sub in range(first_sub[j], first_sub[j + 1]):
                local = offsets[sub]
                h = widths[sub]
                tau = start + local
                count = pairs[sub]
                f0 = table_forcing(tau, local, n, period, warps, table, sub, 0, count, p, fp, fg)
                f1 = table_forcing(tau + 0.5 * h, local + 0.5 * h, n, period, warps, table, sub, 1, count, p, fp, fg)
                f2 = table_forcing(tau + h, local + h, n, period, warps, table, sub, 2, count, p, fp, fg)
                d1, _ = warped_field(s, f0, (c, FROM_X), divided)
                new = _rk4(s, h, d1, f1, f2, c, FROM_X)
                if contact_region(s[2], b) != contact_region(new[2], b):
                    new = split_at_contact(
                        tau, h, s, d1, new, start + refs[sub], n, period, warps, p, pair_k, period_k, fp, fg
                    )
                # an output on a sub-step's end (to round-off) goes to the next one, which holds the
                # pairs in mesh just after it (as the constant-speed histories)
                edge = tau + h - 1e-9 * period
                if o < n_out and out_tau[o] < edge:
                    d_end, _ = warped_field(new, f2, (c, FROM_X), divided)
                    while o < n_out and out_tau[o] < edge:
                        u = (out_tau[o] - tau) / h
                        at = _hermite(s, d1, new, d_end, h, u)
                        terms = warped_forcing(
                            out_tau[o], start + refs[sub], n, period, warps, p, pair_k, period_k, fp, fg
                        )
                        record_row(at, terms, p, history[o])
                        o += 1
                s = new
    final = np.empty(6)
    for j in range(6):
        final[j] = s[j]
    return final, o


__all__ = [
    "FROM_X",
    "warp",
    "mesh_ste",
    "chain_rule",
    "time_part",
    "warped_forcing",
    "table_forcing",
    "table_terms",
    "lane_field",
    "warped_field",
    "split_at_contact",
    "record_row",
    "runup_rhs",
    "integrate_runup",
]
