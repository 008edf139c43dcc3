"""Integrator benchmark: the batch against its references, compile time, and the fast path's work-precision curve.

Prints, in one run:

1. the batch users run: 500 speeds 200-4000 rpm x 20 adhesion torques
   (10,000 runs; ``--quick``: 50 speeds, 1,000 runs) at the rated drive
   torque, ``simulate_batch`` defaults (400 mesh periods, 200 kept), on all
   cores: time, RK4 steps per second, nanoseconds per step and core against
   the ~70 ns a step a scalar core needs and the ~20 ns of SIMD lanes;
2. the same batch on the one-sample kernel (``lanes=False``): time, ratio,
   and that every output is the same, bit for bit;
3. with ``--reference CHECKOUT``: the same batch on the kernels of another
   checkout of the package (26ef8ac: ``git worktree add ../ref26 26ef8ac``),
   loaded from its ``uqgear/_kernels.py`` and run on the same arrays, side by
   side with this one (the old kernels use fast-math: outputs agree to about
   1e-12, not bit for bit);
4. cold compilation: a fresh interpreter with an empty numba cache runs one
   small batch per kernel family (lanes; one-sample; one-sample with pitch
   errors), and the time to its first result;
5. work-precision at 1500 rpm: the fast path's relative RMS error of x
   against scipy DOP853 at rtol 1e-12, for several step counts, beside scipy
   DOP853 and LSODA (same segments, same contact events), each at the fast
   path's error.

With ``--bands``, also the CPU time a step on one thread by speed band
(200-4000 rpm) for each kernel: where the batch spends its time (with
``--reference``, also that checkout's kernel compiled serially, its
``prange`` a ``range``: what the switch to serial batch kernels cost).

Usage: ``python benchmarks/integrator.py [--quick] [--reference CHECKOUT] [--bands] [--no-cold] [--no-precision]``.
"""

from __future__ import annotations

import argparse
import itertools
import os
import resource
import subprocess
import sys
import tempfile
import time
import types
from pathlib import Path

import numba
import numpy as np

import uqgear
from uqgear.physics import _kernels as K
from uqgear.physics import integration
from uqgear.physics.model import build_model
from uqgear.physics.scipy_reference import integrate_scipy
from uqgear.physics.threads import default_threads

SCALAR_LIMIT_NS = 70.0
SIMD_LIMIT_NS = 20.0


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.1f} (1 min) / {five:.1f} (5 min) on {os.cpu_count()} CPUs"


def _grid(design, n_speeds: int):
    lower, upper = design.operation.adhesion_torque_bounds()
    speed, adhesion = np.meshgrid(np.linspace(200.0, 4000.0, n_speeds), np.linspace(lower, upper, 20),
                                  indexing="ij")
    return uqgear.samples_from_mapping({"pinion_speed": speed.ravel(), "adhesion_torque": adhesion.ravel()})


def _timed_batch(design, samples, **kw):
    """(wall time, CPU time of all threads, result): on a shared machine the CPU time moves less with the load."""
    start, cpu = time.perf_counter(), time.process_time()
    result = uqgear.simulate_batch(design, samples, **kw)
    return time.perf_counter() - start, time.process_time() - cpu, result


def _floats(ds) -> dict[str, np.ndarray]:
    return {name: ds[name].values for name in ds.data_vars if np.issubdtype(ds[name].dtype, np.floating)}


def batch(design, n_speeds: int, reference: Path | None) -> None:
    samples = _grid(design, n_speeds)
    n = samples.sizes["sample"]
    threads = default_threads()
    warm = samples.isel(sample=slice(0, 16))
    uqgear.simulate_batch(design, warm, n_periods=4, keep_periods=2)  # compile or load, both families
    uqgear.simulate_batch(design, warm, n_periods=4, keep_periods=2, lanes=False)
    print(f"batch: {n} runs ({n_speeds} speeds 200-4000 rpm x 20 T2 values, rated drive torque), "
          f"400 mesh periods, 200 kept, {threads} threads; {_load()}")
    lanes_time, lanes_cpu, lanes = _timed_batch(design, samples)
    steps = float((lanes["steps_per_period"] * 400).sum())
    per_core = lanes_time * threads / steps * 1e9
    cpu_step = lanes_cpu / steps * 1e9
    print(f"  lanes      : {lanes_time:6.2f} s, CPU {lanes_cpu:6.2f} s  ({lanes_time / n * 1e3:.3f} ms/run, "
          f"{steps / lanes_time / 1e6:.1f} M RK4 steps/s, {per_core:.1f} ns a step per core by wall time, "
          f"{cpu_step:.1f} "
          f"by CPU time: {SCALAR_LIMIT_NS / cpu_step:.2f}x the ~{SCALAR_LIMIT_NS:.0f} ns scalar limit, "
          f"{SIMD_LIMIT_NS / cpu_step:.2f}x the ~{SIMD_LIMIT_NS:.0f} ns SIMD one)")
    one_time, one_cpu, one = _timed_batch(design, samples, lanes=False)
    same = all(a.tobytes() == b.tobytes() for a, b in zip(_floats(lanes).values(), _floats(one).values()))
    print(f"  one-sample : {one_time:6.2f} s, CPU {one_cpu:6.2f} s  ({steps / one_time / 1e6:.1f} M RK4 steps/s)   "
          f"RATIO lanes vs one-sample = {one_time / lanes_time:.2f}x (CPU {one_cpu / lanes_cpu:.2f}x); "
          f"outputs bit-identical: {'yes' if same else 'NO'}")
    if reference is None:
        print("  reference  : skipped (--reference CHECKOUT runs another checkout's kernels side by side)")
        return
    old = _reference_kernels(reference)
    saved = integration.K
    integration.K = old
    try:
        # the old batch kernel is a prange over all runs: one call, numba's threads
        uqgear.simulate_batch(design, warm, n_periods=4, keep_periods=2, lanes=False, threads=1)
        ref_time, ref_cpu, ref = _timed_batch(design, samples, lanes=False, threads=1)
    finally:
        integration.K = saved
    change = max(float(np.nanmax(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))
                 for a, b in zip(_floats(lanes).values(), _floats(ref).values()) if a.size)
    print(f"  reference  : {ref_time:6.2f} s, CPU {ref_cpu:6.2f} s  "
          f"({steps / ref_time / 1e6:.1f} M RK4 steps/s; kernels of "
          f"{reference})   RATIO lanes vs reference = {ref_time / lanes_time:.2f}x (CPU {ref_cpu / lanes_cpu:.2f}x); "
          f"largest relative output change {change:.1e}")


def _reference_kernels(checkout: Path, serial: bool = False) -> types.SimpleNamespace:
    """The batch kernel of an older checkout (``uqgear/_kernels.py``, prange over all runs) behind today's call.

    ``serial``: the same source with the ``prange`` a plain ``range`` and no
    ``parallel=True``, as the batch kernels have been compiled since.
    """
    path = checkout / "uqgear" / "_kernels.py"
    if not path.exists():
        raise SystemExit(
            f"--reference: {path} not found; expected a checkout of 26ef8ac (git worktree add DIR 26ef8ac)"
        )
    # compiled here without its cache: that checkout's cache entries name its own module
    module = types.ModuleType("_kernels_reference")
    source = path.read_text().replace("cache=True", "cache=False")
    if serial:
        source = source.replace("parallel=True, ", "").replace("nb.prange(", "range(")
    exec(compile(source, str(path), "exec"), module.__dict__)  # noqa: S102  (our own older source)
    namespace = types.SimpleNamespace(**{name: getattr(K, name) for name in dir(K) if not name.startswith("__")})

    def integrate_batch(start, stop, order, batch):
        states, params, pair_tables, period_tables, table_index, fp, fg, breakpoints = batch.runs
        steps, n_periods, keep, strides, lyapunov, scales, acc, poincare, history, final = batch[1:]
        rows = order[start:stop]
        acc_rows, poincare_rows, history_rows = acc[rows], poincare[rows], history[rows]
        # its parameter vector is today's first slots (the pitch-error slots came later, appended)
        module.integrate_batch(states[rows], np.ascontiguousarray(params[rows, :module.N_PARAMS]), pair_tables,
                               period_tables, table_index[rows], fp[rows], fg[rows], breakpoints[rows], steps[rows],
                               n_periods, keep, strides[rows], lyapunov, scales[rows], acc_rows, poincare_rows,
                               history_rows)
        acc[rows], poincare[rows], history[rows] = acc_rows, poincare_rows, history_rows
        final[rows] = np.nan

    namespace.integrate_batch = integrate_batch
    return namespace


def speed_bands(design, reference: Path | None) -> None:
    """CPU time a step, one thread, by speed band: where the batch spends its time, kernel by kernel."""
    lower, upper = design.operation.adhesion_torque_bounds()
    kernels = [("lanes", integration.K, {}), ("one-sample", integration.K, {"lanes": False})]
    if reference is not None:
        kernels.append(("reference", _reference_kernels(reference), {"lanes": False}))
        kernels.append(("ref. serial", _reference_kernels(reference, serial=True), {"lanes": False}))
    print(f"speed bands: CPU time a step, one thread (8 T2 values a band: one lane group; {_load()})")
    header = "  ".join(f"{k[0] + ' ns':>14s}" for k in kernels)
    print(f"  {'rpm':>6s} {'steps/period':>12s} {'separation':>10s}  " + header)
    saved, saved_threads = integration.K, numba.get_num_threads()
    numba.set_num_threads(1)  # the reference kernel's prange too
    try:
        for speed in (200.0, 500.0, 1000.0, 2000.0, 3000.0, 4000.0):
            samples = uqgear.samples_from_mapping({"pinion_speed": np.full(8, speed),
                                                   "adhesion_torque": np.linspace(lower, upper, 8)})
            cells, result = [], None
            for _, module, kw in kernels:
                integration.K = module
                uqgear.simulate_batch(design, samples, n_periods=4, keep_periods=2, threads=1, **kw)
                best = np.inf
                for _ in range(3):
                    start = time.process_time()
                    result = uqgear.simulate_batch(design, samples, threads=1, **kw)
                    best = min(best, time.process_time() - start)
                cells.append(best / float((result["steps_per_period"] * 400).sum()) * 1e9)
            print(f"  {speed:6.0f} {int(result['steps_per_period'][0]):12d} "
                  f"{float(result['fraction_separation'].mean()):10.3f}  " + "  ".join(f"{c:14.1f}" for c in cells))
    finally:
        integration.K = saved
        numba.set_num_threads(saved_threads)


COLD_SCRIPT = """
import sys, time
start = time.perf_counter()
import numpy as np
import uqgear
imported = time.perf_counter()
design = uqgear.load_design("locomotive")
samples = uqgear.samples_from_mapping({"pinion_speed": np.full(8, 1500.0)})
family = sys.argv[1]
kw = dict(n_periods=4, keep_periods=2)
if family == "one-sample":
    kw["lanes"] = False
elif family == "pitch errors":
    kw["pitch_errors"] = uqgear.physics.draw_pitch_errors(design, 7, np.random.default_rng(1))
uqgear.simulate_batch(design, samples, **kw)
print(f"{imported - start:.2f} {time.perf_counter() - imported:.2f}")
"""


def cold_compile(quick: bool) -> None:
    print(f"cold compilation (fresh interpreter, empty numba cache; {_load()}):")
    families = ("lanes",) if quick else ("lanes", "one-sample", "pitch errors")
    for family in families:
        with tempfile.TemporaryDirectory() as cache:
            env = {**os.environ, "NUMBA_CACHE_DIR": cache}
            start, children = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
            out = subprocess.run([sys.executable, "-c", COLD_SCRIPT, family], env=env, capture_output=True, text=True,
                                 check=False)
            wall = time.perf_counter() - start
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = after.ru_utime + after.ru_stime - children.ru_utime - children.ru_stime
        if out.returncode != 0:
            print(f"  {family:12s}: failed: {out.stderr.strip().splitlines()[-1:]}")
            continue
        imported, first = (float(v) for v in out.stdout.split())
        print(f"  {family:12s}: first result {first:5.1f} s after import ({imported:.1f} s), {wall:.1f} s in all, "
              f"{cpu:.1f} s of CPU")


def _relative_rms(x, reference):
    return float(np.sqrt(np.mean((x - reference) ** 2)) / np.sqrt(np.mean((reference - reference.mean()) ** 2)))


def _median_time(run, repeats: int = 3) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def _scipy_curve(setup, kw, tight, solver: str, tolerances) -> list[tuple[float, float]]:
    points = []
    for rtol in tolerances:
        start = time.perf_counter()
        history, _, _ = integrate_scipy(setup, kw["n_periods"], kw["keep_periods"], kw["samples_per_period"],
                                        setup.static_state(), rtol, None, solver=solver)
        points.append((_relative_rms(history[:, 2], tight), time.perf_counter() - start))
    return points


def _at_error(points: list[tuple[float, float]], error: float) -> float | None:
    """Time at ``error`` on a curve of (error, time) points, interpolated in log-log; None outside it."""
    ordered = sorted(points)
    for (e0, t0), (e1, t1) in itertools.pairwise(ordered):
        if e0 <= error <= e1 and e0 > 0:
            w = 0.0 if e1 == e0 else (np.log(error) - np.log(e0)) / (np.log(e1) - np.log(e0))
            return float(np.exp(np.log(t0) + w * (np.log(t1) - np.log(t0))))
    return None


def work_precision(design) -> None:
    speed, drive, adhesion = 1500.0, 7000.0, 33000.0
    # 16 samples a period: the step count is a multiple of it, so the coarse end reaches 32 steps a period
    kw = {"n_periods": 200, "keep_periods": 100, "samples_per_period": 16}
    setup = build_model(design, speed, drive, adhesion)
    uqgear.simulate(design, speed, drive, adhesion, n_periods=4, keep_periods=2)  # compile or load
    tight = uqgear.simulate(design, speed, drive, adhesion, method="scipy", rtol=1e-12, **kw)["x"].values
    print(f"work-precision at {speed:.0f} rpm, {kw['n_periods']} mesh periods ({kw['keep_periods']} kept): relative "
          f"RMS error of x against scipy DOP853 rtol=1e-12, one run; {_load()}")
    fast = []
    for steps_per_mode in (8, 12, 16, 24, 32, 48, 64, 96, 128):
        elapsed, result = _median_time(lambda spm=steps_per_mode: uqgear.simulate(design, speed, drive, adhesion,
                                                                                   steps_per_mode=spm, **kw))
        fast.append((steps_per_mode, result.attrs["steps_per_period"], _relative_rms(result["x"].values, tight),
                     elapsed))
    tolerances = [10.0 ** -k for k in range(3, 12)]
    curves = {"DOP853": _scipy_curve(setup, kw, tight, "DOP853", tolerances),
              "LSODA": _scipy_curve(setup, kw, tight, "LSODA", tolerances[:7])}
    names = list(curves)
    print(f"  {'steps/mode':>10s} {'steps/period':>12s} {'error':>8s} {'fast ms':>9s}  "
          + "  ".join(f"{name + ' ms (ratio)':>22s}" for name in names))
    for steps_per_mode, steps, error, elapsed in fast:
        cells = []
        for name in names:
            other = _at_error(curves[name], error)
            cells.append(f"{'-':>22s}" if other is None else f"{other * 1e3:11.1f} ({other / elapsed:6.0f}x)")
        print(f"  {steps_per_mode:10d} {steps:12d} {error:8.1e} {elapsed * 1e3:9.2f}  " + "  ".join(cells))
    for name in names:
        print(f"  {name} curve (error, ms): " + ", ".join(f"({e:.1e}, {t * 1e3:.0f})" for e, t in sorted(curves[name])))
    print("  CyRK, numbalsoda: not run (numbalsoda does not build here; CyRK's numba solver without contact "
          "events did not reproduce the reference and is left out until it does)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="1,000-run batch instead of 10,000; lanes compile only")
    parser.add_argument("--reference", type=Path, metavar="CHECKOUT",
                        help="checkout of an older version (26ef8ac) whose batch kernel runs side by side")
    parser.add_argument("--no-cold", action="store_true", help="skip the cold-compilation timings")
    parser.add_argument("--no-precision", action="store_true", help="skip the work-precision curve")
    parser.add_argument("--bands", action="store_true", help="also CPU time a step by speed band, one thread")
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    batch(design, 50 if args.quick else 500, args.reference)
    if args.bands:
        speed_bands(design, args.reference)
    if not args.no_cold:
        cold_compile(args.quick)
    if not args.no_precision:
        work_precision(design)


if __name__ == "__main__":
    main()
