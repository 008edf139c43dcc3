"""Samples as SIMD lanes: a batch kernel that advances ``LANES`` runs together, bit for bit the one-sample kernel.

One RK4 sub-step of the 3-DOF model is a chain of about 200 dependent
floating-point operations (twelve divisions among them), so a single run
waits on latency, not on arithmetic. Eight runs with the same sub-step
layout (same steps per mesh period, same stiffness breakpoints) are
advanced together here, as the elements of vectors: a lane group keeps its
state, parameters and forcing in rows of ``LANES`` adjacent numbers
(structure of arrays), and a sub-step is one loop over the lanes
(:func:`_step_lanes`) that LLVM's loop vectoriser compiles into 512-bit
vector instructions, one per IEEE operation of the step for all eight runs
(:func:`compile_lanes`).

Each lane computes exactly the operations of the one-sample kernel
(:func:`uqgear.physics._rhs.classical_step`, through the same
:func:`~uqgear.physics._rhs.state_derivative_by`; no fast-math, so nothing
is reassociated or contracted, and selects rather than branches for the dead
zones and the damping switch), so its numbers are the same, bit for bit. Its
twelve divisions by m1, m2 and m_e a sub-step, the slowest vector
instructions, are :func:`uqgear.physics._quotient.quotient`: a multiplication
by 1/m and fused multiply-adds that give the IEEE quotient's bits (a lane
whose dividend falls outside the range where that is proven redoes its
sub-step with IEEE divisions; a run whose divisors do not qualify is not a
lane). What
differs between lanes is data: its own parameters, forcing table, times and
contact state; a lane whose step changes its contact region is redone on
its own by the one-sample code (:func:`~uqgear.physics._rhs._split_at_contact`).

The lanes take every run without pitch errors (:func:`lane_ready`; a pitch-error
run's per-pair contact is the pair kernel's). The whole forcing of a sub-step
(stiffness, friction term, drive, e'') is a table, filled from the one-sample
kernel's own :func:`~uqgear.physics._rhs._forcing_row` at the times it
evaluates it (:mod:`uqgear.physics._lane_tables`): once per run where the
forcing repeats every mesh period, and for every period where tooth factors,
run-out, torque ripple or an adhesion oscillation make it change
(:func:`periodic_forcing`). With ``lyapunov`` a group holds four runs and
their four shadow runs.
"""

from __future__ import annotations

import math

import llvmlite.binding as ll
import numba as nb
import numpy as np
from numba.core.compiler_lock import global_compiler_lock

from uqgear.physics._lane_tables import (
    LANES,
    N_TABLE,
    RIG_CHANNELS,
    STATE_CHANNELS,
    T_DRIVE,
    T_STE,
    T_WEIGHT,
    T_WIDTH,
    _copy_lane,
    _fill_forcing,
    _same_schedule,
    _take_schedule,
)
from uqgear.physics._quotient import exact_divisors, quotient
from uqgear.physics._rhs import (
    ADHESION_AMPLITUDE,
    ECC_AMPLITUDE,
    ECC_KAPPA,
    INLINED,
    JIT_OPTIONS,
    M1,
    M2,
    ME,
    N_ACCUMULATORS,
    OMEGA_MESH,
    PITCH_ERRORS,
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
    RIPPLE_AMPLITUDE,
    TOOTH_FACTORS,
    TWO_PI,
    _split_at_contact,
    build_schedule,
    coefficients,
    contact_region,
    rk4_step,
    rk4_step_weighted,
    state_derivative,
    state_derivative_by,
    static_transmission_error,
)

#: Separation of a shadow run from its run (scaled state), as in the one-sample kernel.
SEPARATION = 1e-7

#: Slots a lane reads beyond :func:`~uqgear.physics._rhs.coefficients`.
N_COEFFICIENTS = 12

# Rows of a lane group's work array: row r of lane l is element r * LANES + l, so that a row is a
# vector of the lanes and every offset a constant (the loop vectoriser then proves that the rows
# do not overlap). The state, the sub-step's result, its first stage, the mesh force and the
# bearing accelerations at its start, what is left to do for the lane (REDO_*), each lane's
# coefficients and the inverses 1/m1, 1/m2, 1/m_e of its divisors.
W_STATE = 0
W_TRIAL = 6
W_SLOPE = 12
W_FORCE = 18
W_A1 = 19
W_A2 = 20
W_REDO = 21
W_COEFFICIENTS = 22
W_INVERSE = W_COEFFICIENTS + N_COEFFICIENTS
N_ROWS = W_INVERSE + 3
#: What a lane's sub-step leaves to the one-sample code: nothing; its split at a contact boundary
#: (the step changes the contact region); the whole sub-step (a quotient outside the range where
#: the exact quotient is proven, see uqgear.physics._quotient).
REDO_NONE = 0.0
REDO_SPLIT = 1.0
REDO_STEP = 2.0


# whether this process has compiled (or loaded) the lane kernel through compile_lanes
_COMPILED = False


def compile_lanes(groups: np.ndarray, arrays: tuple, refused: np.ndarray) -> None:
    """Compile (or load from the cache) the lane kernel for :func:`integrate_lanes`'s arguments.

    A lane group's sub-step is one loop over the lanes (:func:`_step_lanes`); LLVM's loop
    vectoriser turns each of its IEEE operations into one vector instruction on all lanes. It
    reorders nothing (no fast-math, and no reduction across lanes), so the numbers do not change.
    Its cost model keeps vectors at 256 bits on CPUs tuned for that (LLVM's default
    ``prefer-vector-width=256`` on AVX-512 parts), which runs the eight lanes as two vectors of
    four, one after the other: the width is forced to eight lanes (one 512-bit vector with AVX-512,
    two 256-bit ones with AVX2, interleaved) while the loop alone is compiled
    (docs/validation/performance.md compares the two). The loop is then
    inlined, already vectorised, into the rest of the kernel, compiled without the forced width (a
    forced width has LLVM report every other loop it cannot vectorise on stderr). The SLP
    vectoriser stays off: helpers it packed would reach the lane loop as short vectors, which the
    loop vectoriser refuses.

    The width is an LLVM command-line option, global to the process: it is set under numba's
    compiler lock and reset before anything else compiles. This is done once per process; later
    calls return at once.
    """
    global _COMPILED
    if _COMPILED:
        # compiled (or loaded) in this process already: every caller passes the same argument types,
        # and taking the compiler lock and setting the options on every batch costs 0.1-0.2 ms
        return
    with global_compiler_lock:
        # numba.config's options are module attributes it sets at import: no static type knows them
        saved = nb.config.SLP_VECTORIZE  # type: ignore[attr-defined]
        nb.config.SLP_VECTORIZE = 0  # type: ignore[attr-defined]
        try:
            ll.set_option("", f"-force-vector-width={LANES}")
            try:
                _step_lanes(np.zeros(N_ROWS * LANES), np.zeros((1, N_TABLE * LANES)), 0, 0)
            finally:
                ll.set_option("", "-force-vector-width=0")
            integrate_lanes(0, 0, groups, *arrays, refused)
            _COMPILED = True
        finally:
            nb.config.SLP_VECTORIZE = saved  # type: ignore[attr-defined]


def lane_ready(params: np.ndarray) -> np.ndarray:
    """Which runs (rows of parameter vectors) the lanes take: those without pitch errors (whose per-pair
    contact the lanes do not follow) and with divisors the lanes' quotient is exact for."""
    p = np.atleast_2d(params)
    # the lanes divide by a multiplication and fused multiply-adds, exact for these divisors
    return (p[:, PITCH_ERRORS] == 0.0) & exact_divisors(p[:, M1]) & exact_divisors(p[:, M2]) & exact_divisors(p[:, ME])


@nb.njit(**INLINED)
def periodic_forcing(p):
    """Whether a run's forcing repeats every mesh period: no tooth factors, run-out, torque ripple or
    adhesion oscillation. A lane group holding another run fills its forcing table every period."""
    return (
        p[TOOTH_FACTORS] == 0.0
        and p[ECC_AMPLITUDE] == 0.0
        and p[ECC_KAPPA] == 0.0
        and p[RIPPLE_AMPLITUDE] == 0.0
        and p[ADHESION_AMPLITUDE] == 0.0
    )


@nb.njit(**INLINED)
def _row(W, row, lane):
    return W[row * LANES + lane]


@nb.njit(**INLINED)
def _lane_step(W, table, sub, lane):
    """Sub-step ``sub`` of one lane: the one-sample kernel's RK4 step (:func:`~uqgear.physics._rhs.classical_step`
    between its splits), with its start's force and bearing accelerations, and what is left to the
    one-sample code (``REDO_*``), written to ``W``. Returns 1 if something is left, else 0."""
    s = (
        _row(W, W_STATE, lane),
        _row(W, W_STATE + 1, lane),
        _row(W, W_STATE + 2, lane),
        _row(W, W_STATE + 3, lane),
        _row(W, W_STATE + 4, lane),
        _row(W, W_STATE + 5, lane),
    )
    c = (
        _row(W, W_COEFFICIENTS, lane),
        _row(W, W_COEFFICIENTS + 1, lane),
        _row(W, W_COEFFICIENTS + 2, lane),
        _row(W, W_COEFFICIENTS + 3, lane),
        _row(W, W_COEFFICIENTS + 4, lane),
        _row(W, W_COEFFICIENTS + 5, lane),
        _row(W, W_COEFFICIENTS + 6, lane),
        _row(W, W_COEFFICIENTS + 7, lane),
        _row(W, W_COEFFICIENTS + 8, lane),
        _row(W, W_COEFFICIENTS + 9, lane),
        _row(W, W_COEFFICIENTS + 10, lane),
        _row(W, W_COEFFICIENTS + 11, lane),
    )
    inverse = (_row(W, W_INVERSE, lane), _row(W, W_INVERSE + 1, lane), _row(W, W_INVERSE + 2, lane))
    # the sub-step's row: its index is checked for wrap-around once, outside the loop over the lanes
    f = table[sub]
    d1, force, exact = state_derivative_by(
        s, _row(f, 0, lane), _row(f, 1, lane), _row(f, T_DRIVE, lane), _row(f, 2, lane), c, quotient, inverse
    )
    mid = (_row(f, 3, lane), _row(f, 4, lane), _row(f, T_DRIVE + 1, lane), _row(f, 5, lane))
    end = (_row(f, 6, lane), _row(f, 7, lane), _row(f, T_DRIVE + 2, lane), _row(f, 8, lane))
    new, exact_later = rk4_step_weighted(
        s, _row(f, T_WIDTH, lane), _row(f, T_WEIGHT, lane), d1, mid, end, c, quotient, inverse
    )
    b = c[0]
    x = s[2]
    # the one-sample kernel's test (contact_region before and after differ), as choices between values
    crossed = ((x > b) != (new[2] > b)) | ((x < -b) != (new[2] < -b))
    redo = REDO_SPLIT if crossed else REDO_NONE
    redo = redo if exact & exact_later else REDO_STEP
    # written out, not a loop over the tuples: a tuple indexed by a variable goes through memory
    W[W_TRIAL * LANES + lane] = new[0]
    W[(W_TRIAL + 1) * LANES + lane] = new[1]
    W[(W_TRIAL + 2) * LANES + lane] = new[2]
    W[(W_TRIAL + 3) * LANES + lane] = new[3]
    W[(W_TRIAL + 4) * LANES + lane] = new[4]
    W[(W_TRIAL + 5) * LANES + lane] = new[5]
    W[W_SLOPE * LANES + lane] = d1[0]
    W[(W_SLOPE + 1) * LANES + lane] = d1[1]
    W[(W_SLOPE + 2) * LANES + lane] = d1[2]
    W[(W_SLOPE + 3) * LANES + lane] = d1[3]
    W[(W_SLOPE + 4) * LANES + lane] = d1[4]
    W[(W_SLOPE + 5) * LANES + lane] = d1[5]
    W[W_FORCE * LANES + lane] = force
    W[W_A1 * LANES + lane] = d1[3]
    W[W_A2 * LANES + lane] = d1[4]
    W[W_REDO * LANES + lane] = redo
    return 0 if redo == REDO_NONE else 1


@nb.njit(**INLINED)
def _step_lanes(W, table, sub, lanes):
    """Sub-step ``sub`` of the first ``lanes`` lanes (all of them: ``LANES``); returns how many leave
    something to the one-sample code (:func:`_redo_lane`).

    One loop over the lanes, which the loop vectoriser compiles into vector instructions. Its trip
    count comes from the caller at run time: a constant one would have LLVM unroll the loop before
    the vectoriser sees it (its body is still a call then), and treat it as too short for the
    check that ``W`` and ``table`` do not overlap.
    """
    left = 0
    for lane in range(lanes):
        left += _lane_step(W, table, sub, lane)
    return left


@nb.njit(**INLINED)
def _advance(W, lanes):
    """Each lane's state becomes its sub-step's result."""
    for row in range(6):
        for lane in range(lanes):
            W[(W_STATE + row) * LANES + lane] = W[(W_TRIAL + row) * LANES + lane]


@nb.njit(**JIT_OPTIONS)
def _lane_samples(members, lyapunov):
    """(sample of each lane, whether its results are written): padding and shadows run but write nothing."""
    samples = np.empty(LANES, dtype=np.int64)
    written = np.zeros(LANES, dtype=np.bool_)
    half = LANES // 2
    for lane in range(LANES):
        if lyapunov and lane >= half:
            samples[lane] = samples[lane - half]
            continue
        if members[lane] >= 0:
            samples[lane] = members[lane]
            written[lane] = True
        else:
            samples[lane] = members[0]
    return samples, written


@nb.njit(**INLINED)
def _lane_state(W, first, lane):
    return (
        _row(W, first, lane),
        _row(W, first + 1, lane),
        _row(W, first + 2, lane),
        _row(W, first + 3, lane),
        _row(W, first + 4, lane),
        _row(W, first + 5, lane),
    )


@nb.njit(**INLINED)
def _put_state(W, first, lane, s):
    W[first * LANES + lane] = s[0]
    W[(first + 1) * LANES + lane] = s[1]
    W[(first + 2) * LANES + lane] = s[2]
    W[(first + 3) * LANES + lane] = s[3]
    W[(first + 4) * LANES + lane] = s[4]
    W[(first + 5) * LANES + lane] = s[5]


@nb.njit(**JIT_OPTIONS)
def _redo_lane(
    lane,
    n,
    sub,
    W,
    table,
    widths,
    offsets,
    refs,
    period,
    i,
    params,
    pair_tables,
    period_tables,
    table_index,
    factor_pinion,
    factor_gear,
):
    """Finish a lane's sub-step on the one-sample code: its split at a contact boundary, or (a quotient the
    lanes cannot vouch for) the whole sub-step, with IEEE divisions, as the one-sample kernel does."""
    p = params[i]
    table_i = table_index[i]
    start = n * period[lane]
    s = _lane_state(W, W_STATE, lane)
    d1 = _lane_state(W, W_SLOPE, lane)
    attempt = _lane_state(W, W_TRIAL, lane)
    h = widths[sub, lane]
    if _row(W, W_REDO, lane) == REDO_STEP:
        c = coefficients(p)
        f = table[sub]
        d1, force = state_derivative(s, _row(f, 0, lane), _row(f, 1, lane), _row(f, T_DRIVE, lane), _row(f, 2, lane), c)
        attempt = rk4_step(
            s,
            h,
            d1,
            (_row(f, 3, lane), _row(f, 4, lane), _row(f, T_DRIVE + 1, lane), _row(f, 5, lane)),
            (_row(f, 6, lane), _row(f, 7, lane), _row(f, T_DRIVE + 2, lane), _row(f, 8, lane)),
            c,
        )
        _put_state(W, W_SLOPE, lane, d1)
        W[W_FORCE * LANES + lane] = force
        W[W_A1 * LANES + lane] = d1[3]
        W[W_A2 * LANES + lane] = d1[4]
        if contact_region(s[2], c[0]) == contact_region(attempt[2], c[0]):
            _put_state(W, W_TRIAL, lane, attempt)
            return
    done = _split_at_contact(
        start + offsets[sub, lane],
        h,
        s,
        d1,
        attempt,
        start + refs[sub, lane],
        p,
        pair_tables[table_i],
        period_tables[table_i],
        factor_pinion[i],
        factor_gear[i],
    )
    _put_state(W, W_TRIAL, lane, done)


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_lanes(
    first,
    last,
    groups,
    states,
    params,
    pair_tables,
    period_tables,
    table_index,
    factor_pinion,
    factor_gear,
    breakpoints,
    steps_per_period,
    n_periods,
    keep_periods,
    history_stride,
    lyapunov,
    scales,
    accumulators,
    poincare,
    history,
    final_states,
    refused,
):
    """Integrate lane groups ``first`` to ``last - 1`` of a batch (GIL released).

    ``groups`` has one row of ``LANES`` sample indices per group (-1: an
    empty lane); with ``lyapunov`` only the first half of a row is used and
    the second half runs the shadows. The arguments after ``groups`` are
    those of :func:`uqgear.physics._kernels.integrate_batch`, filled alike.
    A run whose sub-step layout differs from its group's first run is not
    integrated: ``refused`` says so, and the caller runs it one at a time.
    """
    for g in range(first, last):
        _integrate_group(
            groups[g],
            states,
            params,
            pair_tables,
            period_tables,
            table_index,
            factor_pinion,
            factor_gear,
            breakpoints,
            steps_per_period,
            n_periods,
            keep_periods,
            history_stride,
            lyapunov,
            scales,
            accumulators,
            poincare,
            history,
            final_states,
            refused,
        )


@nb.njit(**JIT_OPTIONS)
def _integrate_group(
    members,
    states,
    params,
    pair_tables,
    period_tables,
    table_index,
    factor_pinion,
    factor_gear,
    breakpoints,
    steps_per_period,
    n_periods,
    keep_periods,
    history_stride,
    lyapunov,
    scales,
    accumulators,
    poincare,
    history,
    final_states,
    refused,
):
    samples, written = _lane_samples(members, lyapunov)
    lead = samples[0]
    steps = steps_per_period[lead]
    stride = history_stride[lead]
    lead_table = table_index[lead]
    layout = build_schedule(params[lead], pair_tables[lead_table], period_tables[lead_table], breakpoints[lead], steps)
    first_sub = layout[0]
    pairs = layout[4]
    n_sub = first_sub[steps]
    table = np.empty((n_sub, N_TABLE * LANES))
    widths = np.empty((n_sub, LANES))
    offsets = np.empty((n_sub, LANES))
    refs = np.empty((n_sub, LANES))
    # each lane's tabulated stages (its schedule's table), from which its forcing is filled
    stages = np.empty((LANES, n_sub, 3, layout[5].shape[2]))
    W = np.zeros(N_ROWS * LANES)
    period = np.empty(LANES)
    filled = -1
    for lane in range(LANES):
        i = samples[lane]
        if filled >= 0 and _same_schedule(params, i, samples[filled], table_index, breakpoints):
            # the same speed and design as the lane before, another torque: the same schedule
            _copy_lane(stages, widths, offsets, refs, filled, lane)
        else:
            t_i = table_index[i]
            schedule = (
                layout
                if i == lead
                else build_schedule(params[i], pair_tables[t_i], period_tables[t_i], breakpoints[i], steps)
            )
            same = (
                steps_per_period[i] == steps
                and history_stride[i] == stride
                and np.array_equal(schedule[0], first_sub)
                and np.array_equal(schedule[4][:n_sub], pairs[:n_sub])
            )
            if not same:
                # run one at a time by the caller; this lane repeats the lead run and writes nothing
                refused[i] = True
                written[lane] = False
                i = lead
                samples[lane] = lead
                schedule = layout
            _take_schedule(stages, widths, offsets, refs, lane, schedule, n_sub)
            filled = lane
        p = params[i]
        c = coefficients(p)
        for k in range(N_COEFFICIENTS):
            W[(W_COEFFICIENTS + k) * LANES + lane] = c[k]
        W[W_INVERSE * LANES + lane] = 1.0 / p[M1]
        W[(W_INVERSE + 1) * LANES + lane] = 1.0 / p[M2]
        W[(W_INVERSE + 2) * LANES + lane] = 1.0 / p[ME]
        period[lane] = TWO_PI / p[OMEGA_MESH]
        _fill_forcing(
            table, lane, 0, period[lane], widths, offsets, stages[lane], pairs, p, factor_pinion[i], factor_gear[i]
        )
    moving = False
    for lane in range(LANES):
        moving = moving or not periodic_forcing(params[samples[lane]])
    _run_lanes(
        samples,
        written,
        W,
        table,
        widths,
        offsets,
        refs,
        period,
        first_sub,
        steps,
        stride,
        states,
        params,
        pair_tables,
        period_tables,
        table_index,
        factor_pinion,
        factor_gear,
        n_periods,
        keep_periods,
        lyapunov,
        scales,
        accumulators,
        poincare,
        history,
        final_states,
        stages if moving else stages[:0],
        pairs,
    )


@nb.njit(**JIT_OPTIONS)
def _run_lanes(
    samples,
    written,
    W,
    table,
    widths,
    offsets,
    refs,
    period,
    first_sub,
    steps,
    stride,
    states,
    params,
    pair_tables,
    period_tables,
    table_index,
    factor_pinion,
    factor_gear,
    n_periods,
    keep_periods,
    lyapunov,
    scales,
    accumulators,
    poincare,
    history,
    final_states,
    stages,
    pairs,
):
    """The time loop of a lane group: the one-sample kernel's loop, lane by lane (see the module doc).

    ``stages`` holds each lane's tabulated stages where the group's forcing does not repeat every
    mesh period (none: it does): the forcing table is then filled again for every period.
    """
    half = LANES // 2
    # LANES, but not a constant to LLVM (see _step_lanes)
    lanes = W.size // N_ROWS
    live = written.copy()
    if lyapunov:
        live[half:] = written[:half]
    acc = np.zeros(N_ACCUMULATORS * LANES)
    log_growth = np.zeros(LANES)
    for lane in range(LANES):
        for c in range(6):
            W[(W_STATE + c) * LANES + lane] = states[samples[lane], c]
        if lyapunov and lane >= half:
            W[(W_STATE + 2) * LANES + lane] += SEPARATION * scales[samples[lane], 2]
        acc[Q_X_MIN * LANES + lane] = np.inf
        acc[Q_X_MAX * LANES + lane] = -np.inf
        acc[Q_F_MAX * LANES + lane] = -np.inf
        acc[Q_F_MIN * LANES + lane] = np.inf
    moving = stages.shape[0] > 0
    whole_state = poincare.shape[2] >= 6
    first_kept = n_periods - keep_periods
    row = 0
    for n in range(n_periods):
        if moving and n > 0:
            for lane in range(LANES):
                if not live[lane]:
                    # an empty or refused lane's numbers are never read: its table may lag
                    continue
                i = samples[lane]
                _fill_forcing(
                    table,
                    lane,
                    n,
                    period[lane],
                    widths,
                    offsets,
                    stages[lane],
                    pairs,
                    params[i],
                    factor_pinion[i],
                    factor_gear[i],
                )
        kept = n >= first_kept
        if kept:
            for lane in range(LANES):
                if not written[lane]:
                    continue
                if whole_state:
                    # the whole state at the period start, as the one-sample history keeps it
                    for c in range(6):
                        poincare[samples[lane], n - first_kept, c] = _row(W, W_STATE + c, lane)
                else:
                    poincare[samples[lane], n - first_kept, 0] = _row(W, W_STATE + 2, lane)
                    poincare[samples[lane], n - first_kept, 1] = _row(W, W_STATE + 5, lane)
        for j in range(steps):
            for sub in range(first_sub[j], first_sub[j + 1]):
                if _step_lanes(W, table, sub, lanes) != 0:
                    for lane in range(LANES):
                        # an empty lane's numbers are never read: it is not redone
                        if _row(W, W_REDO, lane) != REDO_NONE and live[lane]:
                            _redo_lane(
                                lane,
                                n,
                                sub,
                                W,
                                table,
                                widths,
                                offsets,
                                refs,
                                period,
                                samples[lane],
                                params,
                                pair_tables,
                                period_tables,
                                table_index,
                                factor_pinion,
                                factor_gear,
                            )
                if sub == first_sub[j] and kept:
                    _accumulate(acc, W, lanes)
                    if stride > 0 and j % stride == 0:
                        _record(history, row, W, table[sub], samples, written, n, j, steps, period, params)
                        row += 1
                _advance(W, lanes)
        if lyapunov:
            for lane in range(half):
                _renormalise(W, lane, lane + half, scales[samples[lane]], kept, log_growth)
    for lane in range(LANES):
        if not written[lane]:
            continue
        i = samples[lane]
        for q in range(N_ACCUMULATORS):
            accumulators[i, q] = acc[q * LANES + lane]
        if lyapunov:
            accumulators[i, Q_LYAPUNOV] = log_growth[lane] / (keep_periods * period[lane])
        else:
            accumulators[i, Q_LYAPUNOV] = np.nan
        for c in range(6):
            final_states[i, c] = _row(W, W_STATE + c, lane)


@nb.njit(**INLINED)
def _accumulate(acc, W, lanes):
    """The one-sample kernel's QoI sums for each lane, at the start of a kept grid step."""
    # the same comparisons as there, written as choices between values (selects) and counts that add
    # 0.0 or 1.0 (exact), so that the loop over the lanes vectorises
    for lane in range(lanes):
        x = _row(W, W_STATE + 2, lane)
        force = _row(W, W_FORCE, lane)
        b = _row(W, W_COEFFICIENTS, lane)
        acc[Q_X_SUM * LANES + lane] += x
        acc[Q_X_SQ * LANES + lane] += x * x
        low = acc[Q_X_MIN * LANES + lane]
        acc[Q_X_MIN * LANES + lane] = x if x < low else low  # noqa: FURB136
        high = acc[Q_X_MAX * LANES + lane]
        acc[Q_X_MAX * LANES + lane] = x if x > high else high  # noqa: FURB136
        high = acc[Q_F_MAX * LANES + lane]
        acc[Q_F_MAX * LANES + lane] = force if force > high else high  # noqa: FURB136
        low = acc[Q_F_MIN * LANES + lane]
        acc[Q_F_MIN * LANES + lane] = force if force < low else low  # noqa: FURB136
        a1 = _row(W, W_A1, lane)
        a2 = _row(W, W_A2, lane)
        acc[Q_A1_SQ * LANES + lane] += a1 * a1
        acc[Q_A2_SQ * LANES + lane] += a2 * a2
        drive_side = 1.0 if x > b else 0.0
        back_side = 1.0 if x < -b else 0.0
        back_side = 0.0 if x > b else back_side
        acc[Q_N_DRIVE * LANES + lane] += drive_side
        acc[Q_N_BACK * LANES + lane] += back_side
        acc[Q_N_SEP * LANES + lane] += 1.0 - drive_side - back_side
        acc[Q_COUNT * LANES + lane] += 1.0


@nb.njit(**JIT_OPTIONS)
def _record(history, row, W, forcing, samples, written, n, j, steps, period, params):
    """The decimated histories of each written lane at grid step ``j`` of period ``n`` (``forcing``: the
    forcing table's row of the step's first sub-step)."""
    for lane in range(LANES):
        if not written[lane]:
            continue
        i = samples[lane]
        x = _row(W, W_STATE + 2, lane)
        history[i, 0, row] = x
        if history.shape[1] >= STATE_CHANNELS:
            history[i, 4, row] = _row(W, W_STATE, lane)
            history[i, 5, row] = _row(W, W_STATE + 1, lane)
            history[i, 6, row] = _row(forcing, T_STE, lane)
        if history.shape[1] >= RIG_CHANNELS:
            # the rig's channels: te = x - y1 + y2 + e, and the bearing accelerations
            t = n * period[lane] + j * (period[lane] / steps)
            history[i, 1, row] = (
                x - _row(W, W_STATE, lane) + _row(W, W_STATE + 1, lane) + static_transmission_error(t, params[i])
            )
            history[i, 2, row] = _row(W, W_A1, lane)
            history[i, 3, row] = _row(W, W_A2, lane)


@nb.njit(**JIT_OPTIONS)
def _renormalise(W, lane, shadow, scale, kept, log_growth):
    """Benettin renormalisation of a shadow lane once per mesh period, as in the one-sample kernel."""
    distance = 0.0
    for c in range(6):
        distance += ((_row(W, W_STATE + c, shadow) - _row(W, W_STATE + c, lane)) / scale[c]) ** 2
    distance = math.sqrt(distance)
    if distance > 0.0:
        if kept:
            log_growth[lane] += math.log(distance / SEPARATION)
        ratio = SEPARATION / distance
        for c in range(6):
            here = _row(W, W_STATE + c, lane)
            W[(W_STATE + c) * LANES + shadow] = here + (_row(W, W_STATE + c, shadow) - here) * ratio
    else:
        for c in range(6):
            W[(W_STATE + c) * LANES + shadow] = _row(W, W_STATE + c, lane)
        W[(W_STATE + 2) * LANES + shadow] = _row(W, W_STATE + 2, lane) + SEPARATION * scale[2]
