"""Whether a candidate is named: the decision rules on the candidates' held-out scores (step 5).

Every :class:`~uqgear.diagnosis.decision.Decision` on the model's gap is
made by these rules or, for a set of effects, in :mod:`.sets`: the first
effect's (:func:`decide`, applied by
:func:`~uqgear.diagnosis.pipeline.decide_first`), the named set's, a set
that an unexplained gap's strongest candidate leads and an eccentric shaft
the sideband phases name. Each rule reads the case's
:class:`~.rules.VerdictRules`: its thresholds, and what the pitch-error
allowance lets a gap say (docs/model/unmodelled-effects.md section 6, step
5, and sections 6.2 and 6.4).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

from ..decision import Decision
from ..effects import effect_names, hooks_of
from ..scoring import CandidateScore, RunOutCheck
from .cross_channel import check_channels, inconsistent_decision
from .rules import DEFAULT_RULES, VerdictRules

#: Effects of the library that the diagnosis can name.
EFFECT_NAMES: tuple[str, ...] = effect_names()
#: Possible verdicts: an effect of the library; ``none`` (the nominal model is within noise on
#: held-out runs); ``unexplained`` (a significant gap that no candidate removes); ``inconclusive``
#: (valid data that cannot decide: no line above the noise floor in enough runs, no feature
#: that could be compared on held-out runs, or a gap on one channel that an effect too weak for
#: the other channels to see and that channel's own artefact explain alike).
VERDICTS: tuple[str, ...] = EFFECT_NAMES + ("none", "unexplained", "inconclusive")


def run_out_check(score: CandidateScore, rules: VerdictRules = DEFAULT_RULES) -> RunOutCheck | None:
    """A run-out's fit against the pitch-error classes' first-order run-out on its shaft, or None.

    It applies to an effect whose family reads as a shaft run-out (its
    :attr:`~.effects.EffectFamily.run_out` hook: eccentricity in the library).
    The bounds are the rules' ``run_out_bounds`` (the case's
    :attr:`~uqgear.diagnosis.case.RigCase.run_out_allowance`, empty without a
    pitch-error allowance). The fit counts as modulated when
    it is worse by at least the effect-gain threshold with its mesh-stiffness
    modulation off, which pitch errors do not make.
    """
    family = hooks_of(score.effect)
    if family.run_out is None or not rules.run_out_bounds:
        return None
    values = score.parameters()
    bound = rules.run_out_bound(str(family.run_out_shaft(values)))
    if bound is None:
        return None
    modulated = score.modulation_gain is not None and score.modulation_gain >= rules.thresholds.effect_gain_threshold
    amplitude = float(values.get(family.run_out.amplitude, math.nan))  # type: ignore[arg-type]
    # the run-out as far as the data pin it: it enters the TE directly; without a TE channel it is read
    # through the dynamics, where a gear's own first-order pitch error reads the same, so it is not measured
    interval = score.parameter_intervals().get(family.run_out.amplitude) if "te" in score.channels else None
    low = float(interval[0]) if interval is not None else 0.0
    return RunOutCheck(amplitude, bound, modulated, low)


def ranked(best_per_effect: Mapping[str, CandidateScore], rules: VerdictRules = DEFAULT_RULES) -> list[CandidateScore]:
    """The best variant of each effect, best first, each with its run-out check (new objects)."""
    scores = sorted(best_per_effect.values(), key=lambda entry: -entry.score)
    return [replace(s, run_out=run_out_check(s, rules)) for s in scores]


def _within(score: CandidateScore) -> bool:
    return score.run_out is not None and score.run_out.within


def score_lower_bound(score: CandidateScore, rules: VerdictRules = DEFAULT_RULES) -> float:
    """The lower end of a candidate's 90 % score interval (``score_quantile`` standard errors below it)."""
    return score.score - rules.thresholds.score_quantile * float(score.standard_error)


def holds_against_pitch_errors(score: CandidateScore, rules: VerdictRules = DEFAULT_RULES) -> bool:
    """Whether a candidate's score holds where pitch errors could give as much: at its 90 % lower bound.

    An eccentricity whose fitted run-out is beyond what the gears' stated
    classes make as a first-order run-out needs only its point score:
    pitch errors of those classes seldom make such a run-out
    (docs/model/unmodelled-effects.md section 6.4).
    """
    beyond = score.run_out is not None and score.run_out.beyond
    return score_lower_bound(score, rules) >= rules.thresholds.score_threshold or bool(
        beyond and score.score >= rules.thresholds.score_threshold
    )


def leads_a_set(best: CandidateScore, rules: VerdictRules = DEFAULT_RULES) -> bool:
    """Whether an unexplained gap's best candidate is strong enough to start a forward selection.

    The evidence rules of :func:`decide` without the one on how much of
    the gap it explains alone: a score beyond the threshold, a fit that is
    clearly worse with its effect off, and a shrink whose 90 % interval is
    above zero. With the pitch-error allowance the score must reach the
    threshold at its 90 % lower bound, as :func:`decide` asks of an effect
    that does not halve the gap there: a set led by a weak first effect
    would name it anyway.
    """
    return (
        best.score >= rules.thresholds.score_threshold
        and float(best.effect_gain) >= rules.thresholds.effect_gain_threshold
        and best.shrink_interval[0] > 0.0
        and not _within(best)
        and (not rules.pitch_allowance or holds_against_pitch_errors(best, rules))
        and check_channels(best, rules).consistent
    )


def _straddles(interval: Sequence[float] | None, threshold: float) -> bool:
    if interval is None or len(interval) != 2 or not all(math.isfinite(float(v)) for v in interval):
        return False
    return float(interval[0]) < threshold <= float(interval[1])


def _borderline_figures(
    nominal_gap: float,
    nominal_gap_interval: Sequence[float] | None,
    best: CandidateScore | None,
    rules: VerdictRules,
) -> tuple[dict[str, Any], ...]:
    noise_gap = rules.thresholds.noise_gap
    figures = []
    if nominal_gap_interval is not None and _straddles(nominal_gap_interval, noise_gap):
        figures.append(
            {
                "figure": "nominal_gap",
                "value": nominal_gap,
                "threshold": noise_gap,
                "interval": [float(v) for v in nominal_gap_interval],
            }
        )
    if best is not None:
        error = float(best.standard_error)
        if math.isfinite(error):
            upper = best.score + rules.thresholds.score_quantile * error
            score_interval = [score_lower_bound(best, rules), upper]
            if _straddles(score_interval, rules.thresholds.score_threshold):
                figures.append(
                    {
                        "figure": "score",
                        "value": float(best.score),
                        "threshold": rules.thresholds.score_threshold,
                        "interval": score_interval,
                    }
                )
        if _straddles(best.shrink_interval, rules.thresholds.shrink_threshold):
            figures.append(
                {
                    "figure": "shrink_fraction",
                    "value": float(best.shrink_fraction),
                    "threshold": rules.thresholds.shrink_threshold,
                    "interval": [float(v) for v in best.shrink_interval],
                }
            )
        if best.gap_interval is not None and _straddles(best.gap_interval, noise_gap):
            figures.append(
                {
                    "figure": "gap_with_effect",
                    "value": float(best.gap_with_effect),
                    "threshold": noise_gap,
                    "interval": [float(v) for v in best.gap_interval],
                }
            )
    return tuple(figures)


def _percent(interval: Sequence[float]) -> str:
    return f"{100 * interval[0]:.0f} to {100 * interval[1]:.0f} %"


def decide(
    nominal_gap: float,
    ranking: Sequence[CandidateScore],
    rules: VerdictRules = DEFAULT_RULES,
    *,
    nominal_gap_interval: Sequence[float] | None = None,
) -> Decision:
    """The verdict from the held-out gap of the base model and the ranked candidates on top of it.

    A candidate is named when its score reaches ``score_threshold``, its fit
    is worse by ``effect_gain_threshold`` with its effect off (else it owes
    its score to the nominal parameters it refitted), the lower end of its
    shrink interval is positive, and it explains the gap: shrinks it by
    ``shrink_threshold`` or leaves no significant gap (held-out gap with the
    effect at most ``noise_gap``; a nominal gap just above noise cannot
    shrink by half and still be significant). One that passes the score and
    gain rules but explains only part of the gap is named ``partial`` when
    the lower end of its shrink interval reaches ``partial_shrink``. The
    base model is within noise when its gap is at most ``noise_gap``; a gap
    that could not be measured (NaN) gives ``inconclusive``, never ``none``.
    A candidate these rules name must pass the cross-channel rule too
    (:mod:`.cross_channel`); one that explains a gap on one channel alone,
    which the other channels could not have seen as fitted, gives
    ``inconclusive`` between it and that channel's own artefact.

    Parameters
    ----------
    nominal_gap : float
        Held-out gap of the base model (:func:`~uqgear.diagnosis.scoring.gap_metric`).
    ranking : sequence of CandidateScore
        Candidates best first (their ``gap_interval`` and ``run_out`` where known).
    rules : VerdictRules
        The case's rules (:func:`~.rules.verdict_rules`): the thresholds and,
        with the pitch-error allowance (``rules.pitch_allowance``), that the
        allowance widens the error of every sideband, so while the nominal
        gap is within ``noise_gap`` the gap speaks for no effect, and the
        effect gain must reach ``score_threshold`` too (the effect carries
        the evidence by itself). With ``rules.density_evidence`` (the first
        effect's rules under the allowance) an effect's signature spread over
        many features can leave each of them within noise while the held-out
        density still sees it. Then a score whose 90 % lower bound reaches
        ``score_threshold`` stands in for a shrink interval above zero; the
        run-out guard still applies. Just above the noise gap the same lower
        bound is needed of an effect named because what remains is within
        noise, so the rule does not jump at ``noise_gap``
        (docs/model/unmodelled-effects.md section 6.4).
    nominal_gap_interval : pair of float, optional
        Bootstrap interval of the nominal gap (:func:`~uqgear.diagnosis.scoring.bootstrap_gap`).

    Returns
    -------
    Decision
    """
    best = ranking[0] if ranking else None
    borderline = _borderline_figures(nominal_gap, nominal_gap_interval, best, rules)
    weak_near_noise = False
    if best is not None:
        named, weak_near_noise = _named(best, nominal_gap, borderline, rules)
        if named is not None:
            # a gear effect shows on every channel that sees the mesh
            # (docs/model/unmodelled-effects.md section 6, step 5)
            channels = check_channels(best, rules)
            if channels.consistent:
                return named
            return inconsistent_decision(best, nominal_gap, borderline, rules, channels, explains=not named.partial)
    if not math.isfinite(nominal_gap):
        # no feature could be compared on a held-out run: the data cannot tell "within noise"
        # from "not measured", and no data must never read as a healthy gear
        return Decision(
            "inconclusive",
            "the held-out gap could not be measured: no feature of any run could be "
            "compared with the model on held-out runs",
            borderline=borderline,
        )
    return _unnamed(best, nominal_gap, borderline, rules, weak_near_noise)


def _below_gap(nominal_gap: float, rules: VerdictRules) -> bool:
    """No gap to speak for an effect: the nominal gap is within noise under the pitch-error allowance."""
    return rules.pitch_allowance and nominal_gap <= rules.thresholds.noise_gap


def _carries_evidence(best: CandidateScore, nominal_gap: float, rules: VerdictRules) -> bool:
    """The evidence rules: a score beyond the threshold and a fit clearly worse with the effect off.

    A run-out the gears' own pitch errors make (the run-out check) is no
    eccentric shaft; with no gap to speak for it (:func:`_below_gap`) the
    effect gain must reach the score threshold by itself.
    """
    thresholds = rules.thresholds
    gain = float(best.effect_gain)
    carried = gain >= thresholds.effect_gain_threshold and not _within(best)
    if _below_gap(nominal_gap, rules):
        carried = carried and gain >= thresholds.score_threshold
    return best.score >= thresholds.score_threshold and carried


def _explains(best: CandidateScore, borderline: tuple[dict[str, Any], ...], rules: VerdictRules) -> bool:
    """The effect explains the gap: it shrinks it by ``shrink_threshold`` or leaves what is within noise.

    What remains within noise speaks for the effect only where the gap it
    removed was clearly above noise: a nominal gap whose own interval reaches
    into noise may be noise itself (borderline: none).
    """
    gap_borderline = any(figure["figure"] == "nominal_gap" for figure in borderline)
    return best.shrink_fraction >= rules.thresholds.shrink_threshold or (
        float(best.gap_with_effect) <= rules.thresholds.noise_gap and not gap_borderline
    )


def _by_density(best: CandidateScore, nominal_gap: float, rules: VerdictRules) -> bool:
    """The density route: below the gap, what remains within noise, no shrink, a score that holds at its lower bound."""
    return (
        rules.density_evidence
        and _below_gap(nominal_gap, rules)
        and float(best.gap_with_effect) <= rules.thresholds.noise_gap
        and best.shrink_interval[0] <= 0.0
        and holds_against_pitch_errors(best, rules)
    )


def _weak_near_noise(best: CandidateScore, rules: VerdictRules) -> bool:
    """With the density route, an effect that leaves a gap within noise without halving it, its score not holding.

    With the allowance a gap near noise speaks weakly: an effect named
    because what remains is within noise (not for a shrink of half) must
    hold its density at the 90 % lower bound, as on the density route just
    below the gap.
    """
    return (
        rules.density_evidence
        and best.shrink_fraction < rules.thresholds.shrink_threshold
        and not holds_against_pitch_errors(best, rules)
    )


def _named(
    best: CandidateScore,
    nominal_gap: float,
    borderline: tuple[dict[str, Any], ...],
    rules: VerdictRules,
) -> tuple[Decision | None, bool]:
    """The decision naming ``best`` where the rules of :func:`decide` name it, and whether it was weak near noise."""
    remaining = float(best.gap_with_effect)
    evidence = _carries_evidence(best, nominal_gap, rules)
    if evidence and _by_density(best, nominal_gap, rules):
        return Decision(
            best.effect,
            (
                f"{best.effect} gains {best.score:.1f} nats of held-out predictive density (90 % lower "
                f"bound {score_lower_bound(best, rules):.1f}) over the model without it after its parameter "
                f"penalty; the held-out "
                f"gap ({nominal_gap:.2f}) is within noise because the pitch-error allowance widens the error "
                f"of every sideband, so the evidence is spread over many features: the density shows it, "
                f"the gap cannot"
            ),
            remaining_gap=remaining,
            borderline=borderline,
        ), False
    explains = _explains(best, borderline, rules)
    by_shrink = evidence and explains and best.shrink_interval[0] > 0.0
    weak_near_noise = by_shrink and _weak_near_noise(best, rules)
    if by_shrink and not weak_near_noise:
        within = (
            f"; what remains ({remaining:.2f}) is within noise"
            if best.shrink_fraction < rules.thresholds.shrink_threshold
            else ""
        )
        return Decision(
            best.effect,
            (
                f"{best.effect} gains {best.score:.1f} nats of held-out predictive density over the "
                f"nominal model after its parameter penalty and shrinks the held-out gap by "
                f"{100 * best.shrink_fraction:.0f} % (90 % interval {_percent(best.shrink_interval)}){within}"
            ),
            remaining_gap=remaining,
            borderline=borderline,
        ), False
    if evidence and not explains and best.shrink_interval[0] >= rules.thresholds.partial_shrink:
        return Decision(
            best.effect,
            (
                f"{best.effect} gains {best.score:.1f} nats of held-out predictive density and shrinks "
                f"the held-out gap by {100 * best.shrink_fraction:.0f} % (90 % interval "
                f"{_percent(best.shrink_interval)}), but a gap of {remaining:.2f} "
                f"(above {rules.thresholds.noise_gap:g}) "
                f"remains unexplained"
            ),
            partial=True,
            remaining_gap=remaining,
            borderline=borderline,
        ), False
    return None, weak_near_noise


def _unnamed(
    best: CandidateScore | None,
    nominal_gap: float,
    borderline: tuple[dict[str, Any], ...],
    rules: VerdictRules,
    weak_near_noise: bool,
) -> Decision:
    """``none`` or ``unexplained`` with the reason no candidate was named."""
    run_out = best.run_out if best is not None and _within(best) else None
    beyond = (
        f"; {best.effect} fits a run-out of {1e6 * run_out.run_out:.1f} um, within what the gears' "
        f"stated pitch-error classes make as a first-order run-out (95 %: {1e6 * run_out.bound:.1f} um)"
        if best is not None and run_out is not None
        else ""
    )
    held = ""
    if weak_near_noise and best is not None:
        held = (
            f"; with the pitch-error allowance an effect that leaves a gap within noise without halving it "
            f"must hold {rules.thresholds.score_threshold:g} nats at its score's 90 % lower bound, and {best.effect}'s "
            f"is {score_lower_bound(best, rules):.1f}: pitch errors of the stated classes can give "
            f"as much"
        )
    if nominal_gap <= rules.thresholds.noise_gap:
        return Decision(
            "none",
            f"the nominal model's held-out gap {nominal_gap:.2f} is within noise "
            f"(threshold {rules.thresholds.noise_gap:g}) and no candidate is clearly better{held}{beyond}",
            borderline=borderline,
        )
    gap_figure = next((figure for figure in borderline if figure["figure"] == "nominal_gap"), None)
    if gap_figure is not None:
        # a gap whose own 90 % interval reaches into noise is no evidence of anything the model lacks:
        # the verdict to act on is none, with the borderline stated (docs/model/unmodelled-effects.md section 6, step 5)
        low, high = gap_figure["interval"]
        return Decision(
            "none",
            f"the nominal model's held-out gap {nominal_gap:.2f} is above the noise threshold "
            f"{rules.thresholds.noise_gap:g} but its 90 % interval ({low:.2f} to {high:.2f}) reaches into noise, "
            "and no "
            f"candidate is clearly better: borderline, not evidence of a gap{held}{beyond}",
            borderline=borderline,
        )
    detail = ""
    if best is not None:
        detail = (
            f"; the best candidate, {best.effect}, scores {best.score:.1f} nats and shrinks it by "
            f"{100 * best.shrink_fraction:.0f} % (needed: {rules.thresholds.score_threshold:g} nats, and a shrink of "
            f"{100 * rules.thresholds.shrink_threshold:.0f} % or a remaining gap within noise)"
        )
        detail += held + beyond
    return Decision(
        "unexplained",
        f"the nominal model's held-out gap is {nominal_gap:.2f} (above {rules.thresholds.noise_gap:g}){detail}",
        borderline=borderline,
    )


def decide_verdict(
    nominal_gap: float,
    ranking: Sequence[CandidateScore],
    rules: VerdictRules = DEFAULT_RULES,
    *,
    nominal_gap_interval: Sequence[float] | None = None,
) -> tuple[str, str]:
    """``(verdict, reason)`` of :func:`decide` (same arguments)."""
    decision = decide(nominal_gap, ranking, rules, nominal_gap_interval=nominal_gap_interval)
    return decision.verdict, decision.reason


__all__ = [
    "EFFECT_NAMES",
    "VERDICTS",
    "ranked",
    "run_out_check",
    "score_lower_bound",
    "holds_against_pitch_errors",
    "leads_a_set",
    "decide",
    "decide_verdict",
]
