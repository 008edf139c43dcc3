"""The lanes' exact quotient against IEEE division, bit for bit.

``uqgear.physics._quotient.quotient`` divides by a multiplication and four
fused multiply-adds from a precomputed 1/y; its module docstring proves that
the result is RN(x / y). Checked here on random quotients over the whole
proven range, on the hardest cases (x / y within a few parts in 2^53 of a
midpoint between two floats, built with exact integer arithmetic), on the
model's own divisors, and on the values it hands back (0, infinities, NaN,
dividends outside the range).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
import pytest

import uqgear
from uqgear.physics import _kernels as K
from uqgear.physics._quotient import LARGEST, SMALLEST, exact_divisor, exact_divisors, quotient


@nb.njit(cache=False)
def _quotients(x, y):
    q = np.empty(x.size)
    exact = np.empty(x.size, dtype=np.bool_)
    for i in range(x.size):
        q[i], exact[i] = quotient(x[i], y[i], 1.0 / y[i])
    return q, exact


def _assert_ieee(x: np.ndarray, y: np.ndarray) -> None:
    q, exact = _quotients(x, y)
    assert exact.all()
    expected = x / y
    differ = np.flatnonzero(q.view(np.int64) != expected.view(np.int64))
    assert differ.size == 0, f"{differ.size} quotients differ, e.g. {x[differ[0]]!r} / {y[differ[0]]!r}"


def _random_divisors(rng, n: int, low: float = -60.0, high: float = 60.0) -> np.ndarray:
    y = np.ldexp(rng.uniform(1.0, 2.0, n), rng.integers(int(low), int(high), n))
    return y[np.vectorize(exact_divisor)(y)]


def test_random_quotients_are_ieee_division():
    rng = np.random.default_rng(2024)
    y = _random_divisors(rng, 2_000_000)
    x = np.ldexp(rng.uniform(1.0, 2.0, y.size), rng.integers(-890, 890, y.size)) * rng.choice([-1.0, 1.0], y.size)
    _assert_ieee(x, y)
    # significands of all ones and near them in the divisor (the proof's margin) and in the dividend
    top = np.ldexp(float(2 ** 53 - 2 ** 10 - 1), -52) * np.ldexp(1.0, rng.integers(-50, 50, 100_000))
    _assert_ieee(np.nextafter(np.ldexp(1.0, rng.integers(-50, 50, top.size)), 0.0), top)


def _hard_cases(rng, n: int) -> tuple[np.ndarray, np.ndarray]:
    """x, y whose quotient is t / (2^54 y) ulp-fractions from a midpoint, |t| <= 7: the closest there are.

    With 53-bit integers X, Y (Y odd) and the midpoint M / 2^54 (M odd) of the floats in [1/2, 1):
    X / Y - M / 2^54 = (2^54 X - M Y) / (2^54 Y), so M = -t Y^-1 mod 2^54 and X = (M Y + t) / 2^54.
    """
    xs, ys = [], []
    while len(xs) < n:
        big_y = int(rng.integers(2 ** 51, 2 ** 52 - 2 ** 9)) * 2 + 1
        t = int(rng.choice([-7, -5, -3, -1, 1, 3, 5, 7]))
        middle = (-t * pow(big_y, -1, 2 ** 54)) % 2 ** 54
        big_x, remainder = divmod(middle * big_y + t, 2 ** 54)
        if remainder or not (2 ** 53 < middle and 2 ** 52 <= big_x < 2 ** 53):
            continue
        shift = int(rng.integers(-40, 40))
        xs.append(math.ldexp(big_x, shift))
        ys.append(math.ldexp(big_y, shift + int(rng.integers(-20, 20))))
    return np.array(xs), np.array(ys)


def test_quotients_next_to_a_midpoint_are_ieee_division():
    x, y = _hard_cases(np.random.default_rng(7), 100_000)
    # they are hard: the reciprocal's product alone, RN(x RN(1/y)), is off in a good share of them
    assert np.mean(x * (1.0 / y) != x / y) > 0.1
    _assert_ieee(x, y)
    _assert_ieee(-x, y)


def test_the_models_divisors_are_exact_and_the_lanes_take_them():
    design = uqgear.load_design("locomotive")
    setup = uqgear.physics.build_model(design, 1500.0, 7000.0, 30000.0)
    masses = setup.parameters[[K.M1, K.M2, K.ME]]
    assert exact_divisors(masses).all()
    rng = np.random.default_rng(3)
    for mass in masses:
        x = np.ldexp(rng.uniform(1.0, 2.0, 200_000), rng.integers(-40, 40, 200_000)) * rng.choice([-1.0, 1.0], 200_000)
        _assert_ieee(x, np.full(x.size, mass))


def test_zeros_and_what_is_left_to_ieee_division():
    y = np.full(5, 3.0)
    x = np.array([0.0, -0.0, SMALLEST, LARGEST, -SMALLEST])
    q, exact = _quotients(x, y)
    assert exact.all()
    assert q.view(np.int64).tolist() == (x / 3.0).view(np.int64).tolist()   # zeros keep their sign
    outside = np.array([SMALLEST / 2.0, -1e-300, 5e-324, LARGEST * 2.0, -1e300, np.inf, -np.inf, np.nan])
    _, exact = _quotients(outside, np.full(outside.size, 3.0))
    assert not exact.any()   # the caller divides these by IEEE division


@pytest.mark.parametrize("divisor, accepted", [
    (3.0, True), (1e-19, False), (2.0 ** 61, False), (-3.0, False), (np.inf, False), (np.nan, False),
    (math.ldexp(2 ** 53 - 1, -52), False), (math.ldexp(2 ** 53 - 2 ** 10, -52), False),
    (math.ldexp(2 ** 53 - 2 ** 10 - 1, -52), True), (1.0, True)])
def test_which_divisors_are_exact(divisor, accepted):
    assert exact_divisor(divisor) is accepted
