"""The model of an analysis evaluated through a :class:`~uqgear.uq.runner.Runner` (chunked, checkpointed)."""

from __future__ import annotations

from collections.abc import Callable

import xarray as xr

from ..uq.runner import Runner


class RunnerModel:
    """A model function ``samples -> results`` that evaluates through a :class:`Runner`.

    The uncertainty layer calls a model once per stage with a whole batch;
    this wrapper chunks the batch, spreads it over a scheduler if one is set
    and checkpoints every chunk (so a killed run resumes).
    """

    def __init__(self, runner: Runner, model: Callable[[xr.Dataset], xr.Dataset], key: str,
                 resume: bool) -> None:
        self.runner = runner
        self.model = model
        self.key = key
        self.resume = resume
        #: Model runs requested through this wrapper.
        self.runs = 0

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        self.runs += samples.sizes["sample"]
        return self.runner.run(self.model, samples, key=self.key, resume=self.resume)


__all__ = ["RunnerModel"]
