"""The parts of a design that the derived design reads: the keys of its caches.

The model derives from a design, in this order, the involute geometry of the
pair, the stiffness tables and the natural frequencies that set the step
count. Each derivation is cached, and a cache key that left out a field the
derivation reads would serve one design's result to another. So each
derivation takes a *part* of the design, a frozen dataclass that holds
exactly the fields it may read, and is cached on that part itself:

* :class:`ToothPairDesign`: the involute geometry (tooth counts, module,
  pressure angle, profile shifts, addendum and dedendum);
* :class:`MeshDesign`: the stiffness tables (the tooth pair, face width and
  elastic constants);
* :class:`ModalDesign`: the linearised vibration modes (the mesh, masses,
  inertias and bearing stiffnesses).

A derivation given a part cannot read a field outside it (the part has no
such attribute), and the part equals another exactly when every field it
holds does: the key is complete by construction. A field added to a part is
a field added to its key; the parts nest, each one the one before with the
fields its derivation adds.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, TypeVar

PartT = TypeVar("PartT", bound="DesignPart")


class DesignParts:
    """The parts of a design (or of a larger part) as properties: the keys of the derived design."""

    @property
    def tooth_pair(self) -> ToothPairDesign:
        """The fields the involute geometry reads."""
        return ToothPairDesign.of(self)

    @property
    def mesh_design(self) -> MeshDesign:
        """The fields the stiffness tables read."""
        return MeshDesign.of(self)

    @property
    def modal_design(self) -> ModalDesign:
        """The fields the linearised vibration modes read."""
        return ModalDesign.of(self)


@dataclass(frozen=True)
class DesignPart(DesignParts):
    """A frozen selection of design fields: hashable, equal where every field is."""

    @classmethod
    def of(cls: type[PartT], source: Any) -> PartT:
        """This part of ``source`` (a design, a larger part, any object with the fields)."""
        if type(source) is cls:
            return source
        return cls(**{item.name: getattr(source, item.name) for item in dataclasses.fields(cls)})

    @classmethod
    def keys(cls) -> tuple[str, ...]:
        """The names of the design fields this part holds, in design order."""
        return tuple(item.name for item in dataclasses.fields(cls))


@dataclass(frozen=True)
class ToothPairDesign(DesignPart):
    """The design fields the involute geometry of the pair reads (:func:`~uqgear.physics.geometry.pair_geometry`)."""

    z1: int
    z2: int
    module: float
    pressure_angle: float
    x1: float
    x2: float
    addendum_coefficient: float
    dedendum_coefficient: float


@dataclass(frozen=True)
class MeshDesign(ToothPairDesign):
    """The design fields the mesh stiffness reads (:func:`~uqgear.physics.stiffness.stiffness_tables`)."""

    face_width: float
    youngs_modulus: float
    poisson_ratio: float


@dataclass(frozen=True)
class ModalDesign(MeshDesign):
    """The design fields the linearised 3-DOF modes read (:func:`~uqgear.physics.model.natural_frequencies`)."""

    m1: float
    m2: float
    I1: float
    I2: float
    k1: float
    k2: float


#: The parts, from the geometry up: each holds the fields of the one before.
DESIGN_PARTS: tuple[type[DesignPart], ...] = (ToothPairDesign, MeshDesign, ModalDesign)

__all__ = ["DesignParts", "DesignPart", "ToothPairDesign", "MeshDesign", "ModalDesign", "DESIGN_PARTS"]
