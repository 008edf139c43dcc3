"""The model seen by interval analysis: responses at rows of (sweep point, point of the unit box).

:class:`ModelResponses` turns rows of (sweep point, point of the unit
interval box) into one batch call of the model function and returns the QoIs
(and regime variables) per row; :class:`PboxResponses` returns instead the
statistics of each QoI over the random parameters (common random numbers at
every row). :func:`evaluate_nodes` asks for the same nodes at many sweep points.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import cast

import numpy as np

from ..common.errors import ParameterSpaceError
from .parameter_space import ParameterSpace
from .sampling import unit_hypercube
from .sweeps import ModelFunction, Sweep, batch_samples, call_model


class ModelResponses:
    """QoIs of the model at rows of (sweep point, point of the unit interval box)."""

    runs_per_row = 1

    def __init__(
        self,
        evaluate: ModelFunction,
        space: ParameterSpace,
        sweep: Sweep,
        qoi: Sequence[str] | None,
        regime_variables: Sequence[str],
    ) -> None:
        self._evaluate = evaluate
        self._space = space
        self._sweep = sweep
        self._point_values = sweep.point_values()
        self._qoi = None if qoi is None else list(qoi)
        self._regime = list(regime_variables)
        self.interval_names = list(space.interval_names)
        self.names: list[str] | None = None
        self.units: dict[str, str] = {}
        self.long_names: dict[str, str] = {}
        self.runs = np.zeros(sweep.size, dtype=np.int64)
        self.batch_calls = 0

    def batch(self, sweep_index: np.ndarray, unit_points: np.ndarray) -> tuple[dict[str, np.ndarray], dict[str, str]]:
        """Model inputs for the rows."""
        columns: dict[str, np.ndarray] = {}
        units: dict[str, str] = {}
        for name in self._space.names:
            if name in self._point_values:
                continue
            columns[name] = (
                self._space.from_unit(name, unit_points[:, self.interval_names.index(name)])
                if name in self.interval_names
                else np.full(len(sweep_index), self._space.nominal(name))
            )
            units[name] = self._space.units(name)
        for position, (name, values) in enumerate(self._point_values.items()):
            columns[name] = values[sweep_index]
            units[name] = self._sweep.attrs[position].get("units", "")
        return columns, units

    def __call__(self, sweep_index: np.ndarray, unit_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Values (rows x responses) and regime variables (rows x regime variables)."""
        columns, units = self.batch(sweep_index, unit_points)
        # with no QoI list, every per-sample output comes back and the regime variables are split off
        request = None if self._qoi is None else self._qoi + self._regime
        outputs = call_model(self._evaluate, batch_samples(columns, units), request)
        missing = [name for name in self._regime if name not in outputs]
        if missing:
            raise ParameterSpaceError(
                f"regime_variables: {', '.join(missing)} not returned by the model "
                f"function (it returned {', '.join(map(str, outputs.data_vars))})"
            )
        if self.names is None:
            # the model's outputs are named by strings
            names = (
                self._qoi
                if self._qoi is not None
                else [cast(str, n) for n in outputs.data_vars if n not in self._regime]
            )
            if not names:
                raise ParameterSpaceError("qoi: the model function returned only regime variables")
            self.names = list(names)
            self.units = {name: outputs[name].attrs.get("units", "") for name in self.names}
            self.long_names = {name: outputs[name].attrs.get("long_name", name) for name in self.names}
        values = np.stack([outputs[name].values for name in self.names], axis=1)
        regime = (
            np.stack([outputs[name].values for name in self._regime], axis=1)
            if self._regime
            else np.empty((len(sweep_index), 0))
        )
        np.add.at(self.runs, sweep_index, self.runs_per_row)
        self.batch_calls += 1
        return values, regime


class PboxResponses(ModelResponses):
    """Statistics over the random parameters at rows of (sweep point, interval point)."""

    def __init__(
        self,
        evaluate: ModelFunction,
        space: ParameterSpace,
        sweep: Sweep,
        qoi: Sequence[str] | None,
        n_samples: int,
        sampling: str,
        quantiles: np.ndarray,
        seed_sequence: np.random.SeedSequence,
    ) -> None:
        super().__init__(evaluate, space, sweep, qoi, ())
        self.runs_per_row = n_samples
        self.quantiles = quantiles
        self.random_names = list(space.random_names)
        unit = unit_hypercube(n_samples, len(self.random_names), sampling, seed_sequence)
        # common random numbers: the same random samples at every interval node,
        # so differences between nodes are not sampling noise
        self._random = {name: space.from_unit(name, unit[:, j]) for j, name in enumerate(self.random_names)}
        self.qoi_names: list[str] | None = None

    def __call__(self, sweep_index: np.ndarray, unit_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = self.runs_per_row
        columns, units = self.batch(sweep_index, unit_points)
        expanded = {name: np.repeat(values, n) for name, values in columns.items() if name not in self._random}
        for name, values in self._random.items():
            expanded[name] = np.tile(values, len(sweep_index))
            units[name] = self._space.units(name)
        outputs = call_model(self._evaluate, batch_samples(expanded, units), self._qoi)
        if self.qoi_names is None:
            self.qoi_names = cast(list[str], list(outputs.data_vars))  # the model's outputs are named by strings
            self.units = {name: outputs[name].attrs.get("units", "") for name in self.qoi_names}
            self.long_names = {name: outputs[name].attrs.get("long_name", name) for name in self.qoi_names}
            self.names = [
                f"{q}|{s}"
                for q in self.qoi_names
                for s in ["mean", "std"] + [f"q{i}" for i in range(self.quantiles.size)]
            ]
        values = np.stack([outputs[name].values.reshape(len(sweep_index), n) for name in self.qoi_names], axis=1)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            # a failed run makes the statistic of its node non-finite: flagged, never silently dropped
            mean = values.mean(axis=-1)
            std = values.std(axis=-1, ddof=1)
            quantile = np.moveaxis(np.quantile(values, self.quantiles, axis=-1), 0, -1)
        statistics = np.concatenate([mean[..., None], std[..., None], quantile], axis=-1)
        np.add.at(self.runs, sweep_index, n)
        self.batch_calls += 1
        return statistics.reshape(len(sweep_index), -1), np.empty((len(sweep_index), 0))


def evaluate_nodes(
    responses: ModelResponses, sweep_index: np.ndarray, nodes: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Values (S, k, R) and regime variables (S, k, G) at every node of every sweep point."""
    rows_sweep = np.repeat(sweep_index, nodes.shape[0])
    rows_points = np.tile(nodes, (len(sweep_index), 1))
    values, regime = responses(rows_sweep, rows_points)
    return (values.reshape(len(sweep_index), nodes.shape[0], -1), regime.reshape(len(sweep_index), nodes.shape[0], -1))
