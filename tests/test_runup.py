"""The speed-varying model: speed profiles, the angle-driven forcing, the fast path against the references."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.interpolate import PchipInterpolator

import uqgear
from uqgear.physics import _runup_kernels as R
from uqgear.physics import runup as RU
from uqgear.physics.batch_setup import build_batch
from uqgear.physics.model import HISTORY_COLUMNS
from uqgear.physics.runup import BAND_SHRINK, simulate_runup, simulate_runup_batch, step_bands
from uqgear.physics.speed_profile import RPM, SpeedProfile, SpeedProfileError

T1 = 7000.0
T2 = 33.8e3
STATE = ("y1", "y2", "x", "y1_velocity", "y2_velocity", "x_velocity")


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


def relative_rms(value: np.ndarray, reference: np.ndarray) -> float:
    """RMS of the difference over the RMS of the reference's fluctuation about its mean."""
    return float(np.sqrt(np.mean((value - reference) ** 2)) / np.std(reference))


# ---------------------------------------------------------------- profiles
def test_linear_ramp_angle_is_the_closed_form():
    ramp = SpeedProfile.linear(1500.0, 2500.0, 0.5)
    t = np.linspace(0.0, 0.5, 11)
    assert ramp.direction == "up"
    np.testing.assert_allclose(ramp.speed(t), 1500.0 + 2000.0 * t, rtol=1e-14)
    np.testing.assert_allclose(ramp.acceleration(t), 2000.0 * RPM, rtol=1e-14)
    np.testing.assert_allclose(ramp.angle(t), (1500.0 * t + 1000.0 * t**2) * RPM, rtol=1e-14, atol=1e-14)
    np.testing.assert_allclose(ramp.time_at_angle(ramp.angle(t)), t, atol=1e-14)
    by_rate = SpeedProfile.linear(2500.0, 1500.0, rate_rpm_per_s=-500.0)
    assert by_rate.duration == 2.0 and by_rate.direction == "down"


def test_sampled_profile_angle_is_the_interpolant_integral():
    times, speeds = [0.0, 0.2, 0.5, 1.0], [1000.0, 1400.0, 1500.0, 3000.0]
    linear = SpeedProfile.samples(times, speeds, interpolation="linear")
    trapezoids = np.concatenate([[0.0], np.cumsum(np.diff(times) * 0.5 * (np.array(speeds[1:]) + speeds[:-1]))])
    np.testing.assert_allclose(linear.angle(times), trapezoids * RPM, rtol=1e-14)
    pchip = SpeedProfile.samples(times, speeds)
    fine = np.linspace(0.0, 1.0, 20001)
    np.testing.assert_allclose(float(pchip.angle(1.0)), np.trapezoid(pchip.angular_speed(fine), fine), rtol=1e-8)


@pytest.mark.parametrize(
    ("times", "speeds", "words"),
    [
        ([0.0, 1.0, 2.0], [1500.0, 2500.0, 2000.0], "reverses at t = 1 s"),
        ([0.0, 1.0, 1.0], [1500.0, 2000.0, 2500.0], "times_s: expected strictly increasing"),
        ([0.0, 1.0], [0.0, 2000.0], "speeds_rpm: expected speeds > 0"),
        ([0.0, 1.0], [np.nan, 2000.0], "speeds_rpm: expected finite"),
    ],
)
def test_bad_profiles_are_refused_by_name(times, speeds, words):
    with pytest.raises(SpeedProfileError, match=words) as caught:
        SpeedProfile.samples(times, speeds)
    assert isinstance(caught.value, uqgear.OperatingPointError) and isinstance(caught.value, ValueError)


def test_speed_outside_the_design_range_is_refused(design):
    with pytest.raises(SpeedProfileError, match="pinion_speed_sweep"):
        simulate_runup(design, SpeedProfile.linear(1500.0, 6500.0, 0.1), T1, T2)
    with pytest.raises(SpeedProfileError, match="reverses"):
        SpeedProfile.from_function(lambda t: 2000.0 + 500.0 * np.sin(20.0 * t), 1.0)


# ---------------------------------------------------------------- the angle-driven forcing
def test_chain_rule_term_is_the_second_time_derivative_of_the_ste(design):
    """e'' of the forcing against finite differences of e(tau(t)) along a fast ramp, with run-out."""
    setup = uqgear.build_model(
        design, 1500.0, T1, T2, effects=[uqgear.make_effect("eccentricity", {"amplitude": 20e-6})]
    )
    p = setup.parameters
    profile = SpeedProfile.samples([0.0, 0.05, 0.1], [1500.0, 3000.0, 3500.0])
    omega_ref = setup.pinion_rotation

    def ste_and_acc(t: float) -> tuple[float, float]:
        tau = float(profile.angle(t)) / omega_ref
        rate = float(profile.angular_speed(t)) / omega_ref
        accel = float(profile.acceleration(t)) / omega_ref
        phase = p[uqgear.physics._rhs.OMEGA_MESH] * tau + p[uqgear.physics._rhs.STE_PHASE]
        _, ste, ste_acc = R.time_part(tau, t, rate, accel, math.sin(phase), math.cos(phase), p)
        return ste, ste_acc

    h = 2e-7
    for t in (0.013, 0.031, 0.072):
        numeric = (ste_and_acc(t + h)[0] - 2.0 * ste_and_acc(t)[0] + ste_and_acc(t - h)[0]) / h**2
        assert ste_and_acc(t)[1] == pytest.approx(numeric, rel=2e-4)


def test_constant_profile_is_simulate(design):
    """At constant speed the warp is the identity: the run is simulate's, to round-off."""
    setup = uqgear.build_model(design, 2000.0, T1, T2)
    steps = uqgear.physics.steps_per_period(setup)
    steady = uqgear.simulate(design, 2000.0, T1, T2, n_periods=12, keep_periods=11, samples_per_period=steps)
    start = np.array([float(steady[f"poincare_{name}"][0]) for name in STATE])
    frequency = steady.attrs["mesh_frequency"]
    run = simulate_runup(
        design,
        SpeedProfile.constant(2000.0, 10 / frequency),
        T1,
        T2,
        sample_rate=steps * frequency,
        initial_state=start,
    )
    assert run.attrs["steps_per_period"] == steps
    for name in ("x", "te", "mesh_force", "y1_acceleration", "y2_acceleration", "mesh_stiffness"):
        reference = steady[name].values[: run.sizes["time"]]
        assert np.max(np.abs(run[name].values - reference)) <= 1e-11 * np.max(np.abs(reference)), name
    np.testing.assert_array_equal(run["contact"].values, steady["contact"].values[: run.sizes["time"]])


@pytest.mark.parametrize(("start", "stop"), [(1500.0, 2500.0), (2500.0, 1500.0)])
def test_fast_path_agrees_with_the_scipy_reference_on_a_run_up(design, start, stop):
    """Relative RMS of the DTE difference (over the DTE's own RMS fluctuation) below 1e-3, up and down."""
    ramp = SpeedProfile.linear(start, stop, 0.05)
    fast = simulate_runup(design, ramp, T1, T2, run_in_periods=100)
    start = np.array([fast[name].values[0] for name in STATE])
    reference = simulate_runup(design, ramp, T1, T2, method="scipy", initial_state=start, rtol=1e-8)
    assert relative_rms(fast["x"].values, reference["x"].values) < 1e-3
    assert relative_rms(fast["mesh_force"].values, reference["mesh_force"].values) < 1e-3
    np.testing.assert_array_equal(fast["contact"].values, reference["contact"].values)


def test_slow_ramp_reproduces_steady_responses(design):
    """A 1000 rpm/s ramp: RMS DTE and peak mesh force in 50 rpm bins against steady runs.

    The mesh mode's free response decays in a few ms, in which the speed moves a few rpm, so each
    bin of the ramp is quasi-steady: its RMS DTE and peak mesh force lie between the lowest and the
    highest of the steady values at the bin's edges and centre, widened by 1 % of the centre's value
    (peaks over finite records; the ramp's bin spans a whole range of speeds).
    """
    ramp = simulate_runup(design, SpeedProfile.linear(1500.0, 2500.0, 1.0), T1, T2)
    centres = np.array([1600.0, 1800.0, 2000.0, 2200.0, 2400.0])
    speeds = np.concatenate([centres - 25.0, centres, centres + 25.0])
    samples = uqgear.samples_from_mapping(
        {"pinion_speed": speeds, "drive_torque": np.full(speeds.size, T1), "adhesion_torque": np.full(speeds.size, T2)}
    )
    steady = uqgear.simulate_batch(design, samples, n_periods=300, keep_periods=150)
    for quantity, steady_name in (("rms", "dte_rms"), ("peak", "peak_mesh_force")):
        values = steady[steady_name].values.reshape(3, -1)
        for i, centre in enumerate(centres):
            inside = np.abs(ramp["pinion_speed"].values - centre) <= 25.0
            value = ramp["x"].values[inside].std() if quantity == "rms" else ramp["mesh_force"].values[inside].max()
            slack = 0.01 * values[1, i]
            assert values[:, i].min() - slack <= value <= values[:, i].max() + slack, (quantity, centre)


def test_batch_samples_are_single_runs(design):
    ramp = SpeedProfile.linear(2000.0, 2300.0, 0.03)
    samples = uqgear.samples_from_mapping(
        {"drive_torque": [T1, T1], "adhesion_torque": [25e3, 40e3], "mesh_stiffness_scale": [1.0, 0.9]}
    )
    batch = simulate_runup_batch(design, ramp, samples, run_in_periods=50, threads=2)
    assert dict(batch["x"].sizes) == {"sample": 2, "time": batch.sizes["time"]}
    for i in range(2):
        alone = simulate_runup(
            design,
            ramp,
            T1,
            float(samples["adhesion_torque"][i]),
            mesh_stiffness_scale=float(samples["mesh_stiffness_scale"][i]),
            run_in_periods=50,
        )
        for name in ("x", "te", "mesh_force", "y1_acceleration", "y2_acceleration"):
            np.testing.assert_array_equal(batch[name].values[i], alone[name].values)
    for name in ("pinion_speed", "pinion_angle", "mesh_phase", "x", "mesh_force"):
        assert "units" in batch[name].attrs
    np.testing.assert_allclose(batch["mesh_phase"], design.z1 * batch["pinion_angle"] / (2 * math.pi))


def _lane_groups(design, profile, samples, effects=()):
    """The lane groups :func:`simulate_runup_batch` forms for ``samples`` (lists of sample indices)."""
    n = samples.sizes["sample"]
    full = samples.assign(pinion_speed=("sample", np.full(n, profile.start_speed)))
    setups = build_batch(design, full, effects=effects)
    out_t = RU._output_times(profile, 20480.0)
    return RU._lane_groups(setups, RU._plans(setups, 24, profile, out_t))


def _assert_batch_is_single_runs(design, profile, samples, threads=1, **options):
    names = (*HISTORY_COLUMNS, "te")
    batch = simulate_runup_batch(
        design, profile, samples, run_in_periods=40, variables=names, threads=threads, **options
    )
    for i in range(samples.sizes["sample"]):
        alone = simulate_runup(
            design,
            profile,
            float(samples["drive_torque"][i]),
            float(samples["adhesion_torque"][i]),
            mesh_stiffness_scale=float(samples["mesh_stiffness_scale"][i]),
            run_in_periods=40,
            **options,
        )
        for name in names:
            # the lanes do the one-run kernel's operations in its order: the same numbers, bit for bit
            np.testing.assert_array_equal(batch[name].values[i], alone[name].values, err_msg=f"{name} of {i}")
    return batch


def test_lane_batch_is_the_one_run_kernel_for_every_sample(design):
    """Runs of three stiffness scales and several torques: lane groups with padding lanes, a run alone,
    two runs that lose contact (steps split at the contact boundary)."""
    ramp = SpeedProfile.linear(1800.0, 2300.0, 0.03)
    samples = uqgear.samples_from_mapping(
        {
            "drive_torque": [T1, T1, 300.0, T1, 500.0, T1],
            "adhesion_torque": [25e3, 40e3, 2e3, 30e3, 1e3, T2],
            "mesh_stiffness_scale": [1.0, 1.0, 1.0, 0.9, 0.9, 1.1],
        }
    )
    groups = _lane_groups(design, ramp, samples)
    assert sorted(map(sorted, groups)) == [[0, 1, 2], [3, 4], [5]]
    batch = _assert_batch_is_single_runs(design, ramp, samples, threads=2)
    assert batch["contact"].values[2].min() == 0 and batch["contact"].values[4].min() == 0


def test_lane_batch_is_the_one_run_kernel_with_every_effect(design):
    """Forcing that changes every mesh period (filled in full each period), friction, a damaged tooth, no
    damping in separation, and contact loss."""
    effects = [
        uqgear.make_effect("eccentricity", {"amplitude": 15e-6, "kappa": 0.05}),
        uqgear.make_effect("torque_ripple", {"amplitude": 0.05}),
        uqgear.make_effect("adhesion_oscillation", {"amplitude": 0.1, "frequency": 40.0}),
        uqgear.make_effect("friction", {"coefficient": 0.06}),
        uqgear.make_effect("tooth_damage", {"tooth": 3, "depth": 0.3}),
    ]
    ramp = SpeedProfile.linear(2000.0, 2400.0, 0.03)
    samples = uqgear.samples_from_mapping(
        {"drive_torque": [300.0, T1, T1], "adhesion_torque": [1e3, 25e3, 40e3], "mesh_stiffness_scale": [1.0] * 3}
    )
    assert _lane_groups(design, ramp, samples, effects) == [[0, 1, 2]]
    batch = _assert_batch_is_single_runs(design, ramp, samples, effects=effects, damping_in_separation=False)
    assert batch["contact"].values[0].min() == 0


def test_torque_driven_profile_follows_the_reflected_inertia(design):
    """omega1' = (T1(n1) - T_w / i) / J along the profile, J = I1 + (I2 + m R_w^2) / i^2."""
    speeds, torques = [0.0, 2000.0, 6000.0], [9000.0, 9000.0, 3000.0]
    profile = uqgear.torque_driven_profile(design, speeds, torques, 1000.0, 40.0, wheel_torque=20e3, mass=30e3)
    ratio = design.z2 / design.z1
    inertia = design.I1 + (design.I2 + 30e3 * design.operation.wheel_radius**2) / ratio**2
    t = np.array([2.0, 20.0, 38.0])
    curve = PchipInterpolator(speeds, torques)(profile.speed(t))
    assert profile.speed(t)[0] < 2000.0 < profile.speed(t)[-1]  # both parts of the curve
    np.testing.assert_allclose(profile.acceleration(t), (curve - 20e3 / ratio) / inertia, rtol=1e-5)
    with pytest.raises(SpeedProfileError, match="leaves the curve"):
        uqgear.torque_driven_profile(design, [500.0, 3000.0], [9000.0, 9000.0], 1000.0, 60.0)


@pytest.mark.parametrize(("start", "stop"), [(500.0, 6000.0), (6000.0, 500.0)])
def test_step_bands_give_every_period_the_steps_its_speed_needs(design, start, stop):
    setup = uqgear.build_model(design, start, T1, T2)
    rate = np.linspace(1.0, stop / start, 2001)  # tau' at the period starts of a ramp
    bands = step_bands(setup, rate, 24)
    assert bands[0][0] == 0 and bands[-1][1] == rate.size - 1
    assert all(a[1] == b[0] for a, b in zip(bands[:-1], bands[1:]))
    for first, stop_period, steps in bands:
        for n in range(first, stop_period):
            slowest = uqgear.build_model(design, start * min(rate[n], rate[n + 1]), T1, T2)
            needed = uqgear.physics.steps_per_period(slowest)
            assert needed <= steps <= math.ceil(needed / BAND_SHRINK) + 1


def test_fast_path_agrees_with_the_scipy_reference_with_every_effect(design):
    """Run-out with stiffness modulation, torque ripple, adhesion oscillation, friction, a damaged tooth."""
    effects = [
        uqgear.make_effect("eccentricity", {"amplitude": 15e-6, "kappa": 0.05}),
        uqgear.make_effect("torque_ripple", {"amplitude": 0.05}),
        uqgear.make_effect("adhesion_oscillation", {"amplitude": 0.1, "frequency": 40.0}),
        uqgear.make_effect("friction", {"coefficient": 0.06}),
        uqgear.make_effect("tooth_damage", {"tooth": 3, "depth": 0.3}),
    ]
    ramp = SpeedProfile.linear(1800.0, 2400.0, 0.03)
    fast = simulate_runup(design, ramp, T1, T2, run_in_periods=100, effects=effects)
    start = np.array([fast[name].values[0] for name in STATE])
    reference = simulate_runup(design, ramp, T1, T2, method="scipy", initial_state=start, rtol=1e-8, effects=effects)
    assert relative_rms(fast["x"].values, reference["x"].values) < 1e-3
    assert relative_rms(fast["mesh_force"].values, reference["mesh_force"].values) < 1e-3
