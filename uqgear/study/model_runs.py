"""The model of an analysis evaluated through a :class:`~uqgear.uq.runner.Runner` (chunked, checkpointed)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import xarray as xr

from ..dynamics.filled_batches import join_samples
from ..uq.runner import Runner


class RunnerModel:
    """A model function ``samples -> results`` that evaluates through a :class:`Runner`.

    The uncertainty layer calls a model once per stage with a whole batch;
    this wrapper chunks the batch, spreads it over a scheduler if one is set
    and checkpoints every chunk (so a killed run resumes).
    """

    def __init__(self, runner: Runner, model: Callable[[xr.Dataset], xr.Dataset], key: str, resume: bool) -> None:
        self.runner = runner
        self.model = model
        self.key = key
        self.resume = resume
        #: Model runs requested through this wrapper.
        self.runs = 0

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        self.runs += samples.sizes["sample"]
        return self.runner.run(self.model, samples, key=self.key, resume=self.resume)


class RememberedRuns:
    """A model that runs each distinct sample once and answers a sample it meets again from the earlier run.

    A run depends on its sample's inputs alone, bit for bit (:mod:`uqgear.physics.threads`), so a repeated
    sample needs no second run: the interval analysis's scan nodes come again where guided starts widen its
    bounds over the attractors. Samples match when every input variable holds the same value, bit for bit.

    Parameters
    ----------
    model : callable
        ``samples -> results`` (one result row per sample, along ``sample``); its ``runs`` counts the runs made.

    Examples
    --------
    >>> class Squares:
    ...     runs = 0
    ...     def __call__(self, samples):
    ...         self.runs += samples.sizes["sample"]
    ...         return samples.assign(square=samples["x"] ** 2)
    >>> model = RememberedRuns(Squares())
    >>> _ = model(xr.Dataset({"x": ("sample", [1.0, 2.0])}))
    >>> model(xr.Dataset({"x": ("sample", [2.0, 3.0])}))["square"].values, model.runs
    (array([4., 9.]), 3)
    """

    def __init__(self, model: Any) -> None:
        self.model = model
        self._parts: list[xr.Dataset] = []
        self._where: dict[bytes, tuple[int, int]] = {}  # sample key -> (part, row)

    @property
    def runs(self) -> int:
        """Model runs made (a remembered sample is not run again)."""
        return int(self.model.runs)

    @staticmethod
    def _keys(samples: xr.Dataset) -> list[bytes]:
        names = sorted(str(name) for name in samples.data_vars if samples[name].dims == ("sample",))
        table = np.stack([np.asarray(samples[name].values, dtype=float) for name in names], axis=1)
        head = "\0".join(names).encode()
        return [head + row.tobytes() for row in table]

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        keys = self._keys(samples)
        first: dict[bytes, int] = {}
        for row, key in enumerate(keys):
            if key not in self._where:
                first.setdefault(key, row)  # a sample repeated within the batch runs once
        if first:
            self._parts.append(self.model(samples.isel(sample=list(first.values()))))
            for at, key in enumerate(first):
                self._where[key] = (len(self._parts) - 1, at)
            if len(first) == len(keys):
                return self._parts[-1]
        places = np.array([self._where[key] for key in keys], dtype=np.int64).reshape(len(keys), 2)
        used = np.unique(places[:, 0])
        pieces = [self._parts[part].isel(sample=places[places[:, 0] == part, 1]) for part in used]
        joined = pieces[0] if len(pieces) == 1 else join_samples(pieces)
        order = np.concatenate([np.nonzero(places[:, 0] == part)[0] for part in used])
        out = joined.isel(sample=np.argsort(order, kind="stable"))
        # the sample labels of this call (the inputs are equal, bit for bit, by the key)
        labels = {
            name: samples[name] for name in samples.coords if name in out.coords and samples[name].dims == ("sample",)
        }
        return out.assign_coords(labels) if labels else out


__all__ = ["RunnerModel", "RememberedRuns"]
