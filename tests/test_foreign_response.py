"""The foreign rig's own mesh-force QoIs (uqgear.rig.foreign_response) against closed forms of its physics."""

import math

import numpy as np
import pytest

from uqgear.common.errors import OperatingPointError
from uqgear.physics.design import load_design
from uqgear.rig.foreign_response import FOREIGN_QOI_INFO, foreign_qois
from uqgear.rig.foreign_rig import (
    PAIR_ENTRY_SHARE,
    PAIR_STIFFNESS_PER_WIDTH,
    ForeignGears,
    contact_ratio,
    draw_gears,
    plant_parameters,
)

DESIGN = load_design("locomotive")  # 21:101 teeth
ERROR_FREE = ForeignGears(np.zeros((DESIGN.z1, 3)), np.zeros((DESIGN.z2, 3)))
T1 = 6000.0
BALANCE = T1 * DESIGN.z2 / DESIGN.z1


def _mesh_stiffness(phase):
    """Total mesh stiffness at mesh phases in [0, 1): every pair in contact, its half-sine law written out."""
    eps = contact_ratio(DESIGN)
    peak = PAIR_STIFFNESS_PER_WIDTH * DESIGN.face_width
    total = np.zeros_like(phase)
    for older in range(3):
        s = phase + older
        total += np.where(s < eps, peak * (PAIR_ENTRY_SHARE + (1 - PAIR_ENTRY_SHARE) * np.sin(np.pi * s / eps)), 0.0)
    return total


def test_at_a_crawl_the_error_free_mesh_carries_the_static_force_with_its_stiffness_steps():
    """Quasi-static, error-free gears: the mean force is T1 / r_b1 (= T2 / r_b2 at the balance); the approach is
    F / K(t); and the peak is the jump of the force when a pair enters at 55 % of its stiffness while the approach
    has not yet moved, F K(entry+) / K(entry-)."""
    qois = foreign_qois(DESIGN, 20.0, T1, BALANCE, gears=ERROR_FREE, duration=0.3)
    plant = plant_parameters(DESIGN)
    static = T1 / plant["rb1"]
    assert float(qois["static_mesh_force"][0]) == pytest.approx(static, rel=1e-12)
    assert float(qois["mesh_force_mean"][0]) == pytest.approx(static, rel=1e-3)
    phase = np.linspace(0.0, 1.0, 100_001)[:-1]
    assert float(qois["dte_rms"][0]) == pytest.approx(np.std(static / _mesh_stiffness(phase)), rel=0.02)
    before, after = _mesh_stiffness(np.array([1.0 - 1e-9])), _mesh_stiffness(np.array([0.0]))
    jump = float(after[0] / before[0])
    assert jump > 1.5  # the foreign pair law's load step, which the 3-DOF model's Ishikawa stiffness does not have
    assert float(qois["dynamic_load_factor"][0]) == pytest.approx(jump, rel=0.005)
    assert float(qois["peak_mesh_force"][0]) == pytest.approx(jump * static, rel=0.005)


def test_in_service_the_gear_carries_the_wheel_torque_whatever_the_drive_torque():
    """The speed controller holds the motor's speed: in a steady state the mean mesh force is T2 / r_b2 also when
    T2 is not at the balance of T1; the profile errors and the speed make the peak larger."""
    gears = draw_gears(DESIGN, 6.0, 0)
    plant = plant_parameters(DESIGN)
    loads = np.array([0.9, 1.1]) * BALANCE
    qois = foreign_qois(DESIGN, [2000.0, 2000.0], T1, loads, gears=gears, duration=0.3)
    np.testing.assert_allclose(qois["static_mesh_force"].values, loads / plant["rb2"], rtol=1e-12)
    np.testing.assert_allclose(qois["mesh_force_mean"].values, loads / plant["rb2"], rtol=2e-3)
    assert np.all(qois["peak_mesh_force"].values > qois["mesh_force_mean"].values)
    np.testing.assert_allclose(qois["dynamic_load_factor"].values,
                               qois["peak_mesh_force"].values / qois["static_mesh_force"].values, rtol=1e-12)
    assert set(qois.data_vars) == set(FOREIGN_QOI_INFO) and qois["peak_mesh_force"].attrs["units"] == "N"
    assert qois["pinion_speed"].values.tolist() == [2000.0, 2000.0]


@pytest.mark.parametrize(
    ("arguments", "key"),
    [
        ((-1.0, T1, BALANCE), "pinion_speed"),
        ((1000.0, math.nan, BALANCE), "drive_torque"),
        (([1000.0, 2000.0], [T1, T1, T1], BALANCE), "equal lengths"),
    ],
)
def test_a_wrong_operating_point_is_refused_naming_it(arguments, key):
    with pytest.raises(OperatingPointError, match=key):
        foreign_qois(DESIGN, *arguments, gears=ERROR_FREE)
    with pytest.raises(OperatingPointError, match="duration"):
        foreign_qois(DESIGN, 1000.0, T1, BALANCE, gears=ERROR_FREE, duration=0.0)
