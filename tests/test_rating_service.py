"""A rating's service: speed distributions, missions, kilometres, the rail condition and the bundled profile."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uqgear.common.errors import StudyError
from uqgear.study.rating_service import check_service, service_damage


def test_kilometres_become_hours_at_the_vehicle_speed():
    # 2000 pinion rpm through 101/21 on a 0.625 m wheel: v = 2 pi 2000 / 60 / (101/21) * 0.625 m/s
    speed = 2.0 * math.pi * 2000.0 / 60.0 / (101.0 / 21.0) * 0.625 * 3.6  # km/h
    service = check_service(
        {"kilometres": 1.0e6, "speeds": [2000], "shares": [1.0], "wheel_radius": 0.625, "gear_ratio": 101 / 21},
        "service",
    )
    assert service["hours"] == pytest.approx(1.0e6 / speed, rel=1e-12)
    mission = check_service(
        {
            "mission": [{"pinion_speed": 2000, "kilometres": 1.0e5}, {"pinion_speed": 1000, "hours": 100}],
            "wheel_radius": 0.625,
            "gear_ratio": 101 / 21,
        },
        "service",
    )
    hours = [1.0e5 / speed, 100.0]
    assert mission["hours"] == pytest.approx(sum(hours))
    assert mission["shares"] == pytest.approx([h / sum(hours) for h in hours])


def test_the_bundled_profile_is_a_20000_hour_mission_over_the_adhesion_range():
    service = check_service("locomotive", "service")
    assert service["hours"] == pytest.approx(20000.0)
    assert sum(service["shares"]) == pytest.approx(1.0)
    assert service["rail"] == {"kind": "interval", "adhesion_coefficient": [0.15, 0.33]}
    assert "illustrative" in service["description"]


@pytest.mark.parametrize(
    "value, message",
    [
        ({"hours": 10, "speeds": [1000, 2000], "shares": [0.5, 0.6]}, "service.shares: expected time shares"),
        ({"hours": 10, "speeds": [1000, 2000], "shares": [-0.5, 1.5]}, "service.shares[0]: expected a number"),
        ({"hours": 10, "speeds": [1000], "shares": [1], "speed": 3}, "service.speed: unknown key"),
        ({"speeds": [1000], "shares": [1]}, "service.hours: expected the service's duration"),
        ({"mission": [{"pinion_speed": 1000}]}, "service.mission[0]: expected one duration"),
        ({"hours": 5, "mission": [{"pinion_speed": 1000, "hours": 4}]}, "service.hours: the mission sums to 4 h"),
        (
            {"hours": 1, "speeds": [1000], "shares": [1], "rail": {"adhesion_coefficient": [0.3, 0.2]}},
            "service.rail.adhesion_coefficient: expected an interval",
        ),
        (
            {
                "hours": 1,
                "speeds": [1000],
                "shares": [1],
                "rail": {"adhesion_coefficient": [0.2, 0.3], "shares": [1, 1]},
            },
            "service.rail.shares: expected time shares that sum to 1",
        ),
    ],
)
def test_bad_services_name_their_key(value, message):
    with pytest.raises(StudyError) as error:
        check_service(value, "service")
    assert str(error.value).startswith(message)


def test_a_rail_distribution_weights_the_rates_and_an_interval_bounds_them():
    speeds, torques = np.array([1000.0, 2000.0]), np.array([20e3, 30e3, 40e3])
    rates = np.array([[1.0, 2.0], [4.0, 1.0], [2.0, 3.0]])  # (torque, speed)
    base = {"hours": 100.0, "speeds": [1000.0, 1500.0], "shares": [0.4, 0.6]}
    arm = 23000.0 * 9.80665 * 0.625
    # an interval from the first torque to halfway between the second and third
    interval = {**base, "rail": {"kind": "interval", "adhesion_coefficient": [20e3 / arm, 35e3 / arm]}}
    damage, parts = service_damage(interval, speeds, torques, rates)
    at_1500 = rates.mean(axis=1)  # halfway between the sweep speeds
    end = 0.5 * (rates[1] + rates[2])  # T2 = 35e3: halfway between the second and third torques
    lowest = [min(rates[0, 0], rates[1, 0], end[0]), min(at_1500[0], at_1500[1], end.mean())]
    highest = [max(rates[0, 0], rates[1, 0], end[0]), max(at_1500[0], at_1500[1], end.mean())]
    assert damage.tolist() == pytest.approx([100.0 * np.dot([0.4, 0.6], lowest), 100.0 * np.dot([0.4, 0.6], highest)])
    assert parts.tolist() == pytest.approx([40.0 * highest[0], 60.0 * highest[1]])
    mixed = {
        **base,
        "rail": {"kind": "distribution", "adhesion_coefficient": [20e3 / arm, 40e3 / arm], "shares": [0.25, 0.75]},
    }
    damage, _ = service_damage(mixed, speeds, torques, rates)
    mean = 0.25 * np.array([rates[0, 0], rates[0].mean()]) + 0.75 * np.array([rates[2, 0], rates[2].mean()])
    assert damage.tolist() == pytest.approx([100.0 * np.dot([0.4, 0.6], mean)] * 2)
