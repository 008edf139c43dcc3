"""A lane group's forcing table: each lane's sub-steps and forcing at RK4's three stage times.

:mod:`uqgear.physics._lanes` advances ``LANES`` runs together; what a lane's sub-step reads of
its run's forcing (stiffness, friction term, drive, e'' at the start, middle and end, the width,
RK4's weight, e at the start) sits in one table, row per sub-step, a field's lanes adjacent. A
run whose forcing repeats every mesh period fills its columns once; any other run fills them for
every period, from the one-sample kernel's own :func:`~uqgear.physics._stepper._forcing_row` at the
times :func:`~uqgear.physics._stepper.classical_step` evaluates it, so that the numbers are the same.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from uqgear.physics._rhs import JIT_OPTIONS, MAX_PAIRS, T1, T2, TOOTH_FACTORS
from uqgear.physics._stepper import F_ARM_GEAR, F_ARM_PINION, F_K, F_SINE, scaled_forcing, tooth_extra

#: Runs advanced together: one vector of eight doubles (AVX-512), or two of four.
LANES = 8

# Fields of a sub-step in a lane group's forcing table (sub-step s, field f, lane l at element
# [s, f * LANES + l]): (k, friction term, e'') at the start, middle and end, the width
# h and h / 6 (RK4's weight, divided once here rather than every step: the same number), the
# drive term at the start, middle and end, and e at the start (the recorded STE).
T_WIDTH = 9
T_WEIGHT = 10
T_DRIVE = 11
T_STE = 14
N_TABLE = 15
#: History channels of a lane group: x; with 4, the rig's (te, y1'', y2''); with 7, also y1, y2 and
#: e as the one-sample history records them (:func:`uqgear.physics._kernels.integrate_history`).
RIG_CHANNELS = 4
STATE_CHANNELS = 7


@nb.njit(**JIT_OPTIONS)
def _same_schedule(params, i, j, table_index, breakpoints):
    """Whether runs ``i`` and ``j`` have the same schedule: the same parameters but for the torques T1
    and T2 (which enter the drive term alone), stiffness tables and breakpoints."""
    if table_index[i] != table_index[j]:
        return False
    for k in range(params.shape[1]):
        if k != T1 and k != T2 and params[i, k] != params[j, k]:
            return False
    for k in range(breakpoints.shape[1]):
        a = breakpoints[i, k]
        b = breakpoints[j, k]
        if a != b and not (a != a and b != b):  # noqa: PLR0124  (both NaN: padding)
            return False
    return True


@nb.njit(**JIT_OPTIONS)
def _copy_lane(stages, widths, offsets, refs, source, lane):
    stages[lane] = stages[source]
    for sub in range(widths.shape[0]):
        widths[sub, lane] = widths[sub, source]
        offsets[sub, lane] = offsets[sub, source]
        refs[sub, lane] = refs[sub, source]


@nb.njit(**JIT_OPTIONS)
def _take_schedule(stages, widths, offsets, refs, lane, schedule, n_sub):
    """A lane's sub-steps and tabulated stages, from its schedule."""
    _, sub_offsets, sub_widths, sub_refs, _, tabulated = schedule
    for sub in range(n_sub):
        widths[sub, lane] = sub_widths[sub]
        offsets[sub, lane] = sub_offsets[sub]
        refs[sub, lane] = sub_refs[sub]
    stages[lane] = tabulated[:n_sub]


@nb.njit(**JIT_OPTIONS)
def _fill_forcing(table, lane, n, period, widths, offsets, stages, pairs, p, fp, fg):
    """A lane's columns of the forcing table for mesh period ``n``: the one-sample kernel's
    :func:`~uqgear.physics._stepper._forcing_row` at the times :func:`~uqgear.physics._stepper.classical_step`
    evaluates it (the same operations in the same order, so the same numbers)."""
    start = n * period
    # the tooth factors of the pairs in contact are those of the period: found once, not every stage
    damaged = p[TOOTH_FACTORS] != 0.0
    extras = np.zeros(MAX_PAIRS)
    if damaged:
        for i in range(MAX_PAIRS):
            extras[i] = tooth_extra(n - i, p, fp, fg)
    for sub in range(table.shape[0]):
        t = start + offsets[sub, lane]
        h = widths[sub, lane]
        for stage in range(3):
            at = t if stage == 0 else (t + 0.5 * h if stage == 1 else t + h)
            # _forcing_row's sums, with the period's tooth factors
            k = stages[sub, stage, F_K]
            arm_pinion = stages[sub, stage, F_ARM_PINION]
            arm_gear = stages[sub, stage, F_ARM_GEAR]
            if damaged:
                for i in range(pairs[sub]):
                    k += stages[sub, stage, 4 + 3 * i] * extras[i]
                    arm_pinion += stages[sub, stage, 5 + 3 * i] * extras[i]
                    arm_gear += stages[sub, stage, 6 + 3 * i] * extras[i]
            terms = scaled_forcing(at, k, arm_pinion, arm_gear, stages[sub, stage, F_SINE], p)
            table[sub, (3 * stage) * LANES + lane] = terms[0]
            table[sub, (3 * stage + 1) * LANES + lane] = terms[1]
            table[sub, (3 * stage + 2) * LANES + lane] = terms[4]
            table[sub, (T_DRIVE + stage) * LANES + lane] = terms[2]
            if stage == 0:
                table[sub, T_STE * LANES + lane] = terms[3]
        table[sub, T_WIDTH * LANES + lane] = h
        table[sub, T_WEIGHT * LANES + lane] = h / 6.0
