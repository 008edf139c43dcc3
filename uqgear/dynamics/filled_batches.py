"""Runs that wait for no other run, carried in the small batches of a sweep.

A sweep runs one batch per step: each run starts from the final state of the step before, so a
window of a few points makes batches of one to a few runs. Such a batch costs about as much as a
batch of a lane group per thread (:mod:`uqgear.physics._lanes`: eight runs advance together for the
cost of about two run one at a time), so the runs of a multi-start search that start from states
known beforehand (stable orbits, random states) ride along in the places the steps leave empty
instead of running as a batch of their own afterwards. Every run is computed from its own inputs and
start state, bit for bit the same in any batch (:mod:`uqgear.physics.threads`), so the numbers are
those of running them apart.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import xarray as xr

from ..physics._lane_tables import LANES
from ..physics.threads import default_threads


def join_samples(parts: Sequence[xr.Dataset]) -> xr.Dataset:
    """Batches of runs of one model joined along ``sample`` (coordinates and attributes of the first where they
    differ: the batches share them by construction).

    Examples
    --------
    >>> join_samples([xr.Dataset({"x": ("sample", [1.0])}), xr.Dataset({"x": ("sample", [2.0, 3.0])})])["x"].values
    array([1., 2., 3.])
    """
    return xr.concat(
        parts, dim="sample", coords="minimal", compat="override", join="override", combine_attrs="drop_conflicts"
    )


class FilledBatches:
    """A batch model that fills each batch it is given up to ``fill`` runs with runs of its own (module docstring).

    Parameters
    ----------
    evaluate : callable
        The batch model ``samples -> results`` (one result row per sample, along ``sample``).
    riders : xarray.Dataset
        Samples (start states included) whose runs depend on no other run; they are taken in order.
    fill : int, optional
        Runs per batch to fill up to; default one lane group per thread of a batch.

    Examples
    --------
    >>> class Squares:
    ...     calls = []
    ...     def __call__(self, samples):
    ...         self.calls.append(samples.sizes["sample"])
    ...         return samples.assign(square=samples["x"] ** 2)
    >>> model = Squares()
    >>> filled = FilledBatches(model, xr.Dataset({"x": ("sample", [5.0, 6.0, 7.0])}), fill=3)
    >>> filled(xr.Dataset({"x": ("sample", [1.0, 2.0])}))["square"].values.tolist()
    [1.0, 4.0]
    >>> filled.remaining()["square"].values.tolist(), model.calls
    ([25.0, 36.0, 49.0], [3, 2])
    """

    def __init__(self, evaluate: Callable[[xr.Dataset], xr.Dataset], riders: xr.Dataset, fill: int | None = None):
        self.evaluate = evaluate
        self.riders = riders
        self.fill = int(fill) if fill is not None else LANES * default_threads()
        self._taken = 0
        self._parts: list[xr.Dataset] = []

    @property
    def design(self) -> object:
        """The wrapped model's design (the search reads it for its random starts' box)."""
        return getattr(self.evaluate, "design", None)

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        n = samples.sizes["sample"]
        take = min(max(self.fill - n, 0), self.riders.sizes["sample"] - self._taken)
        if take <= 0:
            return self.evaluate(samples)
        chosen = self.riders.isel(sample=slice(self._taken, self._taken + take))
        result = self.evaluate(join_samples([samples, chosen]))
        self._parts.append(result.isel(sample=slice(n, None)))
        self._taken += take
        return result.isel(sample=slice(0, n))

    def remaining(self) -> xr.Dataset:
        """The results of every rider, in order: those not yet carried run now, in one batch."""
        left = self.riders.sizes["sample"] - self._taken
        if left:
            self._parts.append(self.evaluate(self.riders.isel(sample=slice(self._taken, None))))
            self._taken += left
        return self._parts[0] if len(self._parts) == 1 else join_samples(self._parts)


__all__ = ["FilledBatches", "join_samples"]
