"""Tooth-pair loads and tooth stresses against the static load sharing, ISO 6336 and Hertz."""

from __future__ import annotations

import math

import numpy as np
import pytest

import uqgear
from uqgear.dynamics.tooth_loads import pair_loads, tooth_stresses
from uqgear.physics.geometry import pair_geometry
from uqgear.physics.rating import static_rating

T1 = 7000.0
SAMPLES = 1024


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


def _static_sharing(setup, position, force):
    """Equal deflection across the pairs in contact, loads summing to the mesh force: P_i = F k_i / sum k_j."""
    eps = setup.derived["contact_ratio"]
    grid = np.linspace(0.0, eps, setup.pair_stiffness.size)
    k = np.where(np.isnan(position), 0.0, np.interp(np.nan_to_num(position), grid, setup.pair_stiffness))
    return force * k / k.sum(axis=1, keepdims=True), k


def test_slow_run_reproduces_the_static_load_sharing(design):
    """At 5 rpm the pair loads away from the pair-set changes are the static sharing of the stiffness table."""
    speed, t2 = 5.0, T1 * design.z2 / design.z1
    run = uqgear.simulate(design, speed, T1, t2, n_periods=5, keep_periods=3, samples_per_period=SAMPLES)
    setup = uqgear.build_model(design, speed, T1, t2)
    loads = pair_loads(
        setup, run["x"].values, run["x_velocity"].values, first_period=int(run["period"][0]), samples_per_period=SAMPLES
    )
    # the pairs' loads add up to the kernel's mesh force
    np.testing.assert_allclose(loads["mesh_force"].values, run["mesh_force"].values, rtol=1e-9, atol=1e-6)
    force = T1 / pair_geometry(design).pinion.base_radius
    static, _ = _static_sharing(setup, loads["pair_position"].values, force)
    eps = setup.derived["contact_ratio"]
    phase = (np.arange(loads.sizes["time"]) % SAMPLES) / SAMPLES
    # the stiffness steps at pair entry and exit ring at the natural frequencies; a tenth of a mesh period on
    # they have died out
    settled = np.minimum.reduce([phase, 1.0 - phase, np.abs(phase - (eps - 1.0))]) > 0.1
    error = np.abs(loads["pair_load"].values - static).max(axis=1)[settled] / force
    assert error.max() < 0.005
    # single and double pair contact both occur, with the static split between the two pairs
    carrying = (loads["pair_load"].values[settled] > 0.0).sum(axis=1)
    assert set(carrying.tolist()) == {1, 2}


def test_quasi_static_stress_peaks_are_the_iso_stresses(design):
    """Under the static DTE F / k(t) + b the peak root and flank stresses are ISO 6336's at K_v = 1."""
    speed, t2 = 50.0, T1 * design.z2 / design.z1
    setup = uqgear.build_model(design, speed, T1, t2)
    rating = static_rating(design, T1, speed, dynamic_factor=1.0)
    force = T1 / pair_geometry(design).pinion.base_radius
    eps = setup.derived["contact_ratio"]
    phase = np.arange(4 * SAMPLES) % SAMPLES / SAMPLES
    position = phase[:, None] + np.arange(2)[None, :]
    position = np.where(position < eps, position, np.nan)
    _, k = _static_sharing(setup, position, force)
    x = force / k.sum(axis=1) + design.half_backlash
    stresses = tooth_stresses(setup, rating, x, np.zeros(x.size), first_period=0, samples_per_period=SAMPLES)
    np.testing.assert_allclose(stresses["root_stress_peak"].values, rating.root_stress, rtol=2e-3)
    np.testing.assert_allclose(stresses["contact_stress_peak"].values, rating.contact_stress, rtol=2e-3)
    # the tooth is unloaded outside its engagement: the amplitude is half the peak
    np.testing.assert_allclose(stresses["root_stress_amplitude"], 0.5 * stresses["root_stress_peak"])


def test_single_pair_contact_stress_is_hertz(design):
    """Constant stiffness, one pair in contact: the flank stress is Hertz's line contact (times ISO's Z_eps)."""
    setup = uqgear.build_model(design, 50.0, T1, T1 * design.z2 / design.z1, stiffness="constant")
    rating = static_rating(design, T1, 50.0, dynamic_factor=1.0)
    deflection = 150e-6
    x = np.full(3 * SAMPLES, design.half_backlash + deflection)
    stresses = tooth_stresses(setup, rating, x, np.zeros(x.size), first_period=0, samples_per_period=SAMPLES)
    geometry = pair_geometry(design)
    eps, p_b = geometry.contact_ratio, geometry.base_pitch
    r_b1, r_b2 = geometry.pinion.base_radius, geometry.gear.base_radius
    tan_w = math.tan(geometry.working_pressure_angle)
    position = stresses["position"].values
    single = (position > eps - 1.0 + 0.01) & (position < 1.0 - 0.01)
    # flank radii from the tip circle of the pinion, where contact ends
    rho_1 = math.sqrt(geometry.pinion.tip_radius**2 - r_b1**2) - (eps - position[single]) * p_b
    rho_2 = (r_b1 + r_b2) * tan_w - rho_1
    load = setup.derived["k_mean"] * deflection
    e_star = design.youngs_modulus / (2.0 * (1.0 - design.poisson_ratio**2))
    hertz = np.sqrt(load * e_star / (math.pi * design.face_width) * (1.0 / rho_1 + 1.0 / rho_2))
    z_eps = math.sqrt((4.0 - eps) / 3.0)
    np.testing.assert_allclose(stresses["tooth_load"].values[0, single], load, rtol=1e-12)
    contact = stresses["contact_stress"].values[:, 0, single].max(axis=0)  # one flank or the other
    np.testing.assert_allclose(contact / z_eps, hertz * math.sqrt(1.1), rtol=1e-9)  # K_Hbeta = 1.1
