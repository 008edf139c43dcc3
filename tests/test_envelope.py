"""Envelopes over the T2 interval against direct runs, and the regimes the README states."""

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.common.errors import OperatingPointError
from uqgear.uq.envelope import (
    bifurcation_envelope,
    qoi_envelope,
    regime_map,
    speed_adhesion_grid,
    time_response_envelope,
)
from uqgear.uq.runner import Runner

LIGHT = {"drive_torque": 1000.0}



@pytest.fixture(scope="module")
def grid(design):
    return speed_adhesion_grid(design, [1000.0, 4750.0, 5750.0], [4810.0, 21146.0], fixed=LIGHT,
                               n_periods=1000, keep_periods=600, history_per_period=16)


def test_bands_equal_min_and_max_of_direct_runs(design, grid):
    envelope = qoi_envelope(grid, ["dte_rms", "dynamic_load_factor"])
    for i, speed in enumerate(grid["pinion_speed"].values):
        samples = uqgear.samples_from_mapping({"pinion_speed": [speed, speed], "adhesion_torque": [4810.0, 21146.0],
                                               "drive_torque": [1000.0, 1000.0]})
        direct = uqgear.simulate_batch(design, samples, n_periods=1000, keep_periods=600, lyapunov=True,
                                        history_per_period=16)
        assert envelope["dte_rms"].values[i] == pytest.approx(
            [direct["dte_rms"].values.min(), direct["dte_rms"].values.max()], rel=1e-12)
        worst = direct["adhesion_torque"].values[direct["dynamic_load_factor"].values.argmax()]
        assert envelope["dynamic_load_factor_adhesion_at_bound"].values[i, 1] == worst


def test_regimes_stated_in_readme(grid):
    # README "Where the reference design is nonlinear": light load T1 = 1 kN m, T2 = 4.81 kN m
    labels = regime_map(grid)["regime"].sel(adhesion_torque=4810.0)
    assert labels.sel(pinion_speed=1000.0).item() == "period-1"
    assert labels.sel(pinion_speed=4750.0).item() == "period-2"
    assert labels.sel(pinion_speed=5750.0).item() == "chaotic"
    chaotic = grid.sel(pinion_speed=5750.0, adhesion_torque=4810.0)
    assert chaotic["largest_lyapunov"].item() / chaotic["mesh_frequency"].item() > 0.05
    assert chaotic["fraction_separation"].item() > 0.3
    # at the wet-rail end of the interval the teeth stay in contact at 1000 rpm and response is period-1
    assert grid["regime"].sel(pinion_speed=1000.0, adhesion_torque=21146.0).item() == "period-1"


def test_non_smooth_speeds_are_flagged(grid):
    envelope = qoi_envelope(grid)
    flags = dict(zip(grid["pinion_speed"].values, envelope["non_smooth"].values))
    assert not flags[1000.0]
    assert flags[5750.0]
    assert "regime changes" in str(envelope["non_smooth_reason"].sel(pinion_speed=5750.0).item())


def test_bifurcation_envelope_keeps_the_t2_of_each_point(grid):
    envelope = bifurcation_envelope(grid)
    speed = 4750.0
    points = envelope["poincare_x"].sel(pinion_speed=speed)
    made_by = envelope["point_adhesion_torque"].values
    for torque in grid["adhesion_torque"].values:
        expected = grid["poincare_x"].sel(pinion_speed=speed, adhesion_torque=torque).values
        assert np.array_equal(points.values[made_by == torque], expected)
    lower, upper = envelope["poincare_x_envelope"].sel(pinion_speed=speed).values
    assert lower == points.min() and upper == points.max()


def test_time_response_envelope_contains_periodic_cells(grid):
    response = time_response_envelope(grid)
    band = response["x_envelope"].sel(pinion_speed=1000.0)
    for torque in (4810.0, 21146.0):
        last = response["x_last_period"].sel(pinion_speed=1000.0, adhesion_torque=torque).values
        assert np.all(band.sel(bound="lower").values <= last + 1e-15)
        assert np.all(last <= band.sel(bound="upper").values + 1e-15)
    assert response["periodic_cells"].sel(pinion_speed=5750.0).item() < 2


def test_results_round_trip_through_netcdf(grid, tmp_path):
    for i, result in enumerate((grid, qoi_envelope(grid), bifurcation_envelope(grid), regime_map(grid),
                                time_response_envelope(grid))):
        path = tmp_path / f"r{i}.nc"
        result.to_netcdf(path)
        xr.testing.assert_identical(xr.load_dataset(path), result)


def test_checkpointed_grid_resumes_identically(design, tmp_path):
    kw = {"fixed": LIGHT, "n_periods": 60, "keep_periods": 30, "lyapunov": False}
    runner = Runner(chunk_size=2, checkpoint_dir=tmp_path / "ck", progress=False)
    first = speed_adhesion_grid(design, [1500.0, 3000.0], [5000.0, 20000.0], runner=runner, **kw)
    again = speed_adhesion_grid(design, [1500.0, 3000.0], [5000.0, 20000.0], runner=runner, resume=True, **kw)
    assert runner.last_report.reused_chunks == 2
    xr.testing.assert_identical(first, again)


def test_bad_grid_input(design):
    with pytest.raises(OperatingPointError, match="pinion_speed: expected values > 0 rpm"):
        speed_adhesion_grid(design, [0.0, 100.0], [5000.0])
    with pytest.raises(OperatingPointError, match="adhesion_torque: expected a non-empty list"):
        speed_adhesion_grid(design, [1000.0], [])
    grid = speed_adhesion_grid(design, [1000.0], [5000.0], n_periods=40, keep_periods=20, lyapunov=False)
    with pytest.raises(OperatingPointError, match="qois: 'rms' not in the grid"):
        qoi_envelope(grid, ["rms"])
    with pytest.raises(OperatingPointError, match="no x_history"):
        time_response_envelope(grid)
