"""Amplitude spectra of simulated responses, against frequency or order."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import numpy as np
import scipy.signal
import xarray as xr

from ..common.errors import UqgearError
from ._checks import check_positive, require_number_attr, require_variables


def _as_signal(signal: Any, dim: str) -> tuple[xr.DataArray, str, Any]:
    """The signal as a DataArray along ``dim``, with its units and name ("" and None for an array)."""
    if isinstance(signal, xr.DataArray):
        data_array = signal if signal.ndim != 1 else signal.rename({signal.dims[0]: dim})
        if dim not in data_array.dims:
            raise UqgearError(f"signal: expected a DataArray with dim {dim!r}; it has {signal.dims}")
        units = str(signal.attrs.get("units", ""))
        name = signal.name
    else:
        values = np.asarray(signal, dtype=float)
        if values.ndim != 1:
            raise UqgearError(
                f"signal: expected a 1-D array (or a DataArray with dim {dim!r}); got an array of shape {values.shape}"
            )
        data_array = xr.DataArray(values, dims=[dim])
        units, name = "", None
    return data_array, units, name


def amplitude_spectrum(
    signal: Any,
    sample_rate: float,
    *,
    against: Literal["frequency", "order"] = "frequency",
    shaft_speed_rpm: float | None = None,
    window: str = "hann",
    remove_mean: bool = True,
    dim: str = "time",
) -> xr.DataArray:
    """Single-sided amplitude spectrum, amplitude-correct for lines on a bin.

    The window's coherent gain is divided out, so a sine of amplitude ``A``
    whose frequency falls on a bin (an integer number of its periods in the
    record, as for mesh harmonics in a record of whole mesh periods) gives a
    peak of exactly ``A``. Off-bin lines lose up to the window's scalloping
    loss (1.42 dB for Hann; use ``window="flattop"`` for accurate amplitudes
    of lines between bins).

    Parameters
    ----------
    signal : array_like or xarray.DataArray
        1-D samples, or a DataArray transformed along ``dim``. A DataArray's
        ``units`` become the spectrum's units.
    sample_rate : float
        Samples per second, Hz.
    against : {"frequency", "order"}
        Axis of the result: frequency in Hz, or order (multiples of the shaft
        rotation frequency ``shaft_speed_rpm / 60``; the mesh order of the
        pinion is z1).
    shaft_speed_rpm : float, optional
        Shaft speed in rpm; required for ``against="order"``.
    window : str
        A window name of :func:`scipy.signal.get_window` (periodic form).
    remove_mean : bool
        Subtract the mean first, so the window does not leak the DC level
        into the lowest bins; the 0 Hz amplitude is then 0.
    dim : str
        Dim transformed when ``signal`` is a multi-dim DataArray.

    Returns
    -------
    xarray.DataArray
        ``amplitude`` with dim ``frequency`` (Hz) or ``order`` (with a
        ``frequency`` coord alongside).
    """
    sample_rate = check_positive("sample_rate", sample_rate)
    if against not in ("frequency", "order"):
        raise UqgearError(f"against: expected 'frequency' or 'order'; got {against!r}")
    if against == "order":
        if shaft_speed_rpm is None:
            raise UqgearError("shaft_speed_rpm: required for a spectrum against order; got None")
        shaft_speed_rpm = check_positive("shaft_speed_rpm", shaft_speed_rpm)
    data_array, units, name = _as_signal(signal, dim)
    n_samples = data_array.sizes[dim]
    if n_samples < 2:
        raise UqgearError(f"signal: expected at least 2 samples along {dim!r}; got {n_samples}")
    values = data_array.transpose(..., dim).values.astype(float)
    if not np.all(np.isfinite(values)):
        raise UqgearError("signal: expected finite values; got NaN or infinity")
    try:
        taper = scipy.signal.get_window(window, n_samples, fftbins=True)
    except (ValueError, TypeError) as error:
        raise UqgearError(
            f"window: expected a window name of scipy.signal.get_window "
            f"(hann, hamming, flattop, boxcar, ...); got {window!r} ({error})"
        ) from None
    if remove_mean:
        values = values - values.mean(axis=-1, keepdims=True)
    transform = np.fft.rfft(values * taper, axis=-1)
    amplitude = np.abs(transform) / np.sum(taper)
    # Single-sided: every bin but DC (and Nyquist for even lengths) carries
    # the energy of its negative-frequency twin.
    last = amplitude.shape[-1] if n_samples % 2 else amplitude.shape[-1] - 1
    amplitude[..., 1:last] *= 2.0
    frequency = np.fft.rfftfreq(n_samples, d=1.0 / sample_rate)
    other_dims = [d for d in data_array.transpose(..., dim).dims if d != dim]
    coords = {name_: coord for name_, coord in data_array.coords.items() if dim not in coord.dims}
    attrs = {
        "units": units,
        "long_name": "single-sided amplitude spectrum" + (f" of {name}" if name else ""),
        "window": window,
        "sample_rate": sample_rate,
        "mean_removed": int(bool(remove_mean)),
    }
    frequency_coord = xr.Variable("frequency", frequency, {"units": "Hz", "long_name": "frequency"})
    result = xr.DataArray(
        amplitude,
        dims=[*other_dims, "frequency"],
        coords={**coords, "frequency": frequency_coord},
        attrs=attrs,
        name="amplitude",
    )
    if against == "order":
        assert shaft_speed_rpm is not None  # checked above for a spectrum against order
        shaft_frequency = shaft_speed_rpm / 60.0
        order = xr.Variable(
            "frequency",
            frequency / shaft_frequency,
            {"units": "1", "long_name": "order (multiples of the shaft rotation frequency)"},
        )
        result = result.assign_coords(order=order).swap_dims({"frequency": "order"})
        result.attrs["shaft_speed_rpm"] = shaft_speed_rpm
    return result


def uniform_time_step(ds: xr.Dataset, what: str) -> float:
    """The sampling interval (s) of a record's ``time`` coordinate, which must be uniform.

    Refuses, naming ``what``, a record without ``time``, with fewer than 2 samples, or whose steps differ
    by more than 1e-6 of their mean.
    """
    if "time" not in ds.coords:
        raise UqgearError(f"{what}: the Dataset has no 'time' coordinate")
    time = np.asarray(ds["time"].values, dtype=float)
    if time.size < 2:
        raise UqgearError(f"{what}: expected at least 2 time samples; got {time.size}")
    steps = np.diff(time)
    step = float(np.mean(steps))
    if step <= 0.0 or np.max(np.abs(steps - step)) > 1e-6 * step:
        raise UqgearError(f"{what}: expected a uniformly increasing 'time' coordinate")
    return step


def spectrum_dataset(
    ds: xr.Dataset,
    variable: str | Sequence[str] = "x",
    *,
    against: Literal["frequency", "order"] = "frequency",
    window: str = "hann",
    remove_mean: bool = True,
) -> xr.Dataset:
    """Amplitude spectra of variables of a :func:`~uqgear.physics.integration.simulate` run.

    The sample rate comes from the ``time`` coord, the shaft speed for orders
    from attrs ``pinion_speed`` (so the mesh order is ``z1``).

    Parameters
    ----------
    ds : xarray.Dataset
        A simulate() result.
    variable : str or sequence of str
        Time-history variables to transform (``x``, ``y1_acceleration``, ...).
    against, window, remove_mean
        As in :func:`amplitude_spectrum`.

    Returns
    -------
    xarray.Dataset
        One amplitude spectrum per variable, same names, dim ``frequency`` or
        ``order``; attrs ``pinion_speed``, ``mesh_frequency`` (Hz) and
        ``mesh_order`` (z1) when the run gives them.

    Examples
    --------
    A period-1 response holds the mesh order (z1 = 21 per pinion
    revolution) and its harmonics, and nothing at half the mesh order:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> run = uqgear.simulate(design, 2000.0, 7000.0, 33e3, n_periods=200, keep_periods=100)
    >>> spectrum = uqgear.spectrum_dataset(run, "x", against="order")
    >>> spectrum.attrs["mesh_order"], round(spectrum.attrs["mesh_frequency"], 6)
    (21, 700.0)
    >>> amplitude_um = spectrum["x"].sel(order=[10.5, 21, 42], method="nearest") * 1e6
    >>> amplitude_um.round(1).values
    array([ 0. ,  7.3, 11.1])
    """
    names = [variable] if isinstance(variable, str) else list(variable)
    if not names:
        raise UqgearError("variable: expected at least one variable name; got none")
    require_variables(ds, names, "spectrum_dataset")
    for name in names:
        if "time" not in ds[name].dims:
            raise UqgearError(
                f"spectrum_dataset: variable {name!r} has no 'time' dim (dims {ds[name].dims}); expected a time history"
            )
    sample_rate = 1.0 / uniform_time_step(ds, "spectrum_dataset")
    shaft_speed = None
    if against == "order":
        shaft_speed = require_number_attr(ds, "pinion_speed", "spectrum_dataset")
    spectra = {
        name: amplitude_spectrum(
            ds[name], sample_rate, against=against, shaft_speed_rpm=shaft_speed, window=window, remove_mean=remove_mean
        ).rename(name)
        for name in names
    }
    attrs = {key: ds.attrs[key] for key in ("pinion_speed", "mesh_frequency") if key in ds.attrs}
    if "z1" in ds.attrs:
        attrs["mesh_order"] = ds.attrs["z1"]
    attrs.update({"window": window, "sample_rate": sample_rate})
    return xr.Dataset(spectra, attrs=attrs)
