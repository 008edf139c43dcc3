"""Integrator benchmark: fast path vs scipy reference, and a 10,000-run batch.

Prints, in one run:

1. one simulation with the scipy reference at the tolerance that gives the
   same accuracy as the fast path (both measured against a tight scipy
   solution), their times and ratio;
2. a batch of 500 speeds x 20 adhesion torques (10,000 runs; 400 mesh
   periods, 200 kept) on all cores, its time, and the batch-vs-one-by-one
   ratio measured on a subset;
3. peak memory (resident set) and the size of what the batch keeps;
4. what LLVM fast-math flags would buy: the same kernels compiled from the
   same source with ``fastmath=True`` (all flags) and with only
   ``{nnan, ninf}`` (no reassociation or contraction), timed on one run and on
   a batch against the library's kernels (no fast-math: bit-identical results
   cold, warm and uncached; see ``JIT_OPTIONS`` in ``uqgear/_kernels.py``).

Usage: ``python benchmarks/integrator.py [--quick]`` (``--quick``: 1,000 runs).
"""

from __future__ import annotations

import argparse
import contextlib
import resource
import time
import types
from pathlib import Path

import numpy as np

import uqgear
from uqgear.physics import _kernels as K
from uqgear.physics import integration
from uqgear.physics import model
from uqgear.physics.threads import default_threads


def _relative_rms(x, reference):
    return float(np.sqrt(np.mean((x - reference) ** 2)) / np.sqrt(np.mean((reference - reference.mean()) ** 2)))


def _peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def single_run(design) -> None:
    speed, drive, adhesion = 1500.0, 7000.0, 33000.0
    kw = dict(n_periods=400, keep_periods=200)
    uqgear.simulate(design, speed, drive, adhesion, n_periods=4, keep_periods=2)  # compile
    tight = uqgear.simulate(design, speed, drive, adhesion, method="scipy", rtol=1e-12, **kw)["x"].values
    # the fast run is short enough for timer noise to matter: median of five
    times = []
    for _ in range(5):
        start = time.perf_counter()
        fast = uqgear.simulate(design, speed, drive, adhesion, **kw)
        times.append(time.perf_counter() - start)
    fast_time = float(np.median(times))
    fast_error = _relative_rms(fast["x"].values, tight)
    print(f"single run at {speed:.0f} rpm, 400 mesh periods ({fast.attrs['steps_per_period']} RK4 steps/period)")
    print(f"  fast  : {fast_time * 1e3:8.1f} ms   rel. RMS error vs scipy(rtol=1e-12) = {fast_error:.1e}"
          "   (median of 5 runs)")
    chosen = None
    for rtol in (1e-5, 1e-6, 1e-7, 1e-8, 1e-9):
        start = time.perf_counter()
        ref = uqgear.simulate(design, speed, drive, adhesion, method="scipy", rtol=rtol, **kw)
        elapsed = time.perf_counter() - start
        error = _relative_rms(ref["x"].values, tight)
        print(f"  scipy : {elapsed * 1e3:8.1f} ms   rtol={rtol:.0e}  rel. RMS error = {error:.1e}")
        if error <= fast_error:
            chosen = (rtol, elapsed, error)
            break
    if chosen is None:
        print("  scipy did not reach the fast path's accuracy in the tolerances tried")
        return
    print(f"  matched accuracy: scipy rtol={chosen[0]:.0e} ({chosen[2]:.1e}) vs fast ({fast_error:.1e})")
    print(f"  RATIO scipy / fast = {chosen[1] / fast_time:.0f}x")


def batch(design, n_speeds: int, n_adhesion: int) -> None:
    lower, upper = design.operation.adhesion_torque_bounds()
    speeds = np.linspace(200.0, 6000.0, n_speeds)
    adhesion = np.linspace(lower, upper, n_adhesion)
    grid_speed, grid_adhesion = np.meshgrid(speeds, adhesion, indexing="ij")
    samples = uqgear.samples_from_mapping({"pinion_speed": grid_speed.ravel(),
                                           "adhesion_torque": grid_adhesion.ravel()})
    n = samples.sizes["sample"]
    kw = dict(n_periods=400, keep_periods=200)
    uqgear.simulate_batch(design, samples.isel(sample=slice(0, 2)), n_periods=4, keep_periods=2)  # compile
    rss_before = _peak_rss_mib()
    start = time.perf_counter()
    result = uqgear.simulate_batch(design, samples, **kw)
    elapsed = time.perf_counter() - start
    rss_after = _peak_rss_mib()
    steps = float((result["steps_per_period"] * 400).sum())
    print(f"batch: {n} runs ({n_speeds} speeds 200-6000 rpm x {n_adhesion} T2 values), 400 mesh periods, "
          f"200 kept, {default_threads()} threads")
    print(f"  time {elapsed:.1f} s  ({elapsed / n * 1e3:.2f} ms/run, {steps / elapsed / 1e6:.1f} M RK4 steps/s)")
    print(f"  kept output {result.nbytes / 2**20:.1f} MiB; peak RSS {rss_after:.0f} MiB "
          f"(growth during the batch {rss_after - rss_before:.0f} MiB)")
    full_history = steps * 12 * 8 / 400 * 200 / 2**30
    print(f"  (full histories of the kept periods would be {full_history:.1f} GiB)")
    subset = samples.isel(sample=slice(0, n, max(n // 40, 1)))
    start = time.perf_counter()
    for i in range(subset.sizes["sample"]):
        uqgear.simulate_batch(design, subset.isel(sample=[i]), threads=1, **kw)
    one_by_one = time.perf_counter() - start
    start = time.perf_counter()
    uqgear.simulate_batch(design, subset, **kw)
    together = time.perf_counter() - start
    print(f"  batch vs one-by-one on {subset.sizes['sample']} runs: {one_by_one:.2f} s / {together:.2f} s "
          f"= {one_by_one / together:.2f}x")


def _kernel_variant(options: str) -> types.ModuleType:
    """The library's kernel module compiled anew with other ``JIT_OPTIONS``."""
    source = Path(K.__file__).read_text()
    default = 'JIT_OPTIONS = {"cache": True, "error_model": "numpy"}'
    if default not in source:
        raise RuntimeError("uqgear/_kernels.py no longer defines JIT_OPTIONS as this benchmark expects")
    module = types.ModuleType(f"_kernels_variant_{abs(hash(options))}")
    exec(compile(source.replace(default, f"JIT_OPTIONS = {options}"), K.__file__, "exec"), module.__dict__)
    return module


@contextlib.contextmanager
def _kernels_swapped(module: types.ModuleType):
    # integration and model call the kernels through their module attribute K
    saved = integration.K, model.K
    integration.K = model.K = module
    try:
        yield
    finally:
        integration.K, model.K = saved


def fastmath_cost(design, n_speeds: int) -> None:
    samples = uqgear.samples_from_mapping({"pinion_speed": np.linspace(200.0, 6000.0, n_speeds),
                                           "adhesion_torque": np.full(n_speeds, 33000.0)})
    kw = dict(n_periods=400, keep_periods=200)

    def timed():
        uqgear.simulate_batch(design, samples.isel(sample=slice(0, 2)), n_periods=4, keep_periods=2)
        uqgear.simulate(design, 1500.0, 7000.0, 33000.0, n_periods=4, keep_periods=2)
        single = []
        for _ in range(5):
            start = time.perf_counter()
            uqgear.simulate(design, 1500.0, 7000.0, 33000.0, **kw)
            single.append(time.perf_counter() - start)
        start = time.perf_counter()
        result = uqgear.simulate_batch(design, samples, **kw)
        return float(np.median(single)), time.perf_counter() - start, result["dte_rms"].values

    base_single, base_batch, base_dte = timed()
    print(f"fast-math flags (one run at 1500 rpm; batch of {n_speeds} runs 200-6000 rpm), "
          "time relative to the library's kernels (no fast-math):")
    print(f"  none (library)  : single {base_single * 1e3:6.1f} ms  batch {base_batch:6.2f} s")
    variants = (("{nnan, ninf}", '{"cache": False, "error_model": "numpy", "fastmath": {"nnan", "ninf"}}'),
                ("fastmath=True", '{"cache": False, "error_model": "numpy", "fastmath": True}'))
    for label, options in variants:
        with _kernels_swapped(_kernel_variant(options)):
            single, together, dte = timed()
        change = float(np.max(np.abs(dte - base_dte) / np.abs(base_dte)))
        print(f"  {label:16s}: single {single * 1e3:6.1f} ms  batch {together:6.2f} s   "
              f"speed-up {base_single / single:.3f}x / {base_batch / together:.3f}x; "
              f"max relative change of dte_rms {change:.1e}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000-run batch instead of 10,000")
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    single_run(design)
    batch(design, 50 if args.quick else 500, 20)
    fastmath_cost(design, 40 if args.quick else 200)


if __name__ == "__main__":
    main()
