"""Continuation against brute-force sweeps: the same bifurcation points, located for how much work.

For the bundled ``locomotive`` design at its rated drive torque (7 kN m), with T2 at the balancing
value and at both ends of its interval (wet and dry rail), and optionally at the light load of the
bundled ``paper_speed`` study (T1 = 1 kN m, T2 = 4.81 kN m: the period-doubling cascade), it

* follows the period-1 branch from 200 to 6000 rpm with all its bifurcations
  (:class:`uqgear.dynamics.Continuation`, doubled branches included), timed;
* sweeps the same range by brute force at 25 rpm steps up and down, each run starting from its
  neighbour's final state (1500 mesh periods, 300 kept, as a long transient needs), timed;
* reads off the sweeps where they jump (peak mesh force changing by more than 10 % between
  neighbours), where the teeth first separate and where the up-sweep's period first changes, and
  checks that every fold, grazing and period-doubling point of the continuation lies within one
  sweep step of them;
* prints the time of the sweeps over that of the continuation, per case and in all (aim: >= 5).

Usage: ``python benchmarks/continuation.py [--cases rated wet dry light] [--step 25] [--json out.json]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

import uqgear
from uqgear.dynamics import Continuation, StartedEvaluator, bifurcation_table
from uqgear.dynamics.attractors import up_down_sweeps
from uqgear.physics.design import STANDARD_GRAVITY
from uqgear.physics.integration import samples_from_mapping

JUMP = 0.1


def cases(design: uqgear.Design) -> dict[str, dict[str, float]]:
    operation = design.operation
    low, high = (mu * operation.axle_load * STANDARD_GRAVITY * operation.wheel_radius
                 for mu in operation.adhesion_coefficient)
    rated = operation.drive_torque
    return {"rated": {"drive_torque": rated, "adhesion_torque": rated * design.z2 / design.z1},
            "wet": {"drive_torque": rated, "adhesion_torque": low},
            "dry": {"drive_torque": rated, "adhesion_torque": high},
            "light": {"drive_torque": 1000.0, "adhesion_torque": 4810.0}}


def _changes(values: np.ndarray, speeds: np.ndarray) -> list[tuple[float, float, object, object]]:
    return [(float(speeds[i]), float(speeds[i + 1]), values[i], values[i + 1])
            for i in range(len(values) - 1) if values[i] != values[i + 1]]


def sweep_points(runs: dict, speeds: np.ndarray) -> dict:
    """Jumps, starts and ends of separation and period changes read off the up- and down-sweeps."""
    out: dict = {}
    up, down = runs["up"]["peak_mesh_force"].values, runs["down"]["peak_mesh_force"].values
    # a jump of a sweep is a step where the two sweeps disagree at one end (hysteresis), not a steep
    # but single-valued resonance flank that both sweeps climb alike
    apart = np.abs(up - down) / np.maximum(up, down) > 0.5 * JUMP
    for start, force in (("up", up), ("down", down)):
        change = np.abs(np.diff(force)) / force[:-1]
        steps = np.nonzero((change > JUMP) & (apart[:-1] | apart[1:]))[0]
        out[f"jumps_{start}"] = [(float(speeds[i]), float(speeds[i + 1])) for i in steps]
        out[f"separation_{start}"] = _changes(runs[start]["fraction_separation"].values > 0, speeds)
        out[f"periods_{start}"] = _changes(runs[start]["regime"].values.astype(str), speeds)
    return out


def check(table, found: dict, step: float) -> list[str]:
    """Each continuation point against the sweeps: within one sweep step of where either sweep sees it."""
    lines = []
    for _, row in table.iterrows():
        location, kind, period = row["parameter"], row["type"], int(row["period"])
        if not (row["stable_before"] or row["stable_after"]) and kind != "grazing_separation":
            lines.append(f"{kind} at {location:.2f} rpm (branch {row['branch']}): unstable on both sides, "
                         "no sweep can see it")
            continue
        if kind == "fold" and row["sweep"]:
            # a jump of the peak force, or (off a doubled branch) of the period
            changes = found[f"periods_{row['sweep']}"]
            brackets = [(a, b) for a, b in found[f"jumps_{row['sweep']}"]] + [
                (a, b) for a, b, p, q in changes if period > 1 and f"period-{period}" in (p, q)]
            what = f"fold ({row['sweep']}-sweep jumps)"
        elif kind == "grazing_separation":
            brackets = [(a, b) for start in ("up", "down") for a, b, _, _ in found[f"separation_{start}"]]
            what = "grazing (separation " + ("begins" if row["side"] > 0 else "ends") + " above)"
        elif kind == "period_doubling":
            names = {f"period-{period}", f"period-{2 * period}"}
            brackets = [(a, b) for start in ("up", "down") for a, b, p, q in found[f"periods_{start}"]
                        if {p, q} == names]
            what = f"period doubling {period} -> {2 * period}"
        else:
            continue
        near = [(a, b) for a, b in brackets if a - step <= location <= b + step]
        twin = table[(table["type"] == kind) & (table["branch"] == row["branch"])
                     & (np.abs(table["parameter"] - location) < step) & (table["parameter"] != location)]
        verdict = "ok" if near else ("window narrower than a sweep step: not resolved by the sweeps" if len(twin)
                                     else "MISSED")
        lines.append(f"{what} at {location:.2f} rpm (branch {row['branch']}): sweeps {near or 'nothing near'}"
                     f" -> {verdict}")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--cases", nargs="+", default=["rated", "wet", "dry", "light"])
    parser.add_argument("--step", type=float, default=25.0)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    speeds = np.arange(200.0, 6000.0 + 0.5 * args.step, args.step)
    model = StartedEvaluator(design, {"n_periods": 1500, "keep_periods": 300})
    # compile and warm both paths outside the timings
    Continuation("pinion_speed", 3000.0, 3100.0).fit(design, cases(design)["rated"])
    up_down_sweeps(model, samples_from_mapping({"pinion_speed": [3000.0, 3050.0]}))
    totals = {"continuation": 0.0, "sweeps": 0.0}
    report = {}
    for name in args.cases:
        inputs = cases(design)[name]
        began = time.perf_counter()
        fit = Continuation("pinion_speed", 200.0, 6000.0).fit(design, inputs)
        continuation = time.perf_counter() - began
        began = time.perf_counter()
        samples = samples_from_mapping({"pinion_speed": speeds, **{k: np.full(speeds.size, v)
                                                                   for k, v in inputs.items()}})
        runs = up_down_sweeps(model, samples)
        sweeps = time.perf_counter() - began
        totals["continuation"] += continuation
        totals["sweeps"] += sweeps
        table = bifurcation_table(fit.result_)
        found = sweep_points(runs, speeds)
        print(f"\n=== {name}: T1 = {inputs['drive_torque'] / 1e3:.4g} kN m, T2 = {inputs['adhesion_torque'] / 1e3:.4g} "
              f"kN m; continuation {continuation:.2f} s ({fit.orbit_passes_} mesh periods, "
              f"{len(fit.branches_)} branches), sweeps {sweeps:.1f} s ({2 * speeds.size} runs x 1500 periods); "
              f"ratio {sweeps / continuation:.1f}")
        for _, row in table.iterrows():
            print(f"  {row['type']:<20s} branch {row['branch']} (period {row['period']}) at "
                  f"{row['parameter']:9.3f} rpm "
                  f"+- {row['tolerance']:.3f}  peak force {row['peak_mesh_force'] / 1e3:7.2f} kN  {row['sweep']}")
        for line in check(table, found, args.step):
            print("  check: " + line)
        report[name] = {"inputs": inputs, "continuation_s": continuation, "sweeps_s": sweeps,
                        "bifurcations": table.to_dict(orient="records"), "sweeps": found}
    print(f"\nall cases: continuation {totals['continuation']:.2f} s, sweeps {totals['sweeps']:.1f} s, "
          f"sweeps / continuation = {totals['sweeps'] / totals['continuation']:.1f}")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(report, handle, indent=1, default=float)


if __name__ == "__main__":
    main()
