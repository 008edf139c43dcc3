"""The model's right-hand side, compiled with numba: the base of every kernel.

One right-hand side serves every integrator (the scipy reference calls it
too), and every model extension of docs/model/unmodelled-effects.md section 6 is a slot in the
parameter vector whose neutral value switches it off, so effects plug in
without forking the integrator. The accelerations are written once
(:func:`_accelerations`), as are the mesh damping's switch in separation
(:func:`mesh_damping`), each pair's share of the mesh stiffness
(:func:`smooth_share`), its tooth factor (:func:`teeth_factor`) and the stiffness
modulation (:func:`run_out_modulation`), and :func:`mesh_terms` lists where a
pair's stiffness is assembled from them;
the slots the accelerations read are listed once (:func:`coefficients_by`, read
from a parameter vector and from a lane group's work array), and the time-only
terms are written once for the constant-speed and the run-up model
(:func:`drive_acceleration`, :func:`ste_terms`, at the shaft angle's clock).
docs/model/integrators.md, "Adding a force term or a time-only effect", says
where a new term goes. The time stepping lives in :mod:`uqgear.physics._stepper`; the kernels above
it: :mod:`uqgear.physics._pairs` (pitch errors), :mod:`uqgear.physics._kernels`
(one-sample kernels, which also re-exports the names its callers read from here) and
:mod:`uqgear.physics._lanes` (samples as SIMD lanes).

These helpers are inlined into kernels in other files: a cached kernel is
keyed on the contents of every compiled module of the package
(:mod:`uqgear.physics._cache`), so editing this one recompiles them all.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb

from uqgear.physics._cache import register_kernel_cache

# before any kernel of the package is compiled or loaded from the cache
register_kernel_cache()

# ---------------------------------------------------------------- parameter slots
#: Names of the parameter slots, in order: the one list of them. The slot constants below (each its
#: name in capitals, a global that numba compiles as a constant) take their positions from it, and
#: import fails where one is missing or out of place.
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
) = range(len(PARAMETER_SLOTS))
#: Number of named slots. The parameter vector goes on with the per-tooth pitch offsets
#: (m): z1 of the pinion from index ``N_PARAMS``, then z2 of the gear (docs/model/equations.md
#: section 2.6); ``PITCH_ERRORS`` is 1 when any of them is not zero.
N_PARAMS = len(PARAMETER_SLOTS)
if any(globals()[name.upper()] != slot for slot, name in enumerate(PARAMETER_SLOTS)):
    raise RuntimeError("a parameter slot's constant is not at its name's position")  # pragma: no cover - a source error

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
def table_stiffness(t, p, period_k):
    """k(t): a smooth period table's mesh stiffness of healthy teeth at ``t`` (N/m, before the stiffness scale),
    read at ``t``'s phase in its mesh period."""
    phase = p[OMEGA_MESH] * t / TWO_PI
    phase -= math.floor(phase)
    return _interp_uniform(period_k, phase, 1.0)


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
    return table_stiffness(t, p, period_k) / healthy, healthy


@nb.njit(**INLINED)
def run_out_modulation(t, scale, kappa, omega, phase):
    """``scale`` times the run-out's stiffness modulation 1 + kappa cos(omega t + phase)
    (docs/model/unmodelled-effects.md section 6): the factor on every pair's stiffness at ``t``.

    The one expression of the modulation; every kernel family takes it from here (through
    :func:`modulated_scale` or with the slots read by the caller). Its arguments are scalars: a
    helper that takes an array costs that array's reference count on every call, and the
    tabulated stages call this three times a sub-step (docs/validation/performance.md).
    """
    if kappa != 0.0:
        scale *= 1.0 + kappa * math.cos(omega * t + phase)
    return scale


@nb.njit(**INLINED)
def modulated_scale(t, p):
    """The factor on every mesh stiffness at ``t``: the stiffness scale and the run-out's modulation
    (:func:`run_out_modulation` with the slots of ``p``)."""
    return run_out_modulation(t, p[STIFFNESS_SCALE], p[ECC_KAPPA], p[ECC_OMEGA], p[ECC_PHASE])


@nb.njit(**INLINED)
def teeth_factor(pinion_tooth, gear_tooth, factor_pinion, factor_gear):
    """The stiffness factor f_pinion f_gear of pinion tooth ``pinion_tooth`` meshing with gear tooth
    ``gear_tooth`` (1 for healthy teeth): the one expression of a pair's tooth factor."""
    return factor_pinion[pinion_tooth] * factor_gear[gear_tooth]


@nb.njit(**INLINED)
def tooth_factor(tooth, p, factor_pinion, factor_gear):
    """The stiffness factor f_pinion f_gear of the pair that entered the mesh in period ``tooth``
    (pinion tooth ``tooth mod z1`` on gear tooth ``tooth mod z2``; 1 for healthy teeth)."""
    return teeth_factor(tooth % int(p[Z1]), tooth % int(p[Z2]), factor_pinion, factor_gear)


@nb.njit(**JIT_OPTIONS)
def mesh_terms(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear):
    """Mesh stiffness and friction moment-arm sums at time ``t``.

    The pairs in contact (and each pair's friction direction) are those at
    ``t_ref``, a time strictly inside the current sub-step, so a sub-step
    ending on a breakpoint keeps one smooth stiffness branch.

    Pair i's stiffness is k_p(u + i) r f s(t): its Ishikawa stiffness (the ``pair_k`` table), with a
    smooth period table its share factor r (:func:`smooth_share`, of the table's k(t),
    :func:`table_stiffness`), its tooth factor f (:func:`tooth_factor`, :func:`teeth_factor`) and
    the stiffness scale with the run-out's modulation s(t) (:func:`run_out_modulation`). It is
    assembled from these pieces in three places:

    * here, at any time: the one-sample kernels' split parts (:func:`forcing`) and the run-up
      kernels and lanes;
    * the tabulated stage: :func:`uqgear.physics._stepper._tabulate_stage` stores k_p r of each pair
      for one mesh period, and the tooth factors (``_stepper.tooth_extra``) and s(t)
      (``_stepper.scaled_forcing``) act on it in every period (``_stepper._forcing_row``, the lane
      tables, the run-up's schedule);
    * per pair, for pitch errors: :func:`uqgear.physics._pairs._pair` at any time, and
      ``_pairs._row_pair`` from a tabulated stage with the tooth factors of ``_pairs._tooth_terms``
      and s(t) applied in ``_pairs._forcing_row_pairs``.

    A stiffness factor goes into the shared piece it belongs to (a factor of one pair's teeth:
    :func:`teeth_factor`; of the whole mesh at a time: :func:`run_out_modulation`; of the table's
    k(t): :func:`table_stiffness`, which :func:`smooth_share` and the tabulated stage, dividing by the
    pairs' sum it has just taken, turn into the share), which every path calls. The pair loads of
    :mod:`uqgear.dynamics.tooth_loads` assemble the same product in numpy, for whole histories.

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
            factor = tooth_factor(int(n_ref) - i, p, factor_pinion, factor_gear)
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
        k += table_stiffness(t, p, period_k) - healthy
    scale = modulated_scale(t, p)
    return k * scale, arm_pinion * scale, arm_gear * scale


@nb.njit(**INLINED)
def drive_acceleration(tau, t, p):
    """R1 T1 / I1 + R2 T2 / I2: the relative acceleration the torques drive, with the torque ripple at the
    shaft angle's clock ``tau`` and the adhesion oscillation at time ``t`` (the same at constant speed).

    The one expression of the torques' time-only effects: the constant-speed forcing
    (:func:`_time_terms`) and the run-up's (:func:`uqgear.physics._runup_kernels.time_part`) take it
    from here. A time-only effect on a torque is written here alone (and, if it changes from one mesh
    period to the next, named in :func:`periodic_forcing`).
    """
    drive = p[T1]
    if p[RIPPLE_AMPLITUDE] != 0.0:
        drive *= 1.0 + p[RIPPLE_AMPLITUDE] * math.cos(p[RIPPLE_OMEGA] * tau + p[RIPPLE_PHASE])
    adhesion = p[T2]
    if p[ADHESION_AMPLITUDE] != 0.0:
        adhesion += p[ADHESION_AMPLITUDE] * math.sin(p[ADHESION_OMEGA] * t + p[ADHESION_PHASE])
    return p[R1] * drive / p[I1] + p[R2] * adhesion / p[I2]


@nb.njit(**INLINED)
def mesh_ste(sine, cosine, p):
    """(e, de/dtau, d2e/dtau2) of the mesh-periodic STE from sin and cos of Omega tau + STE phase."""
    ste = p[STE_AMPLITUDE] * sine
    ste_tau = p[STE_AMPLITUDE] * p[OMEGA_MESH] * cosine
    ste_tautau = -p[STE_AMPLITUDE] * p[OMEGA_MESH] * p[OMEGA_MESH] * sine
    return ste, ste_tau, ste_tautau


@nb.njit(**INLINED)
def ste_terms(tau, sine, cosine, p):
    """(e, de/dtau, d2e/dtau2) of the static transmission error at the shaft angle's clock ``tau``, given
    sin and cos of Omega tau + STE phase: the mesh-periodic STE plus any shaft run-out term.

    The one expression of the STE's time-only terms; at constant speed tau is t and d2e/dtau2 is e''
    (the derivative de/dtau, and the cosine it takes, are then not used, and the compiler drops
    them). A time-only effect on the STE is written here alone (and, if it changes from one mesh
    period to the next, named in :func:`periodic_forcing`).
    """
    ste, ste_tau, ste_tautau = mesh_ste(sine, cosine, p)
    # the slots read before the branch: an array whose last use is inside a branch costs a reference
    # count on every call (docs/validation/performance.md, "Compile time and inlining")
    amplitude = p[ECC_AMPLITUDE]
    omega = p[ECC_OMEGA]
    phase = p[ECC_PHASE]
    if amplitude != 0.0:
        angle = omega * tau + phase
        ecc = amplitude * math.sin(angle)
        ste += ecc
        ste_tau += amplitude * omega * math.cos(angle)
        ste_tautau -= omega * omega * ecc
    return ste, ste_tau, ste_tautau


@nb.njit(**INLINED)
def periodic_forcing(p):
    """Whether a run's forcing repeats every mesh period: no tooth factors, run-out, torque ripple or
    adhesion oscillation. A lane group holding another run fills its forcing table every period."""
    return (
        p[TOOTH_FACTORS] == 0.0
        and p[ECC_AMPLITUDE] == 0.0
        and p[ECC_KAPPA] == 0.0
        and p[RIPPLE_AMPLITUDE] == 0.0
        and p[ADHESION_AMPLITUDE] == 0.0
    )


@nb.njit(**INLINED)
def static_transmission_error(t, p):
    """e(t): mesh-periodic STE plus any shaft run-out term, m (:func:`ste_terms`)."""
    ste, _, _ = ste_terms(t, math.sin(p[OMEGA_MESH] * t + p[STE_PHASE]), 0.0, p)
    return ste


# The stepping code below keeps the state, stage derivatives and forcing terms in tuples
# (registers) rather than scratch arrays: slicing rows out of a work array costs reference
# counting on every stage (docs/validation/performance.md, "Compile time and inlining").


@nb.njit(**INLINED)
def _time_terms(t, sine, p):
    """(relative drive acceleration, e(t), e''(t)) given sin(omega t + STE phase) (:func:`drive_acceleration`,
    :func:`ste_terms` at tau = t)."""
    ste, _, ste_acc = ste_terms(t, sine, 0.0, p)
    return drive_acceleration(t, t, p), ste, ste_acc


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
def coefficients_by(read, source, lane):
    """The parameter slots the state-dependent part of the right-hand side reads, as a tuple (registers):
    the one list of them. ``read(source, slot, position, lane)`` returns slot ``slot``, which the tuple
    holds at ``position``: from a parameter vector (:func:`coefficients`) or from a lane group's work
    array (:func:`uqgear.physics._lane_loop.lane_coefficients`). A force term that needs a parameter
    appends its slot here, at the next position, and reads it in :func:`_accelerations`."""
    return (
        read(source, HALF_BACKLASH, 0, lane),
        read(source, CM, 1, lane),
        read(source, DAMP_IN_SEPARATION, 2, lane),
        read(source, K1, 3, lane),
        read(source, K2, 4, lane),
        read(source, CLEARANCE1, 5, lane),
        read(source, CLEARANCE2, 6, lane),
        read(source, C1, 7, lane),
        read(source, C2, 8, lane),
        read(source, M1, 9, lane),
        read(source, M2, 10, lane),
        read(source, ME, 11, lane),
    )


@nb.njit(**INLINED)
def _slot_of(p, slot, position, lane):
    """Slot ``slot`` of the parameter vector ``p`` (a reader of :func:`coefficients_by`)."""
    return p[slot]


@nb.njit(**INLINED)
def coefficients(p):
    """The parameter slots the state-dependent part of the right-hand side reads (:func:`coefficients_by`)."""
    return coefficients_by(_slot_of, p, 0)


def _listed(what: int) -> tuple[int, ...]:
    """The slots (``what`` 1) or positions (``what`` 2) :func:`coefficients_by` lists, in order (in Python)."""
    return tuple(coefficients_by.py_func(lambda source, slot, position, lane: (slot, position)[what - 1], None, 0))


#: The parameter slots :func:`coefficients` holds, in its order.
COEFFICIENT_SLOTS = _listed(1)
#: Length of :func:`coefficients`.
N_COEFFICIENTS = len(COEFFICIENT_SLOTS)
if _listed(2) != tuple(range(N_COEFFICIENTS)):
    raise RuntimeError("coefficients_by lists its positions out of order")  # pragma: no cover - a source error


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
