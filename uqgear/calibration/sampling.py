"""emcee sampling on the emulated likelihood: walker starts, the staged box search and the final run.

The box starts as the prior and is shrunk in stages around the current
posterior (with a margin) until it stops shrinking or the emulator error is
below a fifth of the model-error floor; a posterior that presses against a
box side that is not a prior bound widens the box again. emcee's ensemble
sampler (differential-evolution moves and the snooker move of its paper,
:class:`SnookerMove`) runs on the emulators, vectorised over walkers. The
final run adds independence proposals from a Student t fitted to the last
stage's posterior draws (:class:`IndependenceMove`), and runs in chunks
until the convergence criteria hold or ``max_steps`` is reached;
the first tenth of the chain is burn-in (the walkers start from the last
search stage's posterior draws, and a converged chain is at least 50
autocorrelation times long, so that is at least 5 of them), the rest is
thinned by half the autocorrelation time.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import emcee
import numpy as np
from scipy.stats import qmc

from .convergence import ConvergenceCriteria
from .likelihood import StageLikelihood

#: The first 1/BURN_IN_DIVISOR of the final chain is burn-in (module docstring).
BURN_IN_DIVISOR = 10
#: Most redraws of an independence proposal restricted to the box (:class:`IndependenceMove`).
BOX_REDRAWS = 50


def walker_count(n_walkers: int | None, n_dim: int) -> int:
    """Number of emcee walkers (even): ``n_walkers``, by default 4 x the dimensions, at least 32."""
    count = n_walkers if n_walkers is not None else max(4 * n_dim, 32)
    return count + count % 2


def start_walkers(
    likelihood: StageLikelihood, start_points: np.ndarray | None, rng: np.random.Generator, count: int
) -> np.ndarray:
    """Unit-box start positions (count, n_dim) of the walkers, from earlier draws or a Sobol design."""
    if start_points is None:
        # the best of a Sobol design over the box: spread over every region the data favour
        candidates = qmc.Sobol(likelihood.n_dim, scramble=True, seed=rng).random_base2(12)
        values = np.concatenate([likelihood.log_likelihood(chunk) for chunk in np.array_split(candidates, 16)])
        walkers = candidates[np.argsort(values)[::-1][:count]]
    else:
        unit = likelihood.to_unit(start_points)
        unit = unit[np.all((unit >= 0) & (unit <= 1), axis=1)]
        if unit.shape[0] < count:
            unit = np.concatenate([unit, rng.uniform(0.25, 0.75, (count - unit.shape[0], likelihood.n_dim))])
        walkers = unit[rng.choice(unit.shape[0], size=count, replace=False)]
    walkers = np.clip(walkers, 1e-6, 1.0 - 1e-6)
    values = likelihood.log_likelihood(walkers)
    bad = ~np.isfinite(values)
    if bad.any():
        walkers[bad] = walkers[np.flatnonzero(~bad)[0]] if (~bad).any() else 0.5
    return walkers


class SnookerMove(emcee.moves.RedBlueMove):
    """The snooker move of Ter Braak & Vrugt (2008), as emcee's, corrected and vectorised over walkers.

    Each walker x takes three points z, z1, z2 from the three complementary
    groups; the proposal moves x along the line through z by the projection
    of gamma (z1 - z2) on that line, and is accepted with the extra factor
    (|x' - z| / |x - z|)^(d - 1). emcee's :class:`~emcee.moves.DESnookerMove`
    up to 3.1.6 (the version installed here) divides by the square root of
    the distance instead of the distance and takes half that exponent
    (fixed upstream by emcee pull request 531, after 3.1.6): alone it samples a 3-D
    Gaussian with standard deviations 15 % too small, and our mix of 20 %
    snooker 3 % too small (measured; tests/test_snooker_move.py). It also
    loops over walkers in Python, a fifth of a calibration's time
    (healthy.nc: 12.8 s of 74 s profiled).
    """

    def __init__(self, gammas: float = 1.7) -> None:
        self.gammas = gammas
        super().__init__(nsplits=4)

    def get_proposal(
        self, s: np.ndarray, c: Sequence[np.ndarray], random: np.random.RandomState
    ) -> tuple[np.ndarray, np.ndarray]:
        count, n_dim = s.shape
        picks = np.stack([group[random.randint(len(group), size=count)] for group in c[:3]], axis=1)
        order = np.argsort(random.random_sample((count, 3)), axis=1)  # emcee shuffles the three
        picks = np.take_along_axis(picks, order[:, :, None], axis=1)
        z, z1, z2 = picks[:, 0], picks[:, 1], picks[:, 2]
        delta = s - z
        norm = np.linalg.norm(delta, axis=1)
        # a walker on top of z (walkers collapsed onto one point) has no line to move along: it stays
        # (a proposal equal to the state, accepted with ratio 1) instead of dividing by zero
        moving = norm > 0.0
        safe = np.where(moving, norm, 1.0)
        u = np.where(moving[:, None], delta / safe[:, None], 0.0)
        step = self.gammas * (np.einsum("ij,ij->i", u, z1) - np.einsum("ij,ij->i", u, z2))
        proposal = s + u * step[:, None]
        distance = np.where(moving, np.linalg.norm(proposal - z, axis=1), 1.0)
        metropolis = np.where(moving, np.log(distance) - np.log(safe), 0.0)
        return proposal, (n_dim - 1.0) * metropolis


class IndependenceMove(emcee.moves.MHMove):
    """Metropolis-Hastings independence proposals from a multivariate Student t.

    The t is centred on the mean of earlier posterior draws with their
    covariance as its scale matrix; its heavier tails (``dof`` degrees of
    freedom) cover the target's. Each proposal ignores the walker's position,
    so the acceptance ratio carries the proposal densities, q(x) / q(x').
    Where the posterior is close to the t, a walker decorrelates in a few
    steps instead of the tens a differential-evolution move takes in 14
    dimensions; where it is not, proposals are rejected and the ensemble's
    own moves carry the chain.

    Parameters
    ----------
    draws : array (M, n_dim)
        Earlier posterior draws, M > n_dim.
    dof : float
        Degrees of freedom of the t.
    in_box : bool
        Draw from the t restricted to the unit box, where the target lives:
        a draw outside is drawn again (:data:`BOX_REDRAWS` times at most, then
        the walker stays). The restricted density is the t's over a constant,
        so the ratio q(x) / q(x') is unchanged. Where the posterior fills its
        box in some coordinates (a nuisance the data do not inform, uniform on
        its prior interval), most unrestricted proposals leave the box in one
        of them and are rejected: about 72 % with eight such coordinates.
    """

    def __init__(self, draws: np.ndarray, dof: float = 5.0, in_box: bool = False) -> None:
        if draws.ndim != 2 or draws.shape[0] <= draws.shape[1]:
            raise ValueError(f"IndependenceMove: expected draws of shape (M > n_dim, n_dim); got {draws.shape}")
        self.mean = np.mean(draws, axis=0)
        covariance = np.cov(draws, rowvar=False) + 1e-12 * np.eye(draws.shape[1])
        self.cholesky = np.linalg.cholesky(covariance)
        self.dof, self.in_box = dof, in_box
        super().__init__(self._proposal)

    def _log_density(self, points: np.ndarray) -> np.ndarray:
        whitened = np.linalg.solve(self.cholesky, (points - self.mean).T)
        return -0.5 * (self.dof + points.shape[1]) * np.log1p(np.sum(whitened**2, axis=0) / self.dof)

    def _draw(self, count: int, random: np.random.RandomState) -> np.ndarray:
        normal = random.standard_normal((count, self.mean.size)) @ self.cholesky.T
        scale = np.sqrt(random.chisquare(self.dof, count) / self.dof)
        return self.mean + normal / scale[:, None]

    def _proposal(self, coords: np.ndarray, random: np.random.RandomState) -> tuple[np.ndarray, np.ndarray]:
        proposal = self._draw(coords.shape[0], random)
        if self.in_box:
            outside = np.flatnonzero(np.any((proposal < 0.0) | (proposal > 1.0), axis=1))
            for _ in range(BOX_REDRAWS):
                if outside.size == 0:
                    break
                proposal[outside] = self._draw(outside.size, random)
                outside = outside[np.any((proposal[outside] < 0.0) | (proposal[outside] > 1.0), axis=1)]
            # a t that rarely reaches the box: the walker stays (a proposal of its own position, ratio 1)
            proposal[outside] = coords[outside]
        return proposal, self._log_density(coords) - self._log_density(proposal)


def make_sampler(
    likelihood: StageLikelihood,
    count: int,
    seed: np.random.SeedSequence,
    proposal_draws: np.ndarray | None = None,
    in_box: bool = False,
) -> emcee.EnsembleSampler:
    """An emcee ensemble sampler of the stage likelihood, vectorised over walkers, seeded from ``seed``.

    With ``proposal_draws`` (unit-box posterior draws, more than ``4 n_dim``)
    half of the steps are :class:`IndependenceMove` proposals fitted to them,
    restricted to the box with ``in_box``.
    """
    moves: list[tuple[emcee.moves.Move, float]] = [(emcee.moves.DEMove(), 0.8), (SnookerMove(), 0.2)]
    if proposal_draws is not None and proposal_draws.shape[0] > 4 * likelihood.n_dim:
        # measured on healthy_b.nc: autocorrelation time 58 -> 10 steps, 12000 -> 2000 steps to converge
        independence = IndependenceMove(proposal_draws, in_box=in_box)
        moves = [(emcee.moves.DEMove(), 0.4), (SnookerMove(), 0.1), (independence, 0.5)]
    sampler = emcee.EnsembleSampler(count, likelihood.n_dim, likelihood.log_likelihood, vectorize=True, moves=moves)
    # emcee draws from its own RandomState: seed it from our SeedSequence
    sampler.random_state = np.random.RandomState(np.random.MT19937(seed)).get_state()
    return sampler


def sample(
    likelihood: StageLikelihood, walkers: np.ndarray, steps: int, seed: np.random.SeedSequence
) -> tuple[np.ndarray, np.ndarray]:
    """Chain (step, walker, dim) and acceptance fractions of ``steps`` steps from ``walkers``."""
    sampler = make_sampler(likelihood, walkers.shape[0], seed)
    sampler.run_mcmc(walkers, steps)
    return sampler.get_chain(), sampler.acceptance_fraction


def next_box(
    physical: np.ndarray, box_lower: np.ndarray, box_upper: np.ndarray, prior_lower: np.ndarray, prior_upper: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """The next stage's box around posterior draws, and whether the draws press against a non-prior side."""
    low, high = physical.min(axis=0), physical.max(axis=0)
    width = box_upper - box_lower
    spread = np.maximum(high - low, 0.02 * width)
    at_prior_low = np.isclose(box_lower, prior_lower, rtol=1e-12, atol=0)
    at_prior_high = np.isclose(box_upper, prior_upper, rtol=1e-12, atol=0)
    presses_low = (low - box_lower < 0.02 * width) & ~at_prior_low
    presses_high = (box_upper - high < 0.02 * width) & ~at_prior_high
    truncated = bool(np.any(presses_low | presses_high))
    margin = np.where(presses_low | presses_high, 1.0, 0.5) * spread
    new_lower = np.maximum(low - margin, prior_lower)
    new_upper = np.minimum(high + margin, prior_upper)
    return new_lower, new_upper, truncated


def search_box(
    fit_stage: Callable[[np.ndarray, np.ndarray, np.random.SeedSequence], StageLikelihood],
    prior_lower: np.ndarray,
    prior_upper: np.ndarray,
    *,
    used: np.ndarray,
    walkers: int,
    stage_steps: int,
    max_stages: int,
    error_floor: float,
    rng: np.random.Generator,
    design_seed: np.random.SeedSequence,
    chain_seed: np.random.SeedSequence,
    stages: list[dict[str, Any]],
    start_likelihood: StageLikelihood | None = None,
    start_points: np.ndarray | None = None,
) -> tuple[np.ndarray, bool]:
    """Shrink the emulator box in stages around the posterior (module docstring).

    Parameters
    ----------
    fit_stage : callable
        (box_lower, box_upper, seed) -> the likelihood on emulators trained in that box.
    prior_lower, prior_upper : array (n_dim,)
        The prior box, the first stage's box.
    used : array (op, channel, harmonic) of bool
        The features in the likelihood.
    walkers : int
        Number of walkers.
    stage_steps, max_stages : int
        Steps per stage and most stages.
    error_floor : float
        Lower bound of the model error: an emulator error below a fifth of it ends the search.
    rng : numpy.random.Generator
        Draws of walker starts.
    design_seed, chain_seed : SeedSequence
        Parents of each stage's Sobol design and chain seeds.
    stages : list
        A record of each stage is appended to it.
    start_likelihood : StageLikelihood, optional
        The first stage's likelihood instead of one fitted in the prior box
        (a search resumed on changed features: its box and emulators are kept).
    start_points : array (M, n_dim), optional
        Physical points the first stage's walkers start from.

    Returns
    -------
    start_points : array (M, n_dim)
        Physical posterior draws of the last stage to start from.
    truncated : bool
        Whether the last stage's posterior is truncated by its box.
    """
    box_lower, box_upper = (
        (prior_lower.copy(), prior_upper.copy())
        if start_likelihood is None
        else (start_likelihood.box_lower.copy(), start_likelihood.box_upper.copy())
    )
    design_seeds, chain_seeds = design_seed.spawn(max_stages), chain_seed.spawn(max_stages)
    for stage in range(max_stages):
        likelihood = (
            start_likelihood
            if stage == 0 and start_likelihood is not None
            else fit_stage(box_lower, box_upper, design_seeds[stage])
        )
        start = start_walkers(likelihood, start_points, rng, walkers)
        chain, accept = sample(likelihood, start, stage_steps, chain_seeds[stage])
        kept = chain[chain.shape[0] // 2 :].reshape(-1, likelihood.n_dim)
        physical = likelihood.to_physical(kept)
        new_lower, new_upper, truncated = next_box(physical, box_lower, box_upper, prior_lower, prior_upper)
        old_width = box_upper - box_lower
        new_width = new_upper - new_lower
        stages.append(
            {
                "stage": stage,
                "box_lower": box_lower.tolist(),
                "box_upper": box_upper.tolist(),
                "loo_rms_median": float(np.median(likelihood.loo_rms[used])),
                "loo_rms_max": float(np.max(likelihood.loo_rms[used])),
                "acceptance": float(np.mean(accept)),
                "truncated": truncated,
            }
        )
        start_points = physical[rng.choice(physical.shape[0], size=min(physical.shape[0], 4096), replace=False)]
        shrinking = np.any(new_width < 0.6 * old_width)
        # refining further gains nothing once the emulator error is small against the model-error floor
        accurate = float(np.max(likelihood.loo_rms[used])) <= 0.2 * error_floor
        if not truncated and (accurate or not shrinking):
            return start_points, False
        if stage == max_stages - 1:
            return start_points, truncated
        box_lower, box_upper = new_lower, new_upper
    raise AssertionError("unreachable: the last stage returns")


def final_sampling(
    likelihood: StageLikelihood,
    start_points: np.ndarray,
    rng: np.random.Generator,
    seed: np.random.SeedSequence,
    *,
    walkers: int,
    chunk_steps: int,
    max_steps: int,
    criteria: ConvergenceCriteria,
    names: Sequence[str],
    truncated: bool,
    in_box: bool = False,
) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    """Sample in chunks until converged or ``max_steps``; burn in and thin (``in_box``: :func:`make_sampler`'s).

    Returns
    -------
    verdict : dict
        :meth:`ConvergenceCriteria.verdict` with ``n_steps``, ``burn_in``, ``thin`` and ``n_walkers``.
    physical : array (draw, walker, n_dim)
        Kept draws, in physical units.
    log_likelihood : array (draw, walker)
    """
    start = start_walkers(likelihood, start_points, rng, walkers)
    unit_draws = likelihood.to_unit(start_points)
    sampler = make_sampler(likelihood, start.shape[0], seed, proposal_draws=unit_draws, in_box=in_box)
    state = start
    total = 0
    verdict: dict[str, Any] = {}
    while total < max_steps:
        state = sampler.run_mcmc(state, chunk_steps)
        total += chunk_steps
        chain = sampler.get_chain()
        burn = total // BURN_IN_DIVISOR
        verdict = criteria.verdict(chain[burn:], sampler.acceptance_fraction, truncated, names)
        if verdict["converged"]:
            break
    # the last chunk's chain and burn-in (max_steps >= chunk_steps: the loop ran)
    thin = max(1, int(verdict["tau_max"] // 2))
    kept = chain[burn::thin]  # (draw, chain, dim)
    log_likelihood = sampler.get_log_prob()[burn::thin]
    verdict.update(n_steps=int(total), burn_in=int(burn), thin=int(thin), n_walkers=int(chain.shape[1]))
    return verdict, likelihood.to_physical(kept), log_likelihood
