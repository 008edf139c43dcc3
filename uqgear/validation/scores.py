"""The blind test's scores: confusion matrix, accuracies, false alarms, detection thresholds, effect sets."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from ..diagnosis import VERDICTS, effect_family
from ..diagnosis.settings import DEFAULT_SETTINGS
from .campaigns import HEALTHY

#: Verdicts that name no effect.
NOT_EFFECTS: tuple[str, ...] = (HEALTHY, "unexplained", "inconclusive")


def _thresholds(
    campaigns: Sequence[Mapping[str, Any]], effects: Sequence[str], noise_gap: float
) -> list[dict[str, Any]]:
    """Per effect: the weakest strength detected above which all were, and the strongest one missed."""
    rows = []
    for effect in effects:
        parameter = effect_family(effect).strength
        cases = sorted((c for c in campaigns if c["truth"] == effect), key=lambda c: c["strength_value"])
        detected = [c["strength_value"] for c in cases if c["verdict"] == effect]
        missed = [c["strength_value"] for c in cases if c["verdict"] != effect]
        detected_from = None
        for value in sorted(detected):
            if all(m < value for m in missed):
                detected_from = value
                break
        note = ""
        invisible = [c for c in cases if c["verdict"] != effect and not c["detectable"]]
        if invisible:
            note = f"{len(invisible)} missed below detectability (oracle gap <= {noise_gap:g})"
        rows.append(
            {
                "effect": effect,
                "parameter": parameter,
                "detected_from": detected_from,
                "missed_up_to": max(missed) if missed else None,
                "n": len(cases),
                "note": note,
            }
        )
    return rows


def _truth_set(campaign: Mapping[str, Any]) -> set[str]:
    """The effects acting on a scored campaign (``truth_effects``, else its one ``truth``)."""
    if campaign.get("truth_effects") is not None:
        return set(campaign["truth_effects"])
    return set() if campaign["truth"] == HEALTHY else {campaign["truth"]}


def _control_verdict(campaign: Mapping[str, Any]) -> str:
    """The verdict a campaign without a gear effect should get: ``none``, or ``unexplained`` for a sensor artefact."""
    return str(campaign.get("expected_verdict") or HEALTHY)


def _named_set(campaign: Mapping[str, Any]) -> set[str]:
    """The effects a diagnosis named (``effects_named``, else its verdict when that is an effect)."""
    if campaign.get("effects_named") is not None:
        return set(campaign["effects_named"])
    return {campaign["verdict"]} if campaign["verdict"] not in NOT_EFFECTS else set()


def set_scores(campaigns: Sequence[Mapping[str, Any]], effects: Sequence[str]) -> dict[str, Any]:
    """How well the named effect sets match the true ones.

    Per effect: precision (of the campaigns where it was named, the share
    where it acts) and recall (of the campaigns where it acts, the share
    where it was named), None where undefined (never named, never acting).
    ``set_exact``: the share of campaigns whose named set is exactly the
    true set; an empty true set counts only with the verdict ``none`` (an
    ``unexplained`` or ``inconclusive`` healthy control names nothing, but
    is not right).
    """
    names = list(dict.fromkeys([*effects, *(name for c in campaigns for name in _truth_set(c) | _named_set(c))]))
    rows = []
    for name in names:
        named = [c for c in campaigns if name in _named_set(c)]
        acting = [c for c in campaigns if name in _truth_set(c)]
        hits = sum(1 for c in named if name in _truth_set(c))
        # its share of the shrink where it was rightly named (campaigns that record the shares)
        shares = [
            c["shrink_shares"][list(c["effects_named"]).index(name)]
            for c in named
            if name in _truth_set(c) and c.get("shrink_shares") is not None
        ]
        rows.append(
            {
                "effect": name,
                "named": len(named),
                "acting": len(acting),
                "correct": hits,
                "precision": hits / len(named) if named else None,
                "recall": hits / len(acting) if acting else None,
                "shrink_share_median": float(np.median(shares)) if shares else None,
            }
        )
    exact = [
        (_named_set(c) == _truth_set(c)) and (bool(_truth_set(c)) or c["verdict"] == _control_verdict(c))
        for c in campaigns
    ]
    # against the effects the data can tell (effect_visibility) where the campaign records them
    identifiable = [
        set(c["identifiable_effects"]) if c.get("identifiable_effects") is not None else _truth_set(c)
        for c in campaigns
    ]
    exact_identifiable = [
        _named_set(c) == wanted if _truth_set(c) else c["verdict"] == _control_verdict(c)
        for c, wanted in zip(campaigns, identifiable)
    ]
    multi = [ok for c, ok in zip(campaigns, exact) if len(_truth_set(c)) > 1]
    controls = [c for c in campaigns if not _truth_set(c)]
    # effects missed but reported as not told apart from the gears' own errors (campaigns that record it)
    recorded = [c for c in campaigns if c.get("cannot_tell") is not None]
    missed = [(c, name) for c in recorded for name in sorted(_truth_set(c) - _named_set(c))]
    return {
        "per_effect": rows,
        "set_exact": sum(exact) / len(exact) if exact else math.nan,
        "set_exact_identifiable": sum(exact_identifiable) / len(exact_identifiable) if exact_identifiable else math.nan,
        "effects_not_identifiable": sum(len(_truth_set(c) - wanted) for c, wanted in zip(campaigns, identifiable)),
        "n_multi_effect": len(multi),
        "set_exact_multi_effect": sum(multi) / len(multi) if multi else None,
        "n_controls": len(controls),
        "controls_with_an_effect_named": sum(1 for c in controls if _named_set(c)),
        "effects_missed": len(missed),
        "effects_missed_reported_cannot_tell": sum(
            1 for c, name in missed if any(label.startswith(f"{name}[") for label in c["cannot_tell"])
        ),
        "controls_with_cannot_tell": sum(1 for c in controls if c.get("cannot_tell")),
    }


def summarise(
    campaigns: Sequence[Mapping[str, Any]],
    effects: Sequence[str],
    *,
    seconds: float = math.nan,
    seed_text: str = "",
    noise_gap: float = DEFAULT_SETTINGS.verdict.noise_gap,
) -> dict[str, Any]:
    """Confusion matrix, accuracies, false alarms, shrink statistics, thresholds and effect-set scores.

    The confusion matrix and the accuracies score the verdict (the leading
    effect) against the campaign's ``truth``; ``effect_sets``
    (:func:`set_scores`) scores the named effect sets against the true ones.
    """
    labels = list(effects) + [HEALTHY]
    verdicts = list(VERDICTS)
    counts = np.zeros((len(labels), len(verdicts)), dtype=int)
    for c in campaigns:
        counts[labels.index(c["truth"]), verdicts.index(c["verdict"])] += 1
    n = len(campaigns)
    shrinks = np.array(
        [
            c["shrink_fraction"]
            for c in campaigns
            if c["correct"] and c["truth"] != HEALTHY and c["shrink_fraction"] is not None
        ],
        dtype=float,
    )
    false_alarms = sum(1 for c in campaigns if c["truth"] == HEALTHY and c["verdict"] not in NOT_EFFECTS)
    return {
        "n_campaigns": n,
        "labels": labels,
        "accuracy": sum(c["correct"] for c in campaigns) / n if n else math.nan,
        "accuracy_detectable": sum(c["correct_detectable"] for c in campaigns) / n if n else math.nan,
        "false_alarms": false_alarms,
        "healthy_controls": sum(1 for c in campaigns if c["truth"] == HEALTHY),
        "confusion": {"truth": labels, "verdicts": verdicts, "counts": counts.tolist()},
        "shrink": {
            "n": int(shrinks.size),
            "median": float(np.median(shrinks)) if shrinks.size else None,
            "q25": float(np.quantile(shrinks, 0.25)) if shrinks.size else None,
            "q75": float(np.quantile(shrinks, 0.75)) if shrinks.size else None,
            "minimum": float(shrinks.min()) if shrinks.size else None,
        },
        "thresholds": _thresholds(campaigns, effects, noise_gap),
        "effect_sets": set_scores(campaigns, effects),
        "campaigns": list(campaigns),
        "seconds": seconds,
        "seed": seed_text,
    }


def blindtest_dataset(content: Mapping[str, Any]) -> xr.Dataset:
    """The blind test as a Dataset: per-campaign table and the confusion matrix."""
    campaigns = content["campaigns"]

    def column(key: str, default: float = math.nan) -> np.ndarray:
        return np.array([default if c[key] is None else c[key] for c in campaigns], dtype=float)

    ds = xr.Dataset(
        {
            "confusion": (
                ("truth", "verdict"),
                np.array(content["confusion"]["counts"], dtype=np.int64),
                {"long_name": "campaigns per true effect and verdict", "units": "1"},
            ),
            "strength_value": (
                ("campaign",),
                column("strength_value"),
                {"long_name": "value of the effect's strength parameter", "units": "effect units"},
            ),
            "oracle_gap": (
                ("campaign",),
                column("oracle_gap"),
                {"long_name": "gap between the true model with and without the effect", "units": "1"},
            ),
            "nominal_gap": (
                ("campaign",),
                column("nominal_gap"),
                {"long_name": "held-out gap of the fitted nominal model", "units": "1"},
            ),
            "shrink_fraction": (
                ("campaign",),
                column("shrink_fraction"),
                {"long_name": "held-out gap shrink when the effect is named", "units": "1"},
            ),
            "correct": (
                ("campaign",),
                np.array([int(c["correct"]) for c in campaigns], dtype=np.int8),
                {"long_name": "verdict equals the true label", "units": "1"},
            ),
            "seconds": (("campaign",), column("seconds"), {"long_name": "generation and diagnosis time", "units": "s"}),
        },
        coords={
            "truth": ("truth", list(content["confusion"]["truth"])),
            "verdict": ("verdict", list(content["confusion"]["verdicts"])),
            "campaign": ("campaign", [c["id"] for c in campaigns]),
            "campaign_truth": ("campaign", [c["truth"] for c in campaigns]),
            "campaign_verdict": ("campaign", [c["verdict"] for c in campaigns]),
            "campaign_design": ("campaign", [c["design"] for c in campaigns]),
            "campaign_plan": ("campaign", [c.get("plan", "service") for c in campaigns]),
            "campaign_strength": ("campaign", [c["strength"] for c in campaigns]),
        },
    )
    ds.attrs.update(
        title="uqgear blind test of the gap diagnosis",
        accuracy=content["accuracy"],
        accuracy_detectable=content["accuracy_detectable"],
        false_alarms=content["false_alarms"],
    )
    return ds


__all__ = ["NOT_EFFECTS", "set_scores", "summarise", "blindtest_dataset"]
