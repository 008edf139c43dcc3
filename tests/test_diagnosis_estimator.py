"""The Diagnosis estimator and its settings (uqgear.diagnosis.estimator, uqgear.diagnosis.settings).

Fast tests: every threshold and budget of DiagnosisSettings states its
unit, rule and docs section and is checked when set, a study's ``diagnose``
analysis takes the documented ones, the estimator refuses bad settings
before any work and is never fitted by halves, a prepared campaign cannot
be changed and every allowance returns a new one, and a campaign that
cannot decide is concluded with the settings it was judged by. The six
steps on real campaigns are the labelled and blind-test diagnoses of
tests/test_diagnosis.py and tests/test_blindtest.py.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.common.errors import StudyError
from uqgear.diagnosis import Diagnosis, DiagnosisError, DiagnosisSettings
from uqgear.diagnosis.allowances.pitch_errors import PitchErrorAllowance
from uqgear.diagnosis.case import FeatureModelError
from uqgear.diagnosis.settings import DEFAULT_SETTINGS, GROUPS, PhaseSettings, VerdictSettings
from uqgear.rig.format import read_rig

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"


def test_every_setting_states_its_unit_rule_and_docs_section():
    table = DiagnosisSettings.describe()
    groups = [field.name for field in dataclasses.fields(DiagnosisSettings)]
    assert groups == list(GROUPS)
    fields = {field.name for group in groups for field in dataclasses.fields(getattr(DEFAULT_SETTINGS, group))}
    assert set(table) == fields
    for name, entry in table.items():
        assert entry["unit"] and entry["rule"].strip(), name
        assert entry["docs"].startswith("docs/model/unmodelled-effects.md section 6"), name
        value = getattr(getattr(DEFAULT_SETTINGS, entry["group"]), name)
        assert entry["default"] == (list(value) if isinstance(value, tuple) else value), name
    # the documented decision thresholds a study may set
    assert {"score_threshold", "shrink_threshold", "noise_gap", "max_effects"} <= set(DiagnosisSettings.study_keys())
    assert DEFAULT_SETTINGS.changed() == {}
    assert DiagnosisSettings(score_threshold=15.0, modulation_kappas=(0.02,)).changed() == {
        "score_threshold": 15.0, "modulation_kappas": [0.02]}


@pytest.mark.parametrize("changes, message", [
    ({"score_threshold": -1.0}, r"settings.score_threshold: expected a value in \[0, inf\] \(nat\)"),
    ({"shrink_threshold": 1.5}, r"settings.shrink_threshold: expected a value in \[0, 1\]"),
    ({"max_effects": 2.5}, r"settings.max_effects: expected an integer \(effects\)"),
    ({"noise_gap": float("nan")}, r"settings.noise_gap: expected a number"),
    ({"modulation_kappas": ()}, r"settings.modulation_kappas: expected a non-empty tuple"),
    ({"model_error": {"line": 0.03}}, r"model_error.band: missing"),
])
def test_a_setting_outside_its_range_is_named(changes, message):
    with pytest.raises(DiagnosisError, match=message):
        DiagnosisSettings(**changes)


def test_settings_from_a_mapping_name_the_key_path():
    assert DiagnosisSettings.from_mapping({"score_threshold": 12}).verdict.score_threshold == 12
    # a setting by its own name goes to its group; the nested form means the same
    kappas = (0.02,)
    nested = DiagnosisSettings.from_mapping({"verdict": {"score_threshold": 12},
                                             "phases": {"modulation_kappas": kappas}})
    assert nested == DiagnosisSettings(score_threshold=12, modulation_kappas=kappas)
    assert nested == DiagnosisSettings(verdict=VerdictSettings(score_threshold=12),
                                       phases=PhaseSettings(modulation_kappas=kappas))
    with pytest.raises(DiagnosisError, match=r"s.verdict.score_threshold: set twice"):
        DiagnosisSettings.from_mapping({"score_threshold": 12, "verdict": {"score_threshold": 11}}, where="s")
    with pytest.raises(DiagnosisError, match=r"s.verdict.max_effects: unknown setting; expected one of score_th"):
        DiagnosisSettings.from_mapping({"verdict": {"max_effects": 2}}, where="s")
    with pytest.raises(DiagnosisError, match=r"analyses\[0\].settings.wobble: unknown setting"):
        DiagnosisSettings.from_mapping({"wobble": 1}, where="analyses[0].settings")
    with pytest.raises(DiagnosisError, match=r"s.noise_gap: expected a value in"):
        DiagnosisSettings.from_mapping({"noise_gap": -2.0}, where="s")


def test_a_study_sets_the_documented_thresholds_only(tmp_path):
    from uqgear.study.schema import parse_study

    (tmp_path / "x.nc").write_bytes(b"")
    text = "name: d\nseed: 1\ndesign: locomotive\nanalyses:\n  - type: diagnose\n    rig: x.nc\n"
    study = parse_study(text + "    settings:\n      score_threshold: 15\n      max_effects: 2\n", base_dir=tmp_path)
    assert study.analyses[0].options["settings"] == {"score_threshold": 15, "max_effects": 2}
    with pytest.raises(StudyError, match=r"analyses\[0\].settings.bootstrap_resamples: unknown setting"):
        parse_study(text + "    settings:\n      bootstrap_resamples: 50\n", base_dir=tmp_path)
    with pytest.raises(StudyError, match=r"analyses\[0\].settings.noise_gap: expected a value in"):
        parse_study(text + "    settings:\n      noise_gap: -1\n", base_dir=tmp_path)
    with pytest.raises(StudyError, match=r"analyses\[0\].settings: expected a mapping"):
        parse_study(text + "    settings: 3\n", base_dir=tmp_path)
    # the same thresholds under their groups
    grouped = "    settings:\n      verdict: {score_threshold: 15}\n      selection: {max_effects: 2}\n"
    nested = parse_study(text + grouped, base_dir=tmp_path).analyses[0].options["settings"]
    assert DiagnosisSettings.from_mapping(nested) == DiagnosisSettings(score_threshold=15, max_effects=2)
    with pytest.raises(StudyError, match=r"analyses\[0\].settings.verdict.bootstrap_resamples: unknown setting"):
        parse_study(text + "    settings:\n      verdict: {bootstrap_resamples: 50}\n", base_dir=tmp_path)
    # without settings the analysis's options are as before (its result's key and attributes unchanged)
    assert "settings" not in parse_study(text, base_dir=tmp_path).analyses[0].options


def test_the_estimator_checks_its_settings_before_any_work():
    with pytest.raises(DiagnosisError, match="settings: expected a DiagnosisSettings; got dict"):
        Diagnosis(settings={"score_threshold": 3.0})
    with pytest.raises(DiagnosisError, match="effects: 'wobble' is not a library effect"):
        Diagnosis(effects=["wobble"])
    with pytest.raises(DiagnosisError, match="diagnosis: not fitted yet"):
        Diagnosis().to_dict()
    assert uqgear.Diagnosis is Diagnosis and uqgear.DiagnosisSettings is DiagnosisSettings


def test_a_prepared_campaign_is_never_changed_allowances_make_new_ones(healthy_case):
    case = healthy_case
    with pytest.raises(dataclasses.FrozenInstanceError):
        case.model_error = {}
    absolute = {kind: np.zeros((case.n_op, len(case.channels), int(np.sum(np.array(case.layout.kinds) == kind))))
                for kind in ("line", "band", "rms", "kurtosis")}
    allowance = PitchErrorAllowance(True, "test", (6.0, 8.0), {}, 12, absolute, 0.0, 0.0, 0.0,
                                    run_out_bound={"pinion": 2e-5, "gear": 5e-5})
    allowed = allowance.apply(case)
    assert allowed is not case and isinstance(allowed.model_error, FeatureModelError)
    assert allowed.model_error_before_allowance is case.model_error and allowed.pitch_allowance is allowance
    assert case.pitch_allowance is None and case.run_out_allowance == {} and not isinstance(case.model_error,
                                                                                            FeatureModelError)
    assert allowed.run_out_allowance == {"pinion": 2e-5, "gear": 5e-5}
    # an allowance that does not apply returns the case itself
    assert dataclasses.replace(allowance, applied=False).apply(case) is case


def test_a_campaign_that_cannot_decide_is_concluded_with_the_settings_it_was_judged_by():
    rig = read_rig(DATA / "healthy.nc")
    rng = np.random.default_rng(3)
    noise = rig.copy(deep=True)
    for name in ("te", "acc_pinion", "acc_gear"):
        values = noise[name].values
        noise[name] = noise[name].copy(data=(rng.standard_normal(values.shape) * np.std(values)).astype(np.float32))
    settings = DiagnosisSettings(signal_snr=6.0)
    before = noise.copy(deep=True)
    diagnosis = Diagnosis(settings=settings, workers=1).fit(noise)
    assert diagnosis.decision_.verdict == "inconclusive" and diagnosis.nominal_ is None
    assert diagnosis.ranking_ == [] and diagnosis.effects_ == [] and np.isnan(diagnosis.remaining_gap_)
    content = diagnosis.to_dict()
    assert content["signal"]["threshold"] == 6.0 and content["thresholds"]["signal_snr"] == 6.0
    assert content["settings"] == {"signal_snr": 6.0}
    assert diagnosis.result_.attrs["verdict"] == "inconclusive"
    # the rig Dataset handed in is not changed by the fit
    xr.testing.assert_identical(noise, before)


def test_the_study_reference_lists_the_thresholds_a_study_may_set():
    import re

    text = (Path(__file__).resolve().parent.parent / "docs" / "study-reference.md").read_text()
    table = text[text.index("| setting | group | units | default | rule (docs/model/index.md) |"):]
    table = table[:table.index("\n\n")]
    documented = re.findall(r"^\| `(\w+)` \|", table, flags=re.M)
    assert documented == list(DiagnosisSettings.study_keys())
    for name in documented:
        row = next(line for line in table.splitlines() if line.startswith(f"| `{name}` |"))
        assert f"| {DiagnosisSettings.describe(name)['default']:g} |" in row, row
        assert row.startswith(f"| `{name}` | `{DiagnosisSettings.describe(name)['group']}` |"), row
