"""Runs carried in a sweep's small batches: the same numbers as run apart, fewer batches."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

import uqgear
from uqgear.dynamics import attractors
from uqgear.dynamics.attractors import MultiStart, MultiStartSearch, StartedEvaluator
from uqgear.dynamics.filled_batches import FilledBatches
from uqgear.physics.integration import samples_from_mapping


class _Affine:
    """A batch model whose output is a known function of each sample alone; records its batch sizes."""

    def __init__(self) -> None:
        self.sizes: list[int] = []

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        self.sizes.append(samples.sizes["sample"])
        return xr.Dataset({"y": ("sample", 3.0 * samples["x"].values + 1.0)})


def test_riders_fill_each_batch_and_come_back_in_order() -> None:
    model = _Affine()
    riders = xr.Dataset({"x": ("sample", np.arange(10.0, 17.0))})
    filled = FilledBatches(model, riders, fill=4)
    first = filled(xr.Dataset({"x": ("sample", [1.0])}))
    second = filled(xr.Dataset({"x": ("sample", [2.0, 3.0])}))
    full = filled(xr.Dataset({"x": ("sample", [4.0, 5.0, 6.0, 7.0])}))
    assert first["y"].values.tolist() == [4.0]
    assert second["y"].values.tolist() == [7.0, 10.0]
    assert full["y"].values.tolist() == [13.0, 16.0, 19.0, 22.0]
    # 3 riders in the first batch, 2 in the second, none in the full one; the 2 left run at the end
    np.testing.assert_array_equal(filled.remaining()["y"].values, 3.0 * np.arange(10.0, 17.0) + 1.0)
    assert model.sizes == [4, 4, 4, 2]


def test_a_search_gives_the_same_runs_with_riders_as_without(monkeypatch: pytest.MonkeyPatch) -> None:
    """The random and orbit starts carried in the sweep steps: every run, bit for bit, as in a batch of their own."""
    design = uqgear.load_design("locomotive")
    speeds = [3560.0, 3600.0, 3640.0, 3680.0]
    samples = samples_from_mapping({"pinion_speed": speeds, "adhesion_torque": [21150.0] * 4})
    orbit = np.full((4, 6), np.nan)
    orbit[1:3] = [1e-5, 1e-5, 2e-4, 0.0, 0.0, 0.01]
    found = {}
    for fill in (None, 0):
        sizes: list[int] = []
        evaluate = StartedEvaluator(design, {"n_periods": 60, "keep_periods": 20}, full_regime=False)

        def counted(batch: xr.Dataset, evaluate: StartedEvaluator = evaluate, sizes: list[int] = sizes) -> xr.Dataset:
            sizes.append(batch.sizes["sample"])
            return evaluate(batch)

        monkeypatch.setattr(
            attractors, "FilledBatches", lambda model, riders, fill=fill: FilledBatches(model, riders, fill=fill)
        )
        search = MultiStartSearch(MultiStart(seeded=2), seed=5).fit(
            counted, samples, design, extra_states={"orbit-1": orbit}
        )
        found[fill] = (search.runs_, search.attractors_, sizes)
    carried, apart = found[None], found[0]
    assert carried[0].equals(apart[0]) and carried[1].equals(apart[1])
    # 4 rest runs, then 3 sweep steps of 2 runs each (up and down), then 2 orbit and 8 random starts
    assert apart[2] == [4, 2, 2, 2, 10]
    assert sum(carried[2]) == sum(apart[2]) and len(carried[2]) < len(apart[2])
