"""The ``rating`` analysis: ISO 6336 safety factors and fatigue damage from the simulated dynamic load.

The interval machinery bounds the peak mesh force over the interval parameters (T2 by default)
at every pinion speed of the sweep, taking the worst over attractors where the study's
``simulation.starts`` asks for it (:func:`~uqgear.study.analyses.interval_analysis`). The
simulated dynamic factor is that peak over the static mesh force at the study's drive torque;
it takes the place of ISO's K_v in :func:`~uqgear.physics.rating.static_rating`, whose safety
factors S_F and S_H per gear follow at each bound (the lower safety factor from the upper
dynamic factor). ISO 6336-1 method B's K_v and its safety factors sit beside them.

Fatigue damage over the ``service`` (:mod:`uqgear.study.rating_service`: a speed
distribution or a mission, hours or kilometres, the rail condition): the model runs at every
speed of the sweep at the T2 interval's ends and midpoint, and each tooth's root and flank
stress over the kept steady section is rainflow-counted and Miner-summed on the S-N curves of
the life factors (:mod:`uqgear.study.rating_histories`), giving a damage rate per hour at each
(T2, speed). Which of several coexisting responses the gear holds is unknown, so where the
study's guided starts find more than one attractor at such a point, a history runs from each
attractor's first start as well, and the rates are bounded over the attractors: the upper
damage is the worst attractor's (``damage_rate_start`` names its start), the lower the
mildest's; ``damage_from_rest`` keeps the runs from rest's damage beside them. The service's
speeds take their rates from the sweep (linear between its speeds)
and its rail condition from T2 (an interval: the least and greatest rate at each speed over it;
a distribution: the time-weighted mean). Without ``service`` the illustrative
:data:`RATING_SERVICE` applies: 20,000 h spread evenly over the sweep's speeds inside the
design's service range, over the study's whole T2 interval.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any, cast

import numpy as np
import xarray as xr

from ..physics.geometry import pair_geometry
from ..physics.rating import RatingSettings, dynamic_factor_model, static_rating
from .analyses import AnalysisContext, interval_bounds, register
from .coexistence import MultiStartModel
from .guided_starts import GuidedStartModel
from .rating_histories import HISTORY_TORQUES, StressHistories, history_damage
from .rating_service import check_service, rail_torques, service_damage

#: Illustrative service when a rating states none: hours, spread evenly over the service speeds.
RATING_SERVICE = {"hours": 20000.0, "description": "illustrative: 20,000 h, evenly over the service speeds"}
GEARS, BOUNDS, MODES = ("pinion", "gear"), ("lower", "upper"), ("root", "contact")


def _service(context: AnalysisContext, speeds: np.ndarray) -> dict[str, Any]:
    given = context.options.get("service")
    if given:
        return dict(given)
    low, high = context.design.operation.pinion_speed_service
    inside = [float(speed) for speed in speeds if low <= speed <= high] or [float(speeds[0])]
    return check_service({**RATING_SERVICE, "speeds": inside, "shares": [1.0 / len(inside)] * len(inside)}, "service")


def history_torques(lower: float, upper: float, points: int, service: dict[str, Any]) -> np.ndarray:
    """T2 values of the damage histories: ``points`` evenly across [lower, upper], ends included, and a rail
    distribution's own values (its time-weighted mean then needs no interpolation in T2).

    Examples
    --------
    >>> from uqgear.study.rating_analysis import history_torques
    >>> history_torques(20e3, 40e3, 3, {}).tolist()
    [20000.0, 30000.0, 40000.0]
    >>> rail = {"kind": "distribution", "adhesion_coefficient": [0.25, 0.35], "shares": [0.5, 0.5]}
    >>> [round(t) for t in history_torques(20e3, 50e3, 3, {"rail": rail, "axle_load": 20000, "wheel_radius": 0.5})]
    [20000, 24517, 34323, 35000, 50000]
    """
    torques = [lower + f * (upper - lower) for f in np.linspace(0.0, 1.0, int(points))]
    rail = rail_torques(service)
    if rail is not None and rail[0] == "distribution":
        for value in rail[1]:
            if not any(np.isclose(value, t, rtol=1e-9, atol=0.0) for t in torques):
                torques.append(float(value))
    return np.sort(np.asarray(torques, dtype=float))


def _histories(
    context: AnalysisContext,
    settings: RatingSettings,
    speeds: np.ndarray,
    guided: GuidedStartModel | MultiStartModel | None,
    service: dict[str, Any],
) -> StressHistories:
    """Damage rates at the T2 values of :func:`history_torques` (the study's T2 alone where it is not bounded),
    over the attractors the guided model finds there (from rest alone without guided starts)."""
    fixed = context.fixed_values(exclude=context.options["parameters"])
    if "adhesion_torque" in context.options["parameters"]:
        parameter = context.study.uncertain["adhesion_torque"]
        points = int(context.options.get("history_points") or len(HISTORY_TORQUES))
        torques = history_torques(float(parameter.lower), float(parameter.upper), points, service)
    else:
        torques = np.asarray([float(fixed["adhesion_torque"])])
    starts = guided.attractor_starts if guided is not None else None
    return history_damage(context.design, context.spec.simulation, fixed, speeds, torques, settings, starts)


@register("rating")
def rating_analysis(context: AnalysisContext) -> xr.Dataset:
    """ISO 6336 safety factors per gear against speed, bounded over the interval parameters, and damage."""
    settings = RatingSettings.from_mapping(context.options.get("rating"))
    options = {**context.options, "qois": ("peak_mesh_force",)}
    interval_context = dataclasses.replace(context, spec=dataclasses.replace(context.spec, options=options))
    starts = context.spec.simulation.starts
    # guided starts: the interval's model, whose window points' attractors the histories then start from;
    # every start everywhere: a multi-start model of the same settings searches the history points
    guided: GuidedStartModel | MultiStartModel | None = None
    if starts is not None and starts.guided:
        guided = cast(GuidedStartModel, interval_context.model(poincare=False))
        bounds = interval_bounds(interval_context, guided=guided)
    else:
        bounds = interval_bounds(interval_context)
        if starts is not None:
            guided = cast(MultiStartModel, interval_context.model(poincare=False))
    design = context.design
    torque = float(context.fixed_values(exclude=options["parameters"])["drive_torque"])
    peak = bounds["peak_mesh_force"].transpose("bound", "pinion_speed")
    speeds = np.asarray(peak["pinion_speed"].values, dtype=float)
    # the static mesh force at the study's torque on the pinion base circle (as the model's mesh force)
    simulated = peak.values / (torque / pair_geometry(design).pinion.base_radius)
    iso = dynamic_factor_model(design, torque, settings)
    iso_factor = np.asarray(iso.factor(speeds), dtype=float)
    safety = np.zeros((2, 2, 2, speeds.size))  # (mode, gear, bound, speed)
    safety_iso = np.zeros((2, 2, speeds.size))
    for j, speed in enumerate(speeds):
        for b in range(2):
            # the lower safety factor comes from the upper dynamic factor
            rating = static_rating(design, torque, speed, settings, dynamic_factor=float(simulated[1 - b, j]))
            safety[0, :, b, j], safety[1, :, b, j] = rating.safety_root, rating.safety_contact
        rating = static_rating(design, torque, speed, settings, dynamic_factor=float(iso_factor[j]))
        safety_iso[0, :, j], safety_iso[1, :, j] = rating.safety_root, rating.safety_contact
    nominal = static_rating(design, torque, float(speeds[0]), settings, dynamic_factor=1.0)
    service = _service(context, speeds)
    runs_before = int(guided.runs) if guided is not None else 0
    histories = _histories(context, settings, speeds, guided, service)
    result = _dataset(bounds, speeds, simulated, iso, iso_factor, safety, safety_iso, nominal, settings, service)
    result = _with_damage(result, histories, service, speeds)
    extra = int(guided.runs) - runs_before if guided is not None else 0  # window points the interval did not run
    result.attrs["model_runs"] = int(result.attrs.get("model_runs", 0)) + histories.runs + extra
    result.attrs["history_coexisting_points"] = int((histories.attractor_count > 1).sum())
    result.attrs["damage_over_attractors"] = (
        "none" if starts is None else ("guided" if starts.guided else "every start at every history point")
    )
    if context.posterior is not None:
        # the calibrated gear set: its parameters at their posterior medians (the fixed inputs); the verdict
        # says where a speed lies beyond the campaign they were learnt on
        result.attrs["posterior_source"] = context.posterior.source
        result.attrs["campaign_range"] = json.dumps(context.posterior.campaign)
    return result


def _with_damage(result: xr.Dataset, histories: StressHistories, service, speeds: np.ndarray) -> xr.Dataset:
    """The damage over the service, its rate, the speeds' shares, the life and the stress peaks."""
    # the lower damage from each point's least rate over its attractors, the upper from the greatest
    low, _ = service_damage(service, speeds, histories.torques, histories.rate_bounds[:, :, 0])
    high, parts = service_damage(service, speeds, histories.torques, histories.rate_bounds[:, :, 1])
    damage = np.stack([low[..., 0], high[..., 1]], axis=-1).transpose(0, 2, 1)  # (gear, bound, mode)
    rest, _ = service_damage(service, speeds, histories.torques, histories.rates)
    rest = rest.transpose(0, 2, 1)
    hours = service["hours"]
    total = parts.sum(axis=-1, keepdims=True)
    share = np.divide(parts, total, out=np.zeros_like(parts), where=total > 0.0)
    with np.errstate(divide="ignore"):
        life = np.where(damage > 0.0, hours / np.where(damage > 0.0, damage, 1.0), np.inf)
    # (gear, mode, bound, n): over the T2 run and the attractors
    rate_bounds = np.stack([histories.rate_bounds[:, :, 0].min(axis=2), histories.rate_bounds[:, :, 1].max(axis=2)], 2)
    peaks = histories.peaks
    peak_bounds = np.stack([peaks[:, :, 0].min(axis=2), peaks[:, :, 1].max(axis=2)], axis=2)  # (gear, mode, bound, n)
    gbm = ("gear", "bound", "mode")
    return result.assign(
        damage=(gbm, damage, {"units": "1", "long_name": "Miner damage over the service"}),
        damage_from_rest=(gbm, rest, {"units": "1", "long_name": "Miner damage over the service, runs from rest"}),
        damage_per_hour=(gbm, damage / hours, {"units": "h-1", "long_name": "Miner damage per hour of the service"}),
        life_hours=(gbm, life, {"units": "h", "long_name": "hours of the service to a damage of 1"}),
        damage_rate=(
            ("gear", "mode", "bound", "pinion_speed"),
            rate_bounds,
            {"units": "h-1", "long_name": "Miner damage per hour at the speed, bounds over the T2 run and attractors"},
        ),
        damage_share=(
            ("gear", "mode", "service_speed"),
            share,
            {"units": "1", "long_name": "each service speed's part of the upper damage"},
        ),
        root_stress_peak=(
            ("gear", "bound", "pinion_speed"),
            peak_bounds[:, 0],
            {"units": "Pa", "long_name": "largest simulated tooth root stress, bounds over the T2 run and attractors"},
        ),
        contact_stress_peak=(
            ("gear", "bound", "pinion_speed"),
            peak_bounds[:, 1],
            {"units": "Pa", "long_name": "largest simulated flank stress, bounds over the T2 run and attractors"},
        ),
        history_adhesion_torque=(("history_torque",), histories.torques, {"units": "N m"}),
        history_attractor_count=(
            ("history_torque", "pinion_speed"),
            histories.attractor_count,
            {"units": "1", "long_name": "attractors whose histories were run"},
        ),
        damage_rate_start=(
            ("gear", "mode", "history_torque", "pinion_speed"),
            histories.worst_start,
            {"long_name": "first start of the attractor with the greatest damage rate (rest: the run from rest)"},
        ),
    ).assign_coords(service_speed=("service_speed", np.asarray(service["speeds"]), {"units": "rpm"}))


def _dataset(bounds, speeds, simulated, iso, iso_factor, safety, safety_iso, nominal, settings, service):
    minimum = {"root": settings.minimum_safety_root, "contact": settings.minimum_safety_contact}
    data = {
        "dynamic_factor_iso": (("pinion_speed",), iso_factor, {"units": "1", "long_name": "ISO 6336-1 method B K_v"}),
        "iso_speed_range": (("pinion_speed",), np.asarray(iso.speed_range(speeds), dtype=str), {"units": ""}),
        "dynamic_factor": (
            ("bound", "pinion_speed"),
            simulated,
            {"units": "1", "long_name": "simulated peak mesh force over the static mesh force"},
        ),
        "root_stress_nominal": (("gear",), np.asarray(nominal.root_stress_nominal), {"units": "Pa"}),
        "contact_stress_nominal": (("gear",), np.full(2, nominal.contact_stress_nominal), {"units": "Pa"}),
    }
    for m, mode in enumerate(MODES):
        data[f"safety_factor_{mode}"] = (
            ("gear", "bound", "pinion_speed"),
            safety[m],
            {"units": "1", "minimum": minimum[mode], "long_name": f"{mode} safety factor with the simulated load"},
        )
        data[f"safety_factor_{mode}_iso"] = (
            ("gear", "pinion_speed"),
            safety_iso[m],
            {"units": "1", "minimum": minimum[mode], "long_name": f"{mode} safety factor with ISO's K_v"},
        )
    coords = {
        "pinion_speed": ("pinion_speed", speeds, {"units": "rpm"}),
        "bound": ("bound", list(BOUNDS)),
        "gear": ("gear", list(GEARS)),
        "mode": ("mode", list(MODES)),
    }
    result = xr.Dataset({name: xr.Variable(*spec) for name, spec in data.items()}, coords=coords)
    result["peak_mesh_force"] = bounds["peak_mesh_force"].transpose("bound", "pinion_speed")
    # the interval analysis's record (method, parameters, model runs), less its own name
    attrs = {
        key: value for key, value in bounds.attrs.items() if isinstance(value, (str, int, float)) and key != "analysis"
    }
    attrs.update(
        resonance_speed_iso=float(iso.resonance_speed),
        resonance_speed_iso_units="rpm",
        minimum_safety_root=settings.minimum_safety_root,
        minimum_safety_contact=settings.minimum_safety_contact,
        service=json.dumps(service),
        rating_settings=json.dumps(dataclasses.asdict(settings)),
    )
    result.attrs.update(attrs)
    return result


__all__ = ["rating_analysis", "RATING_SERVICE"]
