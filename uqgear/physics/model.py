"""The 3-DOF bending-torsional gear model (docs/model/equations.md section 2).

:func:`build_model` turns a design, an operating point and optional effects
into a :class:`ModelSetup`: the parameter vector and stiffness tables the
compiled right-hand side reads, plus derived quantities (equivalent mass m_e,
mean mesh force F_T, mean mesh stiffness, natural frequencies).

Damping: c_m = 2 zeta_m sqrt(k_mean m_e) and c_i = 2 zeta_i sqrt(k_i m_i). In
the classical form used by default the mesh damping acts also while the
teeth are apart (``damping_in_separation=True``); set it to False to switch
mesh damping off during separation.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from ..common.errors import OperatingPointError
from . import _kernels as K
from .design import Design
from .design_parts import MeshDesign, ModalDesign
from .geometry import PairGeometry, pair_geometry
from .pitch_errors import PitchErrors
from .stiffness import StiffnessTables, stiffness_tables

STIFFNESS_MODES = ("ishikawa", "fourier", "constant")

#: Columns of a simulated history, in the order the kernels write them (the state, both accelerations,
#: mesh force, mesh stiffness, static transmission error and contact state).
HISTORY_COLUMNS = (
    "y1",
    "y2",
    "x",
    "y1_velocity",
    "y2_velocity",
    "x_velocity",
    "y1_acceleration",
    "y2_acceleration",
    "mesh_force",
    "mesh_stiffness",
    "ste",
    "contact",
)


@functools.lru_cache(maxsize=64)
def _stiffness_tables(mesh: MeshDesign, mode: str) -> StiffnessTables:
    return stiffness_tables(mesh, mode=mode)


def cached_tables(design: Design | MeshDesign, mode: str) -> StiffnessTables:
    """Stiffness tables cached on the design's :class:`~uqgear.physics.design_parts.MeshDesign`.

    The tables are derived from that part alone, so they cannot read a field
    their key leaves out; a batch over k1, zeta, ... (fields outside it)
    shares one set.
    """
    return _stiffness_tables(MeshDesign.of(design), mode)


def equivalent_mass(design: Design | ModalDesign) -> float:
    """m_e = I1 I2 / (I1 R2^2 + I2 R1^2) in kg.

    Examples
    --------
    The base radii are m z cos(alpha) / 2:

    >>> import math
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> cos_alpha = math.cos(math.radians(design.pressure_angle))
    >>> r1, r2 = (design.module * z * cos_alpha / 2 for z in (design.z1, design.z2))
    >>> mass = uqgear.equivalent_mass(design)
    >>> round(mass, 2), math.isclose(mass, design.I1 * design.I2 / (design.I1 * r2**2 + design.I2 * r1**2))
    (120.96, True)
    """
    geometry = pair_geometry(design)
    r1, r2 = geometry.pinion.base_radius, geometry.gear.base_radius
    return design.I1 * design.I2 / (design.I1 * r2**2 + design.I2 * r1**2)


def mean_mesh_force(design: Design, drive_torque: float, adhesion_torque: float) -> float:
    """F_T = m_e (R1 T1 / I1 + R2 T2 / I2), the mean mesh force in N."""
    geometry = pair_geometry(design)
    me = equivalent_mass(design)
    return me * (
        geometry.pinion.base_radius * drive_torque / design.I1 + geometry.gear.base_radius * adhesion_torque / design.I2
    )


def rated_mesh_force(design: Design) -> float:
    """T1_rated / r_b1 in N: the mesh force of the design's rated drive torque on the pinion base circle.

    The fixed reference of the QoI ``load_factor_rated`` (unlike F_T, it does
    not move with the adhesion torque T2). 78.8 kN for the reference design.
    """
    return design.operation.drive_torque / pair_geometry(design).pinion.base_radius


def natural_frequencies(design: Design | ModalDesign, mesh_stiffness: float | None = None) -> np.ndarray:
    """Undamped natural frequencies (Hz) of the linearised 3-DOF model in contact.

    Parameters
    ----------
    design : Design or ModalDesign
        The fields read are those of :class:`~uqgear.physics.design_parts.ModalDesign`.
    mesh_stiffness : float, optional
        Mesh stiffness in N/m; the Ishikawa mean by default.

    Returns
    -------
    ndarray
        The three frequencies in Hz, ascending.

    Examples
    --------
    >>> import math
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> uqgear.natural_frequencies(design).round(1)
    array([ 274.4,  434.1, 1546.5])

    Without mesh stiffness the shafts vibrate alone on their bearings, at
    sqrt(k/m) / 2 pi, and the gear pair turns freely (0 Hz):

    >>> uqgear.natural_frequencies(design, mesh_stiffness=0.0).round(1)
    array([  0. , 355.9, 649.7])
    >>> [round(math.sqrt(k / m) / (2 * math.pi), 1) for k, m in ((design.k2, design.m2), (design.k1, design.m1))]
    [355.9, 649.7]
    """
    k = mesh_stiffness if mesh_stiffness is not None else cached_tables(design, "ishikawa").k_mean
    me = equivalent_mass(design)
    # accelerations of (y1, y2, x) for F = k x
    a = np.array(
        [
            [-design.k1 / design.m1, 0.0, -k / design.m1],
            [0.0, -design.k2 / design.m2, k / design.m2],
            [-design.k1 / design.m1, design.k2 / design.m2, -k / design.m1 - k / design.m2 - k / me],
        ]
    )
    omega2 = np.sort(np.real(np.linalg.eigvals(-a)))
    return np.sqrt(np.maximum(omega2, 0.0)) / (2.0 * math.pi)


@dataclass
class ModelSetup:
    """Everything the integrators need for one run.

    Attributes
    ----------
    parameters : ndarray
        Parameter vector (slots of :mod:`uqgear.physics._kernels`).
    pair_stiffness, period_stiffness : ndarray
        Single-pair stiffness table over the path of contact and the mesh
        stiffness over one period (N/m).
    factor_pinion, factor_gear : ndarray
        Per-tooth stiffness factors (1 = healthy), lengths z1 and z2.
    breakpoints : ndarray
        Mesh phases in (0, 1) where the stiffness or friction direction jumps.
    derived : dict
        Derived scalars for output attributes.
    pitch_errors : PitchErrors or None
        Per-tooth pitch offsets, also written to the tail of ``parameters``
        (docs/model/equations.md section 2.6).
    """

    design: Design
    parameters: np.ndarray
    pair_stiffness: np.ndarray
    period_stiffness: np.ndarray
    factor_pinion: np.ndarray
    factor_gear: np.ndarray
    breakpoints: np.ndarray
    derived: dict[str, float] = field(default_factory=dict)
    effects: tuple = ()
    stiffness: str = "ishikawa"
    pitch_errors: PitchErrors | None = None

    def slot(self, name: str) -> float:
        """Value of a parameter slot by name."""
        return float(self.parameters[K.PARAMETER_SLOTS.index(name)])

    def set_slot(self, name: str, value: float) -> None:
        """Set a parameter slot by name (used by effects)."""
        self.parameters[K.PARAMETER_SLOTS.index(name)] = value

    @property
    def mesh_frequency(self) -> float:
        """Mesh frequency in Hz."""
        return self.parameters[K.OMEGA_MESH] / (2.0 * math.pi)

    @property
    def pinion_rotation(self) -> float:
        """Pinion angular speed W1 in rad/s."""
        return self.parameters[K.OMEGA_MESH] / self.design.z1

    def static_state(self) -> np.ndarray:
        """Static-equilibrium state: teeth in drive-side contact under F_T.

        Each bearing sits F_T / k_i beyond its clearance (bearing clearance
        effect), so a run starting here has no start-up transient to ring
        down; the pinion bearing is pushed to negative y1, the gear's to
        positive y2. With pitch errors x also moves by the stiffness-weighted
        mean offset of the pairs in mesh at t = 0.
        """
        p = self.parameters
        force = self.derived["static_mesh_force"]
        k = self.derived["k_mean"] * p[K.STIFFNESS_SCALE]
        b = p[K.HALF_BACKLASH]
        x = force / k + b if force >= 0 else force / k - b
        if p[K.PITCH_ERRORS] != 0.0:
            x += self._mean_pair_offset()
        direction = math.copysign(1.0, force) if force != 0.0 else 0.0
        y1 = -force / p[K.K1] - direction * p[K.CLEARANCE1]
        y2 = force / p[K.K2] + direction * p[K.CLEARANCE2]
        return np.array([y1, y2, x, 0.0, 0.0, 0.0])

    def _mean_pair_offset(self) -> float:
        """Stiffness-weighted mean pitch offset (m) of the pairs in mesh at t = 0."""
        p = self.parameters
        z1, z2 = self.design.z1, self.design.z2
        eps = p[K.CONTACT_RATIO]
        pairs = np.arange(math.ceil(eps))  # pair i is meshing number -i, at i base pitches along the path
        grid = np.linspace(0.0, eps, self.pair_stiffness.size)
        weights = np.interp(pairs.astype(float), grid, self.pair_stiffness)
        weights = weights * self.factor_pinion[-pairs % z1] * self.factor_gear[-pairs % z2]
        offsets = p[K.N_PARAMS + (-pairs % z1)] + p[K.N_PARAMS + z1 + (-pairs % z2)]
        return float(np.sum(weights * offsets) / np.sum(weights))

    def state_scale(self) -> np.ndarray:
        """Typical magnitudes of the state components (for Lyapunov distances)."""
        length = max(
            self.parameters[K.HALF_BACKLASH], abs(self.derived["static_mesh_force"]) / self.derived["k_mean"], 1e-9
        )
        omega = self.derived["omega_n"]
        return np.array([length, length, length, length * omega, length * omega, length * omega])


def _check_operating(name: str, value: float, lower: float, unit: str, strict: bool = True) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise OperatingPointError(f"{name}: expected a number in {unit}; got {value!r}") from None
    if not math.isfinite(value) or (value <= lower if strict else value < lower):
        relation = ">" if strict else ">="
        raise OperatingPointError(f"{name}: expected a finite value {relation} {lower:g} {unit}; got {value!r}")
    return value


def build_model(
    design: Design,
    pinion_speed: float,
    drive_torque: float,
    adhesion_torque: float,
    *,
    mesh_stiffness_scale: float = 1.0,
    effects: Sequence = (),
    damping_in_separation: bool = True,
    stiffness: str = "ishikawa",
    pitch_errors: PitchErrors | None = None,
) -> ModelSetup:
    """Assemble the model for one operating point.

    Parameters
    ----------
    design : Design
    pinion_speed : float
        Pinion speed n1 in rpm (> 0).
    drive_torque : float
        Drive torque T1 on the pinion in N m (>= 0).
    adhesion_torque : float
        Wheel/rail adhesion torque T2 in N m (>= 0).
    mesh_stiffness_scale : float
        Factor on the Ishikawa mesh stiffness (calibration parameter).
    effects : sequence of Effect
        Unmodelled-effect extensions (:mod:`uqgear.physics.effects`).
    damping_in_separation : bool
        Keep mesh damping while the teeth are apart (classical form, default).
    stiffness : {"ishikawa", "fourier", "constant"}
        Raw Ishikawa curve, its truncated Fourier series, or the constant
        mean k_mean (linear-limit checks).
    pitch_errors : PitchErrors, optional
        Per-tooth pitch offsets along the line of action (z1 pinion and z2
        gear values, m). All zero or none: the classical mesh force k f(x),
        bit for bit; otherwise each pair in mesh deflects by x - e_i
        (docs/model/equations.md section 2.6).

    Returns
    -------
    ModelSetup

    Examples
    --------
    The mesh frequency is z1 n1 / 60; the static state has the mesh
    deflection under the mean mesh force and no velocities:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> setup = uqgear.build_model(design, pinion_speed=2000.0, drive_torque=7000.0, adhesion_torque=33e3)
    >>> round(float(setup.mesh_frequency), 6), design.z1 * 2000.0 / 60.0
    (700.0, 700.0)
    >>> state = setup.static_state()
    >>> print(f"static DTE {state[2] * 1e6:.1f} um, velocities {state[3:].tolist()}")
    static DTE 175.5 um, velocities [0.0, 0.0, 0.0]
    >>> round(setup.derived["static_mesh_force"])
    77450
    """
    pinion_speed = _check_operating("pinion_speed", pinion_speed, 0.0, "rpm")
    drive_torque = _check_operating("drive_torque", drive_torque, 0.0, "N m", strict=False)
    adhesion_torque = _check_operating("adhesion_torque", adhesion_torque, 0.0, "N m", strict=False)
    mesh_stiffness_scale = _check_operating("mesh_stiffness_scale", mesh_stiffness_scale, 0.0, "(factor)")
    if stiffness not in STIFFNESS_MODES:
        raise OperatingPointError(f"stiffness: expected one of {', '.join(STIFFNESS_MODES)}; got {stiffness!r}")
    geometry = pair_geometry(design)
    tables = cached_tables(design, "ishikawa")
    period_table = _period_table(design, tables, stiffness)
    me = equivalent_mass(design)
    _check_pitch_errors(design, pitch_errors)
    p = _parameters(design, geometry, me, tables.k_mean, stiffness, damping_in_separation)
    p[K.T1], p[K.T2] = drive_torque, adhesion_torque
    p[K.OMEGA_MESH] = 2.0 * math.pi * design.z1 * pinion_speed / 60.0
    p[K.STIFFNESS_SCALE] = mesh_stiffness_scale
    p[K.CM] = 2.0 * design.zeta_mesh * math.sqrt(tables.k_mean * mesh_stiffness_scale * me)
    setup = ModelSetup(
        design=design,
        parameters=p,
        pair_stiffness=tables.pair_stiffness,
        period_stiffness=period_table,
        factor_pinion=np.ones(design.z1),
        factor_gear=np.ones(design.z2),
        breakpoints=np.empty(0),
        derived=_derived(design, geometry, p, tables.k_mean),
        effects=tuple(effects),
        stiffness=stiffness,
        pitch_errors=pitch_errors,
    )
    if pitch_errors is not None and pitch_errors.any:
        _set_pitch_errors(p, design, geometry, pitch_errors)
    for effect in effects:
        effect.apply(setup)
    # the kernel skips per-tooth lookups unless some tooth differs
    p[K.TOOTH_FACTORS] = float(np.any(setup.factor_pinion != 1.0) or np.any(setup.factor_gear != 1.0))
    setup.breakpoints = _breakpoints(setup) if stiffness == "ishikawa" or effects else np.empty(0)
    return setup


def _period_table(design: Design, tables: StiffnessTables, stiffness: str) -> np.ndarray:
    """The one-mesh-period stiffness table of the ``stiffness`` mode (unused by the raw Ishikawa path)."""
    if stiffness == "fourier":
        return cached_tables(design, "fourier").period_stiffness
    if stiffness == "constant":
        # linear-limit studies: k(t) = k_mean through the smooth-table path
        return np.full_like(tables.period_stiffness, tables.k_mean)
    return tables.period_stiffness


def _check_pitch_errors(design: Design, pitch_errors: PitchErrors | None) -> None:
    if pitch_errors is not None and not isinstance(pitch_errors, PitchErrors):
        raise OperatingPointError(
            f"pitch_errors: expected a PitchErrors (per-tooth offsets in m) or None; got {type(pitch_errors).__name__}"
        )
    if pitch_errors is not None:
        pitch_errors.check(design)


def _parameters(
    design: Design, geometry: PairGeometry, me: float, k_mean: float, stiffness: str, damping_in_separation: bool
) -> np.ndarray:
    """The parameter vector's slots set by the design and the model's options (the operating point's are zero)."""
    # the named slots, then the per-tooth pitch offsets of pinion and gear (zero without pitch errors)
    p = np.zeros(K.N_PARAMS + design.z1 + design.z2)
    p[K.M1], p[K.M2], p[K.ME] = design.m1, design.m2, me
    p[K.K1], p[K.K2] = design.k1, design.k2
    p[K.C1] = 2.0 * design.zeta1 * math.sqrt(design.k1 * design.m1)
    p[K.C2] = 2.0 * design.zeta2 * math.sqrt(design.k2 * design.m2)
    p[K.HALF_BACKLASH] = design.half_backlash
    p[K.R1], p[K.R2], p[K.I1], p[K.I2] = (geometry.pinion.base_radius, geometry.gear.base_radius, design.I1, design.I2)
    p[K.STE_AMPLITUDE] = design.ste_amplitude
    p[K.DAMP_IN_SEPARATION] = 1.0 if damping_in_separation else 0.0
    p[K.PATH_START] = geometry.contact_start
    p[K.BASE_PITCH] = geometry.base_pitch
    p[K.LOA_LENGTH] = geometry.line_of_action_length
    p[K.PITCH_POSITION] = (geometry.pitch_point - geometry.contact_start) / geometry.base_pitch
    p[K.CONTACT_RATIO] = geometry.contact_ratio
    p[K.USE_PERIOD_TABLE] = 0.0 if stiffness == "ishikawa" else 1.0
    p[K.Z1], p[K.Z2] = design.z1, design.z2
    return p


def _derived(design: Design, geometry: PairGeometry, p: np.ndarray, k_mean: float) -> dict[str, float]:
    """Derived quantities of the operating point in ``p`` (its masses, radii, torques and speed)."""
    me, r1, r2 = float(p[K.ME]), geometry.pinion.base_radius, geometry.gear.base_radius
    drive_torque, adhesion_torque = float(p[K.T1]), float(p[K.T2])
    mesh_stiffness_scale, omega_mesh = float(p[K.STIFFNESS_SCALE]), float(p[K.OMEGA_MESH])
    return {
        "equivalent_mass": me,
        "k_mean": k_mean,
        "static_mesh_force": me * (r1 * drive_torque / design.I1 + r2 * adhesion_torque / design.I2),
        "omega_n": math.sqrt(k_mean * mesh_stiffness_scale / me),
        "mesh_frequency": omega_mesh / (2.0 * math.pi),
        "contact_ratio": geometry.contact_ratio,
        "pinion_base_radius": r1,
        "gear_base_radius": r2,
        "rated_mesh_force": design.operation.drive_torque / r1,
    }


def _set_pitch_errors(p: np.ndarray, design: Design, geometry: PairGeometry, pitch_errors: PitchErrors) -> None:
    """Write the per-tooth offsets into ``p`` and switch the per-pair path on."""
    if geometry.contact_ratio >= K.MAX_PAIRS:
        raise OperatingPointError(
            f"pitch_errors: the per-pair path holds at most {K.MAX_PAIRS} pairs in mesh; "
            f"the contact ratio is {geometry.contact_ratio:.3f}"
        )
    p[K.N_PARAMS : K.N_PARAMS + design.z1] = pitch_errors.pinion
    p[K.N_PARAMS + design.z1 :] = pitch_errors.gear
    p[K.PITCH_ERRORS] = 1.0


def _breakpoints(setup: ModelSetup) -> np.ndarray:
    """Mesh phases in (0, 1) where the pair set or the friction direction changes."""
    p = setup.parameters
    eps = p[K.CONTACT_RATIO]
    points = [eps - math.floor(eps)]
    if p[K.FRICTION] != 0.0:
        pitch = p[K.PITCH_POSITION]
        points.append(pitch - math.floor(pitch))
    return np.array(sorted(u for u in points if 1e-12 < u < 1.0 - 1e-12))


def dimensionless(ds: xr.Dataset, characteristic_length: float | None = None) -> xr.Dataset:
    """Dimensionless form of a simulation: tau = w_n t, X = x/b_c, Y_i = y_i/b_c.

    Parameters
    ----------
    ds : Dataset
        Output of :func:`uqgear.simulate`.
    characteristic_length : float, optional
        b_c in m; the half backlash b by default (dimensionless backlash 1).

    Returns
    -------
    Dataset
        ``X``, ``Y1``, ``Y2`` and their tau-derivatives on coordinate ``tau``;
        attrs ``characteristic_length`` (b_c), ``omega_n`` and ``Omega``
        (mesh frequency / natural frequency).

    Examples
    --------
    >>> import math
    >>> import numpy as np
    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> run = uqgear.simulate(design, 2000.0, 7000.0, 33e3, n_periods=60, keep_periods=20)
    >>> scaled = uqgear.dimensionless(run)
    >>> scaled.attrs["characteristic_length"] == design.backlash / 2, scaled.attrs["dimensionless_backlash"]
    (True, 1.0)
    >>> bool(np.allclose(scaled["X"] * design.backlash / 2, run["x"], rtol=1e-12, atol=0))
    True
    >>> omega = scaled.attrs["Omega"]
    >>> round(omega, 3), math.isclose(omega, 2 * math.pi * 700.0 / scaled.attrs["omega_n"])
    (0.879, True)
    """
    b_c = characteristic_length if characteristic_length is not None else ds.attrs["half_backlash"]
    if not b_c or b_c <= 0:
        raise OperatingPointError("characteristic_length: expected > 0 m (the half backlash is 0; give b_c)")
    omega_n = ds.attrs["omega_n"]
    tau = ds["time"].values * omega_n
    out = xr.Dataset(coords={"tau": ("time", tau, {"units": "1", "long_name": "dimensionless time w_n t"})})
    for name, label in (("x", "X"), ("y1", "Y1"), ("y2", "Y2")):
        out[label] = ("time", ds[name].values / b_c, {"units": "1", "long_name": f"{name} / b_c"})
        out[f"{label}_velocity"] = (
            "time",
            ds[f"{name}_velocity"].values / (b_c * omega_n),
            {"units": "1", "long_name": f"d{label}/dtau"},
        )
    out.attrs.update(
        characteristic_length=b_c,
        omega_n=omega_n,
        Omega=2.0 * math.pi * ds.attrs["mesh_frequency"] / omega_n,
        dimensionless_backlash=ds.attrs["half_backlash"] / b_c,
    )
    return out


__all__ = [
    "build_model",
    "ModelSetup",
    "equivalent_mass",
    "mean_mesh_force",
    "rated_mesh_force",
    "natural_frequencies",
    "dimensionless",
    "STIFFNESS_MODES",
]
