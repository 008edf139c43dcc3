"""Time-varying mesh stiffness by the Ishikawa method, and the ISO 6336 anchor.

Each tooth is a cantilever from the root circle: a rectangle of thickness S_F
up to the effective root radius r_ff, then a trapezoid tapering to the tip
thickness S_k at the tip circle (docs/model/mesh-stiffness.md section 4). Thicknesses are chordal.
On an undercut tooth r_ff is the form radius (the involute's start), the
rectangle takes the undercut flank's narrowest section S_u < S_F, and load
points lie on the generated involute only (the path of contact starts at the
form circle where it limits, :func:`~uqgear.physics.geometry.pair_geometry`).
The shear term uses a shear factor ``shear_factor`` (1.0 by default: the
plain ``integral of F/(G A)`` of docs/model/mesh-stiffness.md; Timoshenko's 1.2 for rectangles is
available). One pair's compliance is the sum of both teeth's bending, shear
and foundation compliances plus the contact compliance.

The mesh stiffness over a mesh period is the sum over the pairs in contact.
The mesh phase ``u`` in [0, 1) counts mesh periods from the moment a pinion
tooth enters contact at the start of the path of contact A; pair ``i`` (i = 0
the newest) sits at path coordinate ``s = s_A + p_b (u + i)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import xarray as xr

from .geometry import PairGeometry, ToothGeometry, pair_geometry

#: ISO 6336-1 method B coefficients of q' (spur and helical gears).
_ISO_Q_COEFFICIENTS = (0.04723, 0.15551, 0.25791, -0.00635, -0.11654, -0.00193, -0.24188, 0.00529, 0.00182)


def tooth_compliance(
    tooth: ToothGeometry,
    contact_radius: np.ndarray,
    face_width: float,
    youngs_modulus: float,
    poisson_ratio: float,
    shear_factor: float = 1.0,
) -> dict[str, np.ndarray]:
    """Ishikawa compliances of one tooth loaded at ``contact_radius``.

    Parameters
    ----------
    tooth : ToothGeometry
    contact_radius : array
        Radii r_x of the load point, m.
    face_width, youngs_modulus, poisson_ratio : float
        B in m, E in Pa, nu.
    shear_factor : float
        Factor on the shear compliance (1.0: the form of docs/model/mesh-stiffness.md).

    Returns
    -------
    dict
        ``bending_rectangle``, ``bending_trapezoid``, ``shear``, ``foundation``
        and ``total`` compliances along the line of action, m/N.
    """
    r_x = np.asarray(contact_radius, dtype=float)
    s_f = float(tooth.chordal_thickness(tooth.effective_root_radius))
    s_k = float(tooth.chordal_thickness(tooth.tip_radius))
    # An undercut root is thinner than the involute at r_ff: the rectangle (and the foundation
    # under it) takes the undercut flank's narrowest section; the trapezoid keeps S_F.
    s_r = s_f if tooth.neck_thickness is None else min(float(tooth.neck_thickness), s_f)
    h_r = max(tooth.effective_root_radius - tooth.root_radius, 0.0)
    h_k = tooth.tip_radius - tooth.root_radius
    h_i = (s_f * h_k - s_k * h_r) / (s_f - s_k)
    length = h_i - h_r
    h_x = r_x - tooth.root_radius
    rho = (h_i - h_x) / length
    cos2 = np.cos(tooth.load_angle(r_x)) ** 2
    e_b = youngs_modulus * face_width
    bending_rectangle = 12.0 * cos2 / (e_b * s_r**3) * (h_x * h_r * (h_x - h_r) + h_r**3 / 3.0)
    bending_trapezoid = 6.0 * cos2 * length**3 / (e_b * s_f**3) * (rho * (4.0 - rho) - 2.0 * np.log(rho) - 3.0)
    if s_r == s_f:
        # one thickness: the form of docs/model/mesh-stiffness.md section 4.1, evaluated as written there
        shear = shear_factor * 2.0 * (1.0 + poisson_ratio) * cos2 / (e_b * s_f) * (h_r + length * np.log(1.0 / rho))
    else:
        shear = shear_factor * 2.0 * (1.0 + poisson_ratio) * cos2 / e_b * (h_r / s_r + length * np.log(1.0 / rho) / s_f)
    foundation = 24.0 * h_x**2 * cos2 / (math.pi * e_b * s_r**2)
    total = bending_rectangle + bending_trapezoid + shear + foundation
    return {
        "bending_rectangle": bending_rectangle,
        "bending_trapezoid": bending_trapezoid,
        "shear": shear,
        "foundation": foundation,
        "total": total,
    }


def contact_compliance(face_width: float, youngs_modulus: float, poisson_ratio: float) -> float:
    """Ishikawa's contact (Hertzian approach) compliance of one pair, m/N."""
    return 4.0 * (1.0 - poisson_ratio**2) / (math.pi * youngs_modulus * face_width)


def single_pair_stiffness(
    design, s: np.ndarray, geometry: PairGeometry | None = None, shear_factor: float = 1.0
) -> np.ndarray:
    """Stiffness of one tooth pair at path coordinates ``s`` (from T1), N/m."""
    geometry = geometry or pair_geometry(design)
    r1, r2 = geometry.contact_radii(s)
    args = (design.face_width, design.youngs_modulus, design.poisson_ratio, shear_factor)
    compliance = (
        tooth_compliance(geometry.pinion, r1, *args)["total"]
        + tooth_compliance(geometry.gear, r2, *args)["total"]
        + contact_compliance(design.face_width, design.youngs_modulus, design.poisson_ratio)
    )
    return 1.0 / compliance


def iso6336_stiffness(design, geometry: PairGeometry | None = None) -> dict[str, float]:
    """ISO 6336-1 (method B) single-pair stiffness c' and mesh stiffness c_gamma.

    Solid gear blanks (C_R = 1), C_M = 0.8, basic-rack factor C_B from the
    dedendum and pressure angle, spur gears (beta = 0).

    Returns
    -------
    dict
        ``c_prime`` and ``c_gamma`` in N/(mm um), and ``mesh_stiffness``
        = c_gamma x face width in N/m.

    Examples
    --------
    c_gamma follows from c' and the contact ratio (ISO 6336-1 eq. for
    spur gears), the mesh stiffness from c_gamma and the face width:

    >>> import uqgear
    >>> design = uqgear.load_design("locomotive")
    >>> iso = uqgear.iso6336_stiffness(design)
    >>> round(iso["c_prime"], 2), round(iso["c_gamma"], 2)
    (13.99, 20.82)
    >>> epsilon = uqgear.mesh_stiffness(design).attrs["contact_ratio"]
    >>> round(iso["c_prime"] * (0.75 * epsilon + 0.25), 2)
    20.82
    >>> print(f"{iso['mesh_stiffness']:.3e} N/m = {iso['c_gamma'] * design.face_width * 1e9:.3e} N/m")
    2.603e+09 N/m = 2.603e+09 N/m
    """
    geometry = geometry or pair_geometry(design)
    c = _ISO_Q_COEFFICIENTS
    z1, z2, x1, x2 = design.z1, design.z2, design.x1, design.x2
    q_prime = (
        c[0]
        + c[1] / z1
        + c[2] / z2
        + c[3] * x1
        + c[4] * x1 / z1
        + c[5] * x2
        + c[6] * x2 / z2
        + c[7] * x1**2
        + c[8] * x2**2
    )
    c_b = (1.0 + 0.5 * (1.2 - design.dedendum_coefficient)) * (1.0 - 0.02 * (20.0 - design.pressure_angle))
    c_prime = 0.8 * 1.0 * c_b / q_prime
    c_gamma = c_prime * (0.75 * geometry.contact_ratio + 0.25)
    # N/(mm um) x mm = N/um = 1e6 N/m
    return {"c_prime": c_prime, "c_gamma": c_gamma, "mesh_stiffness": c_gamma * design.face_width * 1e3 * 1e6}


@dataclass(frozen=True)
class StiffnessTables:
    """Tabulated stiffness for the integrators.

    Attributes
    ----------
    pair_position : ndarray
        Normalised path coordinate q = (s - s_A) / p_b of one pair, 0..eps.
    pair_stiffness : ndarray
        Single-pair stiffness at ``pair_position``, N/m.
    period_stiffness : ndarray
        Mesh stiffness k(u) on a uniform grid of u in [0, 1] (closed: the last
        value repeats the first period's end), N/m.
    contact_ratio : float
    k_mean : float
        Mean of the mesh stiffness over a period, N/m.
    """

    pair_position: np.ndarray
    pair_stiffness: np.ndarray
    period_stiffness: np.ndarray
    contact_ratio: float
    k_mean: float


def _period_grid(n_points: int) -> np.ndarray:
    return np.arange(n_points) / n_points


def _sum_pairs(phase: np.ndarray, contact_ratio: float, pair_k) -> tuple[np.ndarray, np.ndarray]:
    """Sum single-pair stiffness over the pairs in contact at mesh phases ``phase``."""
    total = np.zeros_like(phase)
    count = np.zeros(phase.shape, dtype=int)
    for i in range(int(math.ceil(contact_ratio)) + 1):
        q = phase + i
        inside = q < contact_ratio
        total[inside] += pair_k(q[inside])
        count += inside
    return total, count


def mesh_stiffness(design, *, n_points: int = 1024, n_harmonics: int = 15, shear_factor: float = 1.0) -> xr.Dataset:
    """Ishikawa mesh stiffness of a design over one mesh period.

    Parameters
    ----------
    design : Design
    n_points : int
        Samples over one mesh period (and along one pair's path of contact).
    n_harmonics : int
        Harmonics kept in the truncated Fourier series.
    shear_factor : float
        Factor on the shear compliance (1.0 as in docs/model/mesh-stiffness.md).

    Returns
    -------
    xarray.Dataset
        ``single_pair_stiffness`` (dim ``s``), the compliance components of
        each tooth (dims ``s``, ``component``), ``mesh_stiffness`` and
        ``mesh_stiffness_fourier`` and ``pairs_in_contact`` (dim
        ``mesh_phase``, with ``pinion_angle`` coordinate), Fourier
        coefficients (dim ``harmonic``). Attributes: ``k_mean``, ``k_min``,
        ``k_max`` (N/m), ``contact_ratio``, ``double_contact_fraction``,
        ISO 6336 ``iso_c_prime``, ``iso_c_gamma`` (N/(mm um)),
        ``iso_mesh_stiffness`` (N/m), ``shear_factor``, ``thickness``.

    Examples
    --------
    One or two tooth pairs carry the load; the share of the period with two
    is the contact ratio's fractional part:

    >>> import uqgear
    >>> stiffness = uqgear.mesh_stiffness(uqgear.load_design("locomotive"))
    >>> sorted(set(stiffness["pairs_in_contact"].values.tolist()))
    [1, 2]
    >>> round(stiffness.attrs["contact_ratio"], 3), round(stiffness.attrs["double_contact_fraction"], 3)
    (1.651, 0.651)
    >>> print(f"k_mean {stiffness.attrs['k_mean']:.3g} N/m, ISO 6336 {stiffness.attrs['iso_mesh_stiffness']:.3g} N/m")
    k_mean 3.03e+09 N/m, ISO 6336 2.6e+09 N/m
    >>> k = stiffness["mesh_stiffness"]
    >>> bool(k.min() >= stiffness.attrs["k_min"] * (1 - 1e-12)), round(float(k.mean()) / stiffness.attrs["k_mean"], 3)
    (True, 1.0)
    """
    geometry = pair_geometry(design)
    eps = geometry.contact_ratio
    s = np.linspace(geometry.contact_start, geometry.contact_end, n_points)
    r1, r2 = geometry.contact_radii(s)
    args = (design.face_width, design.youngs_modulus, design.poisson_ratio, shear_factor)
    pinion = tooth_compliance(geometry.pinion, r1, *args)
    gear = tooth_compliance(geometry.gear, r2, *args)
    d_contact = contact_compliance(design.face_width, design.youngs_modulus, design.poisson_ratio)
    k_pair = 1.0 / (pinion["total"] + gear["total"] + d_contact)
    q = (s - geometry.contact_start) / geometry.base_pitch

    def pair_k(position: np.ndarray) -> np.ndarray:
        return np.interp(position, q, k_pair)

    phase = _period_grid(n_points)
    k_period, count = _sum_pairs(phase, eps, pair_k)
    spectrum = np.fft.rfft(k_period) / n_points
    harmonics = np.arange(1, n_harmonics + 1)
    cos_coef = 2.0 * spectrum.real[1 : n_harmonics + 1]
    sin_coef = -2.0 * spectrum.imag[1 : n_harmonics + 1]
    k_mean = float(spectrum.real[0])
    angle = 2.0 * math.pi * np.outer(phase, harmonics)
    k_fourier = k_mean + np.cos(angle) @ cos_coef + np.sin(angle) @ sin_coef
    iso = iso6336_stiffness(design, geometry)
    components = ["bending_rectangle", "bending_trapezoid", "shear", "foundation"]
    ds = xr.Dataset(
        data_vars={
            "single_pair_stiffness": ("s", k_pair, {"units": "N m-1", "long_name": "single tooth-pair stiffness"}),
            "pinion_compliance": (
                ("s", "component"),
                np.stack([pinion[c] for c in components], axis=1),
                {"units": "m N-1", "long_name": "pinion tooth compliance components"},
            ),
            "gear_compliance": (
                ("s", "component"),
                np.stack([gear[c] for c in components], axis=1),
                {"units": "m N-1", "long_name": "gear tooth compliance components"},
            ),
            "mesh_stiffness": ("mesh_phase", k_period, {"units": "N m-1", "long_name": "mesh stiffness k (Ishikawa)"}),
            "mesh_stiffness_fourier": (
                "mesh_phase",
                k_fourier,
                {"units": "N m-1", "long_name": f"mesh stiffness, {n_harmonics}-harmonic Fourier series"},
            ),
            "pairs_in_contact": ("mesh_phase", count, {"units": "1", "long_name": "tooth pairs in contact"}),
            "fourier_cos": ("harmonic", cos_coef, {"units": "N m-1", "long_name": "cosine coefficients a_n of k(u)"}),
            "fourier_sin": ("harmonic", sin_coef, {"units": "N m-1", "long_name": "sine coefficients b_n of k(u)"}),
        },
        coords={
            "s": ("s", s, {"units": "m", "long_name": "path-of-contact coordinate from T1"}),
            "pair_position": ("s", q, {"units": "1", "long_name": "pair position (s - s_A)/p_b"}),
            "pinion_contact_radius": ("s", r1, {"units": "m"}),
            "gear_contact_radius": ("s", r2, {"units": "m"}),
            "component": components,
            "mesh_phase": ("mesh_phase", phase, {"units": "1", "long_name": "mesh phase (fraction of a mesh period)"}),
            "pinion_angle": ("mesh_phase", phase * 2.0 * math.pi / design.z1, {"units": "rad"}),
            "harmonic": harmonics,
        },
        attrs={
            "k_mean": k_mean,
            "k_min": float(k_period.min()),
            "k_max": float(k_period.max()),
            "contact_ratio": eps,
            "double_contact_fraction": float(np.mean(count >= 2)),
            "iso_c_prime": iso["c_prime"],
            "iso_c_gamma": iso["c_gamma"],
            "iso_mesh_stiffness": iso["mesh_stiffness"],
            "contact_compliance": d_contact,
            "shear_factor": shear_factor,
            "thickness": "chordal",
            "n_harmonics": n_harmonics,
            "method": "Ishikawa (rectangle + trapezoid cantilever, foundation, contact)",
        },
    )
    return ds


def stiffness_tables(
    design, *, n_points: int = 1024, mode: str = "ishikawa", n_harmonics: int = 15, shear_factor: float = 1.0
) -> StiffnessTables:
    """Tables of single-pair and period stiffness for the integrators.

    Parameters
    ----------
    mode : {"ishikawa", "fourier"}
        ``ishikawa``: the raw curve with its jumps where pairs enter and leave;
        ``fourier``: the truncated Fourier series (smooth).
    """
    ds = mesh_stiffness(design, n_points=n_points, n_harmonics=n_harmonics, shear_factor=shear_factor)
    if mode == "ishikawa":
        period = ds["mesh_stiffness"].values
    elif mode == "fourier":
        period = ds["mesh_stiffness_fourier"].values
    else:
        from ..common.errors import UqgearError

        raise UqgearError(f"stiffness: expected 'ishikawa' or 'fourier'; got {mode!r}")
    # close the table so linear interpolation on u in [0, 1] needs no wrap logic
    closed = np.append(period, period[0])
    return StiffnessTables(
        pair_position=ds["pair_position"].values.copy(),
        pair_stiffness=ds["single_pair_stiffness"].values.copy(),
        period_stiffness=closed,
        contact_ratio=ds.attrs["contact_ratio"],
        k_mean=ds.attrs["k_mean"],
    )


__all__ = [
    "tooth_compliance",
    "contact_compliance",
    "single_pair_stiffness",
    "iso6336_stiffness",
    "mesh_stiffness",
    "stiffness_tables",
    "StiffnessTables",
]
