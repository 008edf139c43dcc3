"""Cross-channel consistency of a named effect, and the encoder run-out that tests it.

Synthetic held-out figures with a known answer for the rule
(:mod:`uqgear.diagnosis.verdict.cross_channel`), the verdict it gives, and the virtual
rig's encoder-mounting run-out checked against its closed form; constructed campaigns
with a known answer: a run-out and an encoder's run-out too small for the accelerometers (not told
apart), and one they see (named).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from helpers import candidate_score

from uqgear.diagnosis.scoring import RunOutCheck
from uqgear.diagnosis.verdict import decide
from uqgear.diagnosis.verdict.cross_channel import check_channels, one_channel_character
from uqgear.physics.design import load_design
from uqgear.rig.features import extract_features
from uqgear.rig.virtual_rig import simulate_campaign

CHANNELS = ("te", "acc_pinion", "acc_gear")


def _score(effect, gains, before, after, **figures):
    return candidate_score(effect, 60.0, 0.8, low=0.6, gap_with_effect=0.3, effect_gain=40.0,
                           channel_gains=tuple(gains), channel_gaps_before=tuple(before),
                           channel_gaps_after=tuple(after), channels=CHANNELS, **figures)


def test_evidence_on_one_channel_alone_is_that_sensors():
    # a run-out fitted to the TE's shaft lines; both accelerometers gain nothing (under the 5-nat rule)
    run_out = _score("eccentricity", [140.0, 2.0, 1.5], [2.1, 0.1, 0.0], [0.3, 0.1, 0.0])
    check = check_channels(run_out)
    assert (check.consistent, check.channel, check.kind) == (False, 0, "one_channel")
    assert check.others == pytest.approx(3.5)
    decision = decide(2.1, [run_out])
    assert decision.verdict == "unexplained" and decision.one_channel == "te"
    assert "on te alone" in decision.reason and "eccentricity" in decision.reason
    # the rig's gap on the TE alone: a nominal refit's few nats on the clean accelerometers are no evidence
    refit = _score("eccentricity", [50.4, 3.0, 3.2], [2.87, 0.0, 0.0], [1.96, 0.0, 0.0])
    assert check_channels(refit).kind == "one_channel"
    # the same effect with its mesh modulation seen by the accelerometers is a gear's
    modulated = _score("eccentricity", [140.0, 9.0, 7.0], [2.1, 0.6, 0.5], [0.3, 0.1, 0.1])
    assert check_channels(modulated).consistent
    assert decide(2.1, [modulated]).verdict == "eccentricity"


def test_an_effect_too_weak_for_the_other_channels_is_not_told_from_the_one_channels_artefact():
    # a run-out that explains the TE's gap; as fitted it would gain under a nat on each accelerometer
    weak = _score("eccentricity", [140.0, 0.4, -0.3], [2.1, 0.0, 0.0], [0.2, 0.0, 0.0],
                  channel_reach=(150.0, 0.6, 0.3))
    check = check_channels(weak)
    assert (check.consistent, check.kind, check.unseen) == (False, "one_channel", True)
    assert check.reach == pytest.approx(0.9) and check.needed == 10.0
    decision = decide(2.1, [weak])
    assert decision.verdict == "inconclusive" and decision.open_gap and decision.one_channel == "te"
    ambiguity = decision.ambiguity
    assert (ambiguity.effect, ambiguity.channel) == ("eccentricity", "te")
    # both explanations named, and what would separate them: the family's, the sensor's and a reference
    assert "encoder's mounting run-out" in ambiguity.artefact
    assert "eccentricity" in decision.reason and "encoder's mounting run-out" in decision.reason
    separate = " ".join(ambiguity.separated_by)
    assert "higher speed" in separate and "second encoder" in separate and "healthy reference" in separate
    record = ambiguity.summary()
    assert [entry["kind"] for entry in record["candidates"]] == ["effect", "sensor_artefact"]
    assert record["reach"] == {"acc_pinion": 0.6, "acc_gear": 0.3}


def test_an_effect_the_other_channels_could_see_and_do_not_is_still_that_sensors():
    # the same fit predicting 30 nats on the accelerometers, which gain nothing: the rig contradicts it
    seen = _score("eccentricity", [140.0, 0.4, -0.3], [2.1, 0.0, 0.0], [0.2, 0.0, 0.0],
                  channel_reach=(150.0, 18.0, 12.0))
    assert not check_channels(seen).unseen
    decision = decide(2.1, [seen])
    assert decision.verdict == "unexplained" and decision.ambiguity is None and "on te alone" in decision.reason
    # an effect that explains only part of the gap, or a gap within noise, is no ambiguity either
    partial = candidate_score("tooth_damage", 60.0, 0.3, low=0.25, gap_with_effect=1.4, effect_gain=40.0,
                              channel_gains=(140.0, 0.4, -0.3), channel_gaps_before=(2.1, 0.0, 0.0),
                              channel_gaps_after=(1.4, 0.0, 0.0), channels=CHANNELS, channel_reach=(150.0, 0.6, 0.3))
    assert decide(2.1, [partial]).verdict == "unexplained"
    assert decide(0.4, [_score("eccentricity", [140.0, 0.4, -0.3], [0.4, 0.0, 0.0], [0.1, 0.0, 0.0],
                               channel_reach=(150.0, 0.6, 0.3))]).verdict == "none"
    # a family without a look-alike names the sensor's artefacts in general, and its own separating records
    other = decide(2.1, [_score("tooth_damage", [0.4, -0.3, 140.0], [0.1, 0.0, 2.1], [0.0, 0.0, 0.2],
                                channel_reach=(0.2, 0.1, 90.0))])
    assert other.verdict == "inconclusive" and other.ambiguity.channel == "acc_gear"
    assert "gear-side accelerometer's own artefact" in other.ambiguity.artefact
    assert other.ambiguity.separated_by[0].startswith("records at a higher load and speed")


def test_the_reach_is_half_the_squared_shift_the_fit_makes_per_channel():
    from uqgear.diagnosis.scoring import channel_reach

    rng = np.random.default_rng(4)
    base = rng.normal(size=(5, 3, 7))
    shift = np.zeros_like(base)
    shift[:, 0, 2] = 3.0                     # the effect moves one TE feature by 3 noise spreads in every run
    shift[:, 2, :] = 0.1                     # and every acc_gear feature by a tenth
    with_effect = base - shift
    with_effect[1, 1, 4] = np.nan            # a feature not compared in one run
    np.testing.assert_allclose(channel_reach(with_effect, base), (0.5 * 5 * 9.0, 0.0, 0.5 * 35 * 0.01))


def test_an_effect_must_not_predict_a_gap_the_rig_does_not_show():
    # good on the TE and acc_gear, but it leaves acc_pinion (within noise before) 1.4 off, 20 nats worse
    spoils = _score("tooth_damage", [300.0, -20.0, 80.0], [3.0, 0.2, 1.0], [0.4, 1.4, 0.2])
    check = check_channels(spoils)
    assert (check.consistent, check.channel, check.kind) == (False, 1, "predicts_unseen")
    decision = decide(3.0, [spoils])
    assert decision.verdict == "unexplained" and "acc_pinion" in decision.reason
    # noise-level wobble on a channel (a gap that crosses 0.5 but costs under 5 nats) does not count
    wobble = _score("tooth_damage", [300.0, -2.0, 80.0], [3.0, 0.45, 1.0], [0.4, 0.55, 0.2])
    assert check_channels(wobble).consistent


def test_a_torque_oscillation_may_show_on_the_te_alone_and_one_channel_campaigns_are_not_judged():
    stick_slip = _score("adhesion_oscillation", [90.0, 0.5, 0.2], [1.8, 0.0, 0.0], [0.2, 0.0, 0.0])
    assert check_channels(stick_slip).consistent
    alone = candidate_score("eccentricity", 60.0, 0.8, channel_gains=(140.0,), channel_gaps_before=(2.1,),
                            channel_gaps_after=(0.3,), channels=("te",))
    assert check_channels(alone).consistent


def test_the_gap_on_one_channel_is_reported_with_its_character():
    families = [{"channel": "te", "family": "shaft_gear", "score": 2.4, "character": ["order-locked"]},
                {"channel": "te", "family": "mesh_harmonic", "score": 0.0, "character": []},
                {"channel": "acc_gear", "family": "shaft_gear", "score": 0.9, "character": ["order-locked"]}]
    text = one_channel_character("te", families)
    assert text == "; on te the gap lies in shaft_gear (order-locked; gap 2.40)"


def test_a_run_out_read_without_the_te_is_not_beyond_the_pitch_error_bound():
    # measured in the TE (interval above the bound): beyond; read through the dynamics only: not measured
    assert RunOutCheck(40e-6, 22e-6, False, 30e-6).beyond
    assert not RunOutCheck(100e-6, 22e-6, False, 0.0).beyond
    assert RunOutCheck(40e-6, 22e-6, False).beyond      # no interval given: the point value


def test_encoder_run_out_puts_shaft_lines_in_the_te_alone():
    design = load_design("locomotive")
    ops = {"pinion_speed": np.array([900.0, 1500.0]), "drive_torque": np.array([6000.0, 7000.0])}
    options = {"seed": 11, "duration": 0.5, "run_in": 0.05, "relative_noise": 0.0}
    clean = simulate_campaign(design, ops, **options)
    encoder = simulate_campaign(design, ops, encoder_run_out={"pinion": 6e-6, "gear": 9e-6}, **options)
    # both accelerometers exactly as without it; the TE differs by the two lines only
    for name in ("acc_pinion", "acc_gear"):
        np.testing.assert_array_equal(clean[name].values, encoder[name].values)
    added = encoder["te"].values.astype(float) - clean["te"].values.astype(float)
    features = extract_features(clean.assign(te=(clean["te"].dims, added)), design, channels=["te"],
                                order_tracking="never")
    for shaft, amplitude in (("pinion", 6e-6), ("gear", 9e-6)):
        # a 0.5 s record holds a whole number of neither revolution: the window's line fit reads the amplitude
        np.testing.assert_allclose(features["te"].sel(feature=f"shaft_{shaft}1").values,
                                   amplitude, rtol=0.02)
    assert float(np.max(np.abs(features["te"].sel(feature="mesh1").values))) < 1e-3 * 6e-6
    assert math.isclose(float(np.std(added)), math.sqrt(0.5 * (6e-6**2 + 9e-6**2)), rel_tol=0.15)


@pytest.mark.slow
def test_an_encoder_run_out_is_the_te_sensors_and_a_real_run_out_beside_it_is_still_named():
    # small campaigns of the blind test's encoder kinds: 4 service runs of 0.5 s
    from uqgear.diagnosis import Diagnosis
    from uqgear.physics.effects import Eccentricity
    from uqgear.validation import operating_points_of

    design = load_design("locomotive")
    ops = operating_points_of("service", design, 4)
    options = {"duration": 0.5, "run_in": 0.3, "encoder_run_out": {"pinion": 8e-6, "gear": 8e-6}}
    alone = Diagnosis(workers=2, seed=3).fit(simulate_campaign(design, ops, seed=21, **options))
    assert alone.decision_.verdict == "unexplained" and alone.decision_.one_channel == "te"
    assert alone.effects_ == []
    run_out = Eccentricity({"shaft": "pinion", "amplitude": 12e-6, "phase": 1.0, "kappa": 0.03})
    beside = Diagnosis(workers=2, seed=3).fit(simulate_campaign(design, ops, seed=22, effects=[run_out], **options))
    assert [chosen.entry.effect for chosen in beside.effects_][:1] == ["eccentricity"]


def _gate_case(tracked, channels=("te", "acc_gear")):
    from types import SimpleNamespace

    names = ("shaft_gear1", "shaft_gear2", "shaft_gear3")
    observed = np.zeros((4, len(channels), 3))
    if "te" in channels:
        observed[:, 0, :] = 10.0          # the gear's pitch errors: TE shaft lines 10 noise spreads high
    return SimpleNamespace(
        speed=[{"order_tracked": tracked}] * 4, design=SimpleNamespace(z1=21, z2=101), channels=channels,
        layout=SimpleNamespace(names=names, columns=np.arange(3)), observed=observed,
        mask=lambda: np.ones(observed.shape, dtype=bool), line_noise_sigma=lambda: np.ones(observed.shape))


def test_the_pitch_error_gate_judges_a_tracked_gears_near_orders_on_its_te_shaft_lines():
    from uqgear.diagnosis.allowances.pitch_orders import judged_counts

    visible = {"sideband_pinion": {1: (40, 100), 2: (30, 100), 3: (25, 100)},
               "sideband_gear": {1: (30, 100), 2: (9, 100), 3: (17, 100)}}
    model = np.zeros((4, 2, 3))
    # not resampled: every order on its sidebands, as before
    assert judged_counts(_gate_case(False), visible, model, 3.0) == {
        family: {str(order): counts for order, counts in orders.items()} for family, orders in visible.items()}
    # resampled: z1/z2 = 0.21, so gear orders 1-3 lie within one pinion order of their carrier
    gear = judged_counts(_gate_case(True), visible, model, 3.0)["sideband_gear"]
    assert gear == {"1 (TE shaft line)": (4, 4), "2 (TE shaft line)": (4, 4), "3 (TE shaft line)": (4, 4)}
    # without a TE: the near orders pooled
    pooled = judged_counts(_gate_case(True, ("acc_gear",)), visible, np.zeros((4, 1, 3)), 3.0)
    assert pooled["sideband_gear"] == {"1-3 together": (56, 300)}
    assert pooled["sideband_pinion"]["2"] == (30, 100)


def _campaign(seed, **options):
    # a healthy rig of 4 service runs of 0.5 s, all three channels, 2 % sensor noise; perfect gears
    from uqgear.validation import operating_points_of

    design = load_design("locomotive")
    ops = operating_points_of("service", design, 4)
    return simulate_campaign(design, ops, seed=seed, duration=0.5, run_in=0.3, **options)


def _run_out(amplitude):
    from uqgear.physics.effects import Eccentricity

    # a pinion run-out without mesh-stiffness modulation
    return [Eccentricity({"shaft": "pinion", "amplitude": amplitude, "phase": 1.0, "kappa": 0.0})]


def _ambiguous_between_a_run_out_and_the_encoder(diagnosis):
    decision = diagnosis.decision_
    assert decision.verdict == "inconclusive", decision.reason
    assert diagnosis.effects_ == []
    ambiguity = decision.ambiguity
    assert (ambiguity.effect, ambiguity.channel) == ("eccentricity", "te")
    assert "encoder's mounting run-out" in ambiguity.artefact
    # the accelerometers could not have seen the fit: its reach there is far below what the rule asks
    assert sum(value for _, value in ambiguity.reach) < 0.2 * ambiguity.needed
    record = diagnosis.to_dict()
    assert record["verdict"] == "inconclusive" and record["ambiguity"]["channel"] == "te"
    assert [entry["name"] for entry in record["ambiguity"]["candidates"]][0] == "eccentricity"
    assert len(record["ambiguity"]["separated_by"]) == 3


@pytest.mark.slow
def test_a_run_out_too_small_for_the_accelerometers_is_not_told_from_an_encoders():
    from uqgear.diagnosis import Diagnosis

    rig = _campaign(31, effects=_run_out(30e-9))
    _ambiguous_between_a_run_out_and_the_encoder(Diagnosis(workers=2, seed=3).fit(rig))


@pytest.mark.slow
def test_an_encoder_run_out_as_small_is_not_told_from_a_shafts():
    from uqgear.diagnosis import Diagnosis

    rig = _campaign(31, encoder_run_out={"pinion": 30e-9})
    _ambiguous_between_a_run_out_and_the_encoder(Diagnosis(workers=2, seed=3).fit(rig))


@pytest.mark.slow
def test_a_run_out_the_accelerometers_see_is_named():
    from uqgear.diagnosis import Diagnosis

    # a hundred times larger, still without modulation: the housings respond above their noise
    diagnosis = Diagnosis(workers=2, seed=3).fit(_campaign(31, effects=_run_out(3e-6)))
    assert diagnosis.decision_.verdict == "eccentricity" and diagnosis.decision_.ambiguity is None
    assert "ambiguity" not in diagnosis.to_dict()
