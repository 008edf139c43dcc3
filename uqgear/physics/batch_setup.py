"""Batch set-up: one model set-up per sample, the tables they share and the lane groups they run in.

:func:`build_batch` turns a Dataset of samples into :class:`~uqgear.physics.model.ModelSetup`
objects (design keys and effect parameters may vary per sample);
:func:`shared_stiffness_tables` and :func:`breakpoint_table` lay them out for
the batch kernels (:func:`kernel_inputs`: the inputs every batch kernel
reads of each run), :func:`lane_groups` groups the runs that share a sub-step
layout into SIMD lanes (:mod:`uqgear.physics._lanes`) and
:func:`integrate_lane_groups` integrates those groups.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any, cast

import numpy as np
import xarray as xr

from ..common.errors import OperatingPointError
from . import _lanes, _pair_lanes
from ._batch_record import QoiBatch, RunInputs
from ._pair_extremes import N_EXTREMES
from ._rhs import PITCH_ERRORS
from .design import DESIGN_KEYS, Design
from .effects import Effect
from .model import ModelSetup, build_model
from .pitch_errors import PitchErrors
from .threads import spread

#: Operating variables a batch sample may set.
OPERATING_VARIABLES = ("pinion_speed", "drive_torque", "adhesion_torque", "mesh_stiffness_scale")
#: Design keys a batch may vary (the tooth counts fix the tables' layout).
BATCH_DESIGN_KEYS = tuple(key for key in DESIGN_KEYS if key not in ("z1", "z2"))


def _sample_values(samples: xr.Dataset, design: Design) -> dict[str, np.ndarray]:
    if "sample" not in samples.dims:
        raise OperatingPointError("samples: expected a Dataset with dimension 'sample'")
    n = samples.sizes["sample"]
    known = set(OPERATING_VARIABLES) | set(BATCH_DESIGN_KEYS)
    values: dict[str, np.ndarray] = {}
    # sample variables are named by strings (design keys, operating variables, EFFECT.PARAMETER)
    for name in cast(Iterable[str], samples.data_vars):
        if name not in known and "." not in name:
            raise OperatingPointError(
                f"samples.{name}: unknown variable; expected one of {', '.join(sorted(known))} or EFFECT.PARAMETER"
            )
        array = np.asarray(samples[name].values, dtype=float)
        if array.shape != (n,):
            raise OperatingPointError(f"samples.{name}: expected dims ('sample',); got {samples[name].dims}")
        values[name] = array
    if "pinion_speed" not in values:
        raise OperatingPointError("samples.pinion_speed: missing; expected pinion speeds in rpm")
    values.setdefault("drive_torque", np.full(n, design.operation.drive_torque))
    # without a given T2 the adhesion torque balances the drive torque (no rigid acceleration)
    values.setdefault("adhesion_torque", values["drive_torque"] * design.z2 / design.z1)
    values.setdefault("mesh_stiffness_scale", np.ones(n))
    return values


def sample_designs(design: Design, samples: xr.Dataset) -> list[Design]:
    """Each sample's design: ``design`` with the design keys the samples set (those :func:`build_batch` builds).

    Examples
    --------
    >>> import uqgear
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [1000.0, 2000.0], "face_width": [0.1, 0.1]})
    >>> designs = sample_designs(uqgear.load_design("locomotive"), samples)
    >>> designs[0].face_width, designs[0] is designs[1]
    (0.1, True)
    """
    values = _sample_values(samples, design)
    design_keys = [key for key in values if key in BATCH_DESIGN_KEYS]
    designs: dict[tuple, Design] = {}
    result = []
    for i in range(samples.sizes["sample"]):
        design_key = tuple(float(values[key][i]) for key in design_keys)
        if design_key not in designs:
            designs[design_key] = design.replace(**dict(zip(design_keys, design_key))) if design_keys else design
        result.append(designs[design_key])
    return result


def build_batch(
    design: Design,
    samples: xr.Dataset,
    *,
    effects: Sequence[Effect] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    pitch_errors: PitchErrors | None = None,
) -> list[ModelSetup]:
    """One :class:`ModelSetup` per sample (design keys and effect parameters may vary; the pitch errors,
    if any, are those of every sample)."""
    values = _sample_values(samples, design)
    n = samples.sizes["sample"]
    effect_keys = [key for key in values if "." in key]
    by_name = {effect.name: effect for effect in effects}
    for key in effect_keys:
        name, _, parameter = key.partition(".")
        if name not in by_name:
            raise OperatingPointError(
                f"samples.{key}: effect {name!r} is not among the model's effects ({', '.join(by_name) or 'none'})"
            )
        if parameter not in by_name[name].PARAMETERS:
            raise OperatingPointError(
                f"samples.{key}: unknown parameter of {name}; expected one of {', '.join(by_name[name].PARAMETERS)}"
            )
    designs = sample_designs(design, samples)
    setups = []
    for i in range(n):
        sample_effects = list(effects)
        if effect_keys:
            changes: dict[str, dict[str, float]] = {}
            for key in effect_keys:
                name, _, parameter = key.partition(".")
                changes.setdefault(name, {})[parameter] = float(values[key][i])
            sample_effects = [e.with_values(**changes[e.name]) if e.name in changes else e for e in effects]
        setups.append(
            build_model(
                designs[i],
                values["pinion_speed"][i],
                values["drive_torque"][i],
                values["adhesion_torque"][i],
                mesh_stiffness_scale=values["mesh_stiffness_scale"][i],
                effects=sample_effects,
                damping_in_separation=damping_in_separation,
                stiffness=stiffness,
                pitch_errors=pitch_errors,
            )
        )
    return setups



def start_states(
    design: Design,
    samples: xr.Dataset,
    states: np.ndarray | None,
    *,
    effects: Sequence[Effect] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
) -> np.ndarray | None:
    """Start states for :func:`~uqgear.physics.integration.simulate_batch`'s ``initial_states``: the given
    (samples, 6) states, a row with a NaN replaced by that run's static equilibrium (None stays None).

    Examples
    --------
    >>> import numpy as np, uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [1000.0, 2000.0]})
    >>> given = np.array([[0.0, 0.0, 1e-5, 0.0, 0.0, 0.0], [np.nan] * 6])
    >>> states = start_states(design, samples, given)
    >>> float(states[0, 2]), bool(states[1, 2] == build_batch(design, samples)[1].static_state()[2])
    (1e-05, True)
    """
    if states is None:
        return None
    states = np.array(states, dtype=float)
    rest = ~np.all(np.isfinite(states), axis=1)
    if rest.any():
        setups = build_batch(
            design,
            samples.isel(sample=np.nonzero(rest)[0]),
            effects=effects,
            damping_in_separation=damping_in_separation,
            stiffness=stiffness,
        )
        states[rest] = np.stack([setup.static_state() for setup in setups])
    return states


def shared_stiffness_tables(setups: Sequence[ModelSetup]) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """The distinct stiffness tables of a batch's set-ups and, per set-up, the index of its own.

    Set-ups of one design share their tables (the model's stiffness cache),
    so a batch passes each table to the kernels once, not once per sample.
    """
    tables: dict[tuple[int, int], int] = {}
    pair_tables: list[np.ndarray] = []
    period_tables: list[np.ndarray] = []
    table_index = np.empty(len(setups), dtype=np.int64)
    for i, setup in enumerate(setups):
        key = id(setup.pair_stiffness), id(setup.period_stiffness)
        if key not in tables:
            tables[key] = len(pair_tables)
            pair_tables.append(setup.pair_stiffness)
            period_tables.append(setup.period_stiffness)
        table_index[i] = tables[key]
    return pair_tables, period_tables, table_index


def breakpoint_table(setups: Sequence[ModelSetup]) -> np.ndarray:
    """Breakpoints of a batch's set-ups, one row each, padded with NaN (one column at least)."""
    width = max((len(setup.breakpoints) for setup in setups), default=0)
    breakpoints = np.full((len(setups), max(width, 1)), np.nan)
    for i, setup in enumerate(setups):
        breakpoints[i, : len(setup.breakpoints)] = setup.breakpoints
    return breakpoints


def kernel_inputs(setups: Sequence[ModelSetup], states: np.ndarray) -> RunInputs:
    """The inputs every batch kernel reads of each run, for non-empty ``setups`` starting at ``states``.

    The one place a :class:`~uqgear.physics._batch_record.RunInputs` is filled: the one-sample batch
    kernels, the lanes and the harmonic balance all read these.
    """
    pair_tables, period_tables, table_index = shared_stiffness_tables(setups)
    return RunInputs(
        states,
        np.stack([s.parameters for s in setups]),
        np.stack(pair_tables),
        np.stack(period_tables),
        table_index,
        np.stack([s.factor_pinion for s in setups]),
        np.stack([s.factor_gear for s in setups]),
        breakpoint_table(setups),
    )


def integrate_lane_groups(batch: QoiBatch, threads: int | None) -> np.ndarray:
    """Integrate a batch's lane-ready runs in lane groups; returns the runs left to a one-sample kernel.

    The runs left are those the lanes do not take (divisors the lanes' quotient is not exact for,
    groups too small to pay: :func:`lane_groups`) and those a group refused (another sub-step
    layout), in index order.
    """
    params = batch.runs.params
    groups, rest = lane_groups(params, batch.steps_per_period, batch.runs.breakpoints, batch.history_stride,
                               batch.lyapunov)
    if len(groups):
        refused = np.zeros(len(params), dtype=np.bool_)
        # a group holds runs with pitch errors or runs without (lane_groups): each family its own kernel,
        # compiled (or loaded) only for a batch that has its runs
        pitch = params[groups[:, 0], PITCH_ERRORS] != 0.0
        families = ((_lanes.compile_lanes, _lanes.integrate_lanes, groups[~pitch]),
                    (_pair_lanes.compile_pair_lanes, _pair_lanes.integrate_pair_lanes, groups[pitch]))
        for compile_kernel, kernel, family in families:
            if len(family):
                # compiled here, before the threads call it
                compile_kernel(family, batch, refused)

                def run_groups(first: int, last: int, kernel: Any = kernel, family: np.ndarray = family) -> None:
                    kernel(first, last, family, batch, refused)

                spread(run_groups, len(family), threads)
        rest = np.sort(np.concatenate([rest, np.nonzero(refused)[0]])).astype(np.int64)
    return rest


#: The extremes of the tooth-pair loads a batch keeps with ``stresses`` (in the slots' order of
#: :mod:`uqgear.physics._pair_extremes`): name -> (units, description).
PAIR_EXTREME_INFO: dict[str, tuple[str, str]] = {
    "pair_load_max": ("N", "largest load of a tooth pair in mesh at the kept grid steps"),
    "pair_load_min": ("N", "smallest load of a touching tooth pair (negative on the back side)"),
    "flank_load_pinion": ("N m-1", "largest P+ / rho of a pair with its contact on the pinion's dedendum"),
    "flank_load_gear": ("N m-1", "largest P+ / rho of a pair with its contact on the gear's dedendum"),
}
if len(PAIR_EXTREME_INFO) != N_EXTREMES:
    raise RuntimeError("PAIR_EXTREME_INFO and the kernels' extremes differ")  # pragma: no cover - a source error


def extreme_variables(extremes: np.ndarray) -> dict[str, tuple[Any, ...]]:
    """A batch's (runs, N_EXTREMES) extremes as Dataset variables on ``sample`` (:data:`PAIR_EXTREME_INFO`).

    Examples
    --------
    >>> import numpy as np
    >>> sorted(extreme_variables(np.zeros((2, 4))))[:2]
    ['flank_load_gear', 'flank_load_pinion']
    """
    return {
        name: ("sample", extremes[:, j].copy(), {"units": units, "long_name": text})
        for j, (name, (units, text)) in enumerate(PAIR_EXTREME_INFO.items())
    }


#: Share of a lane group's places (eight runs; four with ``lyapunov``) it must fill to be integrated
#: in lanes. A group's vector work is the same whatever it holds: on 256-bit vectors (the eight lanes
#: two vectors) a group of one costs about two runs one at a time, and groups pay from about half the
#: lanes filled (docs/validation/performance.md, "Few runs go one at a time").
MINIMUM_FILL = 0.5


def lane_groups(
    params: np.ndarray, steps: np.ndarray, breakpoints: np.ndarray, strides: np.ndarray, lyapunov: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Lane groups of a batch's lane-ready runs, and the runs left to the one-sample kernels.

    Runs with the same sub-step layout (steps per mesh period, stiffness
    breakpoints, history stride) and the same step family (with or without
    pitch errors) share a group of
    :data:`~uqgear.physics._lanes.LANES` lanes (half as many runs with
    ``lyapunov``: each run's shadow takes a lane); a group with fewer runs
    than :data:`MINIMUM_FILL` of that is left to the one-sample kernels
    (the same numbers, at less cost). Groups come most steps first, so
    that the threads end on the short ones; the runs left are in index order.
    """
    taken = _lanes.lane_ready(params)
    ready = np.nonzero(taken)[0]
    rest = [int(i) for i in np.nonzero(~taken)[0]]
    width = _lanes.LANES // 2 if lyapunov else _lanes.LANES
    minimum = math.ceil(MINIMUM_FILL * width)
    layouts: dict[tuple, list[int]] = {}
    for i in ready:
        # runs with pitch errors take the pair lanes: they never share a group with runs without
        key = (int(steps[i]), breakpoints[i].tobytes(), int(strides[i]), bool(params[i, PITCH_ERRORS] != 0.0))
        layouts.setdefault(key, []).append(int(i))
    rows: list[tuple[int, list[int]]] = []
    for key, members in layouts.items():
        for start in range(0, len(members), width):
            group = members[start : start + width]
            if len(group) >= minimum:
                rows.append((key[0], group))
            else:
                rest += group
    rows.sort(key=lambda row: -row[0])
    groups = np.full((len(rows), _lanes.LANES), -1, dtype=np.int64)
    for g, (_, members) in enumerate(rows):
        groups[g, : len(members)] = members
    return groups, np.array(sorted(rest), dtype=np.int64)


__all__ = [
    "OPERATING_VARIABLES",
    "BATCH_DESIGN_KEYS",
    "build_batch",
    "start_states",
    "sample_designs",
    "shared_stiffness_tables",
    "breakpoint_table",
    "lane_groups",
    "MINIMUM_FILL",
    "kernel_inputs",
    "integrate_lane_groups",
    "PAIR_EXTREME_INFO",
    "extreme_variables",
]
