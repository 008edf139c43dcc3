"""Samples as SIMD lanes: a batch kernel that advances ``LANES`` runs together, bit for bit the one-sample kernel.

One RK4 sub-step of the 3-DOF model is a chain of about 200 dependent
floating-point operations (three divisions among them), so a single run
waits on latency, not on arithmetic. Eight runs with the same sub-step
layout (same steps per mesh period, same stiffness breakpoints) are
advanced together here: the per-lane code of :func:`_lane` is written out
eight times in :func:`_step_lanes`, on loads and stores that are adjacent
across lanes, so that LLVM's SLP vectoriser packs the eight chains into
vector instructions and the lanes' latencies overlap.

Each lane computes exactly the operations of the one-sample kernel
(:func:`uqgear.physics._rhs.classical_step`, through the same
:func:`~uqgear.physics._rhs.state_derivative` and
:func:`~uqgear.physics._rhs.rk4_step`; no fast-math, so nothing is
reassociated or fused), so its numbers are the same, bit for bit. What
differs between lanes is handled per lane: its own parameters, forcing
table, times and contact state; a lane whose step changes its contact
region is redone on its own by the one-sample code
(:func:`~uqgear.physics._rhs._split_at_contact`).

The lanes take the runs whose forcing repeats every mesh period: no pitch
errors, tooth factors, run-out, torque ripple or adhesion oscillation
(:func:`lane_ready`). Then the whole forcing of a sub-step (stiffness,
friction term, drive, e'') is a table built once per run from the
one-sample kernel's own :func:`~uqgear.physics._rhs._forcing_row`. With
``lyapunov`` a group holds four runs and their four shadow runs.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

import numba as nb
import numpy as np

from uqgear.physics._rhs import (
    ADHESION_AMPLITUDE,
    ECC_AMPLITUDE,
    ECC_KAPPA,
    INLINED,
    JIT_OPTIONS,
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
    _forcing_row,
    _split_at_contact,
    build_schedule,
    coefficients,
    state_derivative,
    static_transmission_error,
)

#: Runs advanced together: two vectors of four doubles (AVX2), enough independent chains to hide
#: the latency of one.
LANES = 8
#: Separation of a shadow run from its run (scaled state), as in the one-sample kernel.
SEPARATION = 1e-7

#: Slots a lane reads beyond :func:`~uqgear.physics._rhs.coefficients`.
N_COEFFICIENTS = 12


@contextlib.contextmanager
def slp_vectorised() -> Iterator[None]:
    """Compile with LLVM's SLP vectoriser on (numba leaves it off by default: ``NUMBA_SLP_VECTORIZE``).

    The lanes need it (their code is straight-line, not a loop); it packs
    the same IEEE operations into vector instructions, so the numbers do not
    change. numba reads the setting each time it optimises a module, so it
    is on for what is compiled inside this block (loading from the cache
    compiles nothing).
    """
    saved = nb.config.SLP_VECTORIZE
    nb.config.SLP_VECTORIZE = 1
    try:
        yield
    finally:
        nb.config.SLP_VECTORIZE = saved


def lane_ready(params: np.ndarray) -> np.ndarray:
    """Which runs (rows of parameter vectors) the lanes take: those whose forcing repeats every mesh period."""
    p = np.atleast_2d(params)
    return ((p[:, PITCH_ERRORS] == 0.0) & (p[:, TOOTH_FACTORS] == 0.0) & (p[:, ECC_AMPLITUDE] == 0.0)
            & (p[:, ECC_KAPPA] == 0.0) & (p[:, RIPPLE_AMPLITUDE] == 0.0) & (p[:, ADHESION_AMPLITUDE] == 0.0))


#: Small integers (lane, stage and row numbers) as plain int64: a literal 0..7 in a call makes numba
#: compile the callee once per value (it specialises on literal arguments), eight times the work
LANE = np.arange(LANES, dtype=np.int64)


@nb.njit(**INLINED)
def _coefficients(co, lane):
    return (co[0, lane], co[1, lane], co[2, lane], co[3, lane], co[4, lane], co[5, lane], co[6, lane], co[7, lane],
            co[8, lane], co[9, lane], co[10, lane], co[11, lane])


@nb.njit(**INLINED)
def _first_stage(S, table, drive, co, sub, lane):
    """RK4's first stage of one lane: (ds/dt, mesh force) at the sub-step's start."""
    s = (S[0, lane], S[1, lane], S[2, lane], S[3, lane], S[4, lane], S[5, lane])
    return state_derivative(s, table[sub, 0, 0, lane], table[sub, 0, 1, lane], drive[lane], table[sub, 0, 2, lane],
                            _coefficients(co, lane))


@nb.njit(**INLINED)
def _later_stage(S, D, factor, table, widths, drive, co, sub, stage, lane):
    """RK4's stage at s + (factor h) D of one lane, with the forcing of tabulated ``stage`` (1 middle, 2 end)."""
    h = factor * widths[sub, lane]
    s = (S[0, lane] + h * D[0, lane], S[1, lane] + h * D[1, lane], S[2, lane] + h * D[2, lane],
         S[3, lane] + h * D[3, lane], S[4, lane] + h * D[4, lane], S[5, lane] + h * D[5, lane])
    d, _ = state_derivative(s, table[sub, stage, 0, lane], table[sub, stage, 1, lane], drive[lane],
                            table[sub, stage, 2, lane], _coefficients(co, lane))
    return d


@nb.njit(**INLINED)
def _combined(S, D1, D2, D3, D4, widths, co, sub, lane):
    """RK4's update of one lane (:func:`~uqgear.physics._rhs.rk4_combine`), and 1.0 where it changes the
    contact region (that lane is then redone on its own)."""
    w = widths[sub, lane] / 6.0
    trial = (S[0, lane] + w * (D1[0, lane] + 2.0 * D2[0, lane] + 2.0 * D3[0, lane] + D4[0, lane]),
             S[1, lane] + w * (D1[1, lane] + 2.0 * D2[1, lane] + 2.0 * D3[1, lane] + D4[1, lane]),
             S[2, lane] + w * (D1[2, lane] + 2.0 * D2[2, lane] + 2.0 * D3[2, lane] + D4[2, lane]),
             S[3, lane] + w * (D1[3, lane] + 2.0 * D2[3, lane] + 2.0 * D3[3, lane] + D4[3, lane]),
             S[4, lane] + w * (D1[4, lane] + 2.0 * D2[4, lane] + 2.0 * D3[4, lane] + D4[4, lane]),
             S[5, lane] + w * (D1[5, lane] + 2.0 * D2[5, lane] + 2.0 * D3[5, lane] + D4[5, lane]))
    b = co[0, lane]
    x = S[2, lane]
    crossed = 0.0
    if ((x > b) != (trial[2] > b)) | ((x < -b) != (trial[2] < -b)):
        crossed = 1.0
    return trial, crossed


@nb.njit(**INLINED)
def _put(out, r0, r1, r2, r3, r4, r5, r6, r7):
    """Components of eight lanes' 6-tuples into ``out`` (6, LANES), component by component: adjacent
    stores. Constant indices only: a tuple indexed by a loop variable goes through memory, and its
    copies mislead the vectoriser into pairing components of one lane."""
    out[0, 0], out[0, 1], out[0, 2], out[0, 3] = r0[0], r1[0], r2[0], r3[0]
    out[0, 4], out[0, 5], out[0, 6], out[0, 7] = r4[0], r5[0], r6[0], r7[0]
    out[1, 0], out[1, 1], out[1, 2], out[1, 3] = r0[1], r1[1], r2[1], r3[1]
    out[1, 4], out[1, 5], out[1, 6], out[1, 7] = r4[1], r5[1], r6[1], r7[1]
    out[2, 0], out[2, 1], out[2, 2], out[2, 3] = r0[2], r1[2], r2[2], r3[2]
    out[2, 4], out[2, 5], out[2, 6], out[2, 7] = r4[2], r5[2], r6[2], r7[2]
    out[3, 0], out[3, 1], out[3, 2], out[3, 3] = r0[3], r1[3], r2[3], r3[3]
    out[3, 4], out[3, 5], out[3, 6], out[3, 7] = r4[3], r5[3], r6[3], r7[3]
    out[4, 0], out[4, 1], out[4, 2], out[4, 3] = r0[4], r1[4], r2[4], r3[4]
    out[4, 4], out[4, 5], out[4, 6], out[4, 7] = r4[4], r5[4], r6[4], r7[4]
    out[5, 0], out[5, 1], out[5, 2], out[5, 3] = r0[5], r1[5], r2[5], r3[5]
    out[5, 4], out[5, 5], out[5, 6], out[5, 7] = r4[5], r5[5], r6[5], r7[5]


@nb.njit(**INLINED)
def _put_row(out, row, v0, v1, v2, v3, v4, v5, v6, v7):
    out[row, 0], out[row, 1], out[row, 2], out[row, 3] = v0, v1, v2, v3
    out[row, 4], out[row, 5], out[row, 6], out[row, 7] = v4, v5, v6, v7


@nb.njit(**INLINED)
def _later_stages(S, D, out, factor, table, widths, drive, co, sub, stage):
    _put(out, _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[0]),
         _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[1]),
         _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[2]),
         _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[3]),
         _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[4]),
         _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[5]),
         _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[6]),
         _later_stage(S, D, factor, table, widths, drive, co, sub, stage, LANE[7]))


@nb.njit(**INLINED)
def _step_lanes(S, trial, D1, D2, D3, D4, aux, table, widths, drive, co, sub):
    """Sub-step ``sub`` of all eight lanes into ``trial``; force, y1'', y2'' and the crossing flag into ``aux``.

    Stage by stage, each written out lane by lane (no loop: LLVM unrolls no
    loop body this long) and stored component by component, so that the
    SLP vectoriser finds eight alike operations on adjacent memory, in
    trees shallow enough for its depth limit. Returns the number of lanes
    whose step crossed a contact boundary.
    """
    r0 = _first_stage(S, table, drive, co, sub, LANE[0])
    r1 = _first_stage(S, table, drive, co, sub, LANE[1])
    r2 = _first_stage(S, table, drive, co, sub, LANE[2])
    r3 = _first_stage(S, table, drive, co, sub, LANE[3])
    r4 = _first_stage(S, table, drive, co, sub, LANE[4])
    r5 = _first_stage(S, table, drive, co, sub, LANE[5])
    r6 = _first_stage(S, table, drive, co, sub, LANE[6])
    r7 = _first_stage(S, table, drive, co, sub, LANE[7])
    _put(D1, r0[0], r1[0], r2[0], r3[0], r4[0], r5[0], r6[0], r7[0])
    _put_row(aux, LANE[0], r0[1], r1[1], r2[1], r3[1], r4[1], r5[1], r6[1], r7[1])
    _put_row(aux, LANE[1], r0[0][3], r1[0][3], r2[0][3], r3[0][3], r4[0][3], r5[0][3], r6[0][3], r7[0][3])
    _put_row(aux, LANE[2], r0[0][4], r1[0][4], r2[0][4], r3[0][4], r4[0][4], r5[0][4], r6[0][4], r7[0][4])
    _later_stages(S, D1, D2, 0.5, table, widths, drive, co, sub, LANE[1])
    _later_stages(S, D2, D3, 0.5, table, widths, drive, co, sub, LANE[1])
    _later_stages(S, D3, D4, 1.0, table, widths, drive, co, sub, LANE[2])
    c0 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[0])
    c1 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[1])
    c2 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[2])
    c3 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[3])
    c4 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[4])
    c5 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[5])
    c6 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[6])
    c7 = _combined(S, D1, D2, D3, D4, widths, co, sub, LANE[7])
    _put(trial, c0[0], c1[0], c2[0], c3[0], c4[0], c5[0], c6[0], c7[0])
    _put_row(aux, LANE[3], c0[1], c1[1], c2[1], c3[1], c4[1], c5[1], c6[1], c7[1])
    return (c0[1] + c1[1]) + (c2[1] + c3[1]) + ((c4[1] + c5[1]) + (c6[1] + c7[1]))


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


@nb.njit(**JIT_OPTIONS)
def _split_lane(lane, n, sub, S, trial, D1, widths, offsets, refs, period, i, params, pair_tables,
                period_tables, table_index, factor_pinion, factor_gear):
    """Redo a lane's sub-step that changed its contact region, as the one-sample kernel does."""
    p = params[i]
    table_i = table_index[i]
    start = n * period[lane]
    s = (S[0, lane], S[1, lane], S[2, lane], S[3, lane], S[4, lane], S[5, lane])
    d1 = (D1[0, lane], D1[1, lane], D1[2, lane], D1[3, lane], D1[4, lane], D1[5, lane])
    attempt = (trial[0, lane], trial[1, lane], trial[2, lane], trial[3, lane], trial[4, lane], trial[5, lane])
    done = _split_at_contact(start + offsets[sub, lane], widths[sub, lane], s, d1, attempt, start + refs[sub, lane],
                             p, pair_tables[table_i], period_tables[table_i], factor_pinion[i], factor_gear[i])
    for c in range(6):
        trial[c, lane] = done[c]


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_lanes(first, last, groups, states, params, pair_tables, period_tables, table_index, factor_pinion,
                    factor_gear, breakpoints, steps_per_period, n_periods, keep_periods, history_stride, lyapunov,
                    scales, accumulators, poincare, history, final_states, refused):
    """Integrate lane groups ``first`` to ``last - 1`` of a batch (GIL released).

    ``groups`` has one row of ``LANES`` sample indices per group (-1: an
    empty lane); with ``lyapunov`` only the first half of a row is used and
    the second half runs the shadows. The arguments after ``groups`` are
    those of :func:`uqgear.physics._kernels.integrate_batch`, filled alike.
    A run whose sub-step layout differs from its group's first run is not
    integrated: ``refused`` says so, and the caller runs it one at a time.
    """
    for g in range(first, last):
        _integrate_group(groups[g], states, params, pair_tables, period_tables, table_index, factor_pinion,
                         factor_gear, breakpoints, steps_per_period, n_periods, keep_periods, history_stride,
                         lyapunov, scales, accumulators, poincare, history, final_states, refused)


@nb.njit(**JIT_OPTIONS)
def _integrate_group(members, states, params, pair_tables, period_tables, table_index, factor_pinion, factor_gear,
                     breakpoints, steps_per_period, n_periods, keep_periods, history_stride, lyapunov, scales,
                     accumulators, poincare, history, final_states, refused):
    samples, written = _lane_samples(members, lyapunov)
    lead = samples[0]
    steps = steps_per_period[lead]
    stride = history_stride[lead]
    lead_table = table_index[lead]
    layout = build_schedule(params[lead], pair_tables[lead_table], period_tables[lead_table], breakpoints[lead], steps)
    first_sub = layout[0]
    pairs = layout[4]
    n_sub = first_sub[steps]
    table = np.empty((n_sub, 3, 3, LANES))
    widths = np.empty((n_sub, LANES))
    offsets = np.empty((n_sub, LANES))
    refs = np.empty((n_sub, LANES))
    drive = np.empty(LANES)
    co = np.empty((N_COEFFICIENTS, LANES))
    period = np.empty(LANES)
    for lane in range(LANES):
        i = samples[lane]
        t_i = table_index[i]
        schedule = build_schedule(params[i], pair_tables[t_i], period_tables[t_i], breakpoints[i], steps)
        same = (steps_per_period[i] == steps and history_stride[i] == stride
                and np.array_equal(schedule[0], first_sub) and np.array_equal(schedule[4][:n_sub], pairs[:n_sub]))
        if not same:
            # run one at a time by the caller; this lane repeats the lead run and writes nothing
            refused[i] = True
            written[lane] = False
            i = lead
            samples[lane] = lead
            t_i = lead_table
            schedule = build_schedule(params[i], pair_tables[t_i], period_tables[t_i], breakpoints[i], steps)
        p = params[i]
        _, sub_offsets, sub_widths, sub_refs, sub_pairs, stages = schedule
        for sub in range(n_sub):
            widths[sub, lane] = sub_widths[sub]
            offsets[sub, lane] = sub_offsets[sub]
            refs[sub, lane] = sub_refs[sub]
            for stage in range(3):
                # t and the mesh period n do not enter the forcing of a lane-ready run
                terms = _forcing_row(0.0, 0, stages, sub, stage, sub_pairs[sub], p, factor_pinion[i], factor_gear[i])
                table[sub, stage, 0, lane] = terms[0]
                table[sub, stage, 1, lane] = terms[1]
                table[sub, stage, 2, lane] = terms[4]
                drive[lane] = terms[2]
        c = coefficients(p)
        for k in range(N_COEFFICIENTS):
            co[k, lane] = c[k]
        period[lane] = TWO_PI / p[OMEGA_MESH]
    _run_lanes(samples, written, table, widths, offsets, refs, drive, co, period, first_sub, steps, stride, states,
               params, pair_tables, period_tables, table_index, factor_pinion, factor_gear, n_periods, keep_periods,
               lyapunov, scales, accumulators, poincare, history, final_states)


@nb.njit(**JIT_OPTIONS)
def _run_lanes(samples, written, table, widths, offsets, refs, drive, co, period, first_sub, steps, stride, states,
               params, pair_tables, period_tables, table_index, factor_pinion, factor_gear, n_periods, keep_periods,
               lyapunov, scales, accumulators, poincare, history, final_states):
    """The time loop of a lane group: the one-sample kernel's loop, lane by lane (see the module doc)."""
    half = LANES // 2
    live = written.copy()
    if lyapunov:
        live[half:] = written[:half]
    S = np.empty((6, LANES))
    trial = np.empty((6, LANES))
    aux = np.empty((4, LANES))
    D1 = np.empty((6, LANES))
    D2 = np.empty((6, LANES))
    D3 = np.empty((6, LANES))
    D4 = np.empty((6, LANES))
    acc = np.zeros((N_ACCUMULATORS, LANES))
    log_growth = np.zeros(LANES)
    for lane in range(LANES):
        for c in range(6):
            S[c, lane] = states[samples[lane], c]
        if lyapunov and lane >= half:
            S[2, lane] = S[2, lane] + SEPARATION * scales[samples[lane], 2]
        acc[Q_X_MIN, lane] = np.inf
        acc[Q_X_MAX, lane] = -np.inf
        acc[Q_F_MAX, lane] = -np.inf
        acc[Q_F_MIN, lane] = np.inf
    rig_channels = history.shape[1] >= 4
    first_kept = n_periods - keep_periods
    row = 0
    for n in range(n_periods):
        kept = n >= first_kept
        if kept:
            for lane in range(LANES):
                if written[lane]:
                    poincare[samples[lane], n - first_kept, 0] = S[2, lane]
                    poincare[samples[lane], n - first_kept, 1] = S[5, lane]
        for j in range(steps):
            for sub in range(first_sub[j], first_sub[j + 1]):
                crossed = _step_lanes(S, trial, D1, D2, D3, D4, aux, table, widths, drive, co, sub)
                if sub == first_sub[j] and kept:
                    _accumulate(acc, S, aux, co)
                    if stride > 0 and j % stride == 0:
                        _record(history, row, rig_channels, S, aux, samples, written, n, j, steps, period, params)
                        row += 1
                if crossed != 0.0:
                    for lane in range(LANES):
                        # an empty lane's numbers are never read: it is not redone
                        if aux[3, lane] != 0.0 and live[lane]:
                            _split_lane(lane, n, sub, S, trial, D1, widths, offsets, refs, period,
                                        samples[lane], params, pair_tables, period_tables, table_index,
                                        factor_pinion, factor_gear)
                S, trial = trial, S
        if lyapunov:
            for lane in range(half):
                _renormalise(S, lane, lane + half, scales[samples[lane]], kept, log_growth)
    for lane in range(LANES):
        if not written[lane]:
            continue
        i = samples[lane]
        for q in range(N_ACCUMULATORS):
            accumulators[i, q] = acc[q, lane]
        if lyapunov:
            accumulators[i, Q_LYAPUNOV] = log_growth[lane] / (keep_periods * period[lane])
        else:
            accumulators[i, Q_LYAPUNOV] = np.nan
        for c in range(6):
            final_states[i, c] = S[c, lane]


@nb.njit(**INLINED)
def _accumulate(acc, S, aux, co):
    """The one-sample kernel's QoI sums for each lane, at the start of a kept grid step."""
    # the same comparisons as there, written as choices between values (selects) and counts that add
    # 0.0 or 1.0 (exact), so that the unrolled lanes vectorise
    for lane in range(LANES):
        x = S[2, lane]
        force = aux[0, lane]
        b = co[0, lane]
        acc[Q_X_SUM, lane] += x
        acc[Q_X_SQ, lane] += x * x
        low = acc[Q_X_MIN, lane]
        acc[Q_X_MIN, lane] = x if x < low else low  # noqa: FURB136
        high = acc[Q_X_MAX, lane]
        acc[Q_X_MAX, lane] = x if x > high else high  # noqa: FURB136
        high = acc[Q_F_MAX, lane]
        acc[Q_F_MAX, lane] = force if force > high else high  # noqa: FURB136
        low = acc[Q_F_MIN, lane]
        acc[Q_F_MIN, lane] = force if force < low else low  # noqa: FURB136
        acc[Q_A1_SQ, lane] += aux[1, lane] * aux[1, lane]
        acc[Q_A2_SQ, lane] += aux[2, lane] * aux[2, lane]
        drive_side = 1.0 if x > b else 0.0
        back_side = 1.0 if x < -b else 0.0
        back_side = 0.0 if x > b else back_side
        acc[Q_N_DRIVE, lane] += drive_side
        acc[Q_N_BACK, lane] += back_side
        acc[Q_N_SEP, lane] += 1.0 - drive_side - back_side
        acc[Q_COUNT, lane] += 1.0


@nb.njit(**JIT_OPTIONS)
def _record(history, row, rig_channels, S, aux, samples, written, n, j, steps, period, params):
    """The decimated histories of each written lane at grid step ``j`` of period ``n``."""
    for lane in range(LANES):
        if not written[lane]:
            continue
        i = samples[lane]
        x = S[2, lane]
        history[i, 0, row] = x
        if rig_channels:
            # the rig's channels: te = x - y1 + y2 + e, and the bearing accelerations
            t = n * period[lane] + j * (period[lane] / steps)
            history[i, 1, row] = x - S[0, lane] + S[1, lane] + static_transmission_error(t, params[i])
            history[i, 2, row] = aux[1, lane]
            history[i, 3, row] = aux[2, lane]


@nb.njit(**JIT_OPTIONS)
def _renormalise(S, lane, shadow, scale, kept, log_growth):
    """Benettin renormalisation of a shadow lane once per mesh period, as in the one-sample kernel."""
    distance = 0.0
    for c in range(6):
        distance += ((S[c, shadow] - S[c, lane]) / scale[c]) ** 2
    distance = math.sqrt(distance)
    if distance > 0.0:
        if kept:
            log_growth[lane] += math.log(distance / SEPARATION)
        ratio = SEPARATION / distance
        for c in range(6):
            S[c, shadow] = S[c, lane] + (S[c, shadow] - S[c, lane]) * ratio
    else:
        for c in range(6):
            S[c, shadow] = S[c, lane]
        S[2, shadow] = S[2, lane] + SEPARATION * scale[2]
