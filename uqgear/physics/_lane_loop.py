"""The time loop of a lane group, whichever step its lanes take: set-up, QoI sums, histories, write-out.

A lane group (:mod:`uqgear.physics._lanes`) advances ``LANES`` runs together; the runs without
pitch errors take the classical lane step there, the runs with them the per-pair step of
:mod:`uqgear.physics._pair_lanes`. Everything around the step is the same for both and is here:
each lane's schedule and coefficients (:func:`integrate_group`), the loop over mesh periods and
grid steps with the one-sample kernel's QoI sums, Poincare points, decimated histories and
Lyapunov renormalisation (:func:`run_lanes`). The two entry kernels pass their own step, redo,
forcing fill, period start and contact count as functions; numba inlines this loop into each
(``inline="always"``), so each entry is compiled with static calls to its own family alone.

A lane group's work array ``W`` holds row r of lane l at element ``r * LANES + l``, so that a row
is a vector of the lanes and every offset a constant (the loop vectoriser then proves that the
rows do not overlap).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from uqgear.physics._lane_tables import (
    LANES,
    RIG_CHANNELS,
    STATE_CHANNELS,
    T_STE,
    _copy_lane,
    _same_schedule,
    _take_schedule,
)
from uqgear.physics._pair_extremes import N_EXTREMES, NO_EXTREMES, add_pair_extremes
from uqgear.physics._pairs import _tooth_terms
from uqgear.physics._rhs import (
    INLINED,
    JIT_OPTIONS,
    M1,
    M2,
    MAX_PAIRS,
    ME,
    N_ACCUMULATORS,
    N_COEFFICIENTS,
    OMEGA_MESH,
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
    TWO_PI,
    coefficients,
    coefficients_by,
    periodic_forcing,
    static_transmission_error,
)
from uqgear.physics._stepper import build_schedule

#: Separation of a shadow run from its run (scaled state), as in the one-sample kernel.
SEPARATION = 1e-7

# Rows of a lane group's work array: the state, the sub-step's result, its first stage, the mesh
# force and the bearing accelerations at its start, what is left to do for the lane (REDO_*), each
# lane's coefficients and the inverses 1/m1, 1/m2, 1/m_e of its divisors. A step family may add
# rows after N_ROWS (the pair lanes: each pair's pitch offset).
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
#: the exact quotient is proven, see uqgear.physics._quotient, or a pair's contact change).
REDO_NONE = 0.0
REDO_SPLIT = 1.0
REDO_STEP = 2.0


@nb.njit(**INLINED)
def row_of(W, row, lane):
    """Element ``lane`` of row ``row`` of a lane group's work array (or of a forcing table's row)."""
    return W[row * LANES + lane]


@nb.njit(**INLINED)
def lane_state(W, first, lane):
    """The 6-tuple of rows ``first`` to ``first + 5`` of one lane."""
    return (
        row_of(W, first, lane),
        row_of(W, first + 1, lane),
        row_of(W, first + 2, lane),
        row_of(W, first + 3, lane),
        row_of(W, first + 4, lane),
        row_of(W, first + 5, lane),
    )


@nb.njit(**INLINED)
def put_state(W, first, lane, s):
    """Write the 6-tuple ``s`` to rows ``first`` to ``first + 5`` of one lane."""
    W[first * LANES + lane] = s[0]
    W[(first + 1) * LANES + lane] = s[1]
    W[(first + 2) * LANES + lane] = s[2]
    W[(first + 3) * LANES + lane] = s[3]
    W[(first + 4) * LANES + lane] = s[4]
    W[(first + 5) * LANES + lane] = s[5]


@nb.njit(**INLINED)
def put_start(W, lane, d1, force):
    """A lane's force and bearing accelerations at its sub-step's start (what the QoI sums read), from its
    first stage ``d1``."""
    W[W_FORCE * LANES + lane] = force
    W[W_A1 * LANES + lane] = d1[3]
    W[W_A2 * LANES + lane] = d1[4]


@nb.njit(**INLINED)
def put_step(W, lane, new, d1, force, redo):
    """A lane's sub-step result, first stage, start force and bearing accelerations, and what is left (``REDO_*``).

    Written out, not a loop over the tuples: a tuple indexed by a variable goes through memory.
    """
    put_state(W, W_TRIAL, lane, new)
    put_state(W, W_SLOPE, lane, d1)
    put_start(W, lane, d1, force)
    W[W_REDO * LANES + lane] = redo


@nb.njit(**INLINED)
def region_changed(before, after, b):
    """Whether a deflection from ``before`` to ``after`` changes its contact region (``contact_region``'s test,
    as choices between values, so that a loop over the lanes vectorises)."""
    return ((before > b) != (after > b)) | ((before < -b) != (after < -b))


@nb.njit(**INLINED)
def _row_slot(W, slot, position, lane):
    """A lane's coefficient at ``position`` from its rows of the work array (a reader of
    :func:`~uqgear.physics._rhs.coefficients_by`)."""
    return row_of(W, W_COEFFICIENTS + position, lane)


@nb.njit(**INLINED)
def lane_coefficients(W, lane):
    """(coefficients, inverses of the divisors) of one lane, as tuples (registers): the slots of
    :func:`~uqgear.physics._rhs.coefficients_by`, from the rows :func:`put_coefficients` wrote."""
    c = coefficients_by(_row_slot, W, lane)
    inverse = (row_of(W, W_INVERSE, lane), row_of(W, W_INVERSE + 1, lane), row_of(W, W_INVERSE + 2, lane))
    return c, inverse


@nb.njit(**INLINED)
def put_coefficients(W, lane, p):
    """A lane's coefficients (:func:`~uqgear.physics._rhs.coefficients` of its parameters ``p``) and the
    inverses 1/m1, 1/m2, 1/m_e of its divisors into the rows :func:`lane_coefficients` reads."""
    c = coefficients(p)
    for k in range(N_COEFFICIENTS):
        W[(W_COEFFICIENTS + k) * LANES + lane] = c[k]
    W[W_INVERSE * LANES + lane] = 1.0 / p[M1]
    W[(W_INVERSE + 1) * LANES + lane] = 1.0 / p[M2]
    W[(W_INVERSE + 2) * LANES + lane] = 1.0 / p[ME]


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


@nb.njit(**JIT_OPTIONS)
def _group_layout(members, batch, rows, refused):
    """Each lane's sample, sub-steps and tabulated stages, and its coefficients in a fresh work array.

    A run whose sub-step layout differs from the group's first run is refused (``refused``); its
    lane repeats the lead run and writes nothing.
    """
    runs = batch.runs
    params, pair_tables, period_tables = runs.params, runs.pair_tables, runs.period_tables
    table_index, breakpoints = runs.table_index, runs.breakpoints
    steps_per_period, history_stride = batch.steps_per_period, batch.history_stride
    samples, written = _lane_samples(members, batch.lyapunov)
    lead = samples[0]
    steps = steps_per_period[lead]
    stride = history_stride[lead]
    lead_table = table_index[lead]
    layout = build_schedule(params[lead], pair_tables[lead_table], period_tables[lead_table], breakpoints[lead], steps)
    first_sub = layout[0]
    pairs = layout[4]
    n_sub = first_sub[steps]
    widths = np.empty((n_sub, LANES))
    offsets = np.empty((n_sub, LANES))
    refs = np.empty((n_sub, LANES))
    # each lane's tabulated stages (its schedule's table), from which its forcing is filled
    stages = np.empty((LANES, n_sub, 3, layout[5].shape[2]))
    W = np.zeros(rows * LANES)
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
                # run one at a time by the caller
                refused[i] = True
                written[lane] = False
                samples[lane] = lead
                schedule = layout
            _take_schedule(stages, widths, offsets, refs, lane, schedule, n_sub)
            filled = lane
        put_coefficients(W, lane, params[samples[lane]])
    return samples, written, W, widths, offsets, refs, stages, first_sub, pairs, steps, stride


# numba-inlined into each entry kernel with that family's functions, as uqgear.physics._kernels
# does with its one-sample loop (numba compiles one specialisation per set of functions passed)
@nb.njit(**JIT_OPTIONS, inline="always")
def integrate_group(
    step,
    redo,
    fill,
    start_period,
    contact_counts,
    rows,
    table_width,
    members,
    batch,
    refused,
):
    """Integrate one lane group (``members``: a row of ``groups``) with a step family's functions.

    ``step(W, table, sub, lanes, n_pairs)`` advances every lane over sub-step ``sub`` and returns how
    many leave something to ``redo(lane, n, sub, W, table, widths, offsets, refs, period, i, runs, stages,
    pairs)`` (``runs``: the batch's :class:`~uqgear.physics._batch_record.RunInputs`); ``fill(table, lane, n, period,
    widths, offsets, stages, pairs, p, fp, fg)`` writes a lane's forcing table for period ``n``;
    ``start_period(W, lane, n, p, fp, fg)`` sets what a lane's step reads of period ``n`` beyond the
    table; ``contact_counts(W, lane, n_pairs)`` says (drive side, back side) of a lane's contact as
    0.0 or 1.0. ``rows`` and ``table_width`` size the work array and the forcing table.
    """
    samples, written, W, widths, offsets, refs, stages, first_sub, pairs, steps, stride = _group_layout(
        members, batch, rows, refused
    )
    runs = batch.runs
    params, factor_pinion, factor_gear = runs.params, runs.factor_pinion, runs.factor_gear
    n_periods, keep_periods, lyapunov, scales = batch.n_periods, batch.keep_periods, batch.lyapunov, batch.scales
    table = np.empty((widths.shape[0], table_width * LANES))
    period = np.empty(LANES)
    moving = False
    for lane in range(LANES):
        i = samples[lane]
        period[lane] = TWO_PI / params[i, OMEGA_MESH]
        fill(table, lane, 0, period[lane], widths, offsets, stages[lane], pairs, params[i], factor_pinion[i],
             factor_gear[i])
        moving = moving or not periodic_forcing(params[i])
    half = LANES // 2
    # LANES, but not a constant to LLVM (see uqgear.physics._lanes._step_lanes)
    lanes = W.size // rows
    live = written.copy()
    if lyapunov:
        live[half:] = written[:half]
    acc = _start_lanes(W, runs.states, samples, lyapunov, scales)
    stresses = batch.stresses
    extremes = _start_extremes()
    # each lane's pitch offsets and tooth factors of the pair slots in the current period
    teeth = np.zeros((LANES, 2 * MAX_PAIRS))
    log_growth = np.zeros(LANES)
    whole_state = batch.poincare.shape[2] >= 6
    first_kept = n_periods - keep_periods
    row = 0
    for n in range(n_periods):
        for lane in range(LANES):
            i = samples[lane]
            start_period(W, lane, n, params[i], factor_pinion[i], factor_gear[i])
            if stresses and written[lane]:
                _keep_teeth(teeth[lane], n, params[i], factor_pinion[i], factor_gear[i])
            # an empty or refused lane's numbers are never read: its table may lag
            if moving and n > 0 and live[lane]:
                fill(table, lane, n, period[lane], widths, offsets, stages[lane], pairs, params[i],
                     factor_pinion[i], factor_gear[i])
        kept = n >= first_kept
        if kept:
            _keep_poincare(batch.poincare, W, samples, written, n - first_kept, whole_state)
        for j in range(steps):
            for sub in range(first_sub[j], first_sub[j + 1]):
                if step(W, table, sub, lanes, pairs[sub]) != 0:
                    for lane in range(LANES):
                        # an empty lane's numbers are never read: it is not redone
                        if row_of(W, W_REDO, lane) != REDO_NONE and live[lane]:
                            redo(lane, n, sub, W, table, widths, offsets, refs, period, samples[lane], runs, stages,
                                 pairs)
                if sub == first_sub[j] and kept:
                    for lane in range(lanes):
                        drive_side, back_side = contact_counts(W, lane, pairs[sub])
                        _accumulate(acc, W, lane, drive_side, back_side)
                    if stresses:
                        # outside the vectorised loops: a batch without stresses runs the lanes' code alone
                        _add_lane_extremes(extremes, W, n, j, sub, steps, period, offsets, stages, pairs, samples,
                                           written, params, teeth)
                    if stride > 0 and j % stride == 0:
                        _record(batch.history, row, W, table[sub], samples, written, n, j, steps, period, params)
                        row += 1
                _advance(W, lanes)
        if lyapunov:
            for lane in range(half):
                _renormalise(W, lane, lane + half, scales[samples[lane]], kept, log_growth)
    _write_out(W, acc, log_growth, samples, written, lyapunov, keep_periods, period, batch.accumulators,
               batch.final_states)
    if stresses:
        _write_extremes(batch.stress_extremes, extremes, samples, written)


@nb.njit(**INLINED)
def _start_extremes():
    """Each lane's tooth-pair load extremes at their start (:data:`NO_EXTREMES`)."""
    extremes = np.empty((LANES, N_EXTREMES))
    for lane in range(LANES):
        for e in range(N_EXTREMES):
            extremes[lane, e] = NO_EXTREMES[e]
    return extremes


@nb.njit(**INLINED)
def _write_extremes(out, extremes, samples, written):
    """Each written lane's extremes into its run's row of ``out``."""
    for lane in range(LANES):
        if written[lane]:
            out[samples[lane]] = extremes[lane]


@nb.njit(**INLINED)
def _keep_teeth(row, n, p, fp, fg):
    """A lane's pitch offsets and tooth factors of its pair slots in period ``n`` (:func:`_tooth_terms`)."""
    offsets, factors = _tooth_terms(n, p, fp, fg)
    for i in range(MAX_PAIRS):
        row[i] = offsets[i]
        row[MAX_PAIRS + i] = factors[i]


@nb.njit(**INLINED)
def _add_lane_extremes(extremes, W, n, j, sub, steps, period, offsets, stages, pairs, samples, written, params, teeth):
    """Each written lane's tooth-pair loads at the start of grid step ``j`` (sub-step ``sub``) of period ``n``
    into its extremes, as the one-sample kernel adds them (the same arguments, so the same numbers)."""
    for lane in range(LANES):
        if not written[lane]:
            continue
        row = teeth[lane]
        tooth_terms = ((row[0], row[1], row[2], row[3]), (row[4], row[5], row[6], row[7]))
        kept = (extremes[lane, 0], extremes[lane, 1], extremes[lane, 2], extremes[lane, 3])
        kept = add_pair_extremes(
            kept, row_of(W, W_STATE + 2, lane), row_of(W, W_STATE + 5, lane), n * period[lane] + offsets[sub, lane],
            j / steps, tooth_terms, stages[lane], sub, pairs[sub], params[samples[lane]],
        )
        for e in range(N_EXTREMES):
            extremes[lane, e] = kept[e]


@nb.njit(**JIT_OPTIONS)
def _start_lanes(W, states, samples, lyapunov, scales):
    """Each lane's initial state (a shadow's displaced) into ``W``; returns the QoI sums, started."""
    half = LANES // 2
    acc = np.zeros(N_ACCUMULATORS * LANES)
    for lane in range(LANES):
        for c in range(6):
            W[(W_STATE + c) * LANES + lane] = states[samples[lane], c]
        if lyapunov and lane >= half:
            W[(W_STATE + 2) * LANES + lane] += SEPARATION * scales[samples[lane], 2]
        acc[Q_X_MIN * LANES + lane] = np.inf
        acc[Q_X_MAX * LANES + lane] = -np.inf
        acc[Q_F_MAX * LANES + lane] = -np.inf
        acc[Q_F_MIN * LANES + lane] = np.inf
    return acc


@nb.njit(**JIT_OPTIONS)
def _keep_poincare(poincare, W, samples, written, index, whole_state):
    """The Poincare point of each written lane at the start of kept period ``index``."""
    for lane in range(LANES):
        if not written[lane]:
            continue
        if whole_state:
            # the whole state at the period start, as the one-sample history keeps it
            for c in range(6):
                poincare[samples[lane], index, c] = row_of(W, W_STATE + c, lane)
        else:
            poincare[samples[lane], index, 0] = row_of(W, W_STATE + 2, lane)
            poincare[samples[lane], index, 1] = row_of(W, W_STATE + 5, lane)


@nb.njit(**JIT_OPTIONS)
def _write_out(W, acc, log_growth, samples, written, lyapunov, keep_periods, period, accumulators, final_states):
    """Each written lane's QoI sums, Lyapunov exponent and final state, into the batch's arrays."""
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
            final_states[i, c] = row_of(W, W_STATE + c, lane)


@nb.njit(**INLINED)
def _accumulate(acc, W, lane, drive_side, back_side):
    """The one-sample kernel's QoI sums for a lane at the start of a kept grid step; ``drive_side`` and
    ``back_side`` (0.0 or 1.0, not both 1.0) say its contact there."""
    # the same comparisons as there, written as choices between values (selects) and counts that add
    # 0.0 or 1.0 (exact), so that the loop over the lanes vectorises
    x = row_of(W, W_STATE + 2, lane)
    force = row_of(W, W_FORCE, lane)
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
    a1 = row_of(W, W_A1, lane)
    a2 = row_of(W, W_A2, lane)
    acc[Q_A1_SQ * LANES + lane] += a1 * a1
    acc[Q_A2_SQ * LANES + lane] += a2 * a2
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
        x = row_of(W, W_STATE + 2, lane)
        history[i, 0, row] = x
        if history.shape[1] >= STATE_CHANNELS:
            history[i, 4, row] = row_of(W, W_STATE, lane)
            history[i, 5, row] = row_of(W, W_STATE + 1, lane)
            history[i, 6, row] = row_of(forcing, T_STE, lane)
        if history.shape[1] >= RIG_CHANNELS:
            # the rig's channels: te = x - y1 + y2 + e, and the bearing accelerations
            t = n * period[lane] + j * (period[lane] / steps)
            history[i, 1, row] = (
                x - row_of(W, W_STATE, lane) + row_of(W, W_STATE + 1, lane) + static_transmission_error(t, params[i])
            )
            history[i, 2, row] = row_of(W, W_A1, lane)
            history[i, 3, row] = row_of(W, W_A2, lane)


@nb.njit(**JIT_OPTIONS)
def _renormalise(W, lane, shadow, scale, kept, log_growth):
    """Benettin renormalisation of a shadow lane once per mesh period, as in the one-sample kernel."""
    distance = 0.0
    for c in range(6):
        distance += ((row_of(W, W_STATE + c, shadow) - row_of(W, W_STATE + c, lane)) / scale[c]) ** 2
    distance = math.sqrt(distance)
    if distance > 0.0:
        if kept:
            log_growth[lane] += math.log(distance / SEPARATION)
        ratio = SEPARATION / distance
        for c in range(6):
            here = row_of(W, W_STATE + c, lane)
            W[(W_STATE + c) * LANES + shadow] = here + (row_of(W, W_STATE + c, shadow) - here) * ratio
    else:
        for c in range(6):
            W[(W_STATE + c) * LANES + shadow] = row_of(W, W_STATE + c, lane)
        W[(W_STATE + 2) * LANES + shadow] = row_of(W, W_STATE + 2, lane) + SEPARATION * scale[2]
