"""A virtual rig whose physics is not the diagnosis model's: a model-form gap of the size a real rig gives.

:func:`simulate_foreign_campaign` records a campaign (``uqgear-rig/1``) from a
structurally different gearbox than the 3-DOF model of :mod:`uqgear.physics`:

- eight degrees of freedom: a motor inertia held at speed by a speed
  controller (a proportional-derivative loop on the motor angle, about 15 Hz
  bandwidth) and joined to the pinion by a torsionally elastic input shaft;
  pinion and gear rotations; an elastic output shaft to a load inertia
  carrying the wheel torque T2; each wheel's centre on its bearing along the
  line of action; and a housing mode behind each bearing (a mass on its
  mount), which is where the accelerometers sit;
- a mesh stiffness that is not Ishikawa's: each tooth pair's stiffness rises
  from 55 % at its entry to 100 % midway and falls back (a half sine), pairs
  overlapping by the contact ratio, the pair force lost when the pair
  separates;
- per-tooth profile errors: every tooth of each wheel has its own offset,
  slope and curvature along its path of contact, drawn once per gear set
  from the ISO 1328-1 single pitch tolerance of a quality ``grade``;
- the transmission error as rotary encoders on the two shafts give it (the
  rotations only, not the bearing translations).

The library's effects act through their own physics here (their parameters
as :mod:`uqgear.physics.effects` states them): an eccentric shaft adds its
run-out to every pair's approach and modulates its stiffness; a damaged
tooth lowers the stiffness of the pairs it is in; friction turns each pair's
force into moments about the wheel centres that reverse at the pitch point;
torque ripple acts on the motor; an adhesion oscillation on the load; a
bearing clearance is a dead zone in the bearing spring. The integration is a
fixed-step fourth-order Runge-Kutta scheme compiled with numba (its step a
fortieth of the period of the fastest mode or finer), the records then pass
the same anti-alias filter and noise as :mod:`.virtual_rig`'s.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np
import xarray as xr
from numba import njit

from ..common.errors import RigDataError
from ..physics.design import Design
from ..physics.effects import (
    AdhesionOscillation,
    BearingClearance,
    Eccentricity,
    Effect,
    Friction,
    ToothDamage,
    TorqueRipple,
)
from ..uq.seeds import as_seed_sequence, child_seed
from .format import make_rig_dataset
from .virtual_rig import frequency_filter

#: Pair stiffness at entry and exit as a share of its peak (a half sine between).
PAIR_ENTRY_SHARE = 0.55
#: Mesh stiffness per metre of face width at its peak per pair, N/m/m (ISO 6336-1's c' of a solid steel pair).
PAIR_STIFFNESS_PER_WIDTH = 14e9
#: Housing masses behind each bearing as a share of that wheel's mass, and their mount frequencies relative to
#: the bearing mode of the 3-DOF model (the housing modes lie between the mesh harmonics of the service plan).
HOUSING_MASS_SHARE = 0.5
HOUSING_FREQUENCY_FACTOR = (1.7, 2.3)
#: Torsional stiffness of the input and output shafts relative to the mesh's torsional stiffness at the pinion.
SHAFT_STIFFNESS_FACTOR = (0.5, 0.1)
#: Motor and load inertias relative to the pinion's and the gear's.
MOTOR_INERTIA_FACTOR = 1.5
LOAD_INERTIA_FACTOR = 4.0
#: Speed controller bandwidth, Hz.
CONTROLLER_BANDWIDTH = 15.0
#: Length of the foreign plant's state vector.
N_STATE = 16
#: Guard interval (s) simulated on each side of a foreign record, outside the record the filter keeps.
FOREIGN_RECORD_GUARD = 0.05


@dataclass(frozen=True)
class ForeignGears:
    """One gear set's per-tooth profile errors: (z, 3) offset, slope, curvature (m) per wheel."""

    pinion: np.ndarray
    gear: np.ndarray

    def record(self) -> dict[str, list[list[float]]]:
        return {"pinion": self.pinion.tolist(), "gear": self.gear.tolist()}


def single_pitch_tolerance(design: Design, grade: float) -> tuple[float, float]:
    """ISO 1328-1 single pitch tolerance f_pt of pinion and gear at a grade, m (5: 0.3 (m + 0.4 sqrt d) + 4 um)."""
    module_mm = design.module * 1e3
    values = []
    for teeth in (design.z1, design.z2):
        diameter = module_mm * teeth
        base = 0.3 * (module_mm + 0.4 * math.sqrt(diameter)) + 4.0
        values.append(base * 2.0 ** ((grade - 5.0) / 2.0) * 1e-6)
    return values[0], values[1]


def draw_gears(design: Design, grade: float, seed: int | np.random.SeedSequence) -> ForeignGears:
    """A gear set of a quality grade: each tooth's offset (SD f_pt / 2), slope and curvature (SD f_pt / 4)."""
    rng = np.random.default_rng(as_seed_sequence(seed, error=RigDataError))
    tolerances = single_pitch_tolerance(design, grade)
    wheels = []
    for teeth, tolerance in zip((design.z1, design.z2), tolerances):
        scale = np.array([0.5, 0.25, 0.25]) * tolerance
        wheels.append(rng.standard_normal((teeth, 3)) * scale)
    return ForeignGears(wheels[0], wheels[1])


def contact_ratio(design: Design) -> float:
    """Transverse contact ratio of the pair from its tip and base circles (standard centre distance)."""
    alpha = math.radians(design.pressure_angle)
    r1, r2 = design.module * design.z1 / 2, design.module * design.z2 / 2
    ra1 = r1 + design.module * (design.addendum_coefficient + design.x1)
    ra2 = r2 + design.module * (design.addendum_coefficient + design.x2)
    rb1, rb2 = r1 * math.cos(alpha), r2 * math.cos(alpha)
    path = math.sqrt(ra1**2 - rb1**2) + math.sqrt(ra2**2 - rb2**2) - (r1 + r2) * math.sin(alpha)
    return float(np.clip(path / (math.pi * design.module * math.cos(alpha)), 1.05, 1.95))


@njit(cache=True)
def pair_sum(t, y, p, pin_err, gear_err, eff):  # pragma: no cover - compiled
    """Mesh force and the friction moments on pinion and gear at time t, state y.

    The mesh of the foreign plant, compiled, with the parameter vector of :func:`run_parameters`, the
    per-tooth pitch errors and the effect vector of :func:`effect_vector`; the steady runs, the
    run-ups and the response QoIs all evaluate it.
    """
    f_mesh, eps, kp, entry, z1, z2 = p[0], p[1], p[2], p[3], p[4], p[5]
    rb1, rb2, r1s, r2s, path = p[6], p[7], p[8], p[9], p[10]
    approach = rb1 * y[1] - rb2 * y[2] - y[4] + y[5]
    velocity = rb1 * y[9] - rb2 * y[10] - y[12] + y[13]
    ecc_shaft, ecc_amp, ecc_phase, ecc_kappa = eff[0], eff[1], eff[2], eff[3]
    dmg_gear, dmg_tooth, dmg_depth, mu = eff[4], eff[5], eff[6], eff[7]
    w1 = 2.0 * math.pi * f_mesh / z1
    ws = w1 if ecc_shaft == 0 else w1 * z1 / z2
    run_out = ecc_amp * math.sin(ws * t + ecc_phase)
    modulation = 1.0 + ecc_kappa * math.cos(ws * t + ecc_phase)
    phase = f_mesh * t
    newest = math.floor(phase)
    force = 0.0
    m1 = 0.0
    m2 = 0.0
    for back in range(3):
        n = newest - back
        s = phase - n
        if s >= eps:
            continue
        u = s / eps
        k = kp * (entry + (1.0 - entry) * math.sin(math.pi * u)) * modulation
        i = int(n % z1)
        j = int(n % z2)
        if dmg_depth > 0.0 and ((dmg_gear == 0 and i == int(dmg_tooth)) or (dmg_gear == 1 and j == int(dmg_tooth))):
            k *= 1.0 - dmg_depth
        v = u - 0.5
        err = (
            pin_err[i, 0]
            + pin_err[i, 1] * v
            + pin_err[i, 2] * (v * v - 1.0 / 12.0)
            + gear_err[j, 0]
            + gear_err[j, 1] * v
            + gear_err[j, 2] * (v * v - 1.0 / 12.0)
        )
        delta = approach + err + run_out
        if delta <= 0.0:
            continue
        f = k * delta + p[11] * k * velocity
        if f <= 0.0:
            continue
        force += f
        if mu > 0.0:
            # sliding reverses at the pitch point, midway along the path; arms from each wheel's interference point
            x = (u - 0.5) * path
            sign = 1.0 if x > 0.0 else -1.0
            m1 -= mu * f * sign * (r1s + x)
            m2 += mu * f * sign * (r2s - x)
    return force, m1, m2


@njit(cache=True)
def plant_derivative(y, p, eff, force, m1, m2, motor, load, out):  # pragma: no cover - compiled
    """The plant's equations of motion given the mesh's force and moments and the motor and load torques.

    Written once for every drive of the plant: the speed held at a constant set-point
    (:func:`_derivative`) and the set-point along a ramp (:mod:`.foreign_runup`). ``out`` receives the
    derivative of the state (angles of motor, pinion, gear and load; wheel centres and housings along the
    line of action; then their rates).
    """
    rb1, rb2 = p[6], p[7]
    jm, j1, j2, jl, ma, mb, mh1, mh2 = p[12], p[13], p[14], p[15], p[16], p[17], p[18], p[19]
    ks1, cs1, ks2, cs2 = p[20], p[21], p[22], p[23]
    kb1, cb1, kb2, cb2, kh1, ch1, kh2, ch2 = p[24], p[25], p[26], p[27], p[28], p[29], p[30], p[31]
    clear_which, clearance = eff[14], eff[15]
    shaft1 = ks1 * (y[0] - y[1]) + cs1 * (y[8] - y[9])
    shaft2 = ks2 * (y[2] - y[3]) + cs2 * (y[10] - y[11])
    d1 = y[4] - y[6]
    d2 = y[5] - y[7]
    if clearance > 0.0:
        if clear_which == 0 or clear_which == 2:
            d1 = d1 - clearance if d1 > clearance else (d1 + clearance if d1 < -clearance else 0.0)
        if clear_which == 1 or clear_which == 2:
            d2 = d2 - clearance if d2 > clearance else (d2 + clearance if d2 < -clearance else 0.0)
    bearing1 = kb1 * d1 + cb1 * (y[12] - y[14])
    bearing2 = kb2 * d2 + cb2 * (y[13] - y[15])
    for k in range(8):
        out[k] = y[8 + k]
    out[8] = (motor - shaft1) / jm
    out[9] = (shaft1 - rb1 * force + m1) / j1
    out[10] = (rb2 * force - shaft2 + m2) / j2
    out[11] = (shaft2 - load) / jl
    out[12] = (force - bearing1) / ma
    out[13] = (-force - bearing2) / mb
    out[14] = (bearing1 - kh1 * y[6] - ch1 * y[14]) / mh1
    out[15] = (bearing2 - kh2 * y[7] - ch2 * y[15]) / mh2


@njit(cache=True)
def _derivative(t, y, p, pin_err, gear_err, eff, out):  # pragma: no cover - compiled
    """The plant held at the constant speed p[36] (rad/s) by its speed controller."""
    force, m1, m2 = pair_sum(t, y, p, pin_err, gear_err, eff)
    kc, cc, t1, t2, omega = p[32], p[33], p[34], p[35], p[36]
    ripple_amp, ripple_order, ripple_phase = eff[8], eff[9], eff[10]
    adh_amp, adh_freq, adh_phase = eff[11], eff[12], eff[13]
    motor = t1 * (1.0 + ripple_amp * math.cos(ripple_order * omega * t + ripple_phase))
    motor += kc * (omega * t - y[0]) + cc * (omega - y[8])
    load = t2 * (1.0 + adh_amp * math.sin(2.0 * math.pi * adh_freq * t + adh_phase))
    plant_derivative(y, p, eff, force, m1, m2, motor, load, out)


@njit(cache=True)
def rk4_step(t, y, p, pin_err, gear_err, eff, step, work):  # pragma: no cover - compiled
    """One fourth-order Runge-Kutta step of the state ``y`` (in place) from time t; ``work`` (5, state) is scratch.

    The step of the foreign plant held at a constant speed set-point, compiled; ``step`` is the time
    step in s and ``y`` has :data:`N_STATE` entries.
    """
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    _derivative(t, y, p, pin_err, gear_err, eff, k1)
    for k in range(N_STATE):
        tmp[k] = y[k] + 0.5 * step * k1[k]
    _derivative(t + 0.5 * step, tmp, p, pin_err, gear_err, eff, k2)
    for k in range(N_STATE):
        tmp[k] = y[k] + 0.5 * step * k2[k]
    _derivative(t + 0.5 * step, tmp, p, pin_err, gear_err, eff, k3)
    for k in range(N_STATE):
        tmp[k] = y[k] + step * k3[k]
    _derivative(t + step, tmp, p, pin_err, gear_err, eff, k4)
    for k in range(N_STATE):
        y[k] += step / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k])


@njit(cache=True)
def _integrate(y0, p, pin_err, gear_err, eff, step, n_out, per_out):  # pragma: no cover - compiled
    """RK4 from t = 0; returns (n_out, 6): encoder TE, housing accelerations at pinion and gear, time, and the
    bearing deflections (wheel centre less housing) at pinion and gear."""
    y = y0.copy()
    work = np.empty((5, N_STATE))
    k1 = work[0]
    out = np.empty((n_out, 6))
    t = 0.0
    for index in range(n_out):
        for _ in range(per_out):
            rk4_step(t, y, p, pin_err, gear_err, eff, step, work)
            t += step
        _derivative(t, y, p, pin_err, gear_err, eff, k1)
        out[index, 0] = p[6] * y[1] - p[7] * y[2]
        out[index, 1] = k1[14]
        out[index, 2] = k1[15]
        out[index, 3] = t
        out[index, 4] = y[4] - y[6]
        out[index, 5] = y[5] - y[7]
    return out


#: How an effect's values enter the compiled effect vector: ``encoder(values, design, eff)`` writes its slots.
EffectEncoder = Callable[[Mapping[str, Any], Design, np.ndarray], None]

# the foreign physics of each effect, by effect name (register_foreign_physics)
_ENCODERS: dict[str, EffectEncoder] = {}


def register_foreign_physics(effect: type[Effect]) -> Callable[[EffectEncoder], EffectEncoder]:
    """Give an effect its physics on the foreign rig: a decorator for the function that writes its slots.

    The compiled model has fixed slots (``eff``, 16 values: run-out 0-3,
    damaged tooth 4-6, friction 7, drive torque ripple 8-10, load torque
    oscillation 11-13, bearing clearance 14-15); the encoder writes the
    effect's values into the slots of the physics it shares. An effect with
    no encoder is refused by :func:`simulate_foreign_campaign`.

    Parameters
    ----------
    effect : type of Effect
        The physics effect (its ``name`` keys the registry).

    Returns
    -------
    callable
        The decorator; it registers the encoder and returns it unchanged.

    Examples
    --------
    A drive-torque fluctuation at twice the pinion's rotation, on the drive torque ripple's slots:

    >>> import math
    >>> from uqgear.physics.effects import Effect, EffectParameter
    >>> from uqgear.rig.foreign_rig import effect_vector, register_foreign_physics
    >>> class Cardan(Effect):
    ...     name = "cardan_example"
    ...     PARAMETERS = {"amplitude": EffectParameter(0.02, 0.0, 0.5, "1", "relative fluctuation")}
    >>> @register_foreign_physics(Cardan)
    ... def _cardan(values, design, eff):
    ...     eff[8:11] = (values["amplitude"], 2.0, 0.0)
    >>> effect_vector([Cardan({"amplitude": 0.05})], None)[8:11].tolist()
    [0.05, 2.0, 0.0]
    """

    def register(encoder: EffectEncoder) -> EffectEncoder:
        _ENCODERS[effect.name] = encoder
        return encoder

    return register


@register_foreign_physics(Eccentricity)
def _eccentricity(v: Mapping[str, Any], design: Design, eff: np.ndarray) -> None:
    eff[0:4] = (
        0 if v.get("shaft", "pinion") == "pinion" else 1,
        v.get("amplitude", 10e-6),
        v.get("phase", 0.0),
        v.get("kappa", 0.0),
    )


@register_foreign_physics(ToothDamage)
def _tooth_damage(v: Mapping[str, Any], design: Design, eff: np.ndarray) -> None:
    eff[4:7] = (0 if v.get("gear", "pinion") == "pinion" else 1, v.get("tooth", 0.0), v.get("depth", 0.3))


@register_foreign_physics(Friction)
def _friction(v: Mapping[str, Any], design: Design, eff: np.ndarray) -> None:
    eff[7] = v.get("coefficient", 0.05)


@register_foreign_physics(TorqueRipple)
def _torque_ripple(v: Mapping[str, Any], design: Design, eff: np.ndarray) -> None:
    pole_pairs = int(v.get("pole_pairs", 0)) or int(design.motor_pole_pairs or 3)
    eff[8:11] = (v.get("amplitude", 0.05), 6.0 * pole_pairs, v.get("phase", 0.0))


@register_foreign_physics(AdhesionOscillation)
def _adhesion_oscillation(v: Mapping[str, Any], design: Design, eff: np.ndarray) -> None:
    eff[11:14] = (v.get("amplitude", 0.05), v.get("frequency", 12.0), v.get("phase", 0.0))


@register_foreign_physics(BearingClearance)
def _bearing_clearance(v: Mapping[str, Any], design: Design, eff: np.ndarray) -> None:
    eff[14:16] = ({"pinion": 0, "gear": 1, "both": 2}[v.get("bearing", "pinion")], v.get("clearance", 10e-6))


def effect_vector(effects: Sequence[Effect], design: Design) -> np.ndarray:
    """The effects' parameters in the compiled layout (zeros: absent), each written by its registered encoder.

    Raises
    ------
    RigDataError
        An effect with no physics on the foreign rig (:func:`register_foreign_physics`).

    Examples
    --------
    >>> from uqgear.physics.effects import Friction
    >>> from uqgear.rig.foreign_rig import effect_vector
    >>> float(effect_vector([Friction({"coefficient": 0.08})], None)[7])
    0.08
    """
    eff = np.zeros(16)
    for effect in effects:
        encoder = _ENCODERS.get(effect.name)
        if encoder is None:
            raise RigDataError(f"effects: the foreign rig has no physics for {effect.name!r}")
        encoder(effect.values, design, eff)
    return eff


def run_parameters(design: Design, speed: float, drive_torque: float, load_torque: float) -> tuple[np.ndarray, float]:
    """The compiled parameter vector of one run and the frequency of its fastest mode, Hz.

    ``speed`` in rpm, the torques in N m; the vector is what :func:`pair_sum`, :func:`rk4_step` and
    :func:`plant_derivative` read, the fastest mode sets the time step (:func:`time_step`).
    """
    alpha = math.radians(design.pressure_angle)
    r1, r2 = design.module * design.z1 / 2, design.module * design.z2 / 2
    rb1, rb2 = r1 * math.cos(alpha), r2 * math.cos(alpha)
    eps = contact_ratio(design)
    kp = PAIR_STIFFNESS_PER_WIDTH * design.face_width
    k_mean = kp * eps * (PAIR_ENTRY_SHARE + (1 - PAIR_ENTRY_SHARE) * 2 / math.pi)
    j1, j2 = design.I1, design.I2
    jm, jl = MOTOR_INERTIA_FACTOR * j1, LOAD_INERTIA_FACTOR * j2
    ma, mb = design.m1, design.m2
    mh1, mh2 = HOUSING_MASS_SHARE * ma, HOUSING_MASS_SHARE * mb
    kb1, kb2 = design.k1, design.k2
    kh1 = mh1 * (2 * math.pi * HOUSING_FREQUENCY_FACTOR[0] * math.sqrt(kb1 / ma) / (2 * math.pi)) ** 2
    kh2 = mh2 * (2 * math.pi * HOUSING_FREQUENCY_FACTOR[1] * math.sqrt(kb2 / mb) / (2 * math.pi)) ** 2
    torsion = k_mean * rb1**2
    ks1, ks2 = SHAFT_STIFFNESS_FACTOR[0] * torsion, SHAFT_STIFFNESS_FACTOR[1] * torsion * (r2 / r1) ** 2
    zeta = design.zeta_mesh
    mass_mesh = 1.0 / (rb1**2 / j1 + rb2**2 / j2)
    omega_mesh = math.sqrt(k_mean / mass_mesh)
    cs1 = 2 * zeta * math.sqrt(ks1 * jm * j1 / (jm + j1))
    cs2 = 2 * zeta * math.sqrt(ks2 * j2 * jl / (j2 + jl))
    cb1, cb2 = 2 * design.zeta1 * math.sqrt(kb1 * ma), 2 * design.zeta2 * math.sqrt(kb2 * mb)
    ch1, ch2 = 2 * 0.03 * math.sqrt(kh1 * mh1), 2 * 0.03 * math.sqrt(kh2 * mh2)
    j_total = jm + j1 + (j2 + jl) * (design.z1 / design.z2) ** 2
    w_c = 2 * math.pi * CONTROLLER_BANDWIDTH
    omega = 2 * math.pi * speed / 60.0
    f_mesh = design.z1 * speed / 60.0
    p = np.array(
        [
            f_mesh,
            eps,
            kp,
            PAIR_ENTRY_SHARE,
            design.z1,
            design.z2,
            rb1,
            rb2,
            r1 * math.sin(alpha),
            r2 * math.sin(alpha),
            eps * math.pi * design.module * math.cos(alpha),
            2 * zeta / omega_mesh,
            jm,
            j1,
            j2,
            jl,
            ma,
            mb,
            mh1,
            mh2,
            ks1,
            cs1,
            ks2,
            cs2,
            kb1,
            cb1,
            kb2,
            cb2,
            kh1,
            ch1,
            kh2,
            ch2,
            j_total * w_c**2,
            2 * 0.7 * j_total * w_c,
            drive_torque,
            load_torque,
            omega,
        ]
    )
    fastest = max(
        math.sqrt((k_mean + kb1) / ma),
        math.sqrt((k_mean + kb2) / mb),
        math.sqrt((kb1 + kh1) / mh1),
        math.sqrt((kb2 + kh2) / mh2),
        omega_mesh,
        math.sqrt(ks1 / jm + ks1 / j1),
    ) / (2 * math.pi)
    return p, 1.5 * fastest


#: Names of the entries 12-35 of the compiled parameter vector: inertias (kg m2), masses (kg), stiffnesses (N m/rad,
#: N/m; the controller's as a torsional spring to the commanded angle) and dampings of the 8-DOF gearbox.
PLANT_NAMES = (
    *("jm", "j1", "j2", "jl", "ma", "mb", "mh1", "mh2", "ks1", "cs1", "ks2", "cs2"),
    *("kb1", "cb1", "kb2", "cb2", "kh1", "ch1", "kh2", "ch2", "kc", "cc"),
)


def plant_parameters(design: Design) -> dict[str, float]:
    """The foreign rig's physical constants for a design: :data:`PLANT_NAMES`, base radii and mean mesh stiffness.

    Examples
    --------
    >>> from uqgear.physics.design import load_design
    >>> plant = plant_parameters(load_design("locomotive"))
    >>> round(plant["k_mean"] / 1e9, 2), plant["kb1"] == load_design("locomotive").k1
    (2.42, True)
    """
    p, _ = run_parameters(design, 1000.0, 1.0, 1.0)
    plant = dict(zip(PLANT_NAMES, (float(v) for v in p[12:34])))
    k_mean = p[2] * p[1] * (PAIR_ENTRY_SHARE + (1 - PAIR_ENTRY_SHARE) * 2 / math.pi)
    return {**plant, "rb1": float(p[6]), "rb2": float(p[7]), "k_mean": float(k_mean)}


def time_step(fastest: float, rate: float) -> tuple[int, float]:
    """Integration steps per output sample and the step, s: a fortieth of the fastest mode's period or finer.

    Examples
    --------
    >>> time_step(4000.0, 81920.0)
    (2, 6.103515625e-06)
    """
    per_out = max(1, int(math.ceil(40.0 * fastest / rate)))
    return per_out, 1.0 / (rate * per_out)


def static_state(p: np.ndarray, design: Design) -> np.ndarray:
    """Start near the loaded static state at nominal speed (the run-in settles the rest).

    ``p`` is the parameter vector of :func:`run_parameters`; the state has :data:`N_STATE` entries,
    the initial state of the steady runs and the run-ups alike.
    """
    rb1, rb2, kp, eps = p[6], p[7], p[2], p[1]
    k_mean = kp * eps * (PAIR_ENTRY_SHARE + (1 - PAIR_ENTRY_SHARE) * 2 / math.pi)
    force = p[34] / rb1
    y = np.zeros(N_STATE)
    h1, h2 = force / p[28], -force / p[30]
    y1, y2 = h1 + force / p[24], h2 - force / p[26]
    theta1 = -p[34] / p[20]
    theta2 = (rb1 * theta1 - force / k_mean - y1 + y2) / rb2
    y[:8] = (0.0, theta1, theta2, theta2 - rb2 * force / p[22], y1, y2, h1, h2)
    omega = p[36]
    y[8:12] = (omega, omega, omega * design.z1 / design.z2, omega * design.z1 / design.z2)
    return y


def simulate_foreign_run(
    design: Design,
    speed: float,
    drive_torque: float,
    load_torque: float,
    *,
    gears: ForeignGears,
    effects: Sequence[Effect] = (),
    fs: float = 20480.0,
    duration: float = 0.5,
    start: float = 0.3,
    bearings: bool = False,
) -> dict[str, np.ndarray]:
    """Clean records (te in m, housing accelerations in m s-2) of one run on the ``fs`` grid from ``start``.

    With ``bearings``, also each bearing's deflection (wheel centre less housing along the line of action, m;
    unfiltered) as ``bearing_pinion`` and ``bearing_gear``: where a clearance c is set, the bearing carries no
    force while its deflection is within +-c.
    """
    p, fastest = run_parameters(design, speed, drive_torque, load_torque)
    rate = 4.0 * fs
    per_out, step = time_step(fastest, rate)
    first = int(round((start - FOREIGN_RECORD_GUARD) * rate))
    size = int(round((duration + 2 * FOREIGN_RECORD_GUARD) * rate))
    n_out = first + size
    out = _integrate(
        static_state(p, design), p, gears.pinion, gears.gear, effect_vector(effects, design), step, n_out, per_out
    )[first:]
    passband, stopband = fs / 2.56, fs / 2.0
    records = {}
    n_samples = int(round(duration * fs))
    guard = int(round(FOREIGN_RECORD_GUARD * rate))
    for column, name in ((0, "te"), (1, "acc_pinion"), (2, "acc_gear")):
        signal = out[:, column] - out[:, column].mean()
        filtered = np.fft.irfft(np.fft.rfft(signal) * frequency_filter(size, rate, passband, stopband, 0), n=size)
        records[name] = filtered[guard : guard + 4 * n_samples : 4]
    if bearings:
        records.update(bearing_pinion=out[guard : guard + 4 * n_samples : 4, 4].copy())
        records["bearing_gear"] = out[guard : guard + 4 * n_samples : 4, 5].copy()
    return records


def simulate_foreign_campaign(
    design: Design,
    operating_points: xr.Dataset,
    *,
    gears: ForeignGears,
    effects: Sequence[Effect] = (),
    seed: int | np.random.SeedSequence = 0,
    fs: float = 20480.0,
    duration: float = 0.5,
    run_in: float = 0.3,
    relative_noise: float = 0.02,
    title: str = "",
) -> xr.Dataset:
    """A campaign of the foreign rig at each operating point (``uqgear-rig/1``, the nominal design stated).

    Each run starts at ``run_in`` plus a random fraction of a pinion
    revolution; white noise of ``relative_noise`` times each clean record's
    RMS is added per channel. T2 is the middle of each run's stated
    interval. The gears, the effects and the seed are kept in the
    attributes ``foreign_gears``, ``effects`` and ``seed_entropy``.

    Examples
    --------
    >>> from uqgear.physics.design import load_design
    >>> from uqgear.rig.virtual_rig import default_operating_points
    >>> design = load_design("locomotive")
    >>> ops = default_operating_points(design).isel(op=[0, 4])
    >>> rig = simulate_foreign_campaign(design, ops, gears=draw_gears(design, 6, 1), duration=0.2)
    >>> sorted(rig.data_vars)
    ['acc_gear', 'acc_pinion', 'te']
    """
    sequence = as_seed_sequence(seed, error=RigDataError)
    speeds = np.asarray(operating_points["pinion_speed"].values, dtype=float)
    torques = np.asarray(operating_points["drive_torque"].values, dtype=float)
    lower = np.asarray(operating_points["adhesion_torque_lower"].values, dtype=float)
    upper = np.asarray(operating_points["adhesion_torque_upper"].values, dtype=float)
    n_samples = int(round(duration * fs))
    data = {name: np.empty((speeds.size, n_samples)) for name in ("te", "acc_pinion", "acc_gear")}
    for op, speed in enumerate(speeds):
        run_seed = child_seed(sequence, 1 + op)
        rng = np.random.default_rng(run_seed)
        start = run_in + rng.uniform(0.0, 60.0 / speed)
        clean = simulate_foreign_run(
            design,
            speed,
            torques[op],
            0.5 * (lower[op] + upper[op]),
            gears=gears,
            effects=effects,
            fs=fs,
            duration=duration,
            start=start,
        )
        for name, record in clean.items():
            sigma = relative_noise * float(np.std(record))
            noisy = record + sigma * rng.standard_normal(n_samples)
            data[name][op] = noisy - noisy.mean()
    stamp = datetime.now(UTC).isoformat(timespec="seconds")
    ds = make_rig_dataset(
        time=np.arange(n_samples) / fs,
        pinion_speed=speeds,
        drive_torque=torques,
        adhesion_torque_lower=lower,
        adhesion_torque_upper=upper,
        channels=data,
        design=design,
        title=title or "uqgear foreign virtual rig",
        source="uqgear foreign virtual rig: 8-DOF gearbox (motor, shafts, housing modes), half-sine pair stiffness, "
        "per-tooth profile errors; not the diagnosis model",
        history=f"{stamp}: simulated by uqgear.rig.foreign_rig.simulate_foreign_campaign",
    )
    ds.attrs.update(
        effects=json.dumps([{"name": e.name, "values": dict(e.values)} for e in effects]),
        foreign_gears=json.dumps(gears.record()),
        seed_entropy=str(sequence.entropy),
    )
    return ds


__all__ = [
    "PLANT_NAMES",
    "ForeignGears",
    "contact_ratio",
    "EffectEncoder",
    "draw_gears",
    "effect_vector",
    "plant_parameters",
    "N_STATE",
    "FOREIGN_RECORD_GUARD",
    "pair_sum",
    "plant_derivative",
    "rk4_step",
    "run_parameters",
    "static_state",
    "register_foreign_physics",
    "simulate_foreign_campaign",
    "simulate_foreign_run",
    "single_pitch_tolerance",
    "time_step",
]
