"""Runs with pitch errors as SIMD lanes: the per-pair step of :mod:`uqgear.physics._pairs`, eight runs at once.

With pitch errors each tooth pair in mesh has its own deflection ``x - e_i``
and dead zone (docs/model/equations.md section 2.6); the one-sample pair
kernel (:func:`~uqgear.physics._pairs.scheduled_step_pairs`) computes the mesh
force as ``sum_i k_i f(x - e_i) + c_m x'``. Here a lane group of such runs
advances together, as :mod:`uqgear.physics._lanes` does for the runs without:
each lane computes the one-sample operations in the same order (no
fast-math; dead zones, the damping switch and the pairs beyond those in mesh
as selects), so its numbers are the same, bit for bit.

- The forcing of a sub-step (per pair stiffness and friction term, drive,
  e'', e) is a table filled by the one-sample kernel's own
  :func:`~uqgear.physics._pairs._forcing_row_pairs` at the times it evaluates
  it: once per run where the forcing repeats every mesh period
  (:func:`~uqgear.physics._rhs.periodic_forcing`), else every period.
- The pairs' pitch offsets change every mesh period (the teeth in mesh
  change); they sit in rows of the work array, set at each period start from
  :func:`~uqgear.physics._pairs._tooth_terms`.
- Every group of a schedule has the same pairs in mesh on a sub-step; a
  lane sums over :data:`~uqgear.physics._rhs.MAX_PAIRS` slots, the slots
  beyond those in mesh with zero stiffness and friction (adding a zero
  product leaves a sum's bits as they are: it is never -0.0) and masked out
  of the contact test.
- A lane whose step changes any pair's contact region, or whose quotient
  the lanes cannot vouch for (:mod:`uqgear.physics._quotient`), has its
  sub-step redone by the one-sample code (:func:`_redo_pair_lane`).
"""

from __future__ import annotations

import numba as nb
import numpy as np

from uqgear.physics._batch_record import QoiBatch, run_arrays
from uqgear.physics._lane_loop import (
    N_ROWS,
    REDO_NONE,
    REDO_STEP,
    W_COEFFICIENTS,
    W_STATE,
    W_TRIAL,
    integrate_group,
    lane_coefficients,
    lane_state,
    put_start,
    put_state,
    put_step,
    region_changed,
    row_of,
)
from uqgear.physics._lane_tables import LANES, N_TABLE, T_DRIVE, T_STE, T_WEIGHT, T_WIDTH
from uqgear.physics._lanes import compile_lane_kernel
from uqgear.physics._pairs import (
    PAIR_FRICTION,
    PAIR_K,
    _forcing_row_pairs,
    _tooth_terms,
    pair_derivative_by,
    pair_lane_field,
    substep_pairs,
)
from uqgear.physics._quotient import quotient
from uqgear.physics._rhs import INLINED, JIT_OPTIONS, MAX_PAIRS
from uqgear.physics._stepper import rk4_combine_weighted, rk4_stages

#: Rows of a pair lane group's work array: those of every lane group, then each pair slot's pitch offset.
W_OFFSETS = N_ROWS
N_PAIR_ROWS = W_OFFSETS + MAX_PAIRS
# Fields of a sub-step in a pair lane group's forcing table: those of every lane group (of which the
# pair step reads drive, e'', the width, RK4's weight and e; the totals of k and the friction term are
# the one-sample forcing's, kept for its layout), then per stage each pair slot's stiffness and
# friction term.
P_FIELDS = N_TABLE
P_STAGE = 2 * MAX_PAIRS
N_PAIR_TABLE = P_FIELDS + 3 * P_STAGE


@nb.njit(**JIT_OPTIONS)
def _fill_pair_forcing(table, lane, n, period, widths, offsets, stages, pairs, p, fp, fg):
    """A pair lane's columns of the forcing table for mesh period ``n``: the one-sample kernel's
    :func:`~uqgear.physics._pairs._forcing_row_pairs` at the times
    :func:`~uqgear.physics._pairs.scheduled_step_pairs` evaluates it."""
    start = n * period
    teeth = _tooth_terms(n, p, fp, fg)
    for sub in range(table.shape[0]):
        t = start + offsets[sub, lane]
        h = widths[sub, lane]
        for stage in range(3):
            at = t if stage == 0 else (t + 0.5 * h if stage == 1 else t + h)
            terms = _forcing_row_pairs(at, teeth, stages, sub, stage, pairs[sub], p)
            table[sub, (3 * stage) * LANES + lane] = terms[0]
            table[sub, (3 * stage + 1) * LANES + lane] = terms[1]
            table[sub, (3 * stage + 2) * LANES + lane] = terms[4]
            table[sub, (T_DRIVE + stage) * LANES + lane] = terms[2]
            if stage == 0:
                table[sub, T_STE * LANES + lane] = terms[3]
            first = P_FIELDS + stage * P_STAGE
            for i in range(MAX_PAIRS):
                table[sub, (first + i) * LANES + lane] = terms[PAIR_K + i]
                table[sub, (first + MAX_PAIRS + i) * LANES + lane] = terms[PAIR_FRICTION + i]
        table[sub, T_WIDTH * LANES + lane] = h
        table[sub, T_WEIGHT * LANES + lane] = h / 6.0


@nb.njit(**INLINED)
def _pair_offsets(W, lane, n, p, fp, fg):
    """A lane's pitch offset of each pair slot in mesh period ``n`` (those of the one-sample step)."""
    offsets, _ = _tooth_terms(n, p, fp, fg)
    W[W_OFFSETS * LANES + lane] = offsets[0]
    W[(W_OFFSETS + 1) * LANES + lane] = offsets[1]
    W[(W_OFFSETS + 2) * LANES + lane] = offsets[2]
    W[(W_OFFSETS + 3) * LANES + lane] = offsets[3]


@nb.njit(**INLINED)
def _stage_terms(f, stage, lane):
    """(stiffness, friction term) 4-tuples of the pair slots and (drive, e'') of a lane at one stage."""
    first = P_FIELDS + stage * P_STAGE
    k = (row_of(f, first, lane), row_of(f, first + 1, lane), row_of(f, first + 2, lane), row_of(f, first + 3, lane))
    g = first + MAX_PAIRS
    friction = (row_of(f, g, lane), row_of(f, g + 1, lane), row_of(f, g + 2, lane), row_of(f, g + 3, lane))
    return k, friction, row_of(f, T_DRIVE + stage, lane), row_of(f, 3 * stage + 2, lane)


@nb.njit(**INLINED)
def _crossed(x, new_x, offset, b, in_mesh):
    """Whether a pair slot in mesh changes its contact region over a step (selects, not branches)."""
    return region_changed(x - offset, new_x - offset, b) & in_mesh


@nb.njit(**INLINED)
def _pair_lane_step(W, table, sub, lane, n_pairs):
    """Sub-step ``sub`` of one pair lane: the one-sample pair step's RK4 step, written to ``W`` with what is
    left to the one-sample code (any pair's contact change, an inexact quotient). Returns 1 if something
    is left, else 0."""
    s = lane_state(W, W_STATE, lane)
    c, inverse = lane_coefficients(W, lane)
    e = (
        row_of(W, W_OFFSETS, lane),
        row_of(W, W_OFFSETS + 1, lane),
        row_of(W, W_OFFSETS + 2, lane),
        row_of(W, W_OFFSETS + 3, lane),
    )
    f = table[sub]
    h = row_of(f, T_WIDTH, lane)
    mid = _stage_terms(f, 1, lane)
    d1, force, exact1 = pair_derivative_by(s, _stage_terms(f, 0, lane), e, n_pairs, c, quotient, inverse)
    # the stages and their combination of rk4_by_weighted, called here (one inlined level less to compile)
    d2, d3, d4, exact_later = rk4_stages(pair_lane_field, quotient, s, h, d1, mid, _stage_terms(f, 2, lane),
                                         (e, n_pairs, c, inverse))
    new = rk4_combine_weighted(s, row_of(f, T_WEIGHT, lane), d1, d2, d3, d4)
    b = c[0]
    x = s[2]
    crossed = (
        _crossed(x, new[2], e[0], b, 0 < n_pairs)
        | _crossed(x, new[2], e[1], b, 1 < n_pairs)
        | _crossed(x, new[2], e[2], b, 2 < n_pairs)
        | _crossed(x, new[2], e[3], b, 3 < n_pairs)
    )
    redo = REDO_STEP if crossed else REDO_NONE
    redo = redo if exact1 & exact_later else REDO_STEP
    put_step(W, lane, new, d1, force, redo)
    return 0 if redo == REDO_NONE else 1


@nb.njit(**INLINED)
def _step_pair_lanes(W, table, sub, lanes, n_pairs):
    """Sub-step ``sub`` of the first ``lanes`` pair lanes; returns how many leave something to
    :func:`_redo_pair_lane`. One loop over the lanes, as :func:`uqgear.physics._lanes._step_lanes`."""
    left = 0
    for lane in range(lanes):
        left += _pair_lane_step(W, table, sub, lane, n_pairs)
    return left


@nb.njit(**JIT_OPTIONS)
def _redo_pair_lane(lane, n, sub, W, table, widths, offsets, refs, period, i, runs, stages, pairs):
    """A pair lane's whole sub-step on the one-sample code (:func:`~uqgear.physics._pairs.substep_pairs`: its
    splits at each pair's contact change, IEEE divisions)."""
    p, pair_k, period_k, fp, fg, _ = run_arrays(runs, i)
    start = n * period[lane]
    done, d1, force = substep_pairs(
        start + offsets[sub, lane],
        widths[sub, lane],
        lane_state(W, W_STATE, lane),
        _tooth_terms(n, p, fp, fg),
        stages[lane],
        sub,
        pairs[sub],
        start + refs[sub, lane],
        p,
        pair_k,
        period_k,
        fp,
        fg,
    )
    put_start(W, lane, d1, force)
    put_state(W, W_TRIAL, lane, done)


@nb.njit(**INLINED)
def _pair_contact_counts(W, lane, n_pairs):
    """(drive side, back side) of a pair lane at its state, 0.0 or 1.0, as
    :func:`~uqgear.physics._pairs.pair_contact` says it: drive side if some pair in mesh is in drive-side
    contact, else back side if some pair touches on its back."""
    x = row_of(W, W_STATE + 2, lane)
    b = row_of(W, W_COEFFICIENTS, lane)
    drive = 0.0
    back = 0.0
    for i in range(MAX_PAIRS):
        deflection = x - row_of(W, W_OFFSETS + i, lane)
        in_mesh = i < n_pairs
        drive = 1.0 if (deflection > b) & in_mesh else drive
        back = 1.0 if (deflection < -b) & in_mesh else back
    return drive, 0.0 if drive == 1.0 else back


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_pair_lanes(first, last, groups, batch, refused):
    """:func:`uqgear.physics._lanes.integrate_lanes` for lane groups of runs with pitch errors (GIL released)."""
    for g in range(first, last):
        integrate_group(
            _step_pair_lanes, _redo_pair_lane, _fill_pair_forcing, _pair_offsets, _pair_contact_counts, N_PAIR_ROWS,
            N_PAIR_TABLE, groups[g], batch, refused,
        )


def compile_pair_lanes(groups: np.ndarray, batch: QoiBatch, refused: np.ndarray) -> None:
    """Compile (or load from the cache) :func:`integrate_pair_lanes` for its arguments
    (:func:`~uqgear.physics._lanes.compile_lane_kernel`)."""
    compile_lane_kernel(_step_pair_lanes, N_PAIR_ROWS, N_PAIR_TABLE, integrate_pair_lanes, groups, batch, refused)


__all__ = ["integrate_pair_lanes", "compile_pair_lanes"]
