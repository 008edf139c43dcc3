"""Calibration of a virtual-rig run-up campaign against a steady 8-point campaign of the same rig.

Builds two campaigns of one virtual rig (true mesh stiffness scale 0.98, mesh
damping 0.044, the other parameters nominal; 2 % sensor noise and +-0.2 %
speed wander at 1 Hz): a run-up 1000 -> 5000 rpm and a coast-down
5000 -> 1000 rpm at 200 rpm/s (read as 8 operating points by default, 4
segments per ramp at 8 distinct speeds; ``--segments 8`` reads 8 per ramp),
and the 8 steady runs of the public campaigns (1 s each). Each is written to
a file and calibrated with the defaults (``uqgear.calibrate``), one after the
other; the table gives, per campaign, convergence, the true values inside
their 90 % credible intervals and the wall and CPU time of the calibration
(CPU time of this process; numba and BLAS threads count in it).

Usage: ``python benchmarks/runup_calibration.py [--out DIR] [--seed N] [--segments N]``
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

TRUTH = {"mesh_stiffness_scale": 0.98, "zeta_mesh": 0.044}
NUISANCES = {"relative_noise": 0.02, "speed_wander": [(0.002, 1.0)]}
RAMPS = {
    "start_speed": [1000.0, 5000.0],
    "stop_speed": [5000.0, 1000.0],
    "rate": [200.0, 200.0],
    "drive_torque": [7000.0, 7000.0],
}


def main() -> None:
    import uqgear
    from uqgear.rig.ramp_records import steady_campaign
    from uqgear.rig.virtual_rig import simulate_campaign
    from uqgear.rig.virtual_runup import simulate_runup_campaign

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="folder for the campaigns and calibrations")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--segments", type=int, default=None, help="segments per ramp (default: the ramps share 8)")
    arguments = parser.parse_args()
    folder = arguments.out or Path(tempfile.mkdtemp(prefix="runup-calibration-"))
    folder.mkdir(parents=True, exist_ok=True)
    design = uqgear.load_design("locomotive")
    truth = {
        "mesh_stiffness_scale": 0.98,
        "zeta_mesh": 0.044,
        "backlash": design.backlash,
        "ste_amplitude": design.ste_amplitude,
        "k1": design.k1,
        "k2": design.k2,
    }
    start = time.perf_counter()
    ramps = simulate_runup_campaign(design, RAMPS, true_parameters=TRUTH, seed=arguments.seed, **NUISANCES)
    print(f"run-up campaign simulated in {time.perf_counter() - start:.0f} s")
    steady = simulate_campaign(design, true_parameters=TRUTH, seed=arguments.seed, **NUISANCES)
    if arguments.segments is not None:
        # cut here at the given count, and calibrated as steady-format operating points
        ramps = steady_campaign(ramps, segments=arguments.segments)
    files = {
        "run-up and coast-down (2 ramps)": uqgear.write_rig(folder / "runup.nc", ramps),
        "steady (8 runs of 1 s)": uqgear.write_rig(folder / "steady.nc", steady),
    }
    print("| campaign | operating points | converged | inside 90 % | outside (q05/truth, q95/truth) | wall s | CPU s |")
    print("|---|---|---|---|---|---|---|")
    for label, path in files.items():
        start, cpu = time.perf_counter(), time.process_time()
        calibration = uqgear.calibrate(path, folder / path.stem, seed=0)
        wall, cpu = time.perf_counter() - start, time.process_time() - cpu
        entries = calibration.summary_["parameters"]
        outside = {
            name: (entries[name]["q05"] / value, entries[name]["q95"] / value)
            for name, value in truth.items()
            if not entries[name]["q05"] <= value <= entries[name]["q95"]
        }
        text = ", ".join(f"{name} ({low:.4f}, {high:.4f})" for name, (low, high) in outside.items()) or "-"
        print(
            f"| {label} | {len(calibration.speed_)} | {calibration.converged_} | "
            f"{len(truth) - len(outside)} of {len(truth)} | {text} | {wall:.0f} | {cpu:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
