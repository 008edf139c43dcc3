"""The cost of tooth-stress QoIs: the main study's interval analysis with and without them.

Takes the bundled main study (``t2_envelope``) with its ``interval`` analysis alone, once with its
own QoIs and once with the eight tooth stresses added (``root_stress_peak_pinion`` ...), runs each in
a fresh ``python -m uqgear run`` process after one untimed warm-up that compiles the kernels,
alternating the two ``--repeats`` times (the machine's load drifts; alternating spreads it over
both), and prints the median wall times, their ratio, the same for the processes' CPU time (user
and system: less moved by other work on a shared machine than the wall time), and which of the
analysis's own QoIs' bounds differ (only where a point that a stress's surrogate flags is scanned
for every QoI).

Usage: ``python benchmarks/stress_qois.py [--study t2_envelope] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

STUDIES = Path(__file__).resolve().parents[1] / "uqgear" / "data" / "studies"
STRESSES = [
    f"{quantity}_{gear}"
    for quantity in ("root_stress_peak", "root_stress_amplitude", "contact_stress_peak", "contact_stress_amplitude")
    for gear in ("pinion", "gear")
]


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run(study: Path, out: Path) -> tuple[float, float]:
    """(wall, CPU) seconds of one ``uqgear run`` of ``study``."""
    began = time.perf_counter()
    cpu = _children_cpu()
    # this interpreter's uqgear (the checkout on PYTHONPATH), not whichever console script is first on PATH
    command = [sys.executable, "-m", "uqgear", "run", str(study), "--out", str(out), "--quiet"]
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - began, _children_cpu() - cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", default="t2_envelope")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    import numpy as np
    import xarray as xr

    raw = yaml.safe_load((STUDIES / f"{args.study}.yaml").read_text())
    interval = next(analysis for analysis in raw["analyses"] if analysis["type"] == "interval")
    name = interval.get("name", "interval")
    plain = dict(raw, analyses=[interval])
    stressed = dict(raw, analyses=[dict(interval, qois=[*interval.get("qois", []), *STRESSES])])
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        paths = {"without": root / "without.yaml", "with": root / "with.yaml"}
        paths["without"].write_text(yaml.safe_dump(plain))
        paths["with"].write_text(yaml.safe_dump(stressed))
        run(paths["with"], root / "warm-up")
        times: dict[str, list[float]] = {"with": [], "without": []}
        cpu: dict[str, list[float]] = {"with": [], "without": []}
        for k in range(args.repeats):
            for mode in ("without", "with"):
                wall, used = run(paths[mode], root / f"{mode}-{k}")
                times[mode].append(wall)
                cpu[mode].append(used)
        median = {mode: statistics.median(values) for mode, values in times.items()}
        median_cpu = {mode: statistics.median(values) for mode, values in cpu.items()}
        a = xr.load_dataset(root / "without-0" / f"{name}.nc")
        b = xr.load_dataset(root / "with-0" / f"{name}.nc")
    moved = [q for q in interval.get("qois", []) if not np.array_equal(a[q].values, b[q].values, equal_nan=True)]
    peak = float(b["root_stress_peak_pinion"].max()) / 1e6
    print(f"study {args.study}, analysis {name} ({interval.get('method', 'chebyshev')}), {args.repeats} repeats")
    for mode in ("without", "with"):
        print(f"  {mode:8s} stresses: median {median[mode]:6.1f} s  ({', '.join(f'{t:.1f}' for t in times[mode])})")
    print(f"  ratio with / without: {median['with'] / median['without']:.2f}x")
    for mode in ("without", "with"):
        listed = ", ".join(f"{t:.1f}" for t in cpu[mode])
        print(f"  {mode:8s} stresses: median CPU {median_cpu[mode]:6.1f} s  ({listed})")
    print(f"  CPU ratio with / without: {median_cpu['with'] / median_cpu['without']:.2f}x")
    # a point whose stress bounds the surrogate flags is scanned for every QoI: its other bounds may move
    print(f"  kernel QoIs whose bounds differ: {moved or 'none'}; highest pinion root stress {peak:.0f} MPa")


if __name__ == "__main__":
    main()
