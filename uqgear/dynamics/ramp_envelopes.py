"""Envelopes of run-ups and coast-downs over speed bins, their jumps, and the up/down hysteresis.

A gear pair with backlash has a softening nonlinearity: over a speed range
it can hold a large (impacting) and a small response at once, and a slow run
follows whichever branch it is on until that branch ends, then *jumps*. A
run-up then drops at a higher speed than a coast-down rises, and the range
between the two is where the response depends on the history.

* :func:`ramp_envelope` bins a run by its instantaneous pinion speed and keeps
  per bin the peak of a signal (``peak_mesh_force`` by default: the max over
  the bin) and, from the ``contact`` history (1 drive-side contact, 0 teeth
  apart, -1 back-side contact, as the physics codes it), the fractions of
  time apart and in back-side contact.
* :func:`jump_speeds` reads the jumps of a binned envelope: a relative step
  ``(b - a) / min(|a|, |b|)`` between neighbouring bins above ``threshold``
  (steps in the same sense in consecutive bins make one jump).
* :func:`up_down_envelopes` puts an up and a down run on the same bins, with
  dims ``(direction, pinion_speed)``, and marks where they differ by more
  than a tolerance; :func:`hysteresis_ranges` lists those speed ranges.

This module does no file I/O and no plotting.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr

from ..common.errors import UqgearError
from ._checks import check_positive
from .order_maps import speed_bin_coords, speed_bin_edges, speed_bin_index

#: Values of the ``direction`` dim of :func:`up_down_envelopes`.
RAMP_DIRECTIONS: tuple[str, ...] = ("up", "down")


class RampError(UqgearError):
    """A record is not the run-up or coast-down a ramp analysis needs.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.ramp_envelopes import RampError, ramp_envelope
    >>> ds = xr.Dataset({"pinion_speed": ("time", np.linspace(500, 900, 50))}, coords={"time": np.arange(50.0)})
    >>> try:
    ...     ramp_envelope(ds)
    ... except RampError as error:
    ...     print(error)
    ramp_envelope: the Dataset has no variable 'mesh_force'; it has pinion_speed
    """


def _speed(ds: xr.Dataset, what: str) -> np.ndarray:
    """Instantaneous pinion speed (rpm) per sample: ``pinion_speed``, else the derivative of ``pinion_angle``."""
    if "pinion_speed" in ds.variables and ds["pinion_speed"].dims == ("time",):
        return np.asarray(ds["pinion_speed"].values, dtype=float)
    if "pinion_angle" in ds.variables and ds["pinion_angle"].dims == ("time",) and "time" in ds.coords:
        time = np.asarray(ds["time"].values, dtype=float)
        return np.gradient(np.asarray(ds["pinion_angle"].values, dtype=float), time) * (60.0 / (2.0 * np.pi))
    raise RampError(f"{what}: the Dataset has neither 'pinion_speed' (rpm) nor 'pinion_angle' (rad) over 'time'")


def _binned_max(values: np.ndarray, index: np.ndarray, count: int) -> np.ndarray:
    peak = np.full(count, -np.inf)
    inside = index >= 0
    np.maximum.at(peak, index[inside], values[inside])
    peak[np.isneginf(peak)] = np.nan
    return peak


def _binned_mean(values: np.ndarray, index: np.ndarray, count: int) -> np.ndarray:
    inside = index >= 0
    samples = np.bincount(index[inside], minlength=count)
    total = np.bincount(index[inside], weights=values[inside], minlength=count)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(samples > 0, total / np.maximum(samples, 1), np.nan)


def ramp_envelope(ds: xr.Dataset, *, speed_bins: Any = 20, signal: str = "mesh_force") -> xr.Dataset:
    """Peak of a signal and contact fractions per speed bin of a run-up or coast-down.

    Parameters
    ----------
    ds : xarray.Dataset
        A run over ``time`` with ``pinion_speed`` (rpm) or ``pinion_angle``
        (rad), the signal, and optionally ``contact``.
    speed_bins : int or sequence of float
        Number of equal bins over the run's speed range, or bin edges (rpm);
        a bin holds the speeds from its lower edge up to, not including, its
        upper edge (the last bin includes its upper edge too).
    signal : str
        Signal whose per-bin maximum is kept, as ``peak_<signal>``.

    Returns
    -------
    xarray.Dataset
        ``peak_<signal>`` (the signal's units; NaN in an empty bin) and
        ``sample_count`` over ``pinion_speed`` (bin centres, rpm, with
        ``bin_lower`` and ``bin_upper``); with a ``contact`` history also
        ``fraction_separation`` (``contact == 0``) and
        ``fraction_back_contact`` (``contact == -1``). Attr ``direction``:
        ``"up"`` when the speed rises over the run, else ``"down"``.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.ramp_envelopes import ramp_envelope
    >>> time = np.linspace(0.0, 1.0, 1001)
    >>> speed = 1000.0 + 1000.0 * time
    >>> ds = xr.Dataset({"pinion_speed": ("time", speed), "mesh_force": ("time", 10.0 * speed, {"units": "N"})},
    ...                 coords={"time": time})
    >>> envelope = ramp_envelope(ds, speed_bins=[1000.0, 1500.0, 2000.0])
    >>> envelope["peak_mesh_force"].values.tolist(), envelope.attrs["direction"]
    ([14990.0, 20000.0], 'up')
    """
    if not isinstance(ds, xr.Dataset):
        raise RampError(f"ramp_envelope: expected an xarray Dataset; got {type(ds).__name__}")
    if signal not in ds.data_vars:
        raise RampError(
            f"ramp_envelope: the Dataset has no variable {signal!r}; it has {', '.join(map(str, ds.data_vars))}"
        )
    if ds[signal].dims != ("time",):
        raise RampError(f"{signal}: expected a history over 'time'; it has dims {ds[signal].dims}")
    speed = _speed(ds, "ramp_envelope")
    values = np.asarray(ds[signal].values, dtype=float)
    if not (np.all(np.isfinite(speed)) and np.all(np.isfinite(values))):
        raise RampError(f"ramp_envelope: {signal!r} and the pinion speed should be finite; got NaN or infinity")
    edges = speed_bin_edges(speed, speed_bins)
    index = speed_bin_index(speed, edges)
    count = edges.size - 1
    name = f"peak_{signal}"
    data: dict[str, Any] = {
        name: (
            "pinion_speed",
            _binned_max(values, index, count),
            {"units": str(ds[signal].attrs.get("units", "")), "long_name": f"peak of {signal} in the speed bin"},
        ),
        "sample_count": (
            "pinion_speed",
            np.bincount(index[index >= 0], minlength=count),
            {"units": "1", "long_name": "samples in the speed bin"},
        ),
    }
    if "contact" in ds.variables and ds["contact"].dims == ("time",):
        contact = np.asarray(ds["contact"].values)
        for key, state, text in (
            ("fraction_separation", 0, "teeth apart"),
            ("fraction_back_contact", -1, "in back-side contact"),
        ):
            data[key] = (
                "pinion_speed",
                _binned_mean((contact == state).astype(float), index, count),
                {"units": "1", "long_name": f"fraction of time {text}"},
            )
    direction = "up" if speed[-1] >= speed[0] else "down"
    attrs = {"direction": direction, "signal": signal}
    return xr.Dataset(data, coords=speed_bin_coords(edges), attrs=attrs)


@dataclass(frozen=True)
class Jump:
    """An abrupt change of a binned run envelope.

    Attributes
    ----------
    speed : float
        Pinion speed (rpm) between the two bins it falls between.
    size : float
        Change in the envelope's units, in the run's own sense of travel
        (for a coast-down, the value below minus the value above).
    relative_size : float
        ``size / min(|a|, |b|)`` of the two bin values.
    direction : str
        ``"rise"`` or ``"drop"``, in the run's sense of travel: a run-up
        drops off the large branch (a jump-down), a coast-down rises onto it
        (a jump-up).

    Examples
    --------
    >>> from uqgear.dynamics.ramp_envelopes import Jump
    >>> jump = Jump(speed=2200.0, size=-32e3, relative_size=-0.84, direction="drop")
    >>> jump.direction, jump.speed
    ('drop', 2200.0)
    """

    speed: float
    size: float
    relative_size: float
    direction: str


def _holds(values: np.ndarray, before: int, after: int, width: int, threshold: float, sense: float) -> bool:
    """Whether ``width`` bins up to ``before`` and from ``after`` lie apart, in the step's sense, with medians that
    differ by the threshold."""
    ahead = values[max(before - width + 1, 0) : before + 1]
    behind = values[after : after + width]
    low, high = float(np.median(ahead)), float(np.median(behind))
    base = min(abs(low), abs(high))
    change = high - low
    apart = behind.min() > ahead.max() if sense > 0 else behind.max() < ahead.min()
    return bool(apart and np.sign(change) == np.sign(sense) and (base == 0.0 or abs(change) / base > threshold))


def jump_speeds(
    envelope: xr.Dataset, variable: str | None = None, *, threshold: float = 0.25, persistence: int = 1
) -> tuple[Jump, ...]:
    """Speeds where a binned envelope jumps: relative steps above ``threshold`` between neighbouring bins.

    Empty bins (NaN) are skipped: the step is then taken between the nearest
    filled bins. Consecutive steps in the same sense above the threshold are
    one jump, placed at the largest of them, with their total size.

    Parameters
    ----------
    envelope : xarray.Dataset
        A :func:`ramp_envelope` result, or one ``direction`` selected from
        :func:`up_down_envelopes` (``both.sel(direction="down")``).
    variable : str, optional
        The envelope variable; by default ``peak_<signal>`` of the envelope.
    threshold : float
        Smallest relative step ``|b - a| / min(|a|, |b|)`` that is a jump
        (0.25: the high side at least 1.25 times the low).
    persistence : int
        Bins on each side that must lie apart (every bin after the step
        beyond every bin before it, in the step's sense) with medians that
        differ by the threshold too: a jump leads to a level that holds,
        where a scattered response (chaotic, or bins holding a few mesh
        periods) steps back and forth. 1 takes the bins next to the step
        alone.

    Returns
    -------
    tuple of Jump
        In the run's order of travel.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.ramp_envelopes import jump_speeds
    >>> envelope = xr.Dataset({"peak_mesh_force": ("pinion_speed", [50.0, 52.0, 90.0, 91.0])},
    ...                       coords={"pinion_speed": [1000.0, 1100.0, 1200.0, 1300.0]},
    ...                       attrs={"direction": "down", "signal": "mesh_force"})
    >>> jump_speeds(envelope)
    (Jump(speed=1150.0, size=-38.0, relative_size=-0.7307692307692307, direction='drop'),)
    """
    threshold = check_positive("threshold", threshold)
    if isinstance(persistence, bool) or not isinstance(persistence, (int, np.integer)) or persistence < 1:
        raise RampError(f"persistence: expected an integer >= 1 (bins); got {persistence!r}")
    name = variable if variable is not None else f"peak_{envelope.attrs.get('signal', 'mesh_force')}"
    if not isinstance(envelope, xr.Dataset) or name not in envelope.data_vars:
        raise RampError(f"variable: expected an envelope Dataset holding {name!r}")
    if envelope[name].dims != ("pinion_speed",):
        raise RampError(f"{name}: expected values over 'pinion_speed' only; it has dims {envelope[name].dims}")
    speeds = np.asarray(envelope["pinion_speed"].values, dtype=float)
    values = np.asarray(envelope[name].values, dtype=float)
    filled = np.isfinite(values)
    speeds, values = speeds[filled], values[filled]
    # the run's sense of travel: the envelope's attr, or the direction selected from up_down_envelopes()
    direction = envelope.attrs.get("direction")
    if "direction" in envelope.coords and envelope["direction"].ndim == 0:
        direction = str(envelope["direction"].values)
    if direction == "down":
        speeds, values = speeds[::-1], values[::-1]
    steps: list[tuple[int, float, float]] = []  # (index of the step, size, relative size)
    for i in range(values.size - 1):
        low = min(abs(values[i]), abs(values[i + 1]))
        change = values[i + 1] - values[i]
        relative = change / low if low > 0.0 else np.copysign(np.inf, change)
        if abs(relative) > threshold:
            steps.append((i, change, relative))
    jumps: list[Jump] = []
    group: list[tuple[int, float, float]] = []
    for step in [*steps, None]:
        if group and (step is None or step[0] != group[-1][0] + 1 or np.sign(step[1]) != np.sign(group[-1][1])):
            i, _, _ = max(group, key=lambda item: abs(item[1]))
            if not _holds(values, group[0][0], group[-1][0] + 1, persistence, threshold, group[0][1]):
                group = [] if step is None else [step]
                continue
            size = float(values[group[-1][0] + 1] - values[group[0][0]])
            low = min(abs(values[group[0][0]]), abs(values[group[-1][0] + 1]))
            jumps.append(
                Jump(
                    float(0.5 * (speeds[i] + speeds[i + 1])),
                    size,
                    float(size / low) if low > 0.0 else float(np.copysign(np.inf, size)),
                    "rise" if size > 0.0 else "drop",
                )
            )
            group = []
        if step is not None:
            group.append(step)
    return tuple(jumps)


def up_down_envelopes(
    up: xr.Dataset, down: xr.Dataset, *, speed_bins: Any = 20, signal: str = "mesh_force", tolerance: float = 0.1
) -> xr.Dataset:
    """Envelopes of a run-up and a coast-down on the same speed bins, and where they differ.

    Parameters
    ----------
    up, down : xarray.Dataset
        The run-up (speed rising) and the coast-down (speed falling), as for
        :func:`ramp_envelope`.
    speed_bins : int or sequence of float
        Number of equal bins over the speeds both runs cover, or edges (rpm).
    signal : str
        As in :func:`ramp_envelope`.
    tolerance : float
        Relative difference ``|up - down| / max(|up|, |down|)`` of the peak
        above which a bin is in the hysteresis.

    Returns
    -------
    xarray.Dataset
        The :func:`ramp_envelope` variables over dims ``(direction,
        pinion_speed)``, ``direction = ["up", "down"]``; ``hysteresis``
        (bool over ``pinion_speed``) marks the bins where the peaks differ by
        more than ``tolerance``; attr ``hysteresis_ranges``: the flat list
        ``[low_1, high_1, low_2, ...]`` (rpm) of :func:`hysteresis_ranges`.

    Examples
    --------
    >>> import numpy as np, xarray as xr
    >>> from uqgear.dynamics.ramp_envelopes import hysteresis_ranges, up_down_envelopes
    >>> time = np.linspace(0.0, 1.0, 2001)
    >>> def run(speed, high_below):
    ...     force = np.where(speed < high_below, 2.0, 1.0)
    ...     return xr.Dataset({"pinion_speed": ("time", speed), "mesh_force": ("time", force)},
    ...                       coords={"time": time})
    >>> both = up_down_envelopes(run(1000 + 1000 * time, 1700.0), run(2000 - 1000 * time, 1300.0),
    ...                          speed_bins=10)
    >>> both["peak_mesh_force"].dims, hysteresis_ranges(both)
    (('direction', 'pinion_speed'), ((1300.0, 1700.0),))
    """
    tolerance = check_positive("tolerance", tolerance)
    for name, run, sense in (("up", up, 1.0), ("down", down, -1.0)):
        speed = _speed(run, f"up_down_envelopes ({name})") if isinstance(run, xr.Dataset) else None
        if speed is None or sense * (speed[-1] - speed[0]) <= 0.0:
            raise RampError(f"{name}: expected a run whose pinion speed {'rises' if sense > 0 else 'falls'} over time")
    if isinstance(speed_bins, (int, np.integer)):
        up_speed, down_speed = _speed(up, "up"), _speed(down, "down")
        low = max(float(up_speed.min()), float(down_speed.min()))
        high = min(float(up_speed.max()), float(down_speed.max()))
        if not high > low:
            raise RampError("down: the coast-down covers no speed of the run-up")
        speed_bins = np.linspace(low, high, int(speed_bins) + 1)
    envelopes = [ramp_envelope(run, speed_bins=speed_bins, signal=signal) for run in (up, down)]
    combined = xr.concat(envelopes, dim=xr.Variable("direction", list(RAMP_DIRECTIONS)), combine_attrs="drop")
    peak = combined[f"peak_{signal}"]
    scale = np.maximum(abs(peak.sel(direction="up")), abs(peak.sel(direction="down")))
    difference = abs(peak.sel(direction="up") - peak.sel(direction="down"))
    combined["hysteresis"] = (difference > tolerance * scale).fillna(False).astype(bool)
    combined["hysteresis"].attrs = {"long_name": f"up and down peaks differ by more than {tolerance:g} of the larger"}
    combined.attrs = {"signal": signal, "tolerance": tolerance}
    combined.attrs["hysteresis_ranges"] = [value for pair in hysteresis_ranges(combined) for value in pair]
    return combined


def hysteresis_ranges(combined: xr.Dataset) -> tuple[tuple[float, float], ...]:
    """Speed ranges (rpm, bin edges) of consecutive bins marked ``hysteresis`` by :func:`up_down_envelopes`.

    Examples
    --------
    >>> import xarray as xr
    >>> from uqgear.dynamics.ramp_envelopes import hysteresis_ranges
    >>> marks = xr.Dataset({"hysteresis": ("pinion_speed", [False, True, True, False])},
    ...                    coords={"bin_lower": ("pinion_speed", [0.0, 1.0, 2.0, 3.0]),
    ...                            "bin_upper": ("pinion_speed", [1.0, 2.0, 3.0, 4.0])})
    >>> hysteresis_ranges(marks)
    ((1.0, 3.0),)
    """
    if not isinstance(combined, xr.Dataset) or "hysteresis" not in combined.data_vars:
        raise RampError("hysteresis: expected an up_down_envelopes() result holding 'hysteresis'")
    marked = np.asarray(combined["hysteresis"].values, dtype=bool)
    lower = np.asarray(combined["bin_lower"].values, dtype=float)
    upper = np.asarray(combined["bin_upper"].values, dtype=float)
    ranges: list[tuple[float, float]] = []
    start = None
    for i, mark in enumerate([*marked, False]):
        if mark and start is None:
            start = i
        elif not mark and start is not None:
            ranges.append((float(lower[start]), float(upper[i - 1])))
            start = None
    return tuple(ranges)
