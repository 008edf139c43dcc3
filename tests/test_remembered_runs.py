"""A model that runs each distinct sample once: the answers equal fresh runs, bit for bit, and repeats cost none."""

from __future__ import annotations

import numpy as np
import xarray as xr

import uqgear
from uqgear.physics.integration import BatchEvaluator, samples_from_mapping
from uqgear.study.model_runs import RememberedRuns

RATED = {"drive_torque": 7000.0}


class _Counted:
    """The batch model, counting the samples it runs."""

    def __init__(self, evaluate: BatchEvaluator) -> None:
        self.evaluate = evaluate
        self.runs = 0
        self.calls: list[int] = []

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        self.runs += samples.sizes["sample"]
        self.calls.append(samples.sizes["sample"])
        return self.evaluate(samples)


def _samples(speeds, torques) -> xr.Dataset:
    speeds = np.asarray(speeds, float)
    return samples_from_mapping(
        {
            "pinion_speed": speeds,
            "adhesion_torque": np.asarray(torques, float),
            "drive_torque": np.full(speeds.size, RATED["drive_torque"]),
        }
    )


def test_repeated_samples_are_answered_from_the_earlier_runs_bit_for_bit():
    evaluate = BatchEvaluator(uqgear.load_design("locomotive"), n_periods=60, keep_periods=20)
    counted = _Counted(evaluate)
    model = RememberedRuns(counted)
    first = _samples([2000, 2500, 3000], [21e3, 30e3, 40e3])
    model(first)
    # two remembered samples, one new, and a new one twice within the batch, in mixed order
    second = _samples([3000, 3500, 2000, 3500], [40e3, 25e3, 21e3, 25e3])
    got = model(second)
    assert counted.calls == [3, 1] and model.runs == 4
    fresh = evaluate(second)
    assert got.sizes == fresh.sizes
    for name in fresh.variables:
        np.testing.assert_array_equal(got[name].values, fresh[name].values, err_msg=name)
    # a sample that differs in its last bit is another sample
    third = _samples([np.nextafter(2000.0, 3000.0)], [21e3])
    model(third)
    assert counted.calls == [3, 1, 1]


def test_a_batch_of_new_samples_is_one_call_of_the_model():
    counted = _Counted(BatchEvaluator(uqgear.load_design("locomotive"), n_periods=60, keep_periods=20))
    model = RememberedRuns(counted)
    samples = _samples([2000, 2500], [21e3, 30e3])
    out = model(samples)
    assert counted.calls == [2]
    np.testing.assert_array_equal(out["pinion_speed"].values, [2000.0, 2500.0])
