"""The cost of predicting with a posterior: a prediction study with and without the calibrated posterior.

Calibrates the bundled healthy campaign once (untimed; or takes ``--posterior FILE``), then runs in
fresh processes, after an untimed warm-up that compiles the kernels:

* ``posterior``: a ``prediction`` analysis of 64 joint draws x 7 T2 nodes x 51 speeds (with the
  same from the calibration's prior beside it, as a prediction always has);
* ``without``: the same study with the calibrated parameters as uniform distributions on the
  calibration's prior box instead of the posterior (64 draws of them, no ``_prior``);

and prints both wall times and their ratio (aim: at most 3x). Both run with the study default
(guided starts).

Usage: ``python benchmarks/prediction.py [--posterior cal/posterior.nc] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

import uqgear
from uqgear.calibration.priors import prior_bounds

STUDY = {
    "name": "prediction_cost",
    "seed": 3,
    "design": "locomotive",
    "operating_points": {"pinion_speed": {"start": 1000, "stop": 6000, "num": 51}, "drive_torque": 7000},
    "simulation": {"n_periods": 600, "keep_periods": 200},
    "analyses": [
        {
            "type": "prediction",
            "name": "prediction",
            "parameters": ["adhesion_torque"],
            "points": 7,
            "qois": ["peak_mesh_force", "dynamic_load_factor", "dte_rms"],
        }
    ],
}
T2 = {"adhesion_coefficient": [0.15, 0.33], "axle_load": 23000, "wheel_radius": 0.625}


def run(study: Path, out: Path) -> float:
    began = time.perf_counter()
    subprocess.run(["uqgear", "run", str(study), "--out", str(out)], check=True, capture_output=True)
    return time.perf_counter() - began


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--posterior", type=Path)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        posterior = args.posterior
        if posterior is None:
            uqgear.calibrate(uqgear.example_rig_file("healthy"), root / "calibration", seed=0)
            posterior = root / "calibration" / "posterior.nc"
        draws = uqgear.PosteriorDraws.load(posterior)
        box = prior_bounds(uqgear.load_design("locomotive"), draws.names)
        with_posterior = dict(STUDY, uncertain={"adhesion_torque": T2, "calibrated": {"posterior": str(posterior)}})
        without = dict(
            STUDY,
            uncertain={
                "adhesion_torque": T2,
                **{name: {"distribution": "uniform", "lower": low, "upper": high} for name, (low, high) in box.items()},
            },
        )
        paths = {}
        for label, study in (("posterior", with_posterior), ("without", without)):
            paths[label] = root / f"{label}.yaml"
            paths[label].write_text(yaml.safe_dump(study))
        run(paths["without"], root / "warm-up")
        times = {label: run(path, root / label) for label, path in paths.items()}
        runs = {
            label: int(uqgear.load_result(root / label / "prediction.nc").attrs["model_runs"]) for label in paths
        }
    ratio = times["posterior"] / times["without"]
    print(
        f"prediction, 64 draws x 7 T2 nodes x 51 speeds: with the posterior (and its prior) "
        f"{times['posterior']:.1f} s, {runs['posterior']} runs; without {times['without']:.1f} s, "
        f"{runs['without']} runs; ratio {ratio:.2f}x (aim <= 3x)"
    )
    if args.json:
        args.json.write_text(json.dumps({"seconds": times, "runs": runs, "ratio": ratio}, indent=2))
    sys.stdout.flush()


if __name__ == "__main__":
    main()
