"""Evaluation of sample batches in chunks: in-process or on a dask cluster, with checkpoints.

A model is a function ``evaluate(samples) -> results`` taking and returning an
:class:`xarray.Dataset` with the dim ``sample``. :class:`Runner` splits the
samples into chunks along ``sample`` and evaluates them

* in-process, one chunk after the other, when no scheduler is given: the gear
  simulator already uses all local cores inside one call, so running several
  chunks side by side on one machine would only oversubscribe the cores;
* on a dask.distributed cluster when a scheduler address (or a
  ``distributed.Client``) is given; the model function is then pickled to the
  workers, so it must be a module-level function, a ``functools.partial`` of
  one, or an instance of a module-level class, and uqgear must be importable
  on the workers.

The chunk results are concatenated in sample order, so the output does not
depend on the chunk size, the number of workers or the order in which chunks
finish. The runner draws no random numbers; a model that needs randomness
takes it from the sample data (e.g. a per-sample seed variable).

With a checkpoint folder every finished chunk is written to
``chunk-<index>-<hash>.nc``. The hash covers the chunk's sample values and
attributes, the model function's name and a caller-supplied ``key`` (the
study text and the analysis name, say), so a checkpoint of a different study,
model or sample set is never picked up. ``run(..., resume=True)`` loads the
chunks already finished instead of evaluating them again.

A chunk whose evaluation raises is tried again ``retries`` times; if it still
fails, the run stops with an :class:`~uqgear.common.errors.ExecutionError` naming the
chunk and the original error. A :class:`~uqgear.common.errors.UqgearError` raised by
the model (a user mistake, which would fail again) is not retried and reaches
the caller unchanged.
"""

from __future__ import annotations

import functools
import hashlib
import json
import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from ..common.errors import ExecutionError, UqgearError
from ..common.progress import progress
from .cluster import is_dask_client, run_on_cluster, scheduler_text
from .results import read_dataset, write_dataset

if TYPE_CHECKING:
    from distributed import Client

#: A model: samples (dim ``sample``) in, results (dim ``sample``, same length) out.
Evaluate = Callable[[xr.Dataset], xr.Dataset]

logger = logging.getLogger(__name__)

_CHECKPOINT_FORMAT = b"uqgear-chunk-checkpoint/1\0"


@dataclass(frozen=True)
class RunReport:
    """What the last :meth:`Runner.run` did.

    Attributes
    ----------
    n_samples, n_chunks : int
        Size of the run.
    reused_chunks : int
        Chunks loaded from checkpoints instead of evaluated.
    evaluated_chunks : int
        Chunks evaluated in this run.
    retried_attempts : int
        Evaluations repeated after a failure.
    executor : str
        ``"in-process"`` or the scheduler address.
    """

    n_samples: int
    n_chunks: int
    reused_chunks: int
    evaluated_chunks: int
    retried_attempts: int
    executor: str


def _callable_name(evaluate: Any) -> str:
    """Module and qualified name of a model function, partials and callable objects unwrapped."""
    target = evaluate
    while isinstance(target, functools.partial):
        target = target.func
    if not hasattr(target, "__qualname__"):
        target = type(target)
    return f"{getattr(target, '__module__', '?')}.{getattr(target, '__qualname__', '?')}"


def _attrs_fingerprint(attrs: dict[Any, Any]) -> bytes:
    return repr(sorted((str(name), repr(value)) for name, value in attrs.items())).encode()


def chunk_hash(chunk: xr.Dataset, key: str, evaluate: Any) -> str:
    """Hex digest identifying a chunk's inputs: sample values, attributes, model name and key.

    Strings count by value whatever their numpy dtype (``<U5`` or object), so a
    sample set read back from netCDF hashes like the one written.
    """
    digest = hashlib.sha256(_CHECKPOINT_FORMAT)
    digest.update(key.encode())
    digest.update(b"\0" + _callable_name(evaluate).encode() + b"\0")
    digest.update(_attrs_fingerprint(chunk.attrs))
    for name in sorted(chunk.variables, key=str):
        variable = chunk.variables[name]
        values = np.asarray(variable.values)
        is_text = values.dtype.kind in "OUS"
        header = [
            str(name),
            [str(dim) for dim in variable.dims],
            "text" if is_text else values.dtype.str,
            list(values.shape),
        ]
        digest.update(json.dumps(header).encode())
        digest.update(_attrs_fingerprint(variable.attrs))
        if is_text:
            digest.update(json.dumps([str(item) for item in values.flat]).encode())
        else:
            digest.update(np.ascontiguousarray(values).tobytes())
    return digest.hexdigest()


class Runner:
    """Evaluates a model on a sample set in chunks, in-process or on a dask cluster.

    Parameters
    ----------
    chunk_size : int, default 256
        Samples per chunk (the last chunk may be smaller). Each chunk is one
        model call, one dask task and one checkpoint file.
    scheduler : str or distributed.Client, optional
        None evaluates in-process. An address such as ``"tcp://host:8786"``
        connects to a running dask scheduler for the duration of each run; a
        ``distributed.Client`` is used as is and left open.
    workers : int, optional
        With a scheduler: use only this many of its workers (the first in
        address order); None uses all. Without a scheduler only None or 1.
    checkpoint_dir : str or path-like, optional
        Folder for per-chunk checkpoints (created if missing); None keeps no
        checkpoints.
    retries : int, default 2
        How many times a failing chunk is evaluated again before the run fails.
    progress : bool, default True
        Show a progress bar (only when stderr is a terminal, see
        :mod:`uqgear.common.progress`).
    connect_timeout : float, default 5.0
        Seconds to wait for the scheduler to answer (and for the requested
        workers to be connected).

    Raises
    ------
    ExecutionError
        If an argument has the wrong type or range.
    """

    def __init__(
        self,
        chunk_size: int = 256,
        *,
        scheduler: str | Client | None = None,
        workers: int | None = None,
        checkpoint_dir: str | os.PathLike[str] | None = None,
        retries: int = 2,
        progress: bool = True,
        connect_timeout: float = 5.0,
    ) -> None:
        if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
            raise ExecutionError(f"chunk_size: expected a positive integer; got {chunk_size!r}")
        if isinstance(retries, bool) or not isinstance(retries, (int, np.integer)) or retries < 0:
            raise ExecutionError(f"retries: expected a non-negative integer; got {retries!r}")
        if workers is not None and (
            isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1
        ):
            raise ExecutionError(f"workers: expected None or a positive integer; got {workers!r}")
        if scheduler is None:
            if workers is not None and workers != 1:
                raise ExecutionError(
                    f"workers: expected None or 1 without a scheduler (in-process runs evaluate "
                    f"one chunk at a time and the model uses all local cores); got {workers}; "
                    "give a scheduler address to spread chunks over several workers"
                )
        elif isinstance(scheduler, str):
            if not scheduler.strip():
                raise ExecutionError("scheduler: expected an address like 'tcp://host:8786'; got an empty string")
        elif not is_dask_client(scheduler):
            raise ExecutionError(
                f"scheduler: expected None, an address like 'tcp://host:8786' "
                f"or a distributed.Client; got {type(scheduler).__name__}"
            )
        if not isinstance(connect_timeout, (int, float)) or not connect_timeout > 0:
            raise ExecutionError(f"connect_timeout: expected a positive number of seconds; got {connect_timeout!r}")
        self.chunk_size = int(chunk_size)
        self.scheduler = scheduler
        self.workers = None if workers is None else int(workers)
        self.checkpoint_dir = None if checkpoint_dir is None else Path(checkpoint_dir)
        self.retries = int(retries)
        self.progress = bool(progress)
        self.connect_timeout = float(connect_timeout)
        #: Summary of the last :meth:`run`; None before the first.
        self.last_report: RunReport | None = None

    # ------------------------------------------------------------------ public

    def run(self, evaluate: Evaluate, samples: xr.Dataset, *, key: str = "", resume: bool = False) -> xr.Dataset:
        """Evaluate ``evaluate`` on all samples and return the results in sample order.

        Parameters
        ----------
        evaluate : callable
            The model, ``evaluate(samples) -> results`` with dim ``sample`` of
            the same length in and out. Must be picklable with a scheduler.
        samples : xarray.Dataset
            The samples, dim ``sample``.
        key : str, default ""
            Identifies the analysis for checkpoints (e.g. the study text and
            the analysis name): checkpoints written under another key are
            never reused.
        resume : bool, default False
            Load chunks that have a checkpoint in ``checkpoint_dir`` instead
            of evaluating them.

        Returns
        -------
        xarray.Dataset
            The chunk results concatenated along ``sample``.

        Raises
        ------
        ExecutionError
            If the scheduler cannot be reached, a chunk fails after all
            retries, or the model returns something other than a dataset with
            the chunk's number of samples.
        UqgearError
            Raised by the model itself (passed through, not retried).
        """
        if not callable(evaluate):
            raise ExecutionError(f"evaluate: expected a callable model; got {type(evaluate).__name__}")
        if not isinstance(samples, xr.Dataset) or "sample" not in samples.dims:
            found = (
                f"a Dataset with dims {tuple(samples.dims)}"
                if isinstance(samples, xr.Dataset)
                else type(samples).__name__
            )
            raise ExecutionError(f"samples: expected an xarray Dataset with dim 'sample'; got {found}")
        n_samples = samples.sizes["sample"]
        if n_samples == 0:
            raise ExecutionError("samples: expected at least one sample; got none")
        if not isinstance(key, str):
            raise ExecutionError(f"key: expected a string; got {type(key).__name__}")
        if resume and self.checkpoint_dir is None:
            raise ExecutionError("resume: expected a checkpoint_dir to resume from; the runner has none")

        spans = [(start, min(start + self.chunk_size, n_samples)) for start in range(0, n_samples, self.chunk_size)]
        chunks = [samples.isel(sample=slice(start, stop)) for start, stop in spans]
        results: list[xr.Dataset | None] = [None] * len(spans)
        checkpoint_paths = _checkpoint_paths(self.checkpoint_dir, chunks, key, evaluate)
        if resume:
            _load_checkpoints(checkpoint_paths, spans, results)
        reused = sum(result is not None for result in results)
        if self.checkpoint_dir is not None:
            logger.info("%d of %d chunks reused from checkpoints in %s", reused, len(spans), self.checkpoint_dir)

        pending = [index for index, result in enumerate(results) if result is None]
        executor = "in-process" if self.scheduler is None else scheduler_text(self.scheduler)
        with progress(n_samples, desc="evaluating", unit="sample", enabled=self.progress) as bar:
            bar.update(sum(stop - start for (start, stop), result in zip(spans, results) if result is not None))

            def finish(index: int, result: Any) -> None:
                start, stop = spans[index]
                _check_result(result, index, start, stop)
                if checkpoint_paths:
                    write_dataset(result, checkpoint_paths[index])
                results[index] = result
                bar.update(stop - start)

            if not pending:
                retried = 0
            elif self.scheduler is None:
                retried = self._run_in_process(evaluate, chunks, spans, pending, finish)
            else:
                attempts = self.retries + 1
                retried = run_on_cluster(
                    self.scheduler,
                    evaluate,
                    chunks,
                    spans,
                    pending,
                    finish,
                    workers=self.workers,
                    attempts=attempts,
                    timeout=self.connect_timeout,
                    failed=lambda index, made, exc: _chunk_failed(index, spans[index], made, exc),
                    retrying=lambda index, attempt, exc: _log_retry(index, attempt, attempts, exc),
                )

        self.last_report = RunReport(
            n_samples=n_samples,
            n_chunks=len(spans),
            reused_chunks=reused,
            evaluated_chunks=len(pending),
            retried_attempts=retried,
            executor=executor,
        )
        return _concatenate([result for result in results if result is not None])

    # ------------------------------------------------------------------ execution

    def _run_in_process(
        self,
        evaluate: Evaluate,
        chunks: list[xr.Dataset],
        spans: list[tuple[int, int]],
        pending: list[int],
        finish: Callable[[int, Any], None],
    ) -> int:
        retried = 0
        for index in pending:
            attempts = self.retries + 1
            for attempt in range(1, attempts + 1):
                try:
                    # a fresh copy per attempt: a model that modifies its input in place must
                    # neither change the caller's samples nor see its own earlier changes
                    result = evaluate(chunks[index].copy(deep=True))
                except UqgearError:
                    raise
                except Exception as exc:
                    if attempt == attempts:
                        raise _chunk_failed(index, spans[index], attempts, exc) from exc
                    retried += 1
                    _log_retry(index, attempt, attempts, exc)
                    continue
                finish(index, result)
                break
        return retried


def _checkpoint_paths(folder: Path | None, chunks: list[xr.Dataset], key: str, evaluate: Any) -> list[Path]:
    """The checkpoint file of each chunk in ``folder`` (created if missing), named by index and input hash."""
    if folder is None:
        return []
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ExecutionError(f"checkpoint_dir {folder}: cannot create the folder ({exc})") from None
    width = max(6, len(str(len(chunks) - 1)))
    names = (
        f"chunk-{index:0{width}d}-{chunk_hash(chunk, key, evaluate)[:20]}.nc" for index, chunk in enumerate(chunks)
    )
    return [folder / name for name in names]


def _load_checkpoints(paths: list[Path], spans: list[tuple[int, int]], results: list[xr.Dataset | None]) -> None:
    """Put the usable checkpoints among ``paths`` into ``results``; an unusable one is left to evaluate again."""
    for index, path in enumerate(paths):
        if not path.is_file():
            continue
        try:
            # encodings of the chunk file (chunk sizes, ...) must not leak into the result
            result = read_dataset(path).drop_encoding()
            _check_result(result, index, *spans[index])
        except UqgearError as exc:
            logger.warning("checkpoint %s is unusable and is evaluated again: %s", path, exc)
            continue
        results[index] = result


def _check_result(result: Any, index: int, start: int, stop: int) -> None:
    """Refuse a chunk result that is not a Dataset with the chunk's number of samples."""
    expected = stop - start
    if not isinstance(result, xr.Dataset):
        raise ExecutionError(
            f"chunk {index}: the model returned {type(result).__name__}; "
            f"expected an xarray Dataset with dim 'sample' of length {expected}"
        )
    if result.sizes.get("sample") != expected:
        found = result.sizes.get("sample", "no 'sample' dim")
        raise ExecutionError(
            f"chunk {index}: the model returned a Dataset with sample length "
            f"{found}; expected dim 'sample' of length {expected} "
            f"(samples {start} to {stop - 1})"
        )


def _chunk_failed(index: int, span: tuple[int, int], attempts: int, exc: BaseException) -> ExecutionError:
    """The error of a chunk that failed on every attempt."""
    return ExecutionError(
        f"chunk {index} (samples {span[0]} to {span[1] - 1}) failed after "
        f"{attempts} attempt{'s' if attempts > 1 else ''}: "
        f"{type(exc).__name__}: {exc}"
    )


def _log_retry(index: int, attempt: int, attempts: int, exc: BaseException) -> None:
    """Log that a failed chunk is evaluated again."""
    logger.warning(
        "chunk %d failed (%s: %s); evaluating it again (attempt %d of %d)",
        index,
        type(exc).__name__,
        exc,
        attempt + 1,
        attempts,
    )


def _concatenate(parts: list[xr.Dataset]) -> xr.Dataset:
    """The chunk results in sample order as one Dataset."""
    if len(parts) == 1:
        return parts[0]
    try:
        # only variables with a sample dim are stacked; the others (a time axis, ...)
        # must agree between chunks, which is checked rather than assumed
        return xr.concat(
            parts,
            dim="sample",
            data_vars="minimal",
            coords="minimal",
            compat="equals",
            join="exact",
            combine_attrs="override",
        )
    except (ValueError, KeyError) as exc:
        raise ExecutionError(
            f"the chunk results do not fit together along 'sample' "
            f"({exc}); expected every chunk to return the same variables "
            "and the same non-sample coordinates"
        ) from None


__all__ = ["Runner", "RunReport", "Evaluate", "chunk_hash"]
