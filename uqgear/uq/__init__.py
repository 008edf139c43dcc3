"""The uncertainty layer: parameter spaces, sampling, interval analysis, Monte Carlo,
polynomial chaos, Sobol indices, response envelopes, the runner and results on disk.

May import :mod:`uqgear.common`, :mod:`uqgear.physics` and :mod:`uqgear.dynamics`.
"""

from __future__ import annotations

from .chebyshev import chebyshev_coefficients, chebyshev_nodes
from .envelope import bifurcation_envelope, qoi_envelope, regime_map, speed_adhesion_grid, time_response_envelope
from .interval import IntervalAnalysis
from .monte_carlo import monte_carlo_statistics
from .parameter_space import ParameterSpace
from .parameters import Distribution, Fixed, Interval
from .pbox import pbox, response_envelope
from .polynomial_chaos import PolynomialChaos
from .posterior import DEFAULT_DRAWS, PosteriorDraws, PosteriorError
from .prediction import PosteriorPrediction
from .results import (
    PROVENANCE_ATTRS,
    load_result,
    numba_target_cpu,
    package_versions,
    provenance_attrs,
    read_dataset,
    save_result,
    uqgear_version,
    write_dataset,
)
from .runner import Runner, RunReport, chunk_hash
from .sampling import unit_hypercube
from .seeds import as_seed_sequence, child_seed, seed_attributes
from .sensitivity import SobolAnalysis
from .sweeps import Sweep, evaluate_on_sweep, make_sweep

__all__ = [
    "Interval",
    "Fixed",
    "Distribution",
    "ParameterSpace",
    "PosteriorDraws",
    "PosteriorError",
    "PosteriorPrediction",
    "DEFAULT_DRAWS",
    "PolynomialChaos",
    "Sweep",
    "make_sweep",
    "as_seed_sequence",
    "child_seed",
    "seed_attributes",
    "unit_hypercube",
    "evaluate_on_sweep",
    "monte_carlo_statistics",
    "IntervalAnalysis",
    "response_envelope",
    "pbox",
    "chebyshev_nodes",
    "chebyshev_coefficients",
    "SobolAnalysis",
    "speed_adhesion_grid",
    "qoi_envelope",
    "bifurcation_envelope",
    "regime_map",
    "time_response_envelope",
    "Runner",
    "RunReport",
    "chunk_hash",
    "save_result",
    "load_result",
    "write_dataset",
    "read_dataset",
    "provenance_attrs",
    "package_versions",
    "numba_target_cpu",
    "uqgear_version",
    "PROVENANCE_ATTRS",
]
