"""uqgear: dynamics of railway traction gears under uncertainty.

The package follows the data path, one subpackage a layer; each imports only
the layers below it (``tests/test_layout.py`` checks the graph):

=================  ==========================================================
``common``         error types, atomic file writing, progress, YAML reading
``physics``        design, geometry, Ishikawa stiffness, 3-DOF model, effects,
                   compiled and reference integrators (no plotting, no file output)
``dynamics``       regime classification, spectra, Poincare, bifurcation grids
``uq``             parameter spaces, interval analysis, Monte Carlo, PCE, Sobol,
                   envelopes, the runner, results on disk
``report``         HTML reports from result Datasets
``rig``            rig-file format, features, virtual rig
``calibration``    Bayesian calibration against rig campaigns
``diagnosis``      sim-to-real gap diagnosis
``validation``     the diagnosis's blind test on virtual-rig campaigns
``study``          YAML studies and the analyses they run
``cli``            the ``uqgear`` command
=================  ==========================================================

The names below are what the README's examples use. They are loaded on first
use, so ``import uqgear`` is quick and ``import uqgear.physics`` pulls in
nothing above the physics. The model is described in docs/model/index.md.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = "0.1.0"

#: Public name -> the subpackage that defines it.
_PUBLIC: dict[str, str] = {
    # designs and simulation
    "Design": "physics",
    "Operation": "physics",
    "load_design": "physics",
    "bundled_designs": "physics",
    "mesh_stiffness": "physics",
    "iso6336_stiffness": "physics",
    "build_model": "physics",
    "dimensionless": "physics",
    "equivalent_mass": "physics",
    "natural_frequencies": "physics",
    "simulate": "physics",
    "simulate_batch": "physics",
    "simulate_runup": "physics",
    "simulate_runup_batch": "physics",
    "SpeedProfile": "physics",
    "SpeedProfileError": "physics",
    "torque_driven_profile": "physics",
    "check_speed_range": "physics",
    "samples_from_mapping": "physics",
    "make_effect": "physics",
    "BatchEvaluator": "physics",
    # nonlinear dynamics
    "classify_dataset": "dynamics",
    "classify_batch": "dynamics",
    "spectrum_dataset": "dynamics",
    "order_map": "dynamics",
    "order_spectrum": "dynamics",
    "ramp_envelope": "dynamics",
    "jump_speeds": "dynamics",
    "up_down_envelopes": "dynamics",
    "StressEvaluator": "dynamics",
    "tooth_stress_qois": "dynamics",
    # uncertainty
    "ParameterSpace": "uq",
    "PosteriorDraws": "uq",
    "PosteriorError": "uq",
    "PosteriorPrediction": "uq",
    "Interval": "uq",
    "Distribution": "uq",
    "Fixed": "uq",
    "IntervalAnalysis": "uq",
    "SobolAnalysis": "uq",
    "PolynomialChaos": "uq",
    "response_envelope": "uq",
    "pbox": "uq",
    "save_result": "uq",
    "load_result": "uq",
    # studies and reports
    "load_study": "study",
    "parse_study": "study",
    "run_study": "study",
    "write_report": "report",
    # rig data, calibration, diagnosis
    "read_rig": "rig",
    "write_rig": "rig",
    "ramp_operating_points": "rig",
    "simulate_campaign": "rig",
    "simulate_runup_campaign": "rig",
    "extract_features": "rig",
    "Calibration": "calibration",
    "calibrate": "calibration",
    "Diagnosis": "diagnosis",
    "DiagnosisSettings": "diagnosis",
    "diagnose": "diagnosis",
    "blindtest": "validation",
    # files shipped with the package
    "example_rig_file": "common",
    "bundled_names": "common",
    # errors
    "UqgearError": "common",
    "DesignError": "common",
    "OperatingPointError": "common",
    "ParameterSpaceError": "common",
    "StudyError": "common",
    "RigDataError": "common",
    "ExecutionError": "common",
    "InternalError": "common",
    "UqgearWarning": "common",
    "DesignWarning": "common",
    "UndercutWarning": "common",
}

__all__ = [*_PUBLIC, "__version__"]


def __getattr__(name: str) -> Any:
    try:
        subpackage = _PUBLIC[name]
    except KeyError:
        raise AttributeError(f"module 'uqgear' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(f"{__name__}.{subpackage}"), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
