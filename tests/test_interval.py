"""Interval analysis: scan, vertex, Chebyshev inclusion, optimisation and p-boxes."""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr
from numpy.polynomial import chebyshev as cheb
from scipy import stats

from uqgear.common.errors import ExecutionError, ParameterSpaceError
from uqgear.uq.chebyshev import chebyshev_coefficients, chebyshev_nodes
from uqgear.uq.interval import IntervalAnalysis
from uqgear.uq.interval_bounds import (
    FLAG_FALLBACK,
    FLAG_NONFINITE,
    FLAG_NONSMOOTH,
    FLAG_SURROGATE_ERROR,
    FLAG_VERTEX_EXCEEDED,
)
from uqgear.uq.parameter_space import ParameterSpace
from uqgear.uq.parameters import Distribution, Fixed, Interval
from uqgear.uq.pbox import pbox, response_envelope


class CountingModel:
    """Wraps a function of named parameter arrays; counts batch calls and runs."""

    def __init__(self, function, **units):
        self.function = function
        self.units = units
        self.calls: list[int] = []

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        self.calls.append(samples.sizes["sample"])
        values = {name: samples[name].values for name in samples.data_vars}
        outputs = self.function(**values)
        return xr.Dataset({name: ("sample", value, {"units": self.units.get(name, "")})
                           for name, value in outputs.items()})


def smooth_1d(x, **_):
    return {"y": np.exp(0.8 * x) * np.cos(2.0 * x)}


def dense_truth(function, lower, upper, points=200001):
    grid = np.linspace(lower, upper, points)
    values = function(grid)
    return values.min(), values.max()


def round_trip(dataset: xr.Dataset, tmp_path) -> None:
    path = tmp_path / "result.nc"
    dataset.to_netcdf(path)
    with xr.open_dataset(path) as reloaded:
        xr.testing.assert_identical(reloaded.load(), dataset)


# ---------------------------------------------------------------------------
# Chebyshev inclusion
# ---------------------------------------------------------------------------

def test_chebyshev_bounds_within_one_percent_with_eleven_runs(tmp_path):
    model = CountingModel(smooth_1d, y="m")
    space = ParameterSpace({"x": Interval(-1.0, 1.5)})
    result = IntervalAnalysis("chebyshev", order=7, check_points=3).fit(model, space).result_
    lower, upper = dense_truth(lambda x: np.exp(0.8 * x) * np.cos(2.0 * x), -1.0, 1.5)
    width = upper - lower
    assert int(result["runs"]) == 11 and model.calls == [11]
    assert abs(float(result["y"].sel(bound="lower")) - lower) < 0.01 * width
    assert abs(float(result["y"].sel(bound="upper")) - upper) < 0.01 * width
    assert int(result["flag"].sel(qoi="y")) == 0
    # the error estimate is honest: at least the actual error of the reported bounds
    actual = max(abs(float(result["y"].sel(bound="lower")) - lower), abs(float(result["y"].sel(bound="upper")) - upper))
    assert float(result["y_surrogate_error"]) >= actual
    assert result["y"].attrs["units"] == "m"
    assert result.attrs["method"] == "chebyshev" and result.attrs["order"] == 7
    round_trip(result, tmp_path)


def test_chebyshev_order_ten_at_eleven_gauss_chebyshev_nodes():
    model = CountingModel(smooth_1d)
    result = IntervalAnalysis("chebyshev", order=10, check_points=0).fit(
        model, ParameterSpace({"x": Interval(-1.0, 1.5)})).result_
    lower, upper = dense_truth(lambda x: np.exp(0.8 * x) * np.cos(2.0 * x), -1.0, 1.5)
    assert model.calls == [11]
    np.testing.assert_allclose(result["y"].values, [lower, upper], atol=1e-4 * (upper - lower))


def test_chebyshev_coefficients_reproduce_a_polynomial_exactly():
    # a degree-5 polynomial is its own order-5 Chebyshev series
    coefficients = np.array([0.3, -1.0, 0.5, 0.25, 0.0, 0.125])
    nodes = chebyshev_nodes(6)
    np.testing.assert_allclose(np.polynomial.chebyshev.chebval(nodes, coefficients),
                               cheb.chebval(nodes, coefficients))
    fitted = chebyshev_coefficients(cheb.chebval(nodes, coefficients), 1)
    np.testing.assert_allclose(fitted, coefficients, atol=1e-13)
    # tensor form: c[i, j] T_i(x) T_j(y)
    tensor = np.outer(coefficients[:4], coefficients[2:])
    x, y = np.meshgrid(chebyshev_nodes(4), chebyshev_nodes(4), indexing="ij")
    np.testing.assert_allclose(chebyshev_coefficients(cheb.chebval2d(x, y, tensor), 2), tensor, atol=1e-13)
    np.testing.assert_allclose(np.sort(np.cos(np.pi * (np.arange(6) + 0.5) / 6)), nodes)


def test_chebyshev_flags_a_jump_and_falls_back_to_scan():
    def stepped(x, **_):
        return {"y": np.where(x > 0.37, 1.0, 0.0) + 0.2 * x}

    model = CountingModel(stepped)
    result = IntervalAnalysis("chebyshev", order=6).fit(model, ParameterSpace({"x": Interval(0.0, 1.0)})).result_
    flag = int(result["flag"].sel(qoi="y"))
    assert flag & FLAG_NONSMOOTH and flag & FLAG_FALLBACK
    reasons = json.loads(result["flag"].attrs["flag_reasons"])
    assert "jump between neighbouring Chebyshev nodes" in reasons[0]
    np.testing.assert_allclose(result["y"].values, [0.0, 1.2], atol=1e-12)
    assert len(model.calls) == 2  # nodes + check points, then the scan fallback
    assert int(result["runs"]) == 7 + 4 + 101


def test_chebyshev_with_a_regime_variable_flags_contact_loss():
    def model_function(x, **_):
        # smooth QoI, but the teeth separate (contact loss) for x > 0.8
        return {"y": x ** 2, "separation_fraction": np.clip(x - 0.8, 0.0, None)}

    result = IntervalAnalysis("chebyshev", order=4, regime_variables=["separation_fraction"]).fit(
        CountingModel(model_function), ParameterSpace({"x": Interval(0.0, 1.0)})).result_
    assert list(result["qoi"].values) == ["y"]
    assert int(result["flag"].sel(qoi="y")) & FLAG_NONSMOOTH
    assert "regime variable(s) separation_fraction change" in result["flag"].attrs["flag_reasons"]


# ---------------------------------------------------------------------------
# vertex
# ---------------------------------------------------------------------------

def test_vertex_underestimates_a_non_monotone_function_and_says_so():
    space = ParameterSpace({"x": Interval(0.0, 2.0)})
    model = CountingModel(lambda x, **_: {"y": np.sin(5.0 * x)})
    result = IntervalAnalysis("vertex", fallback="none", check_points=2).fit(model, space).result_
    band = result["y"].values
    assert band[1] < 0.99 and band[0] > -0.99  # true band of sin(5x) on [0, 2] is [-1, 1]
    assert int(result["flag"].sel(qoi="y")) == FLAG_VERTEX_EXCEEDED
    assert "vertex bounds exceeded at interior check points: non-monotone response" in \
        result["flag"].attrs["flag_reasons"]
    assert int(result["runs"]) == 2 + 1 + 2
    fixed = IntervalAnalysis("vertex").fit(model, space).result_
    np.testing.assert_allclose(fixed["y"].values, [-1.0, 1.0], atol=1e-3)
    assert int(fixed["flag"].sel(qoi="y")) == FLAG_VERTEX_EXCEEDED | FLAG_FALLBACK


def test_vertex_is_exact_and_unflagged_for_a_monotone_function():
    space = ParameterSpace({"a": Interval(1.0, 2.0), "b": Interval(-1.0, 0.0), "c": Fixed(3.0)})
    model = CountingModel(lambda a, b, c, **_: {"y": c * a - np.exp(b)})
    result = IntervalAnalysis("vertex", check_points=3).fit(model, space).result_
    np.testing.assert_allclose(result["y"].values, [3.0 - 1.0, 6.0 - np.exp(-1.0)])
    assert int(result["flag"].sel(qoi="y")) == 0
    assert model.calls == [4 + 1 + 3]


# ---------------------------------------------------------------------------
# scan and optimisation, sweeps
# ---------------------------------------------------------------------------

def two_dimensional(a, b, **_):
    return {"y": np.sin(3.0 * a) * np.cos(2.0 * b) + 0.1 * a}


def two_dimensional_truth():
    a, b = np.meshgrid(np.linspace(-1.0, 1.0, 2001), np.linspace(0.0, 1.5, 1501), indexing="ij")
    values = two_dimensional(a, b)["y"]
    return values.min(), values.max()


def test_optimize_finds_the_bounds_of_a_two_dimensional_function(tmp_path):
    space = ParameterSpace({"a": Interval(-1.0, 1.0), "b": Interval(0.0, 1.5)})
    model = CountingModel(two_dimensional)
    result = IntervalAnalysis("optimize", n_starts=2, seed=12).fit(model, space).result_
    lower, upper = two_dimensional_truth()
    np.testing.assert_allclose(result["y"].values, [lower, upper], atol=1e-6)
    assert int(result["runs"]) == sum(model.calls)
    assert result.attrs["batch_calls"] == len(model.calls) < 60
    # the local searches run in lock-step: the rounds carry several searches each
    assert max(model.calls[1:]) > 3
    again = IntervalAnalysis("optimize", n_starts=2, seed=12).fit(CountingModel(two_dimensional), space).result_
    xr.testing.assert_identical(result, again)
    round_trip(result, tmp_path)


def test_scan_along_a_sweep_in_one_batch():
    speeds = xr.DataArray([1000.0, 2000.0, 3000.0], attrs={"units": "rpm"})
    model = CountingModel(lambda x, pinion_speed, **_: {"y": (x - pinion_speed / 2000.0) ** 2}, y="m^2")
    result = IntervalAnalysis("scan", scan_points=201).fit(
        model, ParameterSpace({"x": Interval(0.0, 1.0)}), sweep={"pinion_speed": speeds}).result_
    centre = speeds.values / 2000.0
    expected_lower = np.where(centre < 1.0, 0.0, (1.0 - centre) ** 2)
    expected_upper = np.maximum(centre ** 2, (1.0 - centre) ** 2)
    np.testing.assert_allclose(result["y"].sel(bound="lower").values, expected_lower, atol=1e-12)
    np.testing.assert_allclose(result["y"].sel(bound="upper").values, expected_upper, atol=1e-12)
    assert model.calls == [3 * 201]
    assert result["y"].dims == ("pinion_speed", "bound")
    assert result["pinion_speed"].attrs["units"] == "rpm"
    assert list(result["runs"].values) == [201, 201, 201]


def test_response_envelope_matches_the_analysis_and_batches_all_speeds(tmp_path):
    speeds = np.linspace(500.0, 4000.0, 8)

    def model_function(adhesion_torque, pinion_speed, **_):
        load = adhesion_torque / 4.0e4
        return {"dte_rms": 1e-6 * load * (1.0 + 0.5 * np.sin(pinion_speed / 700.0 + load))}

    space = ParameterSpace({"adhesion_torque": Interval.from_adhesion(0.15, 0.33, 23000.0, 0.625)})
    model = CountingModel(model_function, dte_rms="m")
    envelope = response_envelope(model, space, {"pinion_speed": speeds}, order=6)
    assert model.calls == [8 * (7 + 4)]
    torque = np.linspace(space["adhesion_torque"].lower, space["adhesion_torque"].upper, 20001)
    for speed, (low, high) in zip(speeds, envelope["dte_rms"].values):
        values = model_function(torque, speed)["dte_rms"]
        assert abs(low - values.min()) < 0.01 * (values.max() - values.min())
        assert abs(high - values.max()) < 0.01 * (values.max() - values.min())
    assert not envelope["flag"].values.any()
    round_trip(envelope, tmp_path)


def test_non_finite_model_values_are_flagged():
    model = CountingModel(lambda x, **_: {"y": np.where(x > 0.9, np.nan, x)})
    result = IntervalAnalysis("scan", scan_points=11).fit(model, ParameterSpace({"x": Interval(0.0, 1.0)})).result_
    assert int(result["flag"].sel(qoi="y")) & FLAG_NONFINITE
    assert "1 of 11 model values non-finite" in result["flag"].attrs["flag_reasons"]
    np.testing.assert_allclose(result["y"].values, [0.0, 0.9])


def test_coarse_scan_is_flagged():
    model = CountingModel(lambda x, **_: {"y": np.sin(6.0 * x)})
    result = IntervalAnalysis("scan", scan_points=5).fit(model, ParameterSpace({"x": Interval(0.0, 1.0)})).result_
    assert int(result["flag"].sel(qoi="y")) & FLAG_SURROGATE_ERROR
    assert "scan grid coarse" in result["flag"].attrs["flag_reasons"]


# ---------------------------------------------------------------------------
# p-box
# ---------------------------------------------------------------------------

def test_pbox_bounds_mean_and_quantiles_of_a_product(tmp_path):
    # y = t z with t in [1, 2] and z ~ normal(1, 0.1): mean in [1, 2], q_p in [q_p(z), 2 q_p(z)]
    space = ParameterSpace({"t": Interval(1.0, 2.0), "z": Distribution("normal", mu=1.0, sigma=0.1)})
    model = CountingModel(lambda t, z, **_: {"y": t * z}, y="N")
    result = pbox(model, space, n_samples=4000, seed=21, quantiles=[0.05, 0.95],
                  analysis=IntervalAnalysis("vertex"))
    mean = result["y"].sel(statistic="mean").values
    np.testing.assert_allclose(mean, [1.0, 2.0], atol=0.01)
    np.testing.assert_allclose(result["y"].sel(statistic="std").values, [0.1, 0.2], rtol=0.03)
    quantiles = stats.norm(1.0, 0.1).ppf([0.05, 0.95])
    np.testing.assert_allclose(result["y_quantile"].sel(bound="lower").values, quantiles, rtol=0.01)
    np.testing.assert_allclose(result["y_quantile"].sel(bound="upper").values, 2 * quantiles, rtol=0.01)
    assert len(model.calls) == 1 and int(result["runs"]) == (2 + 1 + 4) * 4000
    assert not result["flag"].values.any()
    assert result["y"].dims == ("statistic", "bound")
    round_trip(result, tmp_path)


def test_pbox_with_chebyshev_flags_a_kinked_statistic():
    # std of |t| z over z is 0.1 |t|: a kink at t = 0 that the series cannot follow
    space = ParameterSpace({"t": Interval(-1.0, 2.0), "z": Distribution("normal", mu=0.0, sigma=0.1)})
    result = pbox(CountingModel(lambda t, z, **_: {"y": t * z}), space, n_samples=200, seed=2,
                  analysis=IntervalAnalysis("chebyshev", order=5, tolerance=0.01))
    assert int(result["flag"].sel(qoi="y")) & FLAG_FALLBACK
    assert "y std" in result["flag"].attrs["flag_reasons"]
    assert float(result["y"].sel(statistic="std", bound="lower")) < 0.005


# ---------------------------------------------------------------------------
# bad input
# ---------------------------------------------------------------------------

@pytest.mark.parametrize(("kwargs", "message"), [
    ({"method": "bisection"}, r"method: unknown interval method 'bisection'; expected one of scan, vertex"),
    ({"fallback": "guess"}, r"fallback: expected one of scan, optimize, none; got 'guess'"),
    ({"order": 0}, r"order: expected an integer >= 1"),
    ({"tolerance": 2.0}, r"tolerance: expected a fraction of the band width in \(0, 1\); got 2.0"),
    ({"method": "optimize"}, r"seed: the optimize method draws seeded starting points; pass seed="),
    ({"fallback": "optimize"}, r"seed: the optimize method"),
    ({"scan_points": 1}, r"scan_points: expected an integer >= 2"),
    ({"qoi": ["y"], "regime_variables": ["y"]}, r"regime_variables: y also listed as qoi"),
])
def test_interval_analysis_rejects_bad_settings(kwargs, message):
    with pytest.raises(ParameterSpaceError, match=message):
        IntervalAnalysis(**kwargs)


def test_interval_analysis_rejects_bad_spaces_and_sweeps():
    model = CountingModel(lambda x, **_: {"y": x})
    analysis = IntervalAnalysis("scan")
    with pytest.raises(ParameterSpaceError, match=r"space: interval analysis needs at least one Interval"):
        analysis.fit(model, ParameterSpace({"x": 1.0}))
    with pytest.raises(ParameterSpaceError, match=r"space: z have distributions; .*use pbox\(\)"):
        analysis.fit(model, ParameterSpace({"x": [0, 1], "z": Distribution("normal", mu=0, sigma=1)}))
    with pytest.raises(ParameterSpaceError, match=r"sweep x: x is an uncertain parameter"):
        analysis.fit(model, ParameterSpace({"x": [0, 1]}), sweep={"x": [0.5]})
    with pytest.raises(ParameterSpaceError, match=r"sweep speed: values must be distinct"):
        analysis.fit(model, ParameterSpace({"x": [0, 1]}), sweep={"speed": [1.0, 1.0]})
    with pytest.raises(ExecutionError, match=r"qoi 'dte_rms': not returned by the model function"):
        IntervalAnalysis("scan", qoi=["dte_rms"]).fit(model, ParameterSpace({"x": [0, 1]}))
    with pytest.raises(ExecutionError, match=r"qoi 'contact': not returned"):
        IntervalAnalysis("scan", regime_variables=["contact"], qoi=["y"]).fit(model, ParameterSpace({"x": [0, 1]}))
    with pytest.raises(ParameterSpaceError, match=r"sweep: a response envelope needs a sweep"):
        response_envelope(model, ParameterSpace({"x": [0, 1]}), {})


def test_pbox_rejects_spaces_without_random_parameters():
    model = CountingModel(lambda x, **_: {"y": x})
    with pytest.raises(ParameterSpaceError, match=r"space: a p-box needs at least one random"):
        pbox(model, ParameterSpace({"x": [0, 1]}), n_samples=10, seed=1)
    with pytest.raises(ParameterSpaceError, match=r"n_samples: expected an integer >= 2; got 1"):
        pbox(model, ParameterSpace({"x": [0, 1], "z": Distribution("normal", mu=0, sigma=1)}), n_samples=1, seed=1)
