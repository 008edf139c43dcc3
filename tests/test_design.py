"""Design loading, validation and involute geometry.

Checked against the derived values of docs/model/reference-design.md section 5.
"""

import math

import pytest

import uqgear
import uqgear.common
from uqgear.common.errors import DesignError
from uqgear.physics.design import DESIGN_KEYS, design_key_bounds, design_key_unit, load_design
from uqgear.physics.geometry import pair_geometry


def test_reference_design_keys_and_provenance(design):
    assert design.z1 == 21 and design.z2 == 101
    assert design.module == pytest.approx(0.009)
    assert design.motor_pole_pairs == 3
    assert set(design.to_dict()) == set(DESIGN_KEYS) | {"motor_pole_pairs"}
    text = uqgear.common.bundled_file("design", "locomotive").read_text()
    assert "Provenance" in text and "NOT the lost parameter table" in text


def test_derived_geometry_matches_model_md(design):
    g = pair_geometry(design)
    # docs/model/reference-design.md section 5: base 88.8 / 427.1, tip 105.75 / 461.25, root 85.5 / 441.0 mm, eps ~ 1.65
    assert g.pinion.base_radius * 1e3 == pytest.approx(88.8, abs=0.05)
    assert g.gear.base_radius * 1e3 == pytest.approx(427.1, abs=0.05)
    assert g.pinion.tip_radius * 1e3 == pytest.approx(105.75, abs=1e-9)
    assert g.gear.tip_radius * 1e3 == pytest.approx(461.25, abs=1e-9)
    assert g.pinion.root_radius * 1e3 == pytest.approx(85.5, abs=1e-9)
    assert g.gear.root_radius * 1e3 == pytest.approx(441.0, abs=1e-9)
    assert g.contact_ratio == pytest.approx(1.65, abs=0.01)
    assert g.centre_distance == pytest.approx(0.009 * 122 / 2)


def test_profile_shift_sum_changes_working_pressure_angle(design):
    shifted = design.replace(x1=0.5, x2=0.0)
    g = pair_geometry(shifted)
    alpha = math.radians(20.0)
    inv = math.tan(g.working_pressure_angle) - g.working_pressure_angle
    assert inv == pytest.approx(math.tan(alpha) - alpha + 2 * math.tan(alpha) * 0.5 / 122, rel=1e-10)
    assert g.centre_distance > 0.009 * 122 / 2


def test_adhesion_torque_interval(design):
    lower, upper = design.operation.adhesion_torque_bounds()
    # T2 = mu Q R_w with Q = 23 t x g; the reference design's provenance quotes "about [21.2, 46.5] kN m"
    assert lower == pytest.approx(0.15 * 23000 * 9.80665 * 0.625, rel=1e-12)
    assert upper == pytest.approx(0.33 * 23000 * 9.80665 * 0.625, rel=1e-12)
    assert lower == pytest.approx(21.2e3, rel=5e-3)
    assert upper == pytest.approx(46.5e3, rel=5e-3)


def test_yaml_exponent_without_sign_is_a_number(tmp_path, design):
    path = tmp_path / "d.yaml"
    lines = [f"  {k}: {v}" for k, v in design.to_dict().items()]
    path.write_text("design:\n" + "\n".join(lines).replace("206000000000.0", "206e9") + "\n")
    assert load_design(path).youngs_modulus == 206e9


def _write(tmp_path, values):
    path = tmp_path / "bad.yaml"
    path.write_text("design:\n" + "\n".join(f"  {k}: {v}" for k, v in values.items()) + "\n")
    return path


@pytest.mark.parametrize("change, message", [
    ({"module": 9}, r"module: expected a value in \[0.0002, 0.05\] m \(SI metres"),
    ({"m1": -60.0}, r"m1: expected a value in .* kg; got -60"),
    ({"face_width": 125}, r"face_width: expected a value in"),
    ({"z1": 21.5}, r"z1: expected an integer"),
    # an undercut pinion is modelled (tests/test_real_gears.py); this one meshes with a gear whose tip,
    # the centre distance shrunk by x2 = -0.25, would cut into the undercut flank
    ({"z1": 12, "x1": 0.0}, r"x1: the gear tip would cut 209 um into the pinion's undercut flank"),
    ({"addendum_coefficient": 0.5, "dedendum_coefficient": 0.75}, r"contact ratio .* below 1"),
    ({"poisson_ratio": "steel"}, r"poisson_ratio: expected a number"),
    ({"dedendum_coefficient": 0.9}, r"dedendum_coefficient: expected more than addendum_coefficient"),
])
def test_implausible_values_name_the_key(tmp_path, design, change, message):
    values = {**design.to_dict(), **change}
    with pytest.raises(DesignError, match=message):
        load_design(_write(tmp_path, values))


def test_missing_and_unknown_keys(tmp_path, design):
    values = design.to_dict()
    del values["k2"]
    with pytest.raises(DesignError, match=r"k2: missing design key"):
        load_design(_write(tmp_path, values))
    values = {**design.to_dict(), "stiffnes": 1.0}
    with pytest.raises(DesignError, match=r"stiffnes: unknown design key"):
        load_design(_write(tmp_path, values))
    # an empty YAML value (``k1:``) reads as None: missing, not a crash
    path = tmp_path / "empty.yaml"
    lines = [f"  {key}: {value}" for key, value in design.to_dict().items() if key != "k1"]
    path.write_text("design:\n" + "\n".join(lines) + "\n  k1:\n")
    with pytest.raises(DesignError, match=r"empty.yaml: k1: missing design key"):
        load_design(path)


def test_bad_files_and_names(tmp_path):
    with pytest.raises(DesignError, match="not a bundled design"):
        load_design("no_such_design")
    with pytest.raises(DesignError, match="design file not found"):
        load_design(tmp_path / "missing.yaml")
    broken = tmp_path / "broken.yaml"
    broken.write_text("design: [1, 2\n")
    with pytest.raises(DesignError, match="not valid YAML"):
        load_design(broken)
    empty = tmp_path / "empty.yaml"
    empty.write_text("z1: 21\n")
    with pytest.raises(DesignError, match="expected a mapping with a 'design' key"):
        load_design(empty)


def test_operation_section_validated(tmp_path, design):
    text = "design:\n" + "\n".join(f"  {k}: {v}" for k, v in design.to_dict().items())
    path = tmp_path / "op.yaml"
    path.write_text(text + "\noperation:\n  adhesion_coefficient: [0.33, 0.15]\n")
    with pytest.raises(DesignError, match=r"operation.adhesion_coefficient: expected lower <= upper"):
        load_design(path)


def test_overrides_are_validated(design):
    assert load_design("locomotive", overrides={"k1": 2e9}).k1 == 2e9
    with pytest.raises(DesignError, match="backlash"):
        load_design("locomotive", overrides={"backlash": 0.3})


@pytest.mark.parametrize(
    "changes",
    [
        {"k1": 2e9},
        {"zeta_mesh": 0.07, "backlash": 3e-4, "ste_amplitude": 1e-5},
        {"z1": 23, "x1": 0.3},
        {"module": 0.008, "face_width": 0.1},
        {"motor_pole_pairs": 3},
        {"motor_pole_pairs": None},
        {"z2": 99.0},
    ],
)
def test_replace_is_the_whole_validation_of_the_changed_mapping(design, changes):
    expected = uqgear.Design.from_mapping(
        {**design.to_dict(), **changes}, name=design.name, operation=design.operation
    )
    changed = design.replace(**changes)
    assert changed == expected
    assert [type(getattr(changed, key)) for key in DESIGN_KEYS] == [type(getattr(expected, key)) for key in DESIGN_KEYS]


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"k1": -1.0}, r"^k1: expected a value in \[100000, 1e\+13\] N/m; got -1.0$"),
        ({"k1": "stiff"}, r"^k1: expected a number"),
        ({"k1": None}, r"^k1: missing design key"),
        ({"z1": 21.5}, r"^z1: expected an integer"),
        ({"dedendum_coefficient": 0.9}, r"^dedendum_coefficient: expected more than addendum_coefficient"),
        ({"x1": -0.9}, r"^x1: .*interference"),
        ({"stiffness": 1.0}, r"^stiffness: unknown design key"),
    ],
)
def test_replace_refuses_what_from_mapping_refuses(design, changes, message):
    with pytest.raises(DesignError, match=message):
        uqgear.Design.from_mapping({**design.to_dict(), **changes})
    with pytest.raises(DesignError, match=message):
        design.replace(**changes)


def test_replace_checks_the_geometry_only_when_a_geometry_key_changes(design, monkeypatch):
    import uqgear.physics.geometry as geometry

    calls = []
    original = geometry.check_geometry
    monkeypatch.setattr(geometry, "check_geometry", lambda d, where="": calls.append(d) or original(d, where))
    design.replace(k1=2e9, zeta_mesh=0.06, backlash=3e-4)
    assert calls == []
    design.replace(x2=0.1)
    assert len(calls) == 1


def test_a_design_keys_unit_is_the_one_validation_states_and_unknown_keys_are_refused():
    # the unit is the text the missing-key message quotes
    design = load_design("locomotive").to_dict()
    del design["pressure_angle"]
    expected = rf"pressure_angle: missing design key \(expected {design_key_unit('pressure_angle')}\)"
    with pytest.raises(DesignError, match=expected):
        uqgear.Design.from_mapping(design)
    assert design_key_unit("z1") == "teeth"
    for lookup in (design_key_unit, design_key_bounds):
        with pytest.raises(DesignError, match=r"stiffnes: unknown design key; expected one of z1, z2"):
            lookup("stiffnes")
