"""The gear physics: design, geometry, Ishikawa stiffness, the 3-DOF model, effects, integrators.

``design`` -> ``geometry`` -> ``stiffness`` -> ``model`` (a :class:`ModelSetup`
derived once per operating point) -> ``integration`` (the compiled RK4 fast
path: right-hand side in ``_rhs``, one-sample kernels in ``_kernels`` and
``_pairs``, batches as SIMD lanes in ``_lanes``; and the scipy reference). ``effects`` holds the
unmodelled effects of docs/model.md section 6 as slots of the same
right-hand side; ``pitch_errors`` the per-tooth pitch offsets every real gear
has (section 2.6), an input of the model set-up, not an effect.

May import :mod:`uqgear.common` only; never plotting or file output (a test
checks it).
"""

from __future__ import annotations

from .design import (
    Design, Operation, load_design, bundled_designs, design_from_json, DESIGN_KEYS,
    OPTIONAL_DESIGN_KEYS, STANDARD_GRAVITY)
from .geometry import (involute, ToothGeometry, PairGeometry, pair_geometry, check_geometry, geometry_notes,
                       least_shift)
from .generation import RackCorner, Undercut, undercut, tip_penetration
from .stiffness import (
    tooth_compliance, contact_compliance, single_pair_stiffness, iso6336_stiffness, mesh_stiffness,
    stiffness_tables, StiffnessTables)
from .model import (
    build_model, ModelSetup, equivalent_mass, mean_mesh_force, rated_mesh_force, natural_frequencies, dimensionless,
    STIFFNESS_MODES)
from .effects import (
    Effect, EffectParameter, EffectError, EFFECTS, make_effect, parse_effect, Eccentricity,
    ToothDamage, Friction, TorqueRipple, AdhesionOscillation, BearingClearance)
from .pitch_errors import PitchErrors, iso1328_single_pitch_tolerance, draw_pitch_errors
from .integration import (
    simulate, simulate_batch, build_batch, samples_from_mapping, steps_per_period, BatchEvaluator,
    QOI_INFO, METHODS)

__all__ = [
    'Design', 'Operation', 'load_design', 'bundled_designs', 'design_from_json', 'DESIGN_KEYS',
    'OPTIONAL_DESIGN_KEYS', 'STANDARD_GRAVITY', 'involute', 'ToothGeometry', 'PairGeometry',
    'pair_geometry', 'check_geometry', 'geometry_notes', 'least_shift', 'RackCorner', 'Undercut', 'undercut',
    'tip_penetration', 'tooth_compliance', 'contact_compliance',
    'single_pair_stiffness', 'iso6336_stiffness', 'mesh_stiffness', 'stiffness_tables',
    'StiffnessTables', 'build_model', 'ModelSetup', 'equivalent_mass', 'mean_mesh_force', 'rated_mesh_force',
    'natural_frequencies', 'dimensionless', 'STIFFNESS_MODES', 'Effect', 'EffectParameter',
    'EffectError', 'EFFECTS', 'make_effect', 'parse_effect', 'Eccentricity', 'ToothDamage',
    'Friction', 'TorqueRipple', 'AdhesionOscillation', 'BearingClearance', 'simulate',
    'simulate_batch', 'build_batch', 'samples_from_mapping', 'steps_per_period', 'BatchEvaluator',
    'QOI_INFO', 'METHODS', 'PitchErrors', 'iso1328_single_pitch_tolerance', 'draw_pitch_errors',
]
