"""Pitch errors of the manufactured gears, as model error of the nominal model.

Every manufactured gear has random single-pitch errors (ISO 1328-1 classes 6
to 8 on traction gears). They put sidebands at all shaft orders around every
mesh harmonic, on both shafts, and change the harmonics themselves: on a
healthy class-7 virtual-rig gear the nominal model (mesh-periodic, perfect
teeth) left a held-out gap of 6-7 noise units, which hid a 12 um run-out and
made every healthy control `unexplained`. A gear's own draw is unknown, so
the diagnosis does not fit per-tooth offsets (hundreds of parameters); it
takes what such errors do to each feature as model error of the nominal
model, from the model itself:

1. whether: at least :data:`MIN_VISIBLE_FRACTION` of the rig's sidebands
   of *each* shaft order 1, 2 and 3 (around every harmonic, both sides) on
   *both* shafts stand :data:`MIN_SIDEBAND_SNR` noise standard deviations
   above the nominal fit. Pitch errors light every order of both shafts; an
   effect of the library lights one shaft's (a damaged tooth), mainly the
   first order (a run-out) or none (friction, torque ripple, ...), and even
   a run-out on one shaft with a damaged tooth on the other leaves an order
   dark: a gear without pitch errors is diagnosed as before, at no cost;
2. how much: the nominal fit is simulated over the whole record without and
   with :data:`DRAWS` random pitch-error draws (ISO 1328-1 single-pitch
   deviations, :func:`uqgear.physics.pitch_errors.draw_pitch_errors`) at
   levels spread evenly over the stated classes (default 6 to 8), and read
   with the rig's own line fit: each line's mean square complex change over
   the draws, per quadrature, becomes an absolute model error of that line
   (a random phasor added to the model's: Rice statistics stay exact); for
   band and RMS features the root mean square change of their power, for the
   kurtosis that of the kurtosis.

The nominal model is then refitted with the widened error, and every
candidate is fitted and scored against it: an effect is named only where it
explains more than pitch errors of the stated classes could.
"""

from __future__ import annotations

import math
import re
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..calibration.errors import CalibrationError
from ..calibration.settings import check_pitch_classes
from ..physics.pitch_errors import PitchErrors, draw_pitch_errors
from .case import RigCase
from .errors import DiagnosisError
from .fitting import FitResult

#: ISO 1328-1 classes assumed when none are stated: the usual range of traction gears.
DEFAULT_CLASSES: tuple[float, float] = (6.0, 8.0)
#: Class of the draws, scaled to the stated classes' levels (tolerances grow by sqrt(2) a class).
REFERENCE_CLASS = 7
#: Pitch-error draws whose changes give the model error.
DRAWS = 12
# Fewest lines a gear's level is read from.
_MIN_LEVEL_LINES = 12
#: A sideband counts as visible this many noise standard deviations above the nominal fit.
MIN_SIDEBAND_SNR = 3.0
#: Fraction of each shaft's sidebands of each order 1..3 that must be visible (measured: class-7 gears 49-88 %;
#: an error-free healthy gear 0-3 %; a run-out or a damaged tooth lights one shaft, a run-out mainly order 1;
#: two effects at once up to 12 % at the order least lit; a transfer-path resonance's coloured noise 16-24 %
#: without its reference).
MIN_VISIBLE_FRACTION = 0.2
_SIDEBAND_FAMILIES = ("sideband_pinion", "sideband_gear")


def check_classes(classes: Any) -> tuple[float, float] | None:
    """Validated ISO 1328-1 class range ``(lowest, highest)``, or None (perfect gears: no allowance).

    The calibration's check (:func:`uqgear.calibration.settings.check_pitch_classes`), raising
    :class:`DiagnosisError`.
    """
    try:
        return check_pitch_classes(classes)
    except CalibrationError as exc:
        raise DiagnosisError(str(exc)) from None


@dataclass(frozen=True)
class PitchErrorAllowance:
    """What pitch errors of the stated classes add to each feature of the nominal model.

    ``levels`` holds per gear the power level of its pitch-error lines read
    off the rig (relative to the draws' mean) and the range of the draws'
    own levels it is held to (:func:`_gear_level`). ``absolute`` maps feature kinds to (n_op, n_channel, features of that
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
    levels: dict[str, dict[str, Any]]
    largest_line_ratio: float
    floor_share: float
    seconds: float

    def summary(self) -> dict[str, Any]:
        """JSON-ready record (``pitch_errors`` of ``diagnosis.json``)."""
        return {"applied": self.applied, "reason": self.reason,
                "classes": None if self.classes is None else list(self.classes),
                "visible_sidebands": {family: {str(order): {"visible": count, "of": total}
                                               for order, (count, total) in orders.items()}
                                      for family, orders in self.visible.items()},
                "draws": self.draws, "levels": self.levels,
                "largest_line_error_to_noise": self.largest_line_ratio,
                "noise_floor_share_of_lines": self.floor_share,
                "seconds": self.seconds,
                "method": "the nominal fit simulated with random ISO 1328-1 pitch-error draws over the stated "
                          "classes; each feature's mean square change becomes absolute model error"}


def _sideband_order(name: str) -> int:
    """Shaft order j of a sideband feature (``mesh{k}_sb_{shaft}{+j}``, :func:`uqgear.rig.features.feature_definitions`)."""
    return int(re.search(r"[+-](\d+)$", name).group(1))


# The lines each gear's pitch errors make: its sidebands and shaft lines (the motor sits on the pinion shaft,
# its ripple lines are pinion orders); the mesh harmonics are both gears'.
_GEAR_FAMILIES = {"pinion": ("sideband_pinion", "shaft_pinion", "motor_line"),
                  "gear": ("sideband_gear", "shaft_gear")}
# Median of |X|^2 / sigma^2 for a complex normal X of per-quadrature spread sigma (2 ln 2).
_RAYLEIGH_MEDIAN_SQUARE = 2.0 * math.log(2.0)


def _gear_level(observed: np.ndarray, model: np.ndarray, noise_sigma: np.ndarray, allowance: np.ndarray,
                changes: np.ndarray, usable: np.ndarray) -> tuple[float, float, float]:
    """One gear's pitch-error power level on the rig relative to the draws' mean, held to the draws' own range.

    The allowance treats each line as an independent random phasor, but the
    lines of one gear share its draw: a pinion whose errors came out large
    raises all of its lines at once (measured: a class-7 pinion's lines at a
    median 1.2-1.9 times the allowance's spread, its gear's at 0.6), which
    the gap adds up as if it were an effect. So the level is read off the
    rig: the factor s for which the median of observed^2 / (noise^2 + s
    allowance^2), over the gear's lines that the model does not make and
    the allowance dominates, is a Rayleigh amplitude's (2 ln 2); medians,
    so a few lines of another cause (a run-out's first order) do not move
    it. It is held to the range of the draws' own levels (the same median
    for each draw against the mean), so that no more than the stated
    classes' pitch errors could make is taken for them: an effect beyond
    that stays visible. Returns (level, lowest draw level, highest); NaN
    level where too few lines qualify.
    """
    chosen = usable & np.isfinite(observed) & (allowance >= noise_sigma) & (model < noise_sigma)
    if chosen.sum() < _MIN_LEVEL_LINES:
        return math.nan, math.nan, math.nan
    # each draw's median of |change|^2 over the mean, as a Rayleigh level (median of Exp(1): ln 2)
    draw_levels = np.median(changes[:, chosen] / np.mean(changes, axis=0)[chosen], axis=1) / math.log(2.0)
    low, high = float(np.min(draw_levels)), float(np.max(draw_levels))
    square = observed[chosen] ** 2
    noise, allowed = noise_sigma[chosen] ** 2, allowance[chosen] ** 2

    def excess(level: float) -> float:
        return float(np.median(square / (noise + level * allowed))) - _RAYLEIGH_MEDIAN_SQUARE

    # the median falls as the level grows: bisect on a log scale inside the draws' range
    if excess(low) <= 0:
        return low, low, high
    if excess(high) >= 0:
        return high, low, high
    lower, upper = math.log(low), math.log(high)
    for _ in range(40):
        middle = 0.5 * (lower + upper)
        if excess(math.exp(middle)) > 0:
            lower = middle
        else:
            upper = middle
    return math.exp(0.5 * (lower + upper)), low, high


def visible_sidebands(case: RigCase, nominal: FitResult) -> dict[str, dict[int, tuple[int, int]]]:
    """Per shaft's sideband family and shaft order: how many of the rig's sidebands stand clear of the nominal fit,
    of how many (usable runs and channels, both sides of every harmonic)."""
    columns = case.layout.columns
    model = nominal.model[..., columns]
    line_scale = np.stack([noise.line_scale[columns] for noise in case.noise])[:, None, :]
    sigma = case.noise_std[..., None] * line_scale
    usable = case.mask()
    with np.errstate(invalid="ignore"):
        clear = usable & (case.observed - np.abs(model) >= MIN_SIDEBAND_SNR * sigma)
    counts: dict[str, dict[int, tuple[int, int]]] = {}
    for family in _SIDEBAND_FAMILIES:
        orders: dict[int, list[int]] = {}
        for index, (name, kind) in enumerate(zip(case.layout.names, case.layout.families)):
            if kind == family:
                orders.setdefault(_sideband_order(name), []).append(index)
        counts[family] = {order: (int(clear[..., chosen].sum()), int(usable[..., chosen].sum()))
                          for order, chosen in sorted(orders.items())}
    return counts


def pitch_error_allowance(case: RigCase, nominal: FitResult, *, classes: tuple[float, float] | None,
                          seed: np.random.SeedSequence, draws: int = DRAWS) -> PitchErrorAllowance:
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
    draws : int
        Pitch-error draws.
    """
    started = time.perf_counter()
    visible = visible_sidebands(case, nominal)

    def not_applied(reason: str) -> PitchErrorAllowance:
        return PitchErrorAllowance(False, reason, classes, visible, 0, {}, {}, 0.0, 0.0, time.perf_counter() - started)

    if classes is None:
        return not_applied("no pitch-error classes stated: the gears are taken as perfect")
    short = [f"{family.split('_')[1]} order {order}: {count} of {total}"
             for family, orders in visible.items() for order, (count, total) in orders.items()
             if total == 0 or count < MIN_VISIBLE_FRACTION * total]
    if short or not all(visible.values()):
        return not_applied(f"the rig's first sidebands do not show pitch errors at every order on both shafts "
                           f"(clear of the nominal fit by {MIN_SIDEBAND_SNR:g} noise std: {', '.join(short)}; at "
                           f"least {100 * MIN_VISIBLE_FRACTION:.0f} % needed at each)")
    problem = nominal.problem
    rng = np.random.default_rng(seed)
    positions = (np.arange(draws) + 0.5) / draws
    levels = math.sqrt(2.0) ** (classes[0] + (classes[1] - classes[0]) * positions - REFERENCE_CLASS)
    clean = [replace(problem.run_task(nominal.vector, op), periodicity="free", phasors=True)
             for op in range(case.n_op)]
    tasks = list(clean)
    for level in levels:
        errors = draw_pitch_errors(case.design, REFERENCE_CLASS, rng)
        scaled = PitchErrors(errors.pinion * level, errors.gear * level)
        tasks += [replace(task, pitch_errors=scaled) for task in clean]
    everything = np.stack([values for values, _ in case.execute(tasks)])
    results = everything[..., case.layout.columns]
    base = results[:case.n_op]
    drawn = results[case.n_op:].reshape(draws, case.n_op, *base.shape[1:])
    # the noise floor the draws' forest of shaft-order lines alone reads as (noise-free records)
    column = case.processors[0].columns["noise_std"]
    forest = everything[case.n_op:, :, column].real.reshape(draws, case.n_op, -1)
    forest_share = np.clip(np.mean(forest ** 2, axis=0) / np.maximum(case.noise_std ** 2, 1e-300), 0.0, 1.0)
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
            noise_power = case.noise_std ** 2 * np.array([getattr(noise, moments)[0] for noise in case.noise])[:, None]
            absolute[kind] = np.sqrt(np.mean(change ** 2, axis=0) + (forest_share * noise_power)[..., None] ** 2)
        chosen = kinds == "kurtosis"
        absolute["kurtosis"] = np.sqrt(np.mean((drawn[..., chosen].real - base[..., chosen].real) ** 2, axis=0))
    absolute = {kind: np.nan_to_num(values, nan=0.0, posinf=0.0) for kind, values in absolute.items()}
    line_scale = np.stack([noise.line_scale[case.layout.columns][line] for noise in case.noise])[:, None, :]
    noise_sigma = case.noise_std[..., None] * line_scale
    levels_read = {}
    for gear, families in _GEAR_FAMILIES.items():
        chosen = np.isin(np.array(case.layout.families)[line], families)
        level, low, high = _gear_level(case.observed[..., line][..., chosen],
                                       np.abs(nominal.model[..., case.layout.columns][..., line][..., chosen]),
                                       noise_sigma[..., chosen], absolute["line"][..., chosen],
                                       np.abs(drawn[..., line][..., chosen] - base[..., line][..., chosen]) ** 2,
                                       case.mask()[..., line][..., chosen])
        levels_read[gear] = {"level": level, "draw_range": [low, high]}
        if math.isfinite(level):
            absolute["line"][..., chosen] *= math.sqrt(level)
    ratio = absolute["line"] / np.maximum(noise_sigma, 1e-300)
    finite = ratio[np.isfinite(ratio)]
    shown = ", ".join(f"{family.split('_')[1]} {sum(c for c, _ in orders.values())} of "
                      f"{sum(t for _, t in orders.values())}" for family, orders in visible.items())
    reason = (f"ISO 1328-1 classes {classes[0]:g} to {classes[1]:g}: the rig's first sidebands show pitch errors "
              f"at every order on both shafts ({shown} clear of the nominal fit)")
    return PitchErrorAllowance(True, reason, classes, visible, draws, absolute, levels_read,
                               float(finite.max()) if finite.size else 0.0,
                               float(np.median(forest_share[case.usable])) if case.usable.any() else 0.0,
                               time.perf_counter() - started)
