"""Runs of the batch model from given start states: ``initial_<state>`` sample variables in, ``final_<state>`` out.

What a multi-start search (:mod:`uqgear.dynamics.attractors`) and a sweep that carries each run's
final state on to the next point run: :class:`StartedEvaluator`, with each run's regime and, where
asked, its tooth stresses; :func:`final_variables` names a batch's final state per state variable.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

from ..physics.batch_setup import PAIR_EXTREME_INFO, start_states
from ..physics.design import Design
from ..physics.integration import STATE_NAMES, simulate_batch
from ..physics.rating import RatingSettings
from .regimes import classify_batch, period_labels
from .stress_qois import stress_variables

#: Sample variables of a start state, and of the final state a started run returns.
INITIAL_VARIABLES = tuple(f"initial_{name}" for name in STATE_NAMES)
FINAL_VARIABLES = tuple(f"final_{name}" for name in STATE_NAMES)


class StartedEvaluator:
    """The batch model with start states: ``initial_<state>`` sample variables in, ``final_<state>`` out.

    A sample whose ``initial_*`` values are NaN starts from its static equilibrium. Picklable (the
    runner ships it to workers). The outputs are those of :func:`simulate_batch` (QoIs, Poincare
    points) plus the final state and the regime of each run (:func:`classify_batch`).

    Parameters
    ----------
    design : Design
    options : mapping
        Keyword arguments of :func:`simulate_batch` (``n_periods``, ``keep_periods``, ...).
    classify_seed : int or SeedSequence
        Seed of the 0-1 test frequencies.
    full_regime : bool
        Classify each run in full (:func:`classify_batch`); False labels it by period detection alone
        (:func:`~uqgear.dynamics.regimes.period_labels`: ``period-n`` or ``aperiodic``), all the grouping needs.
    stresses : RatingSettings, optional
        Also compute the tooth stress QoIs of every run from its own start
        (:func:`~uqgear.dynamics.stress_qois.stress_variables` with these ISO 6336 inputs), in the same pass.
    """

    def __init__(
        self,
        design: Design,
        options: Mapping[str, Any] | None = None,
        classify_seed: Any = 0,
        full_regime: bool = True,
        stresses: RatingSettings | None = None,
    ) -> None:
        self.design = design
        self.options = dict(options or {})
        self.classify_seed = classify_seed
        self.full_regime = full_regime
        self.stresses = stresses

    def __call__(self, samples: xr.Dataset) -> xr.Dataset:
        inputs = samples.drop_vars([name for name in INITIAL_VARIABLES if name in samples.variables])
        states = None
        if all(name in samples.variables for name in INITIAL_VARIABLES):
            given = np.stack([np.asarray(samples[name].values, dtype=float) for name in INITIAL_VARIABLES], axis=1)
            states = start_states(
                self.design,
                inputs,
                given,
                effects=self.options.get("effects", ()),
                damping_in_separation=self.options.get("damping_in_separation", True),
                stiffness=self.options.get("stiffness", "ishikawa"),
            )
        # the stresses from the same pass (the batch's pair-load extremes)
        stressed = self.stresses is not None
        batch = simulate_batch(
            self.design, inputs, initial_states=states, final_state=True, **{**self.options, "stresses": stressed}
        )
        result = final_variables(batch)
        if stressed:
            result = result.drop_vars(list(PAIR_EXTREME_INFO)).assign(
                stress_variables(self.design, inputs, batch, self.stresses)
            )
        classes = classify_batch(result, seed=self.classify_seed) if self.full_regime else period_labels(result)
        return result.merge(classes[["regime", "response_period"]], compat="override")


def final_variables(result: xr.Dataset) -> xr.Dataset:
    """``result`` of :func:`simulate_batch` with ``final_state=True``, its final state as one variable per state
    (``final_<state>``, :data:`FINAL_VARIABLES`): what a sweep carries on, sample by sample.

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.physics.integration import samples_from_mapping
    >>> design = uqgear.load_design("locomotive")
    >>> samples = samples_from_mapping({"pinion_speed": [2000.0], "adhesion_torque": [33.8e3]})
    >>> out = final_variables(uqgear.simulate_batch(design, samples, n_periods=60, keep_periods=20, final_state=True))
    >>> all(name in out for name in FINAL_VARIABLES), "final_state" in out
    (True, False)
    """
    final = result["final_state"].values
    return result.drop_vars(["final_state", "state"]).assign(
        {name: ("sample", final[:, index]) for index, name in enumerate(FINAL_VARIABLES)}
    )


__all__ = ["FINAL_VARIABLES", "INITIAL_VARIABLES", "StartedEvaluator", "final_variables"]
