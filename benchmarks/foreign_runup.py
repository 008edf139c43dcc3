"""The differential diagnosis on run-ups of the foreign virtual rig, against its steady campaigns.

A healthy reference and four test campaigns (healthy, a 20 um run-out of the pinion, the same of
the gear, a 30 % damaged pinion tooth) of the foreign rig (:mod:`uqgear.rig.foreign_rig`, grade-6 gears drawn from seed
11), once as run-ups (:func:`uqgear.rig.foreign_runup.simulate_foreign_runup_campaign`: one ramp
1200 -> 3800 rpm at 300 rpm/s, 7000 N m, cut into 8 operating points by the diagnosis) and once
as the 8 steady service runs of 1 s; each test diagnosed against the reference of its kind
(``Diagnosis(...).fit(test, reference=reference)``). Prints each verdict, the named effect with
its fitted parameters and share of the change, the diagnosis's wall time, and the ratio of the
run-ups' median time to the steady campaigns'. One diagnosis is run first, untimed, so that every
timed one finds the compiled kernels in numba's cache. Timings taken while other jobs load the
machine are noisy: the load average is printed with them.

Usage: ``python benchmarks/foreign_runup.py [--workers 1] [--rate 300]``
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from uqgear.diagnosis import Diagnosis
from uqgear.physics.design import load_design
from uqgear.physics.effects import Eccentricity, ToothDamage
from uqgear.rig.foreign_rig import draw_gears, simulate_foreign_campaign
from uqgear.rig.foreign_runup import simulate_foreign_runup_campaign
from uqgear.rig.virtual_rig import default_operating_points

CASES = {
    "healthy": [],
    "eccentricity": [Eccentricity({"shaft": "pinion", "amplitude": 20e-6, "phase": 0.7})],
    "gear_run_out": [Eccentricity({"shaft": "gear", "amplitude": 20e-6, "phase": 0.7})],
    "tooth_damage": [ToothDamage({"gear": "pinion", "tooth": 5, "depth": 0.3})],
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--rate", type=float, default=300.0, help="run-up rate, rpm/s")
    args = parser.parse_args()
    design = load_design("locomotive")
    gears = draw_gears(design, 6.0, 11)
    ramps = {"start_speed": [1200.0], "stop_speed": [3800.0], "rate": [args.rate], "drive_torque": [7000.0]}
    ops = default_operating_points(design)
    kinds = {
        "run-up": lambda effects, seed: simulate_foreign_runup_campaign(
            design, ramps, gears=gears, effects=effects, seed=seed
        ),
        "steady": lambda effects, seed: simulate_foreign_campaign(
            design, ops, gears=gears, effects=effects, seed=seed, duration=1.0
        ),
    }
    references = {kind: make([], 100) for kind, make in kinds.items()}
    Diagnosis(seed=5, workers=args.workers).fit(kinds["steady"]([], 199), reference=references["steady"])
    seconds: dict[str, list[float]] = {kind: [] for kind in kinds}
    print(f"{'kind':8} {'campaign':13} {'verdict':13} {'named (fitted parameters, share)':60} {'wall s':>7}")
    for index, (name, effects) in enumerate(CASES.items()):
        for kind, make in kinds.items():
            test = make(effects, 200 + index)
            started = time.perf_counter()
            diagnosis = Diagnosis(seed=5, workers=args.workers).fit(test, reference=references[kind])
            seconds[kind].append(time.perf_counter() - started)
            named = (diagnosis.summary_.get("change") or {}).get("named")
            said = "-"
            if named:
                values = ", ".join(
                    f"{key} {value:.3g}" if isinstance(value, float) else f"{key} {value}"
                    for key, value in named["parameters"].items()
                )
                said = f"{named['variant']} ({values}; {named['share']:.0%})"
            print(f"{kind:8} {name:13} {diagnosis.summary_['verdict']:13} {said:60} {seconds[kind][-1]:7.1f}")
    ratio = statistics.median(seconds["run-up"]) / statistics.median(seconds["steady"])
    print(f"median wall time, run-up over steady: {ratio:.2f} (load average {os.getloadavg()[0]:.1f})")


if __name__ == "__main__":
    main()
