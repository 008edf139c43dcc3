"""The rig's own gears, order by order: the pitch-error allowance scaled to what the rig shows.

The pitch-error allowance (:mod:`.pitch_errors`) is the mean square change
a random gear of the stated classes makes to each line. A rig's gears are
one draw, the same in every run. Their tooth positions' j-th Fourier
coefficient over a revolution, E_j, drives the shaft line of order j and the
sidebands +-j around every mesh harmonic of that gear, in every run and
channel, so the lines of one (gear, order) group are off together by one
shared factor, |E_j|^2 over its ensemble mean. That factor is exponentially
distributed (E_j sums many independent pitch deviations) and spreads further
with the class: an allowance held at the mean is far too wide for a gear that
came out fine at an order, and too narrow for one that came out coarse.

So each group's share of the allowance is scaled by the factor that makes
the rig's lines most likely (Rice likelihood of the line amplitudes with
noise, the model's own relative and absolute errors, and the scaled
allowance), within the range pitch errors of the stated classes give that
group: quantiles (``order_factor_quantiles`` of
:class:`~uqgear.diagnosis.DiagnosisSettings`) of |E_j|^2 over many draws of
the tooth positions alone (no simulation), relative to the mean over the
draws the allowance simulated. A rig whose gear shows more at an order than
such gears can is still charged with the excess; below the range the
allowance is not shrunk further. Each model (the nominal one and every fit
with effects) gets its own factors from its own residuals, so an effect that
explains a group's lines is not charged for the nominal model's widening.

The first order is scaled like the others: a gear's first-order pitch error
is a run-out exactly as an eccentric shaft's, so a run-out within what the
classes' gears make is not evidence of an eccentricity; only its
mesh-stiffness modulation can be (docs/model/unmodelled-effects.md section 6.4, "The rig's own
gears, order by order"; the campaigns behind this choice are in
docs/validation/diagnosis.md).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.special

from ...physics.design import Design
from ...physics.pitch_errors import PitchErrors, draw_in_classes, order_powers
from ..case import RigCase
from ..discrepancy import absolute_model_error
from ..settings import DEFAULT_SETTINGS

#: Shaft orders whose groups are scaled (the orders the features hold: shaft lines and sidebands 1..3).
ORDERS: tuple[int, ...] = (1, 2, 3)
# Draws of the tooth positions alone (no simulation) that give those quantiles.
_BOUND_DRAWS = 4000
# Candidate factors per decade between the bounds (a log grid; the likelihood is smooth in the factor).
_GRID_PER_DECADE = 24
_GEARS = ("pinion", "gear")


def _mean_powers(drawn_errors: Sequence[PitchErrors]) -> dict[str, np.ndarray]:
    """Per gear, the mean |E_j|^2 (one per order of :data:`ORDERS`) over pitch-error draws."""
    return {gear: np.mean([order_powers(getattr(errors, gear)) for errors in drawn_errors], axis=0) for gear in _GEARS}


def drawn_amplitudes(drawn_errors: Sequence[PitchErrors]) -> dict[tuple[str, int], float]:
    """Per (gear, order): the RMS |E_j| over the draws the allowance simulated (m, along the line of action)."""
    return {
        (gear, order): float(math.sqrt(power))
        for gear, powers in _mean_powers(drawn_errors).items()
        for order, power in zip(ORDERS, powers)
    }


def class_powers(
    design: Design,
    classes: tuple[float, float],
    drawn_errors: Sequence[PitchErrors],
    rng: np.random.Generator,
    *,
    draws: int = _BOUND_DRAWS,
) -> dict[tuple[str, int], tuple[np.ndarray, float]]:
    """Per (gear, order): |E_j|^2 of ``draws`` gears of ``classes`` (tooth positions only), and the allowance's mean.

    Levels are drawn uniformly over the classes (tolerances grow by sqrt(2)
    a class), as the allowance spreads its draws. The spread of the gears
    the stated classes make, against the allowance's own power
    (:func:`bounds_of`, :func:`share_below`).
    """
    powers = {gear: np.empty((draws, len(ORDERS))) for gear in _GEARS}
    for index in range(draws):
        drawn = draw_in_classes(design, classes, rng.random(), rng)
        for gear in _GEARS:
            powers[gear][index] = order_powers(getattr(drawn, gear))
    return {
        (gear, order): (powers[gear][:, position], max(float(allowed[position]), 1e-300))
        for gear, allowed in _mean_powers(drawn_errors).items()
        for position, order in enumerate(ORDERS)
    }


def bounds_of(
    spread: Mapping[tuple[str, int], tuple[np.ndarray, float]],
    quantiles: tuple[float, ...] = DEFAULT_SETTINGS.pitch.order_factor_quantiles,
) -> dict[tuple[str, int], tuple[float, float]]:
    """Per group, ``quantiles`` of :func:`class_powers` over the allowance's mean: the range its factor is held to."""
    bounds = {}
    for key, (powers, mean) in spread.items():
        low, high = np.quantile(powers, quantiles)
        bounds[key] = (float(low) / mean, float(high) / mean)
    return bounds


def factor_bounds(
    design: Design,
    classes: tuple[float, float],
    drawn_errors: Sequence[PitchErrors],
    rng: np.random.Generator,
    *,
    quantiles: tuple[float, ...] = DEFAULT_SETTINGS.pitch.order_factor_quantiles,
    draws: int = _BOUND_DRAWS,
) -> dict[tuple[str, int], tuple[float, float]]:
    """Per (gear, order): the range of |E_j|^2 that gears of ``classes`` give, over the allowance draws' mean."""
    return bounds_of(class_powers(design, classes, drawn_errors, rng, draws=draws), quantiles)


def share_below(
    spread: Mapping[tuple[str, int], tuple[np.ndarray, float]], factors: Mapping[tuple[str, int], float]
) -> dict[tuple[str, int], float]:
    """Per group, the share of gears of the stated classes whose |E_j| is below the one a fit read (its factor)."""
    return {
        key: float(np.mean(spread[key][0] < factor * spread[key][1]))
        for key, factor in factors.items()
        if key in spread
    }


def driving_order(order: float, teeth: int, orders_per_revolution: float) -> int | None:
    """The order j of a gear's tooth-position coefficients E_j that drives a line at ``order`` pinion orders.

    A gear's pitch errors repeat every revolution and are sampled once a
    tooth, so the line at n z + j (z teeth, any n) is driven by E_j, and
    E_(z - j) is the conjugate of E_j: the line's driving order is its order
    in the gear's revolutions modulo z, folded to at most z / 2. None where
    the line is not a whole order of that gear.

    Examples
    --------
    The first motor line of the locomotive design (3 pole pairs: 18 pinion
    orders) is the pinion's third lower sideband of the first mesh harmonic
    (z1 = 21), and no whole order of the gear (z2 = 101):

    >>> driving_order(18.0, 21, 1.0), driving_order(18.0, 101, 21 / 101)
    (3, None)
    """
    in_revolutions = order / orders_per_revolution
    whole = round(in_revolutions)
    if abs(in_revolutions - whole) > 1e-9 * max(1.0, abs(in_revolutions)):
        return None
    remainder = whole % teeth
    return min(remainder, teeth - remainder)


def line_groups(case: RigCase) -> dict[tuple[str, int], np.ndarray]:
    """Positions, among the layout's line features, of each (gear, order) group: shaft line j and sidebands +-j.

    A motor line (6 p m pinion orders) that falls on a gear's line of a
    scaled order belongs to that group as well: it is the same spectral line
    (on the locomotive design the first motor line is the pinion's third
    lower sideband of the first mesh harmonic, :func:`driving_order`), and
    the gear's errors drive it by the same factor.
    """
    design = case.design
    revolution = {"pinion": (design.z1, 1.0), "gear": (design.z2, design.z1 / design.z2)}
    orders = {definition.name: definition.order for definition in case.processors[0].definitions}
    lines = [
        (name, family)
        for name, family, kind in zip(case.layout.names, case.layout.families, case.layout.kinds)
        if kind == "line"
    ]
    groups: dict[tuple[str, int], list[int]] = {}
    for position, (name, family) in enumerate(lines):
        for gear in _GEARS:
            if family == "motor_line":
                order = driving_order(orders[name], *revolution[gear])
                if order in ORDERS:
                    groups.setdefault((gear, order), []).append(position)
                continue
            if family == f"shaft_{gear}":
                found = re.search(r"(\d+)$", name)
            elif family == f"sideband_{gear}":
                found = re.search(r"[+-](\d+)$", name)
            else:
                continue
            if found is None:  # an internal invariant: the layout names every shaft line and sideband so
                raise ValueError(f"{name!r} is not a shaft line or sideband feature name")
            order = int(found.group(1))
            if order in ORDERS:
                groups.setdefault((gear, order), []).append(position)
    return {key: np.array(positions) for key, positions in groups.items()}


def _rice_log_density(observed: np.ndarray, nu: np.ndarray, variance: np.ndarray) -> np.ndarray:
    """Log density of a Rice amplitude (per-quadrature variance ``variance``), stable for large nu/sigma."""
    argument = observed * nu / variance
    return (
        np.log(np.maximum(observed, 1e-300) / variance)
        - (observed - nu) ** 2 / (2.0 * variance)
        + np.log(np.maximum(scipy.special.i0e(argument), 1e-300))
    )


def fitted_factors(
    case: RigCase,
    model: np.ndarray,
    allowance_line: np.ndarray,
    base_error: Mapping[str, float],
    bounds: Mapping[tuple[str, int], tuple[float, float]],
) -> dict[tuple[str, int], float]:
    """Per (gear, order) group: the factor on the allowance's variance that makes the rig's lines most likely.

    Parameters
    ----------
    case : RigCase
    model : ndarray (n_op, n_channel, all features)
        A fitted model's noise-free features.
    allowance_line : ndarray (n_op, n_channel, line features)
        The allowance's per-quadrature line errors for that model.
    base_error : mapping
        The model error without the allowance (relative, widening, absolute).
    bounds : mapping
        Per group, the factor's range (:func:`factor_bounds`).
    """
    line = np.array(case.layout.kinds) == "line"
    observed = case.observed[..., line]
    nu = np.abs(model[..., case.layout.columns][..., line])
    usable = case.mask()[..., line] & np.isfinite(nu)
    fixed = (
        case.line_noise_sigma()[..., line] ** 2
        + (base_error["line"] * nu) ** 2
        + np.broadcast_to(absolute_model_error(base_error, "line"), nu.shape) ** 2
    )
    factors = {}
    for key, positions in line_groups(case).items():
        low, high = bounds[key]
        chosen = usable[..., positions]
        if not chosen.any() or not high > low:
            factors[key] = 1.0
            continue
        x = observed[..., positions][chosen]
        mean = nu[..., positions][chosen]
        base = fixed[..., positions][chosen]
        extra = allowance_line[..., positions][chosen] ** 2
        count = max(2, int(math.ceil(_GRID_PER_DECADE * math.log10(high / low))) + 1)
        grid = np.geomspace(low, high, count)
        variance = np.maximum(base[None, :] + grid[:, None] * extra[None, :], 1e-300)
        likelihood = _rice_log_density(x[None, :], mean[None, :], variance).sum(axis=1)
        factors[key] = float(grid[int(np.argmax(likelihood))])
    return factors


def scaled_line_errors(
    case: RigCase, allowance_line: np.ndarray, factors: Mapping[tuple[str, int], float]
) -> np.ndarray:
    """The allowance's line errors with each group's variance scaled by its factor (other lines unchanged)."""
    scaled = np.array(allowance_line, dtype=float, copy=True)
    for key, positions in line_groups(case).items():
        scaled[..., positions] *= math.sqrt(factors.get(key, 1.0))
    return scaled


def scaled_to_rig(
    case: RigCase,
    model: np.ndarray,
    allowance_line: np.ndarray,
    base_error: Mapping[str, float],
    bounds: Mapping[tuple[str, int], tuple[float, float]],
) -> tuple[np.ndarray, dict[tuple[str, int], float]]:
    """A model's allowance line errors scaled by its own fitted factors (:func:`fitted_factors`), and the factors."""
    factors = fitted_factors(case, model, allowance_line, base_error, bounds)
    return scaled_line_errors(case, allowance_line, factors), factors


def factors_summary(
    factors: Mapping[tuple[str, int], float],
    bounds: Mapping[tuple[str, int], tuple[float, float]],
    amplitudes: Mapping[tuple[str, int], float],
    shares: Mapping[tuple[str, int], float] | None = None,
) -> dict[str, dict[str, dict[str, Any]]]:
    """JSON-ready: per gear and order, the fitted factor and its range, and what they are as |E_j| in m.

    ``amplitudes`` are the draws' RMS |E_j| (:func:`drawn_amplitudes`): the
    gear's |E_j| as the fit reads it is that times the square root of its
    factor (for the first order, the gear's run-out from its pitch errors).
    ``shares`` (:func:`share_below`), where given, become
    ``share_of_class_gears_below``.
    """
    summary: dict[str, dict[str, dict[str, Any]]] = {}
    for (gear, order), factor in sorted(factors.items()):
        low, high = bounds[(gear, order)]
        rms = amplitudes[(gear, order)]
        summary.setdefault(gear, {})[str(order)] = {
            "factor": factor,
            "low": low,
            "high": high,
            "amplitude_m": rms * math.sqrt(factor),
            "amplitude_range_m": [rms * math.sqrt(low), rms * math.sqrt(high)],
        }
        if shares is not None and (gear, order) in shares:
            summary[gear][str(order)]["share_of_class_gears_below"] = shares[(gear, order)]
    return summary


def judged_counts(
    case: RigCase, visible: dict[str, dict[int, tuple[int, int]]], nominal_model: np.ndarray, min_snr: float
) -> dict[str, dict[str, tuple[int, int]]]:
    """The gate's counts per shaft order; in order-tracked campaigns a gear's orders near their carrier apart.

    Resampling takes a share of the phase modulation of the gear's sidebands within one pinion order of
    their carrier for speed wander, a share that varies with order and run (docs/validation/diagnosis.md,
    "Healthy gears under speed wander"). Those orders are then judged on the TE's shaft lines of the gear
    (the running sum of its pitch errors, which resampling leaves in place), run by run, where the TE is
    recorded; else on their sidebands pooled.
    """
    tracked = any(bool(row.get("order_tracked")) for row in case.speed)
    ratio = case.design.z1 / case.design.z2
    model = nominal_model[..., case.layout.columns]
    with np.errstate(invalid="ignore"):
        clear = case.mask() & (case.observed - np.abs(model) >= min_snr * case.line_noise_sigma())
    te = case.channels.index("te") if "te" in case.channels else None
    judged: dict[str, dict[str, tuple[int, int]]] = {}
    for family, orders in visible.items():
        near = [order for order in orders if tracked and family == "sideband_gear" and order * ratio < 1.0]
        entries = {str(order): counts for order, counts in orders.items() if order not in near}
        for order in near if te is not None else ():
            name = f"shaft_gear{order}"
            if name in case.layout.names:
                column = case.layout.names.index(name)
                entries[f"{order} (TE shaft line)"] = (
                    int(clear[:, te, column].sum()),
                    int(case.mask()[:, te, column].sum()),
                )
        if near and te is None:
            label = f"{min(near)}-{max(near)} together" if len(near) > 1 else str(near[0])
            entries[label] = (sum(orders[o][0] for o in near), sum(orders[o][1] for o in near))
        judged[family] = entries
    return judged


__all__ = [
    "judged_counts",
    "ORDERS",
    "drawn_amplitudes",
    "class_powers",
    "factor_bounds",
    "bounds_of",
    "share_below",
    "driving_order",
    "line_groups",
    "fitted_factors",
    "scaled_line_errors",
    "scaled_to_rig",
    "factors_summary",
]
