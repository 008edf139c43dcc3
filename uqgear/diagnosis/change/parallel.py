"""Independent pieces of the differential route on worker processes, in a fixed order.

Each effect variant's score depends on the variant, the change and the
model of the test runs alone, never on the other variants: the variants are
scored on forked worker processes that inherit what they read (a model with
its simulation grids, the observed change), and the scores come back in the
variants' order. Every piece runs with one BLAS thread, in a worker as in
this process, so the numbers are the same bit for bit for any number of
workers.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from typing import Any

from threadpoolctl import threadpool_limits

# The piece a forked worker runs (set just before the pool is created, cleared after): the
# model's simulation grids are cheaper to share by fork than to pickle.
_INHERITED: Callable[[int], Any] | None = None


def _run_inherited(index: int) -> Any:
    assert _INHERITED is not None, "worker started without its work"  # internal invariant, not user input
    with threadpool_limits(1):
        return _INHERITED(index)


def map_in_order(piece: Callable[[int], Any], count: int, workers: int, dearest: Sequence[bool] = ()) -> list[Any]:
    """``piece(i)`` for ``i`` in ``range(count)``, in that order, on up to ``workers`` forked processes.

    Parameters
    ----------
    piece : callable
        Takes an index and returns a picklable result.
    count : int
        Number of pieces.
    workers : int
        Worker processes (1, or no ``fork`` start method: in this process).
    dearest : sequence of bool, optional
        Pieces expected to cost several times the others: sent out first, so
        that they do not leave a worker idle at the end.

    Examples
    --------
    >>> map_in_order(lambda index: index * index, 4, workers=1)
    [0, 1, 4, 9]
    """
    global _INHERITED
    if workers <= 1 or count < 2 or "fork" not in multiprocessing.get_all_start_methods():
        with threadpool_limits(1):
            return [piece(index) for index in range(count)]
    order = sorted(range(count), key=lambda index: not (index < len(dearest) and dearest[index]))
    _INHERITED = piece
    try:
        with multiprocessing.get_context("fork").Pool(min(workers, count)) as pool:
            answers = pool.map(_run_inherited, order, chunksize=1)
    finally:
        _INHERITED = None
    results: list[Any] = [None] * count
    for index, answer in zip(order, answers):
        results[index] = answer
    return results


__all__ = ["map_in_order"]
