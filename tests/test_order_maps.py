"""Order tracking, order maps, ramp envelopes and jumps on synthetic run-ups with known content."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from uqgear.common.errors import UqgearError
from uqgear.dynamics.angle_resampling import OrderTrackingError, angle_from_pulses, angle_from_speed, resample_to_angle
from uqgear.dynamics.order_maps import order_map, order_spectrum
from uqgear.dynamics.ramp_envelopes import RampError, hysteresis_ranges, jump_speeds, ramp_envelope, up_down_envelopes

SAMPLE_RATE = 20480.0
START, STOP, DURATION = 500.0, 3000.0, 5.0
# order -> (amplitude at 500 rpm, at 3000 rpm, phase): order 42 grows linearly with speed
COMPONENTS = {1.0: (0.3, 0.3, 0.4), 21.0: (1.0, 1.0, -1.2), 42.0: (0.2, 0.6, 2.0), 200.0: (0.1, 0.1, 0.7)}
NOISE = 0.05
FIXED_LINE_HZ, FIXED_LINE_AMPLITUDE = 120.0, 0.5
# order 200 is resolvable while 200 * n / 60 <= 0.8 * fs / 2, i.e. up to this speed (rpm)
ORDER_200_LIMIT = 0.8 * 0.5 * SAMPLE_RATE * 60.0 / 200.0


def _amplitude(order: float, speed: np.ndarray) -> np.ndarray:
    low, high, _ = COMPONENTS[order]
    return low + (high - low) * (speed - START) / (STOP - START)


def _ramp(start: float, stop: float, *, seed: int = 7) -> xr.Dataset:
    """A linear speed ramp whose ``te`` holds the COMPONENTS, a fixed-frequency line and white noise."""
    time = np.arange(0.0, DURATION, 1.0 / SAMPLE_RATE)
    speed = start + (stop - start) * time / DURATION
    angle = 2.0 * np.pi / 60.0 * (start * time + 0.5 * (stop - start) / DURATION * time**2)
    signal = np.zeros_like(time)
    for order, (_, _, phase) in COMPONENTS.items():
        signal += _amplitude(order, speed) * np.cos(order * angle + phase)
    signal += FIXED_LINE_AMPLITUDE * np.cos(2.0 * np.pi * FIXED_LINE_HZ * time)
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    signal += NOISE * rng.standard_normal(time.size)
    force = 5e4 + 2e3 * np.cos(21.0 * angle)
    return xr.Dataset(
        {
            "pinion_speed": ("time", speed, {"units": "rpm"}),
            "pinion_angle": ("time", angle, {"units": "rad"}),
            "te": ("time", signal, {"units": "m"}),
            "mesh_force": ("time", force, {"units": "N"}),
        },
        coords={"time": ("time", time, {"units": "s"})},
        attrs={"design_z1": 21},
    )


@pytest.fixture(scope="module")
def runup() -> xr.Dataset:
    return _ramp(START, STOP)


@pytest.fixture(scope="module")
def runup_map(runup) -> xr.Dataset:
    return order_map(runup, ["te", "mesh_force"], [1.0, 21.0, 42.0, 200.0], speed_bins=10)


def test_order_map_recovers_amplitudes_and_phases_in_every_bin(runup_map):
    """Within 1.5 % in amplitude and 0.02 rad in phase, each bin against the truth at its blocks' mean speed."""
    result = runup_map
    assert result["order_amplitude"].dims == ("signal", "pinion_speed", "order")
    assert result["order_amplitude"].attrs["units"] == "te: m; mesh_force: N"
    assert list(result["signal_units"].values) == ["m", "N"]
    assert np.all(result["block_count"].values >= 2)
    speed = result["mean_speed"].values
    for order in (1.0, 21.0, 42.0):
        amplitude = result["order_amplitude"].sel(signal="te", order=order).values
        phase = result["order_phase"].sel(signal="te", order=order).values
        np.testing.assert_allclose(amplitude, _amplitude(order, speed), rtol=0.015)
        wrapped = np.angle(np.exp(1j * (phase - COMPONENTS[order][2])))
        assert np.max(np.abs(wrapped)) < 0.02
    force = result["order_amplitude"].sel(signal="mesh_force", order=21.0).values
    np.testing.assert_allclose(force, 2e3, rtol=1e-3)


def test_order_above_the_resolvable_limit_is_nan(runup_map):
    """Order 200 reads right at low speed and NaN at the bins above 0.8 fs / 2 / 200 * 60 rpm."""
    result = runup_map
    amplitude = result["order_amplitude"].sel(signal="te", order=200.0)
    phase = result["order_phase"].sel(signal="te", order=200.0)
    above = result["bin_lower"].values > ORDER_200_LIMIT
    below = result["bin_upper"].values + 300.0 < ORDER_200_LIMIT  # a block spans < 300 rpm up there
    assert above.sum() >= 2 and below.sum() >= 5
    assert np.all(np.isnan(amplitude.values[above])) and np.all(np.isnan(phase.values[above]))
    np.testing.assert_allclose(amplitude.values[below], 0.1, rtol=0.03)
    assert np.all(result["max_order"].values[above] < 200.0)


def test_fixed_frequency_line_moves_through_the_orders(runup):
    """The 120 Hz line sits at order 7200 / n in the waterfall and stays out of a fixed order it does not cross."""
    waterfall = order_spectrum(runup, "te", max_order=50.0, speed_bins=10)
    spectrum = waterfall["order_spectrum"].sel(signal="te")
    band = spectrum.sel(order=slice(1.5, 18.0))
    peaks = band.idxmax("order").values
    speed = waterfall["mean_speed"].values
    assert np.all(np.diff(peaks) < 0.0)
    fast = speed > 2000.0
    np.testing.assert_allclose(peaks[fast], 60.0 * FIXED_LINE_HZ / speed[fast], atol=0.3)
    # a steady record at 1200 rpm would read the whole line at order 6; on the ramp it crosses order 6 within
    # a block and smears, and in bins away from 1200 rpm order 6 holds nothing of it
    at_six = order_map(runup, "te", [6.0], speed_bins=10)["order_amplitude"].sel(signal="te", order=6.0)
    away = (at_six["bin_upper"].values < 900.0) | (at_six["bin_lower"].values > 1500.0)
    assert away.sum() >= 6
    assert np.all(at_six.values[away] < 0.01 * FIXED_LINE_AMPLITUDE)
    assert np.all(at_six.values < 0.5 * FIXED_LINE_AMPLITUDE)
    # the tracked lines are whole orders in every bin
    assert np.allclose(spectrum.sel(order=21.0).values, 1.0, rtol=0.02)


def test_speed_signal_alone_and_mesh_orders_give_the_same_map(runup, runup_map):
    """No pinion_angle: the integrated pinion_speed gives the same map; mesh orders are pinion orders / z1."""
    from_speed = order_map(runup.drop_vars("pinion_angle"), "te", [21.0, 42.0], speed_bins=10)
    reference = runup_map["order_amplitude"].sel(signal="te", order=[21.0, 42.0]).values
    np.testing.assert_allclose(from_speed["order_amplitude"].sel(signal="te").values, reference, rtol=1e-3)
    mesh = order_map(runup, "te", [1.0, 2.0], speed_bins=10, order_unit="mesh")
    assert mesh.attrs["mesh_order"] == 21 and mesh.attrs["order_unit"] == "mesh"
    np.testing.assert_allclose(mesh["order_amplitude"].sel(signal="te").values, reference, rtol=1e-12)


def test_noise_free_run_up_is_read_to_the_method_error():
    """Without noise or the fixed line, amplitudes within 1e-4 and phases within 1e-4 rad, order 200 included."""
    time = np.arange(0.0, DURATION, 1.0 / SAMPLE_RATE)
    speed = START + (STOP - START) * time / DURATION
    angle = 2.0 * np.pi / 60.0 * (START * time + 0.5 * (STOP - START) / DURATION * time**2)
    signal = sum(_amplitude(k, speed) * np.cos(k * angle + phase) for k, (_, _, phase) in COMPONENTS.items())
    run = xr.Dataset({"pinion_angle": ("time", angle), "te": ("time", signal)}, coords={"time": time})
    result = order_map(run, "te", list(COMPONENTS), speed_bins=10)
    for order, (_, _, phase) in COMPONENTS.items():
        amplitude = result["order_amplitude"].sel(signal="te", order=order).values
        read = np.isfinite(amplitude)
        assert read.sum() >= 7
        truth = _amplitude(order, result["mean_speed"].values[read])
        np.testing.assert_allclose(amplitude[read], truth, rtol=1e-4)
        error = np.angle(np.exp(1j * (result["order_phase"].sel(signal="te", order=order).values[read] - phase)))
        assert np.max(np.abs(error)) < 1e-4


def test_coast_down_reads_the_same_components():
    coast = _ramp(STOP, START, seed=11)
    result = order_map(coast, "te", [21.0, 42.0], speed_bins=8)
    speed = result["mean_speed"].values
    np.testing.assert_allclose(
        result["order_amplitude"].sel(signal="te", order=42.0).values, _amplitude(42.0, speed), rtol=0.015
    )
    np.testing.assert_allclose(result["order_amplitude"].sel(signal="te", order=21.0).values, 1.0, rtol=0.015)


def test_angle_helpers_against_closed_forms():
    time = np.linspace(0.0, 2.0, 2001)
    speed = 600.0 + 300.0 * time  # rpm
    exact = 2.0 * np.pi / 60.0 * (600.0 * time + 150.0 * time**2)
    np.testing.assert_allclose(angle_from_speed(speed, time), exact, atol=1e-12)
    # a 60-pulse tachometer on the same ramp: pulse j at the root of the angle equation
    revolutions = np.arange(0, int(exact[-1] / (2 * np.pi) * 60)) / 60.0
    pulses = (-600.0 + np.sqrt(600.0**2 + 4 * 150.0 * 60.0 * revolutions)) / 300.0
    inside = time <= pulses[-1]
    np.testing.assert_allclose(angle_from_pulses(pulses, time[inside], 60), exact[inside], atol=1e-6)


def test_resampled_cosine_is_a_cosine_of_the_angle():
    time = np.arange(0.0, 2.0, 1.0 / 8192)
    angle = 2 * np.pi * (10.0 * time + 5.0 * time**2)
    ds = xr.Dataset(
        {"pinion_angle": ("time", angle), "te": ("time", np.cos(42 * angle) + np.cos(3 * angle))}, coords={"time": time}
    )
    tracked = resample_to_angle(ds, "te")
    expected = np.cos(42 * tracked["angle"]) + np.cos(3 * tracked["angle"])
    assert float(abs(tracked["te"] - expected).max()) < 1e-4
    np.testing.assert_allclose(tracked["pinion_speed"], 600.0 + 600.0 * tracked["time"], rtol=1e-9)


@pytest.mark.parametrize(
    ("change", "named"),
    [
        (lambda ds: ds.drop_vars(["pinion_angle", "pinion_speed"]), "pinion_angle"),
        (lambda ds: ds.assign(pinion_angle=ds["pinion_angle"] * 0 + np.sin(20.0 * ds["time"].values)), "pinion_angle"),
        (lambda ds: ds, "no_such_signal"),
    ],
)
def test_bad_input_names_the_variable(change, named):
    time = np.arange(0.0, 1.0, 1.0 / 4096)
    angle = 2 * np.pi * 20.0 * time
    ds = xr.Dataset(
        {
            "pinion_angle": ("time", angle),
            "pinion_speed": ("time", np.full(time.size, 1200.0)),
            "te": ("time", np.cos(angle)),
        },
        coords={"time": time},
    )
    signals = "no_such_signal" if named == "no_such_signal" else "te"
    with pytest.raises(OrderTrackingError, match=named) as caught:
        order_map(change(ds), signals, [1.0], speed_bins=[1000.0, 1400.0])
    assert isinstance(caught.value, UqgearError) and isinstance(caught.value, ValueError)


# ---------------------------------------------------------------------------- ramp envelopes and jumps

JUMP_UP_RUN, JUMP_DOWN_RUN = 2200.0, 1800.0  # rpm: the run-up drops here, the coast-down rises here
MEAN_FORCE, LARGE, SMALL = 30e3, 40e3, 8e3  # N: mean mesh force, mesh-order amplitude on each branch
BIN_WIDTH = 100.0


def _jumping_run(start: float, stop: float, jump: float, seed: int) -> xr.Dataset:
    """A ramp on the large branch below ``jump`` rpm and the small one above; teeth apart where the force is < 0."""
    time = np.arange(0.0, DURATION, 1.0 / SAMPLE_RATE)
    speed = start + (stop - start) * time / DURATION
    angle = 2.0 * np.pi / 60.0 * (start * time + 0.5 * (stop - start) / DURATION * time**2)
    amplitude = np.where(speed < jump, LARGE, SMALL)
    rng = np.random.default_rng(np.random.SeedSequence(seed))
    force = MEAN_FORCE + amplitude * np.cos(21.0 * angle) + 10.0 * rng.standard_normal(time.size)
    contact = np.where(force > 0.0, 1, 0)
    return xr.Dataset(
        {
            "pinion_speed": ("time", speed, {"units": "rpm"}),
            "mesh_force": ("time", np.maximum(force, 0.0), {"units": "N"}),
            "contact": ("time", contact),
        },
        coords={"time": time},
    )


@pytest.fixture(scope="module")
def up_and_down() -> tuple[xr.Dataset, xr.Dataset]:
    return _jumping_run(START, STOP, JUMP_UP_RUN, 3), _jumping_run(STOP, START, JUMP_DOWN_RUN, 4)


def test_envelope_peaks_and_separation_against_closed_forms(up_and_down):
    edges = np.arange(START, STOP + 1.0, BIN_WIDTH)
    envelope = ramp_envelope(up_and_down[0], speed_bins=edges)
    large = envelope["bin_upper"].values <= JUMP_UP_RUN
    small = envelope["bin_lower"].values >= JUMP_UP_RUN
    peak = envelope["peak_mesh_force"].values
    np.testing.assert_allclose(peak[large], MEAN_FORCE + LARGE, rtol=2e-3)
    np.testing.assert_allclose(peak[small], MEAN_FORCE + SMALL, rtol=2e-3)
    # apart while cos(21 theta) < -MEAN_FORCE / LARGE: a fraction arccos(0.75) / pi of the time
    separation = envelope["fraction_separation"].values
    np.testing.assert_allclose(separation[large], np.arccos(MEAN_FORCE / LARGE) / np.pi, atol=0.01)
    assert np.all(separation[small] == 0.0) and np.all(envelope["fraction_back_contact"].values == 0.0)
    assert envelope.attrs["direction"] == "up" and envelope["peak_mesh_force"].attrs["units"] == "N"


def test_jumps_found_within_a_bin_and_the_hysteresis_range(up_and_down):
    up, down = up_and_down
    both = up_down_envelopes(up, down, speed_bins=np.arange(START, STOP + 1.0, BIN_WIDTH))
    assert both["peak_mesh_force"].dims == ("direction", "pinion_speed")
    assert list(both["direction"].values) == ["up", "down"]
    (up_jump,) = jump_speeds(both.sel(direction="up"))
    (down_jump,) = jump_speeds(both.sel(direction="down"))
    assert jump_speeds(ramp_envelope(down, speed_bins=np.arange(START, STOP + 1.0, BIN_WIDTH))) == (down_jump,)
    assert abs(up_jump.speed - JUMP_UP_RUN) <= BIN_WIDTH and up_jump.direction == "drop"
    assert abs(down_jump.speed - JUMP_DOWN_RUN) <= BIN_WIDTH and down_jump.direction == "rise"
    np.testing.assert_allclose(up_jump.size, SMALL - LARGE, rtol=5e-3)
    np.testing.assert_allclose(down_jump.relative_size, (LARGE - SMALL) / (MEAN_FORCE + SMALL), rtol=5e-3)
    ((low, high),) = hysteresis_ranges(both)
    assert JUMP_DOWN_RUN - BIN_WIDTH <= low <= JUMP_DOWN_RUN + BIN_WIDTH
    assert JUMP_UP_RUN - BIN_WIDTH <= high <= JUMP_UP_RUN + BIN_WIDTH
    assert both.attrs["hysteresis_ranges"] == [low, high]


def test_smooth_envelope_has_no_jump():
    envelope = xr.Dataset(
        {"peak_mesh_force": ("pinion_speed", 1e4 * (1.0 + 0.05 * np.arange(20)))},
        coords={"pinion_speed": 500.0 + 100.0 * np.arange(20)},
        attrs={"signal": "mesh_force"},
    )
    assert jump_speeds(envelope) == ()


def test_ramp_input_errors_name_the_variable(up_and_down):
    up, down = up_and_down
    with pytest.raises(RampError, match="te"):
        ramp_envelope(up, signal="te")
    with pytest.raises(RampError, match="down"):
        up_down_envelopes(up, up)
    with pytest.raises(RampError, match="pinion_speed"):
        ramp_envelope(up.drop_vars("pinion_speed"))


def test_order_map_figure_draws_map_and_envelopes(runup, up_and_down):
    from uqgear.report import order_map_figure

    waterfall = order_spectrum(runup, "te", max_order=50.0, speed_bins=6)
    both = up_down_envelopes(*up_and_down, speed_bins=np.arange(START, STOP + 1.0, 250.0))
    figure = order_map_figure(waterfall, envelopes=both)
    map_axes, envelope_axes = figure.axes[:2]
    assert map_axes.get_ylabel() == "pinion order" and "peak mesh force" in envelope_axes.get_ylabel()
    assert len(envelope_axes.get_lines()) == 2 and len(figure.axes) == 3  # the map's colour bar
    with pytest.raises(UqgearError, match="signal"):
        order_map_figure(waterfall, "mesh_force")


def test_steady_simulation_reads_as_its_frequency_spectrum():
    """At constant speed the order map of a simulated DTE equals the FFT spectrum at the mesh orders."""
    import uqgear
    from uqgear.dynamics import spectrum_dataset

    run = uqgear.simulate(uqgear.load_design("locomotive"), 2000.0, 7000.0, 33e3, n_periods=400, keep_periods=320)
    time = run["time"].values
    run = run.assign(pinion_angle=("time", 2.0 * np.pi * 2000.0 / 60.0 * (time - time[0])))
    lines = order_map(
        run, "x", [1.0, 2.0], order_unit="mesh", revolutions_per_block=5, overlap=0.0, speed_bins=[1990.0, 2010.0]
    )
    assert lines.attrs["mesh_order"] == 21 and int(lines["block_count"][0]) == 3
    spectrum = spectrum_dataset(run, "x", against="order")["x"].sel(order=[21.0, 42.0], method="nearest")
    np.testing.assert_allclose(lines["order_amplitude"].sel(signal="x").values[0], spectrum.values, rtol=1e-4)


def test_a_jump_must_hold_its_level_with_persistence():
    # a scattered trace (every other bin 1.4x) against a real step from 1.0 to 2.0 at 1450 rpm
    speeds = np.arange(1000.0, 2000.0, 50.0)
    scattered = np.where(np.arange(speeds.size) % 2 == 0, 1.0, 1.4)
    step = np.where(speeds < 1450.0, 1.0, 2.0) * (1.0 + 0.05 * (np.arange(speeds.size) % 2))
    for values, expected in ((scattered, []), (step, [1425.0])):
        envelope = xr.Dataset(
            {"peak_mesh_force": ("pinion_speed", values)},
            coords={"pinion_speed": speeds},
            attrs={"direction": "up", "signal": "mesh_force"},
        )
        assert [jump.speed for jump in jump_speeds(envelope, threshold=0.25, persistence=3)] == expected
    # without persistence every scattered step reads as a jump
    assert len(jump_speeds(envelope.assign(peak_mesh_force=("pinion_speed", scattered)), threshold=0.25)) > 5
    with pytest.raises(RampError, match="persistence: expected an integer >= 1"):
        jump_speeds(envelope, persistence=0)
