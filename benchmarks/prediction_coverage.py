"""Coverage of calibrated predictions on known truth: virtual-rig campaigns calibrated, diagnosed and predicted.

Each campaign is simulated by the virtual rig with scattered true parameters (as the blind tests
scatter them) and one kind of departure from the plain model:

* ``healthy``: speed wander (+-0.5 % at 1.3 Hz) and the rig's noise;
* ``effect``: a strong eccentricity or tooth damage, which the diagnosis names and the prediction
  carries with its fitted parameters and their intervals;
* ``structural``: a 2.5 kHz resonance on the pinion accelerometer's path, or encoder run-out
  (8 um on both shafts): the rig is not our model plus an effect.

The model is calibrated on it (emcee, default settings), then the 90 % predictive band of peak mesh
force, dynamic load factor and RMS DTE at operating points not in the campaign (speeds between the
campaign's, other drive torques, T2 at the balance of T1) is compared with the true rig's value (the
model at the true parameters with the true effects). On healthy campaigns the spread of the worst
case over the T2 interval (upper bound's q95 - q05) after calibration is compared with the prior's.

With ``--discrepancy`` the calibration learns a model-discrepancy term and the prediction carries it (the
dynamic part of each response scaled by a draw of the DTE's first-mesh-harmonic discrepancy, as the study's
``prediction`` analysis does).

Prints coverage per kind and QoI, and where the truth falls among the predictive draws (its probability
integral transform: the share of draws below it), which tells bands that are too wide from bands that are right
and were lucky. Minutes per campaign (a calibration, and a diagnosis on
``effect`` campaigns).

Usage: ``python benchmarks/prediction_coverage.py [--per-kind 2] [--kinds healthy effect structural] [--seed 1]
[--discrepancy] [--first K] [--skip J] [--run-kinds KIND ...] [--without-artefacts] [--json out.json]``;
``--without-artefacts`` simulates the same campaigns without their speed wander, encoder run-out or transfer
path (what the calibration's bands owe to them); ``--first``, ``--skip`` and
``--run-kinds`` calibrate a
part of the ``--per-kind`` x ``--kinds`` campaigns (the same campaigns as the whole run: the ones left out still take
their random draws), so that the kinds can run side by side in separate processes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import numpy as np

import uqgear
from uqgear.calibration.priors import prior_bounds
from uqgear.diagnosis import Diagnosis, effect_family, named_effects
from uqgear.physics.effect_draws import draw_effect_sets
from uqgear.rig.transfer_path import apply_transfer_path
from uqgear.rig.virtual_rig import simulate_campaign
from uqgear.uq.prediction import scale_dynamic_part
from uqgear.validation.campaigns import effect_draw, scattered_truth, scattered_values

QOIS = ("peak_mesh_force", "dynamic_load_factor", "dte_rms")
#: Held-out operating points: speeds between the campaign's (600-3800 rpm), other drive torques.
HELD_OUT = {"pinion_speed": [1000.0, 1500.0, 2500.0, 3100.0], "drive_torque": [6500.0, 7000.0, 6000.0, 7500.0]}
SIMULATION = {"n_periods": 400, "keep_periods": 200, "steps_per_mode": 32}
DRAWS = 64


def draw_campaign(kind: str, index: int, rng: np.random.Generator, design: uqgear.Design) -> dict[str, Any]:
    """What is random about a campaign (the truth, its effects, the simulation's seed): drawn from ``rng``."""
    truth = scattered_values(scattered_truth(rng), design)
    effects, options, transfer = [], {}, None
    if kind == "healthy":
        options["speed_wander"] = [(0.005, 1.3)]
    elif kind == "effect":
        name = ("eccentricity", "tooth_damage")[index % 2]
        family = effect_family(name)
        effects = [family.make(effect_draw(name, family.ladder[2], rng))]
    elif index % 2 == 0:
        transfer = (2500.0, 0.05)
    else:
        options["encoder_run_out"] = {"pinion": 8e-6, "gear": 8e-6}
    seed = np.random.SeedSequence([int(rng.integers(2**31)), index])
    return {"truth": truth, "effects": effects, "options": options, "transfer": transfer, "seed": seed}


def campaign(
    kind: str, index: int, rng: np.random.Generator, design: uqgear.Design, artefacts: bool = True
) -> dict[str, Any]:
    """The campaign's rig, truth and effects; without ``artefacts`` the rig has neither its speed wander, encoder
    run-out nor transfer path (the same truth, effects, noise and seed)."""
    drawn = draw_campaign(kind, index, rng, design)
    options = drawn["options"] if artefacts else {}
    rig = simulate_campaign(design, true_parameters=drawn["truth"], effects=drawn["effects"], seed=drawn["seed"],
                            run_in=0.3, **options)
    if artefacts and drawn["transfer"] is not None:
        rig = apply_transfer_path(rig, "acc_pinion", *drawn["transfer"])
    return {"rig": rig, "truth": drawn["truth"], "effects": drawn["effects"]}


def held_out_samples(values: dict[str, np.ndarray], design: uqgear.Design) -> Any:
    n = len(HELD_OUT["pinion_speed"])
    rows = {name: np.repeat(np.asarray(v, dtype=float), n) for name, v in values.items()}
    size = len(next(iter(rows.values()))) // n if rows else 1
    speeds = np.tile(HELD_OUT["pinion_speed"], size)
    torques = np.tile(HELD_OUT["drive_torque"], size)
    return uqgear.samples_from_mapping(
        {**rows, "pinion_speed": speeds, "drive_torque": torques, "adhesion_torque": torques * design.z2 / design.z1}
    )


def predict(
    draws: dict[str, np.ndarray], effect_sets: list | None, design: uqgear.Design, factors: np.ndarray | None = None
) -> dict[str, np.ndarray]:
    """QoIs (draw, held-out point) of every draw; the draws' effects one batch each; ``factors`` (draw, point):
    the discrepancy's factor on each run's dynamic part."""
    n = len(HELD_OUT["pinion_speed"])
    size = len(next(iter(draws.values())))
    out = {qoi: np.empty((size, n)) for qoi in QOIS}
    groups = [[i] for i in range(size)] if effect_sets else [list(range(size))]
    for rows in groups:
        effects = effect_sets[rows[0]] if effect_sets else ()
        model = uqgear.BatchEvaluator(design, effects=effects, **SIMULATION)
        result = model(held_out_samples({k: v[rows] for k, v in draws.items()}, design))
        factor = None if factors is None else factors[rows].reshape(-1)
        for qoi in QOIS:
            values = result[qoi].values
            if factor is not None:
                values = scale_dynamic_part(qoi, "", values, result, factor)
            out[qoi][rows] = values.reshape(len(rows), n)
    return out


def worst_spread(draws: dict[str, np.ndarray], design: uqgear.Design) -> float:
    """Spread (q95 - q05 over the draws) of the worst peak mesh force over 7 T2 nodes at 3100 rpm, T1 7 kN m."""
    nodes = np.linspace(21.15e3, 46.52e3, 7)
    size = len(next(iter(draws.values())))
    samples = uqgear.samples_from_mapping(
        {
            **{k: np.repeat(v, nodes.size) for k, v in draws.items()},
            "adhesion_torque": np.tile(nodes, size),
            "pinion_speed": np.full(size * nodes.size, 3100.0),
            "drive_torque": np.full(size * nodes.size, 7000.0),
        }
    )
    worst = uqgear.BatchEvaluator(design, **SIMULATION)(samples)["peak_mesh_force"].values.reshape(size, -1).max(axis=1)
    return float(np.subtract(*np.quantile(worst, [0.95, 0.05])))


def discrepancy_factors(calibration: uqgear.Calibration, space: uqgear.ParameterSpace) -> np.ndarray:
    """exp(delta) of the DTE's first mesh harmonic, (draw, held-out point): each posterior draw's own discrepancy
    coefficients (drawn with its parameters), as the study's ``prediction`` analysis carries them."""
    delta = calibration.discrepancy_.at_draws(space.posterior.discrepancy_beta, HELD_OUT["pinion_speed"],
                                              HELD_OUT["drive_torque"])
    return np.exp(np.nan_to_num(delta.sel(channel="te", harmonic=1).values))


def calibration_options(model_error_floor: float | None) -> dict[str, Any]:
    """The calibration's settings beside the defaults: the model-error prior's lower end where given."""
    return {} if model_error_floor is None else {"model_error_range": (model_error_floor, 0.5)}


def posterior_record(calibration: uqgear.Calibration, truth: dict[str, float]) -> dict[str, Any]:
    """The truth's z-score against each parameter's posterior, and each group's supported model-error level."""
    return {
        # about standard normal where the posterior is calibrated
        "z": {
            name: round(float((truth[name] - np.median(values)) / np.std(values)), 2)
            for name in calibration.parameters
            for values in [calibration.posterior_[name].values.ravel()]
        },
        # the model-error level each (channel, harmonic) group's residuals support, % (posterior median)
        "model_error_q50": {
            group: round(level["q50"] * 100, 3) for group, level in calibration.summary_["model_error"].items()
        },
    }


def scored(predicted: dict[str, np.ndarray], true_values: dict[str, np.ndarray]) -> dict[str, Any]:
    """Per QoI and held-out point: whether the 90 % band holds the truth, and the share of draws below it."""
    covered, pit = {}, {}
    for qoi in QOIS:
        low, high = np.quantile(predicted[qoi], [0.05, 0.95], axis=0)
        covered[qoi] = ((true_values[qoi][0] >= low) & (true_values[qoi][0] <= high)).tolist()
        # where the truth falls in the predictive draws: uniform over campaigns for a calibrated prediction,
        # bunched at 0.5 for bands wider than the errors, at 0 and 1 for bands too narrow
        pit[qoi] = np.mean(predicted[qoi] < true_values[qoi][0], axis=0).tolist()
    return {"covered": covered, "pit": pit}


def place_shares(pits: np.ndarray) -> tuple[float, float]:
    """Shares of truths in the central half and in the outer tenths of their draws (0.5 and 0.2 if calibrated)."""
    return float(np.mean((pits >= 0.25) & (pits <= 0.75))), float(np.mean((pits < 0.1) | (pits > 0.9)))


def one_campaign(
    kind: str, index: int, rng: np.random.Generator, design: uqgear.Design, discrepancy: bool = False,
    artefacts: bool = True, model_error_floor: float | None = None,
) -> dict[str, Any]:
    began = time.perf_counter()
    made = campaign(kind, index, rng, design, artefacts)
    effect_sets, named, verdict = None, [], None
    if kind == "effect":
        # diagnose, then calibrate with the named effects in the model (as a study's calibrate analysis does)
        diagnosis = Diagnosis(design=design, seed=index).fit(made["rig"])
        verdict = str(diagnosis.decision_.verdict)
        try:
            named = named_effects(diagnosis)
            effect_sets = draw_effect_sets(named, DRAWS, index)
        except uqgear.UqgearError:
            named, effect_sets = [], None
    calibration = uqgear.Calibration(
        design=design, seed=index, discrepancy=discrepancy, effects=[effect.central() for effect in named],
        **calibration_options(model_error_floor),
    ).fit(made["rig"])
    entry: dict[str, Any] = {"kind": kind, "converged": bool(calibration.converged_)}
    if verdict is not None:
        entry["verdict"] = verdict
    if not calibration.converged_:
        entry["seconds"] = time.perf_counter() - began
        return entry
    entry.update(posterior_record(calibration, made["truth"]))
    space = uqgear.ParameterSpace.from_posterior(calibration, draws=DRAWS, seed=index)
    draws = {name: space.posterior.column(name) for name in space.posterior.names}
    truth_rows = {k: np.array([v]) for k, v in made["truth"].items()}
    true_values = predict(truth_rows, [tuple(made["effects"])] if made["effects"] else None, design)
    predicted = predict(draws, effect_sets, design, discrepancy_factors(calibration, space) if discrepancy else None)
    entry.update(scored(predicted, true_values))
    if kind == "healthy":
        rng_prior = np.random.default_rng(index)
        box = prior_bounds(design, space.posterior.names)
        prior = {name: rng_prior.uniform(*box[name], DRAWS) for name in space.posterior.names}
        entry["spread_ratio"] = worst_spread(prior, design) / max(worst_spread(draws, design), 1e-9)
    entry["seconds"] = time.perf_counter() - began
    return entry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--per-kind", type=int, default=2)
    parser.add_argument("--kinds", nargs="+", default=["healthy", "effect", "structural"])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--discrepancy", action="store_true")
    parser.add_argument("--first", type=int, help="calibrate only the first FIRST campaigns of each kind")
    parser.add_argument("--skip", type=int, default=0, help="and not the first SKIP of them")
    parser.add_argument("--run-kinds", nargs="+", help="calibrate only these kinds (the others' draws still taken)")
    parser.add_argument("--without-artefacts", action="store_true",
                        help="the same campaigns without speed wander, encoder run-out or transfer path")
    parser.add_argument("--model-error-floor", type=float, default=None,
                        help="the model-error prior's lower end (default: the calibration's)")
    parser.add_argument("--json")
    args = parser.parse_args()
    design = uqgear.load_design("locomotive")
    rng = np.random.default_rng(args.seed)
    entries = []
    # the campaigns are those of the whole --per-kind x --kinds layout: one that is skipped still takes its draws
    first = args.per_kind if args.first is None else min(args.first, args.per_kind)
    run_kinds = args.kinds if args.run_kinds is None else args.run_kinds
    for kind in args.kinds:
        for index in range(args.per_kind):
            if not args.skip <= index < first or kind not in run_kinds:
                draw_campaign(kind, index, rng, design)
                continue
            entry = one_campaign(kind, index, rng, design, args.discrepancy, not args.without_artefacts,
                                 args.model_error_floor)
            entries.append(entry)
            print(json.dumps(entry), flush=True)
    for kind in run_kinds:
        found = [e for e in entries if e["kind"] == kind and "covered" in e]
        for qoi in QOIS:
            flags = [flag for e in found for flag in e["covered"][qoi]]
            share = np.mean(flags) if flags else float("nan")
            print(f"{kind:10s} {qoi:20s} 90 % band covers the truth in {share * 100:5.1f} % of {len(flags)} points")
        for qoi in QOIS:
            pits = np.array([value for e in found for value in e["pit"][qoi]])
            if pits.size:
                # a calibrated prediction puts half its truths in the central half and a tenth in each outer tenth
                central, tails = place_shares(pits)
                print(f"{kind:10s} {qoi:20s} truth's place in the draws: central half {central * 100:5.1f} % "
                      f"(50 % if calibrated), outer tenths {tails * 100:5.1f} % (20 %)")
        z = np.array([value for e in found for value in e["z"].values()])
        if z.size:
            print(f"{kind:10s} parameters: RMS z {np.sqrt(np.mean(z ** 2)):.2f} (1 if calibrated) over {z.size}")
        ratios = [e["spread_ratio"] for e in found if "spread_ratio" in e]
        if ratios:
            print(f"{kind:10s} worst-case spread, prior / posterior: {', '.join(f'{r:.1f}x' for r in ratios)}")
        refused = sum(1 for e in entries if e["kind"] == kind and not e["converged"])
        print(f"{kind:10s} calibrations refused (not converged): {refused} of {first - args.skip}")
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(entries, handle, indent=2)
    sys.stdout.flush()


if __name__ == "__main__":
    main()
