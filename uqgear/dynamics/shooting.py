"""Periodic orbits of the gear model by shooting: Newton on the state at the start of a mesh period.

A period-n orbit is a fixed point of the n-fold Poincare map P^n (the state at mesh phase 0 mapped
over n mesh periods). :class:`Shooting` solves P^n(s) - s = 0 by Newton's method with the monodromy
matrix dP^n/ds as Jacobian; the monodromy comes from the variational equation integrated with the
orbit, carried through the contact switches exactly (saltation matrices, see
:mod:`uqgear.physics._variational`). Its eigenvalues, the Floquet multipliers, give the orbit's
stability (:mod:`uqgear.dynamics.floquet`).

The state is scaled by :meth:`~uqgear.physics.model.ModelSetup.state_scale` (displacements by the
larger of the half backlash and the static mesh deflection, velocities by that times the mesh
natural frequency), so one tolerance serves every component: Newton stops when the scaled
residual and the scaled update are both below ``tolerance`` (1e-9 by default, far below the
integrator's own error, so the orbit is that of the discrete map to round-off).

The integration is the fast path's (same RK4 grid, breakpoints and contact splitting; the
number of steps per mesh period from ``steps_per_mode`` as in
:func:`~uqgear.physics.integration.simulate_batch`), so an orbit found here is the steady state a
long batch run settles on when it is stable. Only models that repeat every mesh period have
period-n orbits of the mesh-period map: the effects of :data:`MESH_PERIODIC_EFFECTS` are allowed;
run-out, tooth damage, torque ripple, adhesion oscillation and pitch errors are refused.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..common.errors import OperatingPointError, UqgearError
from ..physics import kernels as K
from ..physics.design import Design
from ..physics.effects import MESH_PERIODIC_EFFECTS
from ..physics.integration import BATCH_DESIGN_KEYS, steps_per_period
from ..physics.model import ModelSetup, build_model
from .floquet import floquet_multipliers, is_stable

#: Operating variables an orbit's model can be set by (besides the design keys).
ORBIT_VARIABLES = ("pinion_speed", "drive_torque", "adhesion_torque", "mesh_stiffness_scale")


class ShootingError(UqgearError):
    """No periodic orbit was found from the given start (Newton did not converge)."""


def setup_at(
    design: Design,
    values: Mapping[str, float],
    *,
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    effects: Sequence[Any] = (),
) -> ModelSetup:
    """The model set-up at one operating point given as ``{variable: value}``.

    Parameters
    ----------
    design : Design
    values : mapping
        ``pinion_speed`` (rpm, required), ``drive_torque`` (default: the design's rated torque),
        ``adhesion_torque`` (default: the balancing T1 z2 / z1), ``mesh_stiffness_scale`` and any
        design key a batch may vary (``k1``, ``backlash``, ``zeta_mesh``, ...).
    damping_in_separation, stiffness, effects
        As in :func:`uqgear.simulate`.

    Examples
    --------
    >>> import uqgear
    >>> setup = setup_at(uqgear.load_design("locomotive"), {"pinion_speed": 3000.0, "k1": 1.2e9})
    >>> setup.design.k1
    1200000000.0
    """
    unknown = [name for name in values if name not in ORBIT_VARIABLES and name not in BATCH_DESIGN_KEYS]
    if unknown:
        raise OperatingPointError(
            f"{unknown[0]}: not a variable of the model; expected one of {', '.join(ORBIT_VARIABLES)} or a design key"
        )
    if "pinion_speed" not in values:
        raise OperatingPointError("pinion_speed: missing; expected the pinion speed in rpm")
    keys = {name: float(value) for name, value in values.items() if name in BATCH_DESIGN_KEYS}
    local = design.replace(**keys) if keys else design
    drive = float(values.get("drive_torque", design.operation.drive_torque))
    adhesion = float(values.get("adhesion_torque", drive * design.z2 / design.z1))
    setup = build_model(
        local,
        float(values["pinion_speed"]),
        drive,
        adhesion,
        mesh_stiffness_scale=float(values.get("mesh_stiffness_scale", 1.0)),
        effects=effects,
        damping_in_separation=damping_in_separation,
        stiffness=stiffness,
    )
    check_mesh_periodic(setup)
    return setup


def check_mesh_periodic(setup: ModelSetup) -> None:
    """Refuse a model that does not repeat every mesh period (no periodic orbit of the mesh-period map)."""
    others = [effect.name for effect in setup.effects if effect.name not in MESH_PERIODIC_EFFECTS]
    if others:
        raise OperatingPointError(
            f"effects: {others[0]} breaks the mesh periodicity the Poincare map needs; "
            f"periodic orbits allow only {', '.join(MESH_PERIODIC_EFFECTS)}"
        )
    if setup.parameters[K.PITCH_ERRORS] != 0.0 or setup.parameters[K.TOOTH_FACTORS] != 0.0:
        raise OperatingPointError(
            "pitch_errors: per-tooth errors repeat only once per hunting period, not every "
            "mesh period; periodic orbits need a model without them"
        )


@dataclass(frozen=True)
class MapResult:
    """One evaluation of the n-fold Poincare map.

    Attributes
    ----------
    state : ndarray (6,)
        The state after n mesh periods.
    monodromy : ndarray (6, 6) or None
        d(state)/d(start state), when asked for.
    measures : dict
        Orbit extremes and contact counts (:data:`uqgear.physics.kernels.MEASURE_NAMES`).
    """

    state: np.ndarray
    monodromy: np.ndarray | None
    measures: dict[str, float]


class PoincareMap:
    """The gear model at one operating point as the map of the state over n mesh periods.

    Parameters
    ----------
    setup : ModelSetup
        A mesh-periodic model (:func:`setup_at`).
    steps : int, optional
        RK4 grid steps per mesh period; by default from ``steps_per_mode``.
    steps_per_mode : int
        Steps per period of the highest natural mode (as in the batch integrator).
    discrete : bool
        True (default): the monodromy is the exact derivative of the discrete map (what Newton
        solves), the moving contact-crossing point included. False: the variational equation of the
        continuous-time flow with the saltation matrices; the two agree to the integrator's error.

    Examples
    --------
    >>> import uqgear
    >>> setup = setup_at(uqgear.load_design("locomotive"), {"pinion_speed": 3000.0})
    >>> result = PoincareMap(setup)(setup.static_state(), with_matrix=True)
    >>> result.monodromy.shape
    (6, 6)
    """

    def __init__(
        self, setup: ModelSetup, *, steps: int | None = None, steps_per_mode: int = 24, discrete: bool = True
    ) -> None:
        check_mesh_periodic(setup)
        self.setup = setup
        self.discrete = discrete
        self.steps = int(steps) if steps is not None else steps_per_period(setup, steps_per_mode)
        #: Passes over one mesh period so far (with and without the monodromy).
        self.passes = 0

    @property
    def mesh_period(self) -> float:
        """The mesh period in s."""
        return 1.0 / self.setup.mesh_frequency

    def __call__(self, state: np.ndarray, n_periods: int = 1, with_matrix: bool = True) -> MapResult:
        setup = self.setup
        phi = np.empty((6, 6))
        measures = np.empty(K.N_MEASURES)
        end = K.orbit_pass(
            np.ascontiguousarray(state, dtype=float),
            int(n_periods),
            setup.parameters,
            setup.pair_stiffness,
            setup.period_stiffness,
            setup.factor_pinion,
            setup.factor_gear,
            setup.breakpoints,
            self.steps,
            bool(with_matrix),
            self.discrete,
            phi,
            measures,
        )
        self.passes += int(n_periods)
        return MapResult(end, phi if with_matrix else None, dict(zip(K.MEASURE_NAMES, measures.tolist())))


def orbit_qois(measures: Mapping[str, float], setup: ModelSetup) -> dict[str, float]:
    """The batch QoIs of a periodic orbit from its measures (same definitions as :data:`uqgear.QOI_INFO`)."""
    count = max(measures["n_grid"], 1.0)
    mean = measures["x_sum"] / count
    return {
        "peak_mesh_force": measures["force_max"],
        "dynamic_load_factor": measures["force_max"] / setup.derived["static_mesh_force"]
        if setup.derived["static_mesh_force"] > 0
        else math.nan,
        "load_factor_rated": measures["force_max"] / setup.derived["rated_mesh_force"],
        "dte_rms": math.sqrt(max(measures["x_square_sum"] / count - mean * mean, 0.0)),
        "dte_peak_to_peak": measures["x_max"] - measures["x_min"],
        "fraction_separation": measures["n_separation"] / count,
        "fraction_back_contact": measures["n_back"] / count,
        "x_min": measures["x_min_curve"],
        "x_max": measures["x_max"],
        # signed distances of the orbit's lowest DTE from the contact boundaries (< 0: it crosses)
        "separation_margin": measures["x_min_curve"] - float(setup.parameters[K.HALF_BACKLASH]),
        "back_side_margin": measures["x_min_curve"] + float(setup.parameters[K.HALF_BACKLASH]),
    }


@dataclass
class PeriodicOrbit:
    """A periodic orbit of the n-fold Poincare map with its stability.

    Attributes
    ----------
    state : ndarray (6,)
        (y1, y2, x, y1', y2', x') at mesh phase 0.
    period : int
        n: the orbit repeats after n mesh periods.
    monodromy : ndarray (6, 6)
        dP^n/ds at the orbit.
    multipliers : ndarray of complex
        Floquet multipliers, largest modulus first.
    qois : dict
        Peak mesh force, DTE extremes, separation fractions (:func:`orbit_qois`).
    residual : float
        Scaled ``|P^n(s) - s|`` at the end.
    iterations : int
        Newton iterations taken.
    """

    state: np.ndarray
    period: int
    monodromy: np.ndarray
    multipliers: np.ndarray
    qois: dict[str, float] = field(default_factory=dict)
    residual: float = 0.0
    iterations: int = 0

    @property
    def stable(self) -> bool:
        """Every Floquet multiplier inside the unit circle."""
        return is_stable(self.multipliers)

    @property
    def spectral_radius(self) -> float:
        """Largest multiplier modulus."""
        return float(np.max(np.abs(self.multipliers)))


@dataclass(frozen=True)
class ShootingSettings:
    """Settings of the Newton iteration.

    Attributes
    ----------
    tolerance : float
        Scaled residual and update at which Newton stops.
    max_iterations : int
        Newton iterations before giving up.
    steps_per_mode : int
        RK4 steps per period of the highest natural mode.
    """

    tolerance: float = 1e-9
    max_iterations: int = 30
    steps_per_mode: int = 24


def newton_orbit(
    mapping: PoincareMap, guess: np.ndarray, period: int, settings: ShootingSettings, scale: np.ndarray | None = None
) -> PeriodicOrbit | None:
    """Newton on P^n(s) - s = 0 from ``guess``, with a backtracking line search; None if it fails."""
    scale = mapping.setup.state_scale() if scale is None else scale
    state = np.asarray(guess, dtype=float).copy()
    result = mapping(state, period)
    residual = (result.state - state) / scale
    for iteration in range(settings.max_iterations + 1):
        norm = float(np.linalg.norm(residual))
        if not math.isfinite(norm):
            return None
        if norm < settings.tolerance:
            assert result.monodromy is not None  # the map computes its matrix unless asked not to
            return PeriodicOrbit(
                state=state,
                period=period,
                monodromy=result.monodromy,
                multipliers=floquet_multipliers(result.monodromy),
                qois=orbit_qois(result.measures, mapping.setup),
                residual=norm,
                iterations=iteration,
            )
        jacobian = result.monodromy * scale[None, :] / scale[:, None] - np.eye(6)
        try:
            update = np.linalg.solve(jacobian, -residual)
        except np.linalg.LinAlgError:
            return None
        step = 1.0
        while True:
            trial = state + step * update * scale
            trial_result = mapping(trial, period)
            trial_residual = (trial_result.state - trial) / scale
            if np.linalg.norm(trial_residual) < norm or step < 1e-3:
                break
            step *= 0.5
        state, result, residual = trial, trial_result, trial_residual
    return None


class Shooting:
    """Find a period-n orbit of the gear model and its Floquet multipliers.

    Parameters
    ----------
    period : int
        n, the number of mesh periods after which the orbit repeats.
    settings : ShootingSettings, optional

    Attributes
    ----------
    orbit_ : PeriodicOrbit
        The orbit found by :meth:`fit`.
    map_ : PoincareMap
        The Poincare map it is a fixed point of.

    Examples
    --------
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> setup = setup_at(design, {"pinion_speed": 3000.0, "adhesion_torque": 21150.0})
    >>> orbit = Shooting().fit(setup, setup.static_state()).orbit_
    >>> orbit.stable, round(orbit.qois["peak_mesh_force"] / 1e3)
    (True, 75)
    """

    def __init__(self, period: int = 1, settings: ShootingSettings | None = None) -> None:
        self.period = period
        self.settings = settings or ShootingSettings()

    def fit(self, setup: ModelSetup, guess: np.ndarray) -> Shooting:
        """Solve for the orbit from ``guess`` (a state at mesh phase 0, e.g. a long run's final state)."""
        if isinstance(self.period, bool) or not isinstance(self.period, (int, np.integer)) or self.period < 1:
            raise UqgearError(f"period: expected a positive integer number of mesh periods; got {self.period!r}")
        guess = np.asarray(guess, dtype=float)
        if guess.shape != (6,) or not np.all(np.isfinite(guess)):
            raise UqgearError(f"guess: expected 6 finite values (y1, y2, x, y1', y2', x'); got shape {guess.shape}")
        mapping = PoincareMap(setup, steps_per_mode=self.settings.steps_per_mode)
        orbit = newton_orbit(mapping, guess, int(self.period), self.settings)
        if orbit is None:
            raise ShootingError(
                f"no period-{self.period} orbit found from this start in "
                f"{self.settings.max_iterations} Newton iterations; start from a state on or near "
                "the orbit (e.g. the final state of a long run)"
            )
        self.map_ = mapping
        self.orbit_ = orbit
        return self


__all__ = [
    "Shooting",
    "ShootingSettings",
    "ShootingError",
    "PeriodicOrbit",
    "PoincareMap",
    "MapResult",
    "setup_at",
    "check_mesh_periodic",
    "orbit_qois",
    "newton_orbit",
    "MESH_PERIODIC_EFFECTS",
    "ORBIT_VARIABLES",
]
