"""The scipy reference integrator: :func:`scipy.integrate.solve_ivp` on segments between stiffness breakpoints.

DOP853 at tight tolerances by default, with terminal events at the contact
boundaries so every switch of the backlash function is resolved; the
accuracy reference that :func:`uqgear.physics.integration.simulate` runs with
``method="scipy"`` and that the compiled fast path is checked against.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from scipy.integrate import solve_ivp

from . import _kernels as K
from .model import HISTORY_COLUMNS, ModelSetup


def record_grid(
    history: np.ndarray,
    grid: np.ndarray,
    sol: Any,
    state: np.ndarray,
    t_a: float,
    t_end: float,
    period: float,
    first_row: int,
    args: tuple,
    deriv: np.ndarray,
    contact: Callable[[float], int],
) -> None:
    """Write the history rows of the grid points in [t_a, t_end) from one solve_ivp piece.

    Each grid point is recorded once, by the piece that starts it (the state
    itself at t_a, the dense output inside).
    """
    for i in np.nonzero((grid >= t_a - 1e-12 * period) & (grid < t_end))[0]:
        t = grid[i]
        y = np.ascontiguousarray(sol.sol(t)) if t > t_a else state
        row = first_row + i
        force, k, ste = K.record(t, y, *args, deriv)
        history[row, :6] = y
        history[row, 6] = deriv[3]
        history[row, 7] = deriv[4]
        history[row, 8:11] = (force, k, ste)
        history[row, 11] = contact(y[2])


def pair_contact(newest: int, count: int, p: np.ndarray) -> Callable[[float], int]:
    """The contact state of x with the pairs in mesh (``newest``, ``count``): the history's contact column."""
    return lambda x: K._pairs.pair_contact(x, newest, count, p)


def boundary_event(level: float, is_above: bool) -> Callable[[float, np.ndarray], float]:
    """A terminal :func:`scipy.integrate.solve_ivp` event where x (the state's third entry) crosses ``level``,
    directed away from the side x is on (``is_above``): the contact boundaries of the scipy references."""

    def event(t: float, y: np.ndarray) -> float:
        return y[2] - level

    event.terminal = True  # type: ignore[attr-defined]
    event.direction = -1 if is_above else 1  # type: ignore[attr-defined]
    return event


def _pair_boundaries(t_ref: float, p: np.ndarray, b: float) -> tuple[np.ndarray, Callable[[float], int]]:
    """The contact boundaries e_i -+ b of the pairs in mesh at ``t_ref``, and their contact state of x."""
    newest, count = K._pairs.pair_state(t_ref, p)
    offsets = [K._pairs.pair_offset(newest - i, p) for i in range(count)]
    levels = np.unique([e + side for e in offsets for side in (b, -b)])
    return levels, pair_contact(newest, count, p)


def integrate_scipy(
    setup: ModelSetup,
    n_periods: int,
    keep_periods: int,
    samples_per_period: int,
    initial_state: np.ndarray,
    rtol: float,
    atol: float | None,
    solver: str = "DOP853",
) -> tuple[np.ndarray, np.ndarray, dict]:
    """The scipy reference: DOP853 between stiffness breakpoints, a terminal event at every contact boundary.

    ``solver`` names another :func:`scipy.integrate.solve_ivp` method on the
    same segments and events (``benchmarks/integrator.py`` times LSODA so).

    Within a segment between breakpoints the contact boundaries are fixed:
    x = -b and x = +b for the mesh as a whole, and with pitch errors
    x = e_i - b and x = e_i + b for each pair in mesh (its offset e_i, the
    pairs fixed within the segment). Each boundary is an event directed away
    from the side x is on (tracked across events), so every kink of the dead
    zones is resolved.
    """
    p = setup.parameters
    args = (p, setup.pair_stiffness, setup.period_stiffness, setup.factor_pinion, setup.factor_gear)
    period = 1.0 / setup.mesh_frequency
    b = p[K.HALF_BACKLASH]
    atol_vector = setup.state_scale() * (rtol if atol is None else atol)
    phases = np.concatenate([[0.0], setup.breakpoints, [1.0]])
    first_kept = n_periods - keep_periods
    history = np.empty((keep_periods * samples_per_period, len(HISTORY_COLUMNS)))
    poincare = np.empty((keep_periods, 6))
    deriv = np.empty(6)
    state = initial_state.astype(float).copy()
    stats = {"rhs_evaluations": 0, "contact_events": 0, "segments": 0}
    with_pairs = p[K.PITCH_ERRORS] != 0.0
    levels = np.array([-b, b])
    above = state[2] > levels

    def mesh_contact(x: float) -> int:
        return 1 if x > b else (-1 if x < -b else 0)

    contact: Callable[[float], int] = mesh_contact

    for n in range(n_periods):
        kept = n >= first_kept
        if kept:
            poincare[n - first_kept] = state
            grid = (n + np.arange(samples_per_period) / samples_per_period) * period
        for u_a, u_b in zip(phases[:-1], phases[1:]):
            t_a, t_b = (n + u_a) * period, (n + u_b) * period
            t_ref = 0.5 * (t_a + t_b)
            if with_pairs:
                levels, contact = _pair_boundaries(t_ref, p, b)
                above = state[2] > levels
            out = np.empty(6)

            def fun(t, y, t_ref=t_ref, out=out):
                K.rhs(t, y, t_ref, *args, out)
                return out.copy()

            while t_a < t_b:
                events = [boundary_event(level, bool(up)) for level, up in zip(levels, above)]
                sol = solve_ivp(
                    fun, (t_a, t_b), state, method=solver, rtol=rtol, atol=atol_vector, events=events, dense_output=kept
                )
                stats["rhs_evaluations"] += sol.nfev
                stats["segments"] += 1
                t_end = sol.t[-1]
                if kept:
                    record_grid(
                        history,
                        grid,
                        sol,
                        state,
                        t_a,
                        t_end,
                        period,
                        (n - first_kept) * samples_per_period,
                        args,
                        deriv,
                        contact,
                    )
                state = sol.y[:, -1].copy()
                if sol.status == 1:
                    stats["contact_events"] += 1
                    fired = next(i for i, te in enumerate(sol.t_events) if te.size)
                    above[fired] = not above[fired]
                else:
                    above = state[2] > levels
                t_a = t_end
    return history, poincare, stats


__all__ = ["integrate_scipy", "record_grid", "pair_contact", "boundary_event"]
