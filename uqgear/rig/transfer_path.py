"""A transfer-path resonance between the gear and a sensor, applied to one channel of a rig campaign.

Real rigs carry structure the gear model lacks: a housing resonance on the
path from a bearing to its accelerometer, the accelerometer's own mounted
resonance. :func:`apply_transfer_path` filters one channel of a
``uqgear-rig/1`` campaign (a file of ``data/rig/`` or a virtual rig's output)
through a second-order resonance, to test what the diagnosis makes of such a
path (``uqgear diagnose --reference``, :mod:`uqgear.diagnosis.allowances.reference`).

Two shapes, both of unity gain at DC and at frequencies well below the
resonance f0 (damping ratio zeta, w0 = 2 pi f0):

* ``gain=None``: the response of a base-excited single-degree-of-freedom
  sensor, ``H(s) = w0^2 / (s^2 + 2 zeta w0 s + w0^2)``; peak gain
  ``1 / (2 zeta sqrt(1 - zeta^2))`` just below f0, exactly ``1 / (2 zeta)``
  at f0, falling as (f0/f)^2 above.
* ``gain=g``: a resonance of peak gain g at f0 that leaves the signal
  unchanged far from it on both sides (a housing mode in parallel with the
  direct path), ``H(s) = (s^2 + 2 g zeta w0 s + w0^2) / (s^2 + 2 zeta w0 s + w0^2)``;
  its half-power bandwidth is about ``2 zeta f0``.

The filter is digital: the bilinear transform with prewarping at f0, so
that the gain at f0 is exactly the analogue one; elsewhere the digital gain
is the analogue gain at the warped frequency ``(fs / pi) tan(pi f / fs)``
(:func:`transfer_path_gain` gives it exactly). It is causal (not
zero-phase); each record is run in from an odd reflection of its start, so
the filter's own transient does not show in the record.
"""

from __future__ import annotations

import json
import math

import numpy as np
import scipy.signal
import xarray as xr

from ..common.errors import RigDataError
from .sampling import SIGNAL_CHANNELS, sampling_rate

#: Attribute of a filtered channel: JSON list of the transfer paths applied to it, in order.
TRANSFER_PATH_ATTRIBUTE = "transfer_path"

# Run-in before each record, in time constants 1/(zeta w0) of the resonance's decay: the
# start transient falls by e^-12 (6e-6) before the record begins.
_RUN_IN_TIME_CONSTANTS = 12.0


def _check_positive(name: str, value: object) -> float:
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float, np.integer, np.floating))
        or not math.isfinite(float(value))
        or float(value) <= 0.0
    ):
        raise RigDataError(f"transfer path: {name}: expected a positive finite number; got {value!r}")
    return float(value)


def _analogue(frequency: float, damping: float, gain: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator of H(s) (highest power first), w0 in rad/s."""
    w0 = 2.0 * math.pi * frequency
    denominator = np.array([1.0, 2.0 * damping * w0, w0**2])
    if gain is None:
        return np.array([w0**2]), denominator
    return np.array([1.0, 2.0 * gain * damping * w0, w0**2]), denominator


def transfer_path_coefficients(
    frequency: float, damping: float, fs: float, gain: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Digital filter (b, a) of the resonance: bilinear transform prewarped at ``frequency``.

    Parameters
    ----------
    frequency : float
        Resonance frequency f0, Hz, below fs/2.
    damping : float
        Damping ratio zeta, in (0, 1).
    fs : float
        Sampling rate, Hz.
    gain : float, optional
        Peak gain at f0 of the resonance that is unity on both sides; None:
        the base-excited sensor response (module docstring).

    Returns
    -------
    (b, a) : tuple of ndarray
        As for :func:`scipy.signal.lfilter`.
    """
    # prewarping: the analogue resonance placed at the frequency that the bilinear map sends to f0
    warped = fs / math.pi * math.tan(math.pi * frequency / fs)
    numerator, denominator = _analogue(warped, damping, gain)
    return scipy.signal.bilinear(numerator, denominator, fs)


def transfer_path_gain(
    frequencies: np.ndarray, frequency: float, damping: float, fs: float | None = None, gain: float | None = None
) -> np.ndarray:
    """Gain ``|H|`` of the resonance at ``frequencies`` (Hz), analogue or (with ``fs``) the digital filter's.

    The digital filter's gain at f is the analogue one (resonance prewarped)
    at the warped frequency ``(fs / pi) tan(pi f / fs)``.
    """
    f = np.asarray(frequencies, dtype=float)
    f0 = frequency
    if fs is not None:
        f0 = fs / math.pi * math.tan(math.pi * frequency / fs)
        f = fs / math.pi * np.tan(np.pi * np.clip(f, 0.0, 0.5 * fs * (1 - 1e-12)) / fs)
    r = f / f0
    denominator = np.sqrt((1.0 - r**2) ** 2 + (2.0 * damping * r) ** 2)
    if gain is None:
        return 1.0 / denominator
    return np.sqrt((1.0 - r**2) ** 2 + (2.0 * gain * damping * r) ** 2) / denominator


def apply_transfer_path(
    campaign: xr.Dataset, channel: str, frequency: float, damping: float, gain: float | None = None
) -> xr.Dataset:
    """Filter one channel of a rig campaign through a second-order transfer-path resonance.

    Parameters
    ----------
    campaign : xarray.Dataset
        A ``uqgear-rig/1`` campaign (:func:`uqgear.rig.read_rig`, a virtual
        rig's output); not modified.
    channel : str
        The signal to filter: ``te``, ``acc_pinion`` or ``acc_gear``; its
        steady records along ``time`` and its run-up and coast-down records
        (``ramp_<channel>``) along ``ramp_time``, whichever the campaign holds.
    frequency : float
        Resonance frequency f0, Hz, below the Nyquist frequency.
    damping : float
        Damping ratio zeta, in (0, 1).
    gain : float, optional
        Peak gain at f0 of a resonance that is unity far from f0 on both
        sides; default: the base-excited sensor response, unity below f0 and
        peak gain about ``1 / (2 zeta)`` (module docstring).

    Returns
    -------
    xarray.Dataset
        A copy with the channel filtered (its dtype kept; a run with a
        missing sample stays missing), the filter recorded in the channel's
        ``transfer_path`` attribute (a JSON list, one entry per filter
        applied) and in the global ``history``. A ``noise_std`` attribute of
        the channel is dropped: the path colours the sensor noise too.

    Raises
    ------
    RigDataError
        The channel is not a signal of the campaign, the campaign has no
        uniform time grid, or a filter parameter is out of range.
    """
    if not isinstance(campaign, xr.Dataset):
        raise RigDataError(f"transfer path: expected a rig campaign Dataset; got {type(campaign).__name__}")
    # the channel's steady records on time and its ramp records on ramp_time: one sensor, one path
    targets = [
        (name, dim)
        for name, dim in ((channel, "time"), (f"ramp_{channel}", "ramp_time"))
        if channel in SIGNAL_CHANNELS and name in campaign.data_vars
    ]
    if not targets:
        present = [name for name in SIGNAL_CHANNELS if {name, f"ramp_{name}"} & set(campaign.data_vars)]
        raise RigDataError(
            f"transfer path: channel {channel!r}: expected a signal of the campaign, one of "
            f"{', '.join(present) or 'none (the campaign has no signal)'}"
        )
    frequency = _check_positive("frequency", frequency)
    damping = _check_positive("damping", damping)
    if damping >= 1.0:
        raise RigDataError(f"transfer path: damping: expected a damping ratio below 1; got {damping:g}")
    if gain is not None:
        gain = _check_positive("gain", gain)
    out = campaign.copy()
    peak = math.nan
    for name, dim in targets:
        if dim not in campaign.coords:
            raise RigDataError(f"transfer path: the campaign has no {dim} coordinate")
        fs = sampling_rate(np.asarray(campaign[dim].values, dtype=float), where=f"transfer path: {dim}")
        if frequency >= 0.5 * fs:
            raise RigDataError(
                f"transfer path: frequency: expected below the Nyquist frequency {0.5 * fs:g} Hz; got {frequency:g}"
            )
        out[name], peak = _filtered(campaign[name], dim, frequency, damping, fs, gain)
    note = (
        f"{channel} filtered through a transfer-path resonance at {frequency:g} Hz, damping {damping:g}, "
        f"peak gain {peak:.3g} (uqgear.rig.apply_transfer_path)"
    )
    history = str(out.attrs.get("history", "")).strip()
    out.attrs["history"] = f"{history}; {note}" if history else note
    return out


def _filtered(
    signal: xr.DataArray, dim: str, frequency: float, damping: float, fs: float, gain: float | None
) -> tuple[xr.DataArray, float]:
    """One variable's records along ``dim`` through the resonance, with its attributes; and the peak gain."""
    b, a = transfer_path_coefficients(frequency, damping, fs, gain)
    values = np.asarray(signal.transpose(..., dim).values, dtype=float)
    flat = values.reshape(-1, values.shape[-1])
    run_in = min(flat.shape[1] - 1, int(math.ceil(_RUN_IN_TIME_CONSTANTS * fs / (2 * math.pi * frequency * damping))))
    filtered = np.full_like(flat, np.nan)
    for row, record in enumerate(flat):
        if np.isnan(record).any():
            continue
        # odd reflection about the first sample: continuous in value and slope, a steady-looking run-in
        head = 2.0 * record[0] - record[run_in:0:-1]
        filtered[row] = scipy.signal.lfilter(b, a, np.concatenate([head, record]))[run_in:]
    attrs = dict(signal.attrs)
    attrs.pop("noise_std", None)
    peak = float(transfer_path_gain(np.array([frequency]), frequency, damping, fs, gain)[0])
    entry = {
        "kind": "sensor" if gain is None else "resonance",
        "frequency": frequency,
        "damping": damping,
        "peak_gain": peak,
        "discretisation": "bilinear, prewarped at the resonance",
        "fs": fs,
    }
    previous = json.loads(attrs[TRANSFER_PATH_ATTRIBUTE]) if TRANSFER_PATH_ATTRIBUTE in attrs else []
    attrs[TRANSFER_PATH_ATTRIBUTE] = json.dumps(previous + [entry])
    result = xr.DataArray(
        filtered.reshape(values.shape).astype(signal.dtype, copy=False),
        dims=signal.transpose(..., dim).dims,
        coords=signal.transpose(..., dim).coords,
        attrs=attrs,
    ).transpose(*signal.dims)
    return result, peak
