"""Diagnosis benchmark: one 8-op campaign, all six candidate effects, on 2 worker processes.

Runs :func:`uqgear.diagnosis.workflow.diagnose` on a labelled campaign of data/rig/
(default ``tooth_damage.nc``) and prints the verdict, the wall time, the CPU
time (this process and its workers) and where the time went (nominal fit,
screening of the candidates, full fits). The acceptance figure of issue 6 is
at most 5 minutes on 2 cores.

Usage: ``python benchmarks/diagnosis.py [FILE ...] [--workers N]``; with several files (or
``all``) each is diagnosed in turn and a table is printed.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from uqgear.diagnosis.workflow import diagnose

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"
LABELS = {"healthy.nc": "none", "healthy_b.nc": "none", "eccentricity.nc": "eccentricity",
          "tooth_damage.nc": "tooth_damage", "torque_ripple.nc": "torque_ripple",
          "adhesion_oscillation.nc": "adhesion_oscillation", "friction.nc": "friction"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", default=["tooth_damage.nc"], help="rig files in data/rig/ or 'all'")
    parser.add_argument("--workers", type=int, default=None,
                        help="worker processes (default: the library default, one per two CPUs)")
    args = parser.parse_args()
    files = sorted(LABELS) if args.files == ["all"] else args.files
    print(f"cpus available: {os.cpu_count()}, workers: {args.workers}, load average: "
          f"{', '.join(f'{v:.1f}' for v in os.getloadavg())}")
    rows = []
    for name in files:
        path = Path(name) if Path(name).is_file() else DATA / name
        with tempfile.TemporaryDirectory() as out:
            started = time.perf_counter()
            content = diagnose(path, out, seed=0, workers=args.workers)
            wall = time.perf_counter() - started
        timing = content["timing_s"]
        label = LABELS.get(path.name, "?")
        rows.append((path.name, label, content["verdict"], content["gap"]["baseline"],
                     content["gap"]["shrink_fraction"], wall, timing["total_cpu"], timing["nominal_fit"],
                     timing["screening"], timing["full_fits"]))
        print(f"{path.name}: verdict {content['verdict']} (label {label}); wall {wall:.0f} s, CPU {timing['total_cpu']:.0f} s "
              f"(nominal fit {timing['nominal_fit']:.0f} s, screening {timing['screening']:.0f} s, "
              f"full fits {timing['full_fits']:.0f} s)", flush=True)
    print()
    print(f"{'file':26s} {'label':22s} {'verdict':22s} {'gap':>7s} {'shrink':>7s} {'wall s':>7s} {'CPU s':>7s}")
    for name, label, verdict, gap, shrink, wall, cpu, *_ in rows:
        shrink_text = "-" if shrink is None else f"{shrink:.2f}"
        print(f"{name:26s} {label:22s} {verdict:22s} {gap:7.2f} {shrink_text:>7s} {wall:7.0f} {cpu:7.0f}")
    print(f"load average at the end: {', '.join(f'{v:.1f}' for v in os.getloadavg())}")


if __name__ == "__main__":
    main()
