"""YAML studies: the schema and its validation, and the analyses a study runs.

May import every subpackage below it (common, physics, dynamics, uq, rig,
report, calibration, diagnosis, validation); only the command line sits above.
:func:`run_study` writes a study's results as a whole (:mod:`.running`).
"""

from __future__ import annotations

# registers the continuation, prediction, rating and run-up analyses in ANALYSES
from . import (
    continuation_analysis,  # noqa: F401
    prediction,  # noqa: F401
    rating_analysis,  # noqa: F401
    runup_analysis,  # noqa: F401
)
from .analyses import ANALYSES, register
from .analysis_schemas import ANALYSIS_SCHEMAS
from .analysis_specs import AnalysisSpec
from .running import run_analysis, run_study
from .schema import Study, load_study, parse_study, study_from_mapping
from .settings import SimulationSettings
from .variables import VARIABLES

__all__ = [
    "Study",
    "AnalysisSpec",
    "SimulationSettings",
    "load_study",
    "parse_study",
    "study_from_mapping",
    "ANALYSIS_SCHEMAS",
    "VARIABLES",
    "ANALYSES",
    "register",
    "run_analysis",
    "run_study",
]
