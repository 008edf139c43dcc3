"""The report section of a ``rating`` analysis: ISO 6336 safety factors from the simulated load beside ISO's K_v.

One figure: the simulated dynamic factor's band over the interval parameters against ISO 6336-1
method B's K_v curve (its resonance speed marked), and the root and flank safety factors' bands
per gear against speed with ISO's and the required minimum beside them. The findings give, per
failure mode, the smallest safety factor over the interval, where, against the minimum and
against ISO's at that speed, and the damage over the stated service.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import numpy as np
import xarray as xr
from matplotlib import colormaps

from .finding import Finding
from .page import new_figure
from .sections import Section, add_figure, renderer, section_from_attrs

#: Failure modes of a rating: (variable suffix, what fails).
RATING_MODES = (("root", "tooth root"), ("contact", "flank"))


def rating_verdicts(ds: xr.Dataset) -> list[str]:
    """One line per failure mode: the smallest safety factor over the interval, where, against the minimum.

    Examples
    --------
    >>> import numpy as np
    >>> import xarray as xr
    >>> from uqgear.report.rating_sections import rating_verdicts
    >>> dims = ("gear", "bound", "pinion_speed")
    >>> ds = xr.Dataset(
    ...     {
    ...         "safety_factor_root": (dims, np.array([[[1.2, 2.0], [1.8, 2.5]], [[1.5, 2.2], [2.0, 2.6]]])),
    ...         "safety_factor_root_iso": (("gear", "pinion_speed"), np.array([[1.6, 2.1], [1.7, 2.3]])),
    ...         "damage": (("gear", "bound", "mode"), np.array([[[0.0, 0.0], [0.3, 0.0]], [[0.0, 0.0], [0.1, 0.0]]])),
    ...     },
    ...     coords={"gear": ["pinion", "gear"], "bound": ["lower", "upper"], "pinion_speed": [3000.0, 4000.0],
    ...             "mode": ["root", "contact"]},
    ... )
    >>> ds["safety_factor_root"].attrs["minimum"] = 1.4
    >>> ds.attrs["service"] = '{"hours": 20000}'
    >>> for part in rating_verdicts(ds)[0].split("; "):
    ...     print(part)
    tooth root: S_F falls to 1.20 (pinion, 3000 rpm) against the required 1.4 (below it)
    ISO's K_v gives 1.60 there
    Miner damage over 20000 h up to 0.3 (pinion, at least 0 over the rail condition)
    """
    return [finding.text for finding in _verdicts(ds)]


def _verdicts(ds: xr.Dataset) -> list[Finding]:
    findings = []
    service = json.loads(str(ds.attrs.get("service", "{}")))
    hours = service.get("hours")
    for mode, what in RATING_MODES:
        name = f"safety_factor_{mode}"
        if name not in ds:
            continue
        lower = ds[name].sel(bound="lower")
        index = np.unravel_index(int(np.nanargmin(lower.values)), lower.shape)
        facts: dict[str, Any] = {
            "mode": mode,
            "gear": str(lower["gear"].values[index[0]]),
            "pinion_speed": float(lower["pinion_speed"].values[index[1]]),
            "safety_factor": float(lower.values[index]),
            "minimum": float(ds[name].attrs.get("minimum", np.nan)),
        }
        value, minimum = float(lower.values[index]), float(ds[name].attrs.get("minimum", np.nan))
        verdict = "below it" if value < minimum else "above it"
        symbol = "S_F" if mode == "root" else "S_H"
        text = (
            f"{what}: {symbol} falls to {facts['safety_factor']:.2f} ({facts['gear']}, "
            f"{facts['pinion_speed']:.0f} rpm) against the required {facts['minimum']:g} ({verdict})"
        )
        text += _beyond_campaign(ds, facts)
        if f"{name}_iso" in ds:
            facts["safety_factor_iso"] = float(ds[f"{name}_iso"].values[index])
            text += f"; ISO's K_v gives {facts['safety_factor_iso']:.2f} there"
        if "damage" in ds and hours is not None:
            facts["damage"] = float(ds["damage"].sel(mode=mode).max())
            text += (
                f"; Miner damage over {hours:g} h up to {facts['damage']:.3g}"
                if facts["damage"] > 0.0
                else f"; no fatigue damage over {hours:g} h (every cycle below the long-life stress)"
            )
            if facts["damage"] > 0.0:
                text += _damage_detail(ds, mode, facts)
        findings.append(Finding(text, facts, topic="rating"))
    return findings


def _beyond_campaign(ds: xr.Dataset, facts: dict[str, Any]) -> str:
    """Where a calibrated gear set's worst speed lies beyond the rig campaign's speeds: said, with the range."""
    campaign = json.loads(str(ds.attrs.get("campaign_range", "{}")))
    if "pinion_speed" not in campaign:
        return ""
    low, high = campaign["pinion_speed"]
    speed = facts["pinion_speed"]
    facts["beyond_campaign"] = bool(speed < low - 1e-9 * high or speed > high * (1 + 1e-9))
    if not facts["beyond_campaign"]:
        return ""
    return f", beyond the rig campaign's {low:.0f}-{high:.0f} rpm (the model, not the rig data, carries it)"


def _damage_detail(ds: xr.Dataset, mode: str, facts: dict[str, Any]) -> str:
    """The damage's lower bound over the rail condition, the life and the service speed that contributes most."""
    upper = ds["damage"].sel(mode=mode, bound="upper")
    gear = str(upper["gear"].values[int(np.argmax(upper.values))])
    text = (
        f" ({gear}, at least {float(ds['damage'].sel(mode=mode, bound='lower', gear=gear)):.3g} over the rail condition"
    )
    if "life_hours" in ds:
        facts["life_hours"] = float(ds["life_hours"].sel(mode=mode, bound="upper", gear=gear))
        text += f", a life of {facts['life_hours']:.3g} h of this service"
    if "damage_share" in ds:
        share = ds["damage_share"].sel(mode=mode, gear=gear)
        k = int(np.argmax(share.values))
        facts["speed_most"] = float(share["service_speed"].values[k])
        text += f", most of it at {facts['speed_most']:.0f} rpm: {float(share.values[k]):.0%}"
    return text + _attractor_detail(ds, mode, gear, float(upper.sel(gear=gear)), facts) + ")"


def _attractor_detail(ds: xr.Dataset, mode: str, gear: str, upper: float, facts: dict[str, Any]) -> str:
    """Where coexisting responses raise the upper damage: the runs from rest's damage, and which starts."""
    if "damage_from_rest" not in ds or "damage_rate_start" not in ds:
        return ""
    rest = float(ds["damage_from_rest"].sel(mode=mode, bound="upper", gear=gear))
    if not upper > rest * (1.0 + 1e-9):
        return ""
    starts = ds["damage_rate_start"].sel(mode=mode, gear=gear)
    speeds = sorted({float(n) for n in starts["pinion_speed"].values[np.nonzero(starts.values != "rest")[-1]]})
    facts["damage_from_rest"] = rest
    facts["attractor_speeds"] = speeds
    listed = ", ".join(f"{n:.0f}" for n in speeds)
    return f"; {rest:.3g} from rest, the rest from coexisting responses at {listed} rpm"


def rating_findings(results: Sequence[xr.Dataset]) -> list[Finding]:
    """The first screen's verdict of every ``rating`` result: one line per failure mode."""
    return [
        finding for ds in results if str(ds.attrs.get("analysis_type", "")) == "rating" for finding in _verdicts(ds)
    ]


@renderer("rating")
def _render_rating(ds: xr.Dataset, dpi: int) -> Section:
    section = section_from_attrs(ds)
    if "dynamic_factor" not in ds:
        return section
    speeds = np.asarray(ds["pinion_speed"].values, dtype=float)
    figure = new_figure(9.0, 8.4)
    axes = figure.subplots(3, 1, sharex=True)
    band = colormaps["cividis"](0.75)
    factor = ds["dynamic_factor"]
    axes[0].fill_between(
        speeds,
        factor.sel(bound="lower"),
        factor.sel(bound="upper"),
        color=band,
        alpha=0.6,
        label="simulated (peak over static mesh force)",
    )
    axes[0].plot(speeds, ds["dynamic_factor_iso"], color="black", linestyle="--", label="ISO 6336-1 method B K_v")
    resonance = ds.attrs.get("resonance_speed_iso")
    if resonance is not None:
        axes[0].axvline(float(resonance), color="grey", linewidth=0.8, label=f"ISO n_E1 = {float(resonance):.0f} rpm")
    axes[0].set_ylabel("dynamic factor [-]")
    axes[0].legend(fontsize=7, loc="best")
    for ax, (mode, what) in zip(axes[1:], RATING_MODES):
        name = f"safety_factor_{mode}"
        for g, gear in enumerate(ds["gear"].values):
            colour = colormaps["cividis"](0.2 + 0.5 * g)
            values = ds[name].sel(gear=gear)
            ax.fill_between(
                speeds,
                values.sel(bound="lower"),
                values.sel(bound="upper"),
                color=colour,
                alpha=0.45,
                label=f"{gear}, simulated load",
            )
            if f"{name}_iso" in ds:
                ax.plot(
                    speeds, ds[f"{name}_iso"].sel(gear=gear), color=colour, linestyle="--", label=f"{gear}, ISO K_v"
                )
        ax.axhline(float(ds[name].attrs.get("minimum", np.nan)), color="red", linewidth=0.8, label="required minimum")
        ax.set_ylabel(f"{what} safety factor [-]")
        ax.legend(fontsize=7, loc="best")
    axes[-1].set_xlabel("pinion speed [rpm]")
    add_figure(section, figure, "Dynamic factor and ISO 6336 safety factors over the interval against speed", dpi)
    section.findings.extend(rating_verdicts(ds))
    return section


__all__ = ["rating_verdicts", "rating_findings", "RATING_MODES"]
