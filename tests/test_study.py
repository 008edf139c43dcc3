"""Tests of the study schema: shipped studies, defaults, derived values and every kind of mistake."""

from __future__ import annotations

import json
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import uqgear.common
from uqgear.common.errors import StudyError, UqgearError
from uqgear.physics.design import STANDARD_GRAVITY
from uqgear.study.analysis_schemas import ANALYSIS_DEFAULTS, ANALYSIS_SCHEMAS
from uqgear.study.schema import load_study, parse_study
from uqgear.study.variables import VARIABLES

ROOT = Path(__file__).resolve().parent.parent
# the bundled studies, from the installed package (a wheel or sdist has no top-level studies/)
STUDY_DIR = uqgear.common.bundled_file("study", "smoke").parent
STUDIES = sorted(STUDY_DIR.glob("*.yaml"))

MINIMAL = """
seed: 3
operating_points:
  pinion_speed: {start: 1000, stop: 2000, num: 5}
  drive_torque: 1000
uncertain:
  adhesion_torque: {adhesion_coefficient: [0.15, 0.33]}
  mesh_stiffness_scale: {interval: [0.9, 1.1]}
  zeta_mesh: {distribution: normal, mu: 0.05, sigma: 0.005}
analyses:
  - type: interval
  - type: sobol
    samples: 16
  - type: regime_map
    axes: [pinion_speed, adhesion_torque]
"""


def parse(text: str):
    return parse_study(textwrap.dedent(text))


def test_shipped_studies_validate():
    names = {path.stem for path in STUDIES}
    assert {"smoke", "t2_envelope", "paper_speed", "paper_stiffness"} <= names
    for path in STUDIES:
        study = load_study(path)
        assert study.analyses, path
        assert study.text == path.read_text()


def test_smoke_study_covers_every_analysis_type():
    from uqgear.study.analysis_schemas import RIG_TYPES

    # analyses of rig data take a minute each: they have their own studies and slow end-to-end tests
    study = load_study(STUDY_DIR / "smoke.yaml")
    assert {spec.type for spec in study.analyses} == set(ANALYSIS_SCHEMAS) - set(RIG_TYPES)
    covered = {spec.type for path in STUDY_DIR.glob("*.yaml") for spec in load_study(path).analyses}
    assert set(RIG_TYPES) <= covered


@pytest.mark.slow
def test_calibrate_study_end_to_end(tmp_path):
    from uqgear.report.study_report import write_report
    from uqgear.study.running import run_analyses as run_study

    study = load_study(STUDY_DIR / "calibrate_healthy.yaml")
    run_study(study, tmp_path, show_progress=False)
    write_report(tmp_path)
    result = xr.open_dataset(tmp_path / "calibration.nc")
    assert result.attrs["converged"] == 1
    # data/rig/README.md: true mesh_stiffness_scale 0.970, k1 1.010e9 on healthy.nc
    for name, truth in (("mesh_stiffness_scale", 0.970), ("k1", 1.010e9)):
        low, high = np.quantile(result[name].values, [0.05, 0.95])
        assert low <= truth <= high
    text = (tmp_path / "report.html").read_text()
    assert 'data-type="calibrate"' in text and "posterior predictive check with the real model passed" in text


@pytest.mark.slow
def test_diagnose_study_end_to_end(tmp_path):
    from uqgear.report.study_report import write_report
    from uqgear.study.running import run_analyses as run_study

    # the bundled study with two of its six candidates: the labelled-file tests of
    # test_diagnosis.py run this campaign against all six already
    text = (STUDY_DIR / "diagnose_eccentricity.yaml").read_text()
    full = "effects: [eccentricity, tooth_damage, friction, torque_ripple, adhesion_oscillation, bearing_clearance]"
    assert full in text
    text = text.replace(full, "effects: [eccentricity, torque_ripple]")
    text = text.replace("../data/rig/eccentricity.nc", str(ROOT / "data" / "rig" / "eccentricity.nc"))
    (tmp_path / "study.yaml").write_text(text)
    study = load_study(tmp_path / "study.yaml")
    out = tmp_path / "out"
    out.mkdir()
    run_study(study, out, show_progress=False)
    write_report(out)
    result = xr.open_dataset(out / "diagnosis.nc")
    content = json.loads(result.attrs["diagnosis"])
    # data/rig/README.md: eccentricity.nc carries a 12 um pinion run-out
    assert result.attrs["verdict"] == content["verdict"] == "eccentricity"
    assert content["ranking"][0]["parameters"]["shaft"] == "pinion"
    assert content["gap"]["shrink_fraction"] >= 0.7
    assert result["gap_map_nominal"].dims == ("op", "channel", "family")
    result.close()
    assert [entry["effect"] for entry in content["ranking"]] == ["eccentricity", "torque_ripple"]
    text = (out / "report.html").read_text()
    assert 'data-type="diagnose"' in text and "verdict eccentricity" in text


def test_t2_envelope_study_uses_rail_condition_interval():
    study = load_study(STUDY_DIR / "t2_envelope.yaml")
    t2 = study.uncertain["adhesion_torque"]
    lever = 23000 * STANDARD_GRAVITY * 0.625
    assert t2.lower == pytest.approx(0.15 * lever) and t2.upper == pytest.approx(0.33 * lever)
    assert t2.lower == pytest.approx(21145.6, abs=0.1) and t2.upper == pytest.approx(46520.3, abs=0.1)
    kinds = [spec.type for spec in study.analyses]
    assert kinds == ["interval", "bifurcation", "regime_map", "sobol", "rating"]
    assert study.analyses[4].options["parameters"] == ("adhesion_torque",)
    assert study.analyses[0].options["method"] == "chebyshev"
    assert study.analyses[0].options["fallback"] == "scan"
    assert set(study.analyses[3].options["parameters"]) == {
        "adhesion_torque", "mesh_stiffness_scale", "zeta_mesh", "backlash", "ste_amplitude", "k1"}


def test_sweeps_and_values_expand():
    study = parse(MINIMAL)
    speed = study.operating_points["pinion_speed"]
    assert speed.sweep and speed.values == (1000.0, 1250.0, 1500.0, 1750.0, 2000.0)
    torque = study.operating_points["drive_torque"]
    assert not torque.sweep and torque.value == 1000.0
    log_sweep = parse("""
        operating_points:
          k1: {start: 1.0e8, stop: 1.0e10, num: 3, spacing: log}
        analyses:
          - {type: bifurcation, parameter: k1}
        """).operating_points["k1"]
    assert log_sweep.values == pytest.approx((1e8, 1e9, 1e10))
    listed = parse("""
        operating_points: {pinion_speed: [3000, 1000]}
        analyses: [{type: simulate}]
        """).operating_points["pinion_speed"]
    assert listed.values == (3000.0, 1000.0) and listed.sweep


def test_adhesion_interval_defaults_to_the_design_operation_and_can_be_given():
    study = parse(MINIMAL)
    t2 = study.uncertain["adhesion_torque"]
    lower, upper = study.design.operation.adhesion_torque_bounds()
    assert (t2.lower, t2.upper) == pytest.approx((lower, upper))
    assert "0.15" in t2.source and "23000" in t2.source
    given = parse("""
        uncertain:
          adhesion_torque: {adhesion_coefficient: [0.1, 0.2], axle_load: 20000, wheel_radius: 0.5}
        analyses: [{type: interval}]
        """).uncertain["adhesion_torque"]
    assert (given.lower, given.upper) == pytest.approx((0.1 * 20000 * STANDARD_GRAVITY * 0.5,
                                                        0.2 * 20000 * STANDARD_GRAVITY * 0.5))
    direct = parse("""
        uncertain:
          adhesion_torque: {interval: [20000, 40000]}
        analyses: [{type: interval}]
        """).uncertain["adhesion_torque"]
    assert (direct.lower, direct.upper, direct.nominal) == (20000.0, 40000.0, 30000.0)


def test_defaults_and_parameter_selection():
    study = parse(MINIMAL)
    interval, sobol, regime = study.analyses
    assert interval.options["method"] == ANALYSIS_DEFAULTS["interval"]["method"] == "chebyshev"
    # interval analyses take the interval parameters only; sobol takes every uncertain one
    assert interval.options["parameters"] == ("adhesion_torque", "mesh_stiffness_scale")
    assert sobol.options["parameters"] == ("adhesion_torque", "mesh_stiffness_scale", "zeta_mesh")
    assert regime.options["points"] == ANALYSIS_DEFAULTS["regime_map"]["points"]
    assert [spec.name for spec in study.analyses] == ["interval", "sobol", "regime_map"]
    # the normal distribution's nominal value is its median
    assert study.uncertain["zeta_mesh"].nominal == pytest.approx(0.05)


def test_analysis_overrides_merge_over_study_values():
    study = parse("""
        operating_points: {pinion_speed: [1000, 2000], drive_torque: 1000}
        simulation: {n_periods: 500, keep_periods: 100}
        analyses:
          - type: simulate
            operating_points: {pinion_speed: 3000}
            simulation: {keep_periods: 50, lyapunov: true}
        """)
    spec = study.analyses[0]
    assert spec.fixed == {"pinion_speed": 3000.0, "drive_torque": 1000.0}
    assert spec.sweeps == {}
    assert (spec.simulation.n_periods, spec.simulation.keep_periods, spec.simulation.lyapunov) == (500, 50, True)
    assert study.simulation.keep_periods == 100


def test_design_name_path_and_overrides(tmp_path):
    study = parse("""
        design: {name: locomotive, overrides: {backlash: 0.4e-3, k1: 2.0e9}}
        analyses: [{type: simulate, operating_points: {pinion_speed: 1000}}]
        """)
    assert study.design.backlash == 4e-4 and study.design.k1 == 2e9
    assert dict(study.design_overrides) == {"backlash": 4e-4, "k1": 2e9}
    # a relative design path is resolved against the study file's folder
    design_file = ROOT / "data" / "designs" / "locomotive.yaml"
    (tmp_path / "mine.yaml").write_text(design_file.read_text())
    study_file = tmp_path / "study.yaml"
    study_file.write_text("design: {path: mine.yaml}\nanalyses: [{type: simulate, operating_points: "
                          "{pinion_speed: 1000}}]\n")
    assert load_study(study_file).design.z2 == 101


def test_seed_sequences_are_deterministic_and_independent():
    first, second = parse(MINIMAL), parse(MINIMAL)
    draws_a = [np.random.default_rng(s).random(4) for s in first.seed_sequences()]
    draws_b = [np.random.default_rng(s).random(4) for s in second.seed_sequences()]
    for a, b in zip(draws_a, draws_b):
        np.testing.assert_array_equal(a, b)
    assert not np.allclose(draws_a[0], draws_a[1])
    other = parse(MINIMAL.replace("seed: 3", "seed: 4"))
    assert not np.allclose(np.random.default_rng(other.seed_sequences()[0]).random(4), draws_a[0])


# A broken study per line: (YAML text, expected part of the message, literally).
# Each message starts with the key path.
BASE = "operating_points: {pinion_speed: [1000, 2000]}\nuncertain: {adhesion_torque: {interval: [20000, 40000]}}\n"
BAD_STUDIES = [
    (BASE + "analyses:\n  - {type: simulate}\n  - {type: simulate, name: b}\n  - {type: interval, method: chebychev}",
     "analyses[2].method: expected one of scan, vertex, chebyshev, optimize; got 'chebychev'"),
    (BASE + "colour: red\nanalyses: [{type: simulate}]", "colour: unknown key; expected one of name, description"),
    (BASE, "analyses: missing"),
    (BASE + "analyses: []", "analyses: expected a non-empty list of analyses"),
    (BASE + "analyses: [{type: montecarlo}]",
     "analyses[0].type: expected one of simulate, bifurcation, regime_map, interval, monte_carlo, pce, sobol"),
    (BASE + "analyses: [{name: x}]", "analyses[0].type: missing"),
    (BASE + "analyses: [{type: interval, metod: scan}]", "analyses[0].metod: unknown key"),
    (BASE + "seed: -1\nanalyses: [{type: simulate}]", "seed: expected an integer in [0,"),
    (BASE + "seed: lucky\nanalyses: [{type: simulate}]", "seed: expected an integer"),
    (BASE + "design: nowhere\nanalyses: [{type: simulate}]", "design: design 'nowhere': not a bundled design"),
    (BASE + "design: {name: locomotive, overrides: {module_size: 0.01}}\nanalyses: [{type: simulate}]",
     "design.overrides.module_size: unknown design key"),
    (BASE + "design: {name: locomotive, overrides: {backlash: 0.3}}\nanalyses: [{type: simulate}]",
     "design.overrides.backlash: expected a value in [0, 0.005] m, total backlash 2b; got 0.3"),
    (BASE + "design: {name: locomotive, path: x.yaml}\nanalyses: [{type: simulate}]",
     "design: expected exactly one of name"),
    ("operating_points: {speed: 1000}\nanalyses: [{type: simulate}]",
     "operating_points.speed: unknown variable; expected one of pinion_speed"),
    ("operating_points: {pinion_speed: -5}\nanalyses: [{type: simulate}]",
     "operating_points.pinion_speed: expected a number in (0, 100000] rpm; got -5"),
    ("operating_points: {pinion_speed: {start: 1000, stop: 2000}}\nanalyses: [{type: simulate}]",
     "operating_points.pinion_speed.num: missing (required)"),
    ("operating_points: {pinion_speed: {start: 1000, stop: 2000, num: 2.5}}\nanalyses: [{type: simulate}]",
     "operating_points.pinion_speed.num: expected an integer in"),
    ("operating_points: {pinion_speed: [1000, 1000]}\nanalyses: [{type: simulate}]",
     "operating_points.pinion_speed: expected distinct entries"),
    ("operating_points: {k1: [1.0e9, 1.0e14]}\nanalyses: [{type: simulate}]",
     "operating_points.k1: expected values in [100000, 1e+13] N/m"),
    ("uncertain: {adhesion_torque: {interval: [40000, 20000]}}\nanalyses: [{type: interval}]",
     "uncertain.adhesion_torque.interval: expected lower < upper; got [40000, 20000]"),
    ("uncertain: {adhesion_torque: {interval: 30000}}\nanalyses: [{type: interval}]",
     "uncertain.adhesion_torque.interval: expected [lower, upper] in N m"),
    ("uncertain: {zeta_mesh: {distribution: gauss, mu: 0.05}}\nanalyses: [{type: sobol}]",
     "uncertain.zeta_mesh.distribution: expected one of uniform, normal"),
    ("uncertain: {zeta_mesh: {distribution: normal, mu: 0.05}}\nanalyses: [{type: sobol}]",
     "uncertain.zeta_mesh.sigma: missing (required)"),
    ("uncertain: {zeta_mesh: {distribution: normal, mu: 0.05, sigma: 0.2}}\nanalyses: [{type: sobol}]",
     "uncertain.zeta_mesh: expected a distribution whose 0.1 % to 99.9 % quantiles lie in [0, 1]"),
    ("uncertain: {zeta_mesh: {interval: [0.03, 0.08], units: 1}}\nanalyses: [{type: sobol}]",
     "uncertain.zeta_mesh.units: unknown key; expected one of interval"),
    ("uncertain: {adhesion_torque: {adhesion_coefficient: [0.3, 0.1]}}\nanalyses: [{type: interval}]",
     "uncertain.adhesion_torque.adhesion_coefficient: expected lower < upper"),
    ("uncertain: {adhesion_torque: {adhesion_coefficient: [0.15, 0.33], axle_load: 23}}\n"
     "analyses: [{type: interval}]", "uncertain.adhesion_torque.axle_load: expected a number in "
                                     "[1000, 100000] kg; got 23"),
    ("uncertain: {backlash: {interval: [0.1, 0.2]}}\nanalyses: [{type: interval}]",
     "uncertain.backlash: expected bounds in [0, 0.005] m, total backlash 2b; got [0.1, 0.2]"),
    ("operating_points: {adhesion_torque: 30000}\nuncertain: {adhesion_torque: {interval: [2.0e4, 4.0e4]}}\n"
     "analyses: [{type: interval}]", "uncertain.adhesion_torque: also given in operating_points"),
    ("uncertain: {adhesion_torque: {interval: [2.0e4, 4.0e4]}}\n"
     "analyses: [{type: interval, parameters: [adhesion_torque], operating_points: {adhesion_torque: 3.0e4}}]",
     "analyses[0].parameters: adhesion_torque is also given in operating_points"),
    ("operating_points: {pinion_speed: 1000}\nanalyses: [{type: bifurcation, parameter: pinion_speed}]",
     "analyses[0].parameter: pinion_speed is fixed in operating_points; expected a sweep"),
    ("analyses: [{type: bifurcation, parameter: k1}]",
     "analyses[0].parameter: k1 is neither swept in operating_points nor an uncertain interval parameter"),
    ("operating_points: {pinion_speed: [1, 2], k1: [1.0e9, 2.0e9]}\n"
     "analyses: [{type: bifurcation, parameter: pinion_speed}]",
     "analyses[0].operating_points.k1: a bifurcation sweeps only its parameter"),
    (BASE + "analyses: [{type: bifurcation, parameter: pinion_speed, envelope: [k1]}]",
     "analyses[0].envelope: k1 is not an uncertain interval parameter"),
    (BASE + "analyses: [{type: regime_map, axes: [pinion_speed, adhesion_torque, k1]}]",
     "analyses[0].axes: expected exactly two variable names; got 3"),
    (BASE + "analyses: [{type: regime_map}]", "analyses[0].axes: missing (required)"),
    (BASE + "analyses: [{type: sobol, samples: 100}]",
     "analyses[0].samples: expected a power of 2 (Sobol' sequence balance); got 100"),
    (BASE + "analyses: [{type: sobol, qois: [dte_rms, noise]}]", "analyses[0].qois[1]: expected one of dte_mean"),
    ("uncertain: {zeta_mesh: {distribution: uniform, lower: 0.03, upper: 0.07}}\n"
     "analyses: [{type: interval, parameters: [zeta_mesh]}]",
     "analyses[0].parameters: zeta_mesh has a distribution; an interval analysis expects interval parameters"),
    ("analyses: [{type: sobol}]", "analyses[0].parameters: no uncertain parameters to propagate"),
    (BASE + "analyses: [{type: simulate}, {type: simulate}]",
     "analyses[0].name: 'simulate' is used by more than one analysis"),
    (BASE + "analyses: [{type: simulate, name: 'my run'}]", "analyses[0].name: expected a name of letters"),
    (BASE + "simulation: {n_periods: 100, keep_periods: 200}\nanalyses: [{type: simulate}]",
     "simulation.keep_periods: expected at most n_periods (100); got 200"),
    (BASE + "simulation: {n_periods: many}\nanalyses: [{type: simulate}]", "simulation.n_periods: expected an integer"),
    (BASE + "simulation: {stiffness: spline}\nanalyses: [{type: simulate}]",
     "simulation.stiffness: expected one of ishikawa, fourier; got 'spline'"),
    (BASE + "outputs: {report: yes please}\nanalyses: [{type: simulate}]", "outputs.report: expected true or false"),
    (BASE + "analyses: [{type: simulate, labels: [period-1]}]",
     "analyses[0].labels: expected one label per run (2); got 1"),
    (BASE + "analyses: [{type: pce, parameters: [adhesion_torque], order: 2, min_order: 3}]",
     "analyses[0].min_order: expected at most order (2); got 3"),
    (BASE + "analyses: [{type: monte_carlo, intervals: pbox}]",
     "analyses[0].intervals: 'pbox' bounds statistics over interval parameters of the random ones"),
    ("analyses: [{type: simulate}\n", "not valid YAML at line"),
    ("", "study: the file is empty"),
    ("- type: simulate\n", "study: expected a mapping with keys name"),
]


@pytest.mark.parametrize("text, message", BAD_STUDIES)
def test_bad_study_is_rejected_with_its_key_path(text, message):
    with pytest.raises(StudyError) as caught:
        parse_study(text)
    assert message in str(caught.value)
    assert str(caught.value).startswith(message.split(":")[0])
    assert isinstance(caught.value, UqgearError)
    assert "\n" not in str(caught.value)


def test_missing_and_unreadable_study_files(tmp_path):
    with pytest.raises(StudyError, match=re.escape(f"{tmp_path / 'none.yaml'}: study file not found")):
        load_study(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("analyses: [{type: interval, method: chebychev}]\n")
    with pytest.raises(StudyError, match=re.escape(f"{bad}: analyses[0].method: expected one of")):
        load_study(bad)


def test_registries_agree():
    from uqgear.report.sections import RENDERERS
    from uqgear.study.analyses import ANALYSES

    assert set(ANALYSES) == set(ANALYSIS_SCHEMAS) == set(ANALYSIS_DEFAULTS)
    assert set(RENDERERS) == set(ANALYSIS_SCHEMAS)


def test_reference_documents_every_key_and_variable():
    text = (ROOT / "docs" / "study-reference.md").read_text()
    keys = {"name", "description", "seed", "design", "overrides", "path", "operating_points", "uncertain",
            "simulation", "analyses", "outputs", "execution", "chunk_size", "report", "dpi", "interval",
            "distribution", "adhesion_coefficient", "axle_load", "wheel_radius", "start", "stop", "num",
            "spacing", "n_periods", "keep_periods", "lyapunov", "steps_per_mode", "damping_in_separation",
            "stiffness", "type"}
    for schema in ANALYSIS_SCHEMAS.values():
        keys.update(schema)
    keys.update(VARIABLES)
    missing = sorted(key for key in keys if f"`{key}`" not in text)
    assert not missing, f"docs/study-reference.md does not document {missing}"


def test_calibrate_analysis_needs_an_existing_rig_file(tmp_path):
    from uqgear.study.schema import parse_study

    text = "name: c\nseed: 1\ndesign: locomotive\nanalyses:\n  - type: calibrate\n    rig: nothere.nc\n"
    with pytest.raises(StudyError, match=r"analyses\[0\].rig: file .*nothere.nc not found"):
        parse_study(text, base_dir=tmp_path)
    with pytest.raises(StudyError, match=r"analyses\[0\].parameters\[0\]: expected one of"):
        parse_study(text.replace("rig: nothere.nc", "rig: x.nc\n    parameters: [stiffness]"), base_dir=tmp_path)
    (tmp_path / "x.nc").write_bytes(b"")
    study = parse_study(text.replace("nothere.nc", "x.nc"), base_dir=tmp_path)
    assert study.analyses[0].options["parameters"][0] == "mesh_stiffness_scale"
    assert study.analyses[0].options["pitch_classes"] == (6.0, 8.0)
    known = text.replace("nothere.nc", "x.nc") + "    pitch_classes: [7, 7]\n"
    assert parse_study(known, base_dir=tmp_path).analyses[0].options["pitch_classes"] == (7.0, 7.0)
    unknown = text.replace("nothere.nc", "x.nc") + "    pitch_classes: none\n"
    assert parse_study(unknown, base_dir=tmp_path).analyses[0].options["pitch_classes"] is None
    for wrong in ("[8, 6]", "[7]", "seven", "[0, 12]"):
        with pytest.raises(StudyError, match=r"analyses\[0\].pitch_classes: expected \[lowest, highest\]"):
            parse_study(text.replace("nothere.nc", "x.nc") + f"    pitch_classes: {wrong}\n", base_dir=tmp_path)


def test_diagnose_analysis_options_are_checked(tmp_path):
    from uqgear.study.schema import parse_study

    (tmp_path / "x.nc").write_bytes(b"")
    text = "name: d\nseed: 1\ndesign: locomotive\nanalyses:\n  - type: diagnose\n    rig: x.nc\n"
    study = parse_study(text, base_dir=tmp_path)
    assert study.analyses[0].options["effects"] == ("eccentricity", "tooth_damage", "friction", "torque_ripple",
                                                    "adhesion_oscillation", "bearing_clearance")
    with pytest.raises(StudyError, match=r"analyses\[0\].effects\[1\]: expected one of eccentricity"):
        parse_study(text + "    effects: [friction, wobble]\n", base_dir=tmp_path)
    assert study.analyses[0].options["pitch_classes"] == (6.0, 8.0)
    no_classes = parse_study(text + "    pitch_classes: none\n", base_dir=tmp_path)
    assert no_classes.analyses[0].options["pitch_classes"] is None
    for wrong in ("[8, 6]", "[7]", "seven", "[0, 12]"):
        with pytest.raises(StudyError, match=r"analyses\[0\].pitch_classes: expected \[lowest, highest\]"):
            parse_study(text + f"    pitch_classes: {wrong}\n", base_dir=tmp_path)
    with pytest.raises(StudyError, match=r"analyses\[0\].rig: file .*gone.nc not found"):
        parse_study(text.replace("x.nc", "gone.nc"), base_dir=tmp_path)
    with pytest.raises(StudyError, match=r"analyses\[0\].rig: missing \(required\)"):
        parse_study(text.replace("    rig: x.nc\n", "    effects: [friction]\n"), base_dir=tmp_path)
    # the healthy reference campaign (uqgear diagnose --reference): resolved like rig, its absence named
    assert parse_study(text + "    reference: x.nc\n", base_dir=tmp_path).analyses[0].options["reference"] == "x.nc"
    with pytest.raises(StudyError, match=r"analyses\[0\].reference: file .*healthy_gone.nc not found; expected "
                                         r"a uqgear-rig/1 netCDF file of the same rig with a healthy gearbox"):
        parse_study(text + "    reference: healthy_gone.nc\n", base_dir=tmp_path)
    with pytest.raises(StudyError, match=r"analyses\[0\].reference"):
        parse_study(text + "    reference: [x.nc]\n", base_dir=tmp_path)
