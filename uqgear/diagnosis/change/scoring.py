"""Step 4 with a healthy reference: which library effect predicts the change, and what share of it.

The model cannot reproduce a foreign rig, but the change from a healthy
campaign of that rig to a test campaign of it is another matter: the
reference's data anchor the prediction (the model's discrepancy from the
reference, feature by feature and run by run, is taken to hold for the test
campaign), and the model is asked only for the *change* an effect makes.
For each screening variant of each effect family (its shaft, gear or
bearing), the model is simulated at the test runs with and without the
effect over a ladder of the effect's strength (with its other parameters at
their start values); the change it predicts for every condition-monitoring
feature (:mod:`.features`, the noiseless model records read with the rig's
noise) is compared with the observed change in units of that feature's
change threshold, widened by ``change_model_error`` of the predicted change.
The share of the change an effect explains is one less the ratio of the
soft-L1 losses of the residual and of the change itself; the strength with
the largest share is refined by a golden-section search in log strength.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
import xarray as xr

from ...common.forked import map_forked
from ...physics.design import Design
from ..candidates import Candidate
from ..effects import effect_family
from ..execution import one_blas_thread
from ..settings import DiagnosisSettings
from ..simulation import CampaignSimulator
from .detection import CampaignFeatures, ChangeTest, level_floor
from .features import FEATURES, campaign_features

# Strengths scanned per variant before the refinement, and golden-section steps of the refinement.
_LADDER_POINTS = 6
_REFINE_STEPS = 3
_FREE_LADDER_POINTS = 4
# Parameters the amplitude features cannot see (kept at their start values, not reported).
_UNSEEN = ("phase", "tooth")


@dataclass(frozen=True)
class ChangeScore:
    """How well one effect variant predicts the change: its share, its parameters, what it leaves."""

    effect: str
    label: str
    values: dict[str, Any]
    share: float
    loss: float
    loss_without: float
    predicted: np.ndarray  # (n_op, n_channel, n_feature) ln units

    def summary(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "variant": self.label,
            # the features read amplitudes only: a phase or which tooth is not measured and not reported
            "parameters": {key: value for key, value in self.values.items() if key not in _UNSEEN},
            "share": self.share,
            "loss": self.loss,
            "loss_without": self.loss_without,
        }


def soft_l1(z: np.ndarray) -> float:
    """Sum of 2 (sqrt(1 + z^2) - 1): quadratic within a threshold, linear beyond (NaN terms count nothing)."""
    return float(np.nansum(2.0 * (np.sqrt(1.0 + z * z) - 1.0)))


class ChangeModel:
    """The model's features at the test runs, with and without an effect, read as the rig's are."""

    def __init__(self, design: Design, rig: xr.Dataset, test: CampaignFeatures, judged: np.ndarray, share: float):
        self.design = design
        self.ops = np.flatnonzero(judged)
        self.test = test
        self.share = share
        self.simulator = CampaignSimulator(
            design, test.speeds[self.ops], test.torques[self.ops], test.fs, test.size, test.channels
        )
        lower = np.asarray(rig["adhesion_torque_lower"].values, dtype=float)[self.ops]
        upper = np.asarray(rig["adhesion_torque_upper"].values, dtype=float)[self.ops]
        # the resisting torque of each run: the middle of its stated interval
        self.adhesion = 0.5 * (lower + upper)
        self.lower, self.upper = lower, upper
        self._baselines: dict[str, np.ndarray] = {}
        self.baseline = self.baseline_for("mesh")

    def baseline_for(self, periodicity: str) -> np.ndarray:
        """The model without an effect simulated as the variant is (same window and tiling): the difference
        between them is then the effect's alone."""
        if periodicity not in self._baselines:
            self._baselines[periodicity] = self.features([], periodicity)
        return self._baselines[periodicity]

    def gains(self, anchor: np.ndarray) -> np.ndarray:
        """The transfer gains from the model to the rig (:func:`transfer_gains`)."""
        return transfer_gains(self.test.channels, anchor, self.baseline)

    def load_allowance(self, share: float) -> np.ndarray:
        """What a healthy campaign may differ by from a change of load inside the stated T2 intervals.

        ``share`` of the model's change of each feature from the lower to
        the upper end of each run's interval (n_judged, n_channel, n_feature), ln units.
        """
        if share <= 0.0:
            return np.zeros_like(self.baseline)
        low = self.features([], "mesh", adhesion=self.lower)
        high = self.features([], "mesh", adhesion=self.upper)
        return share * np.abs(high - low)

    def features(self, effects: Sequence[Any], periodicity: str, *, adhesion: np.ndarray | None = None) -> np.ndarray:
        """Floored ln features (n_judged, n_channel, n_feature) of the model with ``effects``."""
        torques = self.adhesion if adhesion is None else adhesion
        per_channel: dict[str, list[np.ndarray]] = {channel: [] for channel in self.test.channels}
        for index in range(self.ops.size):
            run = self.simulator.run(index, self.design, 1.0, float(torques[index]), effects, periodicity)
            for channel in self.test.channels:
                per_channel[channel].append(run.records[channel])
        pinion_hz = self.test.speeds[self.ops] / 60.0
        values = np.stack(
            [
                campaign_features(
                    per_channel[channel],
                    self.test.fs,
                    pinion_hz,
                    self.design.z1,
                    self.design.z2,
                    noise=self.test.noise[self.ops, c],
                )
                for c, channel in enumerate(self.test.channels)
            ],
            axis=1,
        )
        # the level floor follows the model's own level (its RMS), as the rig's follows the rig's
        return np.log(np.exp(values) + level_floor(values[..., 0], self.share))


_INDEX = {name.label: index for index, name in enumerate(FEATURES)}
#: Each kurtosis feature and the RMS feature of the same signal (its second moment).
_KURTOSIS_PAIRS = tuple(
    (_INDEX[name.label], _INDEX[name.label.replace("kurtosis", "rms")])
    for name in FEATURES
    if name.family in ("kurtosis", "tsa_residual_kurtosis")
)
_POWER = np.array([name.family not in ("kurtosis", "tsa_residual_kurtosis") for name in FEATURES])


def transfer_gains(channels: Sequence[str], anchor: np.ndarray, baseline: np.ndarray) -> np.ndarray:
    """Power gain from the model's to the rig's signal per (run, channel): the RMS power ratio of the reference
    to the model without the effect, 1 for the transmission error (the same quantity on both sides)."""
    gains = np.exp(anchor[..., 0] - baseline[..., 0])
    for c, channel in enumerate(channels):
        if channel == "te":
            gains[:, c] = 1.0
    return gains


def anchored_change(anchor: np.ndarray, baseline: np.ndarray, with_effect: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """The change an effect predicts on the rig: what it adds to the model, added to the reference's data.

    Powers add: the reference's power plus the model's added power times
    a transfer gain, the lesser of the feature's own ratio of reference to
    model and the channel's (a power the effect lowers falls at most by the
    model's own ratio). A kurtosis follows from the fourth moment of the
    record with the effect's component added as an independent part
    (m4 = m4_ref + 6 m2_ref m2_added + m4_added, the added moments read off
    the model and carried by the gain). Returns ln(predicted / reference)
    per feature.
    """
    # a feature the model carries transfers as it does (its own ratio of rig to model); one the model lacks
    # (at its floor) takes the channel's gain: the lesser of the two
    g = np.minimum(gains[..., None], np.exp(anchor - baseline))
    power = np.exp(anchor) + g * (np.exp(with_effect) - np.exp(baseline))
    # a power the effect takes away is taken in proportion: the rig cannot lose more than the share the model
    # loses (its own content there may be other than the model's)
    ratio = with_effect - baseline
    added = np.log(np.maximum(power, 1e-300)) - anchor
    predicted = np.where(_POWER, anchor + np.where(ratio >= 0.0, added, np.maximum(added, ratio)), anchor)
    for kurt, rms in _KURTOSIS_PAIRS:
        m2_ref, m2_base, m2_eff = np.exp(anchor[..., rms]), np.exp(baseline[..., rms]), np.exp(with_effect[..., rms])
        m4_ref = np.exp(anchor[..., kurt]) * m2_ref**2
        m4_base = np.exp(baseline[..., kurt]) * m2_base**2
        m4_eff = np.exp(with_effect[..., kurt]) * m2_eff**2
        added2 = m2_eff - m2_base
        added4 = m4_eff - m4_base - 6.0 * m2_base * added2
        gain = g[..., rms]
        fourth = m4_ref + 6.0 * m2_ref * gain * added2 + gain**2 * added4
        m2_new = np.exp(predicted[..., rms])
        predicted[..., kurt] = np.log(np.clip(fourth / m2_new**2, 1.0, None))
    return predicted - anchor


def _variant_values(candidate: Candidate, start: Mapping[str, Any], strength: str, value: float) -> dict[str, Any]:
    """The effect's values for one point of the ladder: the variant's choices, a start's other parameters."""
    values: dict[str, Any] = dict(candidate.choices)
    prefix = f"{candidate.effect}."
    values.update({key.removeprefix(prefix): float(v) for key, v in start.items() if v != "proportional"})
    bounds = effect_family(candidate.effect).physics.PARAMETERS[strength]
    values[strength] = float(np.clip(value, bounds.lower, bounds.upper))
    # parameters the family ties to its strength (its ``proportional`` hook: a run-out's mesh modulation)
    for key, factor in effect_family(candidate.effect).proportional.items():
        if start.get(f"{prefix}{key}") == "proportional":
            bounds = effect_family(candidate.effect).physics.PARAMETERS[key]
            values[key] = float(min(factor * value, bounds.upper))
    return values


def _spread(scale: np.ndarray, predicted: np.ndarray, observed: np.ndarray, settings: DiagnosisSettings) -> np.ndarray:
    """The spread a predicted change is judged with: the change threshold and the model form's error, which grows
    with the change (the geometric mean of the predicted and the observed one: an over-prediction is not made
    cheap by its own size, a missed change costs in full)."""
    return np.sqrt(scale**2 + settings.change.change_model_error**2 * np.abs(predicted * observed))


def _golden(loss: Callable[[float], float], low: float, high: float, steps: int) -> tuple[float, float]:
    """Minimum of ``loss`` on [low, high] (log strength) by golden-section search: (argument, value)."""
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = low, high
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = loss(c), loss(d)
    for _ in range(steps):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = loss(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = loss(d)
    return (c, fc) if fc < fd else (d, fd)


def score_variant(
    model: ChangeModel,
    candidate: Candidate,
    observed: np.ndarray,
    scale: np.ndarray,
    anchor: np.ndarray,
    settings: DiagnosisSettings,
) -> ChangeScore:
    """The best strength of one variant, its share of the change and its predicted change."""
    family = effect_family(candidate.effect)
    strength = family.strength
    bounds = family.physics.PARAMETERS[strength]
    ladder = np.geomspace(
        max(family.ladder[0] / 3.0, bounds.lower, 1e-12), min(family.ladder[2] * 10.0, bounds.upper), _LADDER_POINTS
    )
    # phases change no amplitude feature: one start per combination of the other parameters
    starts: list[dict[str, Any]] = list(
        {
            tuple(sorted((k, v) for k, v in s.items() if not k.endswith((f".{strength}", ".phase")))): dict(s)
            for s in candidate.starts
        }.values()
    ) or [{}]
    for key in family.proportional:
        # absent or in proportion to the strength: a fixed value between adds nothing the two do not span
        starts = [start for start in starts if start.get(f"{candidate.effect}.{key}", 0.0) < 1e-6] or starts[:1]
        starts.append({**starts[0], f"{candidate.effect}.{key}": "proportional"})
    points, refine = _LADDER_POINTS, _REFINE_STEPS
    if candidate.periodicity == "free":
        # simulated over the whole record (several times the cost of a tiled one): one start, a coarser ladder
        starts, points, refine = starts[:1], _FREE_LADDER_POINTS, 0
        ladder = np.geomspace(ladder[0], ladder[-1], points)
    without = soft_l1(observed / scale)
    cache: dict[tuple[int, float], tuple[float, np.ndarray]] = {}

    def evaluate(start_index: int, log_value: float) -> float:
        key = (start_index, round(log_value, 9))
        if key not in cache:
            values = _variant_values(candidate, starts[start_index], strength, math.exp(log_value))
            effect = family.make(values)
            baseline = model.baseline_for(candidate.periodicity)
            predicted = anchored_change(
                anchor, baseline, model.features([effect], candidate.periodicity), model.gains(anchor)
            )
            spread = _spread(scale, predicted, observed, settings)
            cache[key] = (soft_l1((observed - predicted) / spread), predicted)
        return cache[key][0]

    best: tuple[float, int, float] = (math.inf, 0, 0.0)
    for index in range(len(starts)):
        logs = np.log(ladder)
        losses = [evaluate(index, float(v)) for v in logs]
        at = int(np.argmin(losses))
        argument, value = float(logs[at]), losses[at]
        if refine:
            low, high = logs[max(at - 1, 0)], logs[min(at + 1, logs.size - 1)]
            refined, refined_value = _golden(partial(evaluate, index), float(low), float(high), refine)
            if refined_value < value:
                argument, value = refined, refined_value
        if value < best[0]:
            best = (value, index, argument)
    loss, index, argument = best
    predicted = cache[(index, round(argument, 9))][1]
    values = _variant_values(candidate, starts[index], strength, math.exp(argument))
    share = 1.0 - loss / without if without > 0 else 0.0
    return ChangeScore(candidate.effect, candidate.label, values, float(share), float(loss), float(without), predicted)


def fixed_line_hints(rig: xr.Dataset, reference: xr.Dataset, channels: Sequence[str]) -> dict[str, float]:
    """The frequency (1 to 100 Hz) at which the test campaign's transmission error rose most over the
    reference's, in the median over runs: a line at a fixed frequency rises there in every run, an
    order-locked one moves with the speed (the stick-slip start of an adhesion oscillation)."""
    if "te" not in channels:
        return {}
    from ...rig.features import sampling_rate

    def spectra(campaign: xr.Dataset) -> tuple[np.ndarray, np.ndarray]:
        records = np.asarray(campaign["te"].values, dtype=float)
        fs = float(sampling_rate(campaign["time"].values))
        window = np.hanning(records.shape[1])
        amplitude = np.abs(np.fft.rfft((records - records.mean(axis=1, keepdims=True)) * window, axis=1))
        return np.fft.rfftfreq(records.shape[1], 1.0 / fs), amplitude

    frequency, test = spectra(rig)
    ref_frequency, ref = spectra(reference)
    band = (frequency >= 1.0) & (frequency <= 100.0)
    if not band.any() or ref_frequency.size != frequency.size:
        return {}
    rise = np.median(np.log(test[:, band] + 1e-300) - np.log(ref.mean(axis=0)[band] + 1e-300), axis=0)
    return {"adhesion_frequency": float(frequency[band][int(np.argmax(rise))])}


def _valid(change: ChangeTest) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The judged runs' change, threshold and anchor, with features that could not be read set to count nothing
    (change 0, threshold infinite)."""
    judged = change.judged
    observed, scale, anchor = change.change[judged], change.threshold[judged], change.anchor[judged]
    valid = np.isfinite(observed) & np.isfinite(scale) & np.isfinite(anchor)
    return np.where(valid, observed, 0.0), np.where(valid, scale, np.inf), np.where(valid, anchor, 0.0)


def score_change(
    change: ChangeTest,
    test: CampaignFeatures,
    rig: xr.Dataset,
    design: Design,
    effects: Sequence[str],
    *,
    settings: DiagnosisSettings,
    model: ChangeModel | None = None,
    reference: xr.Dataset | None = None,
    workers: int = 1,
) -> list[ChangeScore]:
    """Every variant of every candidate effect scored on the change it predicts, best share first.

    Each variant's score reads the model and the change alone: the variants are scored on up to
    ``workers`` forked processes (:func:`~uqgear.common.forked.map_forked`; the baselines they
    share are simulated first, here), those simulated over the whole record sent out first.
    """
    judged = change.judged
    if model is None:
        share = settings.change.replaced_line_floor if change.gears == "replaced" else settings.change.same_line_floor
        model = ChangeModel(design, rig, test, judged, share)
    observed, scale, anchor = _valid(change)
    hints = fixed_line_hints(rig, reference, change.channels) if reference is not None else {}
    candidates = [candidate for name in effects for candidate in effect_family(name).variants(design, hints)]
    for periodicity in dict.fromkeys(candidate.periodicity for candidate in candidates):
        # the baselines are shared by every variant of a periodicity: simulated once, before the workers fork
        model.baseline_for(periodicity)
    piece = partial(_scored, model, candidates, observed, scale, anchor, settings)
    whole_record = [candidate.periodicity == "free" for candidate in candidates]
    scores = map_forked(piece, len(candidates), workers, first=whole_record)
    return sorted(scores, key=lambda score: -score.share)


def _scored(
    model: ChangeModel,
    candidates: Sequence[Candidate],
    observed: np.ndarray,
    scale: np.ndarray,
    anchor: np.ndarray,
    settings: DiagnosisSettings,
    index: int,
) -> ChangeScore:
    """Variant ``index`` scored with one BLAS thread, in a forked process as here (the same bits either way)."""
    with one_blas_thread():
        return score_variant(model, candidates[index], observed, scale, anchor, settings)


def explained_where(change: ChangeTest, score: ChangeScore, settings: DiagnosisSettings) -> dict[str, float]:
    """Share of the change explained per channel (soft-L1, as the whole share)."""
    observed, scale, _ = _valid(change)
    spread = _spread(scale, score.predicted, observed, settings)
    out = {}
    for c, channel in enumerate(change.channels):
        without = soft_l1(observed[:, c] / scale[:, c])
        residual = soft_l1((observed[:, c] - score.predicted[:, c]) / spread[:, c])
        out[channel] = 1.0 - residual / without if without > 0 else 0.0
    return out


__all__ = ["ChangeModel", "ChangeScore", "explained_where", "score_change", "score_variant", "soft_l1"]
