"""The variational equations' Jacobian and saltation matrix against the one right-hand side.

:mod:`uqgear.physics._variational` carries the monodromy matrix along with
hand-derived derivatives of the model: the Jacobian J = d f / d s of the
state-dependent right-hand side (``_jacobian_times``) and the saltation
matrix of the mesh damping's switch at the contact boundaries
(``_saltation``). Both are checked here against the right-hand side every
integrator steps with (``derivative``, ``side_derivative``): J against
central finite differences in every contact region, with and without
bearing clearances in play, for every effect family; S against its
definition I + (f+ - f-) grad(h)^T / (grad(h) . f-) from the two sides'
vector fields. A force term added to the right-hand side without its
derivative fails here.
"""

from __future__ import annotations

import numpy as np
import pytest
from effect_families import FAMILIES

import uqgear
from uqgear.physics import _kernels as K
from uqgear.physics import _variational as V
from uqgear.physics.model import build_model

#: DTE beyond the backlash (m) and bearing deflection (m) of the states the Jacobian is taken at
DEPTH = 2e-5


@pytest.fixture(scope="module")
def design():
    return uqgear.load_design("locomotive")


def _setup(design, family, damping_in_separation=True):
    return build_model(design, 4400.0, 2000.0, 21146.0, effects=FAMILIES[family],
                       damping_in_separation=damping_in_separation)


def _terms(setup, t=0.37e-3):
    return K.forcing(t, t, setup.parameters, setup.pair_stiffness, setup.period_stiffness, setup.factor_pinion,
                     setup.factor_gear)


def _states(setup):
    """A state in each contact region, with each bearing inside and beyond its clearance."""
    b = setup.parameters[K.HALF_BACKLASH]
    for x in (b + DEPTH, 0.0, -b - DEPTH):
        for y in (0.0, 3 * DEPTH):
            yield np.array([-y, 0.5 * y, x, 0.11, -0.07, 0.23])


def _field(s, terms, p, side=2):
    if side == 2:
        d, _ = K.derivative(tuple(s), terms, p)
    else:
        d, _ = K.side_derivative(tuple(s), terms[0], terms[1], terms[2], terms[4], K.coefficients(p), side)
    return np.array(d)


def _finite_differences(s, terms, p, scale):
    columns = []
    for j in range(6):
        step = np.zeros(6)
        step[j] = 1e-6 * scale[j]
        columns.append((_field(s + step, terms, p) - _field(s - step, terms, p)) / (2 * step[j]))
    return np.column_stack(columns)


@pytest.mark.parametrize("damping_in_separation", [True, False])
@pytest.mark.parametrize("family", list(FAMILIES))
def test_the_jacobian_is_the_derivative_of_the_right_hand_side(design, family, damping_in_separation):
    setup = _setup(design, family, damping_in_separation)
    p = setup.parameters
    terms = _terms(setup)
    scale = setup.state_scale()
    for s in _states(setup):
        jacobian = np.empty((6, 6))
        V._jacobian_times(tuple(s), terms, p, np.eye(6), jacobian, 2, 2)
        numeric = _finite_differences(s, terms, p, scale)
        # each row against its own magnitude: the rows of positions and of accelerations differ by ~1e8
        size = np.maximum(np.abs(numeric).max(axis=1, keepdims=True), 1e-300)
        assert np.all(np.abs(jacobian - numeric) <= 1e-6 * size), (family, s)


@pytest.mark.parametrize("family", ["healthy", "friction", "bearing_clearance"])
def test_the_saltation_matrix_is_the_jump_of_the_vector_field(design, family):
    """Without damping in separation the damping force switches at x = +-b: S = I + (f+ - f-) e_x^T / x'."""
    setup = _setup(design, family, damping_in_separation=False)
    p = setup.parameters
    terms = _terms(setup)
    b = p[K.HALF_BACKLASH]
    for before, after, level in ((1, 0, b), (0, 1, b), (-1, 0, -b), (0, -1, -b)):
        # on the boundary, moving from the side it leaves into the one it enters
        velocity = 0.3 * (after - before) * (1.0 if level > 0 else -1.0)
        s = np.array([-1e-6, 2e-6, level, 0.11, -0.07, velocity])
        f_minus = _field(s, terms, p, before)
        f_plus = _field(s, terms, p, after)
        expected = np.eye(6) + np.outer(f_plus - f_minus, np.eye(6)[2]) / f_minus[2]
        phi = np.eye(6)
        V._saltation(phi, V._jump_in_damping(before, after, p), p)
        size = np.abs(expected).max(axis=1, keepdims=True)
        assert np.all(np.abs(phi - expected) <= 1e-12 * size), (before, after)
        assert not np.allclose(phi, np.eye(6))


def test_with_damping_in_separation_the_field_is_continuous_and_there_is_no_jump(design):
    setup = _setup(design, "friction")
    p = setup.parameters
    terms = _terms(setup)
    s = np.array([0.0, 0.0, p[K.HALF_BACKLASH], 0.11, -0.07, -0.3])
    assert np.array_equal(_field(s, terms, p, 1), _field(s, terms, p, 0))
    assert V._jump_in_damping(1, 0, p) == 0.0
