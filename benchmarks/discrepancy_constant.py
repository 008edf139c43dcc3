"""Does the discrepancy's constant hold the stiffnesses at their bounds? Profiles on a foreign campaign's last box.

The foreign campaign (:func:`calibration_discrepancy.foreign_campaign`) is calibrated with the discrepancy term
(default settings); on the last emulator box, the likelihood is rebuilt with the constant coefficient's prior
standard deviation scaled (1: as fitted; 1/4, 1/10; 0: no constant) and with the constant alone. For each it
prints the largest log likelihood over the box, the profile log likelihood of the mesh stiffness scale and of k1
at five points across the box (the other coordinates maximised), and the mean acceptance of 6000 final-run
steps (the unrestricted independence proposals). Scaling a basis column of Phi by c is a prior standard
deviation c tau for its coefficient.

Usage: ``python benchmarks/discrepancy_constant.py [--seed 0]``
"""

from __future__ import annotations

import argparse

import numpy as np
import scipy.optimize
from calibration_discrepancy import foreign_campaign

from uqgear.calibration import Calibration
from uqgear.calibration.convergence import ConvergenceCriteria
from uqgear.calibration.discrepancy import DiscrepancyLikelihood
from uqgear.calibration.sampling import final_sampling

VARIANTS = {"as fitted": (1.0, 1.0, 1.0, 1.0), "constant sd tau / 4": (0.25, 1.0, 1.0, 1.0),
            "constant sd tau / 10": (0.1, 1.0, 1.0, 1.0), "no constant": (0.0, 1.0, 1.0, 1.0),
            "constant alone": (1.0, 0.0, 0.0, 0.0)}
NODES = (0.0, 0.25, 0.5, 0.75, 1.0)


def maximum(likelihood: DiscrepancyLikelihood, rng: np.random.Generator, fixed: tuple[int, float] | None) -> float:
    """The largest log likelihood over the unit box (one coordinate held at a value if ``fixed``)."""
    candidates = rng.uniform(0.0, 1.0, (4000, likelihood.n_dim))
    if fixed is not None:
        candidates[:, fixed[0]] = fixed[1]
    free = [i for i in range(likelihood.n_dim) if fixed is None or i != fixed[0]]
    best = -np.inf
    for start in candidates[np.argsort(likelihood.log_likelihood(candidates))[::-1][:4]]:
        def negative(x: np.ndarray, start: np.ndarray = start) -> float:
            point = start.copy()
            point[free] = x
            return -float(likelihood.log_likelihood(point[None])[0])
        found = scipy.optimize.minimize(negative, start[free], method="L-BFGS-B", bounds=[(0.0, 1.0)] * len(free))
        best = max(best, -found.fun)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    calibration = Calibration(seed=args.seed, discrepancy=True).fit(foreign_campaign(args.seed))
    fitted = calibration._likelihood
    assert isinstance(fitted, DiscrepancyLikelihood)
    names = list(calibration.parameters) + [f"adhesion_torque[{op}]" for op in range(calibration.n_op_)]
    draws = np.concatenate([np.stack([calibration.posterior_[name].values.reshape(-1)
                                      for name in calibration.parameters], axis=1),
                            calibration.posterior_["adhesion_torque"].values.reshape(-1, calibration.n_op_)], axis=1)
    stiffness, k1 = names.index("mesh_stiffness_scale"), names.index("k1")
    low, high = fitted.box_lower[[stiffness, k1]], fitted.box_upper[[stiffness, k1]]
    print(f"box: mesh_stiffness_scale {low[0]:.3f} to {high[0]:.3f}, k1 {low[1]:.4g} to {high[1]:.4g}")
    for label, scales in VARIANTS.items():
        likelihood = DiscrepancyLikelihood(fitted.box_lower, fitted.box_upper, fitted._emulators, fitted._loo,
                                           calibration._features, fitted._n_global,
                                           phi=fitted.phi * np.asarray(scales)[None], tau=fitted.tau)
        rng = np.random.default_rng(0)
        best = maximum(likelihood, rng, None)
        profiles = {name: [round(maximum(likelihood, rng, (index, node)), 2) for node in NODES]
                    for name, index in (("mesh_stiffness_scale", stiffness), ("k1", k1))}
        best = max(best, *(value for values in profiles.values() for value in values))  # the best point found
        verdict, _, _ = final_sampling(likelihood, draws, np.random.default_rng(1), np.random.SeedSequence(2),
                                       walkers=56, chunk_steps=6000, max_steps=6000,
                                       criteria=ConvergenceCriteria(50.0, 1.01, 400.0), names=names, truncated=False)
        print(f"{label:22s} largest log likelihood {best:8.2f}; acceptance {verdict['acceptance_mean']:.3f}; "
              f"profiles at {NODES} of the box: {profiles}", flush=True)


if __name__ == "__main__":
    main()
