"""Tests of uqgear's virtual rig (model -> uqgear-rig/1 data)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from uqgear.common.errors import OperatingPointError, RigDataError
from uqgear.physics.effects import make_effect
from uqgear.physics.integration import simulate
from uqgear.physics.model import natural_frequencies
from uqgear.rig import virtual_rig as V
from uqgear.rig.features import extract_features, line_amplitudes
from uqgear.rig.format import read_rig, rig_design, validate_rig
from uqgear.rig.virtual_rig import (
    adhesion_torque_bounds,
    default_operating_points,
    simulate_campaign,
    synth_rig,
    true_parameters_of,
)

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"

# True parameters of data/rig/healthy.nc (data/rig/README.md)
HEALTHY_TRUTH = {"mesh_stiffness_scale": 0.970, "zeta_mesh": 0.052, "backlash": 0.300e-3,
                 "ste_amplitude": 16.07e-6, "k1": 1.010e9, "k2": 1.889e9,
                 "adhesion_torque": [29780.0, 26120.0, 30700.0, 38230.0, 39380.0, 27090.0, 25820.0, 21300.0]}

SHORT = {"duration": 0.25, "run_in": 0.3}



@pytest.fixture(scope="module")
def small_campaign(design) -> xr.Dataset:
    ops = {"pinion_speed": [900.0, 2500.0], "drive_torque": [6000.0, 7000.0]}
    return simulate_campaign(design, ops, true_parameters={"mesh_stiffness_scale": 1.05, "zeta_mesh": 0.06},
                             seed=7, **SHORT)


def test_default_operating_points_and_bounds_match_the_public_campaign(design):
    # the public file's a-priori T2 intervals are an independent statement of the rule
    public = read_rig(DATA / "healthy.nc")
    ops = default_operating_points(design)
    np.testing.assert_allclose(ops["pinion_speed"].values, public["pinion_speed"].values)
    np.testing.assert_allclose(ops["drive_torque"].values, public["drive_torque"].values)
    # bounds clipped to mu Q R_w differ by g: 9.81 in the public files, standard gravity 9.80665 here
    np.testing.assert_allclose(ops["adhesion_torque_lower"].values, public["adhesion_torque_lower"].values, rtol=4e-4)
    np.testing.assert_allclose(ops["adhesion_torque_upper"].values, public["adhesion_torque_upper"].values, rtol=4e-4)
    unclipped = [0, 2, 3, 4, 5, 6]
    np.testing.assert_allclose(ops["adhesion_torque_lower"].values[unclipped],
                               public["adhesion_torque_lower"].values[unclipped], rtol=1e-9)
    lower, upper = adhesion_torque_bounds(design, [7000.0])
    assert lower[0] == pytest.approx(0.85 * 7000.0 * 101 / 21)
    assert upper[0] == pytest.approx(1.15 * 7000.0 * 101 / 21)


def test_bearing_check_brackets_the_bearing_modes_and_unloads_a_bearing(design):
    """The light-load plan brackets both bearing modes and unloads a bearing deeper than any service point."""
    ops = V.bearing_check_operating_points(design)
    speeds = ops["pinion_speed"].values
    mode_speeds = natural_frequencies(design)[:2] * 60.0 / design.z1
    for speed, factors in zip(mode_speeds, V.BEARING_CHECK_SPEED_FACTORS):
        assert np.any(np.isclose(speeds, speed * min(factors), atol=5.0))
        assert np.any(np.isclose(speeds, speed * max(factors), atol=5.0))
    balancing = 1500.0 * design.z2 / design.z1
    assert np.allclose(ops["adhesion_torque_lower"], 0.85 * balancing)
    assert np.allclose(ops["adhesion_torque_upper"], 1.15 * balancing)

    def least_bearing_load(speed, drive_torque):
        # smallest bearing deflection over the steady response, relative to its mean (< 0: unloaded)
        run = simulate(design, speed, drive_torque, drive_torque * design.z2 / design.z1, n_periods=400,
                       keep_periods=100)
        return min(float(np.min(run[name].values * np.sign(run[name].values.mean())) / abs(run[name].values.mean()))
                   for name in ("y1", "y2"))

    assert least_bearing_load(float(np.round(mode_speeds[0] / 10) * 10), 1500.0) < -0.5
    # at service loads only the run nearest the first bearing mode (800 rpm) comes near unloading
    service = [least_bearing_load(speed, torque) for speed, torque in zip(V.DEFAULT_PINION_SPEEDS,
                                                                          V.DEFAULT_DRIVE_TORQUES)]
    assert min(service) > -0.5 and sum(value < 0.0 for value in service) <= 1
    with pytest.raises(OperatingPointError, match="drive_torque: expected a finite number > 0"):
        V.bearing_check_operating_points(design, drive_torque=0.0)


def test_campaign_is_valid_rig_data_with_truth_recorded(small_campaign, design):
    assert validate_rig(small_campaign).to_dict() == design.to_dict()   # nominal design stored
    assert small_campaign.sizes == {"op": 2, "time": 5120}
    assert small_campaign["te"].dtype == np.float32
    truth = true_parameters_of(small_campaign)
    assert truth["mesh_stiffness_scale"] == 1.05 and truth["zeta_mesh"] == 0.06
    lower = small_campaign["adhesion_torque_lower"].values
    upper = small_campaign["adhesion_torque_upper"].values
    assert np.all((lower <= truth["adhesion_torque"]) & (truth["adhesion_torque"] <= upper))
    assert json.loads(small_campaign.attrs["effects"]) == []
    # te carries no absolute zero: mean removed per run
    assert np.all(np.abs(small_campaign["te"].mean("time").values) < 1e-12)


def test_synth_rig_round_trips(design, tmp_path):
    path = synth_rig(design, tmp_path / "campaign.nc", seed=3, effects=[make_effect("eccentricity",
                                                                                    {"amplitude": 5e-6})],
                     true_parameters={"k1": 0.9e9}, operating_points={"pinion_speed": [1500.0],
                                                                      "drive_torque": [7000.0]}, **SHORT)
    back = read_rig(path)
    assert rig_design(back).to_dict() == design.to_dict()
    assert true_parameters_of(back)["k1"] == 0.9e9
    assert json.loads(back.attrs["effects"])[0]["name"] == "eccentricity"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign.nc"]


def test_seed_makes_campaigns_repeatable(design):
    ops = {"pinion_speed": [1500.0], "drive_torque": [7000.0]}
    first = simulate_campaign(design, ops, seed=5, **SHORT)
    again = simulate_campaign(design, ops, seed=5, **SHORT)
    other = simulate_campaign(design, ops, seed=6, **SHORT)
    xr.testing.assert_equal(first.drop_attrs(), again.drop_attrs())
    assert not np.array_equal(first["acc_pinion"].values, other["acc_pinion"].values)


def test_sensor_noise_level_is_what_was_asked(small_campaign, design):
    # the feature extractor's noise floor is an independent estimator of the added white noise
    features = extract_features(small_campaign, design)
    for name in ("te", "acc_pinion", "acc_gear"):
        ratio = features[name].sel(feature="noise_std") / features[name].sel(feature="rms")
        np.testing.assert_allclose(ratio.values, 0.02, rtol=0.15)


def test_absolute_noise_goes_to_the_noise_std_attribute(design):
    ops = {"pinion_speed": [2000.0], "drive_torque": [7000.0]}
    ds = simulate_campaign(design, ops, seed=1, noise_std={"acc_gear": 0.5}, relative_noise=0.0,
                           channels=("acc_gear",), **SHORT)
    assert ds["acc_gear"].attrs["noise_std"] == 0.5
    features = extract_features(ds, design)
    assert features["acc_gear"].sel(feature="noise_std").values[0] == pytest.approx(0.5, rel=0.15)


def test_noise_free_campaign_reproduces_the_public_healthy_file(design):
    """Our rig at the README's true parameters against the independent reference simulator."""
    public = read_rig(DATA / "healthy.nc")
    ours = simulate_campaign(design, true_parameters=HEALTHY_TRUTH, relative_noise=0.0, seed=2, **SHORT)
    orders = [21, 42]
    for channel in ("te", "acc_pinion", "acc_gear"):
        mine = line_amplitudes(ours[channel], ours["pinion_speed"], orders).values
        theirs = line_amplitudes(public[channel], public["pinion_speed"], orders).values
        # mesh 1 everywhere within 1 %, mesh 2 within 3 % (the public record's noise and chaos at 3800 rpm)
        np.testing.assert_allclose(mine[:, 0], theirs[:, 0], rtol=0.01)
        np.testing.assert_allclose(mine[:, 1], theirs[:, 1], rtol=0.03)


@pytest.mark.parametrize(("changes", "message"), [
    ({"true_parameters": {"stiffness": 1.0}}, r"true_parameters\.stiffness: unknown parameter"),
    ({"true_parameters": {"mesh_stiffness_scale": -1.0}}, r"true_parameters\.mesh_stiffness_scale"),
    ({"true_parameters": {"backlash": 0.3}}, r"backlash: expected a value in"),
    ({"true_parameters": {"adhesion_torque": [1.0, 2.0, 3.0]}}, r"adhesion_torque: expected 1 values"),
    ({"operating_points": {"pinion_speed": [-5.0], "drive_torque": [7000.0]}}, r"pinion_speed: expected speeds > 0"),
    ({"operating_points": {"pinion_speed": [1000.0]}}, r"drive_torque: missing"),
    ({"operating_points": {"pinion_speed": [1000.0], "drive_torque": [1.0], "speed": [1.0]}},
     r"operating_points\.speed: unknown variable"),
    ({"fs": 2000.0}, r"fs: 2000 Hz does not resolve the third mesh harmonic"),
    ({"channels": ("te", "strain")}, r"channels: 'strain' is not a rig channel"),
    ({"noise_std": {"te": -1.0}}, r"noise_std\.te: expected a standard deviation >= 0"),
    ({"relative_noise": -0.1}, r"relative_noise: expected a fraction >= 0"),
    ({"seed": -3}, r"seed: expected a non-negative integer"),
])
def test_bad_input_is_rejected_with_a_message(design, changes, message):
    arguments = {"operating_points": {"pinion_speed": [1000.0], "drive_torque": [7000.0]}, **SHORT, **changes}
    with pytest.raises(OperatingPointError, match=message):
        simulate_campaign(design, **arguments)


def test_synth_rig_needs_an_existing_folder(design, tmp_path):
    with pytest.raises(RigDataError, match="does not exist"):
        synth_rig(design, tmp_path / "missing" / "campaign.nc", seed=1)


def test_true_parameters_of_a_file_without_truth():
    with pytest.raises(RigDataError, match="true_parameters: attribute missing"):
        true_parameters_of(read_rig(DATA / "healthy.nc"))
