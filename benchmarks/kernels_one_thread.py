"""One-thread CPU time of the batch kernels: for comparing two checkouts run after one another.

Prints, for the checkout it runs from (label it with the first argument), the
CPU time (``time.process_time``, best of 3, one thread) of

* a lane batch: 100 speeds 200-4000 rpm x 10 adhesion torques (1,000 runs),
  200 mesh periods, 100 kept;
* the one-sample kernel on 200 of those runs;
* the same 200 runs with a shaft run-out (eccentricity 12 um, stiffness
  modulation kappa 0.05), whose forcing is not mesh-periodic.

Run it on each checkout in turn, A B A B, so that both see the same load; the
package comes from ``PYTHONPATH``, so this file times any checkout:
``PYTHONPATH=CHECKOUT python benchmarks/kernels_one_thread.py LABEL``.
"""

from __future__ import annotations

import sys
import time

import numpy as np

import uqgear
from uqgear.physics.effects import make_effect


def _best_cpu(design, samples, repeats: int = 3, **kw) -> float:
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        uqgear.simulate_batch(design, samples, n_periods=200, keep_periods=100, threads=1, **kw)
        best = min(best, time.process_time() - start)
    return float(best)


def main() -> None:
    label = sys.argv[1] if len(sys.argv) > 1 else "this checkout"
    design = uqgear.load_design("locomotive")
    lower, upper = design.operation.adhesion_torque_bounds()
    speed, adhesion = np.meshgrid(np.linspace(200.0, 4000.0, 100), np.linspace(lower, upper, 10), indexing="ij")
    samples = uqgear.samples_from_mapping({"pinion_speed": speed.ravel(), "adhesion_torque": adhesion.ravel()})
    run_out = [make_effect("eccentricity", {"amplitude": 12e-6, "kappa": 0.05})]
    # compile (or load) every kernel timed below before timing
    warm = samples.isel(sample=slice(0, 16))
    for kw in ({}, {"lanes": False}, {"lanes": False, "effects": run_out}):
        uqgear.simulate_batch(design, warm, n_periods=4, keep_periods=2, threads=1, **kw)
    one = samples.isel(sample=slice(0, 1000, 5))
    lanes = _best_cpu(design, samples)
    one_sample = _best_cpu(design, one, lanes=False)
    with_run_out = _best_cpu(design, one, lanes=False, effects=run_out)
    print(f"{label}: lanes (1000 runs) {lanes:.2f} s CPU, one-sample (200 runs) {one_sample:.2f} s CPU, "
          f"one-sample with run-out (200 runs) {with_run_out:.2f} s CPU")


if __name__ == "__main__":
    main()
