"""The gear physics: design, geometry, Ishikawa stiffness, the 3-DOF model, effects, integrators.

``design`` -> ``geometry`` -> ``stiffness`` -> ``model`` (a :class:`ModelSetup`
derived once per operating point) -> ``integration`` (the compiled RK4 fast
path: right-hand side in ``_rhs``, one-sample kernels in ``_kernels`` and
``_pairs``, batches as SIMD lanes in ``_lanes`` with their forcing tables in ``_lane_tables``;
and the scipy reference; ``history_batch`` the histories of several runs at once; ``runup`` the same model driven
through a ``speed_profile``, with its compiled kernel in ``_runup_kernels``). ``effects`` holds the
unmodelled effects of docs/model/unmodelled-effects.md section 6 as slots of the same
right-hand side; ``pitch_errors`` the per-tooth pitch offsets every real gear
has (section 2.6), an input of the model set-up, not an effect. ``rating`` rates a
design by ISO 6336 method B (docs/model/rating.md section 10).

May import :mod:`uqgear.common` only; never plotting or file output (a test
checks it).
"""

from __future__ import annotations

from .design import (
    DESIGN_KEYS,
    OPTIONAL_DESIGN_KEYS,
    STANDARD_GRAVITY,
    Design,
    Operation,
    bundled_designs,
    design_from_json,
    load_design,
)
from .effects import (
    EFFECTS,
    MESH_PERIODIC_EFFECTS,
    AdhesionOscillation,
    BearingClearance,
    Eccentricity,
    Effect,
    EffectError,
    EffectParameter,
    Friction,
    ToothDamage,
    TorqueRipple,
    make_effect,
    parse_effect,
)
from .generation import RackCorner, Undercut, tip_penetration, undercut
from .geometry import PairGeometry, ToothGeometry, check_geometry, geometry_notes, involute, least_shift, pair_geometry
from .integration import (
    METHODS,
    QOI_INFO,
    BatchEvaluator,
    build_batch,
    samples_from_mapping,
    simulate,
    simulate_batch,
    steps_per_period,
)
from .model import (
    STIFFNESS_MODES,
    ModelSetup,
    build_model,
    dimensionless,
    equivalent_mass,
    mean_mesh_force,
    natural_frequencies,
    rated_mesh_force,
)
from .pitch_errors import PitchErrors, draw_pitch_errors, iso1328_single_pitch_tolerance
from .runup import RUN_IN_PERIODS, check_speed_range, simulate_runup, simulate_runup_batch
from .speed_profile import SpeedProfile, SpeedProfileError, torque_driven_profile
from .stiffness import (
    StiffnessTables,
    contact_compliance,
    iso6336_stiffness,
    mesh_stiffness,
    single_pair_stiffness,
    stiffness_tables,
    tooth_compliance,
)

__all__ = [
    "Design",
    "Operation",
    "load_design",
    "bundled_designs",
    "design_from_json",
    "DESIGN_KEYS",
    "OPTIONAL_DESIGN_KEYS",
    "STANDARD_GRAVITY",
    "involute",
    "ToothGeometry",
    "PairGeometry",
    "pair_geometry",
    "check_geometry",
    "geometry_notes",
    "least_shift",
    "RackCorner",
    "Undercut",
    "undercut",
    "tip_penetration",
    "tooth_compliance",
    "contact_compliance",
    "single_pair_stiffness",
    "iso6336_stiffness",
    "mesh_stiffness",
    "stiffness_tables",
    "StiffnessTables",
    "build_model",
    "ModelSetup",
    "equivalent_mass",
    "mean_mesh_force",
    "rated_mesh_force",
    "natural_frequencies",
    "dimensionless",
    "STIFFNESS_MODES",
    "Effect",
    "EffectParameter",
    "EffectError",
    "EFFECTS",
    "MESH_PERIODIC_EFFECTS",
    "make_effect",
    "parse_effect",
    "Eccentricity",
    "ToothDamage",
    "Friction",
    "TorqueRipple",
    "AdhesionOscillation",
    "BearingClearance",
    "simulate",
    "simulate_batch",
    "build_batch",
    "samples_from_mapping",
    "steps_per_period",
    "BatchEvaluator",
    "QOI_INFO",
    "METHODS",
    "PitchErrors",
    "iso1328_single_pitch_tolerance",
    "draw_pitch_errors",
    "SpeedProfile",
    "SpeedProfileError",
    "torque_driven_profile",
    "simulate_runup",
    "simulate_runup_batch",
    "check_speed_range",
    "RUN_IN_PERIODS",
]
