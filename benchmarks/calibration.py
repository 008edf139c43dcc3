"""Calibration benchmark: one 8-op campaign calibrated end to end, timed.

For each public healthy campaign in ``data/rig/`` it runs the default
calibration (6 global parameters + 8 latent adhesion torques, staged
emulators on real model runs, emcee to convergence, posterior predictive
check with the real model) and prints

* wall-clock and CPU time (CPU time summed over threads), model runs, steps;
* the posterior 90 % interval of every parameter against the true value of
  ``data/rig/README.md``;
* the convergence diagnostics and the posterior predictive check.

Target: <= 3 min per calibration on 2 cores.

With ``--nuisances`` it builds healthy virtual-rig campaigns with speed wander,
mains pickup, sensor noise and the pitch errors of ISO 1328-1 class 7 gears
(each alone and all together, two seeds) and prints the README's table of
true values inside the 90 % intervals (``--rows`` picks rows by a word of
their label).

Usage: ``python benchmarks/calibration.py [--files healthy.nc healthy_b.nc] [--threads N] [--seed S]
[--nuisances [--rows WORD ...]]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from uqgear.calibration import Calibration
from uqgear.physics.threads import default_threads

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"

# data/rig/README.md: true parameters of the labelled healthy campaigns
TRUTH = {
    "healthy.nc": {"mesh_stiffness_scale": 0.970, "zeta_mesh": 0.052, "backlash": 0.300e-3,
                   "ste_amplitude": 16.07e-6, "k1": 1.010e9, "k2": 1.889e9,
                   "adhesion_torque": [29780.0, 26120.0, 30700.0, 38230.0, 39380.0, 27090.0, 25820.0, 21300.0]},
    "healthy_b.nc": {"mesh_stiffness_scale": 0.982, "zeta_mesh": 0.061, "backlash": 0.315e-3,
                     "ste_amplitude": 17.67e-6, "k1": 0.902e9, "k2": 1.984e9,
                     "adhesion_torque": [37260.0, 24610.0, 29480.0, 42940.0, 40720.0, 34090.0, 25030.0, 21390.0]},
}


def run(name: str, threads: int | None, seed: int) -> bool:
    start_wall, start_cpu = time.perf_counter(), time.process_time()
    calibration = Calibration(seed=seed, threads=threads).fit(DATA / name)
    wall, cpu = time.perf_counter() - start_wall, time.process_time() - start_cpu
    diagnostics = calibration.diagnostics_
    print(f"\n=== {name}: wall {wall:.1f} s, CPU {cpu:.1f} s ({default_threads()} threads), "
          f"{calibration.timing_['model_runs']} model runs, {len(calibration.emulator_['stages'])} emulator stages, "
          f"{diagnostics['n_steps']} final emcee steps x {diagnostics['n_walkers']} walkers")
    print(f"converged: {calibration.converged_}  tau_max {diagnostics['tau_max']:.1f}  "
          f"R-hat max {diagnostics['rhat_max']:.4f}  ESS min {diagnostics['ess_min']:.0f}  "
          f"acceptance {diagnostics['acceptance_mean']:.3f}  {'; '.join(diagnostics['reasons'])}")
    print("steps: " + ", ".join(f"{step} {seconds:.1f} s" for step, seconds in calibration.timing_["steps_s"].items()))
    truth = TRUTH[name]
    all_inside = True
    print(f"{'parameter':22s} {'true':>11s} {'q05':>11s} {'q50':>11s} {'q95':>11s}  inside")
    for parameter, entry in calibration.summary_["parameters"].items():
        value = truth[parameter]
        inside = entry["q05"] <= value <= entry["q95"]
        all_inside &= inside
        print(f"{parameter:22s} {value:11.4g} {entry['q05']:11.4g} {entry['q50']:11.4g} {entry['q95']:11.4g}  "
              f"{'yes' if inside else 'NO'}")
    for entry, value in zip(calibration.summary_["adhesion_torque"], truth["adhesion_torque"]):
        inside = entry["q05"] <= value <= entry["q95"]
        print(f"{'T2 at ' + format(entry['pinion_speed'], '.0f') + ' rpm':22s} {value:11.4g} {entry['q05']:11.4g} "
              f"{entry['q50']:11.4g} {entry['q95']:11.4g}  {'yes' if inside else 'NO'}")
    check = calibration.predictive_check_
    print(f"predictive check (real model, {check['draws']} draws, {check['features_used']} features): "
          f"{100 * check['fraction_within_2_sigma']:.0f} % within 2 sigma (noise + model error), "
          f"max |z| {check['max_abs_z']:.2f}, {100 * check['fraction_within_2_noise_sigma']:.0f} % within 2 sigma "
          f"of sensor noise alone, median |relative difference| "
          f"{100 * check['median_abs_relative_difference']:.2f} %, emulator error / LOO estimate "
          f"{check['emulator_error_over_loo']:.2f}; passed: {check['passed']}")
    return all_inside and calibration.converged_ and check["passed"] and wall <= 180.0


#: Healthy virtual-rig campaigns with the nuisances of a real record, one at a time and together.
NUISANCES = {
    "speed wander +-1 % at 1.3 Hz": {"speed_wander": [(0.01, 1.3)]},
    "mains 50/150 Hz on the accelerometers": {"line_interference": {50.0: 0.5, 150.0: 0.2}},
    "3 % sensor noise": {"relative_noise": 0.03},
    "pitch errors, ISO 1328-1 class 7": {"pitch_errors": 7},
    "all of them": {"speed_wander": [(0.01, 1.3)], "line_interference": {50.0: 0.5, 150.0: 0.2},
                    "relative_noise": 0.03, "pitch_errors": 7},
}
NUISANCE_TRUTH = {"mesh_stiffness_scale": 0.98, "zeta_mesh": 0.044}


def nuisance_table(seeds: tuple[int, ...] = (1, 2), rows: tuple[str, ...] = ()) -> None:
    """Calibrate each nuisance campaign (two seeds) and print a Markdown table against the truth.

    ``rows``: only the rows whose label contains one of these words (all by default).
    """
    import uqgear
    from uqgear.rig.virtual_rig import simulate_campaign

    design = uqgear.load_design("locomotive")
    truth = dict(NUISANCE_TRUTH, backlash=design.backlash, ste_amplitude=design.ste_amplitude)
    print("| nuisance | seed | converged | inside 90 % | outside (q05/truth, q95/truth) | wander | wall s |")
    print("|---|---|---|---|---|---|---|")
    for label, options in NUISANCES.items():
        if rows and not any(word in label for word in rows):
            continue
        for seed in seeds:
            rig = simulate_campaign(design, seed=seed, true_parameters=NUISANCE_TRUTH, **options)
            start = time.perf_counter()
            calibration = Calibration(seed=0).fit(rig)
            wall = time.perf_counter() - start
            entries = calibration.summary_["parameters"]
            outside = {name: (entries[name]["q05"] / value, entries[name]["q95"] / value)
                       for name, value in truth.items() if not entries[name]["q05"] <= value <= entries[name]["q95"]}
            wander = max(row["wander"] or 0.0 for row in calibration.speed_)
            text = ", ".join(f"{name} ({low:.4f}, {high:.4f})" for name, (low, high) in outside.items()) or "-"
            print(f"| {label} | {seed} | {calibration.converged_} | {len(truth) - len(outside)} of {len(truth)} | "
                  f"{text} | +-{100 * wander:.2f} % | {wall:.0f} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--files", nargs="+", default=list(TRUTH), choices=list(TRUTH))
    parser.add_argument("--threads", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--nuisances", action="store_true",
                        help="calibrate virtual-rig campaigns with speed wander, mains pickup, noise and pitch "
                             "errors instead")
    parser.add_argument("--rows", nargs="+", default=(),
                        help="with --nuisances: only the rows whose label contains one of these words")
    arguments = parser.parse_args()
    if arguments.nuisances:
        nuisance_table(rows=tuple(arguments.rows))
        return
    results = {name: run(name, arguments.threads, arguments.seed) for name in arguments.files}
    print("\nall criteria met (truth in 90 % CI, converged, predictive check, <= 180 s):",
          dict(results.items()))


if __name__ == "__main__":
    main()
