"""Run-ups and coast-downs on the virtual rig: the speed-varying model turned into ramp records.

:func:`simulate_runup_campaign` drives the true design through each ramp's
speed profile with :func:`uqgear.physics.runup.simulate_runup` (the forcing
follows the pinion angle) and records what a rig would, with the acquisition
chain of :mod:`uqgear.rig.virtual_rig`: the model output at ``oversampling``
times ``fs``, the zero-delay anti-alias low-pass (the accelerations as the
second derivative of the filtered displacements), every ``oversampling``-th
sample kept (the filtered signal is band-limited below fs/2), Gaussian sensor
noise of ``sqrt(noise_std**2 + (relative_noise * rms)**2)`` with rms that of
the whole clean ramp record (a sensor's noise does not follow the speed),
mains lines on the accelerometers and encoder run-out lines that follow the
simulated shaft angle. The tachometer records the simulated pinion speed.

Speed wander multiplies the ramp: n(t) = n_ramp(t) (1 + sum a sin(2 pi f t +
phi)), phases random per ramp; unlike the steady virtual rig, the model runs
through the wandering speed itself. Each ramp is held at its start and stop
speed for a guard interval on either side of the record, which keeps the
filter's edge effects outside it; the model's own run-in is
:data:`uqgear.physics.runup.RUN_IN_PERIODS` mesh periods at the start speed.

Seeds: one SeedSequence per campaign; child 0 draws the true adhesion torques
where not given, child ``1 + r`` is ramp r's, and within it child ``1 + c`` the
noise of channel c and children 1000, 1001 and 1003 the wander, mains and
encoder phases (as in :func:`~uqgear.rig.virtual_rig.simulate_campaign`).

Limits: :func:`~uqgear.physics.runup.simulate_runup` takes no pitch errors, so
``pitch_errors`` is refused; effects are those of
:data:`uqgear.physics.effects.EFFECTS`, whose forcing follows the angle (or,
for the adhesion oscillation, its own clock).
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from ..common.errors import OperatingPointError, RigDataError
from ..physics.design import Design
from ..physics.effects import EFFECTS, Effect
from ..physics.runup import simulate_runup
from ..physics.speed_profile import SpeedProfile, SpeedProfileError
from ..uq.seeds import child_seed
from .campaign_checks import (
    campaign_seed,
    check_encoder_run_out,
    check_line_interference,
    check_positive,
    check_speed_wander,
)
from .format import make_ramp_dataset, write_rig
from .sampling import SIGNAL_CHANNELS
from .virtual_rig import (
    DEFAULT_RELATIVE_NOISE,
    ENCODER_STREAM,
    GUARD_TAPER,
    INTERFERENCE_STREAM,
    RECORD_GUARD,
    WANDER_STREAM,
    add_interference,
    adhesion_torque_bounds,
    band_limited_record,
    encoder_lines_at,
    true_model,
)

#: Keys of a ramp table: required, and optional (``rate`` or ``duration`` gives the length).
RAMP_KEYS: tuple[str, ...] = ("start_speed", "stop_speed", "drive_torque")
OPTIONAL_RAMP_KEYS: tuple[str, ...] = ("rate", "duration", "adhesion_torque_lower", "adhesion_torque_upper")


def ramp_table(design: Design, ramps: Mapping[str, ArrayLike], adhesion: ArrayLike | None, rng) -> dict:
    """Per-ramp arrays: speeds, duration (s), torques and the true adhesion torque.

    ``ramps`` holds :data:`RAMP_KEYS` and optionally :data:`OPTIONAL_RAMP_KEYS` per ramp; where
    ``adhesion`` is not given the true adhesion torque of each ramp is drawn from ``rng`` inside its
    a-priori bounds. The virtual and the foreign rig's run-ups read their ramps through it.

    Raises
    ------
    OperatingPointError
        A key missing or unknown, or a value outside its range, naming the key.
    """
    if not isinstance(ramps, Mapping):
        raise OperatingPointError(f"ramps: expected a mapping of per-ramp arrays; got {type(ramps).__name__}")
    unknown = sorted(set(ramps) - set(RAMP_KEYS) - set(OPTIONAL_RAMP_KEYS))
    if unknown:
        raise OperatingPointError(
            f"ramps.{unknown[0]}: unknown key; expected {', '.join(RAMP_KEYS + OPTIONAL_RAMP_KEYS)}"
        )
    for name in RAMP_KEYS:
        if name not in ramps:
            raise OperatingPointError(f"ramps.{name}: missing; expected one value per ramp")
    table = {name: np.atleast_1d(np.asarray(values, dtype=float)) for name, values in ramps.items()}
    n_ramps = table["start_speed"].size
    for name, values in table.items():
        if values.shape != (n_ramps,) or not np.all(np.isfinite(values)):
            raise OperatingPointError(f"ramps.{name}: expected {n_ramps} finite values (one per ramp); got {values}")
    if ("rate" in table) == ("duration" in table):
        raise OperatingPointError("ramps: expected one of rate (rpm/s) and duration (s) for the ramps' length")
    span = np.abs(table["stop_speed"] - table["start_speed"])
    length = table.pop("rate") if "rate" in table else table["duration"]
    if np.any(length <= 0) or np.any(span <= 0) or np.any(table["drive_torque"] < 0):
        raise OperatingPointError(
            "ramps: expected stop_speed != start_speed, a rate or duration > 0 and drive_torque >= 0; got "
            f"{ {name: np.asarray(values).tolist() for name, values in ramps.items()} }"
        )
    table["duration"] = table["duration"] if "duration" in table else span / length
    lower, upper = adhesion_torque_bounds(design, table["drive_torque"])
    table.setdefault("adhesion_torque_lower", lower)
    table.setdefault("adhesion_torque_upper", upper)
    if adhesion is None:
        table["adhesion_torque"] = rng.uniform(table["adhesion_torque_lower"], table["adhesion_torque_upper"])
    else:
        table["adhesion_torque"] = np.atleast_1d(np.asarray(adhesion, dtype=float))
        if table["adhesion_torque"].shape != (n_ramps,):
            raise OperatingPointError(
                f"true_parameters.adhesion_torque: expected {n_ramps} values (one per ramp); "
                f"got shape {table['adhesion_torque'].shape}"
            )
    return table


def _profile(start: float, stop: float, duration: float, guard: float, wander, phases) -> SpeedProfile:
    """The ramp continued for ``guard`` s on either side (a profile is strictly monotone), times the wander."""
    rate = (stop - start) / duration

    def speed(t: np.ndarray) -> np.ndarray:
        factor = np.ones_like(t)
        for (amplitude, frequency), phase in zip(wander, phases):
            factor = factor + amplitude * np.sin(2.0 * math.pi * frequency * (t - guard) + phase)
        return (start + rate * (t - guard)) * factor

    try:
        return SpeedProfile.from_function(speed, duration + 2.0 * guard)
    except SpeedProfileError as exc:
        raise OperatingPointError(
            f"speed_wander: the wandering ramp {start:g} -> {stop:g} rpm is not monotone ({exc}); expected "
            "a wander whose rate of change a 2 pi f n stays below the ramp rate"
        ) from None


def _check_settings(effects, pitch_errors, channels, noise_std, relative_noise, oversampling) -> None:
    if pitch_errors is not None:
        raise OperatingPointError(
            "pitch_errors: the speed-varying model (uqgear.simulate_runup) takes no pitch errors; "
            "expected None for a run-up campaign"
        )
    for effect in effects:
        if not isinstance(effect, Effect) or effect.name not in EFFECTS:
            raise OperatingPointError(
                f"effects: {getattr(effect, 'name', effect)!r} is not an effect the speed-varying model "
                f"follows; expected one of {', '.join(EFFECTS)}"
            )
    if not channels or any(name not in SIGNAL_CHANNELS for name in channels):
        raise OperatingPointError(f"channels: expected some of {', '.join(SIGNAL_CHANNELS)}; got {channels!r}")
    for name, value in noise_std.items():
        if name not in channels or isinstance(value, bool) or not isinstance(value, (int, float)) or value < 0:
            raise OperatingPointError(f"noise_std.{name}: expected a standard deviation >= 0 of a channel recorded")
    if not math.isfinite(relative_noise) or relative_noise < 0:
        raise OperatingPointError(
            f"relative_noise: expected a fraction >= 0 of the record's RMS; got {relative_noise!r}"
        )
    if isinstance(oversampling, bool) or not isinstance(oversampling, (int, np.integer)) or oversampling < 2:
        raise OperatingPointError(f"oversampling: expected an integer >= 2; got {oversampling!r}")


def _record_ramp(
    sim: xr.Dataset,
    design: Design,
    first: int,
    n_samples: int,
    fs: float,
    oversampling: int,
    settings: dict[str, Any],
    ramp_seed: np.random.SeedSequence,
) -> dict[str, np.ndarray]:
    """One ramp's channels and tachometer through the acquisition chain."""
    time = sim["time"].values
    rate = fs * oversampling
    keep = slice(first, first + n_samples * oversampling, oversampling)
    taper = np.ones(time.size)
    left, right = time < time[0] + GUARD_TAPER, time > time[-1] - GUARD_TAPER
    taper[left] = 0.5 * (1.0 - np.cos(np.pi * (time[left] - time[0]) / GUARD_TAPER))
    taper[right] = 0.5 * (1.0 - np.cos(np.pi * (time[-1] - time[right]) / GUARD_TAPER))
    record_time = np.arange(n_samples) / fs
    interference_rng = np.random.default_rng(child_seed(ramp_seed, INTERFERENCE_STREAM))
    out = {"tachometer": sim["pinion_speed"].values[keep]}
    for index, name in enumerate(settings["channels"]):
        raw, order = (sim["te"].values, 0) if name == "te" else (sim["y1" if name == "acc_pinion" else "y2"].values, 2)
        clean = band_limited_record(time, raw, rate, keep, taper, fs / 2.56, fs / 2.0, order)
        rms = float(np.sqrt(np.mean((clean - clean.mean()) ** 2)))
        sigma = math.hypot(settings["noise_std"].get(name, 0.0), settings["relative_noise"] * rms)
        noisy = clean + sigma * np.random.default_rng(child_seed(ramp_seed, 1 + index)).standard_normal(n_samples)
        if order == 2:
            noisy = add_interference(noisy, settings["interference"], record_time, interference_rng)
        if name == "te" and settings["encoder"]:
            angle = sim["pinion_angle"].values[keep]
            rng = np.random.default_rng(child_seed(ramp_seed, ENCODER_STREAM))
            noisy = noisy + encoder_lines_at(settings["encoder"], design, angle, rng)
        out[name] = noisy - noisy.mean() if name == "te" else noisy
    return out


def _simulate_ramp(design: Design, plant: tuple[Design, float, Sequence[Effect], int], table: Mapping[str, np.ndarray],
                   ramp: int, duration: float, n_samples: int, fs: float, oversampling: int,
                   wander: list[tuple[float, float]], settings: dict[str, Any],
                   ramp_seed: np.random.SeedSequence) -> dict[str, np.ndarray]:
    """One ramp through the true plant (design, stiffness scale, effects, steps per mode), recorded by the rig."""
    true_design, stiffness_scale, effects, steps_per_mode = plant
    guard = math.ceil(RECORD_GUARD * fs) / fs
    phases = np.random.default_rng(child_seed(ramp_seed, WANDER_STREAM)).uniform(0.0, 2.0 * math.pi, len(wander))
    # every ramp keeps the samples of the shortest (the format's ramps share ramp_time)
    profile = _profile(
        float(table["start_speed"][ramp]),
        float(table["stop_speed"][ramp]),
        duration,
        guard,
        wander,
        phases,
    )
    sim = simulate_runup(
        true_design,
        profile,
        float(table["drive_torque"][ramp]),
        float(table["adhesion_torque"][ramp]),
        sample_rate=fs * oversampling,
        mesh_stiffness_scale=stiffness_scale,
        effects=effects,
        steps_per_mode=steps_per_mode,
    )
    first = int(round(guard * fs)) * oversampling
    return _record_ramp(sim, design, first, n_samples, fs, oversampling, settings, ramp_seed)


def _noise_record(settings: Mapping[str, Any], wander: list[tuple[float, float]]) -> dict[str, object]:
    """The campaign's noise, wander, interference and encoder run-out as recorded in its ``noise`` attribute."""
    noise_record: dict[str, object] = {
        "relative_noise": settings["relative_noise"],
        "noise_std": settings["noise_std"],
        "speed_wander": [list(component) for component in wander],
        "line_interference": {f"{frequency:g}": amplitude for frequency, amplitude in settings["interference"].items()},
    }
    if settings["encoder"]:
        noise_record["encoder_run_out"] = dict(settings["encoder"])
    return noise_record


def simulate_runup_campaign(
    design: Design,
    ramps: Mapping[str, ArrayLike],
    *,
    true_parameters: Mapping[str, object] | None = None,
    effects: Sequence[Effect] = (),
    noise_std: Mapping[str, float] | None = None,
    relative_noise: float = DEFAULT_RELATIVE_NOISE,
    speed_wander: Sequence[tuple[float, float]] = (),
    line_interference: Mapping[float, float] | None = None,
    encoder_run_out: Mapping[str, float] | None = None,
    pitch_errors: None = None,
    channels: Sequence[str] = tuple(SIGNAL_CHANNELS),
    fs: float = 20480.0,
    seed: np.random.SeedSequence | int | None = None,
    title: str | None = None,
    oversampling: int = 4,
    steps_per_mode: int = 32,
) -> xr.Dataset:
    """Simulate run-up or coast-down records of the virtual rig, in the ``uqgear-rig/1`` format.

    Parameters
    ----------
    design : Design
        The *nominal* design, stored in the ``design`` attribute.
    ramps : mapping
        Per ramp: ``start_speed`` and ``stop_speed`` (rpm; a coast-down falls),
        ``rate`` (rpm/s, > 0) or ``duration`` (s), ``drive_torque`` (N m), and
        optionally ``adhesion_torque_lower``/``_upper`` (default
        :func:`~uqgear.rig.virtual_rig.adhesion_torque_bounds`).
    true_parameters, effects, noise_std, relative_noise, speed_wander, line_interference, encoder_run_out
        As in :func:`~uqgear.rig.virtual_rig.simulate_campaign`, per ramp
        instead of per run (``adhesion_torque``: one value per ramp; the
        wander multiplies the ramp's speed and the model runs through it).
    pitch_errors : None
        Refused: the speed-varying model takes no pitch errors.
    channels : sequence of str
        Channels to record.
    fs : float
        Sampling rate in Hz.
    seed : SeedSequence or int, optional
        Source of all randomness (module docstring).
    title : str, optional
        Free text for the ``title`` attribute.
    oversampling, steps_per_mode : int
        Model output rate over fs, and RK4 steps per period of the highest
        natural frequency.

    Returns
    -------
    xarray.Dataset
        Ramp records (``ramp`` x ``ramp_time``) with the tachometer
        ``ramp_pinion_speed_signal``; attributes ``true_parameters`` (with
        ``ramp_adhesion_torque``, one per ramp), ``effects``, ``noise``,
        ``seed_entropy`` as :func:`~uqgear.rig.virtual_rig.simulate_campaign`.

    Raises
    ------
    OperatingPointError
        A wrong ramp, true parameter, effect, noise level or setting.

    Examples
    --------
    A 1 s run-up 1500 -> 1700 rpm, then cut into speed bins (none within 0.15 s of either end):

    >>> import uqgear
    >>> from uqgear.rig.virtual_runup import simulate_runup_campaign
    >>> design = uqgear.load_design("locomotive")
    >>> ramps = {"start_speed": [1500.0], "stop_speed": [1700.0], "rate": [200.0], "drive_torque": [7000.0]}
    >>> campaign = simulate_runup_campaign(design, ramps, seed=3, channels=["te"])
    >>> dict(campaign.sizes), sorted(campaign.data_vars)
    ({'ramp': 1, 'ramp_time': 20480}, ['ramp_pinion_speed_signal', 'ramp_te'])
    >>> ops = uqgear.ramp_operating_points(campaign, segments=3)
    >>> [round(float(speed)) for speed in ops["pinion_speed"]]
    [1553, 1600, 1647]
    """
    seed_sequence = campaign_seed(seed)
    fs = check_positive("fs", fs)
    channels = list(channels)
    noise_std = dict(noise_std or {})
    relative_noise = float(relative_noise)
    _check_settings(effects, pitch_errors, channels, noise_std, relative_noise, oversampling)
    settings: dict[str, Any] = {
        "channels": channels,
        "noise_std": noise_std,
        "relative_noise": relative_noise,
        "interference": check_line_interference(line_interference, fs),
        "encoder": check_encoder_run_out(encoder_run_out),
    }
    wander = check_speed_wander(speed_wander)
    true_design, stiffness_scale, true_record = true_model(design, true_parameters)
    adhesion = (true_parameters or {}).get("adhesion_torque")
    table = ramp_table(design, ramps, adhesion, np.random.default_rng(child_seed(seed_sequence, 0)))  # type: ignore[arg-type]
    durations = np.round(table["duration"] * fs).astype(int)
    n_samples = int(durations.min())
    fastest = float(np.maximum(table["start_speed"], table["stop_speed"]).max()) * (1.0 + sum(a for a, _ in wander))
    if not fs > 6.0 * design.z1 * fastest / 60.0:
        raise OperatingPointError(
            f"fs: {fs:g} Hz does not resolve the third mesh harmonic at {fastest:g} rpm; "
            f"expected more than {6.0 * design.z1 * fastest / 60.0:g} Hz"
        )
    records: dict[str, list[np.ndarray]] = {name: [] for name in ("tachometer", *channels)}
    plant = (true_design, stiffness_scale, effects, steps_per_mode)
    for ramp in range(table["start_speed"].size):
        recorded = _simulate_ramp(design, plant, table, ramp, float(durations[ramp]) / fs, n_samples, fs, oversampling,
                                  wander, settings, child_seed(seed_sequence, 1 + ramp))
        for name, values in recorded.items():
            records[name].append(values)
    truth = {
        "mesh_stiffness_scale": stiffness_scale,
        **true_record,
        "ramp_adhesion_torque": [float(value) for value in table["adhesion_torque"]],
    }
    noise_record = _noise_record(settings, wander)
    stamp = datetime.now(UTC).isoformat(timespec="seconds")
    ds = make_ramp_dataset(
        time=np.arange(n_samples) / fs,
        pinion_speed_signal=np.stack(records["tachometer"]),
        drive_torque=table["drive_torque"],
        adhesion_torque_lower=table["adhesion_torque_lower"],
        adhesion_torque_upper=table["adhesion_torque_upper"],
        channels={name: np.stack(records[name]) for name in channels},
        design=design,
        title=title or "uqgear virtual rig run-up campaign",
        source="uqgear virtual rig: 3-DOF gear model through a speed profile (uqgear.simulate_runup), zero-delay "
        f"anti-alias low-pass flat to {fs / 2.56:g} Hz and zero from {fs / 2:g} Hz, Gaussian sensor noise",
        history=f"{stamp}: simulated by uqgear.rig.virtual_runup.simulate_runup_campaign; ramp records at {fs:g} Hz",
        noise_std=noise_std if relative_noise == 0 and noise_std else None,
    )
    ds.attrs.update(
        true_parameters=json.dumps(truth),
        effects=json.dumps([{"name": effect.name, "values": dict(effect.values)} for effect in effects]),
        noise=json.dumps(noise_record),
        seed_entropy=str(seed_sequence.entropy),
        seed_spawn_key=json.dumps([int(k) for k in seed_sequence.spawn_key]),
    )
    return ds


def parse_ramps(texts: Sequence[str], *, option: str = "ramps") -> dict[str, list[float]]:
    """Ramps written ``START:STOP:RATE[:TORQUE]`` (rpm, rpm, rpm/s, N m; torque 7000 by default) as a ramp table.

    Examples
    --------
    >>> parse_ramps(["1000:5000:200", "5000:1000:150:6000"])["drive_torque"]
    [7000.0, 6000.0]
    """
    table: dict[str, list[float]] = {"start_speed": [], "stop_speed": [], "rate": [], "drive_torque": []}
    for text in texts:
        try:
            values = [float(part) for part in text.split(":")]
        except ValueError:
            values = []
        if len(values) not in (3, 4):
            raise OperatingPointError(f"{option} {text}: expected START:STOP:RATE[:TORQUE] in rpm, rpm, rpm/s and N m")
        for name, value in zip(table, [*values, 7000.0][:4]):
            table[name].append(value)
    return table


def synth_runup_rig(
    design: Design, out_path: str | os.PathLike[str], ramps: Mapping[str, ArrayLike], **options: Any
) -> Path:
    """Simulate a run-up campaign (:func:`simulate_runup_campaign` with ``options``) and write it as a rig file.

    This is what ``uqgear synth-rig --ramp START:STOP:RATE[:TORQUE] ...`` runs.
    """
    path = Path(out_path)
    if not path.parent.is_dir():
        raise RigDataError(f"{path}: folder {path.parent} does not exist")
    return write_rig(path, simulate_runup_campaign(design, ramps, **options))


def join_campaigns(steady: xr.Dataset, ramps: xr.Dataset) -> xr.Dataset:
    """One campaign of a steady virtual-rig campaign and a run-up one of the same rig, with both truths.

    The attributes are the steady campaign's, and ``true_parameters`` gains
    the ramps' ``ramp_adhesion_torque``; the other true values must agree.

    Raises
    ------
    RigDataError
        Campaigns of different designs or true parameters, or not one of each kind.
    """
    if "op" not in steady.dims or "ramp" not in ramps.dims or "op" in ramps.dims or "ramp" in steady.dims:
        raise RigDataError("join_campaigns: expected a campaign of steady runs and one of ramp records")
    if steady.attrs.get("design") != ramps.attrs.get("design"):
        raise RigDataError("design: the steady and ramp campaigns hold different nominal designs")
    attrs = dict(steady.attrs)
    if "true_parameters" in steady.attrs and "true_parameters" in ramps.attrs:
        steady_truth, ramp_truth = (
            json.loads(steady.attrs["true_parameters"]),
            json.loads(ramps.attrs["true_parameters"]),
        )
        ramp_adhesion = ramp_truth.pop("ramp_adhesion_torque")
        common = {key: value for key, value in steady_truth.items() if key != "adhesion_torque"}
        if common != ramp_truth:
            raise RigDataError(f"true_parameters: the campaigns' truths differ: {common} and {ramp_truth}")
        attrs["true_parameters"] = json.dumps({**steady_truth, "ramp_adhesion_torque": ramp_adhesion})
    joined = xr.merge([steady, ramps], combine_attrs="override")
    joined.attrs = attrs
    return joined


__all__ = [
    "RAMP_KEYS",
    "OPTIONAL_RAMP_KEYS",
    "simulate_runup_campaign",
    "parse_ramps",
    "synth_runup_rig",
    "join_campaigns",
    "ramp_table",
]
