"""Tests of the blind test's run-up suite: its plan against the real-world suite's, and the campaigns it makes.

The plan is checked against :func:`uqgear.validation.plan_real_world`'s
kinds (the same ones, less those the speed-varying model cannot take); one
of its campaigns is generated and read back as a rig file with ramp
records that carries its truth; a transfer path filters ramp records with
its closed-form gain.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from uqgear import validation as B
from uqgear.common.errors import RigDataError
from uqgear.diagnosis import DiagnosisError
from uqgear.rig import apply_transfer_path, transfer_path_gain
from uqgear.rig.format import read_rig, write_rig
from uqgear.rig.ramp_records import steady_campaign
from uqgear.validation.campaigns import true_values
from uqgear.validation.runup_campaigns import RAMP_PLANS, plan_runup, ramp_table, runup_campaign

FS = 20480.0


def _kind(identifier: str) -> str:
    """A campaign's kind and effects: its identifier without the suite's prefix and the trailing count."""
    return identifier.removeprefix("runup-").rsplit("-", 1)[0]


def test_the_run_up_plan_is_the_real_world_plan_without_pitch_errors():
    real_world = B.plan_real_world(2, np.random.default_rng(3))
    runup = plan_runup(2, np.random.default_rng(3))
    # every real-world kind whose nuisances leave something once pitch errors are taken away has its run-up
    # every real-world kind but those whose only nuisance is pitch errors has its run-up counterpart
    kept = {_kind(spec.identifier) for spec in real_world if spec.nuisances != {"pitch_errors": 7}}
    assert {_kind(spec.identifier) for spec in runup} == kept and len(runup) == 2 * len(kept)
    by_kind = {}
    for spec in real_world:
        by_kind.setdefault(_kind(spec.identifier), spec)
    for spec in runup:
        assert "pitch_errors" not in spec.nuisances and spec.plan in RAMP_PLANS
        other = by_kind[_kind(spec.identifier)]
        # the same families and verdicts, the leading effect at the strong level, the same nuisances otherwise
        assert spec.truth_set() == other.truth_set() and spec.right_verdict() == other.right_verdict()
        assert spec.strength in ("strong", "-")
        assert spec.plan == ("runup_low_speed" if "low_speed" in spec.identifier else "runup")
        same = {key: value for key, value in other.nuisances.items() if key not in ("pitch_errors", "speed_wander")}
        assert {key: value for key, value in spec.nuisances.items() if key != "speed_wander"} == same
        assert ("speed_wander" in spec.nuisances) == ("speed_wander" in other.nuisances)
    assert {spec.design_name for spec in runup} == {"reference", "second"}
    # its own stream: the seed's fourth child, the other suites' plans as they are
    planned = B.planned_campaigns(5, suite="runup", n_per_effect=1)
    fourth = np.random.SeedSequence(5).spawn(4)[3].spawn(2)[0]
    assert [s.identifier for s, _, _ in planned] == [s.identifier for s in plan_runup(1, np.random.default_rng(fourth))]
    assert [s.identifier for s, _, _ in B.planned_campaigns(5, suite="real_world", n_per_effect=1)] == [
        s.identifier for s in B.plan_real_world(1, np.random.default_rng(np.random.SeedSequence(5).spawn(2)[0]))
    ]


def test_ramp_tables_run_up_and_coast_down_over_one_span():
    for plan in RAMP_PLANS:
        table = ramp_table(plan)
        assert table["start_speed"].tolist() == table["stop_speed"][::-1].tolist()
        assert table["start_speed"][0] < table["stop_speed"][0]
    with pytest.raises(DiagnosisError, match="plan: expected one of runup, runup_low_speed"):
        ramp_table("service")


def test_run_up_campaigns_are_rig_files_with_ramp_records_that_carry_their_truth(tmp_path):
    # two effects under speed wander, mains pickup and 3 % noise: every option of the generator but the path
    spec, design, seed = next(planned for planned in B.planned_campaigns(2, suite="runup", n_per_effect=1)
                              if planned[0].identifier.startswith("runup-two_effects_nuisances"))
    truth = true_values(spec, design)
    rig = read_rig(write_rig(tmp_path / "rig.nc", runup_campaign(spec, design, truth, spec.effects(), seed, "t")))
    table = ramp_table(spec.plan)
    assert rig.sizes["ramp"] == 2 and "op" not in rig.dims
    assert rig["ramp_drive_torque"].values.tolist() == table["drive_torque"].tolist()
    speeds = rig["ramp_pinion_speed_signal"].values
    # a run-up then a coast-down over the plan's span (the wander moves the speed by at most 0.5 %)
    assert speeds[0, 0] < speeds[0, -1] and speeds[1, 0] > speeds[1, -1]
    assert np.all(np.abs(speeds[:, [0, -1]] - [[800.0, 3800.0], [3800.0, 800.0]]) < 0.006 * 3800.0)
    # the labels: the effects acting with their drawn values, the scattered truth, a T2 per ramp in its bounds
    effects = json.loads(rig.attrs["effects"])
    assert [entry["name"] for entry in effects] == spec.truth_set()
    assert effects[0]["values"] == pytest.approx(dict(spec.effect_values))
    recorded = json.loads(rig.attrs["true_parameters"])
    assert recorded["mesh_stiffness_scale"] == pytest.approx(truth["mesh_stiffness_scale"])
    adhesion = np.asarray(recorded["ramp_adhesion_torque"])
    assert adhesion.shape == (2,) and np.all(adhesion >= rig["ramp_adhesion_torque_lower"].values)
    assert np.all(adhesion <= rig["ramp_adhesion_torque_upper"].values)
    noise = json.loads(rig.attrs["noise"])
    assert bool(noise["speed_wander"]) == ("speed_wander" in spec.nuisances)
    assert json.loads(rig.attrs["noise"])["line_interference"] == {"50": 0.5, "150": 0.2}
    # cut as the diagnosis reads it: 8 distinct speeds spread over the span, the ramps taking turns
    points = steady_campaign(rig)
    speed = np.sort(points["pinion_speed"].values)
    assert points.sizes["op"] == 8 and np.all(np.diff(speed) > 200.0) and speed[0] < 900.0 < 3700.0 < speed[-1]
    assert sorted(set(points["op_source"].values.tolist())) == ["ramp 0", "ramp 1"]


def test_a_transfer_path_filters_ramp_records_with_its_closed_form_gain():
    f0, zeta = 2500.0, 0.05
    time = np.arange(int(0.5 * FS)) / FS
    records = np.stack([np.cos(2 * np.pi * frequency * time) for frequency in (f0, 1000.0)])
    campaign = xr.Dataset(
        {"ramp_acc_pinion": (("ramp", "ramp_time"), records, {"units": "m s-2"})},
        coords={"ramp_time": time},
        attrs={"history": "test"},
    )
    filtered = apply_transfer_path(campaign, "acc_pinion", f0, zeta)["ramp_acc_pinion"]
    amplitudes = np.sqrt(2.0 * np.mean(filtered.values[:, 2000:] ** 2, axis=1))
    expected = transfer_path_gain(np.array([f0, 1000.0]), f0, zeta, FS)
    assert amplitudes == pytest.approx(expected, rel=2e-3)
    assert json.loads(filtered.attrs["transfer_path"])[0]["frequency"] == f0
    with pytest.raises(RigDataError, match="channel 'te': expected a signal"):
        apply_transfer_path(campaign, "te", f0, zeta)
