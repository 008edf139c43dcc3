"""Run-ups on the foreign virtual rig: a slow ramp is the steady rig, the records are rig data, the seeds hold."""

import numpy as np
import pytest

from uqgear.common.errors import OperatingPointError, RigDataError
from uqgear.physics.design import load_design
from uqgear.physics.effects import Eccentricity, Effect
from uqgear.rig.foreign_rig import draw_gears, simulate_foreign_run
from uqgear.rig.foreign_runup import simulate_foreign_ramp, simulate_foreign_runup_campaign
from uqgear.rig.format import read_rig, write_rig
from uqgear.rig.ramp_records import steady_campaign

DESIGN = load_design("locomotive")
GEARS = draw_gears(DESIGN, 6.0, 1)
FS = 20480.0
T1 = 7000.0
T2 = T1 * DESIGN.z2 / DESIGN.z1


def _line(record: np.ndarray, speed: float, harmonic: int) -> float:
    """Amplitude of a mesh harmonic at a constant speed (projection on the record's whole length)."""
    t = np.arange(record.size) / FS
    return 2.0 * abs(np.mean((record - record.mean()) * np.exp(-2j * np.pi * harmonic * DESIGN.z1 * speed / 60 * t)))


@pytest.mark.parametrize("speed", [1000.0, 3400.0])
def test_a_slow_ramp_through_a_speed_records_the_steady_foreign_run_there(speed):
    # 1 rpm/s: the 0.5 s around the speed sweeps 0.5 rpm, so its lines are the steady run's at that speed; the
    # steady run starts late enough (1 s) that the torsional run-in is gone as it is in the ramp's middle
    steady = simulate_foreign_run(DESIGN, speed, T1, T2, gears=GEARS, duration=0.5, start=1.0)
    ramp = simulate_foreign_ramp(DESIGN, speed - 1.0, speed + 1.0, 2.0, T1, T2, gears=GEARS, start=0.3)
    middle, half = ramp["te"].size // 2, int(0.25 * FS)
    part = {name: record[middle - half : middle + half] for name, record in ramp.items()}
    assert abs(part["speed"].mean() - speed) < 0.05
    for channel in ("te", "acc_pinion", "acc_gear"):
        # measured 0.8 % at most on RMS and the first two mesh harmonics; a mesh or a load that ignores the
        # ramp's speed, or a filter of another order, moves them by tens of per cent
        assert np.std(part[channel]) == pytest.approx(np.std(steady[channel]), rel=0.03), channel
        for harmonic in (1, 2):
            assert _line(part[channel], speed, harmonic) == pytest.approx(
                _line(steady[channel], speed, harmonic), rel=0.03
            ), (channel, harmonic)


def test_the_mesh_follows_the_pinion_angle_through_a_fast_ramp():
    # 1500 -> 2500 rpm in 0.5 s: at the sampled pinion angle the mesh fundamental is one line (order z1); a mesh
    # on the start speed's clock would leave it spread over 21 x 0.5 = 10 orders
    clean = simulate_foreign_ramp(DESIGN, 1500.0, 2500.0, 0.5, T1, T2, gears=GEARS, start=0.3)
    angle = np.cumsum(clean["speed"]) / 60.0 / FS * 2 * np.pi
    uniform = np.linspace(angle[0], angle[-1], angle.size)
    te = np.interp(uniform, angle, clean["te"] - clean["te"].mean())
    revolutions = (angle[-1] - angle[0]) / (2 * np.pi)
    spectrum = np.abs(np.fft.rfft(te * np.hanning(te.size)))
    orders = np.fft.rfftfreq(te.size, 1.0 / te.size) / revolutions
    band = (orders > DESIGN.z1 - 0.5) & (orders < DESIGN.z1 + 0.5)
    wide = (orders > DESIGN.z1 - 6) & (orders < DESIGN.z1 + 6)
    assert np.sum(spectrum[band] ** 2) > 0.8 * np.sum(spectrum[wide] ** 2)


@pytest.fixture(scope="module")
def campaign():
    ramps = {
        "start_speed": [1500.0, 2100.0],
        "stop_speed": [2100.0, 1500.0],
        "rate": [600.0, 600.0],
        "drive_torque": [7000.0, 6000.0],
    }
    run_out = Eccentricity({"shaft": "pinion", "amplitude": 20e-6})
    return simulate_foreign_runup_campaign(DESIGN, ramps, gears=GEARS, effects=[run_out], seed=4, run_in=0.2)


def test_a_foreign_run_up_campaign_is_rig_data_cut_into_eight_operating_points(campaign, tmp_path):
    path = write_rig(tmp_path / "foreign_runup.nc", campaign)
    back = read_rig(path)
    assert dict(back.sizes) == {"ramp": 2, "ramp_time": round(1.0 * FS)}
    np.testing.assert_allclose(back["ramp_te"].values, campaign["ramp_te"].values)
    assert back.attrs["foreign_gears"] == campaign.attrs["foreign_gears"]
    points = steady_campaign(back, design=DESIGN)
    assert points.sizes["op"] == 8
    speeds = np.sort(points["pinion_speed"].values)
    assert 1500.0 < speeds[0] and speeds[-1] < 2100.0 and np.all(np.diff(speeds) > 20.0)
    assert sorted(set(points["drive_torque"].values.tolist())) == [6000.0, 7000.0]


def test_the_tachometer_follows_the_ramp_at_its_rate(campaign):
    time = campaign["ramp_time"].values
    for ramp, (start, rate) in enumerate([(1500.0, 600.0), (2100.0, -600.0)]):
        speed = campaign["ramp_pinion_speed_signal"].values[ramp]
        slope, offset = np.polyfit(time, speed, 1)
        # the controller follows the ramp with a constant angle lag and no speed error once its start has settled;
        # measured 0.07 % off the rate (a tachometer off the ramp, e.g. at the set-point's start speed, fails)
        assert slope == pytest.approx(rate, rel=0.005)
        assert offset == pytest.approx(start, abs=2.0)


def test_the_same_seed_gives_the_same_ramp_records_and_another_seed_other_noise():
    ramps = {"start_speed": [1500.0], "stop_speed": [1600.0], "duration": [0.2], "drive_torque": [7000.0]}
    options = {"gears": GEARS, "run_in": 0.1, "speed_wander": [(0.002, 3.0)]}
    first = simulate_foreign_runup_campaign(DESIGN, ramps, seed=9, **options)
    again = simulate_foreign_runup_campaign(DESIGN, ramps, seed=9, **options)
    other = simulate_foreign_runup_campaign(DESIGN, ramps, seed=10, **options)
    for name in ("ramp_te", "ramp_acc_pinion", "ramp_pinion_speed_signal"):
        np.testing.assert_array_equal(first[name].values, again[name].values)
        assert not np.allclose(first[name].values, other[name].values)


class _Unmodelled(Effect):
    name = "unmodelled_on_the_foreign_rig"
    PARAMETERS = {}


@pytest.mark.parametrize(
    ("change", "error", "key"),
    [
        ({"ramps": {"spin": [1.0]}}, OperatingPointError, "ramps.spin"),
        ({"ramps": {"stop_speed": [7000.0]}}, OperatingPointError, "ramps.stop_speed"),
        ({"ramps": {"start_speed": [100.0]}}, OperatingPointError, "ramps.start_speed"),
        ({"ramps": {"stop_speed": [1500.0]}}, OperatingPointError, "stop_speed != start_speed"),
        ({"speed_wander": [(0.05, 20.0)]}, OperatingPointError, "speed_wander"),
        ({"effects": [_Unmodelled()]}, RigDataError, "effects"),
        ({"relative_noise": -0.1}, RigDataError, "relative_noise"),
    ],
)
def test_bad_ramps_and_settings_are_refused_naming_the_key(change, error, key):
    ramps = {"start_speed": [1500.0], "stop_speed": [1600.0], "duration": [0.1], "drive_torque": [7000.0]}
    options = {"gears": GEARS, "run_in": 0.1, **change}
    options["ramps"] = {**ramps, **change.get("ramps", {})}
    with pytest.raises(error, match=key):
        simulate_foreign_runup_campaign(DESIGN, **options)


def test_a_run_out_on_a_foreign_run_up_is_named_against_a_healthy_run_up_reference():
    from uqgear.diagnosis import Diagnosis

    # 2 s from 1500 to 2700 rpm: the diagnosis cuts both campaigns into 8 segments and compares them as steady runs
    ramps = {"start_speed": [1500.0], "stop_speed": [2700.0], "rate": [600.0], "drive_torque": [7000.0]}
    gears = draw_gears(DESIGN, 6.0, 2)
    reference = simulate_foreign_runup_campaign(DESIGN, ramps, gears=gears, seed=1)
    run_out = Eccentricity({"shaft": "pinion", "amplitude": 20e-6})
    test = simulate_foreign_runup_campaign(DESIGN, ramps, gears=gears, effects=[run_out], seed=2)
    summary = Diagnosis(seed=0, workers=1).fit(test, reference=reference).summary_
    assert summary["verdict"] == "eccentricity"
    named = summary["change"]["named"]["parameters"]
    assert named["shaft"] == "pinion" and 10e-6 < named["amplitude"] < 40e-6


def test_a_feature_no_record_half_estimates_has_no_spread_and_no_warning():
    import warnings

    from uqgear.diagnosis.change.detection import _noise_spread

    # (halves, runs, channels, features): the second feature is NaN in every half, as the gear's lines are in
    # segments shorter than a gear revolution; the first has spreads 1 and 3 over the two runs of each campaign
    reference = np.array([[[[1.0, np.nan]]], [[[3.0, np.nan]]]]).repeat(2, axis=1)
    reference[1, 1, 0, 0] = 7.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        spread = _noise_spread(reference, reference, np.array([0, 1]))
    # pooled (1 + 9 + 1 + 9) / 4 = 5, local 1 and 9: sqrt(local + pooled)
    np.testing.assert_allclose(spread[:, 0, 0], np.sqrt([1.0 + 5.0, 9.0 + 5.0]))
    assert np.all(np.isinf(spread[:, 0, 1]))


@pytest.mark.parametrize(("key", "value"), [("duration", 0.0), ("start", 0.01), ("stop_speed", float("nan"))])
def test_one_ramp_refuses_a_length_start_or_speed_it_cannot_run(key, value):
    arguments = {"start_speed": 1500.0, "stop_speed": 1600.0, "duration": 0.1, "start": 0.1, key: value}
    with pytest.raises(RigDataError, match=key):
        simulate_foreign_ramp(
            DESIGN,
            arguments.pop("start_speed"),
            arguments.pop("stop_speed"),
            arguments.pop("duration"),
            T1,
            T2,
            gears=GEARS,
            **arguments,
        )
