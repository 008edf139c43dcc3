"""Inputs a user can get wrong, or a hostile file can abuse: each fails fast with one clear line."""

from __future__ import annotations

import time

import pytest

from uqgear.cli import main
from uqgear.common.errors import shown
from uqgear.common.resources import bundled_file
from uqgear.common.yamlio import MAX_VALUES, YAMLError, load_yaml
from uqgear.study.schema import parse_study

SMOKE = bundled_file("study", "smoke").read_text()

# nine levels of nine aliases: 9**9 values once expanded (the "billion laughs")
ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8))


def test_an_alias_bomb_is_refused_at_once():
    start = time.perf_counter()
    with pytest.raises(YAMLError, match="expands to more than"):
        load_yaml(ALIAS_BOMB + "description: *i\n")
    assert time.perf_counter() - start < 2.0


def test_an_alias_bomb_in_a_free_text_study_key_gives_one_line_and_exit_2(tmp_path, capsys):
    study = tmp_path / "bomb.yaml"
    study.write_text(ALIAS_BOMB + SMOKE.replace("description: Every", "description: *i\nx_description: Every"))
    start = time.perf_counter()
    assert main(["validate", str(study)]) == 2
    error = capsys.readouterr().err
    assert time.perf_counter() - start < 5.0
    assert error.count("\n") == 1 and "aliases" in error and len(error) < 400


def test_modest_aliases_still_work():
    document = load_yaml("base: &b {lower: 1, upper: 2}\nfirst: *b\nsecond: *b\n")
    assert document["first"] == document["second"] == {"lower": 1, "upper": 2}
    assert MAX_VALUES >= 100_000


def test_a_duplicate_key_names_the_key_and_both_lines():
    text = SMOKE.replace("seed: 20240601", "seed: 20240601\nseed: 7")
    with pytest.raises(Exception, match=r"key 'seed' appears twice in one mapping \(lines 5 and 6\)"):
        parse_study(text)
    # nested mappings too
    with pytest.raises(YAMLError, match=r"key 'lower' appears twice .*lines 2 and 3"):
        load_yaml("range:\n  lower: 1\n  lower: 2\n")


def test_deep_nesting_is_a_yaml_error_not_a_crash():
    with pytest.raises(YAMLError, match="nested too deeply"):
        load_yaml("[" * 50_000 + "]" * 50_000)


def test_error_messages_show_a_bounded_prefix_of_a_value():
    huge = "x" * 10_000_000
    assert len(shown(huge)) <= 80
    nested: list = []
    for _ in range(100_000):
        nested = [nested]
    start = time.perf_counter()
    assert len(shown(nested)) <= 80 and time.perf_counter() - start < 5.0   # unbounded it would recurse 100 000 levels
    with pytest.raises(Exception) as caught:
        parse_study(SMOKE.replace("seed: 20240601", f"seed: {'9' * 5000}x"))
    assert len(str(caught.value)) < 300


# ---------------------------------------------------------------------------- rig files

@pytest.fixture(scope="module")
def healthy():
    import xarray as xr

    from uqgear.common.resources import example_rig_file

    with xr.open_dataset(example_rig_file()) as ds:
        return ds.isel(op=slice(0, 2), time=slice(0, 4096)).load()


def _write(ds, path):
    # the source file's chunking cannot hold a zero-length dimension: write with default encodings
    ds.drop_encoding().to_netcdf(path)
    return str(path)


@pytest.mark.parametrize("command", ["calibrate", "diagnose"])
def test_a_rig_file_without_operating_points_is_one_line_and_exit_2(healthy, tmp_path, capsys, command):
    rig = _write(healthy.isel(op=slice(0, 0)), tmp_path / "empty.nc")
    assert main([command, rig, "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "op: the file holds no operating point" in error
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["calibrate", "diagnose"])
def test_a_deeply_nested_design_attribute_is_one_line_and_exit_2(healthy, tmp_path, capsys, command):
    broken = healthy.copy()
    broken.attrs["design"] = "[" * 100_000 + "]" * 100_000
    rig = _write(broken, tmp_path / "deep.nc")
    assert main([command, rig, "--out", str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "nested too deeply" in error and len(error) < 300


def test_a_design_attribute_that_is_not_an_object_is_refused(healthy, tmp_path, capsys):
    broken = healthy.copy()
    broken.attrs["design"] = "[1, 2, 3]"
    assert main(["calibrate", _write(broken, tmp_path / "list.nc"), "--out", str(tmp_path / "out")]) == 2
    assert "expected a JSON object of design keys" in capsys.readouterr().err


# ---------------------------------------------------------------------------- simulate, report, outputs

@pytest.mark.parametrize("arguments, message", [
    (["--speed", "1e6"], "--speed: expected a number in (0, 100000] rpm; got 1000000"),
    (["--speed", "3000", "--drive-torque", "1e12"], "--drive-torque: expected a number in [0, 1e+07] N m"),
    (["--speed", "3000", "--adhesion-torque", "nan"], "--adhesion-torque: expected a number in"),
    (["--speed", "3000", "--n-periods", "2000000"], "--n-periods: expected an integer in [2, 1e+06]"),
    (["--speed", "3000", "--n-periods", "50", "--keep-periods", "60"], "--keep-periods: expected at most"),
    (["--speed", "3000", "--dpi", "0"], "--dpi: expected an integer in [50, 600] dots per inch; got 0"),
    (["--speed", "3000", "--dpi", "100000"], "--dpi: expected an integer in [50, 600]"),
])
def test_simulate_shares_the_limits_of_studies(arguments, message, capsys):
    assert main(["simulate", *arguments]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and message in error


def test_simulate_and_studies_agree_on_a_negative_torque(capsys):
    # the model has no braking case: both refuse T1 < 0 up front, with the same limits
    assert main(["simulate", "--speed", "2000", "--drive-torque", "-500"]) == 2
    assert "--drive-torque: expected a number in [0, 1e+07] N m; got -500" in capsys.readouterr().err
    with pytest.raises(Exception, match=r"drive_torque: expected a number in \[0, 1e\+07\] N m; got -500"):
        parse_study(SMOKE.replace("drive_torque: 1000 ", "drive_torque: -500 "))


def test_report_dpi_is_checked_before_any_work(tmp_path, capsys):
    for dpi in ("0", "100000"):
        assert main(["report", str(tmp_path), "--dpi", dpi]) == 2
        assert "--dpi: expected an integer in [50, 600]" in capsys.readouterr().err


def test_outputs_are_not_overwritten_without_force(tmp_path, capsys):
    figure = tmp_path / "run.png"
    figure.write_bytes(b"keep me")
    short = ["--speed", "2000", "--n-periods", "40", "--keep-periods", "20"]
    assert main(["simulate", *short, "--out", str(figure)]) == 2
    assert "pass --force" in capsys.readouterr().err and figure.read_bytes() == b"keep me"
    assert main(["simulate", *short, "--out", str(figure), "--force"]) == 0
    assert figure.read_bytes()[:4] == b"\x89PNG"
    rig = tmp_path / "rig.nc"
    rig.write_bytes(b"keep me")
    assert main(["synth-rig", "--out", str(rig)]) == 2
    assert "pass --force" in capsys.readouterr().err and rig.read_bytes() == b"keep me"
    folder = tmp_path / "figure.png"
    folder.mkdir()
    assert main(["simulate", *short, "--out", str(folder)]) == 2
    assert "is a folder" in capsys.readouterr().err
