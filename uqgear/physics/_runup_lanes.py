"""Run-up samples as SIMD lanes: ``LANES`` runs through one speed profile advanced together.

All runs of a run-up batch share the profile, hence the warped-time grid, its
knots (t, tau', tau'') and the output times: runs with the same sub-step layout
(the same bands of steps per mesh period, stiffness tables and breakpoints)
step together as the lanes of :mod:`uqgear.physics._lanes`, in its work array
(:mod:`uqgear.physics._lane_loop`'s rows). A mesh period's forcing (k, friction
term, drive, e'' and 1 / tau' at RK4's three stage times) is filled first, each
lane from the one-run kernel's own :func:`~uqgear.physics._runup_kernels.table_terms`
and the clock evaluated once for all lanes; a sub-step is then one loop over
the lanes, RK4 from the one stage sequence
:func:`~uqgear.physics._stepper.rk4_by_weighted` with the warped field
:func:`~uqgear.physics._runup_kernels.lane_field`, divided by
:func:`~uqgear.physics._quotient.quotient`, compiled into vector instructions
(:func:`~uqgear.physics._lanes.compile_lane_kernel`). A lane whose quotient the
lanes cannot vouch for, or whose step changes its contact region, is finished
by the one-run code (:func:`~uqgear.physics._runup_kernels.split_at_contact`),
and the outputs in a sub-step are the one-run kernel's Hermite rows, lane by
lane: the numbers are those of :func:`~uqgear.physics._runup_kernels.integrate_runup`,
bit for bit.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from uqgear.physics._lane_loop import (
    N_ROWS,
    REDO_NONE,
    REDO_SPLIT,
    REDO_STEP,
    W_REDO,
    W_SLOPE,
    W_STATE,
    W_TRIAL,
    _advance,
    lane_coefficients,
    lane_state,
    put_coefficients,
    put_state,
    put_step,
    region_changed,
    row_of,
)
from uqgear.physics._lane_tables import LANES
from uqgear.physics._lanes import compile_lane_kernel
from uqgear.physics._quotient import quotient
from uqgear.physics._rhs import (
    HALF_BACKLASH,
    INLINED,
    JIT_OPTIONS,
    OMEGA_MESH,
    STE_PHASE,
    T1,
    T2,
    coefficients,
    contact_region,
    divided,
    mesh_ste,
    mesh_terms,
    periodic_forcing,
)
from uqgear.physics._runup_kernels import (
    FROM_X,
    _hermite,
    _rk4,
    _terms,
    chain_rule,
    lane_field,
    record_row,
    split_at_contact,
    table_terms,
    warp,
    warped_field,
)
from uqgear.physics._stepper import F_SINE, rk4_by_weighted

# Fields of a sub-step in the forcing table (field f, lane l at element f * LANES + l of its row):
# (k, friction term, drive, e'', 1 / tau') at each of RK4's three stage times, then the width h
# and h / 6 (RK4's weight, divided once here: the same number as the one-run kernel's).
R_STAGE = 5
R_WIDTH = 3 * R_STAGE
R_WEIGHT = R_WIDTH + 1
N_RUNUP_TABLE = R_WEIGHT + 1


@nb.njit(**INLINED)
def _terms_of(f, stage, lane):
    """A lane's forcing 5-tuple at a stage from its sub-step's table row."""
    first = stage * R_STAGE
    return (
        row_of(f, first, lane),
        row_of(f, first + 1, lane),
        row_of(f, first + 2, lane),
        row_of(f, first + 3, lane),
        row_of(f, first + 4, lane),
    )


@nb.njit(**INLINED)
def _lane_step(W, table, sub, lane):
    """Sub-step ``sub`` of one lane (the one-run kernel's RK4 step); returns 1 if it leaves something
    to the one-run code (``REDO_*`` in ``W``), else 0."""
    s = lane_state(W, W_STATE, lane)
    c, inverse = lane_coefficients(W, lane)
    f = table[sub]
    context = (c, inverse)
    d1, exact = lane_field(s, _terms_of(f, 0, lane), context, quotient)
    new, exact_later = rk4_by_weighted(
        lane_field, quotient, s, row_of(f, R_WIDTH, lane), row_of(f, R_WEIGHT, lane), d1, _terms_of(f, 1, lane),
        _terms_of(f, 2, lane), context,
    )
    redo = REDO_SPLIT if region_changed(s[2], new[2], c[0]) else REDO_NONE
    redo = redo if exact & exact_later else REDO_STEP
    put_step(W, lane, new, d1, 0.0, redo)
    return 0 if redo == REDO_NONE else 1


@nb.njit(**INLINED)
def _step_runup_lanes(W, table, sub, lanes, n_pairs):
    """Sub-step ``sub`` of the first ``lanes`` lanes: one loop over the lanes, vectorised (``n_pairs`` is
    not read: the signature of every lane step, :func:`~uqgear.physics._lanes.compile_lane_kernel`)."""
    left = 0
    for lane in range(lanes):
        left += _lane_step(W, table, sub, lane)
    return left


@nb.njit(**JIT_OPTIONS)
def _redo_lane(lane, W, f, tau, h, tau_ref, n, period, warps, p, pair_k, period_k, fp, fg):
    """Finish a lane's sub-step on the one-run code: the whole step with IEEE divisions (``REDO_STEP``)
    and its split at a contact boundary, as :func:`~uqgear.physics._runup_kernels.integrate_runup` does."""
    s = lane_state(W, W_STATE, lane)
    d1 = lane_state(W, W_SLOPE, lane)
    trial = lane_state(W, W_TRIAL, lane)
    b = p[HALF_BACKLASH]
    if row_of(W, W_REDO, lane) == REDO_STEP:
        c = coefficients(p)
        d1, _ = warped_field(s, _terms_of(f, 0, lane), (c, FROM_X), divided)
        trial = _rk4(s, h, d1, _terms_of(f, 1, lane), _terms_of(f, 2, lane), c, FROM_X)
        put_state(W, W_SLOPE, lane, d1)
        if contact_region(s[2], b) == contact_region(trial[2], b):
            put_state(W, W_TRIAL, lane, trial)
            return
    done = split_at_contact(tau, h, s, d1, trial, tau_ref, n, period, warps, p, pair_k, period_k, fp, fg)
    put_state(W, W_TRIAL, lane, done)


@nb.njit(**JIT_OPTIONS)
def lane_work(states, params):
    """A lane group's work array: each lane's state, coefficients and inverse masses (rows of
    ``states`` and ``params``, one per lane)."""
    W = np.zeros(N_ROWS * LANES)
    for lane in range(LANES):
        put_coefficients(W, lane, params[lane])
        for j in range(6):
            W[(W_STATE + j) * LANES + lane] = states[lane, j]
    return W


@nb.njit(**JIT_OPTIONS)
def _cosines(schedule, params):
    """cos(Omega tau + STE phase) of each lane at each stage time (the same every mesh period: found once)."""
    _, offsets, widths, _, _, _ = schedule
    n_sub = schedule[0][schedule[0].size - 1]
    cosines = np.empty((n_sub, 3, LANES))
    for sub in range(n_sub):
        for stage in range(3):
            local = offsets[sub] if stage == 0 else (
                offsets[sub] + 0.5 * widths[sub] if stage == 1 else offsets[sub] + widths[sub]
            )
            for lane in range(LANES):
                cosines[sub, stage, lane] = math.cos(params[lane, OMEGA_MESH] * local + params[lane, STE_PHASE])
    return cosines


@nb.njit(**JIT_OPTIONS)
def _fill(table, n, period, warps, schedule, stages, cosines, params, fp, fg):
    """Every lane's forcing for mesh period ``n``: the clock once per stage time, then each lane's
    :func:`~uqgear.physics._runup_kernels.table_terms` (the one-run kernel's numbers)."""
    _, offsets, widths, _, pairs, _ = schedule
    knot_t, knot_rate, knot_accel = warps
    start = n * period
    n_sub = table.shape[0]
    clock = np.empty((n_sub, 3, 4))
    for sub in range(n_sub):
        tau = start + offsets[sub]
        h = widths[sub]
        for stage in range(3):
            at = tau if stage == 0 else (tau + 0.5 * h if stage == 1 else tau + h)
            t, rate, accel = warp(at, n, period, knot_t, knot_rate, knot_accel)
            clock[sub, stage, 0] = at
            clock[sub, stage, 1] = t
            clock[sub, stage, 2] = rate
            clock[sub, stage, 3] = accel
    # lane by lane: a lane's rows of the arrays are taken once a period, not at every stage
    for lane in range(LANES):
        p = params[lane]
        tabulated = stages[lane]
        for sub in range(n_sub):
            for stage in range(3):
                terms = table_terms(
                    clock[sub, stage, 0], n, clock[sub, stage, 1], clock[sub, stage, 2], clock[sub, stage, 3],
                    cosines[sub, stage, lane], tabulated, sub, stage, pairs[sub], p, fp, fg,
                )
                first = stage * R_STAGE
                table[sub, first * LANES + lane] = terms[0]
                table[sub, (first + 1) * LANES + lane] = terms[1]
                table[sub, (first + 2) * LANES + lane] = terms[2]
                table[sub, (first + 3) * LANES + lane] = terms[3]
                table[sub, (first + 4) * LANES + lane] = terms[4]
            h = widths[sub]
            table[sub, R_WIDTH * LANES + lane] = h
            table[sub, R_WEIGHT * LANES + lane] = h / 6.0


@nb.njit(**JIT_OPTIONS)
def _steady(params, live):
    """Whether every live lane's forcing but the clock's repeats every mesh period (no tooth factors,
    run-out, torque ripple or adhesion oscillation): then a period changes e'' and 1 / tau' alone."""
    for lane in range(LANES):
        if live[lane] and not periodic_forcing(params[lane]):
            return False
    return True


@nb.njit(**JIT_OPTIONS)
def _ste_slopes(schedule, stages, cosines, params):
    """Each lane's de/dtau and d2e/dtau2 of the mesh-periodic STE at each stage time (the same every mesh
    period): row ``sub``, field 2 stage (de/dtau) and 2 stage + 1 (d2e/dtau2), lanes adjacent."""
    n_sub = schedule[0][schedule[0].size - 1]
    slopes = np.empty((n_sub, 6 * LANES))
    for lane in range(LANES):
        p = params[lane]
        for sub in range(n_sub):
            for stage in range(3):
                _, ste_tau, ste_tautau = mesh_ste(stages[lane, sub, stage, F_SINE], cosines[sub, stage, lane], p)
                slopes[sub, 2 * stage * LANES + lane] = ste_tau
                slopes[sub, (2 * stage + 1) * LANES + lane] = ste_tautau
    return slopes


@nb.njit(**JIT_OPTIONS)
def _refill_clock(table, n, period, warps, schedule, slopes):
    """The parts of a steady group's forcing that change from period to period: e'' (the chain rule at
    the period's clock) and 1 / tau', as :func:`~uqgear.physics._runup_kernels.time_part` finds them."""
    _, offsets, widths, _, _, _ = schedule
    knot_t, knot_rate, knot_accel = warps
    start = n * period
    for sub in range(table.shape[0]):
        tau = start + offsets[sub]
        h = widths[sub]
        for stage in range(3):
            at = tau if stage == 0 else (tau + 0.5 * h if stage == 1 else tau + h)
            _, rate, accel = warp(at, n, period, knot_t, knot_rate, knot_accel)
            w = 1.0 / rate
            first = stage * R_STAGE
            for lane in range(LANES):
                table[sub, (first + 3) * LANES + lane] = chain_rule(
                    slopes[sub, 2 * stage * LANES + lane], slopes[sub, (2 * stage + 1) * LANES + lane], rate, accel
                )
                table[sub, (first + 4) * LANES + lane] = w


@nb.njit(**JIT_OPTIONS)
def mesh_sharing(params):
    """Each lane's earlier lane with the same parameters but for the torques T1 and T2 (whose mesh
    stiffness, friction arms and STE phase are then the same numbers), or -1."""
    share = np.full(LANES, -1, dtype=np.int64)
    for lane in range(LANES):
        for other in range(lane):
            if share[other] < 0 and _same_mesh(params, lane, other):
                share[lane] = other
                break
    return share


@nb.njit(**JIT_OPTIONS)
def _same_mesh(params, i, j):
    for k in range(params.shape[1]):
        if k != T1 and k != T2 and params[i, k] != params[j, k]:
            return False
    return True


@nb.njit(**JIT_OPTIONS)
def _outputs(W, f_end, live, share, tau, h, tau_ref, n, period, warps, params, pair_k, period_k, fp, fg, out_tau, o,
             history):
    """The one-run kernel's history rows of every live lane at the outputs in a sub-step; returns the
    index of the next output. The clock is found once for all lanes, the mesh terms once for the lanes
    that share them (:func:`mesh_sharing`)."""
    edge = tau + h - 1e-9 * period
    n_out = out_tau.size
    stop = o
    while stop < n_out and out_tau[stop] < edge:
        stop += 1
    knot_t, knot_rate, knot_accel = warps
    clock = np.empty((stop - o, 3))
    for k in range(o, stop):
        t, rate, accel = warp(out_tau[k], n, period, knot_t, knot_rate, knot_accel)
        clock[k - o, 0] = t
        clock[k - o, 1] = rate
        clock[k - o, 2] = accel
    # (k, pinion arms, gear arms, sin, cos) of each output and lane, as warped_forcing finds them
    mesh = np.empty((stop - o, LANES, 5))
    for lane in range(LANES):
        if not live[lane]:
            continue
        p = params[lane]
        c = coefficients(p)
        s = lane_state(W, W_STATE, lane)
        d1 = lane_state(W, W_SLOPE, lane)
        new = lane_state(W, W_TRIAL, lane)
        d_end, _ = warped_field(new, _terms_of(f_end, 2, lane), (c, FROM_X), divided)
        source = share[lane]
        for k in range(o, stop):
            at = _hermite(s, d1, new, d_end, h, (out_tau[k] - tau) / h)
            row = mesh[k - o, lane]
            if source >= 0:
                row[:] = mesh[k - o, source]
            else:
                row[0], row[1], row[2] = mesh_terms(out_tau[k], tau_ref, p, pair_k, period_k, fp, fg)
                angle = p[OMEGA_MESH] * out_tau[k] + p[STE_PHASE]
                row[3] = math.sin(angle)
                row[4] = math.cos(angle)
            terms = _terms(
                out_tau[k], clock[k - o, 0], clock[k - o, 1], clock[k - o, 2], row[3], row[4], row[0], row[1], row[2], p
            )
            record_row(at, terms, p, history[lane, k])
    return stop


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_runup_lanes(first, stop, W, live, params, pair_k, period_k, fp, fg, schedule, stages, period, warps,
                          out_tau, o, history):
    """Advance a lane group over mesh periods ``first`` to ``stop - 1`` (GIL released), recording
    ``history[lane]`` rows at the warped times ``out_tau`` from index ``o`` on.

    ``W`` from :func:`lane_work`; ``live`` which lanes hold a run (the others repeat lane 0 and are
    neither redone nor recorded); ``params`` one parameter row per lane; the stiffness tables are the
    group's; ``schedule`` the lead run's :func:`~uqgear.physics._stepper.build_schedule` for the band,
    ``stages`` each lane's tabulated stages of it. Returns the index of the next output.
    """
    first_sub, offsets, widths, refs, pairs, _ = schedule
    n_sub = first_sub[first_sub.size - 1]
    table = np.empty((n_sub, N_RUNUP_TABLE * LANES))
    cosines = _cosines(schedule, params)
    steady = _steady(params, live)
    slopes = _ste_slopes(schedule, stages, cosines, params)
    share = mesh_sharing(params)
    # LANES, but not a constant to LLVM (see uqgear.physics._lanes._step_lanes)
    lanes = W.size // N_ROWS
    for n in range(first, stop):
        if steady and n > first:
            _refill_clock(table, n, period, warps, schedule, slopes)
        else:
            _fill(table, n, period, warps, schedule, stages, cosines, params, fp, fg)
        start = n * period
        for sub in range(n_sub):
            tau = start + offsets[sub]
            h = widths[sub]
            tau_ref = start + refs[sub]
            if _step_runup_lanes(W, table, sub, lanes, pairs[sub]) != 0:
                for lane in range(LANES):
                    if row_of(W, W_REDO, lane) != REDO_NONE and live[lane]:
                        _redo_lane(lane, W, table[sub], tau, h, tau_ref, n, period, warps, params[lane], pair_k,
                                   period_k, fp, fg)
            if o < out_tau.size and out_tau[o] < tau + h - 1e-9 * period:
                o = _outputs(W, table[sub], live, share, tau, h, tau_ref, n, period, warps, params, pair_k,
                             period_k, fp, fg, out_tau, o, history)
            _advance(W, lanes)
    return o


def compile_runup_lanes(*arguments: object) -> None:
    """Compile (or load from the cache) :func:`integrate_runup_lanes` for the types of ``arguments`` (its
    arguments after the first two: :func:`~uqgear.physics._lanes.compile_lane_kernel`)."""
    compile_lane_kernel(_step_runup_lanes, N_ROWS, N_RUNUP_TABLE, integrate_runup_lanes, *arguments)


__all__ = ["LANES", "N_RUNUP_TABLE", "lane_work", "integrate_runup_lanes", "compile_runup_lanes"]
