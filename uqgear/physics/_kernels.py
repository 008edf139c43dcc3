"""Compiled one-sample integrators (numba): single runs, batches of runs one sample at a time.

The right-hand side and the RK4 pieces live in :mod:`uqgear.physics._rhs`
(re-exported here, so that this module is the kernel family's one namespace:
``JIT_OPTIONS``, ``INLINED``, the parameter slots, ``dead_zone``,
``contact_region``, ``mesh_terms``, ``forcing``, ``derivative``,
``build_schedule``, ...), the per-pair path of pitch errors in
:mod:`uqgear.physics._pairs`; this module adds what chooses between the two
(:func:`rhs`, :func:`scheduled_step`) and the kernels that loop over time.

Each loop is compiled per kernel family, on first use: a batch or a single run
without pitch errors compiles the classical step alone
(:func:`integrate_batch`, :func:`integrate_history`), one with pitch errors
the pair path alone (``*_pairs``), through one shared body that takes the step
function as an argument (numba compiles one specialisation per function
passed). The batch kernels' plain samples (no effect that breaks the mesh
period, no pitch errors) go to :mod:`uqgear.physics._lanes` instead.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from uqgear.physics import _pairs
from uqgear.physics._batch_record import run_arrays
from uqgear.physics._pair_extremes import NO_EXTREMES, add_pair_extremes
from uqgear.physics._rhs import (  # noqa: F401  (re-exported: the kernel family's one namespace)
    ADHESION_AMPLITUDE,
    ADHESION_OMEGA,
    ADHESION_PHASE,
    BASE_PITCH,
    C1,
    C2,
    CLEARANCE1,
    CLEARANCE2,
    CM,
    CONTACT_RATIO,
    DAMP_IN_SEPARATION,
    ECC_AMPLITUDE,
    ECC_KAPPA,
    ECC_OMEGA,
    ECC_PHASE,
    FRICTION,
    HALF_BACKLASH,
    I1,
    I2,
    INLINED,
    JIT_OPTIONS,
    K1,
    K2,
    LOA_LENGTH,
    M1,
    M2,
    MAX_PAIRS,
    ME,
    N_ACCUMULATORS,
    N_PARAMS,
    OMEGA_MESH,
    PARAMETER_SLOTS,
    PATH_START,
    PITCH_ERRORS,
    PITCH_POSITION,
    Q_A1_SQ,
    Q_A2_SQ,
    Q_COUNT,
    Q_F_MAX,
    Q_F_MIN,
    Q_LYAPUNOV,
    Q_N_BACK,
    Q_N_DRIVE,
    Q_N_SEP,
    Q_X_MAX,
    Q_X_MIN,
    Q_X_SQ,
    Q_X_SUM,
    R1,
    R2,
    RIPPLE_AMPLITUDE,
    RIPPLE_OMEGA,
    RIPPLE_PHASE,
    STE_AMPLITUDE,
    STE_PHASE,
    STIFFNESS_SCALE,
    T1,
    T2,
    TOOTH_FACTORS,
    TWO_PI,
    USE_PERIOD_TABLE,
    Z1,
    Z2,
    _friction_arms,
    _friction_term,
    _interp_uniform,
    _mesh_position,
    _time_terms,
    coefficients,
    contact_region,
    dead_zone,
    derivative,
    divided,
    forcing,
    mesh_damping,
    mesh_terms,
    side_derivative,
    state_derivative,
    static_transmission_error,
)
from uqgear.physics._stepper import (  # noqa: F401  (re-exported: the kernel family's one namespace)
    BISECTIONS,
    F_ARM_GEAR,
    F_ARM_PINION,
    F_K,
    F_SINE,
    N_FIELDS,
    _add_substep,
    _forcing_row,
    _rk4,
    _shifted,
    _split_at_contact,
    _tabulate_stage,
    build_schedule,
    classical_step,
    crossed_boundary,
    crossing_fraction,
    mesh_contact,
    rk4_combine,
    rk4_combine_weighted,
    rk4_stages,
    rk4_step,
    splits_step,
)


@nb.njit(**JIT_OPTIONS)
def rhs(t, state, t_ref, p, pair_k, period_k, factor_pinion, factor_gear, out):
    """Right-hand side of the 3-DOF model (docs/model/equations.md section 2) plus effect slots.

    ``state`` = (y1, y2, x, y1', y2', x') as an array; writes the derivative
    into ``out`` and returns (mesh force F, mesh stiffness k, static
    transmission error e).
    """
    if p[PITCH_ERRORS] != 0.0:
        # per-pair deflections (docs/model/equations.md section 2.6); runs without pitch errors take the classical
        # path below, which the branch does not touch
        terms = _pairs.forcing_pairs(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear)
        d, force = _pairs.derivative_pairs((state[0], state[1], state[2], state[3], state[4], state[5]), terms, p)
        for j in range(6):
            out[j] = d[j]
        return force, terms[0], terms[3]
    terms = forcing(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear)
    d, force = derivative((state[0], state[1], state[2], state[3], state[4], state[5]), terms, p)
    for j in range(6):
        out[j] = d[j]
    return force, terms[0], terms[3]


@nb.njit(**INLINED)
def scheduled_step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule):
    """Advance the state tuple ``s`` over grid step ``j`` of mesh period ``n``, with or without pitch errors.

    :func:`~uqgear.physics._stepper.classical_step` or
    :func:`~uqgear.physics._pairs.scheduled_step_pairs` as slot
    ``PITCH_ERRORS`` says (same returns). A kernel that knows which it needs
    calls that one: this one compiles both.
    """
    if p[PITCH_ERRORS] != 0.0:
        return _pairs.scheduled_step_pairs(n, j, period, s, p, pair_k, period_k, fp, fg, schedule)
    return classical_step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule)


@nb.njit(**INLINED)
def contact_at(x, n, n_pairs, p):
    """Contact state (1 drive, 0 apart, -1 back side) at DTE ``x`` in mesh period ``n`` with ``n_pairs`` in mesh.

    Without pitch errors it follows from x alone; with them from each pair's
    deflection (:func:`uqgear.physics._pairs.pair_contact`).
    """
    if p[PITCH_ERRORS] != 0.0:
        return _pairs.pair_contact(x, n, n_pairs, p)
    return contact_region(x, p[HALF_BACKLASH])


@nb.njit(**JIT_OPTIONS)
def advance(state, first_period, n_periods, p, pair_k, period_k, fp, fg, schedule):
    """Advance the state array in place over whole mesh periods."""
    steps = schedule[0].size - 1
    period = TWO_PI / p[OMEGA_MESH]
    s = (state[0], state[1], state[2], state[3], state[4], state[5])
    for n in range(first_period, first_period + n_periods):
        for j in range(steps):
            s, _, _, _ = scheduled_step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule)
    for c in range(6):
        state[c] = s[c]


@nb.njit(**JIT_OPTIONS)
def record(t, state, p, pair_k, period_k, fp, fg, deriv):
    """Evaluate derivative and mesh quantities at a grid point (pairs taken just after ``t``)."""
    t_ref = t + 1e-9 * TWO_PI / p[OMEGA_MESH]
    return rhs(t, state, t_ref, p, pair_k, period_k, fp, fg, deriv)


@nb.njit(**JIT_OPTIONS, inline="always")
def _history(
    step,
    contact,
    state0,
    p,
    pair_k,
    period_k,
    fp,
    fg,
    breakpoints,
    steps_per_period,
    n_periods,
    keep_periods,
    stride,
    history,
    poincare,
):
    """Integrate one run, storing histories of the kept periods.

    ``history`` has shape (keep_periods * steps_per_period // stride, 12):
    y1, y2, x, v1, v2, vx, a1, a2, F, k, e, contact. ``poincare`` has shape
    (keep_periods, 6): the state at each kept period start.
    """
    state = state0.copy()
    period = TWO_PI / p[OMEGA_MESH]
    schedule = build_schedule(p, pair_k, period_k, breakpoints, steps_per_period)
    first_sub, offsets, _, _, pairs, table = schedule
    first_kept = n_periods - keep_periods
    row = 0
    for n in range(n_periods):
        s = (state[0], state[1], state[2], state[3], state[4], state[5])
        if n < first_kept:
            for j in range(steps_per_period):
                s, _, _, _ = step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule)
            for c in range(6):
                state[c] = s[c]
            continue
        for j in range(steps_per_period):
            if j == 0:
                for c in range(6):
                    poincare[n - first_kept, c] = s[c]
            start = s
            # the step's first RK4 stage is the derivative at the grid point: reuse it
            s, force, a1, a2 = step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule)
            if j % stride == 0:
                sub = first_sub[j]
                terms = _forcing_row(n * period + offsets[sub], n, table, sub, 0, pairs[sub], p, fp, fg)
                for c in range(6):
                    history[row, c] = start[c]
                history[row, 6] = a1
                history[row, 7] = a2
                history[row, 8] = force
                history[row, 9] = terms[0]
                history[row, 10] = terms[3]
                history[row, 11] = contact(start[2], n, pairs[sub], p)
                row += 1
        for c in range(6):
            state[c] = s[c]
    return state


@nb.njit(**JIT_OPTIONS)
def integrate_history(
    state0,
    p,
    pair_k,
    period_k,
    fp,
    fg,
    breakpoints,
    steps_per_period,
    n_periods,
    keep_periods,
    stride,
    history,
    poincare,
):
    """Integrate one run without pitch errors, storing histories of the kept periods.

    ``history`` has shape (keep_periods * steps_per_period // stride, 12):
    y1, y2, x, v1, v2, vx, a1, a2, F, k, e, contact. ``poincare`` has shape
    (keep_periods, 6): the state at each kept period start.
    """
    return _history(
        classical_step,
        mesh_contact,
        state0,
        p,
        pair_k,
        period_k,
        fp,
        fg,
        breakpoints,
        steps_per_period,
        n_periods,
        keep_periods,
        stride,
        history,
        poincare,
    )


@nb.njit(**JIT_OPTIONS)
def integrate_history_pairs(
    state0,
    p,
    pair_k,
    period_k,
    fp,
    fg,
    breakpoints,
    steps_per_period,
    n_periods,
    keep_periods,
    stride,
    history,
    poincare,
):
    """:func:`integrate_history` with pitch errors (the per-pair path)."""
    return _history(
        _pairs.scheduled_step_pairs,
        _pairs.pair_contact,
        state0,
        p,
        pair_k,
        period_k,
        fp,
        fg,
        breakpoints,
        steps_per_period,
        n_periods,
        keep_periods,
        stride,
        history,
        poincare,
    )


@nb.njit(**INLINED)
def _start_sums(acc):
    """Start a run's QoI sums: the extremes at their identities (the sums are zero)."""
    acc[Q_X_MIN] = np.inf
    acc[Q_X_MAX] = -np.inf
    acc[Q_F_MAX] = -np.inf
    acc[Q_F_MIN] = np.inf


@nb.njit(**INLINED)
def _add_step(acc, x, force, a1, a2, region):
    """Add one kept grid step (DTE, mesh force, accelerations, contact region) to a run's QoI sums."""
    acc[Q_X_SUM] += x
    acc[Q_X_SQ] += x * x
    if x < acc[Q_X_MIN]:
        acc[Q_X_MIN] = x
    if x > acc[Q_X_MAX]:
        acc[Q_X_MAX] = x
    if force > acc[Q_F_MAX]:
        acc[Q_F_MAX] = force
    if force < acc[Q_F_MIN]:
        acc[Q_F_MIN] = force
    acc[Q_A1_SQ] += a1 * a1
    acc[Q_A2_SQ] += a2 * a2
    if region == 1:
        acc[Q_N_DRIVE] += 1.0
    elif region == 0:
        acc[Q_N_SEP] += 1.0
    else:
        acc[Q_N_BACK] += 1.0
    acc[Q_COUNT] += 1.0


@nb.njit(**INLINED)
def _renormalised(shadow, s, scale, separation):
    """(shadow state, distance): the shadow run brought back to ``separation`` from ``s`` (Benettin).

    The distance is the scaled one before; at zero distance the shadow starts again
    ``separation`` away in x.
    """
    distance = 0.0
    for c in range(6):
        distance += ((shadow[c] - s[c]) / scale[c]) ** 2
    distance = math.sqrt(distance)
    if distance > 0.0:
        ratio = separation / distance
        shadow = (
            s[0] + (shadow[0] - s[0]) * ratio,
            s[1] + (shadow[1] - s[1]) * ratio,
            s[2] + (shadow[2] - s[2]) * ratio,
            s[3] + (shadow[3] - s[3]) * ratio,
            s[4] + (shadow[4] - s[4]) * ratio,
            s[5] + (shadow[5] - s[5]) * ratio,
        )
    else:
        shadow = (s[0], s[1], s[2] + separation * scale[2], s[3], s[4], s[5])
    return shadow, distance


# numba-inlined into its callers, so that it is not compiled (and its machine code emitted)
# a second time as a kernel of its own; ``step`` and ``contact`` are compiled functions
# (numba compiles one specialisation per pair of functions passed)
@nb.njit(**JIT_OPTIONS, inline="always")
def _integrate_qoi(
    step,
    contact,
    state,
    p,
    pair_k,
    period_k,
    fp,
    fg,
    breakpoints,
    steps_per_period,
    n_periods,
    keep_periods,
    history_stride,
    acc,
    poincare,
    history,
    lyapunov,
    scale,
    stresses,
    extremes,
):
    """Integrate one run keeping only accumulators, Poincare points and decimated histories.

    ``history`` has shape (channels, points): channel 0 is x; with 4 channels
    also te, y1'' and y2'' (the rig's channels). With ``stresses`` also the
    extremes of the tooth-pair loads at the kept grid steps, into ``extremes``
    (:func:`~uqgear.physics._pair_extremes.add_pair_extremes`).
    """
    period = TWO_PI / p[OMEGA_MESH]
    h = period / steps_per_period
    schedule = build_schedule(p, pair_k, period_k, breakpoints, steps_per_period)
    first_kept = n_periods - keep_periods
    first_sub = schedule[0]
    offsets = schedule[1]
    pairs = schedule[4]
    table = schedule[5]
    kept_extremes = NO_EXTREMES
    _start_sums(acc)
    separation = 1e-7
    s = (state[0], state[1], state[2], state[3], state[4], state[5])
    shadow = (s[0], s[1], s[2] + separation * scale[2], s[3], s[4], s[5])
    log_growth = 0.0
    row = 0
    for n in range(n_periods):
        kept = n >= first_kept
        if kept:
            poincare[n - first_kept, 0] = s[2]
            poincare[n - first_kept, 1] = s[5]
        # the pairs' pitch offsets and tooth factors of the period (read with stresses alone)
        teeth = _pairs._tooth_terms(n, p, fp, fg)
        for j in range(steps_per_period):
            x = s[2]
            state_y1 = s[0]
            state_y2 = s[1]
            if kept and stresses:
                sub = first_sub[j]
                kept_extremes = add_pair_extremes(kept_extremes, x, s[5], n * period + offsets[sub],
                                                  j / steps_per_period, teeth, table, sub, pairs[sub], p)
            s, force, a1, a2 = step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule)
            if kept:
                _add_step(acc, x, force, a1, a2, contact(x, n, pairs[first_sub[j]], p))
                if history_stride > 0 and j % history_stride == 0:
                    history[0, row] = x
                    if history.shape[0] >= 4:
                        # the rig's channels: te = x - y1 + y2 + e, and the bearing accelerations
                        t = n * period + j * h
                        history[1, row] = x - state_y1 + state_y2 + static_transmission_error(t, p)
                        history[2, row] = a1
                        history[3, row] = a2
                    row += 1
            if lyapunov:
                shadow, _, _, _ = step(n, j, period, shadow, p, pair_k, period_k, fp, fg, schedule)
        if lyapunov:
            # Benettin renormalisation once per mesh period in scaled coordinates
            shadow, distance = _renormalised(shadow, s, scale, separation)
            if kept and distance > 0.0:
                log_growth += math.log(distance / separation)
    for c in range(6):
        state[c] = s[c]
    if stresses:
        for e in range(4):
            extremes[e] = kept_extremes[e]
    if lyapunov:
        acc[Q_LYAPUNOV] = log_growth / (keep_periods * period)
    else:
        acc[Q_LYAPUNOV] = np.nan


@nb.njit(**JIT_OPTIONS, inline="always")
def _batch(step, contact, start, stop, order, batch):
    runs = batch.runs
    for k in range(start, stop):
        i = order[k]
        state = runs.states[i].copy()
        p, pair_k, period_k, fp, fg, breakpoints = run_arrays(runs, i)
        _integrate_qoi(
            step,
            contact,
            state,
            p,
            pair_k,
            period_k,
            fp,
            fg,
            breakpoints,
            batch.steps_per_period[i],
            batch.n_periods,
            batch.keep_periods,
            batch.history_stride[i],
            batch.accumulators[i],
            batch.poincare[i],
            batch.history[i],
            batch.lyapunov,
            batch.scales[i],
            batch.stresses,
            batch.stress_extremes[i],
        )
        batch.final_states[i, :] = state


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_batch(start, stop, order, batch):
    """Integrate runs ``order[start:stop]`` of a batch without pitch errors, one at a time (GIL released).

    ``batch`` is a :class:`~uqgear.physics._batch_record.QoiBatch`: its runs' states at t = 0 are
    not changed; each run's state at the end of its last period goes to ``batch.final_states``.

    Threads share a batch by calling this on disjoint ranges
    (:func:`uqgear.physics.threads.spread`); a run's numbers do not depend on
    which thread or range computes it. Not a ``prange``: numba's parallel
    lowering multiplies the kernel's cold compilation time (docs/validation/performance.md).
    """
    _batch(classical_step, mesh_contact, start, stop, order, batch)


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_batch_pairs(start, stop, order, batch):
    """:func:`integrate_batch` for runs with pitch errors (the per-pair path)."""
    _batch(_pairs.scheduled_step_pairs, _pairs.pair_contact, start, stop, order, batch)
