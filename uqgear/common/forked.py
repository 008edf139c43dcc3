"""Independent pieces of work on forked processes, their results in order.

The pieces are closures over large objects (Datasets, a model with its
simulation grids): a forked child inherits them instead of unpickling them,
and only an index goes out and a picklable result comes back. Each piece
runs whole in one process, so its result is that of running it here. Where
forking is not possible (no ``fork`` start method, or inside a daemonic
process, which may not have children) or not worth it, the pieces run here
one after the other.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Callable, Sequence
from typing import Any

# The piece a forked child runs (set just before the pool forks, cleared after).
_INHERITED: Callable[[int], Any] | None = None


def _run_inherited(index: int) -> Any:
    assert _INHERITED is not None, "forked process started without its work"  # internal invariant
    return _INHERITED(index)


def map_forked(
    piece: Callable[[int], Any], count: int, processes: int, *, first: Sequence[bool] = ()
) -> list[Any]:
    """``piece(i)`` for ``i`` in ``range(count)``, in that order, computed on up to ``processes`` forked processes.

    Parameters
    ----------
    piece : callable
        Takes an index and returns a picklable result.
    count : int
        Number of pieces.
    processes : int
        Forked processes at most (below 2, or one piece: here).
    first : sequence of bool, optional
        Pieces expected to cost several times the others: sent out first, so
        that they do not leave a process idle at the end.

    Examples
    --------
    >>> map_forked(lambda index: index * index, 4, processes=1)
    [0, 1, 4, 9]
    """
    global _INHERITED
    if (
        count < 2
        or processes < 2
        or "fork" not in multiprocessing.get_all_start_methods()
        or multiprocessing.current_process().daemon
    ):
        return [piece(index) for index in range(count)]
    order = sorted(range(count), key=lambda index: not (index < len(first) and first[index]))
    _INHERITED = piece
    try:
        with multiprocessing.get_context("fork").Pool(min(processes, count)) as pool:
            answers = pool.map(_run_inherited, order, chunksize=1)
    finally:
        _INHERITED = None
    results: list[Any] = [None] * count
    for index, answer in zip(order, answers):
        results[index] = answer
    return results


__all__ = ["map_forked"]
