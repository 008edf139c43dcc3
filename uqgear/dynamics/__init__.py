"""Nonlinear-dynamics analysis of simulated responses.

Period and regime classification (Poincare points, 0-1 test, largest
Lyapunov exponent), spectra, phase planes, contact fractions, response QoIs,
and bifurcation and sweep grids over the physics' batch integrator; coexisting
responses from several starts (``attractors``); periodic orbits by shooting
with their Floquet multipliers (``shooting``, ``floquet``) and their
continuation in a parameter with located bifurcations (``continuation``,
``bifurcations``, ``branches``) and the speed windows where responses can
coexist (``windows``); rainflow counting and Miner's damage of a stress
history on an ISO 6336 S-N curve (``fatigue``); computed order tracking of
run-ups and coast-downs (``angle_resampling``), their order maps
(``order_maps``), and their binned envelopes, jumps and up/down hysteresis
(``ramp_envelopes``); tooth root and flank stresses of a batch of runs as QoIs
(``stress_qois``).

May import :mod:`uqgear.common` and :mod:`uqgear.physics`.
"""

from __future__ import annotations

from .angle_resampling import (
    RESOLVABLE_FRACTION,
    RUNUP_SIGNALS,
    OrderTrackingError,
    angle_from_pulses,
    angle_from_speed,
    resample_to_angle,
)
from .attractors import MultiStart, MultiStartSearch, StartedEvaluator, extremes_over_attractors
from .branches import bifurcation_table
from .continuation import Continuation, ContinuationSettings
from .fatigue import RainflowCount, damage_rate, miner_damage, rainflow_count
from .floquet import floquet_exponents, floquet_multipliers, is_stable, unstable_counts
from .order_maps import order_map, order_spectrum, speed_bin_edges
from .ramp_envelopes import (
    RAMP_DIRECTIONS,
    Jump,
    RampError,
    hysteresis_ranges,
    jump_speeds,
    ramp_envelope,
    up_down_envelopes,
)
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
from .stress_qois import RUN_QOI_INFO, STRESS_QOI_INFO, STRESS_QOIS, StressEvaluator, tooth_stress_qois
from .sweeps import bifurcation, sweep_grid
from .windows import CoexistenceWindows, find_windows
from .zero_one import zero_one_test

__all__ = [
    "RUN_QOI_INFO",
    "STRESS_QOI_INFO",
    "STRESS_QOIS",
    "StressEvaluator",
    "tooth_stress_qois",
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
    "OrderTrackingError",
    "RESOLVABLE_FRACTION",
    "RUNUP_SIGNALS",
    "angle_from_speed",
    "angle_from_pulses",
    "resample_to_angle",
    "order_map",
    "order_spectrum",
    "speed_bin_edges",
    "RampError",
    "RAMP_DIRECTIONS",
    "Jump",
    "ramp_envelope",
    "jump_speeds",
    "up_down_envelopes",
    "hysteresis_ranges",
]
