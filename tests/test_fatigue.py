"""Rainflow counting and Miner's rule on the S-N curves of the ISO 6336 life factors.

Rainflow counting against the example history of ASTM E1049-85 (its figure of
rainflow counting: ranges 3, 4, 6, 8, 9 counted 0.5, 1.5, 0.5, 1.0, 0.5 times);
Miner's damage of a constant-amplitude history against the S-N curve's value n / N(sigma).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import uqgear
from uqgear.dynamics import damage_rate, miner_damage, rainflow_count
from uqgear.physics.rating import root_life_factor, static_rating

ASTM_E1049_HISTORY = [-2, 1, -3, 5, -1, 3, -4, 4, -2]
ASTM_E1049_COUNTS = {3.0: 0.5, 4.0: 1.5, 6.0: 0.5, 8.0: 1.0, 9.0: 0.5}


def test_rainflow_counts_the_astm_e1049_example():
    count = rainflow_count(ASTM_E1049_HISTORY)
    assert count.histogram() == ASTM_E1049_COUNTS
    # scaled and shifted histories count the same cycles, scaled and shifted
    shifted = rainflow_count(2.0 * np.asarray(ASTM_E1049_HISTORY) + 10.0)
    assert shifted.histogram() == {2 * key: value for key, value in ASTM_E1049_COUNTS.items()}
    assert shifted.peaks == pytest.approx(2.0 * count.peaks + 10.0)


@pytest.fixture(scope="module")
def rating():
    return static_rating(uqgear.load_design("locomotive"), 7000.0, 1000.0, dynamic_factor=1.0)


@pytest.mark.parametrize("level", [1.2, 1.8, 2.4])
def test_constant_amplitude_damage_equals_the_s_n_curve(rating, level):
    curve = rating.root_curve[0]
    sigma = level * curve.stress[1]  # on the sloped part between the static point and the knee
    cycles = 500
    history = np.append(np.tile([0.0, sigma], cycles), 0.0)
    damage = miner_damage(history, curve, repetitions=40.0)
    assert damage == pytest.approx(40.0 * cycles / curve.cycles_to_failure(sigma), rel=1e-12)
    # the curve is the one ISO's Y_NT defines: sigma_FG(N) / sigma_FG(knee) = Y_NT(N) between the static
    # point and the knee, up to the static Y_deltarelT, Y_RrelT and Y_X interpolated beside it
    life = curve.cycles_to_failure(sigma)
    assert 1e3 < life < 3e6
    factors = curve.stress[0] / curve.stress[1], 2.5
    exponent = math.log10(life / 3e6) / math.log10(1e3 / 3e6)
    assert sigma / curve.stress[1] == pytest.approx(factors[0] ** exponent, rel=1e-9)
    assert root_life_factor(life) == pytest.approx(factors[1] ** exponent, rel=1e-9)


def test_below_the_long_life_limit_there_is_no_damage_and_rate_scales(rating):
    curve = rating.contact_curve[0]
    quiet = np.append(np.tile([0.0, 0.8 * curve.stress[-1]], 100), 0.0)
    assert miner_damage(quiet, curve) == 0.0
    loud = np.append(np.tile([0.0, 1.05 * curve.stress[1]], 100), 0.0)
    assert damage_rate(loud, 0.5, curve) == pytest.approx(2.0 * miner_damage(loud, curve))


def test_bad_histories_are_refused(rating):
    with pytest.raises(ValueError, match="history: expected a 1-D sequence of finite values"):
        rainflow_count([[0.0, 1.0], [1.0, 0.0]])
    with pytest.raises(ValueError, match="duration: expected a time > 0 s"):
        damage_rate([0.0, 1.0], 0.0, rating.root_curve[0])
    assert miner_damage([1.0], rating.root_curve[0]) == 0.0


def test_the_fatigue_module_examples_run():
    import doctest

    from uqgear.dynamics import fatigue

    assert doctest.testmod(fatigue).failed == 0
