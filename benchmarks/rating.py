"""The cost of the ISO 6336 rating in the main study: ``t2_envelope`` with and without its ``rating`` analysis.

Runs ``python -m uqgear run`` in a fresh process on the bundled main study and on the same study without its
rating analyses, after one untimed warm-up run that compiles the kernels, alternating the two
``--repeats`` times (the machine's load drifts; alternating spreads it over both), and prints the
median wall times and their ratio (aim: at most 1.3x), with the rating analysis's own model runs
and run time from its result file.

Usage: ``python benchmarks/rating.py [--study t2_envelope] [--repeats 3]``
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

STUDIES = Path(__file__).resolve().parents[1] / "uqgear" / "data" / "studies"


def run(study: Path, out: Path) -> float:
    began = time.perf_counter()
    # this interpreter's uqgear (the checkout on PYTHONPATH), not whichever console script is first on PATH
    command = [sys.executable, "-m", "uqgear", "run", str(study), "--out", str(out), "--quiet"]
    subprocess.run(command, check=True, capture_output=True)
    return time.perf_counter() - began


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", default="t2_envelope")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    import xarray as xr

    raw = yaml.safe_load((STUDIES / f"{args.study}.yaml").read_text())
    ratings = [analysis for analysis in raw["analyses"] if analysis["type"] == "rating"]
    if not ratings:
        raise SystemExit(f"{args.study}: no rating analysis to measure")
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        paths = {"with": root / "with.yaml", "without": root / "without.yaml"}
        paths["with"].write_text(yaml.safe_dump(raw))
        paths["without"].write_text(
            yaml.safe_dump(dict(raw, analyses=[a for a in raw["analyses"] if a["type"] != "rating"]))
        )
        run(paths["with"], root / "warm-up")
        times: dict[str, list[float]] = {"with": [], "without": []}
        for k in range(args.repeats):
            for mode in ("without", "with"):
                times[mode].append(run(paths[mode], root / f"{mode}-{k}"))
        median = {mode: statistics.median(values) for mode, values in times.items()}
        name = ratings[0].get("name", "rating")
        with xr.open_dataset(root / "with-0" / f"{name}.nc") as ds:
            runs, seconds = int(ds.attrs["model_runs"]), float(ds.attrs["run_time_s"])
    print(
        f"{args.study}: without the rating {median['without']:.1f} s, with it {median['with']:.1f} s "
        f"({median['with'] / median['without']:.2f}x; aim <= 1.3x); median of {args.repeats}"
    )
    print(f"  {name}: {runs} model runs, {seconds:.1f} s in the analysis")
    print("  all times: " + "; ".join(f"{mode} " + ", ".join(f"{t:.1f}" for t in ts) for mode, ts in times.items()))


if __name__ == "__main__":
    main()
