"""Pieces of work on forked processes; the differential route's effect scores are the same, bit for bit, on one
process and on two workers."""

import numpy as np

from uqgear.common.forked import map_forked
from uqgear.diagnosis import Diagnosis
from uqgear.physics.design import load_design
from uqgear.physics.effects import make_effect
from uqgear.rig.foreign_rig import draw_gears, simulate_foreign_campaign
from uqgear.rig.virtual_rig import default_operating_points

DESIGN = load_design("locomotive")


def test_pieces_come_back_in_order_with_the_dearest_sent_first():
    squares = map_forked(lambda index: index * index, 5, processes=2, first=[False, False, False, True, False])
    assert squares == [0, 1, 4, 9, 16]
    assert map_forked(lambda index: -index, 3, processes=1) == [0, -1, -2]


def _squares_in_a_daemon(queue):
    queue.put(map_forked(lambda index: index * index, 3, processes=2))


def test_a_daemonic_process_which_may_not_fork_computes_the_pieces_itself():
    import multiprocessing

    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_squares_in_a_daemon, args=(queue,), daemon=True)
    child.start()
    assert queue.get(timeout=60) == [0, 1, 4]
    child.join(timeout=60)
    assert child.exitcode == 0


def test_variant_scores_do_not_depend_on_the_worker_count():
    ops = default_operating_points(DESIGN).isel(op=[1, 5])
    gears = draw_gears(DESIGN, 6, 5)
    reference = simulate_foreign_campaign(DESIGN, ops, gears=gears, seed=6)
    run_out = make_effect("eccentricity", {"shaft": "pinion", "amplitude": 12e-6, "phase": 1.0, "kappa": 0.03})
    test = simulate_foreign_campaign(DESIGN, ops, gears=gears, effects=[run_out], seed=7)
    fits = [
        Diagnosis(effects=["eccentricity", "friction"], seed=3, workers=workers).fit(test, reference=reference)
        for workers in (1, 2)
    ]
    one, two = (fit.change_ for fit in fits)
    assert one.test.changed and len(one.scores) >= 3  # two eccentric shafts and friction were scored
    assert [score.label for score in one.scores] == [score.label for score in two.scores]
    for first, second in zip(one.scores, two.scores):
        assert first.share == second.share and first.values == second.values
        assert np.array_equal(first.predicted, second.predicted, equal_nan=True)
    assert fits[0].decision_.verdict == fits[1].decision_.verdict


def test_bad_reference_options_and_worker_counts_are_refused_naming_them(tmp_path):
    import subprocess
    import sys

    import pytest

    from uqgear.diagnosis import DiagnosisError
    from uqgear.validation.foreign_suite import run_foreign_suite

    with pytest.raises(DiagnosisError, match="reference_route: expected one of change, transfer; got 'bogus'"):
        Diagnosis(reference_route="bogus")
    with pytest.raises(DiagnosisError, match="reference_gears: expected one of same, replaced; got 'new'"):
        Diagnosis(reference_gears="new")
    with pytest.raises(DiagnosisError, match="workers: expected an integer >= 1; got 0"):
        run_foreign_suite(workers=0)  # refused at once, before any campaign is simulated
    completed = subprocess.run(
        [sys.executable, "-m", "uqgear", "diagnose", "rig.nc", "--reference", "healthy.nc",
         "--reference-gears", "bogus", "--out", str(tmp_path / "out")],
        capture_output=True, text=True, cwd=tmp_path,
    )
    assert completed.returncode == 2
    assert completed.stderr.count("\n") == 1 and "--reference-gears: invalid choice: 'bogus'" in completed.stderr
    assert not (tmp_path / "out").exists()
