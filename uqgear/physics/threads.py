"""Spreading a batch of independent runs over threads.

The batch kernels (:func:`uqgear.physics._lanes.integrate_lanes` over lane
groups, :func:`uqgear.physics._kernels.integrate_batch` and the calibration's
harmonic kernel over samples) run items ``start`` to ``stop - 1`` with the GIL
released, so plain Python threads run them side by side. Each sample is
computed by one call from its own inputs, so the numbers are the same, bit
for bit, for any number of threads and any order the chunks finish in.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numba

#: Chunks per thread: small enough that a thread finishing early takes more work
#: (runs at high speed or with separation cost several times the others).
CHUNKS_PER_THREAD = 8


def default_threads() -> int:
    """Threads a batch uses when not told: numba's thread count.

    That is ``NUMBA_NUM_THREADS`` as numba read it at import, else one per
    CPU this process may run on (its affinity): one setting for the threaded
    kernels and numba's own parallel code.
    """
    return max(1, int(numba.config.NUMBA_NUM_THREADS))


def spread(run_range: Callable[[int, int], None], n: int, threads: int | None = None) -> None:
    """Call ``run_range(start, stop)`` over disjoint ranges covering ``range(n)`` on up to ``threads`` threads.

    Parameters
    ----------
    run_range : callable
        Runs samples ``start`` to ``stop - 1`` (a compiled kernel that
        releases the GIL, wrapped with its arrays).
    n : int
        Number of samples.
    threads : int, optional
        Number of threads (default and most :func:`default_threads`); one
        runs everything in the calling thread.
    """
    available = default_threads()
    count = min(available if threads is None else max(1, int(threads)), available, n)
    if n <= 0:
        return
    if count <= 1:
        run_range(0, n)
        return
    size = max(1, -(-n // (count * CHUNKS_PER_THREAD)))
    with ThreadPoolExecutor(max_workers=count, thread_name_prefix="uqgear-batch") as pool:
        futures = [pool.submit(run_range, start, min(start + size, n)) for start in range(0, n, size)]
        for future in futures:
            # re-raises a kernel's exception (all chunks have been submitted; the pool waits for the rest)
            future.result()
