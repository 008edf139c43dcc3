"""How visible a blind-test campaign's effects are, judged independently of the diagnosis: the oracle.

The campaign's features are simulated with the true parameters with and
without the effect; when the difference is within noise and model error
(the gap below the diagnosis' noise threshold), ``none`` is the right
answer for that campaign (``accuracy_detectable`` counts it so).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..diagnosis.case import RigCase
from ..diagnosis.discrepancy import expected_rig_features, standardised_discrepancy
from ..diagnosis.execution import RunTask, execute_run, execute_runs
from ..diagnosis.scoring import capped_squares
from ..physics.design import Design
from ..physics.effects import Effect
from .campaigns import HEALTHY, CampaignSpec


def oracle_gap(case: RigCase, spec: CampaignSpec, truth: Mapping[str, Any]) -> float:
    """How visible the campaign's effect is: the gap between the true model with and without it.

    Both are simulated with the true parameters and T2; what a rig would
    record on average with the effect (:func:`uqgear.diagnosis.discrepancy.expected_rig_features`)
    is compared with the model without it, noise and model error as in the
    diagnosis: sqrt(mean(min(z^2, 10^2))) of those standardised shifts, the
    held-out gap a perfect nominal fit would leave beyond noise. 0 for a
    healthy control.
    """
    if spec.truth == HEALTHY:
        return 0.0
    design, scale, adhesion = _true_model(case, truth)
    effect = spec.effects()
    periodicity = "free"
    with_effect, without = [], []
    for op in range(case.n_op):
        with_effect.append(
            execute_run(case, RunTask(op, design, scale, float(adhesion[op]), tuple(effect), periodicity))[0]
        )
        without.append(execute_run(case, RunTask(op, design, scale, float(adhesion[op]), (), "mesh"))[0])
    columns = case.layout.columns
    # the noise the rig's records carry, as the diagnosis estimates it
    recorded = expected_rig_features(
        np.stack(with_effect)[..., columns], case.noise_std, case.noise, case.layout, band_noise_std=case.band_noise_std
    )
    return _capped_gap(case, recorded, np.stack(without)[..., columns])


def _true_model(case: RigCase, truth: Mapping[str, Any]) -> tuple[Design, float, np.ndarray]:
    """The true design, mesh-stiffness scale and per-run T2 of a campaign's truth."""
    design = case.design.replace(
        **{key: float(truth[key]) for key in ("zeta_mesh", "ste_amplitude", "k1", "k2", "backlash")}
    )
    return design, float(truth["mesh_stiffness_scale"]), np.asarray(truth["adhesion_torque"], dtype=float)


def _capped_gap(case: RigCase, recorded: np.ndarray, plain: np.ndarray) -> float:
    """sqrt(mean(min(z^2, 10^2))) of the standardised shifts between what a rig records and a model."""
    shift, _ = standardised_discrepancy(
        recorded, plain, case.noise_std, case.noise, case.layout, case.model_error, band_noise_std=case.band_noise_std
    )
    squares = capped_squares(shift[case.mask()])
    squares = squares[np.isfinite(squares)]
    return float(math.sqrt(np.mean(squares))) if squares.size else 0.0


def effect_visibility(case: RigCase, spec: CampaignSpec, truth: Mapping[str, Any]) -> dict[str, float]:
    """How visible each of a campaign's effects is next to the others, by the diagnosis's own model error.

    Per effect: the gap (as :func:`oracle_gap`) between the true model with
    all the campaign's effects and with all but that one, both over the
    whole record, standardised with the model error of the case the
    diagnosis reached its verdict on (:attr:`~uqgear.diagnosis.Diagnosis.case_`):
    it holds the pitch-error allowance (and a reference's widening), so an
    effect that the stated manufacturing classes could make as well reads
    as what it is to the data. Empty for a healthy control.
    """
    effects = list(spec.effects())
    if not effects:
        return {}
    design, scale, adhesion = _true_model(case, truth)
    names = list(spec.truth_set())

    def features(chosen: Sequence[Effect]) -> np.ndarray:
        # read as the diagnosis read its fits on this case
        tasks = [
            RunTask(op, design, scale, float(adhesion[op]), tuple(chosen), "free", tracked=case.reads_tracked)
            for op in range(case.n_op)
        ]
        return np.stack([values for values, _ in execute_runs(case, tasks)])[..., case.layout.columns]

    recorded = expected_rig_features(
        features(effects), case.noise_std, case.noise, case.layout, band_noise_std=case.band_noise_std
    )
    return {
        name: _capped_gap(case, recorded, features(effects[:index] + effects[index + 1 :]))
        for index, name in enumerate(names)
    }


__all__ = ["oracle_gap", "effect_visibility"]
