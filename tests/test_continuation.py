"""Continuation of periodic orbits and coexisting responses, against brute-force sweeps of the same model.

The facts checked (locomotive design, T1 = 7 kN m, wet rail T2 = 21.15 kN m): from rest the
response at 3600 rpm is the 107.4 kN one without separation; an up-sweep jumps to the high branch
between 3650 and 3700 rpm and a down-sweep falls off it between 3550 and 3600 rpm, the high
response at 3600 rpm peaking at 176.9 kN with the teeth apart half the time.
"""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.common.errors import UqgearError
from uqgear.dynamics import Continuation, MultiStart, MultiStartSearch, StartedEvaluator, bifurcation_table
from uqgear.dynamics.attractors import up_down_sweeps
from uqgear.dynamics.shooting import Shooting, setup_at
from uqgear.physics.integration import samples_from_mapping
from uqgear.uq.results import read_dataset, write_dataset

WET = {"drive_torque": 7000.0, "adhesion_torque": 21150.0}
RUN = {"n_periods": 1500, "keep_periods": 300}


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


@pytest.fixture(scope="module")
def window(design):
    return Continuation("pinion_speed", 3500.0, 3800.0).fit(design, WET)


def _sweep(design, speeds, inputs, **options):
    samples = samples_from_mapping({"pinion_speed": speeds, **{k: np.full(len(speeds), v) for k, v in inputs.items()}})
    return up_down_sweeps(StartedEvaluator(design, {**RUN, **options}), samples)


def test_both_responses_at_3600_rpm_are_found_with_their_peak_forces(design):
    speeds = np.arange(3500.0, 3751.0, 50.0)
    samples = samples_from_mapping({"pinion_speed": speeds, **{k: np.full(speeds.size, v) for k, v in WET.items()}})
    found = MultiStartSearch(MultiStart(seeded=2), seed=7).fit(StartedEvaluator(design, RUN), samples)
    at = found.attractors_.isel(sample=int(np.nonzero(speeds == 3600.0)[0][0]))
    assert int(at["attractor_count"]) == 2
    forces = np.sort(at["peak_mesh_force"].values[:2])
    assert forces[0] == pytest.approx(107.4e3, rel=2e-3)
    assert forces[1] == pytest.approx(176.9e3, rel=2e-3)
    separation = at["fraction_separation"].values[np.argsort(at["peak_mesh_force"].values[:2])]
    assert separation[0] == 0.0 and separation[1] == pytest.approx(0.5, abs=0.02)
    assert str(at["first_start"].values[0]) == "rest" and "down" in str(at["starts"].values[1])
    # one response where the branches do not overlap
    assert int(found.attractors_["attractor_count"].sel(sample=0)) == 1


def test_the_branch_holds_both_responses_and_its_folds_bound_the_coexistence(design, window):
    table = bifurcation_table(window.result_)
    folds = table[table["type"] == "fold"].sort_values("parameter")
    assert list(folds["sweep"]) == ["down", "up"]
    low, high = folds["parameter"]
    assert 3550.0 < low < 3600.0 and 3650.0 < high < 3700.0    # where the coarse sweeps jump
    ds = window.result_
    near = np.abs(ds["parameter"].values[0] - 3600.0)
    stable = ds["stable"].values[0] == 1
    # the stable points closest to 3600 rpm on the two stable stretches
    lower = stable & (ds["peak_mesh_force"].values[0] < 140e3)
    upper = stable & (ds["peak_mesh_force"].values[0] > 140e3)
    for mask, force in ((lower, 107.4e3), (upper, 176.9e3)):
        index = np.nonzero(mask)[0][np.argmin(near[mask])]
        speed = float(ds["parameter"].values[0, index])
        orbit = Shooting().fit(setup_at(design, {"pinion_speed": speed, **WET}),
                               ds["orbit_state"].values[0, index]).orbit_
        assert orbit.iterations <= 1 and orbit.stable
        assert orbit.qois["peak_mesh_force"] == pytest.approx(float(ds["peak_mesh_force"].values[0, index]), rel=1e-9)
        if abs(speed - 3600.0) < 5.0:
            assert orbit.qois["peak_mesh_force"] == pytest.approx(force, rel=0.01)
    # at a fold a real multiplier passes +1
    values = ds["bifurcation_multiplier_real"].values[(ds["bifurcation_type"] == "fold").values]
    assert np.all(np.min(np.abs(values - 1.0), axis=1) < 0.02)


def test_the_branch_dataset_round_trips_through_netcdf(window, tmp_path):
    path = write_dataset(window.result_, tmp_path / "branches.nc")
    back = read_dataset(path)
    xr.testing.assert_identical(back, window.result_)
    table = bifurcation_table(back)
    assert {"fold", "grazing_separation", "neimark_sacker"} <= set(table["type"])
    assert (table["tolerance"] < 0.01).all()     # rpm: located to 1e-5 of the range or better


def test_continuation_in_a_design_parameter_passes_its_folds(design):
    fit = Continuation("k1", 0.8e9, 1.3e9).fit(design, {"pinion_speed": 3650.0, **WET})
    kinds = sorted(bifurcation_table(fit.result_)["type"])
    assert kinds.count("fold") == 2
    assert fit.result_.attrs["parameter_units"] == "N m-1"


def test_bad_continuation_inputs_are_refused(design):
    with pytest.raises(UqgearError, match="start, stop"):
        Continuation("pinion_speed", 3000.0, 3000.0).fit(design, WET)
    with pytest.raises(UqgearError, match="continuation parameter"):
        Continuation("pinion_speed", 3000.0, 3100.0).fit(design, {"pinion_speed": 3000.0})
    with pytest.raises(UqgearError, match="not a variable"):
        Continuation("no_such_thing", 1.0, 2.0).fit(design, {"pinion_speed": 3000.0})


@pytest.mark.slow
def test_folds_and_grazing_lie_within_one_step_of_what_fine_sweeps_see(design, window):
    step = 10.0
    speeds = np.arange(3540.0, 3711.0, step)
    runs = _sweep(design, speeds, WET)
    table = bifurcation_table(window.result_)
    for direction in ("up", "down"):
        force = runs[direction]["peak_mesh_force"].values
        jumps = np.nonzero(np.abs(np.diff(force)) / force[:-1] > 0.1)[0]
        assert jumps.size == 1
        fold = float(table[(table["type"] == "fold") & (table["sweep"] == direction)]["parameter"].iloc[0])
        assert speeds[jumps[0]] - step <= fold <= speeds[jumps[0] + 1] + step
    separation = runs["up"]["fraction_separation"].values
    first = speeds[np.argmax(separation > 0)]
    grazing = float(table[table["type"] == "grazing_separation"]["parameter"].iloc[0])
    assert first - step <= grazing <= first


@pytest.mark.slow
def test_period_doublings_match_the_brute_force_bifurcation_diagram(design):
    light = {"drive_torque": 1000.0, "adhesion_torque": 4810.0}
    fit = Continuation("pinion_speed", 4600.0, 4900.0).fit(design, light)
    table = bifurcation_table(fit.result_)
    doublings = table[table["type"] == "period_doubling"]
    first = {int(period): float(group["parameter"].min()) for period, group in doublings.groupby("period")}
    assert set(first) >= {1, 2, 4}      # the cascade 1 -> 2 -> 4 -> 8
    step = 10.0
    speeds = np.arange(4650.0, 4871.0, step)
    runs = _sweep(design, speeds, light, n_periods=3000)
    regime = runs["up"]["regime"].values.astype(str)
    for period, location in first.items():
        before, after = f"period-{period}", f"period-{2 * period}"
        changes = [i for i in range(len(regime) - 1) if regime[i] == before and regime[i + 1] == after]
        assert changes, f"the sweep shows no {before} -> {after} change"
        assert any(speeds[i] - step <= location <= speeds[i + 1] + step for i in changes)


@pytest.mark.slow
def test_back_side_grazing_matches_the_first_back_contact_of_a_sweep(design):
    """A tight backlash (2b = 40 um) and a larger STE: the period-2 orbit off a period doubling near 4508 rpm
    begins to hit the back flanks; a down-sweep (coming from the orbit's side) first shows it there."""
    tight = design.replace(backlash=0.04e-3, ste_amplitude=20e-6)
    light = {"drive_torque": 1000.0, "adhesion_torque": 4810.0}
    fit = Continuation("pinion_speed", 4400.0, 4800.0).fit(tight, light)
    table = bifurcation_table(fit.result_)
    onset = table[(table["type"] == "grazing_back_side") & (table["side"] > 0)]
    assert len(onset) == 1 and int(onset["period"].iloc[0]) == 2
    step = 10.0
    speeds = np.arange(4400.0, 4601.0, step)
    runs = _sweep(tight, speeds, light)
    back = runs["down"]["fraction_back_contact"].values
    first = speeds[np.argmax(back > 0)]
    assert first - step <= float(onset["parameter"].iloc[0]) <= first
