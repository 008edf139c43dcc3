"""Integrators against closed forms and against each other."""

import math

import numpy as np
import pytest

import uqgear
from uqgear.common.errors import OperatingPointError
from uqgear.physics.effects import make_effect
from uqgear.physics.model import build_model


def _linear_amplitude(setup, omega):
    """Steady DTE amplitude of the linearised model under STE excitation (complex response)."""
    d = setup.design
    p = setup.parameters
    k = setup.derived["k_mean"]
    me = setup.derived["equivalent_mass"]
    c1, c2, cm = (p[uqgear.physics._kernels.C1], p[uqgear.physics._kernels.C2], p[uqgear.physics._kernels.CM])
    mesh = k + 1j * cm * omega
    a = np.array([
        [-d.m1 * omega ** 2 + 1j * c1 * omega + d.k1, 0.0, mesh],
        [0.0, -d.m2 * omega ** 2 + 1j * c2 * omega + d.k2, -mesh],
        [omega ** 2, -omega ** 2, -omega ** 2 + mesh / me],
    ])
    response = np.linalg.solve(a, np.array([0.0, 0.0, d.ste_amplitude * omega ** 2]))
    return abs(response[2])


@pytest.mark.parametrize("method", ["fast", "scipy"])
@pytest.mark.parametrize("speed", [700.0, 2500.0, 5200.0])
def test_linear_limit_matches_closed_form(design, method, speed):
    # constant stiffness and a load so large the teeth never separate: a linear system
    drive = 60e3
    adhesion = drive * design.z2 / design.z1
    kw = {"stiffness": "constant", "n_periods": 300 if method == "fast" else 120, "keep_periods": 40}
    ds = uqgear.simulate(design, speed, drive, adhesion, method=method, **kw)
    assert np.all(ds["contact"].values == 1)
    setup = build_model(design, speed, drive, adhesion, stiffness="constant")
    expected = _linear_amplitude(setup, 2 * math.pi * ds.attrs["mesh_frequency"])
    fluctuation = ds["x"].values - ds["x"].values.mean()
    simulated = math.sqrt(2.0) * fluctuation.std()
    assert simulated == pytest.approx(expected, rel=0.01)
    # the mean is the static equilibrium x = F_T / k + b
    static = ds.attrs["static_mesh_force"] / ds.attrs["k_mean"] + ds.attrs["half_backlash"]
    assert ds["x"].values.mean() == pytest.approx(static, rel=1e-4)


def test_static_equilibrium_without_excitation(design):
    quiet = design.replace(ste_amplitude=0.0)
    ds = uqgear.simulate(quiet, 1500.0, 7000.0, 30000.0, stiffness="constant", n_periods=50, keep_periods=10)
    force = ds.attrs["static_mesh_force"]
    assert ds["x"].values == pytest.approx(force / ds.attrs["k_mean"] + quiet.half_backlash, rel=1e-9)
    assert ds["y1"].values == pytest.approx(-force / quiet.k1, rel=1e-9)
    assert ds["y2"].values == pytest.approx(force / quiet.k2, rel=1e-9)
    # F_T = m_e (R1 T1/I1 + R2 T2/I2)
    me = uqgear.equivalent_mass(quiet)
    assert force == pytest.approx(me * (ds.attrs["pinion_base_radius"] * 7000 / quiet.I1
                                        + ds.attrs["gear_base_radius"] * 30000 / quiet.I2))


def test_static_state_sits_beyond_bearing_clearance(design):
    """With a bearing dead zone the static state is shifted by the clearance, so a run starting there
    has no start-up transient: the loaded bearings never enter the dead zone at this operating point
    and the response equals the healthy one shifted by the clearance."""
    clearance = [make_effect("bearing_clearance", {"clearance": 2e-4, "bearing": "pinion"})]
    kw = {"n_periods": 60, "keep_periods": 60}
    plain = uqgear.simulate(design, 1500.0, 7000.0, 33000.0, **kw)
    loose = uqgear.simulate(design, 1500.0, 7000.0, 33000.0, effects=clearance, **kw)
    assert np.allclose(loose["y1"].values, plain["y1"].values - 2e-4, rtol=0, atol=1e-12)
    assert np.allclose(loose["x"].values, plain["x"].values, rtol=0, atol=1e-12)


def test_natural_frequencies_as_model_md(design):
    f = uqgear.natural_frequencies(design)
    assert f == pytest.approx([270.0, 430.0, 1550.0], rel=0.03)
    assert uqgear.equivalent_mass(design) == pytest.approx(121.0, rel=0.005)


@pytest.mark.parametrize("speed, drive, adhesion", [
    (600.0, 7000.0, 33000.0),     # low speed, many steps per mesh period
    (2200.0, 2000.0, 21146.0),    # light load near the second-harmonic resonance
    (4400.0, 7000.0, 33000.0),    # mesh resonance with tooth separation
])
def test_fast_matches_scipy_reference(design, speed, drive, adhesion):
    kw = {"n_periods": 150, "keep_periods": 30}
    ref = uqgear.simulate(design, speed, drive, adhesion, method="scipy", **kw)
    fast = uqgear.simulate(design, speed, drive, adhesion, method="fast", **kw)
    x_ref, x_fast = ref["x"].values, fast["x"].values
    relative = np.sqrt(np.mean((x_fast - x_ref) ** 2)) / np.sqrt(np.mean((x_ref - x_ref.mean()) ** 2))
    assert relative <= 1e-3
    assert np.array_equal(ref["contact"].values, fast["contact"].values)


@pytest.mark.parametrize("effect", ["eccentricity", "tooth_damage", "friction", "torque_ripple",
                                    "adhesion_oscillation", "bearing_clearance"])
def test_fast_matches_scipy_with_each_effect(design, effect):
    """The fast path tabulates the mesh-periodic forcing once per run and applies the effects
    that break mesh periodicity on top; scipy evaluates everything afresh at every call."""
    values = {"eccentricity": {"amplitude": 12e-6}, "tooth_damage": {"depth": 0.3},
              "friction": {"coefficient": 0.1}, "torque_ripple": {"amplitude": 0.06},
              "adhesion_oscillation": {"amplitude": 0.05}, "bearing_clearance": {"clearance": 2e-4}}[effect]
    kw = {"n_periods": 120, "keep_periods": 60, "effects": [make_effect(effect, values)]}
    ref = uqgear.simulate(design, 1700.0, 2000.0, 21146.0, method="scipy", **kw)
    fast = uqgear.simulate(design, 1700.0, 2000.0, 21146.0, method="fast", **kw)
    healthy = uqgear.simulate(design, 1700.0, 2000.0, 21146.0, n_periods=120, keep_periods=60)
    def relative(run, reference, name):
        a, b = run[name].values, reference[name].values
        return np.sqrt(np.mean((a - b) ** 2)) / np.sqrt(np.mean((b - b.mean()) ** 2))

    for name in ("x", "y1", "y2", "te"):
        assert relative(fast, ref, name) <= 1e-3, name
    # ... and the effect is not lost on the way: it changes the transmission error by > 10 %
    assert relative(healthy, ref, "te") > 0.1


def test_schedule_tiles_the_mesh_period_and_splits_at_breakpoints(design):
    from uqgear.physics import _kernels as K
    from uqgear.physics.effects import make_effect
    from uqgear.physics.model import build_model

    setup = build_model(design, 1500.0, 7000.0, 33000.0, effects=[make_effect("friction", {"coefficient": 0.1})])
    steps = 96
    first_sub, offsets, widths, refs, pairs, table = K.build_schedule(
        setup.parameters, setup.pair_stiffness, setup.period_stiffness, setup.breakpoints, steps)
    count = first_sub[-1]
    period = 1.0 / setup.mesh_frequency
    # contiguous sub-steps covering [0, period), each grid step starting on its grid point
    assert np.allclose(offsets[1:count], offsets[:count - 1] + widths[:count - 1], rtol=0, atol=1e-15)
    assert offsets[count - 1] + widths[count - 1] == pytest.approx(period, rel=1e-12)
    assert np.allclose(offsets[first_sub[:-1]], np.arange(steps) * period / steps, rtol=0, atol=1e-15)
    # one extra sub-step per breakpoint (pair leaving contact, friction reversing at the pitch point)
    assert count == steps + len(setup.breakpoints)
    ends = np.concatenate([offsets[:count], [period]]) / period
    for phase in setup.breakpoints:
        assert np.min(np.abs(ends - phase)) < 1e-12
    # pairs in contact: eps - 1 of the period with two pairs, the rest with one
    two = widths[:count][pairs[:count] == 2].sum() / period
    assert two == pytest.approx(setup.derived["contact_ratio"] - 1.0, abs=1e-9)
    # the tabulated stiffness at every stage equals the generic forcing there
    for sub in range(0, count, 7):
        for stage, t in enumerate((offsets[sub], offsets[sub] + widths[sub] / 2, offsets[sub] + widths[sub])):
            k = K.forcing(t, refs[sub], setup.parameters, setup.pair_stiffness, setup.period_stiffness,
                          setup.factor_pinion, setup.factor_gear)[0]
            assert table[sub, stage, K.F_K] * setup.parameters[K.STIFFNESS_SCALE] == pytest.approx(k, rel=1e-12)


def test_batch_equals_single_runs(design):
    samples = uqgear.samples_from_mapping({"pinion_speed": [900.0, 4400.0], "adhesion_torque": [25e3, 40e3],
                                           "k1": [1.0e9, 1.3e9]})
    batch = uqgear.simulate_batch(design, samples, n_periods=120, keep_periods=40, history_per_period=8,
                                  rig_channels=True)
    for i in range(2):
        steps = int(batch["steps_per_period"].values[i])
        one = uqgear.simulate(design.replace(k1=float(samples.k1[i])), float(samples.pinion_speed[i]),
                              design.operation.drive_torque, float(samples.adhesion_torque[i]),
                              n_periods=120, keep_periods=40, samples_per_period=steps)
        assert one.attrs["steps_per_period"] == steps
        x = one["x"].values
        assert batch["poincare_x"].values[i] == pytest.approx(one["poincare_x"].values, rel=1e-12)
        assert batch["dte_rms"].values[i] == pytest.approx(x.std(), rel=1e-6)
        assert batch["dte_peak_to_peak"].values[i] == pytest.approx(np.ptp(x), rel=1e-9)
        assert batch["x_history"].values[i] == pytest.approx(x[::steps // 8], rel=1e-12)
        assert batch["te_history"].values[i] == pytest.approx(one["te"].values[::steps // 8], rel=1e-9)
        assert batch["acc_gear_history"].values[i] == pytest.approx(
            one["y2_acceleration"].values[::steps // 8], rel=1e-9)
        assert batch["fraction_separation"].values[i] == pytest.approx(np.mean(one["contact"].values == 0))
        assert batch["acc_pinion_rms"].values[i] == pytest.approx(
            np.sqrt(np.mean(one["y1_acceleration"].values ** 2)), rel=1e-6)
    assert batch["fraction_separation"].values[1] > 0.1   # 4400 rpm: mesh resonance, teeth part
    assert batch.sizes == {"sample": 2, "period": 40, "mesh_cycle": 320}


def test_batch_threads_do_not_change_numbers(design):
    samples = uqgear.samples_from_mapping({"pinion_speed": np.linspace(1000, 5000, 6)})
    one = uqgear.simulate_batch(design, samples, n_periods=60, keep_periods=20, threads=1)
    two = uqgear.simulate_batch(design, samples, n_periods=60, keep_periods=20, threads=2)
    assert np.array_equal(one["poincare_x"].values, two["poincare_x"].values)


def test_effect_slots_change_the_response(design):
    kw = {"n_periods": 200, "keep_periods": 100}
    base = uqgear.simulate(design, 1500.0, 7000.0, 33000.0, **kw)
    neutral = uqgear.simulate(design, 1500.0, 7000.0, 33000.0,
                              effects=[make_effect("torque_ripple", {"amplitude": 0.0})], **kw)
    assert np.array_equal(base["x"].values, neutral["x"].values)
    eccentric = uqgear.simulate(design, 1500.0, 7000.0, 33000.0,
                                effects=[make_effect("eccentricity", {"amplitude": 12e-6})], **kw)
    # run-out adds a once-per-pinion-revolution line to the transmission error
    te = eccentric["te"].values - eccentric["te"].values.mean()
    t = eccentric["time"].values
    w1 = 2 * math.pi * 1500.0 / 60.0
    line = 2 * abs(np.mean(te * np.exp(-1j * w1 * t)))
    assert line == pytest.approx(12e-6, rel=0.05)


def test_dimensionless_records_characteristic_length(design):
    ds = uqgear.simulate(design, 1500.0, 7000.0, 33000.0, n_periods=40, keep_periods=4)
    nd = uqgear.dimensionless(ds)
    assert nd.attrs["characteristic_length"] == design.half_backlash
    assert nd.attrs["dimensionless_backlash"] == 1.0
    assert nd["X"].values == pytest.approx(ds["x"].values / design.half_backlash)
    assert nd.attrs["Omega"] == pytest.approx(2 * math.pi * ds.attrs["mesh_frequency"] / ds.attrs["omega_n"])


@pytest.mark.parametrize("call, message", [
    (lambda d: uqgear.simulate(d, -100.0, 7000.0, 30000.0), r"pinion_speed: expected a finite value > 0 rpm"),
    (lambda d: uqgear.simulate(d, 0.0, 7000.0, 30000.0), r"pinion_speed: expected a finite value > 0"),
    (lambda d: uqgear.simulate(d, 1000.0, -1.0, 30000.0), r"drive_torque: expected a finite value >= 0"),
    (lambda d: uqgear.simulate(d, 1000.0, 7000.0, 30000.0, method="rk45"), r"method: expected one of fast, scipy"),
    (lambda d: uqgear.simulate(d, 1000.0, 7000.0, 30000.0, n_periods=10, keep_periods=20), r"keep_periods"),
    (lambda d: uqgear.simulate(d, 1000.0, 7000.0, 30000.0, stiffness="fem"), r"stiffness: expected one of"),
    (lambda d: uqgear.simulate_batch(d, uqgear.samples_from_mapping({"speed": [1.0]})),
     r"samples.speed: unknown variable"),
    (lambda d: uqgear.simulate_batch(d, uqgear.samples_from_mapping({"adhesion_torque": [1.0]})),
     r"samples.pinion_speed: missing"),
    (lambda d: uqgear.simulate_batch(d, uqgear.samples_from_mapping({"pinion_speed": [1000.0],
                                                                     "friction.coefficient": [0.1]})),
     r"effect 'friction' is not among the model's effects"),
])
def test_bad_operating_input(design, call, message):
    with pytest.raises(OperatingPointError, match=message):
        call(design)


@pytest.mark.slow
@pytest.mark.parametrize("speed, drive, adhesion, expected", [
    (4200.0, 7000.0, 46520.0, "period-1"),   # dry rail: separating but period-1
    (4400.0, 7000.0, 33000.0, "period-17"),  # rated torque, mid interval: a period-17 window (needs >= 170 kept)
    (4750.0, 1000.0, 4810.0, "period-2"),    # light load: period-2 of the doubling cascade
])
def test_fast_and_scipy_classify_alike(design, speed, drive, adhesion, expected):
    from uqgear.dynamics.regimes import classify_dataset

    # 200 kept periods: a period-n label needs 10 repeats (n <= 20), docs/model/analysis-conventions.md section 8
    kw = {"n_periods": 600, "keep_periods": 200, "samples_per_period": 32}
    ref = uqgear.simulate(design, speed, drive, adhesion, method="scipy", **kw)
    fast = uqgear.simulate(design, speed, drive, adhesion, **kw)
    assert classify_dataset(ref).label == classify_dataset(fast).label == expected
    x_ref, x_fast = ref["x"].values, fast["x"].values
    assert np.sqrt(np.mean((x_fast - x_ref) ** 2)) / np.std(x_ref) <= 1e-3


def test_batch_final_state_restarts_the_run_bit_for_bit():
    """Two halves of a run, the second started from the first's final state, are the whole run."""
    design = uqgear.load_design("locomotive")
    samples = uqgear.samples_from_mapping({"pinion_speed": [1500.0, 3600.0], "adhesion_torque": [21.15e3, 30e3]})
    whole = uqgear.simulate_batch(design, samples, n_periods=40, keep_periods=20, final_state=True, threads=1)
    first = uqgear.simulate_batch(design, samples, n_periods=20, keep_periods=20, final_state=True, threads=1)
    second = uqgear.simulate_batch(design, samples, n_periods=20, keep_periods=20, final_state=True, threads=1,
                                   initial_states=first["final_state"].values)
    assert whole["final_state"].dims == ("sample", "state")
    np.testing.assert_array_equal(second["final_state"].values, whole["final_state"].values)
    np.testing.assert_array_equal(second["poincare_x"].values, whole["poincare_x"].values)
    rest = uqgear.simulate_batch(design, samples, n_periods=40, keep_periods=20, threads=1)
    assert "final_state" not in rest
    np.testing.assert_array_equal(rest["peak_mesh_force"].values, whole["peak_mesh_force"].values)


def test_batch_initial_states_of_the_wrong_shape_are_refused():
    design = uqgear.load_design("locomotive")
    samples = uqgear.samples_from_mapping({"pinion_speed": [1500.0, 3600.0]})
    with pytest.raises(uqgear.UqgearError, match="initial_states"):
        uqgear.simulate_batch(design, samples, n_periods=4, keep_periods=2, initial_states=np.zeros((1, 6)))
