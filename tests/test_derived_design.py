"""The derived design (geometry, stiffness tables, modes, set-up) is keyed on the design fields it reads.

Every field of :class:`~uqgear.Design` is changed in turn: where a part of
the design (:mod:`uqgear.physics.design_parts`) holds the field, the part and
what is derived from it change; where it does not, the part is equal and the
cached derivation returns the very same object (it is given the part alone,
so it cannot read the field). The set-up a run integrates changes with every
field but those it is documented not to read.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import uqgear
from uqgear.physics import design_parts
from uqgear.physics.design import Operation
from uqgear.physics.geometry import pair_geometry
from uqgear.physics.integration import _highest_mode
from uqgear.physics.model import build_model, cached_tables

#: A valid change of every design field (the locomotive's geometry stays meshable).
CHANGES = {
    "z1": 22,
    "z2": 102,
    "module": 0.0095,
    "pressure_angle": 20.5,
    "x1": 0.3,
    "x2": -0.2,
    "addendum_coefficient": 0.98,
    "dedendum_coefficient": 1.27,
    "face_width": 0.13,
    "youngs_modulus": 210e9,
    "poisson_ratio": 0.29,
    "m1": 66.0,
    "m2": 440.0,
    "I1": 8.9,
    "I2": 27.5,
    "k1": 1.1e9,
    "k2": 2.2e9,
    "zeta1": 0.06,
    "zeta2": 0.06,
    "zeta_mesh": 0.06,
    "backlash": 0.33e-3,
    "ste_amplitude": 16.5e-6,
    "motor_pole_pairs": 4,
    "name": "changed",
    "operation": Operation(drive_torque=7700.0),
}
#: Fields the set-up does not read: a label, and the motor's pole pairs (the rig's order tracking reads them).
OUTSIDE_THE_SET_UP = {"name", "motor_pole_pairs"}


def _derived(part: type[design_parts.DesignPart], design: uqgear.Design) -> object:
    if part is design_parts.ToothPairDesign:
        return pair_geometry(design)
    if part is design_parts.MeshDesign:
        return cached_tables(design, "ishikawa")
    return _highest_mode(design, 1.0)


def _same(a: object, b: object) -> bool:
    if isinstance(a, float):
        return a == b
    if dataclasses.is_dataclass(a):
        return all(
            np.array_equal(getattr(a, item.name), getattr(b, item.name))
            if isinstance(getattr(a, item.name), np.ndarray)
            else getattr(a, item.name) == getattr(b, item.name)
            for item in dataclasses.fields(a)
        )
    return a == b


def test_every_design_field_has_a_change():
    assert set(CHANGES) == {item.name for item in dataclasses.fields(uqgear.Design)}


def test_the_parts_nest_and_hold_design_fields_only():
    names = {item.name for item in dataclasses.fields(uqgear.Design)}
    for smaller, larger in zip(design_parts.DESIGN_PARTS, design_parts.DESIGN_PARTS[1:]):
        assert set(smaller.keys()) < set(larger.keys())
    assert set(design_parts.DESIGN_PARTS[-1].keys()) <= names


@pytest.mark.parametrize("name", sorted(CHANGES))
def test_a_changed_design_field_changes_what_is_derived_from_it_or_nothing(name):
    design = uqgear.load_design("locomotive")
    if name in ("name", "operation"):
        changed = dataclasses.replace(design, **{name: CHANGES[name]})
    else:
        changed = design.replace(**{name: CHANGES[name]})
    for part in design_parts.DESIGN_PARTS:
        before, after = part.of(design), part.of(changed)
        if name in part.keys():
            assert before != after, part.__name__
            assert not _same(_derived(part, design), _derived(part, changed)), part.__name__
        else:
            # the derivation is given the part alone: an equal part is the same cached result
            assert before == after and hash(before) == hash(after), part.__name__
            assert _derived(part, design) is _derived(part, changed), part.__name__
    setups = [build_model(d, 2000.0, 7000.0, 33e3) for d in (design, changed)]
    same_set_up = np.array_equal(setups[0].parameters, setups[1].parameters) and (
        setups[0].derived == setups[1].derived
    )
    assert same_set_up == (name in OUTSIDE_THE_SET_UP)


def test_a_part_is_its_own_key():
    design = uqgear.load_design("locomotive")
    mesh = design.mesh_design
    assert design_parts.MeshDesign.of(mesh) is mesh
    assert mesh.tooth_pair == design.tooth_pair
    # the tables derived from the part alone are those of the design
    assert cached_tables(mesh, "ishikawa") is cached_tables(design, "ishikawa")
    with pytest.raises(AttributeError):
        design_parts.ModalDesign.of(mesh)
