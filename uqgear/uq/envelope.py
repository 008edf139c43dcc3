"""Response envelopes over the adhesion-torque interval.

T2 is uncertain but bounded, so at every pinion speed the response is a set,
not a value. This module evaluates the model on a speed x T2 grid (through
the :class:`~uqgear.uq.runner.Runner`, so grids scale out to dask and resume from
checkpoints) and derives from it:

* :func:`qoi_envelope`: lower and upper QoI bands against speed over the T2
  interval, with the T2 that attains each bound, and a flag where the response
  is non-smooth in T2 (regime changes, contact loss appearing); on a grid run
  from several starts (``<qoi>_max`` / ``<qoi>_min`` over the attractors, see
  :mod:`uqgear.dynamics.attractors`) the bands span the attractors too and
  ``<qoi>_start_at_bound`` names the start that reached each;
* :func:`bifurcation_envelope`: the union of Poincare points over the T2
  interval at each speed, every point keeping the T2 that made it;
* :func:`regime_map`: period-n / quasi-periodic / chaotic label per
  (speed, T2) cell with its evidence;
* :func:`time_response_envelope`: for periodic cells, the DTE over one mesh
  period folded from the kept periods, and its band over T2.

These are scan-based (the reference interval method): a regime map or a
bifurcation diagram is exactly the non-smooth case where polynomial
surrogates give falsely tight bands.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence

import numpy as np
import xarray as xr

from ..physics.design import Design
from ..dynamics.regimes import REGIME_LABELS
from ..dynamics.sweeps import sweep_grid
from ..common.errors import OperatingPointError
from ..physics.integration import BatchEvaluator
from .runner import Runner

SPEED = "pinion_speed"
ADHESION = "adhesion_torque"


def _values(name: str, values: Sequence[float]) -> np.ndarray:
    array = np.asarray(values, dtype=float).ravel()
    if array.size == 0 or not np.all(np.isfinite(array)):
        raise OperatingPointError(f"{name}: expected a non-empty list of finite values")
    return array


def speed_adhesion_grid(design: Design, pinion_speed: Sequence[float], adhesion_torque: Sequence[float], *,
                        fixed: Mapping[str, float] | None = None, n_periods: int = 400,
                        keep_periods: int = 200, history_per_period: int = 0, lyapunov: bool = True,
                        effects: Sequence = (), runner: Runner | None = None, resume: bool = False,
                        seed: int = 0) -> xr.Dataset:
    """Simulate every (speed, T2) cell and classify its response.

    Parameters
    ----------
    design : Design
    pinion_speed : sequence of float
        Speeds in rpm.
    adhesion_torque : sequence of float
        T2 values in N m spanning the interval (include both ends).
    fixed : mapping, optional
        Other sample variables held constant (``drive_torque``, ``k1``, ...).
    n_periods, keep_periods, history_per_period, lyapunov, effects
        As in :func:`uqgear.simulate_batch`.
    runner : Runner, optional
        Where to run (in-process by default).
    resume : bool
        Reuse the runner's checkpoints.
    seed : int
        Seed of the 0-1 test's random frequencies (classification only).

    Returns
    -------
    xarray.Dataset
        Dims ``pinion_speed``, ``adhesion_torque``, ``period`` (and
        ``mesh_cycle`` with histories): the batch QoIs, Poincare points,
        ``regime``, ``response_period``, ``zero_one_k``.
    """
    speeds = _values(SPEED, pinion_speed)
    torques = _values(ADHESION, adhesion_torque)
    if np.any(speeds <= 0):
        raise OperatingPointError(f"{SPEED}: expected values > 0 rpm; got min {speeds.min():g}")
    if np.any(torques < 0):
        raise OperatingPointError(f"{ADHESION}: expected values >= 0 N m; got min {torques.min():g}")
    evaluator = BatchEvaluator(design, n_periods=n_periods, keep_periods=keep_periods,
                               history_per_period=history_per_period, lyapunov=lyapunov, effects=effects)
    runner = runner or Runner(chunk_size=max(64, speeds.size * torques.size // 8))

    def evaluate(samples: xr.Dataset) -> xr.Dataset:
        return runner.run(evaluator, samples, key=evaluator.key(), resume=resume)

    grid = sweep_grid(design, {SPEED: speeds, ADHESION: torques}, fixed=fixed, seed=seed, evaluate=evaluate)
    grid[SPEED].attrs.update(units="rpm", long_name="pinion speed")
    grid[ADHESION].attrs.update(units="N m", long_name="adhesion torque T2")
    grid.attrs.update(analysis="speed_adhesion_grid", fixed=repr(dict(fixed or {})),
                      interval_lower=float(torques.min()), interval_upper=float(torques.max()))
    return grid


def qoi_envelope(grid: xr.Dataset, qois: Sequence[str] = ("dte_rms", "dynamic_load_factor",
                                                          "fraction_separation")) -> xr.Dataset:
    """Lower and upper QoI bands against speed over the T2 values of ``grid``.

    Returns
    -------
    xarray.Dataset
        Per QoI: ``<qoi>`` on (``pinion_speed``, ``bound``) and
        ``<qoi>_adhesion_at_bound`` (the T2 attaining each bound); ``non_smooth``
        (bool per speed) with the reason in ``non_smooth_reason``.
    """
    missing = [q for q in qois if q not in grid.data_vars]
    if missing:
        raise OperatingPointError(f"qois: {missing[0]!r} not in the grid; expected among "
                                  f"{', '.join(v for v in grid.data_vars if grid[v].dims == (SPEED, ADHESION))}")
    out = xr.Dataset(coords={SPEED: grid[SPEED], "bound": ["lower", "upper"]})
    for name in qois:
        # a grid run from several starts: the bounds over the attractors too, and the start giving each
        several = f"{name}_max" in grid and f"{name}_min" in grid
        lows, highs = (grid[f"{name}_min"], grid[f"{name}_max"]) if several else (grid[name], grid[name])
        lower_index = lows.argmin(ADHESION)
        upper_index = highs.argmax(ADHESION)
        band = xr.concat([lows.min(ADHESION), highs.max(ADHESION)], dim="bound")
        out[name] = band.transpose(SPEED, "bound").assign_attrs(grid[name].attrs)
        at = xr.concat([grid[ADHESION][lower_index], grid[ADHESION][upper_index]], dim="bound")
        out[f"{name}_adhesion_at_bound"] = at.drop_vars(ADHESION, errors="ignore").transpose(SPEED, "bound") \
            .assign_attrs(units="N m", long_name=f"T2 attaining each bound of {name}")
        if several and f"{name}_max_start" in grid:
            starts = xr.concat([grid[f"{name}_min_start"].isel({ADHESION: lower_index}),
                                grid[f"{name}_max_start"].isel({ADHESION: upper_index})], dim="bound")
            out[f"{name}_start_at_bound"] = starts.drop_vars(ADHESION, errors="ignore").transpose(SPEED, "bound") \
                .assign_attrs(long_name=f"start whose attractor attains each bound of {name}")
    reasons = []
    for i in range(grid.sizes[SPEED]):
        cell = grid.isel({SPEED: i})
        labels = set(np.asarray(cell["regime"].values).tolist())
        why = []
        if len(labels) > 1:
            why.append("regime changes over T2 (" + ", ".join(sorted(labels)) + ")")
        separation = cell["fraction_separation"].values
        if np.any(separation > 0) and np.any(separation == 0):
            why.append("contact loss appears within the T2 interval")
        # anything but a period-n label (quasi-periodic, long period, chaotic, uncertain, a failed run)
        if any(not str(label).startswith("period-") for label in labels):
            why.append("non-periodic response")
        reasons.append("; ".join(why))
    out["non_smooth"] = (SPEED, np.array([bool(r) for r in reasons]),
                         {"long_name": "response non-smooth in T2 at this speed (bands from the scan, no surrogate)"})
    out["non_smooth_reason"] = (SPEED, np.array(reasons, dtype=str))
    out.attrs.update(analysis="qoi_envelope", method="scan",
                     interval_lower=grid.attrs.get("interval_lower", float(grid[ADHESION].min())),
                     interval_upper=grid.attrs.get("interval_upper", float(grid[ADHESION].max())),
                     n_adhesion_values=grid.sizes[ADHESION])
    return out


def bifurcation_envelope(grid: xr.Dataset) -> xr.Dataset:
    """Union over T2 of the Poincare points at each speed.

    Returns
    -------
    xarray.Dataset
        ``poincare_x`` on (``pinion_speed``, ``point``) with the coordinate
        ``point_adhesion_torque`` (the T2 that made each point) and
        ``poincare_x_envelope`` on (``pinion_speed``, ``bound``).
    """
    points = grid["poincare_x"].transpose(SPEED, ADHESION, "period")
    n_speed, n_torque, n_period = points.shape
    flat = points.values.reshape(n_speed, n_torque * n_period)
    adhesion = np.repeat(grid[ADHESION].values, n_period)
    out = xr.Dataset(
        {"poincare_x": ((SPEED, "point"), flat, dict(grid["poincare_x"].attrs)),
         "poincare_x_envelope": ((SPEED, "bound"), np.stack([np.nanmin(flat, axis=1), np.nanmax(flat, axis=1)], 1),
                                 {"units": "m", "long_name": "range of Poincare DTE over the T2 interval"})},
        coords={SPEED: grid[SPEED], "bound": ["lower", "upper"],
                "point_adhesion_torque": ("point", adhesion, {"units": "N m", "long_name": "T2 of each point"}),
                "point_period": ("point", np.tile(grid["period"].values, n_torque), {"units": "1"})})
    out.attrs.update(analysis="bifurcation_envelope", half_backlash=grid.attrs.get("half_backlash", np.nan))
    return out


def regime_map(grid: xr.Dataset) -> xr.Dataset:
    """Regime label and evidence per (speed, T2) cell."""
    names = [v for v in ("regime", "regime_reason", "response_period", "zero_one_k", "distinct_points",
                         "largest_lyapunov", "lyapunov_per_period", "fraction_separation",
                         "fraction_back_contact", "dte_rms") if v in grid]
    out = grid[names].copy()
    out.attrs = {"analysis": "regime_map",
                 "labels": ", ".join(REGIME_LABELS),
                 "evidence": "Poincare period detection, 0-1 test K, largest Lyapunov exponent"}
    return out


def time_response_envelope(grid: xr.Dataset) -> xr.Dataset:
    """DTE over one mesh period and its band over T2, for periodic cells.

    The kept history of each cell is folded onto the mesh phase; cells whose
    response is not periodic are excluded (and counted), because a folded
    chaotic record is not a time response.
    """
    if "x_history" not in grid:
        raise OperatingPointError("grid: no x_history; run speed_adhesion_grid with history_per_period > 0")
    cycles = grid["mesh_cycle"].values
    per_period = int(round(1.0 / (cycles[1] - cycles[0])))
    history = grid["x_history"].transpose(SPEED, ADHESION, "mesh_cycle").values
    n_speed, n_torque, n_total = history.shape
    folded = history.reshape(n_speed, n_torque, n_total // per_period, per_period)
    periodic = np.char.startswith(grid["regime"].transpose(SPEED, ADHESION).values.astype(str), "period-")
    last = folded[:, :, -1, :]
    masked = np.where(periodic[:, :, None], folded.min(axis=2), np.nan)
    masked_max = np.where(periodic[:, :, None], folded.max(axis=2), np.nan)
    phase = np.arange(per_period) / per_period
    with warnings.catch_warnings():
        # speeds without any periodic cell have no band: NaN, counted in periodic_cells
        warnings.simplefilter("ignore", RuntimeWarning)
        lower = np.nanmin(masked, axis=1)
        upper = np.nanmax(masked_max, axis=1)
    out = xr.Dataset(
        {"x_last_period": ((SPEED, ADHESION, "mesh_phase"), last,
                           {"units": "m", "long_name": "DTE over the last kept mesh period"}),
         "x_envelope": ((SPEED, "bound", "mesh_phase"), np.stack([lower, upper], axis=1),
                        {"units": "m", "long_name": "DTE band over the T2 interval (periodic cells, all kept periods)"}),
         "periodic_cells": (SPEED, periodic.sum(axis=1), {"units": "1", "long_name": "periodic T2 cells used"})},
        coords={SPEED: grid[SPEED], ADHESION: grid[ADHESION], "bound": ["lower", "upper"],
                "mesh_phase": ("mesh_phase", phase, {"units": "1", "long_name": "fraction of a mesh period"})})
    out.attrs.update(analysis="time_response_envelope")
    return out


__all__ = ["speed_adhesion_grid", "qoi_envelope", "bifurcation_envelope", "regime_map", "time_response_envelope"]
