"""uqgear: dynamics of railway traction gears under uncertainty.

The physics core (design, geometry, Ishikawa stiffness, 3-DOF model, fast and
reference integrators) is importable without plotting or file I/O.
"""

from .design import Design, Operation, bundled_designs, load_design
from .errors import (DesignError, ExecutionError, OperatingPointError, ParameterSpaceError,
                     RigDataError, StudyError, UqgearError)
from .integration import samples_from_mapping, simulate, simulate_batch
from .model import build_model, dimensionless, equivalent_mass, natural_frequencies
from .stiffness import iso6336_stiffness, mesh_stiffness

__version__ = "0.1.0"

__all__ = [
    "Design", "Operation", "load_design", "bundled_designs", "mesh_stiffness", "iso6336_stiffness",
    "simulate", "simulate_batch", "samples_from_mapping", "build_model", "dimensionless",
    "equivalent_mass", "natural_frequencies", "UqgearError", "DesignError", "OperatingPointError",
    "ParameterSpaceError", "StudyError", "RigDataError", "ExecutionError", "__version__",
]
