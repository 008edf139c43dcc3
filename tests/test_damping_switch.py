"""The fast path across the damping switch at |x| = b: fourth-order convergence against a tight scipy reference.

With ``damping_in_separation=False`` the mesh damping force switches off when
the teeth part and on when they meet again, so the vector field jumps at the
contact boundary. The fast path splits a step there; each part is integrated
with the damping of its own side. Checked on the gear at 3600 rpm on wet rail
(teeth apart half of the time) with constant mesh stiffness (no stiffness
jumps or table kinks to blur the order): the error of the Poincare points
against scipy DOP853 at rtol 1e-12 (events at the boundaries) falls at fourth
order, as it does with the classical damping, whose vector field is continuous.
"""

from __future__ import annotations

import numpy as np
import pytest

import uqgear

# a state in drive contact moving out of it: several crossings a period
START = np.array([-7.5e-6, 3.4e-6, 1.2e-4, 0.1, 0.0, 0.3])
STEPS_PER_MODE = (48, 96, 192, 384)


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


def _errors(design, damping_in_separation: bool) -> tuple[np.ndarray, np.ndarray]:
    """(steps per period, largest Poincare error of x in units of b) over the fast path's step counts."""
    kw = {"n_periods": 4, "keep_periods": 4, "samples_per_period": 1, "initial_state": START,
          "damping_in_separation": damping_in_separation, "stiffness": "constant"}
    reference = uqgear.simulate(design, 3600.0, 7000.0, 21150.0, method="scipy", rtol=1e-12, **kw)
    b = reference.attrs["half_backlash"]
    assert 0.3 < float((np.abs(reference["x"].values) <= b).mean()) < 0.7   # the teeth part every period
    steps, errors = [], []
    for steps_per_mode in STEPS_PER_MODE:
        run = uqgear.simulate(design, 3600.0, 7000.0, 21150.0, steps_per_mode=steps_per_mode, **kw)
        steps.append(run.attrs["steps_per_period"])
        errors.append(np.abs(run["poincare_x"].values - reference["poincare_x"].values).max() / b)
    return np.array(steps, dtype=float), np.array(errors)


def _order(steps: np.ndarray, errors: np.ndarray) -> float:
    """Least-squares slope of -log(error) against log(steps)."""
    return float(-np.polyfit(np.log(steps), np.log(errors), 1)[0])


def test_the_damping_switch_converges_at_fourth_order_like_the_continuous_field(design):
    steps, switched = _errors(design, damping_in_separation=False)
    _, continuous = _errors(design, damping_in_separation=True)
    # a split part that took the other side's damping in one stage would leave an error of the order
    # of the step at every crossing: first order, 1e-4 of b at these step counts
    assert _order(steps, switched) > 3.5
    assert switched[-1] < 2e-9
    # and the switch costs no more than the continuous field does
    assert np.all(switched < 3.0 * continuous)
