"""Ishikawa mesh stiffness: beam terms against numerical integration, ISO 6336 anchor."""

import math

import numpy as np
import pytest
from scipy.integrate import quad

from uqgear.physics.geometry import pair_geometry
from uqgear.physics.stiffness import iso6336_stiffness, mesh_stiffness, tooth_compliance


@pytest.fixture(scope="module")
def second_design(design):
    # a second design: z1=17, z2=88, module 10 mm, x1=+0.3, x2=-0.3, face width 130 mm
    return design.replace(z1=17, z2=88, module=0.010, x1=0.3, x2=-0.3, face_width=0.130)


def _beam_integrals(tooth, r_x, design):
    """Bending and shear deflection of the rectangle+trapezoid cantilever by quadrature."""
    s_f = float(tooth.chordal_thickness(tooth.effective_root_radius))
    s_k = float(tooth.chordal_thickness(tooth.tip_radius))
    h_r = tooth.effective_root_radius - tooth.root_radius
    h_k = tooth.tip_radius - tooth.root_radius
    h_i = (s_f * h_k - s_k * h_r) / (s_f - s_k)
    h_x = r_x - tooth.root_radius
    cos2 = math.cos(float(tooth.load_angle(r_x))) ** 2
    E, B, nu = design.youngs_modulus, design.face_width, design.poisson_ratio

    def thickness(y):
        return s_f if y <= h_r else s_f * (h_i - y) / (h_i - h_r)

    bending = quad(lambda y: 12 * (h_x - y) ** 2 / (E * B * thickness(y) ** 3), 0, h_x, points=[h_r])[0]
    shear = quad(lambda y: 2 * (1 + nu) / (E * B * thickness(y)), 0, h_x, points=[h_r])[0]
    return bending * cos2, shear * cos2


@pytest.mark.parametrize("which", ["pinion", "gear"])
def test_bending_and_shear_terms_match_beam_integration(design, which):
    g = pair_geometry(design)
    tooth = getattr(g, which)
    radii = np.linspace(tooth.effective_root_radius + 0.3 * (tooth.tip_radius - tooth.effective_root_radius),
                        tooth.tip_radius, 5)
    terms = tooth_compliance(tooth, radii, design.face_width, design.youngs_modulus, design.poisson_ratio)
    for i, r in enumerate(radii):
        bending, shear = _beam_integrals(tooth, r, design)
        assert terms["bending_rectangle"][i] + terms["bending_trapezoid"][i] == pytest.approx(bending, rel=1e-7)
        assert terms["shear"][i] == pytest.approx(shear, rel=1e-7)


def test_iso6336_values_for_reference_design(design):
    iso = iso6336_stiffness(design)
    # docs/model/mesh-stiffness.md section 4.6: c' ~ 14.0 and c_gamma ~ 20.8 N/(mm um); c_gamma x b ~ 2.6e9 N/m
    assert iso["c_prime"] == pytest.approx(14.0, abs=0.05)
    assert iso["c_gamma"] == pytest.approx(20.8, abs=0.1)
    assert iso["mesh_stiffness"] == pytest.approx(2.6e9, rel=0.01)


@pytest.mark.parametrize("which", ["design", "second_design"])
def test_mean_stiffness_near_iso(request, which):
    d = request.getfixturevalue(which)
    ds = mesh_stiffness(d)
    ratio = ds.attrs["k_mean"] / ds.attrs["iso_mesh_stiffness"]
    assert 0.7 <= ratio <= 1.3
    if which == "design":
        # the virtual rig's README: nominal Ishikawa k_mean = 3.030e9 N/m (chordal, shear factor 1)
        assert ds.attrs["k_mean"] == pytest.approx(3.030e9, rel=2e-3)


@pytest.mark.parametrize("which", ["design", "second_design"])
def test_double_contact_fraction_is_contact_ratio_minus_one(request, which):
    d = request.getfixturevalue(which)
    ds = mesh_stiffness(d, n_points=4000)
    eps = pair_geometry(d).contact_ratio
    assert ds.attrs["double_contact_fraction"] == pytest.approx(eps - 1.0, abs=1e-3)
    pairs = ds["pairs_in_contact"].values
    assert set(np.unique(pairs)) == {1, 2}


def test_fourier_series_reproduces_mean_and_shape(design):
    ds = mesh_stiffness(design, n_harmonics=25)
    raw, fit = ds["mesh_stiffness"].values, ds["mesh_stiffness_fourier"].values
    assert fit.mean() == pytest.approx(ds.attrs["k_mean"], rel=1e-12)
    # the jumps make the truncated series ring, but most of the curve is reproduced
    assert np.median(np.abs(fit - raw)) / ds.attrs["k_mean"] < 0.02
    assert ds.attrs["k_min"] < ds.attrs["k_mean"] < ds.attrs["k_max"]
    assert ds["single_pair_stiffness"].attrs["units"] == "N m-1"


def test_single_pair_stiffness_peaks_inside_path(design):
    ds = mesh_stiffness(design)
    k = ds["single_pair_stiffness"].values
    assert k.argmax() not in (0, k.size - 1)
    assert k[0] < k.max() and k[-1] < k.max()
