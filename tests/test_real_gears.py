"""Gear pairs other than the bundled one: undercut pinions, small modules, low contact ratios.

Geometry is checked against involute geometry written out here independently of
``uqgear.physics`` (tip, root, base radii; the standard contact-ratio formula; the
form radius of a rack-generated tooth, both by solving where the rack corner's path
crosses the involute and by sweeping the rack flank past the tooth). An undercut
tooth is modelled with an ``UndercutWarning``; a pair that cannot mesh is refused with
a ``DesignError`` naming the key. End to end, a 17:38 design with an unshifted pinion
goes through the virtual rig, ``uqgear calibrate`` and ``uqgear diagnose``.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

import uqgear
from uqgear.common.errors import DesignError, RigDataError, UndercutWarning, UqgearWarning
from uqgear.physics.design import Design, load_design
from uqgear.physics.generation import tip_penetration
from uqgear.physics.geometry import TIP_PENETRATION_TOLERANCE, geometry_notes, pair_geometry
from uqgear.physics.stiffness import mesh_stiffness, tooth_compliance

ROOT = Path(__file__).resolve().parent.parent
ENVIRONMENT = {**os.environ, "UQGEAR_PROGRESS": "0", "MPLBACKEND": "Agg"}

#: The bundled 17:38 test-rig gearbox (module 3 mm, no profile shift: the pinion is marginally undercut),
#: as design keys. T2 = mu Q R_w of its operation brackets the balancing torque 100 x 38/17 = 224 N m.
with warnings.catch_warnings():
    warnings.simplefilter("ignore", UndercutWarning)
    _BUNDLED_17_38 = load_design("pair_17_38")
PAIR_17_38 = _BUNDLED_17_38.to_dict()
OPERATION_17_38 = {"drive_torque": _BUNDLED_17_38.operation.drive_torque,
                   "axle_load": _BUNDLED_17_38.operation.axle_load,
                   "wheel_radius": _BUNDLED_17_38.operation.wheel_radius,
                   "adhesion_coefficient": list(_BUNDLED_17_38.operation.adhesion_coefficient)}
#: Small module, high ratio (5.9), no shift: undercut, and the form circle limits the contact.
PAIR_14_83 = {**PAIR_17_38, "z1": 14, "z2": 83, "module": 0.001, "face_width": 0.01}
#: Stub teeth at 25 deg: contact ratio near 1.2, no undercut.
PAIR_STUB = {**PAIR_17_38, "z1": 30, "z2": 60, "pressure_angle": 25.0, "addendum_coefficient": 0.8,
             "dedendum_coefficient": 1.0}
#: A strongly undercut 12-tooth pinion: the gear tip passes below its form circle.
PAIR_12_40 = {**PAIR_17_38, "z1": 12, "z2": 40}


def build(values: dict, **changes) -> Design:
    """A validated design from design keys (warnings recorded by the caller)."""
    return Design.from_mapping({**values, **changes}, name="test")


def quiet(values: dict, **changes) -> Design:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UndercutWarning)
        return build(values, **changes)


# ------------------------------------------------------------------ involute geometry, written out here


def inv(angle):
    return np.tan(angle) - angle


def closed_form(values: dict) -> dict:
    """Radii, working pressure angle, tip-circle contact ratio and the generating-rack limit l."""
    m, alpha = values["module"], math.radians(values["pressure_angle"])
    ha, hf = values["addendum_coefficient"], values["dedendum_coefficient"]
    out = {}
    for i in (1, 2):
        z, x = values[f"z{i}"], values[f"x{i}"]
        r = m * z / 2
        out[f"r{i}"], out[f"rb{i}"] = r, r * math.cos(alpha)
        out[f"ra{i}"], out[f"rf{i}"] = r + (ha + x) * m, r - (hf - x) * m
        out[f"l{i}"] = r * math.sin(alpha) - (ha - x) * m / math.sin(alpha)
        out[f"psi{i}"] = (math.pi / 2 + 2 * x * math.tan(alpha)) / z
    shift = values["x1"] + values["x2"]
    target = inv(alpha) + 2 * math.tan(alpha) * shift / (values["z1"] + values["z2"])
    alpha_w = alpha if shift == 0 else brentq(lambda a: inv(a) - target, 0.05, 1.2)
    a_w = (out["r1"] + out["r2"]) * math.cos(alpha) / math.cos(alpha_w)
    p_b = math.pi * m * math.cos(alpha)
    # the standard formula: tip circles only
    eps = (math.sqrt(out["ra1"] ** 2 - out["rb1"] ** 2) + math.sqrt(out["ra2"] ** 2 - out["rb2"] ** 2)
           - a_w * math.sin(alpha_w)) / p_b
    out.update(alpha=alpha, alpha_w=alpha_w, a_w=a_w, p_b=p_b, eps_standard=eps, loa=a_w * math.sin(alpha_w))
    return out


def undercut_form_radius(values: dict, i: int = 1) -> float:
    """Where the rack corner's path crosses the involute: the rack moves by r phi while the gear turns by phi.

    Cartesian and parametrised by the turning angle, independently of ``uqgear.physics.generation``.
    """
    g = closed_form(values)
    m, alpha, ha = values["module"], g["alpha"], values["addendum_coefficient"]
    r, rb, psi = g[f"r{i}"], g[f"rb{i}"], g[f"psi{i}"]
    u = (ha - values[f"x{i}"]) * m

    def corner(phi):
        x, y = r * psi + u * math.tan(alpha) + r * phi, r - u   # the corner in the fixed frame
        return math.hypot(x, y), math.atan2(x, y) - phi           # radius, angle from the tooth centre line

    def gap(phi):
        rho, beta = corner(phi)
        return beta - (psi + inv(alpha) - inv(math.acos(rb / rho)))

    # the corner is at the base circle (approaching, x < 0) at phi_b; the crossing lies beyond it
    phi_b = (-math.sqrt(rb ** 2 - (r - u) ** 2) - r * psi - u * math.tan(alpha)) / r
    phis = phi_b - np.geomspace(1e-12, 0.5, 4000)
    values_gap = [gap(p) for p in phis]
    k = next(k for k, v in enumerate(values_gap) if v >= 0)
    phi_form = brentq(gap, phis[k - 1], phis[k], xtol=1e-16, rtol=1e-15)
    return corner(phi_form)[0]


def swept_half_angle(values: dict, radii: np.ndarray, i: int = 1, n: int = 400001) -> np.ndarray:
    """Brute force: sweep the rack's straight flank (rolling line to corner) past the tooth; at each
    radius the least polar angle the flank reaches (the generated tooth's half angle)."""
    g = closed_form(values)
    m, alpha, ha = values["module"], g["alpha"], values["addendum_coefficient"]
    r, psi = g[f"r{i}"], g[f"psi{i}"]
    u = (ha - values[f"x{i}"]) * m
    phi = np.linspace(-1.2, 0.6, n)
    p0 = (r * psi + r * phi) + 1j * r
    d = (u * math.tan(alpha) - 1j * u) * np.ones_like(phi)
    out = []
    for rho in radii:
        a, b, c = np.abs(d) ** 2, 2 * (p0.real * d.real + p0.imag * d.imag), np.abs(p0) ** 2 - rho ** 2
        disc = b * b - 4 * a * c
        best = np.inf
        for sign in (-1.0, 1.0):
            s = (-b + sign * np.sqrt(np.maximum(disc, 0.0))) / (2 * a)
            ok = (disc >= 0) & (s >= 0) & (s <= 1)
            points = p0[ok] + s[ok] * d[ok]
            if points.size:
                best = min(best, float(np.min(np.arctan2(points.real, points.imag) - phi[ok])))
        out.append(best)
    return np.array(out)


def involute_half_angle(values: dict, radii: np.ndarray, i: int = 1) -> np.ndarray:
    g = closed_form(values)
    return g[f"psi{i}"] + inv(g["alpha"]) - inv(np.arccos(g[f"rb{i}"] / radii))


# ------------------------------------------------------------------ the 17-tooth pinion without shift


def test_17_tooth_pinion_without_shift_warns_and_is_modelled():
    with pytest.warns(UndercutWarning) as record:
        design = build(PAIR_17_38)
    message = str(record[0].message)
    assert issubclass(record[0].category, UqgearWarning)
    assert message.startswith("x1: the pinion (z1=17, x1=0) is undercut (none from x1 = 0.006)")
    assert "contact ratio 1.609" in message
    g, ref = pair_geometry(design), closed_form(PAIR_17_38)
    for key, value in (("base_radius", "rb"), ("tip_radius", "ra"), ("root_radius", "rf"), ("pitch_radius", "r")):
        assert getattr(g.pinion, key) == pytest.approx(ref[value + "1"], rel=1e-14)
        assert getattr(g.gear, key) == pytest.approx(ref[value + "2"], rel=1e-14)
    assert ref["l1"] == pytest.approx(-4.99e-5, rel=1e-3)        # 0.05 mm past the tangency point: marginal
    assert g.pinion.undercut and not g.gear.undercut
    # form radius: where the corner's path crosses the involute, 0.013 um above the base circle
    form = undercut_form_radius(PAIR_17_38)
    assert g.pinion.form_radius == pytest.approx(form, rel=1e-13)
    assert (g.pinion.form_radius - g.pinion.base_radius) == pytest.approx(1.29e-8, rel=0.01)
    # in roll length the crossing lies about -l/2 from the tangency point (the small-undercut limit)
    assert g.pinion.form_roll == pytest.approx(-ref["l1"] / 2, rel=0.01)
    # the gear tip stays far above the form circle: the standard contact ratio holds
    assert g.tip_contact_start > 20 * g.pinion.form_roll
    assert g.contact_start == g.tip_contact_start and g.contact_end == g.tip_contact_end
    assert g.contact_ratio == pytest.approx(ref["eps_standard"], rel=1e-13)
    assert g.contact_ratio == pytest.approx(1.609, abs=5e-4)
    assert g.centre_distance == pytest.approx(0.003 * 55 / 2, rel=1e-14)
    assert geometry_notes(design) == [message]


def test_the_bundled_17_38_design_loads_with_its_undercut_warning():
    # bundled so that a user (and benchmarks/diagnosis.py) has a real unshifted gearbox by name
    with pytest.warns(UndercutWarning, match="x1: the pinion .z1=17, x1=0. is undercut"):
        design = load_design("pair_17_38")
    assert design.name == "pair_17_38" and "pair_17_38" in uqgear.bundled_designs()
    assert (design.z1, design.z2, design.module, design.x1, design.x2) == (17, 38, 0.003, 0.0, 0.0)


def test_undercut_17_tooth_design_simulates():
    design = quiet(PAIR_17_38)
    run = uqgear.simulate(design, pinion_speed=2000.0, drive_torque=100.0, adhesion_torque=224.0,
                          n_periods=200, keep_periods=60)
    assert np.all(np.isfinite(run["x"].values))
    assert run.attrs["contact_ratio"] == pytest.approx(pair_geometry(design).contact_ratio)
    # mean DTE: the static deflection under F_T plus the half backlash
    stiffness = mesh_stiffness(design)
    assert float(run["x"].mean()) == pytest.approx(run.attrs["static_mesh_force"] / stiffness.attrs["k_mean"]
                                                   + 0.5e-4, rel=0.05)


def test_stiffness_is_continuous_at_the_least_shift():
    # x_min = 1 - 8.5 sin^2(20 deg) = 0.00569: just below the pinion is undercut, just above it is not
    below, above = (quiet(PAIR_17_38, x1=x, x2=-x) for x in (0.0056, 0.0057))
    assert pair_geometry(below).pinion.undercut and not pair_geometry(above).pinion.undercut
    k_below, k_above = (mesh_stiffness(d).attrs["k_mean"] for d in (below, above))
    assert k_below == pytest.approx(k_above, rel=1e-4)


# ------------------------------------------------------------------ strong undercut: the form circle limits contact


@pytest.mark.parametrize("values", [PAIR_12_40, PAIR_14_83], ids=["12:40 m3", "14:83 m1"])
def test_form_radius_of_a_strongly_undercut_pinion(values):
    g = pair_geometry(quiet(values))
    form = undercut_form_radius(values)
    assert g.pinion.form_radius == pytest.approx(form, rel=1e-12)
    # the rack flank swept past the tooth: it cuts inside the involute below r_Ff, follows it above
    span = g.pinion.form_radius - g.pinion.base_radius
    radii = g.pinion.form_radius + span * np.array([-0.5, -0.05, 0.05, 0.5, 20.0])
    swept, involute = swept_half_angle(values, radii), involute_half_angle(values, radii)
    assert np.all(swept[:2] < involute[:2] - 1e-7)
    assert np.allclose(swept[2:], involute[2:], rtol=0, atol=1e-10)
    # the undercut root section (narrowest chord between base and form circles) from the swept profile
    base_to_form = np.linspace(g.pinion.base_radius, g.pinion.form_radius, 201)
    chord = 2 * base_to_form * np.sin(swept_half_angle(values, base_to_form, n=200001))
    assert g.pinion.neck_thickness == pytest.approx(chord.min(), rel=1e-5)
    assert g.pinion.neck_thickness < float(g.pinion.chordal_thickness(g.pinion.form_radius))


def test_contact_ratio_from_the_form_circle_where_it_limits():
    with pytest.warns(UndercutWarning, match=r"contact ratio 1\.459, limited by this form circle \(the tip "
                                             r"circles alone give 1\.647\)"):
        design = build(PAIR_14_83)
    g, ref = pair_geometry(design), closed_form(PAIR_14_83)
    s_form = math.sqrt(undercut_form_radius(PAIR_14_83) ** 2 - ref["rb1"] ** 2)
    s_end = math.sqrt(ref["ra1"] ** 2 - ref["rb1"] ** 2)
    assert g.tip_contact_start < 0 < s_form          # the gear tip passes T1, into the undercut pocket
    assert g.contact_start == pytest.approx(s_form, rel=1e-12)
    assert g.contact_ratio == pytest.approx((s_end - s_form) / ref["p_b"], rel=1e-12)
    assert (g.tip_contact_end - g.tip_contact_start) / g.base_pitch == pytest.approx(ref["eps_standard"], rel=1e-13)
    assert g.contact_ratio == pytest.approx(1.459, abs=5e-4) and ref["eps_standard"] == pytest.approx(1.647, abs=5e-4)
    # the stiffness is integrated over the generated flank only: one or two pairs as the limited ratio says
    ds = mesh_stiffness(design, n_points=4000)
    assert float(ds["pinion_contact_radius"].min()) == pytest.approx(g.pinion.form_radius, rel=1e-12)
    assert ds.attrs["double_contact_fraction"] == pytest.approx(g.contact_ratio - 1, abs=1e-3)
    assert 0.7 <= ds.attrs["k_mean"] / ds.attrs["iso_mesh_stiffness"] <= 1.3
    # and the gear tip that passes the form circle stays clear of the undercut flank
    assert tip_penetration(g.pinion.rack_corner, 14, g.pinion.root_radius, g.pinion.tip_radius, mate_teeth=83,
                           mate_tip_radius=g.gear.tip_radius,
                           mate_tip_half_angle=float(g.gear.half_angle(g.gear.tip_radius)),
                           centre_distance=g.centre_distance) < 0


def test_equal_undercut_gears_limit_contact_at_both_ends():
    # 14:14 without shift: both teeth undercut, each mating tip passes the other's form circle
    with pytest.warns(UndercutWarning) as record:
        design = build(PAIR_17_38, z1=14, z2=14)
    assert [str(w.message)[:3] for w in record] == ["x1:", "x2:"]
    g, ref = pair_geometry(design), closed_form({**PAIR_17_38, "z1": 14, "z2": 14})
    s_form1 = math.sqrt(undercut_form_radius({**PAIR_17_38, "z1": 14, "z2": 14}, 1) ** 2 - ref["rb1"] ** 2)
    s_form2 = math.sqrt(undercut_form_radius({**PAIR_17_38, "z1": 14, "z2": 14}, 2) ** 2 - ref["rb2"] ** 2)
    assert s_form1 == pytest.approx(s_form2, rel=1e-12)
    assert g.contact_start == pytest.approx(s_form1, rel=1e-12)
    assert g.contact_end == pytest.approx(ref["loa"] - s_form2, rel=1e-12)
    assert g.contact_ratio == pytest.approx((ref["loa"] - 2 * s_form1) / ref["p_b"], rel=1e-12)
    assert g.contact_ratio < ref["eps_standard"]


def test_undercut_tooth_compliance_matches_beam_integration():
    design = quiet(PAIR_12_40)
    tooth = pair_geometry(design).pinion
    s_u, s_f = tooth.neck_thickness, float(tooth.chordal_thickness(tooth.effective_root_radius))
    s_k = float(tooth.chordal_thickness(tooth.tip_radius))
    h_r, h_k = tooth.effective_root_radius - tooth.root_radius, tooth.tip_radius - tooth.root_radius
    h_i = (s_f * h_k - s_k * h_r) / (s_f - s_k)
    E, B, nu = design.youngs_modulus, design.face_width, design.poisson_ratio

    def thickness(y):  # rectangle of the undercut section, then the trapezoid from S_F
        return s_u if y <= h_r else s_f * (h_i - y) / (h_i - h_r)

    radii = np.linspace(tooth.form_radius, tooth.tip_radius, 4)
    terms = tooth_compliance(tooth, radii, B, E, nu)
    for k, r_x in enumerate(radii):
        h_x, cos2 = r_x - tooth.root_radius, math.cos(float(tooth.load_angle(r_x))) ** 2
        bending = quad(lambda y, h_x=h_x: 12 * (h_x - y) ** 2 / (E * B * thickness(y) ** 3), 0, h_x, points=[h_r])[0]
        shear = quad(lambda y: 2 * (1 + nu) / (E * B * thickness(y)), 0, h_x, points=[h_r])[0]
        assert terms["bending_rectangle"][k] + terms["bending_trapezoid"][k] == pytest.approx(bending * cos2, rel=1e-7)
        assert terms["shear"][k] == pytest.approx(shear * cos2, rel=1e-7)
        assert terms["foundation"][k] == pytest.approx(24 * h_x ** 2 * cos2 / (math.pi * E * B * s_u ** 2), rel=1e-12)


# ------------------------------------------------------------------ no undercut, contact ratio near 1.2


def test_stub_teeth_with_contact_ratio_near_1_2():
    with warnings.catch_warnings():
        warnings.simplefilter("error", UqgearWarning)          # not undercut: no warning
        design = build(PAIR_STUB)
    g, ref = pair_geometry(design), closed_form(PAIR_STUB)
    assert not g.pinion.undercut and not g.gear.undercut and geometry_notes(design) == []
    assert g.pinion.form_radius == pytest.approx(math.hypot(ref["rb1"], ref["l1"]), rel=1e-14)
    assert g.gear.form_radius == pytest.approx(math.hypot(ref["rb2"], ref["l2"]), rel=1e-14)
    assert g.contact_ratio == pytest.approx(ref["eps_standard"], rel=1e-13)
    assert g.contact_ratio == pytest.approx(1.2306, abs=1e-4)
    ds = mesh_stiffness(design, n_points=4000)
    assert ds.attrs["double_contact_fraction"] == pytest.approx(g.contact_ratio - 1, abs=1e-3)


def test_bundled_design_has_no_notes_and_its_tip_touches_the_involute_only():
    design = load_design("locomotive")
    g = pair_geometry(design)
    assert geometry_notes(design) == [] and not g.pinion.undercut
    # the tip-path check on a healthy pair: the tip corner touches the involute at the start of contact
    depth = tip_penetration(g.pinion.rack_corner, 21, g.pinion.root_radius, g.pinion.tip_radius, mate_teeth=101,
                            mate_tip_radius=g.gear.tip_radius,
                            mate_tip_half_angle=float(g.gear.half_angle(g.gear.tip_radius)),
                            centre_distance=g.centre_distance)
    assert -1e-8 < depth < TIP_PENETRATION_TOLERANCE * design.module


# ------------------------------------------------------------------ what cannot mesh is refused, naming the key


@pytest.mark.parametrize("changes, message", [
    ({"z1": 8}, r"^x1: contact ratio 0\.916 is below 1: the undercut pinion's involute starts too high"),
    ({"z1": 12, "z2": 101, "x2": -0.25}, r"^x1: the gear tip would cut 69\.8 um into the pinion's undercut flank"),
    ({"z1": 10, "x1": 1.0}, r"^x1: the pinion teeth are pointed at the tip"),
    ({"x1": 0.9, "x2": 0.9}, r"^dedendum_coefficient: no tip clearance \(-0\.0668 mm\)"),
    ({"z1": 30, "z2": 60, "addendum_coefficient": 0.5, "dedendum_coefficient": 0.75},
     r"^addendum_coefficient: contact ratio 0\.914 is below 1"),
], ids=["undercut contact ratio < 1", "tip cuts undercut flank", "pointed", "no tip clearance", "contact ratio < 1"])
def test_pairs_that_cannot_mesh_are_refused(changes, message):
    with pytest.raises(DesignError, match=message):
        quiet(PAIR_17_38, **changes)


def test_refusal_names_the_file_and_key(tmp_path):
    path = tmp_path / "pair.yaml"
    lines = "\n".join(f"  {key}: {value}" for key, value in {**PAIR_17_38, "z1": 8}.items())
    path.write_text(f"design:\n{lines}\n")
    with pytest.raises(DesignError, match=rf"^{path}: x1: contact ratio"):
        load_design(path)


# ------------------------------------------------------------------ --design replaces the rig file's design


def _rig(design: Design, n_op: int = 2):
    from uqgear.rig.format import make_rig_dataset

    rng = np.random.default_rng(0)
    time = np.arange(4096) / 20480.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UndercutWarning)   # the design is checked (and warned about) elsewhere
        return make_rig_dataset(time=time, pinion_speed=np.linspace(1500.0, 3000.0, n_op),
                                drive_torque=np.full(n_op, 100.0), adhesion_torque_lower=np.full(n_op, 150.0),
                                adhesion_torque_upper=np.full(n_op, 300.0),
                                channels={"te": 1e-6 * rng.standard_normal((n_op, time.size))}, design=design,
                                title="synthetic", source="test", history="")


def _refused_design_json() -> str:
    return json.dumps({**PAIR_17_38, "z1": 8})     # contact ratio 0.916: refused


def test_design_given_replaces_the_rig_files_without_validating_it(tmp_path):
    from uqgear.diagnosis.inputs import load_rig_input
    from uqgear.rig.format import read_rig, validate_rig, write_rig

    design = quiet(PAIR_17_38)
    ds = _rig(design)
    ds.attrs["design"] = _refused_design_json()
    with pytest.raises(RigDataError, match=r"rig data: design\.x1: contact ratio 0\.916 is below 1"):
        validate_rig(ds)
    assert validate_rig(ds, design=design) is design
    path = tmp_path / "refused.nc"
    ds.to_netcdf(path)                     # as another tool would write it
    with pytest.raises(RigDataError, match=rf"{path}: design\.x1: contact ratio"):
        read_rig(path)
    assert read_rig(path, design=design).attrs["design"] == _refused_design_json()   # kept, unused
    loaded, _ = load_rig_input(path, design=design)
    assert loaded.sizes["op"] == 2
    # the replacing design's z1 decides the sampling-rate check
    with pytest.raises(RigDataError, match="does not resolve the third mesh harmonic"):
        validate_rig(ds, design=quiet(PAIR_17_38, z1=80, z2=160))
    # the file's copy must still be a JSON object, as the format says
    ds.attrs["design"] = "[1, 2]"
    with pytest.raises(RigDataError, match="design: expected JSON text of an object"):
        validate_rig(ds, design=design)
    # and the file's own undercut design is read, with the warning, where none is given
    good = tmp_path / "good.nc"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UndercutWarning)
        write_rig(good, _rig(design))
    with pytest.warns(UndercutWarning, match=r"^x1: the pinion \(z1=17, x1=0\) is undercut"):
        assert validate_rig(read_rig(good)).to_dict() == design.to_dict()


def test_cli_refuses_a_rig_design_that_cannot_mesh_without_design_option(tmp_path):
    ds = _rig(quiet(PAIR_17_38))
    ds.attrs["design"] = _refused_design_json()
    rig = tmp_path / "refused.nc"
    ds.to_netcdf(rig)
    done = subprocess.run([sys.executable, "-m", "uqgear", "diagnose", str(rig), "--out", str(tmp_path / "d")],
                          cwd=ROOT, env=ENVIRONMENT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [f"uqgear: error: {rig}: design.x1: contact ratio 0.916 is below 1: "
                                                "the undercut pinion's involute starts too high (form radius "
                                                "11.42 mm); expected >= 1 (a larger x1, no undercut from 0.532); "
                                                "got 0"]


def test_cli_prints_the_undercut_warning_once(tmp_path):
    design_file = tmp_path / "pair.yaml"
    lines = "\n".join(f"  {key}: {value}" for key, value in PAIR_17_38.items())
    operation = "\n".join(f"  {key}: {value}" for key, value in OPERATION_17_38.items())
    design_file.write_text(f"name: pair_17_38\ndesign:\n{lines}\noperation:\n{operation}\n")
    done = subprocess.run([sys.executable, "-m", "uqgear", "simulate", "--speed", "2000", "--design",
                           str(design_file), "--n-periods", "60", "--keep-periods", "20"],
                          cwd=ROOT, env=ENVIRONMENT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr.splitlines() == [
        f"uqgear: warning: {message}" for message in geometry_notes(quiet(PAIR_17_38))]
    assert "(pair_17_38): period-1" in done.stdout


def test_study_report_lists_the_undercut_as_a_caveat():
    import xarray as xr

    from uqgear.report.study_report import _design_notes

    ds = xr.Dataset(attrs={"design": json.dumps(PAIR_17_38)})
    assert _design_notes(ds) == geometry_notes(quiet(PAIR_17_38))
    assert _design_notes(xr.Dataset(attrs={"design": load_design("locomotive").to_json()})) == []


# ------------------------------------------------------------------ end to end


def test_17_tooth_unshifted_pinion_end_to_end(tmp_path):
    """Virtual-rig campaign of the 17:38 design -> uqgear calibrate -> uqgear diagnose.

    About 15 s on 2 cores: two short runs, one calibrated parameter, one candidate effect, one worker.
    """
    from uqgear.rig.format import write_rig
    from uqgear.rig.virtual_rig import simulate_campaign

    design_file = tmp_path / "pair_17_38.yaml"
    lines = "\n".join(f"  {key}: {value}" for key, value in PAIR_17_38.items())
    operation = "\n".join(f"  {key}: {value}" for key, value in OPERATION_17_38.items())
    design_file.write_text(f"name: pair_17_38\ndesign:\n{lines}\noperation:\n{operation}\n")
    with pytest.warns(UndercutWarning):
        design = load_design(design_file)
    # two operating points (the least a diagnosis holds out from), short records
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UndercutWarning)      # warned above
        campaign = simulate_campaign(design, {"pinion_speed": [1500.0, 3000.0], "drive_torque": [80.0, 120.0]},
                                     seed=3, duration=0.2, run_in=0.2)
        rig = write_rig(tmp_path / "campaign.nc", campaign)
    # a copy whose own design attribute would be refused: --design replaces it
    refused = tmp_path / "refused.nc"
    shutil.copy(rig, refused)
    import netCDF4

    with netCDF4.Dataset(refused, "a") as handle:
        handle.setncattr("design", _refused_design_json())

    def uqgear_cli(*arguments):
        return subprocess.run([sys.executable, "-m", "uqgear", *map(str, arguments)], cwd=ROOT, env=ENVIRONMENT,
                              capture_output=True, text=True, timeout=600)

    warning = f"uqgear: warning: {geometry_notes(design)[0]}"
    calibrated = uqgear_cli("calibrate", rig, "--out", tmp_path / "cal", "--params", "mesh_stiffness_scale")
    assert calibrated.returncode == 0, calibrated.stderr
    assert calibrated.stderr.splitlines() == [warning]
    content = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert content["converged"] and content["design"]["z1"] == 17
    assert content["design_notes"] == geometry_notes(design)
    estimate = content["parameters"]["mesh_stiffness_scale"]
    assert estimate["q05"] <= 1.0 <= estimate["q95"]                  # the rig's true scale is nominal
    assert "Design:</b> x1: the pinion (z1=17, x1=0) is undercut" in (tmp_path / "cal" / "report.html").read_text()

    diagnosed = uqgear_cli("diagnose", refused, "--out", tmp_path / "diag", "--design", design_file,
                           "--effects", "eccentricity", "--workers", "1")
    assert diagnosed.returncode == 0, diagnosed.stderr
    assert diagnosed.stderr.splitlines() == [warning]
    content = json.loads((tmp_path / "diag" / "diagnosis.json").read_text())
    assert content["verdict"] == "none"                                # a healthy rig of the same design
    assert content["design_notes"] == geometry_notes(design)
    assert "Design:</b> x1: the pinion (z1=17, x1=0) is undercut" in (tmp_path / "diag" / "report.html").read_text()
