"""Nonlinear-dynamics analysis of simulated responses.

Period and regime classification (Poincare points, 0-1 test, largest
Lyapunov exponent), spectra, phase planes, contact fractions, response QoIs,
and bifurcation and sweep grids over the physics' batch integrator; coexisting
responses from several starts (``attractors``); periodic orbits by shooting
with their Floquet multipliers (``shooting``, ``floquet``) and their
continuation in a parameter with located bifurcations (``continuation``,
``bifurcations``, ``branches``) and the speed windows where responses can
coexist (``windows``); rainflow counting and Miner's damage of a stress
history on an ISO 6336 S-N curve (``fatigue``).

May import :mod:`uqgear.common` and :mod:`uqgear.physics`.
"""

from __future__ import annotations

from .attractors import MultiStart, MultiStartSearch, StartedEvaluator, extremes_over_attractors
from .branches import bifurcation_table
from .continuation import Continuation, ContinuationSettings
from .fatigue import RainflowCount, damage_rate, miner_damage, rainflow_count
from .floquet import floquet_exponents, floquet_multipliers, is_stable, unstable_counts
from .regimes import (
    ResponseClass,
    classify_batch,
    classify_dataset,
    classify_response,
    count_distinct_points,
    detect_period,
)
from .response import contact_fractions, phase_plane, poincare_section, response_qois
from .shooting import PeriodicOrbit, PoincareMap, Shooting, ShootingError, ShootingSettings, setup_at
from .spectra import amplitude_spectrum, spectrum_dataset
from .sweeps import bifurcation, sweep_grid
from .windows import CoexistenceWindows, find_windows
from .zero_one import zero_one_test

__all__ = [
    "detect_period",
    "count_distinct_points",
    "zero_one_test",
    "ResponseClass",
    "classify_response",
    "classify_dataset",
    "classify_batch",
    "amplitude_spectrum",
    "spectrum_dataset",
    "phase_plane",
    "poincare_section",
    "contact_fractions",
    "response_qois",
    "bifurcation",
    "sweep_grid",
    "MultiStart",
    "MultiStartSearch",
    "StartedEvaluator",
    "extremes_over_attractors",
    "floquet_multipliers",
    "unstable_counts",
    "is_stable",
    "floquet_exponents",
    "Shooting",
    "ShootingSettings",
    "ShootingError",
    "PeriodicOrbit",
    "PoincareMap",
    "setup_at",
    "Continuation",
    "ContinuationSettings",
    "bifurcation_table",
    "CoexistenceWindows",
    "find_windows",
    "RainflowCount",
    "rainflow_count",
    "miner_damage",
    "damage_rate",
]
