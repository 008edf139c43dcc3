"""Period and regime classification of simulated gear responses.

Pure numerics on the Poincare sections of :func:`uqgear.physics.integration.simulate` and
:func:`uqgear.physics.integration.simulate_batch` (docs/model/analysis-conventions.md section 8): periodicity
detection, distinct Poincare points, the Gottwald-Melbourne 0-1 test for chaos, and
response classification (period-n, quasi-periodic, chaotic) with its evidence.

Classification (all thresholds are parameters of :func:`classify_response`):

* **period-n**: the Poincare sequence repeats with period ``n`` (smallest
  ``n`` up to ``max_period``; by default a quarter of the kept periods) when
  every point agrees with the point ``n`` mesh periods later to within
  ``rtol`` times the scale of its component (default ``rtol = 1e-3``;
  :func:`classify_dataset` and :func:`classify_batch` take the scale from the
  peak-to-peak of the DTE, velocities scaled by the mesh angular frequency,
  so the tolerance is 0.1 % of the orbit size), **and** the period is seen at
  least ``min_repeats`` times (default 10: ``n <= N / 10`` for ``N`` kept
  Poincare points). Long periods do occur in the gear model (a stable
  period-10 orbit near 3250 rpm at light load), which is why the search does
  not stop at 8;
* **quasi_periodic_or_long_period**: the sequence repeats with a period ``n``
  but fewer than ``min_repeats`` times (``n > N / min_repeats``): a few
  repeats cannot tell a long-period lock from a slowly drifting
  quasi-periodic orbit, so no period is claimed (``response_period`` 0; the
  repeat found is in the evidence as ``repeat_period``);
* otherwise (no repeat), with a largest Lyapunov exponent ``lambda`` (nats
  per mesh period) the exponent and the 0-1 test are read side by side:
  **chaotic** if ``lambda > lyapunov_threshold`` (0.01 per mesh period, above
  what a finite-time Benettin estimate of a zero exponent over a few hundred
  periods reaches) and ``K > k_threshold`` (0.5, midway between the regular
  limit 0 and the chaotic limit 1); **quasi-periodic** if
  ``lambda <= lyapunov_threshold`` and ``K <= k_threshold``; **uncertain**
  if they disagree (the exponent says chaotic but ``K <= 0.5``, or the
  exponent says regular but ``K > 0.5``), the reason naming which test said
  what;
* without an exponent, **chaotic** if ``K > k_threshold``, else
  **quasi-periodic** (bounded, non-repeating, the Poincare points on a closed
  curve);
* **undetermined** (batches only): a run with non-finite Poincare points.

The 0-1 test works on the Poincare sequence of ``x`` (one value per mesh
period), never on the densely sampled time history, whose oversampling would
bias ``K``. Its ``K`` converges slowly for quasi-periodic responses: with 200
Poincare points, quasi-periodic gear responses were seen at ``K`` = 0.6-0.9,
falling below 0.25 with 1000 points; with a Lyapunov exponent such runs are
``uncertain`` rather than called chaotic on ``K`` alone. For regime maps keep
>= 1000 periods and pass the Lyapunov exponent. ``K`` is unreliable too for a
periodic sequence whose period is not small against ``N/10`` (it is reported,
but the period test decides first).

Units: the QoI ``largest_lyapunov`` of ``simulate_batch`` is in 1/s (the
kernel divides the log growth by the kept time); the classifier works in nats
per mesh period (``largest_lyapunov`` times the mesh period, see
:func:`classify_dataset` / :func:`classify_batch`, which convert by the
variable's ``units`` attribute).
"""

from __future__ import annotations

import math
import types
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr
from scipy.cluster.hierarchy import fcluster, linkage

from ..common.errors import UqgearError
from ._checks import Seed, check_positive, require_variables
from .zero_one import MIN_ZERO_ONE_POINTS, zero_one_frequencies, zero_one_median

#: Regime labels :func:`classify_response` can return besides ``period-n``.
QUASI_PERIODIC = "quasi-periodic"
CHAOTIC = "chaotic"
#: A repeat seen fewer than ``min_repeats`` times: long period or quasi-periodic, not told apart.
LONG_PERIOD = "quasi_periodic_or_long_period"
#: Non-periodic run whose Lyapunov exponent and 0-1 test disagree on chaos.
UNCERTAIN = "uncertain"
#: Label of a batch sample whose Poincare points are not all finite (a failed run).
UNDETERMINED = "undetermined"
#: Every regime label, ``period-n`` standing for period-1, period-2, ... (reports enumerate these).
REGIME_LABELS: tuple[str, ...] = ("period-n", LONG_PERIOD, QUASI_PERIODIC, CHAOTIC, UNCERTAIN, UNDETERMINED)
#: Fewest repeats of a period in the kept Poincare points for a period-n label.
MIN_PERIOD_REPEATS = 10


# ----------------------------------------------------------------------------
# input checks
# ----------------------------------------------------------------------------


def _check_min_repeats(min_repeats: Any) -> int:
    if isinstance(min_repeats, bool) or not isinstance(min_repeats, (int, np.integer)) or min_repeats < 1:
        raise UqgearError(f"min_repeats: expected an integer >= 1; got {min_repeats!r}")
    return int(min_repeats)


def _check_max_period(max_period: Any) -> int:
    if isinstance(max_period, bool) or not isinstance(max_period, (int, np.integer)) or max_period < 1:
        raise UqgearError(f"max_period: expected an integer >= 1; got {max_period!r}")
    return int(max_period)


def _resolve_max_period(max_period: int | None, n_points: int) -> int:
    # Default: periods that repeat at least four times in the kept window.
    if max_period is None:
        return max(1, n_points // 4)
    return _check_max_period(max_period)


def _as_points(points: Any, name: str = "points") -> np.ndarray:
    """Poincare points as a float array of shape (n_points, n_components)."""
    array = np.asarray(points.values if isinstance(points, xr.DataArray) else points, dtype=float)
    if array.ndim == 1:
        array = array[:, np.newaxis]
    if array.ndim != 2:
        raise UqgearError(
            f"{name}: expected a 1-D sequence (x per period) or a 2-D array "
            f"(period, component); got an array of shape {array.shape}"
        )
    if array.shape[0] == 0 or array.shape[1] == 0:
        raise UqgearError(f"{name}: expected at least one Poincare point; got an empty array")
    if not np.all(np.isfinite(array)):
        raise UqgearError(f"{name}: expected finite values; got NaN or infinity (a diverged or failed run?)")
    return array


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
        rms = np.sqrt(np.mean(points**2, axis=0))
        result = np.maximum(spread, rms)
    else:
        try:
            result = np.asarray(scale, dtype=float)
        except (TypeError, ValueError):
            raise UqgearError(
                f"scale: expected one number or one per component ({n_components}); got {scale!r}"
            ) from None
        if result.ndim > 1 or result.size not in (1, n_components):
            raise UqgearError(f"scale: expected one number or one per component ({n_components}); got {scale!r}")
        result = np.broadcast_to(result.reshape(-1), (n_components,)).copy()
        if not np.all(np.isfinite(result)) or np.any(result < 0.0):
            raise UqgearError(f"scale: expected non-negative finite numbers; got {scale!r}")
    # A component that is exactly zero everywhere has no scale; any non-zero
    # difference then counts as a mismatch.
    return np.where(result > 0.0, result, np.finfo(float).tiny)


def detect_period(
    points: Any, max_period: int = 8, rtol: float = 1e-3, scale: float | Sequence[float] | np.ndarray | None = None
) -> int:
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
    rtol = check_positive("rtol", rtol)
    array = _as_points(points)
    scaled = array / _component_scale(array, scale)
    for period in range(1, max_period + 1):
        if 2 * period > scaled.shape[0]:
            break
        if np.max(np.abs(scaled[period:] - scaled[:-period])) <= rtol:
            return period
    return 0


def count_distinct_points(
    points: Any, rtol: float = 1e-3, scale: float | Sequence[float] | np.ndarray | None = None
) -> int:
    """Number of distinct Poincare points: clusters of diameter <= ``rtol * scale``.

    Complete-linkage clustering with the Chebyshev distance on the scaled
    points (``scale`` as in :func:`detect_period`).
    """
    rtol = check_positive("rtol", rtol)
    array = _as_points(points)
    if array.shape[0] == 1:
        return 1
    scaled = array / _component_scale(array, scale)
    tree = linkage(scaled, method="complete", metric="chebyshev")
    return int(np.max(fcluster(tree, t=rtol, criterion="distance")))


@dataclass(frozen=True)
class ResponseClass:
    """Regime of a steady response, with the evidence behind it.

    Attributes
    ----------
    label : str
        ``"period-n"`` (n = 1..max_period, seen at least ``min_repeats``
        times), ``"quasi_periodic_or_long_period"``, ``"quasi-periodic"``,
        ``"chaotic"`` or ``"uncertain"`` (``"undetermined"`` only in batches,
        for a failed run); :data:`REGIME_LABELS`.
    period : int
        ``n`` of a period-n response; 0 otherwise.
    evidence : Mapping
        ``distinct_points`` (int), ``zero_one_k`` (float; 0 when the ``x``
        sequence is constant within the periodicity tolerance),
        ``largest_lyapunov`` (float or None, nats per mesh period),
        ``repeat_period`` (int: the smallest repeat found, also when too long
        for a period-n label; 0 if none), ``n_points`` (int) and ``reason``
        (a short sentence).
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


def _decide(
    period: int,
    k: float,
    lyapunov: float | None,
    n_distinct: int,
    n_points: int,
    max_period: int,
    rtol: float,
    k_threshold: float,
    lyapunov_threshold: float,
    min_repeats: int,
) -> tuple[str, int, str]:
    k_chaotic = k > k_threshold
    k_text = f"0-1 test K={k:.3f} {'>' if k_chaotic else '<='} {k_threshold:g}"
    lyapunov_text = ""
    if lyapunov is not None:
        lyapunov_text = (
            f"largest Lyapunov exponent {lyapunov:.3g} per mesh period "
            f"{'>' if lyapunov > lyapunov_threshold else '<='} {lyapunov_threshold:g}"
        )
    if period > 0 and period * min_repeats <= n_points:
        reason = (
            f"the Poincare sequence repeats every {period} mesh period(s) to within "
            f"rtol={rtol:g} ({n_distinct} distinct point(s) of {n_points})"
        )
        if lyapunov is not None and lyapunov > lyapunov_threshold:
            reason += f"; note: Lyapunov exponent {lyapunov:.3g} > {lyapunov_threshold:g} disagrees"
        return f"period-{period}", period, reason
    if period > 0:
        reason = (
            f"the Poincare sequence repeats every {period} mesh periods to within rtol={rtol:g}, "
            f"but only {n_points / period:.3g} times in {n_points} kept periods (fewer than "
            f"{min_repeats}): a long period or a quasi-periodic orbit, not told apart ({k_text}"
            + (f"; {lyapunov_text}" if lyapunov_text else "")
            + ")"
        )
        return LONG_PERIOD, 0, reason
    start = f"no period <= {max_period}, {n_distinct} distinct points of {n_points}; "
    if lyapunov is not None:
        lyapunov_chaotic = lyapunov > lyapunov_threshold
        if lyapunov_chaotic == k_chaotic:
            reason = start + f"{lyapunov_text} and {k_text} agree"
            return (CHAOTIC if lyapunov_chaotic else QUASI_PERIODIC), 0, reason
        if lyapunov_chaotic:
            disagreement = "the Lyapunov exponent says chaotic, the 0-1 test says regular"
        else:
            disagreement = "the 0-1 test says chaotic, the Lyapunov exponent says regular"
        return UNCERTAIN, 0, start + f"{lyapunov_text} but {k_text}: {disagreement}"
    if k_chaotic:
        return CHAOTIC, 0, start + k_text
    return QUASI_PERIODIC, 0, start + k_text + ": bounded, regular, non-repeating"


def classify_response(
    poincare_points: Any,
    *,
    max_period: int | None = None,
    rtol: float = 1e-3,
    scale: float | Sequence[float] | np.ndarray | None = None,
    lyapunov: float | None = None,
    seed: Seed = 0,
    n_c: int = 100,
    k_threshold: float = 0.5,
    lyapunov_threshold: float = 0.01,
    min_repeats: int = MIN_PERIOD_REPEATS,
) -> ResponseClass:
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
        ``K`` above which the 0-1 test calls a non-periodic response chaotic.
    lyapunov_threshold : float
        Exponent (per mesh period) above which the Lyapunov test calls a
        non-periodic response chaotic. When ``lyapunov`` is given, the two
        tests must agree for ``chaotic`` or ``quasi-periodic``; if they
        disagree the label is ``uncertain``.
    min_repeats : int
        Fewest repeats of a period in the ``N`` points for a period-n label
        (``n <= N / min_repeats``); a repeat seen fewer times gives
        ``quasi_periodic_or_long_period``.

    Returns
    -------
    ResponseClass
        Decision rule in the module docstring.
    """
    rtol = check_positive("rtol", rtol)
    array = _as_points(poincare_points, "poincare_points")
    if array.shape[0] < MIN_ZERO_ONE_POINTS:
        raise UqgearError(
            f"poincare_points: expected at least {MIN_ZERO_ONE_POINTS} Poincare points "
            f"(keep more periods); got {array.shape[0]}"
        )
    max_period = _resolve_max_period(max_period, array.shape[0])
    min_repeats = _check_min_repeats(min_repeats)
    if lyapunov is not None:
        try:
            lyapunov = float(lyapunov)
        except (TypeError, ValueError):
            raise UqgearError(f"lyapunov: expected a number (per mesh period) or None; got {lyapunov!r}") from None
        if math.isnan(lyapunov):
            lyapunov = None
    component_scale = _component_scale(array, scale)
    return _classify_points(
        array,
        component_scale,
        zero_one_frequencies(seed, n_c),
        max_period,
        rtol,
        lyapunov,
        float(k_threshold),
        float(lyapunov_threshold),
        min_repeats,
    )


def _classify_points(
    array: np.ndarray,
    component_scale: np.ndarray,
    frequencies: np.ndarray,
    max_period: int,
    rtol: float,
    lyapunov: float | None,
    k_threshold: float,
    lyapunov_threshold: float,
    min_repeats: int = MIN_PERIOD_REPEATS,
) -> ResponseClass:
    repeat = detect_period(array, max_period, rtol, component_scale)
    n_distinct = count_distinct_points(array, rtol, component_scale)
    k = zero_one_median(array[:, 0], frequencies, constant_tolerance=rtol * component_scale[0])
    label, period, reason = _decide(
        repeat, k, lyapunov, n_distinct, array.shape[0], max_period, rtol, k_threshold, lyapunov_threshold, min_repeats
    )
    evidence = {
        "n_points": int(array.shape[0]),
        "distinct_points": n_distinct,
        "zero_one_k": k,
        "largest_lyapunov": lyapunov,
        "repeat_period": int(repeat),
        "reason": reason,
    }
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
            warnings.warn(
                "largest_lyapunov is in 1/s but the Dataset gives no mesh frequency "
                "(mesh_frequency, or pinion_speed and attrs z1); the exponent is ignored",
                stacklevel=3,
            )
            return None
        return exponent * (2.0 * math.pi / angular)
    if units in {"", "1", "1/period", "period-1", "permeshperiod", "1/meshperiod", "meshperiod-1"}:
        return exponent
    warnings.warn(
        f"largest_lyapunov has units {units!r}, expected 1/s or per mesh period; the exponent is ignored", stacklevel=3
    )
    return None


def _scale_array(x_scale: Any, angular: Any, has_velocity: bool) -> np.ndarray | None:
    if x_scale is None:
        return None
    if not has_velocity:
        return np.array([x_scale], dtype=float)
    if angular is None:
        return None
    return np.array([x_scale, x_scale * angular], dtype=float)


def classify_dataset(
    ds: xr.Dataset,
    *,
    max_period: int | None = None,
    rtol: float = 1e-3,
    seed: Seed = 0,
    n_c: int = 100,
    k_threshold: float = 0.5,
    lyapunov_threshold: float = 0.01,
    min_repeats: int = MIN_PERIOD_REPEATS,
) -> ResponseClass:
    """Classify the response of one :func:`~uqgear.physics.integration.simulate` run.

    Uses ``poincare_x`` and, when present, ``poincare_x_velocity``. The scale
    of ``x`` is the peak-to-peak of the kept ``x`` history, that of the
    velocity this times the mesh angular frequency (fallbacks as in
    :func:`detect_period` when the history is absent). A ``largest_lyapunov``
    variable (units ``s-1`` or per mesh period) joins the evidence.

    Other parameters are those of :func:`classify_response`.

    Examples
    --------
    At rated torque and 2000 rpm the response settles on a period-1 orbit:
    once the transient has passed, the Poincare points (one a mesh period)
    coincide:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> run = uqgear.simulate(design, 2000.0, 7000.0, 33e3, n_periods=200, keep_periods=100)
    >>> response = uqgear.classify_dataset(run)
    >>> response.label, response.period, response.evidence["distinct_points"]
    ('period-1', 1, 1)
    """
    require_variables(ds, ["poincare_x"], "classify_dataset")
    if set(ds["poincare_x"].dims) != {"period"}:
        raise UqgearError(
            f"classify_dataset: poincare_x should have the single dim 'period'; "
            f"it has {ds['poincare_x'].dims} (use classify_batch for a batch)"
        )
    columns = [ds["poincare_x"].values]
    has_velocity = "poincare_x_velocity" in ds.variables
    if has_velocity:
        columns.append(ds["poincare_x_velocity"].values)
    x_scale = float(np.ptp(ds["x"].values)) if "x" in ds.variables and ds["x"].size else None
    scale = _scale_array(x_scale, _mesh_angular_frequency(ds), has_velocity)
    exponent = _lyapunov_per_period(ds)
    lyapunov = None if exponent is None else float(exponent)
    return classify_response(
        np.column_stack(columns),
        max_period=max_period,
        rtol=rtol,
        scale=scale,
        lyapunov=lyapunov,
        seed=seed,
        n_c=n_c,
        k_threshold=k_threshold,
        lyapunov_threshold=lyapunov_threshold,
        min_repeats=min_repeats,
    )


def _classify_runs(
    points: list[np.ndarray],
    x_scale: np.ndarray | None,
    angular: np.ndarray | None,
    exponent: np.ndarray | None,
    has_velocity: bool,
    frequencies: np.ndarray,
    max_period: int,
    rtol: float,
    k_threshold: float,
    lyapunov_threshold: float,
    min_repeats: int = MIN_PERIOD_REPEATS,
) -> dict[str, np.ndarray]:
    """Regime, period, 0-1 test K, Lyapunov exponent per mesh period, distinct points and reason of each
    run (rows of the ``points`` components)."""
    n_runs = points[0].shape[0]
    regime = np.empty(n_runs, dtype=object)
    reason = np.empty(n_runs, dtype=object)
    response_period = np.zeros(n_runs, dtype=np.int64)
    zero_one_k = np.full(n_runs, np.nan)
    lyapunov_per_period = np.full(n_runs, np.nan)
    distinct = np.zeros(n_runs, dtype=np.int64)
    for run in range(n_runs):
        array = np.column_stack([component[run] for component in points])
        if not np.all(np.isfinite(array)):
            regime[run] = UNDETERMINED
            reason[run] = "non-finite Poincare points (a failed or diverged run)"
            continue
        scale = _scale_array(
            None if x_scale is None else x_scale[run], None if angular is None else angular[run], has_velocity
        )
        if scale is not None and not np.all(np.isfinite(scale)):
            scale = None
        component_scale = _component_scale(array, scale)
        lyapunov = None
        if exponent is not None and np.isfinite(exponent[run]):
            lyapunov = float(exponent[run])
            lyapunov_per_period[run] = lyapunov
        result = _classify_points(
            array,
            component_scale,
            frequencies,
            max_period,
            rtol,
            lyapunov,
            k_threshold,
            lyapunov_threshold,
            min_repeats,
        )
        regime[run] = result.label
        reason[run] = result.reason
        response_period[run] = result.period
        zero_one_k[run] = result.evidence["zero_one_k"]
        distinct[run] = result.evidence["distinct_points"]
    return {
        "regime": regime,
        "response_period": response_period,
        "zero_one_k": zero_one_k,
        "lyapunov_per_period": lyapunov_per_period,
        "distinct_points": distinct,
        "regime_reason": reason,
    }


def period_labels(ds: xr.Dataset, *, max_period: int | None = None, rtol: float = 1e-3) -> xr.Dataset:
    """Period detection alone for every run of a batch result: ``regime`` ``period-n`` where the Poincare points
    repeat with period n, ``aperiodic`` where they do not (``undetermined`` for non-finite points), and
    ``response_period``. The same scales and period test as :func:`classify_batch`, without the 0-1 test
    and the distinct-point count that tell the non-periodic regimes apart (several times the cost of a
    run): for grouping steady responses, where only periodic against not matters.

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [2000.0, 4000.0], "drive_torque": [7000.0, 500.0],
    ...                                         "adhesion_torque": [33e3, 500.0 * 101 / 21]})
    >>> batch = uqgear.simulate_batch(design, samples, n_periods=300, keep_periods=100)
    >>> period_labels(batch)["regime"].values.tolist()
    ['period-1', 'aperiodic']
    """
    require_variables(ds, ["poincare_x"], "period_labels")
    poincare_x = ds["poincare_x"].transpose("sample", "period")
    n = poincare_x.sizes["sample"]
    max_period = _resolve_max_period(max_period, poincare_x.sizes["period"])
    has_velocity = "poincare_x_velocity" in ds.variables
    x = poincare_x.values
    velocity = ds["poincare_x_velocity"].transpose("sample", "period").values if has_velocity else None
    x_scale = np.asarray(ds["dte_peak_to_peak"].values, float) if "dte_peak_to_peak" in ds.variables else None
    mesh_angular = _mesh_angular_frequency(ds)
    angular = (
        np.broadcast_to(np.asarray(getattr(mesh_angular, "values", mesh_angular), float), (n,))
        if mesh_angular is not None
        else None
    )
    labels = np.empty(n, dtype=object)
    periods = np.zeros(n, dtype=np.int64)
    for run in range(n):
        array = x[run][:, None] if velocity is None else np.column_stack([x[run], velocity[run]])
        if not np.all(np.isfinite(array)):
            labels[run] = UNDETERMINED
            continue
        scale = _scale_array(
            None if x_scale is None else x_scale[run], None if angular is None else angular[run], has_velocity
        )
        if scale is not None and not np.all(np.isfinite(scale)):
            scale = None
        periods[run] = detect_period(array, max_period, rtol, _component_scale(array, scale))
        labels[run] = f"period-{periods[run]}" if periods[run] > 0 else "aperiodic"
    return xr.Dataset(
        {
            "regime": ("sample", labels.astype(str), {"long_name": "period-n, aperiodic or undetermined"}),
            "response_period": ("sample", periods, {"units": "1", "long_name": "period n, 0 if not periodic"}),
        }
    )


def _regime_variables(runs: Mapping[str, Any], template: xr.DataArray) -> dict[str, xr.DataArray]:
    """The classification of every run as variables over the run dims of ``template``."""

    def build(values: np.ndarray, attrs: dict[str, str]) -> xr.DataArray:
        return template.copy(data=values.reshape(template.shape)).assign_attrs(attrs)

    labels = np.array([str(label) for label in runs["regime"]], dtype=str)
    reasons = np.array([str(text) for text in runs["regime_reason"]], dtype=str)
    return {
        "regime": build(
            labels,
            {
                "long_name": "response regime (period-n, quasi_periodic_or_long_period, "
                "quasi-periodic, chaotic, uncertain, undetermined)"
            },
        ),
        "response_period": build(
            runs["response_period"], {"units": "1", "long_name": "period n of a period-n response, 0 otherwise"}
        ),
        "zero_one_k": build(runs["zero_one_k"], {"units": "1", "long_name": "median K of the 0-1 test for chaos"}),
        "lyapunov_per_period": build(
            runs["lyapunov_per_period"],
            {
                "units": "1",
                "long_name": "largest Lyapunov exponent in nats per mesh period "
                "(largest_lyapunov in s-1 times the mesh period)",
            },
        ),
        "distinct_points": build(runs["distinct_points"], {"units": "1", "long_name": "distinct Poincare points"}),
        "regime_reason": build(reasons, {"long_name": "evidence for the regime"}),
    }


def classify_batch(
    ds: xr.Dataset,
    *,
    max_period: int | None = None,
    rtol: float = 1e-3,
    seed: Seed = 0,
    n_c: int = 100,
    k_threshold: float = 0.5,
    lyapunov_threshold: float = 0.01,
    min_repeats: int = MIN_PERIOD_REPEATS,
) -> xr.Dataset:
    """Classify every run of a :func:`~uqgear.physics.integration.simulate_batch` result.

    Every dim of ``poincare_x`` other than ``period`` (``sample``, or the
    parameter dims of a sweep) is a run. The scale of ``x`` is
    ``dte_peak_to_peak`` when present, the velocity scale that times the mesh
    angular frequency (from ``mesh_frequency``, or ``pinion_speed`` and attrs
    ``z1``); otherwise the fallbacks of :func:`detect_period`. All runs share
    the same 0-1 test frequencies, so a run's result does not depend on its
    position in the batch. A run with non-finite Poincare points is labelled
    ``"undetermined"``. A ``largest_lyapunov`` variable (units ``s-1`` or per
    mesh period) is read side by side with the 0-1 test (module docstring).

    Returns
    -------
    xarray.Dataset
        Over the run dims (coords carried along): ``regime`` (str),
        ``response_period`` (int, 0 if not period-n; not ``period``, which
        is the Poincare dim), ``zero_one_k`` (float), ``lyapunov_per_period``
        (float, nats per mesh period; NaN without an exponent),
        ``distinct_points`` (int) and ``regime_reason`` (str).

    Examples
    --------
    Rated torque at 2000 rpm against a light load at 4000 rpm, where the
    teeth separate and impact: the 0-1 test's K is near 0 for the periodic
    run and large for the irregular one:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> samples = uqgear.samples_from_mapping({"pinion_speed": [2000.0, 4000.0], "drive_torque": [7000.0, 500.0],
    ...                                         "adhesion_torque": [33e3, 500.0 * 101 / 21]})
    >>> batch = uqgear.simulate_batch(design, samples, n_periods=300, keep_periods=100)
    >>> regimes = uqgear.classify_batch(batch)
    >>> regimes["regime"].values.tolist(), regimes["response_period"].values.tolist()
    (['period-1', 'chaotic'], [1, 0])
    >>> bool(regimes["zero_one_k"][0] < 0.1), bool(regimes["zero_one_k"][1] > 0.5)
    (True, True)
    >>> (batch["fraction_separation"] > 0).values.tolist()
    [False, True]
    """
    require_variables(ds, ["poincare_x"], "classify_batch")
    poincare_x = ds["poincare_x"]
    if "period" not in poincare_x.dims:
        raise UqgearError(f"classify_batch: poincare_x should have a 'period' dim; it has {poincare_x.dims}")
    rtol = check_positive("rtol", rtol)
    if poincare_x.sizes["period"] < MIN_ZERO_ONE_POINTS:
        raise UqgearError(
            f"classify_batch: expected at least {MIN_ZERO_ONE_POINTS} Poincare periods "
            f"(keep_periods); got {poincare_x.sizes['period']}"
        )
    max_period = _resolve_max_period(max_period, poincare_x.sizes["period"])
    min_repeats = _check_min_repeats(min_repeats)
    frequencies = zero_one_frequencies(seed, n_c)
    run_dims = [dim for dim in poincare_x.dims if dim != "period"]
    template = poincare_x.isel(period=0, drop=True).transpose(*run_dims)
    has_velocity = "poincare_x_velocity" in ds.variables

    def per_run(value: xr.DataArray | float) -> np.ndarray:
        # One number per run, in the flattened run order of the points.
        values = (
            value.broadcast_like(template).transpose(*run_dims).values if isinstance(value, xr.DataArray) else value
        )
        return np.broadcast_to(np.asarray(values, dtype=float), template.shape).reshape(-1)

    points = [poincare_x.transpose(*run_dims, "period").values.reshape(-1, poincare_x.sizes["period"])]
    if has_velocity:
        points.append(ds["poincare_x_velocity"].transpose(*run_dims, "period").values.reshape(points[0].shape))
    x_scale = per_run(ds["dte_peak_to_peak"]) if "dte_peak_to_peak" in ds.variables else None
    mesh_angular = _mesh_angular_frequency(ds)
    angular = per_run(mesh_angular) if mesh_angular is not None else None
    per_period = _lyapunov_per_period(ds)
    exponent = per_run(per_period) if per_period is not None else None

    runs = _classify_runs(
        points,
        x_scale,
        angular,
        exponent,
        has_velocity,
        frequencies,
        max_period,
        rtol,
        float(k_threshold),
        float(lyapunov_threshold),
        min_repeats,
    )

    return xr.Dataset(
        _regime_variables(runs, template),
        attrs={
            "max_period": max_period,
            "rtol": rtol,
            "k_threshold": float(k_threshold),
            "lyapunov_threshold": float(lyapunov_threshold),
            "min_repeats": min_repeats,
            "zero_one_n_c": int(frequencies.size),
        },
    )
