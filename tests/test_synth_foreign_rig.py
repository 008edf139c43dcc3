"""``uqgear synth-rig --foreign GRADE``: foreign-rig campaigns from the command line, steady and run-up.

The files are checked against the Python API run with the seeds the command states
(child 0 of the seed's SeedSequence for the gears, child 1 for the campaign), against
the ramp the command was given (the tachometer), and for what is refused.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import cli_in_process as _cli

from uqgear.physics.design import load_design
from uqgear.physics.effects import parse_effect
from uqgear.rig import read_rig
from uqgear.rig.foreign_rig import draw_gears, simulate_foreign_campaign
from uqgear.rig.foreign_runup import simulate_foreign_runup_campaign
from uqgear.rig.virtual_rig import default_operating_points
from uqgear.uq.seeds import child_seed

DESIGN = load_design("locomotive")
RAMP = "1500:1600:500"  # 0.2 s of ramp record
RAMP_TABLE = {"start_speed": [1500.0], "stop_speed": [1600.0], "rate": [500.0], "drive_torque": [7000.0]}


def _seeds(seed: int) -> tuple[np.random.SeedSequence, np.random.SeedSequence]:
    sequence = np.random.SeedSequence(seed)
    return child_seed(sequence, 0), child_seed(sequence, 1)


def _gears(rig) -> dict[str, np.ndarray]:
    return {wheel: np.array(rows) for wheel, rows in json.loads(rig.attrs["foreign_gears"]).items()}


def _ramp(capsys, path: Path, *more: str):
    made = _cli(capsys, "synth-rig", "--out", path, "--foreign", "6", "--ramp", RAMP, *more)
    assert made.returncode == 0, made.stderr
    return read_rig(path)


def test_a_steady_foreign_campaign_is_the_foreign_rig_at_the_default_operating_points(tmp_path, capsys):
    made = _cli(capsys, "synth-rig", "--out", tmp_path / "steady.nc", "--foreign", "6", "--seed", "3",
                "--effect", "eccentricity:amplitude=8e-6")
    assert made.returncode == 0, made.stderr
    assert "foreign virtual rig campaign written" in made.stdout and "grade 6" in made.stdout
    rig = read_rig(tmp_path / "steady.nc")
    points = default_operating_points(DESIGN)
    np.testing.assert_array_equal(rig["pinion_speed"], points["pinion_speed"])
    assert rig.sizes["time"] == 20480 and sorted(rig.data_vars) == ["acc_gear", "acc_pinion", "te"]
    assert rig.attrs["source"].startswith("uqgear foreign virtual rig") and rig.attrs["foreign_grade"] == 6.0
    assert json.loads(rig.attrs["effects"])[0]["name"] == "eccentricity"
    assert json.loads(rig.attrs["foreign_gears_seed"]) == {"entropy": "3", "spawn_key": [0]}
    assert (rig.attrs["seed_entropy"], json.loads(rig.attrs["seed_spawn_key"])) == ("3", [1])
    # the gears and the first run, from the Python API with the seeds the file states
    gears_seed, campaign_seed = _seeds(3)
    gears = draw_gears(DESIGN, 6, gears_seed)
    np.testing.assert_array_equal(_gears(rig)["pinion"], gears.pinion)
    np.testing.assert_array_equal(_gears(rig)["gear"], gears.gear)
    first = simulate_foreign_campaign(DESIGN, points.isel(op=[0]), gears=gears, seed=campaign_seed, duration=1.0,
                                      effects=[parse_effect("eccentricity:amplitude=8e-6")])
    for name in ("te", "acc_pinion", "acc_gear"):
        expected = first[name].values[0]
        np.testing.assert_allclose(rig[name].values[0], expected, rtol=0, atol=1e-6 * np.abs(expected).max())


def test_a_foreign_run_up_follows_its_ramp_and_runs_the_steady_campaigns_gears(tmp_path, capsys):
    rig = _ramp(capsys, tmp_path / "ramp.nc", "--seed", "3")
    steady = _cli(capsys, "synth-rig", "--out", tmp_path / "steady.nc", "--foreign", "6", "--seed", "3")
    assert steady.returncode == 0, steady.stderr
    assert read_rig(tmp_path / "steady.nc").attrs["foreign_gears"] == rig.attrs["foreign_gears"]
    assert rig.sizes["ramp"] == 1 and rig.sizes["ramp_time"] == 4096  # 0.2 s at 20480 Hz
    assert "run-up" in rig.attrs["title"] and rig.attrs["foreign_grade"] == 6.0
    speed = rig["ramp_pinion_speed_signal"].values[0]
    assert abs(speed[:200].mean() - 1500.0) < 10.0 and abs(speed[-200:].mean() - 1600.0) < 10.0
    gears_seed, campaign_seed = _seeds(3)
    gears = draw_gears(DESIGN, 6, gears_seed)
    np.testing.assert_array_equal(_gears(rig)["pinion"], gears.pinion)
    expected = simulate_foreign_runup_campaign(DESIGN, RAMP_TABLE, gears=gears, seed=campaign_seed)["ramp_te"]
    np.testing.assert_allclose(rig["ramp_te"], expected, rtol=0, atol=1e-6 * float(np.abs(expected).max()))


def test_one_seed_gives_the_same_numbers_and_a_gears_seed_the_same_gears_under_other_noise(tmp_path, capsys):
    first, again = _ramp(capsys, tmp_path / "a.nc", "--seed", "5"), _ramp(capsys, tmp_path / "b.nc", "--seed", "5")
    other = _ramp(capsys, tmp_path / "c.nc", "--seed", "6")
    shared = _ramp(capsys, tmp_path / "d.nc", "--seed", "6", "--gears-seed", "5")
    for name in ("ramp_te", "ramp_acc_pinion", "ramp_acc_gear", "ramp_pinion_speed_signal"):
        np.testing.assert_array_equal(first[name], again[name])
    assert not np.array_equal(_gears(first)["gear"], _gears(other)["gear"])
    np.testing.assert_array_equal(_gears(first)["gear"], _gears(shared)["gear"])
    assert not np.array_equal(first["ramp_te"], shared["ramp_te"])


@pytest.mark.parametrize("args, message", [
    (["--foreign", "6", "--true", "k1=1.1e9"], "uqgear: error: --true: the foreign rig (--foreign) has no true"),
    (["--foreign", "12"], "uqgear: error: --foreign: expected an ISO 1328-1 flank tolerance class from 1 to 11"),
    (["--foreign", "nan"], "uqgear: error: --foreign: expected an ISO 1328-1"),
    (["--gears-seed", "4"], "uqgear: error: --gears-seed: seeds the gears of the foreign rig; give it with --foreign"),
    (["--foreign", "6", "--ramp", "100:200:50"], "uqgear: error: ramps.start_speed: expected speeds in the design's"),
])
def test_what_the_foreign_rig_does_not_take_is_refused_in_one_line_leaving_nothing(tmp_path, capsys, args, message):
    refused = _cli(capsys, "synth-rig", "--out", tmp_path / "x.nc", *args)
    assert refused.returncode == 2
    assert refused.stderr.startswith(message) and len(refused.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []
