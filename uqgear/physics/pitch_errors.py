"""Per-tooth pitch errors: the normal state of a manufactured gear (docs/model/equations.md section 2.6).

A :class:`PitchErrors` holds one displacement per tooth of the pinion and of
the gear along the line of action; :func:`~uqgear.physics.model.build_model`
puts them into the pair loop of the kernels, where the pair of pinion tooth
i and gear tooth j deflects by ``x - (e_pinion[i] + e_gear[j])``.

:func:`iso1328_single_pitch_tolerance` gives the tolerance f_pT of ISO
1328-1:2013 and :func:`draw_pitch_errors` draws the pitch errors of a pair
made to a flank tolerance class. Pitch errors are not an effect of the
diagnosis library (every gear has them): they are an input of the model set-up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import overload

import numpy as np
from numpy.typing import ArrayLike

from ..common.errors import OperatingPointError
from .design import Design

#: Flank tolerance classes of ISO 1328-1:2013 (1 finest .. 11 coarsest).
ISO1328_CLASSES = tuple(range(1, 12))

#: Largest pitch offset accepted, m: 1 mm is far beyond ISO class 11 for any module this model takes.
MAX_PITCH_OFFSET = 1e-3

#: Class at which pitch errors are drawn before being scaled to another (tolerances grow by sqrt(2) a class).
REFERENCE_CLASS = 7

#: ISO 1328-1 classes (lowest, highest) assumed for a rig's gears when none are stated: the usual range of
#: traction gears.
DEFAULT_CLASSES: tuple[float, float] = (6.0, 8.0)


def _per_tooth(name: str, values: ArrayLike, teeth: int | None) -> np.ndarray:
    try:
        array = np.array(values, dtype=float)
    except (TypeError, ValueError):
        raise OperatingPointError(f"{name}: expected one pitch offset per tooth in m; got {values!r:.80}") from None
    if array.ndim != 1 or array.size == 0:
        raise OperatingPointError(f"{name}: expected a 1-D array of per-tooth offsets in m; got shape {array.shape}")
    if teeth is not None and array.size != teeth:
        raise OperatingPointError(f"{name}: expected {teeth} values (one per tooth); got {array.size}")
    bad = ~np.isfinite(array) | (np.abs(array) > MAX_PITCH_OFFSET)
    if np.any(bad):
        index = int(np.argmax(bad))
        raise OperatingPointError(
            f"{name}[{index}]: expected a finite offset within +-{MAX_PITCH_OFFSET:g} m "
            f"(SI metres: 10 um is 1e-5); got {array[index]!r}"
        )
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class PitchErrors:
    """Per-tooth pitch offsets along the line of action, m.

    Parameters
    ----------
    pinion, gear : array_like
        One value per tooth (z1 and z2 of them), tooth 0 being the one that
        enters contact at t = 0 (numbering as for ``tooth_damage``). A
        positive value delays that tooth's drive-side contact: the pair's
        deflection is ``x - (e_pinion[i] + e_gear[j])``, so it comes into
        contact later and carries less load under drive, and touches earlier
        on the back side (the whole tooth is displaced, both flanks).

    Raises
    ------
    OperatingPointError
        An offset that is not finite, above 1 mm, or not a 1-D array,
        named as ``pitch_errors.pinion[i]`` or ``pitch_errors.gear[j]``.
    """

    pinion: np.ndarray
    gear: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "pinion", _per_tooth("pitch_errors.pinion", self.pinion, None))
        object.__setattr__(self, "gear", _per_tooth("pitch_errors.gear", self.gear, None))

    def check(self, design: Design) -> PitchErrors:
        """Self, after checking one value per tooth of the design (z1 pinion, z2 gear values)."""
        _per_tooth("pitch_errors.pinion", self.pinion, design.z1)
        _per_tooth("pitch_errors.gear", self.gear, design.z2)
        return self

    @property
    def any(self) -> bool:
        """True when some offset is not zero (the kernels then take the per-pair path)."""
        return bool(np.any(self.pinion != 0.0) or np.any(self.gear != 0.0))

    @classmethod
    def zeros(cls, design: Design) -> PitchErrors:
        """No pitch errors (the results equal those without any, bit for bit)."""
        return cls(np.zeros(design.z1), np.zeros(design.z2))

    def to_dict(self) -> dict[str, list[float]]:
        """JSON-ready lists in m."""
        return {"pinion": [float(v) for v in self.pinion], "gear": [float(v) for v in self.gear]}

    def __repr__(self) -> str:
        def span(a: np.ndarray) -> str:
            return f"{a.size} teeth, |e| <= {1e6 * float(np.max(np.abs(a))):.2f} um"

        return f"PitchErrors(pinion: {span(self.pinion)}; gear: {span(self.gear)})"


def iso1328_single_pitch_tolerance(reference_diameter: float, module: float, tolerance_class: int) -> float:
    """Single pitch tolerance f_pT of ISO 1328-1:2013, m (unrounded).

    ``f_pT = (0.001 d + 0.4 m_n + 5) sqrt(2)^(A - 5)`` micrometres with the
    reference diameter d and normal module m_n in mm and A the flank
    tolerance class (ISO 1328-1:2013, formula (5); the standard rounds the
    result, >10 um to 1 um, 5-10 um to 0.5 um, below to 0.1 um, which is
    left out here so the value is continuous in d and m_n).

    Parameters
    ----------
    reference_diameter, module : float
        d and m_n in m (> 0).
    tolerance_class : int
        A in 1..11.
    """
    if (
        isinstance(tolerance_class, bool)
        or not isinstance(tolerance_class, (int, np.integer))
        or int(tolerance_class) not in ISO1328_CLASSES
    ):
        raise OperatingPointError(
            f"pitch_errors: expected an ISO 1328-1 flank tolerance class, an integer in 1..11; got {tolerance_class!r}"
        )
    for name, value in (("reference_diameter", reference_diameter), ("module", module)):
        if not (isinstance(value, (int, float, np.floating)) and math.isfinite(value) and value > 0):
            raise OperatingPointError(f"{name}: expected a length > 0 in m; got {value!r}")
    d_mm, m_mm = 1e3 * reference_diameter, 1e3 * module
    return (0.001 * d_mm + 0.4 * m_mm + 5.0) * math.sqrt(2.0) ** (int(tolerance_class) - 5) * 1e-6


def _draw_gear(rng: np.random.Generator, teeth: int, tolerance: float, cos_alpha: float) -> np.ndarray:
    single = rng.normal(0.0, 0.5 * tolerance, teeth)
    # closure: the pitches of one gear add up to its circumference
    single -= single.mean()
    position = np.cumsum(single)
    # a common shift of all teeth is a change of backlash, not a pitch error
    position -= position.mean()
    return position * cos_alpha


def draw_pitch_errors(design: Design, tolerance_class: int, rng: np.random.Generator) -> PitchErrors:
    """Random pitch errors of a pinion and a gear made to ISO 1328-1:2013 flank tolerance class A.

    Per gear (z teeth, reference diameter d = m z, f_pT of
    :func:`iso1328_single_pitch_tolerance`):

    1. single pitch deviations f_pt,k ~ N(0, (f_pT/2)^2), independent: a
       process whose +-2 sigma band is the tolerance (about 95 % of the
       pitches inside +-f_pT, as a capable process for that class gives);
    2. closure: their mean is removed, so they add up to zero around the gear;
    3. cumulative pitch deviations (tooth positions) F_p,k = sum_{i<=k} f_pt,i,
       their mean removed (a shift of every tooth is backlash, not pitch);
    4. along the line of action: times cos(alpha), the transverse pitch
       measured on the reference circle becoming a base pitch.

    Tooth k's single pitch deviation is then ``(e_k - e_{k-1}) / cos(alpha)``
    (cyclic). The running sum is a random walk: on a gear with many teeth its
    range can exceed the cumulative pitch tolerance F_pT of the same class,
    which real gears hold through correlated (run-out-like) deviations.

    Parameters
    ----------
    design : Design
        Tooth counts, module and pressure angle.
    tolerance_class : int
        A in 1..11 (e.g. 6, 7, 8 for traction gears).
    rng : numpy.random.Generator
        Source of the draw (pinion first, then gear).

    Returns
    -------
    PitchErrors
    """
    pinion_tolerance = iso1328_single_pitch_tolerance(design.module * design.z1, design.module, tolerance_class)
    gear_tolerance = iso1328_single_pitch_tolerance(design.module * design.z2, design.module, tolerance_class)
    cos_alpha = math.cos(math.radians(design.pressure_angle))
    return PitchErrors(
        _draw_gear(rng, design.z1, pinion_tolerance, cos_alpha), _draw_gear(rng, design.z2, gear_tolerance, cos_alpha)
    )


@overload
def class_level(classes: tuple[float, float], position: float) -> float: ...
@overload
def class_level(classes: tuple[float, float], position: np.ndarray) -> np.ndarray: ...


def class_level(classes: tuple[float, float], position: float | np.ndarray) -> float | np.ndarray:
    """Scale of a :data:`REFERENCE_CLASS` draw at ``position`` (0..1) across the classes (lowest, highest).

    ``sqrt(2) ** (class - REFERENCE_CLASS)`` with the class spread evenly
    (``position`` uniform or stratified) from the lowest to the highest.
    """
    return math.sqrt(2.0) ** (classes[0] + (classes[1] - classes[0]) * position - REFERENCE_CLASS)


def draw_at_level(design: Design, level: float, rng: np.random.Generator) -> PitchErrors:
    """Pitch errors drawn at :data:`REFERENCE_CLASS` and scaled by ``level`` (1: that class)."""
    errors = draw_pitch_errors(design, REFERENCE_CLASS, rng)
    return PitchErrors(errors.pinion * level, errors.gear * level)


def draw_in_classes(
    design: Design, classes: tuple[float, float], position: float, rng: np.random.Generator
) -> PitchErrors:
    """Pitch errors drawn at :data:`REFERENCE_CLASS` and scaled to the class at ``position`` across ``classes``."""
    return draw_at_level(design, class_level(classes, position), rng)


def check_classes(classes: object, *, error: type[ValueError] = OperatingPointError) -> tuple[float, float] | None:
    """None, or (lowest, highest) ISO 1328-1 flank tolerance classes within 1..11 (``error`` names the key)."""
    if classes is None:
        return None
    try:
        low, high = (float(value) for value in classes)  # type: ignore[attr-defined]
    except (TypeError, ValueError):
        raise error(
            f"pitch_classes: expected two ISO 1328-1 classes (lowest, highest) in 1..11 or none; got {classes!r:.80}"
        ) from None
    if not (1.0 <= low <= high <= 11.0):
        raise error(f"pitch_classes: expected 1 <= lowest <= highest <= 11; got ({low:g}, {high:g})")
    return low, high


def order_powers(errors: np.ndarray, orders: tuple[int, ...] = (1, 2, 3)) -> np.ndarray:
    """|E_j|^2 of tooth positions ``errors`` (..., z): the power of their j-th Fourier coefficient per revolution.

    E_j drives a gear's shaft line of order j and its sidebands +-j around
    every mesh harmonic; E_1 is the kinematic run-out its pitch errors make.
    """
    errors = np.asarray(errors, dtype=float)
    teeth = errors.shape[-1]
    phases = np.exp(-2j * np.pi * np.outer(np.arange(teeth), np.asarray(orders)) / teeth)  # (z, orders)
    return np.abs(2.0 / teeth * (errors @ phases)) ** 2


def run_out_bounds(
    design: Design, classes: tuple[float, float], rng: np.random.Generator, *, quantile: float = 0.95, draws: int = 4000
) -> dict[str, float]:
    """Per gear, the first-order run-out (m, along the line of action) that pitch errors of ``classes`` stay under.

    The running sum of a gear's pitch errors is a kinematic run-out: its
    first Fourier coefficient over the teeth, 2/z |sum e_i exp(-2 pi i i/z)|,
    acts exactly as an eccentricity's e_s (both enter the TE along the line
    of action), so a shaft run-out below such a bound is not evidence of an
    eccentric shaft on gears of those classes. Levels are drawn uniformly
    over the classes; tooth positions only, no simulation.
    """
    bounds = {}
    for gear, teeth in (("pinion", design.z1), ("gear", design.z2)):
        phases = np.exp(-2j * np.pi * np.arange(teeth) / teeth)
        amplitudes = np.empty(draws)
        for index in range(draws):
            errors = getattr(draw_in_classes(design, classes, rng.random(), rng), gear)
            amplitudes[index] = 2.0 / teeth * abs(np.sum(errors * phases))
        bounds[gear] = float(np.quantile(amplitudes, quantile))
    return bounds


__all__ = [
    "PitchErrors",
    "iso1328_single_pitch_tolerance",
    "draw_pitch_errors",
    "ISO1328_CLASSES",
    "REFERENCE_CLASS",
    "DEFAULT_CLASSES",
    "class_level",
    "draw_at_level",
    "draw_in_classes",
    "check_classes",
    "order_powers",
    "run_out_bounds",
]
