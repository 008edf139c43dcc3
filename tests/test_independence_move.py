"""The independence move of the calibration's final run: its proposal ratio, and that it samples right."""

from __future__ import annotations

import emcee
import numpy as np
import pytest
import scipy.stats

from uqgear.calibration.sampling import IndependenceMove, SnookerMove


def test_the_ratio_is_that_of_scipys_multivariate_t():
    rng = np.random.default_rng(2)
    draws = rng.multivariate_normal([0.2, -0.4, 1.0], [[1.0, 0.3, 0.0], [0.3, 0.5, 0.1], [0.0, 0.1, 0.2]], 500)
    move = IndependenceMove(draws, dof=5.0)
    coords = rng.normal(size=(7, 3))
    proposal, factor = move.get_proposal(coords, np.random.RandomState(3))
    reference = scipy.stats.multivariate_t(loc=draws.mean(axis=0), shape=np.cov(draws, rowvar=False), df=5.0)
    # ln q(x) - ln q(x'): an independence proposal's Hastings factor
    np.testing.assert_allclose(factor, reference.logpdf(coords) - reference.logpdf(proposal), rtol=1e-9, atol=1e-9)


def test_too_few_draws_are_refused():
    with pytest.raises(ValueError, match="M > n_dim"):
        IndependenceMove(np.zeros((3, 3)))


# a skewed target: x0 ~ Gamma(3, scale 0.5), x1 | x0 ~ N(x0, 0.3^2), x2 ~ N(-1, 2^2)
_TRUE_MEAN = np.array([1.5, 1.5, -1.0])
_TRUE_STD = np.array([np.sqrt(3) * 0.5, np.sqrt(0.75 + 0.09), 2.0])


def _log_target(points: np.ndarray) -> np.ndarray:
    x0, x1, x2 = points.T
    with np.errstate(divide="ignore", invalid="ignore"):
        value = 2.0 * np.log(x0) - x0 / 0.5 - 0.5 * ((x1 - x0) / 0.3) ** 2 - 0.5 * ((x2 + 1.0) / 2.0) ** 2
    return np.where(x0 > 0, value, -np.inf)


# alone on a fit lighter-tailed than the target the chain is right but slow in the tails (8000 steps:
# spreads 3.5 % short; 40000 steps: within 3 %); the calibration always mixes it with the ensemble moves
@pytest.mark.parametrize(("weight", "fitted_on"), [(1.0, "too wide"), (0.5, "too wide"),
                                                   (0.5, "shifted and too narrow")],
                         ids=["alone, too wide", "calibration mix, too wide", "calibration mix, shifted, too narrow"])
def test_it_samples_a_skewed_target_from_a_wrong_fit(weight, fitted_on):
    rng = np.random.default_rng(5)
    # the proposal is fitted on draws that are not the target's: the chain must still be right
    if fitted_on == "too wide":
        draws = rng.normal([1.0, 1.0, 0.0], [2.0, 2.0, 4.0], size=(400, 3))
    else:
        draws = rng.normal([2.0, 1.2, -0.5], [0.5, 0.5, 1.0], size=(400, 3))
    moves = [(IndependenceMove(draws), weight)]
    if weight < 1.0:
        moves += [(emcee.moves.DEMove(), 0.8 * (1 - weight)), (SnookerMove(), 0.2 * (1 - weight))]
    sampler = emcee.EnsembleSampler(32, 3, _log_target, vectorize=True, moves=moves)
    sampler.random_state = np.random.RandomState(np.random.MT19937(np.random.SeedSequence(7))).get_state()
    start = np.abs(rng.normal([1.5, 1.5, -1.0], 0.3, size=(32, 3)))
    sampler.run_mcmc(start, 8000)
    flat = sampler.get_chain(discard=1000, flat=True)
    np.testing.assert_allclose(flat.mean(axis=0), _TRUE_MEAN, atol=0.05 * _TRUE_STD.max())
    np.testing.assert_allclose(flat.std(axis=0) / _TRUE_STD, 1.0, atol=0.03)


def test_restricted_to_the_box_it_proposes_inside_with_the_same_ratio():
    rng = np.random.default_rng(4)
    draws = rng.uniform(0.0, 1.0, (400, 6))  # a posterior that fills its box: most t draws leave it
    free, boxed = IndependenceMove(draws), IndependenceMove(draws, in_box=True)
    coords = rng.uniform(0.0, 1.0, (2000, 6))
    proposal, factor = boxed.get_proposal(coords, np.random.RandomState(3))
    assert np.all((proposal >= 0.0) & (proposal <= 1.0))
    reference = scipy.stats.multivariate_t(loc=draws.mean(axis=0), shape=np.cov(draws, rowvar=False), df=5.0)
    np.testing.assert_allclose(factor, reference.logpdf(coords) - reference.logpdf(proposal), rtol=1e-9, atol=1e-9)
    unrestricted, _ = free.get_proposal(coords, np.random.RandomState(3))
    assert np.mean(np.any((unrestricted < 0.0) | (unrestricted > 1.0), axis=1)) > 0.4


def _log_boxed_target(points: np.ndarray) -> np.ndarray:
    """x0 ~ N(0.3, 0.1^2) and four coordinates uniform, all on the unit box."""
    inside = np.all((points >= 0.0) & (points <= 1.0), axis=1)
    return np.where(inside, -0.5 * ((points[:, 0] - 0.3) / 0.1) ** 2, -np.inf)


def test_restricted_to_the_box_it_samples_a_target_with_uninformed_coordinates_and_is_accepted_more():
    """The calibration's mix on a target whose nuisance coordinates fill the box: the marginals are right
    (a truncated normal and uniforms), and the restricted proposals are accepted more often."""
    rng = np.random.default_rng(6)
    draws = np.column_stack([rng.normal(0.3, 0.1, 400), rng.uniform(0.0, 1.0, (400, 4))])
    acceptance = {}
    for in_box in (False, True):
        moves = [(emcee.moves.DEMove(), 0.4), (SnookerMove(), 0.1), (IndependenceMove(draws, in_box=in_box), 0.5)]
        sampler = emcee.EnsembleSampler(32, 5, _log_boxed_target, vectorize=True, moves=moves)
        sampler.random_state = np.random.RandomState(np.random.MT19937(np.random.SeedSequence(8))).get_state()
        sampler.run_mcmc(np.clip(draws[:32], 0.01, 0.99), 4000)
        flat = sampler.get_chain(discard=1000, flat=True)
        acceptance[in_box] = float(np.mean(sampler.acceptance_fraction))
        truncated = scipy.stats.truncnorm(-3.0, 7.0, loc=0.3, scale=0.1)
        np.testing.assert_allclose(flat.mean(axis=0), [truncated.mean(), 0.5, 0.5, 0.5, 0.5], atol=0.02)
        np.testing.assert_allclose(flat.std(axis=0), [truncated.std(), *[np.sqrt(1 / 12)] * 4], rtol=0.04)
    assert acceptance[True] > 1.2 * acceptance[False]
