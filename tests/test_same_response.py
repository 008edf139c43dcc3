"""Runs that repeat the first run bit for bit join its attractor without a comparison: the grouping is unchanged."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from uqgear.dynamics import attractors
from uqgear.dynamics.attractors import MultiStart, group_attractors
from uqgear.dynamics.same_response import COMPARED_FRACTIONS, COMPARED_QOIS


def _runs() -> xr.Dataset:
    """3 samples x 4 starts: sample 0's up and down repeat its rest run, seeded-1 is another response; sample 1's
    rest run has a NaN QoI (it matches nothing, not even its copies); sample 2's starts differ within the tolerance."""
    rng = np.random.default_rng(3)
    points = rng.uniform(-1.0, 1.0, size=(3, 4, 5)) * 1e-4
    points[:, 1:3] = points[:, :1]
    points[0, 3] += 5e-4
    points[2, 1:] = points[2, 0] * (1.0 + 1e-6)
    qoi = np.full((3, 4), 1.0e5)
    qoi[0, 3] = 2.0e5
    qoi[1, :3] = np.nan
    data = {name: (("sample", "start"), qoi.copy()) for name in COMPARED_QOIS}
    data |= {name: (("sample", "start"), np.zeros((3, 4))) for name in COMPARED_FRACTIONS}
    data |= {
        "regime": (("sample", "start"), np.full((3, 4), "period-1")),
        "poincare_x": (("sample", "start", "period"), points),
        "poincare_x_velocity": (("sample", "start", "period"), points * 100.0),
    }
    runs = xr.Dataset(data, coords={"pinion_speed": ("sample", [3600.0, 3650.0, 3700.0])})
    runs = runs.assign_coords(start=["rest", "up", "down", "seeded-1"])
    return runs.assign_attrs(half_backlash=1.5e-4, design_z1=21)


def test_copies_of_the_first_run_group_as_the_full_comparison_does(monkeypatch: pytest.MonkeyPatch) -> None:
    settings = MultiStart(seeded=1)
    quick = group_attractors(_runs(), None, settings)
    monkeypatch.setattr(attractors, "copies_of_first", lambda compared, *_: np.zeros(compared["dte_rms"].shape, bool))
    full = group_attractors(_runs(), None, settings)
    assert quick.equals(full)
    np.testing.assert_array_equal(quick.attrs["_membership"], full.attrs["_membership"])
    # sample 0: rest, up and down one attractor, seeded-1 another; sample 1: four (NaN never matches); sample 2: one
    assert quick["attractor_count"].values.tolist() == [2, 4, 1]
    assert quick["starts"].values[0, :2].tolist() == ["rest,up,down", "seeded-1"]
