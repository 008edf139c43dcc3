"""Order tracking: speed profiles and order amplitudes recovered from records at a wandering speed.

The checks are against known truth: synthetic records built as lines at
known orders of a known shaft-angle history, and virtual-rig campaigns whose
only difference is the speed wander (same seed, same truth, same noise).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.common.errors import StudyError
from uqgear.rig.features import extract_features, line_amplitudes
from uqgear.rig.order_tracking import (
    estimate_pinion_angle,
    resample_to_angle,
    speed_summary,
    tachometer_angle,
    track_orders,
)
from uqgear.rig.virtual_rig import simulate_campaign

FS = 20480.0
N = 20480
TIME = np.arange(N) / FS
Z1 = 21
# mesh harmonics, pinion-order sidebands (run-out) and a shaft line, with their amplitudes
LINES = {21.0: 1.0, 42.0: 0.3, 63.0: 0.1, 20.0: 0.05, 22.0: 0.04, 1.0: 0.02}


def _record(speed: float, rate_of_time, noise: float = 0.01, seed: int = 0):
    """Two channels of lines at LINES' orders of the pinion angle, and the true speed in rpm."""
    rate = 2.0 * math.pi * speed / 60.0 * rate_of_time(TIME)
    angle = np.concatenate([[0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) / FS)])
    first = sum(a * np.cos(order * angle + 0.1 * order) for order, a in LINES.items())
    second = sum(0.5 * a * np.cos(order * angle + 0.2 * order + 1.0) for order, a in LINES.items())
    rng = np.random.default_rng(seed)
    first = first + noise * first.std() * rng.standard_normal(N)
    second = second + noise * second.std() * rng.standard_normal(N)
    return np.stack([first, second]), rate * 60.0 / (2.0 * math.pi)


PROFILES = {
    "sine 1 % at 1 Hz, 1500 rpm": (1500.0, lambda t: 1.0 + 0.01 * np.sin(2 * np.pi * 1.0 * t + 0.3)),
    "sine 1 % at 4 Hz, 3800 rpm": (3800.0, lambda t: 1.0 + 0.01 * np.sin(2 * np.pi * 4.0 * t + 0.3)),
    "sine 0.3 % at 0.8 Hz, 600 rpm": (600.0, lambda t: 1.0 + 0.003 * np.sin(2 * np.pi * 0.8 * t + 0.3)),
    "chirp 2 % over the record, 1500 rpm": (1500.0, lambda t: 1.0 + 0.02 * (t - 0.5)),
}


@pytest.mark.parametrize("name", list(PROFILES))
def test_speed_profile_and_order_amplitudes_are_recovered(name):
    speed, profile = PROFILES[name]
    records, true_speed = _record(speed, profile)
    estimate = estimate_pinion_angle(list(records), ["a", "b"], FS, speed, Z1, band_limit=8000.0)
    assert estimate.angle is not None and "a:mesh1" in estimate.lines
    estimated_speed = np.gradient(estimate.angle) * FS * 60.0 / (2.0 * math.pi)
    interior = slice(N // 10, N - N // 10)
    assert np.max(np.abs(estimated_speed[interior] / true_speed[interior] - 1.0)) < 5e-4
    resampled = resample_to_angle(records, estimate.angle)
    mean_speed = estimate.angle[-1] / ((N - 1) / FS) * 60.0 / (2.0 * math.pi)
    signal = xr.DataArray(resampled[0], dims="time", coords={"time": TIME})
    amplitudes = line_amplitudes(signal, mean_speed, list(LINES)).values
    assert np.allclose(amplitudes, list(LINES.values()), rtol=0.01, atol=0.0)
    # without tracking the same lines are smeared far beyond that
    raw = line_amplitudes(xr.DataArray(records[0], dims="time", coords={"time": TIME}), speed, [63.0]).values
    assert abs(raw[0] / LINES[63.0] - 1.0) > 0.1


def test_a_two_percent_sine_keeps_order_amplitudes():
    records, _ = _record(1500.0, lambda t: 1.0 + 0.02 * np.sin(2 * np.pi * 2.0 * t + 0.3))
    estimate = estimate_pinion_angle(list(records), ["a", "b"], FS, 1500.0, Z1, band_limit=8000.0)
    resampled = resample_to_angle(records, estimate.angle)
    mean_speed = estimate.angle[-1] / ((N - 1) / FS) * 60.0 / (2.0 * math.pi)
    amplitudes = line_amplitudes(xr.DataArray(resampled[1], dims="time", coords={"time": TIME}), mean_speed,
                                 list(LINES)).values
    assert np.allclose(amplitudes, 0.5 * np.array(list(LINES.values())), rtol=0.01, atol=0.0)


def _dataset(records: np.ndarray, speed: float) -> xr.Dataset:
    return xr.Dataset({"te": (("op", "time"), records[:1]), "acc_pinion": (("op", "time"), records[1:])},
                      coords={"time": TIME, "pinion_speed": ("op", [speed])})


def test_constant_speed_records_are_left_as_they_are(design):
    records, _ = _record(1500.0, lambda t: np.ones_like(t))
    signals = _dataset(records, 1500.0)
    tracked = track_orders(signals, design)
    assert not bool(tracked["order_tracked"].values[0])
    assert np.array_equal(tracked["te"].values, signals["te"].values)
    assert float(tracked["pinion_speed"].values[0]) == 1500.0
    assert tracked["speed_mean"].values[0] == pytest.approx(1500.0, rel=1e-5)
    plain = extract_features(signals, design, order_tracking="never")
    auto = extract_features(signals, design)
    assert np.array_equal(plain["te"].values, auto["te"].values, equal_nan=True)


def test_a_wrong_stated_speed_is_corrected(design):
    records, _ = _record(1497.0, lambda t: np.ones_like(t))
    tracked = track_orders(_dataset(records, 1500.0), design)
    assert bool(tracked["order_tracked"].values[0])
    # the mean rests on the angle at the record ends, the least certain part: 0.005 % is a
    # thirtieth of a bin at the third mesh harmonic
    assert float(tracked["pinion_speed"].values[0]) == pytest.approx(1497.0, rel=5e-5)
    assert float(tracked["pinion_speed_stated"].values[0]) == 1500.0
    row = speed_summary(tracked)[0]
    assert row["stated_rpm"] == 1500.0 and row["order_tracked"]


def test_a_tachometer_channel_is_integrated(design):
    records, true_speed = _record(1500.0, lambda t: 1.0 + 0.01 * np.sin(2 * np.pi * 1.0 * t))
    estimate = tachometer_angle(true_speed, FS)
    assert np.allclose(np.gradient(estimate.angle) * FS * 60 / (2 * math.pi), true_speed, rtol=1e-4)
    signals = _dataset(records, 1500.0)
    signals["pinion_speed_signal"] = (("op", "time"), true_speed[None])
    tracked = track_orders(signals, design)
    assert str(tracked["speed_reference"].values[0]) == "pinion_speed_signal"
    assert bool(tracked["order_tracked"].values[0])


def test_noise_alone_gives_no_estimate_and_no_resampling(design):
    rng = np.random.default_rng(3)
    signals = _dataset(rng.standard_normal((2, N)), 1500.0)
    tracked = track_orders(signals, design)
    assert not bool(tracked["order_tracked"].values[0])
    assert np.isnan(tracked["speed_mean"].values[0])
    assert "30 dB" in str(tracked["speed_reference"].values[0])
    with pytest.raises(uqgear.RigDataError, match="cannot estimate the pinion angle"):
        track_orders(signals, design, mode="always")
    with pytest.raises(StudyError, match="order_tracking: expected one of auto, always, never"):
        extract_features(signals, design, order_tracking="sometimes")



def test_virtual_rig_wander_is_undone_by_tracking(design):
    """Same campaign with and without +-1 % wander at 1.3 Hz: tracked mesh lines agree to 1 % (or the noise)."""
    ops = {"pinion_speed": [1700.0, 3400.0], "drive_torque": [8000.0, 5500.0]}
    options = {"seed": 11, "duration": 1.0, "run_in": 0.2, "line_interference": {50.0: 0.5, 150.0: 0.2}}
    steady = simulate_campaign(design, ops, **options)
    wandering = simulate_campaign(design, ops, speed_wander=[(0.01, 1.3)], **options)
    names = ["mesh1", "mesh2", "mesh3"]
    reference = extract_features(steady, design, order_tracking="never")
    smeared = extract_features(wandering, design, order_tracking="never")
    tracked = extract_features(wandering, design)
    assert tracked["order_tracked"].values.all()
    low, high = tracked["speed_min"].values, tracked["speed_max"].values
    assert np.allclose(low / ops["pinion_speed"], 0.99, atol=1e-3)
    assert np.allclose(high / ops["pinion_speed"], 1.01, atol=1e-3)
    for channel in ("te", "acc_pinion", "acc_gear"):
        expected = reference[channel].sel(feature=names).values
        noise = 3.0 * reference[channel].sel(feature="noise_std").values[:, None] * math.sqrt(2.0 * 2.0 / N)
        got = tracked[channel].sel(feature=names).values
        assert np.all(np.abs(got - expected) <= np.maximum(0.01 * expected, noise)), channel
        assert np.any(np.abs(smeared[channel].sel(feature=names).values / expected - 1.0) > 0.2)


@pytest.mark.parametrize("options, message", [
    ({"speed_wander": [(0.01,)]}, r"speed_wander\[0\]: expected \(relative amplitude, frequency in Hz\)"),
    ({"speed_wander": [(0.5, 1.0)]}, r"speed_wander\[0\]: expected a relative amplitude in \[0, 0.2\); got 0.5"),
    ({"speed_wander": [(0.01, 0.0)]}, r"speed_wander\[0\]: expected a frequency > 0 Hz; got 0.0"),
    ({"line_interference": {20000.0: 0.5}}, r"line_interference: expected frequencies in \(0, fs/2\) Hz"),
    ({"line_interference": {50.0: -1.0}}, r"line_interference.50: expected an amplitude >= 0 m s-2; got -1.0"),
])
def test_virtual_rig_nuisance_options_are_checked(design, options, message):
    with pytest.raises(uqgear.OperatingPointError, match=message):
        simulate_campaign(design, {"pinion_speed": [1500.0], "drive_torque": [6000.0]}, seed=1, **options)


def test_a_tachometer_variable_in_a_rig_file_is_checked(design, tmp_path):
    rig = uqgear.read_rig(uqgear.example_rig_file("healthy"))
    good = rig.assign(pinion_speed_signal=(("op", "time"),
                                           np.broadcast_to(rig["pinion_speed"].values[:, None], rig["te"].shape),
                                           {"units": "rpm", "long_name": "instantaneous pinion speed"}))
    path = uqgear.write_rig(tmp_path / "tacho.nc", good)
    assert "pinion_speed_signal" in uqgear.read_rig(path).data_vars
    with pytest.raises(uqgear.RigDataError, match=r"pinion_speed_signal: expected dims \('op', 'time'\)"):
        uqgear.write_rig(tmp_path / "bad.nc", good.assign(pinion_speed_signal=good["pinion_speed_signal"].isel(time=0)))
    with pytest.raises(uqgear.RigDataError, match="pinion_speed_signal"):
        uqgear.write_rig(tmp_path / "bad_units.nc", good.assign(
            pinion_speed_signal=good["pinion_speed_signal"].assign_attrs(units="Hz")))


def _modulated(design, speed: float, amplitudes, depth: float, phase_depth: float, phase: float) -> np.ndarray:
    """One channel at constant speed: mesh harmonics amplitude- and phase-modulated once per gear revolution."""
    shaft = 2.0 * math.pi * speed / 60.0
    gear = shaft * design.z1 / design.z2
    record = np.zeros(N)
    for k, amplitude in enumerate(amplitudes, start=1):
        modulation = phase_depth * np.sin(gear * TIME + phase + 0.7)
        envelope = amplitude * (1.0 + depth * np.cos(gear * TIME + phase))
        record += envelope * np.cos(k * design.z1 * shaft * TIME + 0.3 * k + modulation)
    return record


@pytest.mark.parametrize("speed, strengths", [(2800.0, ([1.0, 3.0, 0.5], [0.5, 2.0, 0.8])),
                                               (1200.0, ([2.0, 0.4, 0.2], [0.3, 0.2, 0.1]))])
def test_the_tracker_image_takes_from_a_model_record_what_the_tracker_takes(design, speed, strengths):
    """A constant-speed record with gear-order sidebands, resampled on its own mesh lines, loses part of them.

    The first-order image (TrackerImage, with the weights the tracker reports)
    applied to the record's phasors gives the sidebands resampling it gives
    (the tracker itself): within 7 % of each (2 % at the higher speed; at the
    lower one the demodulation filter's transients fill more of the record)
    and with at most a fifth of the error of reading the record untracked,
    while doing nothing to the mesh lines.
    """
    from uqgear.diagnosis.case import FEATURE_OPTIONS
    from uqgear.diagnosis.processing import RunProcessor
    from uqgear.rig.order_tracking import accelerations, tracker_image

    channels = ("acc_pinion", "acc_gear")
    records = np.stack([
        _modulated(design, speed, strengths[0], 0.004, 0.006, 0.2),
        _modulated(design, speed, strengths[1], 0.003, 0.005, 1.0),
    ])
    records = records + 1e-5 * np.random.default_rng(1).standard_normal(records.shape)
    variables = {name: (("op", "time"), records[c][None], {"units": "m s-2"}) for c, name in enumerate(channels)}
    signals = xr.Dataset(variables, coords={"time": TIME, "op": [0]})
    signals["pinion_speed"] = ("op", [speed])
    tracked = track_orders(signals, design, mode="always")
    row = speed_summary(tracked)[0]
    image = tracker_image(row, channels, design.z1, accelerations(tracked, channels))
    assert image is not None and math.isclose(sum(image.weights), 1.0)
    processor = RunProcessor(design, speed, FS, N, dict(FEATURE_OPTIONS, band_limit=FS / 2.56))
    resampled = np.stack([np.asarray(tracked[name].values[0]) for name in channels])
    truth = processor.model_features(resampled)
    plain = processor.model_features(records)
    imaged = processor.model_features(records, image)
    sidebands = [processor.columns[f"mesh{k}_sb_gear{sign}1"] for k in (1, 2, 3) for sign in "+-"]
    error = np.abs(imaged[:, sidebands] - truth[:, sidebands])
    assert np.all(error <= (0.02 if speed > 2000.0 else 0.07) * truth[:, sidebands])
    # the tracking took a share of the sidebands the image reproduces, not a rounding
    untracked = np.abs(plain[:, sidebands] - truth[:, sidebands])
    assert np.max(untracked / truth[:, sidebands]) > 0.3
    assert np.sum(error) <= 0.2 * np.sum(untracked)
    meshes = [processor.columns[f"mesh{k}"] for k in (1, 2, 3)]
    assert np.allclose(imaged[:, meshes], plain[:, meshes], rtol=1e-12, atol=0.0)
    # a record resampled on a tachometer takes nothing from the sidebands
    tachometer = {**row, "reference": "pinion_speed_signal", "reference_weights": []}
    assert tracker_image(tachometer, channels, 21, (True, True)) is None
