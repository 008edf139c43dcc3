"""Chunks on a dask.distributed cluster: connecting, choosing workers, submitting, retrying.

The cluster side of :class:`~uqgear.uq.runner.Runner`; dask is imported only
when a scheduler is used.
"""

from __future__ import annotations

import logging
import uuid
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, cast

import xarray as xr

from ..common.errors import ExecutionError, UqgearError

if TYPE_CHECKING:
    from distributed import Client, Future

logger = logging.getLogger(__name__)

#: The error a chunk that failed its last attempt raises: (index, attempts made, its error).
FailedChunk = Callable[[int, int, BaseException], ExecutionError]
#: Told of a chunk that is evaluated again: (index, the attempt that failed, its error).
RetryingChunk = Callable[[int, int, BaseException], None]


def is_dask_client(candidate: Any) -> bool:
    """Whether ``candidate`` is a ``distributed.Client`` (False where dask is not installed)."""
    try:
        from distributed import Client
    except ImportError:
        return False
    return isinstance(candidate, Client)


def scheduler_text(scheduler: str | Client) -> str:
    """The scheduler's address for messages."""
    if isinstance(scheduler, str):
        return scheduler
    address = getattr(scheduler, "scheduler", None)
    return str(getattr(address, "address", "dask client"))


def connect(scheduler: str | Client, timeout: float) -> tuple[Client, bool]:
    """The client to use and whether it was opened here (and must be closed here)."""
    if not isinstance(scheduler, str):
        return scheduler, False
    from distributed import Client

    try:
        client = Client(scheduler, timeout=timeout, set_as_default=False)
    except Exception as exc:
        raise ExecutionError(
            f"scheduler {scheduler}: cannot connect within {timeout:g} s "
            f"({type(exc).__name__}: {exc}); expected a running dask scheduler at this "
            "address (start one with `dask scheduler` and workers with "
            "`dask worker <address>`)"
        ) from None
    return client, True


def select_workers(client: Client, workers: int | None, timeout: float, label: str) -> list[str] | None:
    """Addresses of the first ``workers`` workers to restrict the tasks to; None for all."""
    wanted = 1 if workers is None else workers
    try:
        client.wait_for_workers(wanted, timeout=timeout)
    except TimeoutError:
        connected = len(client.scheduler_info(n_workers=-1)["workers"])
        if workers is not None:
            raise ExecutionError(
                f"workers: expected at least {workers} workers at scheduler "
                f"{label}; {connected} connected after {timeout:g} s"
            ) from None
        logger.warning("scheduler %s has no workers yet; chunks wait until workers join", label)
    if workers is None:
        return None
    addresses = sorted(client.scheduler_info(n_workers=-1)["workers"])
    return addresses[:workers]


def run_on_cluster(
    scheduler: str | Client,
    evaluate: Callable[[xr.Dataset], xr.Dataset],
    chunks: Sequence[xr.Dataset],
    spans: Sequence[tuple[int, int]],
    pending: Sequence[int],
    finish: Callable[[int, Any], None],
    *,
    workers: int | None,
    attempts: int,
    timeout: float,
    failed: FailedChunk,
    retrying: RetryingChunk,
) -> int:
    """Evaluate the ``pending`` chunks (samples ``spans``) on the cluster, each result to ``finish`` as it arrives.

    A chunk whose evaluation raises is submitted again until ``attempts``
    are spent; a :class:`~uqgear.common.errors.UqgearError` of the model is
    raised at once. Unfinished tasks are cancelled on the way out, and a
    client opened here is closed.

    Returns
    -------
    int
        Evaluations repeated after a failure.
    """
    from distributed import as_completed

    client, owned = connect(scheduler, timeout)
    in_flight: dict[str, tuple[int, int, Future]] = {}
    try:
        restrict = select_workers(client, workers, timeout, scheduler_text(scheduler))
        placement: dict[str, Any] = {} if restrict is None else {"workers": restrict, "allow_other_workers": False}

        def submit(index: int, attempt: int) -> Future:
            future = client.submit(
                evaluate,
                chunks[index],
                key=f"uqgear-chunk-{index}-{attempt}-{uuid.uuid4().hex[:12]}",
                pure=False,
                **placement,
            )
            in_flight[cast(str, future.key)] = (index, attempt, future)  # the string key given above
            return future

        completed = as_completed([submit(index, 1) for index in pending], loop=client.loop)
        retried = 0
        for future in completed:
            index, attempt, _ = in_flight.pop(future.key)
            if future.status == "finished":
                result = future.result()
                future.release()
                finish(index, result)
                continue
            if future.status == "cancelled":
                raise ExecutionError(
                    f"chunk {index} (samples {spans[index][0]} to {spans[index][1] - 1}) was "
                    f"cancelled by the scheduler {scheduler_text(scheduler)} (lost connection?)"
                )
            exc = future.exception()
            if isinstance(exc, UqgearError):
                raise exc
            if attempt == attempts or not isinstance(exc, Exception):
                raise failed(index, attempt, exc) from exc
            retried += 1
            retrying(index, attempt, exc)
            completed.add(submit(index, attempt + 1))
        return retried
    finally:
        if in_flight:
            client.cancel([future for _, _, future in in_flight.values()])
        if owned:
            client.close()


__all__ = ["connect", "is_dask_client", "run_on_cluster", "scheduler_text", "select_workers"]
