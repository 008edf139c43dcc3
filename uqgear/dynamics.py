"""Nonlinear-dynamics analysis of simulated gear responses.

Pure numerics on the Datasets of :func:`uqgear.integration.simulate` and
:func:`uqgear.integration.simulate_batch` (model.md section 5): Poincare
sections, periodicity detection, the Gottwald-Melbourne 0-1 test for chaos,
response classification (period-n, quasi-periodic, chaotic) with its evidence,
amplitude spectra against frequency and order, contact-state fractions, the
scalar response quantities of interest, and bifurcation sweeps.

Classification (all thresholds are parameters of :func:`classify_response`):

* **periodic**: the Poincare sequence repeats with period ``n`` (smallest
  ``n`` up to ``max_period``; by default a quarter of the kept periods, so
  that a period is seen at least four times) when every point agrees with
  the point ``n`` mesh periods later to within ``rtol`` times the scale of
  its component (default ``rtol = 1e-3``; :func:`classify_dataset` and
  :func:`classify_batch` take the scale from the peak-to-peak of the DTE,
  velocities scaled by the mesh angular frequency, so the tolerance is 0.1 %
  of the orbit size). Long periods do occur in the gear model (a stable
  period-10 orbit near 3250 rpm at light load), which is why the search does
  not stop at 8;
* otherwise, when a largest Lyapunov exponent is known, **chaotic** if it
  exceeds ``lyapunov_threshold`` (0.01 per mesh period, above what a
  finite-time Benettin estimate of a zero exponent over a few hundred periods
  reaches) and **quasi-periodic** if not: the exponent is the firmer evidence;
* without an exponent, **chaotic** if the median 0-1 test statistic ``K``
  exceeds ``k_threshold`` (0.5, midway between the regular limit 0 and the
  chaotic limit 1), else **quasi-periodic** (bounded, non-repeating, the
  Poincare points on a closed curve).

The 0-1 test works on the Poincare sequence of ``x`` (one value per mesh
period), never on the densely sampled time history, whose oversampling would
bias ``K``. Its ``K`` converges slowly for quasi-periodic responses: with 200
Poincare points, quasi-periodic gear responses were seen at ``K`` = 0.6-0.9,
falling below 0.25 with 1000 points. For regime maps keep >= 1000 periods or
pass the Lyapunov exponent. ``K`` is unreliable too for a periodic sequence
whose period is not small against ``N/10`` (it is reported, but the period
test decides first).
"""

from __future__ import annotations

import math
import types
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
import pandas as pd
import scipy.signal
import xarray as xr
from scipy.cluster.hierarchy import fcluster, linkage

from .errors import UqgearError

#: Regime labels :func:`classify_response` can return besides ``period-n``.
QUASI_PERIODIC = "quasi-periodic"
CHAOTIC = "chaotic"
#: Label of a batch sample whose Poincare points are not all finite (a failed run).
UNDETERMINED = "undetermined"

#: Fewest Poincare points the 0-1 test accepts: n_cut = N/10 must give a
#: correlation over at least two lags.
MIN_ZERO_ONE_POINTS = 20

_CONTACT_STATES = {"fraction_drive_contact": 1, "fraction_separation": 0, "fraction_back_contact": -1}
_CONTACT_LONG_NAMES = {
    "fraction_drive_contact": "fraction of time in drive-side contact (x > b)",
    "fraction_separation": "fraction of time with the teeth apart (|x| <= b)",
    "fraction_back_contact": "fraction of time in back-side contact (x < -b)",
}

Seed = int | np.random.SeedSequence


# ----------------------------------------------------------------------------
# input checks
# ----------------------------------------------------------------------------

def _check_max_period(max_period: Any) -> int:
    if isinstance(max_period, bool) or not isinstance(max_period, (int, np.integer)) or max_period < 1:
        raise UqgearError(f"max_period: expected an integer >= 1; got {max_period!r}")
    return int(max_period)


def _resolve_max_period(max_period: int | None, n_points: int) -> int:
    # Default: periods that repeat at least four times in the kept window.
    if max_period is None:
        return max(1, n_points // 4)
    return _check_max_period(max_period)


def _check_positive(name: str, value: Any) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise UqgearError(f"{name}: expected a positive number; got {value!r}") from None
    if not math.isfinite(number) or number <= 0.0:
        raise UqgearError(f"{name}: expected a positive finite number; got {value!r}")
    return number


def _rng(seed: Seed) -> np.random.Generator:
    if isinstance(seed, np.random.SeedSequence):
        return np.random.default_rng(seed)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UqgearError(f"seed: expected a non-negative integer or a numpy.random.SeedSequence; got {seed!r}")
    return np.random.default_rng(np.random.SeedSequence(int(seed)))


def _as_points(points: Any, name: str = "points") -> np.ndarray:
    """Poincare points as a float array of shape (n_points, n_components)."""
    array = np.asarray(points.values if isinstance(points, xr.DataArray) else points, dtype=float)
    if array.ndim == 1:
        array = array[:, np.newaxis]
    if array.ndim != 2:
        raise UqgearError(f"{name}: expected a 1-D sequence (x per period) or a 2-D array "
                          f"(period, component); got an array of shape {array.shape}")
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise UqgearError(f"{name}: expected at least one Poincare point; got an empty array")
    if not np.all(np.isfinite(array)):
        raise UqgearError(f"{name}: expected finite values; got NaN or infinity "
                          f"(a diverged or failed run?)")
    return array


def _require(ds: xr.Dataset, names: Sequence[str], what: str) -> None:
    if not isinstance(ds, xr.Dataset):
        raise UqgearError(f"{what}: expected an xarray Dataset; got {type(ds).__name__}")
    missing = [name for name in names if name not in ds.variables]
    if missing:
        raise UqgearError(f"{what}: the Dataset lacks variable(s) {', '.join(missing)}; "
                          f"it has {', '.join(sorted(map(str, ds.data_vars))) or 'none'}")


def _require_attr(ds: xr.Dataset, name: str, what: str) -> float:
    if name not in ds.attrs:
        raise UqgearError(f"{what}: the Dataset lacks the attribute {name!r} "
                          f"(expected a simulate() result)")
    try:
        return float(ds.attrs[name])
    except (TypeError, ValueError):
        raise UqgearError(f"{what}: attribute {name!r} should be a number; got {ds.attrs[name]!r}") from None


# ----------------------------------------------------------------------------
# periodicity and the 0-1 test
# ----------------------------------------------------------------------------

def _component_scale(points: np.ndarray, scale: Any) -> np.ndarray:
    n_components = points.shape[1]
    if scale is None:
        # Fallback without a time history: the larger of the spread and the
        # RMS value, so that a period-1 sequence (no spread) is judged
        # against its magnitude rather than against its own noise.
        spread = np.ptp(points, axis=0)
        rms = np.sqrt(np.mean(points ** 2, axis=0))
        result = np.maximum(spread, rms)
    else:
        try:
            result = np.asarray(scale, dtype=float)
        except (TypeError, ValueError):
            raise UqgearError(f"scale: expected one number or one per component ({n_components}); "
                              f"got {scale!r}") from None
        if result.ndim > 1 or result.size not in (1, n_components):
            raise UqgearError(f"scale: expected one number or one per component ({n_components}); "
                              f"got {scale!r}")
        result = np.broadcast_to(result.reshape(-1), (n_components,)).copy()
        if not np.all(np.isfinite(result)) or np.any(result < 0.0):
            raise UqgearError(f"scale: expected non-negative finite numbers; got {scale!r}")
    # A component that is exactly zero everywhere has no scale; any non-zero
    # difference then counts as a mismatch.
    return np.where(result > 0.0, result, np.finfo(float).tiny)


def detect_period(points: Any, max_period: int = 8, rtol: float = 1e-3,
                  scale: float | Sequence[float] | None = None) -> int:
    """Smallest period of a Poincare sequence.

    Parameters
    ----------
    points : array_like, shape (n_points,) or (n_points, n_components)
        Poincare points in order, one per mesh (forcing) period: ``x`` alone
        or ``(x, x_velocity)``.
    max_period : int
        Largest period tried.
    rtol : float
        Tolerance relative to ``scale``: period ``n`` is accepted when
        ``|p[i + n, c] - p[i, c]| <= rtol * scale[c]`` for every ``i`` and
        component ``c``.
    scale : float or sequence of float, optional
        Scale of each component (e.g. the peak-to-peak of the time history).
        Default: per component the larger of the spread and the RMS value of
        the points.

    Returns
    -------
    int
        The smallest ``n`` in ``1..max_period`` for which the sequence repeats
        (only periods that repeat at least once, ``2 n <= n_points``, are
        tried); 0 if none.
    """
    max_period = _check_max_period(max_period)
    rtol = _check_positive("rtol", rtol)
    array = _as_points(points)
    scaled = array / _component_scale(array, scale)
    for period in range(1, max_period + 1):
        if 2 * period > scaled.shape[0]:
            break
        if np.max(np.abs(scaled[period:] - scaled[:-period])) <= rtol:
            return period
    return 0


def count_distinct_points(points: Any, rtol: float = 1e-3,
                          scale: float | Sequence[float] | None = None) -> int:
    """Number of distinct Poincare points: clusters of diameter <= ``rtol * scale``.

    Complete-linkage clustering with the Chebyshev distance on the scaled
    points (``scale`` as in :func:`detect_period`).
    """
    rtol = _check_positive("rtol", rtol)
    array = _as_points(points)
    if array.shape[0] == 1:
        return 1
    scaled = array / _component_scale(array, scale)
    tree = linkage(scaled, method="complete", metric="chebyshev")
    return int(np.max(fcluster(tree, t=rtol, criterion="distance")))


def _zero_one_frequencies(seed: Seed, n_c: Any) -> np.ndarray:
    if isinstance(n_c, bool) or not isinstance(n_c, (int, np.integer)) or n_c < 1:
        raise UqgearError(f"n_c: expected an integer >= 1; got {n_c!r}")
    # (pi/5, 4pi/5) keeps c away from the resonances c = 0 and c = pi
    # (Gottwald & Melbourne 2009, section 3).
    return _rng(seed).uniform(math.pi / 5.0, 4.0 * math.pi / 5.0, int(n_c))


def _zero_one_median(series: np.ndarray, frequencies: np.ndarray, constant_tolerance: float = 0.0) -> float:
    n_points = series.size
    spread = np.ptp(series)
    magnitude = np.max(np.abs(series))
    if spread <= max(1e-12 * magnitude, constant_tolerance) or spread == 0.0:
        # A constant sequence (period 1 to round-off, or to the periodicity
        # tolerance) is regular; the statistic itself would see the residual
        # noise and, like any noise, report K near 1.
        return 0.0
    phi = series / spread
    mean = np.mean(phi)
    n_cut = n_points // 10
    lags = np.arange(1, n_cut + 1)
    j = np.arange(1, n_points + 1)
    angles = np.outer(frequencies, j)
    p = np.cumsum(phi * np.cos(angles), axis=1)
    q = np.cumsum(phi * np.sin(angles), axis=1)
    msd = np.empty((frequencies.size, n_cut))
    for index, lag in enumerate(lags):
        msd[:, index] = np.mean((p[:, lag:] - p[:, :-lag]) ** 2 + (q[:, lag:] - q[:, :-lag]) ** 2, axis=1)
    # Modified mean-square displacement D_c(n) = M_c(n) - V_osc(c, n): the
    # oscillatory term of a non-zero mean is removed before correlating.
    oscillation = mean ** 2 * (1.0 - np.cos(np.outer(frequencies, lags))) / (1.0 - np.cos(frequencies))[:, None]
    displacement = msd - oscillation
    centred_lags = lags - lags.mean()
    centred = displacement - displacement.mean(axis=1, keepdims=True)
    norms = np.sqrt(np.sum(centred ** 2, axis=1) * np.sum(centred_lags ** 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        correlation = np.where(norms > 0.0, centred @ centred_lags / norms, 0.0)
    return float(np.median(correlation))


def zero_one_test(series: Any, seed: Seed = 0, n_c: int = 100) -> float:
    """Gottwald-Melbourne 0-1 test for chaos, correlation method.

    Follows Gottwald & Melbourne, "On the implementation of the 0-1 test for
    chaos", SIAM J. Appl. Dyn. Syst. 8 (2009) 129-145: for each of ``n_c``
    frequencies ``c`` drawn uniformly in (pi/5, 4 pi/5), the translation
    variables ``p_c(n) = sum_j phi_j cos(j c)``, ``q_c(n) = sum_j phi_j sin(j c)``
    give the modified mean-square displacement ``D_c(n)`` for ``n <= N/10``;
    ``K_c`` is the correlation coefficient of ``D_c(n)`` with ``n``, and the
    result is the median of ``K_c`` over ``c`` (which suppresses the isolated
    resonant ``c`` at which a regular series gives a spuriously large ``K_c``).

    Parameters
    ----------
    series : array_like, shape (N,)
        A discrete-time observable, e.g. the Poincare sequence of ``x``
        (not an oversampled time history). ``N >= 20``; a few hundred or more
        sharpen the result.
    seed : int or numpy.random.SeedSequence
        Seeds the draw of the frequencies ``c``.
    n_c : int
        Number of frequencies ``c``.

    Returns
    -------
    float
        Median ``K``: near 0 for regular (periodic, quasi-periodic) dynamics,
        near 1 for chaotic dynamics (and for noise). A sequence constant to
        round-off gives exactly 0.
    """
    array = np.asarray(series.values if isinstance(series, xr.DataArray) else series, dtype=float)
    if array.ndim != 1:
        raise UqgearError(f"series: expected a 1-D sequence; got an array of shape {array.shape}")
    if array.size < MIN_ZERO_ONE_POINTS:
        raise UqgearError(f"series: the 0-1 test needs at least {MIN_ZERO_ONE_POINTS} values "
                          f"(keep more Poincare periods); got {array.size}")
    if not np.all(np.isfinite(array)):
        raise UqgearError("series: expected finite values; got NaN or infinity")
    return _zero_one_median(array, _zero_one_frequencies(seed, n_c))


# ----------------------------------------------------------------------------
# classification
# ----------------------------------------------------------------------------

@dataclass(frozen=True)
class ResponseClass:
    """Regime of a steady response, with the evidence behind it.

    Attributes
    ----------
    label : str
        ``"period-n"`` (n = 1..max_period), ``"quasi-periodic"`` or ``"chaotic"``
        (``"undetermined"`` only in batches, for a failed run).
    period : int
        ``n`` of a period-n response; 0 otherwise.
    evidence : Mapping
        ``distinct_points`` (int), ``zero_one_k`` (float; 0 when the ``x``
        sequence is constant within the periodicity tolerance),
        ``largest_lyapunov`` (float or None, per mesh period), ``n_points``
        (int) and ``reason`` (a short sentence).
    """

    label: str
    period: int
    evidence: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "evidence", types.MappingProxyType(dict(self.evidence)))

    @property
    def reason(self) -> str:
        """Human-readable justification of the label."""
        return str(self.evidence.get("reason", ""))


def _decide(period: int, k: float, lyapunov: float | None, n_distinct: int, n_points: int,
            max_period: int, rtol: float, k_threshold: float,
            lyapunov_threshold: float) -> tuple[str, int, str]:
    k_chaotic = k > k_threshold
    k_text = f"0-1 test K={k:.3f} {'>' if k_chaotic else '<='} {k_threshold:g}"
    if period > 0:
        reason = (f"the Poincare sequence repeats every {period} mesh period(s) to within "
                  f"rtol={rtol:g} ({n_distinct} distinct point(s) of {n_points})")
        if lyapunov is not None and lyapunov > lyapunov_threshold:
            reason += f"; note: Lyapunov exponent {lyapunov:.3g} > {lyapunov_threshold:g} disagrees"
        return f"period-{period}", period, reason
    start = f"no period <= {max_period}, {n_distinct} distinct points of {n_points}; "
    if lyapunov is not None:
        lyapunov_chaotic = lyapunov > lyapunov_threshold
        reason = (start + f"largest Lyapunov exponent {lyapunov:.3g} per mesh period "
                  f"{'>' if lyapunov_chaotic else '<='} {lyapunov_threshold:g}")
        reason += f" ({k_text}{', agrees' if k_chaotic == lyapunov_chaotic else ', disagrees'})"
        return (CHAOTIC if lyapunov_chaotic else QUASI_PERIODIC), 0, reason
    if k_chaotic:
        return CHAOTIC, 0, start + k_text
    return QUASI_PERIODIC, 0, start + k_text + ": bounded, regular, non-repeating"


def classify_response(poincare_points: Any, *, max_period: int | None = None, rtol: float = 1e-3,
                      scale: float | Sequence[float] | None = None, lyapunov: float | None = None,
                      seed: Seed = 0, n_c: int = 100, k_threshold: float = 0.5,
                      lyapunov_threshold: float = 0.01) -> ResponseClass:
    """Classify a steady response from its Poincare points.

    Parameters
    ----------
    poincare_points : array_like, shape (N,) or (N, n_components)
        Poincare points, first column ``x`` (used for the 0-1 test), further
        columns e.g. ``x_velocity``. ``N >= 20``.
    max_period : int, optional
        Largest period tried; default a quarter of the number of points.
    rtol, scale
        Periodicity detection, see :func:`detect_period`.
    lyapunov : float, optional
        Largest Lyapunov exponent in nats per mesh period (multiply an
        exponent in 1/s by the mesh period).
    seed, n_c
        0-1 test frequencies, see :func:`zero_one_test`.
    k_threshold : float
        ``K`` above which a non-periodic response is chaotic when no
        Lyapunov exponent is given.
    lyapunov_threshold : float
        Exponent (per mesh period) above which a non-periodic response is
        chaotic; when ``lyapunov`` is given it decides, ``K`` only
        corroborates.

    Returns
    -------
    ResponseClass
        Decision rule in the module docstring.
    """
    rtol = _check_positive("rtol", rtol)
    array = _as_points(poincare_points, "poincare_points")
    if array.shape[0] < MIN_ZERO_ONE_POINTS:
        raise UqgearError(f"poincare_points: expected at least {MIN_ZERO_ONE_POINTS} Poincare points "
                          f"(keep more periods); got {array.shape[0]}")
    max_period = _resolve_max_period(max_period, array.shape[0])
    if lyapunov is not None:
        try:
            lyapunov = float(lyapunov)
        except (TypeError, ValueError):
            raise UqgearError(f"lyapunov: expected a number (per mesh period) or None; got {lyapunov!r}") from None
        if math.isnan(lyapunov):
            lyapunov = None
    component_scale = _component_scale(array, scale)
    return _classify_points(array, component_scale, _zero_one_frequencies(seed, n_c), max_period, rtol,
                            lyapunov, float(k_threshold), float(lyapunov_threshold))


def _classify_points(array: np.ndarray, component_scale: np.ndarray, frequencies: np.ndarray,
                     max_period: int, rtol: float, lyapunov: float | None, k_threshold: float,
                     lyapunov_threshold: float) -> ResponseClass:
    period = detect_period(array, max_period, rtol, component_scale)
    n_distinct = count_distinct_points(array, rtol, component_scale)
    k = _zero_one_median(array[:, 0], frequencies, constant_tolerance=rtol * component_scale[0])
    label, period, reason = _decide(period, k, lyapunov, n_distinct, array.shape[0], max_period, rtol,
                                    k_threshold, lyapunov_threshold)
    evidence = {"n_points": int(array.shape[0]), "distinct_points": n_distinct, "zero_one_k": k,
                "largest_lyapunov": lyapunov, "reason": reason}
    return ResponseClass(label, period, evidence)


def _mesh_angular_frequency(ds: xr.Dataset) -> xr.DataArray | float | None:
    """Mesh angular frequency of each run in rad/s, if the Dataset tells it."""
    if "mesh_frequency" in ds.variables:
        return 2.0 * math.pi * ds["mesh_frequency"]
    if "mesh_frequency" in ds.attrs:
        return 2.0 * math.pi * float(ds.attrs["mesh_frequency"])
    if "pinion_speed" in ds.variables and "z1" in ds.attrs:
        return 2.0 * math.pi * float(ds.attrs["z1"]) * ds["pinion_speed"] / 60.0
    if "pinion_speed" in ds.attrs and "z1" in ds.attrs:
        return 2.0 * math.pi * float(ds.attrs["z1"]) * float(ds.attrs["pinion_speed"]) / 60.0
    return None


def _lyapunov_per_period(ds: xr.Dataset) -> xr.DataArray | None:
    """The Dataset's largest Lyapunov exponent converted to nats per mesh period."""
    if "largest_lyapunov" not in ds.variables:
        return None
    exponent = ds["largest_lyapunov"]
    units = str(exponent.attrs.get("units", "")).replace(" ", "").lower()
    if units in {"s-1", "1/s", "hz", "s^-1"}:
        angular = _mesh_angular_frequency(ds)
        if angular is None:
            warnings.warn("largest_lyapunov is in 1/s but the Dataset gives no mesh frequency "
                          "(mesh_frequency, or pinion_speed and attrs z1); the exponent is ignored",
                          stacklevel=3)
            return None
        return exponent * (2.0 * math.pi / angular)
    if units in {"", "1", "1/period", "period-1", "permeshperiod", "1/meshperiod", "meshperiod-1"}:
        return exponent
    warnings.warn(f"largest_lyapunov has units {units!r}, expected 1/s or per mesh period; "
                  f"the exponent is ignored", stacklevel=3)
    return None


def _scale_array(x_scale: Any, angular: Any, has_velocity: bool) -> np.ndarray | None:
    if x_scale is None:
        return None
    if not has_velocity:
        return np.array([x_scale], dtype=float)
    if angular is None:
        return None
    return np.array([x_scale, x_scale * angular], dtype=float)


def classify_dataset(ds: xr.Dataset, *, max_period: int | None = None, rtol: float = 1e-3, seed: Seed = 0,
                     n_c: int = 100, k_threshold: float = 0.5,
                     lyapunov_threshold: float = 0.01) -> ResponseClass:
    """Classify the response of one :func:`~uqgear.integration.simulate` run.

    Uses ``poincare_x`` and, when present, ``poincare_x_velocity``. The scale
    of ``x`` is the peak-to-peak of the kept ``x`` history, that of the
    velocity this times the mesh angular frequency (fallbacks as in
    :func:`detect_period` when the history is absent). A ``largest_lyapunov``
    variable (units ``s-1`` or per mesh period) joins the evidence.

    Other parameters are those of :func:`classify_response`.
    """
    _require(ds, ["poincare_x"], "classify_dataset")
    if set(ds["poincare_x"].dims) != {"period"}:
        raise UqgearError(f"classify_dataset: poincare_x should have the single dim 'period'; "
                          f"it has {ds['poincare_x'].dims} (use classify_batch for a batch)")
    columns = [ds["poincare_x"].values]
    has_velocity = "poincare_x_velocity" in ds.variables
    if has_velocity:
        columns.append(ds["poincare_x_velocity"].values)
    x_scale = float(np.ptp(ds["x"].values)) if "x" in ds.variables and ds["x"].size else None
    scale = _scale_array(x_scale, _mesh_angular_frequency(ds), has_velocity)
    exponent = _lyapunov_per_period(ds)
    lyapunov = None if exponent is None else float(exponent)
    return classify_response(np.column_stack(columns), max_period=max_period, rtol=rtol, scale=scale,
                             lyapunov=lyapunov, seed=seed, n_c=n_c, k_threshold=k_threshold,
                             lyapunov_threshold=lyapunov_threshold)


def classify_batch(ds: xr.Dataset, *, max_period: int | None = None, rtol: float = 1e-3, seed: Seed = 0,
                   n_c: int = 100, k_threshold: float = 0.5,
                   lyapunov_threshold: float = 0.01) -> xr.Dataset:
    """Classify every run of a :func:`~uqgear.integration.simulate_batch` result.

    Every dim of ``poincare_x`` other than ``period`` (``sample``, or the
    parameter dims of a sweep) is a run. The scale of ``x`` is
    ``dte_peak_to_peak`` when present, the velocity scale that times the mesh
    angular frequency (from ``mesh_frequency``, or ``pinion_speed`` and attrs
    ``z1``); otherwise the fallbacks of :func:`detect_period`. All runs share
    the same 0-1 test frequencies, so a run's result does not depend on its
    position in the batch. A run with non-finite Poincare points is labelled
    ``"undetermined"``.

    Returns
    -------
    xarray.Dataset
        Over the run dims (coords carried along): ``regime`` (str),
        ``response_period`` (int, 0 if not periodic; not ``period``, which is
        the Poincare dim), ``zero_one_k`` (float) and ``distinct_points``
        (int).
    """
    _require(ds, ["poincare_x"], "classify_batch")
    poincare_x = ds["poincare_x"]
    if "period" not in poincare_x.dims:
        raise UqgearError(f"classify_batch: poincare_x should have a 'period' dim; it has {poincare_x.dims}")
    rtol = _check_positive("rtol", rtol)
    if poincare_x.sizes["period"] < MIN_ZERO_ONE_POINTS:
        raise UqgearError(f"classify_batch: expected at least {MIN_ZERO_ONE_POINTS} Poincare periods "
                          f"(keep_periods); got {poincare_x.sizes['period']}")
    max_period = _resolve_max_period(max_period, poincare_x.sizes["period"])
    frequencies = _zero_one_frequencies(seed, n_c)
    run_dims = [dim for dim in poincare_x.dims if dim != "period"]
    template = poincare_x.isel(period=0, drop=True).transpose(*run_dims)
    has_velocity = "poincare_x_velocity" in ds.variables

    def per_run(value: xr.DataArray | float) -> np.ndarray:
        # One number per run, in the flattened run order of the points.
        if isinstance(value, xr.DataArray):
            value = value.broadcast_like(template).transpose(*run_dims).values
        return np.broadcast_to(np.asarray(value, dtype=float), template.shape).reshape(-1)

    points = [poincare_x.transpose(*run_dims, "period").values.reshape(-1, poincare_x.sizes["period"])]
    if has_velocity:
        points.append(ds["poincare_x_velocity"].transpose(*run_dims, "period").values.reshape(points[0].shape))
    x_scale = per_run(ds["dte_peak_to_peak"]) if "dte_peak_to_peak" in ds.variables else None
    angular = _mesh_angular_frequency(ds)
    angular = per_run(angular) if angular is not None else None
    exponent = _lyapunov_per_period(ds)
    exponent = per_run(exponent) if exponent is not None else None

    n_runs = points[0].shape[0]
    regime = np.empty(n_runs, dtype=object)
    response_period = np.zeros(n_runs, dtype=np.int64)
    zero_one_k = np.full(n_runs, np.nan)
    distinct = np.zeros(n_runs, dtype=np.int64)
    for run in range(n_runs):
        array = np.column_stack([component[run] for component in points])
        if not np.all(np.isfinite(array)):
            regime[run] = UNDETERMINED
            continue
        scale = _scale_array(None if x_scale is None else x_scale[run],
                             None if angular is None else angular[run], has_velocity)
        if scale is not None and not np.all(np.isfinite(scale)):
            scale = None
        component_scale = _component_scale(array, scale)
        lyapunov = None
        if exponent is not None and np.isfinite(exponent[run]):
            lyapunov = float(exponent[run])
        result = _classify_points(array, component_scale, frequencies, max_period, rtol, lyapunov,
                                  float(k_threshold), float(lyapunov_threshold))
        regime[run] = result.label
        response_period[run] = result.period
        zero_one_k[run] = result.evidence["zero_one_k"]
        distinct[run] = result.evidence["distinct_points"]

    def build(values: np.ndarray, attrs: dict[str, str]) -> xr.DataArray:
        return template.copy(data=values.reshape(template.shape)).assign_attrs(attrs)

    labels = np.array([str(label) for label in regime], dtype=str)
    return xr.Dataset(
        {
            "regime": build(labels, {"long_name": "response regime (period-n, quasi-periodic, chaotic)"}),
            "response_period": build(response_period, {"units": "1",
                                                       "long_name": "period n of a period-n response, 0 otherwise"}),
            "zero_one_k": build(zero_one_k, {"units": "1", "long_name": "median K of the 0-1 test for chaos"}),
            "distinct_points": build(distinct, {"units": "1", "long_name": "distinct Poincare points"}),
        },
        attrs={"max_period": max_period, "rtol": rtol, "k_threshold": float(k_threshold),
               "lyapunov_threshold": float(lyapunov_threshold), "zero_one_n_c": int(frequencies.size)},
    )


# ----------------------------------------------------------------------------
# spectra
# ----------------------------------------------------------------------------

def amplitude_spectrum(signal: Any, sample_rate: float, *,
                       against: Literal["frequency", "order"] = "frequency",
                       shaft_speed_rpm: float | None = None, window: str = "hann",
                       remove_mean: bool = True, dim: str = "time") -> xr.DataArray:
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
    sample_rate = _check_positive("sample_rate", sample_rate)
    if against not in ("frequency", "order"):
        raise UqgearError(f"against: expected 'frequency' or 'order'; got {against!r}")
    if against == "order":
        if shaft_speed_rpm is None:
            raise UqgearError("shaft_speed_rpm: required for a spectrum against order; got None")
        shaft_speed_rpm = _check_positive("shaft_speed_rpm", shaft_speed_rpm)
    if isinstance(signal, xr.DataArray):
        data_array = signal if signal.ndim != 1 else signal.rename({signal.dims[0]: dim})
        if dim not in data_array.dims:
            raise UqgearError(f"signal: expected a DataArray with dim {dim!r}; it has {signal.dims}")
        units = str(signal.attrs.get("units", ""))
        name = signal.name
    else:
        values = np.asarray(signal, dtype=float)
        if values.ndim != 1:
            raise UqgearError(f"signal: expected a 1-D array (or a DataArray with dim {dim!r}); "
                              f"got an array of shape {values.shape}")
        data_array = xr.DataArray(values, dims=[dim])
        units, name = "", None
    n_samples = data_array.sizes[dim]
    if n_samples < 2:
        raise UqgearError(f"signal: expected at least 2 samples along {dim!r}; got {n_samples}")
    values = data_array.transpose(..., dim).values.astype(float)
    if not np.all(np.isfinite(values)):
        raise UqgearError("signal: expected finite values; got NaN or infinity")
    try:
        taper = scipy.signal.get_window(window, n_samples, fftbins=True)
    except (ValueError, TypeError) as error:
        raise UqgearError(f"window: expected a window name of scipy.signal.get_window "
                          f"(hann, hamming, flattop, boxcar, ...); got {window!r} ({error})") from None
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
    attrs = {"units": units, "long_name": "single-sided amplitude spectrum" + (f" of {name}" if name else ""),
             "window": window, "sample_rate": sample_rate, "mean_removed": int(bool(remove_mean))}
    frequency_coord = xr.Variable("frequency", frequency, {"units": "Hz", "long_name": "frequency"})
    result = xr.DataArray(amplitude, dims=[*other_dims, "frequency"],
                          coords={**coords, "frequency": frequency_coord}, attrs=attrs, name="amplitude")
    if against == "order":
        shaft_frequency = shaft_speed_rpm / 60.0
        order = xr.Variable("frequency", frequency / shaft_frequency,
                            {"units": "1", "long_name": "order (multiples of the shaft rotation frequency)"})
        result = result.assign_coords(order=order).swap_dims({"frequency": "order"})
        result.attrs["shaft_speed_rpm"] = shaft_speed_rpm
    return result


def _time_step(ds: xr.Dataset, what: str) -> float:
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


def spectrum_dataset(ds: xr.Dataset, variable: str | Sequence[str] = "x", *,
                     against: Literal["frequency", "order"] = "frequency", window: str = "hann",
                     remove_mean: bool = True) -> xr.Dataset:
    """Amplitude spectra of variables of a :func:`~uqgear.integration.simulate` run.

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
    """
    names = [variable] if isinstance(variable, str) else list(variable)
    if not names:
        raise UqgearError("variable: expected at least one variable name; got none")
    _require(ds, names, "spectrum_dataset")
    for name in names:
        if "time" not in ds[name].dims:
            raise UqgearError(f"spectrum_dataset: variable {name!r} has no 'time' dim "
                              f"(dims {ds[name].dims}); expected a time history")
    sample_rate = 1.0 / _time_step(ds, "spectrum_dataset")
    shaft_speed = None
    if against == "order":
        shaft_speed = _require_attr(ds, "pinion_speed", "spectrum_dataset")
    spectra = {name: amplitude_spectrum(ds[name], sample_rate, against=against, shaft_speed_rpm=shaft_speed,
                                        window=window, remove_mean=remove_mean).rename(name)
               for name in names}
    attrs = {key: ds.attrs[key] for key in ("pinion_speed", "mesh_frequency") if key in ds.attrs}
    if "z1" in ds.attrs:
        attrs["mesh_order"] = ds.attrs["z1"]
    attrs.update({"window": window, "sample_rate": sample_rate})
    return xr.Dataset(spectra, attrs=attrs)


# ----------------------------------------------------------------------------
# phase plane, Poincare section, contact and QoIs
# ----------------------------------------------------------------------------

def phase_plane(ds: xr.Dataset, variable: str = "x") -> xr.Dataset:
    """Displacement and velocity histories of one coordinate, for a phase portrait.

    Parameters
    ----------
    ds : xarray.Dataset
        A simulate() result.
    variable : str
        ``x``, ``y1`` or ``y2``; its velocity is ``<variable>_velocity``.

    Returns
    -------
    xarray.Dataset
        ``displacement`` (m) and ``velocity`` (m s-1) over ``time``.
    """
    if not isinstance(variable, str):
        raise UqgearError(f"variable: expected a variable name such as 'x'; got {variable!r}")
    velocity_name = f"{variable}_velocity"
    _require(ds, [variable, velocity_name], "phase_plane")
    displacement = ds[variable].copy()
    velocity = ds[velocity_name].copy()
    displacement.attrs = {"units": ds[variable].attrs.get("units", "m"),
                          "long_name": f"{variable} displacement"}
    velocity.attrs = {"units": ds[velocity_name].attrs.get("units", "m s-1"),
                      "long_name": f"{variable} velocity"}
    return xr.Dataset({"displacement": displacement, "velocity": velocity}, attrs={"variable": variable})


def poincare_section(ds: xr.Dataset) -> xr.Dataset:
    """The Poincare section (state once per mesh period) of a simulate() result.

    Returns
    -------
    xarray.Dataset
        The ``poincare_*`` variables over the ``period`` dim, with the run's
        attrs.
    """
    if not isinstance(ds, xr.Dataset):
        raise UqgearError(f"poincare_section: expected an xarray Dataset; got {type(ds).__name__}")
    names = [name for name in ds.data_vars if str(name).startswith("poincare_")]
    if not names:
        raise UqgearError("poincare_section: the Dataset has no poincare_* variables "
                          "(expected poincare_x, poincare_x_velocity, ...)")
    return ds[names].copy()


def contact_fractions(ds: xr.Dataset) -> xr.Dataset:
    """Fractions of time in each contact state, from the ``contact`` history.

    Returns
    -------
    xarray.Dataset
        ``fraction_drive_contact`` (``contact == 1``), ``fraction_separation``
        (0) and ``fraction_back_contact`` (-1), averaged over ``time`` (other
        dims kept); they add up to 1.
    """
    _require(ds, ["contact"], "contact_fractions")
    contact = ds["contact"]
    if "time" not in contact.dims:
        raise UqgearError(f"contact_fractions: 'contact' should have a 'time' dim; it has {contact.dims}")
    if contact.sizes["time"] == 0:
        raise UqgearError("contact_fractions: 'contact' has no time samples")
    values = np.unique(contact.values)
    unexpected = sorted(set(values.tolist()) - {-1, 0, 1})
    if unexpected:
        raise UqgearError(f"contact_fractions: 'contact' should hold only -1, 0 and 1; got {unexpected[:5]}")
    return xr.Dataset({name: (contact == state).mean("time").astype(float).assign_attrs(
        units="1", long_name=_CONTACT_LONG_NAMES[name]) for name, state in _CONTACT_STATES.items()})


def response_qois(ds: xr.Dataset) -> xr.Dataset:
    """Scalar quantities of interest of a simulate() run.

    Named and defined like the QoIs of ``simulate_batch``, reduced over
    ``time`` (other dims kept):

    * ``dte_mean``: mean of ``x``, m;
    * ``dte_rms``: RMS of ``x - mean(x)``, m;
    * ``dte_peak_to_peak``: ``max(x) - min(x)``, m;
    * ``dynamic_load_factor``: peak mesh force in the loading direction over
      the static mesh force, ``max(F sign(F_T)) / |F_T|`` (``max(F) / F_T``
      for a driving load);
    * ``acc_pinion_rms``, ``acc_gear_rms``: RMS of ``y1_acceleration`` and
      ``y2_acceleration`` (their mean is zero in a steady state), m s-2;
    * the three contact fractions of :func:`contact_fractions`.
    """
    _require(ds, ["x", "mesh_force", "y1_acceleration", "y2_acceleration", "contact"], "response_qois")
    if "time" not in ds["x"].dims:
        raise UqgearError(f"response_qois: 'x' should have a 'time' dim; it has {ds['x'].dims}")
    static_force = _require_attr(ds, "static_mesh_force", "response_qois")
    if static_force == 0.0 or not math.isfinite(static_force):
        raise UqgearError(f"response_qois: attribute static_mesh_force should be a non-zero number "
                          f"(a loaded mesh); got {static_force!r}")
    x = ds["x"]
    mean = x.mean("time")
    qois = {
        "dte_mean": mean.assign_attrs(units="m", long_name="mean dynamic transmission error x"),
        "dte_rms": np.sqrt(((x - mean) ** 2).mean("time")).assign_attrs(
            units="m", long_name="RMS of the dynamic transmission error about its mean"),
        "dte_peak_to_peak": (x.max("time") - x.min("time")).assign_attrs(
            units="m", long_name="peak-to-peak dynamic transmission error"),
        "dynamic_load_factor": ((ds["mesh_force"] * math.copysign(1.0, static_force)).max("time")
                                / abs(static_force)).assign_attrs(
            units="1", long_name="peak mesh force over static mesh force"),
        "acc_pinion_rms": np.sqrt((ds["y1_acceleration"] ** 2).mean("time")).assign_attrs(
            units="m s-2", long_name="RMS pinion acceleration along the line of action"),
        "acc_gear_rms": np.sqrt((ds["y2_acceleration"] ** 2).mean("time")).assign_attrs(
            units="m s-2", long_name="RMS gear acceleration along the line of action"),
    }
    result = xr.Dataset(qois)
    return result.merge(contact_fractions(ds))


# ----------------------------------------------------------------------------
# bifurcation sweeps
# ----------------------------------------------------------------------------

def _check_values(name: str, values: Any) -> np.ndarray:
    array = np.asarray(values, dtype=float) if not isinstance(values, str) else np.array([])
    if array.ndim != 1 or array.size == 0:
        raise UqgearError(f"{name}: expected a non-empty 1-D sequence of numbers; got {values!r}")
    if not np.all(np.isfinite(array)):
        raise UqgearError(f"{name}: expected finite numbers; got {values!r}")
    return array


def _check_fixed(fixed: Mapping[str, float] | None, swept: Sequence[str]) -> dict[str, float]:
    if fixed is None:
        return {}
    if not isinstance(fixed, Mapping):
        raise UqgearError(f"fixed: expected a mapping of variable name to value; got {fixed!r}")
    result = {}
    for key, value in fixed.items():
        if key in swept:
            raise UqgearError(f"fixed: {key!r} is also swept; give it either as swept or as fixed")
        try:
            result[str(key)] = float(value)
        except (TypeError, ValueError):
            raise UqgearError(f"fixed: {key}: expected a number; got {value!r}") from None
    return result


def _run_and_classify(design: Any, samples: xr.Dataset, n_periods: int, keep_periods: int,
                      lyapunov: bool, max_period: int | None, rtol: float, seed: Seed,
                      evaluate: Callable[[xr.Dataset], xr.Dataset] | None = None) -> xr.Dataset:
    if evaluate is not None:
        result = evaluate(samples)
    else:
        # Imported here: the integrators are a heavier module (numba kernels) and
        # the analysis functions must stay importable and testable on their own.
        from .design import load_design
        from .integration import simulate_batch

        result = simulate_batch(load_design(design), samples, n_periods=n_periods, keep_periods=keep_periods,
                                lyapunov=bool(lyapunov))
    classes = classify_batch(result, max_period=max_period, rtol=rtol, seed=seed)
    return result.merge(classes, compat="override")


def bifurcation(design: Any, parameter: str, values: Sequence[float], *,
                fixed: Mapping[str, float] | None = None, n_periods: int = 400, keep_periods: int = 200,
                lyapunov: bool = True, max_period: int | None = None, rtol: float = 1e-3,
                seed: Seed = 0) -> xr.Dataset:
    """Bifurcation diagram: Poincare values and regime against one parameter.

    Builds one ``samples`` Dataset (the swept ``parameter`` plus the ``fixed``
    values) and runs :func:`uqgear.integration.simulate_batch` once.

    Parameters
    ----------
    design : Design, str or mapping
        The gear design, anything :func:`uqgear.design.load_design` accepts.
    parameter : str
        A simulate_batch sample variable: ``pinion_speed``, ``drive_torque``,
        ``adhesion_torque``, a design key or ``mesh_stiffness_scale``.
    values : sequence of float
        Values of the parameter (one column of the diagram each).
    fixed : mapping, optional
        Other sample variables held at one value (e.g. ``{"pinion_speed": 3000.0}``).
    n_periods, keep_periods : int
        Mesh periods simulated and kept for the Poincare section.
    lyapunov : bool
        Also estimate the largest Lyapunov exponent (doubles the cost) and
        let it decide chaotic against quasi-periodic. On by default: with a
        few hundred kept periods the 0-1 test alone mistakes slowly
        converging quasi-periodic responses for chaos (module docstring).
    max_period, rtol, seed
        Classification, see :func:`classify_batch`.

    Returns
    -------
    xarray.Dataset
        Dims (``parameter``, ``period``): ``poincare_x`` and the other
        simulate_batch outputs, plus ``regime``, ``response_period``,
        ``zero_one_k`` and ``distinct_points``.
    """
    if not isinstance(parameter, str) or not parameter or parameter in ("sample", "period"):
        raise UqgearError(f"parameter: expected the name of a sample variable such as 'pinion_speed'; "
                          f"got {parameter!r}")
    return sweep_grid(design, {parameter: values}, fixed=fixed, n_periods=n_periods,
                      keep_periods=keep_periods, lyapunov=lyapunov, max_period=max_period, rtol=rtol,
                      seed=seed)


def sweep_grid(design: Any, parameters: Mapping[str, Sequence[float]], *,
               fixed: Mapping[str, float] | None = None, n_periods: int = 400, keep_periods: int = 200,
               lyapunov: bool = True, max_period: int | None = None, rtol: float = 1e-3,
               seed: Seed = 0, evaluate: Callable[[xr.Dataset], xr.Dataset] | None = None) -> xr.Dataset:
    """Regime map over the full grid of several parameters (e.g. speed x adhesion torque).

    Parameters
    ----------
    design : Design, str or mapping
        The gear design, anything :func:`uqgear.design.load_design` accepts.
    parameters : mapping of str to sequence of float
        Swept sample variables and their values; the grid is their Cartesian
        product, run as one simulate_batch call.
    fixed, n_periods, keep_periods, lyapunov, max_period, rtol, seed
        As in :func:`bifurcation`.
    evaluate : callable, optional
        The model as ``evaluate(samples) -> Dataset`` (e.g. a batch evaluator
        run through a :class:`~uqgear.runner.Runner`); its own settings then
        replace ``n_periods``, ``keep_periods`` and ``lyapunov``. Default:
        :func:`~uqgear.integration.simulate_batch` in-process.

    Returns
    -------
    xarray.Dataset
        One dim per swept parameter (in the given order) plus ``period``,
        with the variables of :func:`bifurcation`.
    """
    if not isinstance(parameters, Mapping) or not parameters:
        raise UqgearError(f"parameters: expected a mapping of sample variable name to values; got {parameters!r}")
    names = [str(name) for name in parameters]
    for name in names:
        if not name or name in ("sample", "period"):
            raise UqgearError(f"parameters: expected sample variable names such as 'pinion_speed'; got {name!r}")
    axes = [_check_values(name, parameters[name]) for name in names]
    for name, axis in zip(names, axes):
        if np.unique(axis).size != axis.size:
            raise UqgearError(f"{name}: expected distinct values; got repeated values in {axis.tolist()}")
    constants = _check_fixed(fixed, names)
    index = pd.MultiIndex.from_product(axes, names=names)
    n_samples = len(index)
    data = {name: ("sample", index.get_level_values(name).to_numpy(dtype=float)) for name in names}
    data.update({name: ("sample", np.full(n_samples, value)) for name, value in constants.items()})
    samples = xr.Dataset(data)
    result = _run_and_classify(design, samples, n_periods, keep_periods, lyapunov, max_period, rtol, seed,
                               evaluate)
    result = result.drop_vars([name for name in names if name in result.variables])
    if "sample" in result.variables:
        result = result.drop_vars("sample")
    if len(names) == 1:
        return result.assign_coords({names[0]: ("sample", axes[0])}).swap_dims({"sample": names[0]})
    coords = xr.Coordinates.from_pandas_multiindex(index, "sample")
    return result.assign_coords(coords).unstack("sample").transpose(*names, ...)
