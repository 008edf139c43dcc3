"""Convergence diagnostics of MCMC chains: split R-hat, autocorrelation time, ESS and the verdict.

Convergence (all must hold, else the result is reported as not converged):
chain length after burn-in >= ``autocorr_factor`` x the largest integrated
autocorrelation time (emcee), rank-normalised split-R-hat (walkers as chains)
<= ``rhat_threshold``, effective sample size >= ``min_ess`` for every
parameter, mean acceptance fraction in [0.1, 0.9], and a posterior not
truncated by an emulator box.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import emcee
import numpy as np
import scipy.stats

from .errors import CalibrationError


def _as_chains(chains: np.ndarray, where: str) -> np.ndarray:
    array = np.asarray(chains, dtype=float)
    if array.ndim != 2 or array.shape[0] < 2 or array.shape[1] < 4:
        raise CalibrationError(f"{where}: expected draws of shape (chains >= 2, draws >= 4); got {array.shape}")
    if not np.all(np.isfinite(array)):
        raise CalibrationError(f"{where}: expected finite draws")
    return array


def split_rhat(chains: np.ndarray, *, rank_normalize: bool = True) -> float:
    """Split-chain potential scale reduction factor R-hat.

    Each chain is split in halves and the between/within variance ratio of
    Gelman et al. (BDA3, eq. 11.4) is computed; with ``rank_normalize`` the
    draws are first replaced by normal scores of their pooled ranks
    (Vehtari et al. 2021, Bayesian Analysis 16, 667), which makes the value
    robust to heavy tails.

    Parameters
    ----------
    chains : array (n_chains, n_draws)
        Draws of one scalar; for emcee, walkers as chains.

    Returns
    -------
    float
        About 1 for chains sampling the same distribution; > 1.01 signals
        chains that have not mixed.
    """
    array = _as_chains(chains, "split_rhat")
    half = array.shape[1] // 2
    split = np.concatenate([array[:, :half], array[:, array.shape[1] - half :]], axis=0)
    if rank_normalize:
        ranks = scipy.stats.rankdata(split, method="average").reshape(split.shape)
        split = scipy.stats.norm.ppf((ranks - 0.375) / (split.size + 0.25))
    n = split.shape[1]
    within = np.mean(np.var(split, axis=1, ddof=1))
    between = n * np.var(np.mean(split, axis=1), ddof=1)
    if within == 0:
        return 1.0 if between == 0 else math.inf
    pooled = (n - 1) / n * within + between / n
    return float(math.sqrt(pooled / within))


def integrated_autocorrelation_time(chains: np.ndarray) -> float:
    """Integrated autocorrelation time (in steps) of an ensemble of chains (emcee's estimator).

    Parameters
    ----------
    chains : array (n_chains, n_draws)
    """
    array = _as_chains(chains, "integrated_autocorrelation_time")
    return float(emcee.autocorr.integrated_time(array.T[:, :, None], tol=0, quiet=True)[0])


def effective_sample_size(chains: np.ndarray) -> float:
    """Effective sample size: the number of draws over the integrated autocorrelation time.

    About the number of draws for independent draws.
    """
    array = _as_chains(chains, "effective_sample_size")
    return float(array.size / max(integrated_autocorrelation_time(array), 1.0))


@dataclass(frozen=True)
class ConvergenceCriteria:
    """What a converged chain must satisfy (module docstring)."""

    autocorr_factor: float
    rhat_threshold: float
    min_ess: float

    def verdict(
        self, chain: np.ndarray, acceptance: np.ndarray, truncated: bool, names: Sequence[str]
    ) -> dict[str, Any]:
        """Diagnostics of a chain (step, walker, parameter) after burn-in and whether it converged.

        Parameters
        ----------
        chain : array (steps, walkers, parameters)
        acceptance : array (walkers,)
            Acceptance fraction of each walker.
        truncated : bool
            Whether the posterior is truncated by the emulator box.
        names : sequence of str
            Parameter names, in the chain's order.
        """
        per_parameter = parameter_diagnostics(chain, names)
        tau_max = float(max(entry["tau"] for entry in per_parameter.values()))
        length = chain.shape[0]
        reasons = []
        if length < self.autocorr_factor * tau_max:
            reasons.append(
                f"chain of {length} steps after burn-in is shorter than {self.autocorr_factor:g} "
                f"autocorrelation times ({tau_max:.0f} steps)"
            )
        worst_rhat = max(entry["rhat"] for entry in per_parameter.values())
        if worst_rhat > self.rhat_threshold:
            reasons.append(f"split R-hat {worst_rhat:.3f} > {self.rhat_threshold:g}")
        lowest_ess = min(entry["ess"] for entry in per_parameter.values())
        if lowest_ess < self.min_ess:
            reasons.append(f"effective sample size {lowest_ess:.0f} < {self.min_ess:g}")
        mean_acceptance = float(np.mean(acceptance))
        if not 0.1 <= mean_acceptance <= 0.9:
            reasons.append(f"mean acceptance fraction {mean_acceptance:.3f} outside [0.1, 0.9]")
        if truncated:
            reasons.append("posterior truncated by the emulator box after the last stage")
        return {
            "converged": not reasons,
            "reasons": reasons,
            "tau_max": tau_max,
            "rhat_max": float(worst_rhat),
            "ess_min": float(lowest_ess),
            "acceptance_mean": mean_acceptance,
            "acceptance_min": float(np.min(acceptance)),
            "acceptance_max": float(np.max(acceptance)),
            "steps_after_burn_in": int(length),
            "parameters": per_parameter,
        }


def parameter_diagnostics(chain: np.ndarray, names: Sequence[str]) -> dict[str, dict[str, float]]:
    """Integrated autocorrelation time, effective sample size and split R-hat of each parameter.

    A parameter that never moves gets tau 1, ESS the number of draws and R-hat 1.
    """
    per_parameter = {}
    for index, name in enumerate(names):
        draws = chain[:, :, index].T  # (walker, step)
        if np.ptp(draws) == 0:
            tau, ess, rhat = 1.0, float(draws.size), 1.0
        else:
            tau = integrated_autocorrelation_time(draws)
            ess = draws.size / max(tau, 1.0)
            rhat = split_rhat(draws)
        per_parameter[name] = {"tau": float(tau), "ess": float(ess), "rhat": float(rhat)}
    return per_parameter
