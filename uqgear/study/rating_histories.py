"""Tooth stress histories of a ``rating`` analysis and the fatigue damage rates they give.

At every pinion speed of the rating's sweep the model runs from rest at a few
adhesion torques (the rating's ``history_points`` evenly across the T2 interval,
by default :data:`HISTORY_TORQUES`: its ends and midpoint; a rail distribution's
own values besides), all in one batch (:func:`~uqgear.physics.history_batch.integrate_histories`);
the kept steady section of each run gives every tooth engagement's root and
flank stress (:func:`~uqgear.dynamics.tooth_loads.tooth_stresses`), which are
rainflow-counted and Miner-summed on the rating's S-N curves
(:func:`~uqgear.dynamics.fatigue.engagement_damage`). A tooth meets one
engagement per revolution of its gear, so the damage per hour at pinion speed
n is that per engagement times 60 n (pinion) or 60 n / u (gear).

Where several steady responses coexist at a point, the caller's ``starts`` names each
attractor's first start (the state the run that first reached it began from); a history runs
from each of those states besides the run from rest, and the point's rates and stress peaks
are bounded over its attractors.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import xarray as xr

from ..dynamics.fatigue import engagement_damage
from ..dynamics.tooth_loads import tooth_stresses
from ..physics.batch_setup import build_batch
from ..physics.history_batch import integrate_histories
from ..physics.rating import RatingSettings, static_rating
from .settings import SimulationSettings

#: Where across the T2 interval the histories are run (fractions of the interval).
HISTORY_TORQUES = (0.0, 0.5, 1.0)
#: History samples per mesh period (the stress peaks' resolution along the path of contact).
HISTORY_SAMPLES = 64


@dataclass(frozen=True)
class StressHistories:
    """Damage rates and stress peaks of the history runs (gear, mode, [bound,] torque, speed).

    Attributes
    ----------
    torques : ndarray
        Adhesion torques T2 run, N m, increasing.
    rates : ndarray
        (gear, mode, torque, speed) Miner damage per hour of the runs from rest (modes root, contact).
    rate_bounds : ndarray
        (gear, mode, bound, torque, speed) least and greatest damage per hour over the attractors at
        each point (equal to ``rates`` where the gear holds one response).
    worst_start : ndarray
        (gear, mode, torque, speed) the first start of the attractor with the greatest rate
        (``rest``: the run from rest's).
    attractor_count : ndarray
        (torque, speed) attractors whose histories were run.
    peaks : ndarray
        (gear, mode, bound, torque, speed) least and greatest over the attractors of the largest
        root (mode 0) and flank (mode 1) stress, Pa.
    runs : int
        Model runs.
    """

    torques: np.ndarray
    rates: np.ndarray
    rate_bounds: np.ndarray
    worst_start: np.ndarray
    attractor_count: np.ndarray
    peaks: np.ndarray
    runs: int


#: ``starts(samples)``: each sample's attractors as (first start label, start state; NaN: from rest).
AttractorStarts = Callable[[xr.Dataset], Sequence[Sequence[tuple[str, np.ndarray]]]]


def history_damage(
    design,
    simulation: SimulationSettings,
    fixed: Mapping[str, float],
    speeds: Sequence[float] | np.ndarray,
    torques: Sequence[float] | np.ndarray,
    settings: RatingSettings,
    starts: AttractorStarts | None = None,
) -> StressHistories:
    """Run the histories at every (T2, speed) and count their damage; see the module text.

    ``fixed`` holds the other inputs of a run (drive torque, uncertain parameters at their nominal
    values), named as batch sample variables. ``starts`` gives each point's attractors (the guided
    model's :meth:`~uqgear.study.guided_starts.GuidedStartModel.attractor_starts`): a history runs
    from each one's start besides the run from rest, and the rates and peaks are bounded over them.
    """
    speeds_a, torques_a = np.asarray(speeds, dtype=float), np.asarray(torques, dtype=float)
    grid_t, grid_n = (values.ravel() for values in np.meshgrid(torques_a, speeds_a, indexing="ij"))
    others = {name: value for name, value in fixed.items() if name not in ("pinion_speed", "adhesion_torque")}
    samples = xr.Dataset(
        {
            "pinion_speed": ("sample", grid_n),
            "adhesion_torque": ("sample", grid_t),
            **{name: ("sample", np.full(grid_n.size, float(value))) for name, value in others.items()},
        },
        # labelled as the interval machinery labels its samples: ``starts`` may join them with its own runs
        coords={"sample": np.arange(grid_n.size)},
    )
    found = starts(samples) if starts is not None else [[("rest", np.full(6, np.nan))]] * grid_n.size
    # the run from rest at every point, then one from each other attractor's first start
    point, labels, states = list(range(grid_n.size)), ["rest"] * grid_n.size, [np.full(6, np.nan)] * grid_n.size
    for index, attractors in enumerate(found):
        for label, state in attractors:
            if label != "rest" and np.all(np.isfinite(state)):
                point.append(index)
                labels.append(label)
                states.append(np.asarray(state, dtype=float))
    setups = build_batch(
        design,
        samples.isel(sample=point),
        effects=simulation.effects,
        damping_in_separation=simulation.damping_in_separation,
        stiffness=simulation.stiffness,
    )
    keep = simulation.keep_periods
    runs = integrate_histories(
        setups, simulation.n_periods, keep, HISTORY_SAMPLES, simulation.steps_per_mode, np.stack(states)
    )
    torque = float(others.get("drive_torque", design.operation.drive_torque))
    per_run = [
        _run_damage(design, setup, history, torque, float(grid_n[p]), settings, simulation)
        for p, setup, (history, _) in zip(point, setups, runs)
    ]
    return _bounded(torques_a, speeds_a.size, np.asarray(point), labels, per_run, len(setups))


def _run_damage(design, setup, history, torque, speed, settings, simulation) -> tuple[np.ndarray, np.ndarray]:
    """(gear, mode) damage per hour and stress peak of one history run."""
    u = design.z2 / design.z1
    rating = static_rating(design, torque, speed, settings, dynamic_factor=1.0)
    first = simulation.n_periods - simulation.keep_periods
    stresses = tooth_stresses(setup, rating, history[:, 2], first_period=first, samples_per_period=HISTORY_SAMPLES)
    rates, peaks = np.zeros((2, 2)), np.zeros((2, 2))
    for g in range(2):
        per_hour = 60.0 * speed / (u if g else 1.0)
        for m, (name, curve) in enumerate((("root", rating.root_curve[g]), ("contact", rating.contact_curve[g]))):
            rates[g, m] = engagement_damage(stresses[f"{name}_stress"].values[g], curve) * per_hour
            peaks[g, m] = float(stresses[f"{name}_stress_peak"].values[g])
    return rates, peaks


def _bounded(torques, n_speeds, point, labels, per_run, runs) -> StressHistories:
    """Rates and peaks per point: the run from rest's, and their bounds over the point's attractors."""
    shape = (torques.size, n_speeds)
    n_points = torques.size * n_speeds
    rates = np.stack([r for r, _ in per_run], axis=-1)  # (gear, mode, run)
    peaks = np.stack([p for _, p in per_run], axis=-1)
    rest = rates[..., :n_points]
    bounds, peak_bounds = np.zeros((2, 2, 2, n_points)), np.zeros((2, 2, 2, n_points))
    worst = np.full((2, 2, n_points), "rest", dtype=object)
    count = np.bincount(point, minlength=n_points)
    for index in range(n_points):
        mine = np.nonzero(point == index)[0]
        bounds[:, :, 0, index], bounds[:, :, 1, index] = rates[..., mine].min(-1), rates[..., mine].max(-1)
        peak_bounds[:, :, 0, index], peak_bounds[:, :, 1, index] = peaks[..., mine].min(-1), peaks[..., mine].max(-1)
        top = mine[np.argmax(rates[..., mine], axis=-1)]  # (gear, mode): the run with the greatest rate
        worst[:, :, index] = np.asarray(labels, dtype=object)[top]
    return StressHistories(
        torques=torques,
        rates=rest.reshape(2, 2, *shape),
        rate_bounds=bounds.reshape(2, 2, 2, *shape),
        worst_start=worst.astype(str).reshape(2, 2, *shape),
        attractor_count=count.reshape(shape),
        peaks=peak_bounds.reshape(2, 2, 2, *shape),
        runs=runs,
    )


__all__ = ["AttractorStarts", "HISTORY_TORQUES", "HISTORY_SAMPLES", "StressHistories", "history_damage"]
