"""The cost of seeing every response: a study from rest only, with every start at every point, and guided.

For each study named (default: the bundled main study ``t2_envelope``) it runs ``uqgear run`` in a
fresh process three times, after one untimed warm-up run that compiles the kernels:

* ``starts: false``: every point from rest (what a study without guided starts ran);
* ``starts: true``: every point from rest, its sweep neighbours and random states;
* the default, guided starts: extra starts only inside the windows the continuation finds;

and prints the wall times, the guided and the every-start time over the from-rest time, and where
each found coexisting responses (the report's first-screen sentences).

Usage: ``python benchmarks/coexistence.py [--studies t2_envelope paper_speed nonlinear_windows] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import re
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--studies", nargs="+", default=["t2_envelope"])
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
            windows = {mode: found(root / f"{name}-{mode}") for mode in MODES}
            report[name] = {"seconds": times, "found": windows}
            print(f"{name}: from rest {times['rest']:.1f} s, every start {times['every']:.1f} s "
                  f"({times['every'] / times['rest']:.2f}x), guided {times['guided']:.1f} s "
                  f"({times['guided'] / times['rest']:.2f}x; aim <= 1.35x)")
            for mode in ("every", "guided"):
                print(f"  {mode}: {len(windows[mode])} coexistence statements")
                for line in windows[mode]:
                    print(f"    {line.strip()}")
            missed = set(windows["every"]) - set(windows["guided"])
            print(f"  every-start statements the guided run does not make word for word: {len(missed)}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
