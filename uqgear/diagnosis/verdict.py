"""The verdict: decision rules on the held-out scores, where the gap lies and its character per family."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.stats

from ..physics.effects import EFFECTS
from ..rig.features import FEATURE_FAMILIES
from .case import RigCase
from .scoring import capped_squares, excess_over_noise

#: Effects of the library that the diagnosis can name.
EFFECT_NAMES: tuple[str, ...] = tuple(EFFECTS)
#: Possible verdicts: an effect of the library; ``none`` (the nominal model is within noise on
#: held-out runs); ``unexplained`` (a significant gap that no candidate removes); ``inconclusive``
#: (valid data that cannot decide: no line above the noise floor in enough runs, or no feature
#: that could be compared on held-out runs).
VERDICTS: tuple[str, ...] = EFFECT_NAMES + ("none", "unexplained", "inconclusive")
#: A rig line counts as signal when its amplitude is at least this many per-quadrature noise
#: spreads: white noise alone reaches 5 (Rayleigh tail exp(-12.5)) in about one of 270,000 lines.
SIGNAL_SNR = 5.0
#: Runs with a line above the noise floor that a diagnosis needs: one to fit, one held out.
MIN_INFORMATIVE_RUNS = 2

#: A candidate must gain this much held-out log predictive density (nats, after the penalty) to be named.
SCORE_THRESHOLD = 10.0
#: ... and shrink the held-out gap by at least this fraction.
SHRINK_THRESHOLD = 0.5
#: The nominal model is within noise when its held-out gap is below this (and no candidate is named).
NOISE_GAP_THRESHOLD = 0.5
#: A named effect must itself improve its fit's robust cost by at least this much (about nats).
EFFECT_GAIN_THRESHOLD = 5.0
#: An effect that clears the score and gain rules but not the shrink rule is still named, with an
#: unexplained remainder, when the lower end of its shrink interval reaches this fraction.
PARTIAL_SHRINK_THRESHOLD = 0.2
# A held-out feature this many sigmas off counts as a gap in the "where" list.
_WHERE_Z = 3.0



@dataclass(frozen=True)
class Decision:
    """A verdict with the figures that decided it.

    Attributes
    ----------
    verdict, reason : str
        As :func:`decide_verdict` returns them.
    partial : bool
        The named effect explains only part of the gap: what remains
        (``remaining_gap``) is significant and unexplained.
    remaining_gap : float or None
        Held-out gap with the named effect (``None`` when none is named).
    borderline : tuple of dict
        Deciding figures that lie within their own spread of their threshold
        (``figure``, ``value``, ``threshold``, ``interval``): a rerun on
        another campaign of the same rig could go the other way.
    """

    verdict: str
    reason: str
    partial: bool = False
    remaining_gap: float | None = None
    borderline: tuple[dict[str, Any], ...] = ()


def _straddles(interval: Sequence[float] | None, threshold: float) -> bool:
    if interval is None or len(interval) != 2 or not all(math.isfinite(float(v)) for v in interval):
        return False
    return float(interval[0]) < threshold <= float(interval[1])


#: Standard errors on each side of a score for its 90 % interval (the normal 95 % quantile).
SCORE_QUANTILE = 1.645


def score_lower_bound(entry: Mapping[str, Any]) -> float:
    """The lower end of a candidate's 90 % score interval (``score`` - 1.645 ``standard_error``; -inf without one)."""
    return entry["score"] - SCORE_QUANTILE * float(entry.get("standard_error", math.inf))


def holds_against_pitch_errors(entry: Mapping[str, Any], score_threshold: float = SCORE_THRESHOLD) -> bool:
    """Whether a candidate's score holds where pitch errors could give as much: at its 90 % lower bound.

    An eccentricity whose fitted run-out is beyond what the gears' stated
    classes make as a first-order run-out (95 %; ``beyond_pitch_errors`` in
    its ranking entry) needs only its point score: pitch errors of those
    classes seldom make such a run-out. With the allowance scaled to the
    rig's own gears (:mod:`~uqgear.diagnosis.gear_orders`) the nominal model
    read a 40 um pinion run-out (bound 22 um) on class-7 gears as the
    pinion's own errors at 17 um, and the run-out's fit held 19.8 nats but
    not at its lower bound.
    """
    return score_lower_bound(entry) >= score_threshold or bool(
        entry.get("beyond_pitch_errors") and entry["score"] >= score_threshold)


def _borderline_figures(nominal_gap: float, nominal_gap_interval: Sequence[float] | None,
                        best: Mapping[str, Any] | None, *, score_threshold: float, shrink_threshold: float,
                        noise_gap: float) -> tuple[dict[str, Any], ...]:
    figures = []
    if _straddles(nominal_gap_interval, noise_gap):
        figures.append({"figure": "nominal_gap", "value": nominal_gap, "threshold": noise_gap,
                        "interval": [float(v) for v in nominal_gap_interval]})
    if best is not None:
        error = float(best.get("standard_error", math.nan))
        if math.isfinite(error):
            score_interval = [score_lower_bound(best), best["score"] + SCORE_QUANTILE * error]
            if _straddles(score_interval, score_threshold):
                figures.append({"figure": "score", "value": float(best["score"]), "threshold": score_threshold,
                                "interval": score_interval})
        if _straddles(best.get("shrink_interval"), shrink_threshold):
            figures.append({"figure": "shrink_fraction", "value": float(best["shrink_fraction"]),
                            "threshold": shrink_threshold,
                            "interval": [float(v) for v in best["shrink_interval"]]})
        if _straddles(best.get("gap_interval"), noise_gap):
            figures.append({"figure": "gap_with_effect", "value": float(best["gap_with_effect"]),
                            "threshold": noise_gap, "interval": [float(v) for v in best["gap_interval"]]})
    return tuple(figures)


def decide(nominal_gap: float, ranking: Sequence[Mapping[str, Any]], *,
           nominal_gap_interval: Sequence[float] | None = None,
           score_threshold: float = SCORE_THRESHOLD, shrink_threshold: float = SHRINK_THRESHOLD,
           noise_gap: float = NOISE_GAP_THRESHOLD, effect_gain_threshold: float = EFFECT_GAIN_THRESHOLD,
           partial_shrink: float = PARTIAL_SHRINK_THRESHOLD, pitch_allowance: bool = False,
           density_evidence: bool = False) -> Decision:
    """The verdict from the held-out gap of the nominal model and the ranked candidates.

    Parameters
    ----------
    nominal_gap : float
        Held-out gap of the nominal model (:func:`gap_metric`).
    ranking : sequence of mapping
        Candidates best first, each with ``effect``, ``score`` (held-out log
        density gain over the nominal model minus the parameter penalty),
        ``shrink_fraction``, ``shrink_interval`` ([5 %, 95 %]) and optionally
        ``gap_with_effect`` (its held-out gap), ``gap_interval``,
        ``standard_error`` (of the score) and ``effect_gain`` (how much worse
        its fit is with the effect switched off, robust cost).
    nominal_gap_interval : pair of float, optional
        Bootstrap interval of the nominal gap (:func:`bootstrap_gap`).
    score_threshold, shrink_threshold, noise_gap : float
        A candidate is named when its score reaches the threshold, the lower
        end of its shrink interval is positive, and it explains the gap:
        shrinks it by ``shrink_threshold`` or leaves no significant gap
        (held-out gap with the effect at most ``noise_gap``; a nominal gap
        just above noise cannot shrink by half and still be significant).
        The nominal model is within noise when its gap is at most ``noise_gap``;
        a gap that could not be measured (NaN: no feature compared on a
        held-out run) gives ``inconclusive``, never ``none``.
    effect_gain_threshold : float
        A candidate whose fit is as good with its effect off (``effect_gain``
        below this) owes its score to the nominal parameters it refitted, not
        to the effect, and is never named.
    partial_shrink : float
        A candidate that passes the score and gain rules but explains only
        part of the gap is named with an unexplained remainder (``partial``)
        when the lower end of its shrink interval reaches this fraction;
        below it the verdict is ``unexplained``.
    pitch_allowance : bool
        The model error holds the pitch-error allowance: it widens the error
        of every sideband, so while the nominal gap is within ``noise_gap``
        the gap speaks for no effect, and the effect gain must reach
        ``score_threshold`` too (the effect carries the evidence by itself).
        For the first effect and every further one (forward selection).
    density_evidence : bool
        With ``pitch_allowance`` only, for the first effect only: an effect's
        signature spread over many features can leave each of them within
        noise (a held-out gap within ``noise_gap``, nothing to shrink) while
        the held-out density still sees it. Then a score whose 90 % lower
        bound (1.645 standard errors below it) reaches ``score_threshold``
        stands in for a shrink interval above zero; the run-out guard still
        applies. Just above the noise gap the same lower bound is needed of
        an effect named because what remains is within noise (a shrink below
        ``shrink_threshold``), so the rule does not jump at ``noise_gap``.
        An eccentricity whose run-out is beyond the classes' first-order
        run-out (``beyond_pitch_errors``) needs its point score only
        (:func:`holds_against_pitch_errors`). A further effect must shrink
        the gap that is left.

    Returns
    -------
    Decision
    """
    if density_evidence and not pitch_allowance:
        raise ValueError("decide: density_evidence stands in for a gap only under the pitch-error allowance; "
                         "expected pitch_allowance=True with it")
    best = ranking[0] if ranking else None
    weak_near_noise = False
    borderline = _borderline_figures(nominal_gap, nominal_gap_interval, best, score_threshold=score_threshold,
                                     shrink_threshold=shrink_threshold, noise_gap=noise_gap)
    if best is not None:
        remaining = float(best.get("gap_with_effect", math.inf))
        explains = best["shrink_fraction"] >= shrink_threshold or remaining <= noise_gap
        # a run-out the gears' own pitch errors make (the candidate ranking's flag) is no eccentric shaft
        carried = (float(best.get("effect_gain", math.inf)) >= effect_gain_threshold
                   and not best.get("within_pitch_errors"))
        score_low = score_lower_bound(best)
        below_gap = pitch_allowance and nominal_gap <= noise_gap
        if below_gap:
            # no gap to speak for it: the effect must carry the score threshold by itself (a control with
            # every nuisance had torque ripple at 30 nats with a gain of 5.9, a run-out 65 nats with 29)
            carried = carried and float(best.get("effect_gain", math.inf)) >= score_threshold
        evidence = best["score"] >= score_threshold and carried
        holds = holds_against_pitch_errors(best, score_threshold)
        by_density = (density_evidence and below_gap and remaining <= noise_gap and best["shrink_interval"][0] <= 0.0
                      and holds)
        if evidence and by_density:
            return Decision(str(best["effect"]), (
                f"{best['effect']} gains {best['score']:.1f} nats of held-out predictive density (90 % lower "
                f"bound {score_low:.1f}) over the model without it after its parameter penalty; the held-out "
                f"gap ({nominal_gap:.2f}) is within noise because the pitch-error allowance widens the error "
                f"of every sideband, so the evidence is spread over many features: the density shows it, "
                f"the gap cannot"), remaining_gap=remaining, borderline=borderline)
        # with the allowance a gap near noise speaks weakly: an effect named because what remains is within
        # noise (not for a shrink of half) must hold its density at the 90 % lower bound, as on the density
        # route just below the gap (out of sample, a healthy class-7 control at a gap of 0.51 had a 17 um
        # run-out with kappa 0.026 at 26 +- 15 nats; pitch errors shift the pairs' load sharing too)
        by_shrink = evidence and explains and best["shrink_interval"][0] > 0.0
        weak_near_noise = (by_shrink and density_evidence and best["shrink_fraction"] < shrink_threshold
                           and not holds)
        if by_shrink and not weak_near_noise:
            within = (f"; what remains ({remaining:.2f}) is within noise"
                      if best["shrink_fraction"] < shrink_threshold else "")
            return Decision(str(best["effect"]), (
                f"{best['effect']} gains {best['score']:.1f} nats of held-out predictive density over the "
                f"nominal model after its parameter penalty and shrinks the held-out gap by "
                f"{100 * best['shrink_fraction']:.0f} % (90 % interval {100 * best['shrink_interval'][0]:.0f} "
                f"to {100 * best['shrink_interval'][1]:.0f} %){within}"),
                remaining_gap=remaining, borderline=borderline)
        if evidence and not explains and best["shrink_interval"][0] >= partial_shrink:
            return Decision(str(best["effect"]), (
                f"{best['effect']} gains {best['score']:.1f} nats of held-out predictive density and shrinks "
                f"the held-out gap by {100 * best['shrink_fraction']:.0f} % (90 % interval "
                f"{100 * best['shrink_interval'][0]:.0f} to {100 * best['shrink_interval'][1]:.0f} %), but a "
                f"gap of {remaining:.2f} (above {noise_gap:g}) remains unexplained"),
                partial=True, remaining_gap=remaining, borderline=borderline)
    if not math.isfinite(nominal_gap):
        # no feature could be compared on a held-out run: the data cannot tell "within noise"
        # from "not measured", and no data must never read as a healthy gear
        return Decision("inconclusive", "the held-out gap could not be measured: no feature of any run could be "
                                        "compared with the model on held-out runs", borderline=borderline)
    run_out = best.get("within_pitch_errors") if best is not None else None
    beyond = (f"; {best['effect']} fits a run-out of {1e6 * run_out['run_out']:.1f} um, within what the gears' "
              f"stated pitch-error classes make as a first-order run-out (95 %: {1e6 * run_out['bound']:.1f} um)"
              if run_out else "")
    held = ""
    if weak_near_noise:
        held = (f"; with the pitch-error allowance an effect that leaves a gap within noise without halving it "
                f"must hold {score_threshold:g} nats at its score's 90 % lower bound, and {best['effect']}'s "
                f"is {score_low:.1f}: pitch errors of the stated classes can give as much")
    if nominal_gap <= noise_gap:
        return Decision("none", f"the nominal model's held-out gap {nominal_gap:.2f} is within noise "
                                f"(threshold {noise_gap:g}) and no candidate is clearly better{held}{beyond}",
                        borderline=borderline)
    detail = ""
    if best is not None:
        detail = (f"; the best candidate, {best['effect']}, scores {best['score']:.1f} nats and shrinks it by "
                  f"{100 * best['shrink_fraction']:.0f} % (needed: {score_threshold:g} nats, and a shrink of "
                  f"{100 * shrink_threshold:.0f} % or a remaining gap within noise)")
        detail += held + beyond
    return Decision("unexplained", f"the nominal model's held-out gap is {nominal_gap:.2f} "
                                   f"(above {noise_gap:g}){detail}", borderline=borderline)


def decide_verdict(nominal_gap: float, ranking: Sequence[Mapping[str, Any]], **thresholds: float) -> tuple[str, str]:
    """``(verdict, reason)`` of :func:`decide` (same arguments)."""
    decision = decide(nominal_gap, ranking, **thresholds)
    return decision.verdict, decision.reason


def line_signal_to_noise(case: RigCase) -> np.ndarray:
    """Amplitude over per-quadrature noise spread of every compared rig line (n_op, n_channel, F).

    NaN for features that are not lines, for lines outside the band and for
    records the comparison cannot use (missing samples, no noise floor).
    """
    line = np.array(case.layout.kinds) == "line"
    sigma = case.line_noise_sigma()
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = case.observed / sigma
    usable = case.usable[..., None] & line[None, None, :] & np.isfinite(ratio) & (sigma > 0)
    return np.where(usable, ratio, np.nan)


def uninformative_reason(case: RigCase, *, snr: float = SIGNAL_SNR,
                         min_runs: int = MIN_INFORMATIVE_RUNS) -> str | None:
    """Why a valid campaign cannot be diagnosed, or None when it can.

    A diagnosis compares the rig's lines with the model's on held-out runs:
    it needs at least ``min_runs`` runs in which some usable channel shows a
    line (mesh harmonic, sideband, shaft or motor line) at least ``snr``
    noise spreads high. Below that every record is noise as far as the
    features can tell, and any verdict but ``inconclusive`` would be a guess.
    """
    ratio = line_signal_to_noise(case)
    with np.errstate(invalid="ignore"):
        informative = np.nan_to_num(ratio, nan=0.0) >= snr
    runs = informative.any(axis=(1, 2))
    if int(runs.sum()) >= min_runs:
        return None
    usable_runs = int(case.usable.any(axis=1).sum())
    strongest = float(np.nanmax(ratio)) if np.isfinite(ratio).any() else math.nan
    if usable_runs < min_runs:
        return (f"only {usable_runs} of {case.n_op} runs have a channel whose noise floor can be measured; "
                f"the diagnosis needs at least {min_runs} (each run is predicted by a fit to the others)")
    where = ("no run" if not runs.any() else
             "only run " + ", ".join(str(int(op)) for op in np.flatnonzero(runs)))
    detail = f"; the strongest line is {strongest:.1f} noise spreads high" if math.isfinite(strongest) else ""
    return (f"{where} of {case.n_op} shows a line above the noise floor ({snr:g} noise spreads) in any channel"
            f"{detail}: the records carry noise only as far as the features can tell, so the data cannot decide "
            f"between a healthy gear and an effect; the diagnosis needs such lines in at least {min_runs} runs")


def where_gap(z: np.ndarray, case: RigCase, *, limit: int = 12) -> list[dict[str, Any]]:
    """The features carrying a held-out gap: RMS z over runs, runs beyond 3 sigma, strongest first."""
    entries = []
    for c, channel in enumerate(case.channels):
        for f, name in enumerate(case.layout.names):
            values = z[:, c, f]
            finite = np.isfinite(values)
            if not finite.any():
                continue
            score = float(np.sqrt(np.mean(values[finite] ** 2)))
            ops = [int(op) for op in np.flatnonzero(finite & (np.abs(np.nan_to_num(values)) > _WHERE_Z))]
            if score > _WHERE_Z / 1.5 and ops:
                entries.append({"channel": channel, "feature": name, "family": case.layout.families[f],
                                "ops": ops, "score": score})
    entries.sort(key=lambda entry: -entry["score"])
    return entries[:limit]


def _shaft_lines_in_band(z: np.ndarray, case: RigCase, channel: int) -> bool:
    """Whether shaft-order lines inside the low band carry a gap (> 3 sigma) in some run."""
    low, high = case.processors[0].low_band
    for f, family in enumerate(case.layout.families):
        if not family.startswith("shaft_"):
            continue
        order = case.processors[0].definitions[case.layout.columns[f]].order
        frequency = order * case.speeds / 60.0
        inside = (frequency >= low) & (frequency <= high)
        if np.any(inside & (np.abs(np.nan_to_num(z[:, channel, f])) > _WHERE_Z)):
            return True
    return False


def family_character(z: np.ndarray, case: RigCase, locked_lines: Sequence[Mapping[str, Any]]
                     ) -> list[dict[str, Any]]:
    """Per channel and feature family: held-out gap and its character.

    ``order-locked`` for a gap on lines at orders of the shafts or the mesh;
    ``frequency-locked`` for the low-frequency band when lines keep their
    frequency across runs; ``load-dependent`` / ``speed-dependent`` when the
    per-run discrepancy follows the drive torque / speed (|Spearman| >= 0.7).
    """
    rows = []
    families = np.array(case.layout.families)
    for c, channel in enumerate(case.channels):
        for family in FEATURE_FAMILIES:
            chosen = families == family
            if not chosen.any():
                continue
            values = z[:, c, chosen]
            finite = np.isfinite(values)
            if not finite.any():
                continue
            score = excess_over_noise(float(np.mean(capped_squares(values[finite]))))
            per_run = np.array([np.sqrt(np.nanmean(capped_squares(values[op]))) if finite[op].any() else np.nan
                                for op in range(case.n_op)])
            character = []
            if score > NOISE_GAP_THRESHOLD:
                if family not in ("low_frequency", "broadband"):
                    character.append("order-locked")
                elif family == "low_frequency":
                    low = [line for line in locked_lines if line["frequency"] <= case.processors[0].low_band[1]]
                    if low:
                        character.append("frequency-locked")
                    elif _shaft_lines_in_band(z, case, c):
                        character.append("order-locked (shaft lines in the band)")
                    else:
                        character.append("not order-locked")
                ok = np.isfinite(per_run)
                if ok.sum() >= 4 and np.ptp(per_run[ok]) > 0:
                    for label, driver in (("load-dependent", case.drive_torques), ("speed-dependent", case.speeds)):
                        if np.ptp(driver[ok]) > 0:
                            rho = scipy.stats.spearmanr(per_run[ok], driver[ok]).statistic
                            if np.isfinite(rho) and abs(rho) >= 0.7:
                                character.append(label)
            rows.append({"channel": channel, "family": family, "score": score,
                         "per_run": [None if not np.isfinite(v) else float(v) for v in per_run],
                         "character": character})
    return rows


