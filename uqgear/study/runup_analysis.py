"""The ``runup`` analysis: the gear through a speed ramp, up and down, over the interval parameters.

For every combination of ``points`` values across each interval parameter of ``parameters`` (by default
every interval of the study: T2 from wet to dry rail) the gear runs up from ``pinion_speed.start`` to
``pinion_speed.stop`` at ``rate`` rpm/s and coasts down the same span
(:func:`~uqgear.physics.runup.simulate_runup_batch`, the forcing following the pinion angle). Each run
is binned along the ramp (:func:`~uqgear.dynamics.ramp_envelopes.ramp_envelope`): the peak mesh force and
the contact fractions per speed bin, whose bounds over the interval nodes give ``peak_mesh_force`` on
(``bound``, ``direction``, ``pinion_speed``); its order content by computed order tracking
(:func:`~uqgear.dynamics.order_maps.order_map`); and the speeds where its envelope jumps
(:func:`~uqgear.dynamics.ramp_envelopes.jump_speeds` on bins of ``jump_bin`` rpm, finer than the
envelope's, the new level holding over three bins on each side). With ``folds`` the period-1 branch of
each case is continued over the same span (:class:`~uqgear.dynamics.continuation.Continuation`), so that each jump
stands beside the fold it falls from: a run-up leaves a branch at a fold whose sweep direction is ``up``,
a coast-down at one whose direction is ``down``, later than the fold by a distance that shrinks with the
rate. ``compare_rates`` repeats the ramps at other rates for the jump speeds alone.

A calibrated posterior (``uncertain.calibrated``) enters at its medians (:meth:`AnalysisContext.fixed_values`)
and the diagnosed effects of ``model.effects`` at their fitted values: a ramp is one run per case, not a
posterior-predictive band (the ``prediction`` analysis gives that at steady speeds).
"""

from __future__ import annotations

import itertools
import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from ..dynamics.continuation import Continuation, ContinuationSettings
from ..dynamics.order_maps import order_map, speed_bin_edges
from ..dynamics.ramp_envelopes import Jump, jump_speeds, ramp_envelope
from ..dynamics.shooting import ShootingSettings
from ..physics.integration import samples_from_mapping
from ..physics.runup import simulate_runup_batch
from ..physics.speed_profile import SpeedProfile
from .analyses import AnalysisContext, register

#: Signals whose order content a run-up maps (the DTE, the mesh force, the bearing accelerations).
RUNUP_SIGNALS = ("te", "mesh_force", "y1_acceleration", "y2_acceleration")
#: Per-bin envelope variables kept from each run.
ENVELOPE_VARIABLES = ("peak_mesh_force", "fraction_separation", "fraction_back_contact")
#: The two senses of travel, in the order of the ``direction`` dim.
DIRECTIONS = ("up", "down")


@dataclass(frozen=True)
class RampResult:
    """The runs of one sense of travel at one rate, every interval case at once.

    Attributes
    ----------
    direction : str
        ``"up"`` or ``"down"``.
    rate : float
        Ramp rate, rpm/s (positive).
    envelopes : xarray.Dataset
        :data:`ENVELOPE_VARIABLES` on (``case``, ``pinion_speed``).
    orders : xarray.Dataset or None
        ``order_amplitude`` on (``case``, ``signal``, ``pinion_speed``, ``order``); None where not mapped.
    jumps : tuple of tuple of Jump
        Per case, the jumps of its peak mesh force in the order of travel.
    seconds : float
        Wall time of the runs.
    """

    direction: str
    rate: float
    envelopes: xr.Dataset
    orders: xr.Dataset | None
    jumps: tuple[tuple[Jump, ...], ...]
    seconds: float


def _cases(context: AnalysisContext) -> tuple[list[dict[str, float]], dict[str, list[float]]]:
    """Every combination of ``points`` values across the interval parameters (one empty case without)."""
    names = list(context.options["parameters"])
    grids = [context.axis_values(name) for name in names]
    cases = [dict(zip(names, map(float, values))) for values in itertools.product(*grids)] or [{}]
    return cases, {name: [case[name] for case in cases] for name in names}


def ramp_speeds(options: Mapping[str, Any], direction: str) -> tuple[float, float]:
    """(first, last) speed of a ramp in its sense of travel, rpm."""
    low, high = sorted((float(options["pinion_speed"]["start"]), float(options["pinion_speed"]["stop"])))
    return (low, high) if direction == "up" else (high, low)


def _orders(options: Mapping[str, Any], z1: int) -> np.ndarray:
    """The pinion orders mapped: the study's, or every half order up to three mesh orders."""
    if options["orders"]:
        return np.asarray(sorted(options["orders"]), dtype=float)
    return np.arange(0.5, 3.0 * z1 + 0.25, 0.5)


#: Mesh periods a jump bin holds at least, at the span's lowest speed: the peak over fewer scatters.
JUMP_BIN_PERIODS = 20
#: Bins on each side of a jump whose medians must differ by the threshold (the new level holds).
JUMP_PERSISTENCE = 3


def jump_bin(options: Mapping[str, Any], z1: int, rate: float) -> float:
    """Width of the jump bins, rpm: ``jump_bin``, or at least :data:`JUMP_BIN_PERIODS` mesh periods at the lowest
    speed and at least 5 rpm.

    Examples
    --------
    >>> from uqgear.study.runup_analysis import jump_bin
    >>> span = {"pinion_speed": {"start": 3500.0, "stop": 4300.0}, "jump_bin": None}
    >>> round(jump_bin(span, 21, 2000.0), 1), jump_bin(span, 21, 100.0)
    (32.7, 5.0)
    """
    if options.get("jump_bin") is not None:
        return float(options["jump_bin"])
    low = ramp_speeds(options, "up")[0]
    return max(5.0, rate * JUMP_BIN_PERIODS / (z1 * low / 60.0))


def jump_edges(edges: np.ndarray, width: float) -> np.ndarray:
    """Bin edges about ``width`` rpm apart over the span of ``edges`` (never coarser than ``edges``).

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.study.runup_analysis import jump_edges
    >>> jump_edges(np.array([3400.0, 3500.0, 3600.0]), 40.0).tolist()
    [3400.0, 3440.0, 3480.0, 3520.0, 3560.0, 3600.0]
    """
    count = max(int(np.ceil((edges[-1] - edges[0]) / width)), edges.size - 1)
    return np.linspace(float(edges[0]), float(edges[-1]), count + 1)


def block_revolutions(edges: np.ndarray, rate: float, longest: int = 8) -> int:
    """Pinion revolutions per order-tracking block: at most ``longest``, and short enough that a block at the
    lowest speed spans at most one speed bin (a longer block would leave bins without a block of their own).

    Examples
    --------
    >>> import numpy as np
    >>> from uqgear.study.runup_analysis import block_revolutions
    >>> block_revolutions(np.linspace(500.0, 6000.0, 41), 100.0)
    8
    >>> block_revolutions(np.linspace(3500.0, 4300.0, 17), 2000.0)
    1
    """
    width = float(np.min(np.diff(edges)))
    revolutions_in_bin = width / rate * float(edges[0]) / 60.0
    return int(max(1, min(longest, np.floor(revolutions_in_bin))))


def _ramp(
    context: AnalysisContext,
    cases: Sequence[Mapping[str, float]],
    fixed: Mapping[str, float],
    direction: str,
    rate: float,
    *,
    edges: np.ndarray,
    map_orders: bool,
) -> RampResult:
    """Run every case through one ramp and reduce each run to its envelope, order map and jumps."""
    options = context.options
    first, last = ramp_speeds(options, direction)
    profile = SpeedProfile.linear(first, last, rate_rpm_per_s=rate if last > first else -rate)
    samples = samples_from_mapping(
        {
            **{name: [float(value)] * len(cases) for name, value in fixed.items()},
            **{name: [case[name] for case in cases] for name in cases[0]},
        }
    )
    simulation = context.spec.simulation
    began = time.perf_counter()
    runs = simulate_runup_batch(
        context.design,
        profile,
        samples,
        sample_rate=float(options["sample_rate"]),
        variables=tuple(dict.fromkeys([*RUNUP_SIGNALS, "contact"])),
        # the diagnosed effects of ``model.effects`` at their fitted values
        effects=tuple(effect.central() for effect in context.effects),
        damping_in_separation=simulation.damping_in_separation,
        stiffness=simulation.stiffness,
        steps_per_mode=simulation.steps_per_mode,
        threads=context.threads,
    )
    envelopes, maps, jumps = [], [], []
    orders = _orders(options, context.design.z1)
    for index in range(len(cases)):
        run = runs.isel(sample=index)
        envelope = ramp_envelope(run, speed_bins=edges)
        envelopes.append(envelope[[name for name in ENVELOPE_VARIABLES if name in envelope]])
        # jumps on bins finer than the envelope's, a jump is located to one of them
        fine = ramp_envelope(run, speed_bins=jump_edges(edges, jump_bin(options, context.design.z1, rate)))
        jumps.append(
            jump_speeds(
                fine, "peak_mesh_force", threshold=float(options["jump_threshold"]), persistence=JUMP_PERSISTENCE
            )
        )
        if map_orders:
            blocks = block_revolutions(edges, rate)
            mapped = order_map(
                run, RUNUP_SIGNALS, orders.tolist(), speed_bins=edges.tolist(), revolutions_per_block=blocks
            )
            maps.append(mapped[["order_amplitude"]])
    seconds = time.perf_counter() - began
    return RampResult(
        direction=direction,
        rate=rate,
        envelopes=xr.concat(envelopes, dim="case"),
        orders=xr.concat(maps, dim="case") if maps else None,
        jumps=tuple(jumps),
        seconds=seconds,
    )


def _folds(
    context: AnalysisContext, cases: Sequence[Mapping[str, float]], fixed: Mapping[str, float]
) -> list[list[tuple[float, str]]]:
    """Per case, the folds of stable stretches of the continued branches: (speed, sweep direction)."""
    low, high = ramp_speeds(context.options, "up")
    simulation = context.spec.simulation
    settings = ContinuationSettings(
        max_period=int(context.options["max_period"]),
        shooting=ShootingSettings(steps_per_mode=simulation.steps_per_mode),
    )
    found = []
    for case in cases:
        fitted = Continuation(
            "pinion_speed",
            low,
            high,
            settings=settings,
            damping_in_separation=simulation.damping_in_separation,
            stiffness=simulation.stiffness,
        ).fit(context.design, {**fixed, **case})
        table = fitted.result_
        kinds = np.asarray(table["bifurcation_type"].values, dtype=str)
        sweeps = np.asarray(table["bifurcation_sweep"].values, dtype=str)
        where = np.asarray(table["bifurcation_parameter"].values, dtype=float)
        found.append(
            sorted((float(where[k]), str(sweeps[k])) for k in range(kinds.size) if kinds[k] == "fold" and sweeps[k])
        )
    return found


def _padded(rows: Sequence[Sequence[float]], width: int) -> np.ndarray:
    out = np.full((len(rows), max(width, 1)), np.nan)
    for i, row in enumerate(rows):
        out[i, : len(row)] = row
    return out


def _jump_variables(ramps: Sequence[RampResult], folds: list[list[tuple[float, str]]] | None) -> dict[str, Any]:
    """Jump speeds and sizes on (``direction``, ``case``, ``jump``), with the distance to the matching fold."""
    width = max((len(jumps) for ramp in ramps for jumps in ramp.jumps), default=0)
    speeds = np.stack([_padded([[j.speed for j in jumps] for jumps in ramp.jumps], width) for ramp in ramps])
    sizes = np.stack([_padded([[j.size for j in jumps] for jumps in ramp.jumps], width) for ramp in ramps])
    dims = ("direction", "case", "jump")
    out: dict[str, Any] = {
        "jump_speed": (dims, speeds, {"units": "rpm", "long_name": "speed where the binned peak mesh force jumps"}),
        "jump_size": (dims, sizes, {"units": "N", "long_name": "change of the peak mesh force there, in travel"}),
    }
    if folds is not None:
        distance = np.full(speeds.shape, np.nan)
        for d, ramp in enumerate(ramps):
            for c, jumps in enumerate(ramp.jumps):
                matching = [speed for speed, sweep in folds[c] if sweep == ramp.direction]
                for j, jump in enumerate(jumps):
                    if matching:
                        distance[d, c, j] = min(matching, key=lambda s: abs(s - jump.speed)) - jump.speed
        out["jump_fold_distance"] = (
            dims,
            -distance,
            {
                "units": "rpm",
                "long_name": "jump speed minus the nearest fold of the same sweep direction (continuation)",
            },
        )
        width = max((len(f) for f in folds), default=0)
        out["fold_speed"] = (
            ("case", "fold"),
            _padded([[speed for speed, _ in f] for f in folds], width),
            {"units": "rpm", "long_name": "fold of a stable stretch of the continued branches"},
        )
        out["fold_sweep"] = (
            ("case", "fold"),
            np.array([[sweep for _, sweep in f] + [""] * (max(width, 1) - len(f)) for f in folds], dtype=str),
            {"long_name": "sweep direction that jumps at the fold (up: a run-up, down: a coast-down)"},
        )
    return out


def _bounded(per_case: xr.DataArray, bounded: bool) -> xr.DataArray:
    """Bounds over the interval cases (dim ``bound``), or the one case where nothing is an interval."""
    if not bounded:
        return per_case.isel(case=0, drop=True)
    lower, upper = per_case.min("case", skipna=True), per_case.max("case", skipna=True)
    return xr.concat([lower, upper], dim="bound").assign_coords(bound=["lower", "upper"])


def _rate_jumps(
    context: AnalysisContext,
    cases: Sequence[Mapping[str, float]],
    fixed: Mapping[str, float],
    edges: np.ndarray,
    main: Sequence[RampResult],
) -> dict[str, Any]:
    """Jump speeds at the main rate (``main``) and each rate of ``compare_rates``, on (``rate``, ``direction``, ...)."""
    rate = float(context.options["rate"])
    others = sorted({float(value) for value in context.options["compare_rates"]} - {rate})
    per_rate = {rate: list(main)}
    for other in others:
        per_rate[other] = [
            _ramp(context, cases, fixed, direction, other, edges=edges, map_orders=False)
            for direction in _senses(context)
        ]
    rates = sorted(per_rate)
    width = max((len(jumps) for ramps in per_rate.values() for ramp in ramps for jumps in ramp.jumps), default=0)
    speeds = np.stack(
        [
            np.stack([_padded([[j.speed for j in jumps] for jumps in ramp.jumps], width) for ramp in per_rate[r]])
            for r in rates
        ]
    )
    return {
        "rate_jump_speed": (
            ("rate", "direction", "case", "jump_at_rate"),
            speeds,
            {"units": "rpm", "long_name": "jump speed of the peak mesh force at each ramp rate"},
        ),
        "rate": ("rate", np.asarray(rates), {"units": "rpm/s", "long_name": "ramp rate"}),
    }


def _senses(context: AnalysisContext) -> tuple[str, ...]:
    chosen = str(context.options["direction"])
    return DIRECTIONS if chosen == "both" else (chosen,)


@register("runup")
def runup_analysis(context: AnalysisContext) -> xr.Dataset:
    """Run-up and coast-down envelopes, order maps and jump speeds over the interval parameters (see the module).

    Output dims: ``direction`` (``up``, ``down``), ``pinion_speed`` (bin centres, rpm), ``bound`` (where
    an interval parameter is bounded over), ``case`` (the interval nodes, as ``case_<name>``), ``signal``,
    ``order`` (pinion orders), ``jump``, and with ``folds`` ``fold``, with ``compare_rates`` ``rate``.
    """
    options = context.options
    names = list(options["parameters"])
    cases, case_values = _cases(context)
    fixed = context.fixed_values(exclude=[*names, "pinion_speed"])
    low, high = ramp_speeds(options, "up")
    edges = speed_bin_edges(np.array([low, high]), int(options["speed_bins"]))
    ramps = [
        _ramp(context, cases, fixed, direction, float(options["rate"]), edges=edges, map_orders=True)
        for direction in _senses(context)
    ]
    began = time.perf_counter()
    # the continuation needs a model that repeats every mesh period: the diagnosed effects do not
    folds = _folds(context, cases, fixed) if options["folds"] and not context.effects else None
    fold_seconds = time.perf_counter() - began
    per_case = xr.concat([ramp.envelopes for ramp in ramps], dim="direction")
    per_case = per_case.assign_coords(direction=[ramp.direction for ramp in ramps])
    result = xr.Dataset(coords=per_case.coords)
    bounded = bool(names)
    for name in ENVELOPE_VARIABLES:
        if name in per_case:
            result[name] = _bounded(per_case[name], bounded).assign_attrs(per_case[name].attrs)
            result[f"{name}_case"] = per_case[name].transpose("direction", "case", "pinion_speed")
    maps = xr.concat([ramp.orders for ramp in ramps if ramp.orders is not None], dim="direction")
    maps = maps.assign_coords(direction=[ramp.direction for ramp in ramps])
    amplitude = maps["order_amplitude"]
    # the map a designer checks against limits: the largest amplitude of each order over the cases and senses
    result["order_amplitude"] = amplitude.max(["direction", "case"], skipna=True).assign_attrs(
        amplitude.attrs, long_name="largest order amplitude over the interval cases and both senses of travel"
    )
    result["order_amplitude_case"] = amplitude.transpose("direction", "case", "signal", "pinion_speed", "order")
    result = result.merge(xr.Dataset(_jump_variables(ramps, folds)))
    if options["compare_rates"]:
        result = result.merge(xr.Dataset(_rate_jumps(context, cases, fixed, edges, ramps)))
    for name, values in case_values.items():
        result = result.assign_coords({f"case_{name}": ("case", np.asarray(values))})
    result.attrs.update(
        parameters=json.dumps(names),
        fixed_inputs=json.dumps({k: float(v) for k, v in fixed.items()}),
        ramp_rate=float(options["rate"]),
        speed_start=low,
        speed_stop=high,
        sample_rate=float(options["sample_rate"]),
        jump_threshold=float(options["jump_threshold"]),
        jump_bin=float(np.diff(jump_edges(edges, jump_bin(options, context.design.z1, float(options["rate"]))))[0]),
        runup_seconds=float(sum(ramp.seconds for ramp in ramps)),
        fold_seconds=float(fold_seconds),
        model_runs=len(cases) * len(ramps) * len({float(options["rate"]), *map(float, options["compare_rates"])}),
        design_z1=int(context.design.z1),
    )
    return result


__all__ = ["runup_analysis", "RampResult", "ramp_speeds", "RUNUP_SIGNALS", "ENVELOPE_VARIABLES", "DIRECTIONS"]
