"""The cost of seeing every response: a study from rest only, with every start at every point, and guided.

For each study named (default: the bundled main study ``t2_envelope``) it runs ``uqgear run`` in a
fresh process three times, after one untimed warm-up run that compiles the kernels:

* ``starts: false``: every point from rest (what a study without guided starts ran);
* ``starts: true``: every point from rest, its sweep neighbours and random states;
* the default, guided starts: extra starts only inside the windows the continuation finds;

and prints the wall times, the guided and the every-start time over the from-rest time, and where
each found coexisting responses: the report's first-screen sentences, and the grid points (analysis, speed,
other inputs) with more than one attractor.

The random starts of ``starts: true`` find some responses at some seeds only (a basin a few per cent of the
box). ``--every-seeds K`` runs the every-start study K times with the seeds seed, seed + 1, ... (untimed
after the first) and calls a point *robust* when every one of them finds coexisting responses there; the
guided run is checked against the robust points.

``--repeat K`` (default 3) times K from-rest and guided runs, alternating, and prints the median and the
worst of the K ratios: one pair's ratio moves by 0.1-0.3 with what else the machine does.

Usage: ``python benchmarks/coexistence.py [--studies t2_envelope paper_speed nonlinear_windows]
[--every-seeds K] [--repeat K] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

STUDIES = Path(__file__).resolve().parents[1] / "uqgear" / "data" / "studies"
MODES = {"rest": False, "every": True, "guided": "guided"}


def run(study: Path, out: Path) -> float:
    began = time.perf_counter()
    subprocess.run(["uqgear", "run", str(study), "--out", str(out)], check=True, capture_output=True)
    return time.perf_counter() - began


def found(out: Path) -> list[str]:
    html = (out / "report.html").read_text()
    return sorted(set(re.findall(r"\d+ steady responses coexist [^<(]*", html)))


def points(out: Path) -> set[str]:
    """Every grid point of every result with more than one attractor, as 'analysis: input=value, ...'."""
    import numpy as np
    import xarray as xr

    held = set()
    for path in sorted(out.glob("*.nc")):
        with xr.open_dataset(path) as ds:
            if "attractor_count" not in ds or "pinion_speed" not in ds["attractor_count"].dims:
                continue
            count = ds["attractor_count"]
            for index in zip(*np.nonzero(count.values > 1)):
                where = ", ".join(f"{dim}={float(ds[dim].values[i]):.6g}" for dim, i in zip(count.dims, index))
                held.add(f"{path.stem}: {where}")
    return held


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", nargs="+", default=["t2_envelope"])
    parser.add_argument("--every-seeds", type=int, default=1)
    parser.add_argument("--repeat", type=int, default=3, help="alternating from-rest and guided runs timed")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    report = {}
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        for name in args.studies:
            raw = yaml.safe_load((STUDIES / f"{name}.yaml").read_text())
            paths = {}
            for mode, value in MODES.items():
                variant = dict(raw, simulation={**(raw.get("simulation") or {}), "starts": value})
                paths[mode] = root / f"{name}-{mode}.yaml"
                paths[mode].write_text(yaml.safe_dump(variant))
            run(paths["guided"], root / f"{name}-warm-up")
            times = {mode: run(path, root / f"{name}-{mode}") for mode, path in paths.items()}
            # the from-rest and guided runs again, alternating: the ratio of each pair, then the median and worst
            pairs = [times["guided"] / times["rest"]]
            for k in range(1, args.repeat):
                rest = run(paths["rest"], root / f"{name}-rest-{k}")
                pairs.append(run(paths["guided"], root / f"{name}-guided-{k}") / rest)
            windows = {mode: found(root / f"{name}-{mode}") for mode in MODES}
            held = {mode: points(root / f"{name}-{mode}") for mode in MODES}
            robust = set(held["every"])
            for k in range(1, args.every_seeds):
                variant = dict(yaml.safe_load(paths["every"].read_text()), seed=int(raw.get("seed", 0)) + k)
                again = root / f"{name}-every-{k}.yaml"
                again.write_text(yaml.safe_dump(variant))
                run(again, root / f"{name}-every-{k}")
                robust &= points(root / f"{name}-every-{k}")
            report[name] = {
                "seconds": times,
                "guided_over_rest": pairs,
                "found": windows,
                "points": {mode: sorted(values) for mode, values in held.items()},
                "robust": sorted(robust),
            }
            print(f"{name}: from rest {times['rest']:.1f} s, every start {times['every']:.1f} s "
                  f"({times['every'] / times['rest']:.2f}x), guided {times['guided']:.1f} s "
                  f"({times['guided'] / times['rest']:.2f}x; aim <= 1.35x)")
            if len(pairs) > 1:
                print(f"  guided / rest over {len(pairs)} alternating pairs: median {statistics.median(pairs):.2f}x, "
                      f"worst {max(pairs):.2f}x ({', '.join(f'{r:.2f}' for r in pairs)})")
            for mode in ("every", "guided"):
                print(f"  {mode}: {len(windows[mode])} coexistence statements")
                for line in windows[mode]:
                    print(f"    {line.strip()}")
            missed = set(windows["every"]) - set(windows["guided"])
            print(f"  every-start statements the guided run does not make word for word: {len(missed)}")
            print(f"  points with coexisting responses: every start {len(held['every'])}, guided {len(held['guided'])}"
                  f", found by all {args.every_seeds} every-start seed(s) {len(robust)}")
            for line in sorted(robust - held["guided"]):
                print(f"    robust, missed by guided: {line}")
            for line in sorted(held["every"] - held["guided"] - robust):
                print(f"    every-start seed {raw.get('seed', 0)} only, missed by guided: {line}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
