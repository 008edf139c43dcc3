"""The ``runup`` study analysis: its file layout, its envelopes against the run-up simulator run by hand, its
first screen, and bad input refused in one line through the real command line."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.dynamics import ramp_envelope
from uqgear.study.runup_analysis import block_revolutions

STUDY = """
name: ramps
design: locomotive
seed: 5
operating_points:
  drive_torque: 7000
uncertain:
  adhesion_torque: {interval: [25.0e+3, 40.0e+3]}
analyses:
  - type: runup
    name: ramp
    pinion_speed: {start: 2000, stop: 2300}
    rate: 3000
    points: 2
    speed_bins: 6
    sample_rate: 10240
    folds: false
"""


@pytest.fixture(scope="module")
def ramp_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("runup")
    (folder / "study.yaml").write_text(STUDY)
    run = subprocess.run(
        [sys.executable, "-m", "uqgear", "run", str(folder / "study.yaml"), "--out", str(folder / "out")],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    with xr.open_dataset(folder / "out" / "ramp.nc") as ds:
        return ds.load(), (folder / "out" / "report.html").read_text()


def test_layout_of_the_result(ramp_run):
    ds, _ = ramp_run
    assert ds["peak_mesh_force"].dims == ("bound", "direction", "pinion_speed")
    assert ds["direction"].values.tolist() == ["up", "down"]
    assert ds["order_amplitude"].dims == ("signal", "pinion_speed", "order")
    assert ds.sizes["pinion_speed"] == 6 and ds["peak_mesh_force"].attrs["units"] == "N"
    np.testing.assert_allclose(ds["case_adhesion_torque"].values, [25.0e3, 40.0e3])
    # the bounds are the extremes over the interval cases, bin by bin
    per_case = ds["peak_mesh_force_case"]
    np.testing.assert_array_equal(ds["peak_mesh_force"].sel(bound="upper").values, per_case.max("case").values)
    np.testing.assert_array_equal(ds["peak_mesh_force"].sel(bound="lower").values, per_case.min("case").values)


def test_envelope_equals_the_simulator_run_by_hand(ramp_run):
    ds, _ = ramp_run
    design = uqgear.load_design("locomotive")
    for direction, (first, last) in (("up", (2000.0, 2300.0)), ("down", (2300.0, 2000.0))):
        profile = uqgear.SpeedProfile.linear(first, last, rate_rpm_per_s=3000.0 if last > first else -3000.0)
        samples = uqgear.samples_from_mapping({"drive_torque": [7000.0], "adhesion_torque": [40.0e3]})
        simulation = uqgear.parse_study(STUDY).analyses[0].simulation
        runs = uqgear.simulate_runup_batch(
            design, profile, samples, sample_rate=10240.0, steps_per_mode=simulation.steps_per_mode
        )
        by_hand = ramp_envelope(runs.isel(sample=0), speed_bins=np.linspace(2000.0, 2300.0, 7))
        stored = ds["peak_mesh_force_case"].sel(direction=direction).isel(case=1)
        np.testing.assert_allclose(stored.values, by_hand["peak_mesh_force"].values, rtol=1e-12)


def test_first_screen_states_the_ramps(ramp_run):
    ds, page = ramp_run
    assert "Run-up and coast-down 2000-2300 rpm at 3000 rpm/s, T2 = 25.0-40.0 kN m: peak mesh force" in page
    upper = float(ds["peak_mesh_force_case"].sel(direction="up").max())
    assert f"run-up {upper / 1e3:.1f} kN" in page


def test_block_length_keeps_one_block_per_bin():
    edges = np.linspace(3500.0, 4300.0, 17)
    blocks = block_revolutions(edges, 1000.0)
    # the longest whole number of revolutions at the lowest speed that spans at most one bin of 50 rpm
    assert blocks * 60.0 / 3500.0 * 1000.0 <= 50.0 < (blocks + 1) * 60.0 / 3500.0 * 1000.0
    assert block_revolutions(edges, 10.0) == 8 and block_revolutions(edges, 1e5) == 1


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("stop: 2300", "stop: 2000", "analyses[0].pinion_speed: expected two different speeds"),
        ("stop: 2300", "stop: 9000", "analyses[0].pinion_speed.stop: expected a speed in the design's range"),
        (", stop: 2300", "", "analyses[0].pinion_speed.stop: missing"),
        ("rate: 3000", "rate: -5", "analyses[0].rate: expected a number"),
        ("rate: 3000", "rate: 3000\n    direction: sideways", "analyses[0].direction: expected one of"),
    ],
)
def test_bad_input_names_the_key(old, new, message):
    with pytest.raises(uqgear.StudyError) as error:
        uqgear.parse_study(STUDY.replace(old, new))
    assert message in str(error.value) and "\n" not in str(error.value)


def test_bad_input_on_the_command_line_is_one_line_and_exit_2(tmp_path):
    (tmp_path / "study.yaml").write_text(STUDY.replace("stop: 2300", "stop: 9000"))
    run = subprocess.run(
        [sys.executable, "-m", "uqgear", "run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2, run.stderr
    assert "analyses[0].pinion_speed.stop: expected a speed in the design's range" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_other_sweeps_are_refused():
    text = STUDY.replace("  drive_torque: 7000", "  drive_torque: [6000, 7000]")
    with pytest.raises(uqgear.StudyError, match="operating_points.drive_torque: a run-up sweeps the pinion speed"):
        uqgear.parse_study(text)


def test_span_defaults_to_the_speed_sweep():
    text = STUDY.replace("    pinion_speed: {start: 2000, stop: 2300}\n", "").replace(
        "  drive_torque: 7000", "  drive_torque: 7000\n  pinion_speed: {start: 1500, stop: 2500, num: 11}"
    )
    spec = uqgear.parse_study(text).analyses[0]
    assert dict(spec.options["pinion_speed"]) == {"start": 1500.0, "stop": 2500.0}
    with pytest.raises(uqgear.StudyError, match=r"analyses\[0\].pinion_speed: missing"):
        uqgear.parse_study(STUDY.replace("    pinion_speed: {start: 2000, stop: 2300}\n", ""))


def test_ramps_jump_near_the_folds_and_nearer_as_they_slow():
    """On wet rail the locomotive gear holds two responses between two folds of its period-1 branch; a run-up
    leaves the lower branch at the upper fold, a coast-down the upper branch at the lower fold, late by an
    amount that shrinks with the ramp rate (the continuation's folds are the independent reference)."""
    design = uqgear.load_design("locomotive")
    inputs = {"drive_torque": 7000.0, "adhesion_torque": 21.1e3}
    table = uqgear.dynamics.Continuation("pinion_speed", 3450.0, 3800.0).fit(design, inputs).result_
    kinds = table["bifurcation_type"].values.astype(str)
    sweeps = table["bifurcation_sweep"].values.astype(str)
    where = table["bifurcation_parameter"].values
    fold = {sense: float(where[(kinds == "fold") & (sweeps == sense)][0]) for sense in ("up", "down")}
    assert fold["down"] < fold["up"]
    edges = np.arange(3450.0, 3800.1, 5.0)
    samples = uqgear.samples_from_mapping({name: [value] for name, value in inputs.items()})
    late = {}
    for rate in (1000.0, 60.0):
        for sense, (first, last) in (("up", (3450.0, 3800.0)), ("down", (3800.0, 3450.0))):
            profile = uqgear.SpeedProfile.linear(first, last, rate_rpm_per_s=rate if sense == "up" else -rate)
            run = uqgear.simulate_runup_batch(design, profile, samples, sample_rate=10240.0).isel(sample=0)
            jumps = uqgear.jump_speeds(ramp_envelope(run, speed_bins=edges), threshold=0.15, persistence=3)
            assert len(jumps) == 1, (rate, sense, jumps)
            # how far past the fold, in the sense of travel (a jump is located to a 5 rpm bin)
            late[rate, sense] = (jumps[0].speed - fold[sense]) * (1.0 if sense == "up" else -1.0)
    for sense in ("up", "down"):
        assert -5.0 <= late[60.0, sense] <= 10.0, late
        assert late[1000.0, sense] >= late[60.0, sense] - 5.0, late
    assert max(late[1000.0, "up"], late[1000.0, "down"]) > max(late[60.0, "up"], late[60.0, "down"]), late
