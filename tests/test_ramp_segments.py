"""A ramp segment read alike from the rig's record and from the model (uqgear.rig.ramp_segments)."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

import uqgear
from uqgear.diagnosis.case import prepare_case
from uqgear.diagnosis.execution import RunTask, execute_run
from uqgear.diagnosis.simulation import CampaignSimulator
from uqgear.physics.effects import make_effect
from uqgear.rig.format import rig_design
from uqgear.rig.ramp_records import RAMP_SETTLING, steady_campaign
from uqgear.rig.ramp_segments import SegmentCleaner, SegmentProfile, segment_profiles
from uqgear.rig.virtual_rig import RECORD_GUARD, true_model
from uqgear.rig.virtual_runup import simulate_runup_campaign

FS = 20480.0


def test_a_segment_profile_is_the_tachometers_quadratic_continued_over_lead_and_guard():
    time = np.arange(4096) / FS
    speed = 1200.0 + 150.0 * time + 40.0 * time**2
    segment = SegmentProfile.from_tachometer(speed, FS)
    # a quadratic is fitted exactly, and its mean is the record's
    assert np.allclose(segment.speed_at(time), speed, rtol=1e-12)
    assert segment.mean_speed == pytest.approx(speed.mean(), rel=1e-12)
    profile = segment.profile(lead=0.15, guard=0.025)
    assert profile.duration == pytest.approx(0.15 + time.size / FS + 0.025)
    # the profile's t = 0 lies the lead before the segment's first sample
    for t in (-0.15, 0.0, 0.1, 0.2):
        assert float(profile.speed(t + 0.15)) == pytest.approx(1200.0 + 150.0 * t + 40.0 * t**2, rel=1e-9)


def test_a_segment_profile_whose_quadratic_would_turn_back_keeps_the_ramps_direction():
    """A coast-down segment flattening out under a wander: its quadratic continued over the guard would rise
    again, so the straight line through the tachometer drives the model, and the profile is monotone."""
    time = np.arange(4198) / FS
    centred = time - 0.5 * time.size / FS
    speed = 3800.0 - 210.0 * centred + 1000.0 * centred**2
    assert np.all(np.diff(speed) < 0)
    segment = SegmentProfile.from_tachometer(speed, FS)
    slope, mean = np.polyfit(time - 0.5 * time.size / FS, speed, 1)
    assert segment.coefficients == pytest.approx((0.0, slope, mean))
    profile = segment.profile(lead=0.15, guard=0.025)
    assert profile.direction == "down"
    assert np.all(np.diff(profile.speed(np.linspace(0.0, profile.duration, 400))) < 0)


def test_the_cleaning_takes_out_a_carriers_linear_change_and_keeps_its_lines(design):
    time = np.arange(4096) / FS
    speed = 1500.0 + 300.0 * time
    angle = 2 * np.pi * np.cumsum(speed / 60.0) / FS
    lines = np.cos(21 * angle) + 0.3 * np.sin(42 * angle + 0.4) + 0.05 * np.cos(20 * angle)
    drift = 4.0 * (time - time.mean()) * np.cos(21 * angle + 0.7)
    cleaner = SegmentCleaner(speed, FS, design)
    te = cleaner.clean(lines + drift + 2.0 + 7.0 * time, "te")
    assert np.max(np.abs(te - (lines - lines.mean()))) < 0.02
    # an acceleration keeps its mean (no trend is taken from it); its drift is the one the order tracking
    # will see, after dividing by (speed / mean speed)^2
    scale = (speed / speed.mean()) ** 2
    acceleration = cleaner.clean(scale * (lines + drift), "acc_pinion")
    assert np.max(np.abs(acceleration - scale * lines)) < 0.02
    # a record with a NaN sample is left as it is (unusable either way)
    broken = lines.copy()
    broken[5] = np.nan
    assert np.isnan(cleaner.clean(broken, "te")[5])


def test_steady_runs_have_no_segment_profile():
    rig = uqgear.read_rig(uqgear.example_rig_file("healthy"))
    assert segment_profiles(rig) == (None,) * rig.sizes["op"]


@pytest.fixture(scope="module")
def low_speed_run_up(design):
    """A noise-free run-up 1150 -> 2150 rpm at 200 rpm/s, cut into 8 segments."""
    truth = {"mesh_stiffness_scale": 0.96, "zeta_mesh": 0.045, "adhesion_torque": [30e3]}
    ramps = {"start_speed": [1150.0], "stop_speed": [2150.0], "rate": [200.0], "drive_torque": [8000.0]}
    rig = simulate_runup_campaign(design, ramps, true_parameters=truth, relative_noise=0.0, seed=3)
    return rig, steady_campaign(rig, design=design)


def _line_errors(case, simulator, task_of) -> np.ndarray:
    """Per segment, the largest difference of a line's amplitude, model against record, over the channel's
    largest line (the worst channel)."""
    worst = []
    for op in range(case.speeds.size):
        features, _ = execute_run(dataclasses.replace(case, simulator=simulator), task_of(op))
        names = case.processors[op].names
        lines = [index for index, name in enumerate(names) if name.startswith(("mesh", "shaft"))]
        observed = np.abs(case.observed_all[op][:, lines])
        largest = np.nanmax(observed, axis=1, keepdims=True)
        worst.append(np.nanmax(np.abs(observed - np.abs(features[:, lines])) / largest))
    return np.array(worst)


def test_the_model_read_through_each_segment_gives_the_run_ups_features(design, low_speed_run_up):
    """At the true parameters the model read through each segment's speeds reproduces the segment's lines to
    2e-3 of the channel's largest, where a steady run at the segment's mean speed reads them up to ten times
    (and more) further off."""
    rig, segments = low_speed_run_up
    case = prepare_case(segments, rig_design(rig), seed=np.random.SeedSequence(1))
    assert all(profile is not None for profile in case.simulator.segments)
    truth = json.loads(segments.attrs["true_parameters"])
    adhesion = truth.pop("adhesion_torque")
    true_design, scale, _ = true_model(design, truth)

    def task_of(op: int) -> RunTask:
        return RunTask(op, true_design, scale, adhesion[op], (), "mesh")

    through = _line_errors(case, case.simulator, task_of)
    steady = CampaignSimulator(design, case.speeds, case.drive_torques, case.fs, case.size, case.channels)
    at_mean_speed = _line_errors(case, steady, task_of)
    assert np.all(through < 2e-3), through
    assert np.max(at_mean_speed) > 10.0 * np.max(through), (at_mean_speed, through)
    # the segments keep the settling time off the record's ends
    first = float(segments["pinion_speed"].values.min())
    assert first > 1150.0 + 200.0 * RAMP_SETTLING


def _record_frame(effect, design, start: float, rate: float):
    """The virtual rig's effect as seen from its ramp record's first sample: the simulation starts its shafts
    at angle 0 a guard interval before the record (uqgear.rig.virtual_runup), so the record's shafts start
    turned on by the angle of that interval."""
    guard = math.ceil(RECORD_GUARD * FS) / FS
    # the profile before the record is the ramp continued back: speed start + rate (t - guard), t from 0 to guard
    turned = (start * guard - rate * guard**2 / 2.0) * math.pi / 30.0
    teeth = turned * design.z1 / (2.0 * math.pi)
    if effect.name == "tooth_damage":
        return effect.turned(design, int(round(teeth)), 0.0)
    shaft = design.z1 if effect.values["shaft"] == "pinion" else design.z2
    phase = effect.values["phase"] + 2.0 * math.pi * teeth / shaft
    return effect.with_values(phase=(phase + math.pi) % (2.0 * math.pi) - math.pi)


@pytest.mark.parametrize(
    "effect",
    [
        make_effect("eccentricity", {"shaft": "gear", "amplitude": 12e-6, "kappa": 0.03, "phase": 1.0}),
        make_effect("tooth_damage", {"gear": "gear", "tooth": 7, "depth": 0.35}),
    ],
    ids=["gear run-out", "gear tooth damage"],
)
def test_effects_turned_to_each_segments_place_on_its_ramp_reproduce_it(design, effect):
    """A gear effect on a run-up of segments of 1.2-2 gear revolutions: with the effect turned on to where
    each segment starts on its ramp (Effect.turned), the model at the truth reproduces every segment's lines
    to 2e-3 of the channel's largest; left where each segment's run starts, up to ten times as far off."""
    truth = {"mesh_stiffness_scale": 0.96, "zeta_mesh": 0.045, "adhesion_torque": [30e3]}
    ramps = {"start_speed": [1150.0], "stop_speed": [2150.0], "rate": [200.0], "drive_torque": [8000.0]}
    rig = simulate_runup_campaign(design, ramps, true_parameters=truth, effects=[effect], relative_noise=0.0, seed=3)
    segments = steady_campaign(rig, design=design)
    case = prepare_case(segments, rig_design(rig), seed=np.random.SeedSequence(1))
    recorded = json.loads(segments.attrs["true_parameters"])
    adhesion = recorded.pop("adhesion_torque")
    true_design, scale, _ = true_model(design, recorded)
    in_record = _record_frame(effect, design, 1150.0, 200.0)

    def task_of(op: int) -> RunTask:
        return RunTask(op, true_design, scale, adhesion[op], (in_record,), "free")

    turned = _line_errors(case, case.simulator, task_of)
    assert np.all(turned < 2e-3), turned
    unturned = CampaignSimulator(
        design, case.speeds, case.drive_torques, case.fs, case.size, case.channels,
        segments=[dataclasses.replace(segment, start_angle=0.0, start_time=0.0) for segment in case.simulator.segments],
    )
    left = _line_errors(case, unturned, task_of)
    assert np.max(left) > 10.0 * np.max(turned), (left, turned)
