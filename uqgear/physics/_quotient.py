"""x / y, correctly rounded, from a multiplication and four fused multiply-adds when 1/y is known.

A vector division is the slowest instruction of an RK4 step (its throughput
is about one double every two cycles whatever the vector width), and every
divisor of the model's accelerations (m1, m2, m_e) is a constant of the run.
With z = RN(1/y) computed once by an IEEE division, :func:`quotient` returns
exactly RN(x / y), the bits IEEE division gives, by the refinement

    q0 = RN(x z),   q1 = RN(q0 + RN(x - q0 y) z),   q2 = RN(q1 + RN(x - q1 y) z)

(each bracket of the form a + b c one fused multiply-add, rounded once). Why
q2 is RN(x / y), for y = Y 2^e with a 53-bit significand Y and Q = x / y in
[2^k, 2^(k+1)), ulp = 2^(k-52), and no underflow or overflow:

* |yz - 1| <= Y 2^-106 < 2^-53 (z within half an ulp of 1/y), so q0 is within
  2 ulp of Q, and q0 + RN(x - q0 y) z = Q + (Q - q0)(yz (1 + d) - 1) with
  |d| <= 2^-53 is within 2^-50 ulp of Q: q1 is one of the two floats around
  Q, within (1/2 + 2^-50) ulp of it;
* the remainder x - q1 y of such a faithful quotient is a float (Boldo and
  Daumas, 2003), so the fused multiply-add computes it exactly, and
  q1 + (x - q1 y) z = Q + (Q - q1)(yz - 1), off Q by less than
  (1/2 + 2^-50) ulp Y 2^-106;
* Q is never a midpoint between two floats, and its distance to one is a
  non-zero multiple of 2^(k-53) / Y, so at least ulp / (2 Y);
* the error is smaller than that distance when Y^2 (1 + 2^-49) < 2^106, which
  holds for every significand Y < 2^53 - 2^10: then no midpoint lies between
  Q and the refined value, and q2 = RN(Q).

:func:`exact_divisors` says whether a divisor qualifies (positive, 2^-60 to
2^60, significand below 2^53 - 2^10: all but one in 2^43 of them).
:func:`quotient` is exact for dividends of magnitude 2^-900 to 2^900 and for
0 (then x z is x / y); for any other dividend it says so, and the caller
divides by IEEE division instead.
``tests/test_quotient.py`` compares it with IEEE division bit for bit on
random and on hard cases (quotients next to a midpoint).

The fused multiply-add is LLVM's ``llvm.fma`` intrinsic: one instruction on
CPUs with FMA (x86-64 since Haswell), a correctly rounded library call
otherwise.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import types
from numba.core.extending import intrinsic

from uqgear.physics._rhs import INLINED

#: Dividends |x| from SMALLEST to LARGEST: the proof's range (no underflow in the remainder).
SMALLEST = 2.0**-900
LARGEST = 2.0**900
#: Divisors y from 2^-60 to 2^60 (quotients of the dividends above stay normal), significands below
#: 2^53 - 2^10.
DIVISOR_RANGE = (2.0**-60, 2.0**60)
LARGEST_SIGNIFICAND = 2**53 - 2**10


@intrinsic
def fma(typingctx, a, b, c):
    """a * b + c rounded once (IEEE fused multiply-add, LLVM's ``llvm.fma.f64``)."""
    sig = types.float64(types.float64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        double = ir.DoubleType()
        function = builder.module.declare_intrinsic("llvm.fma", [double], ir.FunctionType(double, [double] * 3))
        return builder.call(function, args)

    return sig, codegen


@nb.njit(**INLINED)
def quotient(x, y, z):
    """(RN(x / y), whether that is what it is) for a divisor :func:`exact_divisors` accepts and z = RN(1 / y).

    The second value is False for a dividend outside SMALLEST to LARGEST in
    magnitude but 0 (tiny or huge, infinite, NaN): divide those by IEEE
    division instead.
    """
    q0 = x * z
    # fma is a numba intrinsic: its Python signature (typing context first) is not the call's
    q1 = fma(fma(-q0, y, x), z, q0)  # type: ignore[call-arg, var-annotated]
    q2 = fma(fma(-q1, y, x), z, q1)
    size = abs(x)
    inside = (size >= SMALLEST) & (size <= LARGEST)
    # 0: x z is x / y, the zero of the right sign (a choice, not a branch)
    return (q2 if inside else q0), inside | (size == 0.0)


def exact_divisors(values: np.ndarray) -> np.ndarray:
    """Whether :func:`quotient` divides by each element exactly: positive, 2^-60 to 2^60, significand below
    2^53 - 2^10 (an array of bools of the same shape)."""
    y = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore"):
        inside = (y >= DIVISOR_RANGE[0]) & (y <= DIVISOR_RANGE[1])
    significand, _ = np.frexp(np.where(inside, y, 1.0))
    return inside & (np.ldexp(significand, 53) < LARGEST_SIGNIFICAND)


def exact_divisor(y: float) -> bool:
    """:func:`exact_divisors` of one number."""
    return bool(exact_divisors(np.array([y]))[0])
