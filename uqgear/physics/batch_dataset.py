"""A batch's result as a Dataset: the QoIs from the kernels' sums, the Poincare section, histories and attrs.

:func:`batch_dataset` turns the arrays the batch kernels write
(:class:`BatchArrays`) into the Dataset :func:`uqgear.physics.integration.simulate_batch`
returns; :data:`QOI_INFO` names its QoIs, :data:`STATE_NAMES` the state's
components and :data:`VARIABLE_UNITS` / :data:`VARIABLE_LONG_NAMES` the
time-history variables of both integration paths.
"""

from __future__ import annotations

from collections.abc import Hashable, Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr

from . import _kernels as K
from ._pair_extremes import N_EXTREMES
from .batch_setup import extreme_variables
from .design import Design
from .effects import Effect
from .model import ModelSetup
from .pitch_errors import PitchErrors

#: The state vector's components, in order.
STATE_NAMES = ("y1", "y2", "x", "y1_velocity", "y2_velocity", "x_velocity")

#: Units of the time-history variables.
VARIABLE_UNITS = {
    "y1": "m",
    "y2": "m",
    "x": "m",
    "y1_velocity": "m s-1",
    "y2_velocity": "m s-1",
    "x_velocity": "m s-1",
    "y1_acceleration": "m s-2",
    "y2_acceleration": "m s-2",
    "mesh_force": "N",
    "mesh_stiffness": "N m-1",
    "ste": "m",
    "contact": "1",
    "te": "m",
}
#: Descriptions of the time-history variables.
VARIABLE_LONG_NAMES = {
    "y1": "pinion centre displacement along the line of action",
    "y2": "gear centre displacement along the line of action",
    "x": "dynamic transmission error (DTE)",
    "y1_velocity": "pinion centre velocity",
    "y2_velocity": "gear centre velocity",
    "x_velocity": "DTE velocity",
    "y1_acceleration": "pinion centre acceleration",
    "y2_acceleration": "gear centre acceleration",
    "mesh_force": "mesh force F = k f(x) + c_m x'",
    "mesh_stiffness": "mesh stiffness k(t)",
    "ste": "static transmission error e(t)",
    "contact": "contact state: 1 drive side, 0 separated, -1 back side",
    "te": "transmission error R1 theta1 - R2 theta2 = x - y1 + y2 + e",
}

#: QoIs returned by :func:`uqgear.physics.integration.simulate_batch`, with units and descriptions.
QOI_INFO: dict[str, tuple[str, str]] = {
    "dte_mean": ("m", "mean dynamic transmission error"),
    "dte_rms": ("m", "RMS of the DTE about its mean"),
    "dte_peak_to_peak": ("m", "peak-to-peak DTE"),
    "dynamic_load_factor": (
        "1",
        "maximum mesh force / the run's own static mesh force F_T (from its T1 and T2, so it moves with T2)",
    ),
    "peak_mesh_force": ("N", "maximum mesh force F = k f(x) + c_m x' in the kept section"),
    "load_factor_rated": (
        "1",
        "maximum mesh force / rated mesh force T1_rated / r_b1 "
        "(the design's rated drive torque on the pinion base circle)",
    ),
    "acc_pinion_rms": ("m s-2", "RMS pinion centre acceleration"),
    "acc_gear_rms": ("m s-2", "RMS gear centre acceleration"),
    "fraction_drive_contact": ("1", "fraction of time in drive-side contact"),
    "fraction_separation": ("1", "fraction of time with the teeth apart"),
    "fraction_back_contact": ("1", "fraction of time in back-side contact (impact)"),
    "largest_lyapunov": (
        "s-1",
        "largest Lyapunov exponent in 1/s: Benettin log growth over the kept time "
        "(renormalised once per mesh period; times the mesh period for nats per "
        "mesh period)",
    ),
}


class BatchArrays(NamedTuple):
    """The arrays the batch kernels write, one row per run (the outputs of a ``QoiBatch``).

    Attributes
    ----------
    accumulators : ndarray, shape (n, N_ACCUMULATORS)
        QoI sums (slots ``Q_*`` of :mod:`uqgear.physics._kernels`).
    poincare : ndarray, shape (n, keep_periods, 2)
        DTE and its velocity once per kept mesh period.
    history : ndarray, shape (n, channels, points)
        Decimated histories (channels: x, or x, te, y1'', y2'').
    final_states : ndarray, shape (n, 6)
        Each run's state at the end of its last period.
    extremes : ndarray, shape (n, N_EXTREMES)
        Tooth-pair load extremes (slots ``E_*``).
    """

    accumulators: np.ndarray
    poincare: np.ndarray
    history: np.ndarray
    final_states: np.ndarray
    extremes: np.ndarray

    @classmethod
    def allocate(cls, n: int, keep_periods: int, history_per_period: int, rig_channels: bool) -> BatchArrays:
        """Arrays for ``n`` runs, zeroed where the kernels add to them.

        Examples
        --------
        >>> arrays = BatchArrays.allocate(3, 20, 16, rig_channels=True)
        >>> arrays.poincare.shape, arrays.history.shape
        ((3, 20, 2), (3, 4, 320))
        """
        channels = 4 if rig_channels and history_per_period > 0 else 1
        return cls(
            accumulators=np.zeros((n, K.N_ACCUMULATORS)),
            poincare=np.empty((n, keep_periods, 2)),
            history=np.empty((n, channels, keep_periods * history_per_period if history_per_period > 0 else 0)),
            final_states=np.empty((n, 6)),
            extremes=np.zeros((n, N_EXTREMES)),
        )


def _qois(accumulators: np.ndarray, setups: Sequence[ModelSetup], lyapunov: bool) -> dict[str, np.ndarray]:
    n = len(setups)
    count = np.maximum(accumulators[:, K.Q_COUNT], 1.0)
    mean_x = accumulators[:, K.Q_X_SUM] / count
    mean_force = np.array([s.derived["static_mesh_force"] for s in setups])
    rated_force = np.array([s.derived["rated_mesh_force"] for s in setups])
    qois = {
        "dte_mean": mean_x,
        "dte_rms": np.sqrt(np.maximum(accumulators[:, K.Q_X_SQ] / count - mean_x**2, 0.0)),
        "dte_peak_to_peak": accumulators[:, K.Q_X_MAX] - accumulators[:, K.Q_X_MIN],
        "dynamic_load_factor": np.divide(
            accumulators[:, K.Q_F_MAX], mean_force, out=np.full(n, np.nan), where=mean_force > 0
        ),
        "acc_pinion_rms": np.sqrt(accumulators[:, K.Q_A1_SQ] / count),
        "acc_gear_rms": np.sqrt(accumulators[:, K.Q_A2_SQ] / count),
        "fraction_drive_contact": accumulators[:, K.Q_N_DRIVE] / count,
        "fraction_separation": accumulators[:, K.Q_N_SEP] / count,
        "fraction_back_contact": accumulators[:, K.Q_N_BACK] / count,
        "peak_mesh_force": accumulators[:, K.Q_F_MAX].copy(),
        "load_factor_rated": np.divide(
            accumulators[:, K.Q_F_MAX], rated_force, out=np.full(n, np.nan), where=rated_force > 0
        ),
    }
    if lyapunov:
        qois["largest_lyapunov"] = accumulators[:, K.Q_LYAPUNOV]
    return qois


def _run_variables(
    arrays: BatchArrays, setups: Sequence[ModelSetup], steps: np.ndarray, lyapunov: bool, stresses: bool
) -> dict[Hashable, tuple[Any, ...]]:
    """The QoIs, the tooth-load extremes, the Poincare section and each run's mesh frequency and steps."""
    data: dict[Hashable, tuple[Any, ...]] = {
        name: ("sample", value, {"units": QOI_INFO[name][0], "long_name": QOI_INFO[name][1]})
        for name, value in _qois(arrays.accumulators, setups, lyapunov).items()
    }
    if stresses:
        data.update(extreme_variables(arrays.extremes))
    data["poincare_x"] = (
        ("sample", "period"),
        arrays.poincare[:, :, 0],
        {"units": "m", "long_name": "DTE once per mesh period"},
    )
    data["poincare_x_velocity"] = (
        ("sample", "period"),
        arrays.poincare[:, :, 1],
        {"units": "m s-1", "long_name": "DTE velocity once per mesh period"},
    )
    mean_force = np.array([s.derived["static_mesh_force"] for s in setups])
    data["static_mesh_force"] = ("sample", mean_force, {"units": "N", "long_name": "mean mesh force F_T"})
    data["mesh_frequency"] = (
        "sample",
        np.array([s.mesh_frequency for s in setups]),
        {"units": "Hz", "long_name": "mesh frequency"},
    )
    data["steps_per_period"] = ("sample", steps, {"units": "1", "long_name": "RK4 steps per mesh period"})
    return data


def _sample_coords(samples: xr.Dataset, n_periods: int, keep_periods: int) -> dict[Hashable, tuple[Any, ...]]:
    """The kept periods, and the samples' variables and ``sample`` coordinates as coordinates."""
    coords: dict[Hashable, tuple[Any, ...]] = {
        "period": ("period", np.arange(n_periods - keep_periods, n_periods), {"units": "1"})
    }
    for name in samples.data_vars:
        coords[name] = ("sample", samples[name].values, dict(samples[name].attrs))
    for name in samples.coords:
        if samples[name].dims == ("sample",) and name not in coords:
            coords[name] = ("sample", samples[name].values, dict(samples[name].attrs))
    return coords


def _add_histories(
    data: dict[Hashable, tuple[Any, ...]],
    coords: dict[Hashable, tuple[Any, ...]],
    history: np.ndarray,
    n_periods: int,
    keep_periods: int,
    history_per_period: int,
) -> None:
    """Add the decimated DTE history (and with four channels the rig's) and its ``mesh_cycle`` axis."""
    data["x_history"] = (("sample", "mesh_cycle"), history[:, 0], {"units": "m", "long_name": "decimated DTE history"})
    if history.shape[1] == 4:
        for j, (name, key) in enumerate(
            (("te_history", "te"), ("acc_pinion_history", "y1_acceleration"), ("acc_gear_history", "y2_acceleration")),
            start=1,
        ):
            data[name] = (
                ("sample", "mesh_cycle"),
                history[:, j],
                {"units": VARIABLE_UNITS[key], "long_name": VARIABLE_LONG_NAMES[key]},
            )
    coords["mesh_cycle"] = (
        "mesh_cycle",
        n_periods - keep_periods + np.arange(keep_periods * history_per_period) / history_per_period,
        {"units": "1", "long_name": "time in mesh periods"},
    )


def _batch_attrs(
    design: Design,
    setups: Sequence[ModelSetup],
    *,
    n_periods: int,
    keep_periods: int,
    steps_per_mode: int,
    damping_in_separation: bool,
    stiffness: str,
    effects: Sequence[Effect],
    pitch_errors: PitchErrors | None,
) -> dict[str, Any]:
    attrs: dict[str, Any] = dict(
        method="fast",
        n_periods=n_periods,
        keep_periods=keep_periods,
        steps_per_mode=steps_per_mode,
        design_name=design.name,
        damping_in_separation=int(damping_in_separation),
        stiffness=stiffness,
        effects="; ".join(repr(e) for e in effects) or "none",
        **{f"design_{key}": value for key, value in design.to_dict().items()},
    )
    half_backlash = np.array([s.parameters[K.HALF_BACKLASH] for s in setups])
    if len(setups) and np.all(half_backlash == half_backlash[0]):
        attrs["half_backlash"] = float(half_backlash[0])
    if pitch_errors is not None:
        attrs.update(pitch_errors_pinion=pitch_errors.pinion.copy(), pitch_errors_gear=pitch_errors.gear.copy())
    return attrs


def batch_dataset(
    design: Design,
    samples: xr.Dataset,
    setups: Sequence[ModelSetup],
    steps: np.ndarray,
    arrays: BatchArrays,
    *,
    n_periods: int,
    keep_periods: int,
    history_per_period: int,
    lyapunov: bool,
    stresses: bool,
    final_state: bool,
    steps_per_mode: int,
    damping_in_separation: bool,
    stiffness: str,
    effects: Sequence[Effect],
    pitch_errors: PitchErrors | None,
) -> xr.Dataset:
    """The Dataset of an integrated batch (the return value of :func:`~uqgear.physics.integration.simulate_batch`).

    Parameters
    ----------
    design, samples
        The batch's base design and samples.
    setups : sequence of ModelSetup
        One per sample.
    steps : ndarray of int64
        Each run's RK4 steps per mesh period.
    arrays : BatchArrays
        What the kernels wrote.
    n_periods, keep_periods, history_per_period, lyapunov, stresses, final_state
        What the batch integrated and keeps.
    steps_per_mode, damping_in_separation, stiffness, effects, pitch_errors
        The model's options, kept as attrs.

    Returns
    -------
    xarray.Dataset
        As :func:`~uqgear.physics.integration.simulate_batch` describes.

    Examples
    --------
    An empty batch still names its QoIs and the kept periods:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> empty = uqgear.samples_from_mapping({"pinion_speed": []})
    >>> ds = batch_dataset(design, empty, [], np.zeros(0, dtype=np.int64), BatchArrays.allocate(0, 5, 0, False),
    ...                    n_periods=10, keep_periods=5, history_per_period=0, lyapunov=False, stresses=False,
    ...                    final_state=False, steps_per_mode=24, damping_in_separation=True, stiffness="ishikawa",
    ...                    effects=(), pitch_errors=None)
    >>> dict(ds.sizes), ds["period"].values.tolist()
    ({'sample': 0, 'period': 5}, [5, 6, 7, 8, 9])
    """
    data = _run_variables(arrays, setups, steps, lyapunov, stresses)
    coords = _sample_coords(samples, n_periods, keep_periods)
    if history_per_period > 0:
        _add_histories(data, coords, arrays.history, n_periods, keep_periods, history_per_period)
    if final_state:
        data["final_state"] = (
            ("sample", "state"),
            arrays.final_states,
            {"units": "m, m, m, m s-1, m s-1, m s-1", "long_name": "state at the end of the last period"},
        )
        coords["state"] = ("state", list(STATE_NAMES), {"long_name": "state component"})
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update(
        _batch_attrs(
            design,
            setups,
            n_periods=n_periods,
            keep_periods=keep_periods,
            steps_per_mode=steps_per_mode,
            damping_in_separation=damping_in_separation,
            stiffness=stiffness,
            effects=effects,
            pitch_errors=pitch_errors,
        )
    )
    return ds


__all__ = ["batch_dataset", "BatchArrays", "QOI_INFO", "STATE_NAMES", "VARIABLE_UNITS", "VARIABLE_LONG_NAMES"]
