"""The model's right-hand side and RK4 building blocks, compiled with numba: the base of every kernel.

One right-hand side serves every integrator (the scipy reference calls it
too), and every model extension of docs/model/unmodelled-effects.md section 6 is a slot in the
parameter vector whose neutral value switches it off, so effects plug in
without forking the integrator. The kernels that use these pieces live above
this module: :mod:`uqgear.physics._pairs` (pitch errors),
:mod:`uqgear.physics._kernels` (one-sample kernels, which also re-exports
every name here) and :mod:`uqgear.physics._lanes` (samples as SIMD lanes).

Time stepping (fast path): classical RK4 on a uniform grid of ``N`` steps per
mesh period, so Poincare samples fall on grid points. Two kinds of
non-smoothness are located instead of stepped over:

* mesh-stiffness jumps (a pair enters at mesh phase 0, leaves at frac(eps);
  the friction force reverses at the pitch point) happen at known phases: a
  step containing one is split there, and the set of pairs in contact is
  taken from the sub-step's midpoint (``t_ref``), so each sub-step sees a
  smooth stiffness;
* contact boundaries |x| = b depend on the state: when a step changes the
  contact region, the crossing is located on the step's cubic Hermite
  interpolant and the step is redone in two parts.

These helpers are inlined into kernels in other files: a cached kernel is
keyed on the contents of every compiled module of the package
(:mod:`uqgear.physics._cache`), so editing this one recompiles them all.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np

from uqgear.physics._cache import register_kernel_cache

# before any kernel of the package is compiled or loaded from the cache
register_kernel_cache()

# ---------------------------------------------------------------- parameter slots
(
    M1,
    M2,
    ME,
    K1,
    K2,
    C1,
    C2,
    CM,
    HALF_BACKLASH,
    R1,
    R2,
    I1,
    I2,
    T1,
    T2,
    OMEGA_MESH,
    STE_AMPLITUDE,
    STE_PHASE,
    STIFFNESS_SCALE,
    DAMP_IN_SEPARATION,
    RIPPLE_AMPLITUDE,
    RIPPLE_OMEGA,
    RIPPLE_PHASE,
    ADHESION_AMPLITUDE,
    ADHESION_OMEGA,
    ADHESION_PHASE,
    ECC_AMPLITUDE,
    ECC_OMEGA,
    ECC_PHASE,
    ECC_KAPPA,
    FRICTION,
    CLEARANCE1,
    CLEARANCE2,
    PATH_START,
    BASE_PITCH,
    LOA_LENGTH,
    PITCH_POSITION,
    CONTACT_RATIO,
    USE_PERIOD_TABLE,
    Z1,
    Z2,
    TOOTH_FACTORS,
    PITCH_ERRORS,
) = range(43)
#: Number of named slots. The parameter vector goes on with the per-tooth pitch offsets
#: (m): z1 of the pinion from index ``N_PARAMS``, then z2 of the gear (docs/model/equations.md
#: section 2.6); ``PITCH_ERRORS`` is 1 when any of them is not zero.
N_PARAMS = 43

#: Names of the parameter slots, in order (for error messages and tests).
PARAMETER_SLOTS = (
    "m1",
    "m2",
    "me",
    "k1",
    "k2",
    "c1",
    "c2",
    "cm",
    "half_backlash",
    "R1",
    "R2",
    "I1",
    "I2",
    "T1",
    "T2",
    "omega_mesh",
    "ste_amplitude",
    "ste_phase",
    "stiffness_scale",
    "damp_in_separation",
    "ripple_amplitude",
    "ripple_omega",
    "ripple_phase",
    "adhesion_amplitude",
    "adhesion_omega",
    "adhesion_phase",
    "ecc_amplitude",
    "ecc_omega",
    "ecc_phase",
    "ecc_kappa",
    "friction",
    "clearance1",
    "clearance2",
    "path_start",
    "base_pitch",
    "loa_length",
    "pitch_position",
    "contact_ratio",
    "use_period_table",
    "z1",
    "z2",
    "tooth_factors",
    "pitch_errors",
)

# QoI accumulator layout of the batch kernel
(
    Q_X_SUM,
    Q_X_SQ,
    Q_X_MIN,
    Q_X_MAX,
    Q_F_MAX,
    Q_A1_SQ,
    Q_A2_SQ,
    Q_N_DRIVE,
    Q_N_SEP,
    Q_N_BACK,
    Q_COUNT,
    Q_LYAPUNOV,
    Q_F_MIN,
) = range(13)
N_ACCUMULATORS = 13

TWO_PI = 2.0 * math.pi
#: Most tooth pairs in contact at once that a schedule holds (spur gears have at most 3).
MAX_PAIRS = 4

#: Compilation options of every kernel. No ``fastmath``: it licenses LLVM to
#: reassociate sums and contract multiply-adds, and it did so differently for
#: freshly compiled and cache-loaded parallel code, so the same input gave
#: different last bits on a first and a later run (and may on another CPU).
#: Without it the kernels are bit-identical cold, warm and uncached;
#: ``benchmarks/integrator.py`` measures what fastmath would buy.
JIT_OPTIONS: dict[str, Any] = {"cache": True, "error_model": "numpy"}
#: Options of the helpers the stepping code calls on every stage. They are inlined by LLVM
#: (``forceinline``: the ``alwaysinline`` attribute), which gives the same numbers, bit for bit, as
#: numba's own ``inline="always"`` and compiles faster: numba copies and retypes a callee's IR at
#: every call site, nested calls included. A plain call is no option: passing the arrays of a step
#: costs their reference counts on every grid step (docs/validation/performance.md, "Compile time
#: and inlining").
INLINED: dict[str, Any] = {**JIT_OPTIONS, "forceinline": True}


@nb.njit(**INLINED)
def dead_zone(x, half_width):
    """Backlash function f(x): x - b above b, x + b below -b, 0 between."""
    # both branches' values first, then a choice with empty arms: LLVM turns it into selects, which
    # keeps a lane kernel's code in one block for the SLP vectoriser (same values, same bits)
    above = x - half_width
    below = x + half_width
    value = 0.0
    if x < -half_width:
        value = below
    if x > half_width:  # checked last, so it decides as if first
        value = above
    return value


@nb.njit(**INLINED)
def contact_region(x, half_width):
    """1 drive-side contact, 0 separation, -1 back-side contact."""
    if x > half_width:
        return 1
    if x < -half_width:
        return -1
    return 0


@nb.njit(**INLINED)
def _interp_uniform(table, position, span):
    """Linear interpolation on a uniform grid over [0, span], clamped at the ends."""
    n = table.shape[0]
    scaled = position / span * (n - 1)
    if scaled <= 0.0:
        return table[0]
    if scaled >= n - 1:
        return table[n - 1]
    i = int(scaled)
    w = scaled - i
    return table[i] * (1.0 - w) + table[i + 1] * w


@nb.njit(**INLINED)
def _mesh_position(t, t_ref, p):
    """(n_ref, u_ref, u): mesh cycle and phase at ``t_ref``, and the phase of ``t`` in that cycle.

    Pair i (0 = the newest) is in contact while u_ref + i < eps; its position on
    the path of contact is u + i base pitches.
    """
    cycles_ref = p[OMEGA_MESH] * t_ref / TWO_PI
    n_ref = math.floor(cycles_ref)
    return n_ref, cycles_ref - n_ref, p[OMEGA_MESH] * t / TWO_PI - n_ref


@nb.njit(**INLINED)
def _friction_arms(kp, position, position_ref, p):
    """k_i sign_i s_i (pinion) and k_i sign_i (L - s_i) (gear) of one pair at ``position`` base pitches.

    Sliding reverses at the pitch point: beyond it (recess) the pinion flank
    slides faster than the gear flank; ``position_ref`` decides the side.
    """
    sign = 1.0 if position_ref > p[PITCH_POSITION] else -1.0
    s = p[PATH_START] + p[BASE_PITCH] * position
    return kp * sign * s, kp * sign * (p[LOA_LENGTH] - s)


@nb.njit(**INLINED)
def smooth_share(t, u_ref, u, p, pair_k, period_k):
    """(r, sum_i k_p(u + i)): a smooth stiffness table's share factor, and the pairs' Ishikawa sum.

    With a smooth period table (``fourier``, ``constant``) the table's k(t) is the mesh stiffness of
    healthy teeth, shared among the pairs in mesh in proportion to their Ishikawa stiffness: pair i
    carries r k_p(u + i), r = k(t) / sum_i k_p(u + i). Every path takes its pairs' stiffness from
    this one rule, so a damaged tooth removes its own share and tooth friction loads each pair by
    its share of the mesh force, whatever the table. Without a table: (1, 0), r not applied.
    """
    if p[USE_PERIOD_TABLE] == 0.0:
        return 1.0, 0.0
    eps = p[CONTACT_RATIO]
    healthy = 0.0
    i = 0
    while u_ref + i < eps:
        healthy += _interp_uniform(pair_k, u + i, eps)
        i += 1
    phase = p[OMEGA_MESH] * t / TWO_PI
    phase -= math.floor(phase)
    return _interp_uniform(period_k, phase, 1.0) / healthy, healthy


@nb.njit(**INLINED)
def modulated_scale(t, p):
    """The factor on every mesh stiffness at ``t``: the stiffness scale and the run-out's modulation
    1 + kappa cos(W_s t + phase) (docs/model/unmodelled-effects.md section 6)."""
    scale = p[STIFFNESS_SCALE]
    if p[ECC_KAPPA] != 0.0:
        scale *= 1.0 + p[ECC_KAPPA] * math.cos(p[ECC_OMEGA] * t + p[ECC_PHASE])
    return scale


@nb.njit(**JIT_OPTIONS)
def mesh_terms(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear):
    """Mesh stiffness and friction moment-arm sums at time ``t``.

    The pairs in contact (and each pair's friction direction) are those at
    ``t_ref``, a time strictly inside the current sub-step, so a sub-step
    ending on a breakpoint keeps one smooth stiffness branch. Each pair's
    stiffness is its share of a smooth table (:func:`smooth_share`) times its
    tooth factors.

    Returns
    -------
    k, arm_pinion, arm_gear
        Mesh stiffness (N/m) and sums of k_i * sign_i * arm_i over the pairs
        (pinion arms from T1, gear arms from T2), used for tooth friction.
    """
    n_ref, u_ref, u = _mesh_position(t, t_ref, p)
    eps = p[CONTACT_RATIO]
    friction = p[FRICTION]
    damaged = p[TOOTH_FACTORS] != 0.0
    smooth = p[USE_PERIOD_TABLE] != 0.0
    ratio, healthy = smooth_share(t, u_ref, u, p, pair_k, period_k)
    k = 0.0
    arm_pinion = 0.0
    arm_gear = 0.0
    i = 0
    while u_ref + i < eps:
        kp = _interp_uniform(pair_k, u + i, eps)
        pair = kp * ratio if smooth else kp
        if damaged:
            tooth = int(n_ref) - i
            factor = factor_pinion[tooth % int(p[Z1])] * factor_gear[tooth % int(p[Z2])]
            if smooth:
                # the tooth's loss of its share; the healthy sum is replaced by the table below
                k += pair * (factor - 1.0)
            pair *= factor
        k += kp if smooth else pair
        if friction != 0.0:
            pinion, gear = _friction_arms(pair, u + i, u_ref + i, p)
            arm_pinion += pinion
            arm_gear += gear
        i += 1
    if smooth:
        # the pairs' healthy sum replaced by the smooth curve, which carries their healthy share
        phase = p[OMEGA_MESH] * t / TWO_PI
        phase -= math.floor(phase)
        k += _interp_uniform(period_k, phase, 1.0) - healthy
    scale = modulated_scale(t, p)
    return k * scale, arm_pinion * scale, arm_gear * scale


@nb.njit(**INLINED)
def static_transmission_error(t, p):
    """e(t): mesh-periodic STE plus any shaft run-out term, m."""
    ste = p[STE_AMPLITUDE] * math.sin(p[OMEGA_MESH] * t + p[STE_PHASE])
    if p[ECC_AMPLITUDE] != 0.0:
        ste += p[ECC_AMPLITUDE] * math.sin(p[ECC_OMEGA] * t + p[ECC_PHASE])
    return ste


# The stepping code below keeps the state, stage derivatives and forcing terms in tuples
# (registers) rather than scratch arrays: slicing rows out of a work array costs reference
# counting on every stage (docs/validation/performance.md, "Compile time and inlining").


@nb.njit(**INLINED)
def _time_terms(t, sine, p):
    """(relative drive acceleration, e(t), e''(t)) given sin(omega t + STE phase)."""
    drive = p[T1]
    if p[RIPPLE_AMPLITUDE] != 0.0:
        drive *= 1.0 + p[RIPPLE_AMPLITUDE] * math.cos(p[RIPPLE_OMEGA] * t + p[RIPPLE_PHASE])
    adhesion = p[T2]
    if p[ADHESION_AMPLITUDE] != 0.0:
        adhesion += p[ADHESION_AMPLITUDE] * math.sin(p[ADHESION_OMEGA] * t + p[ADHESION_PHASE])
    ste = p[STE_AMPLITUDE] * sine
    ste_acc = -p[STE_AMPLITUDE] * p[OMEGA_MESH] * p[OMEGA_MESH] * sine
    if p[ECC_AMPLITUDE] != 0.0:
        ecc = p[ECC_AMPLITUDE] * math.sin(p[ECC_OMEGA] * t + p[ECC_PHASE])
        ste += ecc
        ste_acc -= p[ECC_OMEGA] * p[ECC_OMEGA] * ecc
    return p[R1] * drive / p[I1] + p[R2] * adhesion / p[I2], ste, ste_acc


@nb.njit(**JIT_OPTIONS)
def forcing(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear):
    """Time-only terms of the right-hand side at any time.

    Returns (k, friction term, relative drive acceleration
    R1 T1(t)/I1 + R2 T2(t)/I2, e(t), e''(t)); the friction term times the
    backlash function f(x) is the relative acceleration tooth friction takes
    away (see :func:`_friction_term`).
    """
    k, arm_pinion, arm_gear = mesh_terms(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear)
    drive, ste, ste_acc = _time_terms(t, math.sin(p[OMEGA_MESH] * t + p[STE_PHASE]), p)
    return k, _friction_term(arm_pinion, arm_gear, p), drive, ste, ste_acc


@nb.njit(**INLINED)
def _friction_term(arm_pinion, arm_gear, p):
    """mu (R1 sum_i k_i s_i sign_i / I1 + R2 sum_i k_i (L - s_i) sign_i / I2).

    The friction moments are -mu f(x) sum k_i s_i sign_i on the pinion and
    +mu f(x) sum k_i (L - s_i) sign_i on the gear, so R1 theta1'' - R2 theta2''
    loses f(x) times this term.
    """
    if p[FRICTION] == 0.0:
        return 0.0
    return p[FRICTION] * (p[R1] * arm_pinion / p[I1] + p[R2] * arm_gear / p[I2])


@nb.njit(**INLINED)
def coefficients(p):
    """The parameter slots the state-dependent part of the right-hand side reads, as a tuple (registers)."""
    return (
        p[HALF_BACKLASH],
        p[CM],
        p[DAMP_IN_SEPARATION],
        p[K1],
        p[K2],
        p[CLEARANCE1],
        p[CLEARANCE2],
        p[C1],
        p[C2],
        p[M1],
        p[M2],
        p[ME],
    )


@nb.njit(**INLINED)
def divided(x, y, z):
    """(x / y by IEEE division, True); ``z`` (1 / y) unused. The quotient of the one-sample kernels."""
    return x / y, True


#: The ``inverse`` argument of :func:`state_derivative_by` where the quotient does not read it.
NO_INVERSE = (1.0, 1.0, 1.0)


@nb.njit(**INLINED)
def mesh_damping(c, apart):
    """The mesh damping coefficient from :func:`coefficients`: c_m, or 0 where no tooth pair touches
    (``apart``) and the model has no damping in separation. Every path and the variational equations
    take the damping switch from here."""
    damping = c[1]
    if (c[2] == 0.0) & apart:  # no short circuit: a select, not a branch
        damping = 0.0
    return damping


@nb.njit(**INLINED)
def _accelerations(s, k, friction_term, drive, ste_acc, c, fx, damping, divide, inverse):
    """(ds/dt, mesh force F, whether each quotient is exact) from the forcing values, :func:`coefficients`,
    f(x), the mesh damping and a quotient function ``divide(x, y, 1 / y)`` (:func:`divided`, or
    :func:`uqgear.physics._quotient.quotient` with ``inverse`` = (1/m1, 1/m2, 1/m_e))."""
    _, _, _, k1, k2, clearance1, clearance2, c1, c2, m1, m2, me = c
    vx = s[5]
    force = k * fx + damping * vx
    bearing1 = k1 * dead_zone(s[0], clearance1)
    bearing2 = k2 * dead_zone(s[1], clearance2)
    a1, exact1 = divide(-c1 * s[3] - bearing1 - force, m1, inverse[0])
    a2, exact2 = divide(-c2 * s[4] - bearing2 + force, m2, inverse[1])
    per_mass, exact3 = divide(force, me, inverse[2])
    # R1 theta1'' - R2 theta2'' with the rigid-body rotation eliminated; tooth friction
    # (zero unless the friction effect is on) is linear in f(x), its time part precomputed
    relative = drive - per_mass - fx * friction_term
    return (s[3], s[4], vx, a1, a2, a1 - a2 + relative - ste_acc), force, exact1 & exact2 & exact3


@nb.njit(**INLINED)
def state_derivative_by(s, k, friction_term, drive, ste_acc, c, divide, inverse):
    """:func:`state_derivative` with the quotient function ``divide`` (see :func:`_accelerations`).

    Returns (ds/dt, F, whether every quotient is exact).
    """
    fx = dead_zone(s[2], c[0])
    return _accelerations(s, k, friction_term, drive, ste_acc, c, fx, mesh_damping(c, fx == 0.0), divide, inverse)


@nb.njit(**INLINED)
def state_derivative(s, k, friction_term, drive, ste_acc, c):
    """State-dependent part of the right-hand side from the forcing values and :func:`coefficients`.

    ``s`` = (y1, y2, x, y1', y2', x'); ``k``, ``friction_term``, ``drive``
    and ``ste_acc`` are the terms 0, 1, 2 and 4 of :func:`forcing`.
    Returns (ds/dt as a 6-tuple, mesh force F). The one expression of the
    model's accelerations: the one-sample and the lane kernels both call it
    (the lanes through :func:`state_derivative_by`), so they round alike.
    """
    d, force, _ = state_derivative_by(s, k, friction_term, drive, ste_acc, c, divided, NO_INVERSE)
    return d, force


@nb.njit(**INLINED)
def side_derivative(s, k, friction_term, drive, ste_acc, c, region):
    """:func:`state_derivative` with the mesh damping of contact region ``region`` (1, 0, -1), whatever x is.

    Without damping in separation the damping force switches at |x| = b; a
    step split there evaluates each part with its own side's damping, so
    that neither part sees the other side's vector field (its stages may
    stray across the boundary by round-off or by the step's own error).
    With damping in separation this is :func:`state_derivative`, bit for bit.
    """
    fx = dead_zone(s[2], c[0])
    damping = mesh_damping(c, region == 0)
    d, force, _ = _accelerations(s, k, friction_term, drive, ste_acc, c, fx, damping, divided, NO_INVERSE)
    return d, force


@nb.njit(**INLINED)
def derivative(s, terms, p):
    """State-dependent part of the right-hand side.

    ``s`` = (y1, y2, x, y1', y2', x'), ``terms`` from :func:`forcing`.
    Returns (ds/dt as a 6-tuple, mesh force F).
    """
    return state_derivative(s, terms[0], terms[1], terms[2], terms[4], coefficients(p))


@nb.njit(**INLINED)
def _shifted(s, h, d):
    return (s[0] + h * d[0], s[1] + h * d[1], s[2] + h * d[2], s[3] + h * d[3], s[4] + h * d[4], s[5] + h * d[5])


@nb.njit(**INLINED)
def rk4_combine_weighted(s, w, d1, d2, d3, d4):
    """The classical RK4 update of ``s`` from its four stage derivatives, with the weight w = h / 6 given."""
    return (
        s[0] + w * (d1[0] + 2.0 * d2[0] + 2.0 * d3[0] + d4[0]),
        s[1] + w * (d1[1] + 2.0 * d2[1] + 2.0 * d3[1] + d4[1]),
        s[2] + w * (d1[2] + 2.0 * d2[2] + 2.0 * d3[2] + d4[2]),
        s[3] + w * (d1[3] + 2.0 * d2[3] + 2.0 * d3[3] + d4[3]),
        s[4] + w * (d1[4] + 2.0 * d2[4] + 2.0 * d3[4] + d4[4]),
        s[5] + w * (d1[5] + 2.0 * d2[5] + 2.0 * d3[5] + d4[5]),
    )


@nb.njit(**INLINED)
def rk4_combine(s, h, d1, d2, d3, d4):
    """The classical RK4 update of ``s`` over ``h`` from its four stage derivatives."""
    return rk4_combine_weighted(s, h / 6.0, d1, d2, d3, d4)


@nb.njit(**INLINED)
def rk4_stages(field, divide, s, h, d1, mid, end, context):
    """The later stage derivatives d2, d3, d4 of the classical RK4 step from ``s`` over ``h`` given its first
    stage ``d1``: the one stage sequence of every integrator of the package.

    ``field(state, terms, context, divide)`` is the right-hand side, returning (ds/dt, whether its
    quotients are exact); ``mid`` and ``end`` are its forcing terms at the step's midpoint and end;
    ``divide`` the quotient function (:func:`state_derivative_by`). Each caller passes its own field
    (classical, one side's damping, per pair, lanes, the variational pass), specialised and inlined at
    compile time. Returns (d2, d3, d4, whether every quotient of these stages is exact).
    """
    d2, exact2 = field(_shifted(s, 0.5 * h, d1), mid, context, divide)
    d3, exact3 = field(_shifted(s, 0.5 * h, d2), mid, context, divide)
    d4, exact4 = field(_shifted(s, h, d3), end, context, divide)
    return d2, d3, d4, exact2 & exact3 & exact4


@nb.njit(**INLINED)
def rk4_with(field, divide, s, h, w, d1, mid, end, context):
    """The classical RK4 step from ``s`` over ``h`` (w = h / 6) given its first stage ``d1``
    (:func:`rk4_stages`). Returns (new state, whether every quotient of the later stages is exact)."""
    d2, d3, d4, exact = rk4_stages(field, divide, s, h, d1, mid, end, context)
    return rk4_combine_weighted(s, w, d1, d2, d3, d4), exact


@nb.njit(**INLINED)
def _classical_field(s, terms, p, divide):
    """:func:`derivative` as a field of :func:`rk4_with` (``terms`` from :func:`forcing`)."""
    d, _ = derivative(s, terms, p)
    return d, True


@nb.njit(**INLINED)
def _table_field(s, terms, context, divide):
    """:func:`state_derivative_by` as a field of :func:`rk4_with`: ``terms`` a forcing 4-tuple (k, friction
    term, drive, e''), ``context`` (:func:`coefficients`, the inverse masses ``divide`` reads)."""
    c, inverse = context
    d, _, exact = state_derivative_by(s, terms[0], terms[1], terms[2], terms[3], c, divide, inverse)
    return d, exact


@nb.njit(**INLINED)
def _side_field(s, terms, context, divide):
    """:func:`side_derivative` as a field of :func:`rk4_with`: ``context`` (:func:`coefficients`, region)."""
    c, region = context
    d, _ = side_derivative(s, terms[0], terms[1], terms[2], terms[4], c, region)
    return d, True


@nb.njit(**INLINED)
def _rk4(s, h, d1, mid, end, p):
    """One classical RK4 step from ``s`` with first stage ``d1`` and the forcing at the midpoint and end."""
    new, _ = rk4_with(_classical_field, divided, s, h, h / 6.0, d1, mid, end, p)
    return new


@nb.njit(**INLINED)
def rk4_step_weighted(s, h, w, d1, mid, end, c, divide, inverse):
    """:func:`_rk4` from forcing 4-tuples (k, friction term, drive, e''), :func:`coefficients`, w = h / 6 and a
    quotient function (:func:`state_derivative_by`). Returns (new state, whether every quotient is exact)."""
    return rk4_with(_table_field, divide, s, h, w, d1, mid, end, (c, inverse))


@nb.njit(**INLINED)
def rk4_step(s, h, d1, mid, end, c):
    """:func:`_rk4` from forcing 4-tuples (k, friction term, drive, e'') and :func:`coefficients`."""
    new, _ = rk4_step_weighted(s, h, h / 6.0, d1, mid, end, c, divided, NO_INVERSE)
    return new


#: A contact crossing closer than this fraction of a step to either end is not split at: the parts
#: would be too short to gain anything over the unsplit step.
SPLIT_MARGIN = 1e-9


@nb.njit(**INLINED)
def splits_step(theta):
    """Whether a step is split at the crossing fraction ``theta`` (:data:`SPLIT_MARGIN`)."""
    return SPLIT_MARGIN < theta < 1.0 - SPLIT_MARGIN


#: Bisection steps of a contact crossing on a step's Hermite interpolant: 2^-40 of a step, far below
#: the step's own error.
BISECTIONS = 40


@nb.njit(**JIT_OPTIONS)
def crossing_fraction(x0, v0, x1, v1, h, level, iterations):
    """Fraction of a step where the cubic Hermite interpolant of x reaches ``level``, by ``iterations``
    bisection steps: the one bisection of every split step (the fast path's, the per-pair path's and
    the variational pass's)."""
    lo = 0.0
    hi = 1.0
    g_lo = x0 - level
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        s = mid
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = s**3 - 2 * s**2 + s
        h01 = -2 * s**3 + 3 * s**2
        h11 = s**3 - s**2
        value = h00 * x0 + h10 * h * v0 + h01 * x1 + h11 * h * v1 - level
        if (value > 0.0) == (g_lo > 0.0):
            lo = mid
            g_lo = value
        else:
            hi = mid
    return 0.5 * (lo + hi)


@nb.njit(**INLINED)
def _crossing_fraction(x0, v0, x1, v1, h, level):
    """:func:`crossing_fraction` to :data:`BISECTIONS` steps: where the integrators split a step."""
    return crossing_fraction(x0, v0, x1, v1, h, level, BISECTIONS)


@nb.njit(**INLINED)
def _rk4_side(s, h, d1, mid, end, p, region):
    """:func:`_rk4` with the later stages on the mesh damping of contact region ``region`` (:func:`side_derivative`)."""
    new, _ = rk4_with(_side_field, divided, s, h, h / 6.0, d1, mid, end, (coefficients(p), region))
    return new


@nb.njit(**INLINED)
def crossed_boundary(before, after, b):
    """(boundary level, region entered) of a step from contact region ``before`` to ``after``.

    The level is that of the boundary next to the side the step leaves; the region entered is the
    one just beyond it (a step from one contact side to the other enters separation first).
    """
    if before == 1 or (before == 0 and after == -1):
        level = b if before == 1 else -b
    else:
        level = -b if before == -1 else b
    entered = 0 if before != 0 else (1 if level > 0.0 else -1)
    return level, entered


@nb.njit(**JIT_OPTIONS)
def _split_at_contact(t, h, s, d1, trial, t_ref, p, pair_k, period_k, fp, fg):
    """``trial`` (the step from ``s`` over [t, t+h]), redone in two parts where it changes the
    contact region, split where the cubic Hermite interpolant of x crosses the boundary.

    Each part is integrated with the mesh damping of its own side of the boundary
    (:func:`side_derivative`), the second from the derivative at the split point on the side the
    step enters. Without damping in separation the damping force switches at the boundary, and a
    stage evaluated with the other side's damping costs an error of the order of the step at
    every crossing (first-order convergence); the crossing is then also located on the step taken
    with the first side's damping throughout, not on ``trial``, whose later stages mix the two
    sides. With damping in separation the vector field is continuous there and both sides'
    damping is the same: the parts are the plain RK4 steps, bit for bit.
    """
    b = p[HALF_BACKLASH]
    before = contact_region(s[2], b)
    after = contact_region(trial[2], b)
    if before == after:
        return trial
    level, entered = crossed_boundary(before, after, b)
    end = forcing(t + h, t_ref, p, pair_k, period_k, fp, fg)
    if p[DAMP_IN_SEPARATION] == 0.0:
        trial = _rk4_side(s, h, d1, forcing(t + 0.5 * h, t_ref, p, pair_k, period_k, fp, fg), end, p, before)
    theta = _crossing_fraction(s[2], s[5], trial[2], trial[5], h, level)
    if not splits_step(theta):
        return trial
    h_a = theta * h
    h_b = h - h_a
    middle = forcing(t + h_a, t_ref, p, pair_k, period_k, fp, fg)
    part = _rk4_side(s, h_a, d1, forcing(t + 0.5 * h_a, t_ref, p, pair_k, period_k, fp, fg), middle, p, before)
    d_middle, _ = side_derivative(part, middle[0], middle[1], middle[2], middle[4], coefficients(p), entered)
    return _rk4_side(
        part, h_b, d_middle, forcing(t + h_a + 0.5 * h_b, t_ref, p, pair_k, period_k, fp, fg), end, p, entered
    )


# ---------------------------------------------------------------- one mesh period tabulated
# fields of a tabulated stage: healthy k, friction arm sums, sin(omega t + STE phase), then
# per pair in contact its healthy stiffness and friction arms (for tooth factors); with a smooth
# table, k is the table's and each pair's fields are its share of it (smooth_share)
(F_K, F_ARM_PINION, F_ARM_GEAR, F_SINE) = range(4)
N_FIELDS = 4 + 3 * MAX_PAIRS


@nb.njit(**JIT_OPTIONS)
def _tabulate_stage(t, t_ref, p, pair_k, period_k, row):
    """The mesh-periodic forcing at local time ``t`` (first mesh period) into ``row``; returns the pair count."""
    _, u_ref, u = _mesh_position(t, t_ref, p)
    eps = p[CONTACT_RATIO]
    k = 0.0
    arm_pinion = 0.0
    arm_gear = 0.0
    i = 0
    while u_ref + i < eps:
        if i >= MAX_PAIRS:
            raise ValueError("more tooth pairs in contact than a schedule holds")
        kp = _interp_uniform(pair_k, u + i, eps)
        pinion, gear = _friction_arms(kp, u + i, u_ref + i, p)
        row[4 + 3 * i] = kp
        row[5 + 3 * i] = pinion
        row[6 + 3 * i] = gear
        k += kp
        arm_pinion += pinion
        arm_gear += gear
        i += 1
    if p[USE_PERIOD_TABLE] != 0.0:
        # the smooth curve, each pair its share of it (smooth_share): what tooth factors and friction act on
        phase = p[OMEGA_MESH] * t / TWO_PI
        phase -= math.floor(phase)
        smooth = _interp_uniform(period_k, phase, 1.0)
        ratio = smooth / k
        k = smooth
        arm_pinion = 0.0
        arm_gear = 0.0
        for j in range(i):
            row[4 + 3 * j] *= ratio
            row[5 + 3 * j] *= ratio
            row[6 + 3 * j] *= ratio
            arm_pinion += row[5 + 3 * j]
            arm_gear += row[6 + 3 * j]
    row[F_K] = k
    row[F_ARM_PINION] = arm_pinion
    row[F_ARM_GEAR] = arm_gear
    row[F_SINE] = math.sin(p[OMEGA_MESH] * t + p[STE_PHASE])
    return i


@nb.njit(**JIT_OPTIONS)
def build_schedule(p, pair_k, period_k, breakpoints, steps_per_period):
    """Sub-steps of one mesh period and their forcing at RK4's three stage times.

    Everything in the forcing that repeats every mesh period (pair
    stiffnesses, friction arms, the STE phase) is evaluated here once per
    run instead of three times per step; the effect slots that do not repeat
    (run-out, tooth factors, torque ripple, adhesion oscillation) are applied
    on top in :func:`_forcing_row`. Grid step ``j`` of any period is made of
    sub-steps ``first_sub[j]`` to ``first_sub[j + 1] - 1`` (split at the
    stiffness breakpoints exactly as the generic stepping would).

    Returns
    -------
    first_sub, offsets, widths, refs, pairs, table
        ``offsets``/``widths``/``refs``: sub-step start, length and reference
        time (its midpoint) within the period; ``pairs``: pairs in contact;
        ``table``: (sub-step, stage, field) forcing values.
    """
    period = TWO_PI / p[OMEGA_MESH]
    h = period / steps_per_period
    capacity = steps_per_period * (breakpoints.size + 1)
    offsets = np.empty(capacity)
    widths = np.empty(capacity)
    refs = np.empty(capacity)
    pairs = np.empty(capacity, dtype=np.int64)
    table = np.zeros((capacity, 3, N_FIELDS))
    first_sub = np.empty(steps_per_period + 1, dtype=np.int64)
    du = p[OMEGA_MESH] * h / TWO_PI
    count = 0
    for j in range(steps_per_period):
        first_sub[j] = count
        t_now = j * h
        end = (j + 1) * h
        cycles0 = p[OMEGA_MESH] * t_now / TWO_PI
        base = math.floor(cycles0 + 1e-9)
        u0 = cycles0 - base
        for bp in breakpoints:
            if u0 + 1e-12 < bp < u0 + du - 1e-12:
                t_break = (base + bp) * TWO_PI / p[OMEGA_MESH]
                count = _add_substep(t_now, t_break, count, p, pair_k, period_k, offsets, widths, refs, pairs, table)
                t_now = t_break
        count = _add_substep(t_now, end, count, p, pair_k, period_k, offsets, widths, refs, pairs, table)
    first_sub[steps_per_period] = count
    return first_sub, offsets, widths, refs, pairs, table


@nb.njit(**JIT_OPTIONS)
def _add_substep(start, end, count, p, pair_k, period_k, offsets, widths, refs, pairs, table):
    t_ref = 0.5 * (start + end)
    offsets[count] = start
    widths[count] = end - start
    refs[count] = t_ref
    pairs[count] = _tabulate_stage(start, t_ref, p, pair_k, period_k, table[count, 0])
    _tabulate_stage(0.5 * (start + end), t_ref, p, pair_k, period_k, table[count, 1])
    _tabulate_stage(end, t_ref, p, pair_k, period_k, table[count, 2])
    return count + 1


@nb.njit(**INLINED)
def _forcing_row(t, n, table, sub, stage, n_pairs, p, factor_pinion, factor_gear):
    """:func:`forcing` at absolute time ``t`` in mesh period ``n`` from a tabulated stage."""
    k = table[sub, stage, F_K]
    arm_pinion = table[sub, stage, F_ARM_PINION]
    arm_gear = table[sub, stage, F_ARM_GEAR]
    if p[TOOTH_FACTORS] != 0.0:
        for i in range(n_pairs):
            extra = tooth_extra(n - i, p, factor_pinion, factor_gear)
            k += table[sub, stage, 4 + 3 * i] * extra
            arm_pinion += table[sub, stage, 5 + 3 * i] * extra
            arm_gear += table[sub, stage, 6 + 3 * i] * extra
    return scaled_forcing(t, k, arm_pinion, arm_gear, table[sub, stage, F_SINE], p)


@nb.njit(**INLINED)
def tooth_extra(tooth, p, factor_pinion, factor_gear):
    """The tooth factors' change of pair stiffness, f_pinion f_gear - 1, of the pair entering in period ``tooth``."""
    return factor_pinion[tooth % int(p[Z1])] * factor_gear[tooth % int(p[Z2])] - 1.0


@nb.njit(**INLINED)
def scaled_forcing(t, k, arm_pinion, arm_gear, sine, p):
    """:func:`forcing` at ``t`` from the pair sums ``k`` and friction arms (tooth factors applied) and
    sin(omega t + STE phase): the stiffness scale, the run-out's modulation and the time terms."""
    scale = modulated_scale(t, p)
    drive, ste, ste_acc = _time_terms(t, sine, p)
    return k * scale, _friction_term(arm_pinion * scale, arm_gear * scale, p), drive, ste, ste_acc


@nb.njit(**INLINED)
def classical_step(n, j, period, s, p, pair_k, period_k, fp, fg, schedule):
    """Advance the state tuple ``s`` over grid step ``j`` of mesh period ``n`` (no pitch errors).

    ``schedule`` comes from :func:`build_schedule`: the step is split at the
    stiffness breakpoints, and each sub-step, which sees one smooth
    stiffness branch, is split once more where it crosses a contact
    boundary.

    Returns
    -------
    state, force, a1, a2
        The new state tuple, and the mesh force and accelerations of y1, y2
        at the step's start (first RK4 stage).
    """
    first_sub, offsets, widths, refs, pairs, table = schedule
    start = n * period
    force = 0.0
    a1 = 0.0
    a2 = 0.0
    for sub in range(first_sub[j], first_sub[j + 1]):
        t = start + offsets[sub]
        h = widths[sub]
        n_pairs = pairs[sub]
        d1, f = derivative(s, _forcing_row(t, n, table, sub, 0, n_pairs, p, fp, fg), p)
        if sub == first_sub[j]:
            force = f
            a1 = d1[3]
            a2 = d1[4]
        trial = _rk4(
            s,
            h,
            d1,
            _forcing_row(t + 0.5 * h, n, table, sub, 1, n_pairs, p, fp, fg),
            _forcing_row(t + h, n, table, sub, 2, n_pairs, p, fp, fg),
            p,
        )
        if contact_region(s[2], p[HALF_BACKLASH]) == contact_region(trial[2], p[HALF_BACKLASH]):
            s = trial
        else:
            s = _split_at_contact(t, h, s, d1, trial, start + refs[sub], p, pair_k, period_k, fp, fg)
    return s, force, a1, a2


@nb.njit(**INLINED)
def mesh_contact(x, n, n_pairs, p):
    """Contact state (1 drive, 0 apart, -1 back side) of the mesh as a whole: from x alone.

    The signature of :func:`uqgear.physics._pairs.pair_contact`, so that a
    kernel takes either as its contact function.
    """
    return contact_region(x, p[HALF_BACKLASH])
