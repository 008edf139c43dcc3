"""One-thread CPU time of the batch kernels with and without the tooth-pair load extremes (``stresses=True``).

The main study's interval nodes (51 speeds 1000-6000 rpm x 7 adhesion torques, 357 runs, 600 mesh
periods, 200 kept) in SIMD lanes, and every fifth of them (72) one sample at a time, each timed without and with
the extremes the tooth stresses follow from (``time.process_time``, best of 3, one thread,
alternated); prints the times and their ratios. The extremes are kept at every kept grid step, in
the same pass.

Usage: ``python benchmarks/kernel_stresses.py``
"""

from __future__ import annotations

import time

import numpy as np

import uqgear


def _cpu(design, samples, **kw) -> float:
    start = time.process_time()
    uqgear.simulate_batch(design, samples, n_periods=600, keep_periods=200, threads=1, **kw)
    return time.process_time() - start


def main() -> None:
    design = uqgear.load_design("locomotive")
    speeds = np.repeat(np.linspace(1000.0, 6000.0, 51), 7)
    lower, upper = design.operation.adhesion_torque_bounds()
    adhesion = np.tile(np.linspace(lower, upper, 7), 51)
    samples = uqgear.samples_from_mapping({"pinion_speed": speeds, "adhesion_torque": adhesion})
    one = samples.isel(sample=slice(0, len(speeds), 5))
    for kw in ({}, {"lanes": False}):
        for stresses in (False, True):
            # compile (or load) every kernel timed below before timing
            uqgear.simulate_batch(design, samples.isel(sample=slice(0, 16)), n_periods=4, keep_periods=2,
                                  threads=1, stresses=stresses, **kw)
    for name, batch, kw in (("lanes", samples, {}), ("one-sample", one, {"lanes": False})):
        best = {False: np.inf, True: np.inf}
        for _ in range(3):
            for stresses in (False, True):
                best[stresses] = min(best[stresses], _cpu(design, batch, stresses=stresses, **kw))
        print(f"{name} ({batch.sizes['sample']} runs): {best[False]:.2f} s CPU without, {best[True]:.2f} s with "
              f"the extremes ({best[True] / best[False]:.2f}x)")


if __name__ == "__main__":
    main()
