"""The foreign virtual rig's own mesh-force QoIs at operating points: what a prediction of it should cover.

:mod:`.foreign_rig` records what a rig's sensors give (encoder TE, housing
accelerations). A prediction of the load a designer sizes against needs the
mesh force itself, which the foreign physics computes pair by pair
(``pair_sum``: each tooth pair's stiffness times its deflection, profile
errors included, plus its mesh damping). :func:`foreign_qois` integrates the
same equations of motion (the same parameters, start state and step) and
reduces the force and the mesh approach over the steady part of each run, as
:func:`uqgear.simulate`'s QoIs of the 3-DOF model are reduced over the kept
section:

* ``peak_mesh_force``: the largest total mesh force, N;
* ``mesh_force_mean``: its mean, N;
* ``static_mesh_force``: the run's static mesh force T2 / r_b2, N. The speed
  controller holds the motor's speed, so in a steady state the gear carries
  the wheel torque T2 and the mean force equals it; at the balance
  T2 = T1 z2 / z1 it is the 3-DOF model's T1 / r_b1;
* ``dynamic_load_factor``: ``peak_mesh_force / static_mesh_force``;
* ``dte_rms``: the root mean square about its mean of the mesh approach
  r_b1 theta1 - r_b2 theta2 - y_a + y_b (the wheels' approach along the line
  of action from rotations and centre displacements, each pair's deflection
  being it plus that pair's profile errors), m: the 3-DOF model's DTE x is
  that approach with one lumped pair.

The force is sampled at every integration step (a fortieth of the fastest
mode's period or finer), so the peak is that of the integrated trajectory.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import xarray as xr
from numba import njit

from ..common.errors import OperatingPointError
from ..physics.design import Design
from ..physics.effects import Effect
from .foreign_rig import (
    N_STATE,
    ForeignGears,
    effect_vector,
    pair_sum,
    rk4_step,
    run_parameters,
    static_state,
    time_step,
)

#: The QoIs of :func:`foreign_qois`: units and meaning.
FOREIGN_QOI_INFO: dict[str, tuple[str, str]] = {
    "peak_mesh_force": ("N", "largest total mesh force over the steady part of the run"),
    "mesh_force_mean": ("N", "mean total mesh force over the steady part of the run"),
    "static_mesh_force": ("N", "static mesh force T2 / r_b2 (the gear carries the wheel torque)"),
    "dynamic_load_factor": ("1", "peak mesh force over the static mesh force"),
    "dte_rms": ("m", "RMS about its mean of the mesh approach along the line of action"),
}
# the accumulators of _integrate_mesh
_F_MAX, _F_SUM, _X_SUM, _X_SQ, _COUNT = range(5)
# the output rate whose step simulate_foreign_run takes at its default sampling rate (4 x 20480 Hz)
_RATE = 4.0 * 20480.0


@njit(cache=True)
def _integrate_mesh(y0, p, pin_err, gear_err, eff, step, n_steps, first):  # pragma: no cover - compiled
    """RK4 from t = 0 over ``n_steps``; from step ``first`` on, the largest and summed mesh force and the sum and
    sum of squares of the mesh approach (about its value at ``first``, against cancellation), and the count."""
    y = y0.copy()
    work = np.empty((5, N_STATE))
    out = np.zeros(5)
    out[_F_MAX] = -np.inf
    reference = 0.0
    t = 0.0
    for index in range(n_steps):
        rk4_step(t, y, p, pin_err, gear_err, eff, step, work)
        t += step
        if index < first:
            continue
        force, _, _ = pair_sum(t, y, p, pin_err, gear_err, eff)
        approach = p[6] * y[1] - p[7] * y[2] - y[4] + y[5]
        if index == first:
            reference = approach
        out[_F_MAX] = max(out[_F_MAX], force)
        out[_F_SUM] += force
        out[_X_SUM] += approach - reference
        out[_X_SQ] += (approach - reference) ** 2
        out[_COUNT] += 1.0
    return out


def _as_points(name: str, values: float | Sequence[float] | np.ndarray, lower: float) -> np.ndarray:
    """Operating-point values as a finite 1-D array above ``lower``."""
    array = np.atleast_1d(np.asarray(values, dtype=float))
    if array.ndim != 1 or not np.all(np.isfinite(array)) or not np.all(array > lower):
        raise OperatingPointError(f"{name}: expected finite values > {lower:g}; got {values!r}")
    return array


def _one_run(
    design: Design, speed: float, drive_torque: float, load_torque: float, gears: ForeignGears, eff: np.ndarray,
    start: float, duration: float,
) -> dict[str, float]:
    """The QoIs of one run (:data:`FOREIGN_QOI_INFO`)."""
    p, fastest = run_parameters(design, speed, drive_torque, load_torque)
    _, step = time_step(fastest, _RATE)
    first = int(round(start / step))
    n_steps = first + int(round(duration / step))
    out = _integrate_mesh(static_state(p, design), p, gears.pinion, gears.gear, eff, step, n_steps, first)
    count = out[_COUNT]
    mean_x = out[_X_SUM] / count
    static = load_torque / p[7]
    return {
        "peak_mesh_force": float(out[_F_MAX]),
        "mesh_force_mean": float(out[_F_SUM] / count),
        "static_mesh_force": float(static),
        "dynamic_load_factor": float(out[_F_MAX] / static),
        "dte_rms": math.sqrt(max(out[_X_SQ] / count - mean_x**2, 0.0)),
    }


def foreign_qois(
    design: Design,
    pinion_speed: float | Sequence[float] | np.ndarray,
    drive_torque: float | Sequence[float] | np.ndarray,
    adhesion_torque: float | Sequence[float] | np.ndarray,
    *,
    gears: ForeignGears,
    effects: Sequence[Effect] = (),
    start: float = 0.3,
    duration: float = 0.5,
) -> xr.Dataset:
    """The foreign rig's own mesh-force QoIs at operating points (module docstring).

    Parameters
    ----------
    design : Design
        The gearbox (as :func:`~uqgear.rig.foreign_rig.simulate_foreign_run` takes it).
    pinion_speed, drive_torque, adhesion_torque : float or array-like (n,)
        Operating points: pinion speed (rpm), T1 and T2 (N m); scalars are broadcast.
    gears : ForeignGears
        The gear set's per-tooth profile errors (:func:`~uqgear.rig.foreign_rig.draw_gears`).
    effects : sequence of Effect
        Effects, through the foreign rig's own physics.
    start : float
        Run-in before the steady part, s (the campaign's ``run_in``).
    duration : float
        Length of the steady part the QoIs are reduced over, s.

    Returns
    -------
    xarray.Dataset
        Each QoI of :data:`FOREIGN_QOI_INFO` over ``point``, with the operating points as coordinates.

    Raises
    ------
    OperatingPointError
        A speed, torque or time that is not a positive finite number, or point arrays of different lengths.

    Examples
    --------
    At a crawl the mesh carries the static force: peak and mean are T2 / r_b2, which at the balance
    T2 = T1 z2 / z1 is T1 / r_b1:

    >>> from uqgear.physics.design import load_design
    >>> from uqgear.rig.foreign_rig import draw_gears
    >>> design = load_design("locomotive")
    >>> qois = foreign_qois(design, 20.0, 6000.0, 6000.0 * design.z2 / design.z1, gears=draw_gears(design, 6, 0),
    ...                     duration=0.1)
    >>> static = float(qois["static_mesh_force"][0])
    >>> round(static), round(float(qois["mesh_force_mean"][0]) / static, 3)
    (67567, 1.0)
    """
    speed = _as_points("pinion_speed", pinion_speed, 0.0)
    torque = _as_points("drive_torque", drive_torque, 0.0)
    load = _as_points("adhesion_torque", adhesion_torque, 0.0)
    _as_points("start", start, 0.0)
    _as_points("duration", duration, 0.0)
    try:
        speed, torque, load = np.broadcast_arrays(speed, torque, load)
    except ValueError:
        raise OperatingPointError(
            f"pinion_speed, drive_torque, adhesion_torque: expected equal lengths or scalars; got "
            f"{speed.size}, {torque.size}, {load.size}"
        ) from None
    eff = effect_vector(effects, design)
    runs = [_one_run(design, *point, gears, eff, float(start), float(duration)) for point in zip(speed, torque, load)]
    data = {
        name: ("point", np.array([run[name] for run in runs]), {"units": units, "long_name": meaning})
        for name, (units, meaning) in FOREIGN_QOI_INFO.items()
    }
    coords = {
        "pinion_speed": ("point", speed.copy(), {"units": "rpm"}),
        "drive_torque": ("point", torque.copy(), {"units": "N m"}),
        "adhesion_torque": ("point", load.copy(), {"units": "N m"}),
    }
    return xr.Dataset(data, coords=coords, attrs={"source": "uqgear foreign virtual rig (uqgear.rig.foreign_response)"})


__all__ = ["FOREIGN_QOI_INFO", "foreign_qois"]
