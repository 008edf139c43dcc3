"""Tests of the model-discrepancy term of the calibration (uqgear.calibration.discrepancy)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.special
import xarray as xr
from scipy.stats import multivariate_normal

from uqgear.calibration import Calibration, CalibrationError
from uqgear.calibration.discrepancy import DiscrepancyBasis, DiscrepancyLikelihood, tau_grid
from uqgear.calibration.discrepancy_results import (
    discrepancy_dataset,
    discrepancy_summary,
    fit_discrepancy,
    joint_beta_draws,
    read_discrepancy,
)
from uqgear.calibration.emulator import PolynomialEmulator
from uqgear.calibration.failure import failure_causes
from uqgear.calibration.likelihood import Features, StageLikelihood
from uqgear.common.errors import StudyError
from uqgear.rig.virtual_rig import simulate_campaign

SPEEDS = np.array([600.0, 800.0, 1250.0, 1700.0, 2200.0, 2800.0, 3400.0, 3800.0])
TORQUES = np.array([7000.0, 5000.0, 6000.0, 8000.0, 7500.0, 6500.0, 5500.0, 5000.0])
N_GLOBAL = 1


def _emulators(n_op, slope=0.0):
    """Per run, an exact linear emulator of the 9 log features in (global parameter, T2), z in [-1, 1]."""
    rng = np.random.default_rng(0)
    z = rng.uniform(-1.0, 1.0, (16, N_GLOBAL + 1))
    outputs = slope * z[:, :1] * np.arange(1, 10)[None, :] / 9.0
    return [PolynomialEmulator(N_GLOBAL + 1, 1).fit(z, outputs) for _ in range(n_op)]


def _features(log_observed, used, noise_variance, model_error_grid):
    return Features(None, used, np.where(used, log_observed, 0.0), np.where(used, noise_variance, 1.0),
                    np.asarray(model_error_grid, float))


def _likelihoods(features, n_op, tau, slope=0.0, no_discrepancy=0.0):
    box = (np.zeros(N_GLOBAL + n_op), np.ones(N_GLOBAL + n_op))
    emulators, loo = _emulators(n_op, slope), np.zeros((n_op, 9))
    phi = DiscrepancyBasis.of_campaign(SPEEDS[:n_op], TORQUES[:n_op]).matrix(SPEEDS[:n_op], TORQUES[:n_op])
    plain = StageLikelihood(*box, emulators, loo, features, N_GLOBAL)
    return plain, DiscrepancyLikelihood(*box, emulators, loo, features, N_GLOBAL, phi=phi, tau=np.asarray(tau),
                                        no_discrepancy=no_discrepancy)


# --------------------------------------------------------------------------- (a) the marginal likelihood


def test_marginal_likelihood_equals_the_gaussian_and_a_monte_carlo_integral_over_beta():
    """One tau and one sigma: the Woodbury form against the dense Gaussian and a Monte Carlo integral over beta."""
    n_op, tau, sigma = 5, 0.15, 0.1
    rng = np.random.default_rng(1)
    used = np.zeros((n_op, 3, 3), bool)
    used[:, 0, 0] = True
    used[[0, 2, 3], 1, 1] = True  # a group with features left out at two runs
    noise = rng.uniform(0.01, 0.03, used.shape)
    log_observed = rng.normal(0.0, 0.2, used.shape)
    features = _features(log_observed, used, noise, [sigma])
    _, likelihood = _likelihoods(features, n_op, [tau])
    point = np.full((1, N_GLOBAL + n_op), 0.5)  # the emulators predict 0: residual = log_observed
    terms = likelihood.group_log_likelihood(log_observed[None] - likelihood.emulate(point))[0]
    phi = likelihood.phi
    beta = rng.normal(0.0, tau, (400_000, phi.shape[1]))
    for channel, harmonic in ((0, 0), (1, 1)):
        rows = used[:, channel, harmonic]
        r, basis = log_observed[rows, channel, harmonic], phi[rows]
        variance = noise[rows, channel, harmonic] + sigma**2
        exact = multivariate_normal(np.zeros(rows.sum()), np.diag(variance) + tau**2 * basis @ basis.T).logpdf(r)
        assert terms[channel, harmonic] == pytest.approx(exact, abs=1e-10)
        # the integral over beta ~ N(0, tau^2 I) of the likelihood given beta, by Monte Carlo
        given = -0.5 * np.sum((r[None] - beta @ basis.T) ** 2 / variance + np.log(2 * np.pi * variance), axis=1)
        monte_carlo = scipy.special.logsumexp(given) - np.log(beta.shape[0])
        assert terms[channel, harmonic] == pytest.approx(monte_carlo, abs=0.02)
    # a group without features adds nothing
    assert terms[2, 2] == 0.0


def test_marginal_likelihood_tends_to_the_ordinary_one_as_tau_tends_to_zero():
    n_op = 8
    rng = np.random.default_rng(2)
    used = rng.uniform(size=(n_op, 3, 3)) > 0.2
    log_observed = rng.normal(0.0, 0.1, used.shape)
    features = _features(log_observed, used, rng.uniform(1e-4, 1e-3, used.shape), np.geomspace(0.01, 0.5, 32))
    plain, vanishing = _likelihoods(features, n_op, [1e-9], slope=0.3)
    points = rng.uniform(size=(40, N_GLOBAL + n_op))
    residual = log_observed[None] - plain.emulate(points)
    np.testing.assert_allclose(vanishing.group_terms(residual), plain.group_terms(residual), rtol=0, atol=1e-8)
    np.testing.assert_allclose(vanishing.log_likelihood(points), plain.log_likelihood(points), rtol=0, atol=1e-7)
    # and a discrepancy the data do not need costs little: the wide grid's likelihood stays close
    _, wide = _likelihoods(features, n_op, tau_grid((0.005, 3.0)), slope=0.3)
    assert np.all(np.isfinite(wide.log_likelihood(points)))


# --------------------------------------------------------------------------- (b) a known discrepancy recovered


def _synthetic(delta, theta=0.4, noise_sd=0.01, seed=3, no_discrepancy=0.0):
    """Log features = the emulators at theta + delta(speed, torque) per channel + noise (8 runs)."""
    n_op = SPEEDS.size
    rng = np.random.default_rng(seed)
    used = np.ones((n_op, 3, 3), bool)
    used[:, 2, 2] = False  # one group without data
    plain, _ = _likelihoods(_features(np.zeros(used.shape), used, noise_sd**2, [0.01]), n_op, [0.1], slope=0.3)
    point = np.concatenate([[theta], np.full(n_op, 0.5)])
    truth = delta(SPEEDS, TORQUES)  # (op, channel, harmonic)
    log_observed = plain.emulate(point[None])[0] + truth + rng.normal(0.0, noise_sd, used.shape)
    features = _features(log_observed, used, noise_sd**2, np.geomspace(0.01, 0.5, 32))
    _, likelihood = _likelihoods(features, n_op, tau_grid((0.005, 3.0)), slope=0.3, no_discrepancy=no_discrepancy)
    # posterior draws of the parameter: narrow around the truth (its own posterior is not the subject here)
    draws = np.tile(point, (200, 1))
    draws[:, 0] += rng.normal(0.0, 0.002, 200)
    return features, likelihood, draws, truth


def _smooth_delta(speed, torque):
    s = 2 * (speed - 600.0) / 3200.0 - 1
    t = 2 * (torque - 5000.0) / 3000.0 - 1
    shape = 0.3 + 0.2 * s - 0.1 * t + 0.25 * s**2
    return shape[:, None, None] * np.array([1.0, -0.5, 2.0])[None, :, None] * np.ones((1, 1, 3))


def test_a_known_smooth_discrepancy_is_recovered_within_its_stated_uncertainty():
    features, likelihood, draws, truth = _synthetic(_smooth_delta)
    basis = DiscrepancyBasis.of_campaign(SPEEDS, TORQUES)
    fit = fit_discrepancy(draws, likelihood, features, basis)
    mean, sd = fit.discrepancy.mean_at(SPEEDS, TORQUES), fit.discrepancy.sd_at(SPEEDS, TORQUES)
    used_groups = features.used.any(axis=0)
    error = (mean - truth)[:, used_groups]
    assert np.all(np.abs(error) <= 3.0 * sd[:, used_groups])
    assert np.max(sd[:, used_groups]) < 0.05  # informative: the discrepancy is up to 1.5 in log units
    assert np.isnan(mean[:, 2, 2]).all()
    # tau's posterior sits near the coefficients' size (about 0.1-0.6 here), far from both grid ends
    assert 0.05 < fit.tau_quantiles[0, 0, 1] < 1.5
    # a group whose data carry no discrepancy gets a small tau
    features_zero, likelihood_zero, draws_zero, _ = _synthetic(lambda s, t: np.zeros((s.size, 3, 3)))
    fit_zero = fit_discrepancy(draws_zero, likelihood_zero, features_zero, basis)
    assert fit_zero.tau_quantiles[0, 0, 1] < 0.05
    operating = {"pinion_speed": SPEEDS, "drive_torque": TORQUES}
    summary = discrepancy_summary(fit, features, np.zeros(features.used.shape), operating)
    assert summary["groups"]["te_mesh1"]["mean"] == pytest.approx(list(mean[:, 0, 0]))
    # the share of the predictive variance, recomputed from its parts (acc_pinion: all three groups used)
    parts = {
        "discrepancy": sd[:, 1] ** 2,
        "parameters": fit.parameter_variance[:, 1],
        "model_error": np.broadcast_to(fit.sigma_median[1] ** 2, (SPEEDS.size, 3)),
        "noise": features.noise_variance[:, 1],
    }
    share = parts["discrepancy"].sum() / sum(part.sum() for part in parts.values())
    assert summary["share"]["acc_pinion"] == pytest.approx(share)
    # the size of the shift its mean makes: that of the true discrepancy
    for channel, c in (("te", 0), ("acc_pinion", 1)):
        assert summary["rms_mean"][channel] == pytest.approx(np.sqrt(np.mean(truth[:, c] ** 2)), rel=0.05)
    assert summary["share"]["te"] < 0.9 and summary["share"]["te"] > 0.0


def test_discrepancy_draws_at_new_points_and_read_back_from_a_file(tmp_path):
    features, likelihood, draws, _ = _synthetic(_smooth_delta)
    fit = fit_discrepancy(draws, likelihood, features, DiscrepancyBasis.of_campaign(SPEEDS, TORQUES))
    speeds, torques = np.array([1000.0, 3000.0]), np.array([6000.0, 7000.0])
    samples = fit.discrepancy.at(speeds, torques, 20000, np.random.default_rng(4))
    assert samples.dims == ("draw", "point", "channel", "harmonic") and "log" in samples.attrs["units"]
    mean = fit.discrepancy.mean_at(speeds, torques)
    np.testing.assert_allclose(samples.mean("draw").values[:, :2], mean[:, :2], atol=0.002)
    np.testing.assert_allclose(samples.std("draw").values[:, :2], fit.discrepancy.sd_at(speeds, torques)[:, :2],
                               rtol=0.05)
    # the truth at the new points lies within the draws' 99 % range
    truth = _smooth_delta(speeds, torques)
    low, high = samples.isel(channel=[0, 1]).quantile([0.005, 0.995], dim="draw").values
    assert np.all((low[:, :2] <= truth[:, :2]) & (truth[:, :2] <= high[:, :2]))
    path = tmp_path / "posterior.nc"
    discrepancy_dataset(fit, {"pinion_speed": SPEEDS, "drive_torque": TORQUES}).to_netcdf(path)
    read = read_discrepancy(xr.load_dataset(path))
    again = read.at(speeds, torques, 50, np.random.default_rng(5))
    direct = fit.discrepancy.at(speeds, torques, 50, np.random.default_rng(5))
    np.testing.assert_array_equal(again.values, direct.values)
    with pytest.raises(CalibrationError, match="no discrepancy"):
        read_discrepancy(xr.Dataset())


# --------------------------------------------------------------------------- (b2) the point at zero, joint draws


def test_joint_draws_follow_the_posterior_of_beta_given_the_parameters():
    """One (sigma, tau) pair: the draws' mean and covariance against the dense Gaussian conditional."""
    n_op, tau, sigma = 8, 0.15, 0.05
    rng = np.random.default_rng(6)
    used = np.ones((n_op, 3, 3), bool)
    log_observed = rng.normal(0.0, 0.2, used.shape)
    noise = np.full(used.shape, 1e-4)
    _, likelihood = _likelihoods(_features(log_observed, used, noise, [sigma]), n_op, [tau], slope=0.3)
    point = np.full(N_GLOBAL + n_op, 0.5)
    draws = joint_beta_draws(np.tile(point, (40_000, 1)), likelihood, np.random.default_rng(7))
    r = (log_observed - likelihood.emulate(point[None])[0])[:, 0, 0]  # te mesh1 over the runs
    phi = likelihood.phi
    total = np.diag(noise[:, 0, 0] + sigma**2) + tau**2 * phi @ phi.T
    gain = tau**2 * phi.T @ np.linalg.inv(total)
    mean, covariance = gain @ r, tau**2 * np.eye(4) - gain @ phi * tau**2
    sd = np.sqrt(np.diag(covariance))
    assert np.all(np.abs(draws[:, 0].mean(axis=0) - mean) <= 4 * sd / np.sqrt(40_000))
    np.testing.assert_allclose(np.cov(draws[:, 0].T), covariance, rtol=0.05, atol=0.05 * sd.max() ** 2)


def test_with_no_discrepancy_in_the_data_the_point_at_zero_takes_the_weight():
    """Data with no discrepancy: most draws carry none, so the band shrinks towards the ordinary one; a known
    discrepancy: none of the draws is zero and they hold the truth."""
    basis = DiscrepancyBasis.of_campaign(SPEEDS, TORQUES)
    phi = basis.matrix(SPEEDS, TORQUES)
    zero = lambda s, t: np.zeros((s.size, 3, 3))  # noqa: E731
    spreads = {}
    for weight in (0.0, 0.5):
        _, likelihood, draws, _ = _synthetic(zero, no_discrepancy=weight)
        beta = joint_beta_draws(draws, likelihood, np.random.default_rng(8))  # (M, G, p)
        delta = np.einsum("np,mp->mn", phi, beta[:, 0])  # te mesh1 at the runs
        spreads[weight] = np.subtract(*np.quantile(delta, [0.95, 0.05], axis=0))
        if weight:
            # the posterior weight of tau = 0 rises above its prior's one half
            assert np.mean(np.all(beta[:, :8] == 0.0, axis=2)) > 0.7
    # the 90 % band of the discrepancy at the runs narrows (about 0.6 times here)
    assert np.mean(spreads[0.5] / spreads[0.0]) < 0.8
    _, likelihood, draws, truth = _synthetic(_smooth_delta, no_discrepancy=0.5)
    beta = joint_beta_draws(draws, likelihood, np.random.default_rng(9))
    assert not np.any(np.all(beta[:, :8] == 0.0, axis=2))
    assert np.isnan(beta[:, 8]).all()  # the group without data
    delta = np.einsum("np,mgp->mng", phi, beta[:, :8])
    low, high = np.quantile(delta, [0.005, 0.995], axis=0)
    expected = truth.reshape(SPEEDS.size, -1)[:, :8]
    assert np.all((low <= expected) & (expected <= high))


def test_joint_draws_take_back_what_the_parameters_move():
    """Parameter draws that move the emulated features: the discrepancy drawn with each draw takes the features
    back towards the data, so that model plus discrepancy spreads less than the model alone; drawn apart from the
    parameters (the summary Gaussian) it spreads more."""
    features, likelihood, draws, _ = _synthetic(_smooth_delta)
    spread = draws.copy()
    # a wide parameter posterior, seen most by acc_gear mesh2 (the emulators' steepest group with data)
    spread[:, 0] = np.clip(np.random.default_rng(10).normal(0.4, 0.15, draws.shape[0]), 0.01, 0.99)
    emulated = likelihood.emulate(spread)[:, :, 2, 1]  # (M, op)
    phi = likelihood.phi
    joint = np.einsum("np,mp->mn", phi, joint_beta_draws(spread, likelihood, np.random.default_rng(11))[:, 7])
    fit = fit_discrepancy(spread, likelihood, features, DiscrepancyBasis.of_campaign(SPEEDS, TORQUES))
    apart = fit.discrepancy.at(SPEEDS, TORQUES, spread.shape[0], np.random.default_rng(12)).values[:, :, 2, 1]
    model_sd = emulated.std(axis=0)
    assert np.all((emulated + joint).std(axis=0) < 0.5 * model_sd)
    assert np.all((emulated + apart).std(axis=0) > model_sd)


# --------------------------------------------------------------------------- (c) the estimator, off and on


_CHEAP = {"n_training": 32, "emulator_degree": 2, "max_stages": 1, "stage_steps": 200, "chunk_steps": 500,
          "max_steps": 1000, "predictive_draws": 2, "pitch_correction": False, "seed": 1}


@pytest.fixture(scope="module")
def cheap_rig(design):
    ops = {"pinion_speed": [1250.0, 2200.0, 3400.0], "drive_torque": [6000.0, 7500.0, 5500.0]}
    truth = {"mesh_stiffness_scale": 1.1}
    return simulate_campaign(design, ops, true_parameters=truth, seed=5, duration=0.2, run_in=0.2)


def test_without_the_option_every_number_is_unchanged(cheap_rig):
    default = Calibration(["mesh_stiffness_scale"], **_CHEAP).fit(cheap_rig)
    off = Calibration(["mesh_stiffness_scale"], discrepancy=False, **_CHEAP).fit(cheap_rig)
    xr.testing.assert_identical(default.posterior_, off.posterior_)
    xr.testing.assert_identical(default.predictive_, off.predictive_)
    assert default.summary_ == off.summary_ and default.predictive_check_ == off.predictive_check_
    assert default.diagnostics_ == off.diagnostics_ and "discrepancy" not in default.summary_
    assert default.discrepancy_ is None and "discrepancy_beta_mean" not in default.posterior_
    with pytest.raises(CalibrationError, match="no fitted discrepancy"):
        default.discrepancy_at([2000.0], [6000.0], 3, np.random.default_rng(0))


def test_a_fit_with_the_discrepancy_reports_and_carries_it(cheap_rig, tmp_path):
    from uqgear.calibration import write_calibration

    fitted = Calibration(["mesh_stiffness_scale"], discrepancy=True, **_CHEAP).fit(cheap_rig)
    summary = fitted.summary_["discrepancy"]
    assert set(summary["share"]) == {"te", "acc_pinion", "acc_gear"}
    assert all(0.0 <= share < 1.0 for share in summary["share"].values())
    assert {"q05", "q50", "q95"} <= set(summary["groups"]["te_mesh1"]["tau"])
    check = fitted.predictive_check_
    assert "passed_without_discrepancy" in check and "z_discrepancy" in fitted.predictive_
    assert "parameter_log_std" in fitted.predictive_ and "discrepancy_log_std" in fitted.predictive_
    draws = fitted.discrepancy_at([2000.0, 3000.0], [6000.0, 6500.0], 7, np.random.default_rng(0))
    assert draws.shape == (7, 2, 3, 3)
    # one draw of the coefficients with each posterior draw, kept aligned through thinning
    from uqgear.uq.posterior import PosteriorDraws

    beta = fitted.posterior_["discrepancy_beta"]
    assert beta.dims == ("chain", "draw", "channel", "harmonic", "basis")
    posterior = PosteriorDraws.from_calibration(fitted)
    assert posterior.discrepancy_beta.shape == (posterior.size, 3, 3, 4)
    thinned = posterior.thin(5, seed=2)
    for value, beta_row in zip(thinned.values[:, 0], thinned.discrepancy_beta):  # the chains repeat rows
        same = posterior.values[:, 0] == value
        assert any(np.array_equal(beta_row, other, equal_nan=True) for other in posterior.discrepancy_beta[same])
    paths = write_calibration(fitted, tmp_path / "out")
    read = read_discrepancy(xr.load_dataset(paths["posterior"]))
    np.testing.assert_allclose(read.beta_mean, fitted.discrepancy_.beta_mean)
    assert "discrepancy" in paths["report"].read_text().lower()
    with pytest.raises(CalibrationError, match="discrepancy_range"):
        Calibration(discrepancy_range=(0.5, 0.1))
    with pytest.raises(CalibrationError, match="discrepancy: expected true or false"):
        Calibration(discrepancy="yes")


def test_the_discrepancy_lifts_the_capped_model_error_cause_only_when_it_explains_the_misfit():
    z = np.zeros((2, 3, 1))
    predictive = xr.Dataset({"z_total": (("op", "channel", "harmonic"), z),
                             "relative_difference": (("op", "channel", "harmonic"), z)},
                            coords={"channel": ["te", "acc_pinion", "acc_gear"], "harmonic": [1],
                                    "pinion_speed": ("op", [1000.0, 2000.0])})
    summary = {"parameters": {}, "model_error": {"te_mesh1": {"q50": 0.5}},
               "discrepancy": {"groups": {"te_mesh1": {"tau": {"q50": 0.4}}}}}
    parts = {"diagnostics": {"reasons": []}, "summary": summary, "predictive": predictive, "model_error_cap": 0.5}
    explained = failure_causes(predictive_check={"passed": True}, discrepancy_cap=3.0, **parts)
    assert explained["message"] == ""
    unexplained = failure_causes(predictive_check={"passed": False, "fraction_within_2_sigma": 0.5,
                                                   "median_abs_relative_difference": 0.3}, discrepancy_cap=3.0, **parts)
    assert [c["kind"] for c in unexplained["causes"]] == ["predictive_misfit", "model_error_at_cap"]
    # without the discrepancy the cap is a cause as before
    ordinary = failure_causes(predictive_check={"passed": True}, **parts)
    assert [c["kind"] for c in ordinary["causes"]] == ["model_error_at_cap"]
    summary["discrepancy"]["groups"]["te_mesh1"]["tau"]["q50"] = 2.9
    capped = failure_causes(predictive_check={"passed": True}, discrepancy_cap=3.0, **parts)
    assert [c["kind"] for c in capped["causes"]] == ["discrepancy_at_cap"]


def test_the_command_line_and_a_study_switch_it_on():
    from uqgear.cli import build_parser
    from uqgear.study.analysis_schemas import ANALYSIS_DEFAULTS, ANALYSIS_SCHEMAS

    parser = build_parser()
    assert parser.parse_args(["calibrate", "rig.nc", "--out", "cal", "--discrepancy"]).discrepancy is True
    assert parser.parse_args(["calibrate", "rig.nc", "--out", "cal"]).discrepancy is False
    assert ANALYSIS_DEFAULTS["calibrate"]["discrepancy"] is False
    assert ANALYSIS_SCHEMAS["calibrate"]["discrepancy"](True, "analyses[0].discrepancy") is True
    with pytest.raises(StudyError, match=r"analyses\[0\]\.discrepancy"):
        ANALYSIS_SCHEMAS["calibrate"]["discrepancy"]("yes", "analyses[0].discrepancy")
