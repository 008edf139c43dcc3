"""Shared ground floor: error types, atomic file writing, progress bars, YAML reading,
and the files shipped in the package (bundled designs, studies, example rig campaigns).

Imports nothing of uqgear; every other subpackage may import it.
"""

from __future__ import annotations

from .errors import (
    DesignError,
    DesignWarning,
    ExecutionError,
    InternalError,
    OperatingPointError,
    ParameterSpaceError,
    RigDataError,
    StudyError,
    UndercutWarning,
    UqgearError,
    UqgearWarning,
    internal_step,
    shown,
)
from .fileio import atomic_path, write_text_atomic
from .forked import map_forked
from .progress import PROGRESS_ENVIRONMENT_VARIABLE, progress, progress_enabled
from .resources import ResourceError, bundled_file, bundled_names, example_rig_file
from .steps import FAILURE_RECORD, StepLog, write_failure_record
from .yamlio import YAMLError, load_yaml

__all__ = [
    "map_forked",
    "ResourceError",
    "bundled_file",
    "bundled_names",
    "example_rig_file",
    "shown",
    "UqgearError",
    "DesignError",
    "OperatingPointError",
    "ParameterSpaceError",
    "StudyError",
    "RigDataError",
    "ExecutionError",
    "InternalError",
    "internal_step",
    "UqgearWarning",
    "DesignWarning",
    "UndercutWarning",
    "atomic_path",
    "write_text_atomic",
    "progress",
    "progress_enabled",
    "PROGRESS_ENVIRONMENT_VARIABLE",
    "load_yaml",
    "YAMLError",
    "FAILURE_RECORD",
    "StepLog",
    "write_failure_record",
]
