"""Run-up segments against steady runs at their speeds, and against the diagnosis's model read through them.

For one campaign of the run-up blind suite (``--campaign``, a prefix of its
identifier; ``--seed``) and each ramp rate (``--rates``, rpm/s), the
campaign is made noise-free with its true parameters and effects, cut into
its 8 operating points as the diagnosis cuts it, and the same design, truth
and effects are run steady at each segment's speed, torque and T2 for the
segment's length. Printed per rate: the segment length, the pinion and gear
revolutions it holds at the slowest segment, and per channel the largest
difference between the segment's and the steady run's amplitude of a line
at gear orders (``shaft_gear*``, ``*_sb_gear*``) as a multiple of the
channel's largest steady line (mesh harmonics, sidebands, shaft orders), and
how many gear-order lines differ by more than 1 % of it; then the same
against the diagnosis's own model of each segment (driven through the speeds
the segment swept from shortly before it, cleaned and order-tracked as the
segment was: :mod:`uqgear.rig.ramp_segments`) and against a steady run at
the segment's mean speed read the same way, per channel the largest
difference of a gear-order line and of any line over the segment's largest
line (and of any line from 1200 rpm up). ``--diagnose``
then diagnoses the campaign (with its noise and nuisances) at each rate
as the blind test does and prints the verdict and the named set (a
campaign diagnosed against a healthy reference is diagnosed here without
it; a wandering ramp slower than its wander turns back is refused).

Usage: ``python benchmarks/runup_segments.py [--seed 1] [--campaign runup-two_effects-eccentricity+tooth_damage]
[--rates 200 60] [--diagnose] [--workers 1]``
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main() -> None:
    from uqgear.diagnosis import Diagnosis, DiagnosisSeeds
    from uqgear.rig.features import extract_features
    from uqgear.rig.ramp_records import steady_campaign
    from uqgear.rig.virtual_rig import simulate_campaign
    from uqgear.validation import planned_campaigns
    from uqgear.validation.blind_test import _blind
    from uqgear.validation.campaigns import true_values
    from uqgear.validation.runup_campaigns import runup_campaign

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--campaign", default="runup-two_effects-eccentricity+tooth_damage")
    parser.add_argument("--rates", type=float, nargs="+", default=[200.0, 60.0])
    parser.add_argument("--diagnose", action="store_true")
    parser.add_argument("--workers", type=int, default=1)
    args = parser.parse_args()
    spec, design, seed = next(planned for planned in planned_campaigns(args.seed, suite="runup", n_per_effect=1)
                              if planned[0].identifier.startswith(args.campaign))
    truth = true_values(spec, design)
    ratio = design.z1 / design.z2
    print(f"{spec.identifier} (seed {args.seed}): effects {[(e.name, dict(e.values)) for e in spec.effects()]}")
    for rate in args.rates:
        quiet = {key: value for key, value in spec.nuisances.items() if key == "channels"}
        rig = _noise_free(spec, design, truth, rate, quiet)
        points = steady_campaign(rig)
        fs = 1.0 / float(points["time"].values[1] - points["time"].values[0])
        length = points.sizes["time"] / fs
        slowest = float(points["pinion_speed"].min())
        adhesion = json.loads(points.attrs["true_parameters"])["adhesion_torque"]
        steady = simulate_campaign(
            design,
            {"pinion_speed": points["pinion_speed"].values, "drive_torque": points["drive_torque"].values},
            true_parameters={**truth, "adhesion_torque": np.asarray(adhesion)},
            effects=spec.effects(), relative_noise=0.0, duration=length, run_in=0.5, seed=2, **quiet,
        )
        cut, held = extract_features(points, design), extract_features(steady, design)
        revolutions = length * slowest / 60.0
        print(f"rate {rate:g} rpm/s: segments of {length:.3f} s, at the slowest ({slowest:.0f} rpm) "
              f"{revolutions:.1f} pinion and {revolutions * ratio:.2f} gear revolutions")
        for channel in cut.data_vars:
            names = [str(name) for name in cut[channel]["feature"].values]
            gear = [index for index, name in enumerate(names) if "gear" in name and ("shaft" in name or "_sb_" in name)]
            x, y = np.abs(cut[channel].values[:, gear]), np.abs(held[channel].values[:, gear])
            # the difference against the channel's largest steady line (mesh harmonics, sidebands, shaft orders):
            # a line the steady run holds small that the segment reads large counts as it does in the diagnosis
            lines = [index for index, name in enumerate(names) if name.startswith(("mesh", "shaft"))]
            scale = float(np.nanmax(np.abs(held[channel].values[:, lines])))
            differences = np.abs(x - y) / scale
            op, line = np.unravel_index(int(np.nanargmax(differences)), differences.shape)
            where = f"{names[gear[line]]} at {float(points['pinion_speed'][op]):.0f} rpm"
            print(f"  {channel:11s} largest |segment - steady| of a gear-order line "
                  f"{float(differences[op, line]):9.3g} x the largest steady line ({where}); "
                  f"gear-order lines off by more than 1 % of it: {int(np.sum(differences > 0.01))} of "
                  f"{differences.size}")
        _through_segments(spec, design, truth, points, adhesion)
        if args.diagnose:
            started = time.perf_counter()
            generation, noise, diagnosis, learn = seed.spawn(4)
            noisy = runup_campaign(spec, design, truth, spec.effects(), generation, "rate check", rate)
            fitted = Diagnosis(design=design, seed=DiagnosisSeeds(noise, diagnosis, learn), workers=args.workers,
                               reference_route="transfer").fit(_blind(noisy))
            print(f"  diagnosis: {fitted.decision_.verdict}, named {[c.entry.effect for c in fitted.effects_]} "
                  f"(truth {spec.truth_set()}) in {time.perf_counter() - started:.0f} s", flush=True)


def _through_segments(spec, design, truth, points, adhesion) -> None:
    """The diagnosis's model of each segment at the true parameters and effects against the segment, read two
    ways: through the speeds the segment swept (the diagnosis's reading) and as a steady run at its mean speed;
    per channel the largest difference of a gear-order line and of any line over the channel's largest line at
    that segment, and the same from the segments at 1200 rpm and up."""
    import dataclasses

    from uqgear.diagnosis.case import prepare_case
    from uqgear.diagnosis.execution import RunTask, execute_run
    from uqgear.diagnosis.simulation import CampaignSimulator
    from uqgear.rig.virtual_rig import true_model

    case = prepare_case(points, design, seed=np.random.SeedSequence(0))
    steady = CampaignSimulator(design, case.speeds, case.drive_torques, case.fs, case.size, case.channels)
    true_design, scale, _ = true_model(design, truth)
    for label, simulator in (("through the segment", case.simulator), ("as a steady run", steady)):
        reading = dataclasses.replace(case, simulator=simulator)
        worst: dict[str, list[tuple[float, float, float]]] = {channel: [] for channel in case.channels}
        for op in range(case.speeds.size):
            task = RunTask(op, true_design, scale, float(adhesion[op]), tuple(spec.effects()), "free")
            model, _ = execute_run(reading, task)
            names = case.processors[op].names
            lines = [index for index, name in enumerate(names) if name.startswith(("mesh", "shaft"))]
            gear = [index for index in lines if "gear" in names[index]]
            for c, channel in enumerate(case.channels):
                observed, modelled = np.abs(case.observed_all[op, c]), np.abs(model[c])
                difference = np.abs(observed - modelled) / float(np.nanmax(observed[lines]))
                worst[channel].append(
                    (float(np.nanmax(difference[gear])), float(np.nanmax(difference[lines])), float(case.speeds[op]))
                )
        for channel, rows in worst.items():
            gear_line = max(rows, key=lambda row: row[0])
            any_line = max(rows, key=lambda row: row[1])
            upper = max(row[1] for row in rows if row[2] >= 1200.0)
            print(f"  {channel:11s} read {label}: largest |segment - model| over the segment's largest line: a "
                  f"gear-order line {gear_line[0]:8.3g} ({gear_line[2]:.0f} rpm), any line {any_line[1]:8.3g} "
                  f"({any_line[2]:.0f} rpm), any line from 1200 rpm {upper:8.3g}")


def _noise_free(spec, design, truth, rate, options):
    """The campaign's ramps without noise or nuisances (its channels kept), true parameters and effects."""
    from uqgear.rig.virtual_runup import simulate_runup_campaign
    from uqgear.validation.runup_campaigns import ramp_table

    return simulate_runup_campaign(design, ramp_table(spec.plan, rate), true_parameters=dict(truth),
                                   effects=spec.effects(), relative_noise=0.0, seed=3, **options)


if __name__ == "__main__":
    main()
