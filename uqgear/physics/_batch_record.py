"""The batch kernels' arguments as two typed records, declared once.

Every batch kernel (one sample at a time, the SIMD lanes, the pair lanes,
the calibration's harmonic balance) reads each run's state, parameters,
stiffness tables, tooth factors and breakpoints: :class:`RunInputs`. The
kernels that integrate to QoIs also take the layout of the integration and
the arrays they write: :class:`QoiBatch`, which holds the runs' inputs.
Both are named tuples, which numba passes to a compiled function as one
argument of a fixed tuple type and reads by field name, so an input the
kernels need is added here, filled by
:func:`uqgear.physics.batch_setup.kernel_inputs` (or where the
:class:`QoiBatch` is built) and read where it is used, and no kernel
signature changes. :func:`run_arrays` gives the compiled code one run's
arrays.

The records are part of the kernels' argument types: this module is one of
the compiled modules (:data:`uqgear.physics._cache.COMPILED_MODULES`), so a
changed record recompiles every cached kernel.
"""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np

from uqgear.physics._rhs import INLINED


class RunInputs(NamedTuple):
    """Each run's inputs, one row (or table) per run of a batch.

    Attributes
    ----------
    states : ndarray, shape (n, 6)
        The state at t = 0 (not changed by the kernels).
    params : ndarray, shape (n, slots)
        Parameter vectors (slots of :mod:`uqgear.physics._rhs`).
    pair_tables, period_tables : ndarray, shape (tables, points)
        The batch's distinct single-pair and period stiffness tables.
    table_index : ndarray of int64, shape (n,)
        Each run's row of the stiffness tables.
    factor_pinion, factor_gear : ndarray, shape (n, z1) and (n, z2)
        Per-tooth stiffness factors.
    breakpoints : ndarray, shape (n, width)
        Mesh phases where the stiffness or friction direction jumps, NaN-padded.
    """

    states: np.ndarray
    params: np.ndarray
    pair_tables: np.ndarray
    period_tables: np.ndarray
    table_index: np.ndarray
    factor_pinion: np.ndarray
    factor_gear: np.ndarray
    breakpoints: np.ndarray


class QoiBatch(NamedTuple):
    """A batch integrated to QoIs: its runs' inputs, the integration's layout and the arrays written.

    Attributes
    ----------
    runs : RunInputs
    steps_per_period : ndarray of int64, shape (n,)
        RK4 grid steps a mesh period.
    n_periods, keep_periods : int
        Mesh periods integrated and kept (the last ones).
    history_stride : ndarray of int64, shape (n,)
        Grid steps between history points (0: no history).
    lyapunov : bool
        Integrate a shadow of each run for its largest Lyapunov exponent.
    scales : ndarray, shape (n, 6)
        Typical state magnitudes (Lyapunov distances).
    accumulators, poincare, history, final_states : ndarray
        Written: QoI sums (slots ``Q_*``), the Poincare section, the
        decimated histories and the state at the end of the last period.
    stresses : bool
        Also keep the extremes of the tooth-pair loads over the kept grid
        steps (:mod:`uqgear.physics._pair_extremes`); checked outside the
        lanes' vectorised sub-step, so a batch without costs nothing.
    stress_extremes : ndarray, shape (n, N_EXTREMES)
        Written where ``stresses``: each run's extremes (slots ``E_*``).
    """

    runs: RunInputs
    steps_per_period: np.ndarray
    n_periods: int
    keep_periods: int
    history_stride: np.ndarray
    lyapunov: bool
    scales: np.ndarray
    accumulators: np.ndarray
    poincare: np.ndarray
    history: np.ndarray
    final_states: np.ndarray
    stresses: bool
    stress_extremes: np.ndarray


@nb.njit(**INLINED)
def run_arrays(runs, i):
    """Run ``i``'s (parameters, pair table, period table, pinion factors, gear factors, breakpoints)."""
    table = runs.table_index[i]
    return (
        runs.params[i],
        runs.pair_tables[table],
        runs.period_tables[table],
        runs.factor_pinion[i],
        runs.factor_gear[i],
        runs.breakpoints[i],
    )


__all__ = ["RunInputs", "QoiBatch", "run_arrays"]
