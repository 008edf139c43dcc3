"""The gear model of a study with extra starts only where responses can coexist (``starts: guided``).

Running every point from several starts (``starts: true``) finds every response a point holds but
multiplies the cost of a study by the number of starts, although the responses coexist only in a
few per cent of the speed x T2 plane. The guided model first follows the periodic branches in pinion
speed by continuation at ``nodes`` values of the adhesion torque across its interval
(:func:`uqgear.dynamics.windows.find_windows`; at the analysis's own T2 where T2 is fixed) and takes
the speed windows where a branch folds, doubles, loses stability or grazes. Then, for every batch:

* every point runs from rest, through the same model as a study without starts: a point outside
  every window gives today's from-rest numbers, bit for bit;
* the points inside a window (their speed, scaled to the windows' inputs where the sample changes
  the mesh-mode frequency, :func:`~uqgear.dynamics.windows.equivalent_speeds`, within a window at
  their T2) run again from rest, from their up- and down-sweep neighbours' final states (among the
  window points), from every stable orbit the continuation holds at their speed (``orbit-1``,
  ``orbit-2``, ...) and from ``seeded`` random states; their steady responses are grouped into
  attractors (:class:`~uqgear.dynamics.attractors.MultiStartSearch`).

The output has the layout of :class:`~uqgear.study.coexistence.MultiStartModel` for every point
(``<qoi>`` of the worst attractor, ``<qoi>_max`` / ``_min`` / ``_rest``, ``attractor_count``,
``attractor_*``); outside the windows it is the rest run's, one attractor. The windows found and the
points and runs spent are in the attributes ``windows``, ``window_points`` and ``model_runs``.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast

import numpy as np
import xarray as xr

from ..dynamics.attractors import (
    ATTRACTOR_QOIS,
    FINAL_VARIABLES,
    MultiStart,
    MultiStartSearch,
    StartedEvaluator,
    sweep_order,
    with_starts,
)
from ..dynamics.regimes import period_labels
from ..dynamics.stress_qois import RUN_QOI_INFO
from ..dynamics.windows import CoexistenceWindows, equivalent_speeds, follow_nodes, windows_from
from ..physics.design import Design
from .coexistence import PER_ATTRACTOR, attractor_starts, summarise
from .settings import SimulationSettings

#: How far (in window margins) a grid point may lie from the one whose final state a sweep carries into it (from
#: outside a window, or between window points): the margin is at least the study's finest speed step, so twice it
#: takes in the analyses' own grid steps, and a longer step (listed speeds of a single-speed analysis) is no sweep.
ENTRY_REACH = 2.0
#: The node input of the windows: the uncertain adhesion torque.
NODE_PARAMETER = "adhesion_torque"
#: Continuations already made in this process, by their inputs (they hold for every analysis of a study
#: that runs the same design over the same speeds): the windows are found once per study run.
_FITS: dict[str, tuple[list[Any], float]] = {}
_FITS_MAX = 16


def _fits(
    design: Design,
    speed_range: tuple[float, float],
    fixed: Mapping[str, float],
    nodes: Sequence[float],
    simulation: SimulationSettings,
    threads: int | None = None,
) -> tuple[list[Any], float]:
    key = json.dumps(
        {
            "design": design.to_dict(),
            "range": list(speed_range),
            "fixed": dict(fixed),
            "nodes": list(nodes),
            "damping_in_separation": simulation.damping_in_separation,
            "stiffness": simulation.stiffness,
        },
        sort_keys=True,
        default=str,
    )
    if key not in _FITS:
        began = time.perf_counter()
        fits = follow_nodes(
            design,
            speed_range,
            fixed,
            node_parameter=NODE_PARAMETER if len(nodes) else None,
            node_values=nodes,
            damping_in_separation=simulation.damping_in_separation,
            stiffness=simulation.stiffness,
            threads=threads,
        )
        if len(_FITS) >= _FITS_MAX:
            _FITS.pop(next(iter(_FITS)))
        _FITS[key] = (fits, time.perf_counter() - began)
    return _FITS[key]


def analysis_windows(context: Any, simulation: SimulationSettings) -> CoexistenceWindows:
    """The windows of an analysis (an :class:`~uqgear.study.analyses.AnalysisContext`): continuations over the
    hull of the study's and the analysis's speeds, at ``nodes`` T2 values across its interval where T2 is
    uncertain and not fixed by the analysis, else at its fixed value; every other input at the analysis's
    fixed values (uncertain parameters at their nominal values)."""
    starts = cast(MultiStart, simulation.starts)
    speeds = _speeds(context)
    step = float(np.min(np.diff(np.unique(speeds)))) if np.unique(speeds).size > 1 else 0.0
    # the study's finest speed step joins a window's sweep neighbours to it (all analyses share the
    # continuations); a coarse grid's step would make the windows span most of the range, so it counts up
    # to five times the set margin
    margin = max(float(starts.margin), min(step, 5.0 * float(starts.margin)))
    low, high = float(speeds.min()) - margin, float(speeds.max()) + margin
    # the branches are followed from a positive speed: half the lowest speed at most below it
    low = max(low, 0.5 * float(speeds.min()))
    fixed = {
        name: float(value)
        for name, value in context.fixed_values(exclude=["pinion_speed", NODE_PARAMETER]).items()
        if name != "pinion_speed"
    }
    nodes: list[float] = []
    uncertain = context.study.uncertain.get(NODE_PARAMETER)
    given = context.spec.fixed.get(NODE_PARAMETER)
    if given is not None or uncertain is None:
        fixed[NODE_PARAMETER] = float(given if given is not None else context.fixed_values()[NODE_PARAMETER])
    else:
        nodes = np.linspace(float(uncertain.lower), float(uncertain.upper), int(starts.nodes)).tolist()
    fits, seconds = _fits(context.design, (low, high), fixed, nodes, simulation, context.threads)
    return windows_from(fits, margin, node_parameter=NODE_PARAMETER if nodes else None, fixed=fixed, seconds=seconds)


def _speeds(context: Any) -> np.ndarray:
    """Every pinion speed the study's analyses name (the analysis's own among them), sorted and unique."""
    found: list[float] = []
    for spec in context.study.analyses:
        if "pinion_speed" in spec.sweeps:
            found += [float(v) for v in np.asarray(spec.sweeps["pinion_speed"].values, dtype=float)]
        if "pinion_speed" in spec.fixed:
            found.append(float(spec.fixed["pinion_speed"]))
    return np.unique(np.asarray(found or [context.fixed_values()["pinion_speed"]], dtype=float))


class GuidedStartModel:
    """The model ``samples -> results`` with extra starts only inside the coexistence windows (module docstring).

    Parameters
    ----------
    rest : callable
        The from-rest model of the analysis (the model of a study without starts).
    started : callable
        The started batch model (:func:`~uqgear.study.coexistence.started_model`).
    design : Design
    settings : MultiStart
    windows : CoexistenceWindows
    seed : SeedSequence
        Seed of the random starts (the same for every call).
    poincare : bool
        Keep Poincare points.
    exponents : callable, optional
        The started batch model with the largest Lyapunov exponent, where ``rest`` gives it and
        ``started`` does not: a window point whose worst response no rest run reached runs again from
        that response's start with it (the same trajectory, bit for bit), so that ``largest_lyapunov``
        is the worst response's, while the other extra starts skip the exponent's cost (the grouping
        does not read it).
    """

    def __init__(
        self,
        rest: Any,
        started: Any,
        design: Design,
        settings: MultiStart,
        windows: CoexistenceWindows,
        seed: Any,
        poincare: bool = True,
        exponents: Any = None,
    ) -> None:
        self.rest = rest
        self.started = started
        self.design = design
        self.settings = settings
        self.windows = windows
        self.seed = seed
        self.poincare = poincare
        self.exponents = exponents
        #: Points that lay in a window, over every call.
        self.window_points = 0
        #: Per call with window points: their sample values, and each one's attractors as (first start, its state).
        self.found: list[tuple[dict[str, np.ndarray], list[list[tuple[str, np.ndarray]]]]] = []

    @property
    def runs(self) -> int:
        """Model runs made so far (rest runs and extra starts)."""
        again = int(self.exponents.runs) if self.exponents is not None else 0
        return int(self.rest.runs) + int(self.started.runs) + again

    def _where(self, samples: xr.Dataset) -> tuple[np.ndarray, np.ndarray]:
        """Each sample's equivalent speed and node value (NaN without one)."""
        speeds = equivalent_speeds(samples, self.design, self.windows)
        if NODE_PARAMETER in samples and self.windows.node_parameter is not None:
            return speeds, np.asarray(samples[NODE_PARAMETER].values, dtype=float)
        return speeds, np.full(speeds.size, math.nan)

    def inside(self, samples: xr.Dataset) -> np.ndarray:
        """Which samples lie in a window."""
        return self.windows.contains(*self._where(samples))

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        base = self.rest(samples)
        speeds, values = self._where(samples)
        inside = self.windows.contains(speeds, values)
        self.window_points += int(inside.sum())
        rows = np.nonzero(inside)[0]
        found = None
        if rows.size:
            subset = samples.isel(sample=rows)
            rest = base.isel(sample=rows)
            rest = rest.merge(period_labels(rest)[["regime", "response_period"]], compat="override")
            # where only a grazing point made the window, the branch is stable and one-valued through it: its one
            # orbit is the rest run's, and a jump shows in the sweeps; the orbit and random starts are spent where
            # a branch folds, doubles or loses stability
            branching = self.windows.branching(speeds[rows], values[rows])
            starts = self._orbit_starts(speeds[rows], values[rows])
            for column in starts.values():
                column[~branching] = np.nan
            entry = self._sweep_entry(samples, inside, base) if self.settings.sweeps else None
            search = MultiStartSearch(self.settings, self.seed).fit(
                self.started,
                subset,
                self.design,
                extra_states=starts,
                rest=rest,
                seeded_rows=branching,
                sweep_entry=entry,
                sweep_reach=ENTRY_REACH * float(self.windows.margin),
            )
            found = summarise(search, subset, poincare=self.poincare)
            self._remember(subset, search)
            if self.exponents is not None and "largest_lyapunov" in rest:
                found = self._worst_exponents(found, search, subset, rest)
        # the rest runs' final states serve the sweeps only; the result has the layout of a study without them
        base = base.drop_vars([name for name in FINAL_VARIABLES if name in base.variables])
        out = combine(base, found, rows, poincare=self.poincare)
        if not self.poincare:
            out = out.drop_dims("period", errors="ignore")
        out.attrs.update(
            starts=json.dumps(self.settings.to_dict()),
            window_points=int(rows.size),
            windows=json.dumps(self.windows.to_records()),
        )
        return out

    def _remember(self, samples: xr.Dataset, search: MultiStartSearch) -> None:
        """Keep each window point's attractors as their first starts' labels and states (NaN: from rest)."""
        values = {name: np.asarray(samples[name].values, dtype=float) for name in _point_variables(samples)}
        self.found.append((values, attractor_starts(search)))

    def attractor_starts(self, samples: xr.Dataset) -> list[list[tuple[str, np.ndarray]]]:
        """Each sample's attractors as (first start, its state; NaN: from rest): one, from rest, outside the
        windows; inside, those a call found at the same point, else those of a call made now."""
        out = self._recall(samples)
        missing = [row for row, found in enumerate(out) if found is None]
        if missing:
            self(samples.isel(sample=missing))
            again = self._recall(samples.isel(sample=missing))
            for row, found in zip(missing, again):
                out[row] = found
        return [found if found is not None else [("rest", np.full(6, np.nan))] for found in out]

    def _recall(self, samples: xr.Dataset) -> list[list[tuple[str, np.ndarray]] | None]:
        """The attractors remembered at each sample's point (the rest run's alone outside the windows; None:
        not found)."""
        names = _point_variables(samples)
        values = {name: np.asarray(samples[name].values, dtype=float) for name in names}
        inside = self.inside(samples)
        out: list[list[tuple[str, np.ndarray]] | None] = []
        for row in range(samples.sizes["sample"]):
            if not inside[row]:
                out.append([("rest", np.full(6, np.nan))])
                continue
            found = None
            for known, attractors in reversed(self.found):
                if set(known) != set(names):
                    continue
                same = np.ones(len(attractors), dtype=bool)
                for name in names:
                    same &= np.isclose(known[name], values[name][row], rtol=1e-9, atol=0.0)
                hits = np.nonzero(same)[0]
                if hits.size:
                    found = attractors[int(hits[0])]
                    break
            out.append(found)
        return out

    def _sweep_entry(self, samples: xr.Dataset, inside: np.ndarray, base: xr.Dataset) -> dict[str, np.ndarray] | None:
        """The states the sweeps enter each stretch of window points with (rows of the in-window samples; NaN
        where none): the final state of the point just outside it on the grid of ``samples``, run from rest (the
        rest runs ``base`` hold it where their model returns final states; else it is run again).

        Outside the windows the gear holds one response, so that state is the one a sweep over the whole grid
        carries to the window's edge; a sweep that started from rest at the window's first point would enter the
        window on another path and can miss the branch a run-up follows into it. Only a neighbour within
        :data:`ENTRY_REACH` window margins enters: over a longer step (the listed speeds of a single-speed
        analysis, 1000 rpm apart) the carried state follows no branch and is one more start at twice the cost."""
        rows = np.nonzero(inside)[0]
        speeds = np.asarray(samples[self.settings.sweep_variable].values, dtype=float)
        reach = ENTRY_REACH * float(self.windows.margin)
        position = np.full(inside.size, -1)
        position[rows] = np.arange(rows.size)
        entry = {direction: np.full((rows.size, 6), np.nan) for direction in ("up", "down")}
        neighbours: list[tuple[str, int, int]] = []  # (direction, in-window row, outside sample)
        for members in sweep_order(samples, self.settings.sweep_variable):
            inner = inside[members]
            for k in np.nonzero(inner)[0]:
                for direction, j in (("up", k - 1), ("down", k + 1)):
                    if 0 <= j < members.size and not inner[j] and abs(speeds[members[j]] - speeds[members[k]]) <= reach:
                        neighbours.append((direction, int(position[members[k]]), int(members[j])))
        if not neighbours:
            return None
        outside = np.unique([sample for _, _, sample in neighbours])
        if all(name in base.variables for name in FINAL_VARIABLES):
            finals = base.isel(sample=outside)
        else:
            finals = self.started(with_starts(samples, outside, np.full((outside.size, 6), np.nan)))
        states = np.stack([np.asarray(finals[name].values, dtype=float) for name in FINAL_VARIABLES], axis=1)
        at = {int(sample): row for row, sample in enumerate(outside)}
        for direction, row, sample in neighbours:
            entry[direction][row] = states[at[sample]]
        return entry

    def _worst_exponents(
        self, found: xr.Dataset, search: MultiStartSearch, samples: xr.Dataset, rest: xr.Dataset
    ) -> xr.Dataset:
        """``found`` with ``largest_lyapunov`` of each point's worst response: the rest run's where the rest start
        reached it, else a run again from the start that first reached it, with the exponent."""
        worst = np.asarray(found["worst_attractor_start"].values).astype(str)
        values = np.asarray(rest["largest_lyapunov"].values, dtype=float).copy()
        again = np.nonzero(worst != "rest")[0]
        if again.size:
            states = np.stack([search.start_states_[worst[row]][row] for row in again])
            values[again] = self.exponents(with_starts(samples, again, states))["largest_lyapunov"].values
        return found.assign(largest_lyapunov=("sample", values, dict(rest["largest_lyapunov"].attrs)))

    def _orbit_starts(self, speeds: np.ndarray, values: np.ndarray) -> dict[str, np.ndarray]:
        """The stable orbits at each (equivalent speed, node value) as start states ``orbit-1``, ``orbit-2``, ..."""
        states = [self.windows.orbit_states(float(s), float(v)) for s, v in zip(speeds, values)]
        width = max((len(found) for found in states), default=0)
        out = {}
        for k in range(width):
            column = np.full((speeds.size, 6), np.nan)
            for row, found in enumerate(states):
                if k < len(found):
                    column[row] = found[k]
            out[f"orbit-{k + 1}"] = column
        return out


def _point_variables(samples: xr.Dataset) -> list[str]:
    """The sample variables that name a point (not its start state)."""
    return sorted(
        str(name)
        for name in samples.data_vars
        if samples[name].dims == ("sample",)
        and not str(name).startswith("initial_")
        and np.issubdtype(samples[name].dtype, np.number)
    )


def _rest_layout(base: xr.Dataset, poincare: bool) -> xr.Dataset:
    """The multi-start layout of runs from rest alone: one attractor, the rest start's."""
    n = base.sizes["sample"]
    # every variable is gathered first and merged once: a merge per variable costs more than the rest of the call
    added: dict[str, Any] = {}
    for name in [*RUN_QOI_INFO, "static_mesh_force", "mesh_frequency", "steps_per_period"]:
        if name in base:
            added[f"{name}_rest"] = base[name].assign_attrs(long_name=f"{name} from rest")
    for name in ATTRACTOR_QOIS:
        if name not in base:
            continue
        for bound in ("max", "min"):
            added[f"{name}_{bound}"] = base[name].assign_attrs(
                units=RUN_QOI_INFO[name][0], long_name=f"{bound} over attractors of {name}"
            )
            added[f"{name}_{bound}_attractor"] = ("sample", np.zeros(n, dtype=np.int64))
            added[f"{name}_{bound}_start"] = ("sample", np.full(n, "rest"))
    added["attractor_count"] = (
        "sample",
        np.ones(n, dtype=np.int64),
        {"units": "1", "long_name": "distinct steady responses found"},
    )
    for name in PER_ATTRACTOR:
        if name in base:
            added[f"attractor_{name}"] = (("sample", "attractor"), base[name].values[:, None], dict(base[name].attrs))
    regime = np.asarray(base["regime"].values).astype(str) if "regime" in base else np.full(n, "")
    for name, values in (
        ("regime", regime),
        ("share", np.ones(n)),
        ("starts", np.full(n, "rest")),
        ("first_start", np.full(n, "rest")),
    ):
        added[f"attractor_{name}"] = (("sample", "attractor"), values[:, None])
    added["worst_attractor_start"] = ("sample", np.full(n, "rest"))
    if poincare and "poincare_x" in base:
        added["poincare_x_rest"] = base["poincare_x"]
        for start in ("up", "down"):
            added[f"poincare_x_{start}"] = base["poincare_x"].where(False)
    out = base.copy()
    out.update(added)
    return out.assign_coords(attractor=("attractor", [0]))


def _widened(out: xr.Dataset, width: int) -> xr.Dataset:
    """``out`` on ``width`` attractors: the new entries of non-float variables empty (``""`` or 0), not NaN."""
    out = out.reindex(attractor=np.arange(width))
    filled: dict[str, Any] = {}
    for name in cast(Iterable[str], out.data_vars):
        if "attractor" in out[name].dims and out[name].dtype.kind not in "fc":
            values = out[name].values
            text = values.dtype.kind in "USO"
            column = np.where(np.arange(width)[None, :] == 0, values, "" if text else 0)
            filled[name] = (out[name].dims, column.astype(str) if text else column)
    out.update(filled)
    return out


def combine(base: xr.Dataset, found: xr.Dataset | None, rows: np.ndarray, poincare: bool = True) -> xr.Dataset:
    """The from-rest runs of every point (``base``) with the multi-start outputs ``found`` of the points ``rows``
    written over them."""
    out = _rest_layout(base, poincare)
    if found is None:
        return out
    width = max(found.sizes.get("attractor", 1), 1)
    if width > 1:
        out = _widened(out, width)
    written: dict[str, Any] = {}
    for name in cast(Iterable[str], found.data_vars):
        if name not in out.data_vars or "sample" not in found[name].dims:
            continue
        # plain variables: a DataArray would carry (and copy) every sample coordinate along
        target = out.variables[name]
        dims = ("sample", *(dim for dim in target.dims if dim != "sample"))
        values = target.transpose(*dims).values.copy()
        column = found.variables[name].transpose(*dims).values
        if values.dtype.kind in "USO" or column.dtype.kind in "USO":
            values = values.astype(str).astype(object)
            column = column.astype(str)
        if column.ndim == 2 and column.shape[1] < values.shape[1]:
            pad = np.full(
                (column.shape[0], values.shape[1] - column.shape[1]), np.nan if column.dtype.kind == "f" else ""
            )
            column = np.concatenate([column, pad.astype(column.dtype)], axis=1)
        values[rows] = column
        if values.dtype == object:
            values = values.astype(str)
        written[name] = (dims, values, target.attrs)
    out.update(written)
    if "regime" in out and "attractor_regime" in found:
        worst = np.asarray(found["worst_attractor_start"].values).astype(str)
        first = np.asarray(found["attractor_first_start"].values).astype(str)
        regimes = np.asarray(found["attractor_regime"].values).astype(str)
        picked = [regimes[i][list(first[i]).index(worst[i])] for i in range(rows.size)]
        values = np.asarray(out["regime"].values).astype(object)
        values[rows] = picked
        out["regime"] = ("sample", values.astype(str), out["regime"].attrs)
    return out


class _CountedRuns:
    """A batch model that counts the runs it makes."""

    def __init__(self, evaluate: Any) -> None:
        self.evaluate = evaluate
        self.design = evaluate.design
        self.runs = 0

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        self.runs += samples.sizes["sample"]
        return self.evaluate(samples)


def guided_start_model(context: Any, simulation: SimulationSettings, rest: Any, poincare: bool) -> GuidedStartModel:
    """The guided model of an analysis: ``rest`` is its from-rest model (``simulation.starts`` guided).

    The extra starts run in this process, without checkpoints: they are a few per cent of the runs,
    in small batches (a sweep is one batch per step), for which a checkpoint file costs more than the
    runs. Their runs are labelled by period detection alone and skip the Lyapunov exponent (the
    grouping needs neither); the analyses classify the response they report in full, with the exponent
    of the worst response (:class:`GuidedStartModel`, ``exponents``)."""
    starts = cast(MultiStart, simulation.starts)
    windows = analysis_windows(context, simulation)
    options = simulation.batch_options(context.threads)
    seed = context.stage_seed(99)
    stresses = simulation.stresses
    started = _CountedRuns(
        StartedEvaluator(context.design, {**options, "lyapunov": False}, seed, full_regime=False, stresses=stresses)
    )
    exponents = None
    if simulation.lyapunov:
        exponents = _CountedRuns(StartedEvaluator(context.design, options, seed, full_regime=False, stresses=stresses))
    return GuidedStartModel(
        rest, started, context.design, starts, windows, context.stage_seed(98), poincare, exponents=exponents
    )


def widen_over_attractors(
    context: Any,
    result: xr.Dataset,
    names: Sequence[str],
    qois: Sequence[str],
    fixed: Mapping[str, float],
    model: GuidedStartModel | None = None,
) -> xr.Dataset:
    """Interval bounds from rest (``result``) widened over the attractors at the sweep points whose box reaches a
    coexistence window: there the nodes of a grid of ``points`` per interval parameter that lie in a window run with
    the guided model, and each bound is the outer of the from-rest bound and the extremes over their attractors.
    Elsewhere the from-rest bounds stand, bit for bit. ``model``: the analysis's guided model (default: a new one)."""
    from ..uq.sweeps import batch_samples, make_sweep

    model = model if model is not None else context.model(poincare=False)
    assert isinstance(model, GuidedStartModel)  # the caller's condition: guided starts
    counted = int(model.runs)  # runs of a given model already in ``result``'s count
    space = context.parameter_space(names, fixed)
    sweep = context.sweep()
    points = int(context.options["points"] or 9)
    spec = make_sweep(sweep, space)
    intervals = [space[name] for name in space.interval_names]
    axes = [np.linspace(float(p.lower), float(p.upper), points) for p in intervals]
    grid = np.stack([a.ravel() for a in np.meshgrid(*axes, indexing="ij")], axis=1)
    flat: dict[str, np.ndarray] = {}
    sweep_values = spec.point_values()
    n_points = spec.size
    for column, name in enumerate(space.interval_names):
        flat[name] = np.tile(grid[:, column], n_points)
    for name in space.names:
        if name not in space.interval_names and name not in flat:
            flat[name] = np.full(grid.shape[0] * n_points, float(space[name].value))
    for name, values in sweep_values.items():
        flat[name] = np.repeat(values, grid.shape[0])
    samples = batch_samples(flat, {})
    in_window = model.inside(samples)
    inside = in_window.reshape(n_points, grid.shape[0]).any(axis=1)
    out = result.copy()
    dims = tuple(spec.names)
    count = np.ones(n_points, dtype=np.int64)
    for qoi in qois:
        # the from-rest bounds beside the widened ones: where responses coexist the report draws both branches
        out[f"{qoi}_from_rest"] = result[qoi].assign_attrs(long_name=f"bounds of {qoi} over the runs from rest")
        out[f"{qoi}_start"] = (
            (*dims, "bound"),
            np.full((*spec.shape, 2), "rest"),
            {"long_name": f"start whose attractor gives each bound of {qoi}"},
        )
    if in_window.any():
        # only the grid nodes inside a window: elsewhere the from-rest bounds already hold every response
        rows = np.nonzero(in_window)[0]
        found = model(samples.isel(sample=rows))
        point_of = rows // grid.shape[0]
        for qoi in qois:
            bounds = out[qoi].transpose(*dims, "bound").values.reshape(n_points, 2).copy()
            starts = out[f"{qoi}_start"].transpose(*dims, "bound").values.reshape(n_points, 2).astype(object)
            for column, (bound, better) in enumerate((("min", np.less), ("max", np.greater))):
                values = np.asarray(found[f"{qoi}_{bound}"].values, dtype=float)
                labels = np.asarray(found[f"{qoi}_{bound}_start"].values).astype(str)
                for row, point in enumerate(point_of):
                    if np.isfinite(values[row]) and better(values[row], bounds[point, column]):
                        bounds[point, column] = values[row]
                        starts[point, column] = labels[row]
            out[qoi] = ((*dims, "bound"), bounds.reshape(*spec.shape, 2), out[qoi].attrs)
            labelled = starts.astype(str).reshape(*spec.shape, 2)
            out[f"{qoi}_start"] = ((*dims, "bound"), labelled, out[f"{qoi}_start"].attrs)
        np.maximum.at(count, point_of, np.asarray(found["attractor_count"].values, dtype=np.int64))
        units = {name: str(getattr(space[name], "units", "")) for name in space.interval_names}
        out.update(_branches(found, rows, grid, units, qois, spec.shape, dims))
    count = count.reshape(spec.shape)
    inside = inside.reshape(spec.shape)
    out["attractor_count"] = (dims, count, {"units": "1", "long_name": "most attractors at any point of the box"})
    out["coexisting"] = (dims, count > 1, {"long_name": "responses coexist somewhere in the box"})
    out["in_window"] = (
        dims,
        inside,
        {"long_name": "the box reaches a coexistence window (bounds also scanned over attractors)"},
    )
    out.attrs.update(
        model_runs=int(out.attrs.get("model_runs", 0)) + int(model.runs) - counted,
        starts=json.dumps(model.settings.to_dict()),
        windows=json.dumps(model.windows.to_records()),
        window_points=int(model.window_points),
        window_seconds=float(model.windows.seconds),
    )
    return out


def _branches(
    found: xr.Dataset,
    rows: np.ndarray,
    grid: np.ndarray,
    units: Mapping[str, str],
    qois: Sequence[str],
    shape: tuple[int, ...],
    dims: tuple[str, ...],
) -> dict[str, Any]:
    """Both branches where responses coexist: at each sweep point, the in-window node where the coexisting
    responses' peak mesh forces differ most, each QoI's lowest and highest response there, and that node's
    interval parameter values. NaN where no node holds two responses.

    The bounds alone cannot show a second branch that lies inside the band (a wet-rail jump under the dry-rail
    upper bound); these two values are what the envelope figure draws as the branches."""
    n_points = int(np.prod(shape))
    # ``found`` holds the in-window rows of the (sweep point, grid node) table
    point_of, node = rows // grid.shape[0], rows % grid.shape[0]
    several = np.asarray(found["attractor_count"].values, dtype=np.int64) > 1
    high = np.asarray(found["peak_mesh_force_max"].values, dtype=float)
    low = np.asarray(found["peak_mesh_force_min"].values, dtype=float)
    spread = np.where(several & np.isfinite(high) & np.isfinite(low), high - low, -np.inf)
    chosen = np.full(n_points, -1)
    best = np.full(n_points, -np.inf)
    for row in np.nonzero(np.isfinite(spread))[0]:
        if spread[row] > best[point_of[row]]:
            best[point_of[row]], chosen[point_of[row]] = spread[row], row
    held = chosen >= 0
    out: dict[str, Any] = {}
    for qoi in qois:
        if f"{qoi}_max" not in found:
            continue
        pair = np.full((n_points, 2), np.nan)
        for column, bound in enumerate(("min", "max")):
            pair[held, column] = np.asarray(found[f"{qoi}_{bound}"].values, dtype=float)[chosen[held]]
        out[f"{qoi}_branches"] = (
            (*dims, "branch"),
            pair.reshape(*shape, 2),
            {"units": RUN_QOI_INFO[qoi][0], "long_name": f"{qoi} of the lowest and highest coexisting response"},
        )
    if out:
        out["branch"] = ("branch", ["lower", "upper"])
        for column, name in enumerate(units):
            where = np.full(n_points, np.nan)
            where[held] = grid[node[chosen[held]], column]
            out[f"branch_{name}"] = (
                dims,
                where.reshape(shape),
                {
                    "units": units[name],
                    "long_name": f"{name} at which the coexisting responses of the branches were found",
                },
            )
    return out


__all__ = [
    "GuidedStartModel",
    "guided_start_model",
    "analysis_windows",
    "combine",
    "widen_over_attractors",
    "NODE_PARAMETER",
]
