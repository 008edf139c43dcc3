"""The dynamic factor K_v of ISO 6336-1 method B for spur gears.

ISO's K_v is a single-degree-of-freedom estimate: the pair's resonance speed
n_E1 follows from the mesh stiffness c_gamma_alpha and the reduced mass of
the two gear bodies; the pinion speed over n_E1 (the resonance ratio N) puts
the operating point in one of four ranges, each with its formula in the
pitch and profile deviations (B_p, B_f) and the tip relief (B_k):

- subcritical, N <= N_S: K_v = N K + 1, K = C_v1 B_p + C_v2 B_f + C_v3 B_k;
- main resonance, N_S < N <= 1.15: K_v = C_v1 B_p + C_v2 B_f + C_v4 B_k + 1;
- intermediate, 1.15 < N < 1.5: linear between the main resonance's value at 1.15 and the supercritical one at 1.5;
- supercritical, N >= 1.5: K_v = C_v5 B_p + C_v6 B_f + C_v7.

N_S = 0.85, or 0.5 + 0.35 sqrt(K_A F_t / (100 b)) where the line load K_A F_t / b is below 100 N/mm.
The deviations are the ISO 1328-1 tolerances of the settings' accuracy grade
less the running-in allowance of case-hardened steel (y_alpha = 0.075 f_pb, at most 3 um);
without a stated tip relief, C_a is the running-in relief C_ay of ISO 6336-1.
Speeds in rpm, forces in N, lengths in m unless a name says otherwise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..geometry import pair_geometry
from ..model import equivalent_mass
from ..pitch_errors import iso1328_single_pitch_tolerance
from ..stiffness import iso6336_stiffness
from .settings import RatingSettings

#: Names of the speed ranges, in order of the resonance ratio.
SPEED_RANGES = ("subcritical", "main_resonance", "intermediate", "supercritical")
#: Where the main resonance range ends and the supercritical begins (resonance ratio N).
MAIN_RESONANCE_END, SUPERCRITICAL_START = 1.15, 1.5


@dataclass(frozen=True)
class DynamicFactorModel:
    """ISO 6336-1 method B's dynamic factor of one design at one drive torque.

    Attributes
    ----------
    resonance_speed : float
        n_E1, pinion rpm.
    reduced_mass : float
        m_red per unit face width, kg/m.
    mesh_stiffness : float
        c_gamma_alpha, N/(mm um).
    single_pair_stiffness : float
        c', N/(mm um).
    line_load : float
        K_A F_t / b, N/mm.
    lower_limit : float
        N_S, the end of the subcritical range.
    b_p, b_f, b_k : float
        The non-dimensional pitch, profile and tip-relief parameters.
    c_v : tuple of float
        C_v1 .. C_v7.
    """

    resonance_speed: float
    reduced_mass: float
    mesh_stiffness: float
    single_pair_stiffness: float
    line_load: float
    lower_limit: float
    b_p: float
    b_f: float
    b_k: float
    c_v: tuple[float, ...]

    def _main(self) -> float:
        c = self.c_v
        return c[0] * self.b_p + c[1] * self.b_f + c[3] * self.b_k + 1.0

    def _super(self) -> float:
        c = self.c_v
        return c[4] * self.b_p + c[5] * self.b_f + c[6]

    def ratio(self, pinion_speed):
        """Resonance ratio N = n1 / n_E1."""
        return np.asarray(pinion_speed, dtype=float) / self.resonance_speed

    def speed_range(self, pinion_speed) -> np.ndarray:
        """The name of the speed range (:data:`SPEED_RANGES`) at each pinion speed."""
        n = np.atleast_1d(self.ratio(pinion_speed))
        index = np.select(
            [n <= self.lower_limit, n <= MAIN_RESONANCE_END, n < SUPERCRITICAL_START], [0, 1, 2], default=3
        )
        return np.asarray(SPEED_RANGES)[index]

    def factor(self, pinion_speed):
        """K_v at pinion speed(s) in rpm."""
        n = np.asarray(self.ratio(pinion_speed), dtype=float)
        c = self.c_v
        k = c[0] * self.b_p + c[1] * self.b_f + c[2] * self.b_k
        main, supercritical = self._main(), self._super()
        intermediate = supercritical + (main - supercritical) / (SUPERCRITICAL_START - MAIN_RESONANCE_END) * (
            SUPERCRITICAL_START - n
        )
        value = np.select(
            [n <= self.lower_limit, n <= MAIN_RESONANCE_END, n < SUPERCRITICAL_START],
            [n * k + 1.0, main, intermediate],
            default=supercritical,
        )
        return float(value) if value.ndim == 0 else value


def _c_v(contact_ratio: float) -> tuple[float, ...]:
    """C_v1 .. C_v7 of ISO 6336-1 (table of method B) for a total contact ratio eps_gamma."""
    eps = contact_ratio
    if eps <= 2.0:
        first = (0.32, 0.34, 0.23, 0.90, 0.47, 0.47)
    else:
        first = (
            0.32,
            0.57 / (eps - 0.3),
            0.096 / (eps - 1.56),
            (0.57 - 0.05 * eps) / (eps - 1.44),
            0.47,
            0.12 / (eps - 1.74),
        )
    if eps <= 1.5:
        seventh = 0.75
    elif eps <= 2.5:
        seventh = 0.125 * math.sin(math.pi * (eps - 2.0)) + 0.875
    else:
        seventh = 1.0
    return (*first, seventh)


def solid_blank_reduced_mass(design, density: float = 7830.0) -> float:
    """ISO 6336-1's reduced mass per unit face width of two solid gear blanks, kg/m (for comparison).

    The rating uses the design's own inertias (:func:`dynamic_factor_model`); this is what ISO
    takes where they are not known: m_red = (pi/8) (d_m1/d_b1)^2 d_m1^2 / (1/rho + 1/(rho u^2)).
    """
    geometry = pair_geometry(design)
    d_m1 = geometry.pinion.tip_radius + geometry.pinion.root_radius
    d_b1 = 2.0 * geometry.pinion.base_radius
    u = design.z2 / design.z1
    return math.pi / 8.0 * (d_m1 / d_b1) ** 2 * d_m1**2 / (1.0 / density + 1.0 / (density * u**2))


def dynamic_factor_model(design, drive_torque: float, settings: RatingSettings | None = None) -> DynamicFactorModel:
    """ISO 6336-1 method B's dynamic factor for a design at a drive torque (pinion, N m).

    The reduced mass is the design's own (its inertias I1, I2 reduced to the
    line of action, the traction motor's rotor included), per unit face width;
    the stiffnesses are ISO's c' and c_gamma (:func:`~uqgear.physics.stiffness.iso6336_stiffness`).

    Examples
    --------
    >>> import uqgear
    >>> from uqgear.physics.rating import dynamic_factor_model
    >>> model = dynamic_factor_model(uqgear.load_design("locomotive"), 7000.0)
    >>> round(model.resonance_speed), round(model.line_load, 1)
    (2109, 592.6)
    >>> [str(name) for name in model.speed_range([1000.0, 2300.0, 3000.0, 4000.0])]
    ['subcritical', 'main_resonance', 'intermediate', 'supercritical']
    >>> [round(float(value), 3) for value in model.factor([1000.0, 2300.0, 4000.0])]
    [1.198, 2.056, 1.047]
    """
    settings = settings or RatingSettings()
    geometry = pair_geometry(design)
    iso = iso6336_stiffness(design, geometry)
    c_prime, c_gamma = iso["c_prime"], iso["c_gamma"]
    reduced_mass = equivalent_mass(design) / design.face_width
    # N/(mm um) is 1e9 N/m^2 (per metre of face width); kg/m over that gives s^2
    omega = math.sqrt(c_gamma * 1e9 / reduced_mass)
    resonance_speed = 60.0 * omega / (2.0 * math.pi * design.z1)
    tangential = drive_torque / geometry.pinion.pitch_radius
    line_load = settings.application_factor * tangential / (design.face_width * 1e3)
    lower = 0.85 if line_load >= 100.0 else 0.5 + 0.35 * math.sqrt(line_load / 100.0)
    grade = settings.accuracy_grade
    diameter = 2.0 * geometry.gear.pitch_radius
    f_pb = iso1328_single_pitch_tolerance(diameter, design.module, grade) * 1e6
    f_fa = (0.55 * design.module * 1e3 + 5.0) * math.sqrt(2.0) ** (grade - 5)
    running_in = min(0.075 * f_pb, 3.0)
    c_ay = (settings.material.sigma_Hlim / 1e6 / 97.0 - 18.45) ** 2 / 18.0 + 1.5
    return DynamicFactorModel(
        resonance_speed=resonance_speed,
        reduced_mass=reduced_mass,
        mesh_stiffness=c_gamma,
        single_pair_stiffness=c_prime,
        line_load=line_load,
        lower_limit=lower,
        b_p=c_prime * max(f_pb - running_in, 0.0) / line_load,
        b_f=c_prime * max(f_fa - running_in, 0.0) / line_load,
        b_k=abs(1.0 - c_prime * c_ay / line_load),
        c_v=_c_v(geometry.contact_ratio),
    )


__all__ = [
    "DynamicFactorModel",
    "dynamic_factor_model",
    "solid_blank_reduced_mass",
    "SPEED_RANGES",
    "MAIN_RESONANCE_END",
    "SUPERCRITICAL_START",
]
