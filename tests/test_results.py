"""Tests of saving and loading results: exact round trips, provenance, atomic writes, errors."""

from __future__ import annotations

import json
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
import pytest
import scipy
import xarray as xr

from uqgear.common.errors import UqgearError
from uqgear.physics.design import design_from_json, load_design
from uqgear.uq.results import (
    ENCODED_ATTRS_MARKER,
    PROVENANCE_ATTRS,
    load_result,
    read_dataset,
    save_result,
    write_dataset,
)

ATTRS_OF_ALL_KINDS = {
    "title": "interval analysis",
    "empty": "",
    "non_ascii": "Zahnrad ü 齿轮",
    "count": 3,
    "negative": -7,
    "huge": 2**80,
    "ratio": 0.25,
    "not_a_number": float("nan"),
    "flag_true": True,
    "flag_false": False,
    "numpy_bool": np.bool_(True),
    "nothing": None,
    "numbers": [1, 2, 3],
    "one_number": [4.5],
    "empty_list": [],
    "labels": ["stick", "slip", "impact"],
    "one_label": ["lower"],
    "mixed": [1, "a", None, True],
    "nested": {"method": "pce", "order": 3, "bounds": [[0.0, 1.0], [2.0, 3.0]], "ok": False},
    "int8_scalar": np.int8(-4),
    "float32_scalar": np.float32(1.5),
    "float_array": np.array([0.5, 1.5, 2.5]),
    "int32_array": np.array([1, 2], dtype=np.int32),
    "one_element_array": np.array([7.0]),
    "matrix": np.arange(6, dtype=np.int16).reshape(2, 3),
    "bool_array": np.array([True, False]),
}


@pytest.fixture
def result() -> xr.Dataset:
    rng = np.random.default_rng(np.random.SeedSequence(7))
    peaks = rng.normal(size=(4, 3))
    peaks[1, 2] = np.nan
    return xr.Dataset(
        {
            "peak_force": (("sample", "regime"), peaks, {"units": "N", "converged": True,
                                                         "note": None, "channels": ["a"]}),
            "regime_code": ("sample", np.array([0, 1, -1, 2], dtype=np.int8)),
            "is_impact": ("sample", np.array([True, False, False, True])),
            "interval": (("bound", "regime"), np.array([[0.0, 1.0, np.nan], [2.0, 3.0, 4.0]]),
                         {"units": "N", "quantiles": [0.05, 0.95]}),
            "label": ("sample", np.array(["a", "bb", "ccc", ""])),
        },
        coords={
            "sample": np.arange(4),
            "regime": ("regime", np.array(["no_impact", "single_sided", "double_sided"]),
                       {"description": "impact regime"}),
            "bound": ["lower", "upper"],
            "speed": ("sample", np.array([10.0, 20.0, 30.0, 40.0]), {"units": "rad/s"}),
        },
        attrs=dict(ATTRS_OF_ALL_KINDS),
    )


def _without_provenance(ds: xr.Dataset) -> xr.Dataset:
    stripped = ds.copy()
    stripped.attrs = {k: v for k, v in ds.attrs.items() if k not in PROVENANCE_ATTRS}
    return stripped


def test_round_trip_is_identical(result, tmp_path):
    path = tmp_path / "result.nc"
    saved = save_result(result, path)
    assert saved == path
    loaded = load_result(path)
    xr.testing.assert_identical(_without_provenance(loaded), result)
    assert loaded["regime_code"].dtype == np.int8
    assert loaded["is_impact"].dtype == bool
    assert loaded["regime"].values.tolist() == ["no_impact", "single_sided", "double_sided"]
    assert loaded["bound"].values.tolist() == ["lower", "upper"]
    assert np.isnan(loaded["peak_force"].values[1, 2])
    assert np.isnan(loaded.attrs["not_a_number"])
    # types that an equality check would let pass
    assert loaded.attrs["flag_true"] is True and loaded.attrs["flag_false"] is False
    assert loaded.attrs["nothing"] is None
    assert loaded.attrs["one_label"] == ["lower"] and loaded.attrs["one_number"] == [4.5]
    assert loaded.attrs["huge"] == 2**80
    assert loaded.attrs["matrix"].dtype == np.int16 and loaded.attrs["matrix"].shape == (2, 3)
    assert loaded.attrs["bool_array"].dtype == bool
    assert loaded["peak_force"].attrs["converged"] is True
    assert ENCODED_ATTRS_MARKER not in loaded.attrs
    assert ENCODED_ATTRS_MARKER not in loaded["peak_force"].attrs


def test_saving_leaves_the_dataset_unchanged(result, tmp_path):
    before = result.copy(deep=True)
    save_result(result, tmp_path / "result.nc", study_text="a: 1\n")
    xr.testing.assert_identical(result, before)
    assert result.attrs["flag_true"] is True


def test_loaded_file_is_closed(result, tmp_path):
    path = tmp_path / "result.nc"
    save_result(result, path)
    loaded = load_result(path)
    path.unlink()  # a lazily loaded dataset would fail to read its values after this
    assert loaded["peak_force"].values.shape == (4, 3)
    save_result(loaded, path)  # and the path can be written again


def test_provenance_attributes(result, tmp_path):
    design = load_design("locomotive")
    seed = np.random.SeedSequence(12345678901234567890123456789)
    study = "analysis: interval\nsamples: 100\n"
    path = save_result(result, tmp_path / "result.nc", seed=seed, design=design,
                       study_text=study)
    attrs = load_result(path).attrs

    versions = json.loads(attrs["provenance_versions"])
    assert versions["numpy"] == np.__version__
    assert versions["scipy"] == scipy.__version__
    assert versions["xarray"] == xr.__version__
    assert {"uqgear", "chaospy", "SALib", "emcee", "numba"} <= set(versions)
    assert attrs["uqgear_version"] == versions["uqgear"]
    assert np.random.SeedSequence(int(attrs["seed"])).entropy == seed.entropy
    assert "seed_spawn_key" not in attrs
    assert design_from_json(attrs["design"]).to_dict() == design.to_dict()
    assert attrs["study"] == study
    created = datetime.fromisoformat(attrs["created"])
    assert created.utcoffset() == timedelta(0)
    assert abs(datetime.now(UTC) - created) < timedelta(minutes=5)


def test_spawned_seed_records_its_spawn_key(result, tmp_path):
    child = np.random.SeedSequence(42).spawn(3)[2]
    attrs = load_result(save_result(result, tmp_path / "r.nc", seed=child)).attrs
    rebuilt = np.random.SeedSequence(int(attrs["seed"]),
                                     spawn_key=json.loads(attrs["seed_spawn_key"]))
    assert rebuilt.generate_state(4).tolist() == child.generate_state(4).tolist()


def test_saving_again_replaces_old_provenance(result, tmp_path):
    first = load_result(save_result(result, tmp_path / "a.nc", seed=5, study_text="x: 1\n"))
    second = load_result(save_result(first, tmp_path / "b.nc"))
    assert "seed" not in second.attrs and "study" not in second.attrs
    xr.testing.assert_identical(_without_provenance(second), result)


def test_failed_write_keeps_the_old_file_and_leaves_no_partial_file(result, tmp_path,
                                                                    monkeypatch):
    path = tmp_path / "result.nc"
    save_result(result, path)
    old_bytes = path.read_bytes()

    def half_write_then_fail(self, target, **options):
        Path(target).write_bytes(b"CDF\x01 half written")
        raise OSError("disk full")

    monkeypatch.setattr(xr.Dataset, "to_netcdf", half_write_then_fail)
    with pytest.raises(UqgearError, match=r"result\.nc: could not write the netCDF file "
                                          r"\(OSError: disk full\)"):
        save_result(result.assign_attrs(title="changed"), path)
    assert path.read_bytes() == old_bytes
    assert sorted(p.name for p in tmp_path.iterdir()) == ["result.nc"]


def test_missing_folder_is_reported(result, tmp_path):
    path = tmp_path / "no_such_folder" / "result.nc"
    with pytest.raises(UqgearError, match=r"result\.nc: the folder .*no_such_folder does not "
                                          r"exist"):
        save_result(result, path)


def test_folder_as_target_is_reported(result, tmp_path):
    with pytest.raises(UqgearError, match="is a folder; expected a file path"):
        save_result(result, tmp_path)


def test_unstorable_attribute_is_reported(result, tmp_path):
    with pytest.raises(UqgearError, match=r"attribute 'members': cannot store an attribute of "
                                          r"type set"):
        save_result(result.assign_attrs(members={1, 2}), tmp_path / "r.nc")
    result["peak_force"].attrs["callback"] = [print]
    with pytest.raises(UqgearError, match=r"variable 'peak_force': attribute 'callback': cannot "
                                          r"store this attribute"):
        save_result(result, tmp_path / "r.nc")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(("options", "message"), [
    ({"seed": -1}, r"seed: expected a non-negative integer; got -1"),
    ({"seed": "42"}, r"seed: expected a non-negative integer or a numpy SeedSequence; got '42'"),
    ({"design": 3}, r"design: expected a Design or its JSON text; got int"),
    ({"design": "{not json"}, r"design: expected a Design or its JSON text"),
    ({"study_text": {"analysis": "mc"}}, r"study_text: expected the study YAML as a string"),
])
def test_bad_provenance_is_reported(result, tmp_path, options, message):
    with pytest.raises(UqgearError, match=message):
        save_result(result, tmp_path / "r.nc", **options)


def test_not_a_dataset_is_reported(tmp_path):
    with pytest.raises(UqgearError, match="expected an xarray Dataset to save; got DataArray"):
        save_result(xr.DataArray([1.0]), tmp_path / "r.nc")


def test_loading_missing_or_foreign_files_is_reported(tmp_path):
    with pytest.raises(UqgearError, match=r"missing\.nc: no such file"):
        load_result(tmp_path / "missing.nc")
    text_file = tmp_path / "notes.nc"
    text_file.write_text("just text")
    with pytest.raises(UqgearError, match=r"notes\.nc: not a readable netCDF file"):
        load_result(text_file)


def test_plain_write_adds_no_provenance(result, tmp_path):
    loaded = read_dataset(write_dataset(result, tmp_path / "chunk.nc"))
    xr.testing.assert_identical(loaded, result)
    assert not set(PROVENANCE_ATTRS) & set(loaded.attrs)
