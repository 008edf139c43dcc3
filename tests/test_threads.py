"""Spreading a batch over threads: every sample once, errors surface, the caller's thread for one."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import numpy as np
import pytest

from uqgear.physics.threads import spread


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


# the CPUs this process may run on (numba's default thread count)
USABLE_CPUS = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


@pytest.mark.parametrize("setting, expected", [("3", 3), ("1", 1), (None, USABLE_CPUS)])
def test_threads_default_to_numbas_setting(setting, expected):
    # numba reads NUMBA_NUM_THREADS once, at import: a fresh interpreter sees the setting
    environment = {key: value for key, value in os.environ.items() if key != "NUMBA_NUM_THREADS"}
    if setting is not None:
        environment["NUMBA_NUM_THREADS"] = setting
    code = "from uqgear.physics.threads import default_threads; print(default_threads())"
    answer = subprocess.run([sys.executable, "-c", code], env=environment, capture_output=True, text=True, check=True)
    assert int(answer.stdout) == expected
