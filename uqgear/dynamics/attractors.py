"""Coexisting steady responses: every point run from several starts, the results grouped into attractors.

A gear pair with backlash can hold more than one steady response at one operating point (the jump
phenomenon): which one a run shows depends on where it starts. :class:`MultiStartSearch` runs each
point of a batch from

* **rest**: the static equilibrium (what every single run does);
* **up** and **down**: the final state of the neighbouring point of an up-sweep and of a
  down-sweep along ``sweep_variable`` (pinion speed by default), the points grouped by the values
  of every other input, each sweep starting from rest at its first point;
* **seeded-1 ... seeded-N**: states drawn uniformly (one SeedSequence, reproducible) from a box
  around the static equilibrium: each displacement within +-``box`` times the half backlash b,
  each velocity within +-``box`` times the larger of the mesh-frequency velocity across the
  backlash (omega_h b) and the rest start's own steady velocity of that coordinate,

and groups each point's steady responses into distinct attractors. Two runs reached the same
attractor when their QoIs agree (peak mesh force, RMS and peak-to-peak DTE within ``tolerance``
relative, time fractions in separation and back-side contact within ``tolerance`` absolute) and
their Poincare sets are close: the Hausdorff distance between the sets of (x, x') points, x in
units of b and x' of omega_h b, at most ``poincare_tolerance``. When either response is not
periodic both tolerances are 5 times wider (:data:`NON_PERIODIC_FACTOR`): a torus or a strange
attractor sampled twice gives two different point clouds and extremes. A run that has not settled
(a transient near an unstable orbit decays slowly) shows as a response of its own: keep
``n_periods`` long enough. Each attractor keeps its QoIs and regime (from its first start, in the order
rest, up, down, seeded), the share of starts that reached it and which starts.

The model is any ``evaluate(samples) -> Dataset`` that understands the sample variables
``initial_<state>`` (a start state) and returns ``final_<state>`` (:class:`StartedEvaluator`
wraps :func:`~uqgear.physics.integration.simulate_batch`); every stage is one batch call, the
sweeps one call per step (all groups and both directions together).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import UqgearError
from ..physics.design import Design
from ..physics.integration import build_batch
from .filled_batches import FilledBatches, join_samples
from .hausdorff import hausdorff
from .same_response import COMPARED_FRACTIONS, COMPARED_QOIS, copies_of_first, same_response, self_same
from .started_runs import FINAL_VARIABLES, INITIAL_VARIABLES, StartedEvaluator, final_variables
from .stress_qois import RUN_QOI_INFO, STRESS_QOIS

#: QoIs every attractor keeps.
ATTRACTOR_QOIS = (
    "peak_mesh_force",
    "dynamic_load_factor",
    "load_factor_rated",
    "dte_rms",
    "dte_peak_to_peak",
    "dte_mean",
    "acc_pinion_rms",
    "acc_gear_rms",
    "fraction_drive_contact",
    "fraction_separation",
    "fraction_back_contact",
    # present where the runs computed them (StartedEvaluator's ``stresses``)
    *STRESS_QOIS,
)


@dataclass(frozen=True)
class MultiStart:
    """Which starts every point gets, and how steady responses are grouped.

    Attributes
    ----------
    sweeps : bool
        Also start from the neighbouring point's final state in an up- and a down-sweep.
    seeded : int
        Random starts per point.
    box : float
        Half-width of the random box (module docstring).
    sweep_variable : str
        The sample variable the sweeps run along.
    tolerance, poincare_tolerance : float
        Grouping tolerances (module docstring).
    guided : bool
        Spend the extra starts only inside the speed windows where the periodic branches fold, double,
        lose stability or graze (:mod:`uqgear.dynamics.windows`), with the stable orbits found there as
        starts of their own; every other point runs from rest alone. False: every point gets every start.
    nodes : int
        Guided: continuations per interval of the node input (the adhesion torque), both ends included.
    margin : float
        Guided: rpm added on both sides of every window (at least the study's finest speed step, up to five
        margins).
    """

    sweeps: bool = True
    seeded: int = 2
    box: float = 1.0
    sweep_variable: str = "pinion_speed"
    tolerance: float = 0.02
    poincare_tolerance: float = 0.05
    guided: bool = False
    nodes: int = 5
    margin: float = 50.0

    def start_labels(self) -> list[str]:
        """The starts, in grouping order."""
        return ["rest"] + (["up", "down"] if self.sweeps else []) + [f"seeded-{i + 1}" for i in range(self.seeded)]

    def to_dict(self) -> dict[str, Any]:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any] | None, where: str = "starts") -> MultiStart:
        """Settings from a mapping of some of the attributes (the rest default)."""
        values = dict(values or {})
        unknown = sorted(set(values) - set(cls.__dataclass_fields__))
        if unknown:
            raise UqgearError(
                f"{where}.{unknown[0]}: unknown key; expected among {', '.join(cls.__dataclass_fields__)}"
            )
        settings = cls(**values)
        if isinstance(settings.seeded, bool) or not isinstance(settings.seeded, int) or not 0 <= settings.seeded <= 64:
            raise UqgearError(f"{where}.seeded: expected an integer in [0, 64]; got {settings.seeded!r}")
        for name in ("box", "tolerance", "poincare_tolerance"):
            value = getattr(settings, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= 10:
                raise UqgearError(f"{where}.{name}: expected a number in (0, 10]; got {value!r}")
        for name in ("sweeps", "guided"):
            if not isinstance(getattr(settings, name), bool):
                raise UqgearError(f"{where}.{name}: expected true or false; got {getattr(settings, name)!r}")
        if isinstance(settings.nodes, bool) or not isinstance(settings.nodes, int) or not 1 <= settings.nodes <= 64:
            raise UqgearError(f"{where}.nodes: expected an integer in [1, 64]; got {settings.nodes!r}")
        margin = settings.margin
        if isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0 <= margin <= 2000:
            raise UqgearError(f"{where}.margin: expected a number of rpm in [0, 2000]; got {margin!r}")
        return settings


def _velocity_scale(samples: xr.Dataset, design: Design) -> np.ndarray:
    """omega_h b per sample (mesh angular frequency times the half backlash)."""
    speed = np.asarray(samples["pinion_speed"].values, dtype=float)
    backlash = (
        np.asarray(samples["backlash"].values, dtype=float)
        if "backlash" in samples
        else np.full(speed.size, design.backlash)
    )
    return 2.0 * math.pi * design.z1 * speed / 60.0 * 0.5 * backlash


def sweep_order(samples: xr.Dataset, variable: str, reach: float | None = None) -> list[np.ndarray]:
    """The samples grouped by every input but ``variable``, each group sorted by it (sample indices).

    ``reach``: a group is cut where two neighbours lie farther apart than this in ``variable``. A sweep
    carries a state over a step as a run-up does only where the step is short; over a long one (two listed
    speeds 1200 rpm apart) the carried state follows no branch and is one more start at twice the cost.

    Examples
    --------
    >>> from uqgear.physics.integration import samples_from_mapping
    >>> samples = samples_from_mapping({"pinion_speed": [3850.0, 3800.0, 5000.0], "adhesion_torque": [2e4] * 3})
    >>> [g.tolist() for g in sweep_order(samples, "pinion_speed")]
    [[1, 0, 2]]
    >>> [g.tolist() for g in sweep_order(samples, "pinion_speed", reach=100.0)]
    [[1, 0], [2]]
    """
    if variable not in samples:
        return [np.array([i]) for i in range(samples.sizes["sample"])]
    others = [
        name
        for name in samples.data_vars
        if name != variable and name not in INITIAL_VARIABLES and samples[name].dims == ("sample",)
    ]
    n = samples.sizes["sample"]
    # one array of the other inputs, compared row by row as bytes: per-entry xarray access costs seconds on a
    # Sobol batch; + 0.0 makes -0.0 and 0.0 one key, as float comparison does
    table = np.stack([np.asarray(samples[name].values, dtype=float) for name in others], axis=1) if others else None
    rows = table + 0.0 if table is not None else np.zeros((n, 0))
    groups: dict[bytes, list[int]] = {}
    for index in range(n):
        groups.setdefault(rows[index].tobytes(), []).append(index)
    values = np.asarray(samples[variable].values, dtype=float)
    ordered = [np.asarray(members)[np.argsort(values[members], kind="stable")] for members in groups.values()]
    if reach is None:
        return ordered
    cut: list[np.ndarray] = []
    for members in ordered:
        gaps = np.nonzero(np.diff(values[members]) > reach)[0]
        cut += np.split(members, gaps + 1) if gaps.size else [members]
    return cut


def with_starts(samples: xr.Dataset, index: np.ndarray, states: np.ndarray) -> xr.Dataset:
    """The samples ``index`` with the start states ``states`` (one row each; NaN: from rest) as ``initial_<state>``."""
    # one assignment: a merge per variable costs more than a small batch's runs
    return samples.isel(sample=index).assign(
        {name: ("sample", states[:, column]) for column, name in enumerate(INITIAL_VARIABLES)}
    )


def _final_states(result: xr.Dataset) -> np.ndarray:
    return np.stack([np.asarray(result[name].values, dtype=float) for name in FINAL_VARIABLES], axis=1)


def _sweep_runs(
    evaluate: Callable[[xr.Dataset], xr.Dataset],
    samples: xr.Dataset,
    rest: xr.Dataset,
    groups: Sequence[np.ndarray],
    rest_index: np.ndarray | None = None,
    starts: Mapping[str, np.ndarray] | None = None,
    entry: Mapping[str, np.ndarray] | None = None,
) -> dict[str, xr.Dataset]:
    """Up- and down-sweep runs of every sample: one batch per step over all groups and both directions.

    ``rest`` holds the rest runs of the samples ``rest_index`` (default: all), which must include
    each group's first and last member that ``entry`` does not give: the sweeps start there. ``entry``
    (``up`` and ``down``, arrays of shape (n_samples, 6), NaN rows where none) gives the state a sweep
    enters a sample with instead of its neighbour's in the group (the final state of a point outside the
    samples). ``starts`` (``up`` and ``down``) receive the state each run started from.
    """
    rows_of = {
        int(sample): row
        for row, sample in enumerate(np.arange(samples.sizes["sample"]) if rest_index is None else rest_index)
    }
    finals = _final_states(rest) if rows_of and all(name in rest for name in FINAL_VARIABLES) else None

    def entering(direction: str, sample: int) -> np.ndarray | None:
        state = None if entry is None or direction not in entry else np.asarray(entry[direction][sample], float)
        return state if state is not None and np.all(np.isfinite(state)) else None

    carried: dict[str, dict[int, np.ndarray]] = {"up": {}, "down": {}}  # sample index -> the final state it passes on
    from_rest: dict[str, list[int]] = {"up": [], "down": []}  # first points whose sweep run is their rest run
    longest = max((len(members) for members in groups), default=0)
    steps: list[xr.Dataset] = []
    step_samples: list[int] = []  # the sample of each run of the steps, in order
    step_directions: list[str] = []
    for step in range(longest):
        index, states, directions = [], [], []
        for direction in ("up", "down"):
            for members in groups:
                if step >= len(members):
                    continue
                ordered = members if direction == "up" else members[::-1]
                sample = int(ordered[step])
                state = entering(direction, sample)
                if state is None and step == 0:
                    assert finals is not None  # the caller's condition: rest runs with final states at the ends
                    carried[direction][sample] = finals[rows_of[sample]]
                    from_rest[direction].append(sample)
                    continue
                index.append(sample)
                states.append(state if state is not None else carried[direction][int(ordered[step - 1])])
                directions.append(direction)
        if not index:
            continue
        result = evaluate(with_starts(samples, np.array(index), np.array(states)))
        if starts is not None:
            for sample, direction, state in zip(index, directions, states):
                starts[direction][sample] = state
        ends = _final_states(result)
        for row, (sample, direction) in enumerate(zip(index, directions)):
            carried[direction][sample] = ends[row]
        steps.append(result)
        step_samples += index
        step_directions += directions
    # the steps joined once, each direction's runs taken out once: an isel per step and direction costs more
    # than the small batches' runs
    joined = join_samples(steps) if steps else None
    out = {}
    for direction in ("up", "down"):
        # the first point of a sweep that enters from nothing is its rest run
        firsts = np.array(from_rest[direction], dtype=int)
        parts = [(firsts, rest.isel(sample=[rows_of[int(i)] for i in firsts]))] if firsts.size else []
        mine = np.nonzero(np.asarray(step_directions) == direction)[0]
        if mine.size:
            assert joined is not None
            parts.append((np.asarray(step_samples, dtype=int)[mine], joined.isel(sample=mine)))
        order = np.concatenate([indices for indices, _ in parts])
        out[direction] = join_samples([part for _, part in parts]).isel(sample=np.argsort(order, kind="stable"))
    return out


def up_down_sweeps(
    evaluate: Callable[[xr.Dataset], xr.Dataset], samples: xr.Dataset, variable: str = "pinion_speed"
) -> dict[str, xr.Dataset]:
    """Brute-force up- and down-sweeps along ``variable``: each run starts from its neighbour's final state.

    Only the first point of each sweep starts from rest. Returns ``{"up": runs, "down": runs}``, each
    in the order of ``samples`` (one batch call per sweep step, both directions and every group of
    the other inputs together).

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.physics.integration import samples_from_mapping
    >>> design = uqgear.load_design("locomotive")
    >>> speeds = [3550.0, 3600.0, 3650.0, 3700.0]
    >>> samples = samples_from_mapping({"pinion_speed": speeds, "adhesion_torque": [21150.0] * 4})
    >>> runs = up_down_sweeps(StartedEvaluator(design, {"n_periods": 1500, "keep_periods": 300}), samples)
    >>> [round(float(f) / 1e3) for f in runs["down"]["peak_mesh_force"].values]
    [102, 177, 178, 180]
    """
    groups = sweep_order(samples, variable)
    ends = np.unique(np.concatenate([[members[0], members[-1]] for members in groups])).astype(int)
    rest = evaluate(with_starts(samples, ends, np.full((ends.size, 6), np.nan)))
    return _sweep_runs(evaluate, samples, rest, groups, ends)


class MultiStartSearch:
    """Run every point of a batch from several starts and group the steady responses into attractors.

    Parameters
    ----------
    settings : MultiStart, optional
    seed : int or SeedSequence
        Seed of the random starts.

    Attributes
    ----------
    runs_ : xarray.Dataset
        Every run: dims ``sample``, ``start`` (and ``period``): QoIs, ``regime``, Poincare points,
        ``attractor`` (the index of the attractor it reached).
    attractors_ : xarray.Dataset
        Dims ``sample``, ``attractor``: QoIs, ``regime``, ``share`` (of starts), ``first_start``,
        ``starts`` (comma-separated labels), ``attractor_count`` per sample; padded with NaN / ''.
    model_runs_ : int
        Model runs made.
    start_states_ : dict of ndarray
        Per start label, the state each sample's run started from (shape (n_samples, 6)): NaN where
        it started at rest (the static equilibrium) or made no run of its own.

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.physics.integration import samples_from_mapping
    >>> design = uqgear.load_design("locomotive")
    >>> samples = samples_from_mapping({"pinion_speed": [3600.0, 3700.0], "adhesion_torque": [21150.0] * 2})
    >>> model = StartedEvaluator(design, {"n_periods": 1500, "keep_periods": 300})
    >>> found = MultiStartSearch(MultiStart(seeded=0)).fit(model, samples)
    >>> [int(n) for n in found.attractors_["attractor_count"].values]
    [2, 1]
    """

    def __init__(self, settings: MultiStart | None = None, seed: Any = 0) -> None:
        self.settings = settings or MultiStart()
        self.seed = seed

    def fit(
        self,
        evaluate: Callable[[xr.Dataset], xr.Dataset],
        samples: xr.Dataset,
        design: Design | None = None,
        extra_states: Mapping[str, np.ndarray] | None = None,
        rest: xr.Dataset | None = None,
        seeded_rows: np.ndarray | None = None,
        sweep_entry: Mapping[str, np.ndarray] | None = None,
        sweep_reach: float | None = None,
    ) -> MultiStartSearch:
        """Run the starts and group the responses (``design`` only for the box's scales; default the
        evaluator's ``design``).

        ``extra_states`` adds starts of its own: label -> states of shape (n_samples, 6), a row of NaN
        where a sample has no such start (its entry is left out of the grouping). They come after
        the sweeps and before the random starts in the grouping order (states on known orbits,
        :meth:`uqgear.dynamics.windows.CoexistenceWindows.orbit_states`).

        ``rest`` gives the rest runs already made (outputs of the same model with ``regime``, in the order
        of ``samples``); they are not run again, and without final states only the sweeps' first points
        are. ``seeded_rows`` (booleans, one per sample; default all) says which samples get the random
        starts; the others' random entries are left out of the grouping, and the chosen ones start from the
        same states as with every sample chosen. ``sweep_entry`` (``up``, ``down``: states of shape (n_samples, 6),
        NaN rows where none) gives the state a sweep enters a sample with from outside ``samples``: the final
        state of the point before it (up) or after it (down) on a grid of which ``samples`` is a part, so that a
        sweep through a window of the grid enters it as a sweep over the whole grid would."""
        if "sample" not in samples.dims or "pinion_speed" not in samples:
            raise UqgearError("samples: expected a Dataset with dimension 'sample' and variable 'pinion_speed'")
        design = design if design is not None else getattr(evaluate, "design", None)
        settings = self.settings
        n = samples.sizes["sample"]
        runs = 0
        if rest is None:
            rest = evaluate(with_starts(samples, np.arange(n), np.full((n, 6), np.nan)))
            runs += n
        stages: dict[str, xr.Dataset] = {"rest": rest}
        self.start_states_ = {"rest": np.full((n, 6), np.nan)}
        requested: dict[str, np.ndarray] = {}
        for label, states in (extra_states or {}).items():
            states = np.asarray(states, dtype=float)
            if states.shape != (n, 6):
                raise UqgearError(f"extra_states[{label!r}]: expected shape ({n}, 6); got {states.shape}")
            requested[label] = states
        if settings.seeded:
            if design is None:
                raise UqgearError("design: needed for the random starts' box (pass design=)")
            starts = self._seeded_states(samples, rest, design, seeded_rows)
            if seeded_rows is not None:
                starts[~np.tile(np.asarray(seeded_rows, dtype=bool), settings.seeded)] = np.nan
            for k in range(settings.seeded):
                requested[f"seeded-{k + 1}"] = starts[k * n : (k + 1) * n]
        # the orbit and random starts wait for no other run: they ride in the sweeps' small step batches
        riders = _rider_samples(samples, requested)
        filled = FilledBatches(evaluate, riders) if settings.sweeps and riders is not None else None
        if settings.sweeps:
            runs += self._sweep_stages(filled or evaluate, samples, rest, stages, sweep_entry, sweep_reach)
        ridden = evaluate if filled is None else (lambda _: filled.remaining())
        stages.update(_extra_stages(ridden, samples, requested, rest))
        self.start_states_.update(requested)
        runs += sum(int(np.all(np.isfinite(states), axis=1).sum()) for states in requested.values())
        labels = settings.start_labels()
        if extra_states:
            at = labels.index("down") + 1 if "down" in labels else 1
            labels = labels[:at] + list(extra_states) + labels[at:]
        self.runs_ = _stacked(stages, labels, n)
        self.attractors_ = group_attractors(self.runs_, design, settings)
        self.runs_["attractor"] = (("sample", "start"), self.attractors_.attrs.pop("_membership"))
        self.model_runs_ = int(runs)
        return self

    def _sweep_stages(
        self,
        evaluate: Callable[[xr.Dataset], xr.Dataset],
        samples: xr.Dataset,
        rest: xr.Dataset,
        stages: dict,
        entry: Mapping[str, np.ndarray] | None = None,
        reach: float | None = None,
    ) -> int:
        """Add the ``up`` and ``down`` stages (and their start states) of :meth:`fit`; returns the runs made."""
        n = samples.sizes["sample"]
        groups = sweep_order(samples, self.settings.sweep_variable, reach)
        starts = {direction: np.full((n, 6), np.nan) for direction in ("up", "down")}
        entered = {
            direction: np.all(np.isfinite(np.asarray(entry[direction], dtype=float)), axis=1)
            if entry is not None and direction in entry
            else np.zeros(n, dtype=bool)
            for direction in ("up", "down")
        }
        # a sweep's first point is its rest run unless the sweep enters it with a state from outside
        runs = 2 * n - sum(int(not entered["up"][m[0]]) + int(not entered["down"][m[-1]]) for m in groups)
        swept = [m for m in groups if len(m) > 1 or entered["up"][m[0]] or entered["down"][m[-1]]]
        if swept and all(name in rest for name in FINAL_VARIABLES):
            stages.update(_sweep_runs(evaluate, samples, rest, groups, starts=starts, entry=entry))
        elif swept:
            # the sweeps start from the rest runs' final states at each group's ends (where nothing enters them)
            needed = [int(m[0]) for m in swept if not entered["up"][m[0]]]
            needed += [int(m[-1]) for m in swept if not entered["down"][m[-1]]]
            ends = np.unique(np.asarray(needed, dtype=int))
            edges = evaluate(with_starts(samples, ends, np.full((ends.size, 6), np.nan))) if ends.size else rest
            runs += ends.size
            swept_rows = np.sort(np.concatenate(swept)).astype(int)
            for direction, part in _sweep_runs(evaluate, samples, edges, swept, ends, starts, entry).items():
                # a point alone in its group, entered from nowhere, has no sweep neighbour: its sweep starts are
                # its rest run
                stages[direction] = _put_rows(rest, swept_rows, part)
        else:
            # every point alone in its sweep, entered from nowhere: its sweep starts are its rest run
            stages.update({"up": rest, "down": rest})
        self.start_states_.update(starts)
        return runs

    def _seeded_states(
        self, samples: xr.Dataset, rest: xr.Dataset, design: Design, rows: np.ndarray | None = None
    ) -> np.ndarray:
        """Every sample's random start states, shape (seeded * n, 6); only the samples ``rows`` (booleans, default
        all) get their box's centre, the others NaN: the draws are the same whichever samples are chosen."""
        n = samples.sizes["sample"]
        settings = self.settings
        # effect parameters (``family.parameter``) left out: the random box is centred on the plain model's
        # static state, which the effects shift by far less than the box's width
        dropped = [v for v in samples.data_vars if v in INITIAL_VARIABLES or "." in str(v)]
        chosen = np.arange(n) if rows is None else np.nonzero(np.asarray(rows, dtype=bool))[0]
        static = np.full((n, 6), np.nan)
        if chosen.size:
            inputs = samples.drop_vars(dropped).isel(sample=chosen)
            static[chosen] = np.stack([setup.static_state() for setup in build_batch(design, inputs)])
        half_backlash = 0.5 * (
            np.asarray(samples["backlash"].values, float) if "backlash" in samples else np.full(n, design.backlash)
        )
        if all(name in rest for name in FINAL_VARIABLES):
            steady = np.abs(_final_states(rest)[:, 3:])
        else:
            # rest runs without final states: the DTE velocity's largest value on the Poincare section
            steady = np.zeros((n, 3))
            steady[:, 2] = np.nanmax(np.abs(rest["poincare_x_velocity"].transpose("sample", "period").values), axis=1)
        velocity = np.maximum(_velocity_scale(samples, design)[:, None], steady)
        widths = settings.box * np.concatenate([np.repeat(half_backlash[:, None], 3, axis=1), velocity], axis=1)
        seed = self.seed if isinstance(self.seed, np.random.SeedSequence) else np.random.SeedSequence(self.seed)
        rng = np.random.default_rng(seed)
        draws = rng.uniform(-1.0, 1.0, size=(settings.seeded, n, 6))
        return (static[None] + draws * widths[None]).reshape(settings.seeded * n, 6)


def _stacked(stages: Mapping[str, xr.Dataset], labels: Sequence[str], n: int) -> xr.Dataset:
    """The runs of every start on dim ``start`` (in the order of ``labels``), the variables all stages share."""
    # stages from other models (given rest runs) may carry variables of their own
    shared = set.intersection(*(set(stage.data_vars) for stage in stages.values()))
    stacked = xr.concat(
        [
            stages[label][[name for name in stages[label].data_vars if name in shared]]
            .drop_vars([v for v in INITIAL_VARIABLES if v in stages[label].variables])
            .assign_coords(sample=np.arange(n))
            for label in labels
        ],
        dim="start",
        coords="minimal",
        compat="override",
        join="override",
        combine_attrs="drop_conflicts",
    )
    return stacked.assign_coords(start=("start", list(labels)))


def _put_rows(target: xr.Dataset, rows: np.ndarray, part: xr.Dataset) -> xr.Dataset:
    """A copy of ``target`` with its samples ``rows`` replaced by the samples of ``part`` (in that order)."""
    out = target.copy()
    written: dict[Any, Any] = {}
    for name in list(out.data_vars):
        # plain variables and one update: a DataArray per variable copies every sample coordinate along
        if name in part.data_vars and "sample" in out.variables[name].dims:
            variable = out.variables[name]
            dims = ("sample", *(dim for dim in variable.dims if dim != "sample"))
            values = variable.transpose(*dims).values.copy()
            column = part.variables[name].transpose(*dims).values
            if values.dtype.kind in "US" and column.dtype.itemsize > values.dtype.itemsize:
                values = values.astype(column.dtype)
            values[rows] = column
            written[name] = (dims, values, variable.attrs)
    out.update(written)
    return out


def _picked(requested: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per stage, the samples with a start state of their own (rows without NaN)."""
    return {label: np.nonzero(np.all(np.isfinite(states), axis=1))[0] for label, states in requested.items()}


def _rider_samples(samples: xr.Dataset, requested: Mapping[str, np.ndarray]) -> xr.Dataset | None:
    """The runs of every stage from its start states as one batch, stage after stage (None: no run)."""
    picked = _picked(requested)
    index = np.concatenate([np.zeros(0, dtype=np.int64), *picked.values()])
    if index.size == 0:
        return None
    return with_starts(samples, index, np.concatenate([requested[label][rows] for label, rows in picked.items()]))


def _extra_stages(
    evaluate: Callable[[xr.Dataset], xr.Dataset],
    samples: xr.Dataset,
    requested: Mapping[str, np.ndarray],
    template: xr.Dataset,
) -> dict[str, xr.Dataset]:
    """The runs of every stage from its start states (label -> states of shape (n_samples, 6)), all in one batch:
    each run is computed from its own inputs, so one batch gives the numbers of one batch per stage, at the cost
    of one call. A row of NaN gives NaN outputs and no Poincare points (no run); ``template`` (runs of the same
    model) gives the layout."""
    blank = template.copy(deep=True)
    cleared: dict[Any, Any] = {}
    for name in list(blank.data_vars):
        # plain arrays and one update: a DataArray per variable copies every sample coordinate along
        variable = blank.variables[name]
        if variable.dtype.kind == "f":
            cleared[name] = (variable.dims, np.full(variable.shape, np.nan, dtype=variable.dtype), variable.attrs)
        elif variable.dtype.kind in "US":
            cleared[name] = (variable.dims, np.full(variable.shape, "", dtype=variable.dtype), variable.attrs)
    blank.update(cleared)
    picked = _picked(requested)
    riders = _rider_samples(samples, requested)
    if riders is None:
        return dict.fromkeys(requested, blank)
    result = evaluate(riders)
    out, at = {}, 0
    for label, rows in picked.items():
        out[label] = _put_rows(blank, rows, result.isel(sample=slice(at, at + rows.size))) if rows.size else blank
        at += rows.size
    return out


def group_attractors(runs: xr.Dataset, design: Design | None, settings: MultiStart) -> xr.Dataset:
    """Group the runs of every sample (dims ``sample``, ``start``) into attractors (see the module docstring)."""
    n, labels = runs.sizes["sample"], [str(v) for v in runs["start"].values]
    grouping = _group_runs(runs, design, settings)
    members = grouping.members
    width = max((len(groups) for groups in members), default=0)
    data: dict[str, Any] = {}
    for name in ATTRACTOR_QOIS:
        if name not in runs:
            continue
        table = runs[name].transpose("sample", "start").values
        values = np.full((n, width), np.nan)
        for i, groups in enumerate(members):
            for k, group in enumerate(groups):
                values[i, k] = float(table[i, group[0]])
        data[name] = (
            ("sample", "attractor"),
            values,
            {"units": RUN_QOI_INFO[name][0], "long_name": RUN_QOI_INFO[name][1]},
        )
    data.update(_attractor_starts(members, grouping.regimes, labels, width))
    out = xr.Dataset(data, coords={"attractor": ("attractor", np.arange(width))})
    out.attrs.update(settings.to_dict())
    out.attrs["_membership"] = grouping.membership
    return out


@dataclass(frozen=True)
class _Grouping:
    """The runs of every sample grouped into attractors.

    ``members[i][k]``: the starts of sample ``i`` that reached its attractor ``k`` (first found first);
    ``membership`` (sample, start): the attractor each start reached, -1 where it did not run;
    ``regimes`` (sample, start): each run's regime.
    """

    members: list[list[list[int]]]
    membership: np.ndarray
    regimes: np.ndarray


def _group_runs(runs: xr.Dataset, design: Design | None, settings: MultiStart) -> _Grouping:
    """Compare each sample's runs start by start: a run is the first attractor it matches, or a new one."""
    n, n_starts = runs.sizes["sample"], runs.sizes["start"]
    half_backlash = float(design.half_backlash) if design is not None else float(runs.attrs.get("half_backlash", 1.0))
    speed = np.asarray(runs["pinion_speed"].values if "pinion_speed" in runs.coords else runs["pinion_speed"].values)
    speed = speed if speed.ndim == 1 else speed[0]
    z1 = design.z1 if design is not None else int(runs.attrs.get("design_z1", 1))
    members: list[list[list[int]]] = []
    membership = np.zeros((n, n_starts), dtype=np.int64)
    # plain arrays once: per-entry xarray indexing costs more than the comparisons
    compared = {
        name: runs[name].transpose("sample", "start").values.astype(float)
        for name in (*COMPARED_QOIS, *COMPARED_FRACTIONS)
    }
    regimes = runs["regime"].transpose("sample", "start").values.astype(str)
    poincare_x = runs["poincare_x"].transpose("sample", "start", "period").values
    poincare_v = runs["poincare_x_velocity"].transpose("sample", "start", "period").values
    # a start that did not run (no finite Poincare point) is left out before its entry is built
    ran = np.any(np.isfinite(poincare_x) & np.isfinite(poincare_v), axis=2)
    copies = copies_of_first(compared, regimes, poincare_x, poincare_v)
    for i in range(n):
        omega_b = 2.0 * math.pi * z1 * float(np.ravel(speed)[i]) / 60.0 * half_backlash
        found: list[dict[str, Any]] = []
        groups: list[list[int]] = []
        for j in range(n_starts):
            if not ran[i, j]:
                membership[i, j] = -1
                continue
            if j and copies[i, j] and groups and groups[0][0] == 0 and self_same(found[0]):
                membership[i, j] = 0
                # the first start's run again, bit for bit (a sweep's end, a start alone in its sweep): its attractor
                groups[0].append(j)
                continue
            points = np.stack([poincare_x[i, j] / half_backlash, poincare_v[i, j] / omega_b], axis=1)
            entry: dict[str, Any] = {name: float(values[i, j]) for name, values in compared.items()}
            entry.update(regime=regimes[i, j], points=points[np.all(np.isfinite(points), axis=1)])
            match = next((k for k, other in enumerate(found) if same_response(other, entry, settings)), None)
            if match is None:
                found.append(entry)
                groups.append([j])
                membership[i, j] = len(found) - 1
            else:
                groups[match].append(j)
                membership[i, j] = match
        members.append(groups)
    return _Grouping(members, membership, regimes)


def _attractor_starts(members: list[list[list[int]]], regimes: np.ndarray, labels: list[str],
                      width: int) -> dict[str, Any]:
    """Per attractor: its regime, the starts that reached it (the first, all, their share); per sample the count."""
    n = len(members)
    regime = np.full((n, width), "", dtype=object)
    first = np.full((n, width), "", dtype=object)
    which = np.full((n, width), "", dtype=object)
    share = np.full((n, width), np.nan)
    for i, groups in enumerate(members):
        total = sum(len(group) for group in groups)
        for k, group in enumerate(groups):
            regime[i, k] = regimes[i, group[0]]
            first[i, k] = labels[group[0]]
            which[i, k] = ",".join(labels[j] for j in group)
            share[i, k] = len(group) / total
    return {
        "regime": (("sample", "attractor"), regime.astype(str), {"long_name": "response regime of the attractor"}),
        "first_start": (("sample", "attractor"), first.astype(str), {"long_name": "first start that reached it"}),
        "starts": (("sample", "attractor"), which.astype(str), {"long_name": "starts that reached it"}),
        "share": (
            ("sample", "attractor"),
            share,
            {"units": "1", "long_name": "share of the starts that reached it"},
        ),
        "attractor_count": (
            "sample",
            np.array([len(g) for g in members], dtype=np.int64),
            {"units": "1", "long_name": "distinct steady responses found"},
        ),
    }


def extremes_over_attractors(attractors: xr.Dataset, qois: Sequence[str]) -> xr.Dataset:
    """Per sample, the largest and smallest value of each QoI over its attractors, with which attractor and
    first start gave it: ``<qoi>_max``, ``<qoi>_min``, ``<qoi>_max_start``, ``<qoi>_min_start`` and
    ``<qoi>_max_attractor``, ``<qoi>_min_attractor``."""
    out = xr.Dataset()
    for name in qois:
        values = attractors[name].values
        finite = np.where(np.isfinite(values), values, np.nan)
        for bound, pick in (("max", np.nanargmax), ("min", np.nanargmin)):
            held = np.asarray(np.isfinite(finite).any(axis=1))  # a sample without any finite value gives attractor 0
            index = np.where(held, pick(np.where(held[:, None], finite, 0.0), axis=1), 0).astype(np.int64)
            rows = np.arange(values.shape[0])
            units, long_name = RUN_QOI_INFO[name]
            out[f"{name}_{bound}"] = (
                "sample",
                finite[rows, index],
                {"units": units, "long_name": f"{bound} over attractors of {name}"},
            )
            out[f"{name}_{bound}_attractor"] = ("sample", index, {"long_name": f"attractor giving {name}_{bound}"})
            out[f"{name}_{bound}_start"] = (
                "sample",
                attractors["first_start"].values[rows, index].astype(str),
                {"long_name": f"first start reaching the attractor of {name}_{bound}"},
            )
    return out


__all__ = [
    "MultiStart",
    "MultiStartSearch",
    "StartedEvaluator",
    "final_variables",
    "group_attractors",
    "extremes_over_attractors",
    "sweep_order",
    "up_down_sweeps",
    "with_starts",
    "hausdorff",
    "INITIAL_VARIABLES",
    "FINAL_VARIABLES",
    "ATTRACTOR_QOIS",
]
