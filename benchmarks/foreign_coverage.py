"""Coverage of the calibrated prediction on the foreign virtual rig: its own mesh force at held-out operating points.

A foreign campaign (:func:`calibration_discrepancy.foreign_campaign`: another simulator, no backlash, housing
modes, per-tooth profile errors of ISO grade 6 gears, at the 8 default operating points) is calibrated with the
discrepancy term (default settings otherwise). Its posterior then predicts, with
:class:`uqgear.uq.prediction.PosteriorPrediction` carrying the discrepancy (the dynamic part of each response
scaled by exp(delta) of the DTE's first mesh harmonic, as the study's ``prediction`` analysis does), peak mesh
force, dynamic load factor and RMS DTE at operating points that are not the campaign's: four inside its speed
range and two outside it (flagged ``outside``), T2 at the balance of T1. Each 90 % band (5 % to 95 % over the
draws) is compared with the foreign rig's own value (:func:`uqgear.rig.foreign_response.foreign_qois`, same
gears), and the same band without the discrepancy is given beside it.

Prints one JSON record per campaign seed and the share of covered cases per QoI, inside and outside the
campaign's range. A few minutes per seed (the calibration).

With ``--effective-priors`` the stiffness priors are those of ``calibration_discrepancy.EFFECTIVE_PRIORS``.

Usage: ``python benchmarks/foreign_coverage.py [--seeds 0 1] [--effective-priors] [--json PATH]``
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

from calibration_discrepancy import EFFECTIVE_PRIORS, foreign_campaign

import uqgear
from uqgear.calibration import Calibration
from uqgear.rig.foreign_response import foreign_qois
from uqgear.rig.foreign_rig import draw_gears
from uqgear.study.prediction import DiscrepancyFactors
from uqgear.uq.prediction import PosteriorPrediction

QOIS = ("peak_mesh_force", "dynamic_load_factor", "dte_rms")
#: Held-out operating points (pinion speed rpm, T1 N m): four between the campaign's speeds (600-3800 rpm), two
#: outside them.
HELD_OUT = ((1000.0, 6500.0), (1500.0, 7000.0), (2500.0, 6000.0), (3100.0, 7500.0), (450.0, 6000.0), (4200.0, 6000.0))
SIMULATION = {"n_periods": 400, "keep_periods": 200, "steps_per_mode": 32}
DRAWS = 64


def band(posterior: Any, discrepancy: Any, design: uqgear.Design, speed: float, torque: float,
         seed: int) -> dict[str, list[float]]:
    """The 5, 50 and 95 % quantiles over the posterior draws of each QoI at one operating point (``posterior``:
    the calibration's Dataset; ``discrepancy``: its fitted discrepancy, or None for the band without it)."""
    balance = torque * design.z2 / design.z1
    model = uqgear.BatchEvaluator(design, fixed={"drive_torque": torque, "adhesion_torque": balance}, **SIMULATION)
    space = uqgear.ParameterSpace.from_posterior(posterior, draws=DRAWS, seed=seed, allow_unconverged=True)
    factors = None if discrepancy is None else DiscrepancyFactors(discrepancy, torque)
    prediction = PosteriorPrediction(QOIS, draws=DRAWS, seed=seed, discrepancy=factors)
    prediction.fit(model, space, {"pinion_speed": [speed]})
    return {qoi: [float(v) for v in prediction.result_[qoi].sel(bound="upper").values[:, 0]] for qoi in QOIS}


def one_seed(seed: int, effective_priors: bool = False) -> dict[str, Any]:
    began = time.perf_counter()
    design = uqgear.load_design("locomotive")
    rig = foreign_campaign(seed)
    priors = EFFECTIVE_PRIORS if effective_priors else None
    calibration = Calibration(seed=seed, discrepancy=True, priors=priors).fit(rig)
    speeds = rig["pinion_speed"].values
    record: dict[str, Any] = {
        "seed": seed,
        "effective_priors": effective_priors,
        "converged": bool(calibration.converged_),
        "refusal": calibration.failure()["message"],
        "rhat_max": calibration.diagnostics_["rhat_max"],
        "share": calibration.summary_["discrepancy"]["share"],
        "points": [],
    }
    truth = foreign_qois(design, [p[0] for p in HELD_OUT], [p[1] for p in HELD_OUT],
                         [p[1] * design.z2 / design.z1 for p in HELD_OUT], gears=draw_gears(design, 6.0, seed))
    for index, (speed, torque) in enumerate(HELD_OUT):
        entry: dict[str, Any] = {"pinion_speed": speed, "drive_torque": torque,
                                 "outside": bool(speed < speeds.min() or speed > speeds.max())}
        with_delta, without = (band(calibration.posterior_, fitted, design, speed, torque, seed)
                               for fitted in (calibration.discrepancy_, None))
        for qoi in QOIS:
            value = float(truth[qoi].values[index])
            entry[qoi] = {"foreign": value, "band": with_delta[qoi], "band_without_discrepancy": without[qoi],
                          "covered": with_delta[qoi][0] <= value <= with_delta[qoi][2],
                          "covered_without_discrepancy": without[qoi][0] <= value <= without[qoi][2]}
        record["points"].append(entry)
    record["seconds"] = round(time.perf_counter() - began, 1)
    return record


def shares(records: list[dict[str, Any]]) -> list[str]:
    """One line per QoI and range: the share of cases whose band covers the foreign value."""
    lines = []
    for outside in (False, True):
        cases = [p for r in records for p in r["points"] if p["outside"] is outside]
        where = "outside the campaign's speeds" if outside else "inside the campaign's speeds"
        for qoi in QOIS:
            covered = sum(p[qoi]["covered"] for p in cases)
            plain = sum(p[qoi]["covered_without_discrepancy"] for p in cases)
            lines.append(f"{qoi:20s} {where}: covered in {covered} of {len(cases)} with the discrepancy, "
                         f"{plain} of {len(cases)} without")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--effective-priors", action="store_true", help="calibration_discrepancy.EFFECTIVE_PRIORS")
    parser.add_argument("--json", default=None, help="also write the records here")
    args = parser.parse_args()
    records = []
    for seed in args.seeds:
        records.append(one_seed(seed, args.effective_priors))
        print(json.dumps(records[-1], default=float), flush=True)
    print("\n".join(shares(records)))
    if args.json:
        with open(args.json, "w") as handle:
            json.dump(records, handle, indent=2, default=float)


if __name__ == "__main__":
    main()
