"""Cost of the speed-varying simulation against constant-speed runs (one thread, CPU time, best of 3).

Prints

* the pace per simulated second of a run-up batch (8 adhesion torques 21-46 kN m,
  ramp 1500 -> 2500 rpm in 1 s) on the SIMD lanes, with histories at 20.48 kHz
  and with next to none (10 Hz: the difference is the output's cost), and on
  the one-run kernel (``lanes=False``), against :func:`uqgear.simulate_batch`
  of the same 8 samples at the ramp's mean speed (2000 rpm) over the same
  simulated time, on the lanes without histories and with the rig channels at
  32 samples a mesh period, and on the one-sample kernel, as ratios;
* a long run-up 500 -> 6000 rpm (``--duration`` s, 30 by default) at 20.48 kHz
  against a stepped sweep of 23 steady speeds 500-6000 rpm, once with the
  default 400 mesh periods each and once spending the same simulated time
  (duration / 23 s each).

``PYTHONPATH=. python benchmarks/runup.py [--duration 30]``
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import numpy as np

import uqgear

T1 = 7000.0


def best_cpu(work: Callable[[], object], repeats: int = 3) -> float:
    """Least CPU time of ``repeats`` calls, s."""
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        work()
        best = min(best, time.process_time() - start)
    return float(best)


def pace(design: uqgear.Design) -> None:
    """Run-up batch against constant-speed batches over the same simulated time."""
    torques = np.linspace(21e3, 46e3, 8)
    ramp = uqgear.SpeedProfile.linear(1500.0, 2500.0, 1.0)
    runup_samples = uqgear.samples_from_mapping({"drive_torque": np.full(8, T1), "adhesion_torque": torques})
    steady_samples = runup_samples.assign(pinion_speed=("sample", np.full(8, 2000.0)))
    periods = int(round(2000.0 / 60.0 * design.z1 * ramp.duration))

    def runup(**kw: Any) -> Callable[[], object]:
        return lambda: uqgear.simulate_runup_batch(design, ramp, runup_samples, threads=1, run_in_periods=1, **kw)

    def steady(**kw: object) -> Callable[[], object]:
        return lambda: uqgear.simulate_batch(
            design, steady_samples, n_periods=periods, keep_periods=periods, threads=1, **kw
        )

    for work in (runup(), runup(sample_rate=10.0), runup(lanes=False), steady(), steady(lanes=False)):
        work()
    steady(history_per_period=32, rig_channels=True)()
    t_runup = best_cpu(runup())
    t_quiet = best_cpu(runup(sample_rate=10.0))
    t_alone = best_cpu(runup(lanes=False))
    t_alone_quiet = best_cpu(runup(lanes=False, sample_rate=10.0))
    t_steady = best_cpu(steady())
    t_history = best_cpu(steady(history_per_period=32, rig_channels=True))
    t_one = best_cpu(steady(lanes=False))
    simulated = 8 * ramp.duration
    print(f"run-up batch, lanes: {t_runup / simulated:.4f} s CPU per simulated second (8 runs of 1 s, 20.48 kHz out)")
    print(f"run-up batch, lanes, 10 Hz out: {t_quiet / simulated:.4f} s CPU per simulated second")
    print(
        f"run-up batch, one-run kernel: {t_alone / simulated:.4f} (20.48 kHz out), "
        f"{t_alone_quiet / simulated:.4f} (10 Hz out) s CPU per simulated second"
    )
    print(f"steady batch, QoIs only: {t_steady / simulated:.4f} s CPU per simulated second ({periods} periods)")
    print(f"steady batch, rig channels 32 a period: {t_history / simulated:.4f} s CPU per simulated second")
    print(f"steady batch, one-sample kernel (no lanes), QoIs only: {t_one / simulated:.4f} s CPU per simulated second")
    print(
        f"ratio run-up lanes (20.48 kHz) / steady: {t_runup / t_steady:.2f} (lanes, QoIs only), "
        f"{t_runup / t_history:.2f} (lanes, histories), {t_runup / t_one:.2f} (one-sample kernel, QoIs only)"
    )
    print(f"ratio run-up lanes (10 Hz) / steady lanes, QoIs only: {t_quiet / t_steady:.2f}")
    print(
        f"ratio run-up lanes / run-up one-run kernel: {t_runup / t_alone:.2f} (20.48 kHz), "
        f"{t_quiet / t_alone_quiet:.2f} (10 Hz)"
    )


def long_run(design: uqgear.Design, duration: float) -> None:
    """A run-up over the sweep range against a stepped sweep of steady speeds."""
    ramp = uqgear.SpeedProfile.linear(500.0, 6000.0, duration)
    speeds = np.linspace(500.0, 6000.0, 23)
    samples = uqgear.samples_from_mapping(
        {"pinion_speed": speeds, "drive_torque": np.full(23, T1), "adhesion_torque": np.full(23, 33.8e3)}
    )
    uqgear.simulate_runup(design, uqgear.SpeedProfile.linear(500.0, 6000.0, 0.05), T1, 33.8e3, run_in_periods=2)
    start = time.perf_counter()
    cpu = time.process_time()
    run = uqgear.simulate_runup(design, ramp, T1, 33.8e3)
    t_runup, w_runup = time.process_time() - cpu, time.perf_counter() - start
    t_default = best_cpu(lambda: uqgear.simulate_batch(design, samples, threads=1), repeats=1)
    # the same simulated time: duration / 23 s at each speed, half of it kept
    each = duration / speeds.size
    periods = np.maximum(np.round(speeds / 60.0 * design.z1 * each).astype(int), 2)
    cpu = time.process_time()
    for speed, count in zip(speeds, periods):
        one = samples.isel(sample=[int(np.argmin(np.abs(speeds - speed)))])
        uqgear.simulate_batch(design, one, n_periods=int(count), keep_periods=int(count) // 2, threads=1)
    t_equal = time.process_time() - cpu
    print(
        f"run-up 500 -> 6000 rpm in {duration:g} s at 20.48 kHz ({run.sizes['time']} samples, "
        f"{run.attrs['band_steps'].size} bands of {run.attrs['band_steps'].max()} to {run.attrs['band_steps'].min()} "
        f"steps a period): {t_runup:.2f} s CPU, {w_runup:.2f} s wall (run-in included)"
    )
    print(f"23 steady speeds x 400 periods (simulate_batch, QoIs): {t_default:.2f} s CPU")
    print(f"23 steady speeds x {each:.3f} s each (the same simulated time): {t_equal:.2f} s CPU")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=30.0, help="length of the long run-up, s")
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    pace(design)
    long_run(design, args.duration)


if __name__ == "__main__":
    main()
