"""The first line of a diagnosis report: verdict, certainty, evidence and next step, from diagnosis.json."""

from __future__ import annotations

from uqgear.report.diagnosis_first_screen import at_a_glance
from uqgear.report.diagnosis_report import diagnosis_findings

SPEEDS = {"speed": [{"stated_rpm": rpm} for rpm in (600.0, 800.0, 1250.0, 1700.0)]}


def test_a_named_effect_says_what_to_inspect_and_where_the_evidence_is():
    content = {"verdict": "eccentricity", "borderline": [], "rig": SPEEDS,
               "where": [{"channel": "te", "feature": "shaft_gear1", "family": "shaft_gear", "ops": [0, 3],
                          "score": 4.0},
                         {"channel": "acc_gear", "feature": "mesh1_sb_gear+1", "family": "sideband_gear",
                          "ops": [1], "score": 3.1}],
               "effects": [{"effect": "eccentricity", "parameters": {"shaft": "gear", "amplitude": 1.2e-5}}]}
    finding = at_a_glance(content)
    assert finding.text.startswith("At a glance: eccentricity (sure: no deciding figure is near its threshold)")
    assert "evidence on te, acc_gear at 600, 800 and 1700 rpm" in finding.text
    assert finding.facts["next"] == "measure the run-out of the gear shaft"
    # it opens the report's headline
    assert diagnosis_findings(content)[0].topic == "at_a_glance"


def test_unexplained_on_one_channel_points_at_the_sensor_and_a_borderline_gap_at_more_runs():
    sensor = at_a_glance({"verdict": "unexplained", "one_channel_gap": "te", "borderline": [], "rig": SPEEDS,
                          "where": [{"channel": "te", "ops": [2]}]})
    assert "check the te sensor and its mounting" in sensor.text and "1250 rpm" in sensor.text
    unexplained = at_a_glance({"verdict": "unexplained", "borderline": [], "where": []})
    assert "record a healthy reference campaign" in unexplained.facts["next"]
    borderline = at_a_glance({"verdict": "none", "where": [], "borderline": [
        {"figure": "nominal_gap", "value": 0.524, "threshold": 0.5, "interval": [0.0, 0.83]}]})
    assert "(borderline: nominal gap 0.52 against 0.5, 90 % interval 0 to 0.83)" in borderline.text
    assert borderline.facts["next"] == "record more runs before acting"
    healthy = at_a_glance({"verdict": "none", "borderline": [], "where": [{"channel": "te", "ops": [1]}]})
    assert healthy.facts["next"].startswith("nothing to do") and "within noise" in healthy.text
    assert "record more runs" in at_a_glance({"verdict": "inconclusive"}).facts["next"]


def test_an_ambiguous_verdict_names_both_explanations_and_what_separates_them_in_one_sentence():
    ambiguity = {"candidates": [{"kind": "effect", "name": "eccentricity"},
                                {"kind": "sensor_artefact", "name": "te sensor artefact",
                                 "description": "an encoder's mounting run-out"}],
                 "channel": "te", "reach": {"acc_pinion": 0.4, "acc_gear": 0.1}, "needed": 10.0,
                 "separated_by": ["records at a higher speed: a run-out's response grows with speed",
                                  "a second encoder on the same shaft: an encoder's own artefact moves with it",
                                  "a healthy reference campaign: a sensor's artefact is in both"]}
    finding = at_a_glance({"verdict": "inconclusive", "one_channel_gap": "te", "ambiguity": ambiguity,
                           "borderline": [], "rig": SPEEDS, "where": [{"channel": "te", "ops": [1, 2]}]})
    assert finding.text.startswith("At a glance: inconclusive between eccentricity and an encoder's mounting "
                                   "run-out on te, which these data cannot tell apart")
    assert finding.facts["next"] == ("tell the two apart with records at a higher speed; or a second encoder on "
                                     "the same shaft; or a healthy reference campaign")
    assert finding.text.count(". ") == 0 and finding.text.endswith(".")
    # the report's verdict line names both too
    verdict_line = diagnosis_findings({"verdict": "inconclusive", "ambiguity": ambiguity, "borderline": []})[1]
    assert "eccentricity and an encoder's mounting run-out explain the gap on te alike" in verdict_line.text
    # without the record an inconclusive verdict still asks for more runs
    assert "record more runs" in at_a_glance({"verdict": "inconclusive"}).facts["next"]
