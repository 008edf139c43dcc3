"""The ``rating`` analysis: ISO 6336 safety factors and damage from the simulated dynamic load, in a study.

A tiny study (two speeds, short runs, T2 bounded by a first-order Chebyshev
inclusion) runs once; its ``rating.nc`` is checked against the static rating
it is built from: the lower safety factor is the static one at the upper
simulated dynamic factor, ISO's K_v curve is method B's, and the damage is
Miner's sum of one pulsating cycle per tooth and revolution over the service.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.cli import main
from uqgear.physics.rating import RatingSettings, dynamic_factor_model, static_rating

STUDY = """
name: rating_check
seed: 3
design: {name: locomotive}
operating_points:
  pinion_speed: [1500, 4000]
  drive_torque: 7000
uncertain:
  adhesion_torque: {adhesion_coefficient: [0.15, 0.33], axle_load: 23000, wheel_radius: 0.625}
simulation: {n_periods: 60, keep_periods: 20}
analyses:
  - type: rating
    order: 1
    points: 2
    rating: {material: {sigma_Flim: 1.5e+8, sigma_Hlim: 6.0e+8}}
    service: {hours: 1000, speeds: [1500, 3000], shares: [0.25, 0.75]}
"""
SETTINGS = RatingSettings.from_mapping({"material": {"sigma_Flim": 1.5e8, "sigma_Hlim": 6.0e8}})


@pytest.fixture(scope="module")
def rating(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rating")
    (folder / "study.yaml").write_text(STUDY)
    assert main(["run", str(folder / "study.yaml"), "--out", str(folder / "out")]) == 0
    with xr.open_dataset(folder / "out" / "rating.nc") as ds:
        return ds.load()


def test_the_result_has_the_named_variables_with_dims_and_units(rating):
    dims = {
        "dynamic_factor_iso": ("pinion_speed",),
        "dynamic_factor": ("bound", "pinion_speed"),
        "root_stress_nominal": ("gear",),
        "contact_stress_nominal": ("gear",),
        "safety_factor_root": ("gear", "bound", "pinion_speed"),
        "safety_factor_contact": ("gear", "bound", "pinion_speed"),
        "damage": ("gear", "bound", "mode"),
    }
    for name, expected in dims.items():
        assert rating[name].dims == expected, name
        assert "units" in rating[name].attrs, name
    assert rating["root_stress_nominal"].attrs["units"] == "Pa"
    assert list(rating["mode"].values) == ["root", "contact"]
    design = uqgear.load_design("locomotive")
    model = dynamic_factor_model(design, 7000.0, SETTINGS)
    assert rating.attrs["resonance_speed_iso"] == pytest.approx(model.resonance_speed)
    assert rating["dynamic_factor_iso"].values == pytest.approx(model.factor(np.array([1500.0, 4000.0])))


def test_safety_factors_are_the_static_rating_at_the_simulated_dynamic_factor(rating):
    design = uqgear.load_design("locomotive")
    for j, speed in enumerate([1500.0, 4000.0]):
        upper = float(rating["dynamic_factor"].sel(bound="upper").values[j])
        static = static_rating(design, 7000.0, speed, SETTINGS, dynamic_factor=upper)
        low = rating.isel(pinion_speed=j).sel(bound="lower")
        assert low["safety_factor_root"].values == pytest.approx(static.safety_root)
        assert low["safety_factor_contact"].values == pytest.approx(static.safety_contact)
    assert (rating["safety_factor_root"].sel(bound="lower") <= rating["safety_factor_root"].sel(bound="upper")).all()
    force = rating["peak_mesh_force"] / rating["dynamic_factor"]
    assert force.values == pytest.approx(7000.0 / uqgear.load_design("locomotive").z1 / 0.0045 / np.cos(np.radians(20)))


def test_damage_is_miners_sum_over_the_service(rating):
    design = uqgear.load_design("locomotive")
    service = json.loads(rating.attrs["service"])
    speeds = rating["pinion_speed"].values
    upper = rating["dynamic_factor"].sel(bound="upper").values
    expected = 0.0
    for speed, share in zip(service["speeds"], service["shares"]):
        static = static_rating(design, 7000.0, speed, SETTINGS, dynamic_factor=float(np.interp(speed, speeds, upper)))
        cycles = service["hours"] * share * 60.0 * speed
        expected += cycles / static.root_curve[0].cycles_to_failure(static.root_stress[0])
    assert expected > 0.0
    assert float(rating["damage"].sel(gear="pinion", bound="upper", mode="root")) == pytest.approx(expected)
    assert (rating["damage"].sel(bound="lower") <= rating["damage"].sel(bound="upper")).all()


BAD = [
    ("rating: {material: {sigma_Hlim: 1500}}", "analyses[0].rating.material.sigma_Hlim: expected a value in"),
    ("service: {hours: 100, speeds: [1500, 3000], shares: [0.5, 0.4]}", "analyses[0].service.shares: expected time"),
    ("service: {hours: 100, speeds: [1500, 5000], shares: [0.5, 0.5]}", "analyses[0].service.speeds: 5000 rpm is"),
    ("rating: {K_A: 1.2}", "analyses[0].rating.K_A: unknown key"),
]


@pytest.mark.parametrize("line, message", BAD)
def test_bad_rating_input_exits_2_with_one_line(tmp_path, capsys, line, message):
    text = STUDY.split("    rating:")[0] + f"    {line}\n"
    (tmp_path / "study.yaml").write_text(text)
    assert main(["run", str(tmp_path / "study.yaml"), "--out", str(tmp_path / "out")]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and captured.err.count("\n") == 1
    with pytest.raises(uqgear.StudyError, match="a rating sweeps only pinion_speed"):
        uqgear.parse_study(STUDY.replace("drive_torque: 7000", "drive_torque: [6000, 7000]"))
