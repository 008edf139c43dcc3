"""The calibration report's model discrepancy: its headline finding and its section.

A calibration with ``discrepancy=True`` (:mod:`uqgear.calibration.discrepancy`)
says per channel how much of the posterior-predictive variance is the
discrepancy's and how far its mean shifts the log amplitudes, and per
(channel, harmonic) group the posterior of its scale tau.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

from .finding import Finding

#: Sources of the posterior-predictive variance, in the order of the report's table.
SOURCES = ("discrepancy", "parameters", "model_error", "noise", "emulator")


def discrepancy_finding(discrepancy: Mapping[str, Any]) -> Finding:
    """The headline finding: each channel's discrepancy share and the size of its mean.

    Examples
    --------
    >>> finding = discrepancy_finding({"share": {"te": 0.1}, "rms_mean": {"te": 0.05}})
    >>> finding.text.startswith("Model discrepancy: its share of the posterior-predictive variance te 10 %")
    True
    """
    shares, rms = discrepancy["share"], discrepancy["rms_mean"]
    text = (
        "Model discrepancy: its share of the posterior-predictive variance "
        + ", ".join(f"{channel} {100 * share:.0f} %" for channel, share in shares.items())
        + " (the rest: parameters, iid model error, sensor noise and emulator error); its mean shifts the "
        "log amplitudes by (rms) "
        + ", ".join(f"{channel} {value:.3g}" for channel, value in rms.items())
        + "."
    )
    return Finding(text, {"share": dict(shares), "rms_mean": dict(rms)}, "discrepancy")


def discrepancy_section(
    discrepancy: Mapping[str, Any], table: Callable[[Sequence[Sequence[Any]], Sequence[str]], str]
) -> list[str]:
    """The section's HTML parts: each channel's variance shares and the size of the mean, tau per group.

    Examples
    --------
    >>> entry = {"variance_shares": {"te": dict.fromkeys(SOURCES, 0.2)}, "rms_mean": {"te": 0.05},
    ...          "groups": {"te_mesh1": {"tau": {"q05": 0.01, "q50": 0.02, "q95": 0.05}}}}
    >>> parts = discrepancy_section(entry, lambda rows, header: f"{len(rows)} x {len(header)}")
    >>> parts[1:]
    ['1 x 7', '1 x 4']
    """
    shares = discrepancy["variance_shares"]
    return [
        "<h2>Model discrepancy (log amplitude)</h2>",
        table(
            [
                (channel, *(f"{100 * entry[source]:.1f} %" for source in SOURCES), discrepancy["rms_mean"][channel])
                for channel, entry in shares.items()
            ],
            ("channel", "discrepancy", "parameters", "iid model error", "sensor noise", "emulator", "rms of its mean"),
        ),
        table(
            [
                (group, entry["tau"]["q05"], entry["tau"]["q50"], entry["tau"]["q95"])
                for group, entry in discrepancy["groups"].items()
            ],
            ("group", "tau q05", "tau q50", "tau q95"),
        ),
    ]


__all__ = ["SOURCES", "discrepancy_finding", "discrepancy_section"]
