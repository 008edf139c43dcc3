"""Tests of signal features against synthetic signals with known truth and the bundled rig campaigns."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from uqgear.common.errors import DesignError, RigDataError, StudyError
from uqgear.rig.features import (
    FEATURE_FAMILIES,
    extract_features,
    feature_definitions,
    line_amplitudes,
    order_spectrum,
    sampling_rate,
)
from uqgear.rig.format import read_rig, rig_design

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"
FS = 20480.0
N_TIME = 20480
TIME = np.arange(N_TIME) / FS
SPEEDS = np.array([600.0, 2200.0])
NOISE = 0.01
# Line amplitudes at known orders (z1 = 21, z2 = 101, p = 3): gear sidebands at
# 600 rpm lie only 2.08 Hz (2 bins) from the mesh line, which a plain windowed
# DFT cannot separate; the joint fit must.
TRUTH = {"mesh1": 1.0, "mesh2": 0.4, "mesh3": 0.1, "mesh1_sb_pinion+1": 0.05, "mesh1_sb_pinion-1": 0.03,
         "mesh2_sb_pinion+2": 0.02, "mesh1_sb_gear+1": 0.05, "mesh1_sb_gear-2": 0.04, "mesh3_sb_gear+3": 0.03,
         "motor_ripple2": 0.07, "shaft_pinion1": 0.2, "shaft_gear1": 0.1}
# A line locked to no order (adhesion oscillation) in the low band
FREE_FREQUENCY, FREE_AMPLITUDE = 50.0, 0.3



@pytest.fixture(scope="module")
def synthetic(design) -> xr.Dataset:
    rng = np.random.default_rng(np.random.SeedSequence(5150))
    orders = {definition.name: definition.order for definition in feature_definitions(design)}
    records = np.zeros((SPEEDS.size, N_TIME))
    for index, speed in enumerate(SPEEDS):
        for name, amplitude in TRUTH.items():
            records[index] += amplitude * np.cos(2 * np.pi * orders[name] * speed / 60 * TIME
                                                 + rng.uniform(0, 2 * np.pi))
        records[index] += FREE_AMPLITUDE * np.sin(2 * np.pi * FREE_FREQUENCY * TIME + rng.uniform(0, 2 * np.pi))
        records[index] += rng.normal(0.0, NOISE, N_TIME)
    return xr.Dataset({"te": (("op", "time"), records, {"units": "m"})},
                      coords={"time": TIME, "pinion_speed": ("op", SPEEDS, {"units": "rpm"})})


@pytest.fixture(scope="module")
def synthetic_features(synthetic, design):
    return extract_features(synthetic, design, low_band=(5.0, 80.0))


def test_line_amplitudes_match_the_truth(synthetic_features):
    te = synthetic_features["te"]
    for name, amplitude in TRUTH.items():
        np.testing.assert_allclose(te.sel(feature=name).values, amplitude, rtol=0.015, err_msg=name)
    # the motor line at order 18 is also the third lower pinion sideband of mesh 1: one fitted line
    np.testing.assert_array_equal(te.sel(feature="motor_ripple1").values,
                                  te.sel(feature="mesh1_sb_pinion-3").values)
    absent = [name for name in te["feature"].values
              if not np.isnan(te["order"].sel(feature=name)) and name not in TRUTH
              and name not in ("motor_ripple1", "mesh1_sb_pinion-3")]
    # lines not in the signal read at the noise level of a fitted amplitude (~1e-4)
    assert float(te.sel(feature=absent).max()) < 1e-3


def test_low_band_rms_noise_and_rms_match_the_truth(synthetic_features, synthetic):
    te = synthetic_features["te"]
    # 5-80 Hz holds the free line and shaft lines: pinion 1x at 600 rpm (10 Hz);
    # gear 1x (7.6 Hz) and pinion 1x (36.7 Hz) at 2200 rpm
    in_band = [FREE_AMPLITUDE**2 + TRUTH["shaft_pinion1"]**2,
               FREE_AMPLITUDE**2 + TRUTH["shaft_pinion1"]**2 + TRUTH["shaft_gear1"]**2]
    np.testing.assert_allclose(te.sel(feature="low_band_rms").values, np.sqrt(np.array(in_band) / 2), rtol=0.01)
    np.testing.assert_allclose(te.sel(feature="noise_std").values, NOISE, rtol=0.1)
    total = sum(a**2 for a in TRUTH.values()) + FREE_AMPLITUDE**2
    np.testing.assert_allclose(te.sel(feature="rms").values, np.sqrt(total / 2 + NOISE**2), rtol=0.01)


def test_feature_metadata(synthetic_features, design):
    features = synthetic_features
    assert features["te"].dims == ("op", "feature")
    assert features["te"].attrs["units"] == "m"
    assert set(features["family"].values) == set(FEATURE_FAMILIES)
    assert features["family"].sel(feature="mesh2_sb_gear-3") == "sideband_gear"
    assert features["family"].sel(feature="low_band_rms") == "low_frequency"
    assert features["order"].sel(feature="mesh2_sb_gear-3") == pytest.approx(42 - 3 * 21 / 101)
    assert features["order"].sel(feature="motor_ripple2") == 36
    assert bool(features["dimensionless"].sel(feature="kurtosis"))
    assert not bool(features["dimensionless"].sel(feature="noise_std"))
    np.testing.assert_allclose(features["frequency"].sel(feature="mesh1").values, 21 * SPEEDS / 60)
    # 3 harmonics x (1 + 2 shafts x 2 sides x 3 sidebands) + 2 x 3 shaft orders + 2 motor lines + 5 others
    assert features.sizes["feature"] == 3 * 13 + 6 + 2 + 5
    names = [d.name for d in feature_definitions(design.replace(motor_pole_pairs=None))]
    assert not any(name.startswith("motor") for name in names)


def test_kurtosis_and_crest_factor_closed_forms(design):
    rng = np.random.default_rng(np.random.SeedSequence(77))
    period = 1024
    impulses = np.zeros(N_TIME)
    impulses[::period] = 1.0
    records = np.stack([rng.standard_normal(N_TIME),
                        np.cos(2 * np.pi * FS / 64 * TIME),  # whole periods, peaks on samples
                        impulses])
    signals = xr.Dataset({"acc_gear": (("op", "time"), records)},
                         coords={"time": TIME, "pinion_speed": ("op", [1000.0, 1000.0, 1000.0])})
    features = extract_features(signals, design)["acc_gear"]
    kurtosis = features.sel(feature="kurtosis").values
    assert kurtosis[0] == pytest.approx(3.0, abs=0.15)  # Gaussian; std of the estimate ~0.03
    assert kurtosis[1] == pytest.approx(1.5, rel=1e-6)  # sine: 3/2
    share = 1 / period  # centred impulse train: ((1-q)^3 + q^3) / (q (1-q))
    assert kurtosis[2] == pytest.approx(((1 - share)**3 + share**3) / (share * (1 - share)), rel=1e-9)
    assert features.sel(feature="crest_factor").values[1] == pytest.approx(np.sqrt(2), rel=1e-9)
    assert features.sel(feature="rms").values[1] == pytest.approx(1 / np.sqrt(2), rel=1e-9)


def test_nan_run_is_unusable_for_its_channel_only(synthetic, design):
    two = synthetic.assign(acc_gear=synthetic["te"].copy())
    two["acc_gear"][1, 500] = np.nan
    features = extract_features(two, design)
    assert bool(features["acc_gear"].isel(op=1).isnull().all())
    assert not bool(features["acc_gear"].isel(op=0).isnull().any())
    # the same samples give the same features whichever channel carries them
    np.testing.assert_array_equal(features["acc_gear"].isel(op=0).values, features["te"].isel(op=0).values)
    assert not bool(features["te"].isnull().any())


def test_extra_dimensions_are_kept(synthetic, design):
    stacked = xr.concat([synthetic, 2 * synthetic], dim="sample")
    features = extract_features(stacked, design, n_harmonics=1, n_sidebands=1, n_shaft_orders=1)
    assert features["te"].dims == ("sample", "op", "feature")
    np.testing.assert_allclose(features["te"].isel(sample=1).sel(feature="mesh1").values,
                               2 * features["te"].isel(sample=0).sel(feature="mesh1").values, rtol=1e-12)


def test_lines_above_the_band_limit_are_nan(synthetic, design):
    te = extract_features(synthetic, design, band_limit=500.0)["te"]
    # mesh 1 is at 210 Hz at 600 rpm, 770 Hz at 2200 rpm
    assert te.sel(feature="mesh1").values[0] == pytest.approx(1.0, rel=0.01)
    assert np.isnan(te.sel(feature="mesh1").values[1])
    assert np.isnan(te.sel(feature="mesh3").values).all()


def test_order_spectrum_reads_line_amplitudes(synthetic):
    spectrum = order_spectrum(synthetic["te"], synthetic["pinion_speed"])
    assert spectrum.dims == ("op", "order")
    for index in range(SPEEDS.size):
        row = spectrum.isel(op=index)
        # order 63 is fine for both records: no line within four bins
        assert float(row.sel(order=slice(60, 66)).idxmax()) == pytest.approx(63, abs=0.01)
        assert float(row.sel(order=slice(60, 66)).max()) == pytest.approx(TRUTH["mesh3"], rel=0.02)
    on_grid = order_spectrum(synthetic["te"].isel(op=1), 2200.0, orders=[21.0, 42.0], padding=1)
    np.testing.assert_allclose(on_grid.values, [TRUTH["mesh1"], TRUTH["mesh2"]], rtol=0.01)


def test_line_amplitudes_of_close_lines():
    # two lines 1.5 bins apart: a Hann-windowed DFT leaks a sixth of each into the other, the joint fit none
    signal = xr.DataArray(np.cos(2 * np.pi * 100 * TIME) + 0.5 * np.sin(2 * np.pi * 101.5 * TIME),
                          dims="time", coords={"time": TIME})
    amplitudes = line_amplitudes(signal, 60.0, [100.0, 101.5])
    np.testing.assert_allclose(amplitudes.values, [1.0, 0.5], rtol=1e-9)
    with pytest.raises(StudyError, match="orders: expected finite positive orders"):
        line_amplitudes(signal, 60.0, [0.0, 10.0])



@pytest.mark.parametrize("size", [N_TIME, 20000, 127])
def test_blocked_projection_is_the_window_weighted_basis_projection(size):
    # a few records go through the blocked projection, many through the basis: both are the same sums
    from uqgear.rig.features import analysis_window
    from uqgear.rig.line_fit import _BASIS_ROWS, LineFit

    taper = analysis_window("hann", size)
    frequencies = np.array([35.0, 700.0, 701.3, 1400.0, 2100.5, 7000.0])
    fit = LineFit(frequencies, FS, size, FS / 2.56, taper)
    time = np.arange(size) / FS
    rng = np.random.default_rng(5)
    records = rng.standard_normal((_BASIS_ROWS + 2, size)) + 2.0 * np.cos(2 * np.pi * 700.0 * time + 0.4)
    # the basis by angle sums is the cosines and sines of the lines' phases (those lose up to 1e-11 to
    # the rounding of arguments of up to 2 pi 7000 Hz x 1 s)
    _, first = np.unique(fit.groups, return_index=True)
    phase = 2.0 * np.pi * np.outer(np.arange(size) / FS, frequencies[fit.inside][first])
    expected = np.concatenate([np.ones((size, 1)), np.cos(phase), np.sin(phase)], axis=1) * taper[:, None]
    np.testing.assert_allclose(fit.weighted, expected, rtol=0, atol=1e-10)
    direct = fit.weighted.T @ records.T
    blocked = fit._blocked.project(records)
    np.testing.assert_allclose(blocked, direct, rtol=0, atol=1e-12 * np.abs(direct).max())
    # the coefficients of a few records and of many agree record by record
    few, many = fit.coefficients(records[:3]), fit.coefficients(records)
    np.testing.assert_allclose(few, many[:, :3], rtol=0, atol=1e-12 * np.abs(many).max())

def test_sampling_rate():
    assert sampling_rate(TIME) == pytest.approx(FS, rel=1e-12)
    with pytest.raises(RigDataError, match=r"time: expected uniform spacing 1/fs; step 2 is"):
        sampling_rate([0.0, 1.0, 2.0, 3.5])
    with pytest.raises(RigDataError, match="expected increasing sample instants"):
        sampling_rate([3.0, 2.0, 1.0])
    with pytest.raises(RigDataError, match="at least 2 samples"):
        sampling_rate([0.0])


def test_extract_features_rejects_bad_input(synthetic, design):
    with pytest.raises(RigDataError, match="signals: pinion_speed: missing"):
        extract_features(synthetic.drop_vars("pinion_speed"), design)
    slow = synthetic.assign_coords(pinion_speed=("op", [600.0, 0.0]))
    with pytest.raises(RigDataError, match=r"signals: te: pinion_speed: expected finite speeds > 0 rpm"):
        extract_features(slow, design)
    with pytest.raises(RigDataError, match="signals: acc_pinion: no such channel variable; present: te"):
        extract_features(synthetic, design, channels=["acc_pinion"])
    with pytest.raises(RigDataError, match="no channel variable; expected at least one of te"):
        extract_features(synthetic.rename(te="x"), design)
    with pytest.raises(RigDataError, match="expected an xarray Dataset"):
        extract_features(synthetic["te"], design)
    jittered = synthetic.assign_coords(time=TIME + np.where(np.arange(N_TIME) == 7, 1e-5, 0.0))
    with pytest.raises(RigDataError, match="signals: te: time: expected uniform spacing"):
        extract_features(jittered, design)
    with pytest.raises(DesignError, match="design: expected a uqgear Design"):
        extract_features(synthetic, design.to_dict())
    with pytest.raises(StudyError, match="n_harmonics: expected an integer >= 1; got 0"):
        extract_features(synthetic, design, n_harmonics=0)
    with pytest.raises(StudyError, match="n_sidebands: expected fewer than z1 = 21"):
        extract_features(synthetic, design, n_sidebands=21)
    with pytest.raises(StudyError, match="window: expected a scipy.signal window name"):
        extract_features(synthetic, design, window="no-such-window")
    with pytest.raises(StudyError, match=r"band_limit: expected a frequency in \(0, fs/2 = 10240\] Hz"):
        extract_features(synthetic, design, band_limit=20000.0)
    with pytest.raises(StudyError, match="low_band: expected"):
        extract_features(synthetic, design, low_band=(80.0, 2.0))


@pytest.fixture(scope="module")
def campaigns():
    features = {}
    for name in ("healthy", "eccentricity"):
        ds = read_rig(DATA / f"{name}.nc")
        features[name] = extract_features(ds, rig_design(ds))
    return features


def test_healthy_campaign_is_mesh_dominated(campaigns):
    features = campaigns["healthy"]
    lines = features["order"].notnull()
    for channel in ("te", "acc_pinion", "acc_gear"):
        values = features[channel].sel(feature=lines)
        strongest = values.idxmax("feature")
        assert set(strongest.values) <= {"mesh1", "mesh2", "mesh3"}, channel
        noise = features[channel].sel(feature="noise_std")
        rms = features[channel].sel(feature="rms")
        assert bool(((noise > 0) & (noise < 0.05 * rms)).all()), channel
    # at 600 rpm the response is nearly quasi-static: the te mesh line is of the
    # order of the STE amplitude (nominal 15 um, true 16.07 um per the README)
    assert 8e-6 < float(features["te"].sel(feature="mesh1").isel(op=0)) < 30e-6
    # a healthy pair has no 1x pinion line worth speaking of
    assert float(features["te"].sel(feature="shaft_pinion1").max()) < 1e-7


def test_eccentricity_campaign_shows_runout_and_pinion_sidebands(campaigns):
    healthy, eccentric = campaigns["healthy"], campaigns["eccentricity"]
    # README: pinion run-out e_s = 12.0 um enters the te directly at 1x pinion
    np.testing.assert_allclose(eccentric["te"].sel(feature="shaft_pinion1").values, 12e-6, rtol=0.05)
    sidebands = ["mesh1_sb_pinion+1", "mesh1_sb_pinion-1"]
    for channel in ("te", "acc_pinion"):
        ratio = (eccentric[channel].sel(feature=sidebands).sum("feature")
                 / healthy[channel].sel(feature=sidebands).sum("feature"))
        assert bool((ratio > 2).all()), (channel, ratio.values)


def test_features_need_no_rig_attributes(campaigns):
    ds = read_rig(DATA / "healthy.nc").isel(op=[0, 5])
    design = rig_design(ds)
    model_like = xr.Dataset({"te": (("op", "time"), ds["te"].values.astype(np.float64))},
                            coords={"time": ds["time"].values})
    model_like["pinion_speed"] = ("op", ds["pinion_speed"].values)
    features = extract_features(model_like, design)
    np.testing.assert_allclose(features["te"].values, campaigns["healthy"]["te"].isel(op=[0, 5]).values,
                               rtol=1e-9)


def test_unresolvable_lines_at_low_speed_report_the_earlier_line(design):
    # at 30 rpm the mesh line is at 10.5 Hz and gear sidebands 0.1 Hz apart, well
    # within one bin (1 Hz) of it; pinion orders are 0.5 Hz apart
    rng = np.random.default_rng(np.random.SeedSequence(31))
    record = np.cos(2 * np.pi * 10.5 * TIME) + rng.normal(0.0, NOISE, N_TIME)
    signals = xr.Dataset({"te": (("op", "time"), record[None])},
                         coords={"time": TIME, "pinion_speed": ("op", [30.0])})
    te = extract_features(signals, design)["te"].isel(op=0)
    assert float(te.sel(feature="mesh1")) == pytest.approx(1.0, rel=0.01)
    for name in ("mesh1_sb_gear+1", "mesh1_sb_gear-3", "mesh1_sb_pinion+1"):
        assert float(te.sel(feature=name)) == float(te.sel(feature="mesh1")), name
    assert np.isnan(float(te.sel(feature="shaft_gear1")))  # 0.1 Hz: below one bin
    # pinion orders too dense to leave out: the floor is still found
    assert float(te.sel(feature="noise_std")) == pytest.approx(NOISE, rel=0.1)
