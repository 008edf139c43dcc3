"""Tests of the uqgear-rig/1 reader, validator and writer."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
import xarray as xr

from uqgear.common.errors import RigDataError, UqgearError
from uqgear.rig.format import CONVENTIONS, make_rig_dataset, read_rig, rig_design, usable_runs, validate_rig, write_rig

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"
FS = 20480.0
N_TIME = 512



@pytest.fixture()
def valid(design) -> xr.Dataset:
    """A small valid campaign: 3 runs of 512 samples, one run of acc_gear with a gap."""
    rng = np.random.default_rng(np.random.SeedSequence(20240501))
    channels = {"te": 1e-5 * rng.standard_normal((3, N_TIME)),
                "acc_pinion": 100.0 * rng.standard_normal((3, N_TIME)),
                "acc_gear": 20.0 * rng.standard_normal((3, N_TIME))}
    channels["acc_gear"][1, 100:110] = np.nan
    return make_rig_dataset(
        time=np.arange(N_TIME) / FS, pinion_speed=[600.0, 1200.0, 3800.0], drive_torque=[7000.0, 5000.0, 6000.0],
        adhesion_torque_lower=[21000.0, 25000.0, 22000.0], adhesion_torque_upper=[30000.0, 33000.0, 30000.0],
        channels=channels, design=design, title="test campaign", source="unit test", history="made by a test",
        noise_std={"te": 2e-7})


def test_round_trip_keeps_values_and_attributes(valid, design, tmp_path):
    path = write_rig(tmp_path / "campaign.nc", valid)
    back = read_rig(path)
    xr.testing.assert_identical(back, valid)
    assert back["te"].dtype == np.float32
    assert back["te"].attrs["noise_std"] == pytest.approx(2e-7)
    assert back.attrs["conventions"] == CONVENTIONS
    assert json.loads(back.attrs["design"]) == design.to_dict()
    assert rig_design(back).to_dict() == design.to_dict()
    # the temporary file of the atomic write is gone
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign.nc"]


def test_write_replaces_existing_file_and_keeps_it_when_invalid(valid, tmp_path):
    path = tmp_path / "campaign.nc"
    path.write_text("old content")
    write_rig(path, valid)
    np.testing.assert_array_equal(read_rig(path)["acc_pinion"].values, valid["acc_pinion"].values)
    before = path.read_bytes()
    broken = valid.assign_attrs(conventions="uqgear-rig/0")
    with pytest.raises(RigDataError, match=re.escape(f"{path}: conventions")):
        write_rig(path, broken)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["campaign.nc"]


def test_write_needs_existing_folder(valid, tmp_path):
    with pytest.raises(RigDataError, match="does not exist"):
        write_rig(tmp_path / "missing" / "campaign.nc", valid)


def test_usable_runs_marks_nan_runs_per_channel(valid):
    usable = usable_runs(valid)
    assert usable.dims == ("channel", "op")
    assert list(usable["channel"].values) == ["te", "acc_pinion", "acc_gear"]
    expected = np.ones((3, 3), dtype=bool)
    expected[2, 1] = False  # only acc_gear of run 1 has missing samples
    np.testing.assert_array_equal(usable.values, expected)


def _drop_units(ds, name):
    ds[name].attrs.pop("units")
    return ds


def _pop_global(ds, key):
    ds.attrs.pop(key)
    return ds


def _pop_attr(ds, name, key):
    ds[name].attrs.pop(key)
    return ds


def _set_attr(ds, name, key, value):
    ds[name].attrs[key] = value
    return ds


def _set_design(ds, change):
    values = json.loads(ds.attrs["design"])
    change(values)
    ds.attrs["design"] = json.dumps(values)
    return ds


def _nonuniform_time(ds):
    time = ds["time"].values.copy()
    time[200:] += 0.3 / FS
    return ds.assign_coords(time=("time", time, ds["time"].attrs))


def _with_values(ds, name, values):
    return ds.assign_coords({name: ("op", np.asarray(values, dtype=float), ds[name].attrs)})


BROKEN = {
    "conventions missing": (lambda ds: _pop_global(ds, "conventions"),
                            r"conventions: missing global attribute; expected 'uqgear-rig/1'"),
    "conventions wrong": (lambda ds: ds.assign_attrs(conventions="CF-1.8"),
                          r"conventions: expected 'uqgear-rig/1'; got 'CF-1.8'"),
    "title missing": (lambda ds: _pop_global(ds, "title"), r"title: missing global attribute"),
    "time coordinate missing": (lambda ds: ds.drop_vars("time"), r"time: missing coordinate"),
    "pinion_speed missing": (lambda ds: ds.drop_vars("pinion_speed"), r"pinion_speed: missing coordinate"),
    "drive_torque missing": (lambda ds: ds.drop_vars("drive_torque"), r"drive_torque: missing coordinate"),
    "lower bound missing": (lambda ds: ds.drop_vars("adhesion_torque_lower"),
                            r"adhesion_torque_lower: missing coordinate"),
    "upper bound missing": (lambda ds: ds.drop_vars("adhesion_torque_upper"),
                            r"adhesion_torque_upper: missing coordinate"),
    "speed as data variable": (lambda ds: ds.reset_coords("pinion_speed"),
                               r"pinion_speed: missing coordinate \(found as a data variable\)"),
    "te transposed": (lambda ds: ds.assign(te=ds["te"].transpose("time", "op")),
                      r"te: expected dims \('op', 'time'\); got \('time', 'op'\)"),
    "te without time": (lambda ds: ds.assign(te=ds["te"].mean("time", keep_attrs=True)),
                        r"te: expected dims \('op', 'time'\); got \('op',\)"),
    "te units missing": (lambda ds: _drop_units(ds, "te"), r"te: missing 'units' attribute; expected 'm'"),
    "te in mm": (lambda ds: _set_attr(ds, "te", "units", "mm"), r"te: expected units 'm'; got 'mm'"),
    "acceleration in g": (lambda ds: _set_attr(ds, "acc_pinion", "units", "g"),
                          r"acc_pinion: expected units 'm s-2'; got 'g'"),
    "time in ms": (lambda ds: _set_attr(ds, "time", "units", "ms"), r"time: expected units 's'; got 'ms'"),
    "speed in rad/s": (lambda ds: _set_attr(ds, "pinion_speed", "units", "rad/s"),
                       r"pinion_speed: expected units 'rpm'; got 'rad/s'"),
    "torque in kN m": (lambda ds: _set_attr(ds, "drive_torque", "units", "kN m"),
                       r"drive_torque: expected units 'N m'; got 'kN m'"),
    "bound units missing": (lambda ds: _drop_units(ds, "adhesion_torque_upper"),
                            r"adhesion_torque_upper: missing 'units' attribute; expected 'N m'"),
    "long_name missing": (lambda ds: _pop_attr(ds, "acc_gear", "long_name"),
                          r"acc_gear: missing 'long_name' attribute"),
    "noise_std negative": (lambda ds: _set_attr(ds, "te", "noise_std", -1.0),
                           r"te: noise_std: expected a number >= 0 in m; got -1.0"),
    "no data variable": (lambda ds: ds.drop_vars(["te", "acc_pinion", "acc_gear"]),
                         r"no data variable; expected at least one of te, acc_pinion, acc_gear"),
    "unknown data variable": (lambda ds: ds.assign(temperature=ds["te"] * 0 + 20.0),
                              r"temperature: unknown data variable"),
    "integer samples": (lambda ds: ds.assign(acc_gear=ds["acc_gear"].fillna(0).astype(np.int32)),
                        r"acc_gear: expected floating-point samples"),
    "extra dimension": (lambda ds: ds.assign_coords(sensor=("sensor", [1, 2])), r"sensor: unknown dimension"),
    "zero speed": (lambda ds: _with_values(ds, "pinion_speed", [600.0, 0.0, 3800.0]),
                   r"pinion_speed: expected speeds > 0 rpm; op 1 has 0"),
    "negative speed": (lambda ds: _with_values(ds, "pinion_speed", [-600.0, 1200.0, 3800.0]),
                       r"pinion_speed: expected speeds > 0 rpm; op 0 has -600"),
    "NaN torque": (lambda ds: _with_values(ds, "drive_torque", [7000.0, np.nan, 6000.0]),
                   r"drive_torque: expected finite values"),
    "inverted bounds": (lambda ds: _with_values(ds, "adhesion_torque_lower", [21000.0, 40000.0, 22000.0]),
                        r"adhesion_torque_lower: expected <= adhesion_torque_upper; op 1 has lower 40000 N m "
                        r"> upper 33000 N m"),
    "design missing": (lambda ds: _pop_global(ds, "design"), r"design: missing global attribute"),
    "design not JSON": (lambda ds: ds.assign_attrs(design="{z1: 21,"), r"design: not a JSON object"),
    "design key missing": (lambda ds: _set_design(ds, lambda values: values.pop("backlash")),
                           r"design\.backlash: missing design key"),
    "design value wrong": (lambda ds: _set_design(ds, lambda values: values.update(module=9.0)),
                           r"design\.module: expected a value in"),
    "non-uniform time": (_nonuniform_time, r"time: expected uniform spacing 1/fs; step 199"),
    "sampling too slow": (lambda ds: _with_values(ds, "pinion_speed", [600.0, 1200.0, 10000.0]),
                          r"time: sampling rate 20480 Hz does not resolve the third mesh harmonic at 10000 rpm; "
                          r"expected fs > 6 z1 n1_max/60 = 21000 Hz"),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_read_rejects_broken_file(valid, tmp_path, case):
    break_it, message = BROKEN[case]
    broken = break_it(valid.copy(deep=True))
    path = tmp_path / "broken.nc"
    broken.to_netcdf(path, engine="netcdf4")
    with pytest.raises(RigDataError, match=re.escape(str(path)) + ": " + message):
        read_rig(path)


def test_validate_names_the_source_in_memory(valid):
    broken = valid.copy(deep=True)
    broken["te"].attrs["units"] = "um"
    with pytest.raises(RigDataError, match=r"^campaign 7: te: expected units 'm'; got 'um'$"):
        validate_rig(broken, where="campaign 7")
    with pytest.raises(RigDataError, match="expected an xarray Dataset"):
        validate_rig({"te": 1.0})


def test_equivalent_unit_spellings_are_accepted_and_normalised(valid, tmp_path):
    relabelled = valid.copy(deep=True)
    relabelled["acc_pinion"].attrs["units"] = "m/s^2"
    relabelled["drive_torque"].attrs["units"] = "N.m"
    relabelled["pinion_speed"].attrs["units"] = "1/min"
    path = tmp_path / "spelling.nc"
    relabelled.to_netcdf(path, engine="netcdf4")
    back = read_rig(path)
    assert back["acc_pinion"].attrs["units"] == "m s-2"
    assert back["drive_torque"].attrs["units"] == "N m"
    assert back["pinion_speed"].attrs["units"] == "rpm"


def test_read_rejects_missing_and_unreadable_files(tmp_path):
    with pytest.raises(RigDataError, match=re.escape(f"{tmp_path / 'absent.nc'}: rig data file not found")):
        read_rig(tmp_path / "absent.nc")
    text = tmp_path / "notes.nc"
    text.write_text("not netCDF at all")
    with pytest.raises(RigDataError, match=re.escape(f"{text}: not a readable netCDF-4 file")):
        read_rig(text)


def test_rig_design_rejects_bad_json(valid):
    broken = valid.assign_attrs(design=json.dumps({"z1": 21}))
    with pytest.raises(UqgearError, match=r"campaign: design\.z2: missing design key"):
        rig_design(broken, where="campaign")


def test_make_rig_dataset_rejects_inconsistent_parts(design):
    parts = {"time": np.arange(N_TIME) / FS, "pinion_speed": [600.0, 1200.0], "drive_torque": [7000.0, 5000.0],
                 "adhesion_torque_lower": [21000.0, 25000.0], "adhesion_torque_upper": [30000.0, 33000.0],
                 "design": design, "title": "t", "source": "s", "history": "h"}
    good = np.zeros((2, N_TIME))
    with pytest.raises(RigDataError, match=r"te: expected shape \(op, time\) = \(2, 512\); got \(3, 512\)"):
        make_rig_dataset(channels={"te": np.zeros((3, N_TIME))}, **parts)
    with pytest.raises(RigDataError, match=r"acc_motor: unknown channel; expected te, acc_pinion, acc_gear"):
        make_rig_dataset(channels={"acc_motor": good}, **parts)
    with pytest.raises(RigDataError, match=r"noise_std: acc_gear is not one of the channels given"):
        make_rig_dataset(channels={"te": good}, noise_std={"acc_gear": 0.1}, **parts)
    with pytest.raises(RigDataError, match=r"drive_torque: expected one value per run \(2, as pinion_speed\)"):
        make_rig_dataset(channels={"te": good}, **{**parts, "drive_torque": [7000.0]})
    with pytest.raises(RigDataError, match=r"design: expected a uqgear Design; got dict"):
        make_rig_dataset(channels={"te": good}, **{**parts, "design": design.to_dict()})
    with pytest.raises(RigDataError, match=r"no data variable"):
        make_rig_dataset(channels={}, **parts)


@pytest.mark.parametrize("name", ["healthy", "eccentricity"])
def test_bundled_campaigns_follow_the_format(name):
    ds = read_rig(DATA / f"{name}.nc")
    # README of the virtual rig: 8 runs of 1.0 s at 20480 Hz, these speeds
    assert ds.sizes == {"op": 8, "time": 20480}
    np.testing.assert_array_equal(ds["pinion_speed"].values, [600, 800, 1250, 1700, 2200, 2800, 3400, 3800])
    np.testing.assert_allclose(ds["drive_torque"].values, [7000, 5000, 6000, 8000, 7500, 6500, 5500, 5000])
    assert float(ds["time"][1] - ds["time"][0]) == pytest.approx(1 / 20480)
    assert set(ds.data_vars) == {"te", "acc_pinion", "acc_gear"}
    assert bool(usable_runs(ds).all())
    design = rig_design(ds)
    assert (design.z1, design.z2, design.motor_pole_pairs) == (21, 101, 3)
    assert np.all(ds["adhesion_torque_lower"] <= ds["adhesion_torque_upper"])
