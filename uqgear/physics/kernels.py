"""The compiled model's interface for analyses that run its kernels themselves.

Most of the package reaches the model through :func:`~uqgear.physics.integration.simulate`,
:func:`~uqgear.physics.integration.simulate_batch` and their relatives. A few analyses step the
model inside compiled loops of their own: the periodic-orbit shooting and its Floquet multipliers
(:mod:`uqgear.dynamics.shooting`), the tooth-pair loads read from a run's parameter vector
(:mod:`uqgear.dynamics.tooth_loads`) and the calibration's steady harmonics
(:mod:`uqgear.calibration.harmonics`). They take what they need from here: the parameter vector's
slots (:data:`PARAMETER_SLOTS`, each a constant named as its slot in capitals), the one-sample
stepping kernels, the variational orbit pass, and the tolerance of the pitch point's dedendum test
the tooth-stress extremes apply (:data:`PITCH_TOLERANCE`). The names are those of the private kernel modules
(:mod:`uqgear.physics._rhs`, :mod:`uqgear.physics._kernels`, :mod:`uqgear.physics._variational`);
a module that compiles a call to one of them is listed in :data:`uqgear.physics._cache.COMPILED_MODULES`
so that its cached machine code follows the kernels'.

Examples
--------
>>> import uqgear
>>> from uqgear.physics import kernels
>>> setup = uqgear.build_model(uqgear.load_design("locomotive"), 3000.0, 7000.0, 33.8e3)
>>> kernels.PARAMETER_SLOTS[kernels.HALF_BACKLASH], float(setup.parameters[kernels.Z1])
('half_backlash', 21.0)
"""

from __future__ import annotations

from ._kernels import advance, scheduled_step
from ._pair_extremes import PITCH_TOLERANCE
from ._rhs import (
    BASE_PITCH,
    CM,
    CONTACT_RATIO,
    ECC_KAPPA,
    ECC_OMEGA,
    ECC_PHASE,
    HALF_BACKLASH,
    LOA_LENGTH,
    N_PARAMS,
    OMEGA_MESH,
    PARAMETER_SLOTS,
    PATH_START,
    PITCH_ERRORS,
    PITCH_POSITION,
    STE_AMPLITUDE,
    STIFFNESS_SCALE,
    TOOTH_FACTORS,
    TWO_PI,
    USE_PERIOD_TABLE,
    Z1,
    Z2,
    static_transmission_error,
)
from ._stepper import build_schedule
from ._variational import MEASURE_NAMES, N_MEASURES, orbit_pass

__all__ = [
    "BASE_PITCH",
    "CM",
    "CONTACT_RATIO",
    "ECC_KAPPA",
    "ECC_OMEGA",
    "ECC_PHASE",
    "HALF_BACKLASH",
    "LOA_LENGTH",
    "MEASURE_NAMES",
    "N_MEASURES",
    "N_PARAMS",
    "OMEGA_MESH",
    "PARAMETER_SLOTS",
    "PATH_START",
    "PITCH_ERRORS",
    "PITCH_POSITION",
    "PITCH_TOLERANCE",
    "STE_AMPLITUDE",
    "STIFFNESS_SCALE",
    "TOOTH_FACTORS",
    "TWO_PI",
    "USE_PERIOD_TABLE",
    "Z1",
    "Z2",
    "advance",
    "build_schedule",
    "orbit_pass",
    "scheduled_step",
    "static_transmission_error",
]
