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
(:func:`uqgear.physics._stepper.classical_step`, through the same
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
its own by the one-sample code (:func:`~uqgear.physics._stepper._split_at_contact`).

This module's kernel takes the runs without pitch errors; those with them take
the per-pair step of :mod:`uqgear.physics._pair_lanes`, in the same time loop
(:func:`uqgear.physics._lane_loop.integrate_group`). The whole forcing of a
sub-step (stiffness, friction term, drive, e'') is a table, filled from the
one-sample kernel's own :func:`~uqgear.physics._stepper._forcing_row` at the
times it evaluates it (:mod:`uqgear.physics._lane_tables`): once per run
where the forcing repeats every mesh period, and for every period where
tooth factors, run-out, torque ripple or an adhesion oscillation make it
change (:func:`periodic_forcing`). With ``lyapunov`` a group holds four runs
and their four shadow runs.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import llvmlite.binding as ll
import numba as nb
import numpy as np
from numba.core.compiler_lock import global_compiler_lock

from uqgear.physics._batch_record import QoiBatch, run_arrays
from uqgear.physics._lane_loop import (
    N_ROWS,
    REDO_NONE,
    REDO_SPLIT,
    REDO_STEP,
    W_COEFFICIENTS,
    W_REDO,
    W_SLOPE,
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
from uqgear.physics._lane_tables import LANES, N_TABLE, T_DRIVE, T_WEIGHT, T_WIDTH, _fill_forcing
from uqgear.physics._quotient import exact_divisors, quotient
from uqgear.physics._rhs import (
    INLINED,
    JIT_OPTIONS,
    M1,
    M2,
    ME,
    coefficients,
    contact_region,
    periodic_forcing,
    state_derivative,
    state_derivative_by,
)
from uqgear.physics._stepper import _split_at_contact, rk4_step, rk4_step_weighted

# the lane kernels this process has compiled (or loaded) through compile_lane_kernel
_COMPILED: set[str] = set()


def compile_lane_kernel(step: Any, rows: int, table_width: int, kernel: Callable[..., Any], *arguments: Any) -> None:
    """Compile (or load from the cache) a lane kernel, ``kernel``, whose sub-step over the lanes is ``step``.

    ``kernel(0, 0, *arguments)`` compiles it for the types of its calls and does no work (its first
    two arguments bound the lane groups or periods it runs).

    A lane group's sub-step is one loop over the lanes (:func:`_step_lanes`, or the pair lanes'
    step); LLVM's loop vectoriser turns each of its IEEE operations into one vector instruction on
    all lanes. It reorders nothing (no fast-math, and no reduction across lanes), so the numbers do
    not change. Its cost model keeps vectors at 256 bits on CPUs tuned for that (LLVM's default
    ``prefer-vector-width=256`` on AVX-512 parts), which runs the eight lanes as two vectors of
    four, one after the other: the width is forced to eight lanes (one 512-bit vector with AVX-512,
    two 256-bit ones with AVX2, interleaved) while the loop alone is compiled
    (docs/validation/performance.md compares the two). The loop is then
    inlined, already vectorised, into the rest of the kernel, compiled without the forced width (a
    forced width has LLVM report every other loop it cannot vectorise on stderr). The SLP
    vectoriser stays off: helpers it packed would reach the lane loop as short vectors, which the
    loop vectoriser refuses. ``rows`` and ``table_width`` size the step's work array and forcing
    table (fields per lane).

    The width is an LLVM command-line option, global to the process: it is set under numba's
    compiler lock and reset before anything else compiles. This is done once per kernel and
    process; later calls return at once.
    """
    name = kernel.__name__
    if name in _COMPILED:
        # compiled (or loaded) in this process already: every caller passes the same argument types,
        # and the compiler lock and the options would cost every batch (docs/validation/performance.md)
        return
    with global_compiler_lock:
        # numba.config's options are module attributes it sets at import: no static type knows them
        saved = nb.config.SLP_VECTORIZE  # type: ignore[attr-defined]
        nb.config.SLP_VECTORIZE = 0  # type: ignore[attr-defined]
        try:
            ll.set_option("", f"-force-vector-width={LANES}")
            try:
                step(np.zeros(rows * LANES), np.zeros((1, table_width * LANES)), 0, 0, 0)
            finally:
                ll.set_option("", "-force-vector-width=0")
            kernel(0, 0, *arguments)
            _COMPILED.add(name)
        finally:
            nb.config.SLP_VECTORIZE = saved  # type: ignore[attr-defined]


def compile_lanes(groups: np.ndarray, batch: QoiBatch, refused: np.ndarray) -> None:
    """Compile (or load from the cache) :func:`integrate_lanes` for its arguments (:func:`compile_lane_kernel`)."""
    compile_lane_kernel(_step_lanes, N_ROWS, N_TABLE, integrate_lanes, groups, batch, refused)


def lane_ready(params: np.ndarray) -> np.ndarray:
    """Which runs (rows of parameter vectors) the lanes take: those with divisors the lanes' quotient is
    exact for (with or without pitch errors: :func:`uqgear.physics._pair_lanes.integrate_pair_lanes`
    takes the runs with them)."""
    p = np.atleast_2d(params)
    # the lanes divide by a multiplication and fused multiply-adds, exact for these divisors
    return exact_divisors(p[:, M1]) & exact_divisors(p[:, M2]) & exact_divisors(p[:, ME])


@nb.njit(**INLINED)
def _lane_step(W, table, sub, lane):
    """Sub-step ``sub`` of one lane: the one-sample kernel's RK4 step (:func:`~uqgear.physics._stepper.classical_step`
    between its splits), with its start's force and bearing accelerations, and what is left to the
    one-sample code (``REDO_*``), written to ``W``. Returns 1 if something is left, else 0."""
    s = lane_state(W, W_STATE, lane)
    c, inverse = lane_coefficients(W, lane)
    # the sub-step's row: its index is checked for wrap-around once, outside the loop over the lanes
    f = table[sub]
    d1, force, exact = state_derivative_by(
        s, row_of(f, 0, lane), row_of(f, 1, lane), row_of(f, T_DRIVE, lane), row_of(f, 2, lane), c, quotient, inverse
    )
    mid = (row_of(f, 3, lane), row_of(f, 4, lane), row_of(f, T_DRIVE + 1, lane), row_of(f, 5, lane))
    end = (row_of(f, 6, lane), row_of(f, 7, lane), row_of(f, T_DRIVE + 2, lane), row_of(f, 8, lane))
    new, exact_later = rk4_step_weighted(
        s, row_of(f, T_WIDTH, lane), row_of(f, T_WEIGHT, lane), d1, mid, end, c, quotient, inverse
    )
    b = c[0]
    x = s[2]
    # the one-sample kernel's test (contact_region before and after differ)
    redo = REDO_SPLIT if region_changed(x, new[2], b) else REDO_NONE
    redo = redo if exact & exact_later else REDO_STEP
    put_step(W, lane, new, d1, force, redo)
    return 0 if redo == REDO_NONE else 1


@nb.njit(**INLINED)
def _step_lanes(W, table, sub, lanes, n_pairs):
    """Sub-step ``sub`` of the first ``lanes`` lanes (all of them: ``LANES``); returns how many leave
    something to the one-sample code (:func:`_redo_lane`). ``n_pairs`` (the pairs in mesh) is not
    read: the signature of every lane step (:func:`uqgear.physics._lane_loop.integrate_group`).

    One loop over the lanes, which the loop vectoriser compiles into vector instructions. Its trip
    count comes from the caller at run time: a constant one would have LLVM unroll the loop before
    the vectoriser sees it (its body is still a call then), and treat it as too short for the
    check that ``W`` and ``table`` do not overlap.
    """
    left = 0
    for lane in range(lanes):
        left += _lane_step(W, table, sub, lane)
    return left


@nb.njit(**JIT_OPTIONS)
def _redo_lane(lane, n, sub, W, table, widths, offsets, refs, period, i, runs, stages, pairs):
    """Finish a lane's sub-step on the one-sample code: its split at a contact boundary, or (a quotient the
    lanes cannot vouch for) the whole sub-step, with IEEE divisions, as the one-sample kernel does.
    (``stages`` and ``pairs`` are not read: the signature of every lane redo.)"""
    p, pair_k, period_k, fp, fg, _ = run_arrays(runs, i)
    start = n * period[lane]
    s = lane_state(W, W_STATE, lane)
    d1 = lane_state(W, W_SLOPE, lane)
    attempt = lane_state(W, W_TRIAL, lane)
    h = widths[sub, lane]
    if row_of(W, W_REDO, lane) == REDO_STEP:
        c = coefficients(p)
        f = table[sub]
        d1, force = state_derivative(
            s, row_of(f, 0, lane), row_of(f, 1, lane), row_of(f, T_DRIVE, lane), row_of(f, 2, lane), c
        )
        attempt = rk4_step(
            s,
            h,
            d1,
            (row_of(f, 3, lane), row_of(f, 4, lane), row_of(f, T_DRIVE + 1, lane), row_of(f, 5, lane)),
            (row_of(f, 6, lane), row_of(f, 7, lane), row_of(f, T_DRIVE + 2, lane), row_of(f, 8, lane)),
            c,
        )
        put_state(W, W_SLOPE, lane, d1)
        put_start(W, lane, d1, force)
        if contact_region(s[2], c[0]) == contact_region(attempt[2], c[0]):
            put_state(W, W_TRIAL, lane, attempt)
            return
    done = _split_at_contact(
        start + offsets[sub, lane],
        h,
        s,
        d1,
        attempt,
        start + refs[sub, lane],
        p,
        pair_k,
        period_k,
        fp,
        fg,
    )
    put_state(W, W_TRIAL, lane, done)


@nb.njit(**INLINED)
def _mesh_contact_counts(W, lane, n_pairs):
    """(drive side, back side) of a lane's mesh at its state, 0.0 or 1.0: from x alone, as
    :func:`~uqgear.physics._stepper.mesh_contact` says it (``n_pairs`` not read)."""
    x = row_of(W, W_STATE + 2, lane)
    b = row_of(W, W_COEFFICIENTS, lane)
    drive_side = 1.0 if x > b else 0.0
    back_side = 1.0 if x < -b else 0.0
    back_side = 0.0 if x > b else back_side
    return drive_side, back_side


@nb.njit(**INLINED)
def _no_period_terms(W, lane, n, p, fp, fg):
    """What a classical lane reads of its mesh period beyond the forcing table: nothing."""


@nb.njit(**JIT_OPTIONS, nogil=True)
def integrate_lanes(first, last, groups, batch, refused):
    """Integrate lane groups ``first`` to ``last - 1`` of a batch of runs without pitch errors (GIL released).

    ``groups`` has one row of ``LANES`` sample indices per group (-1: an
    empty lane); with ``lyapunov`` only the first half of a row is used and
    the second half runs the shadows. ``batch`` is the
    :class:`~uqgear.physics._batch_record.QoiBatch` of
    :func:`uqgear.physics._kernels.integrate_batch`.
    A run whose sub-step layout differs from its group's first run is not
    integrated: ``refused`` says so, and the caller runs it one at a time.
    """
    for g in range(first, last):
        integrate_group(
            _step_lanes, _redo_lane, _fill_forcing, _no_period_terms, _mesh_contact_counts, N_ROWS, N_TABLE,
            groups[g], batch, refused,
        )


__all__ = ["LANES", "compile_lane_kernel", "compile_lanes", "lane_ready", "periodic_forcing", "integrate_lanes"]
