"""The random starts of chosen samples, and points alone in their sweep, in a multi-start search."""

from __future__ import annotations

import numpy as np

import uqgear
from uqgear.dynamics.attractors import MultiStart, MultiStartSearch, StartedEvaluator
from uqgear.physics.integration import samples_from_mapping


def _search(seeded_rows: np.ndarray | None) -> MultiStartSearch:
    design = uqgear.load_design("locomotive")
    # three speeds 1000 rpm apart, each alone in its sweep (the listed speeds of a single-speed analysis)
    samples = samples_from_mapping({"pinion_speed": [2000.0, 3000.0, 4000.0], "adhesion_torque": [21150.0] * 3})
    evaluate = StartedEvaluator(design, {"n_periods": 60, "keep_periods": 20}, full_regime=False)
    return MultiStartSearch(MultiStart(seeded=2), seed=11).fit(
        evaluate, samples, design, seeded_rows=seeded_rows, sweep_reach=100.0
    )


def test_chosen_samples_start_where_they_would_with_every_sample_chosen() -> None:
    every, some = _search(None), _search(np.array([False, True, False]))
    for label in ("seeded-1", "seeded-2"):
        np.testing.assert_array_equal(some.start_states_[label][1], every.start_states_[label][1])
        assert np.isnan(some.start_states_[label][[0, 2]]).all()
        assert np.isfinite(every.start_states_[label]).all()
    assert some.model_runs_ == 3 + 2 and every.model_runs_ == 3 + 6


def test_a_point_alone_in_its_sweep_has_its_rest_run_as_its_sweep_runs() -> None:
    search = _search(None)
    runs = search.runs_
    for start in ("up", "down"):
        for name in ("peak_mesh_force", "poincare_x", "final_x"):
            np.testing.assert_array_equal(runs[name].sel(start=start).values, runs[name].sel(start="rest").values)
        assert np.isnan(search.start_states_[start]).all()
    assert all(starts.startswith("rest,up,down") for starts in search.attractors_["starts"].values[:, 0])
