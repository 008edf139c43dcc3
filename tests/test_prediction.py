"""Calibrate -> diagnose -> predict: the posterior and the diagnosed effects as inputs, and the prediction analysis.

Checked against independent references: a posterior of known mean and covariance (sample moments
within their standard errors), effects built by hand with ``make_effect`` (the same runs, bit for
bit), the split normal's quantiles (the diagnosis' interval ends), and the batch model run directly
at fixed parameters (the prediction's bounds over T2 with a posterior of one point).
"""

from __future__ import annotations

import json
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.diagnosis.named_effects import named_effects
from uqgear.physics.effect_draws import UncertainEffect, draw_effect_sets

MEAN = np.array([1.02, 0.05])
COV = np.array([[1e-4, 1.5e-6], [1.5e-6, 4e-5]])


def _posterior(rows: np.ndarray, *, converged: int = 1, design=None, speeds=(1500.0, 2500.0, 3500.0)) -> xr.Dataset:
    design = design or uqgear.load_design("locomotive")
    return xr.Dataset(
        {
            "mesh_stiffness_scale": (("chain", "draw"), rows[..., 0]),
            "zeta_mesh": (("chain", "draw"), rows[..., 1]),
        },
        coords={
            "pinion_speed": ("op", list(speeds)),
            "drive_torque": ("op", [7000.0] * len(speeds)),
            "adhesion_torque_lower": ("op", [25e3] * len(speeds)),
            "adhesion_torque_upper": ("op", [40e3] * len(speeds)),
        },
        attrs={
            "converged": converged,
            "parameters": json.dumps(["mesh_stiffness_scale", "zeta_mesh"]),
            "design": design.to_json(),
        },
    )


@pytest.fixture(scope="module")
def known_posterior() -> xr.Dataset:
    rows = np.random.default_rng(7).multivariate_normal(MEAN, COV, size=(16, 250))
    return _posterior(rows)


# ---------------------------------------------------------------------------- posterior as input


def test_joint_draws_keep_mean_and_covariance(known_posterior):
    space = uqgear.ParameterSpace.from_posterior(
        known_posterior, {"adhesion_torque": [21e3, 46e3]}, draws=None, seed=0
    )
    samples = space.sample(20000, seed=3, interval_treatment="uniform")
    values = np.stack([samples["mesh_stiffness_scale"].values, samples["zeta_mesh"].values], axis=1)
    n = values.shape[0]
    standard_error = np.sqrt(np.diag(COV) / n)
    # the true mean, within 4 standard errors of the draws and of the resampling
    assert np.all(np.abs(values.mean(axis=0) - MEAN) < 4 * np.sqrt(2) * standard_error)
    covariance = np.cov(values, rowvar=False)
    # variances within 4 standard errors (var of s^2 ~ 2 sigma^4 / n), the correlation kept
    assert np.all(np.abs(np.diag(covariance) - np.diag(COV)) < 4 * np.sqrt(2 / n) * np.diag(COV) * np.sqrt(2))
    correlation = covariance[0, 1] / np.sqrt(covariance[0, 0] * covariance[1, 1])
    truth = COV[0, 1] / np.sqrt(COV[0, 0] * COV[1, 1])
    assert abs(correlation - truth) < 4 * (1 - truth**2) / np.sqrt(n) * np.sqrt(2)
    # the interval parameter stays uniform on its bounds and independent of the draws
    assert samples["adhesion_torque"].min() >= 21e3 and samples["adhesion_torque"].max() <= 46e3


def test_thinning_takes_whole_rows_and_is_seeded(known_posterior):
    draws = uqgear.PosteriorDraws.from_dataset(known_posterior)
    thinned = draws.thin(64, seed=5)
    again = draws.thin(64, seed=5)
    assert thinned.size == 64 and np.array_equal(thinned.values, again.values)
    rows = {tuple(row) for row in draws.values}
    assert all(tuple(row) in rows for row in thinned.values)
    assert not np.array_equal(thinned.values, draws.thin(64, seed=6).values)
    assert draws.campaign["pinion_speed"] == (1500.0, 3500.0)


def test_posterior_space_refusals_and_pickling(known_posterior):
    unconverged = known_posterior.assign_attrs(converged=0)
    with pytest.raises(uqgear.PosteriorError, match="has not converged"):
        uqgear.ParameterSpace.from_posterior(unconverged)
    space = uqgear.ParameterSpace.from_posterior(unconverged, allow_unconverged=True, draws=8)
    assert space.posterior.size == 8 and not space.posterior.converged
    with pytest.raises(uqgear.ParameterSpaceError, match="zeta_mesh: given both"):
        uqgear.ParameterSpace.from_posterior(known_posterior, {"zeta_mesh": [0.03, 0.08]})
    assert pickle.loads(pickle.dumps(space)) == space


# ---------------------------------------------------------------------------- effects as input


def test_effect_passed_in_gives_the_runs_of_make_effect_by_hand(design):
    record = {
        "verdict": "eccentricity",
        "effects": [
            {
                "effect": "eccentricity",
                "parameters": {"shaft": "pinion", "amplitude": 12e-6, "phase": 1.75, "kappa": 0.03},
                "parameter_intervals": {"amplitude": [11.5e-6, 12.5e-6]},
            }
        ],
    }
    (effect,) = named_effects(record)
    by_hand = uqgear.make_effect("eccentricity", {"shaft": "pinion", "amplitude": 12e-6, "phase": 1.75, "kappa": 0.03})
    samples = uqgear.samples_from_mapping({"pinion_speed": [1500.0, 3000.0], "adhesion_torque": [30e3, 40e3]})
    options = {"fixed": {"drive_torque": 7000.0}, "n_periods": 80, "keep_periods": 42}
    passed = uqgear.BatchEvaluator(design, effects=[effect], **options)(samples)
    manual = uqgear.BatchEvaluator(design, effects=[by_hand], **options)(samples)
    healthy = uqgear.BatchEvaluator(design, **options)(samples)
    assert np.array_equal(passed["dte_rms"].values, manual["dte_rms"].values)
    assert np.array_equal(passed["peak_mesh_force"].values, manual["peak_mesh_force"].values)
    assert not np.array_equal(passed["dte_rms"].values, healthy["dte_rms"].values)


def test_effect_draws_follow_the_reported_interval():
    effect = UncertainEffect("tooth_damage", {"gear": "pinion", "tooth": 7.0, "depth": 0.35}, {"depth": (0.30, 0.42)})
    depths = np.array([effects[0].values["depth"] for effects in draw_effect_sets([effect], 20000, seed=1)])
    low, median, high = np.quantile(depths, [0.05, 0.5, 0.95])
    # a split normal: median at the fit, 5 % and 95 % quantiles at the interval's (lopsided) ends
    assert abs(median - 0.35) < 0.003 and abs(low - 0.30) < 0.003 and abs(high - 0.42) < 0.003


def test_a_tooth_left_open_is_drawn_evenly_and_travels_through_the_diagnosis_json():
    effect = UncertainEffect(
        "tooth_damage", {"gear": "pinion", "tooth": 0.0, "depth": 0.35}, {"depth": (0.30, 0.42)},
        {"tooth": range(21)},
    )
    draws = draw_effect_sets([effect], 21000, seed=2)
    counts = np.bincount([int(effects[0].values["tooth"]) for effects in draws], minlength=21)
    # a fair 21-sided draw: each count 1000 +- 3 sd (sd = sqrt(21000 * p (1 - p)) = 30.9)
    assert counts.size == 21 and np.all(np.abs(counts - 1000) < 93)
    depths = np.array([effects[0].values["depth"] for effects in draws])
    assert abs(np.median(depths) - 0.35) < 0.003  # the interval's draws as without choices
    assert effect.central().values["tooth"] == 0.0
    (back,) = named_effects({"verdict": "tooth_damage", "effects": [effect.to_dict()]})
    assert back == effect


def test_which_tooth_matters_only_over_a_window_of_part_revolutions(design):
    # 21 pinion teeth: 210 mesh periods are 10 revolutions, 200 are 9.5 (the damaged tooth meets the mesh 9 or 10
    # times, depending on which tooth it is)
    samples = uqgear.samples_from_mapping({"pinion_speed": [3100.0], "adhesion_torque": [33e3]})
    spread = {}
    for keep in (200, 210):
        values = [
            float(
                uqgear.BatchEvaluator(
                    design, effects=[uqgear.make_effect("tooth_damage", {"tooth": tooth, "depth": 0.35})],
                    fixed={"drive_torque": 7000.0}, n_periods=keep + 200, keep_periods=keep,
                )(samples)["dte_rms"][0]
            )
            for tooth in (0.0, 5.0, 11.0)
        ]
        spread[keep] = np.ptp(values) / np.mean(values)
    assert spread[210] < 1e-5 < 1e-3 < spread[200]


def test_bad_choices_are_refused_naming_the_parameter():
    with pytest.raises(uqgear.UqgearError, match=r"tooth_damage\.tooth: given both an interval and choices"):
        UncertainEffect("tooth_damage", {"depth": 0.3}, {"tooth": (0.0, 3.0)}, {"tooth": [0, 1]})
    with pytest.raises(uqgear.UqgearError, match=r"tooth_damage\.tooth: expected at least one value"):
        UncertainEffect("tooth_damage", {"depth": 0.3}, {}, {"tooth": []})
    with pytest.raises(uqgear.UqgearError, match=r"tooth_damage\.colour: choices for an unknown parameter"):
        UncertainEffect("tooth_damage", {"depth": 0.3}, {}, {"colour": [1.0]})
    with pytest.raises(uqgear.UqgearError, match=r"tooth_damage\.depth"):
        UncertainEffect("tooth_damage", {"depth": 0.3}, {}, {"depth": [0.3, 2.0]})
    for field, given in (("choices", "[0, 1]"), ("intervals", "3")):
        with pytest.raises(uqgear.StudyError, match=rf"model\.effects\.tooth_damage\.{field}: expected a mapping"):
            uqgear.parse_study(
                "name: s\nuncertain: {adhesion_torque: {interval: [30000, 40000]}}\n"
                "analyses:\n  - {type: interval, name: m}\n"
                f"model:\n  effects:\n    tooth_damage: {{depth: 0.3, {field}: {given}}}\n"
            )
    with pytest.raises(uqgear.StudyError, match=r"model\.effects\.tooth_damage\.tooth: expected a list"):
        uqgear.parse_study(
            "name: s\nuncertain: {adhesion_torque: {interval: [30000, 40000]}}\n"
            "analyses:\n  - {type: interval, name: m}\n"
            "model:\n  effects:\n    tooth_damage: {depth: 0.3, choices: {tooth: 3}}\n"
        )


def test_diagnosis_without_a_named_effect_is_refused():
    with pytest.raises(uqgear.UqgearError, match="names no effect \\(verdict: inconclusive\\)"):
        named_effects({"verdict": "inconclusive", "effects": []})


# ---------------------------------------------------------------------------- the study


STUDY = """
name: predicted
seed: 4
design: locomotive
operating_points:
  pinion_speed: [1000, 2500, 4500]
  drive_torque: 7000
uncertain:
  adhesion_torque: {{adhesion_coefficient: [0.15, 0.33], axle_load: 23000, wheel_radius: 0.625}}
  calibrated: {{posterior: {posterior}, draws: {draws}{extra}}}
{model}simulation: {{n_periods: 80, keep_periods: 30, starts: false}}
analyses:
  - {{type: prediction, name: prediction, points: 3, qois: [peak_mesh_force, dte_rms]}}
"""


def _study_text(posterior: Path, draws: int = 6, extra: str = "", model: str = "") -> str:
    return STUDY.format(posterior=posterior, draws=draws, extra=extra, model=model)


def test_prediction_of_a_one_point_posterior_is_the_model_run_there(tmp_path, design):
    # every draw at the same parameters: each quantile is the bound over the T2 nodes of that one model
    rows = np.broadcast_to(np.array([1.05, 0.06]), (2, 10, 2)).copy()
    _posterior(rows).to_netcdf(tmp_path / "posterior.nc")
    study = uqgear.parse_study(_study_text(tmp_path / "posterior.nc"), base_dir=tmp_path)
    (path,) = uqgear.run_study(study, tmp_path / "out", show_progress=False)
    result = uqgear.load_result(path)
    t2 = study.uncertain["adhesion_torque"]
    nodes = np.linspace(t2.lower, t2.upper, 3)
    speeds = np.array([1000.0, 2500.0, 4500.0])
    grid = uqgear.samples_from_mapping(
        {
            "pinion_speed": np.tile(speeds, 3),
            "adhesion_torque": np.repeat(nodes, 3),
            "mesh_stiffness_scale": np.full(9, 1.05),
            "zeta_mesh": np.full(9, 0.06),
        }
    )
    settings = {"n_periods": 80, "keep_periods": 30, "steps_per_mode": study.simulation.steps_per_mode}
    direct = uqgear.BatchEvaluator(design, fixed={"drive_torque": 7000.0}, **settings)(grid)
    force = direct["peak_mesh_force"].values.reshape(3, 3)
    for q in result["quantile"].values:
        at = result["peak_mesh_force"].sel(quantile=q)
        np.testing.assert_array_equal(at.sel(bound="upper").values, force.max(axis=0))
        np.testing.assert_array_equal(at.sel(bound="lower").values, force.min(axis=0))
    # the prior spreads where the posterior does not; the speeds outside 1500-3500 rpm are flagged
    prior = result["peak_mesh_force_prior"].sel(bound="upper")
    assert float((prior.isel(quantile=-1) - prior.isel(quantile=0)).max()) > 0
    assert result["extrapolated"].values.tolist() == [True, False, True]
    assert json.loads(result.attrs["narrowing"])["mesh_stiffness_scale"] == 0.0
    # the first screen's numbers are the result's: the worst case's band before and after, and where
    from uqgear.report.prediction_sections import prediction_findings

    first, extrapolation = prediction_findings([result])
    upper = result["peak_mesh_force"].sel(bound="upper")
    at = int(np.argmax(upper.sel(quantile=0.5).values))
    assert first.facts["at"] == {"pinion_speed": at}
    band = upper.isel(pinion_speed=at).values
    assert first.facts["posterior"] == [float(band[0]), float(band[-1])]
    assert "from the design's tolerances" in first.text and "after calibration on posterior.nc" in first.text
    assert "extrapolates beyond the rig campaign" in extrapolation.text
    assert "1000 rpm and 4500 rpm" in extrapolation.text


def test_prediction_samples_the_diagnosed_effect_per_draw(tmp_path):
    rows = np.random.default_rng(2).multivariate_normal(MEAN, COV, size=(4, 50))
    _posterior(rows).to_netcdf(tmp_path / "posterior.nc")
    model = (
        "model:\n  effects:\n    eccentricity: {shaft: pinion, amplitude: 12.0e-6, kappa: 0.03, "
        "intervals: {amplitude: [10.0e-6, 14.0e-6]}}\n"
    )
    # with guided starts: the extra starts carry each draw's effect parameters too
    text = _study_text(tmp_path / "posterior.nc", draws=4, model=model).replace(", starts: false", "")
    study = uqgear.parse_study(text.replace("[1000, 2500, 4500]", "[3600, 3700]"), base_dir=tmp_path)
    (path,) = uqgear.run_study(study, tmp_path / "out", show_progress=False)
    result = uqgear.load_result(path)
    assert int(result.attrs["effects_sampled"]) == 1
    assert json.loads(result.attrs["effects"])[0]["effect"] == "eccentricity"
    assert result["peak_mesh_force_draws"].sizes["draw"] == 4


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"converged": 0}, "uncertain.calibrated.posterior: the posterior has not converged"),
        ({"design": {"module": 0.01}}, "calibrated on another design (module"),
        ({"twice": True}, "uncertain.zeta_mesh: also calibrated"),
        ({"missing": True}, "posterior file not found"),
        ({"effects": "nothing"}, "model.effects: the diagnosis names no effect"),
    ],
)
def test_bad_inputs_are_refused_in_one_line_exit_2_nothing_written(tmp_path, change, message):
    design = uqgear.load_design("locomotive")
    if "design" in change:
        design = design.replace(**change["design"])
    rows = np.random.default_rng(2).multivariate_normal(MEAN, COV, size=(2, 20))
    _posterior(rows, converged=change.get("converged", 1), design=design).to_netcdf(tmp_path / "posterior.nc")
    posterior = tmp_path / ("absent.nc" if change.get("missing") else "posterior.nc")
    text = _study_text(posterior)
    if change.get("twice"):
        text = text.replace("  calibrated:", "  zeta_mesh: {interval: [0.03, 0.08]}\n  calibrated:")
    if change.get("effects"):
        (tmp_path / "diagnosis.json").write_text(json.dumps({"verdict": "unexplained", "effects": []}))
        text = text.replace("simulation:", "model: {effects: diagnosis.json}\nsimulation:")
    (tmp_path / "study.yaml").write_text(text)
    out = tmp_path / "out"
    run = subprocess.run(
        [sys.executable, "-m", "uqgear", "run", str(tmp_path / "study.yaml"), "--out", str(out)],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 2, run.stderr
    assert message in run.stderr and len(run.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_inputs_from_analyses_must_come_first():
    text = """
name: loop
analyses:
  - {type: prediction, name: prediction}
  - {type: calibrate, name: calibration, rig: healthy}
uncertain:
  adhesion_torque: {interval: [21.0e+3, 46.0e+3]}
  calibrated: {analysis: calibration}
"""
    with pytest.raises(uqgear.StudyError, match="analysis 'prediction' runs before 'calibration'"):
        uqgear.parse_study(text)
    with pytest.raises(uqgear.StudyError, match="'nope' is not a calibrate analysis"):
        uqgear.parse_study(text.replace("{analysis: calibration}", "{analysis: nope}"))


def test_a_calibration_runs_after_the_diagnosis_whose_effects_it_carries(tmp_path, monkeypatch):
    text = """
name: loop
analyses:
  - {type: calibrate, name: calibration, rig: eccentricity}
  - {type: diagnose, name: diagnosis, rig: eccentricity}
model: {effects: {analysis: diagnosis}}
"""
    with pytest.raises(uqgear.StudyError, match="analysis 'calibration' runs before 'diagnosis'"):
        uqgear.parse_study(text)
    # effects given by value: the calibration's model carries them at their fitted values
    given = "model:\n  effects:\n    tooth_damage: {gear: pinion, depth: 0.35, intervals: {depth: [0.3, 0.4]}}\n"
    study = uqgear.parse_study(
        "name: loop\nanalyses:\n  - {type: calibrate, name: calibration, rig: eccentricity}\n" + given
    )
    seen = {}

    class Stop(Exception):
        pass

    class Recording:
        def __init__(self, **settings):
            seen.update(settings)

        def fit(self, rig):
            raise Stop

    monkeypatch.setattr(uqgear.calibration, "Calibration", Recording)
    with pytest.raises(Stop):
        uqgear.run_study(study, tmp_path / "out", show_progress=False)
    (effect,) = seen["effects"]
    expected = uqgear.make_effect("tooth_damage", {"gear": "pinion", "depth": 0.35})
    assert (effect.name, dict(effect.values)) == (expected.name, dict(expected.values))


def test_bundled_loop_study_validates():
    study = uqgear.load_study("calibrated_prediction")
    assert [spec.type for spec in study.analyses] == ["diagnose", "calibrate", "prediction", "rating"]
    # the prediction bounds a tooth stress with its ISO inputs, so the chain ends in the rating's verdict
    prediction = study.analyses[2]
    assert "root_stress_peak_pinion" in prediction.options["qois"] and prediction.simulation.stresses is not None
    assert study.calibrated.analysis == "calibration" and study.effects.analysis == "diagnosis"
    assert set(study.calibrated.names) == {"mesh_stiffness_scale", "zeta_mesh", "backlash", "ste_amplitude", "k1", "k2"}


def test_other_analyses_hold_calibrated_parameters_at_their_posterior_median(tmp_path, known_posterior):
    known_posterior.to_netcdf(tmp_path / "posterior.nc")
    text = _study_text(tmp_path / "posterior.nc", draws=50).replace(
        "analyses:\n", "analyses:\n  - {type: interval, name: band, parameters: [adhesion_torque], method: vertex}\n"
    )
    study = uqgear.parse_study(text, base_dir=tmp_path)
    band, _ = uqgear.run_study(study, tmp_path / "out", show_progress=False)
    fixed = json.loads(uqgear.load_result(band).attrs["fixed_inputs"])
    thinned = uqgear.PosteriorDraws.from_dataset(known_posterior).thin(
        50, np.random.SeedSequence(4, spawn_key=(2,))
    )
    assert fixed["mesh_stiffness_scale"] == thinned.median("mesh_stiffness_scale")
    assert fixed["zeta_mesh"] == thinned.median("zeta_mesh")


def test_prediction_without_a_posterior_draws_the_study_distributions(tmp_path):
    text = """
name: unconditioned
seed: 2
operating_points: {pinion_speed: [1500, 3000], drive_torque: 7000}
uncertain:
  adhesion_torque: {interval: [25.0e+3, 40.0e+3]}
  zeta_mesh: {distribution: uniform, lower: 0.03, upper: 0.08}
simulation: {n_periods: 80, keep_periods: 30, starts: false}
analyses:
  - {type: prediction, name: prediction, points: 2, draws: 12, qois: [dte_rms]}
"""
    (path,) = uqgear.run_study(uqgear.parse_study(text), tmp_path / "out", show_progress=False)
    result = uqgear.load_result(path)
    assert result.attrs["draws_from"] == "study" and int(result.attrs["draws"]) == 12
    assert "dte_rms_prior" not in result and not bool(result["extrapolated"].any())
    upper = result["dte_rms"].sel(bound="upper")
    assert bool((upper.isel(quantile=-1) > upper.isel(quantile=0)).all())  # the damping's spread shows


def _doubling_posterior(path: Path) -> None:
    """A one-point posterior whose discrepancy is known exactly: the rig's DTE mesh harmonic is twice the model's
    at every operating point."""
    from uqgear.calibration.discrepancy import DiscrepancyBasis
    from uqgear.calibration.discrepancy_results import Discrepancy, DiscrepancyFit, discrepancy_dataset

    mean = np.zeros((3, 3, 4))
    mean[0, 0, 0] = np.log(2.0)  # te, first mesh harmonic, the constant of the basis
    fit = DiscrepancyFit(
        Discrepancy(DiscrepancyBasis((1500.0, 3500.0), (6000.0, 8000.0)), mean, np.zeros((3, 3, 4, 4))),
        np.zeros((3, 3, 3)), np.zeros((3, 3)), np.zeros((3, 3, 3)), (0.005, 3.0),
    )
    rows = np.broadcast_to(np.array([1.05, 0.06]), (2, 10, 2)).copy()
    posterior = _posterior(rows)
    posterior = posterior.merge(discrepancy_dataset(fit, {"pinion_speed": posterior["pinion_speed"].values,
                                                          "drive_torque": posterior["drive_torque"].values}))
    posterior.attrs.update(discrepancy_dataset(fit, {"pinion_speed": np.array([2000.0]),
                                                     "drive_torque": np.array([7000.0])}).attrs)
    posterior.to_netcdf(path)


def _posterior_grid(study) -> xr.Dataset:
    """The one-point posterior's parameters at every speed and T2 node of the prediction (T2 major)."""
    t2 = study.uncertain["adhesion_torque"]
    return uqgear.samples_from_mapping(
        {
            "pinion_speed": np.tile([1000.0, 2500.0, 4500.0], 3),
            "adhesion_torque": np.repeat(np.linspace(t2.lower, t2.upper, 3), 3),
            "mesh_stiffness_scale": np.full(9, 1.05),
            "zeta_mesh": np.full(9, 0.06),
        }
    )


def test_a_calibrated_discrepancy_scales_the_dynamic_part(tmp_path, design):
    _doubling_posterior(tmp_path / "posterior.nc")
    study = uqgear.parse_study(_study_text(tmp_path / "posterior.nc"), base_dir=tmp_path)
    (path,) = uqgear.run_study(study, tmp_path / "out", show_progress=False)
    result = uqgear.load_result(path)
    assert int(result.attrs["discrepancy"]) == 1
    grid = _posterior_grid(study)
    settings = {"n_periods": 80, "keep_periods": 30, "steps_per_mode": study.simulation.steps_per_mode}
    direct = uqgear.BatchEvaluator(design, fixed={"drive_torque": 7000.0}, **settings)(grid)
    static = direct["static_mesh_force"].values
    scaled = (static + 2.0 * (direct["peak_mesh_force"].values - static)).reshape(3, 3)
    np.testing.assert_allclose(result["peak_mesh_force"].sel(bound="upper", quantile=0.5), scaled.max(axis=0),
                               rtol=1e-12)
    dte = 2.0 * direct["dte_rms"].values.reshape(3, 3)  # the RMS about the mean is all dynamic
    np.testing.assert_allclose(result["dte_rms"].sel(bound="upper", quantile=0.5), dte.max(axis=0), rtol=1e-12)
    # the prior's runs, the design's tolerances before the rig data, carry no discrepancy
    assert result["peak_mesh_force_prior"].sel(bound="upper").min() < scaled.max(axis=0).min()


def test_a_prediction_bounds_the_tooth_stresses_and_scales_them_with_the_load(tmp_path, design):
    # the stresses of the model run directly, scaled as the tooth load: the root stress by the ratio of the
    # discrepancy's peak mesh force to the model's, the flank stress by its square root (Hertz)
    from uqgear.dynamics.stress_qois import StressEvaluator

    _doubling_posterior(tmp_path / "posterior.nc")
    text = _study_text(tmp_path / "posterior.nc").replace(
        "qois: [peak_mesh_force, dte_rms]",
        "qois: [peak_mesh_force, root_stress_peak_pinion, contact_stress_peak_gear], rating: {face_load_factor: 1.2}",
    )
    study = uqgear.parse_study(text, base_dir=tmp_path)
    (path,) = uqgear.run_study(study, tmp_path / "out", show_progress=False)
    result = uqgear.load_result(path)
    settings = {"n_periods": 80, "keep_periods": 30, "steps_per_mode": study.simulation.steps_per_mode}
    rating = uqgear.physics.rating.RatingSettings(face_load_factor=1.2)
    direct = StressEvaluator(design, rating=rating, fixed={"drive_torque": 7000.0}, **settings)(
        _posterior_grid(study)
    )
    peak, static = direct["peak_mesh_force"].values, direct["static_mesh_force"].values
    ratio = (static + 2.0 * (peak - static)) / peak
    root = (direct["root_stress_peak_pinion"].values * ratio).reshape(3, 3)
    flank = (direct["contact_stress_peak_gear"].values * np.sqrt(ratio)).reshape(3, 3)
    for name, expected in (("root_stress_peak_pinion", root), ("contact_stress_peak_gear", flank)):
        band = result[name].sel(quantile=0.5)
        np.testing.assert_allclose(band.sel(bound="upper"), expected.max(axis=0), rtol=1e-12)
        np.testing.assert_allclose(band.sel(bound="lower"), expected.min(axis=0), rtol=1e-12)
        assert result[name].attrs["units"] == "Pa" and f"{name}_prior" in result
    # the discrepancy doubles the dynamic load: every stress above the model's own
    assert bool((ratio > 1.0).all())
    # a rating block needs a stress QoI
    with pytest.raises(uqgear.StudyError, match=r"analyses\[0\]\.rating: only the tooth stress QoIs"):
        uqgear.parse_study(text.replace("root_stress_peak_pinion, contact_stress_peak_gear", "dte_rms"),
                           base_dir=tmp_path)


@pytest.mark.parametrize(
    ("section", "message"),
    [
        ("uncertain:\n  calibrated: {posterior: p.nc, analysis: cal}\n",
         "uncertain.calibrated: expected exactly one of posterior (a file) and analysis (NAME)"),
        ("model:\n  effects: {wobble: {amplitude: 1.0}}\n", "model.effects.wobble: unknown effect"),
        ("model:\n  effects: {eccentricity: {amplitude: -1.0e-5}}\n", "model.effects.eccentricity.amplitude"),
        ("model:\n  effects: [eccentricity]\n", "model.effects: expected a diagnosis.json path"),
    ],
)
def test_wrong_model_inputs_are_refused_naming_the_key(section, message):
    text = (
        "name: wrong\noperating_points: {pinion_speed: [2000, 3000]}\n"
        "analyses:\n  - {type: bifurcation, parameter: pinion_speed}\n" + section
    )
    with pytest.raises(uqgear.StudyError) as caught:
        uqgear.parse_study(text)
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_each_draw_carries_the_discrepancy_drawn_with_its_parameters():
    # three draws of the coefficients, known: the factor of each draw is exp(phi . beta) of its own row
    from uqgear.calibration.discrepancy import DiscrepancyBasis
    from uqgear.calibration.discrepancy_results import Discrepancy
    from uqgear.study.prediction import DiscrepancyFactors

    basis = DiscrepancyBasis((1000.0, 3000.0), (6000.0, 8000.0))
    fitted = Discrepancy(basis, np.zeros((3, 3, 4)), np.zeros((3, 3, 4, 4)))
    beta = np.zeros((3, 3, 3, 4))
    beta[1, 0, 0, 0] = np.log(2.0)  # the second draw: twice the DTE's mesh harmonic everywhere
    beta[2, 0, 0, 1] = 0.1  # the third: a slope in speed
    beta[2, 1, 0, 0] = 5.0  # another channel's discrepancy is not carried
    factors = DiscrepancyFactors(fitted, 7000.0, beta)(
        {"pinion_speed": np.array([1000.0, 3000.0])}, 3, np.random.default_rng(0)
    )
    np.testing.assert_allclose(factors, [[1.0, 1.0], [2.0, 2.0], [np.exp(-0.1), np.exp(0.1)]], rtol=1e-12)
    # thinning keeps each row's coefficients with its parameters
    posterior = uqgear.PosteriorDraws(("zeta_mesh",), np.array([[0.04], [0.05], [0.06]]), discrepancy_beta=beta)
    thinned = posterior.thin(2, seed=0)
    for value, row in zip(thinned.values[:, 0], thinned.discrepancy_beta):
        np.testing.assert_array_equal(row, beta[int(round(value * 100)) - 4])
    with pytest.raises(uqgear.PosteriorError, match="discrepancy_beta"):
        uqgear.PosteriorDraws(("zeta_mesh",), np.array([[0.04], [0.05]]), discrepancy_beta=beta)


def test_a_stress_qoi_from_a_model_without_stresses_is_refused_naming_it(design):
    posterior = _posterior(np.broadcast_to(np.array([1.05, 0.06]), (1, 2, 2)).copy())
    space = uqgear.ParameterSpace.from_posterior(posterior, {"adhesion_torque": [25e3, 40e3]}, draws=2, seed=1)
    model = uqgear.BatchEvaluator(design, fixed={"drive_torque": 7000.0, "pinion_speed": 2000.0},
                                  n_periods=20, keep_periods=10)
    with pytest.raises(uqgear.ParameterSpaceError, match="qoi: 'root_stress_peak_pinion' is not among the model's"):
        uqgear.PosteriorPrediction(["root_stress_peak_pinion"], points=2).fit(model, space)
