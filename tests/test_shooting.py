"""Shooting and Floquet multipliers against independent truth.

* the linear constant-stiffness limit: the monodromy is the matrix exponential of the system matrix
  over one mesh period, and the orbit is the closed-form harmonic response;
* a piecewise-linear single-degree-of-freedom oscillator with clearance, solved here with scipy
  (events at the clearance, tight tolerances) and its monodromy by finite differences, with
  the mesh damping on and off in separation (continuous vector field, and a jump that needs a
  saltation matrix);
* the gear model itself: the monodromy against central finite differences of the same map
  across contact crossings and Ishikawa stiffness jumps, and the flow's monodromy (saltation
  form) against finite differences of the scipy reference integrator.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import uqgear
from uqgear.common.errors import OperatingPointError
from uqgear.dynamics.floquet import (
    FOLD,
    NEIMARK_SACKER,
    PERIOD_DOUBLING,
    UnstableCounts,
    crossing_types,
    floquet_multipliers,
    unstable_counts,
)
from uqgear.dynamics.shooting import PoincareMap, Shooting, ShootingError, ShootingSettings, newton_orbit, setup_at
from uqgear.physics import _kernels as K
from uqgear.physics.integration import STATE_NAMES


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


def _system_matrix(setup) -> np.ndarray:
    """d(state)/dt = A state + forcing, in contact with constant mesh stiffness (docs/model/equations.md section 2)."""
    p = setup.parameters
    k = setup.derived["k_mean"] * p[K.STIFFNESS_SCALE]
    m1, m2, me, c = p[K.M1], p[K.M2], p[K.ME], p[K.CM]
    a = np.zeros((6, 6))
    a[0, 3] = a[1, 4] = a[2, 5] = 1.0
    # m1 y1'' = -c1 y1' - k1 y1 - F,  m2 y2'' = -c2 y2' - k2 y2 + F,  F = k (x - b) + c x'
    a[3] = [-p[K.K1] / m1, 0, -k / m1, -p[K.C1] / m1, 0, -c / m1]
    a[4] = [0, -p[K.K2] / m2, k / m2, 0, -p[K.C2] / m2, c / m2]
    # x'' = y1'' - y2'' - F / m_e + ...
    a[5] = a[3] - a[4] - np.array([0, 0, k / me, 0, 0, c / me])
    return a


def test_linear_limit_monodromy_is_the_matrix_exponential_and_the_orbit_the_harmonic_response(design):
    setup = setup_at(design, {"pinion_speed": 1500.0}, stiffness="constant")
    a = _system_matrix(setup)
    exact = expm(a * (1.0 / setup.mesh_frequency))
    scale = setup.state_scale()
    scaled = lambda m: m * scale[None, :] / scale[:, None]  # noqa: E731
    errors = []
    for steps_per_mode in (48, 96):
        orbit = newton_orbit(PoincareMap(setup, steps_per_mode=steps_per_mode), setup.static_state(), 1,
                             ShootingSettings())
        assert orbit is not None and orbit.qois["fraction_separation"] == 0.0
        errors.append(np.linalg.norm(scaled(orbit.monodromy - exact)) / np.linalg.norm(scaled(exact)))
    # RK4's monodromy converges to exp(A T) at fourth order
    assert errors[1] < 1e-6 and 12.0 < errors[0] / errors[1] < 20.0
    np.testing.assert_allclose(np.sort(np.abs(orbit.multipliers)), np.sort(np.abs(np.linalg.eigvals(exact))),
                               atol=1e-6)
    # steady response: the static state plus Im(Z e^{i w t}), (i w - A) Z = e_r w^2 on the x' row (-e'')
    omega = 2 * math.pi * setup.mesh_frequency
    forcing = np.zeros(6, dtype=complex)
    forcing[5] = design.ste_amplitude * omega ** 2
    z = np.linalg.solve(1j * omega * np.eye(6) - a, forcing)
    expected = setup.static_state() + z.imag
    np.testing.assert_allclose(orbit.state / scale, expected / scale, atol=1e-6)
    assert orbit.stable


def _locked_bearings(setup) -> None:
    """Bearings so heavy and stiff (critically damped) that y1, y2 stay at 1e-10 of x: a 1-DOF mesh."""
    p = setup.parameters
    for mass, stiffness, damping in ((K.M1, K.K1, K.C1), (K.M2, K.K2, K.C2)):
        p[mass], p[stiffness] = 1e12, 1e21
        p[damping] = 2.0 * math.sqrt(p[mass] * p[stiffness])


def _oscillator_map(setup, damping_in_separation: bool):
    """The 1-DOF clearance oscillator m_e x'' + c x' + k f(x) = F_T - m_e e''(t) over one mesh period, by scipy."""
    p = setup.parameters
    me, k, c, b = p[K.ME], setup.derived["k_mean"], p[K.CM], p[K.HALF_BACKLASH]
    force_t = setup.derived["static_mesh_force"]
    omega, amplitude = p[K.OMEGA_MESH], p[K.STE_AMPLITUDE]
    period = 2 * math.pi / omega

    def rhs(t, y):
        x, v = y
        fx = x - b if x > b else (x + b if x < -b else 0.0)
        damping = c if (damping_in_separation or fx != 0.0) else 0.0
        return [v, (force_t - k * fx - damping * v) / me + amplitude * omega ** 2 * math.sin(omega * t)]

    def boundary(level):
        event = lambda t, y: y[0] - level  # noqa: E731
        event.terminal = True
        return event

    def advance(y):
        t, y = 0.0, np.array(y, dtype=float)
        while t < period:
            sol = solve_ivp(rhs, (t, period), y, method="DOP853", rtol=1e-12, atol=1e-16,
                            events=[boundary(b), boundary(-b)])
            t, y = sol.t[-1], sol.y[:, -1]
            if sol.status == 1:
                # step off the boundary along the flow so the event does not fire again at once
                t_next = min(t + 1e-12 * period, period)
                y = y + (t_next - t) * np.array(rhs(t, y))
                t = t_next
        return y

    return advance


# With the damping switched off in separation the vector field jumps at the clearance; the fast
# integrator's split step takes each side's damping, so its orbit converges as fast as with the
# continuous field, and the flow's multipliers need the saltation matrix.
@pytest.mark.parametrize("damping_in_separation, orbit_tolerance, multiplier_tolerance",
                         [(True, 1e-7, 2e-5), (False, 1e-7, 2e-5)])
def test_clearance_oscillator_orbit_and_multipliers_match_an_independent_scipy_solution(
        design, damping_in_separation, orbit_tolerance, multiplier_tolerance):
    setup = setup_at(design, {"pinion_speed": 2000.0}, stiffness="constant",
                     damping_in_separation=damping_in_separation)
    _locked_bearings(setup)
    mapping = PoincareMap(setup, steps=400, discrete=False)
    guess = setup.static_state()
    guess[:2] = 0.0
    guess = mapping(guess, 300, with_matrix=False).state
    orbit = newton_orbit(mapping, guess, 1, ShootingSettings())
    assert orbit is not None
    assert 0.05 < orbit.qois["fraction_separation"] < 0.95   # the teeth separate every period
    assert abs(orbit.state[0]) < 1e-12 and abs(orbit.state[1]) < 1e-12
    advance = _oscillator_map(setup, damping_in_separation)
    y = orbit.state[[2, 5]].copy()
    for _ in range(3):       # Newton on the scipy map with a finite-difference Jacobian
        end = advance(y)
        scale = np.array([setup.parameters[K.HALF_BACKLASH], setup.parameters[K.HALF_BACKLASH] * 5e3])
        jac = np.empty((2, 2))
        for col in range(2):
            step = np.zeros(2)
            step[col] = 1e-5 * scale[col]
            jac[:, col] = (advance(y + step) - advance(y - step)) / (2 * step[col])
        y = y - np.linalg.solve(jac - np.eye(2), end - y)
    np.testing.assert_allclose(orbit.state[[2, 5]] / scale, y / scale, atol=orbit_tolerance)
    reference = floquet_multipliers(jac)
    np.testing.assert_allclose(np.abs(orbit.multipliers[:2]), np.abs(reference), rtol=2e-5)
    np.testing.assert_allclose(orbit.multipliers[:2], reference, atol=multiplier_tolerance)
    assert np.all(np.abs(orbit.multipliers[2:]) < 1e-6)   # the locked bearings' modes


_CROSSING_STATE = np.array([-7.5e-6, 3.4e-6, 1.2e-4, 0.1, 0.0, 0.3])


@pytest.mark.parametrize("damping_in_separation", [True, False])
@pytest.mark.parametrize("stiffness", ["ishikawa", "fourier"])
def test_gear_monodromy_is_the_derivative_of_the_map_across_contact_and_stiffness_jumps(design, damping_in_separation,
                                                                                       stiffness):
    setup = setup_at(design, {"pinion_speed": 3600.0, "adhesion_torque": 21150.0},
                     damping_in_separation=damping_in_separation, stiffness=stiffness)
    mapping = PoincareMap(setup)
    result = mapping(_CROSSING_STATE, 2)
    assert result.measures["crossings"] >= 3
    assert (len(setup.breakpoints) > 0) == (stiffness == "ishikawa")
    scale = setup.state_scale()
    fd = np.empty((6, 6))
    for col in range(6):
        step = np.zeros(6)
        step[col] = 1e-7 * scale[col]
        fd[:, col] = (mapping(_CROSSING_STATE + step, 2, with_matrix=False).state
                      - mapping(_CROSSING_STATE - step, 2, with_matrix=False).state) / (2 * step[col])
    scaled = lambda m: m * scale[None, :] / scale[:, None]  # noqa: E731
    assert np.linalg.norm(scaled(result.monodromy - fd)) / np.linalg.norm(scaled(fd)) < 1e-6


def _scipy_map(design, state, damping_in_separation):
    run = uqgear.simulate(design, 3600.0, 7000.0, 21150.0, method="scipy", n_periods=2, keep_periods=2,
                          samples_per_period=1, initial_state=state, damping_in_separation=damping_in_separation,
                          rtol=1e-12)
    return np.array([run[f"poincare_{name}"].values[1] for name in STATE_NAMES])


@pytest.mark.slow
@pytest.mark.parametrize("damping_in_separation, tolerance", [(True, 3e-4), (False, 2e-3)])
def test_flow_monodromy_with_saltation_matches_the_scipy_reference(design, damping_in_separation, tolerance):
    setup = setup_at(design, {"pinion_speed": 3600.0, "adhesion_torque": 21150.0},
                     damping_in_separation=damping_in_separation)
    scale = setup.state_scale()
    fd = np.empty((6, 6))
    for col in range(6):
        step = np.zeros(6)
        step[col] = 1e-4 * scale[col]
        fd[:, col] = (_scipy_map(design, _CROSSING_STATE + step, damping_in_separation)
                      - _scipy_map(design, _CROSSING_STATE - step, damping_in_separation)) / (2 * step[col])
    flow = PoincareMap(setup, discrete=False)(_CROSSING_STATE).monodromy
    scaled = lambda m: m * scale[None, :] / scale[:, None]  # noqa: E731
    assert np.linalg.norm(scaled(flow - fd)) / np.linalg.norm(scaled(fd)) < tolerance


def test_wet_rail_3600_rpm_holds_two_stable_orbits(design):
    """From rest the low orbit (107.4 kN, in contact); from the 3700 rpm high response the 176.9 kN one."""
    setup = setup_at(design, {"pinion_speed": 3600.0, "adhesion_torque": 21150.0})
    low = Shooting().fit(setup, setup.static_state()).orbit_
    high_start = setup_at(design, {"pinion_speed": 3700.0, "adhesion_torque": 21150.0})
    relaxed = PoincareMap(high_start)(high_start.static_state(), 1500, with_matrix=False).state
    high = Shooting().fit(setup, relaxed).orbit_
    assert low.stable and high.stable
    assert low.qois["peak_mesh_force"] == pytest.approx(107.4e3, rel=2e-3)
    assert low.qois["fraction_separation"] == 0.0
    assert high.qois["peak_mesh_force"] == pytest.approx(176.9e3, rel=2e-3)
    assert high.qois["fraction_separation"] == pytest.approx(0.5, abs=0.02)


def test_floquet_counts_and_crossing_types():
    assert list(floquet_multipliers(np.diag([0.2, -1.5, 0.9]))) == [-1.5, 0.9, 0.2]
    assert unstable_counts(np.array([1.2, -0.3, 0.5 + 1j, 0.5 - 1j])) == UnstableCounts(1, 0, 2)
    stable = UnstableCounts(0, 0, 0)
    assert crossing_types(stable, UnstableCounts(1, 0, 0), turned=True) == [FOLD]
    assert crossing_types(stable, UnstableCounts(0, 1, 0), turned=False) == [PERIOD_DOUBLING]
    assert crossing_types(stable, UnstableCounts(0, 0, 2), turned=False) == [NEIMARK_SACKER]
    # two real multipliers outside the circle colliding into a pair: no bifurcation
    assert crossing_types(UnstableCounts(2, 0, 0), UnstableCounts(0, 0, 2), turned=False) == []


def test_shooting_refuses_what_it_cannot_do(design):
    with pytest.raises(OperatingPointError, match="eccentricity"):
        setup_at(design, {"pinion_speed": 3000.0}, effects=[uqgear.make_effect("eccentricity", {"amplitude": 5e-6})])
    with pytest.raises(OperatingPointError, match="pinion_speed: missing"):
        setup_at(design, {"drive_torque": 7000.0})
    setup = setup_at(design, {"pinion_speed": 3000.0})
    with pytest.raises(uqgear.UqgearError, match="guess"):
        Shooting().fit(setup, np.zeros(5))
    with pytest.raises(ShootingError, match="period-1"):
        Shooting(settings=ShootingSettings(max_iterations=0)).fit(setup, setup.static_state() * 3.0)
