"""Samples as SIMD lanes: the same numbers as the one-sample kernel, bit for bit, whatever a batch holds.

Each check runs one batch twice, through the lanes (``simulate_batch``'s
default) and through the one-sample kernel (``lanes=False``), and compares
every float output byte for byte. The one-sample kernel is checked against
scipy and closed forms in tests/test_integration.py.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import numba as nb
import numpy as np
import pytest

import uqgear
from uqgear.physics import _lane_loop, _rhs, batch_setup, integration
from uqgear.physics import effects as E
from uqgear.physics._lanes import LANES, lane_ready
from uqgear.physics.model import build_model
from uqgear.physics.pitch_errors import draw_pitch_errors

# the rule that leaves groups of few runs to the one-sample kernel, as the package sets it
MINIMUM_FILL = batch_setup.MINIMUM_FILL


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


@pytest.fixture(autouse=True)
def every_group_in_lanes(monkeypatch):
    # the lanes hold every group here, however few its runs (random speeds make groups of one or
    # two), so that what is compared with the one-sample kernel is the lanes
    monkeypatch.setattr(batch_setup, "MINIMUM_FILL", 0.0)


def _differing(first, second) -> list[str]:
    names = [name for name in first.data_vars if np.issubdtype(first[name].dtype, np.floating)]
    assert names
    return [name for name in names if first[name].values.tobytes() != second[name].values.tobytes()]


def _both(design, samples, **kw):
    lanes = uqgear.simulate_batch(design, samples, **kw)
    one = uqgear.simulate_batch(design, samples, lanes=False, **kw)
    return lanes, one


def _speeds(n, lower=600.0, upper=5600.0, seed=0):
    rng = np.random.default_rng(seed)
    return uqgear.samples_from_mapping({"pinion_speed": rng.uniform(lower, upper, n),
                                        "adhesion_torque": rng.uniform(21e3, 46e3, n)})


def test_lanes_match_the_one_sample_kernel_through_separation_and_impacts(design):
    # up to 5600 rpm: drive contact, contact loss and back-side impacts, groups of 8 and partly filled ones
    samples = _speeds(29)
    lanes, one = _both(design, samples, n_periods=120, keep_periods=40, final_state=True)
    assert float(lanes["fraction_separation"].max()) > 0.05  # contact is lost, so lanes were split at |x| = b
    assert _differing(lanes, one) == []


@pytest.mark.parametrize("case", ["lyapunov", "rig_channels", "effects", "restart"])
def test_lanes_match_the_one_sample_kernel(design, case):
    samples = _speeds(11, seed=1)
    kw: dict = {"n_periods": 80, "keep_periods": 30}
    if case == "lyapunov":
        kw["lyapunov"] = True  # a run and its shadow take two lanes
    elif case == "rig_channels":
        kw.update(history_per_period=16, rig_channels=True)
    elif case == "effects":
        # mesh-periodic effects and settings stay in the lanes
        kw.update(effects=[E.make_effect("friction", {"coefficient": 0.08}), E.make_effect("bearing_clearance")],
                  damping_in_separation=False, stiffness="fourier")
    else:
        kw.update(initial_states=np.column_stack([np.zeros((11, 2)), np.full(11, 1e-4), np.zeros((11, 3))]),
                  final_state=True)
    lanes, one = _both(design, samples, **kw)
    assert _differing(lanes, one) == []


@pytest.mark.parametrize("name, values", [
    ("torque_ripple", {"amplitude": 0.05}),
    ("adhesion_oscillation", {"amplitude": 0.1, "frequency": 37.0}),
    ("eccentricity", {"amplitude": 3e-5, "kappa": 0.1, "shaft": "gear"}),
    ("tooth_damage", {"depth": 0.4, "tooth": 5.0}),
])
def test_forcing_that_does_not_repeat_every_mesh_period_stays_in_the_lanes(design, name, values):
    # every third run without the effect: groups mix runs whose forcing table is filled once with runs
    # whose table is filled every period; up to 5600 rpm the teeth separate, so lanes are split too
    samples = _speeds(20, seed=2)
    effect = E.make_effect(name, values)
    key = next(key for key in ("amplitude", "depth") if key in values)
    samples[f"{name}.{key}"] = ("sample", np.where(np.arange(20) % 3 == 0, 0.0, values[key]))
    kw = {"n_periods": 60, "keep_periods": 20, "effects": [effect], "history_per_period": 8, "rig_channels": True}
    setups = integration.build_batch(design, samples, effects=kw["effects"])
    assert lane_ready(np.stack([s.parameters for s in setups])).all()
    lanes, one = _both(design, samples, **kw)
    assert float(lanes["fraction_separation"].max()) > 0.05
    assert _differing(lanes, one) == []


@pytest.mark.parametrize("case", ["impacts", "lyapunov", "rig_channels", "friction", "tooth_damage", "eccentricity"])
def test_runs_with_pitch_errors_take_the_pair_lanes_bit_for_bit(design, case):
    # per-pair dead zones: pairs change contact one by one, and a lane's step is redone where any does
    pitch = draw_pitch_errors(design, 7, np.random.default_rng(0))
    samples = _speeds(13, seed=3)
    kw: dict = {"n_periods": 60, "keep_periods": 20, "pitch_errors": pitch}
    if case == "impacts":
        # light load and a fifth of the backlash: back-side impacts, counted from each pair's deflection
        samples = uqgear.samples_from_mapping({"pinion_speed": np.linspace(2000.0, 5600.0, 13),
                                               "drive_torque": np.full(13, 700.0),
                                               "adhesion_torque": np.full(13, 700.0 * design.z2 / design.z1),
                                               "backlash": np.full(13, design.backlash / 5)})
        kw["final_state"] = True
    elif case == "lyapunov":
        kw["lyapunov"] = True
    elif case == "rig_channels":
        kw.update(history_per_period=16, rig_channels=True)
    elif case == "friction":
        kw.update(effects=[E.make_effect("friction", {"coefficient": 0.08})], damping_in_separation=False,
                  stiffness="fourier")
    elif case == "tooth_damage":
        # the forcing table filled every period, in groups mixed with runs whose table is filled once
        samples["tooth_damage.depth"] = ("sample", np.where(np.arange(13) % 3 == 0, 0.0, 0.4))
        kw.update(effects=[E.make_effect("tooth_damage", {"depth": 0.4, "tooth": 5.0})], history_per_period=8,
                  rig_channels=True)
    else:
        kw["effects"] = [E.make_effect("eccentricity", {"amplitude": 3e-5, "kappa": 0.1, "shaft": "gear"})]
    setups = integration.build_batch(design, samples, pitch_errors=pitch, effects=kw.get("effects", ()))
    assert lane_ready(np.stack([s.parameters for s in setups])).all()
    lanes, one = _both(design, samples, **kw)
    assert float(lanes["fraction_separation"].max()) > 0.05
    if case == "impacts":
        assert float(lanes["fraction_back_contact"].max()) > 0.0
    assert _differing(lanes, one) == []
    # and the pitch errors are in the numbers: without them the response differs
    plain = uqgear.simulate_batch(design, samples, **{**kw, "pitch_errors": None})
    assert "dte_rms" in _differing(lanes, plain)


def test_runs_with_and_without_pitch_errors_never_share_a_lane_group(design):
    samples = uqgear.samples_from_mapping({"pinion_speed": np.full(6, 2500.0)})
    pitch = draw_pitch_errors(design, 7, np.random.default_rng(0))
    setups = (integration.build_batch(design, samples)
              + integration.build_batch(design, samples, pitch_errors=pitch))
    params = np.stack([s.parameters for s in setups])
    steps = np.array([integration.steps_per_period(s) for s in setups])
    groups, rest = batch_setup.lane_groups(params, steps, batch_setup.breakpoint_table(setups),
                                           np.zeros(len(setups), dtype=np.int64), lyapunov=False)
    assert rest.size == 0
    assert sorted(sorted(row[row >= 0].tolist()) for row in groups) == [[0, 1, 2, 3, 4, 5], [6, 7, 8, 9, 10, 11]]


def test_runs_a_group_cannot_hold_are_run_one_at_a_time(design, monkeypatch):
    # different profile shifts move the stiffness breakpoints: one group for all of them is refused
    # lane by lane, and the refused runs go through the one-sample kernel
    samples = uqgear.samples_from_mapping({"pinion_speed": np.full(LANES, 2500.0),
                                           "x1": np.linspace(0.10, 0.40, LANES)})
    kw = {"n_periods": 40, "keep_periods": 10}
    one = uqgear.simulate_batch(design, samples, lanes=False, **kw)

    def one_group(params, steps, breakpoints, strides, lyapunov):
        return np.arange(len(params), dtype=np.int64)[None, :], np.empty(0, dtype=np.int64)

    refused = []
    original = batch_setup._lanes.integrate_lanes

    def spying(first, last, groups, *arrays):
        original(first, last, groups, *arrays)
        refused.append(arrays[-1].copy())

    monkeypatch.setattr(batch_setup, "lane_groups", one_group)
    monkeypatch.setattr(batch_setup._lanes, "integrate_lanes", spying)
    lanes = uqgear.simulate_batch(design, samples, **kw)
    assert np.any(refused[-1]) and not refused[-1][0]
    assert _differing(lanes, one) == []


def test_lane_groups_share_one_layout_and_put_the_longest_first(design):
    samples = uqgear.samples_from_mapping({"pinion_speed": np.repeat([300.0, 3000.0, 5000.0], [3, 9, 4])})
    setups = integration.build_batch(design, samples)
    params = np.stack([s.parameters for s in setups])
    steps = np.array([integration.steps_per_period(s) for s in setups])
    groups, rest = batch_setup.lane_groups(params, steps, batch_setup.breakpoint_table(setups),
                                           np.zeros(len(setups), dtype=np.int64), lyapunov=False)
    assert rest.size == 0
    members = [row[row >= 0] for row in groups]
    assert sorted(np.concatenate(members).tolist()) == list(range(len(setups)))
    assert all(len(set(steps[m])) == 1 for m in members)
    assert [steps[m[0]] for m in members] == sorted((steps[m[0]] for m in members), reverse=True)
    with_shadows, _ = batch_setup.lane_groups(params, steps, batch_setup.breakpoint_table(setups),
                                              np.zeros(len(setups), dtype=np.int64), lyapunov=True)
    assert np.all(with_shadows[:, LANES // 2:] == -1)


def test_groups_of_fewer_runs_than_half_the_lanes_go_to_the_one_sample_kernel(design, monkeypatch):
    monkeypatch.setattr(batch_setup, "MINIMUM_FILL", MINIMUM_FILL)
    speeds = np.repeat([300.0, 3000.0, 5000.0], [3, LANES + 1, LANES // 2])
    samples = uqgear.samples_from_mapping({"pinion_speed": speeds})
    setups = integration.build_batch(design, samples)
    params = np.stack([s.parameters for s in setups])
    steps = np.array([integration.steps_per_period(s) for s in setups])
    no_history = np.zeros(len(setups), dtype=np.int64)
    groups, rest = batch_setup.lane_groups(params, steps, batch_setup.breakpoint_table(setups), no_history,
                                           lyapunov=False)
    # 300 rpm: three runs; 3000 rpm: a full group and one run over; 5000 rpm: half a group, in lanes
    assert rest.tolist() == [0, 1, 2, 3 + LANES]
    assert sorted(len(row[row >= 0]) for row in groups) == [LANES // 2, LANES]
    # with a run's shadow in a lane, half of four runs is enough
    groups, rest = batch_setup.lane_groups(params[-2:], steps[-2:], batch_setup.breakpoint_table(setups[-2:]),
                                           no_history[-2:], lyapunov=True)
    assert rest.size == 0 and len(groups) == 1
    # the runs left give the numbers the lanes would
    mixed = uqgear.simulate_batch(design, samples, n_periods=30, keep_periods=10)
    monkeypatch.setattr(batch_setup, "MINIMUM_FILL", 0.0)
    assert _differing(mixed, uqgear.simulate_batch(design, samples, n_periods=30, keep_periods=10)) == []


def test_a_job_compiles_only_the_kernel_family_it_uses(tmp_path):
    # a fresh interpreter: a plain batch loads (or compiles) the lanes alone, not the one-sample
    # kernels nor the pitch-error path
    script = textwrap.dedent("""
        import numpy as np
        import uqgear
        from uqgear.physics import _kernels as K, _lanes as L, _pair_lanes as P
        design = uqgear.load_design("locomotive")
        uqgear.simulate_batch(design, uqgear.samples_from_mapping({"pinion_speed": np.full(4, 1500.0)}),
                              n_periods=4, keep_periods=2)
        print(len(L.integrate_lanes.signatures), len(K.integrate_batch.signatures),
              len(K.integrate_batch_pairs.signatures), len(K.integrate_history_pairs.signatures),
              len(P.integrate_pair_lanes.signatures))
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["1", "0", "0", "0", "0"]


def test_a_quotient_outside_the_proven_range_is_redone_with_ieee_division(design):
    # at rest, unloaded and without transmission error, velocities of 1e-280 leave every acceleration's
    # numerator below the range where the lanes' quotient is proven exact: each sub-step is redone on
    # the one-sample code, and the tiny motion shows any bit it got wrong
    n = 5
    samples = uqgear.samples_from_mapping({"pinion_speed": np.linspace(1000.0, 3000.0, n),
                                           "drive_torque": np.zeros(n), "adhesion_torque": np.zeros(n),
                                           "ste_amplitude": np.zeros(n)})
    states = np.zeros((n, 6))
    states[:, 3:] = np.array([1e-280, -3e-281, 7e-281])
    lanes, one = _both(design, samples, n_periods=6, keep_periods=6, initial_states=states, final_state=True)
    assert 0.0 < np.abs(lanes["final_state"].values).max() < 1e-250
    assert _differing(lanes, one) == []


def test_a_lane_reads_the_coefficients_of_its_run(design):
    """The lanes' coefficient rows and the one-sample kernels' coefficients come from the one list of slots
    (``_rhs.coefficients_by``): every slot of every lane, and the inverses of the divisors."""
    params = np.array(
        [build_model(design, 1000.0 + 400.0 * lane, 7000.0, 20e3 + 1e3 * lane).parameters for lane in range(LANES)]
    )
    params[:, list(_rhs.COEFFICIENT_SLOTS)] += np.arange(LANES)[:, None] * 1e-3  # each lane its own numbers

    @nb.njit
    def read(params):
        W = np.zeros(_lane_loop.N_ROWS * LANES)
        for lane in range(LANES):
            _lane_loop.put_coefficients(W, lane, params[lane])
        out = np.empty((LANES, _rhs.N_COEFFICIENTS + 3))
        for lane in range(LANES):
            c, inverse = _lane_loop.lane_coefficients(W, lane)
            for k in range(_rhs.N_COEFFICIENTS):
                out[lane, k] = c[k]
            for k in range(3):
                out[lane, _rhs.N_COEFFICIENTS + k] = inverse[k]
        return out

    rows = read(params)
    for lane in range(LANES):
        p = params[lane]
        assert rows[lane, : _rhs.N_COEFFICIENTS].tolist() == list(_rhs.coefficients(p))
        assert rows[lane, : _rhs.N_COEFFICIENTS].tolist() == [p[slot] for slot in _rhs.COEFFICIENT_SLOTS]
        assert rows[lane, _rhs.N_COEFFICIENTS :].tolist() == [1 / p[_rhs.M1], 1 / p[_rhs.M2], 1 / p[_rhs.ME]]
