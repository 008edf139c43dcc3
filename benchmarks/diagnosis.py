"""Diagnosis benchmark: one 8-op campaign, all six candidate effects, on 2 worker processes.

Runs :func:`uqgear.diagnosis.diagnose` on a labelled campaign of data/rig/
(default ``tooth_damage.nc``) and prints the verdict, the wall time, the CPU
time (this process and its workers) and where the time went (nominal fit,
screening of the candidates, full fits). The goal is at most 5 minutes a
campaign on 2 cores.

Usage: ``python benchmarks/diagnosis.py [FILE ...] [--workers N] [--fifty-khz]``; with several
files (or ``all``) each is diagnosed in turn and a table is printed. ``--fifty-khz`` adds the second
goal (at most 60 s): a 6-run campaign at 50 kHz of a 17:38 test-rig gearbox
(module 3 mm, unshifted, so marginally undercut) with a 12 um pinion run-out that modulates the mesh
stiffness by 3 % (an eccentric pinion every channel sees; a run-out without that modulation shows in
the TE alone, like an encoder's, and is reported as a one-channel gap), made by the virtual rig
first (not timed). The first figure is the 8-run campaign at 20.48 kHz (default ``tooth_damage.nc``,
at most 20 s).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import warnings
from pathlib import Path

from uqgear.common.errors import UndercutWarning
from uqgear.diagnosis import diagnose
from uqgear.physics.design import load_design
from uqgear.physics.effects import Eccentricity
from uqgear.rig.format import write_rig
from uqgear.rig.virtual_rig import simulate_campaign

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"
LABELS = {"healthy.nc": "none", "healthy_b.nc": "none", "eccentricity.nc": "eccentricity",
          "tooth_damage.nc": "tooth_damage", "torque_ripple.nc": "torque_ripple",
          "adhesion_oscillation.nc": "adhesion_oscillation", "friction.nc": "friction"}
def fifty_khz_campaign(folder: Path) -> Path:
    """A 6-run, 50 kHz, 1 s campaign of the bundled 17:38 gearbox (``pair_17_38``).

    Its pinion is eccentric (virtual rig, seed 5).
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UndercutWarning)       # the unshifted 17-tooth pinion, modelled
        design = load_design("pair_17_38")
        campaign = simulate_campaign(
            design, {"pinion_speed": [900.0, 1400.0, 2000.0, 2600.0, 3300.0, 4000.0],
                     "drive_torque": [110.0, 90.0, 100.0, 120.0, 95.0, 105.0]},
            effects=[Eccentricity({"shaft": "pinion", "amplitude": 12e-6, "kappa": 0.03})], fs=50000.0, seed=5,
            title="17:38 gearbox, 50 kHz, 6 runs, 12 um pinion run-out modulating the mesh by 3 %")
        return write_rig(folder / "pair_17_38_50khz.nc", campaign)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("files", nargs="*", default=["tooth_damage.nc"], help="rig files in data/rig/ or 'all'")
    parser.add_argument("--fifty-khz", action="store_true",
                        help="also diagnose a generated 6-run 50 kHz campaign of a 17:38 gearbox")
    parser.add_argument("--workers", type=int, default=None,
                        help="worker processes (default: the library default, one per CPU, at most 8)")
    args = parser.parse_args()
    files = sorted(LABELS) if args.files == ["all"] else args.files
    generated = tempfile.TemporaryDirectory()
    if args.fifty_khz:
        clock = time.perf_counter()
        path = fifty_khz_campaign(Path(generated.name))
        LABELS[path.name] = "eccentricity"
        files = [*files, str(path)]
        print(f"generated {path.name} in {time.perf_counter() - clock:.0f} s (not timed below)")
    print(f"cpus available: {os.cpu_count()}, workers: {args.workers}, load average: "
          f"{', '.join(f'{v:.1f}' for v in os.getloadavg())}")
    rows = []
    for name in files:
        path = Path(name) if Path(name).is_file() else DATA / name
        with tempfile.TemporaryDirectory() as out:
            started = time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UndercutWarning)
                content = diagnose(path, out, seed=0, workers=args.workers)
            wall = time.perf_counter() - started
        timing = content["timing_s"]
        label = LABELS.get(path.name, "?")
        rows.append((path.name, label, content["verdict"], content["gap"]["baseline"],
                     content["gap"]["shrink_fraction"], wall, timing["total_cpu"], timing["nominal_fit"],
                     timing["screening"], timing["full_fits"]))
        print(f"{path.name}: verdict {content['verdict']} (label {label}); wall {wall:.0f} s, "
              f"CPU {timing['total_cpu']:.0f} s "
              f"(nominal fit {timing['nominal_fit']:.0f} s, screening {timing['screening']:.0f} s, "
              f"full fits {timing['full_fits']:.0f} s)", flush=True)
    print()
    print(f"{'file':26s} {'label':22s} {'verdict':22s} {'gap':>7s} {'shrink':>7s} {'wall s':>7s} {'CPU s':>7s}")
    for name, label, verdict, gap, shrink, wall, cpu, *_ in rows:
        shrink_text = "-" if shrink is None else f"{shrink:.2f}"
        print(f"{name:26s} {label:22s} {verdict:22s} {gap:7.2f} {shrink_text:>7s} {wall:7.0f} {cpu:7.0f}")
    print(f"load average at the end: {', '.join(f'{v:.1f}' for v in os.getloadavg())}")
    generated.cleanup()


if __name__ == "__main__":
    main()
