"""Interval bounds by multi-start optimisation, all local searches in lock-step.

From the best points of a seeded screening sample, bounded L-BFGS-B searches
(finite-difference gradients) minimise and maximise each response; every
search runs in its own thread and their requests go to the model together,
one batch call per round (:func:`optimize_bounds`).
"""

from __future__ import annotations

import functools
import threading
import warnings
from collections.abc import Callable, Sequence

import numpy as np
from scipy.optimize import minimize

from .interval_bounds import FLAG_NONFINITE, Bounds, flag_common_problems, tensor_grid
from .interval_responses import ModelResponses, evaluate_nodes
from .sampling import unit_hypercube


class _Aborted(Exception):
    """The batch evaluation failed; local searches stop."""


class _NonFinite(Exception):
    """The model returned a non-finite value; this local search stops."""


class _LockstepBatcher:
    """Collects the requests of all local searches and evaluates them in one call per round.

    Each local search runs scipy's optimiser in its own thread; its objective
    posts points and waits. When every live search is waiting, the collected
    points go to the model in one batch.
    """

    def __init__(self, workers: int) -> None:
        self._condition = threading.Condition()
        self._pending: dict[int, tuple[int, np.ndarray]] = {}
        self._results: dict[int, np.ndarray] = {}
        self._active = workers
        self._abort = False

    def request(self, worker: int, sweep_row: int, points: np.ndarray) -> np.ndarray:
        with self._condition:
            if self._abort:
                raise _Aborted
            self._pending[worker] = (sweep_row, points)
            self._condition.notify_all()
            self._condition.wait_for(lambda: worker in self._results or self._abort)
            if self._abort:
                raise _Aborted
            return self._results.pop(worker)

    def finish(self) -> None:
        with self._condition:
            self._active -= 1
            self._condition.notify_all()

    def serve(self, evaluate: Callable[[dict[int, tuple[int, np.ndarray]]], dict[int, np.ndarray]]) -> int:
        """Evaluate rounds until every search has finished; returns the number of rounds."""
        rounds = 0
        while True:
            with self._condition:
                self._condition.wait_for(lambda: len(self._pending) >= self._active)
                if self._active == 0:
                    return rounds
                requests = dict(self._pending)
                self._pending.clear()
            try:
                results = evaluate(requests)
            except BaseException:
                with self._condition:
                    self._abort = True
                    self._condition.notify_all()
                raise
            rounds += 1
            with self._condition:
                self._results.update(results)
                self._condition.notify_all()


def optimize_bounds(
    responses: ModelResponses,
    sweep_index: np.ndarray,
    dimensions: int,
    seed_sequence: np.random.SeedSequence,
    n_starts: int,
    screen_points: int,
    max_iterations: int,
    step: float,
    regime_names: Sequence[str],
) -> Bounds:
    """The ``optimize`` method: bounds from multi-start L-BFGS-B searches after a seeded screening."""
    screen = [
        np.full((1, dimensions), 0.5),
        unit_hypercube(screen_points, dimensions, "latin_hypercube", seed_sequence),
    ]
    if dimensions <= 6:
        screen.insert(0, tensor_grid([np.array([0.0, 1.0])] * dimensions))
    screen_nodes = np.vstack(screen)
    values, regime = evaluate_nodes(responses, sweep_index, screen_nodes)
    names = responses.names
    assert names is not None  # set by the model's first call, which every bounding method makes
    responses_count = values.shape[2]
    bounds = Bounds.empty(sweep_index, responses_count)
    bounds.observe(values)
    flag_common_problems(bounds, values, regime, regime_names, names)
    outcome = _SearchOutcome(bounds.flag.shape)
    searches = _starting_points(values, screen_nodes, n_starts)
    batcher = _LockstepBatcher(len(searches))
    settings = (step, dimensions, max_iterations)
    threads = [threading.Thread(target=_search, args=(batcher, outcome, settings, i, *spec), daemon=True)
               for i, spec in enumerate(searches)]
    for thread in threads:
        thread.start()
    try:
        batcher.serve(functools.partial(_evaluate_requests, responses, sweep_index, bounds))
    finally:
        for thread in threads:
            thread.join()
    if outcome.failures:
        raise outcome.failures[0]
    for row, r in zip(*np.nonzero(outcome.nonfinite_seen & ~(bounds.flag & FLAG_NONFINITE).astype(bool))):
        bounds.add_reason(row, r, FLAG_NONFINITE, f"{names[r]}: non-finite model value met by a local search")
    bounds.lower, bounds.upper = bounds.observed_lower.copy(), bounds.observed_upper.copy()
    return bounds


class _SearchOutcome:
    """What the local searches met, gathered from their threads under one lock."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self.nonfinite_seen = np.zeros(shape, dtype=bool)
        self.failures: list[BaseException] = []
        self.lock = threading.Lock()


def _search(batcher: _LockstepBatcher, outcome: _SearchOutcome, settings: tuple[float, int, int], worker: int,
            row: int, r: int, sign: float, start: np.ndarray) -> None:
    """One L-BFGS-B search (in its own thread) for the minimum (sign +1) or maximum (-1) of response ``r``.

    Its points go to the batcher, which evaluates every search's requests in one batch per round;
    ``settings`` are the finite-difference step, the dimensions and the iteration limit.
    """
    step, dimensions, max_iterations = settings

    def objective(x: np.ndarray) -> tuple[float, np.ndarray]:
        x = np.clip(x, 0.0, 1.0)
        steps = np.where(x + step <= 1.0, step, -step)
        points = np.vstack([x, x + np.diag(steps)])
        result = batcher.request(worker, row, points)[:, r]
        if not np.all(np.isfinite(result)):
            raise _NonFinite
        return sign * result[0], sign * (result[1:] - result[0]) / steps

    try:
        minimize(
            objective,
            start,
            jac=True,
            method="L-BFGS-B",
            bounds=[(0.0, 1.0)] * dimensions,
            options={"maxiter": max_iterations, "maxfun": 2 * max_iterations},
        )
    except _NonFinite:
        with outcome.lock:
            outcome.nonfinite_seen[row, r] = True
    except _Aborted:
        pass
    except BaseException as error:  # re-raised in the calling thread
        with outcome.lock:
            outcome.failures.append(error)
    finally:
        batcher.finish()


def _evaluate_requests(responses: ModelResponses, sweep_index: np.ndarray, bounds: Bounds,
                       requests: dict[int, tuple[int, np.ndarray]]) -> dict[int, np.ndarray]:
    """One round of the searches' points as one model batch; every value found widens the observed bounds."""
    workers = sorted(requests)  # the batch does not depend on thread timing
    rows = np.concatenate([np.full(len(requests[w][1]), requests[w][0]) for w in workers])
    points = np.vstack([requests[w][1] for w in workers])
    found, _ = responses(sweep_index[rows], points)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for row in np.unique(rows):
            chosen = found[rows == row]
            bounds.observed_lower[row] = np.fmin(bounds.observed_lower[row], np.nanmin(chosen, axis=0))
            bounds.observed_upper[row] = np.fmax(bounds.observed_upper[row], np.nanmax(chosen, axis=0))
    results, position = {}, 0
    for w in workers:
        size = len(requests[w][1])
        results[w] = found[position : position + size]
        position += size
    return results


def _starting_points(
    values: np.ndarray, screen_nodes: np.ndarray, n_starts: int
) -> list[tuple[int, int, float, np.ndarray]]:
    """(sweep row, response, sign, start) of every local search: the best finite screening nodes.

    ``values`` (S, k, R) are the responses at the ``screen_nodes``; sign +1
    searches the minimum, -1 the maximum.
    """
    searches = []
    for row in range(values.shape[0]):
        for r in range(values.shape[2]):
            for sign in (1.0, -1.0):
                objective = sign * values[row, :, r]
                order = [k for k in np.argsort(objective) if np.isfinite(objective[k])]
                for k in order[:n_starts]:
                    searches.append((row, r, sign, screen_nodes[k]))
    return searches
