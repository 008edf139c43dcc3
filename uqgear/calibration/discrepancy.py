"""A model-discrepancy term in the likelihood (Kennedy-O'Hagan style, in the order domain).

Where the physics of a campaign is not the model's (another gearbox, shaft
modes, profile errors), the misfit of a mesh-harmonic feature is not
independent from run to run: it varies smoothly with the operating point.
The iid relative model error of :mod:`~uqgear.calibration.likelihood` can
only absorb such a misfit by growing until it reaches its cap, and the fit is
refused. With the discrepancy term each (channel, harmonic) group g gains a
smooth function of the operating point,

    delta_g(speed, torque) = sum_k beta_{g,k} phi_k(s, t),
    phi = (1, s, t, s^2),

with s and t the run's pinion speed and drive torque scaled to [-1, 1] over
the campaign, and beta_{g,k} ~ N(0, tau_g^2) independent. beta is
integrated out analytically, so the residual vector r_g of the group over
the runs is Gaussian,

    r_g ~ N(0, D_g + tau_g^2 Phi Phi^T),

D_g the diagonal variances of the ordinary likelihood (sensor noise,
emulator leave-one-out error and the iid model error sigma_g^2). tau_g's
prior is a mixture: tau_g = 0 (no discrepancy in the group: the ordinary
likelihood) with probability :data:`NO_DISCREPANCY_PROBABILITY` (one half,
indifference between the two models), otherwise log-uniform on
``discrepancy_range`` (0.5 % to 300 % in log-amplitude units by default). It is
integrated out on a grid jointly with sigma_g.

Why the point at zero: a discrepancy a campaign cannot resolve (8 runs, 4
coefficients, features with an iid model error of at least 1 %) keeps a
log-uniform tau near the bottom of its range, about 0.5 %, and the
prediction then carries a discrepancy of that size however well the model
fits. With the point at zero the data weigh the two models: where the
residuals show no smooth misfit, the marginal likelihood of the slab is
spread over scales the data rule out and tau = 0 takes most of the weight
(Bayesian model averaging); where they do, the slab takes it all.

Why a grid and not emcee: each group has its own tau_g (nine with three
channels and three harmonics, more with more harmonics), and sampling them
would add as many walker dimensions to a posterior that already has 6 + n_op;
the grid sum is exact up to the grid's resolution (as for the iid model
error), and its cost does not depend on the number of groups' dimensions. The
inverse covariance is kept in Woodbury form (D^-1 and the p x p matrix
C = (tau^-2 I + Phi^T D^-1 Phi)^-1) with its log-determinant, for every
(sigma, tau) grid pair and group, once per stage: none of it depends on the
model parameters. C and C Phi^T D^-1 r are also the covariance and mean of
beta given the residuals, which is how the fitted discrepancy is reported
(:mod:`~uqgear.calibration.discrepancy_results`).

A feature left out of the likelihood has a zero row in Phi, unit variance
and zero residual, so it adds nothing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .emulator import PolynomialEmulator
from .likelihood import Features, StageLikelihood

#: Names of the basis functions of the discrepancy (s: scaled pinion speed, t: scaled drive torque).
BASIS_NAMES = ("1", "s", "t", "s^2")
#: Default bounds of the log-uniform prior of tau (standard deviation of each beta, log-amplitude units).
DEFAULT_DISCREPANCY_RANGE = (0.005, 3.0)
#: Points of the tau grid (log-spaced).
TAU_POINTS = 20
#: Prior probability that a group has no discrepancy (tau = 0); the log-uniform range shares the rest.
NO_DISCREPANCY_PROBABILITY = 0.5


@dataclass(frozen=True)
class DiscrepancyBasis:
    """The basis phi(s, t) of the discrepancy, with the scaling of speed and torque to [-1, 1].

    Parameters
    ----------
    speed_range : (float, float)
        Pinion speeds (rpm) that map to s = -1 and s = 1.
    torque_range : (float, float)
        Drive torques (N m) that map to t = -1 and t = 1.

    Examples
    --------
    >>> basis = DiscrepancyBasis((1000.0, 3000.0), (5000.0, 7000.0))
    >>> basis.matrix([1000.0, 2000.0, 3000.0], [5000.0, 6000.0, 7000.0]).tolist()
    [[1.0, -1.0, -1.0, 1.0], [1.0, 0.0, 0.0, 0.0], [1.0, 1.0, 1.0, 1.0]]
    """

    speed_range: tuple[float, float]
    torque_range: tuple[float, float]

    @classmethod
    def of_campaign(cls, pinion_speed: np.ndarray, drive_torque: np.ndarray) -> DiscrepancyBasis:
        """The basis scaled over a campaign's operating points."""
        speed, torque = np.asarray(pinion_speed, float), np.asarray(drive_torque, float)
        return cls((float(speed.min()), float(speed.max())), (float(torque.min()), float(torque.max())))

    @staticmethod
    def _scaled(values: np.ndarray, bounds: tuple[float, float]) -> np.ndarray:
        low, high = bounds
        # a campaign at one speed (or torque) carries no information on the slope: the column is zero
        if high - low <= 1e-12 * max(abs(high), 1.0):
            return np.zeros_like(values)
        return 2.0 * (values - low) / (high - low) - 1.0

    def matrix(
        self, pinion_speed: Sequence[float] | np.ndarray, drive_torque: Sequence[float] | np.ndarray
    ) -> np.ndarray:
        """Phi (n, 4) at operating points; outside the campaign's range the polynomial extrapolates."""
        speed = np.atleast_1d(np.asarray(pinion_speed, float))
        torque = np.atleast_1d(np.asarray(drive_torque, float))
        s, t = self._scaled(speed, self.speed_range), self._scaled(torque, self.torque_range)
        return np.stack([np.ones_like(s), s, t, s**2], axis=1)


def tau_prior(tau: np.ndarray, no_discrepancy: float) -> tuple[np.ndarray, np.ndarray]:
    """The grid of tau with the point tau = 0 in front (where ``no_discrepancy`` > 0), and its log prior weights.

    Examples
    --------
    >>> grid, log_weights = tau_prior(np.array([0.01, 0.1]), 0.5)
    >>> grid.tolist(), np.exp(log_weights).round(3).tolist()
    ([0.0, 0.01, 0.1], [0.5, 0.25, 0.25])
    """
    tau = np.asarray(tau, dtype=float)
    if no_discrepancy <= 0.0:
        return tau, np.full(tau.size, -np.log(tau.size))
    grid = np.concatenate([[0.0], tau])
    weights = np.concatenate([[no_discrepancy], np.full(tau.size, (1.0 - no_discrepancy) / tau.size)])
    return grid, np.log(weights)


def _log_mean_exp(values: np.ndarray, axes: tuple[int, ...]) -> np.ndarray:
    """log mean exp over ``axes`` (a grid average with equal weights), stable for large terms."""
    # written out: scipy.special.logsumexp takes twice as long here, in the sampler's innermost loop
    peak = values.max(axis=axes, keepdims=True)
    mean = np.exp(values - peak).mean(axis=axes)
    return np.squeeze(peak, axis=axes) + np.log(mean)


def tau_grid(discrepancy_range: tuple[float, float]) -> np.ndarray:
    """The log-spaced grid of tau (equal weights: a log-uniform prior).

    Examples
    --------
    >>> grid = tau_grid((0.005, 3.0))
    >>> grid.size, float(grid[0]), float(grid[-1])
    (20, 0.005, 3.0)
    """
    return np.geomspace(discrepancy_range[0], discrepancy_range[1], TAU_POINTS)


class DiscrepancyLikelihood(StageLikelihood):
    """:class:`StageLikelihood` with a discrepancy function per (channel, harmonic) group integrated out.

    Parameters
    ----------
    box_lower, box_upper, emulators, loo, features, n_global
        As :class:`StageLikelihood`.
    phi : array (op, 4)
        The basis at the campaign's runs (:meth:`DiscrepancyBasis.matrix`).
    tau : array (L,)
        The tau grid of the log-uniform part of the prior (:func:`tau_grid`).
    no_discrepancy : float
        Prior probability of tau = 0 (:data:`NO_DISCREPANCY_PROBABILITY`); 0 leaves the log-uniform grid alone.

    Notes
    -----
    :meth:`group_terms` returns the terms with tau integrated out, so that
    everything written for the ordinary likelihood (the model-error summary,
    the sum over sigma) works unchanged; :meth:`joint_terms` keeps the tau
    axis (``tau``: the grid with the point at zero, ``slab_tau`` the
    log-uniform part alone). At tau = 0 the terms equal the ordinary
    likelihood's.

    Examples
    --------
    One run, one feature (te mesh1) and an emulator that predicts 0: the
    likelihood is that of a Gaussian of variance noise + sigma^2 + tau^2
    (phi = 1 at one run), averaged over the grids:

    >>> import numpy as np
    >>> from uqgear.calibration.emulator import PolynomialEmulator
    >>> from uqgear.calibration.likelihood import Features
    >>> used = np.zeros((1, 3, 1), bool); used[0, 0, 0] = True
    >>> features = Features(None, used, np.where(used, 0.1, 0.0), np.full(used.shape, 1e-4), np.array([0.01]))
    >>> z = np.random.default_rng(0).uniform(-1, 1, (8, 2))  # one global parameter, then the run's T2
    >>> emulator = PolynomialEmulator(2, 1).fit(z, np.zeros((8, 3)))
    >>> likelihood = DiscrepancyLikelihood(np.zeros(2), np.ones(2), [emulator], np.zeros((1, 3)), features, 1,
    ...                                    phi=np.array([[1.0, 0.0, 0.0, 0.0]]), tau=np.array([0.1]),
    ...                                    no_discrepancy=0.0)
    >>> variance = 1e-4 + 0.01**2 + 0.1**2
    >>> expected = -0.5 * (np.log(2 * np.pi * variance) + 0.1**2 / variance)
    >>> bool(np.isclose(likelihood.log_likelihood(np.array([[0.5, 0.5]]))[0], expected))
    True
    """

    def __init__(
        self,
        box_lower: np.ndarray,
        box_upper: np.ndarray,
        emulators: Sequence[PolynomialEmulator],
        loo: np.ndarray,
        features: Features,
        n_global: int,
        *,
        phi: np.ndarray,
        tau: np.ndarray,
        no_discrepancy: float = NO_DISCREPANCY_PROBABILITY,
    ) -> None:
        super().__init__(box_lower, box_upper, emulators, loo, features, n_global)
        self.phi, self.slab_tau, self.no_discrepancy = np.asarray(phi, float), np.asarray(tau, float), no_discrepancy
        #: The tau grid (with 0 in front where no_discrepancy > 0) and its log prior weights.
        self.tau, self.log_tau_weights = tau_prior(self.slab_tau, no_discrepancy)
        self.used = features.used
        n_op, n_channels, n_harmonics = self.shape
        n_groups, n_basis = n_channels * n_harmonics, self.phi.shape[1]
        used = features.used.reshape(n_op, n_groups).T  # (G, op)
        #: D^-1 per (group, op, sigma): zero for a feature left out (StageLikelihood.inverse_total).
        self.inverse_diagonal = self.inverse_total.reshape(-1, n_op, n_groups).transpose(2, 1, 0)
        phi_group = np.where(used[:, :, None], self.phi[None], 0.0)  # (G, op, p)
        weighted = self.inverse_diagonal[..., None] * phi_group[:, :, None]  # (G, op, K, p)
        #: D^-1 Phi per (group, op, sigma x basis): the projection of a residual on the basis.
        self.weighted_basis = weighted.reshape(n_groups, n_op, -1)
        information = np.einsum("gnp,gnkq->gkpq", phi_group, weighted)  # Phi^T D^-1 Phi
        squared = self.tau[None, None, :, None, None] ** 2
        # M = I + tau^2 Phi^T D^-1 Phi, finite at tau = 0 (where C = tau^2 M^-1 = 0)
        scaled = np.eye(n_basis) + squared * information[:, :, None]
        #: M^-1 per (group, sigma, tau); C = tau^2 M^-1 (:func:`joint_beta_draws` takes its root).
        self.unit_covariance = np.linalg.inv(scaled)
        #: C = (tau^-2 I + Phi^T D^-1 Phi)^-1 per (group, sigma, tau): the covariance of beta given r.
        self.beta_covariance = squared * self.unit_covariance  # (G, K, L, p, p)
        # log det(D + tau^2 Phi Phi^T) - log det D = log det(I + tau^2 Phi^T D^-1 Phi)
        _, extra = np.linalg.slogdet(scaled)  # (G, K, L)
        normaliser = self.log_normaliser.reshape(-1, n_groups).T  # (G, K)
        #: log normalising constant per (group, sigma, tau).
        self.joint_normaliser = normaliser[:, :, None] - 0.5 * extra
        # u^T C u as one matrix product per (group, sigma): the products u_p u_q (p <= q) against C's
        # entries, off-diagonal ones counted twice
        self._pairs = np.triu_indices(n_basis)
        twice = np.where(self._pairs[0] == self._pairs[1], 1.0, 2.0)
        entries = self.beta_covariance[..., self._pairs[0], self._pairs[1]] * twice  # (G, K, L, pairs)
        self._quadratic = np.ascontiguousarray(entries.transpose(0, 1, 3, 2))  # (G, K, pairs, L)

    def with_features(self, features: Features) -> DiscrepancyLikelihood:
        """The likelihood of other observed features on the same box, emulators and basis."""
        return DiscrepancyLikelihood(
            self.box_lower,
            self.box_upper,
            self._emulators,
            self._loo,
            features,
            self._n_global,
            phi=self.phi,
            tau=self.slab_tau,
            no_discrepancy=self.no_discrepancy,
        )

    def group_residuals(self, residual: np.ndarray) -> np.ndarray:
        """Residuals (M, op, channel, harmonic) as (group, M, op), zero where a feature is left out."""
        masked = np.where(self.used[None], residual, 0.0)
        return masked.reshape(masked.shape[0], self.shape[0], -1).transpose(2, 0, 1)

    def projections(self, residual: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """r^T D^-1 r (G, M, K) and u = Phi^T D^-1 r (G, M, K, p) of residuals (M, op, channel, harmonic)."""
        r = self.group_residuals(residual)
        squares = np.matmul(r**2, self.inverse_diagonal)
        projected = np.matmul(r, self.weighted_basis).reshape(*r.shape[:2], -1, self.phi.shape[1])
        return squares, projected

    def _terms(self, residual: np.ndarray) -> np.ndarray:
        """Log likelihood per (group, sigma, point, tau), summed over runs."""
        squares, projected = self.projections(residual)
        pairs = projected[..., self._pairs[0]] * projected[..., self._pairs[1]]  # (G, M, K, pairs)
        # r^T (D + tau^2 Phi Phi^T)^-1 r = r^T D^-1 r - u^T C u (Woodbury)
        explained = np.matmul(pairs.transpose(0, 2, 1, 3), self._quadratic)  # (G, K, M, L)
        quadratic = squares.transpose(0, 2, 1)[..., None] - explained
        return self.joint_normaliser[:, :, None, :] - 0.5 * quadratic

    def _weighted_terms(self, residual: np.ndarray) -> np.ndarray:
        """Log likelihood plus tau's log prior weight per (group, sigma, point, tau), plus log L so that a mean over
        tau is the prior-weighted sum."""
        return self._terms(residual) + (self.log_tau_weights + np.log(self.tau.size))

    def joint_terms(self, residual: np.ndarray) -> np.ndarray:
        """Log likelihood plus tau's log prior weight (up to a constant) per (point, sigma, tau, group), summed over
        runs: normalised over (sigma, tau), the grid posterior."""
        return self._weighted_terms(residual).transpose(2, 1, 3, 0)

    def group_terms(self, residual: np.ndarray) -> np.ndarray:
        """Log likelihood per (point, sigma, channel, harmonic), tau integrated out over its prior."""
        marginal = _log_mean_exp(self._weighted_terms(residual), (3,))  # (G, K, M)
        return marginal.transpose(2, 1, 0).reshape(residual.shape[0], marginal.shape[1], *self.shape[1:])

    def group_log_likelihood(self, residual: np.ndarray) -> np.ndarray:
        """Log likelihood per (point, channel, harmonic), sigma (equal grid weights) and tau integrated out."""
        marginal = _log_mean_exp(self._weighted_terms(residual), (1, 3))  # (G, M)
        return marginal.T.reshape(residual.shape[0], *self.shape[1:])


__all__ = [
    "BASIS_NAMES",
    "DEFAULT_DISCREPANCY_RANGE",
    "NO_DISCREPANCY_PROBABILITY",
    "DiscrepancyBasis",
    "DiscrepancyLikelihood",
    "tau_grid",
    "tau_prior",
]
