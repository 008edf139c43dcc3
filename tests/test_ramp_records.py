"""Tests of run-up and coast-down records: the format, the speed bins they are cut into, and their readers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr

from uqgear.calibration import Calibration
from uqgear.calibration.outputs import write_calibration
from uqgear.cli import main
from uqgear.common.errors import OperatingPointError, RigDataError
from uqgear.diagnosis import diagnose
from uqgear.physics.effects import make_effect
from uqgear.rig.features import extract_features
from uqgear.rig.format import make_ramp_dataset, make_rig_dataset, read_rig, validate_rig, write_rig
from uqgear.rig.ramp_format import reversal
from uqgear.rig.ramp_records import (
    MAX_SPEED_CHANGE,
    RESOLVED_GEAR_REVOLUTIONS,
    ramp_operating_points,
    segment_notes,
    steady_campaign,
)
from uqgear.rig.virtual_rig import simulate_campaign
from uqgear.rig.virtual_runup import join_campaigns, simulate_runup_campaign

FS = 20480.0
#: Mesh-harmonic amplitudes of the synthetic transmission error, m (known truth).
AMPLITUDES = (2.0e-6, 0.8e-6, 0.3e-6)


def _order_signal(design, speed: np.ndarray, fs: float) -> np.ndarray:
    """Mesh harmonics of constant amplitude that follow the pinion angle integrated from ``speed`` (rpm)."""
    rate = 2.0 * math.pi * speed / 60.0
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) / fs)])
    return sum(a * np.cos((k + 1) * design.z1 * angle + 0.3 * k) for k, a in enumerate(AMPLITUDES))


def _ramps(design, speeds: np.ndarray, fs: float = FS) -> xr.Dataset:
    time = np.arange(speeds.shape[1]) / fs
    te = np.stack([_order_signal(design, speed, fs) for speed in speeds])
    return make_ramp_dataset(
        time=time,
        pinion_speed_signal=speeds,
        drive_torque=np.full(len(speeds), 7000.0),
        adhesion_torque_lower=np.full(len(speeds), 28000.0),
        adhesion_torque_upper=np.full(len(speeds), 38000.0),
        channels={"te": te},
        design=design,
        title="synthetic run-up",
        source="tests",
        history="",
    )


@pytest.fixture(scope="module")
def run_up(design) -> xr.Dataset:
    # 1000 -> 2000 rpm in 10 s with a 0.5 % tachometer ripple at 3 Hz
    time = np.arange(int(10 * FS)) / FS
    speed = 1000.0 + 100.0 * time + 5.0 * np.sin(2 * math.pi * 3.0 * time)
    return _ramps(design, speed[None, :])


def _steady(design, speeds, size: int) -> xr.Dataset:
    time = np.arange(size) / FS
    te = np.stack([_order_signal(design, np.full(size, speed), FS) for speed in speeds])
    return make_rig_dataset(
        time=time,
        pinion_speed=speeds,
        drive_torque=np.full(len(speeds), 7000.0),
        adhesion_torque_lower=np.full(len(speeds), 28000.0),
        adhesion_torque_upper=np.full(len(speeds), 38000.0),
        channels={"te": te - te.mean(axis=1, keepdims=True)},
        design=design,
        title="synthetic steady runs",
        source="tests",
        history="",
    )


def test_ramp_records_round_trip_alone_and_beside_steady_runs(design, run_up, tmp_path):
    steady = _steady(design, [1200.0, 1800.0], 4096)
    mixed = xr.merge([steady, run_up], combine_attrs="override")
    for name, ds in (("ramps", run_up), ("mixed", mixed)):
        back = read_rig(write_rig(tmp_path / f"{name}.nc", ds))
        assert dict(back.sizes) == dict(ds.sizes)
        for variable in ds.data_vars:
            np.testing.assert_array_equal(back[variable].values, ds[variable].values.astype(np.float32))
            assert back[variable].attrs["units"] == ds[variable].attrs["units"]
        for coordinate in ds.coords:
            np.testing.assert_array_equal(back[coordinate].values, ds[coordinate].values)
    assert "op" not in read_rig(tmp_path / "ramps.nc").dims


def _without_tachometer(ds):
    return ds.drop_vars("ramp_pinion_speed_signal")


def _reversing(ds):
    speed = ds["ramp_pinion_speed_signal"].values.copy()
    half = speed.shape[1] // 2
    speed[:, half:] = speed[:, half][:, None] - 0.5 * (speed[:, half:] - speed[:, half][:, None])
    return ds.assign(ramp_pinion_speed_signal=ds["ramp_pinion_speed_signal"].copy(data=speed))


def _with_nan(ds):
    speed = ds["ramp_pinion_speed_signal"].values.copy()
    speed[0, 100] = np.nan
    return ds.assign(ramp_pinion_speed_signal=ds["ramp_pinion_speed_signal"].copy(data=speed))


def _non_positive(ds):
    return ds.assign(ramp_pinion_speed_signal=ds["ramp_pinion_speed_signal"] - 1500.0)


def _fast(ds):
    # 3 z1 n / 60 at 2000 rpm is 2100 Hz: 4 kHz of sampling does not resolve it
    return ds.assign_coords(ramp_time=ds["ramp_time"] * 5.12)


def _no_torque(ds):
    return ds.drop_vars("ramp_drive_torque")


@pytest.mark.parametrize(
    ("break_it", "message"),
    [
        (_without_tachometer, r"ramp_pinion_speed_signal: missing; a run-up or coast-down record needs"),
        (_reversing, r"ramp_pinion_speed_signal: ramp 0 reverses at sample \d+"),
        (_with_nan, r"ramp_pinion_speed_signal: ramp 0 has NaN"),
        (_non_positive, r"ramp_pinion_speed_signal: ramp 0 reaches -\d+ rpm; expected speeds > 0"),
        (_fast, r"ramp_time: sampling rate 4000 Hz does not resolve the third mesh harmonic"),
        (_no_torque, r"ramp_drive_torque: missing coordinate"),
    ],
    ids=["no speed reference", "reversing speed", "NaN speed", "speed <= 0", "undersampled", "no torque"],
)
def test_bad_ramp_records_are_refused_naming_the_variable(run_up, tmp_path, break_it, message):
    broken = break_it(run_up.copy(deep=True))
    with pytest.raises(RigDataError, match=message):
        validate_rig(broken, where="campaign.nc")
    # the file is refused on reading with its path in the message
    path = tmp_path / "broken.nc"
    broken.drop_encoding().to_netcdf(path, engine="netcdf4")
    with pytest.raises(RigDataError, match=str(path)):
        read_rig(path)


def test_reversal_is_the_step_back_against_the_ramp_direction():
    coast_down = np.array([3000.0, 2500.0, 2600.0, 1000.0])
    assert reversal(coast_down) == (pytest.approx(100.0 / 2000.0), 2)
    assert reversal(np.linspace(1000.0, 2000.0, 50)) == (0.0, 0)


def test_segments_follow_the_rules_and_match_steady_records_at_their_speed(design, run_up):
    ops = ramp_operating_points(run_up, segments=6)
    size, speeds = ops.sizes["time"], ops["pinion_speed"].values
    assert ops.sizes["op"] == 6 and list(ops["op_source"].values) == ["ramp 0"] * 6
    # evenly spaced up to the 5 rpm ripple, each at least 2 revolutions long, sweeping at most 5 % of its speed
    np.testing.assert_allclose(np.diff(speeds), np.diff(speeds).mean(), atol=2 * 5.0 + 1.0)
    assert size / FS >= 2 * 60.0 / speeds.min()
    assert np.all(100.0 * size / FS <= MAX_SPEED_CHANGE * speeds * 1.02)
    np.testing.assert_allclose(ops["pinion_speed_signal"].mean("time").values, speeds)
    # the features of each segment equal those of a steady record at its mean speed, and the truth
    ramp_features = extract_features(ops, design, channels=["te"])["te"]
    steady_features = extract_features(_steady(design, speeds, size), design, channels=["te"])["te"]
    assert bool(ramp_features["order_tracked"].all())
    for harmonic, amplitude in enumerate(AMPLITUDES, start=1):
        ramp_line = ramp_features.sel(feature=f"mesh{harmonic}").values
        steady_line = steady_features.sel(feature=f"mesh{harmonic}").values
        np.testing.assert_allclose(ramp_line, steady_line, rtol=0.01)
        np.testing.assert_allclose(ramp_line, amplitude, rtol=0.01)


def test_a_coast_down_gives_segments_in_falling_speed(design):
    time = np.arange(int(6 * FS)) / FS
    ops = ramp_operating_points(_ramps(design, (2500.0 - 150.0 * time)[None, :]), segments=5)
    assert np.all(np.diff(ops["pinion_speed"].values) < 0)


def test_mixed_campaign_segments_take_the_steady_length_and_say_where_they_come_from(design, run_up):
    steady = _steady(design, [1200.0, 1800.0], 4096)
    mixed = steady_campaign(xr.merge([steady, run_up], combine_attrs="override"))
    validate_rig(mixed)
    assert mixed.sizes["time"] == 4096 and mixed.sizes["op"] == 2 + 8
    assert list(mixed["op_source"].values) == ["steady"] * 2 + ["ramp 0"] * 8
    assert not any(name.startswith("ramp") for name in mixed.variables)
    # steady runs without a tachometer keep reading their angle from the signals
    assert bool(mixed["pinion_speed_signal"].isel(op=[0, 1]).isnull().all())
    features = extract_features(mixed, design, channels=["te"])["te"]
    np.testing.assert_allclose(features.sel(feature="mesh1").values, AMPLITUDES[0], rtol=0.01)
    # 1 s steady records: a segment that long sweeps 100 rpm, 10 % at 1000 rpm
    long_steady = _steady(design, [1200.0], int(FS))
    with pytest.raises(RigDataError, match=r"ramp_pinion_speed_signal: ramp 0: a segment of 1 s changes speed by"):
        steady_campaign(xr.merge([long_steady, run_up], combine_attrs="override"))


def test_ramps_over_one_span_share_eight_points_and_take_turns_along_the_speeds(design):
    """A run-up and a coast-down over 1000 <-> 2000 rpm: 4 segments each at 8 distinct, evenly spaced speeds."""
    time = np.arange(int(4 * FS)) / FS
    ramps = _ramps(design, np.stack([1000.0 + 250.0 * time, 2000.0 - 250.0 * time]))
    ops = ramp_operating_points(ramps)
    assert list(ops["op_source"].values) == ["ramp 0"] * 4 + ["ramp 1"] * 4
    up, down = ops["pinion_speed"].values[:4], ops["pinion_speed"].values[4:]
    assert np.all(np.diff(up) > 0) and np.all(np.diff(down) < 0)
    speeds = np.sort(ops["pinion_speed"].values)
    # the run-up takes the 1st, 3rd, ... of the 8 speeds, the coast-down the 2nd, 4th, ...
    np.testing.assert_allclose(speeds[0::2], np.sort(up), rtol=0, atol=0)
    np.testing.assert_allclose(np.diff(speeds), np.diff(speeds).mean(), atol=2.0)
    # as one ramp over the span is cut
    one = ramp_operating_points(ramps.isel(ramp=[0]))["pinion_speed"].values
    np.testing.assert_allclose(speeds, one, atol=2.0)
    # segments given: each ramp over its own span
    assert ramp_operating_points(ramps, segments=8).sizes["op"] == 16


def test_segment_rules_are_checked_where_the_length_is_given(run_up):
    with pytest.raises(RigDataError, match=r"fewer than 2 pinion revolutions at 10\d\d rpm"):
        ramp_operating_points(run_up, segment_duration=0.1)
    with pytest.raises(RigDataError, match=r"segments: expected a whole number"):
        ramp_operating_points(run_up, segments=0)


# --------------------------------------------------------------------------- virtual rig run-ups


def test_virtual_slow_run_up_gives_the_features_of_steady_runs_at_the_segment_speeds(design):
    """100 rpm/s from 1000 to 2000 rpm: the segments' mesh harmonics within 3 % of steady runs (measured: 1.2 %)."""
    truth = {"adhesion_torque": [33000.0]}
    ramps = {"start_speed": [1000.0], "stop_speed": [2000.0], "rate": [100.0], "drive_torque": [7000.0]}
    campaign = simulate_runup_campaign(design, ramps, true_parameters=truth, relative_noise=0.0, seed=1)
    validate_rig(campaign)
    ops = ramp_operating_points(campaign, segments=5)
    speeds = ops["pinion_speed"].values
    steady = simulate_campaign(
        design,
        {"pinion_speed": speeds, "drive_torque": np.full(5, 7000.0)},
        true_parameters={"adhesion_torque": np.full(5, 33000.0)},
        relative_noise=0.0,
        duration=ops.sizes["time"] / FS,
        run_in=0.5,
        seed=2,
    )
    ramp_features, steady_features = extract_features(ops, design), extract_features(steady, design)
    for channel in ("te", "acc_pinion", "acc_gear"):
        for harmonic in (1, 2, 3):
            np.testing.assert_allclose(
                ramp_features[channel].sel(feature=f"mesh{harmonic}").values,
                steady_features[channel].sel(feature=f"mesh{harmonic}").values,
                rtol=0.03,
                err_msg=f"{channel} mesh{harmonic}",
            )
    # the tachometer is the simulated speed: the ramp's, to the sample
    tachometer = campaign["ramp_pinion_speed_signal"].values[0]
    np.testing.assert_allclose(tachometer, 1000.0 + 100.0 * campaign["ramp_time"].values, rtol=1e-6)


def test_virtual_run_up_is_seeded_and_refuses_what_the_speed_varying_model_does_not_take(design, tmp_path):
    ramps = {
        "start_speed": [1500.0, 1800.0],
        "stop_speed": [1700.0, 1600.0],
        "rate": [200.0, 200.0],
        "drive_torque": [7000.0, 6000.0],
    }
    first = simulate_runup_campaign(
        design, ramps, seed=5, channels=["te", "acc_gear"], encoder_run_out={"pinion": 1e-6}
    )
    again = simulate_runup_campaign(
        design, ramps, seed=5, channels=["te", "acc_gear"], encoder_run_out={"pinion": 1e-6}
    )
    assert dict(first.sizes) == {"ramp": 2, "ramp_time": 20480}
    np.testing.assert_array_equal(first["ramp_te"].values, again["ramp_te"].values)
    assert np.all(np.diff(first["ramp_pinion_speed_signal"].values[1]) < 0)  # the second is a coast-down
    truth = json.loads(first.attrs["true_parameters"])["ramp_adhesion_torque"]
    assert np.all((first["ramp_adhesion_torque_lower"] <= truth) & (truth <= first["ramp_adhesion_torque_upper"]))
    # read as operating points, the truth follows the segments
    ops = steady_campaign(read_rig(write_rig(tmp_path / "ramps.nc", first)))
    # two ramps share the 8 points, 4 each
    assert json.loads(ops.attrs["true_parameters"])["adhesion_torque"] == [truth[0]] * 4 + [truth[1]] * 4
    with pytest.raises(OperatingPointError, match="pitch_errors: the speed-varying model"):
        simulate_runup_campaign(design, ramps, pitch_errors=7)
    with pytest.raises(OperatingPointError, match="speed_wander: the wandering ramp 1500 -> 1700 rpm is not monotone"):
        simulate_runup_campaign(design, ramps, speed_wander=[(0.05, 5.0)])
    with pytest.raises(OperatingPointError, match="ramps: expected one of rate"):
        simulate_runup_campaign(design, {**ramps, "duration": [1.0, 1.0]})


def test_synth_rig_writes_a_run_up_campaign(tmp_path):
    out = tmp_path / "runup.nc"
    assert main(["synth-rig", "--out", str(out), "--ramp", "1500:1600:400", "--ramp", "1700:1600:400:6000"]) == 0
    campaign = read_rig(out)
    assert campaign.sizes["ramp"] == 2 and campaign["ramp_drive_torque"].values.tolist() == [7000.0, 6000.0]
    assert main(["synth-rig", "--out", str(tmp_path / "bad.nc"), "--ramp", "1500:1600"]) == 2


def test_calibration_of_a_run_up_beside_steady_runs_holds_the_truth(design, tmp_path):
    """One ramp 1200 -> 3600 rpm at 200 rpm/s with wander beside two steady runs: the stiffness scale and the STE
    amplitude inside their 90 % intervals widened by 1 % of the value (the segments' mesh harmonics differ from
    steady runs' by up to ~1 %); the mesh damping, which the calibration reads from the segments' harmonics as
    though they were steady runs', within 8 % of the truth (docs/validation/calibration.md, "Run-up campaigns":
    its median lies 5-6 % low on this campaign)."""
    truth = {"mesh_stiffness_scale": 1.06, "zeta_mesh": 0.058, "ste_amplitude": 13.5e-6}
    ramps = simulate_runup_campaign(
        design,
        {"start_speed": [1200.0], "stop_speed": [3600.0], "rate": [200.0], "drive_torque": [7000.0]},
        true_parameters=truth,
        seed=11,
        speed_wander=[(0.002, 1.0)],
    )
    # the steady records' length sets the segments' (0.125 s: 5 % of 1200 rpm at 200 rpm/s is 0.3 s)
    steady = simulate_campaign(
        design,
        {"pinion_speed": [1500.0, 3000.0], "drive_torque": [7000.0, 7000.0]},
        true_parameters=truth,
        seed=12,
        duration=0.125,
        run_in=0.3,
    )
    path = write_rig(tmp_path / "mixed.nc", join_campaigns(steady, ramps))
    calibration = Calibration(
        tuple(truth), n_training=64, stage_steps=400, chunk_steps=1000, max_steps=8000, predictive_draws=4, seed=3
    ).fit(path)
    assert calibration.converged_, calibration.diagnostics_["reasons"]
    for name, value in truth.items():
        entry = calibration.summary_["parameters"][name]
        if name == "zeta_mesh":
            assert abs(entry["q50"] - value) <= 0.08 * value, (name, entry)
        else:
            assert entry["q05"] - 0.01 * value <= value <= entry["q95"] + 0.01 * value, (name, entry)
    assert [row["source"] for row in calibration.speed_] == ["steady"] * 2 + ["ramp 0"] * 8
    paths = write_calibration(calibration, tmp_path / "out")
    assert [row["source"] for row in json.loads(paths["json"].read_text())["speed"]][-1] == "ramp 0"


def test_diagnosis_of_a_run_up_names_the_effect_of_steady_runs(design, tmp_path):
    """Pinion eccentricity of 30 um on a 1500 -> 3000 rpm run-up: the diagnosis names it, as from steady runs."""
    effects = [make_effect("eccentricity", {"amplitude": 30e-6})]
    ramps = {"start_speed": [1500.0], "stop_speed": [3000.0], "rate": [300.0], "drive_torque": [7000.0]}
    campaign = simulate_runup_campaign(design, ramps, effects=effects, seed=4)
    content = diagnose(
        write_rig(tmp_path / "runup.nc", campaign), tmp_path / "out", effects=["eccentricity"], workers=1, report=False
    )
    assert content["verdict"] == "eccentricity", content["reason"]
    record = json.loads((tmp_path / "out" / "diagnosis.json").read_text())
    assert [row["source"] for row in record["rig"]["speed"]] == ["ramp 0"] * 8
    # 300 rpm/s from 1500 rpm: segments of 0.25 s hold 1.3 gear revolutions, which the record says
    (note,) = record["rig_notes"]
    assert "gear revolutions (operating point 0" in note and "ramp 0" in note


def _cut(size: int, speeds: list[float], sources: list[str], fs: float = 20480.0) -> xr.Dataset:
    coords = {"time": np.arange(size) / fs, "pinion_speed": ("op", speeds), "op_source": ("op", sources)}
    return xr.Dataset(coords=coords)


def test_segment_notes_name_the_shortest_ramp_segment_and_the_rate_that_resolves_the_gear(design):
    ratio = design.z1 / design.z2
    # 0.25 s at 1500 and 3000 rpm: 1.30 and 2.60 gear revolutions; the note names the first
    (note,) = segment_notes(_cut(5120, [3000.0, 1500.0], ["ramp 0", "ramp 1"]), design)
    revolutions = 0.25 * 1500.0 / 60.0 * ratio
    assert f"as few as {revolutions:.2f} gear revolutions (operating point 1, 1500 rpm, ramp 1)" in note
    # the rate: RESOLVED_GEAR_REVOLUTIONS gear revolutions within MAX_SPEED_CHANGE of speed change
    length = RESOLVED_GEAR_REVOLUTIONS * 60.0 / (1500.0 * ratio)
    assert f"at most {MAX_SPEED_CHANGE * 1500.0 / length:.0f} rpm/s at 1500 rpm" in note
    # long enough segments, steady runs and a campaign without op_source get none
    assert segment_notes(_cut(20480, [1500.0, 3000.0], ["ramp 0", "ramp 0"]), design) == []
    assert segment_notes(_cut(1024, [600.0, 800.0], ["steady", "steady"]), design) == []
    assert segment_notes(xr.Dataset(coords={"time": np.arange(8) / 8.0}), design) == []
