"""Histories of several runs at once: :func:`~uqgear.physics.integration.integrate_fast`'s, with the runs in SIMD lanes.

A run's history from the fast integrator is a chain of dependent RK4 steps
that waits on latency; runs with the same sub-step layout advance together
as the lanes of :mod:`uqgear.physics._lanes` (runs with pitch errors: of
:mod:`uqgear.physics._pair_lanes`), which compute each run's numbers bit for
bit as the one-sample kernel does. Groups too small to pay for their lanes
(:data:`~uqgear.physics.batch_setup.MINIMUM_FILL`) and any run a lane group
cannot hold are integrated one at a time, so every run's history is the one
:func:`~uqgear.physics.integration.integrate_fast` returns, whatever company
it is in.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ._batch_record import QoiBatch
from ._lane_tables import STATE_CHANNELS
from ._pair_extremes import N_EXTREMES
from ._rhs import N_ACCUMULATORS
from .batch_setup import integrate_lane_groups, kernel_inputs
from .integration import integrate_fast, steps_per_period
from .model import HISTORY_COLUMNS, ModelSetup

#: Columns of the histories :func:`integrate_histories` returns (those of
#: :data:`~uqgear.physics.model.HISTORY_COLUMNS` of the same names): the bearing
#: displacements, the DTE and the static transmission error, m.
STATE_HISTORY_COLUMNS = ("y1", "y2", "x", "ste")
# where the lanes record them (uqgear.physics._lane_loop: channels 4, 5, 0 and 6)
_LANE_CHANNELS = [4, 5, 0, 6]
_ONE_SAMPLE_COLUMNS = [HISTORY_COLUMNS.index(name) for name in STATE_HISTORY_COLUMNS]


def integrate_histories(
    setups: Sequence[ModelSetup],
    n_periods: int,
    keep_periods: int,
    samples_per_period: int,
    steps_per_mode: int,
    states: np.ndarray | None = None,
    threads: int | None = 1,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Histories and Poincare states of several runs, each from static equilibrium or a given state.

    Parameters
    ----------
    setups : sequence of ModelSetup
        The runs (:func:`uqgear.physics.model.build_model`), of one gear pair.
    n_periods, keep_periods : int
        Mesh periods integrated, and kept at the end.
    samples_per_period : int
        History samples per mesh period.
    steps_per_mode : int
        RK4 steps per period of the highest natural frequency.
    states : ndarray, optional
        (runs, 6) start states (those of ``integrate_fast``'s ``state0``); a row of NaN, or none
        given, starts that run at its static equilibrium.
    threads : int, optional
        Threads over the lane groups (None: all cores). One by default: a diagnosis's worker
        processes are its parallelism. The numbers do not depend on it.

    Returns
    -------
    list of (history, poincare)
        Per run: its history over the kept periods, (keep_periods *
        samples_per_period, 4) with the columns :data:`STATE_HISTORY_COLUMNS`,
        and the state at each kept period start, (keep_periods, 6); the same
        numbers as those columns of :func:`~uqgear.physics.integration.integrate_fast`'s.

    Examples
    --------
    >>> import numpy as np, uqgear
    >>> from uqgear.physics.model import build_model
    >>> from uqgear.physics.effects import make_effect
    >>> from uqgear.physics.integration import integrate_fast
    >>> design = uqgear.load_design("locomotive")
    >>> runs = [build_model(design, 1500.0, 7000.0, 33e3, effects=[make_effect("tooth_damage", {"depth": d})])
    ...         for d in (0.1, 0.2, 0.3, 0.4)]
    >>> together = integrate_histories(runs, 40, 10, 16, 24)
    >>> alone, poincare, _ = integrate_fast(runs[1], 40, 10, 16, 24, runs[1].static_state())
    >>> bool(np.array_equal(together[1][0], alone[:, [0, 1, 2, 10]]) and np.array_equal(together[1][1], poincare))
    True
    """
    n = len(setups)
    if n == 0:
        return []
    steps = np.array([steps_per_period(s, steps_per_mode, multiple_of=samples_per_period) for s in setups])
    starts = np.stack([s.static_state() for s in setups])
    if states is not None:
        given = np.all(np.isfinite(states), axis=1)
        starts[given] = np.asarray(states, dtype=float)[given]
    history = np.empty((n, STATE_CHANNELS, keep_periods * samples_per_period))
    poincare = np.empty((n, keep_periods, 6))
    batch = QoiBatch(
        kernel_inputs(setups, starts),
        steps,
        int(n_periods),
        int(keep_periods),
        (steps // samples_per_period).astype(np.int64),
        False,
        np.ones((n, 6)),
        np.zeros((n, N_ACCUMULATORS)),
        poincare,
        history,
        np.empty((n, 6)),
        False,
        np.empty((n, N_EXTREMES)),
    )
    rest = integrate_lane_groups(batch, threads=threads)
    left = set(rest.tolist())
    results: list[tuple[np.ndarray, np.ndarray] | None] = [
        None if i in left else (history[i][_LANE_CHANNELS].T.copy(), poincare[i]) for i in range(n)
    ]
    for i in rest:
        setup = setups[i]
        one, poincare_i, _ = integrate_fast(
            setup, n_periods, keep_periods, samples_per_period, steps_per_mode, starts[i].copy()
        )
        results[i] = (one[:, _ONE_SAMPLE_COLUMNS], poincare_i)
    return results  # type: ignore[return-value]


__all__ = ["integrate_histories", "STATE_HISTORY_COLUMNS"]
