"""The foreign rig's own modes and the bearing check planned on them: closed forms, the equations of motion
assembled row by row, and the rig's own simulation entering a bearing clearance where the plan says."""

import math

import numpy as np
import pytest

from uqgear.common.errors import OperatingPointError
from uqgear.physics.design import load_design
from uqgear.physics.effects import make_effect
from uqgear.rig.foreign_modes import BEARING_CHECK_DRIVE_TORQUE, SPRINGS, bearing_check_plan, natural_modes
from uqgear.rig.foreign_rig import CONTROLLER_BANDWIDTH, draw_gears, plant_parameters, simulate_foreign_run
from uqgear.rig.virtual_rig import BEARING_CHECK_SPEED_FACTORS, bearing_check_operating_points

DESIGN = load_design("locomotive")  # 21:101 teeth


def _equations_of_motion(plant):
    """Stiffness and mass matrices written row by row from the foreign rig's equations of motion (motor, pinion,
    gear, load angles; pinion and gear centres; their housings), the mesh force F = k (rb1 t1 - rb2 t2 - xa + xb)."""
    p = plant
    km, rb1, rb2 = p["k_mean"], p["rb1"], p["rb2"]
    mesh = np.array([0.0, rb1, -rb2, 0.0, -1.0, 1.0, 0.0, 0.0])  # d F / d state, over km
    k = np.zeros((8, 8))
    k[0, [0, 1]] = (p["kc"] + p["ks1"], -p["ks1"])
    k[1, [0, 1]] = (-p["ks1"], p["ks1"])
    k[1] += rb1 * km * mesh
    k[2, [2, 3]] = (p["ks2"], -p["ks2"])
    k[2] -= rb2 * km * mesh
    k[3, [2, 3]] = (-p["ks2"], p["ks2"])
    k[4, [4, 6]] = (p["kb1"], -p["kb1"])
    k[4] -= km * mesh
    k[5, [5, 7]] = (p["kb2"], -p["kb2"])
    k[5] += km * mesh
    k[6, [4, 6]] = (-p["kb1"], p["kb1"] + p["kh1"])
    k[7, [5, 7]] = (-p["kb2"], p["kb2"] + p["kh2"])
    mass = np.diag([p[name] for name in ("jm", "j1", "j2", "jl", "ma", "mb", "mh1", "mh2")])
    return k, mass


def test_the_modes_solve_the_equations_of_motion_and_the_slowest_is_the_speed_controller():
    modes = natural_modes(DESIGN)
    stiffness, mass = _equations_of_motion(plant_parameters(DESIGN))
    np.testing.assert_allclose(stiffness, stiffness.T, rtol=1e-12, atol=1e-3 * np.abs(stiffness).max())
    omega2 = (2 * math.pi * modes.frequencies) ** 2
    # K phi = w^2 M phi for every mode, the shapes mass-normalised
    residual = stiffness @ modes.shapes - mass @ modes.shapes * omega2
    assert np.abs(residual).max() < 1e-8 * np.abs(stiffness @ modes.shapes).max()
    np.testing.assert_allclose(modes.shapes.T @ mass @ modes.shapes, np.eye(8), atol=1e-9)
    np.testing.assert_allclose(modes.energy_shares.sum(axis=0), 1.0, rtol=1e-12)
    # the drive train turning as one body on the controller's spring: sqrt(kc / J) = the controller's bandwidth
    assert modes.frequencies[0] == pytest.approx(CONTROLLER_BANDWIDTH, rel=0.02)
    assert modes.energy_shares[SPRINGS.index("controller"), 0] > 0.95


def test_the_bearing_check_runs_the_mesh_fundamental_through_the_rigs_own_bearing_modes():
    modes = natural_modes(DESIGN)
    bearing = modes.bearing_frequencies(2)
    shares = modes.bearing_shares[np.searchsorted(modes.frequencies, bearing)]
    assert np.all(shares >= 0.5) and bearing[0] < bearing[1]
    # every slower mode is not bearing-dominated
    assert np.all(modes.bearing_shares[modes.frequencies < bearing[0]] < 0.5)
    plan = bearing_check_plan(DESIGN)
    mesh = plan["pinion_speed"].values * DESIGN.z1 / 60.0
    factors = np.concatenate([mesh[:4] / bearing[0], mesh[4:] / bearing[1]])
    np.testing.assert_allclose(factors, np.concatenate(BEARING_CHECK_SPEED_FACTORS), atol=0.02)
    assert np.all(plan["drive_torque"].values == BEARING_CHECK_DRIVE_TORQUE)
    with pytest.raises(OperatingPointError, match="mode_frequencies"):
        bearing_check_operating_points(DESIGN, mode_frequencies=[300.0])


@pytest.mark.parametrize("speed, torque, entered", [
    (970.0, BEARING_CHECK_DRIVE_TORQUE, True),    # the mesh fundamental on the second bearing mode, light load
    (970.0, 1500.0, False),                       # the 3-DOF model's bearing-check load keeps them loaded
    (1250.0, 6000.0, False),                      # a service run
])
def test_a_clearance_is_entered_on_the_rigs_own_bearing_check_and_never_in_service(speed, torque, entered):
    clearance = 50e-6
    effect = make_effect("bearing_clearance", {"bearing": "both", "clearance": clearance})
    run = simulate_foreign_run(DESIGN, speed, torque, torque * DESIGN.z2 / DESIGN.z1, gears=draw_gears(DESIGN, 6, 1),
                               effects=[effect], duration=0.1, start=0.25, bearings=True)
    for name in ("bearing_pinion", "bearing_gear"):
        deflection = run[name]
        # loaded, each bearing sits a clearance plus its static deflection off centre
        static = torque / plant_parameters(DESIGN)["rb1"] / plant_parameters(DESIGN)[
            "kb1" if name == "bearing_pinion" else "kb2"]
        assert abs(np.median(deflection)) == pytest.approx(clearance + static, rel=0.5)
        assert bool(np.any(np.abs(deflection) < clearance)) is entered
