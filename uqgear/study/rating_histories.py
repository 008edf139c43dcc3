"""Tooth stress histories of a ``rating`` analysis and the fatigue damage rates they give.

At every pinion speed of the rating's sweep the model runs from rest at a few
adhesion torques (:data:`HISTORY_TORQUES` across the T2 interval: its ends and
midpoint), all in one batch (:func:`~uqgear.physics.history_batch.integrate_histories`);
the kept steady section of each run gives every tooth engagement's root and
flank stress (:func:`~uqgear.dynamics.tooth_loads.tooth_stresses`), which are
rainflow-counted and Miner-summed on the rating's S-N curves
(:func:`~uqgear.dynamics.fatigue.engagement_damage`). A tooth meets one
engagement per revolution of its gear, so the damage per hour at pinion speed
n is that per engagement times 60 n (pinion) or 60 n / u (gear).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
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
    """Damage rates and stress peaks of the history runs (gear, mode or not, torque, speed).

    Attributes
    ----------
    torques : ndarray
        Adhesion torques T2 run, N m, increasing.
    rates : ndarray
        (gear, mode, torque, speed) Miner damage per hour (modes root, contact).
    root_peak, contact_peak : ndarray
        (gear, torque, speed) largest root and flank stress, Pa.
    runs : int
        Model runs.
    """

    torques: np.ndarray
    rates: np.ndarray
    root_peak: np.ndarray
    contact_peak: np.ndarray
    runs: int


def history_damage(
    design,
    simulation: SimulationSettings,
    fixed: Mapping[str, float],
    speeds: Sequence[float] | np.ndarray,
    torques: Sequence[float] | np.ndarray,
    settings: RatingSettings,
) -> StressHistories:
    """Run the histories at every (T2, speed) and count their damage; see the module text.

    ``fixed`` holds the other inputs of a run (drive torque, uncertain parameters at their nominal
    values), named as batch sample variables.
    """
    speeds_a, torques_a = np.asarray(speeds, dtype=float), np.asarray(torques, dtype=float)
    grid_t, grid_n = (values.ravel() for values in np.meshgrid(torques_a, speeds_a, indexing="ij"))
    others = {name: value for name, value in fixed.items() if name not in ("pinion_speed", "adhesion_torque")}
    samples = xr.Dataset(
        {
            "pinion_speed": ("sample", grid_n),
            "adhesion_torque": ("sample", grid_t),
            **{name: ("sample", np.full(grid_n.size, float(value))) for name, value in others.items()},
        }
    )
    setups = build_batch(
        design,
        samples,
        effects=simulation.effects,
        damping_in_separation=simulation.damping_in_separation,
        stiffness=simulation.stiffness,
    )
    keep = simulation.keep_periods
    runs = integrate_histories(setups, simulation.n_periods, keep, HISTORY_SAMPLES, simulation.steps_per_mode)
    torque = float(others.get("drive_torque", design.operation.drive_torque))
    u = design.z2 / design.z1
    shape = (torques_a.size, speeds_a.size)
    rates = np.zeros((2, 2, *shape))
    peaks = np.zeros((2, 2, *shape))
    for index, (setup, (history, _)) in enumerate(zip(setups, runs)):
        i, j = np.unravel_index(index, shape)
        rating = static_rating(design, torque, float(speeds_a[j]), settings, dynamic_factor=1.0)
        stresses = tooth_stresses(
            setup, rating, history[:, 2], first_period=simulation.n_periods - keep, samples_per_period=HISTORY_SAMPLES
        )
        for g in range(2):
            per_hour = 60.0 * float(speeds_a[j]) / (u if g else 1.0)
            for m, (name, curve) in enumerate((("root", rating.root_curve[g]), ("contact", rating.contact_curve[g]))):
                stress = stresses[f"{name}_stress"].values[g]
                rates[g, m, i, j] = engagement_damage(stress, curve) * per_hour
                peaks[g, m, i, j] = float(stresses[f"{name}_stress_peak"].values[g])
    return StressHistories(
        torques=torques_a, rates=rates, root_peak=peaks[:, 0], contact_peak=peaks[:, 1], runs=len(setups)
    )


__all__ = ["HISTORY_TORQUES", "HISTORY_SAMPLES", "StressHistories", "history_damage"]
