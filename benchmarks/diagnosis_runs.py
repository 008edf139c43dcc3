"""Where one model run of a diagnosis spends its time: integration, band-limiting and resampling, features.

A diagnosis simulates 2000-4000 model runs a campaign; this benchmark times
the three parts of one run at each operating point of a campaign, on one
core, for the three kinds of run the diagnosis makes:

- *tiled*: the nominal model, one mesh period's window tiled over the record
  (most runs of the fits and of the screening);
- *whole record*: the nominal model simulated over the whole record with its
  guards, as a response that does not repeat is (an adhesion oscillation,
  two effects on different shafts);
- *pitch errors*: the whole record with per-tooth pitch errors of ISO 1328
  class 7 (the pitch-error allowance and the sideband phase test), whose
  tooth pairs each have their own contact.

It prints the median and the largest of each part over the operating points,
in ms for the three channels of a run, and each kind's share spent in
integration.

It then times the integration of a group of one, two, four and eight runs
of one operating point (a fit's finite-difference neighbours: the mesh
stiffness scale stepped) integrated together, in SIMD lanes
(:func:`uqgear.physics.history_batch.integrate_histories`, every group in
the lanes), against one at a time with the one-sample kernel (the
reference path), over the whole record, for the nominal model and with each
effect whose forcing changes from one mesh period to the next, and with
pitch errors (the pair lanes, :mod:`uqgear.physics._pair_lanes`): a group costs
its whole vector width, which is where the package's rule comes from
(:data:`uqgear.physics.batch_setup.MINIMUM_FILL`); and the line fit's projection of one
run's three records and of a group's 24, blocked and against the whole
least-squares basis (the reference path), at each speed.

Usage: ``python benchmarks/diagnosis_runs.py [FILE] [--repeats N]`` (default
``data/rig/tooth_damage.nc``, 5 repeats).
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from uqgear.diagnosis.case import prepare_case
from uqgear.diagnosis.execution import RunTask
from uqgear.diagnosis.inputs import load_rig_input, resolve_design
from uqgear.diagnosis.settings import DEFAULT_SETTINGS
from uqgear.physics import batch_setup
from uqgear.physics._lanes import LANES
from uqgear.physics.effects import make_effect
from uqgear.physics.history_batch import integrate_histories
from uqgear.physics.integration import integrate_fast
from uqgear.physics.pitch_errors import draw_pitch_errors

DATA = Path(__file__).resolve().parent.parent / "data" / "rig"


def _best_ms(work: Callable[[], object], repeats: int) -> tuple[float, object]:
    """The fastest of ``repeats`` calls (after one warm-up), ms, and the last result."""
    result = work()
    best = math.inf
    for _ in range(repeats):
        started = time.perf_counter()
        result = work()
        best = min(best, time.perf_counter() - started)
    return 1e3 * best, result


def time_runs(path: Path, repeats: int) -> dict[str, np.ndarray]:
    """Per kind of run: (n_op, 3) ms of integration, band-limiting and resampling, features."""
    rig, _ = load_rig_input(path)
    design = resolve_design(None, rig)
    case = prepare_case(rig, design, seed=1, settings=DEFAULT_SETTINGS)
    simulator = case.simulator
    errors = draw_pitch_errors(design, 7, np.random.default_rng(1))
    parts: dict[str, list[list[float]]] = {"tiled": [], "whole record": [], "pitch errors": []}
    for op in range(case.n_op):
        torque = float(rig["drive_torque"].values[op]) * design.z2 / design.z1
        run_in = simulator.run_in_periods(op)
        window = simulator.window_periods("mesh", op)
        periods, samples = simulator.whole_window(op)
        kinds = {
            "tiled": (None, run_in + window + 1, window + 1),
            "whole record": (None, run_in + periods, periods),
            "pitch errors": (errors, run_in + periods, periods),
        }
        for kind, (pitch_errors, n_periods, keep) in kinds.items():
            setup = simulator._setup(op, RunTask(op, design, 1.0, torque, (), "free", pitch_errors))
            integrate_ms, simulated = _best_ms(partial(simulator._integrate, op, [setup], n_periods, keep), repeats)
            signals, poincare = simulated[0]
            if kind == "tiled":
                resample_ms, run = _best_ms(partial(simulator._tiled, op, signals, poincare, window, "mesh"), repeats)
                if run is None:
                    # this speed's nominal response does not repeat: the diagnosis simulates it in full
                    parts[kind].append([math.nan] * 3)
                    continue
            else:
                kept = {name: values[:samples] for name, values in signals.items()}
                resample_ms, run = _best_ms(partial(simulator._whole, op, kept), repeats)
            records = np.stack([run.records[channel] for channel in case.channels])
            features_ms, _ = _best_ms(partial(case.processors[op].model_features, records), repeats)
            parts[kind].append([integrate_ms, resample_ms, features_ms])
    return {kind: np.array(values) for kind, values in parts.items()}


#: Effects whose forcing changes from one mesh period to the next, as a group's runs carry them; the
#: group "pitch errors" is the nominal model with ISO 1328 class 7 pitch errors (the pair lanes).
GROUP_EFFECTS = {
    "nominal": (),
    "tooth damage": (make_effect("tooth_damage", {"depth": 0.2}),),
    "eccentricity": (make_effect("eccentricity", {"amplitude": 2e-5, "kappa": 0.05}),),
    "torque ripple": (make_effect("torque_ripple", {"amplitude": 0.05}),),
    "eccentricity + tooth damage": (
        make_effect("eccentricity", {"amplitude": 2e-5, "kappa": 0.05}),
        make_effect("tooth_damage", {"depth": 0.2}),
    ),
    "pitch errors": (),
}


def _one_at_a_time(setups: list, n_periods: int, keep: int, per_period: int, steps_per_mode: int) -> list:
    return [integrate_fast(s, n_periods, keep, per_period, steps_per_mode, s.static_state()) for s in setups]


#: Runs in a timed group: one (a least-squares trial point), a screening's neighbours, half and all the lanes.
GROUP_SIZES = (1, 2, 4, 8)


def time_groups(path: Path, repeats: int) -> dict[str, np.ndarray]:
    """Per kind of group: (n_op, len(GROUP_SIZES), 2) ms to integrate a group's runs over the whole
    record, together in lanes (whatever their number: the package's rule is lifted) and one at a time."""
    rig, _ = load_rig_input(path)
    design = resolve_design(None, rig)
    case = prepare_case(rig, design, seed=1, settings=DEFAULT_SETTINGS)
    simulator = case.simulator
    out: dict[str, list[list[list[float]]]] = {kind: [] for kind in GROUP_EFFECTS}
    errors = draw_pitch_errors(design, 7, np.random.default_rng(1))
    rule, batch_setup.MINIMUM_FILL = batch_setup.MINIMUM_FILL, 0.0
    try:
        for op in range(case.n_op):
            torque = float(rig["drive_torque"].values[op]) * design.z2 / design.z1
            periods, _ = simulator.whole_window(op)
            n_periods, per_period = simulator.run_in_periods(op) + periods, simulator.samples_per_period[op]
            for kind, effects in GROUP_EFFECTS.items():
                pitch_errors = errors if kind == "pitch errors" else None
                setups = [
                    simulator._setup(
                        op, RunTask(op, design, 1.0 + 0.002 * member, torque, effects, "free", pitch_errors)
                    )
                    for member in range(max(GROUP_SIZES))
                ]
                row = []
                for size in GROUP_SIZES:
                    arguments = (setups[:size], n_periods, periods, per_period, simulator.steps_per_mode)
                    together_ms, _ = _best_ms(partial(integrate_histories, *arguments), repeats)
                    alone_ms, _ = _best_ms(partial(_one_at_a_time, *arguments), repeats)
                    row.append([together_ms, alone_ms])
                out[kind].append(row)
    finally:
        batch_setup.MINIMUM_FILL = rule
    return {kind: np.array(values) for kind, values in out.items()}


def time_line_fit(path: Path, repeats: int) -> dict[str, np.ndarray]:
    """Per speed: ms of the line fit's projection of 3 and 24 records, blocked and against the whole basis.

    Three records are one run's channels (most groups of a diagnosis hold one run), 24 a full group
    of eight; the whole basis is the reference path (``LineFit.weighted``), the blocked projection
    what ``LineFit.coefficients`` uses below 24 records.
    """
    rig, _ = load_rig_input(path)
    design = resolve_design(None, rig)
    case = prepare_case(rig, design, seed=1, settings=DEFAULT_SETTINGS)
    rng = np.random.default_rng(2)
    out: dict[str, list[float]] = {"3 blocked": [], "3 basis": [], "24 blocked": [], "24 basis": []}
    with threadpool_limits(1):
        for processor in case.processors:
            fit = processor.fit
            for count in (3, 24):
                records = rng.standard_normal((count, processor.size))
                blocked_ms, _ = _best_ms(partial(fit._blocked.project, records), repeats)
                basis_ms, _ = _best_ms(partial(np.matmul, fit.weighted.T, records.T), repeats)
                out[f"{count} blocked"].append(blocked_ms)
                out[f"{count} basis"].append(basis_ms)
    return {key: np.array(values) for key, values in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("file", nargs="?", default=str(DATA / "tooth_damage.nc"))
    parser.add_argument("--repeats", type=int, default=5)
    options = parser.parse_args()
    parts = time_runs(Path(options.file), options.repeats)
    print(f"one model run of {Path(options.file).name}, three channels, one core (ms; median / largest over speeds)")
    print(f"{'run':14s} {'integration':>16s} {'resampling':>16s} {'features':>16s} {'integration share':>18s}")
    for kind, values in parts.items():
        cells = [f"{np.nanmedian(values[:, part]):7.1f} / {np.nanmax(values[:, part]):5.1f}" for part in range(3)]
        share = np.nanmedian(values[:, 0] / values.sum(axis=1))
        missing = int(np.isnan(values[:, 0]).sum())
        note = f"  ({missing} speed(s) do not repeat)" if missing else ""
        print(f"{kind:14s} {cells[0]:>16s} {cells[1]:>16s} {cells[2]:>16s} {share:17.0%}{note}")
    groups = time_groups(Path(options.file), options.repeats)
    smallest = math.ceil(batch_setup.MINIMUM_FILL * LANES)
    print(f"runs of one speed over the whole record, one core: one at a time / together in lanes, by runs in the "
          f"group (median over speeds; least in brackets); groups of {smallest} runs or more go to the lanes")
    print(f"  {'':28s} " + "".join(f"{f'{size} run(s)':>16s}" for size in GROUP_SIZES))
    for kind, values in groups.items():
        ratio = values[:, :, 1] / values[:, :, 0]
        cells = [f"{np.median(ratio[:, k]):5.2f}x ({ratio[:, k].min():4.2f})" for k in range(len(GROUP_SIZES))]
        print(f"  {kind:28s} " + "".join(f"{cell:>16s}" for cell in cells))
    line_fit = time_line_fit(Path(options.file), options.repeats)
    print("line fit's projection, one core (ms; median over speeds): blocked / whole basis (ratio)")
    for count in (3, 24):
        blocked, basis = np.median(line_fit[f"{count} blocked"]), np.median(line_fit[f"{count} basis"])
        print(f"  {count:2d} records: {blocked:6.2f} / {basis:6.2f} ({basis / blocked:4.1f}x)")


if __name__ == "__main__":
    main()
