"""Spreading a batch over threads: every sample once, errors surface, the caller's thread for one."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from uqgear.physics.threads import default_threads, spread


@pytest.mark.parametrize("n, threads", [(1, 4), (7, 2), (100, 2), (101, 3), (5, 1), (0, 2)])
def test_every_sample_is_run_exactly_once(n, threads):
    counts = np.zeros(n, dtype=int)
    lock = threading.Lock()

    def run_range(start, stop):
        assert 0 <= start < stop <= n
        with lock:
            counts[start:stop] += 1

    spread(run_range, n, threads)
    assert counts.tolist() == [1] * n


def test_one_thread_runs_in_the_calling_thread():
    seen = []
    spread(lambda start, stop: seen.append((threading.current_thread(), start, stop)), 10, 1)
    assert seen == [(threading.current_thread(), 0, 10)]


def test_a_kernel_error_reaches_the_caller():
    def run_range(start, stop):
        if start <= 42 < stop:
            raise ValueError("more tooth pairs in contact than a schedule holds")

    with pytest.raises(ValueError, match="more tooth pairs"):
        spread(run_range, 100, 2)


def test_threads_default_to_the_environment(monkeypatch):
    monkeypatch.setenv("NUMBA_NUM_THREADS", "3")
    assert default_threads() == 3
    monkeypatch.delenv("NUMBA_NUM_THREADS")
    assert default_threads() >= 1
