"""The differential diagnosis against a healthy reference: condition-monitoring features, the change test,
operating points carried or refused, the change scoring, and the foreign virtual rig."""

import json
import math
from functools import partial

import numpy as np
import pytest

from uqgear.diagnosis import DiagnosisError, DiagnosisSettings
from uqgear.diagnosis.change.detection import carry_reference, judge_change, read_campaign
from uqgear.diagnosis.change.features import FEATURES, record_features
from uqgear.diagnosis.change.scoring import anchored_change, soft_l1
from uqgear.physics.design import load_design
from uqgear.rig.format import make_rig_dataset

FS = 20480.0
INDEX = {name.label: index for index, name in enumerate(FEATURES)}
DESIGN = load_design("locomotive")  # 21:101 teeth


def _records(speeds, *, seed, line=0.0, impulse=0.0, duration=1.0, noise=0.05):
    """Synthetic records with known content: mesh harmonics, optional pinion order-1 line and gear-once-per-rev
    impulses, white noise of known SD."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * FS)) / FS
    out = []
    for speed in speeds:
        f1 = speed / 60.0
        mesh = DESIGN.z1 * f1
        phase = rng.uniform(0, 2 * np.pi)
        x = 1.0 * np.sin(2 * np.pi * mesh * t + phase) + 0.3 * np.sin(4 * np.pi * mesh * t + 2 * phase)
        x += line * np.sin(2 * np.pi * f1 * t + rng.uniform(0, 2 * np.pi))
        if impulse:
            f2 = f1 * DESIGN.z1 / DESIGN.z2
            angle = (f2 * t + rng.uniform()) % 1.0
            x += impulse * np.exp(-0.5 * ((angle - 0.5) / 0.002) ** 2)
        out.append(x + noise * rng.standard_normal(t.size))
    return np.array(out)


def _campaign(speeds, torques=None, **options):
    speeds = np.asarray(speeds, dtype=float)
    torques = np.full(speeds.size, 5000.0) if torques is None else np.asarray(torques, dtype=float)
    te = _records(speeds, **options)
    return make_rig_dataset(
        time=np.arange(te.shape[1]) / FS, pinion_speed=speeds, drive_torque=torques,
        adhesion_torque_lower=torques * 4.3, adhesion_torque_upper=torques * 5.3, channels={"te": te},
        design=DESIGN, title="synthetic", source="synthetic", history="synthetic")


SPEEDS = [800.0, 1400.0, 2000.0, 2600.0, 3200.0]


# ---------------------------------------------------------------------------------------------- features


def test_features_of_a_sine_at_pinion_order_one_are_its_closed_forms():
    t = np.arange(int(FS)) / FS
    amplitude, f1 = 2.0, 1200.0 / 60.0
    values = record_features(amplitude * np.sin(2 * np.pi * f1 * t), FS, f1, DESIGN.z1, DESIGN.z2, noise=0.0)
    assert math.exp(values[INDEX["rms"]]) == pytest.approx(amplitude**2 / 2, rel=1e-3)
    assert math.exp(values[INDEX["kurtosis"]]) == pytest.approx(1.5, rel=1e-3)   # a sine's kurtosis
    assert math.exp(values[INDEX["pinion_order1"]]) == pytest.approx(amplitude**2, rel=1e-2)
    assert math.exp(values[INDEX["pinion_order2"]]) < 1e-6 * amplitude**2


def test_gaussian_noise_mixes_into_the_kurtosis_in_closed_form():
    t = np.arange(int(FS)) / FS
    sine = np.sin(2 * np.pi * 20.0 * t)
    values = record_features(sine, FS, 20.0, DESIGN.z1, DESIGN.z2, noise=0.5)
    # m2 = 0.5 + 0.5, m4 = 3/8 + 6 * 0.5 * 0.5 + 3 * 0.25
    assert math.exp(values[INDEX["kurtosis"]]) == pytest.approx((0.375 + 1.5 + 0.75) / 1.0, rel=1e-3)


# ---------------------------------------------------------------------------------------------- the change test


def test_two_healthy_campaigns_of_one_rig_show_no_change():
    settings = DiagnosisSettings()
    reference = read_campaign(_campaign(SPEEDS, seed=1), DESIGN, ("te",))
    test = read_campaign(_campaign(SPEEDS, seed=2), DESIGN, ("te",))
    change = judge_change(reference, test, settings=settings)
    assert not change.changed
    largest = change.summary()["largest"]
    assert abs(largest["change_db"]) < largest["threshold_db"]


@pytest.mark.parametrize("options, family, shaft", [
    ({"line": 0.2}, "shaft_line", "pinion"),
    ({"impulse": 1.5}, "tsa_residual_kurtosis", "gear"),
])
def test_a_known_change_is_found_where_it_was_put(options, family, shaft):
    settings = DiagnosisSettings()
    reference = read_campaign(_campaign(SPEEDS, seed=1), DESIGN, ("te",))
    test = read_campaign(_campaign(SPEEDS, seed=2, **options), DESIGN, ("te",))
    change = judge_change(reference, test, settings=settings)
    assert change.changed
    groups = {(entry["family"], entry["shaft"]) for entry in change.where()}
    assert (family, shaft) in groups
    found = next(e for e in change.where() if (e["family"], e["shaft"]) == (family, shaft))
    assert found["direction"] == "up" and len(found["ops"]) == len(SPEEDS)


def test_a_change_inside_the_replaced_gears_allowance_is_none_for_replaced_gears_only():
    # the whole record 4 dB down: beyond the run-to-run allowance, inside a replaced gear set's spread
    reference = read_campaign(_campaign(SPEEDS, seed=1), DESIGN, ("te",))
    test = _campaign(SPEEDS, seed=2)
    scaled = read_campaign(test.assign(te=test["te"] * 10 ** (-4 / 20)), DESIGN, ("te",))
    settings = DiagnosisSettings()
    assert judge_change(reference, scaled, settings=settings, gears="same").changed
    assert not judge_change(reference, scaled, settings=settings, gears="replaced").changed


# ---------------------------------------------------------------------------------------------- operating points


def test_mismatched_operating_points_are_carried_inside_the_range_and_not_judged_outside():
    settings = DiagnosisSettings()
    reference = read_campaign(_campaign(SPEEDS, seed=1), DESIGN, ("te",))
    # between reference runs, on one, and beyond the fastest
    test_speeds = np.array([1100.0, 2000.0, 3600.0])
    test = read_campaign(_campaign(test_speeds, seed=2), DESIGN, ("te",))
    carried = carry_reference(reference, test.speeds, test.torques, speed_tolerance=0.01, torque_tolerance=0.05)
    assert carried.inside.tolist() == [True, True, False]
    assert "outside the reference's 800 to 3200 rpm" in carried.reasons[2]
    # linear in speed between the two nearest reference runs, with a spread that vanishes at a reference run
    weight = (1100.0 - 800.0) / 600.0
    np.testing.assert_allclose(carried.values[0], (1 - weight) * reference.values[0] + weight * reference.values[1])
    assert np.all(carried.spread[1] == 0.0) and np.any(carried.spread[0] > 0.0)
    change = judge_change(reference, test, settings=settings)
    summary = change.summary()
    assert summary["judged_runs"] == 2
    assert [entry["op"] for entry in summary["inconclusive_runs"]] == [2]
    assert not change.changed


def test_a_torque_off_the_references_is_outside_and_a_test_wholly_outside_is_refused():
    settings = DiagnosisSettings()
    reference = read_campaign(_campaign(SPEEDS, seed=1), DESIGN, ("te",))
    test = read_campaign(_campaign([1400.0, 2000.0], torques=[5000.0, 6000.0], seed=2), DESIGN, ("te",))
    change = judge_change(reference, test, settings=settings)
    assert change.judged.tolist() == [True, False]
    assert "more than 5% off the reference's 5000 N m" in change.reasons[1]
    outside = read_campaign(_campaign([4000.0, 5000.0], seed=3), DESIGN, ("te",))
    with pytest.raises(DiagnosisError, match="no test operating point lies inside the reference.s range"):
        judge_change(reference, outside, settings=settings)


def test_the_cli_refuses_a_reference_that_covers_no_test_point_in_one_line(tmp_path):
    import subprocess
    import sys

    from uqgear.rig.format import write_rig

    reference, test = _campaign(SPEEDS[:3], seed=1), _campaign([3600.0, 3800.0], seed=2)
    write_rig(tmp_path / "ref.nc", reference)
    write_rig(tmp_path / "test.nc", test)
    completed = subprocess.run(
        [sys.executable, "-m", "uqgear", "diagnose", str(tmp_path / "test.nc"), "--reference",
         str(tmp_path / "ref.nc"), "--out", str(tmp_path / "out")], capture_output=True, text=True)
    assert completed.returncode == 2, completed.stderr
    lines = completed.stderr.strip().splitlines()
    assert len(lines) == 1 and "no test operating point lies inside the reference's range" in lines[0]
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------------- change scoring


def test_an_added_power_is_carried_onto_the_reference_and_a_kurtosis_follows_its_fourth_moment():
    anchor = np.zeros((1, 1, len(FEATURES)))
    baseline = np.zeros_like(anchor)
    anchor[..., INDEX["rms"]] = math.log(4.0)          # rig reference: m2 = 4, kurtosis 3
    anchor[..., INDEX["kurtosis"]] = math.log(3.0)
    baseline[..., INDEX["rms"]] = math.log(1.0)        # model without the effect: m2 = 1, kurtosis 3
    baseline[..., INDEX["kurtosis"]] = math.log(3.0)
    effect = baseline.copy()
    effect[..., INDEX["rms"]] = math.log(2.0)          # with the effect: m2 = 2, m4 = 10
    effect[..., INDEX["kurtosis"]] = math.log(10.0 / 4.0)
    change = anchored_change(anchor, baseline, effect, np.ones((1, 1)))
    assert math.exp(change[0, 0, INDEX["rms"]]) == pytest.approx(5.0 / 4.0)
    # an independent part of m2 = 1 and m4 = 10 - 3 - 6 * 1 * 1 = 1 added to the rig's m2 = 4, m4 = 48:
    # m4 = 48 + 6 * 4 * 1 + 1 = 73 over m2^2 = 25
    assert math.exp(change[0, 0, INDEX["kurtosis"]] + anchor[0, 0, INDEX["kurtosis"]]) == pytest.approx(73 / 25)


def test_soft_l1_is_quadratic_near_zero_and_linear_far_out():
    assert soft_l1(np.array([1e-3])) == pytest.approx(1e-6, rel=1e-3)
    assert soft_l1(np.array([1000.0])) == pytest.approx(2 * 999.0005, rel=1e-6)


# ---------------------------------------------------------------------------------------------- the foreign rig


def test_the_foreign_rig_records_a_valid_campaign_with_its_gears_and_effects():
    from uqgear.physics.effects import make_effect
    from uqgear.rig.foreign_rig import draw_gears, simulate_foreign_campaign, single_pitch_tolerance
    from uqgear.rig.format import validate_rig
    from uqgear.rig.virtual_rig import default_operating_points

    ops = default_operating_points(DESIGN).isel(op=[0, 5])
    gears = draw_gears(DESIGN, 6, 3)
    assert gears.pinion.shape == (DESIGN.z1, 3) and gears.gear.shape == (DESIGN.z2, 3)
    # ISO 1328-1 f_pt, grade 5, pinion d = 189 mm, m = 9 mm: 0.3 (9 + 0.4 sqrt(189)) + 4 = 8.35 um
    assert single_pitch_tolerance(DESIGN, 5)[0] == pytest.approx(8.35e-6, rel=1e-3)
    run_out = make_effect("eccentricity", {"shaft": "pinion", "amplitude": 20e-6})
    rig = simulate_foreign_campaign(DESIGN, ops, gears=gears, effects=[run_out], seed=4, duration=0.2)
    validate_rig(rig, where="foreign rig")
    assert json.loads(rig.attrs["effects"])[0]["values"]["amplitude"] == 20e-6
    # the run-out appears in the encoder TE as a pinion order-1 line: of its size where the shafts follow it
    # quasi-statically (600 rpm), amplified nearer the torsional modes
    features = read_campaign(rig, DESIGN, ("te",))
    line = np.sqrt(np.exp(features.values[:, 0, INDEX["pinion_order1"]]))
    assert line[0] == pytest.approx(20e-6, rel=0.15) and line[1] > 15e-6
    # the same seed gives the same campaign
    again = simulate_foreign_campaign(DESIGN, ops, gears=gears, effects=[run_out], seed=4, duration=0.2)
    np.testing.assert_array_equal(rig["te"].values, again["te"].values)


def test_an_effects_visibility_grows_with_it_from_zero_and_crosses_the_threshold_between_tiny_and_strong():
    """The visibility oracle: the noise-free change an effect makes, over the thresholds a change test drew
    from two healthy campaigns; none for no effect, below 1 for a run-out far under the gears' own errors,
    above 1 for one that dominates the pinion's order-1 line, growing with the run-out in between and, for a
    small one, in proportion to it."""
    from uqgear.physics.effects import make_effect
    from uqgear.rig.foreign_rig import draw_gears, simulate_foreign_campaign
    from uqgear.rig.virtual_rig import default_operating_points
    from uqgear.validation.foreign_suite import change_visibility

    ops = default_operating_points(DESIGN).isel(op=[0, 5])
    gears = draw_gears(DESIGN, 6, 3)
    channels = ("te", "acc_pinion", "acc_gear")
    reference = read_campaign(simulate_foreign_campaign(DESIGN, ops, gears=gears, seed=1, duration=0.5), DESIGN,
                              channels)
    healthy = read_campaign(simulate_foreign_campaign(DESIGN, ops, gears=gears, seed=2, duration=0.5), DESIGN,
                            channels)
    test = judge_change(reference, healthy, settings=DiagnosisSettings())

    def seen(amplitude):
        effects = [make_effect("eccentricity", {"shaft": "pinion", "amplitude": amplitude})] if amplitude else []
        campaign = partial(simulate_foreign_campaign, DESIGN, ops, gears=gears, seed=2, duration=0.5)
        return change_visibility(test, DESIGN, campaign, effects)

    visibility = [seen(amplitude) for amplitude in (0.0, 0.02e-6, 0.2e-6, 2e-6, 20e-6)]
    assert visibility[0] == 0.0
    assert visibility[1] < 1.0 < visibility[4]
    assert visibility[1] < visibility[2] < visibility[3] < visibility[4]
    # a line much weaker than the gears' own order-1 line changes its ln power by 2 (a / A) cos(phase) to first
    # order: ten times the run-out, ten times the change
    assert visibility[2] / visibility[1] == pytest.approx(10.0, rel=0.05)


# ---------------------------------------------------------------------------------------------- end to end


def test_the_foreign_suite_finds_no_change_between_healthy_campaigns_nor_from_an_effect_below_its_thresholds():
    from uqgear.validation.foreign_suite import run_foreign_suite

    result = run_foreign_suite(seed=3, effects=["bearing_clearance"], n_ops=4, duration=0.5)
    assert [entry["campaign"] for entry in result["campaigns"]] == [
        "healthy_same", "healthy_replaced", "bearing_clearance-0", "healthy_bearing_check"]
    assert result["healthy_none"] and not result["false_effect_on_healthy"]
    for entry in result["campaigns"]:
        assert abs(entry["largest_change_db"]) < entry["largest_threshold_db"]
    # the clearance's own noise-free change stays below the change test's thresholds: `none` is all the data
    # support, wrong against the truth, right where only visible effects count
    clearance = result["campaigns"][2]
    assert clearance["verdict"] == "none" and not clearance["exactly_right"]
    assert 0.0 < clearance["visibility"] < 1.0 and clearance["visible"] is False and clearance["right_where_visible"]
    assert result["exactly_right"] == 0.75 and result["exactly_right_visible"] == 1.0
    assert result["effects_visible"] == 0


def test_bearing_clearances_bring_a_healthy_control_on_their_own_plan_and_the_cli_writes_a_new_folder(
        tmp_path, monkeypatch):
    from uqgear.cli import main
    from uqgear.validation import foreign_suite

    plan = foreign_suite.foreign_campaign_plan(["eccentricity", "bearing_clearance"], 1)
    assert plan[-1] == ("healthy_bearing_check", None)
    assert [name for _, name in plan] == [None, None, "eccentricity", "bearing_clearance", None]
    assert ("healthy_bearing_check", None) not in foreign_suite.foreign_campaign_plan(["eccentricity"], 1)
    # the suite's record lands in a folder that did not exist (its work replaced by a stand-in)
    monkeypatch.setattr(foreign_suite, "run_foreign_suite", lambda **_: {
        "campaigns": [], "exactly_right": 1.0, "effects_exactly_right": 1.0, "exactly_right_visible": 1.0,
        "effects_visible": 0, "healthy_none": True})
    out = tmp_path / "new" / "foreign"
    assert main(["blindtest", "--suite", "foreign", "--out", str(out)]) == 0
    assert json.loads((out / "blindtest.json").read_text())["healthy_none"] is True
    assert sorted(path.name for path in out.parent.iterdir()) == ["foreign"]


@pytest.mark.slow
def test_a_run_out_added_on_the_foreign_rig_is_named_with_its_share_on_the_reports_first_screen(tmp_path):
    from uqgear.diagnosis import diagnose
    from uqgear.physics.effects import make_effect
    from uqgear.rig.foreign_rig import draw_gears, simulate_foreign_campaign
    from uqgear.rig.virtual_rig import default_operating_points

    ops = default_operating_points(DESIGN).isel(op=[0, 2, 4, 6])
    gears = draw_gears(DESIGN, 6, 5)
    reference = simulate_foreign_campaign(DESIGN, ops, gears=gears, seed=6)
    run_out = make_effect("eccentricity", {"shaft": "pinion", "amplitude": 12e-6, "phase": 1.0, "kappa": 0.03})
    test = simulate_foreign_campaign(DESIGN, ops, gears=gears, effects=[run_out], seed=7)
    content = diagnose(test, tmp_path / "out", reference=reference, effects=["eccentricity", "tooth_damage"],
                       seed=3, workers=1)
    assert content["verdict"] == "eccentricity", content["reason"]
    named = content["change"]["named"]
    assert named["parameters"]["shaft"] == "pinion" and named["share"] >= 0.2
    assert 4e-6 <= named["parameters"]["amplitude"] <= 4e-5     # the run-out's size, within the model form's error
    where = content["change"]["test"]["where"]
    assert any(entry["channel"] == "te" and entry["family"] == "shaft_line" and entry["shaft"] == "pinion"
               for entry in where)
    assert set(content["change"]["timing_s"]) == {"change_test", "change_scoring"}
    page = (tmp_path / "out" / "report.html").read_text()
    first = page[page.index("What changed since the healthy reference"):page.index('class="verdict"')]
    assert "Changed since the reference: te shaft line of the pinion up" in first
    assert "Verdict eccentricity: eccentricity[pinion]" in first and "of the change" in first
