"""The service a ``rating`` analysis sums fatigue damage over: speeds, time and rail condition.

A study's ``service`` is a bundled profile's name (:data:`PROFILES`, files in
``uqgear/data/services``) or a mapping:

- a speed distribution, ``speeds`` (pinion rpm) with their ``shares`` of the
  time (non-negative, summing to 1), over ``hours``, or over ``kilometres``
  travelled (converted to hours with ``wheel_radius`` and ``gear_ratio``: the
  vehicle speed at pinion speed n is ``2 pi n / 60 / gear_ratio * wheel_radius``);
- or a speed-time ``mission``: segments ``{pinion_speed, hours}`` or
  ``{pinion_speed, kilometres}``, whose durations sum to the service
  (``hours``, if also given, must equal that sum);
- ``rail``: the rail condition as an interval of the adhesion coefficient
  (``adhesion_coefficient: [lower, upper]``) or a distribution over it
  (``adhesion_coefficient`` values with their ``shares`` of the time); by
  default the study's whole adhesion interval. ``axle_load`` and
  ``wheel_radius`` turn mu into T2 = mu Q g R_w as the study's adhesion
  torque does (defaults: 23 t, 0.625 m).

:func:`check_service` validates one and returns its normal form (hours, speeds,
shares, rail); :func:`service_damage` sums damage rates over it.
"""

from __future__ import annotations

import math
from importlib import resources
from typing import Any

import numpy as np
import yaml

from ..common.errors import StudyError, shown
from .checkers import check_mapping, list_of, number

#: Bundled illustrative service profiles (``uqgear/data/services/NAME.yaml``).
PROFILES = ("locomotive",)
#: Axle load (kg) and wheel radius (m) of the rail condition's mu -> T2 where a service states none.
DEFAULT_AXLE_LOAD, DEFAULT_WHEEL_RADIUS = 23000.0, 0.625
_SPEED = number("rpm", 0.0, 1e5, lower_open=True)
_DURATION = {"hours": number("h", 0.0, 1e7, lower_open=True), "kilometres": number("km", 0.0, 1e9, lower_open=True)}


def _profile(name: str, path: str) -> dict[str, Any]:
    if name not in PROFILES:
        raise StudyError(
            f"{path}: expected a service mapping or a bundled profile ({', '.join(PROFILES)}); got {name!r}"
        )
    text = resources.files("uqgear").joinpath("data", "services", f"{name}.yaml").read_text()
    return dict(yaml.safe_load(text))


def _vehicle_speed(checked: dict[str, Any], path: str, key: str) -> float:
    """km/h per pinion rpm."""
    for needed in ("wheel_radius", "gear_ratio"):
        if needed not in checked:
            raise StudyError(f"{path}.{needed}: required to convert {key} to hours")
    return 2.0 * math.pi / 60.0 / checked["gear_ratio"] * checked["wheel_radius"] * 3.6


def _mission(segments: list, checked: dict[str, Any], path: str) -> tuple[list[float], list[float]]:
    speeds, hours = [], []
    for k, raw in enumerate(segments):
        where = f"{path}.mission[{k}]"
        segment = check_mapping(raw, where, {"pinion_speed": _SPEED, **_DURATION}, required=("pinion_speed",))
        given = [key for key in _DURATION if key in segment]
        if len(given) != 1:
            raise StudyError(f"{where}: expected one duration, hours or kilometres; got {', '.join(given) or 'none'}")
        duration = segment[given[0]]
        if given[0] == "kilometres":
            duration /= _vehicle_speed(checked, path, f"{where}.kilometres") * segment["pinion_speed"]
        speeds.append(segment["pinion_speed"])
        hours.append(duration)
    return speeds, hours


def _rail(raw: Any, path: str) -> dict[str, Any]:
    rail = check_mapping(
        raw,
        path,
        {
            "adhesion_coefficient": list_of(number("", 0.0, 1.5), what="a list of adhesion coefficients"),
            "shares": list_of(number("", 0.0, 1.0), what="a list of time shares"),
        },
        required=("adhesion_coefficient",),
    )
    mu = rail["adhesion_coefficient"]
    if "shares" not in rail:
        if len(mu) != 2 or not mu[0] <= mu[1]:
            raise StudyError(f"{path}.adhesion_coefficient: expected an interval [lower, upper]; got {shown(mu)}")
        return {"kind": "interval", "adhesion_coefficient": list(mu)}
    if len(rail["shares"]) != len(mu):
        raise StudyError(
            f"{path}.shares: expected one share per adhesion coefficient ({len(mu)}); got {len(rail['shares'])}"
        )
    if abs(sum(rail["shares"]) - 1.0) > 1e-6:
        raise StudyError(f"{path}.shares: expected time shares that sum to 1; got a sum of {sum(rail['shares']):g}")
    return {"kind": "distribution", "adhesion_coefficient": list(mu), "shares": list(rail["shares"])}


def check_service(value: Any, path: str) -> dict[str, Any]:
    """Validate a ``service`` and return its normal form: hours, speeds, shares, rail (and what was given).

    Examples
    --------
    >>> from uqgear.study.rating_service import check_service
    >>> service = check_service({"mission": [{"pinion_speed": 1000, "hours": 300},
    ...                                      {"pinion_speed": 3000, "hours": 100}]}, "service")
    >>> service["hours"], service["speeds"], service["shares"]
    (400.0, [1000.0, 3000.0], [0.75, 0.25])
    >>> try:
    ...     check_service({"hours": 100, "speeds": [1000], "shares": [0.5]}, "service")
    ... except ValueError as error:
    ...     print(error)
    service.shares: expected time shares that sum to 1 (the whole service); got a sum of 0.5
    """
    if isinstance(value, str):
        return {**check_service(_profile(value, path), path), "profile": value}
    checked = check_mapping(
        value,
        path,
        {
            **_DURATION,
            "speeds": list_of(_SPEED, what="a list of pinion speeds in rpm"),
            "shares": list_of(number("", 0.0, 1.0), what="a list of time shares"),
            "mission": list_of(lambda raw, where: raw, what="a list of {pinion_speed, hours or kilometres}"),
            "rail": lambda raw, where: _rail(raw, where),
            "wheel_radius": number("m", 0.2, 1.5),
            "gear_ratio": number("", 1.0, 20.0),
            "axle_load": number("kg", 1000.0, 100_000.0),
            "description": lambda raw, where: str(raw),
        },
    )
    if "mission" in checked:
        for key in ("speeds", "shares", "kilometres"):
            if key in checked:
                raise StudyError(f"{path}.{key}: a mission states its own speeds and durations; expected no {key}")
        speeds, hours = _mission(checked["mission"], checked, path)
        total = sum(hours)
        if "hours" in checked and abs(checked["hours"] - total) > 1e-6 * total:
            raise StudyError(f"{path}.hours: the mission sums to {total:g} h; got {checked['hours']:g}")
        shares = [h / total for h in hours]
    else:
        for key in ("speeds", "shares"):
            if key not in checked:
                raise StudyError(f"{path}.{key}: required (or a mission)")
        speeds, shares = checked["speeds"], checked["shares"]
        if len(speeds) != len(shares):
            raise StudyError(f"{path}.shares: expected one share per speed ({len(speeds)}); got {len(shares)}")
        if abs(sum(shares) - 1.0) > 1e-6:
            raise StudyError(
                f"{path}.shares: expected time shares that sum to 1 (the whole service); got a sum of {sum(shares):g}"
            )
        if ("hours" in checked) == ("kilometres" in checked):
            raise StudyError(f"{path}.hours: expected the service's duration, hours or kilometres (one of them)")
        total = checked.get("hours", 0.0)
        if "kilometres" in checked:
            mean = _vehicle_speed(checked, path, "kilometres") * sum(n * s for n, s in zip(speeds, shares))
            total = checked["kilometres"] / mean
    normal: dict[str, Any] = {
        "hours": float(total),
        "speeds": [float(n) for n in speeds],
        "shares": [float(s) for s in shares],
    }
    for key in ("rail", "description", "kilometres", "wheel_radius", "gear_ratio", "axle_load"):
        if key in checked:
            normal[key] = checked[key]
    return normal


def rail_torques(service: dict[str, Any]) -> tuple[str, np.ndarray, np.ndarray] | None:
    """The rail condition as (kind, T2 values in N m, shares); None for the study's whole adhesion interval."""
    rail = service.get("rail")
    if not rail:
        return None
    arm = service.get("axle_load", DEFAULT_AXLE_LOAD) * 9.80665 * service.get("wheel_radius", DEFAULT_WHEEL_RADIUS)
    torques = np.asarray(rail["adhesion_coefficient"], dtype=float) * arm
    shares = np.asarray(rail.get("shares", [0.5, 0.5]), dtype=float)
    return rail["kind"], torques, shares


def service_damage(
    service: dict[str, Any], speeds: np.ndarray, torques: np.ndarray, rates: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Damage over a service from damage rates at sweep speeds and adhesion torques.

    Parameters
    ----------
    service : dict
        :func:`check_service`'s normal form.
    speeds : ndarray
        The sweep's pinion speeds, rpm, increasing (the service's lie among them).
    torques : ndarray
        Adhesion torques T2 of the rates, N m, increasing.
    rates : ndarray
        (..., torque, speed) damage per hour.

    Returns
    -------
    damage : ndarray
        (..., bound) damage over the service, lower and upper over the rail condition (equal for a
        distribution, whose damage is its time-weighted mean).
    contribution : ndarray
        (..., service speed) each service speed's part of the upper damage.

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.study.rating_service import service_damage
    >>> service = {"hours": 10.0, "speeds": [1000.0, 2000.0], "shares": [0.5, 0.5]}
    >>> rates = np.array([[1.0, 3.0], [2.0, 5.0]])           # (torque, speed) per hour
    >>> damage, parts = service_damage(service, np.array([1000.0, 2000.0]), np.array([1e4, 2e4]), rates)
    >>> damage.tolist(), parts.tolist()
    ([20.0, 35.0], [10.0, 25.0])
    """
    rates = np.asarray(rates, dtype=float)
    lead = rates.shape[:-2]
    flat = rates.reshape(-1, torques.size, speeds.size)
    at_speed = np.stack([[np.interp(n, speeds, row) for n in service["speeds"]] for rows in flat for row in rows])
    at_speed = at_speed.reshape(flat.shape[0], torques.size, len(service["speeds"]))
    rail = rail_torques(service)
    if rail is None or rail[0] == "interval":
        low, high = (torques[0], torques[-1]) if rail is None else (rail[1][0], rail[1][-1])
        inside = (torques >= low) & (torques <= high)
        ends = np.stack([_interp_torque(at_speed, torques, t) for t in (low, high)], axis=1)
        candidates = np.concatenate([at_speed[:, inside], ends], axis=1)
        per_speed = np.stack([candidates.min(axis=1), candidates.max(axis=1)], axis=1)
    else:
        mean = sum(share * _interp_torque(at_speed, torques, t) for t, share in zip(rail[1], rail[2]))
        per_speed = np.stack([mean, mean], axis=1)
    weights = service["hours"] * np.asarray(service["shares"])
    parts = per_speed * weights  # (n, bound, service speed)
    damage = parts.sum(axis=2)
    return damage.reshape(*lead, 2), parts[:, 1].reshape(*lead, len(service["speeds"]))


def _interp_torque(at_speed: np.ndarray, torques: np.ndarray, torque: float) -> np.ndarray:
    """(n, service speed) rates at one adhesion torque, linear between the torques run."""
    if torques.size == 1:
        return at_speed[:, 0]
    j = int(np.clip(np.searchsorted(torques, torque) - 1, 0, torques.size - 2))
    w = (torque - torques[j]) / (torques[j + 1] - torques[j])
    return at_speed[:, j] * (1.0 - w) + at_speed[:, j + 1] * w


__all__ = ["PROFILES", "check_service", "rail_torques", "service_damage"]
