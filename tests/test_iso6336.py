"""The static ISO 6336 rating (method B, spur gears) against an independent code and ISO's published values.

Independent implementation: hanslhansl/din3990 (DIN 3990-11, Python; commit
50249959d237fb7dc012e414ddef02d72002471b, run with its companion packages
diniso21771, din3962 and diniso1328). DIN 3990 and ISO 6336 share the root
section (30-degree tangent), the tip-load form factor Y_Fa and stress
correction Y_Sa (ISO 6336-3 method C), and the contact factors Z_H, Z_E,
Z_eps, Z_B (M_1), Z_D (M_2) and sigma_H0 of ISO 6336-2. Its values were
printed by its ``Calculator`` for two spur cases and are copied below:

- the locomotive design (m 9 mm, z 21/101, x +0.25/-0.25, b 125 mm, basic rack
  h_fP = 1.25 m, rho_fP = 0.38 m) at T1 = 7 kN m (P = 733.04 kW at 1000 rpm),
  all load factors set to 1;
- the spur example shipped with that code (``examples/example_1.py``: m 4 mm,
  z 19/104, x 0.5/0.15, b 48.64 mm, rho_fP = 0.25 m, P = 55 kW at 980 rpm),
  load factors set to 1.

Differences (this implementation against DIN 3990-11's code), locomotive:
s_Fn +0.011 % (DIN stops the tangent iteration after 5 steps), rho_F -0.001 %,
h_Fa +0.001 %, alpha_Fan 0.000 %, Y_Fa -0.020 %, Y_Sa +0.006 %, q_s +0.011 %,
Z_H, Z_eps, Z_B, M_2 identical to 1e-12, Z_E +0.006 % (189.81 from E and nu
against ISO's rounded 189.8), sigma_H0 +0.006 % (from Z_E). Example 1: the
same within 0.01 %. Method B's Y_S (load at the outer point of single pair
contact) against DIN 3990's conversion Y_S = Y_Sa (0.6 + 0.4 eps_alpha):
+0.24 % (pinion), -0.49 % (gear).

ISO's published values: Z_E = 189.8 sqrt(N/mm^2) for steel on steel (ISO
6336-2), Z_H = 2.495 for a 20-degree pair without net profile shift (ISO
6336-2 figure of Z_H), the life factors' knee points of case-hardened steel
(ISO 6336-2 and -3 tables: Z_NT 1.6 / 1.0 / 0.85 at 1e5 / 5e7 / 1e10, Y_NT
2.5 / 1.0 / 0.85 at 1e3 / 3e6 / 1e10), K_v's continuity at the range limits.

Method B's own spur factors (Y_F, Y_S with the load at the outer point of
single pair contact, Z_B, Z_D) against two published calculation reports of
a commercial ISO 6336 code (KISSsoft, ``KISSSOFT_SPUR_STAGES`` below), and
the worked example 1 of ISO/TR 6336-30 through its transverse section.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

import uqgear
from uqgear.physics.design_parts import MeshDesign
from uqgear.physics.rating import (
    RatingError,
    RatingSettings,
    StressLifeCurve,
    contact_factors,
    contact_life_factor,
    dynamic_factor_model,
    root_life_factor,
    root_section,
    static_rating,
)

# (s_Fn mm, rho_F mm, h_Fa mm, alpha_Fan deg, Y_Fa, Y_Sa, q_s) per gear, as DIN 3990-11's code printed them
DIN_LOCOMOTIVE_ROOT = {
    "pinion": (
        18.85659627583135,
        4.392694635562661,
        17.492314003183655,
        31.414326910093326,
        2.4126352500029355,
        1.6840508354261747,
        2.146358652291796,
    ),
    "gear": (
        19.941066451424106,
        4.6481828381535575,
        16.973730539749326,
        21.727702802622836,
        2.2786758458114775,
        1.7212264844720708,
        2.1450389480962726,
    ),
}
DIN_LOCOMOTIVE_CONTACT = {
    "Z_H": 2.4945731713945873,
    "Z_eps": 0.8849571823828819,
    "M_1": 1.0186967928680244,
    "M_2": 0.9207985031569713,
    "Z_E": 189.8,
    "sigma_H0": 815.4196058455034,
    "eps_alpha": 1.6505523560468516,
    "Y_S": (2.1222761309018416, 2.169125662377489),
}
DIN_EXAMPLE_ROOT = {
    "pinion": (
        8.748743355951145,
        1.3161477577049423,
        8.174657642839318,
        34.561848000666245,
        2.246336378902072,
        1.9147262565947287,
        3.32361746799878,
    ),
    "gear": (
        9.239504610725831,
        1.325999192893118,
        7.834245947926714,
        22.738705423178445,
        2.1616566798058514,
        2.008781657562889,
        3.48397821817927,
    ),
}
DIN_EXAMPLE_CONTACT = {
    "Z_H": 2.3959406670899934,
    "Z_eps": 0.9062149129606385,
    "M_1": 1.0055470454986402,
    "M_2": 0.8835590102280199,
    "Z_E": 189.8,
    "sigma_H0": 875.3827378988158,
}


@pytest.fixture(scope="module")
def locomotive():
    return uqgear.load_design("locomotive")


@pytest.fixture(scope="module")
def example():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", uqgear.UqgearWarning)
        return uqgear.load_design("locomotive").replace(
            z1=19, z2=104, module=0.004, x1=0.5, x2=0.15, face_width=0.04864
        )


def _check_root(design, reference, fillet):
    for gear, values in reference.items():
        section = root_section(design, gear, load="tip", rack_fillet_coefficient=fillet)
        ours = (
            section.chord * 1e3,
            section.fillet_radius * 1e3,
            section.moment_arm * 1e3,
            math.degrees(section.load_angle),
            section.form_factor,
            section.stress_correction,
            section.notch_parameter,
        )
        for name, mine, theirs in zip(("s_Fn", "rho_F", "h_Fa", "alpha_Fan", "Y_Fa", "Y_Sa", "q_s"), ours, values):
            assert mine == pytest.approx(theirs, rel=5e-4), f"{gear} {name}: {mine} against {theirs}"


def _check_contact(design, reference, torque):
    factors = contact_factors(design)
    assert factors.zone == pytest.approx(reference["Z_H"], rel=1e-9)
    assert factors.contact_ratio == pytest.approx(reference["Z_eps"], rel=1e-9)
    assert factors.single_pair_pinion == pytest.approx(max(1.0, reference["M_1"]), rel=1e-9)
    assert factors.single_pair_gear == pytest.approx(max(1.0, reference["M_2"]), rel=1e-9)
    assert factors.elasticity / 1e3 == pytest.approx(reference["Z_E"], rel=1e-3)
    rating = static_rating(design, torque, 1000.0, dynamic_factor=1.0)
    assert rating.contact_stress_nominal / 1e6 == pytest.approx(reference["sigma_H0"], rel=1e-3)


def test_root_section_and_tip_factors_match_the_din3990_code(locomotive, example):
    _check_root(locomotive, DIN_LOCOMOTIVE_ROOT, 0.38)
    _check_root(example, DIN_EXAMPLE_ROOT, 0.25)


def test_contact_factors_and_nominal_contact_stress_match_the_din3990_code(locomotive, example):
    _check_contact(locomotive, DIN_LOCOMOTIVE_CONTACT, 7000.0)
    _check_contact(example, DIN_EXAMPLE_CONTACT, 55e3 / (980.0 * math.pi / 30.0))


def test_method_b_stress_correction_against_din3990s_conversion_of_the_tip_value(locomotive):
    for index, (gear, tolerance) in enumerate((("pinion", 0.01), ("gear", 0.08))):
        section = root_section(locomotive, gear)
        assert section.stress_correction == pytest.approx(DIN_LOCOMOTIVE_CONTACT["Y_S"][index], rel=tolerance)
        # the load at the outer point of single pair contact sits lower on the tooth than the tip load
        assert section.moment_arm < root_section(locomotive, gear, load="tip").moment_arm


def test_published_iso_values(locomotive):
    assert contact_factors(locomotive).elasticity / 1e3 == pytest.approx(189.8, abs=0.05)
    standard = locomotive.replace(x1=0.0, x2=0.0)
    assert contact_factors(standard).zone == pytest.approx(2.495, abs=5e-4)
    assert [contact_life_factor(n) for n in (1e4, 1e5, 5e7, 1e10, 1e12)] == pytest.approx([1.6, 1.6, 1.0, 0.85, 0.85])
    assert [root_life_factor(n) for n in (1e2, 1e3, 3e6, 1e10)] == pytest.approx([2.5, 2.5, 1.0, 0.85])


def test_nominal_stresses_follow_their_definitions(locomotive):
    rating = static_rating(locomotive, 7000.0, 1000.0, dynamic_factor=1.0)
    force = 7000.0 / (locomotive.module * locomotive.z1 / 2)
    assert rating.tangential_force == pytest.approx(force)
    for section, stress in zip(rating.root, rating.root_stress_nominal):
        assert stress == pytest.approx(
            force / (locomotive.face_width * locomotive.module) * section.form_factor * section.stress_correction
        )
    # doubling the torque doubles the root stress and multiplies the contact stress by sqrt(2)
    double = static_rating(locomotive, 14000.0, 1000.0, dynamic_factor=1.0)
    assert double.root_stress_nominal[0] == pytest.approx(2 * rating.root_stress_nominal[0])
    assert double.contact_stress_nominal == pytest.approx(math.sqrt(2) * rating.contact_stress_nominal)
    # safety factors are strengths over stresses, and the dynamic factor enters sigma_F linearly
    dynamic = static_rating(locomotive, 7000.0, 1000.0, dynamic_factor=1.5)
    assert dynamic.root_stress[1] == pytest.approx(1.5 * rating.root_stress[1])
    assert dynamic.safety_contact[0] == pytest.approx(rating.safety_contact[0] / math.sqrt(1.5))
    assert rating.safety_root[0] == pytest.approx(rating.root_strength[0] / rating.root_stress[0])


def test_finite_life_raises_the_permissible_stress_along_the_s_n_curve(locomotive):
    endurance = static_rating(locomotive, 7000.0, 1000.0, dynamic_factor=1.0)
    short = static_rating(locomotive, 7000.0, 1000.0, dynamic_factor=1.0, cycles=1e3)
    long = static_rating(locomotive, 7000.0, 1000.0, dynamic_factor=1.0, cycles=1e11)
    assert short.root_strength[0] > endurance.root_strength[0] > long.root_strength[0]
    assert long.contact_strength[0] == pytest.approx(0.85 * endurance.contact_strength[0])
    curve = endurance.root_curve[0]
    assert curve.cycles_to_failure(curve.strength(1e5)) == pytest.approx(1e5, rel=1e-9)


def test_iso_dynamic_factor_ranges_and_continuity(locomotive):
    model = dynamic_factor_model(locomotive, 7000.0)
    # n_E1 is the undamped mesh frequency of c_gamma b on the reduced mass, in pinion rpm
    omega = math.sqrt(uqgear.iso6336_stiffness(locomotive)["mesh_stiffness"] / uqgear.equivalent_mass(locomotive))
    assert model.resonance_speed == pytest.approx(60 * omega / (2 * math.pi * locomotive.z1))
    n_e1 = model.resonance_speed
    assert model.factor(1e-6 * n_e1) == pytest.approx(1.0, abs=1e-5)
    for limit in (1.15, 1.5):
        below, above = model.factor(n_e1 * (limit - 1e-9)), model.factor(n_e1 * (limit + 1e-9))
        assert below == pytest.approx(above, rel=1e-6)
    speeds = n_e1 * np.array([0.5, 1.0, 1.3, 2.0])
    assert list(model.speed_range(speeds)) == ["subcritical", "main_resonance", "intermediate", "supercritical"]
    assert model.factor(n_e1) == max(model.factor(n_e1 * np.linspace(0.05, 3.0, 60)))


def test_bad_rating_input_names_the_key():
    with pytest.raises(RatingError, match=r"rating\.material\.sigma_Flim: expected a value in"):
        RatingSettings.from_mapping({"material": {"sigma_Flim": 500}})
    with pytest.raises(RatingError, match=r"rating\.no_such_key: unknown key"):
        RatingSettings.from_mapping({"no_such_key": 1})
    with pytest.raises(RatingError, match=r"rating\.accuracy_grade: expected an integer"):
        RatingSettings.from_mapping({"accuracy_grade": 6.5})
    with pytest.raises(RatingError, match=r"rating\.material\.hardening: expected one of case_hardened"):
        RatingSettings.from_mapping({"material": {"hardening": "nitrided"}})
    assert issubclass(RatingError, uqgear.UqgearError)


def test_stress_life_curve_inverse():
    curve = StressLifeCurve(cycles=(1e3, 3e6, 1e10), stress=(2.5e9, 1e9, 0.85e9))
    cycles = np.logspace(3.1, 9.9, 7)
    assert curve.cycles_to_failure(curve.strength(cycles)) == pytest.approx(cycles, rel=1e-9)
    assert curve.cycles_to_failure(3e9) == 1.0
    assert math.isinf(curve.cycles_to_failure(0.85e9))


def test_the_rating_modules_examples_run():
    import doctest

    from uqgear.physics.rating import contact, dynamic, life, root, settings, static

    for module in (settings, root, contact, life, dynamic, static):
        result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
        assert result.failed == 0, module.__name__


# ISO/TR 6336-30:2017, Calculation examples for the application of ISO 6336 parts 1, 2, 3, 5,
# example 1 ("single helical case carburized gear pair"), results of its annex A: m_n 8 mm,
# alpha_n 20 deg, z 17/103, x +0.145/0, beta 15.8 deg, b 100 mm, a 500 mm, T1 9 kN m at
# n1 360 rpm, 50 000 h, S_Hmin 1. The values are the report's, as tabulated against it in
# gfsReboucas/Drivetrain, MATISO_6336.m, example_01 (commit 4a88df348fc70d04254c84bd375bb2bab0d15d0d).
TR_6336_30_EXAMPLE_1 = {
    "F_t": 127352.0,  # N
    "v": 2.664,  # m/s
    "Z_H": 2.39533,
    "Z_E": 189.81170,  # sqrt(N/mm^2)
    "Z_eps": 0.803,
    "Z_beta": 1.01944,
    "sigma_H0": 1206.58207,  # N/mm^2
    "N_L1": 1.080e9,
    "N_L2": 1.783e8,
    "Z_NT1": 0.91,
    "Z_NT2": 0.962,
}


def test_iso_tr_6336_30_example_1_through_its_transverse_section():
    """The published worked example's factors that a spur code computes, within 1 %.

    The example is helical; its transverse section is a spur pair (module m_t =
    m_n / cos beta, pressure angle alpha_t, profile shift x_n cos beta, addendum
    and dedendum m_n and 1.25 m_n), and ISO 6336-2 writes the helical factors on
    that section: Z_H = Z_H(section) sqrt(cos beta_b); with an overlap ratio
    eps_beta >= 1, Z_eps = 1 / sqrt(eps_alpha); Z_beta = 1 / sqrt(cos beta).
    Differences (this code against the report): Z_H +0.002 %, Z_eps +0.042 %
    (the report rounds to 0.803), Z_E 0.000 %, Z_beta 0.000 %, sigma_H0
    -0.013 %, N_L2 -0.027 % and Z_NT2 -0.025 % (the report rounds N_L2 to
    1.783e8), Z_NT1 +0.006 %, F_t 0.000 %, v +0.007 %. Not compared: the report's K_v, K_Hbeta, K_Fbeta, Z_L, Z_v,
    Z_R (load and lubrication factors this code does not compute) and the
    helical root factors (virtual spur gear z_n, not tabulated in the source).
    """
    example = TR_6336_30_EXAMPLE_1
    beta, alpha_n = math.radians(15.8), math.radians(20.0)
    alpha_t = math.atan(math.tan(alpha_n) / math.cos(beta))
    beta_b = math.atan(math.tan(beta) * math.cos(alpha_t))
    m_t = 0.008 / math.cos(beta)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", uqgear.UqgearWarning)
        section = uqgear.load_design("locomotive").replace(
            z1=17,
            z2=103,
            module=m_t,
            pressure_angle=math.degrees(alpha_t),
            x1=0.145 * math.cos(beta),
            x2=0.0,
            addendum_coefficient=math.cos(beta),
            dedendum_coefficient=1.25 * math.cos(beta),
            face_width=0.1,
            youngs_modulus=206e9,
            poisson_ratio=0.3,
        )
    geometry = uqgear.physics.geometry.pair_geometry(section)
    assert geometry.centre_distance == pytest.approx(0.500, rel=1e-4)
    eps_beta = 0.1 * math.sin(beta) / (math.pi * 0.008)
    assert eps_beta >= 1.0
    factors = contact_factors(section)
    z_h = factors.zone * math.sqrt(math.cos(beta_b))
    z_eps = 1.0 / math.sqrt(geometry.contact_ratio)
    z_beta = 1.0 / math.sqrt(math.cos(beta))
    d_1 = 2.0 * geometry.pinion.pitch_radius
    force = 9000.0 / (d_1 / 2.0)
    u = 103 / 17
    sigma_h0 = z_h * factors.elasticity * z_eps * z_beta * math.sqrt(force / (d_1 * 0.1) * (u + 1.0) / u)
    cycles_1 = 360.0 * 60.0 * 50e3
    ours = {
        "F_t": force,
        "v": 360.0 * math.pi / 30.0 * d_1 / 2.0,
        "Z_H": z_h,
        "Z_E": factors.elasticity / 1e3,
        "Z_eps": z_eps,
        "Z_beta": z_beta,
        "sigma_H0": sigma_h0 / 1e6,
        "N_L1": cycles_1,
        "N_L2": cycles_1 / u,
        "Z_NT1": contact_life_factor(cycles_1),
        "Z_NT2": contact_life_factor(cycles_1 / u),
    }
    for name, published in example.items():
        assert ours[name] == pytest.approx(published, rel=0.01), f"{name}: {ours[name]} against {published}"
    # tighter where the report prints five or more figures
    for name in ("Z_H", "Z_E", "F_t"):
        assert ours[name] == pytest.approx(example[name], rel=1e-4), name


# KISSsoft calculation reports (KISSsoft Release 03/2017 A, "ISO 6336:2006 Method B", basic
# rack 1.25 / 0.38 / 1.0 ISO 53 profile A, E 206 GPa, nu 0.3) of the two spur sun-planet
# stages of the NREL 5 MW drivetrain, published in gfsReboucas/Drivetrain,
# @NREL_5MW/stage_02.rtf and @NREL_5MW/stage_01.rtf (commit 2a41bf1ce829b76800693e2b52c91e5f74d074d4).
# Pinion: the sun; gear: a planet (3 planets; F_t is the report's force per mesh). Lengths in mm,
# angles in degrees, stresses in N/mm^2; each value as printed, with its number of decimals.
KISSSOFT_SPUR_STAGES = {
    "stage_02": {
        "input": {"m": 21.0, "z": (18, 36), "x": (0.3890, 0.5039), "b": 550.0, "k": -1.75, "F_t": 285900.438},
        "printed": {
            "a": (584.000, 3),
            "d_a": ((432.838, 815.663), 3),
            "d_f": ((341.838, 724.663), 3),
            "eps_alpha": (1.370, 3),
            "d_en": ((408.342, 794.110), 3),
            "Y_F": ((1.47, 1.38), 2),
            "Y_S": ((2.04, 2.18), 2),
            "h_Fe": ((24.33, 25.73), 2),
            "alpha_Fen": ((25.74, 24.68), 2),
            "s_Fn": ((44.78, 47.70), 2),
            "rho_F": ((9.52, 8.69), 2),
            "sigma_F0": ((73.95, 74.21), 2),
            "Z_H": (2.25, 2),
            "Z_E": (189.81, 2),
            "Z_eps": (0.936, 3),
            "Z_B, Z_D": ((1.08, 1.00), 2),
            "sigma_H0": (573.40, 2),
        },
    },
    "stage_01": {
        "input": {"m": 45.0, "z": (19, 17), "x": (0.6170, 0.8021), "b": 491.0, "k": -10.861, "F_t": 779454.877},
        "printed": {
            "a": (863.000, 3),
            "d_a": ((978.808, 905.470), 3),
            "d_f": ((798.030, 724.692), 3),
            "eps_alpha": (1.115, 3),
            "d_en": ((961.716, 887.259), 3),
            "Y_F": ((1.56, 1.44), 2),
            "Y_S": ((2.06, 2.14), 2),
            "h_Fe": ((64.83, 65.24), 2),
            "alpha_Fen": ((30.75, 33.33), 2),
            "s_Fn": ((101.18, 104.13), 2),
            "rho_F": ((18.12, 17.19), 2),
            "sigma_F0": ((113.46, 108.94), 2),
            "Z_H": (2.06, 2),
            "Z_E": (189.81, 2),
            "Z_eps": (0.981, 3),
            "Z_B, Z_D": ((1.04, 1.05), 2),
            "sigma_H0": (759.92, 2),
        },
    },
}
# Values the report derives from its actual centre distance (with backlash) and its own
# F_t: ours lie within 1e-4 of them but may differ in the last printed digit.
KISSSOFT_LAST_DIGIT = ("a", "d_en", "sigma_F0", "sigma_H0")
# Diameters carry the rounding of the printed profile shifts (4 decimals: +-2 m 5e-5).
KISSSOFT_SHIFTED = ("d_a", "d_f")


def _kisssoft_stage(name):
    """The stage's sun-planet pair, rated; the report's tip alteration k is the addendum's shortening."""
    given = KISSSOFT_SPUR_STAGES[name]["input"]
    keys = {
        "z1": given["z"][0],
        "z2": given["z"][1],
        "module": given["m"] / 1e3,
        "x1": given["x"][0],
        "x2": given["x"][1],
        "face_width": given["b"] / 1e3,
        "addendum_coefficient": 1.0 + given["k"] / given["m"],
        "dedendum_coefficient": 1.25,
        "pressure_angle": 20.0,
        "youngs_modulus": 206e9,
        "poisson_ratio": 0.3,
    }
    if name == "stage_02":
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", uqgear.UqgearWarning)
            design = uqgear.load_design("locomotive").replace(**keys)
    else:
        # Design refuses this pair: its geometry takes the generating rack's flank height from
        # h_a* (tip shortening is not modelled), so the shortened addendum lifts the model's root
        # form circles above the mating tips' reach. The rating reads only the tip and root
        # circles and the path of contact, so the geometry's own design part is rated.
        design = MeshDesign(**keys)
    torque = given["F_t"] * given["m"] * given["z"][0] / 2e3
    rating = static_rating(design, torque, 100.0, dynamic_factor=1.0)
    geometry = uqgear.physics.geometry.pair_geometry(design)
    pinion, gear = rating.root
    return {
        "a": geometry.centre_distance * 1e3,
        "d_a": (2e3 * geometry.pinion.tip_radius, 2e3 * geometry.gear.tip_radius),
        "d_f": (2e3 * geometry.pinion.root_radius, 2e3 * geometry.gear.root_radius),
        "eps_alpha": geometry.contact_ratio,
        "d_en": (pinion.load_diameter * 1e3, gear.load_diameter * 1e3),
        "Y_F": (pinion.form_factor, gear.form_factor),
        "Y_S": (pinion.stress_correction, gear.stress_correction),
        "h_Fe": (pinion.moment_arm * 1e3, gear.moment_arm * 1e3),
        "alpha_Fen": (math.degrees(pinion.load_angle), math.degrees(gear.load_angle)),
        "s_Fn": (pinion.chord * 1e3, gear.chord * 1e3),
        "rho_F": (pinion.fillet_radius * 1e3, gear.fillet_radius * 1e3),
        "sigma_F0": tuple(stress / 1e6 for stress in rating.root_stress_nominal),
        "Z_H": rating.contact.zone,
        "Z_E": rating.contact.elasticity / 1e3,
        "Z_eps": rating.contact.contact_ratio,
        "Z_B, Z_D": (rating.contact.single_pair_pinion, rating.contact.single_pair_gear),
        "sigma_H0": rating.contact_stress_nominal / 1e6,
    }


@pytest.mark.parametrize("name", sorted(KISSSOFT_SPUR_STAGES))
def test_spur_pairs_against_published_kisssoft_method_b_reports(name):
    """Two spur pairs' method B root and contact factors against a commercial code's reports.

    Every printed factor is within 1 % and rounds to the printed figure: Y_F,
    Y_S at the outer point of single pair contact, the critical section's h_Fe,
    alpha_Fen, s_Fn, rho_F, and Z_H, Z_E, Z_eps, Z_B, Z_D, eps_alpha, the tip and
    root diameters (the latter to the rounding of the printed profile shifts).
    The centre distance, load diameter d_en and the nominal stresses are within
    1e-4 (the report computes them at its actual centre distance). Differences:
    docs/validation/verification.md.
    """
    ours = _kisssoft_stage(name)
    module = KISSSOFT_SPUR_STAGES[name]["input"]["m"]
    for key, (printed, decimals) in KISSSOFT_SPUR_STAGES[name]["printed"].items():
        pairs = zip(ours[key], printed) if isinstance(printed, tuple) else [(ours[key], printed)]
        rounding = 0.5 * 10.0**-decimals + (2.0 * module * 5e-5 if key in KISSSOFT_SHIFTED else 0.0)
        for mine, theirs in pairs:
            assert mine == pytest.approx(theirs, rel=0.01), f"{name} {key}: {mine} against {theirs}"
            if key in KISSSOFT_LAST_DIGIT:
                assert mine == pytest.approx(theirs, rel=1e-4), f"{name} {key}: {mine} against {theirs}"
            else:
                assert abs(mine - theirs) <= rounding + 1e-9, f"{name} {key}: {mine} rounds off {theirs}"
