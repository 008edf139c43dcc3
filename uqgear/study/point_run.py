"""One operating point simulated in full: histories, Poincare points, the DTE spectrum, QoIs and regime.

:func:`simulate_point` is the run behind the ``simulate`` analysis and
``uqgear simulate``; the batch runs of the other analyses keep only QoIs.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

import uqgear.dynamics as dynamics

from ..dynamics.stress_qois import STRESS_QOI_INFO
from ..dynamics.tooth_loads import GEARS, tooth_stresses
from ..physics.design import Design
from ..physics.effect_draws import as_effect
from ..physics.integration import QOI_INFO, simulate
from ..physics.model import build_model
from ..physics.rating import RatingSettings, static_rating
from .settings import SimulationSettings
from .variables import OPERATING_VARIABLES, VARIABLES, variable_units_short

#: Design keys an operating point may set.
DESIGN_VARIABLES: frozenset[str] = frozenset(name for name in VARIABLES if name not in OPERATING_VARIABLES)


def qoi_attrs(name: str) -> dict[str, str]:
    units, long_name = QOI_INFO[name]
    return {"units": units, "long_name": long_name}


def simulate_point(
    design: Design,
    point: Mapping[str, float],
    *,
    simulation: SimulationSettings,
    samples_per_period: int = 64,
    method: str = "fast",
    largest_lyapunov: float | None = None,
    seed: np.random.SeedSequence | int = 0,
    label: str = "",
    rating: RatingSettings | None = None,
) -> xr.Dataset:
    """One full simulation with its Poincare points, DTE spectrum, QoIs and regime.

    Parameters
    ----------
    design : Design
    point : mapping
        ``pinion_speed`` (rpm), ``drive_torque`` and ``adhesion_torque``
        (N m), optionally ``mesh_stiffness_scale`` and design keys.
    simulation : SimulationSettings
    samples_per_period : int
        History samples per mesh period.
    method : {"fast", "scipy"}
    largest_lyapunov : float, optional
        Largest Lyapunov exponent in 1/s (from a batch run of the same
        point); it decides chaotic against quasi-periodic.
    seed : SeedSequence or int
        Seed of the 0-1 test frequencies.
    label : str
        A label for reports (e.g. "period-1").
    rating : RatingSettings, optional
        ISO 6336 inputs of the tooth stresses (defaults where not given).

    Returns
    -------
    xarray.Dataset
        Histories on ``mesh_cycle`` (time in mesh periods), Poincare points
        on ``period``, the DTE amplitude spectrum on ``order``; scalars:
        the inputs, QoIs, ``regime``, ``response_period``, ``zero_one_k``,
        ``regime_reason``; the tooth stresses along the path of contact (``root_stress_path``,
        ``contact_stress_path``: dims ``gear``, ``bound``, ``position``) and their QoIs.
    """
    design_keys = {key: value for key, value in point.items() if key in DESIGN_VARIABLES}
    run_design = design.replace(**design_keys) if design_keys else design
    # the study's diagnosed effects enter every run, these panels' too
    model: dict[str, Any] = {
        "mesh_stiffness_scale": point.get("mesh_stiffness_scale", 1.0),
        "effects": tuple(as_effect(effect) for effect in simulation.effects),
        "damping_in_separation": simulation.damping_in_separation,
        "stiffness": simulation.stiffness,
    }
    operating = (point["pinion_speed"], point["drive_torque"], point["adhesion_torque"])
    run = simulate(
        run_design,
        *operating,
        method=method,
        n_periods=simulation.n_periods,
        keep_periods=simulation.keep_periods,
        samples_per_period=samples_per_period,
        steps_per_mode=simulation.steps_per_mode,
        **model,
    )
    if largest_lyapunov is not None:
        run["largest_lyapunov"] = ((), float(largest_lyapunov), qoi_attrs("largest_lyapunov"))
    response = dynamics.classify_dataset(run, seed=seed)
    spectrum = dynamics.spectrum_dataset(run, "x", against="order")["x"]
    qois = dynamics.response_qois(run)
    mesh_cycle = run["time"].values / run.attrs["mesh_period"]
    frequency = (
        spectrum["frequency"].values
        if "frequency" in spectrum.coords
        else spectrum["order"].values * point["pinion_speed"] / 60.0
    )
    data = _run_variables(run, spectrum, frequency, response, qois, point, label, largest_lyapunov)
    setup = build_model(run_design, *operating, **model)
    stresses = _path_stresses(setup, operating, run, simulation, samples_per_period, rating)
    coords = _point_coords(run, mesh_cycle, spectrum, stresses.pop("position"))
    attrs = {
        "z1": run.attrs["z1"],
        "z2": run.attrs["z2"],
        "mesh_period": run.attrs["mesh_period"],
        "n_periods": simulation.n_periods,
        "keep_periods": simulation.keep_periods,
        "samples_per_period": samples_per_period,
        "method": method,
    }
    data.update(stresses)
    return xr.Dataset(data, coords=coords, attrs=attrs)


def _run_variables(
    run: xr.Dataset,
    spectrum: xr.DataArray,
    frequency: np.ndarray,
    response: dynamics.ResponseClass,
    qois: xr.Dataset,
    point: Mapping[str, float],
    label: str,
    largest_lyapunov: float | None,
) -> dict[str, Any]:
    """The run's spectrum, regime, constants, histories, Poincare points, inputs and QoIs as variables."""
    data: dict[str, Any] = {
        "time_s": ("mesh_cycle", run["time"].values, {"units": "s", "long_name": "time"}),
        "spectrum_x": (
            "order",
            spectrum.values,
            {"units": "m", "long_name": "amplitude spectrum of the DTE x (Hann window)"},
        ),
        "spectrum_frequency": ("order", frequency, {"units": "Hz", "long_name": "frequency of the bin"}),
        "regime": ((), response.label, {"long_name": "response regime"}),
        "response_period": ((), int(response.period), {"units": "1", "long_name": "period n, 0 if none"}),
        "zero_one_k": (
            (),
            float(response.evidence["zero_one_k"]),
            {"units": "1", "long_name": "median K of the 0-1 test"},
        ),
        "regime_reason": ((), response.reason, {"long_name": "evidence for the regime"}),
        "label": ((), label, {"long_name": "label given in the study"}),
        "mesh_frequency": ((), float(run.attrs["mesh_frequency"]), {"units": "Hz"}),
        "static_mesh_force": ((), float(run.attrs["static_mesh_force"]), {"units": "N"}),
        "half_backlash": ((), float(run.attrs["half_backlash"]), {"units": "m"}),
        "largest_lyapunov": (
            (),
            float("nan") if largest_lyapunov is None else float(largest_lyapunov),
            qoi_attrs("largest_lyapunov"),
        ),
    }
    for name in (
        "x",
        "x_velocity",
        "y1",
        "y2",
        "y1_acceleration",
        "y2_acceleration",
        "mesh_force",
        "mesh_stiffness",
        "contact",
    ):
        data[name] = ("mesh_cycle", run[name].values, dict(run[name].attrs))
    for name in ("poincare_x", "poincare_x_velocity"):
        data[name] = ("period", run[name].values, dict(run[name].attrs))
    for name, value in point.items():
        data[name] = ((), float(value), {"units": variable_units_short(name)})
    for qoi in qois.data_vars:
        data[str(qoi)] = ((), float(qois[qoi].values), dict(qois[qoi].attrs))
    return data


def _point_coords(run: xr.Dataset, mesh_cycle: np.ndarray, spectrum: xr.DataArray,
                  position: np.ndarray) -> dict[str, Any]:
    """Time in mesh periods, period index, order, contact position, gear and bound."""
    coords: dict[str, Any] = {
        "mesh_cycle": ("mesh_cycle", mesh_cycle, {"units": "1", "long_name": "time in mesh periods"}),
        "period": ("period", run["period"].values, {"units": "1", "long_name": "mesh period index"}),
        "order": (
            "order",
            spectrum["order"].values,
            {"units": "1", "long_name": "order (multiples of the pinion rotation)"},
        ),
    }
    coords["position"] = (
        "position",
        position,
        {"units": "base pitches", "long_name": "contact point on the path of contact from its start"},
    )
    coords["gear"] = ("gear", list(GEARS), {"long_name": "gear of the pair"})
    coords["bound"] = ("bound", ["lower", "upper"], {"long_name": "lowest and highest over the engagements"})
    return coords


def _path_stresses(
    setup,
    operating: tuple[float, float, float],
    run: xr.Dataset,
    simulation: SimulationSettings,
    samples_per_period: int,
    rating: RatingSettings | None,
) -> dict[str, Any]:
    """The tooth stresses of a run: over every engagement the highest and lowest at each contact point of the
    path, per gear, and the stress QoIs (docs/model/rating.md section 10.6)."""
    iso = static_rating(setup.design, operating[1], operating[0], rating, dynamic_factor=1.0)
    first = simulation.n_periods - simulation.keep_periods
    stresses = tooth_stresses(
        setup, iso, run["x"].values, run["x_velocity"].values, first_period=first, samples_per_period=samples_per_period
    )
    data: dict[str, Any] = {"position": stresses["position"].values}
    for name, text in (("root_stress", "tooth root stress"), ("contact_stress", "flank contact stress")):
        values = stresses[name].values  # (gear, engagement, position)
        data[f"{name}_path"] = (
            ("gear", "bound", "position"),
            np.stack([values.min(axis=1), values.max(axis=1)], axis=1),
            {"units": "Pa", "long_name": f"{text} along the path of contact, lowest and highest over the engagements"},
        )
    for qoi, (units, text) in STRESS_QOI_INFO.items():
        quantity, gear = qoi.rsplit("_", 1)
        data[qoi] = ((), float(stresses[quantity].values[GEARS.index(gear)]), {"units": units, "long_name": text})
    return data


__all__ = ["simulate_point", "qoi_attrs", "DESIGN_VARIABLES"]
