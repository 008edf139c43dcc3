"""YAML studies: the schema and its validation, and the analyses a study runs.

May import every subpackage below it (common, physics, dynamics, uq, rig,
report, calibration, diagnosis, validation); only the command line sits above.
:func:`run_study` writes a study's results as a whole (:mod:`.running`).
"""

from __future__ import annotations

from .schema import (Study, load_study, parse_study, study_from_mapping)
from .analysis_specs import AnalysisSpec
from .settings import SimulationSettings
from .analysis_schemas import ANALYSIS_SCHEMAS
from .variables import VARIABLES
from .analyses import (ANALYSES, register, run_analysis)
from .running import run_study
# registers the continuation analysis in ANALYSES
from . import continuation_analysis  # noqa: F401

__all__ = [
    'Study', 'AnalysisSpec', 'SimulationSettings', 'load_study', 'parse_study',
    'study_from_mapping', 'ANALYSIS_SCHEMAS', 'VARIABLES', 'ANALYSES', 'register', 'run_analysis',
    'run_study',
]
