"""Jump speeds of run-ups and coast-downs against the continuation's folds, at several ramp rates.

On wet rail (T2 = 21.1 kN m) and on dry rail (46.5 kN m) at T1 = 7 kN m, the locomotive gear's period-1
branch is continued over 3400-3900 rpm (:class:`uqgear.dynamics.Continuation`); its folds of stable
stretches are where a slow sweep leaves a branch (direction ``up``: a run-up; ``down``: a coast-down).
Each rate then runs the gear up and down the same span (:func:`uqgear.simulate_runup_batch`), bins the
peak mesh force in 5 rpm bins and finds its jumps (:func:`uqgear.jump_speeds`, threshold 0.15). Prints
per rate and sense the jump speeds and how far past the matching fold they lie in the sense of travel
(a jump is located to a bin: +-5 rpm), and the time of the ramps.

``PYTHONPATH=. python benchmarks/runup_jumps.py [--rates 2000 1000 500 250 125 60 30]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import uqgear
from uqgear.dynamics import Continuation, jump_speeds, ramp_envelope

T1 = 7000.0
SPAN = (3400.0, 3900.0)


def folds(design: uqgear.Design, t2: float) -> dict[str, list[float]]:
    """Fold speeds of stable stretches per sweep direction."""
    table = Continuation("pinion_speed", *SPAN).fit(design, {"drive_torque": T1, "adhesion_torque": t2}).result_
    kinds = table["bifurcation_type"].values.astype(str)
    sweeps = table["bifurcation_sweep"].values.astype(str)
    where = table["bifurcation_parameter"].values
    return {sense: sorted(float(s) for s in where[(kinds == "fold") & (sweeps == sense)]) for sense in ("up", "down")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rates", type=float, nargs="+", default=[2000.0, 1000.0, 500.0, 250.0, 125.0, 60.0, 30.0])
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    edges = np.arange(SPAN[0], SPAN[1] + 0.1, 5.0)
    for t2 in (21.1e3, 46.5e3):
        found = folds(design, t2)
        print(f"T2 = {t2 / 1e3:.1f} kN m: folds up {found['up']} rpm, down {found['down']} rpm")
        print(f"{'rate rpm/s':>10} {'sense':>5} {'jumps rpm':>22} {'past the fold rpm':>18} {'ramp s':>7}")
        samples = uqgear.samples_from_mapping({"drive_torque": [T1], "adhesion_torque": [t2]})
        for rate in args.rates:
            for sense, (first, last) in (("up", SPAN), ("down", SPAN[::-1])):
                began = time.perf_counter()
                profile = uqgear.SpeedProfile.linear(first, last, rate_rpm_per_s=rate if sense == "up" else -rate)
                run = uqgear.simulate_runup_batch(design, profile, samples, sample_rate=10240.0).isel(sample=0)
                jumps = jump_speeds(ramp_envelope(run, speed_bins=edges), threshold=0.15, persistence=3)
                seconds = time.perf_counter() - began
                speeds = [jump.speed for jump in jumps]
                past = [
                    (speed - min(found[sense], key=lambda fold: abs(fold - speed))) * (1 if sense == "up" else -1)
                    for speed in speeds
                    if found[sense]
                ]
                print(
                    f"{rate:10g} {sense:>5} {str(speeds):>22} {str([round(p, 1) for p in past]):>18} {seconds:7.2f}"
                )


if __name__ == "__main__":
    main()
