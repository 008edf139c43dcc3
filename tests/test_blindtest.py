"""Tests of the blind checks of the gap diagnosis (uqgear.validation).

The scoring (confusion matrix, accuracies, false alarms, thresholds) is
checked on hand-made verdicts; the campaign plan on its counts and ladder;
a small blind test (slow) generates campaigns with the virtual rig, withholds
their labels and checks the verdicts against the truth.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

from uqgear import validation as B
from uqgear.diagnosis import EFFECT_NAMES, DiagnosisError, effect_family
from uqgear.physics.design import load_design


def test_second_design_is_the_one_asked_for():
    design = B.second_design(load_design("locomotive"))
    assert (design.z1, design.z2, design.module, design.x1, design.x2, design.face_width) == \
        (17, 88, 0.010, 0.3, -0.3, 0.130)


def test_plan_covers_every_effect_strength_and_design():
    specs = B.plan_campaigns(3, np.random.default_rng(4))
    assert len(specs) == 3 * (len(EFFECT_NAMES) + 2)
    for effect in EFFECT_NAMES:
        mine = [s for s in specs if s.truth == effect]
        assert {s.strength for s in mine} == set(B.STRENGTHS)
        assert {s.design_name for s in mine} == {"reference", "second"}
        # the effect is buildable with its drawn values
        assert all(len(s.effects()) == 1 for s in mine)
    healthy = [s for s in specs if s.truth == B.HEALTHY]
    assert len(healthy) == 6 and all(s.effects() == [] for s in healthy)
    # healthy controls cover both plans on both designs; a clearance can only show on the bearing check
    assert {(s.plan, s.design_name) for s in healthy} == {(plan, name) for plan in B.PLANS
                                                         for name in ("reference", "second")}
    assert all(s.plan == ("bearing_check" if s.truth == "bearing_clearance" else "service")
               for s in specs if s.truth != B.HEALTHY)
    again = B.plan_campaigns(3, np.random.default_rng(4))
    assert [s.effect_values for s in again] == [s.effect_values for s in specs]


def test_plan_rejects_bad_requests():
    rng = np.random.default_rng(0)
    with pytest.raises(DiagnosisError, match="n_per_effect: expected an integer >= 1"):
        B.plan_campaigns(0, rng)
    with pytest.raises(DiagnosisError, match="effects: 'gear_whine' is not a library effect"):
        B.plan_campaigns(1, rng, effects=["gear_whine"])
    with pytest.raises(DiagnosisError, match="designs: 'third' unknown"):
        B.plan_campaigns(1, rng, designs=["third"])
    with pytest.raises(DiagnosisError, match="n_ops: expected an integer >= 3"):
        B.blindtest("unused", n_ops=2)
    with pytest.raises(DiagnosisError, match="plan: expected one of service, bearing_check"):
        B.operating_points_of("overspeed", load_design("locomotive"))
    with pytest.raises(DiagnosisError, match="suite: expected one of library, real_world, encoderless, runup; "
                       "got 'fleet'"):
        B.planned_campaigns(0, suite="fleet")


def test_planned_campaigns_are_the_blind_tests_own(tmp_path):
    # the real-world suite's campaigns in order, each design the one its spec names, a seed each
    planned = B.planned_campaigns(1, suite="real_world", n_per_effect=2)
    specs = B.plan_real_world(2, np.random.default_rng(np.random.SeedSequence(1).spawn(2)[0]))
    assert [spec.identifier for spec, _, _ in planned] == [spec.identifier for spec in specs]
    reference = load_design("locomotive")
    designs = {"reference": reference, "second": B.second_design(reference)}
    assert designs["second"] != reference
    assert all(design == designs[spec.design_name] for spec, design, _ in planned)
    assert {spec.design_name for spec, _, _ in planned} == {"reference", "second"}
    assert len({seed.spawn_key for _, _, seed in planned}) == len(planned)
    # a wrong suite fails blindtest before anything is written
    with pytest.raises(DiagnosisError, match="suite: expected one of"):
        B.blindtest(tmp_path / "out", suite="fleet")
    assert not (tmp_path / "out").exists()


def test_the_encoderless_suite_draws_every_family_without_a_te_from_its_own_stream():
    planned = B.planned_campaigns(5, suite="encoderless", n_per_effect=4)
    specs = [spec for spec, _, _ in planned]
    # its own stream: the seed's third child, so the other suites' plans are the ones they were
    third = np.random.SeedSequence(5).spawn(3)[2].spawn(2)[0]
    assert [s.identifier for s in specs] == [s.identifier for s in B.plan_encoderless(4, np.random.default_rng(third))]
    assert [s.identifier for s, _, _ in B.planned_campaigns(5, suite="real_world", n_per_effect=1)] == [
        s.identifier for s in B.plan_real_world(1, np.random.default_rng(np.random.SeedSequence(5).spawn(2)[0]))
    ]
    assert len({seed.spawn_key for _, _, seed in planned}) == len(planned)
    for name in EFFECT_NAMES:
        family = effect_family(name)
        drawn = [s for s in specs if s.truth == name]
        assert len(drawn) == 4 and {s.plan for s in drawn} == {family.plan}
        assert all(family.ladder[0] <= s.strength_value <= family.ladder[2] for s in drawn)
        assert all(s.effect_values[family.strength] == s.strength_value for s in drawn)
    assert [s.truth for s in specs].count(B.HEALTHY) == 2
    assert all(s.nuisances["channels"] == ("acc_pinion", "acc_gear") for s in specs)
    assert sum("speed_wander" in s.nuisances for s in specs) == len(specs) // 2
    frequencies = [s.effect_values["frequency"] for s in specs if s.truth == "adhesion_oscillation"]
    assert all(6.0 <= f <= 30.0 for f in frequencies) and len(set(frequencies)) == 4


def test_plans_pick_their_runs():
    design = load_design("locomotive")
    service = B.operating_points_of("service", design, 4)
    assert service["pinion_speed"].tolist() == [600.0, 1250.0, 2800.0, 3800.0]
    check = B.operating_points_of("bearing_check", design)
    assert check["pinion_speed"].size == 8 and np.all(check["drive_torque"] == 1500.0)


def _campaign(truth, verdict, strength_value=1.0, detectable=True, shrink=None):
    return {"id": f"{truth}-{verdict}-{strength_value}", "truth": truth, "verdict": verdict,
            "strength": "-", "strength_value": strength_value, "design": "reference",
            "correct": truth == verdict,
            "correct_detectable": truth == verdict or (not detectable and verdict == B.HEALTHY),
            "detectable": detectable, "oracle_gap": 1.0, "nominal_gap": 1.0, "shrink_fraction": shrink,
            "seconds": 1.0}


def test_summary_counts_confusion_accuracy_and_false_alarms():
    campaigns = [_campaign("friction", "friction", 0.1, shrink=0.9),
                 _campaign("friction", "none", 0.02, detectable=False),
                 _campaign("friction", "friction", 0.05, shrink=0.7),
                 _campaign("eccentricity", "tooth_damage", 5e-6),
                 _campaign(B.HEALTHY, "none"), _campaign(B.HEALTHY, "torque_ripple")]
    content = B.summarise(campaigns, ["friction", "eccentricity"])
    counts = np.array(content["confusion"]["counts"])
    labels, verdicts = content["labels"], content["confusion"]["verdicts"]
    assert counts.sum() == 6
    assert counts[labels.index("friction"), verdicts.index("friction")] == 2
    assert counts[labels.index("eccentricity"), verdicts.index("tooth_damage")] == 1
    assert content["accuracy"] == pytest.approx(3 / 6)
    assert content["accuracy_detectable"] == pytest.approx(4 / 6)
    assert content["false_alarms"] == 1
    assert content["shrink"]["median"] == pytest.approx(0.8)
    friction = next(t for t in content["thresholds"] if t["effect"] == "friction")
    assert friction["detected_from"] == pytest.approx(0.05) and friction["missed_up_to"] == pytest.approx(0.02)
    assert "below detectability" in friction["note"]
    ds = B.blindtest_dataset(content)
    assert ds["confusion"].dims == ("truth", "verdict") and int(ds["confusion"].sum()) == 6


def test_effect_sets_are_scored_against_the_truth_and_against_what_the_data_can_tell():
    """set_exact against the true set; set_exact_identifiable against the effects visible beyond the model error."""
    def entry(truth, named, verdict, identifiable):
        return {"truth": truth[0] if truth else B.HEALTHY, "truth_effects": truth, "effects_named": named,
                "verdict": verdict, "shrink_shares": [0.5] * len(named), "identifiable_effects": identifiable}

    campaigns = [
        # a run-out the pitch errors could make, friction named: wrong set, right on what can be told
        entry(["eccentricity", "friction"], ["friction"], "friction", ["friction"]),
        # a run-out hidden in the allowance, nothing named: the same
        entry(["eccentricity"], [], "none", []),
        # both named and both visible: right either way
        entry(["eccentricity", "tooth_damage"], ["eccentricity", "tooth_damage"], "eccentricity",
              ["eccentricity", "tooth_damage"]),
        # an effect named that cannot be told is wrong either way
        entry(["tooth_damage"], ["tooth_damage", "friction"], "tooth_damage", ["tooth_damage"]),
        # a control is right only with `none`
        entry([], [], "unexplained", []),
        entry([], [], "none", []),
    ]
    sets = B.set_scores(campaigns, ["eccentricity", "friction", "tooth_damage"])
    assert sets["set_exact"] == pytest.approx(2 / 6)
    assert sets["set_exact_identifiable"] == pytest.approx(4 / 6)
    assert sets["effects_not_identifiable"] == 2
    # campaigns that do not record what can be told are scored against their truth
    old = [{key: value for key, value in c.items() if key != "identifiable_effects"} for c in campaigns]
    assert B.set_scores(old, ["eccentricity"])["set_exact_identifiable"] == pytest.approx(2 / 6)


@pytest.mark.slow
def test_small_blind_test(tmp_path):
    """Two withheld campaigns (a torque ripple and a healthy control, 4 runs) get the right verdicts."""
    content = B.blindtest(tmp_path, n_per_effect=1, effects=["torque_ripple"], n_healthy=1, n_ops=4,
                          duration=0.5, seed=3)
    assert content["n_campaigns"] == 2
    verdicts = {c["truth"]: c["verdict"] for c in content["campaigns"]}
    assert verdicts == {"torque_ripple": "torque_ripple", "none": "none"}
    assert content["false_alarms"] == 0
    ripple = next(c for c in content["campaigns"] if c["truth"] == "torque_ripple")
    assert ripple["oracle_gap"] > 1.0 and ripple["shrink_fraction"] >= 0.7
    on_disk = json.loads((tmp_path / "blindtest.json").read_text())
    assert on_disk["accuracy"] == pytest.approx(1.0)
    assert (tmp_path / "report.html").read_text().startswith("<!DOCTYPE html>")
    ds = xr.open_dataset(tmp_path / "blindtest.nc")
    assert int(ds["confusion"].sum()) == 2
    ds.close()
    # the diagnosis saw no label: the rig file it read carries the truth only in our copy
    assert (tmp_path / "campaigns" / ripple["id"] / "rig.nc").is_file()


@pytest.mark.slow
def test_small_blind_test_on_the_bearing_check(tmp_path):
    """A withheld clearance in both bearings, on 4 light-load bearing check runs, is named with its shrink."""
    content = B.blindtest(tmp_path, n_per_effect=1, effects=["bearing_clearance"], n_healthy=0, n_ops=4,
                          duration=0.5, seed=3, report=False)
    (campaign,) = content["campaigns"]
    assert campaign["plan"] == "bearing_check" and campaign["effect_values"]["bearing"] == "both"
    assert campaign["oracle_gap"] > 1.0
    assert campaign["verdict"] == "bearing_clearance", campaign["reason"]
    assert campaign["shrink_fraction"] >= 0.5
