"""Mesh-harmonic features: steady amplitudes of the model (numba kernels) and of rig records.

The model features of one run come from :func:`model_harmonics`: the steady
periodic response is found by Newton shooting on the one-mesh-period map
(stable orbit checked through the Floquet multipliers), or, when there is no
stable period-1 orbit (contact loss, chaos) by a plain transient of
``transient`` s followed by an average over ``window`` s. Harmonic
amplitudes are exact Fourier coefficients over whole mesh periods; those of
the accelerations are taken from the smooth displacements by integration by
parts, because sampling y'' itself would alias its jumps at the mesh
stiffness steps (the rig's anti-alias filter removes them).

The observed features (:func:`observed_harmonics`) are the amplitudes of a
joint line fit of the rig records (:func:`uqgear.rig.features.extract_features`)
with the sensor-noise standard deviation of each amplitude.
"""

from __future__ import annotations

import math
from collections.abc import Hashable, Sequence
from typing import Any

import numba as nb
import numpy as np
import scipy.signal
import xarray as xr

from ..physics import kernels as K
from ..physics._batch_record import run_arrays
from ..physics.batch_setup import build_batch, kernel_inputs
from ..physics.design import Design
from ..physics.effects import MESH_PERIODIC_EFFECTS, Effect
from ..physics.integration import steps_per_period
from ..physics.threads import spread
from ..rig.features import extract_features
from .errors import CalibrationError

#: Channels of :func:`model_harmonics`, in order.
HARMONIC_CHANNELS: tuple[str, ...] = ("te", "acc_pinion", "acc_gear")


# ---------------------------------------------------------------------------
# numba kernels
# ---------------------------------------------------------------------------


@nb.njit(cache=True)
def _scaled_change(a, b, scale):
    worst = 0.0
    for c in range(6):
        d = abs(a[c] - b[c]) / scale[c]
        if d > worst:
            worst = d
    return worst


@nb.njit(cache=True)
def _shoot(state, p, pair_k, period_k, fp, fg, schedule, scale, tolerance, max_newton):
    """Newton iteration on the one-period map from t = 0; 1 if a stable periodic orbit is found."""
    base = np.empty(6)
    probe = np.empty(6)
    jacobian = np.empty((6, 6))
    residual = np.empty(6)
    for iteration in range(max_newton):
        for c in range(6):
            base[c] = state[c]
        K.advance(base, 0, 1, p, pair_k, period_k, fp, fg, schedule)
        if iteration > 0 and _scaled_change(base, state, scale) < tolerance:
            return 1
        for c in range(6):
            for r in range(6):
                probe[r] = state[r]
            delta = 1e-6 * scale[c]
            probe[c] += delta
            K.advance(probe, 0, 1, p, pair_k, period_k, fp, fg, schedule)
            for r in range(6):
                jacobian[r, c] = (probe[r] - base[r]) / delta
        # an orbit that the transient would not reach (a Floquet multiplier
        # outside the unit circle) is no steady state
        multipliers = np.linalg.eigvals(jacobian.astype(np.complex128))
        radius = 0.0
        for value in multipliers:
            if abs(value) > radius:
                radius = abs(value)
        if radius >= 1.0:
            return 0
        system = jacobian.copy()
        for c in range(6):
            system[c, c] -= 1.0
            residual[c] = state[c] - base[c]
        correction = np.linalg.solve(system, residual)
        for c in range(6):
            state[c] += correction[c]
    return 0


# numba-inlined into _steady_harmonics, itself inlined into its only caller
@nb.njit(cache=True, inline="always")
def _fourier_tables(n_harmonics, per_period):
    """Cosines and sines of the first ``n_harmonics`` mesh harmonics at the samples of one mesh period."""
    cosines = np.empty((n_harmonics, per_period))
    sines = np.empty((n_harmonics, per_period))
    for k in range(n_harmonics):
        for j in range(per_period):
            angle = K.TWO_PI * (k + 1) * j / per_period
            cosines[k, j] = math.cos(angle)
            sines[k, j] = math.sin(angle)
    return cosines, sines


# numba-inlined into _steady_harmonics, itself inlined into its only caller
@nb.njit(cache=True, inline="always")
def _amplitudes(sums, state, start, count, window, omega, n_harmonics, out):
    """Each channel's mesh-harmonic amplitudes from the Fourier sums over ``count`` samples of ``window`` s:
    the TE's directly, the accelerations' from the displacement sums and the state change."""
    for k in range(n_harmonics):
        out[0, k] = 2.0 * math.hypot(sums[0, k, 0], sums[0, k, 1]) / count
        w = (k + 1) * omega
        for channel in range(1, 3):
            # integral of y'' e^{-ikwt} over whole periods, by parts twice:
            # dv + ikw dy - (kw)^2 * integral of y e^{-ikwt}
            dy = state[channel - 1] - start[channel - 1]
            dv = state[channel + 2] - start[channel + 2]
            real = dv / window - w * w * sums[channel, k, 0] / count
            imaginary = w * dy / window - w * w * sums[channel, k, 1] / count
            out[channel, k] = 2.0 * math.hypot(real, imaginary)


# numba-inlined into its only caller (not compiled and emitted twice; see uqgear.physics._kernels.INLINED)
@nb.njit(cache=True, inline="always")
def _steady_harmonics(
    state,
    p,
    pair_k,
    period_k,
    fp,
    fg,
    bps,
    steps,
    stride,
    transient_periods,
    min_periods,
    max_periods,
    tolerance,
    scale,
    n_harmonics,
    shoot,
    out,
    info,
):
    schedule = K.build_schedule(p, pair_k, period_k, bps, steps)
    previous = np.empty(6)
    start = np.empty(6)
    omega = p[K.OMEGA_MESH]
    period = K.TWO_PI / omega
    h = period / steps
    per_period = steps // stride
    cosines, sines = _fourier_tables(n_harmonics, per_period)
    found = 0
    if shoot:
        candidate = state.copy()
        found = _shoot(candidate, p, pair_k, period_k, fp, fg, schedule, scale, tolerance, 4)
        if found == 1:
            for c in range(6):
                state[c] = candidate[c]
    offset = 0
    if found == 0:
        K.advance(state, 0, transient_periods, p, pair_k, period_k, fp, fg, schedule)
        offset = transient_periods
    sums = np.zeros((3, n_harmonics, 2))
    for c in range(6):
        previous[c] = state[c]
        start[c] = state[c]
    used = 0
    periodic = 0
    for m in range(max_periods):
        n = offset + m
        s = (state[0], state[1], state[2], state[3], state[4], state[5])
        for j in range(steps):
            if j % stride == 0:
                ste = K.static_transmission_error(n * period + j * h, p)
                sample = j // stride
                for channel in range(3):
                    if channel == 0:
                        value = s[2] - s[0] + s[1] + ste
                    else:
                        value = s[channel - 1]
                    for k in range(n_harmonics):
                        sums[channel, k, 0] += value * cosines[k, sample]
                        sums[channel, k, 1] -= value * sines[k, sample]
            s, _, _, _ = K.scheduled_step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule)
        for c in range(6):
            state[c] = s[c]
        used += 1
        if _scaled_change(state, previous, scale) < tolerance:
            periodic += 1
        else:
            periodic = 0
        for c in range(6):
            previous[c] = state[c]
        if used >= min_periods and periodic >= min_periods:
            break
    _amplitudes(sums, state, start, used * per_period, used * period, omega, n_harmonics, out)
    info[0] = used
    info[1] = 1.0 if periodic >= min_periods else 0.0


@nb.njit(cache=True, nogil=True)
def _harmonics_batch(
    start, stop, runs, steps, stride, transient_periods, min_periods, max_periods, tolerance, scales, n_harmonics,
    shoot, out, info,
):
    """Samples ``start`` to ``stop - 1`` of ``runs`` (a :class:`~uqgear.physics._batch_record.RunInputs`; GIL
    released; threads share a batch by ranges)."""
    for i in range(start, stop):
        state = runs.states[i].copy()
        p, pair_k, period_k, fp, fg, breakpoints = run_arrays(runs, i)
        _steady_harmonics(
            state,
            p,
            pair_k,
            period_k,
            fp,
            fg,
            breakpoints,
            steps[i],
            stride[i],
            transient_periods[i],
            min_periods,
            max_periods[i],
            tolerance,
            scales[i],
            n_harmonics,
            shoot,
            out[i],
            info[i],
        )


# ---------------------------------------------------------------------------
# model features
# ---------------------------------------------------------------------------


def averaging_revolution(design: Design, effects: Sequence[Effect]) -> int:
    """Mesh periods of the revolution a window without mesh periodicity is a whole number of.

    A gear's revolution (``z2`` periods) where an effect repeats over it (a
    gear run-out, a damaged gear tooth), otherwise the pinion's (``z1``).
    Whole pinion revolutions keep pinion-order lines off the mesh harmonics.
    A gear-locked effect needs whole gear revolutions: a shorter window sees
    a part of its cycle (its stiffness modulation read at one place of the
    revolution), so the harmonics depend on its phase and a calibration's
    mesh stiffness and damping absorb the difference, where a rig's records,
    some gear revolutions long, average over the cycle.

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> averaging_revolution(design, [uqgear.make_effect("eccentricity", {"shaft": "gear"})])
    101
    >>> averaging_revolution(design, [uqgear.make_effect("tooth_damage", {"gear": "pinion"})])
    21
    """
    if any(effect.repeat_shaft == "gear" for effect in effects):
        return int(design.z2)
    return int(design.z1)


def model_harmonics(
    design: Design,
    samples: xr.Dataset,
    *,
    effects: Sequence[Effect] = (),
    n_harmonics: int = 3,
    transient: float = 0.2,
    window: float = 0.1,
    samples_per_period: int = 64,
    tolerance: float = 1e-6,
    steps_per_mode: int = 24,
    threads: int | None = None,
) -> xr.Dataset:
    """Steady mesh-harmonic amplitudes of te, acc_pinion and acc_gear, many samples in parallel.

    Parameters
    ----------
    design : Design
        Base design; sample variables named like design keys override it.
    samples : xarray.Dataset
        Dimension ``sample`` with the variables of
        :func:`uqgear.simulate_batch` (``pinion_speed`` required,
        ``drive_torque``, ``adhesion_torque``, ``mesh_stiffness_scale``,
        design keys, ``EFFECT.PARAMETER``).
    effects : sequence of Effect
        Model extensions. Effects other than friction and bearing clearance
        break the mesh periodicity: then no shooting, and the averaging
        window is a whole number of revolutions (:func:`averaging_revolution`).
    n_harmonics : int
        Mesh harmonics k = 1..n_harmonics.
    transient, window : float
        Without a stable periodic orbit: the transient discarded and the
        averaging window, in s.
    samples_per_period : int
        Samples per mesh period for the Fourier sums (of smooth signals only).
    tolerance : float
        Relative change of the state over one period that counts as periodic
        (state scaled by the static mesh deflection).
    steps_per_mode : int
        RK4 steps per period of the highest natural frequency.
    threads : int, optional
        Number of threads (default: all cores).

    Returns
    -------
    xarray.Dataset
        ``amplitude`` over (sample, channel, harmonic) in the channels' units;
        ``periodic`` (bool) and ``window_periods`` over sample; the sample
        variables as coordinates.
    """
    if isinstance(n_harmonics, bool) or not isinstance(n_harmonics, (int, np.integer)) or not 1 <= n_harmonics:
        raise CalibrationError(f"n_harmonics: expected an integer >= 1; got {n_harmonics!r}")
    if samples_per_period < 2 * n_harmonics + 2:
        raise CalibrationError(
            f"samples_per_period: expected at least {2 * n_harmonics + 2} for "
            f"{n_harmonics} harmonics; got {samples_per_period!r}"
        )
    setups, steps = _batch_setups(design, samples, effects, steps_per_mode, samples_per_period)
    n = len(setups)
    stride = steps // samples_per_period
    mesh_frequency = np.array([s.mesh_frequency for s in setups])
    periodic_model = all(effect.name in MESH_PERIODIC_EFFECTS for effect in effects)
    revolution = averaging_revolution(design, effects)
    transient_periods = np.ceil(transient * mesh_frequency).astype(np.int64)
    window_periods = np.maximum(np.ceil(window * mesh_frequency).astype(np.int64), 2)
    if not periodic_model:
        window_periods = (np.ceil(window_periods / revolution) * revolution).astype(np.int64)
    scales = _state_scales(setups)
    out = np.zeros((n, 3, int(n_harmonics)))
    info = np.zeros((n, 2))
    if n:
        arrays = (
            kernel_inputs(setups, np.stack([s.static_state() for s in setups])),
            steps,
            stride,
            transient_periods,
            2,
            window_periods,
            float(tolerance),
            scales,
            int(n_harmonics),
            periodic_model,
            out,
            info,
        )
        spread(lambda start, stop: _harmonics_batch(start, stop, *arrays), n, threads)
    coords: dict[Hashable, Any] = {"channel": list(HARMONIC_CHANNELS), "harmonic": np.arange(1, n_harmonics + 1)}
    for name in samples.data_vars:
        coords[name] = ("sample", samples[name].values)
    return xr.Dataset(
        {
            "amplitude": (
                ("sample", "channel", "harmonic"),
                out,
                {"long_name": "steady mesh-harmonic amplitude", "units": "m (te), m s-2 (acc_pinion, acc_gear)"},
            ),
            "periodic": ("sample", info[:, 1] > 0, {"long_name": "steady response periodic in the mesh period"}),
            "window_periods": ("sample", info[:, 0].astype(int), {"long_name": "mesh periods averaged"}),
        },
        coords=coords,
    )


def _batch_setups(
    design: Design, samples: xr.Dataset, effects: Sequence[Effect], steps_per_mode: int, samples_per_period: int
) -> tuple[list[Any], np.ndarray]:
    """Model set-ups of the samples and each one's integration steps per mesh period."""
    setups: list[Any] = []
    step_counts: list[int] = []
    # in chunks, so that each run's step count is found while the model's
    # per-design stiffness cache still holds its design
    for start in range(0, samples.sizes["sample"], 256):
        chunk = build_batch(design, samples.isel(sample=slice(start, start + 256)), effects=effects)
        setups.extend(chunk)
        step_counts.extend(steps_per_period(s, steps_per_mode, multiple_of=samples_per_period) for s in chunk)
    return setups, np.array(step_counts, dtype=np.int64)


def _state_scales(setups: Sequence[Any]) -> np.ndarray:
    """Scale of each state variable (static mesh deflection and its velocity) per set-up."""
    n = len(setups)
    scales = np.empty((n, 6))
    for i, setup in enumerate(setups):
        length = abs(setup.derived["static_mesh_force"]) / (
            setup.derived["k_mean"] * setup.parameters[K.STIFFNESS_SCALE]
        )
        length = max(length, float(setup.parameters[K.STE_AMPLITUDE]), 1e-9)
        velocity = length * setup.derived["omega_n"]
        scales[i] = (length, length, length, velocity, velocity, velocity)
    return scales


# ---------------------------------------------------------------------------
# observed features
# ---------------------------------------------------------------------------


def line_noise_factor(size: int, window: str = "hann") -> float:
    """Std of a line amplitude from a weighted least-squares fit in white noise of unit std.

    Each quadrature coefficient has variance 2 sum(w^2) / (sum w)^2 for
    weights w (3/N for a Hann window); at high signal-to-noise ratio the
    amplitude has the same standard deviation.
    """
    weights = scipy.signal.get_window(window, size, fftbins=False)
    return math.sqrt(2.0 * np.sum(weights**2) / np.sum(weights) ** 2)


def observed_harmonics(
    rig: xr.Dataset, design: Design, *, channels: Sequence[str] = HARMONIC_CHANNELS, n_harmonics: int = 3
) -> xr.Dataset:
    """Mesh-harmonic amplitudes of rig data with their noise standard deviations, and their first sidebands.

    Returns
    -------
    xarray.Dataset
        Over (op, channel, harmonic): ``amplitude`` and ``amplitude_std``
        (sensor-noise std of the amplitude, from the record's own noise floor;
        a sideband's is the same); over (op, channel, harmonic, sideband):
        ``sideband_amplitude``, the shaft-order sidebands k z1 +- j (pinion)
        and k z1 +- j z1/z2 (gear), j = 1..3, read in the same line fit. NaN
        for channels absent, runs unusable or lines above the band.
    """
    present = [name for name in channels if name in rig.data_vars]
    if not present:
        raise CalibrationError(
            f"channels: none of {', '.join(channels)} is in the rig data (found {', '.join(map(str, rig.data_vars))})"
        )
    # sidebands stay in the joint line fit and out of the noise floor, should the rig have any
    features = extract_features(
        rig,
        design,
        channels=present,
        n_harmonics=n_harmonics,
        n_sidebands=min(3, design.z1 - 1),
        n_shaft_orders=0,
        n_motor_lines=0,
    )
    return harmonic_lines(features, rig.sizes["time"], n_harmonics)


def harmonic_lines(features: xr.Dataset, size: int, n_harmonics: int) -> xr.Dataset:
    """:func:`observed_harmonics` from the features of :func:`~uqgear.rig.features.extract_features` (records of
    ``size`` samples), with every sideband order they hold."""
    n_op = features.sizes["op"]
    names = [str(name) for name in features["feature"].values]
    labels = [name[len("mesh1_sb_") :] for name in names if name.startswith("mesh1_sb_")]
    amplitude = np.full((n_op, len(HARMONIC_CHANNELS), n_harmonics), np.nan)
    noise = np.full_like(amplitude, np.nan)
    sideband = np.full((n_op, len(HARMONIC_CHANNELS), n_harmonics, len(labels)), np.nan)
    factor = line_noise_factor(size)
    for index, name in enumerate(HARMONIC_CHANNELS):
        if name not in features.data_vars:
            continue
        values = features[name]
        amplitude[:, index, :] = (
            values.sel(feature=[f"mesh{k}" for k in range(1, n_harmonics + 1)]).transpose("op", "feature").values
        )
        noise[:, index, :] = (values.sel(feature="noise_std").values * factor)[:, None]
        for k in range(n_harmonics):
            row = [f"mesh{k + 1}_sb_{label}" for label in labels]
            sideband[:, index, k, :] = values.sel(feature=row).transpose("op", "feature").values
    return xr.Dataset(
        {
            "amplitude": (("op", "channel", "harmonic"), amplitude, {"long_name": "observed mesh-harmonic amplitude"}),
            "amplitude_std": (
                ("op", "channel", "harmonic"),
                noise,
                {"long_name": "sensor-noise standard deviation of the amplitude"},
            ),
            "sideband_amplitude": (
                ("op", "channel", "harmonic", "sideband"),
                sideband,
                {"long_name": "amplitude of the shaft-order sidebands of each mesh harmonic"},
            ),
        },
        coords={
            "channel": list(HARMONIC_CHANNELS),
            "harmonic": np.arange(1, n_harmonics + 1),
            "sideband": labels,
            "pinion_speed": ("op", features["pinion_speed"].values),
        },
    )
