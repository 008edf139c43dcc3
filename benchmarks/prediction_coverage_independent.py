"""Coverage of calibrated predictions on the independent simulator's labelled campaigns.

The seven labelled campaigns (``healthy``, ``healthy_b`` and one effect each: eccentricity, tooth damage,
torque ripple, adhesion oscillation, friction) come from an independent implementation of the model, with
the true parameters and effects of their README. Each is calibrated with the discrepancy term (without it:
``--without-discrepancy``) and its true effect in the model (as a study calibrates once its diagnosis has
named the effect), at a given floor of the model-error prior, and predicts peak mesh force, dynamic
load factor and RMS DTE at the four held-out operating points of ``prediction_coverage.py``, 64 posterior
draws each carrying its discrepancy.
The truth is, as there, the model at the file's true parameters with its true effect.

Unlike ``prediction_coverage.py``, whose campaigns are simulated by the model's own integrator, these records
carry the small systematic differences between two implementations of the model that the model-error floor
is set for: the pair tells a floor that is too wide on the model's own data from one that is too narrow on
another implementation's.

Prints one JSON record per file (parameter z-scores of the truth against the posterior, the model-error level
of each group, coverage, the truth's place among the draws) and the pooled coverage.

Usage: ``python benchmarks/prediction_coverage_independent.py [--model-error-floor 0.01] [--without-discrepancy]
[--files healthy ...] [--rig-dir data/rig] [--json out.json]`` (the campaigns are read from the repository's
``data/rig``, or another folder of the same files).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from prediction_coverage import (
    DRAWS,
    QOIS,
    calibration_options,
    discrepancy_factors,
    place_shares,
    posterior_record,
    predict,
    scored,
)

import uqgear
from uqgear.physics.effects import make_effect


def _truth(scale: float, zeta: float, backlash_mm: float, ste_um: float, k1: float, k2: float) -> dict[str, float]:
    return {"mesh_stiffness_scale": scale, "zeta_mesh": zeta, "backlash": backlash_mm * 1e-3,
            "ste_amplitude": ste_um * 1e-6, "k1": k1 * 1e9, "k2": k2 * 1e9}


#: The labelled campaigns' true parameters (their README's table).
TRUTH = {
    "healthy": _truth(0.970, 0.052, 0.300, 16.07, 1.010, 1.889),
    "healthy_b": _truth(0.982, 0.061, 0.315, 17.67, 0.902, 1.984),
    "eccentricity": _truth(1.086, 0.063, 0.280, 16.73, 0.966, 2.131),
    "tooth_damage": _truth(0.986, 0.043, 0.273, 16.76, 0.968, 1.856),
    "torque_ripple": _truth(0.936, 0.067, 0.301, 12.32, 1.042, 1.956),
    "adhesion_oscillation": _truth(1.039, 0.045, 0.275, 17.90, 1.002, 1.822),
    "friction": _truth(1.002, 0.044, 0.296, 15.60, 0.968, 1.910),
}
#: Their true effects.
EFFECTS = {
    "eccentricity": {"shaft": "pinion", "amplitude": 12e-6, "phase": 1.75, "kappa": 0.03},
    "tooth_damage": {"gear": "pinion", "tooth": 7, "depth": 0.35},
    "torque_ripple": {"amplitude": 0.06, "phase": 6.26, "pole_pairs": 3},
    "adhesion_oscillation": {"amplitude": 0.05, "frequency": 12.0, "phase": 4.72},
    "friction": {"coefficient": 0.08},
}
RIG_DIR = Path(__file__).resolve().parent.parent / "data" / "rig"


def load(name: str, rig_dir: Path) -> xr.Dataset:
    with xr.open_dataset(rig_dir / f"{name}.nc") as rig:
        return rig.load()


def one_file(
    name: str, rig_dir: Path, floor: float | None, design: uqgear.Design, discrepancy: bool = True
) -> dict[str, Any]:
    began = time.perf_counter()
    effects = [make_effect(name, EFFECTS[name])] if name in EFFECTS else []
    calibration = uqgear.Calibration(
        design=design, seed=0, discrepancy=discrepancy, effects=effects, **calibration_options(floor)
    ).fit(load(name, rig_dir))
    truth = TRUTH[name]
    entry: dict[str, Any] = {
        "file": name, "converged": bool(calibration.converged_), **posterior_record(calibration, truth)
    }
    space = uqgear.ParameterSpace.from_posterior(calibration, draws=DRAWS, seed=0, allow_unconverged=True)
    draws = {key: space.posterior.column(key) for key in space.posterior.names}
    effect_sets = [tuple(effects)] * DRAWS if effects else None
    true_values = predict({k: np.array([v]) for k, v in truth.items()}, [tuple(effects)] if effects else None, design)
    factors = discrepancy_factors(calibration, space) if discrepancy else None
    predicted = predict(draws, effect_sets, design, factors)
    entry.update(scored(predicted, true_values))
    entry["seconds"] = round(time.perf_counter() - began, 1)
    return entry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rig-dir", type=Path, default=RIG_DIR)
    parser.add_argument("--files", nargs="+", default=list(TRUTH))
    parser.add_argument("--model-error-floor", type=float, default=None,
                        help="the model-error prior's lower end (default: the calibration's)")
    parser.add_argument("--without-discrepancy", action="store_true", help="the ordinary calibration")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    entries = []
    for name in args.files:
        entry = one_file(name, args.rig_dir, args.model_error_floor, design, not args.without_discrepancy)
        entries.append(entry)
        print(json.dumps(entry), flush=True)
    z = np.array([value for entry in entries for value in entry["z"].values()])
    print(f"parameters: RMS z {np.sqrt(np.mean(z ** 2)):.2f} (1 if calibrated), "
          f"inside +-1.645: {np.mean(np.abs(z) <= 1.645) * 100:.0f} % of {z.size} (90 %)")
    for qoi in QOIS:
        flags = [flag for entry in entries for flag in entry["covered"][qoi]]
        pits = np.array([value for entry in entries for value in entry["pit"][qoi]])
        central, tails = place_shares(pits)
        print(f"{qoi:20s} covered {np.mean(flags) * 100:5.1f} % of {len(flags)}; truth's place: central half "
              f"{central * 100:5.1f} % (50 %), outer tenths {tails * 100:5.1f} % (20 %)")
    if args.json:
        args.json.write_text(json.dumps(entries, indent=2))


if __name__ == "__main__":
    main()
