"""Step 1 with a healthy reference: has the test campaign changed beyond what two healthy campaigns differ by?

Both campaigns are reduced to the condition-monitoring features of
:mod:`.features` (with the first three mesh harmonics, features of the
model's own). A feature's change is its test value less the reference's
carried to the test run's speed, in natural-log units (a power ratio). It
counts as a change where it exceeds what two healthy campaigns of one rig
differ by (docs/model/unmodelled-effects.md section 6.1):

- sensor noise and run-to-run variation, measured in both campaigns by the
  scatter between the two halves of each record (pooled with the other runs
  of that channel and feature), times ``change_z``;
- the speed and load difference, as the spread of carrying the reference
  between its two nearest runs in speed (zero at a reference run);
- a load difference inside the runs' stated T2 intervals: ``load_allowance``
  of the change the model makes from one end of the interval to the other;
- a run-to-run allowance per feature family (``change_allowance_db``), and,
  where the gear set was replaced since the reference, the spread of gears
  of the same quality (``replaced_allowance_db``, lines measured above a
  floor of ``replaced_line_floor`` of the channel's RMS).

Test runs outside the reference's speed range, or whose drive torque differs
from the reference's at that speed by more than ``torque_tolerance``, are not
judged (``inconclusive`` for those runs).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from ...physics.design import Design
from ..errors import DiagnosisError
from ..settings import DiagnosisSettings
from .features import FAMILIES, FEATURES, campaign_features
from .options import GEAR_STATES

#: Families measured as powers of lines or of a part of the signal: a level floor applies to them.
LEVEL_FAMILIES = ("mesh_harmonic", "shaft_line", "sideband_energy", "tsa_residual_rms")
#: What a change of each family points to (the kind of change reported).
KIND = {
    "rms": "overall level",
    "kurtosis": "impulsiveness of the record",
    "mesh_harmonic": "meshing (mesh harmonics)",
    "shaft_line": "once- or twice-per-revolution lines",
    "sideband_energy": "modulation of the meshing (sidebands)",
    "tsa_residual_rms": "what the shaft's average holds besides the meshing",
    "tsa_residual_kurtosis": "a local impulse once per revolution (TSA residual kurtosis)",
}
_DB = 10.0 / math.log(10.0)


@dataclass(frozen=True)
class CampaignFeatures:
    """A campaign's condition-monitoring features: whole records and their halves, per run and channel."""

    channels: tuple[str, ...]
    values: np.ndarray  # (n_op, n_channel, n_feature)
    halves: np.ndarray  # (2, n_op, n_channel, n_feature)
    noise: np.ndarray  # (n_op, n_channel) white-noise variance of the whole record
    speeds: np.ndarray  # (n_op,) rpm
    torques: np.ndarray  # (n_op,) N m
    fs: float
    size: int


def read_campaign(rig: xr.Dataset, design: Design, channels: Sequence[str]) -> CampaignFeatures:
    """The features of every record of a rig campaign (and of each record's halves)."""
    from ...rig.features import sampling_rate

    fs = float(sampling_rate(rig["time"].values))
    speeds = np.asarray(rig["pinion_speed"].values, dtype=float)
    pinion_hz = speeds / 60.0
    values, halves, noise = [], [], []
    for channel in channels:
        records = np.asarray(rig[channel].values, dtype=float)
        half = records.shape[1] // 2
        values.append(campaign_features(list(records), fs, pinion_hz, design.z1, design.z2))
        halves.append(
            [
                campaign_features(list(records[:, part]), fs, pinion_hz, design.z1, design.z2)
                for part in (slice(0, half), slice(half, 2 * half))
            ]
        )
        from .features import noise_variance

        noise.append([noise_variance(record) for record in records])
    return CampaignFeatures(
        tuple(channels),
        np.stack(values, axis=1),
        np.stack([np.stack([h[k] for h in halves], axis=1) for k in range(2)]),
        np.array(noise).T,
        speeds,
        np.asarray(rig["drive_torque"].values, dtype=float),
        fs,
        int(rig.sizes["time"]),
    )


@dataclass(frozen=True)
class Carried:
    """The reference's features at the test runs' speeds, with the spread of carrying them."""

    values: np.ndarray  # (n_op_test, n_channel, n_feature)
    spread: np.ndarray  # (n_op_test, n_channel, n_feature), ln units
    inside: np.ndarray  # (n_op_test,) bool
    nearest: np.ndarray  # (n_op_test,) reference run nearest in speed
    reasons: tuple[str, ...]  # why each outside run is outside ('' inside)


def outside_reasons(
    ref_speeds: np.ndarray,
    ref_torques: np.ndarray,
    speeds: np.ndarray,
    torques: np.ndarray,
    *,
    speed_tolerance: float,
    torque_tolerance: float,
) -> tuple[str, ...]:
    """Why each test run lies outside the reference's range ('' for a run inside it).

    Outside: a pinion speed beyond the reference's slowest and fastest runs
    by more than ``speed_tolerance``, or a drive torque more than
    ``torque_tolerance`` off the reference's interpolated at that speed.
    """
    order = np.argsort(ref_speeds)
    ref_speeds, ref_torques = np.asarray(ref_speeds, dtype=float)[order], np.asarray(ref_torques, dtype=float)[order]
    low, high = ref_speeds[0] * (1 - speed_tolerance), ref_speeds[-1] * (1 + speed_tolerance)
    reasons = []
    for speed, torque in zip(speeds, torques):
        ref_torque = float(np.interp(speed, ref_speeds, ref_torques))
        reason = ""
        if not low <= speed <= high:
            reason = f"{speed:g} rpm lies outside the reference's {ref_speeds[0]:g} to {ref_speeds[-1]:g} rpm"
        elif abs(torque - ref_torque) > torque_tolerance * max(abs(ref_torque), 1.0):
            reason = (
                f"{torque:g} N m is more than {torque_tolerance:.0%} off the reference's {ref_torque:g} N m "
                f"at {speed:g} rpm"
            )
        reasons.append(reason)
    return tuple(reasons)


def check_coverage(
    test: xr.Dataset, reference: xr.Dataset, *, where: str, speed_tolerance: float, torque_tolerance: float
) -> None:
    """Refuse a reference that covers none of the test runs (before any work; one line naming the first)."""
    reasons = outside_reasons(
        np.asarray(reference["pinion_speed"].values, dtype=float),
        np.asarray(reference["drive_torque"].values, dtype=float),
        np.asarray(test["pinion_speed"].values, dtype=float),
        np.asarray(test["drive_torque"].values, dtype=float),
        speed_tolerance=speed_tolerance,
        torque_tolerance=torque_tolerance,
    )
    if all(reasons):
        raise DiagnosisError(
            f"reference {where}: no test operating point lies inside the reference's range (operating point 0: "
            f"{reasons[0]}); expected a reference campaign covering the test plan"
        )


def carry_reference(
    reference: CampaignFeatures,
    speeds: np.ndarray,
    torques: np.ndarray,
    *,
    speed_tolerance: float,
    torque_tolerance: float,
) -> Carried:
    """The reference's features interpolated in speed to each test run (linearly between its two nearest runs).

    The spread of carrying is half the difference between those two runs,
    scaled by how far the test run lies from the nearer one (zero at a
    reference run, at most a quarter of the difference midway). A test run
    outside the reference's speed range (by more than ``speed_tolerance``)
    or whose drive torque is more than ``torque_tolerance`` off the
    reference's at that speed lies outside.
    """
    order = np.argsort(reference.speeds)
    ref_speeds, ref_values = reference.speeds[order], reference.values[order]
    n_op = speeds.size
    values = np.zeros((n_op, *reference.values.shape[1:]))
    spread = np.zeros_like(values)
    inside = np.ones(n_op, dtype=bool)
    nearest = np.zeros(n_op, dtype=int)
    reasons = outside_reasons(
        reference.speeds,
        reference.torques,
        speeds,
        torques,
        speed_tolerance=speed_tolerance,
        torque_tolerance=torque_tolerance,
    )
    for op, speed in enumerate(speeds):
        nearest[op] = int(order[np.argmin(np.abs(ref_speeds - speed))])
        clipped = float(np.clip(speed, ref_speeds[0], ref_speeds[-1]))
        upper = int(np.clip(np.searchsorted(ref_speeds, clipped), 1, max(ref_speeds.size - 1, 1)))
        lower = upper - 1 if ref_speeds.size > 1 else 0
        span = ref_speeds[upper] - ref_speeds[lower]
        weight = 0.0 if span <= 0 else (clipped - ref_speeds[lower]) / span
        values[op] = (1 - weight) * ref_values[lower] + weight * ref_values[upper]
        spread[op] = 0.5 * np.abs(ref_values[upper] - ref_values[lower]) * 2.0 * min(weight, 1 - weight)
        inside[op] = not reasons[op]
    return Carried(values, spread, inside, nearest, reasons)


def _floored(values: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """ln power features with a floor power added (the level floor of the line families)."""
    return np.log(np.exp(values) + floor)


def level_floor(level_ln_power: np.ndarray, share: float) -> np.ndarray:
    """The floor power of the line families, (..., n_feature): ``share`` of the channel's RMS (as an amplitude)."""
    level = np.exp(level_ln_power)[..., None] * 2.0 * share**2
    mask = np.array([name.family in LEVEL_FAMILIES for name in FEATURES], dtype=float)
    return level * mask


@dataclass(frozen=True)
class ChangeTest:
    """Whether and where the test campaign differs from the reference beyond healthy variation.

    Attributes hold, per (test run, channel, feature): ``change`` (ln
    units), ``threshold`` (ln units) and ``ratio`` = |change| / threshold;
    ``judged`` marks the runs inside the reference's range.
    """

    channels: tuple[str, ...]
    change: np.ndarray
    threshold: np.ndarray
    noise_spread: np.ndarray
    judged: np.ndarray
    reasons: tuple[str, ...]
    gears: str
    anchor: np.ndarray  # the reference's (floored) features carried to the test runs
    test_values: np.ndarray  # the test's (floored) features
    floor: np.ndarray
    speeds: np.ndarray
    summary_: dict[str, Any] = field(default_factory=dict)

    @property
    def ratio(self) -> np.ndarray:
        return self.ratio_of(self.change)

    def ratio_of(self, change: np.ndarray) -> np.ndarray:
        """|change| / threshold for a change of the same runs and features (ln units); 0 where not judged.

        ``change`` is this test's own or another one read alike, e.g. a
        withheld effect's noise-free change (:meth:`change_between`) judged
        against the thresholds this test drew from healthy variation.
        """
        with np.errstate(invalid="ignore"):
            ratio = np.abs(change) / self.threshold
        ratio[~self.judged] = 0.0
        # a feature that could not be read (a shaft not turning once in the record) is not judged
        ratio[~np.isfinite(ratio)] = 0.0
        return ratio

    def change_between(self, before: CampaignFeatures, after: CampaignFeatures) -> np.ndarray:
        """The change from ``before`` to ``after`` (campaigns at this test's runs) as this test reads one.

        Both are floored at this test's line floor, as the reference and
        the test are, so that a line below it changes nothing.
        """
        return _floored(after.values, self.floor) - _floored(before.values, self.floor)

    @property
    def significant(self) -> np.ndarray:
        return self.ratio > 1.0

    @property
    def changed(self) -> bool:
        return bool(self.significant.any())

    def largest(self) -> dict[str, Any]:
        """The largest change relative to its threshold: where, its size and threshold in dB."""
        op, ch, feat = np.unravel_index(int(np.argmax(self.ratio)), self.ratio.shape)
        return {
            "op": int(op),
            "speed_rpm": float(self.speeds[op]),
            "channel": self.channels[ch],
            "feature": FEATURES[feat].label,
            "family": FEATURES[feat].family,
            "change_db": float(self.change[op, ch, feat] * _DB),
            "threshold_db": float(self.threshold[op, ch, feat] * _DB),
            "ratio": float(self.ratio[op, ch, feat]),
        }

    def where(self) -> list[dict[str, Any]]:
        """The changed (channel, family, shaft) groups, largest first, with their runs and kind."""
        groups: dict[tuple[str, str, str], dict[str, Any]] = {}
        significant = self.significant
        for op, ch, feat in zip(*np.nonzero(significant)):
            name = FEATURES[feat]
            key = (self.channels[ch], name.family, name.shaft)
            entry = groups.setdefault(
                key,
                {
                    "channel": key[0],
                    "family": key[1],
                    "shaft": key[2] or None,
                    "kind": KIND[key[1]],
                    "ops": set(),
                    "largest_db": 0.0,
                    "largest_ratio": 0.0,
                    "features": set(),
                },
            )
            entry["ops"].add(int(op))
            entry["features"].add(name.label)
            if self.ratio[op, ch, feat] > entry["largest_ratio"]:
                entry["largest_ratio"] = float(self.ratio[op, ch, feat])
                entry["largest_db"] = float(self.change[op, ch, feat] * _DB)
        listed = sorted(groups.values(), key=lambda item: -item["largest_ratio"])
        for entry in listed:
            entry["ops"] = sorted(entry["ops"])
            entry["speeds_rpm"] = [float(self.speeds[op]) for op in entry["ops"]]
            entry["features"] = sorted(entry["features"])
            entry["direction"] = "up" if entry["largest_db"] > 0 else "down"
        return listed

    def summary(self) -> dict[str, Any]:
        """JSON-ready record of the test."""
        judged = int(self.judged.sum())
        return {
            "changed": self.changed,
            "gears": self.gears,
            "judged_runs": judged,
            "inconclusive_runs": [{"op": op, "reason": reason} for op, reason in enumerate(self.reasons) if reason],
            "largest": self.largest() if judged else None,
            "where": self.where(),
            "features_compared": int(judged * self.change.shape[1] * self.change.shape[2]),
            "features_changed": int(self.significant.sum()),
        }


def _noise_spread(reference_halves: np.ndarray, test_halves: np.ndarray, carried_nearest: np.ndarray) -> np.ndarray:
    """Noise and run-to-run spread of a change, per (test run, channel, feature), ln units.

    The spread of a whole record's feature is half the difference of its
    halves' values; each run's own is averaged with the pool of its channel
    and feature over all runs of both campaigns (a single difference is a
    poor estimate of a spread).
    """
    ref_var = (reference_halves[0] - reference_halves[1]) ** 2 / 4.0
    test_var = (test_halves[0] - test_halves[1]) ** 2 / 4.0
    # a half too short to average a shaft's revolution gives no estimate (NaN): the pool stands in for it;
    # a feature no half estimates (the gear's lines in the short segments of a fast ramp) has no spread: inf
    both = np.concatenate([ref_var, test_var])
    count = np.sum(np.isfinite(both), axis=0)
    pooled = np.where(count > 0, np.nansum(both, axis=0) / np.maximum(count, 1), np.inf)
    local = 0.5 * (ref_var[carried_nearest] + test_var)
    local = np.where(np.isfinite(local), local, pooled[None])
    return np.sqrt(2.0 * 0.5 * (local + pooled[None]))


def family_allowance(settings: DiagnosisSettings, gears: str) -> np.ndarray:
    """Per feature, the allowance of its family in ln units (run-to-run; plus the replaced gears' spread)."""
    allowance = np.array([settings.change.change_allowance_db for _ in FEATURES]) / _DB
    if gears == "replaced":
        replaced = dict(zip(FAMILIES, settings.change.replaced_allowance_db))
        allowance = allowance + np.array([replaced[name.family] for name in FEATURES]) / _DB
    return allowance


def judge_change(
    reference: CampaignFeatures,
    test: CampaignFeatures,
    *,
    settings: DiagnosisSettings,
    gears: str = "same",
    load_allowance: np.ndarray | None = None,
) -> ChangeTest:
    """Judge every feature of every test run against the reference carried to it (module docstring).

    Raises
    ------
    DiagnosisError
        ``gears`` is not ``same`` or ``replaced``; or no test run lies inside the reference's range.
    """
    if gears not in GEAR_STATES:
        raise DiagnosisError(f"reference_gears: expected one of {', '.join(GEAR_STATES)}; got {gears!r}")
    carried = carry_reference(
        reference,
        test.speeds,
        test.torques,
        speed_tolerance=settings.reference.speed_tolerance,
        torque_tolerance=settings.reference.torque_tolerance,
    )
    if not carried.inside.any():
        first = carried.reasons[0]
        raise DiagnosisError(
            f"reference: no test operating point lies inside the reference's range (operating point 0: {first}); "
            "expected a reference campaign covering the test plan"
        )
    share = settings.change.replaced_line_floor if gears == "replaced" else settings.change.same_line_floor
    # the floor follows the reference's level at the test run (its RMS feature)
    floor = level_floor(carried.values[..., 0], share)
    anchor = _floored(carried.values, floor)
    observed = _floored(test.values, floor)
    change = observed - anchor
    spread = _noise_spread(reference.halves, test.halves, carried.nearest)
    spread = np.sqrt(spread**2 + carried.spread**2)
    threshold = settings.change.change_z * spread + family_allowance(settings, gears)[None, None, :]
    if load_allowance is not None:
        # the load of each run may differ inside its stated T2 interval (judged runs only)
        threshold[carried.inside] += load_allowance
    return ChangeTest(
        test.channels,
        change,
        threshold,
        spread,
        carried.inside,
        carried.reasons,
        gears,
        anchor,
        observed,
        floor,
        test.speeds,
    )


__all__ = [
    "CampaignFeatures",
    "Carried",
    "ChangeTest",
    "GEAR_STATES",
    "KIND",
    "carry_reference",
    "check_coverage",
    "outside_reasons",
    "family_allowance",
    "level_floor",
    "read_campaign",
    "judge_change",
]
