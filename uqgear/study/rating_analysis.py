"""The ``rating`` analysis: ISO 6336 safety factors and fatigue damage from the simulated dynamic load.

The interval machinery bounds the peak mesh force over the interval parameters (T2 by default)
at every pinion speed of the sweep, taking the worst over attractors where the study's
``simulation.starts`` asks for it (:func:`~uqgear.study.analyses.interval_analysis`). The
simulated dynamic factor is that peak over the static mesh force at the study's drive torque;
it takes the place of ISO's K_v in :func:`~uqgear.physics.rating.static_rating`, whose safety
factors S_F and S_H per gear follow at each bound (the lower safety factor from the upper
dynamic factor). ISO 6336-1 method B's K_v and its safety factors sit beside them.

Fatigue damage over the ``service`` (hours, pinion speeds and their shares of the time):
each tooth carries one pulsating load cycle per revolution, from zero to the peak stress
at the dynamic factor of that speed (interpolated in the sweep), so its rainflow count is
that one cycle per revolution; Miner's rule on the S-N curves of the life factors sums it
(:func:`~uqgear.dynamics.fatigue.miner_damage`). Oscillations of the load within one tooth's
mesh are not counted here. Without ``service`` the illustrative :data:`RATING_SERVICE`
applies: 20,000 h spread evenly over the sweep's speeds inside the design's service range.
"""

from __future__ import annotations

import dataclasses
import json
from typing import Any

import numpy as np
import xarray as xr

from ..dynamics.fatigue import RainflowCount, miner_damage
from ..physics.geometry import pair_geometry
from ..physics.rating import RatingSettings, dynamic_factor_model, static_rating
from .analyses import AnalysisContext, interval_analysis, register

#: Illustrative service when a rating states none: hours, spread evenly over the service speeds.
RATING_SERVICE = {"hours": 20000.0, "description": "illustrative: 20,000 h, evenly over the service speeds"}
GEARS, BOUNDS, MODES = ("pinion", "gear"), ("lower", "upper"), ("root", "contact")


def _service(context: AnalysisContext, speeds: np.ndarray) -> dict[str, Any]:
    given = context.options.get("service")
    if given:
        return dict(given)
    low, high = context.design.operation.pinion_speed_service
    inside = [float(speed) for speed in speeds if low <= speed <= high] or [float(speeds[0])]
    return {**RATING_SERVICE, "speeds": inside, "shares": [1.0 / len(inside)] * len(inside)}


def _damage(design, torque: float, settings: RatingSettings, service, factor_at) -> np.ndarray:
    """Miner damage (gear, mode) over the service, one pulsating cycle per tooth and revolution."""
    u = design.z2 / design.z1
    damage = np.zeros((2, 2))
    for speed, share in zip(service["speeds"], service["shares"]):
        rating = static_rating(design, torque, speed, settings, dynamic_factor=float(factor_at(speed)))
        pinion_cycles = service["hours"] * share * 60.0 * speed
        for g, cycles in enumerate((pinion_cycles, pinion_cycles / u)):
            for m, (stress, curve) in enumerate(
                ((rating.root_stress[g], rating.root_curve[g]), (rating.contact_stress[g], rating.contact_curve[g]))
            ):
                count = RainflowCount(
                    ranges=np.array([stress]), means=np.array([0.5 * stress]), counts=np.array([cycles])
                )
                damage[g, m] += miner_damage(count, curve)
    return damage


@register("rating")
def rating_analysis(context: AnalysisContext) -> xr.Dataset:
    """ISO 6336 safety factors per gear against speed, bounded over the interval parameters, and damage."""
    settings = RatingSettings.from_mapping(context.options.get("rating"))
    options = {**context.options, "qois": ("peak_mesh_force",)}
    interval_context = dataclasses.replace(context, spec=dataclasses.replace(context.spec, options=options))
    bounds = interval_analysis(interval_context)
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
    damage = np.stack(
        [_damage(design, torque, settings, service, lambda n, row=row: np.interp(n, speeds, row)) for row in simulated],
        axis=1,
    )  # (gear, bound, mode)
    return _dataset(bounds, speeds, simulated, iso, iso_factor, safety, safety_iso, nominal, damage, settings, service)


def _dataset(bounds, speeds, simulated, iso, iso_factor, safety, safety_iso, nominal, damage, settings, service):
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
        "damage": (("gear", "bound", "mode"), damage, {"units": "1", "long_name": "Miner damage over the service"}),
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
