"""Held-out scoring: the gap metric, its bootstrap, and the scores of a candidate on held-out runs."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.stats

from .candidates import Candidate
from .fitting import FitResult, parameter_intervals
from .heldout import HeldOut
from .settings import DEFAULT_SETTINGS

# ---------------------------------------------------------------------------------------------- gap metric

GAP_METRIC = "excess_rms_standardised_discrepancy_capped_at_10"
# Each feature's squared discrepancy counts at most this much, so that a few
# features thousands of sigmas off do not decide alone how far a gap shrank.
_GAP_CAP = 10.0
# E[min(z^2, cap^2)] for z ~ N(0, 1): the noise level the gap is measured from.
GAP_NOISE_LEVEL = float(
    1.0
    - 2.0 * (_GAP_CAP * scipy.stats.norm.pdf(_GAP_CAP) + scipy.stats.norm.sf(_GAP_CAP))
    + 2.0 * _GAP_CAP**2 * scipy.stats.norm.sf(_GAP_CAP)
)


def capped_squares(z: np.ndarray) -> np.ndarray:
    """min(z^2, cap^2) (NaN stays NaN)."""
    return np.minimum(np.asarray(z, dtype=float) ** 2, _GAP_CAP**2)


def gap_metric(z: np.ndarray) -> float:
    """The gap: RMS standardised discrepancy in excess of noise.

    sqrt(max(mean(min(z^2, 10^2)) - E_noise, 0)): 0 when the features scatter
    about the model as noise and model error allow; in units of that scatter
    otherwise, each feature counting at most 10 sigma. NaN entries are ignored.
    """
    values = capped_squares(z)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return math.nan
    return excess_over_noise(float(np.mean(values)))


def excess_over_noise(mean_square: float) -> float:
    """The gap of features with this mean capped square: sqrt(max(mean_square - E_noise, 0))."""
    return math.sqrt(max(mean_square - GAP_NOISE_LEVEL, 0.0))


def _per_run_squares(z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per run (axis 0): the sum of capped squares and the count of finite entries."""
    n_op = z.shape[0]
    squares = np.array([np.nansum(capped_squares(z[op])) for op in range(n_op)])
    counts = np.array([np.sum(np.isfinite(z[op])) for op in range(n_op)])
    return squares, counts


def shrink_fraction(before: float, after: float) -> float:
    """1 - after/before (0 when there is no gap to shrink; negative when it grew)."""
    if not before > 0:
        return 0.0
    return 1.0 - after / before


def bootstrap_shrink(
    z_before: np.ndarray,
    z_after: np.ndarray,
    rng: np.random.Generator,
    n_resamples: int = DEFAULT_SETTINGS.verdict.bootstrap_resamples,
) -> tuple[float, float, float]:
    """Shrink fraction and its 5 % and 95 % bootstrap quantiles, resampling runs.

    The quantiles are over the resamples that hold a gap to shrink (the
    central resample does whenever the result is not 0).

    Parameters
    ----------
    z_before, z_after : ndarray (n_op, ...)
        Held-out standardised discrepancies of the nominal model and the
        model with the effect.
    """
    before = np.asarray(z_before, dtype=float)
    after = np.asarray(z_after, dtype=float)
    n_op = before.shape[0]
    # per-run sums of squares and counts make each resample cheap
    squares_before, counts = _per_run_squares(before)
    squares_after, _ = _per_run_squares(after)

    def shrink_of(index: Any) -> float:
        count = counts[index].sum()
        if count == 0:
            return math.nan
        gap_before = excess_over_noise(squares_before[index].sum() / count)
        gap_after = excess_over_noise(squares_after[index].sum() / count)
        # a resample that left out every run carrying the gap has nothing to shrink: the
        # fraction is undefined there, not 0 (a gap confined to one run would otherwise get a
        # lower bound of 0 from the third of resamples that miss that run)
        return shrink_fraction(gap_before, gap_after) if gap_before > 0 else math.nan

    central = shrink_of(np.arange(n_op))
    if not math.isfinite(central):
        return 0.0, 0.0, 0.0
    samples = np.array([shrink_of(rng.integers(0, n_op, n_op)) for _ in range(n_resamples)])
    samples = samples[np.isfinite(samples)]
    return central, float(np.quantile(samples, 0.05)), float(np.quantile(samples, 0.95))


def bootstrap_gap(
    z: np.ndarray, rng: np.random.Generator, n_resamples: int = DEFAULT_SETTINGS.verdict.bootstrap_resamples
) -> tuple[float, float]:
    """5 % and 95 % bootstrap quantiles of :func:`gap_metric`, resampling runs (axis 0)."""
    values = np.asarray(z, dtype=float)
    n_op = values.shape[0]
    squares, counts = _per_run_squares(values)
    gaps = []
    for _ in range(n_resamples):
        index = rng.integers(0, n_op, n_op)
        count = counts[index].sum()
        if count:
            gaps.append(excess_over_noise(squares[index].sum() / count))
    if not gaps:
        return math.nan, math.nan
    return float(np.quantile(gaps, 0.05)), float(np.quantile(gaps, 0.95))


# ---------------------------------------------------------------------------------------------- candidate scores


@dataclass(frozen=True)
class RunOutCheck:
    """An eccentricity's fitted run-out against what the gears' stated pitch-error classes make as a run-out.

    ``within``: the run-out is no more than the classes' first-order
    run-out bound and the fit is not clearly worse without its mesh-stiffness
    modulation (which pitch errors do not make): no evidence of an eccentric
    shaft. ``beyond``: the run-out exceeds the bound, at the lower end of its
    90 % interval (``run_out_low``; the point value where none is given): a
    run-out the data leave open (no TE recorded, where the run-out is read
    through the dynamics only) is no evidence that the gears' errors could
    not make it.
    """

    run_out: float
    bound: float
    modulated: bool
    run_out_low: float | None = None

    @property
    def within(self) -> bool:
        return self.run_out <= self.bound and not self.modulated

    @property
    def beyond(self) -> bool:
        low = self.run_out if self.run_out_low is None else self.run_out_low
        return low > self.bound


@dataclass(frozen=True)
class CandidateScore:
    """Held-out scores of one candidate effect (its best variant): what the verdict reads and the ranking reports.

    The quantities carry the names they have in ``diagnosis.json``.
    """

    effect: str
    label: str
    fit: FitResult
    held: HeldOut
    stage: str
    delta_log_density: float
    standard_error: float
    penalty: float
    score: float
    gap_with_effect: float
    shrink_fraction: float
    shrink_interval: tuple[float, float]
    # robust cost of the base model at this fit's base parameters and T2 minus the fit's own:
    # what the effect itself adds (a screening fit shares the base's parameters)
    effect_gain: float = math.inf
    # an eccentricity fit's robust cost with its mesh-stiffness modulation (kappa) off minus its own:
    # evidence that pitch errors, which make a run-out but no modulation, cannot give (None: not measured)
    modulation_gain: float | None = None
    # the bootstrap 5 % and 95 % quantiles of gap_with_effect, where a decision asked for them
    gap_interval: tuple[float, float] | None = None
    # an eccentricity's run-out against the pitch-error classes' run-out, where an allowance applies
    run_out: RunOutCheck | None = None
    # per channel (the case's order): the held-out log-density gain over the base, and the held-out gap
    # of the base and of the model with the effect (the cross-channel consistency rule reads them)
    channel_gains: tuple[float, ...] = ()
    channel_gaps_before: tuple[float, ...] = ()
    channel_gaps_after: tuple[float, ...] = ()
    channels: tuple[str, ...] = ()
    # per channel: what the effect's fit would gain there on held-out runs were it real, half the sum of squares
    # of its change to the standardised discrepancies (its prediction in noise spreads); the channels that cannot
    # see it by this measure cannot tell it from another channel's own artefact
    channel_reach: tuple[float, ...] = ()

    def figures(self) -> dict[str, Any]:
        """The figures the ranking reports (``modulation_gain`` where it was measured)."""
        figures: dict[str, Any] = {
            "effect": self.effect,
            "score": self.score,
            "standard_error": self.standard_error,
            "shrink_fraction": self.shrink_fraction,
            "shrink_interval": list(self.shrink_interval),
            "gap_with_effect": self.gap_with_effect,
            "effect_gain": self.effect_gain,
        }
        if self.modulation_gain is not None:
            figures["modulation_gain"] = self.modulation_gain
        return figures

    def _candidate(self) -> Candidate:
        candidate = self.fit.problem.candidate
        assert candidate is not None  # internal invariant: a score is of a fit with its candidate
        return candidate

    def parameters(self) -> dict[str, object]:
        """Fitted parameters of this candidate's effect (natural units) and its fixed choices.

        Only the new candidate's: in a fit on top of named effects theirs are reported with them.
        """
        candidate = self._candidate()
        values: dict[str, object] = dict(candidate.choices)
        fitted = self.fit.values
        values.update({spec.name.split(".", 1)[1]: float(fitted[spec.name]) for spec in candidate.fitted})
        return values

    def parameter_intervals(self) -> dict[str, list[float]]:
        """90 % Laplace intervals of this candidate's fitted parameters (:func:`~.fitting.parameter_intervals`)."""
        candidate = self._candidate()
        intervals = parameter_intervals(self.fit, [spec.name for spec in candidate.fitted])
        return {name.split(".", 1)[1]: [low, high] for name, (low, high) in intervals.items()}


def score_candidate(
    fit_result: FitResult,
    held: HeldOut,
    nominal_held: HeldOut,
    stage: str,
    rng: np.random.Generator,
    *,
    n_resamples: int = DEFAULT_SETTINGS.verdict.bootstrap_resamples,
) -> CandidateScore:
    """Held-out log-density gain over the base model, its standard error, penalty and gap shrink.

    The base is the nominal model, or in forward selection the model with
    the effects already named (``nominal_held`` is then its held-out
    predictions): the gain, the penalty (the new effect's parameters only)
    and the shrink are the new effect's on top of it.
    """
    candidate = fit_result.problem.candidate
    if candidate is None:  # an internal invariant: only a fit with an effect is a candidate
        raise ValueError("score_candidate: the fit has no candidate effect")
    difference = held.log_density - nominal_held.log_density
    per_run = np.array([np.nansum(difference[op]) for op in range(difference.shape[0])])
    n_runs = per_run.size
    delta = float(per_run.sum())
    standard_error = float(math.sqrt(n_runs) * per_run.std(ddof=1)) if n_runs > 1 else math.inf
    n_features = int(np.isfinite(held.z).sum())
    penalty = 0.5 * len(candidate.fitted) * math.log(max(n_features, 2))
    gap = gap_metric(held.z)
    shrink, low, high = bootstrap_shrink(nominal_held.z, held.z, rng, n_resamples)
    n_channels = held.z.shape[1]
    return CandidateScore(
        effect=candidate.effect,
        label=candidate.label,
        fit=fit_result,
        held=held,
        stage=stage,
        delta_log_density=delta,
        standard_error=standard_error,
        penalty=penalty,
        score=delta - penalty,
        gap_with_effect=gap,
        shrink_fraction=shrink,
        shrink_interval=(low, high),
        channel_gains=tuple(float(np.nansum(difference[:, c])) for c in range(n_channels)),
        channel_gaps_before=tuple(gap_metric(nominal_held.z[:, c]) for c in range(n_channels)),
        channel_gaps_after=tuple(gap_metric(held.z[:, c]) for c in range(n_channels)),
        channels=tuple(fit_result.problem.case.channels),
        channel_reach=channel_reach(held.z, nominal_held.z),
    )


def channel_reach(z_with: np.ndarray, z_base: np.ndarray) -> tuple[float, ...]:
    """Per channel: the held-out log-density a fitted effect would gain there were it real, nats.

    The effect moves each feature's standardised discrepancy by its
    prediction in noise spreads (``z_base - z_with``); were the effect real,
    a channel would gain half the sum of their squares on average (the
    information a Gaussian shift of that size carries). A channel where this
    stays small cannot see the effect as fitted, whatever the rig holds.

    Parameters
    ----------
    z_with, z_base : ndarray (n_op, n_channel, F)
        Held-out standardised discrepancies with the effect and of its base.

    Examples
    --------
    >>> import numpy as np
    >>> base = np.zeros((2, 2, 3))
    >>> with_effect = base.copy()
    >>> with_effect[:, 0, 0] = 4.0      # four noise spreads on one feature of channel 0, both runs
    >>> channel_reach(with_effect, base)
    (16.0, 0.0)
    """
    shift = np.asarray(z_base, dtype=float) - np.asarray(z_with, dtype=float)
    return tuple(float(0.5 * np.nansum(shift[:, c] ** 2)) for c in range(shift.shape[1]))


__all__ = [
    "GAP_METRIC",
    "GAP_NOISE_LEVEL",
    "capped_squares",
    "gap_metric",
    "excess_over_noise",
    "shrink_fraction",
    "bootstrap_shrink",
    "bootstrap_gap",
    "RunOutCheck",
    "CandidateScore",
    "score_candidate",
    "channel_reach",
]
