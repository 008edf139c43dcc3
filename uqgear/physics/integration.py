"""Integrators: the scipy reference and the compiled fast path.

* ``method="scipy"``: :func:`scipy.integrate.solve_ivp` (DOP853, tight
  tolerances) on segments between the known stiffness breakpoints, with
  terminal events at the contact boundaries |x| = b so every switch of the
  backlash function is resolved. This is the accuracy reference.
* ``method="fast"``: fixed-step RK4 compiled with numba (see
  :mod:`uqgear.physics._kernels`), step length set by the highest natural frequency
  (``steps_per_mode`` steps per period of the fastest mode) and an integer
  number of steps per mesh period, with stiffness breakpoints and contact
  crossings located inside steps. :func:`simulate_batch` runs many samples in
  parallel over cores and keeps only QoIs, Poincare points and optionally a
  decimated DTE history.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import OperatingPointError
from . import _kernels as K
from ._batch_record import QoiBatch
from .batch_dataset import QOI_INFO as QOI_INFO
from .batch_dataset import STATE_NAMES as STATE_NAMES
from .batch_dataset import VARIABLE_LONG_NAMES, VARIABLE_UNITS, BatchArrays, batch_dataset

# BATCH_DESIGN_KEYS: the rig, the dynamics and the calibration import it from here
from .batch_setup import BATCH_DESIGN_KEYS as BATCH_DESIGN_KEYS
from .batch_setup import build_batch, integrate_lane_groups, kernel_inputs
from .design import Design
from .design_parts import ModalDesign
from .effect_draws import as_effect
from .effects import Effect
from .model import HISTORY_COLUMNS, ModelSetup, build_model, cached_tables, natural_frequencies
from .pitch_errors import PitchErrors
from .scipy_reference import integrate_scipy
from .threads import spread

METHODS = ("fast", "scipy")
_UNITS, _LONG_NAMES = VARIABLE_UNITS, VARIABLE_LONG_NAMES


def _check_counts(n_periods: int, keep_periods: int) -> None:
    if int(n_periods) != n_periods or n_periods < 1:
        raise OperatingPointError(f"n_periods: expected a positive integer; got {n_periods!r}")
    if int(keep_periods) != keep_periods or not 1 <= keep_periods <= n_periods:
        raise OperatingPointError(
            f"keep_periods: expected an integer in [1, n_periods={n_periods}]; got {keep_periods!r}"
        )


def _highest_mode(design: Design, stiffness_scale: float) -> float:
    """Highest natural frequency (Hz) at the peak mesh stiffness, cached on the design's modal part."""
    return _modal_highest(design.modal_design, float(stiffness_scale))


@functools.lru_cache(maxsize=4096)
def _modal_highest(modal: ModalDesign, stiffness_scale: float) -> float:
    k_peak = float(np.max(cached_tables(modal, "ishikawa").period_stiffness)) * stiffness_scale
    return float(natural_frequencies(modal, k_peak)[-1])


#: Fewest grid steps a mesh period.
MINIMUM_STEPS = 32


def steps_per_period(
    setup: ModelSetup, steps_per_mode: int = 24, minimum: int = MINIMUM_STEPS, multiple_of: int = 1
) -> int:
    """Grid steps per mesh period for the fast integrator.

    Enough steps for ``steps_per_mode`` per period of the highest natural
    frequency (with the peak mesh stiffness), at least ``minimum``, rounded
    up to a multiple of ``multiple_of`` (the output sampling).
    """
    f_high = _highest_mode(setup.design, float(setup.parameters[K.STIFFNESS_SCALE]))
    return _steps_for(f_high, setup.mesh_frequency, steps_per_mode, minimum, multiple_of)


def _steps_for(f_high: float, mesh_frequency: float, steps_per_mode: int, minimum: int, multiple_of: int) -> int:
    needed = max(minimum, math.ceil(steps_per_mode * f_high / mesh_frequency))
    return int(math.ceil(needed / multiple_of) * multiple_of)


def _batch_steps(setups: Sequence[ModelSetup], steps_per_mode: int, multiple_of: int) -> np.ndarray:
    """:func:`steps_per_period` of each set-up, the highest mode looked up once per design and stiffness scale."""
    highest: dict[tuple[int, float], float] = {}
    steps = np.empty(len(setups), dtype=np.int64)
    for i, setup in enumerate(setups):
        # the set-ups hold their designs, so an id stands for one design while this runs
        key = (id(setup.design), float(setup.parameters[K.STIFFNESS_SCALE]))
        if key not in highest:
            highest[key] = _highest_mode(setup.design, key[1])
        steps[i] = _steps_for(highest[key], setup.mesh_frequency, steps_per_mode, MINIMUM_STEPS, multiple_of)
    return steps


def _attrs(setup: ModelSetup, method: str, n_periods: int, keep_periods: int, steps: int) -> dict:
    p = setup.parameters
    attrs = {f"design_{key}": value for key, value in setup.design.to_dict().items()}
    attrs.update(
        {
            "design_name": setup.design.name,
            "pinion_speed": float(p[K.OMEGA_MESH] * 60.0 / (2.0 * math.pi * setup.design.z1)),
            "drive_torque": float(p[K.T1]),
            "adhesion_torque": float(p[K.T2]),
            "mesh_stiffness_scale": float(p[K.STIFFNESS_SCALE]),
            "mesh_frequency": setup.mesh_frequency,
            "mesh_period": 1.0 / setup.mesh_frequency,
            "half_backlash": float(p[K.HALF_BACKLASH]),
            "z1": setup.design.z1,
            "z2": setup.design.z2,
            "method": method,
            "n_periods": n_periods,
            "keep_periods": keep_periods,
            "steps_per_period": steps,
            "damping_in_separation": int(p[K.DAMP_IN_SEPARATION]),
            "stiffness": setup.stiffness,
            "mesh_damping": float(p[K.CM]),
            "effects": "; ".join(repr(e) for e in setup.effects) or "none",
            "units_note": "SI units; pinion_speed in rpm",
        }
    )
    attrs.update({key: float(value) for key, value in setup.derived.items()})
    if setup.pitch_errors is not None:
        attrs.update(
            pitch_errors_pinion=setup.pitch_errors.pinion.copy(), pitch_errors_gear=setup.pitch_errors.gear.copy()
        )
    return attrs


def _integrate_fast(
    setup: ModelSetup,
    n_periods: int,
    keep_periods: int,
    samples_per_period: int,
    steps_per_mode: int,
    initial_state: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, int]:
    steps = steps_per_period(setup, steps_per_mode, multiple_of=samples_per_period)
    stride = steps // samples_per_period
    history = np.empty((keep_periods * samples_per_period, len(HISTORY_COLUMNS)))
    poincare = np.empty((keep_periods, 6))
    kernel = K.integrate_history_pairs if setup.parameters[K.PITCH_ERRORS] != 0.0 else K.integrate_history
    kernel(
        initial_state.astype(float),
        setup.parameters,
        setup.pair_stiffness,
        setup.period_stiffness,
        setup.factor_pinion,
        setup.factor_gear,
        setup.breakpoints,
        steps,
        n_periods,
        keep_periods,
        stride,
        history,
        poincare,
    )
    return history, poincare, steps


def simulate(
    design: Design,
    pinion_speed: float,
    drive_torque: float,
    adhesion_torque: float,
    *,
    method: str = "fast",
    n_periods: int = 400,
    keep_periods: int = 200,
    samples_per_period: int = 64,
    mesh_stiffness_scale: float = 1.0,
    effects: Sequence[Effect] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    steps_per_mode: int = 24,
    rtol: float = 1e-10,
    atol: float | None = None,
    initial_state: np.ndarray | None = None,
    pitch_errors: PitchErrors | None = None,
) -> xr.Dataset:
    """Simulate one operating point of the gear pair.

    Parameters
    ----------
    design : Design
        Gear design (:func:`uqgear.load_design`).
    pinion_speed : float
        Pinion speed n1 in rpm (> 0).
    drive_torque, adhesion_torque : float
        T1 and T2 in N m.
    method : {"fast", "scipy"}
        Compiled RK4 fast path or the scipy reference.
    n_periods, keep_periods : int
        Mesh periods integrated in total and kept at the end (the rest is the
        transient).
    samples_per_period : int
        Output samples per mesh period in the kept histories.
    mesh_stiffness_scale : float
        Factor on the Ishikawa mesh stiffness.
    effects : sequence of Effect
        Model extensions (:mod:`uqgear.physics.effects`).
    damping_in_separation : bool
        Mesh damping acts while the teeth are apart (classical form).
    stiffness : {"ishikawa", "fourier"}
        Raw stiffness curve or its truncated Fourier series.
    steps_per_mode : int
        Fast path: RK4 steps per period of the highest natural frequency.
    rtol, atol : float
        Scipy reference tolerances (atol relative to the state's scale).
    initial_state : array of 6, optional
        (y1, y2, x, y1', y2', x') at t = 0; static equilibrium by default.
    pitch_errors : PitchErrors, optional
        Per-tooth pitch offsets (:mod:`uqgear.physics.pitch_errors`); with
        them ``contact`` is 1 while some pair is in drive-side contact.

    Returns
    -------
    xarray.Dataset
        Histories on ``time`` (kept periods), Poincare points on ``period``
        (state at each kept mesh-period start), every parameter in attrs
        (the pitch errors as ``pitch_errors_pinion`` and ``_gear``, m).

    Examples
    --------
    A short run at 2000 rpm (60 mesh periods, the last 20 kept, 64 samples each): the teeth stay in
    contact, and the mesh force oscillates about the mean mesh force F_T that the torques impose:

    >>> import uqgear
    >>> run = uqgear.simulate(uqgear.load_design("locomotive"), 2000.0, 7000.0, 33e3, n_periods=60, keep_periods=20)
    >>> run.sizes["time"], run["period"].values[[0, -1]].tolist(), float(run["contact"].mean())
    (1280, [40, 59], 1.0)
    >>> force_ratio = float(run["mesh_force"].mean()) / run.attrs["static_mesh_force"]
    >>> round(force_ratio, 2), round(float(run["x"].std()) * 1e6, 2)       # DTE RMS in um
    (1.0, 9.43)
    """
    if method not in METHODS:
        raise OperatingPointError(f"method: expected one of {', '.join(METHODS)}; got {method!r}")
    _check_counts(n_periods, keep_periods)
    if int(samples_per_period) != samples_per_period or samples_per_period < 1:
        raise OperatingPointError(f"samples_per_period: expected a positive integer; got {samples_per_period!r}")
    setup = build_model(
        design,
        pinion_speed,
        drive_torque,
        adhesion_torque,
        mesh_stiffness_scale=mesh_stiffness_scale,
        effects=effects,
        damping_in_separation=damping_in_separation,
        stiffness=stiffness,
        pitch_errors=pitch_errors,
    )
    state0 = setup.static_state() if initial_state is None else np.asarray(initial_state, dtype=float)
    if state0.shape != (6,):
        raise OperatingPointError(
            f"initial_state: expected 6 values (y1, y2, x, y1', y2', x'); got shape {state0.shape}"
        )
    if method == "fast":
        history, poincare, steps = _integrate_fast(
            setup, n_periods, keep_periods, samples_per_period, steps_per_mode, state0
        )
        extra: dict[str, Any] = {"steps_per_mode": steps_per_mode}
    else:
        history, poincare, stats = integrate_scipy(
            setup, n_periods, keep_periods, samples_per_period, state0, rtol, atol
        )
        steps = samples_per_period
        extra = {"rtol": rtol, "solver": "DOP853", **stats}
    period = 1.0 / setup.mesh_frequency
    first_kept = n_periods - keep_periods
    time = (first_kept + np.arange(keep_periods * samples_per_period) / samples_per_period) * period
    data = {}
    for column, name in enumerate(HISTORY_COLUMNS):
        values = history[:, column].astype(np.int8) if name == "contact" else history[:, column]
        data[name] = ("time", values, {"units": _UNITS[name], "long_name": _LONG_NAMES[name]})
    te = history[:, 2] - history[:, 0] + history[:, 1] + history[:, 10]
    data["te"] = ("time", te, {"units": "m", "long_name": _LONG_NAMES["te"]})
    for column, name in enumerate(("y1", "y2", "x", "y1_velocity", "y2_velocity", "x_velocity")):
        data[f"poincare_{name}"] = (
            "period",
            poincare[:, column],
            {"units": _UNITS[name], "long_name": f"{name} once per mesh period"},
        )
    ds = xr.Dataset(
        data,
        coords={
            "time": ("time", time, {"units": "s", "long_name": "time"}),
            "period": ("period", np.arange(first_kept, n_periods), {"units": "1", "long_name": "mesh period index"}),
        },
    )
    ds.attrs.update(_attrs(setup, method, n_periods, keep_periods, steps))
    ds.attrs.update(samples_per_period=samples_per_period, **extra)
    return ds


# ---------------------------------------------------------------------------- batches


def _run_batch(batch: QoiBatch, threads: int | None, lanes: bool = True) -> None:
    """Integrate a batch: lane-ready runs in lane groups, the others (and any the lanes refuse) one at a time.

    Each run's numbers are the same, bit for bit, whichever kernel and thread compute it.
    """
    params = batch.runs.params
    rest = integrate_lane_groups(batch, threads) if lanes else np.arange(len(params), dtype=np.int64)
    if len(rest):
        # the pair path is compiled only for a batch with pitch errors
        pitch = params[rest, K.PITCH_ERRORS] != 0.0
        for kernel, order in ((K.integrate_batch, rest[~pitch]), (K.integrate_batch_pairs, rest[pitch])):
            if len(order):

                def run_range(start: int, stop: int, kernel: Any = kernel, order: np.ndarray = order) -> None:
                    kernel(start, stop, order, batch)

                spread(run_range, len(order), threads)


def _initial_states(setups: Sequence[ModelSetup], initial_states: np.ndarray | None) -> np.ndarray:
    """Each run's start: the given states, checked, or each one's static equilibrium."""
    n = len(setups)
    if initial_states is None:
        return np.stack([s.static_state() for s in setups]) if n else np.empty((0, 6))
    states = np.array(initial_states, dtype=float)
    if states.shape != (n, 6) or not np.all(np.isfinite(states)):
        raise OperatingPointError(
            f"initial_states: expected finite values of shape ({n}, 6) "
            f"(y1, y2, x, y1', y2', x' per sample); got shape {states.shape}"
        )
    return states


def simulate_batch(
    design: Design,
    samples: xr.Dataset,
    *,
    n_periods: int = 400,
    keep_periods: int = 200,
    history_per_period: int = 0,
    rig_channels: bool = False,
    lyapunov: bool = False,
    effects: Sequence[Effect] = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    steps_per_mode: int = 24,
    threads: int | None = None,
    pitch_errors: PitchErrors | None = None,
    initial_states: np.ndarray | None = None,
    final_state: bool = False,
    lanes: bool = True,
    stresses: bool = False,
) -> xr.Dataset:
    """Simulate many parameter samples in parallel, keeping only what is asked.

    Parameters
    ----------
    design : Design
        Base design; sample variables named like design keys override it.
    samples : xarray.Dataset
        Dimension ``sample``; variables among ``pinion_speed`` (rpm, required),
        ``drive_torque`` (N m; default the design's rated torque),
        ``adhesion_torque`` (N m; default T1 z2/z1, the balancing value),
        ``mesh_stiffness_scale``, design keys (``k1``, ``backlash``, ...) and
        ``EFFECT.PARAMETER`` for effects passed in ``effects``.
    n_periods, keep_periods : int
        Mesh periods integrated and kept.
    history_per_period : int
        If > 0, also keep the DTE ``x`` at this many points per kept mesh
        period (variable ``x_history`` on dim ``mesh_cycle``).
    rig_channels : bool
        With ``history_per_period``: also keep ``te`` (x - y1 + y2 + e),
        ``acc_pinion`` (y1'') and ``acc_gear`` (y2'') histories, the rig's channels.
    lyapunov : bool
        Also estimate the largest Lyapunov exponent (doubles the cost).
    effects, damping_in_separation, stiffness, steps_per_mode
        As in :func:`simulate`.
    threads : int, optional
        Number of threads (default: all cores).
    pitch_errors : PitchErrors, optional
        Per-tooth pitch offsets of every sample (as in :func:`simulate`).
    initial_states : array of shape (n_samples, 6), optional
        Each sample's (y1, y2, x, y1', y2', x') at t = 0 (mesh phase 0); each
        sample's static equilibrium by default.
    final_state : bool
        Also return each sample's state at the end of its last period (mesh
        phase 0 again) as ``final_state`` on dims ``sample`` and ``state``, to
        start a later batch from it (sweeps that follow a branch). The restart
        continues a mesh-periodic run exactly; effects and pitch errors with a
        longer period start their own phase again at t = 0.
    lanes : bool
        Advance runs of one sub-step layout eight at a time as SIMD lanes
        (:mod:`uqgear.physics._lanes`; with pitch errors
        :mod:`uqgear.physics._pair_lanes`); False runs every sample on the
        one-sample kernel. The numbers are the same, bit for bit.
    stresses : bool
        Also keep, in the same pass, the extremes of the tooth-pair loads over the kept grid
        steps that the tooth stresses follow from (variables of
        :data:`~uqgear.physics.batch_setup.PAIR_EXTREME_INFO`;
        :func:`~uqgear.dynamics.stress_qois.tooth_stress_qois`); the other outputs do not change.

    Returns
    -------
    xarray.Dataset
        Dims ``sample`` and ``period``: the QoIs of :data:`QOI_INFO`,
        ``poincare_x`` and ``poincare_x_velocity``; input variables as
        coordinates on ``sample``.

    Examples
    --------
    Eight adhesion torques at 2000 rpm in one call (DTE RMS in um); each sample is independent of the
    others: run alone, it gives the same numbers, bit for bit:

    >>> import numpy as np
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": np.full(8, 2000.0),
    ...                                         "adhesion_torque": np.linspace(21e3, 46e3, 8)})
    >>> batch = uqgear.simulate_batch(design, samples, n_periods=60, keep_periods=20)
    >>> (batch["dte_rms"] * 1e6).round(2).values
    array([ 6.21,  7.17,  8.13,  9.09, 10.05, 11.01, 11.97, 12.93])
    >>> alone = uqgear.simulate_batch(design, samples.isel(sample=[3]), n_periods=60, keep_periods=20)
    >>> bool(alone["dte_rms"][0] == batch["dte_rms"][3])
    True
    """
    _check_counts(n_periods, keep_periods)
    setups = build_batch(
        design,
        samples,
        effects=effects,
        damping_in_separation=damping_in_separation,
        stiffness=stiffness,
        pitch_errors=pitch_errors,
    )
    steps = _batch_steps(setups, steps_per_mode, max(int(history_per_period), 1))
    states = _initial_states(setups, initial_states)
    n = len(setups)
    arrays = BatchArrays.allocate(n, keep_periods, history_per_period, rig_channels)
    if n:
        history_stride = (steps // history_per_period) if history_per_period > 0 else np.zeros(n, dtype=np.int64)
        batch = QoiBatch(
            kernel_inputs(setups, states),
            steps,
            n_periods,
            keep_periods,
            history_stride.astype(np.int64),
            bool(lyapunov),
            np.stack([s.state_scale() for s in setups]),
            arrays.accumulators,
            arrays.poincare,
            arrays.history,
            arrays.final_states,
            bool(stresses),
            arrays.extremes,
        )
        _run_batch(batch, threads, lanes)
    return batch_dataset(
        design,
        samples,
        setups,
        steps,
        arrays,
        n_periods=n_periods,
        keep_periods=keep_periods,
        history_per_period=history_per_period,
        lyapunov=lyapunov,
        stresses=stresses,
        final_state=final_state,
        steps_per_mode=steps_per_mode,
        damping_in_separation=damping_in_separation,
        stiffness=stiffness,
        effects=effects,
        pitch_errors=pitch_errors,
    )


def samples_from_mapping(values: Mapping[str, Sequence[float] | np.ndarray]) -> xr.Dataset:
    """Build a ``sample`` Dataset from equal-length arrays (a convenience).

    Parameters
    ----------
    values : mapping of str to array-like
        One value per sample for each variable (see :func:`simulate_batch`).

    Returns
    -------
    xarray.Dataset
        One float variable on dim ``sample`` per key.

    Raises
    ------
    OperatingPointError
        The arrays differ in length.

    Examples
    --------
    >>> import uqgear
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [1000, 2000], "adhesion_torque": [21e3, 46e3]})
    >>> dict(samples.sizes), samples["pinion_speed"].dtype.name
    ({'sample': 2}, 'float64')
    """
    arrays = {name: np.atleast_1d(np.asarray(v, dtype=float)) for name, v in values.items()}
    lengths = {a.shape[0] for a in arrays.values()}
    if len(lengths) > 1:
        raise OperatingPointError(f"samples: expected equal lengths; got {sorted(lengths)}")
    return xr.Dataset({name: ("sample", a) for name, a in arrays.items()})


class BatchEvaluator:
    """The gear model as an ``evaluate(samples) -> Dataset`` function.

    A picklable callable (settings in ``__init__``) so the runner can ship it
    to dask workers; every uncertainty analysis takes a model of this form.

    Parameters
    ----------
    design : Design
    fixed : mapping, optional
        Sample variables held constant (added to every sample unless the
        samples carry them).
    n_periods, keep_periods, history_per_period, rig_channels, lyapunov, effects,
    damping_in_separation, stiffness, steps_per_mode, threads, pitch_errors, final_state, stresses
        As in :func:`simulate_batch` (``threads`` does not change the
        results, so :meth:`key` leaves it out).

    Examples
    --------
    The model at 2000 rpm and the rated torque, as a function of the adhesion
    torque alone; it returns what :func:`simulate_batch` does:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> model = uqgear.BatchEvaluator(design, fixed={"pinion_speed": 2000.0, "drive_torque": 7000.0},
    ...                               n_periods=60, keep_periods=20)
    >>> samples = uqgear.samples_from_mapping({"adhesion_torque": [21e3, 33e3]})
    >>> qois = model(samples)
    >>> (qois["dte_rms"] * 1e6).round(2).values, "pinion_speed" in samples    # the samples are not changed
    (array([6.21, 9.43]), False)
    >>> full = samples.assign(pinion_speed=("sample", [2000.0] * 2), drive_torque=("sample", [7000.0] * 2))
    >>> bool((uqgear.simulate_batch(design, full, n_periods=60, keep_periods=20)["dte_rms"] == qois["dte_rms"]).all())
    True
    """

    def __init__(
        self,
        design: Design,
        *,
        fixed: Mapping[str, float] | None = None,
        n_periods: int = 400,
        keep_periods: int = 200,
        history_per_period: int = 0,
        rig_channels: bool = False,
        lyapunov: bool = False,
        effects: Sequence[Any] = (),
        damping_in_separation: bool = True,
        stiffness: str = "ishikawa",
        steps_per_mode: int = 24,
        threads: int | None = None,
        pitch_errors: PitchErrors | None = None,
        final_state: bool = False,
        stresses: bool = False,
    ) -> None:
        _check_counts(n_periods, keep_periods)
        self.design = design
        self.fixed = dict(fixed or {})
        self.n_periods = n_periods
        self.keep_periods = keep_periods
        self.history_per_period = history_per_period
        self.rig_channels = rig_channels
        self.lyapunov = lyapunov
        # a diagnosis' effects_ (or UncertainEffects) enter at their fitted values
        self.effects = tuple(as_effect(effect) for effect in effects)
        self.damping_in_separation = damping_in_separation
        self.stiffness = stiffness
        self.steps_per_mode = steps_per_mode
        self.threads = threads
        self.pitch_errors = pitch_errors
        self.final_state = final_state
        self.stresses = stresses

    def completed(self, samples: xr.Dataset) -> xr.Dataset:
        """A copy of ``samples`` with the fixed inputs they do not carry (what a run is given)."""
        samples = samples.copy()
        for name, value in self.fixed.items():
            if name not in samples.data_vars:
                samples[name] = ("sample", np.full(samples.sizes["sample"], float(value)))
        return samples

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        samples = self.completed(samples)
        return simulate_batch(
            self.design,
            samples,
            n_periods=self.n_periods,
            keep_periods=self.keep_periods,
            history_per_period=self.history_per_period,
            rig_channels=self.rig_channels,
            lyapunov=self.lyapunov,
            effects=self.effects,
            damping_in_separation=self.damping_in_separation,
            stiffness=self.stiffness,
            steps_per_mode=self.steps_per_mode,
            threads=self.threads,
            pitch_errors=self.pitch_errors,
            final_state=self.final_state,
            stresses=self.stresses,
        )

    def key(self) -> str:
        """A text identifying the settings (for checkpoint hashing)."""
        settings: tuple[Any, ...] = (
            self.design.to_json(),
            sorted(self.fixed.items()),
            self.n_periods,
            self.keep_periods,
            self.history_per_period,
            self.rig_channels,
            self.lyapunov,
            [repr(e) for e in self.effects],
            self.damping_in_separation,
            self.stiffness,
            self.steps_per_mode,
        )
        if self.pitch_errors is not None:
            # only then: the keys of existing checkpoints stay as they were
            settings += (self.pitch_errors.to_dict(),)
        if self.final_state:
            settings += ("final_state",)
        if self.stresses:
            settings += ("pair_load_extremes",)
        return repr(settings)


__all__ = [
    "simulate",
    "simulate_batch",
    "build_batch",
    "samples_from_mapping",
    "steps_per_period",
    "BatchEvaluator",
    "QOI_INFO",
    "METHODS",
]

#: Public name of the fast integrator (the diagnosis simulates campaigns with it and the history columns).
integrate_fast = _integrate_fast
