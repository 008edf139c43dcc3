"""Uncertainty-layer benchmark.

Prints, in one run:

1. for each interval method (vertex, chebyshev, optimize) on the reference
   design, the QoI bands over the T2 interval at speeds across the range:
   model runs, seconds, and the bound error against a dense scan (the
   reference), plus how many speeds each method flagged as non-smooth;
2. a 10,000-sample Monte Carlo (T2 uniform on its interval for this purpose,
   mesh stiffness scale normal) with 1 and with 2 workers, in-process (numba
   threads) and on a dask LocalCluster on loopback, and their ratio; the
   results are checked to be identical.

Usage: ``python benchmarks/uncertainty.py [--quick]``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import xarray as xr

import uqgear
from uqgear.physics.integration import BatchEvaluator
from uqgear.uq.interval import IntervalAnalysis
from uqgear.uq.parameter_space import ParameterSpace
from uqgear.uq.parameters import Distribution, Interval
from uqgear.uq.runner import Runner


def interval_methods(design, speeds: np.ndarray, scan_points: int) -> None:
    lower, upper = design.operation.adhesion_torque_bounds()
    space = ParameterSpace({"adhesion_torque": Interval(lower, upper, units="N m")})
    model = BatchEvaluator(design, n_periods=300, keep_periods=100)
    qois = ["dte_rms", "dynamic_load_factor"]
    sweep = {"pinion_speed": speeds}
    start = time.perf_counter()
    reference = IntervalAnalysis("scan", scan_points=scan_points, qoi=qois).fit(model, space, sweep=sweep).result_
    scan_time = time.perf_counter() - start
    print(f"interval methods over T2 in [{lower / 1e3:.1f}, {upper / 1e3:.1f}] kN m at {speeds.size} speeds "
          f"({speeds.min():.0f}-{speeds.max():.0f} rpm), reference: scan with {scan_points} points "
          f"({int(reference['runs'].sum())} runs, {scan_time:.1f} s)")
    print(f"  {'method':10s} {'runs':>6s} {'seconds':>8s} " + " ".join(f"{q + ' max err':>26s}" for q in qois)
          + f" {'flagged':>8s}")
    settings = {"vertex": {}, "chebyshev": {"order": 6, "check_points": 3, "fallback": "scan"},
                "optimize": {"n_starts": 2}}
    for method, options in settings.items():
        start = time.perf_counter()
        result = IntervalAnalysis(method, qoi=qois, seed=1, **options).fit(model, space, sweep=sweep).result_
        elapsed = time.perf_counter() - start
        errors = []
        for q in qois:
            width = (reference[q].sel(bound="upper") - reference[q].sel(bound="lower")).values
            scale = np.maximum(np.abs(reference[q].sel(bound="upper").values), 1e-300)
            error = np.abs(result[q].values - reference[q].values).max(axis=-1) / scale
            errors.append(f"{100 * error.max():10.2f} % (median {100 * np.median(error):5.2f} %)")
            del width
        flagged = int((result["flag"].values != 0).any(axis=0).sum()) if "flag" in result else 0
        print(f"  {method:10s} {int(result['runs'].sum()):6d} {elapsed:8.1f} " + " ".join(f"{e:>26s}" for e in errors)
              + f" {flagged:8d}")


def monte_carlo(design, n_samples: int) -> None:
    lower, upper = design.operation.adhesion_torque_bounds()
    space = ParameterSpace({"adhesion_torque": Interval(lower, upper, units="N m"),
                            "mesh_stiffness_scale": Distribution("normal", mu=1.0, sigma=0.05)})
    samples = space.sample(n_samples, "latin_hypercube", seed=20261121, interval_treatment="uniform")
    model = BatchEvaluator(design, fixed={"pinion_speed": 3000.0}, n_periods=200, keep_periods=100)
    model(samples.isel(sample=slice(0, 2)))  # compile
    print(f"Monte Carlo: {n_samples} samples at 3000 rpm (T2 uniform on its interval, stiffness scale N(1, 0.05))")
    timings = {}
    results = {}
    for threads in (1, 2):
        model.threads = threads
        start = time.perf_counter()
        results[f"threads={threads}"] = Runner(chunk_size=1000, progress=False).run(model, samples)
        timings[f"threads={threads}"] = time.perf_counter() - start
    model.threads = 2
    from distributed import Client, LocalCluster

    for workers in (1, 2):
        with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=None, env={"NUMBA_NUM_THREADS": "1"}) as cluster, Client(cluster) as client:
            client.run(lambda: uqgear.simulate_batch(uqgear.load_design(), uqgear.samples_from_mapping(
                {"pinion_speed": [3000.0]}), n_periods=2, keep_periods=1))  # compile on the workers
            start = time.perf_counter()
            runner = Runner(chunk_size=500, scheduler=client, progress=False)
            results[f"dask workers={workers}"] = runner.run(model, samples)
            timings[f"dask workers={workers}"] = time.perf_counter() - start
    for name, elapsed in timings.items():
        print(f"  {name:16s} {elapsed:7.1f} s  ({n_samples / elapsed:7.0f} runs/s)")
    print(f"  speed-up 2 vs 1: in-process {timings['threads=1'] / timings['threads=2']:.2f}x, "
          f"dask {timings['dask workers=1'] / timings['dask workers=2']:.2f}x")
    first = results["threads=1"]
    identical = all(xr.Dataset.identical(first[["dte_rms"]], r[["dte_rms"]]) for r in results.values())
    print(f"  identical results across worker counts: {identical}")
    stats = first["dte_rms"]
    print(f"  dte_rms mean {float(stats.mean()) * 1e6:.3f} um, 5-95 % [{float(stats.quantile(0.05)) * 1e6:.3f}, "
          f"{float(stats.quantile(0.95)) * 1e6:.3f}] um")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer speeds and 2,000 Monte Carlo samples")
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    speeds = np.linspace(500.0, 6000.0, 12 if args.quick else 23)
    interval_methods(design, speeds, scan_points=21 if args.quick else 41)
    monte_carlo(design, 2000 if args.quick else 10000)


if __name__ == "__main__":
    main()
