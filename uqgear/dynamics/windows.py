"""Where a gear can hold more than one steady response: speed windows found by continuation.

A backlash gear holds coexisting responses only near the bifurcations of its periodic branches:
between the two folds of a hysteresis loop, where a branch has lost stability (a Neimark-Sacker
torus, a period doubling, the unstable middle of a fold pair) and next to the grazing points where
the teeth start to separate. :func:`find_windows` follows the period-1 branch in pinion speed
(:class:`~uqgear.dynamics.continuation.Continuation`, with the branches born at its period
doublings) at a few values (*nodes*) of one other input, usually the adhesion torque T2, and
records at each node

* the **windows**: the parameter hull of every unstable stretch of a branch (widened to the stable
  points on either side), the hull of every doubled branch and every located bifurcation point,
  each widened by ``margin`` on both sides and merged where they overlap;
* the **stable stretches**: runs of consecutive stable orbits, whose states at mesh phase 0 serve
  as start states of runs inside a window (:meth:`CoexistenceWindows.orbit_states`).

Between two nodes a window moves continuously with the node input, so the windows at a value
between two nodes are each node's windows joined with the nearest window of the other node (their
hull): a window drifting across the speed axis between the nodes stays covered. Where a branch
folds, doubles or loses stability (:meth:`CoexistenceWindows.branching`) a window is joined only with
its counterpart, the nearest window where the two overlap or are each other's nearest: one without a
counterpart at the other node (born or gone between them, or moved out of the speeds followed) is not
joined with a window far away, whose hull would span the speeds between them. Inputs other than
the speed and the node input are held at the values the windows were found at; a sample that
changes the mesh-mode frequency (mesh stiffness scale, bearing stiffnesses, masses) is tested at
its *equivalent speed*, the speed at which its mesh frequency stands in the same ratio to its
highest natural frequency as the sample's does (:func:`equivalent_speeds`): the windows sit around
the mesh resonances.

The windows are a guide for where extra starts are worth their cost
(:class:`uqgear.study.guided_starts.GuidedStartModel`), not a proof that nothing coexists elsewhere:
a window born and gone between two nodes, and responses coexisting away from every bifurcation of
the period-1 branch family (an isolated branch), are not seen.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import UqgearError
from ..common.forked import map_forked
from ..physics.design import Design
from ..physics.model import natural_frequencies
from ..physics.stiffness import stiffness_tables
from ..physics.threads import default_threads
from .continuation import Continuation, ContinuationSettings
from .shooting import PoincareMap, setup_at

#: Windows are looked for in this sweep variable.
SWEEP_VARIABLE = "pinion_speed"
#: Sample variables that move the natural frequencies (tested at the equivalent speed).
MODAL_VARIABLES = ("mesh_stiffness_scale", "k1", "k2", "m1", "m2", "I1", "I2")
#: Window kinds of a contact boundary crossed by a stable orbit: where a window has no other kind, the branch
#: stays stable and one-valued through it.
GRAZING_KINDS = ("grazing_separation", "grazing_back_side")
#: Location tolerance of the continuation as a fraction of the speed range: a window is widened by
#: a margin of tens of rpm, so locating its edges to 1e-3 of the range (5 rpm on 1000-6000 rpm)
#: is enough and cheaper than the continuation's default 1e-5.
LOCATION_TOLERANCE = 1e-3


@dataclass(frozen=True)
class Window:
    """A speed span where responses may coexist, at one node.

    Attributes
    ----------
    low, high : float
        The span in rpm, margin included.
    kinds : tuple of str
        What made it: ``unstable`` (a stretch of unstable orbits), ``doubled`` (a period-doubled
        branch) and the bifurcation types located in it (``fold``, ``grazing_separation``, ...).
    """

    low: float
    high: float
    kinds: tuple[str, ...]

    def distance(self, other: Window) -> float:
        """Gap between the two spans (0 where they overlap)."""
        return max(0.0, max(self.low, other.low) - min(self.high, other.high))

    def hull(self, other: Window) -> Window:
        kinds = tuple(dict.fromkeys((*self.kinds, *other.kinds)))
        return Window(min(self.low, other.low), max(self.high, other.high), kinds)


@dataclass(frozen=True)
class StableStretch:
    """Consecutive stable orbits of one branch, sorted by speed.

    Attributes
    ----------
    period : int
        n of the period-n orbits.
    speeds : ndarray
        Pinion speeds of the orbits (ascending).
    states : ndarray of shape (len(speeds), 6)
        Each orbit's state at mesh phase 0.
    """

    period: int
    speeds: np.ndarray
    states: np.ndarray

    def state_at(self, speed: float) -> np.ndarray | None:
        """The orbit state at ``speed`` (linear between neighbouring orbits); None outside the stretch."""
        if self.speeds.size == 0 or not self.speeds[0] <= speed <= self.speeds[-1]:
            return None
        return np.array([np.interp(speed, self.speeds, self.states[:, k]) for k in range(6)])


@dataclass(frozen=True)
class NodeWindows:
    """The windows and stable stretches found at one value of the node input."""

    value: float
    windows: tuple[Window, ...]
    stretches: tuple[StableStretch, ...]
    bifurcations: tuple[tuple[str, float], ...]


@dataclass(frozen=True)
class CoexistenceWindows:
    """Speed windows of possible coexistence at nodes of one input (module docstring).

    Attributes
    ----------
    node_parameter : str or None
        The input the nodes lie along (None: one node, no such input).
    nodes : tuple of NodeWindows
        Sorted by value.
    margin : float
        rpm added on both sides of every window.
    speed_range : tuple of float
        The speeds followed.
    fixed : dict
        The other inputs the windows were found at.
    seconds : float
        Time spent finding them.
    orbit_passes : int
        Mesh periods the continuation integrated.
    """

    node_parameter: str | None
    nodes: tuple[NodeWindows, ...]
    margin: float
    speed_range: tuple[float, float]
    fixed: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0
    orbit_passes: int = 0

    def spans_at(self, value: float, counterparts: bool = False) -> list[Window]:
        """The windows at a value of the node input: between two nodes each node's windows joined with the nearest
        window of the other node (with ``counterparts``, only with their counterpart: module docstring); beyond
        the outer nodes, the outer node's windows."""
        values = np.array([node.value for node in self.nodes])
        if len(self.nodes) == 1 or not np.isfinite(value):
            return list(self.nodes[0].windows)
        if value <= values[0]:
            return list(self.nodes[0].windows)
        if value >= values[-1]:
            return list(self.nodes[-1].windows)
        upper = int(np.searchsorted(values, value, side="right"))
        below, above = self.nodes[upper - 1], self.nodes[upper]
        spans = []
        for own, other in ((below.windows, above.windows), (above.windows, below.windows)):
            for window in own:
                if counterparts:
                    nearest = _counterpart(window, own, other)
                else:
                    nearest = min(other, key=window.distance, default=None)
                spans.append(window if nearest is None else window.hull(nearest))
        return spans

    def contains(
        self, speeds: Sequence[float] | np.ndarray, values: Sequence[float] | np.ndarray | None = None
    ) -> np.ndarray:
        """Which (speed, node value) pairs lie in a window."""
        return self._inside(speeds, values, lambda window: True, counterparts=False)

    def branching(
        self, speeds: Sequence[float] | np.ndarray, values: Sequence[float] | np.ndarray | None = None
    ) -> np.ndarray:
        """Which (speed, node value) pairs lie in a window that more than a grazing point made: where a branch
        folds, doubles or loses stability (:data:`GRAZING_KINDS`), joined across the nodes with counterparts only."""
        return self._inside(
            speeds, values, lambda window: not set(window.kinds) <= set(GRAZING_KINDS), counterparts=True
        )

    def _inside(
        self,
        speeds: Sequence[float] | np.ndarray,
        values: Sequence[float] | np.ndarray | None,
        counts: Callable[[Window], bool],
        counterparts: bool,
    ) -> np.ndarray:
        """Which (speed, node value) pairs lie in a window that ``counts`` (:meth:`spans_at`)."""
        speed_array = np.asarray(speeds, dtype=float)
        value_array = np.full(speed_array.shape, math.nan) if values is None else np.asarray(values, dtype=float)
        cache: dict[float, list[Window]] = {}
        inside = np.zeros(speed_array.shape, dtype=np.bool_)
        for index, (speed, value) in enumerate(zip(speed_array.ravel(), value_array.ravel())):
            key = float(value)
            spans = cache.get(key)
            if spans is None:
                spans = cache[key] = [window for window in self.spans_at(key, counterparts) if counts(window)]
            inside.flat[index] = any(window.low <= speed <= window.high for window in spans)
        return inside

    def nearest_node(self, value: float) -> NodeWindows:
        if not np.isfinite(value) or len(self.nodes) == 1:
            return self.nodes[0]
        return min(self.nodes, key=lambda node: abs(node.value - value))

    def orbit_states(self, speed: float, value: float = math.nan) -> list[np.ndarray]:
        """States on every stable orbit the nearest node holds at ``speed`` (start states of extra runs)."""
        found = (stretch.state_at(speed) for stretch in self.nearest_node(value).stretches)
        return [state for state in found if state is not None]

    def to_records(self) -> list[dict[str, Any]]:
        """Every node's windows as plain values (for result attributes and reports)."""
        return [
            {
                "value": node.value,
                "windows": [[window.low, window.high, list(window.kinds)] for window in node.windows],
                "bifurcations": [[kind, location] for kind, location in node.bifurcations],
            }
            for node in self.nodes
        ]


def _counterpart(window: Window, own: Sequence[Window], other: Sequence[Window]) -> Window | None:
    """The window of the neighbouring node that ``window`` (one of ``own``) moves into: the nearest one where they
    overlap or are each other's nearest; None where it has none there (it is born or gone between the nodes, or
    has left the speed range followed), so that it is not joined across the windows in between."""
    nearest = min(other, key=window.distance, default=None)
    if nearest is None or window.distance(nearest) == 0.0:
        return nearest
    return nearest if min(own, key=nearest.distance) == window else None


def _stretches(branch: Any) -> list[tuple[int, int, bool]]:
    """Maximal runs of equal stability along a branch: (first, last, stable)."""
    runs: list[tuple[int, int, bool]] = []
    for index, point in enumerate(branch.points):
        stable = bool(point.stable)
        if runs and runs[-1][2] == stable:
            runs[-1] = (runs[-1][0], index, stable)
        else:
            runs.append((index, index, stable))
    return runs


def _monotone_pieces(branch: Any, parameters: np.ndarray, first: int, last: int) -> list[StableStretch]:
    """The stable points ``first`` to ``last`` of a branch as stretches one-valued in speed: a stretch that turns
    (on a kink of the discrete map) is split where it does, each piece sorted by speed."""
    turns = np.nonzero(np.diff(np.sign(np.diff(parameters[first : last + 1]))))[0] + 1
    pieces = []
    for start, stop in zip([first, *(first + turns)], [*(first + turns), last]):
        if stop > start:
            order = np.argsort(parameters[start : stop + 1], kind="stable")
            states = np.array([branch.points[i].state for i in range(start, stop + 1)])[order]
            pieces.append(StableStretch(branch.period, parameters[start : stop + 1][order], states))
    return pieces


def _node_windows(fit: Continuation, value: float, margin: float) -> NodeWindows:
    """Windows and stable stretches of one continuation (module docstring)."""
    spans: list[Window] = []
    stretches: list[StableStretch] = []
    for branch in fit.branches_:
        parameters = np.array([point.parameter for point in branch.points])
        if branch.period > 1 and parameters.size:
            spans.append(Window(float(parameters.min()), float(parameters.max()), ("doubled",)))
        for first, last, stable in _stretches(branch):
            if stable:
                stretches += _monotone_pieces(branch, parameters, first, last)
                continue
            low, high = max(first - 1, 0), min(last + 1, len(branch.points) - 1)
            spans.append(
                Window(float(parameters[low : high + 1].min()), float(parameters[low : high + 1].max()), ("unstable",))
            )
    bifurcations = tuple((str(item.kind), float(item.parameter)) for item in fit.bifurcations_)
    spans += [Window(location, location, (kind,)) for kind, location in bifurcations]
    widened = sorted((Window(w.low - margin, w.high + margin, w.kinds) for w in spans), key=lambda w: w.low)
    merged: list[Window] = []
    for window in widened:
        if merged and window.low <= merged[-1].high:
            merged[-1] = merged[-1].hull(window)
        else:
            merged.append(window)
    return NodeWindows(float(value), tuple(merged), tuple(stretches), bifurcations)


def follow_nodes(
    design: Design,
    speed_range: tuple[float, float],
    fixed: Mapping[str, float],
    *,
    node_parameter: str | None = None,
    node_values: Sequence[float] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    threads: int | None = None,
) -> list[tuple[float, Continuation]]:
    """The continuation in pinion speed at each node: ``[(node value, fitted Continuation), ...]`` sorted by value
    (one node of value NaN without ``node_parameter``). Parameters as :func:`find_windows`; the nodes are
    followed side by side on up to ``threads`` forked processes (default: as many as a batch uses threads), each
    whole in one process, so the fits are the same for any number."""
    low, high = sorted(float(value) for value in speed_range)
    if not (math.isfinite(low) and math.isfinite(high)) or high <= low:
        raise UqgearError(f"speed_range: expected two different finite speeds; got {speed_range!r}")
    values = [float(v) for v in node_values] if node_parameter is not None and len(node_values) else [math.nan]
    settings = ContinuationSettings(tolerance=LOCATION_TOLERANCE * (high - low), max_period=2)
    base = {key: float(value) for key, value in fixed.items() if key != SWEEP_VARIABLE}

    def follow(value: float) -> tuple[float, Continuation]:
        inputs = dict(base) if node_parameter is None or not math.isfinite(value) else {**base, node_parameter: value}
        continuation = Continuation(
            SWEEP_VARIABLE,
            low,
            high,
            settings=settings,
            damping_in_separation=damping_in_separation,
            stiffness=stiffness,
        )
        return value, continuation.fit(design, inputs)

    ordered = sorted(values)
    count = min(default_threads() if threads is None else max(1, int(threads)), len(ordered))
    if count > 1:
        # any mesh-periodic point loads the same kernel: the lowest node's inputs at the lowest speed
        first = dict(base) if node_parameter is None else {**base, node_parameter: ordered[0]}
        _load_orbit_kernel(design, {**first, SWEEP_VARIABLE: low}, damping_in_separation, stiffness)
    # one forked process per node at a time: a continuation is mostly Python between its compiled orbit passes,
    # so threads would take turns at the GIL; each node's fit is computed whole in one process, as here
    return map_forked(lambda index: follow(ordered[index]), len(ordered), count)


def _load_orbit_kernel(
    design: Design, values: Mapping[str, float], damping_in_separation: bool, stiffness: str
) -> None:
    """One mesh period of the orbit map at ``values``, result unused: the compiled orbit kernel is loaded here, once,
    before the processes fork, and each of them inherits it instead of loading it again (about as long as a node's
    continuation). Inputs the map refuses are left to the continuation, which says what is wrong with them."""
    try:
        setup = setup_at(design, values, damping_in_separation=damping_in_separation, stiffness=stiffness)
        PoincareMap(setup)(setup.static_state(), 1, with_matrix=True)
    except UqgearError:
        return


def windows_from(
    fits: Sequence[tuple[float, Continuation]],
    margin: float,
    *,
    node_parameter: str | None = None,
    fixed: Mapping[str, float] | None = None,
    seconds: float = 0.0,
) -> CoexistenceWindows:
    """The windows of the continuations of :func:`follow_nodes`, each widened by ``margin`` rpm."""
    if not math.isfinite(margin) or margin < 0:
        raise UqgearError(f"margin: expected a non-negative number of rpm; got {margin!r}")
    if not fits:
        raise UqgearError("fits: expected at least one continuation")
    first = fits[0][1]
    return CoexistenceWindows(
        node_parameter=node_parameter,
        nodes=tuple(_node_windows(fit, value, float(margin)) for value, fit in fits),
        margin=float(margin),
        speed_range=(float(min(first.start, first.stop)), float(max(first.start, first.stop))),
        fixed={key: float(value) for key, value in (fixed or {}).items() if key != SWEEP_VARIABLE},
        seconds=float(seconds),
        orbit_passes=int(sum(fit.orbit_passes_ for _, fit in fits)),
    )


def find_windows(
    design: Design,
    speed_range: tuple[float, float],
    fixed: Mapping[str, float],
    *,
    node_parameter: str | None = None,
    node_values: Sequence[float] = (),
    margin: float = 50.0,
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    threads: int | None = None,
) -> CoexistenceWindows:
    """Follow the periodic branches in pinion speed at each node and collect the windows (module docstring).

    Parameters
    ----------
    design : Design
    speed_range : (float, float)
        Lowest and highest pinion speed (rpm) to follow.
    fixed : mapping
        Every other input (``drive_torque``, ``adhesion_torque``, design keys, ...), at the values the
        windows hold for.
    node_parameter : str, optional
        The input whose ``node_values`` each get a continuation (it overrides ``fixed``).
    node_values : sequence of float
    margin : float
        rpm added on both sides of every window (at least the speed step of the grid the windows
        guide, so that a window point's sweep neighbours lie in it too).
    damping_in_separation, stiffness : as in :func:`uqgear.simulate`
    threads : int, optional
        Processes the nodes are followed on (the windows are the same for any number).

    Returns
    -------
    CoexistenceWindows

    Examples
    --------
    On wet rail at rated torque the bundled gear's period-1 branch folds twice near 3600 rpm and
    turns unstable (a torus) above 3720 rpm:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> found = find_windows(design, (3000.0, 4500.0), {"drive_torque": 7000.0, "adhesion_torque": 21145.6})
    >>> [(round(w.low), round(w.high)) for w in found.nodes[0].windows]
    [(3523, 4322)]
    >>> bool(found.contains([3650.0, 3000.0]).tolist() == [True, False])
    True
    >>> len(found.orbit_states(3650.0))     # the low and the high period-1 orbit
    2
    """
    began = time.perf_counter()
    fits = follow_nodes(
        design,
        speed_range,
        fixed,
        node_parameter=node_parameter,
        node_values=node_values,
        damping_in_separation=damping_in_separation,
        stiffness=stiffness,
        threads=threads,
    )
    return windows_from(fits, margin, node_parameter=node_parameter, fixed=fixed, seconds=time.perf_counter() - began)


def _highest_frequency(design: Design, inputs: Mapping[str, float], mean_stiffness: float) -> float:
    """Highest natural frequency (Hz, the mesh mode) with the modal inputs among ``inputs`` applied
    (``mean_stiffness``: the design's mean mesh stiffness; the modal inputs leave the geometry alone)."""
    keys = {
        name: float(value)
        for name, value in inputs.items()
        if name in MODAL_VARIABLES and name != "mesh_stiffness_scale"
    }
    varied = design.replace(**keys) if keys else design
    scale = float(inputs.get("mesh_stiffness_scale", 1.0))
    return float(natural_frequencies(varied, mean_stiffness * scale)[-1])


def equivalent_speeds(samples: xr.Dataset, design: Design, windows: CoexistenceWindows) -> np.ndarray:
    """Each sample's pinion speed scaled to the windows' inputs: speed x f_ref / f_sample, f the highest natural
    frequency (the mesh mode). Samples that change no modal input keep their speed."""
    speeds = np.asarray(samples[SWEEP_VARIABLE].values, dtype=float)
    varied = [name for name in MODAL_VARIABLES if name in samples and samples[name].dims == ("sample",)]
    if not varied:
        return speeds
    mean = float(stiffness_tables(design, mode="ishikawa").k_mean)
    reference = _highest_frequency(design, windows.fixed, mean)
    columns = np.stack([np.asarray(samples[name].values, dtype=float) for name in varied], axis=1)
    unique, inverse = np.unique(columns, axis=0, return_inverse=True)
    ratios = np.empty(len(unique))
    for row, values in enumerate(unique):
        inputs = {**windows.fixed, **dict(zip(varied, values.tolist()))}
        ratios[row] = reference / _highest_frequency(design, inputs, mean)
    return speeds * ratios[np.ravel(inverse)]


__all__ = [
    "CoexistenceWindows",
    "NodeWindows",
    "StableStretch",
    "Window",
    "equivalent_speeds",
    "find_windows",
    "follow_nodes",
    "windows_from",
    "MODAL_VARIABLES",
    "GRAZING_KINDS",
]
