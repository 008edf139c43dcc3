"""Pitch errors of the manufactured gears, as model error of the nominal model (the ``pitch_errors`` allowance).

Every manufactured gear has random single-pitch errors (ISO 1328-1 classes 6
to 8 on traction gears). They put sidebands at all shaft orders around every
mesh harmonic, on both shafts, change the harmonics themselves and raise the
noise floor with their forest of lines: a perfect-gear nominal model reads
them as a gap an effect could be named for. A gear's own draw is unknown and
one offset per tooth is out of reach of the fits, so the diagnosis takes what
such errors do to each feature as model error of the nominal model, from the
model itself (docs/model/unmodelled-effects.md section 6.4):

1. whether: at least ``min_visible_fraction`` of the rig's sidebands of
   *each* shaft order 1, 2 and 3 (around every harmonic, both sides) on
   *both* shafts stand ``min_sideband_snr`` noise spreads above the nominal
   fit (:class:`~uqgear.diagnosis.DiagnosisSettings`). Pitch errors light
   every order of both shafts; an effect of the library lights one shaft's
   (a damaged tooth), mainly the first order (a run-out) or none, so a gear
   without pitch errors is diagnosed as before, at no cost;
2. how much: the nominal fit is simulated over the whole record without and
   with ``pitch_draws`` random pitch-error draws
   (:func:`uqgear.physics.pitch_errors.draw_in_classes`) at levels spread
   evenly over the stated classes, and read with the rig's own line fit:
   each line's mean square complex change over the draws, per quadrature,
   becomes an absolute model error of that line (a random phasor added to the
   model's: Rice statistics stay exact); for band and RMS features the root
   mean square change of their power, plus the share of the noise power the
   draws' lines alone read as; for the kurtosis the root mean square change
   of the kurtosis. Each (gear, order) group of lines is then scaled to the
   rig's own gears (:mod:`.pitch_orders`).

The nominal model is then refitted with the widened error, and every
candidate is fitted and scored against its own model's allowance
(:func:`with_own_allowance`): an effect is named only where it explains more
than pitch errors of the stated classes could.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ...physics.pitch_errors import DEFAULT_CLASSES, PitchErrors, draw_in_classes, run_out_bounds
from ...physics.pitch_errors import check_classes as check_tolerance_classes
from ...uq.seeds import child_seed
from ..case import FeatureModelError, RigCase
from ..effects import run_out_family
from ..errors import DiagnosisError
from ..fit_problem import FitProblem, robust_cost
from ..fitting import FitResult, fit
from ..settings import DEFAULT_SETTINGS, DiagnosisSettings
from .pitch_orders import (
    bounds_of,
    class_powers,
    drawn_amplitudes,
    factors_summary,
    judged_counts,
    scaled_to_rig,
    share_below,
)

_SIDEBAND_FAMILIES = ("sideband_pinion", "sideband_gear")
# Draws of the tooth positions alone (no simulation) that give the run-out bounds.
_RUN_OUT_DRAWS = 4000


def check_classes(classes: Any) -> tuple[float, float] | None:
    """Validated ISO 1328-1 class range ``(lowest, highest)``, or None (perfect gears: no allowance).

    :func:`uqgear.physics.pitch_errors.check_classes`, raising :class:`DiagnosisError`.
    """
    return check_tolerance_classes(classes, error=DiagnosisError)


@dataclass(frozen=True)
class PitchErrorAllowance:
    """What pitch errors of the stated classes add to each feature of the nominal model.

    ``absolute`` maps feature kinds to (n_op, n_channel, features of that
    kind) absolute model errors (:class:`~uqgear.diagnosis.case.FeatureModelError`);
    empty where not applied. ``floor_share`` is the median share of the
    rig's noise floor estimate that the draws' lines alone would read as
    (their forest of shaft-order lines raises the floor a record's noise is
    read from).
    """

    applied: bool
    reason: str
    classes: tuple[float, float] | None
    visible: dict[str, dict[int, tuple[int, int]]]
    draws: int
    absolute: dict[str, np.ndarray]
    largest_line_ratio: float
    floor_share: float
    seconds: float
    run_out_bound: dict[str, float] = field(default_factory=dict)
    # the scaled draws simulated (a fit with effects is simulated with the same ones: :func:`allowance_for_fit`)
    drawn_errors: tuple[PitchErrors, ...] = field(default=(), repr=False, compare=False)
    # per (gear, shaft order): the range of the rig's own share of the allowance, and the nominal fit's
    # factor in it (:mod:`.pitch_orders`); ``absolute`` holds the lines scaled by it
    factor_bounds: dict[tuple[str, int], tuple[float, float]] = field(default_factory=dict)
    factors: dict[tuple[str, int], float] = field(default_factory=dict)
    # per group, the share of gears of the stated classes with a smaller |E_j| than the nominal fit read
    class_shares: dict[tuple[str, int], float] = field(default_factory=dict)
    #: Its entry in ``diagnosis.json``.
    key: ClassVar[str] = "pitch_errors"

    def apply(self, case: RigCase) -> RigCase:
        """The case with this allowance added to its model error (the case itself where it is not applied)."""
        if not self.applied:
            return case
        return replace(
            case,
            model_error_before_allowance=case.model_error,
            pitch_allowance=self,
            model_error=FeatureModelError.combined(case.model_error, self.absolute),
        )

    def summary(self) -> dict[str, Any]:
        """JSON-ready record (``pitch_errors`` of ``diagnosis.json``)."""
        return {
            "applied": self.applied,
            "reason": self.reason,
            "classes": None if self.classes is None else list(self.classes),
            "visible_sidebands": {
                family: {str(order): {"visible": count, "of": total} for order, (count, total) in orders.items()}
                for family, orders in self.visible.items()
            },
            "draws": self.draws,
            "largest_line_error_to_noise": self.largest_line_ratio,
            "noise_floor_share_of_lines": self.floor_share,
            "run_out_within_pitch_errors_m": dict(self.run_out_bound),
            "order_factors": factors_summary(
                self.factors, self.factor_bounds, drawn_amplitudes(self.drawn_errors), self.class_shares
            )
            if self.factors
            else {},
            "seconds": self.seconds,
            "method": "the nominal fit simulated with random ISO 1328-1 pitch-error draws over the stated "
            "classes; each feature's mean square change becomes absolute model error",
        }


def _sideband_order(name: str) -> int:
    """Shaft order j of a sideband feature, ``mesh{k}_sb_{shaft}{+j}`` (rig.features.feature_definitions)."""
    found = re.search(r"[+-](\d+)$", name)
    if found is None:  # an internal invariant: the layout names every sideband so
        raise ValueError(f"{name!r} is not a sideband feature name")
    return int(found.group(1))


def visible_sidebands(
    case: RigCase, nominal: FitResult, *, min_snr: float = DEFAULT_SETTINGS.pitch.min_sideband_snr
) -> dict[str, dict[int, tuple[int, int]]]:
    """Per shaft's sideband family and shaft order: how many of the rig's sidebands stand ``min_snr`` noise
    spreads clear of the nominal fit, of how many (usable runs and channels, both sides of every harmonic)."""
    model = nominal.model[..., case.layout.columns]
    sigma = case.line_noise_sigma()
    usable = case.mask()
    with np.errstate(invalid="ignore"):
        clear = usable & (case.observed - np.abs(model) >= min_snr * sigma)
    counts: dict[str, dict[int, tuple[int, int]]] = {}
    for family in _SIDEBAND_FAMILIES:
        orders: dict[int, list[int]] = {}
        for index, (name, kind) in enumerate(zip(case.layout.names, case.layout.families)):
            if kind == family:
                orders.setdefault(_sideband_order(name), []).append(index)
        counts[family] = {
            order: (int(clear[..., chosen].sum()), int(usable[..., chosen].sum()))
            for order, chosen in sorted(orders.items())
        }
    return counts


def pitch_error_allowance(
    case: RigCase,
    nominal: FitResult,
    *,
    classes: tuple[float, float] | None,
    seed: np.random.SeedSequence,
    settings: DiagnosisSettings = DEFAULT_SETTINGS,
) -> PitchErrorAllowance:
    """The model error that pitch errors of ``classes`` add to the nominal fit's features (module docstring).

    Parameters
    ----------
    case : RigCase
        The prepared campaign.
    nominal : FitResult
        The nominal fit: its parameters and T2 are simulated.
    classes : (float, float) or None
        ISO 1328-1 flank tolerance classes the gears are made to (None: no allowance).
    seed : SeedSequence
        Source of the draws.
    settings : DiagnosisSettings
        The gate (``min_sideband_snr``, ``min_visible_fraction``), the draws
        (``pitch_draws``) and the run-out bound's quantile (``run_out_quantile``).
    """
    started = time.perf_counter()
    draws, fraction = settings.pitch.pitch_draws, settings.pitch.min_visible_fraction
    visible = visible_sidebands(case, nominal, min_snr=settings.pitch.min_sideband_snr)

    def not_applied(reason: str) -> PitchErrorAllowance:
        return PitchErrorAllowance(False, reason, classes, visible, 0, {}, 0.0, 0.0, time.perf_counter() - started)

    if classes is None:
        return not_applied("no pitch-error classes stated: the gears are taken as perfect")
    short = [
        f"{family.split('_')[1]} order {order}: {count} of {total}"
        for family, orders in judged_counts(case, visible, nominal.model, settings.pitch.min_sideband_snr).items()
        for order, (count, total) in orders.items()
        if total == 0 or count < fraction * total
    ]
    if short or not all(visible.values()):
        return not_applied(
            f"the rig's first sidebands do not show pitch errors at every order on both shafts "
            f"(clear of the nominal fit by {settings.pitch.min_sideband_snr:g} noise std: {', '.join(short)}; "
            f"at least {100 * fraction:.0f} % needed at each)"
        )
    rng = np.random.default_rng(seed)
    bounds = run_out_bounds(
        case.design,
        classes,
        np.random.default_rng(child_seed(seed, 0)),
        quantile=settings.pitch.run_out_quantile,
        draws=_RUN_OUT_DRAWS,
    )
    positions = (np.arange(draws) + 0.5) / draws
    drawn_errors = [draw_in_classes(case.design, classes, position, rng) for position in positions]
    absolute, forest_share = allowance_errors(case, nominal.problem, nominal.vector, drawn_errors)
    # the rig's gears are one draw: each (gear, order) group's share scaled to what the rig shows
    spread = class_powers(case.design, classes, drawn_errors, np.random.default_rng(child_seed(seed, 1)))
    ranges = bounds_of(spread, settings.pitch.order_factor_quantiles)
    absolute["line"], factors = scaled_to_rig(case, nominal.model, absolute["line"], case.model_error, ranges)
    line = np.array(case.layout.kinds) == "line"
    ratio = absolute["line"] / np.maximum(case.line_noise_sigma()[..., line], 1e-300)
    finite = ratio[np.isfinite(ratio)]
    shown = ", ".join(
        f"{family.split('_')[1]} {sum(c for c, _ in orders.values())} of {sum(t for _, t in orders.values())}"
        for family, orders in visible.items()
    )
    reason = (
        f"ISO 1328-1 classes {classes[0]:g} to {classes[1]:g}: the rig's first sidebands show pitch errors "
        f"at every order on both shafts ({shown} clear of the nominal fit)"
    )
    return PitchErrorAllowance(
        True,
        reason,
        classes,
        visible,
        draws,
        absolute,
        float(finite.max()) if finite.size else 0.0,
        float(np.median(forest_share[case.usable])) if case.usable.any() else 0.0,
        time.perf_counter() - started,
        bounds,
        tuple(drawn_errors),
        ranges,
        factors,
        share_below(spread, factors),
    )


def allowance_errors(
    case: RigCase, problem: FitProblem, vector: np.ndarray, drawn_errors: Sequence[PitchErrors]
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Each feature's absolute model error: the model at ``vector`` simulated without and with each pitch-error draw.

    Parameters
    ----------
    case : RigCase
    problem : FitProblem
        The model (its effects act in every run).
    vector : ndarray
        Its optimiser vector (parameters and T2 positions).
    drawn_errors : sequence of PitchErrors
        The draws, already scaled to their classes.

    Returns
    -------
    absolute : dict
        Per feature kind, (n_op, n_channel, features of that kind) errors (module docstring).
    forest_share : ndarray (n_op, n_channel)
        The share of each record's noise power that the draws' forest of lines alone reads as.
    """
    clean = [replace(problem.run_task(vector, op), periodicity="free", reduction="phasors") for op in range(case.n_op)]
    tasks = list(clean)
    for errors in drawn_errors:
        tasks += [replace(task, pitch_errors=errors) for task in clean]
    draws = len(drawn_errors)
    everything = np.stack([values for values, _ in case.execute(tasks)])
    results = everything[..., case.layout.columns]
    base = results[: case.n_op]
    drawn = results[case.n_op :].reshape(draws, case.n_op, *base.shape[1:])
    # the noise floor the draws' forest of shaft-order lines alone reads as (noise-free records)
    column = case.processors[0].columns["noise_std"]
    forest = everything[case.n_op :, :, column].real.reshape(draws, case.n_op, -1)
    forest_share = np.clip(np.mean(forest**2, axis=0) / np.maximum(case.noise_std**2, 1e-300), 0.0, 1.0)
    kinds = np.array(case.layout.kinds)
    absolute: dict[str, np.ndarray] = {}
    with np.errstate(invalid="ignore"):
        line = kinds == "line"
        # per quadrature: half the mean square complex change
        absolute["line"] = np.sqrt(0.5 * np.mean(np.abs(drawn[..., line] - base[..., line]) ** 2, axis=0))
        for kind, moments in (("band", "band_power"), ("rms", "total_power")):
            chosen = kinds == kind
            change = np.abs(drawn[..., chosen]) ** 2 - np.abs(base[..., chosen]) ** 2
            # the rig's noise power is read from a floor the forest raises: up to that share of it may be
            # the lines', not noise, so the noise power these features expect is that uncertain too
            unit_power = np.array([getattr(noise, moments)[0] for noise in case.noise])[:, None]
            noise_power = case.noise_std_for(kind) ** 2 * unit_power
            absolute[kind] = np.sqrt(np.mean(change**2, axis=0) + (forest_share * noise_power)[..., None] ** 2)
        chosen = kinds == "kurtosis"
        absolute["kurtosis"] = np.sqrt(np.mean((drawn[..., chosen].real - base[..., chosen].real) ** 2, axis=0))
    absolute = {kind: np.nan_to_num(values, nan=0.0, posinf=0.0) for kind, values in absolute.items()}
    return absolute, forest_share


def allowance_for_fit(
    case: RigCase, result: FitResult, allowance: PitchErrorAllowance, base_error: Mapping[str, float]
) -> FeatureModelError:
    """The model error of a fit with effects: ``base_error`` plus what the allowance's draws do to *its* features.

    What pitch errors do to the features depends on the model they act in:
    sliding friction, which reverses at the pitch point, switches at
    instants the pitch errors shift tooth by tooth and raises sidebands the
    nominal model's draws do not. Scored with the nominal model's allowance,
    a fit with such an effect would be charged with sidebands that only its
    own combination with pitch errors makes, and an effect with a line there
    credited with them. The fit is simulated with the same draws (the same
    gears' errors the nominal allowance used), so the two models' held-out
    densities are compared on equal terms (docs/model/unmodelled-effects.md section 6.4, "Each
    model its own allowance").
    """
    absolute, _ = allowance_errors(case, result.problem, result.vector, allowance.drawn_errors)
    if allowance.factor_bounds:
        # its own share of the rig's gears' errors, from its own residuals
        absolute["line"], _ = scaled_to_rig(case, result.model, absolute["line"], base_error, allowance.factor_bounds)
    return FeatureModelError.combined(base_error, absolute)


def with_own_allowance(
    result: FitResult, *, max_evaluations: int = DEFAULT_SETTINGS.screening.full_fit_evaluations
) -> FitResult:
    """A fit with effects refitted with its own model's pitch-error allowance (:func:`allowance_for_fit`).

    Unchanged when the case has no allowance applied or the fit has no
    effect. The refit starts at the fit's optimum (the allowance mostly
    re-weights a few sidebands); its problem holds the new model error,
    which later fits on top of it (forward selection) start from.
    """
    case = result.problem.case
    allowance = case.pitch_allowance
    if not isinstance(allowance, PitchErrorAllowance) or not allowance.applied or not result.problem.candidates:
        return result
    base_error = case.model_error_before_allowance
    own = allowance_for_fit(case, result, allowance, case.model_error if base_error is None else base_error)
    refit = fit(
        result.problem.with_model_error(own),
        [result.vector],
        free=result.free,
        max_evaluations=max_evaluations,
        tolerance=1e-3,
    )
    return refit.after(result)


def modulation_gain(result: FitResult, parameter: str) -> float:
    """How much worse a run-out's fit is with its mesh-stiffness modulation off (robust cost).

    Pitch errors make a first-order run-out (the cumulative pitch error) but
    no modulation of the mesh stiffness: a fit that is clearly worse with its
    modulation ``parameter`` (``FAMILY.PARAMETER``, the family's
    :attr:`~uqgear.diagnosis.effects.RunOut.modulation`; ``eccentricity.kappa``
    in the library) at its lower bound ("absent") holds evidence of an
    eccentric shaft that the gears' pitch errors cannot give, whatever its
    run-out. The cost is taken with the fit's own model error (its
    pitch-error allowance), like the effect gain. NaN for a fit without that
    parameter.
    """
    problem = result.problem
    names = [spec.name for spec in problem.specs]
    if parameter not in names:
        return math.nan
    index = names.index(parameter)
    vector = np.array(result.vector, dtype=float)
    vector[index] = problem.lower[index]
    model, _ = problem.model_features([vector])
    off = robust_cost(problem.residual_vector(problem.discrepancy(model[0])[0], vector))
    return float(off - result.cost)


def first_order_reads(allowance: PitchErrorAllowance | None) -> dict[str, tuple[float, float]]:
    """Per gear: the run-out its first-order lines read as (m, along the line of action), and its share among gears.

    The run-out is the allowance draws' RMS |E_1| scaled by the factor the
    nominal fit read off the rig (:func:`.pitch_orders.scaled_to_rig`); the
    share places it among gears of the stated classes
    (:func:`.pitch_orders.share_below`). Empty where no allowance was applied.
    """
    if allowance is None or not allowance.applied or not allowance.class_shares:
        return {}
    amplitudes = drawn_amplitudes(allowance.drawn_errors)
    return {
        shaft: (amplitudes[(shaft, 1)] * math.sqrt(allowance.factors[(shaft, 1)]), allowance.class_shares[(shaft, 1)])
        for shaft in ("pinion", "gear")
        if (shaft, 1) in allowance.class_shares
    }




def run_outs_not_told_apart(
    allowance: PitchErrorAllowance | None,
    named_shafts: Sequence[str],
    *,
    effect: str | None = None,
    share_threshold: float = DEFAULT_SETTINGS.pitch.large_run_out_share,
) -> list[dict[str, Any]]:
    """Gears whose first-order errors read as a run-out large for their classes, with no eccentricity named there.

    A gear's first-order pitch error is a run-out exactly as an eccentric
    shaft's (both move its shaft line 1 in the same way, and its first
    sidebands mostly through the rest of its errors), so a run-out of a
    size the stated classes make is the gear's own to the diagnosis
    (:mod:`.pitch_orders`). Where the nominal fit read the gear's first order
    as larger than ``share_threshold`` of such gears have, a shaft
    run-out may be part of it: the diagnosis cannot tell, and says so
    rather than naming an eccentricity or nothing.

    Parameters
    ----------
    allowance : PitchErrorAllowance or None
        The case's allowance (nothing is reported where none was applied).
    named_shafts : sequence of str
        Shafts ("pinion", "gear") whose eccentricity was named.
    effect : str, optional
        The effect a shaft run-out is named as (default: the first registered family with a
        :attr:`~uqgear.diagnosis.effects.EffectFamily.run_out` hook, ``eccentricity``).
    share_threshold : float
        The share of the classes' gears above which a gear's first-order reading is reported.

    Returns
    -------
    list of dict
        Per such gear: ``effect``, ``shaft``, ``run_out_m``
        (the |E_1| the nominal fit read, along the line of action),
        ``share_of_class_gears_below``, ``classes``, ``run_out_95_m`` (the
        classes' 95 % first-order run-out) and ``reason``.
    """
    if allowance is None or allowance.classes is None:
        return []
    if effect is None:
        # the library's run-out family is always registered
        effect = run_out_family().name  # type: ignore[union-attr]
    low, high = allowance.classes
    found = []
    for shaft, (run_out, share) in first_order_reads(allowance).items():
        if share < share_threshold or shaft in named_shafts:
            continue
        found.append(
            {
                "effect": effect,
                "shaft": shaft,
                "run_out_m": run_out,
                "share_of_class_gears_below": share,
                "classes": [low, high],
                "run_out_95_m": allowance.run_out_bound.get(shaft),
                "reason": f"the {shaft}'s first-order lines read as a run-out of {1e6 * run_out:.3g} um along the line "
                f"of action, more than {100 * share:.0f} % of ISO 1328-1 class {low:g} to {high:g} "
                f"{shaft}s have from their pitch errors: an eccentric {shaft} shaft may be part of it, and "
                f"the lines cannot tell a shaft's run-out from the {shaft}'s own first-order errors here "
                f"(a run-out measurement of the {shaft} can)",
            }
        )
    return found


__all__ = [
    "DEFAULT_CLASSES",
    "PitchErrorAllowance",
    "check_classes",
    "run_out_bounds",
    "visible_sidebands",
    "pitch_error_allowance",
    "allowance_errors",
    "allowance_for_fit",
    "with_own_allowance",
    "modulation_gain",
    "first_order_reads",
    "run_outs_not_told_apart",
]
