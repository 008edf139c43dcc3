"""Rig data: the ``uqgear-rig/1`` netCDF format, signal features, and a virtual rig.

May import :mod:`uqgear.common`, :mod:`uqgear.physics` and :mod:`uqgear.uq`.
"""

from __future__ import annotations

from .features import (
    FEATURE_FAMILIES,
    SIGNAL_CHANNELS,
    FeatureDefinition,
    extract_features,
    feature_definitions,
    line_amplitudes,
    order_spectrum,
    sampling_rate,
)
from .foreign_modes import ForeignModes, bearing_check_plan, natural_modes
from .foreign_response import foreign_qois
from .foreign_rig import (
    ForeignGears,
    draw_gears,
    register_foreign_physics,
    simulate_foreign_campaign,
    simulate_foreign_run,
)
from .foreign_runup import simulate_foreign_runup_campaign
from .foreign_synth import synth_foreign_rig
from .format import (
    CONVENTIONS,
    RIG_COORDINATES,
    make_ramp_dataset,
    make_rig_dataset,
    read_rig,
    rig_design,
    usable_runs,
    validate_rig,
    write_rig,
)
from .ramp_records import ramp_operating_points, steady_campaign
from .ramp_segments import SegmentCleaner, SegmentProfile, segment_profiles
from .transfer_path import apply_transfer_path, transfer_path_gain
from .usability import check_usable_signal, record_states
from .virtual_rig import (
    adhesion_torque_bounds,
    bearing_check_operating_points,
    default_operating_points,
    simulate_campaign,
    synth_rig,
    true_parameters_of,
)
from .virtual_runup import join_campaigns, simulate_runup_campaign

__all__ = [
    "CONVENTIONS",
    "RIG_COORDINATES",
    "validate_rig",
    "read_rig",
    "rig_design",
    "usable_runs",
    "make_rig_dataset",
    "make_ramp_dataset",
    "ramp_operating_points",
    "SegmentCleaner",
    "SegmentProfile",
    "segment_profiles",
    "steady_campaign",
    "write_rig",
    "SIGNAL_CHANNELS",
    "FEATURE_FAMILIES",
    "FeatureDefinition",
    "feature_definitions",
    "sampling_rate",
    "order_spectrum",
    "line_amplitudes",
    "extract_features",
    "simulate_campaign",
    "simulate_runup_campaign",
    "join_campaigns",
    "synth_rig",
    "default_operating_points",
    "adhesion_torque_bounds",
    "true_parameters_of",
    "bearing_check_operating_points",
    "check_usable_signal",
    "record_states",
    "apply_transfer_path",
    "transfer_path_gain",
    "ForeignGears",
    "draw_gears",
    "simulate_foreign_campaign",
    "simulate_foreign_runup_campaign",
    "synth_foreign_rig",
    "simulate_foreign_run",
    "register_foreign_physics",
    "foreign_qois",
    "ForeignModes",
    "natural_modes",
    "bearing_check_plan",
]
