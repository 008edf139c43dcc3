"""Where the held-out gap lies and its character, and whether a campaign's data can decide at all."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import scipy.stats

from ..rig.features import FEATURE_FAMILIES
from .case import RigCase
from .scoring import capped_squares, excess_over_noise
from .settings import DEFAULT_SETTINGS


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


def uninformative_reason(
    case: RigCase,
    *,
    snr: float = DEFAULT_SETTINGS.features.signal_snr,
    min_runs: int = DEFAULT_SETTINGS.features.min_informative_runs,
) -> str | None:
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
        return (
            f"only {usable_runs} of {case.n_op} runs have a channel whose noise floor can be measured; "
            f"the diagnosis needs at least {min_runs} (each run is predicted by a fit to the others)"
        )
    where = "no run" if not runs.any() else "only run " + ", ".join(str(int(op)) for op in np.flatnonzero(runs))
    detail = f"; the strongest line is {strongest:.1f} noise spreads high" if math.isfinite(strongest) else ""
    return (
        f"{where} of {case.n_op} shows a line above the noise floor ({snr:g} noise spreads) in any channel"
        f"{detail}: the records carry noise only as far as the features can tell, so the data cannot decide "
        f"between a healthy gear and an effect; the diagnosis needs such lines in at least {min_runs} runs"
    )


def where_gap(
    z: np.ndarray, case: RigCase, *, limit: int = 12, where_z: float = DEFAULT_SETTINGS.verdict.where_z
) -> list[dict[str, Any]]:
    """The features carrying a held-out gap: RMS z over runs, runs beyond ``where_z`` sigma, strongest first."""
    entries: list[dict[str, Any]] = []
    for c, channel in enumerate(case.channels):
        for f, name in enumerate(case.layout.names):
            values = z[:, c, f]
            finite = np.isfinite(values)
            if not finite.any():
                continue
            score = float(np.sqrt(np.mean(values[finite] ** 2)))
            ops = [int(op) for op in np.flatnonzero(finite & (np.abs(np.nan_to_num(values)) > where_z))]
            if score > where_z / 1.5 and ops:
                entries.append(
                    {"channel": channel, "feature": name, "family": case.layout.families[f], "ops": ops, "score": score}
                )
    entries.sort(key=lambda entry: -entry["score"])
    return entries[:limit]


def _shaft_lines_in_band(z: np.ndarray, case: RigCase, channel: int, where_z: float) -> bool:
    """Whether shaft-order lines inside the low band carry a gap (> ``where_z`` sigma) in some run."""
    low, high = case.processors[0].low_band
    for f, family in enumerate(case.layout.families):
        if not family.startswith("shaft_"):
            continue
        order = case.processors[0].definitions[case.layout.columns[f]].order
        frequency = order * case.speeds / 60.0
        inside = (frequency >= low) & (frequency <= high)
        if np.any(inside & (np.abs(np.nan_to_num(z[:, channel, f])) > where_z)):
            return True
    return False


def family_character(
    z: np.ndarray,
    case: RigCase,
    locked_lines: Sequence[Mapping[str, Any]],
    *,
    noise_gap: float = DEFAULT_SETTINGS.verdict.noise_gap,
    where_z: float = DEFAULT_SETTINGS.verdict.where_z,
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
            per_run = np.array(
                [
                    np.sqrt(np.nanmean(capped_squares(values[op]))) if finite[op].any() else np.nan
                    for op in range(case.n_op)
                ]
            )
            character = []
            if score > noise_gap:
                if family not in ("low_frequency", "broadband"):
                    character.append("order-locked")
                elif family == "low_frequency":
                    low = [line for line in locked_lines if line["frequency"] <= case.processors[0].low_band[1]]
                    if low:
                        character.append("frequency-locked")
                    elif _shaft_lines_in_band(z, case, c, where_z):
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
            rows.append(
                {
                    "channel": channel,
                    "family": family,
                    "score": score,
                    "per_run": [None if not np.isfinite(v) else float(v) for v in per_run],
                    "character": character,
                }
            )
    return rows


__all__ = ["line_signal_to_noise", "uninformative_reason", "where_gap", "family_character"]
