"""Run-ups and coast-downs on the foreign virtual rig (:mod:`.foreign_rig`): its plant driven through a ramp.

:func:`simulate_foreign_runup_campaign` records ramp records (docs/rig-data-format.md, "Run-up and
coast-down records") of the foreign rig's 8-DOF gearbox. The ramp is the speed controller's
set-point: the motor angle reference is the integral of the ramp speed, held at the start speed
for the run-in and at the stop speed after the ramp; the controller (proportional-derivative on
the motor angle, no feed-forward) then carries the inertias through the ramp with a constant angle
lag, the ramp's acceleration over the squared controller bandwidth (2.4e-3 rad at 200 rpm/s), and
no speed error once the start of the ramp has settled (tens of milliseconds).

Nothing assumes a fixed speed: the mesh phase, the profile error of each pair in contact and an
eccentric shaft's run-out follow the pinion's simulated angle, the drive torque ripple the motor's
angle; the load torque oscillation keeps its own clock. At constant speed this is the steady
foreign rig up to the shaft twist's constant phase offset, so a slow ramp reproduces its steady
runs (tests/test_foreign_runup.py).

The acquisition is the steady foreign rig's: the model at four times ``fs``, the zero-delay
anti-alias low-pass (after removing the record's straight line, which a ramp's circular filter
would otherwise see as a jump, and adding it back), every fourth sample kept, white noise of
``relative_noise`` times each clean ramp record's RMS. The tachometer channel is the pinion's
simulated speed, as a tachometer on the pinion shaft gives it (no noise). Speed wander multiplies
the ramp's set-point, n(t) = n_ramp(t) (1 + sum a sin(2 pi f t + phi)).

Seeds: one SeedSequence per campaign; child ``1 + r`` is ramp r's: its generator draws the run-in's
random fraction of a pinion revolution and then each channel's noise, as
:func:`~.foreign_rig.simulate_foreign_campaign` does per run, and its child 1000 the wander phases.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime

import numpy as np
import xarray as xr
from numba import njit
from numpy.typing import ArrayLike

from ..common.errors import OperatingPointError, RigDataError
from ..physics.design import Design
from ..physics.effects import Effect
from ..uq.seeds import as_seed_sequence, child_seed
from .campaign_checks import check_speed_wander
from .foreign_rig import (
    FOREIGN_RECORD_GUARD,
    N_STATE,
    ForeignGears,
    effect_vector,
    pair_sum,
    plant_derivative,
    run_parameters,
    static_state,
    time_step,
)
from .format import make_ramp_dataset
from .virtual_rig import WANDER_STREAM, frequency_filter
from .virtual_runup import ramp_table

_RPM = 2.0 * math.pi / 60.0


@njit(cache=True)
def _piece_angle(a, b, t, wander):  # pragma: no cover - compiled
    """Integral from 0 to t of (a + b s)(1 + sum_i w0 sin(w1 s + w2)) ds (rad) for wander rows (w0, w1, w2)."""
    total = a * t + 0.5 * b * t * t
    for i in range(wander.shape[0]):
        amp, w, phase = wander[i, 0], wander[i, 1], wander[i, 2]
        at_t = -(a + b * t) * math.cos(w * t + phase) / w + b * math.sin(w * t + phase) / (w * w)
        at_0 = -a * math.cos(phase) / w + b * math.sin(phase) / (w * w)
        total += amp * (at_t - at_0)
    return total


@njit(cache=True)
def _reference(t, ramp, wander):  # pragma: no cover - compiled
    """The set-point's angle (rad) and speed (rad/s) at time t: held, ramped from ramp[0] to ramp[1] s, held.

    ``ramp`` = (ramp start s, ramp end s, start speed rad/s, rate rad/s2, stop speed rad/s).
    """
    t0, t1, w_start, rate, w_stop = ramp[0], ramp[1], ramp[2], ramp[3], ramp[4]
    pieces = ((w_start, 0.0, 0.0, t0), (w_start - rate * t0, rate, t0, t1), (w_stop, 0.0, t1, 1e300))
    angle = 0.0
    speed = 0.0
    for a, b, lo, hi in pieces:
        if t <= lo:
            break
        angle += _piece_angle(a, b, min(t, hi), wander) - _piece_angle(a, b, lo, wander)
        if t <= hi:
            speed = a + b * t
    factor = 1.0
    for i in range(wander.shape[0]):
        factor += wander[i, 0] * math.sin(wander[i, 1] * t + wander[i, 2])
    if t <= 0.0:
        speed = w_start
    return angle, speed * factor


@njit(cache=True)
def _reference_speeds(times, ramp, wander):  # pragma: no cover - compiled
    out = np.empty(times.size)
    for k in range(times.size):
        out[k] = _reference(times[k], ramp, wander)[1]
    return out


@njit(cache=True)
def _ramp_derivative(t, y, p, pin_err, gear_err, eff, ramp, wander, out):  # pragma: no cover - compiled
    """The foreign plant's derivative with the speed set-point on the ramp; p[0] = z1 / (2 pi) (see caller)."""
    # the mesh at the pinion's real angle: pair_sum's clock times p[0] is the mesh phase
    force, m1, m2 = pair_sum(y[1], y, p, pin_err, gear_err, eff)
    kc, cc, t1, t2 = p[32], p[33], p[34], p[35]
    theta_ref, omega_ref = _reference(t, ramp, wander)
    # the torque ripple follows the motor's angle, the adhesion oscillation its own clock
    motor = t1 * (1.0 + eff[8] * math.cos(eff[9] * y[0] + eff[10]))
    motor += kc * (theta_ref - y[0]) + cc * (omega_ref - y[8])
    load = t2 * (1.0 + eff[11] * math.sin(2.0 * math.pi * eff[12] * t + eff[13]))
    plant_derivative(y, p, eff, force, m1, m2, motor, load, out)


@njit(cache=True)
def _integrate_ramp(y0, p, pin_err, gear_err, eff, ramp, wander, step, n_out, per_out):  # pragma: no cover
    """RK4 from t = 0; returns (n_out, 4): encoder TE, housing accelerations at pinion and gear, pinion speed."""
    y = y0.copy()
    work = np.empty((5, N_STATE))
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    out = np.empty((n_out, 4))
    t = 0.0
    for index in range(n_out):
        for _ in range(per_out):
            _ramp_derivative(t, y, p, pin_err, gear_err, eff, ramp, wander, k1)
            for k in range(N_STATE):
                tmp[k] = y[k] + 0.5 * step * k1[k]
            _ramp_derivative(t + 0.5 * step, tmp, p, pin_err, gear_err, eff, ramp, wander, k2)
            for k in range(N_STATE):
                tmp[k] = y[k] + 0.5 * step * k2[k]
            _ramp_derivative(t + 0.5 * step, tmp, p, pin_err, gear_err, eff, ramp, wander, k3)
            for k in range(N_STATE):
                tmp[k] = y[k] + step * k3[k]
            _ramp_derivative(t + step, tmp, p, pin_err, gear_err, eff, ramp, wander, k4)
            for k in range(N_STATE):
                y[k] += step / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k])
            t += step
        _ramp_derivative(t, y, p, pin_err, gear_err, eff, ramp, wander, k1)
        out[index, 0] = p[6] * y[1] - p[7] * y[2]
        out[index, 1] = k1[14]
        out[index, 2] = k1[15]
        out[index, 3] = y[9]
    return out


def _wander_rows(wander: Sequence[tuple[float, float]], phases: np.ndarray) -> np.ndarray:
    rows = [(amplitude, 2.0 * math.pi * frequency, phase) for (amplitude, frequency), phase in zip(wander, phases)]
    return np.array(rows, dtype=float).reshape(-1, 3)


def simulate_foreign_ramp(
    design: Design,
    start_speed: float,
    stop_speed: float,
    duration: float,
    drive_torque: float,
    load_torque: float,
    *,
    gears: ForeignGears,
    effects: Sequence[Effect] = (),
    fs: float = 20480.0,
    start: float = 0.3,
    samples: int | None = None,
    wander: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """Clean records of one ramp of the foreign rig on the ``fs`` grid, from the ramp's start at ``start`` s.

    The set-point is held at ``start_speed`` (rpm) until ``start``, ramps to ``stop_speed`` over
    ``duration`` s and is held after; ``samples`` (default: the ramp's) are recorded from ``start``.
    ``wander`` rows are (relative amplitude, angular frequency rad/s, phase) of the set-point's
    wander. Returns ``te`` (m), ``acc_pinion`` and ``acc_gear`` (m s-2) and ``speed``, the pinion's
    simulated speed (rpm).

    Examples
    --------
    >>> from uqgear.physics.design import load_design
    >>> from uqgear.rig.foreign_rig import draw_gears
    >>> design = load_design("locomotive")
    >>> clean = simulate_foreign_ramp(design, 1500.0, 1600.0, 0.25, 7000.0, 33667.0,
    ...                               gears=draw_gears(design, 6, 1), start=0.2)
    >>> speed = clean["speed"]
    >>> speed.size, round(float(speed[0]), -1), round(float(speed[-1]), -1)
    (5120, 1500.0, 1600.0)
    """
    for key, value, least in (
        ("start_speed", start_speed, 0.0),
        ("stop_speed", stop_speed, 0.0),
        ("duration", duration, 0.0),
        ("start", start, FOREIGN_RECORD_GUARD),
        ("fs", fs, 0.0),
    ):
        if not (math.isfinite(value) and value > least):
            raise RigDataError(f"{key}: expected a finite value > {least:g}; got {value!r}")
    p, fastest = run_parameters(design, float(start_speed), float(drive_torque), float(load_torque))
    # pair_sum's clock times p[0] is the mesh phase: with p[0] = z1 / (2 pi) and the pinion's angle as the clock
    # (_ramp_derivative), the mesh, its profile errors and a run-out follow the angle, not a fixed speed
    p[0] = design.z1 / (2.0 * math.pi)
    rows = np.zeros((0, 3)) if wander is None else np.asarray(wander, dtype=float).reshape(-1, 3)
    ramp = np.array(
        [start, start + duration, start_speed * _RPM, (stop_speed - start_speed) * _RPM / duration, stop_speed * _RPM]
    )
    p[36] = _reference(0.0, ramp, rows)[1]
    rate = 4.0 * fs
    per_out, step = time_step(fastest, rate)
    n_samples = int(round(duration * fs)) if samples is None else int(samples)
    first = int(round((start - FOREIGN_RECORD_GUARD) * rate))
    guard = int(round(FOREIGN_RECORD_GUARD * rate))
    size = 4 * n_samples + 2 * guard
    out = _integrate_ramp(
        static_state(p, design),
        p,
        gears.pinion,
        gears.gear,
        effect_vector(effects, design),
        ramp,
        rows,
        step,
        first + size,
        per_out,
    )[first:]
    passband, stopband = fs / 2.56, fs / 2.0
    records = {}
    kept = slice(guard, guard + 4 * n_samples, 4)
    index = np.arange(size, dtype=float)
    for column, name in ((0, "te"), (1, "acc_pinion"), (2, "acc_gear")):
        # the ramp's straight line taken out before the circular filter and put back (a low-pass keeps a line)
        line = np.polyval(np.polyfit(index, out[:, column], 1), index)
        response = np.fft.rfft(out[:, column] - line) * frequency_filter(size, rate, passband, stopband, 0)
        records[name] = (np.fft.irfft(response, n=size) + line)[kept]
    records["speed"] = out[kept, 3] / _RPM
    return records


def _check_ramp_speeds(
    design: Design, table: dict[str, np.ndarray], wander: Sequence[tuple[float, float]], fs: float
) -> None:
    low, high = design.operation.pinion_speed_sweep
    for key in ("start_speed", "stop_speed"):
        outside = (table[key] < low) | (table[key] > high)
        if np.any(outside):
            raise OperatingPointError(
                f"ramps.{key}: expected speeds in the design's pinion_speed_sweep [{low:g}, {high:g}] rpm; "
                f"got {table[key][outside].tolist()}"
            )
    swing = sum(amplitude for amplitude, _ in wander)
    slowest = float(np.minimum(table["start_speed"], table["stop_speed"]).min()) * (1.0 - swing)
    fastest = float(np.maximum(table["start_speed"], table["stop_speed"]).max()) * (1.0 + swing)
    if slowest < low or fastest > high:
        raise OperatingPointError(
            f"speed_wander: the wandering ramps reach {slowest:g} to {fastest:g} rpm; expected speeds in the "
            f"design's pinion_speed_sweep [{low:g}, {high:g}] rpm"
        )
    if not fs > 6.0 * design.z1 * fastest / 60.0:
        raise OperatingPointError(
            f"fs: {fs:g} Hz does not resolve the third mesh harmonic at {fastest:g} rpm; "
            f"expected more than {6.0 * design.z1 * fastest / 60.0:g} Hz"
        )


def _check_monotone(
    start: float, duration: float, start_speed: float, stop_speed: float, rows: np.ndarray, fs: float
) -> None:
    """Refuse a set-point that reverses within the ramp (a wander faster than the ramp)."""
    rate = (stop_speed - start_speed) * _RPM / duration
    ramp = np.array([start, start + duration, start_speed * _RPM, rate, stop_speed * _RPM])
    times = np.linspace(ramp[0], ramp[1], max(2, int((ramp[1] - ramp[0]) * fs / 4)))
    change = np.diff(_reference_speeds(times, ramp, rows)) * np.sign(stop_speed - start_speed)
    if np.any(change <= 0.0):
        raise OperatingPointError(
            f"speed_wander: the wandering ramp {start_speed:g} -> {stop_speed:g} rpm reverses; expected a wander "
            "whose rate of change a 2 pi f n stays below the ramp rate"
        )


def simulate_foreign_runup_campaign(
    design: Design,
    ramps: Mapping[str, ArrayLike],
    *,
    gears: ForeignGears,
    effects: Sequence[Effect] = (),
    seed: int | np.random.SeedSequence = 0,
    fs: float = 20480.0,
    run_in: float = 0.3,
    relative_noise: float = 0.02,
    speed_wander: Sequence[tuple[float, float]] = (),
    title: str = "",
) -> xr.Dataset:
    """Run-up or coast-down records of the foreign rig (``uqgear-rig/1`` ramp records, the nominal design stated).

    Parameters
    ----------
    design : Design
        The nominal design (stored in the ``design`` attribute) and the plant's.
    ramps : mapping
        The ramp table of :func:`~uqgear.rig.virtual_runup.simulate_runup_campaign`: per ramp
        ``start_speed`` and ``stop_speed`` (rpm, within ``design.operation.pinion_speed_sweep``),
        ``rate`` (rpm/s) or ``duration`` (s), ``drive_torque`` (N m), optionally
        ``adhesion_torque_lower``/``_upper``; the load torque T2 is the middle of the two.
    gears, effects, seed, fs, run_in, relative_noise
        As in :func:`~uqgear.rig.foreign_rig.simulate_foreign_campaign`, per ramp instead of per run
        (the ramp starts after ``run_in`` plus a random fraction of a pinion revolution at its start speed).
    speed_wander : sequence of (amplitude, frequency Hz)
        Wander of the speed set-point (module docstring); phases random per ramp.
    title : str
        Free text for the ``title`` attribute.

    Returns
    -------
    xarray.Dataset
        Ramp records (``ramp`` x ``ramp_time``: every ramp keeps the samples of the shortest) with the
        tachometer ``ramp_pinion_speed_signal``; attributes ``effects``, ``foreign_gears``, ``noise`` and
        ``seed_entropy``.

    Raises
    ------
    OperatingPointError
        A wrong ramp table (naming its key), speeds outside the design's sweep, a reversing
        wandering ramp, or a sampling rate that misses the third mesh harmonic.
    RigDataError
        An effect the foreign rig has no physics for, a bad seed, run-in or noise level.

    Examples
    --------
    >>> from uqgear.physics.design import load_design
    >>> from uqgear.rig.foreign_rig import draw_gears
    >>> design = load_design("locomotive")
    >>> ramps = {"start_speed": [1500.0], "stop_speed": [1600.0], "duration": [0.25], "drive_torque": [7000.0]}
    >>> rig = simulate_foreign_runup_campaign(design, ramps, gears=draw_gears(design, 6, 1), run_in=0.2)
    >>> dict(rig.sizes), sorted(rig.data_vars)
    ({'ramp': 1, 'ramp_time': 5120}, ['ramp_acc_gear', 'ramp_acc_pinion', 'ramp_pinion_speed_signal', 'ramp_te'])
    """
    sequence = as_seed_sequence(seed, error=RigDataError)
    for key, value in (("fs", fs), ("run_in", run_in), ("relative_noise", relative_noise)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise RigDataError(f"{key}: expected a finite number >= 0; got {value!r}")
    if fs <= 0 or run_in <= FOREIGN_RECORD_GUARD:
        raise RigDataError(f"fs, run_in: expected fs > 0 Hz and run_in > {FOREIGN_RECORD_GUARD:g} s; "
                           f"got {fs!r} and {run_in!r}")
    wander = check_speed_wander(speed_wander)
    table = ramp_table(design, ramps, None, np.random.default_rng(child_seed(sequence, 0)))
    _check_ramp_speeds(design, table, wander, fs)
    effect_vector(effects, design)  # an effect without foreign physics is refused before any ramp
    n_samples = int(np.round(table["duration"] * fs).min())
    records: dict[str, list[np.ndarray]] = {name: [] for name in ("te", "acc_pinion", "acc_gear", "speed")}
    for index in range(table["start_speed"].size):
        ramp_seed = child_seed(sequence, 1 + index)
        rng = np.random.default_rng(ramp_seed)
        begin, end = float(table["start_speed"][index]), float(table["stop_speed"][index])
        start = run_in + rng.uniform(0.0, 60.0 / begin)
        phases = np.random.default_rng(child_seed(ramp_seed, WANDER_STREAM)).uniform(0.0, 2.0 * math.pi, len(wander))
        rows = _wander_rows(wander, phases)
        duration = float(table["duration"][index])
        _check_monotone(start, duration, begin, end, rows, fs)
        clean = simulate_foreign_ramp(
            design,
            begin,
            end,
            duration,
            float(table["drive_torque"][index]),
            0.5 * float(table["adhesion_torque_lower"][index] + table["adhesion_torque_upper"][index]),
            gears=gears,
            effects=effects,
            fs=fs,
            start=start,
            samples=n_samples,
            wander=rows,
        )
        records["speed"].append(clean.pop("speed"))
        for name, record in clean.items():
            sigma = relative_noise * float(np.std(record))
            noisy = record + sigma * rng.standard_normal(n_samples)
            records[name].append(noisy - noisy.mean())
    return _ramp_campaign(design, table, records, fs, effects, gears, sequence, relative_noise, wander, title)


def _ramp_campaign(
    design: Design,
    table: dict[str, np.ndarray],
    records: dict[str, list[np.ndarray]],
    fs: float,
    effects: Sequence[Effect],
    gears: ForeignGears,
    sequence: np.random.SeedSequence,
    relative_noise: float,
    wander: Sequence[tuple[float, float]],
    title: str,
) -> xr.Dataset:
    stamp = datetime.now(UTC).isoformat(timespec="seconds")
    n_samples = records["te"][0].size
    ds = make_ramp_dataset(
        time=np.arange(n_samples) / fs,
        pinion_speed_signal=np.stack(records["speed"]),
        drive_torque=table["drive_torque"],
        adhesion_torque_lower=table["adhesion_torque_lower"],
        adhesion_torque_upper=table["adhesion_torque_upper"],
        channels={name: np.stack(records[name]) for name in ("te", "acc_pinion", "acc_gear")},
        design=design,
        title=title or "uqgear foreign virtual rig run-up campaign",
        source="uqgear foreign virtual rig: 8-DOF gearbox (motor on a speed controller following the ramp, shafts, "
        "housing modes), half-sine pair stiffness, per-tooth profile errors; not the diagnosis model",
        history=f"{stamp}: simulated by uqgear.rig.foreign_runup.simulate_foreign_runup_campaign; "
        f"ramp records at {fs:g} Hz",
    )
    ds.attrs.update(
        effects=json.dumps([{"name": e.name, "values": dict(e.values)} for e in effects]),
        foreign_gears=json.dumps(gears.record()),
        noise=json.dumps({"relative_noise": relative_noise, "speed_wander": [list(c) for c in wander]}),
        seed_entropy=str(sequence.entropy),
    )
    return ds


__all__ = ["simulate_foreign_ramp", "simulate_foreign_runup_campaign"]
