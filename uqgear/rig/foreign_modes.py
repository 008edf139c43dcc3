"""The foreign rig's own natural modes and the light-load bearing check planned on them.

A test engineer places a bearing check on the rig's resonances (from a
run-up or a tap test), not on a model's. For the foreign virtual rig of
:mod:`.foreign_rig` these come from its 8-DOF model linearised at the mean
mesh stiffness (every tooth pair in contact, the controller as a torsional
spring to the commanded angle, no clearance): :func:`natural_modes` gives
each undamped mode with the share of its strain energy in each spring, and
:func:`bearing_check_plan` runs the mesh fundamental through the two lowest
modes whose energy lies mostly in the bearings and housing mounts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import xarray as xr

from ..common.errors import RigDataError
from ..physics.design import Design
from .foreign_rig import plant_parameters
from .virtual_rig import bearing_check_operating_points

#: Drive torque of the foreign rig's bearing check, N m (a tenth of the rating). Its per-tooth profile errors
#: excite its bearing modes less than the 3-DOF model's mesh excitation does: at the 1500 N m of
#: :data:`uqgear.rig.virtual_rig.BEARING_CHECK_DRIVE_TORQUE` its bearings stay loaded at its own modes
#: (docs/validation/diagnosis.md, "What changed since a healthy reference").
BEARING_CHECK_DRIVE_TORQUE = 750.0
#: A mode is bearing-dominated when at least this share of its strain energy lies in the bearing and housing springs.
BEARING_ENERGY_SHARE = 0.5
#: The springs of the linearised model, in :attr:`ForeignModes.energy_shares` order.
SPRINGS = (
    "controller",
    "input_shaft",
    "output_shaft",
    "mesh",
    "bearing_pinion",
    "bearing_gear",
    "housing_pinion",
    "housing_gear",
)


@dataclass(frozen=True)
class ForeignModes:
    """Undamped modes of the linearised foreign rig.

    Attributes
    ----------
    frequencies : ndarray, shape (8,)
        Natural frequencies, Hz, ascending.
    shapes : ndarray, shape (8, 8)
        Mass-normalised mode shapes in columns; rows: motor, pinion, gear and
        load rotations (rad), pinion and gear centres, pinion and gear housings (m).
    energy_shares : ndarray, shape (8, 8)
        Share of each mode's (column) strain energy in each spring of :data:`SPRINGS` (row).
    """

    frequencies: np.ndarray
    shapes: np.ndarray
    energy_shares: np.ndarray

    @property
    def bearing_shares(self) -> np.ndarray:
        """Share of each mode's strain energy in the bearing and housing springs."""
        return self.energy_shares[4:].sum(axis=0)

    def bearing_frequencies(self, count: int = 2) -> np.ndarray:
        """The ``count`` lowest bearing-dominated natural frequencies, Hz (:data:`BEARING_ENERGY_SHARE`)."""
        found = self.frequencies[self.bearing_shares >= BEARING_ENERGY_SHARE][:count]
        if found.size < count:
            raise RigDataError(f"count: the foreign rig has {found.size} bearing-dominated modes; asked for {count}")
        return found


def _spring_matrices(design: Design) -> tuple[np.ndarray, list[np.ndarray]]:
    """Mass matrix and one stiffness matrix per spring of :data:`SPRINGS`."""
    plant = plant_parameters(design)
    names = ("jm", "j1", "j2", "jl", "ma", "mb", "mh1", "mh2")
    mass = np.diag([plant[name] for name in names])
    unit = np.eye(8)
    mesh_direction = plant["rb1"] * unit[1] - plant["rb2"] * unit[2] - unit[4] + unit[5]
    springs = (
        (plant["kc"], unit[0]),
        (plant["ks1"], unit[0] - unit[1]),
        (plant["ks2"], unit[2] - unit[3]),
        (plant["k_mean"], mesh_direction),
        (plant["kb1"], unit[4] - unit[6]),
        (plant["kb2"], unit[5] - unit[7]),
        (plant["kh1"], unit[6]),
        (plant["kh2"], unit[7]),
    )
    return mass, [stiffness * np.outer(direction, direction) for stiffness, direction in springs]


def natural_modes(design: Design) -> ForeignModes:
    """Natural modes of the foreign rig linearised at the mean mesh stiffness.

    Parameters
    ----------
    design : Design
        The nominal design the foreign rig is built from.

    Returns
    -------
    ForeignModes

    Examples
    --------
    >>> from uqgear.physics.design import load_design
    >>> modes = natural_modes(load_design("locomotive"))
    >>> modes.bearing_frequencies().round(0)
    array([277., 356.])
    """
    mass, stiffnesses = _spring_matrices(design)
    omega2, shapes = scipy.linalg.eigh(sum(stiffnesses), mass)
    energies = np.array([np.einsum("im,ij,jm->m", shapes, k, shapes) for k in stiffnesses])
    frequencies = np.sqrt(np.maximum(omega2, 0.0)) / (2.0 * math.pi)
    return ForeignModes(frequencies, shapes, energies / energies.sum(axis=0))


def bearing_check_plan(design: Design, drive_torque: float = BEARING_CHECK_DRIVE_TORQUE) -> xr.Dataset:
    """The foreign rig's light-load bearing check: its mesh fundamental through its own bearing-dominated modes.

    :func:`uqgear.rig.virtual_rig.bearing_check_operating_points` at the two
    lowest bearing-dominated frequencies of :func:`natural_modes`.

    Examples
    --------
    >>> from uqgear.physics.design import load_design
    >>> bearing_check_plan(load_design("locomotive"))["pinion_speed"].values
    array([ 710.,  790.,  870.,  950.,  970., 1070., 1170., 1270.])
    """
    frequencies = natural_modes(design).bearing_frequencies(2)
    return bearing_check_operating_points(design, drive_torque, mode_frequencies=frequencies)


__all__ = [
    "BEARING_CHECK_DRIVE_TORQUE",
    "BEARING_ENERGY_SHARE",
    "SPRINGS",
    "ForeignModes",
    "bearing_check_plan",
    "natural_modes",
]
