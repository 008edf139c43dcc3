"""The diagnosis on rigs without encoders: the encoder-less blind suite, per effect family.

Runs the campaigns of ``planned_campaigns(seed, suite="encoderless")`` (each
library effect alone on a rig with the two bearing-housing accelerometers and
no TE, its strength drawn across its ladder, every second campaign under speed
wander; two healthy controls) one by one, printing each campaign's verdict as
it comes, then per family the fraction named right and the fraction right
counting ``none`` as right where the effect is invisible (the oracle's gap at
most the noise's), and the controls' verdicts; each campaign's line and each
miss state the oracle's gap over the noise threshold (how far above noise the
effect stood).

Usage: ``python benchmarks/diagnosis_encoderless.py --seeds 1 [--n-per-effect 3] [--workers 1] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from collections import defaultdict
from pathlib import Path
from typing import Any

from uqgear.diagnosis.settings import DEFAULT_SETTINGS
from uqgear.validation import diagnose_campaign, planned_campaigns
from uqgear.validation.campaigns import HEALTHY


def run(seeds: list[int], n_per_effect: int, workers: int, out: Path) -> list[dict[str, Any]]:
    """Every campaign of the suite for each seed, diagnosed blind; their entries (``seed`` added)."""
    entries = []
    for seed in seeds:
        for spec, design, campaign_seed in planned_campaigns(seed, suite="encoderless", n_per_effect=n_per_effect):
            clock = time.perf_counter()
            entry = diagnose_campaign(spec, design, campaign_seed, out / f"seed-{seed}" / spec.identifier,
                                      n_ops=8, duration=1.0, workers=workers)
            entry["seed"] = seed
            entries.append(entry)
            print(f"{seed:4d} {spec.identifier:40s} {spec.strength_value:10.3g} {entry['verdict']:22s} "
                  f"detectable={entry['detectable']!s:5s} {visibility(entry):>12s} "
                  f"{time.perf_counter() - clock:5.0f} s", flush=True)
    return entries


def visibility(entry: dict[str, Any]) -> str:
    """How far above noise the campaign's effect is: the oracle's gap over the noise threshold (``-`` for a control)."""
    if entry["truth"] == HEALTHY:
        return "-"
    return f"{entry['oracle_gap'] / DEFAULT_SETTINGS.verdict.noise_gap:.2f} x noise"


def table(entries: list[dict[str, Any]]) -> None:
    """Per family: named right, and right counting ``none`` where the effect is invisible."""
    rows: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for entry in entries:
        rows[entry["truth"]].append(entry)
    print(f"\n{'family':22s} {'named':>8s} {'right where visible':>20s}")
    for truth, cases in rows.items():
        named = sum(entry["verdict"] == truth for entry in cases)
        right = sum(bool(entry["correct_detectable"]) for entry in cases)
        label = "none (controls)" if truth == HEALTHY else truth
        print(f"{label:22s} {named:4d} / {len(cases):<3d} {right:12d} / {len(cases)}")
    # each visible effect left unnamed, with how far its oracle gap stood above the noise threshold
    for entry in entries:
        if not entry["correct_detectable"]:
            print(f"  missed: {entry['id']} ({entry['verdict']}), {visibility(entry)}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--n-per-effect", type=int, default=3)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        out = args.out or Path(folder)
        entries = run(args.seeds, args.n_per_effect, args.workers, out)
        if args.out is not None:
            (out / "entries.json").write_text(json.dumps(entries, indent=1, default=str))
    table(entries)


if __name__ == "__main__":
    main()
