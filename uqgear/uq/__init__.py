"""The uncertainty layer: parameter spaces, sampling, interval analysis, Monte Carlo,
polynomial chaos, Sobol indices, response envelopes, the runner and results on disk.

May import :mod:`uqgear.common`, :mod:`uqgear.physics` and :mod:`uqgear.dynamics`.
"""

from __future__ import annotations

from .seeds import as_seed_sequence, child_seed, seed_attributes
from .parameters import Interval, Fixed, Distribution
from .parameter_space import ParameterSpace
from .sampling import unit_hypercube
from .sweeps import Sweep, make_sweep, evaluate_on_sweep
from .monte_carlo import monte_carlo_statistics
from .polynomial_chaos import PolynomialChaos
from .interval import IntervalAnalysis
from .chebyshev import chebyshev_nodes, chebyshev_coefficients
from .pbox import response_envelope, pbox
from .sensitivity import SobolAnalysis
from .envelope import speed_adhesion_grid, qoi_envelope, bifurcation_envelope, regime_map, time_response_envelope
from .runner import Runner, RunReport, chunk_hash
from .results import (
    save_result,
    load_result,
    write_dataset,
    read_dataset,
    provenance_attrs,
    package_versions,
    numba_target_cpu,
    uqgear_version,
    PROVENANCE_ATTRS,
)

__all__ = [
    "Interval",
    "Fixed",
    "Distribution",
    "ParameterSpace",
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
