"""Sobol indices through SALib."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import xarray as xr

from uqgear.common.errors import ParameterSpaceError
from uqgear.uq.parameter_space import ParameterSpace
from uqgear.uq.parameters import Distribution, Interval
from uqgear.uq.sensitivity import SobolAnalysis
from uqgear.uq.sweeps import evaluate_on_sweep

ISHIGAMI_S1 = np.array([0.3139, 0.4424, 0.0])
ISHIGAMI_ST = np.array([0.5576, 0.4424, 0.2437])
# S13 = V13 / V (the only non-zero interaction of the Ishigami function)
ISHIGAMI_S13 = 0.2437


def ishigami(samples: xr.Dataset) -> xr.Dataset:
    x1, x2, x3 = (samples[name].values for name in ("x1", "x2", "x3"))
    y = np.sin(x1) + 7.0 * np.sin(x2) ** 2 + 0.1 * x3 ** 4 * np.sin(x1)
    return xr.Dataset({"y": ("sample", y, {"units": "m"})})


def ishigami_space() -> ParameterSpace:
    # two intervals (uniform assumed for the indices) and one uniform random parameter
    return ParameterSpace({"x1": Interval(-math.pi, math.pi),
                           "x2": Distribution("uniform", lower=-math.pi, upper=math.pi),
                           "x3": Interval(-math.pi, math.pi), "offset": 0.0})


def round_trip(dataset: xr.Dataset, tmp_path) -> None:
    path = tmp_path / "result.nc"
    dataset.to_netcdf(path)
    with xr.open_dataset(path) as reloaded:
        xr.testing.assert_identical(reloaded.load(), dataset)


def test_ishigami_indices_within_their_confidence_intervals(tmp_path):
    result = SobolAnalysis(n_base=1024, seed=0).fit(ishigami, ishigami_space()).result_
    estimate = result["y"].transpose("param", "index").values
    confidence = result["y_conf"].transpose("param", "index").values
    analytic = np.stack([ISHIGAMI_S1, ISHIGAMI_ST], axis=-1)
    assert np.all(np.abs(estimate - analytic) <= confidence)
    assert np.all(confidence < 0.1)  # the intervals are informative, not vacuous
    assert list(result["param"].values) == ["x1", "x2", "x3"]
    assert list(result["index"].values) == ["S1", "ST"]
    assumed = json.loads(result.attrs["distribution_assumed"])
    assert assumed["x1"].startswith("uniform on interval") and "implies no distribution" in assumed["x1"]
    assert assumed["x2"].startswith("uniform(")
    assert result.attrs["runs"] == 1024 * (3 + 2)
    round_trip(result, tmp_path)


def test_second_order_ishigami_interaction():
    analysis = SobolAnalysis(n_base=2048, second_order=True, seed=3)
    samples = analysis.sample(ishigami_space())
    assert samples.sizes["sample"] == 2048 * (2 * 3 + 2)
    result = analysis.analyze(samples, ishigami(samples))
    s2 = result["y_S2"]
    conf = result["y_S2_conf"]
    assert abs(float(s2.sel(param="x1", param_2="x3")) - ISHIGAMI_S13) <= float(conf.sel(param="x1", param_2="x3"))
    assert abs(float(s2.sel(param="x1", param_2="x2"))) <= float(conf.sel(param="x1", param_2="x2"))
    assert abs(float(s2.sel(param="x2", param_2="x3"))) <= float(conf.sel(param="x2", param_2="x3"))


def test_indices_along_a_sweep_match_the_linear_closed_form():
    # y = w a + b with a, b uniform on [0, 1]: S_a = w^2 / (w^2 + 1), no interactions
    def model(samples: xr.Dataset) -> xr.Dataset:
        return xr.Dataset({"y": ("sample", samples["pinion_speed"].values * samples["a"].values
                                 + samples["b"].values)})

    calls = []

    def counted(samples: xr.Dataset) -> xr.Dataset:
        calls.append(samples.sizes["sample"])
        return model(samples)

    speeds = np.array([0.5, 1.0, 3.0])
    space = ParameterSpace({"a": Interval(0.0, 1.0), "b": Interval(0.0, 1.0)})
    result = SobolAnalysis(n_base=512, seed=5).fit(counted, space, sweep={"pinion_speed": speeds}).result_
    assert calls == [3 * 512 * 4]
    assert result["y"].dims == ("pinion_speed", "param", "index")
    expected = speeds ** 2 / (speeds ** 2 + 1.0)
    for index in ("S1", "ST"):
        np.testing.assert_allclose(result["y"].sel(param="a", index=index).values, expected, atol=0.02)
        np.testing.assert_allclose(result["y"].sel(param="b", index=index).values, 1.0 - expected, atol=0.02)


def test_parameter_subset_holds_the_others_at_nominal():
    space = ParameterSpace({"a": Interval(0.0, 2.0), "b": Distribution("normal", mu=5.0, sigma=1.0)})
    analysis = SobolAnalysis(n_base=64, parameters=["a"], seed=1)
    samples = analysis.sample(space)
    assert samples.sizes["sample"] == 64 * 3
    np.testing.assert_allclose(samples["b"].values, 5.0)
    assert json.loads(samples.attrs["held_at_nominal"]) == {"b": pytest.approx(5.0)}
    result = analysis.analyze(samples, xr.Dataset({"y": ("sample", samples["a"].values ** 2)}))
    assert list(result["param"].values) == ["a"]
    assert float(result["y"].sel(param="a", index="ST")) == pytest.approx(1.0, abs=0.05)


def test_same_seed_same_numbers_different_seed_different():
    first = SobolAnalysis(n_base=256, seed=11).fit(ishigami, ishigami_space()).result_
    again = SobolAnalysis(n_base=256, seed=np.random.SeedSequence(11)).fit(ishigami, ishigami_space()).result_
    other = SobolAnalysis(n_base=256, seed=12).fit(ishigami, ishigami_space()).result_
    xr.testing.assert_identical(first, again)
    assert not np.allclose(first["y"].values, other["y"].values)


def test_constant_output_gives_undefined_indices():
    analysis = SobolAnalysis(n_base=32, seed=1)
    samples = analysis.sample(ParameterSpace({"a": Interval(0.0, 1.0), "b": Interval(0.0, 1.0)}))
    result = analysis.analyze(samples, xr.Dataset({"y": ("sample", np.ones(samples.sizes["sample"]))}))
    assert np.all(np.isnan(result["y"].values))


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"n_base": 1000, "seed": 1}, r"n_base: the Sobol sequence needs a power of 2; got 1000 \(try 512 or 1024\)"),
    ({"n_base": 4, "seed": 1}, r"n_base: expected an integer >= 8; got 4"),
    ({"n_base": 64}, r"seed: the Sobol design is scrambled"),
    ({"n_base": 64, "seed": 1, "conf_level": 1.5}, r"conf_level: expected a number in \(0, 1\); got 1.5"),
    ({"n_base": 64, "seed": 1, "num_resamples": 0}, r"num_resamples: expected an integer >= 2"),
    ({"n_base": 64, "seed": 1, "parameters": "a"}, r"parameters: expected a list of parameter names"),
])
def test_sobol_rejects_bad_settings(kwargs, message):
    with pytest.raises(ParameterSpaceError, match=message):
        SobolAnalysis(**kwargs)


def test_sobol_rejects_bad_parameters_and_outputs():
    space = ParameterSpace({"a": Interval(0.0, 1.0), "c": 2.0})
    with pytest.raises(ParameterSpaceError, match=r"parameters: 'c' is not an interval or random parameter"):
        SobolAnalysis(n_base=16, parameters=["a", "c"], seed=1).sample(space)
    with pytest.raises(ParameterSpaceError, match=r"second_order: needs at least two analysed parameters"):
        SobolAnalysis(n_base=16, second_order=True, seed=1).sample(space)
    analysis = SobolAnalysis(n_base=16, seed=1)
    samples = analysis.sample(space)
    with pytest.raises(ParameterSpaceError, match=r"outputs: expected an xarray.Dataset with dimension 'sample' "
                                                  r"of length 48"):
        analysis.analyze(samples, xr.Dataset({"y": ("sample", np.ones(40))}))
    with pytest.raises(ParameterSpaceError, match=r"samples: expected the Dataset returned by SobolAnalysis.sample"):
        analysis.analyze(xr.Dataset({"a": ("sample", np.ones(48))}), xr.Dataset({"y": ("sample", np.ones(48))}))
    with pytest.raises(ParameterSpaceError, match=r"second_order: the samples were drawn with second_order=False"):
        SobolAnalysis(n_base=16, second_order=True, seed=1).analyze(samples, evaluate_on_sweep(
            lambda s: xr.Dataset({"y": ("sample", s["a"].values)}), samples))
