"""Our own virtual test rig: the gear model turned into rig data (``uqgear-rig/1``).

:func:`simulate_campaign` runs the 3-DOF model at every operating point of a
campaign with chosen *true* parameters (mesh stiffness scale, any design key,
the adhesion torque of each run, unmodelled effects) and records what a rig
would: steady records of the transmission error and the two bearing-housing
accelerations, sampled at ``fs`` after a run-in, behind an anti-alias low-pass,
with Gaussian sensor noise, stored as float32. The file's ``design`` attribute
is the *nominal* design; the truth is kept in the attributes
``true_parameters`` and ``effects`` (JSON) so that blind checks can score a
calibration or a diagnosis against it.

Acquisition chain, per run and channel:

1. The model is integrated from static equilibrium over ``run_in`` plus a
   random fraction of a pinion revolution (the record start is arbitrary, as
   on a rig), then over the record and a guard interval on each side, with
   an output rate of at least ``oversampling * fs``.
2. Anti-alias filter: a zero-delay linear-phase low-pass, flat (gain 1) up to
   ``passband`` (8 kHz at 20480 Hz), a raised-cosine transition, and exactly
   zero from ``stopband`` (fs/2 = 10.24 kHz) on, applied in the frequency
   domain. The accelerations are taken as the second time derivative of the
   filtered displacements, which is the filtered acceleration (a filter
   commutes with differentiation) without the aliasing that sampling the
   jumps of y'' (mesh stiffness steps) would cause.
3. The filtered signal is band-limited, so a cubic spline resamples it onto
   the ``fs`` grid exactly enough (relative error below 1e-4 in the band).
4. Sensor noise: white Gaussian noise of standard deviation
   ``sqrt(noise_std**2 + (relative_noise * rms)**2)``, rms that of the run's
   clean record (the public campaigns use 2 % of the run's RMS); each run and
   channel has its own stream, spawned from the seed.
5. ``te`` has its mean removed (encoders carry no absolute zero).

Pitch errors (``pitch_errors``): a manufactured gear pair has a pitch error on
every tooth. Given an ISO 1328-1:2013 flank tolerance class, one random set
is drawn per campaign (the same gears in every run,
:func:`uqgear.physics.pitch_errors.draw_pitch_errors`) and acts in the model's
pair loop (docs/model/equations.md section 2.6); the set is kept in the ``noise``
attribute with the other nuisances, which a blind diagnosis never sees.

Adhesion torque: the file carries a-priori bounds of +-15 % around the
balancing value (z2/z1) T1, clipped to mu in the design's adhesion range times
Q R_w (:func:`adhesion_torque_bounds`); the true T2 of each run is drawn
uniformly inside unless given.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import SupportsFloat, cast

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike
from scipy.interpolate import CubicSpline

from ..common.errors import OperatingPointError, RigDataError
from ..physics.design import Design
from ..physics.effects import Effect
from ..physics.integration import BATCH_DESIGN_KEYS, simulate
from ..physics.model import natural_frequencies
from ..physics.pitch_errors import PitchErrors, draw_pitch_errors, iso1328_single_pitch_tolerance
from ..uq.seeds import child_seed
from .campaign_checks import (
    campaign_seed,
    check_encoder_run_out,
    check_line_interference,
    check_positive,
    check_speed_wander,
)
from .features import SIGNAL_CHANNELS
from .format import make_rig_dataset, write_rig
from .ramp_segments import SOURCE_COORDINATES

#: Pinion speeds (rpm) and drive torques (N m) of the public campaigns.
DEFAULT_PINION_SPEEDS: tuple[float, ...] = (600.0, 800.0, 1250.0, 1700.0, 2200.0, 2800.0, 3400.0, 3800.0)
DEFAULT_DRIVE_TORQUES: tuple[float, ...] = (7000.0, 5000.0, 6000.0, 8000.0, 7500.0, 6500.0, 5500.0, 5000.0)

#: Half-width of the a-priori adhesion torque interval around (z2/z1) T1.
ADHESION_SPREAD = 0.15

#: Relative sensor noise of the public campaigns (of each run's RMS).
DEFAULT_RELATIVE_NOISE = 0.02

#: Keys ``true_parameters`` accepts besides the batch-variable design keys.
TRUE_PARAMETER_EXTRAS: tuple[str, ...] = ("mesh_stiffness_scale", "adhesion_torque")

#: Guard interval (s) simulated on each side of a record so that the filter's
#: edge effects (it is applied to a finite piece) stay outside the record.
RECORD_GUARD = 0.025
#: Outer part (s) of the guard interval that is tapered before the filter.
GUARD_TAPER = 0.015


def adhesion_torque_bounds(design: Design, drive_torque: ArrayLike,
                           spread: float = ADHESION_SPREAD) -> tuple[np.ndarray, np.ndarray]:
    """A-priori bounds of T2 per run: +-``spread`` around (z2/z1) T1, clipped to mu Q R_w.

    Parameters
    ----------
    design : Design
        Gives the ratio and, through ``design.operation``, the adhesion range.
    drive_torque : array_like
        T1 of each run, N m.
    spread : float
        Relative half-width around the balancing torque.

    Returns
    -------
    (lower, upper) : tuple of ndarray
        N m.
    """
    torque = np.asarray(drive_torque, dtype=float)
    balancing = torque * design.z2 / design.z1
    low_limit, high_limit = design.operation.adhesion_torque_bounds()
    lower = np.clip(balancing * (1.0 - spread), low_limit, high_limit)
    upper = np.clip(balancing * (1.0 + spread), low_limit, high_limit)
    return lower, upper


def default_operating_points(design: Design | None = None) -> xr.Dataset:
    """The 8 operating points of the public campaigns.

    Parameters
    ----------
    design : Design, optional
        When given, the adhesion torque bounds of :func:`adhesion_torque_bounds`
        are included.

    Returns
    -------
    xarray.Dataset
        Dimension ``op``: ``pinion_speed`` (rpm), ``drive_torque`` (N m) and,
        with a design, ``adhesion_torque_lower`` and ``adhesion_torque_upper``.
    """
    ops = xr.Dataset({
        "pinion_speed": ("op", np.array(DEFAULT_PINION_SPEEDS), {"units": "rpm", "long_name": "mean pinion speed"}),
        "drive_torque": ("op", np.array(DEFAULT_DRIVE_TORQUES), {"units": "N m", "long_name": "drive torque T1"}),
    })
    if design is not None:
        lower, upper = adhesion_torque_bounds(design, ops["drive_torque"].values)
        ops["adhesion_torque_lower"] = ("op", lower, {"units": "N m", "long_name": "lower bound of T2"})
        ops["adhesion_torque_upper"] = ("op", upper, {"units": "N m", "long_name": "upper bound of T2"})
    return ops


#: Drive torque of the light-load bearing check, N m (about a fifth of the rating).
BEARING_CHECK_DRIVE_TORQUE = 1500.0

#: Pinion speeds of the bearing check as multiples of the speeds that put the mesh fundamental
#: on the two bearing-dominated modes: bracketing each, since the true stiffnesses move them.
BEARING_CHECK_SPEED_FACTORS: tuple[tuple[float, ...], tuple[float, ...]] = ((0.9, 1.0, 1.1, 1.2),
                                                                            (0.95, 1.05, 1.15, 1.25))


def bearing_check_operating_points(design: Design, drive_torque: float = BEARING_CHECK_DRIVE_TORQUE,
                                   spread: float = ADHESION_SPREAD,
                                   mode_frequencies: ArrayLike | None = None) -> xr.Dataset:
    """A light-load run through the bearing modes: the plan that can show a bearing clearance.

    At service loads both bearings stay loaded and a clearance (a dead zone
    in the bearing force) is never entered. At light load, with the mesh
    fundamental near one of the two lowest (bearing-dominated) natural
    frequencies of the nominal design, the dynamic bearing force exceeds
    the static one and a bearing unloads. Eight runs: four around each of
    those speeds (:data:`BEARING_CHECK_SPEED_FACTORS`), rounded to 10 rpm.
    The load torque is the rig brake's, +-``spread`` around the balancing
    (z2/z1) T1; the wheel/rail adhesion range does not bound it on a rig.

    Parameters
    ----------
    design : Design
        Nominal design (its natural frequencies place the speeds).
    drive_torque : float
        T1 of every run, N m (> 0).
    spread : float
        Relative half-width of the T2 interval around the balancing torque.
    mode_frequencies : array_like of 2 floats, optional
        The two bearing-dominated natural frequencies of the rig under test, Hz
        (from a run-up or a tap test, or a model of that rig); the nominal
        design's by default. A rig's own modes, not the diagnosis model's,
        decide where its bearings unload.

    Returns
    -------
    xarray.Dataset
        Dimension ``op``: ``pinion_speed``, ``drive_torque``,
        ``adhesion_torque_lower`` and ``adhesion_torque_upper``.
    """
    torque = check_positive("drive_torque", drive_torque)
    if isinstance(spread, bool) or not isinstance(spread, (int, float)) or not 0.0 <= spread < 1.0:
        raise OperatingPointError(f"spread: expected a relative half-width in [0, 1); got {spread!r}")
    if mode_frequencies is None:
        modes = natural_frequencies(design)[:2]
    else:
        modes = np.asarray(mode_frequencies, dtype=float)
        if modes.shape != (2,) or not np.all(np.isfinite(modes) & (modes > 0.0)):
            raise OperatingPointError(f"mode_frequencies: expected two positive frequencies in Hz; "
                                      f"got {mode_frequencies!r}")
    mode_speeds = modes * 60.0 / design.z1
    speeds = np.concatenate([speed * np.asarray(factors)
                             for speed, factors in zip(mode_speeds, BEARING_CHECK_SPEED_FACTORS)])
    speeds = np.round(speeds / 10.0) * 10.0
    balancing = np.full(speeds.size, torque * design.z2 / design.z1)
    return xr.Dataset({
        "pinion_speed": ("op", speeds, {"units": "rpm", "long_name": "mean pinion speed"}),
        "drive_torque": ("op", np.full(speeds.size, torque), {"units": "N m", "long_name": "drive torque T1"}),
        "adhesion_torque_lower": ("op", balancing * (1.0 - spread), {"units": "N m",
                                                                     "long_name": "lower bound of T2"}),
        "adhesion_torque_upper": ("op", balancing * (1.0 + spread), {"units": "N m",
                                                                     "long_name": "upper bound of T2"}),
    })


def _operating_table(design: Design, operating_points: xr.Dataset | Mapping[str, ArrayLike] | None,
                     adhesion_override: ArrayLike | None, rng: np.random.Generator) -> dict[str, np.ndarray]:
    where = "operating_points"
    if operating_points is None:
        operating_points = default_operating_points()
    if isinstance(operating_points, xr.Dataset):
        # where a campaign's operating point came from (ramp_records: its source, a segment's place on its
        # ramp) is not a quantity it ran at
        raw = {str(name): operating_points[name].values for name in operating_points.variables
               if operating_points[name].dims == ("op",) and name not in SOURCE_COORDINATES}
    elif isinstance(operating_points, Mapping):
        raw = {str(name): np.asarray(values, dtype=float) for name, values in operating_points.items()}
    else:
        raise OperatingPointError(f"{where}: expected an xarray Dataset over 'op' or a mapping of arrays; "
                                  f"got {type(operating_points).__name__}")
    known = ("pinion_speed", "drive_torque", "adhesion_torque", "adhesion_torque_lower", "adhesion_torque_upper")
    unknown = sorted(set(raw) - set(known))
    if unknown:
        raise OperatingPointError(f"{where}.{unknown[0]}: unknown variable; expected {', '.join(known)}")
    for name in ("pinion_speed", "drive_torque"):
        if name not in raw:
            raise OperatingPointError(f"{where}.{name}: missing; expected one value per run")
    table = {name: np.atleast_1d(np.asarray(values, dtype=float)) for name, values in raw.items()}
    n_op = table["pinion_speed"].size
    for name, values in table.items():
        if values.shape != (n_op,):
            raise OperatingPointError(f"{where}.{name}: expected {n_op} values (one per run, as pinion_speed); "
                                      f"got shape {values.shape}")
        if not np.all(np.isfinite(values)):
            raise OperatingPointError(f"{where}.{name}: expected finite values; got {values}")
    if np.any(table["pinion_speed"] <= 0):
        raise OperatingPointError(f"{where}.pinion_speed: expected speeds > 0 rpm; got {table['pinion_speed']}")
    if np.any(table["drive_torque"] < 0):
        raise OperatingPointError(f"{where}.drive_torque: expected torques >= 0 N m; got {table['drive_torque']}")
    lower, upper = adhesion_torque_bounds(design, table["drive_torque"])
    table.setdefault("adhesion_torque_lower", lower)
    table.setdefault("adhesion_torque_upper", upper)
    if np.any(table["adhesion_torque_lower"] > table["adhesion_torque_upper"]):
        raise OperatingPointError(f"{where}.adhesion_torque_lower: expected <= adhesion_torque_upper; got "
                                  f"{table['adhesion_torque_lower']} and {table['adhesion_torque_upper']}")
    if adhesion_override is not None:
        table["adhesion_torque"] = np.atleast_1d(np.asarray(adhesion_override, dtype=float))
        if table["adhesion_torque"].shape != (n_op,):
            raise OperatingPointError(f"true_parameters.adhesion_torque: expected {n_op} values (one per run); "
                                      f"got shape {table['adhesion_torque'].shape}")
    if "adhesion_torque" not in table:
        table["adhesion_torque"] = rng.uniform(table["adhesion_torque_lower"], table["adhesion_torque_upper"])
    return table


def true_model(design: Design, true_parameters: Mapping[str, object] | None) -> tuple[Design, float, dict]:
    """The true design, stiffness scale and the JSON-ready record of the truth.

    ``true_parameters`` takes ``mesh_stiffness_scale`` (a factor in [0.1, 10], 1 where absent),
    ``adhesion_torque`` (set per run elsewhere, skipped here) and any batch-variable design key;
    the steady and the run-up virtual rig read their truth through it.

    Raises
    ------
    OperatingPointError
        An unknown key, a scale outside [0.1, 10] or a design value the design refuses.
    """
    values = dict(true_parameters or {})
    allowed = set(BATCH_DESIGN_KEYS) | set(TRUE_PARAMETER_EXTRAS)
    unknown = sorted(set(values) - allowed)
    if unknown:
        raise OperatingPointError(f"true_parameters.{unknown[0]}: unknown parameter; expected "
                                  f"mesh_stiffness_scale, adhesion_torque or a design key "
                                  f"({', '.join(BATCH_DESIGN_KEYS)})")
    scale = values.pop("mesh_stiffness_scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.floating)) or not 0.1 <= scale <= 10.0:
        raise OperatingPointError(f"true_parameters.mesh_stiffness_scale: expected a factor in [0.1, 10]; "
                                  f"got {scale!r}")
    values.pop("adhesion_torque", None)
    try:
        true_design = design.replace(**values) if values else design
    except ValueError as exc:
        raise OperatingPointError(f"true_parameters: {exc}") from None
    # Design.from_mapping accepted them, so they are numbers
    return true_design, float(scale), {key: float(cast(SupportsFloat, values[key])) for key in values}


def frequency_filter(size: int, rate: float, passband: float, stopband: float,
                     derivative_order: int) -> np.ndarray:
    """Real-FFT response: gain 1 to ``passband``, raised cosine to 0 at ``stopband``, times (i w)^order."""
    frequency = np.fft.rfftfreq(size, 1.0 / rate)
    gain = np.ones_like(frequency)
    transition = (frequency > passband) & (frequency < stopband)
    gain[transition] = 0.5 * (1.0 + np.cos(np.pi * (frequency[transition] - passband) / (stopband - passband)))
    gain[frequency >= stopband] = 0.0
    return gain * (2j * np.pi * frequency) ** derivative_order


def band_limited_record(time: np.ndarray, signal: np.ndarray, rate: float, keep: slice, taper: np.ndarray,
             passband: float, stopband: float, derivative_order: int) -> np.ndarray:
    """Band-limit a simulated signal (optionally differentiated) and return it on ``time[keep]``.

    The acquisition chain's anti-alias step, shared by the steady and the run-up virtual rig: the
    signal less its mean, times ``taper``, filtered by :func:`frequency_filter` (``derivative_order``
    time derivatives taken in the same pass); the mean is added back to an underived signal.
    """
    mean = signal.mean()
    tapered = (signal - mean) * taper
    response = frequency_filter(signal.size, rate, passband, stopband, derivative_order)
    filtered = np.fft.irfft(np.fft.rfft(tapered) * response, n=signal.size)
    if derivative_order == 0:
        filtered += mean
    return filtered[keep]


#: Spawn-key index of a run's speed wander phases. The indices of the per-run random streams of the
#: nuisances lie above those of the record start and the channels' noise, so that adding a nuisance
#: leaves every other draw as it was.
WANDER_STREAM = 1000
#: Spawn-key index of a run's line interference phases.
INTERFERENCE_STREAM = 1001
# The pitch errors are the gears', one draw per campaign: a child of the campaign's seed (whose
# children 1, 2, ... are the runs', so this one is free for campaigns of up to 1001 runs).
_PITCH_STREAM = 1002
#: Spawn-key index of a run's encoder run-out phases (the record start is arbitrary, so their phase is too).
ENCODER_STREAM = 1003


def _pitch_errors(design: Design, pitch_errors: int | PitchErrors | Mapping[str, ArrayLike] | None,
                  seed_sequence: np.random.SeedSequence) -> tuple[PitchErrors | None, dict | None]:
    """The campaign's pitch errors and their JSON record (grade, tolerances, values in m)."""
    if pitch_errors is None:
        return None, None
    record: dict[str, object]
    if isinstance(pitch_errors, (int, np.integer)) and not isinstance(pitch_errors, bool):
        grade = int(pitch_errors)
        errors = draw_pitch_errors(design, grade, np.random.default_rng(child_seed(seed_sequence, _PITCH_STREAM)))
        record = {"iso1328_class": grade,
                  "single_pitch_tolerance_pinion": iso1328_single_pitch_tolerance(
                      design.module * design.z1, design.module, grade),
                  "single_pitch_tolerance_gear": iso1328_single_pitch_tolerance(
                      design.module * design.z2, design.module, grade)}
    elif isinstance(pitch_errors, PitchErrors):
        errors, record = pitch_errors, {"iso1328_class": None}
    elif isinstance(pitch_errors, Mapping):
        unknown = sorted(set(pitch_errors) - {"pinion", "gear"})
        if unknown or len(pitch_errors) != 2:
            raise OperatingPointError(f"pitch_errors: expected the keys pinion and gear (per-tooth offsets in m); "
                                      f"got {sorted(pitch_errors)}")
        # PitchErrors takes array_like and converts it; its fields are typed as the arrays they become
        errors = PitchErrors(cast(np.ndarray, pitch_errors["pinion"]), cast(np.ndarray, pitch_errors["gear"]))
        record = {"iso1328_class": None}
    else:
        raise OperatingPointError(f"pitch_errors: expected an ISO 1328-1 flank tolerance class (integer 1..11), "
                                  f"a PitchErrors or a mapping with pinion and gear offsets in m; "
                                  f"got {pitch_errors!r:.80}")
    errors.check(design)
    return errors, {**record, **errors.to_dict()}


def _encoder_lines(encoder: Mapping[str, float], design: Design, speed: float, sample_time: np.ndarray,
                   rng: np.random.Generator) -> np.ndarray:
    """The TE an eccentric encoder mounting adds: once per revolution of its shaft, at the shaft's actual angle."""
    return encoder_lines_at(encoder, design, 2.0 * math.pi * speed / 60.0 * sample_time, rng)


def encoder_lines_at(encoder: Mapping[str, float], design: Design, pinion_angle: np.ndarray,
                     rng: np.random.Generator) -> np.ndarray:
    """The TE of eccentric encoder mountings at the pinion angles ``pinion_angle`` (rad); a phase per shaft."""
    lines = np.zeros(pinion_angle.size)
    for shaft in ("pinion", "gear"):
        phase = rng.uniform(0.0, 2.0 * math.pi)    # drawn for both shafts, so each keeps its draw
        if shaft in encoder:
            ratio = 1.0 if shaft == "pinion" else design.z1 / design.z2
            lines += encoder[shaft] * np.sin(ratio * pinion_angle + phase)
    return lines


def add_interference(signal: np.ndarray, interference: Mapping[float, float], record_time: np.ndarray,
                     rng: np.random.Generator) -> np.ndarray:
    """``signal`` plus fixed-frequency lines (Hz -> amplitude), each at a phase drawn from ``rng`` in turn."""
    for frequency, amplitude in interference.items():
        signal = signal + amplitude * np.cos(2.0 * math.pi * frequency * record_time + rng.uniform(0.0, 2.0 * math.pi))
    return signal


def simulate_campaign(design: Design, operating_points: xr.Dataset | Mapping[str, ArrayLike] | None = None, *,
                      true_parameters: Mapping[str, object] | None = None, effects: Sequence[Effect] = (),
                      noise_std: Mapping[str, float] | None = None,
                      relative_noise: float = DEFAULT_RELATIVE_NOISE, fs: float = 20480.0, duration: float = 1.0,
                      run_in: float = 1.0, seed: np.random.SeedSequence | int | None = None,
                      channels: Sequence[str] = tuple(SIGNAL_CHANNELS), title: str | None = None,
                      oversampling: int = 4, steps_per_mode: int = 32,
                      speed_wander: Sequence[tuple[float, float]] = (),
                      line_interference: Mapping[float, float] | None = None,
                      pitch_errors: int | PitchErrors | Mapping[str, ArrayLike] | None = None,
                      encoder_run_out: Mapping[str, float] | None = None) -> xr.Dataset:
    """Simulate a rig campaign and return it in the ``uqgear-rig/1`` format.

    Parameters
    ----------
    design : Design
        The *nominal* design, stored in the ``design`` attribute.
    operating_points : xarray.Dataset or mapping, optional
        Over dimension ``op``: ``pinion_speed`` (rpm) and ``drive_torque``
        (N m), optionally ``adhesion_torque_lower``/``_upper`` (default
        :func:`adhesion_torque_bounds`) and the true ``adhesion_torque``
        (default: uniform inside the bounds, from the seed). Default: the 8
        runs of the public campaigns (:func:`default_operating_points`).
    true_parameters : mapping, optional
        The rig's true values: ``mesh_stiffness_scale`` (factor on the
        nominal Ishikawa stiffness, default 1), any design key (``zeta_mesh``,
        ``backlash``, ``ste_amplitude``, ``k1``, ``k2``, ...; default nominal)
        and ``adhesion_torque`` (one value per run, N m).
    effects : sequence of Effect
        Unmodelled effects acting on the rig (:mod:`uqgear.physics.effects`).
    noise_std : mapping, optional
        Channel -> absolute sensor noise standard deviation (channel units).
    relative_noise : float
        Sensor noise as a fraction of each run's clean RMS (0 for none).
    fs : float
        Sampling rate in Hz.
    duration, run_in : float
        Record length and discarded run-in in s (a run-in below the filter's
        25 ms guard interval is raised to it).
    seed : SeedSequence or int, optional
        Source of all randomness (true T2 if not given, record starts, noise).
        Without one a fresh SeedSequence is drawn and recorded in ``attrs``.
    channels : sequence of str
        Channels to record, among ``te``, ``acc_pinion``, ``acc_gear``.
    title : str, optional
        Free text for the ``title`` attribute.
    oversampling : int
        The model output rate is at least ``oversampling * fs`` before
        filtering and resampling.
    steps_per_mode : int
        RK4 steps per period of the highest natural frequency.
    speed_wander : sequence of (float, float)
        Components (relative amplitude, frequency in Hz) of the pinion speed's
        wander within each record: n(t) = n1 (1 + sum a sin(2 pi f t + phi)),
        phases random per run. The model runs at the mean speed and its
        output is read at the pinion angle the wandering shaft reaches
        (quasi-steady: the response follows the angle, accelerations scale
        with the squared instantaneous speed), which is what order tracking
        must undo.
    line_interference : mapping, optional
        Frequency (Hz) -> amplitude (m s-2) of fixed-frequency lines (mains
        pickup, e.g. ``{50: 0.5, 150: 0.2}``) on the accelerometer channels,
        phases random per run and channel.
    pitch_errors : int, PitchErrors or mapping, optional
        Pitch errors of the rig's gears, the same in every run. An integer is
        an ISO 1328-1:2013 flank tolerance class A (1..11; traction gears are
        typically 6 to 8): per gear (reference diameter d = m z, module m)
        the single pitch tolerance is
        ``f_pT = (0.001 d + 0.4 m + 5) sqrt(2)^(A - 5)`` um (d, m in mm;
        ISO 1328-1:2013 formula (5), unrounded), the single pitch deviations
        are drawn normal with sigma = f_pT / 2, closed (their sum over the
        gear is zero), summed to tooth positions (mean removed) and taken
        along the line of action (times cos alpha); see
        :func:`uqgear.physics.pitch_errors.draw_pitch_errors`. The draw has
        its own stream (child 1002 of the seed), so every other draw of the
        campaign is as without pitch errors. Explicit offsets: a
        :class:`~uqgear.physics.pitch_errors.PitchErrors` or a mapping
        ``{"pinion": z1 values, "gear": z2 values}`` in m. Recorded in the
        ``noise`` attribute (class, tolerances, offsets).
    encoder_run_out : mapping, optional
        Shaft (``pinion``, ``gear``) -> amplitude (m, in ``te`` units) of a
        run-out of that shaft's encoder mounting: an eccentric encoder disc
        reads its shaft's angle with a once-per-revolution error, so ``te``
        gains a line at 1x that shaft's rotation, following the shaft's
        actual angle (wander included), with a phase random per run. It is
        the sensor's, not the gears': the mesh and both accelerometers are
        untouched. Added after the sensor noise, whose level it leaves as it was.

    Returns
    -------
    xarray.Dataset
        Valid ``uqgear-rig/1`` data; extra global attributes
        ``true_parameters`` (JSON: mesh_stiffness_scale, the design keys given,
        adhesion_torque per run), ``effects`` (JSON list of name and values),
        ``noise`` (JSON; with pitch errors also ``pitch_errors``: the
        ``iso1328_class`` or null, the tolerances f_pT of pinion and gear in
        m and the per-tooth ``pinion`` and ``gear`` offsets in m), ``seed_entropy``.

    Raises
    ------
    OperatingPointError
        A wrong operating point, true parameter, noise level or setting.

    Examples
    --------
    Two short runs of a rig whose mesh is 10 % stiffer than the nominal
    design's; the truth is recorded with the data, and the same seed gives
    the same campaign:

    >>> import json
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> runs = {"pinion_speed": [1500.0, 3000.0], "drive_torque": [7000.0, 5000.0]}
    >>> campaign = uqgear.simulate_campaign(design, runs, true_parameters={"mesh_stiffness_scale": 1.1},
    ...                                     duration=0.1, run_in=0.05, seed=7)
    >>> campaign.attrs["conventions"], dict(campaign.sizes), list(campaign.data_vars)
    ('uqgear-rig/1', {'op': 2, 'time': 2048}, ['te', 'acc_pinion', 'acc_gear'])
    >>> truth = json.loads(campaign.attrs["true_parameters"])
    >>> truth["mesh_stiffness_scale"], len(truth["adhesion_torque"])
    (1.1, 2)
    >>> bool((campaign["adhesion_torque_lower"] <= truth["adhesion_torque"]).all())
    True
    >>> again = uqgear.simulate_campaign(design, runs, true_parameters={"mesh_stiffness_scale": 1.1},
    ...                                  duration=0.1, run_in=0.05, seed=7)
    >>> bool((again["te"] == campaign["te"]).all())
    True
    """
    seed_sequence = campaign_seed(seed)
    fs = check_positive("fs", fs)
    duration = check_positive("duration", duration)
    if isinstance(run_in, bool) or not isinstance(run_in, (int, float)) or not math.isfinite(run_in) or run_in < 0:
        raise OperatingPointError(f"run_in: expected a duration >= 0 s; got {run_in!r}")
    relative_noise = float(relative_noise)
    if not math.isfinite(relative_noise) or relative_noise < 0:
        raise OperatingPointError(f"relative_noise: expected a fraction >= 0 of the run's RMS; got {relative_noise!r}")
    if isinstance(oversampling, bool) or not isinstance(oversampling, (int, np.integer)) or oversampling < 2:
        raise OperatingPointError(f"oversampling: expected an integer >= 2; got {oversampling!r}")
    channels = list(channels)
    noise_std = _check_noise_std(noise_std, channels)
    wander = check_speed_wander(speed_wander)
    interference = check_line_interference(line_interference, fs)
    encoder = check_encoder_run_out(encoder_run_out)
    true_design, stiffness_scale, true_record = true_model(design, true_parameters)
    pitch, pitch_record = _pitch_errors(design, pitch_errors, seed_sequence)
    top_rng = np.random.default_rng(child_seed(seed_sequence, 0))
    # one value per run, checked by _operating_table
    adhesion_override = cast("ArrayLike | None", (true_parameters or {}).get("adhesion_torque"))
    table = _operating_table(design, operating_points, adhesion_override, top_rng)
    n_op = table["pinion_speed"].size
    fastest = float(table["pinion_speed"].max())
    if not fs > 6.0 * design.z1 * fastest / 60.0:
        raise OperatingPointError(f"fs: {fs:g} Hz does not resolve the third mesh harmonic at {fastest:g} rpm; "
                                  f"expected more than {6.0 * design.z1 * fastest / 60.0:g} Hz")
    n_samples = int(round(duration * fs))
    acquisition = _Acquisition(
        fs=fs, duration=duration, run_in=float(run_in), oversampling=int(oversampling), channels=tuple(channels),
        noise_std=noise_std, relative_noise=relative_noise, wander=wander, interference=interference,
        encoder=encoder, record_time=np.arange(n_samples) / fs,
        # largest time shift of the wandering shaft against the mean rotation
        wander_shift=sum(amplitude / (2.0 * math.pi * frequency) for amplitude, frequency in wander) * 2.0)
    plant = _TruePlant(true_design, stiffness_scale, tuple(effects), steps_per_mode, pitch)
    # children derived from the spawn key: the same seed object always gives the same campaign
    run_seeds = [child_seed(seed_sequence, 1 + op) for op in range(n_op)]
    data = {name: np.empty((n_op, n_samples)) for name in channels}
    for op in range(n_op):
        records = _record_run(design, plant, acquisition, float(table["pinion_speed"][op]),
                              (float(table["drive_torque"][op]), float(table["adhesion_torque"][op])), run_seeds[op])
        for name in channels:
            data[name][op] = records[name]

    stamp = datetime.now(UTC).isoformat(timespec="seconds")
    truth = {"mesh_stiffness_scale": stiffness_scale, **true_record,
             "adhesion_torque": [float(v) for v in table["adhesion_torque"]]}
    effect_record = [{"name": effect.name, "values": dict(effect.values)} for effect in effects]
    noise_record = {"relative_noise": relative_noise, "noise_std": noise_std,
                    "speed_wander": [list(component) for component in wander],
                    "line_interference": {f"{frequency:g}": amplitude for frequency, amplitude in interference.items()}}
    if encoder:
        noise_record["encoder_run_out"] = dict(encoder)
    if pitch_record is not None:
        noise_record["pitch_errors"] = pitch_record
    ds = make_rig_dataset(
        time=acquisition.record_time, pinion_speed=table["pinion_speed"], drive_torque=table["drive_torque"],
        adhesion_torque_lower=table["adhesion_torque_lower"], adhesion_torque_upper=table["adhesion_torque_upper"],
        channels=data, design=design,
        title=title or "uqgear virtual rig campaign",
        source="uqgear virtual rig: 3-DOF gear model (fast RK4 integrator), zero-delay anti-alias low-pass "
               f"flat to {acquisition.passband:g} Hz and zero from {acquisition.stopband:g} Hz, Gaussian sensor noise",
        history=f"{stamp}: simulated by uqgear.rig.virtual_rig.simulate_campaign; {duration:g} s records at "
                f"{fs:g} Hz after a run-in of {run_in:g} s plus a random start within a pinion revolution",
        noise_std=noise_std if relative_noise == 0 and noise_std else None)
    ds.attrs.update(true_parameters=json.dumps(truth), effects=json.dumps(effect_record),
                    noise=json.dumps(noise_record), seed_entropy=str(seed_sequence.entropy),
                    seed_spawn_key=json.dumps([int(k) for k in seed_sequence.spawn_key]))
    return ds


def _check_noise_std(noise_std: Mapping[str, float] | None, channels: list[str]) -> dict[str, float]:
    """The channels recorded (at least one, each a rig channel) and the fixed noise of some of them."""
    for name in channels:
        if name not in SIGNAL_CHANNELS:
            raise OperatingPointError(f"channels: {name!r} is not a rig channel; expected {', '.join(SIGNAL_CHANNELS)}")
    if not channels:
        raise OperatingPointError("channels: expected at least one channel")
    noise_std = dict(noise_std or {})
    for name, value in noise_std.items():
        if name not in channels:
            raise OperatingPointError(f"noise_std.{name}: not among the channels recorded ({', '.join(channels)})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
            raise OperatingPointError(f"noise_std.{name}: expected a standard deviation >= 0 in "
                                      f"{SIGNAL_CHANNELS[name][0]}; got {value!r}")
    return noise_std


@dataclass(frozen=True)
class _Acquisition:
    """How the rig records: sample rate, record length, run-in, noise, speed wander, interference, encoder."""

    fs: float
    duration: float
    run_in: float
    oversampling: int
    channels: tuple[str, ...]
    noise_std: dict[str, float]
    relative_noise: float
    wander: list[tuple[float, float]]
    interference: dict[float, float]
    encoder: dict[str, float]
    record_time: np.ndarray
    wander_shift: float

    @property
    def passband(self) -> float:
        """Upper edge of the anti-alias filter's flat band (Hz)."""
        return self.fs / 2.56

    @property
    def stopband(self) -> float:
        """Lower edge of the anti-alias filter's stop band (Hz)."""
        return self.fs / 2.0


@dataclass(frozen=True)
class _TruePlant:
    """The gearbox the rig holds: its true design and mesh stiffness scale, effects, integrator steps, pitch errors."""

    design: Design
    stiffness_scale: float
    effects: tuple[Effect, ...]
    steps_per_mode: int
    pitch: PitchErrors | None


def _record_run(design: Design, plant: _TruePlant, acquisition: _Acquisition, speed: float,
                torques: tuple[float, float], run_seed: np.random.SeedSequence) -> dict[str, np.ndarray]:
    """One run's records of every channel: simulated with guards, filtered, resampled at the record's times."""
    channels = acquisition.channels
    duration, n_samples = acquisition.duration, acquisition.record_time.size
    wander_shift, record_time = acquisition.wander_shift, acquisition.record_time
    mesh_frequency = design.z1 * speed / 60.0
    op_seed, *channel_seeds = (child_seed(run_seed, index) for index in range(1 + len(channels)))
    # arbitrary record start: anywhere within a pinion revolution after the run-in
    # (never inside the filter's guard interval at the start of the simulation)
    start = max(acquisition.run_in, RECORD_GUARD) + np.random.default_rng(op_seed).uniform(0.0, 60.0 / speed)
    per_period = int(math.ceil(acquisition.oversampling * acquisition.fs / mesh_frequency))
    first_period = max(int(math.floor((start - RECORD_GUARD - wander_shift) * mesh_frequency)), 0)
    last_period = int(math.ceil((start + duration + RECORD_GUARD + wander_shift) * mesh_frequency)) + 1
    sim = simulate(plant.design, speed, torques[0], torques[1],
                   n_periods=last_period, keep_periods=last_period - first_period,
                   samples_per_period=per_period, mesh_stiffness_scale=plant.stiffness_scale, effects=plant.effects,
                   steps_per_mode=plant.steps_per_mode, pitch_errors=plant.pitch)
    time = sim["time"].values
    rate = per_period * mesh_frequency
    keep = slice(int(np.searchsorted(time, start - 0.5 * RECORD_GUARD - wander_shift)),
                 int(np.searchsorted(time, start + duration + 0.5 * RECORD_GUARD + wander_shift)))
    # taper only the outer part of the guard intervals, far from the record
    taper = np.ones(time.size)
    ramp_left = time < time[0] + GUARD_TAPER
    taper[ramp_left] = 0.5 * (1.0 - np.cos(np.pi * (time[ramp_left] - time[0]) / GUARD_TAPER))
    ramp_right = time > time[-1] - GUARD_TAPER
    taper[ramp_right] = 0.5 * (1.0 - np.cos(np.pi * (time[-1] - time[ramp_right]) / GUARD_TAPER))
    sample_time = start + record_time
    speed_ratio = np.ones(n_samples)
    if acquisition.wander:
        phases = np.random.default_rng(child_seed(run_seed, WANDER_STREAM)).uniform(
            0.0, 2.0 * math.pi, len(acquisition.wander))
        for (amplitude, frequency), phase in zip(acquisition.wander, phases):
            omega = 2.0 * math.pi * frequency
            sample_time = sample_time + amplitude / omega * (math.cos(phase) - np.cos(omega * record_time + phase))
            speed_ratio = speed_ratio + amplitude * np.sin(omega * record_time + phase)
    interference_rng = np.random.default_rng(child_seed(run_seed, INTERFERENCE_STREAM))
    records = {}
    for name, channel_seed in zip(channels, channel_seeds):
        if name == "te":
            raw, order = sim["te"].values, 0
        else:
            raw, order = sim["y1" if name == "acc_pinion" else "y2"].values, 2
        filtered = band_limited_record(time, raw, rate, keep, taper, acquisition.passband, acquisition.stopband, order)
        clean = CubicSpline(time[keep], filtered)(sample_time)
        if order == 2:
            clean = clean * speed_ratio**2
        rms = float(np.sqrt(np.mean((clean - clean.mean()) ** 2)))
        sigma = math.hypot(acquisition.noise_std.get(name, 0.0), acquisition.relative_noise * rms)
        noisy = clean + sigma * np.random.default_rng(channel_seed).standard_normal(n_samples)
        if order == 2:
            noisy = add_interference(noisy, acquisition.interference, record_time, interference_rng)
        if name == "te" and acquisition.encoder:
            noisy = noisy + _encoder_lines(acquisition.encoder, design, speed, sample_time,
                                           np.random.default_rng(child_seed(run_seed, ENCODER_STREAM)))
        records[name] = noisy - noisy.mean() if name == "te" else noisy
    return records


def true_parameters_of(ds: xr.Dataset) -> dict[str, object]:
    """The truth recorded by :func:`simulate_campaign` (``true_parameters`` attribute)."""
    text = ds.attrs.get("true_parameters")
    if not isinstance(text, str):
        raise RigDataError("true_parameters: attribute missing; only campaigns of uqgear's virtual rig carry "
                           "their true parameters")
    return json.loads(text)


def synth_rig(design: Design, out_path: str | os.PathLike[str], *, effects: Sequence[Effect] = (),
              true_parameters: Mapping[str, object] | None = None,
              seed: np.random.SeedSequence | int | None = None, noise_std: Mapping[str, float] | None = None,
              relative_noise: float = DEFAULT_RELATIVE_NOISE,
              operating_points: xr.Dataset | Mapping[str, ArrayLike] | None = None,
              duration: float = 1.0, run_in: float = 1.0, title: str | None = None,
              pitch_errors: int | PitchErrors | Mapping[str, ArrayLike] | None = None) -> Path:
    """Simulate a campaign (:func:`simulate_campaign`) and write it atomically as a rig file.

    This is what ``uqgear synth-rig --design FILE --out FILE.nc [--effect ...] [--seed N]`` runs.

    Parameters
    ----------
    design : Design
        Nominal design (stored in the file).
    out_path : str or path-like
        Target ``.nc`` file; its folder must exist.
    effects, true_parameters, seed, noise_std, relative_noise, operating_points, duration, run_in, title, pitch_errors
        As in :func:`simulate_campaign`.

    Returns
    -------
    pathlib.Path
        The file written.
    """
    path = Path(out_path)
    if not path.parent.is_dir():
        raise RigDataError(f"{path}: folder {path.parent} does not exist")
    ds = simulate_campaign(design, operating_points, true_parameters=true_parameters, effects=effects,
                           noise_std=noise_std, relative_noise=relative_noise, duration=duration, run_in=run_in,
                           seed=seed, title=title, pitch_errors=pitch_errors)
    return write_rig(path, ds)


__all__ = ["simulate_campaign", "synth_rig", "default_operating_points", "adhesion_torque_bounds",
           "true_parameters_of", "bearing_check_operating_points", "BEARING_CHECK_DRIVE_TORQUE",
           "BEARING_CHECK_SPEED_FACTORS", "DEFAULT_PINION_SPEEDS", "DEFAULT_DRIVE_TORQUES", "ADHESION_SPREAD",
           "DEFAULT_RELATIVE_NOISE", "RECORD_GUARD", "GUARD_TAPER", "WANDER_STREAM", "INTERFERENCE_STREAM",
           "ENCODER_STREAM", "band_limited_record", "true_model"]
