"""Speed-varying simulation: the gear pair driven through a prescribed pinion speed profile (run-up, coast-down).

The model is that of :func:`uqgear.physics.integration.simulate` with the
mesh-periodic forcing evaluated at the pinion angle instead of a fixed mesh
frequency (docs/model/run-up.md section 11.1): at the warped time
tau(t) = z1 theta1(t) / Omega_ref, Omega_ref the mesh frequency at the
profile's start speed. The mesh phase, the pairs in contact, the Ishikawa
stiffness, the STE, the shaft run-out and the motor torque ripple follow the
shaft angles; the STE's acceleration takes the chain rule
e'' = e_tautau tau'^2 + e_tau tau''. Masses, stiffnesses, damping and the
adhesion oscillation (its own clock) do not depend on the speed.

``method="scipy"`` integrates in physical time with :func:`scipy.integrate.solve_ivp`
(DOP853) between the stiffness breakpoints (their times from the profile's
inverse angle) with events at the contact boundaries, the reference;
``method="fast"`` steps RK4 in warped time (:mod:`uqgear.physics._runup_kernels`).
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from typing import Any, NamedTuple

import numpy as np
import xarray as xr
from scipy.integrate import solve_ivp
from scipy.interpolate import PPoly

from ..common.errors import OperatingPointError
from . import _kernels as K
from . import _runup_kernels as R
from . import _runup_lanes as RL
from ._lanes import LANES, lane_ready
from ._stepper import build_schedule
from .batch_setup import build_batch
from .design import Design
from .effects import Effect
from .integration import (
    _LONG_NAMES,
    _UNITS,
    METHODS,
    MINIMUM_STEPS,
    _attrs,
    _highest_mode,
    _steps_for,
    samples_from_mapping,
    simulate_batch,
)
from .model import HISTORY_COLUMNS, ModelSetup
from .scipy_reference import boundary_event
from .speed_profile import RPM, SpeedProfile
from .threads import spread

#: Mesh periods of the constant-speed run-in at the start speed that gives the default initial state.
RUN_IN_PERIODS = 200
#: The variables on (sample, time) that :func:`simulate_runup_batch` returns by default.
BATCH_VARIABLES = ("x", "te", "mesh_force", "y1_acceleration", "y2_acceleration", "contact")


def check_speed_range(design: Design, profile: SpeedProfile) -> None:
    """Refuse a profile outside the design's sweep range ``operation.pinion_speed_sweep`` (rpm).

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> try:
    ...     uqgear.check_speed_range(design, uqgear.SpeedProfile.linear(500.0, 7000.0, 1.0))
    ... except uqgear.SpeedProfileError as error:
    ...     print(error)
    speed profile: expected speeds in the design's pinion_speed_sweep [200, 6000] rpm; got 500 to 7000 rpm
    """
    from .speed_profile import SpeedProfileError

    if not isinstance(profile, SpeedProfile):
        raise SpeedProfileError(f"profile: expected a SpeedProfile; got {type(profile).__name__}")
    low, high = design.operation.pinion_speed_sweep
    slowest, fastest = profile.speed_range()
    if slowest < low or fastest > high:
        raise SpeedProfileError(
            f"speed profile: expected speeds in the design's pinion_speed_sweep [{low:g}, {high:g}] rpm; "
            f"got {slowest:g} to {fastest:g} rpm"
        )


def _clock(profile: SpeedProfile, angle: np.ndarray, omega_ref: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, tau', tau'') at pinion angles ``angle``.

    Past the profile's end (the rest of the last mesh period of a fast run) its
    last piece goes on, so the knots' Hermite stays smooth across the end.
    """
    speed = PPoly(profile.coefficients, profile.knots, extrapolate=True)
    turned = speed.antiderivative()
    t = np.interp(angle, profile.angle(profile.knots), profile.knots)
    beyond = angle > float(profile.angle(profile.duration))
    t[beyond] = profile.duration
    for _ in range(60):
        correction = (turned(t) * RPM - angle) / (speed(t) * RPM)
        t = t - correction
        if np.all(np.abs(correction) <= 1e-15 * max(profile.duration, 1.0)):
            break
    return t, speed(t) * RPM / omega_ref, speed(t, 1) * RPM / omega_ref


def _output_times(profile: SpeedProfile, sample_rate: float) -> np.ndarray:
    if not math.isfinite(sample_rate) or sample_rate <= 0.0:
        raise OperatingPointError(f"sample_rate: expected a finite rate > 0 Hz; got {sample_rate!r}")
    return np.arange(int(math.floor(profile.duration * sample_rate + 1e-9)) + 1) / sample_rate


def _run_in(design: Design, samples: xr.Dataset, options: dict) -> np.ndarray:
    """Each sample's state after ``run_in_periods`` mesh periods at the start speed (mesh phase 0)."""
    batch = simulate_batch(
        design,
        samples,
        n_periods=options["run_in_periods"],
        keep_periods=1,
        final_state=True,
        effects=options["effects"],
        damping_in_separation=options["damping_in_separation"],
        stiffness=options["stiffness"],
        steps_per_mode=options["steps_per_mode"],
        threads=options["threads"],
    )
    return np.asarray(batch["final_state"].values, dtype=float)


#: A run-up's band of mesh periods on one grid ends where its lowest speed needs this fraction of its steps.
BAND_SHRINK = 0.8
#: A coast-down's band takes this factor more steps than its first period needs (its speed falls on).
BAND_GROWTH = 1.2


def step_bands(setup: ModelSetup, rate: np.ndarray, steps_per_mode: int) -> list[tuple[int, int, int]]:
    """(first period, stop period, steps per period) of the bands of mesh periods that share one grid.

    Each mesh period needs :func:`uqgear.physics.integration.steps_per_period`'s steps at the lower
    of its end speeds (``rate`` = tau' at the period starts, one more than there are periods). A band
    keeps its grid while that is enough and not more than 1 / :data:`BAND_SHRINK` times what is needed;
    a coast-down's new band takes :data:`BAND_GROWTH` times its first period's need.
    """
    f_high = _highest_mode(setup.design, float(setup.parameters[K.STIFFNESS_SCALE]))
    lowest = setup.mesh_frequency * np.minimum(rate[:-1], rate[1:])
    needed = [_steps_for(f_high, float(f), steps_per_mode, MINIMUM_STEPS, 1) for f in lowest]
    bands = []
    first, steps = 0, needed[0]
    for n in range(1, len(needed)):
        if needed[n] > steps or needed[n] < BAND_SHRINK * steps:
            bands.append((first, n, steps))
            first = n
            steps = needed[n] if needed[n] < steps else int(math.ceil(BAND_GROWTH * needed[n]))
    bands.append((first, len(needed), steps))
    return bands


class _Plan(NamedTuple):
    """A run's warped-time grid: output tau, mesh period, clock knots, bands and their schedules."""

    out_tau: np.ndarray
    period: float
    warps: tuple[np.ndarray, np.ndarray, np.ndarray]
    bands: list[tuple[int, int, int]]
    schedules: list[tuple[np.ndarray, ...]]


def _plan(setup: ModelSetup, steps_per_mode: int, profile: SpeedProfile, out_t: np.ndarray) -> _Plan:
    p = setup.parameters
    omega_ref = setup.pinion_rotation
    period = 2.0 * math.pi / p[K.OMEGA_MESH]
    out_tau = profile.angle(out_t) / omega_ref
    n_periods = int(math.ceil(out_tau[-1] / period * (1.0 + 1e-12))) + 1
    angles = np.arange(n_periods + 1) * period * omega_ref
    warps = _clock(profile, angles, omega_ref)
    bands = step_bands(setup, warps[1], steps_per_mode)
    schedules = [
        build_schedule(p, setup.pair_stiffness, setup.period_stiffness, setup.breakpoints, steps)
        for _, _, steps in bands
    ]
    return _Plan(out_tau, period, warps, bands, schedules)


def _integrate_fast(
    setup: ModelSetup, steps_per_mode: int, profile: SpeedProfile, out_t: np.ndarray, state0: np.ndarray
) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """History rows at ``out_t`` by the compiled warped-time RK4 (see :mod:`uqgear.physics._runup_kernels`),
    and the bands of steps per period it took (:func:`step_bands`)."""
    p = setup.parameters
    out_tau, period, warps, bands, schedules = _plan(setup, steps_per_mode, profile, out_t)
    history = np.empty((out_t.size, len(HISTORY_COLUMNS)))
    state = np.ascontiguousarray(state0, dtype=float)
    tables = (setup.pair_stiffness, setup.period_stiffness, setup.factor_pinion, setup.factor_gear)
    o = 0
    for (first, stop, _), schedule in zip(bands, schedules):
        state, o = R.integrate_runup(state, p, *tables, schedule, period, first, stop, warps, out_tau, o, history)
    return history, bands


def _plans(
    setups: Sequence[ModelSetup], steps_per_mode: int, profile: SpeedProfile, out_t: np.ndarray
) -> list[_Plan]:
    """Each run's :func:`_plan`, found once for runs that differ in their torques alone (which the grid
    does not depend on)."""
    found: dict[bytes, _Plan] = {}
    plans = []
    for setup in setups:
        grid = setup.parameters.copy()
        grid[[K.T1, K.T2]] = 0.0
        arrays = (grid, setup.pair_stiffness, setup.period_stiffness, setup.factor_pinion, setup.factor_gear)
        key = b"".join(np.ascontiguousarray(a).tobytes() for a in (*arrays, setup.breakpoints))
        if key not in found:
            found[key] = _plan(setup, steps_per_mode, profile, out_t)
        plans.append(found[key])
    return plans


def _lane_key(setup: ModelSetup, plan: _Plan) -> tuple[Any, ...]:
    """What runs stepping as lanes of one group share: the grid, its sub-steps and the stiffness tables."""
    arrays = [setup.pair_stiffness, setup.period_stiffness, setup.factor_pinion, setup.factor_gear, setup.breakpoints]
    for schedule in plan.schedules:
        # the arrays hold as many sub-steps as a period may have; those past the last are not set
        n_sub = int(schedule[0][-1])
        arrays.append(schedule[0])
        arrays.extend(values[:n_sub] for values in schedule[1:5])
    return (plan.period, tuple(plan.bands), *(np.ascontiguousarray(a).tobytes() for a in arrays))


def _lane_groups(setups: Sequence[ModelSetup], plans: Sequence[_Plan]) -> list[list[int]]:
    """The samples in lane groups of up to ``LANES`` (a run alone in its group: a group of one)."""
    by_key: dict[tuple[Any, ...], list[int]] = {}
    ready = lane_ready(np.array([setup.parameters for setup in setups]))
    groups: list[list[int]] = []
    for i, (setup, plan) in enumerate(zip(setups, plans)):
        if ready[i]:
            by_key.setdefault(_lane_key(setup, plan), []).append(i)
        else:
            groups.append([i])
    for members in by_key.values():
        groups.extend(members[j : j + LANES] for j in range(0, len(members), LANES))
    return groups


def _lane_arguments(
    members: list[int], setups: Sequence[ModelSetup], plans: Sequence[_Plan], states: np.ndarray, n_out: int
) -> tuple[Any, ...]:
    """The arguments of :func:`uqgear.physics._runup_lanes.integrate_runup_lanes` for a group's first band
    (padding lanes repeat the first run)."""
    lanes = members + [members[0]] * (LANES - len(members))
    lead = setups[members[0]]
    params = np.array([setups[i].parameters for i in lanes])
    live = np.arange(LANES) < len(members)
    W = RL.lane_work(np.ascontiguousarray(states[lanes]), params)
    tables = (lead.pair_stiffness, lead.period_stiffness, lead.factor_pinion, lead.factor_gear)
    plan = plans[members[0]]
    stages = np.array([plans[i].schedules[0][5] for i in lanes])
    history = np.empty((LANES, n_out, len(HISTORY_COLUMNS)))
    return (W, live, params, *tables, plan.schedules[0], stages, plan.period, plan.warps, plan.out_tau, 0, history)


def _integrate_lanes(
    members: list[int], setups: Sequence[ModelSetup], plans: Sequence[_Plan], states: np.ndarray, n_out: int
) -> np.ndarray:
    """History rows (member, time, column) of a lane group, band by band."""
    arguments = list(_lane_arguments(members, setups, plans, states, n_out))
    lanes = members + [members[0]] * (LANES - len(members))
    o = 0
    for b, (first, stop, _) in enumerate(plans[members[0]].bands):
        arguments[7] = plans[members[0]].schedules[b]
        arguments[8] = np.array([plans[i].schedules[b][5] for i in lanes])
        arguments[12] = o
        o = RL.integrate_runup_lanes(first, stop, *arguments)
    return arguments[13][: len(members)]


def _integrate_scipy(
    setup: ModelSetup, profile: SpeedProfile, out_t: np.ndarray, state0: np.ndarray, rtol: float, atol: float | None
) -> np.ndarray:
    """History rows at ``out_t`` by DOP853 in physical time between the stiffness breakpoints."""
    p = setup.parameters
    tables = (setup.pair_stiffness, setup.period_stiffness, setup.factor_pinion, setup.factor_gear)
    omega_ref = setup.pinion_rotation
    period = 2.0 * math.pi / p[K.OMEGA_MESH]
    b = p[K.HALF_BACKLASH]
    atol_vector = setup.state_scale() * (rtol if atol is None else atol)
    n_periods = int(math.ceil(float(profile.angle(profile.duration)) / omega_ref / period)) + 1
    phases = np.concatenate([[0.0], setup.breakpoints, [1.0]])
    edges_tau = (np.arange(n_periods)[:, None] + phases[None, :]) * period
    edges_t = _clock(profile, edges_tau.ravel() * omega_ref, omega_ref)[0].reshape(edges_tau.shape)
    history = np.empty((out_t.size, len(HISTORY_COLUMNS)))
    row = np.empty(len(HISTORY_COLUMNS))
    state = np.asarray(state0, dtype=float).copy()
    levels = np.array([-b, b])
    above = state[2] > levels

    def clock(t: float) -> tuple[float, float, float]:
        tc = min(max(t, 0.0), profile.duration)
        return (
            float(profile.angle(tc)) / omega_ref,
            float(profile.angular_speed(tc)) / omega_ref,
            float(profile.acceleration(tc)) / omega_ref,
        )

    for n in range(n_periods):
        for i in range(phases.size - 1):
            t_a, t_b = edges_t[n, i], min(edges_t[n, i + 1], profile.duration)
            if t_a >= profile.duration:
                return history
            tau_ref = 0.5 * (edges_tau[n, i] + edges_tau[n, i + 1])

            def fun(t: float, y: np.ndarray, tau_ref: float = tau_ref) -> np.ndarray:
                tau, rate, accel = clock(t)
                d = R.runup_rhs(tau, tau_ref, t, rate, accel, y, p, *tables, row)
                return np.array(d)

            while t_a < t_b:
                events = [boundary_event(level, bool(up)) for level, up in zip(levels, above)]
                sol = solve_ivp(
                    fun,
                    (t_a, t_b),
                    state,
                    method="DOP853",
                    rtol=rtol,
                    atol=atol_vector,
                    events=events,
                    dense_output=True,
                )
                t_end = sol.t[-1]
                last = t_end >= profile.duration
                for k in np.nonzero((out_t >= t_a) & ((out_t < t_end) | last & (out_t <= t_end)))[0]:
                    y = sol.sol(out_t[k]) if out_t[k] > t_a else state
                    tau, rate, accel = clock(out_t[k])
                    # the pairs just after the sample (one on a segment's end takes the next segment's)
                    after = tau + 1e-9 * period
                    R.runup_rhs(tau, after, out_t[k], rate, accel, np.ascontiguousarray(y), p, *tables, history[k])
                state = sol.y[:, -1].copy()
                if sol.status == 1:
                    fired = next(j for j, te in enumerate(sol.t_events) if te.size)
                    above[fired] = not above[fired]
                else:
                    above = state[2] > levels
                t_a = t_end
    return history


def _profile_variables(profile: SpeedProfile, out_t: np.ndarray, z1: int) -> dict[str, tuple[Any, ...]]:
    angle = profile.angle(out_t)
    return {
        "pinion_speed": ("time", profile.speed(out_t), {"units": "rpm", "long_name": "pinion speed n1"}),
        "pinion_angle": ("time", angle, {"units": "rad", "long_name": "pinion angle theta1 (unwrapped, 0 at t = 0)"}),
        "mesh_phase": (
            "time",
            z1 * angle / (2.0 * math.pi),
            {"units": "1", "long_name": "mesh cycles z1 theta1 / 2 pi"},
        ),
    }


def _history_variables(history: np.ndarray, dims: tuple[str, ...]) -> dict[str, tuple[Any, ...]]:
    """The history columns (and te) as Dataset variables; ``history`` (..., time, column)."""
    data: dict[str, tuple[Any, ...]] = {}
    for column, name in enumerate(HISTORY_COLUMNS):
        values = history[..., column].astype(np.int8) if name == "contact" else history[..., column]
        data[name] = (dims, values, {"units": _UNITS[name], "long_name": _LONG_NAMES[name]})
    te = history[..., 2] - history[..., 0] + history[..., 1] + history[..., 10]
    data["te"] = (dims, te, {"units": "m", "long_name": _LONG_NAMES["te"]})
    return data


def _run_attrs(profile: SpeedProfile, sample_rate: float, steps: int, run_in: int | None) -> dict[str, Any]:
    return {
        "profile_kind": profile.kind,
        "profile_direction": profile.direction,
        "start_speed": profile.start_speed,
        "stop_speed": profile.stop_speed,
        "duration": profile.duration,
        "reference_speed": profile.start_speed,
        "sample_rate": float(sample_rate),
        "steps_per_period": steps,
        "run_in_periods": -1 if run_in is None else run_in,
        "units_note": "SI units; speeds in rpm",
    }


def _check_method(method: str) -> None:
    if method not in METHODS:
        raise OperatingPointError(f"method: expected one of {', '.join(METHODS)}; got {method!r}")


def simulate_runup(
    design: Design,
    profile: SpeedProfile,
    drive_torque: float,
    adhesion_torque: float,
    *,
    method: str = "fast",
    sample_rate: float = 20480.0,
    mesh_stiffness_scale: float = 1.0,
    effects: Sequence[Effect] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    steps_per_mode: int = 24,
    rtol: float = 1e-10,
    atol: float | None = None,
    initial_state: np.ndarray | None = None,
    run_in_periods: int = RUN_IN_PERIODS,
) -> xr.Dataset:
    """Simulate the gear pair through a prescribed pinion speed profile (a run-up or a coast-down).

    The forcing follows the pinion angle theta1(t) (module docstring and
    docs/model/run-up.md). Unless ``initial_state`` is given the run starts
    from the state reached after ``run_in_periods`` mesh periods at the
    start speed from static equilibrium (a constant-speed run-in on the fast
    path, :func:`uqgear.physics.integration.simulate_batch`, for either
    method), at mesh phase 0.

    Parameters
    ----------
    design : Design
    profile : SpeedProfile
        Pinion speed against time, within the design's ``operation.pinion_speed_sweep``.
    drive_torque, adhesion_torque : float
        T1 and T2 in N m (constant; effects may modulate them).
    method : {"fast", "scipy"}
        RK4 in warped time (compiled), or DOP853 in physical time (the reference).
    sample_rate : float
        Output samples per second, uniform in time from t = 0 to the profile's end.
    mesh_stiffness_scale, effects, damping_in_separation, stiffness, rtol, atol
        As in :func:`uqgear.simulate`.
    steps_per_mode : int
        Fast path: RK4 steps per period of the highest natural frequency. The
        grid is uniform in mesh phase over bands of mesh periods, each with the
        steps its lowest speed needs (:func:`step_bands`; attrs ``band_first_period``
        and ``band_steps``); ``steps_per_period`` in attrs is the most of them.
    initial_state : array of 6, optional
        (y1, y2, x, y1', y2', x') at t = 0 (mesh phase 0).
    run_in_periods : int
        Length of the run-in.

    Returns
    -------
    xarray.Dataset
        On dim ``time`` (s): ``pinion_speed`` (rpm), ``pinion_angle`` (rad,
        unwrapped), ``mesh_phase`` (mesh cycles), the state, ``y1_acceleration``,
        ``y2_acceleration``, ``mesh_force``, ``mesh_stiffness``, ``ste``,
        ``contact`` and ``te``, each with ``units``; the design and the run in attrs.

    Examples
    --------
    A 0.05 s ramp 2000 -> 2200 rpm at 10.24 kHz (a short run-in): the mesh phase is z1 theta1 / 2 pi,
    and the teeth stay in contact:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> ramp = uqgear.SpeedProfile.linear(2000.0, 2200.0, 0.05)
    >>> run = uqgear.simulate_runup(design, ramp, 7000.0, 33.8e3, sample_rate=10240.0, run_in_periods=40)
    >>> run.sizes["time"], round(float(run["mesh_phase"][-1]), 3), int(run["contact"].min())
    (513, 36.75, 1)
    """
    _check_method(method)
    setup, out_t, history, bands = _run(
        design,
        profile,
        (drive_torque, adhesion_torque, mesh_stiffness_scale),
        _run_options(effects, damping_in_separation, stiffness, steps_per_mode, run_in_periods, 1),
        sample_rate,
        initial_state,
        (method, rtol, atol),
    )
    steps = max((band[2] for band in bands), default=0)
    data = _profile_variables(profile, out_t, design.z1)
    data.update(_history_variables(history, ("time",)))
    ds = xr.Dataset(data, coords={"time": ("time", out_t, {"units": "s", "long_name": "time"})})
    ds.attrs.update(_attrs(setup, method, 0, 0, steps))
    for key in ("pinion_speed", "n_periods", "keep_periods", "mesh_frequency", "mesh_period"):
        ds.attrs.pop(key, None)
    ds.attrs.update(
        _run_attrs(profile, float(sample_rate), steps, None if initial_state is not None else run_in_periods)
    )
    if method == "scipy":
        ds.attrs.update(rtol=rtol, solver="DOP853")
    else:
        ds.attrs.update(
            band_first_period=np.array([band[0] for band in bands]), band_steps=np.array([band[2] for band in bands])
        )
    return ds


def simulate_runup_batch(
    design: Design,
    profile: SpeedProfile,
    samples: xr.Dataset,
    *,
    sample_rate: float = 20480.0,
    variables: Sequence[str] = BATCH_VARIABLES,
    effects: Sequence[Effect] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    steps_per_mode: int = 24,
    threads: int | None = None,
    initial_states: np.ndarray | None = None,
    run_in_periods: int = RUN_IN_PERIODS,
    lanes: bool = True,
) -> xr.Dataset:
    """Many samples (adhesion torques, stiffness scales, design keys, effect parameters) through one profile.

    The samples share the profile, hence the warped-time grid: those that
    also share its sub-steps in every band (the same stiffness scale and
    design, any torques) step together, eight at a time, as SIMD lanes
    (:mod:`uqgear.physics._runup_lanes`); any other runs alone on the
    compiled one-run kernel of :func:`simulate_runup`. Lane groups and lone
    runs are spread over threads (:func:`uqgear.physics.threads.spread`);
    the run-ins are one :func:`uqgear.simulate_batch`. A sample gives the
    same numbers, bit for bit, as :func:`simulate_runup` with its values.

    Parameters
    ----------
    samples : xarray.Dataset
        Sample variables on dim ``sample`` as for :func:`uqgear.simulate_batch`,
        except ``pinion_speed`` (the profile sets it).
    variables : sequence of str
        History variables returned on (sample, time).
    threads, initial_states
        As in :func:`uqgear.simulate_batch`.
    sample_rate, effects, damping_in_separation, stiffness, steps_per_mode, run_in_periods
        As in :func:`simulate_runup`.
    lanes : bool
        Step runs of one grid together as SIMD lanes; False runs every sample
        on the one-run kernel. The numbers are the same, bit for bit.

    Returns
    -------
    xarray.Dataset
        ``pinion_speed``, ``pinion_angle``, ``mesh_phase`` on ``time``, the
        ``variables`` on (``sample``, ``time``), the sample variables as
        coordinates on ``sample``.

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> ramp = uqgear.SpeedProfile.linear(2000.0, 2200.0, 0.02)
    >>> samples = uqgear.samples_from_mapping({"drive_torque": [7000.0] * 2, "adhesion_torque": [25e3, 40e3]})
    >>> runs = uqgear.simulate_runup_batch(design, ramp, samples, sample_rate=10240.0, run_in_periods=40)
    >>> dict(runs["te"].sizes), bool((runs["mesh_force"].mean("time").diff("sample") > 0).all())
    ({'sample': 2, 'time': 205}, True)
    """
    check_speed_range(design, profile)
    _check_batch_request(samples, variables)
    n = samples.sizes.get("sample", 0)
    full = samples.assign(pinion_speed=("sample", np.full(n, profile.start_speed)))
    setups = build_batch(
        design, full, effects=effects, damping_in_separation=damping_in_separation, stiffness=stiffness
    )
    options = _run_options(effects, damping_in_separation, stiffness, steps_per_mode, run_in_periods, threads)
    states = _batch_states(design, full, options, initial_states)
    out_t = _output_times(profile, float(sample_rate))
    plans = _plans(setups, steps_per_mode, profile, out_t)
    steps = np.array([max(band[2] for band in plan.bands) for plan in plans], dtype=np.int64)
    history = _integrate_batch(setups, plans, states, profile, out_t, steps_per_mode, threads, lanes)
    data = _profile_variables(profile, out_t, design.z1)
    everything = _history_variables(history, ("sample", "time"))
    data.update({name: everything[name] for name in variables})
    data["steps_per_period"] = ("sample", steps, {"units": "1", "long_name": "most RK4 steps per mesh period"})
    coords: dict[Hashable, tuple[Any, ...]] = {"time": ("time", out_t, {"units": "s", "long_name": "time"})}
    for name in samples.data_vars:
        coords[name] = ("sample", samples[name].values, dict(samples[name].attrs))
    ds = xr.Dataset(data, coords=coords)
    ds.attrs.update({f"design_{key}": value for key, value in design.to_dict().items()})
    ds.attrs.update(design_name=design.name, method="fast", stiffness=stiffness, steps_per_mode=steps_per_mode)
    ds.attrs.update(
        damping_in_separation=int(damping_in_separation), effects="; ".join(repr(e) for e in effects) or "none"
    )
    ds.attrs.update(
        _run_attrs(
            profile,
            float(sample_rate),
            int(steps.max()) if n else 0,
            None if initial_states is not None else run_in_periods,
        )
    )
    return ds


def _run_options(
    effects: Sequence[Effect],
    damping_in_separation: bool,
    stiffness: str,
    steps_per_mode: int,
    run_in_periods: int,
    threads: int | None,
) -> dict[str, Any]:
    """The model and integration options a run-up passes to its run-in and its set-ups."""
    return {
        "effects": tuple(effects),
        "damping_in_separation": damping_in_separation,
        "stiffness": stiffness,
        "steps_per_mode": steps_per_mode,
        "run_in_periods": run_in_periods,
        "threads": threads,
    }


def _run(
    design: Design,
    profile: SpeedProfile,
    loads: tuple[float, float, float],
    options: dict[str, Any],
    sample_rate: float,
    initial_state: np.ndarray | None,
    solver: tuple[str, float, float | None],
) -> tuple[ModelSetup, np.ndarray, np.ndarray, list[tuple[int, int, int]]]:
    """One run through ``profile``: its set-up, output times, history rows and bands (:func:`simulate_runup`)."""
    check_speed_range(design, profile)
    drive_torque, adhesion_torque, mesh_stiffness_scale = loads
    samples = samples_from_mapping(
        {
            "pinion_speed": [profile.start_speed],
            "drive_torque": [drive_torque],
            "adhesion_torque": [adhesion_torque],
            "mesh_stiffness_scale": [mesh_stiffness_scale],
        }
    )
    setup = build_batch(
        design,
        samples,
        effects=options["effects"],
        damping_in_separation=options["damping_in_separation"],
        stiffness=options["stiffness"],
    )[0]
    if initial_state is None:
        state0 = _run_in(design, samples, options)[0]
    else:
        state0 = np.asarray(initial_state, dtype=float)
        if state0.shape != (6,) or not np.all(np.isfinite(state0)):
            raise OperatingPointError(
                f"initial_state: expected 6 finite values (y1, y2, x, y1', y2', x'); got shape {state0.shape}"
            )
    out_t = _output_times(profile, float(sample_rate))
    method, rtol, atol = solver
    if method == "fast":
        history, bands = _integrate_fast(setup, options["steps_per_mode"], profile, out_t, state0)
        return setup, out_t, history, bands
    return setup, out_t, _integrate_scipy(setup, profile, out_t, state0, rtol, atol), []


def runup_history(
    design: Design,
    profile: SpeedProfile,
    drive_torque: float,
    adhesion_torque: float,
    *,
    sample_rate: float,
    mesh_stiffness_scale: float = 1.0,
    effects: Sequence[Effect] = (),
    steps_per_mode: int = 24,
    run_in_periods: int = RUN_IN_PERIODS,
) -> tuple[np.ndarray, np.ndarray]:
    """The fast path of :func:`simulate_runup` as arrays: output times (s) and history rows (time, column).

    The columns are :data:`uqgear.physics.model.HISTORY_COLUMNS`; the numbers are those of
    :func:`simulate_runup` with the same arguments, bit for bit, without building its Dataset (which
    costs as much as integrating a fraction of a second: a caller that simulates many short runs and
    reads two or three columns, the diagnosis's model of a ramp segment, skips it).

    Examples
    --------
    >>> import numpy as np, uqgear
    >>> from uqgear.physics.runup import runup_history
    >>> design = uqgear.load_design("locomotive")
    >>> ramp = uqgear.SpeedProfile.linear(2000.0, 2200.0, 0.05)
    >>> times, history = runup_history(design, ramp, 7000.0, 33.8e3, sample_rate=10240.0, run_in_periods=40)
    >>> run = uqgear.simulate_runup(design, ramp, 7000.0, 33.8e3, sample_rate=10240.0, run_in_periods=40)
    >>> history.shape, bool(np.array_equal(history[:, 0], run["y1"].values))
    ((513, 12), True)
    """
    options = _run_options(effects, True, "ishikawa", steps_per_mode, run_in_periods, 1)
    _, out_t, history, _ = _run(
        design, profile, (drive_torque, adhesion_torque, mesh_stiffness_scale), options, sample_rate, None,
        ("fast", 1e-10, None),
    )
    return out_t, history


def _check_batch_request(samples: xr.Dataset, variables: Sequence[str]) -> None:
    if "pinion_speed" in samples.data_vars:
        raise OperatingPointError(
            "samples: pinion_speed is set by the speed profile; expected no pinion_speed variable"
        )
    unknown = [name for name in variables if name not in HISTORY_COLUMNS and name != "te"]
    if unknown:
        raise OperatingPointError(f"variables: expected names of {', '.join(HISTORY_COLUMNS)} or te; got {unknown}")


def _batch_states(design: Design, full: xr.Dataset, options: dict, initial_states: np.ndarray | None) -> np.ndarray:
    """Each run's start: the given states, checked, or the state after its run-in at the start speed."""
    n = full.sizes.get("sample", 0)
    if initial_states is None:
        return _run_in(design, full, options)
    states = np.asarray(initial_states, dtype=float)
    if states.shape != (n, 6) or not np.all(np.isfinite(states)):
        raise OperatingPointError(
            f"initial_states: expected finite values of shape ({n}, 6); got shape {states.shape}"
        )
    return states


def _integrate_batch(
    setups: Sequence[ModelSetup],
    plans: Sequence[_Plan],
    states: np.ndarray,
    profile: SpeedProfile,
    out_t: np.ndarray,
    steps_per_mode: int,
    threads: int | None,
    lanes: bool,
) -> np.ndarray:
    """Every run's history, shape (runs, times, HISTORY_COLUMNS): lane groups and lone runs spread over threads."""
    n = len(setups)
    history = np.empty((n, out_t.size, len(HISTORY_COLUMNS)))
    groups = _lane_groups(setups, plans) if lanes else [[i] for i in range(n)]
    lane_groups = [members for members in groups if len(members) > 1]
    if lane_groups:
        # compiled once, before the threads start (the lanes' vector width is a process-wide option)
        RL.compile_runup_lanes(*_lane_arguments(lane_groups[0], setups, plans, states, 0))

    def run_range(start: int, stop: int) -> None:
        for members in groups[start:stop]:
            if len(members) > 1:
                history[members] = _integrate_lanes(members, setups, plans, states, out_t.size)
            else:
                history[members[0]] = _integrate_fast(setups[members[0]], steps_per_mode, profile, out_t,
                                                      states[members[0]])[0]

    spread(run_range, len(groups), threads)
    return history


__all__ = [
    "simulate_runup",
    "runup_history",
    "simulate_runup_batch",
    "check_speed_range",
    "step_bands",
    "RUN_IN_PERIODS",
    "BATCH_VARIABLES",
    "BAND_SHRINK",
    "BAND_GROWTH",
]
