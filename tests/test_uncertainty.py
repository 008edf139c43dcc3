"""Parameter spaces, sampling, Monte Carlo statistics and polynomial chaos."""

from __future__ import annotations

import math

import chaospy
import numpy as np
import pytest
import xarray as xr
from scipy import stats

from uqgear.common.errors import ExecutionError, ParameterSpaceError, UqgearError
from uqgear.physics.design import load_design
from uqgear.uq.monte_carlo import monte_carlo_statistics
from uqgear.uq.parameter_space import ParameterSpace
from uqgear.uq.parameters import DISTRIBUTION_NAMES, Distribution, Fixed, Interval
from uqgear.uq.polynomial_chaos import PolynomialChaos, number_of_terms, total_degree_indices
from uqgear.uq.sampling import SAMPLING_METHODS
from uqgear.uq.seeds import as_seed_sequence
from uqgear.uq.sweeps import call_model, evaluate_on_sweep

# Ishigami function with a = 7, b = 0.1 on [-pi, pi]^3 (Ishigami & Homma 1990).
ISHIGAMI_MEAN = 3.5
ISHIGAMI_VARIANCE = 0.5 + 7 ** 2 / 8 + 0.1 * math.pi ** 4 / 5 + 0.1 ** 2 * math.pi ** 8 / 18
ISHIGAMI_S1 = np.array([0.3139, 0.4424, 0.0])
ISHIGAMI_ST = np.array([0.5576, 0.4424, 0.2437])


def ishigami(samples: xr.Dataset) -> xr.Dataset:
    x1, x2, x3 = (samples[name].values for name in ("x1", "x2", "x3"))
    y = np.sin(x1) + 7.0 * np.sin(x2) ** 2 + 0.1 * x3 ** 4 * np.sin(x1)
    return xr.Dataset({"y": ("sample", y, {"units": "m"})})


def ishigami_space() -> ParameterSpace:
    return ParameterSpace({name: Distribution("uniform", lower=-math.pi, upper=math.pi)
                           for name in ("x1", "x2", "x3")})


def round_trip(dataset: xr.Dataset, tmp_path) -> None:
    path = tmp_path / "result.nc"
    dataset.to_netcdf(path)
    with xr.open_dataset(path) as reloaded:
        xr.testing.assert_identical(reloaded.load(), dataset)


# ---------------------------------------------------------------------------
# parameter kinds
# ---------------------------------------------------------------------------

def test_adhesion_interval_matches_closed_form_and_design():
    interval = Interval.from_adhesion(0.15, 0.33, 23000.0, 0.625)
    lever = 23000.0 * 9.80665 * 0.625
    assert interval.lower == pytest.approx(0.15 * lever)
    assert interval.upper == pytest.approx(0.33 * lever)
    assert interval.units == "N m"
    # docs/model/reference-design.md: T2 in about [21.2, 46.5] kN m; design.py computes the same
    assert (interval.lower, interval.upper) == pytest.approx(load_design().operation.adhesion_torque_bounds())
    assert interval.lower == pytest.approx(21.15e3, rel=2e-3)


@pytest.mark.parametrize(("arguments", "message"), [
    ((-0.1, 0.3, 23000, 0.625), r"adhesion_coefficient lower bound: expected a number in \[0, 1.5\]"),
    ((0.3, 0.15, 23000, 0.625), r"adhesion_coefficient: inverted interval"),
    ((0.15, 0.33, 0.0, 0.625), r"axle_load: expected a positive mass in kg; got 0.0"),
    ((0.15, 0.33, 23000, -1.0), r"wheel_radius: expected a positive radius in m; got -1.0"),
    ((0.15, "dry", 23000, 0.625), r"adhesion_coefficient upper bound"),
])
def test_adhesion_interval_rejects_bad_input(arguments, message):
    with pytest.raises(ParameterSpaceError, match=message):
        Interval.from_adhesion(*arguments)


def test_interval_errors_name_the_parameter():
    with pytest.raises(ParameterSpaceError, match=r"adhesion_torque: .*inverted interval.*lower=5.0 > upper=1.0"):
        ParameterSpace({"adhesion_torque": [5.0, 1.0]})
    with pytest.raises(ParameterSpaceError, match=r"mesh_stiffness_scale: .*empty interval"):
        ParameterSpace({"mesh_stiffness_scale": {"interval": [1.0, 1.0]}})
    with pytest.raises(ParameterSpaceError, match=r"Interval\(2, 1\): inverted interval"):
        Interval(2, 1)
    with pytest.raises(ParameterSpaceError, match=r"lower bound: expected a finite number; got nan"):
        Interval(float("nan"), 1.0)
    with pytest.raises(ParameterSpaceError, match=r"adhesion_torque: expected \[lower, upper\]; got \[1, 2, 3\]"):
        ParameterSpace({"adhesion_torque": [1, 2, 3]})
    # the errors are user errors: ValueError subclasses of the project's base class
    assert issubclass(ParameterSpaceError, UqgearError) and issubclass(ParameterSpaceError, ValueError)


def test_unknown_distribution_lists_known_ones():
    with pytest.raises(ParameterSpaceError, match=r"distribution 'weibul': unknown; expected one of "
                                                  r"normal, uniform, lognormal, beta, truncnormal, triangle"):
        Distribution("weibul", scale=1.0)
    with pytest.raises(ParameterSpaceError, match=r"backlash: distribution 'gauss': unknown"):
        ParameterSpace({"backlash": {"distribution": "gauss", "mu": 1.0, "sigma": 0.1}})


@pytest.mark.parametrize(("name", "params", "message"), [
    ("normal", {"mu": 1.0, "sigma": 0.0}, r"normal\(mu, sigma\): sigma must be > 0; got 0.0"),
    ("normal", {"mu": 1.0}, r"missing parameter\(s\) sigma"),
    ("normal", {"mu": 1.0, "sigma": 1.0, "scale": 2.0}, r"unknown parameter\(s\) scale"),
    ("uniform", {"lower": 2.0, "upper": 1.0}, r"expected lower <= upper"),
    ("triangle", {"lower": 0.0, "mode": 2.0, "upper": 1.0}, r"expected lower <= mode <= upper"),
    ("beta", {"alpha": -1.0, "beta": 2.0}, r"alpha must be > 0"),
    ("truncnormal", {"mu": 0.0, "sigma": 1.0, "lower": 1.0, "upper": 1.0}, r"expected lower < upper"),
    ("lognormal", {"mu": 0.0, "sigma": "wide"}, r"sigma: expected a finite number; got 'wide'"),
    ("gamma", {"shape": 2.0, "scale": -1.0}, r"scale must be > 0"),
])
def test_distribution_rejects_bad_parameters(name, params, message):
    with pytest.raises(ParameterSpaceError, match=message):
        Distribution(name, **params)


@pytest.mark.parametrize(("name", "params", "mean", "std"), [
    ("normal", {"mu": 2.0, "sigma": 0.5}, 2.0, 0.5),
    ("uniform", {"lower": 1.0, "upper": 3.0}, 2.0, 2.0 / math.sqrt(12)),
    ("lognormal", {"mu": 0.1, "sigma": 0.25, "shift": 1.0},
     1.0 + math.exp(0.1 + 0.25 ** 2 / 2), math.sqrt((math.exp(0.25 ** 2) - 1) * math.exp(0.2 + 0.25 ** 2))),
    ("beta", {"alpha": 2.0, "beta": 3.0, "lower": 1.0, "upper": 3.0},
     1.0 + 2.0 * 2.0 / 5.0, 2.0 * math.sqrt(2 * 3 / (5 ** 2 * 6))),
    ("truncnormal", {"mu": 0.0, "sigma": 1.0, "lower": -1.0, "upper": 1.0},
     0.0, math.sqrt(stats.truncnorm(-1, 1).var())),
    ("triangle", {"lower": 0.0, "mode": 1.0, "upper": 4.0}, 5.0 / 3.0, math.sqrt((0 + 1 + 16 - 0 - 0 - 4) / 18)),
    ("gamma", {"shape": 2.0, "scale": 3.0, "shift": 1.0}, 7.0, math.sqrt(2.0) * 3.0),
    ("exponential", {"scale": 2.0, "shift": 1.0}, 3.0, 2.0),
])
def test_distribution_maps_to_chaospy_and_samples_correctly(name, params, mean, std):
    distribution = Distribution(name, units="m", **params)
    chaospy_distribution = distribution.to_chaospy()
    assert float(chaospy.E(chaospy.variable(), chaospy_distribution)) == pytest.approx(mean, rel=1e-6, abs=1e-9)
    assert float(chaospy.Std(chaospy.variable(), chaospy_distribution)) == pytest.approx(std, rel=1e-4)
    standard, location, scale = distribution.standardized()
    standard_mean = float(chaospy.E(chaospy.variable(), standard))
    assert location + scale * standard_mean == pytest.approx(mean, abs=1e-9 + 1e-6 * abs(mean))
    assert scale * float(chaospy.Std(chaospy.variable(), standard)) == pytest.approx(std, rel=1e-4)
    values = ParameterSpace({"p": distribution}).sample(20000, "latin_hypercube", seed=11)["p"].values
    assert values.mean() == pytest.approx(mean, abs=0.02 * std)
    assert values.std() == pytest.approx(std, rel=0.03)
    assert set(DISTRIBUTION_NAMES) >= {"normal", "uniform", "lognormal", "beta", "truncnormal", "triangle"}


def test_parameter_space_parses_plain_specifications():
    space = ParameterSpace({
        "adhesion_torque": {"adhesion_coefficient": [0.15, 0.33], "axle_load": 23000, "wheel_radius": 0.625},
        "mesh_stiffness_scale": {"distribution": "normal", "mu": 1.0, "sigma": 0.05},
        "backlash": {"interval": [2e-4, 4e-4], "units": "m"},
        "drive_torque": 7000.0,
        "zeta_mesh": {"fixed": 0.05, "units": "1"},
    })
    assert space.interval_names == ("adhesion_torque", "backlash")
    assert space.random_names == ("mesh_stiffness_scale",)
    assert space.fixed_names == ("drive_torque", "zeta_mesh")
    assert space.units("adhesion_torque") == "N m"
    assert space.nominal("backlash") == pytest.approx(3e-4)
    assert space.nominal("mesh_stiffness_scale") == pytest.approx(1.0)
    assert space["drive_torque"] == Fixed(7000.0)
    assert ParameterSpace(space.to_dict()) == space


@pytest.mark.parametrize(("spec", "message"), [
    ({"x": {"interval": [0, 1], "fixed": 2}}, r"x: expected exactly one of the keys"),
    ({"x": {"interval": [0, 1], "unit": "m"}}, r"x: unknown key\(s\) unit for a interval parameter"),
    ({"x": {"adhesion_coefficient": [0.1, 0.2], "axle_load": 1000}}, r"x: adhesion_coefficient needs wheel_radius"),
    ({"x": "wide"}, r"x: expected Interval, Distribution, Fixed, a number"),
    ({"x": True}, r"x: expected a number, \[lower, upper\] or a mapping; got True"),
    ({"2x": 1.0}, r"parameter name '2x': expected an identifier"),
    ({}, r"parameter space: expected a non-empty mapping"),
])
def test_parameter_space_rejects_bad_specifications(spec, message):
    with pytest.raises(ParameterSpaceError, match=message):
        ParameterSpace(spec)


def test_unknown_parameter_lookup_lists_known():
    space = ParameterSpace({"a": [0, 1]})
    with pytest.raises(ParameterSpaceError, match=r"parameter 'b': not in the parameter space; known: a"):
        space["b"]


# ---------------------------------------------------------------------------
# sampling
# ---------------------------------------------------------------------------

def mixed_space() -> ParameterSpace:
    return ParameterSpace({"adhesion_torque": Interval(2.0e4, 4.0e4, "N m"),
                           "mesh_stiffness_scale": Distribution("normal", mu=1.0, sigma=0.05),
                           "pinion_speed": Fixed(3000.0, "rpm")})


@pytest.mark.parametrize("method", [m for m in SAMPLING_METHODS if m != "grid"])
def test_sampling_methods_cover_the_space_and_record_the_seed(method):
    samples = mixed_space().sample(256, method, seed=np.random.SeedSequence(42), interval_treatment="uniform")
    torque = samples["adhesion_torque"].values
    assert samples.sizes["sample"] == 256
    assert torque.min() >= 2.0e4 and torque.max() <= 4.0e4
    # uniform treatment of the interval: mean near the midpoint (1/sqrt(12 n) standard error)
    assert torque.mean() == pytest.approx(3.0e4, abs=4 * 2.0e4 / math.sqrt(12 * 256))
    assert np.all(samples["pinion_speed"].values == 3000.0)
    assert samples.attrs["seed_entropy"] == "42"
    assert "uniform" in samples.attrs["interval_treatment"]
    assert samples["adhesion_torque"].attrs["units"] == "N m"
    assert samples["adhesion_torque"].attrs["kind"] == "interval"


def test_latin_hypercube_stratifies_every_parameter():
    samples = mixed_space().sample(50, "latin_hypercube", seed=3, interval_treatment="uniform")
    unit = (samples["adhesion_torque"].values - 2.0e4) / 2.0e4
    assert np.array_equal(np.sort(np.floor(unit * 50)), np.arange(50))
    probabilities = stats.norm(1.0, 0.05).cdf(samples["mesh_stiffness_scale"].values)
    assert np.array_equal(np.sort(np.floor(probabilities * 50)), np.arange(50))


def test_grid_sampling_includes_interval_bounds():
    samples = ParameterSpace({"a": Interval(0.0, 2.0), "b": Interval(-1.0, 1.0)}).sample(
        3, "grid", interval_treatment="uniform")
    assert samples.sizes["sample"] == 9
    assert sorted(set(samples["a"].values)) == [0.0, 1.0, 2.0]
    assert samples.attrs["seed_entropy"].startswith("none")


def test_same_seed_same_samples_and_different_seed_different():
    space = mixed_space()
    first = space.sample(64, "sobol", seed=7, interval_treatment="uniform")
    again = space.sample(64, "sobol", seed=np.random.SeedSequence(7), interval_treatment="uniform")
    other = space.sample(64, "sobol", seed=8, interval_treatment="uniform")
    xr.testing.assert_identical(first, again)
    assert not np.allclose(first["adhesion_torque"].values, other["adhesion_torque"].values)


def test_intervals_are_not_sampled_unless_asked():
    space = mixed_space()
    with pytest.raises(ParameterSpaceError, match=r"adhesion_torque: an interval implies no distribution; "
                                                  r"pass interval_treatment='uniform'"):
        space.sample(10, "monte_carlo", seed=1)
    excluded = space.sample(10, "monte_carlo", seed=1, interval_treatment="exclude")
    assert "adhesion_torque" not in excluded and "mesh_stiffness_scale" in excluded
    assert excluded.attrs["interval_treatment"].startswith("excluded")


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"n": 100, "method": "sobol", "seed": 1}, r"n: the 'sobol' sampling method needs a power of 2; got 100"),
    ({"n": 0, "method": "monte_carlo", "seed": 1}, r"n: expected an integer >= 1; got 0"),
    ({"n": 10, "method": "random", "seed": 1}, r"method: unknown sampling method 'random'; expected one of "
                                               r"monte_carlo, latin_hypercube"),
    ({"n": 10, "method": "halton"}, r"seed: the 'halton' sampling method is random; pass seed="),
    ({"n": 10, "method": "halton", "seed": -3}, r"seed: expected a non-negative integer or a numpy SeedSequence"),
    ({"n": 10, "method": "halton", "seed": 1, "interval_treatment": "midpoint"}, r"interval_treatment: expected"),
])
def test_sampling_rejects_bad_settings(kwargs, message):
    space = ParameterSpace({"a": Distribution("normal", mu=0.0, sigma=1.0), "b": Interval(0.0, 1.0)})
    kwargs.setdefault("interval_treatment", "uniform")
    with pytest.raises(ParameterSpaceError, match=message):
        space.sample(**kwargs)


def test_seed_sequence_from_integer_is_the_same_stream():
    assert as_seed_sequence(5).entropy == np.random.SeedSequence(5).entropy
    with pytest.raises(ParameterSpaceError, match="seed: expected"):
        as_seed_sequence("five")


# ---------------------------------------------------------------------------
# running the model
# ---------------------------------------------------------------------------

def test_evaluate_on_sweep_runs_one_batch_with_the_sweep_values():
    calls = []

    def model(samples: xr.Dataset) -> xr.Dataset:
        calls.append(samples.sizes["sample"])
        return xr.Dataset({"load": ("sample", samples["adhesion_torque"].values * samples["pinion_speed"].values,
                                    {"units": "N m rpm"})})

    samples = ParameterSpace({"adhesion_torque": Interval(1.0, 2.0)}).sample(
        4, "grid", interval_treatment="uniform")
    outputs = evaluate_on_sweep(model, samples, {"pinion_speed": xr.DataArray([10.0, 20.0, 30.0],
                                                                              attrs={"units": "rpm"})})
    assert calls == [12]
    assert outputs["load"].dims == ("pinion_speed", "sample")
    expected = np.outer([10.0, 20.0, 30.0], samples["adhesion_torque"].values)
    np.testing.assert_allclose(outputs["load"].values, expected)
    assert outputs["pinion_speed"].attrs["units"] == "rpm"
    assert outputs["load"].attrs["units"] == "N m rpm"


@pytest.mark.parametrize(("model", "qoi", "message"), [
    (lambda s: {"y": s["a"].values}, None, r"model function: expected an xarray.Dataset .* got dict"),
    (lambda s: xr.Dataset({"y": ("sample", np.ones(3))}), None, r"expected dimension 'sample' of length 5"),
    (lambda s: xr.Dataset({"y": ("sample", s["a"].values)}), ["dte_rms"],
     r"qoi 'dte_rms': not returned by the model function; it returned y"),
])
def test_call_model_reports_a_bad_model_function(model, qoi, message):
    batch = xr.Dataset({"a": ("sample", np.arange(5.0))})
    with pytest.raises(ExecutionError, match=message):
        call_model(model, batch, qoi)


def test_sweep_must_not_override_an_uncertain_parameter():
    samples = xr.Dataset({"a": ("sample", np.arange(3.0))})
    with pytest.raises(ParameterSpaceError, match=r"sweep pinion_speed: expected a non-empty 1-D sequence"):
        evaluate_on_sweep(lambda s: s, samples, {"pinion_speed": [[1.0, 2.0]]})
    from uqgear.uq.sweeps import make_sweep
    with pytest.raises(ParameterSpaceError, match=r"sweep a: a is an uncertain parameter"):
        make_sweep({"a": [1.0]}, ParameterSpace({"a": [0, 1]}))


# ---------------------------------------------------------------------------
# Monte Carlo statistics
# ---------------------------------------------------------------------------

def test_monte_carlo_statistics_match_the_normal_distribution(tmp_path):
    space = ParameterSpace({"x": Distribution("normal", mu=2.0, sigma=0.5, units="m")})
    samples = space.sample(20000, "latin_hypercube", seed=1)
    outputs = xr.Dataset({"y": ("sample", samples["x"].values, {"units": "m"})}, attrs=samples.attrs)
    outputs["y"][:3] = np.nan  # failed runs are left out and counted
    result = monte_carlo_statistics(outputs, quantiles=[0.05, 0.5, 0.95])
    assert result["y"].sel(statistic="mean") == pytest.approx(2.0, abs=1e-3)
    assert result["y"].sel(statistic="std") == pytest.approx(0.5, rel=5e-3)
    np.testing.assert_allclose(result["y_quantile"].values, stats.norm(2.0, 0.5).ppf([0.05, 0.5, 0.95]), atol=5e-3)
    assert int(result["y_count"]) == 19997
    assert result["y"].attrs["units"] == "m"
    assert result.attrs["seed_entropy"] == "1"
    round_trip(result, tmp_path)


def test_monte_carlo_statistics_reject_bad_input():
    outputs = xr.Dataset({"y": ("sample", np.arange(4.0))})
    with pytest.raises(ParameterSpaceError, match=r"quantiles: expected a sequence of numbers in \[0, 1\]"):
        monte_carlo_statistics(outputs, quantiles=[0.5, 1.5])
    with pytest.raises(ParameterSpaceError, match=r"outputs: no variable has the dimension 'run'"):
        monte_carlo_statistics(outputs, dim="run")


def test_samples_round_trip_through_netcdf(tmp_path):
    round_trip(mixed_space().sample(16, "sobol", seed=2, interval_treatment="uniform"), tmp_path)


# ---------------------------------------------------------------------------
# polynomial chaos
# ---------------------------------------------------------------------------

def smooth_model(samples: xr.Dataset) -> xr.Dataset:
    z, u = samples["z"].values, samples["u"].values
    return xr.Dataset({"y": ("sample", np.exp(0.3 * z) + u ** 2 + 0.5 * z * u, {"units": "N"})})


def smooth_space() -> ParameterSpace:
    return ParameterSpace({"z": Distribution("normal", mu=0.0, sigma=1.0),
                           "u": Distribution("uniform", lower=-1.0, upper=1.0), "unused": 4.0})


def test_pce_moments_match_monte_carlo_and_closed_form(tmp_path):
    pce = PolynomialChaos(max_order=6, seed=4).fit(smooth_model, smooth_space())
    # E[exp(0.3 z)] = exp(0.045); E[u^2] = 1/3; the cross term has mean 0
    mean = math.exp(0.045) + 1.0 / 3.0
    variance = (math.exp(0.18) - math.exp(0.09)) + (1.0 / 5.0 - 1.0 / 9.0) + 0.25 / 3.0
    result = pce.result_
    assert float(result["y"].sel(statistic="mean")) == pytest.approx(mean, rel=1e-4)
    assert float(result["y"].sel(statistic="variance")) == pytest.approx(variance, rel=1e-3)
    samples = smooth_space().sample(40000, "latin_hypercube", seed=9)
    monte_carlo = monte_carlo_statistics(smooth_model(samples), quantiles=[0.05, 0.5, 0.95])
    assert float(result["y"].sel(statistic="mean")) == pytest.approx(
        float(monte_carlo["y"].sel(statistic="mean")),
        abs=3 * float(monte_carlo["y"].sel(statistic="mean_standard_error")),
    )
    assert float(result["y"].sel(statistic="std")) == pytest.approx(float(monte_carlo["y"].sel(statistic="std")),
                                                                     rel=0.01)
    np.testing.assert_allclose(result["y_quantile"].values, monte_carlo["y_quantile"].values, rtol=0.02)
    assert int(result["y_order"]) >= 4
    assert result.attrs["n_samples"] == 2 * number_of_terms(2, 6)
    round_trip(result, tmp_path)


def test_pce_sobol_indices_match_analytic_ishigami():
    result = PolynomialChaos(max_order=10, seed=1).fit(ishigami, ishigami_space()).result_
    np.testing.assert_allclose(result["y_sobol"].sel(index="S1").values, ISHIGAMI_S1, atol=0.01)
    np.testing.assert_allclose(result["y_sobol"].sel(index="ST").values, ISHIGAMI_ST, atol=0.01)
    assert float(result["y"].sel(statistic="mean")) == pytest.approx(ISHIGAMI_MEAN, abs=0.02)
    assert float(result["y"].sel(statistic="variance")) == pytest.approx(ISHIGAMI_VARIANCE, rel=0.01)
    loo = result["y_loo_error"].values
    assert loo[-1] < 1e-3 < loo[0]  # the LOO error falls with the order on this function
    assert int(result["y_order"]) == int(result["order"][np.nanargmin(loo)])


def test_pce_sobol_from_coefficients_equals_chaospy_sens():
    space = ParameterSpace({"a": Distribution("normal", mu=1.0, sigma=0.3), "b": Interval(0.0, 2.0)})

    def model(samples: xr.Dataset) -> xr.Dataset:
        a, b = samples["a"].values, samples["b"].values
        return xr.Dataset({"y": ("sample", a ** 2 * b + np.sin(b) + a, {"units": "1"})})

    pce = PolynomialChaos(max_order=3, min_order=3, n_samples=60, seed=5).fit(model, space)
    joint = chaospy.J(chaospy.Normal(1.0, 0.3), chaospy.Uniform(0.0, 2.0))
    expansion = chaospy.generate_expansion(3, joint, normed=True)
    nodes = np.stack([pce.samples_["a"].values, pce.samples_["b"].values])
    polynomial = chaospy.fit_regression(expansion, nodes, pce.outputs_["y"].values)
    sobol = pce.result_["y_sobol"]
    np.testing.assert_allclose(sobol.sel(index="S1").values, chaospy.Sens_m(polynomial, joint), rtol=1e-6)
    np.testing.assert_allclose(sobol.sel(index="ST").values, chaospy.Sens_t(polynomial, joint), rtol=1e-6)
    assert float(pce.result_["y"].sel(statistic="mean")) == pytest.approx(float(chaospy.E(polynomial, joint)))
    assert "uniform" in pce.result_.attrs["interval_treatment"]


def test_pce_leave_one_out_finds_the_exact_order_and_predicts():
    space = ParameterSpace({"a": Distribution("uniform", lower=-1.0, upper=2.0),
                            "b": Distribution("normal", mu=0.0, sigma=1.0)})

    def cubic(samples: xr.Dataset) -> xr.Dataset:
        a, b = samples["a"].values, samples["b"].values
        return xr.Dataset({"y": ("sample", a ** 3 - 2 * a * b + b ** 2 + 1.0)})

    pce = PolynomialChaos(max_order=5, seed=6).fit(cubic, space)
    loo = pce.result_["y_loo_error"]
    assert float(loo.sel(order=2)) > 1e-3
    assert float(loo.sel(order=3)) < 1e-20
    assert int(pce.result_["y_order"]) >= 3
    new = space.sample(50, "monte_carlo", seed=99)
    np.testing.assert_allclose(pce.predict(new)["y"].values, cubic(new)["y"].values, rtol=1e-8, atol=1e-8)


def test_pce_quantiles_of_a_linear_model_match_the_normal_quantiles():
    space = ParameterSpace({"x": Distribution("normal", mu=3.0, sigma=2.0)})
    result = PolynomialChaos(max_order=2, quantiles=[0.1, 0.9], surrogate_samples=40000, seed=8).fit(
        lambda s: xr.Dataset({"y": ("sample", s["x"].values)}), space).result_
    np.testing.assert_allclose(result["y_quantile"].values, stats.norm(3.0, 2.0).ppf([0.1, 0.9]), atol=0.05)


def test_pce_along_a_sweep_and_reproducible():
    def model(samples: xr.Dataset) -> xr.Dataset:
        return xr.Dataset({"y": ("sample", samples["speed"].values * samples["u"].values)})

    space = ParameterSpace({"u": Interval(0.0, 1.0)})
    first = PolynomialChaos(max_order=2, seed=3).fit(model, space, sweep={"speed": [1.0, 2.0, 4.0]}).result_
    again = PolynomialChaos(max_order=2, seed=np.random.SeedSequence(3)).fit(
        model, space, sweep={"speed": [1.0, 2.0, 4.0]}).result_
    xr.testing.assert_identical(first, again)
    np.testing.assert_allclose(first["y"].sel(statistic="mean").values, [0.5, 1.0, 2.0], rtol=1e-10)
    np.testing.assert_allclose(first["y"].sel(statistic="std").values, np.array([1, 2, 4]) / math.sqrt(12),
                               rtol=1e-10)
    assert first["y"].dims == ("speed", "statistic")


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"max_order": 3, "min_order": 4, "seed": 1}, r"min_order: expected <= max_order=3; got 4"),
    ({"max_order": 0, "seed": 1}, r"max_order: expected an integer >= 1"),
    ({"max_order": 2}, r"seed: PolynomialChaos draws random samples; pass seed="),
    ({"max_order": 2, "sampling": "grid", "seed": 1}, r"sampling: expected one of"),
    ({"max_order": 2, "oversampling": 0.5, "seed": 1}, r"oversampling: expected a number >= 1"),
])
def test_pce_rejects_bad_settings(kwargs, message):
    with pytest.raises(ParameterSpaceError, match=message):
        PolynomialChaos(**kwargs)


def test_pce_rejects_too_few_samples_and_fixed_only_spaces():
    with pytest.raises(ParameterSpaceError, match=r"n_samples: 4 samples cannot fit order 2"):
        PolynomialChaos(max_order=3, min_order=2, n_samples=4, seed=1).fit(smooth_model, smooth_space())
    with pytest.raises(ParameterSpaceError, match=r"space: polynomial chaos needs at least one interval or random"):
        PolynomialChaos(max_order=2, seed=1).fit(smooth_model, ParameterSpace({"z": 1.0}))


def test_total_degree_indices_are_graded_and_complete():
    indices = total_degree_indices(3, 4)
    assert indices.shape == (number_of_terms(3, 4), 3) == (35, 3)
    assert np.all(np.diff(indices.sum(axis=1)) >= 0)
    assert len({tuple(row) for row in indices}) == 35


def test_pce_leave_one_out_error_equals_brute_force_refits():
    space = ParameterSpace({"a": Distribution("normal", mu=0.0, sigma=1.0), "b": Interval(-1.0, 1.0)})

    def model(samples: xr.Dataset) -> xr.Dataset:
        a, b = samples["a"].values, samples["b"].values
        return xr.Dataset({"y": ("sample", np.exp(0.5 * a) * np.sin(2.0 * b))})

    pce = PolynomialChaos(max_order=2, min_order=2, n_samples=25, seed=2).fit(model, space)
    nodes = np.stack([pce.samples_["a"].values, pce.samples_["b"].values])
    y = pce.outputs_["y"].values
    joint = chaospy.J(chaospy.Normal(0.0, 1.0), chaospy.Uniform(-1.0, 1.0))
    expansion = chaospy.generate_expansion(2, joint, normed=True)
    residuals = []
    for left_out in range(y.size):
        keep = np.arange(y.size) != left_out
        polynomial = chaospy.fit_regression(expansion, nodes[:, keep], y[keep])
        residuals.append(y[left_out] - polynomial(*nodes[:, left_out]))
    brute_force = np.mean(np.square(residuals)) / np.var(y)
    assert float(pce.result_["y_loo_error"].sel(order=2)) == pytest.approx(brute_force, rel=1e-8)


def test_parameter_space_pickles_for_distributed_workers():
    import pickle

    space = mixed_space()
    assert pickle.loads(pickle.dumps(space)) == space
    assert pickle.loads(pickle.dumps(space["mesh_stiffness_scale"])).params["sigma"] == 0.05
