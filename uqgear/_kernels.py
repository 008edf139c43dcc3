"""Compiled right-hand side and fixed-step integrators (numba).

One right-hand side serves every integrator (the scipy reference calls it
too), and every model extension of model.md section 6 is a slot in the
parameter vector whose neutral value switches it off, so effects plug in
without forking the integrator.

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
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

# ---------------------------------------------------------------- parameter slots
(M1, M2, ME, K1, K2, C1, C2, CM, HALF_BACKLASH, R1, R2, I1, I2, T1, T2, OMEGA_MESH,
 STE_AMPLITUDE, STE_PHASE, STIFFNESS_SCALE, DAMP_IN_SEPARATION,
 RIPPLE_AMPLITUDE, RIPPLE_OMEGA, RIPPLE_PHASE,
 ADHESION_AMPLITUDE, ADHESION_OMEGA, ADHESION_PHASE,
 ECC_AMPLITUDE, ECC_OMEGA, ECC_PHASE, ECC_KAPPA,
 FRICTION, CLEARANCE1, CLEARANCE2,
 PATH_START, BASE_PITCH, LOA_LENGTH, PITCH_POSITION, CONTACT_RATIO,
 USE_PERIOD_TABLE, Z1, Z2, TOOTH_FACTORS) = range(42)
N_PARAMS = 42

#: Names of the parameter slots, in order (for error messages and tests).
PARAMETER_SLOTS = (
    "m1", "m2", "me", "k1", "k2", "c1", "c2", "cm", "half_backlash", "R1", "R2", "I1", "I2",
    "T1", "T2", "omega_mesh", "ste_amplitude", "ste_phase", "stiffness_scale",
    "damp_in_separation", "ripple_amplitude", "ripple_omega", "ripple_phase",
    "adhesion_amplitude", "adhesion_omega", "adhesion_phase", "ecc_amplitude", "ecc_omega",
    "ecc_phase", "ecc_kappa", "friction", "clearance1", "clearance2", "path_start",
    "base_pitch", "loa_length", "pitch_position", "contact_ratio", "use_period_table", "z1", "z2",
    "tooth_factors",
)

# QoI accumulator layout of the batch kernel
(Q_X_SUM, Q_X_SQ, Q_X_MIN, Q_X_MAX, Q_F_MAX, Q_A1_SQ, Q_A2_SQ, Q_N_DRIVE, Q_N_SEP, Q_N_BACK,
 Q_COUNT, Q_LYAPUNOV, Q_F_MIN) = range(13)
N_ACCUMULATORS = 13

TWO_PI = 2.0 * math.pi
#: Rows of the scratch array ``work`` that :func:`step` needs (k2, k3, k4, tmp, forcing terms).
WORK_ROWS = 5


@nb.njit(cache=True, inline="always", error_model="numpy", fastmath=True)
def dead_zone(x, half_width):
    """Backlash function f(x): x - b above b, x + b below -b, 0 between."""
    if x > half_width:
        return x - half_width
    if x < -half_width:
        return x + half_width
    return 0.0


@nb.njit(cache=True, inline="always", error_model="numpy", fastmath=True)
def contact_region(x, half_width):
    """1 drive-side contact, 0 separation, -1 back-side contact."""
    if x > half_width:
        return 1
    if x < -half_width:
        return -1
    return 0


@nb.njit(cache=True, inline="always", error_model="numpy", fastmath=True)
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


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def mesh_terms(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear):
    """Mesh stiffness and friction moment-arm sums at time ``t``.

    The pairs in contact (and each pair's friction direction) are those at
    ``t_ref``, a time strictly inside the current sub-step, so a sub-step
    ending on a breakpoint keeps one smooth stiffness branch.

    Returns
    -------
    k, arm_pinion, arm_gear
        Mesh stiffness (N/m) and sums of k_i * sign_i * arm_i over the pairs
        (pinion arms from T1, gear arms from T2), used for tooth friction.
    """
    cycles_ref = p[OMEGA_MESH] * t_ref / TWO_PI
    n_ref = math.floor(cycles_ref)
    u_ref = cycles_ref - n_ref
    u = p[OMEGA_MESH] * t / TWO_PI - n_ref
    eps = p[CONTACT_RATIO]
    friction = p[FRICTION]
    damaged = p[TOOTH_FACTORS] != 0.0
    k = 0.0
    arm_pinion = 0.0
    arm_gear = 0.0
    i = 0
    while u_ref + i < eps:
        kp = _interp_uniform(pair_k, u + i, eps)
        if damaged:
            tooth = int(n_ref) - i
            kp *= factor_pinion[tooth % int(p[Z1])] * factor_gear[tooth % int(p[Z2])]
        k += kp
        if friction != 0.0:
            # sliding reverses at the pitch point: beyond it (recess) the
            # pinion flank slides faster than the gear flank
            sign = 1.0 if u_ref + i > p[PITCH_POSITION] else -1.0
            s = p[PATH_START] + p[BASE_PITCH] * (u + i)
            arm_pinion += kp * sign * s
            arm_gear += kp * sign * (p[LOA_LENGTH] - s)
        i += 1
    if p[USE_PERIOD_TABLE] != 0.0:
        # smooth Fourier-series (or constant) curve; tooth factors act through
        # the pair sum above, so only its healthy part is replaced
        healthy = 0.0
        i = 0
        while u_ref + i < eps:
            healthy += _interp_uniform(pair_k, u + i, eps)
            i += 1
        phase = p[OMEGA_MESH] * t / TWO_PI
        phase -= math.floor(phase)
        k += _interp_uniform(period_k, phase, 1.0) - healthy
    scale = p[STIFFNESS_SCALE]
    if p[ECC_KAPPA] != 0.0:
        scale *= 1.0 + p[ECC_KAPPA] * math.cos(p[ECC_OMEGA] * t + p[ECC_PHASE])
    return k * scale, arm_pinion * scale, arm_gear * scale


@nb.njit(cache=True, inline="always", error_model="numpy", fastmath=True)
def static_transmission_error(t, p):
    """e(t): mesh-periodic STE plus any shaft run-out term, m."""
    ste = p[STE_AMPLITUDE] * math.sin(p[OMEGA_MESH] * t + p[STE_PHASE])
    if p[ECC_AMPLITUDE] != 0.0:
        ste += p[ECC_AMPLITUDE] * math.sin(p[ECC_OMEGA] * t + p[ECC_PHASE])
    return ste


@nb.njit(cache=True, inline="always", error_model="numpy", fastmath=True)
def forcing(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear, terms):
    """Time-only terms of the right-hand side, written into ``terms``.

    ``terms`` = (k, arm_pinion, arm_gear, relative drive acceleration
    R1 T1(t)/I1 + R2 T2(t)/I2, e(t), e''(t)). RK4's two midpoint stages
    share one evaluation.
    """
    k, arm_pinion, arm_gear = mesh_terms(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear)
    drive = p[T1]
    if p[RIPPLE_AMPLITUDE] != 0.0:
        drive *= 1.0 + p[RIPPLE_AMPLITUDE] * math.cos(p[RIPPLE_OMEGA] * t + p[RIPPLE_PHASE])
    adhesion = p[T2]
    if p[ADHESION_AMPLITUDE] != 0.0:
        adhesion += p[ADHESION_AMPLITUDE] * math.sin(p[ADHESION_OMEGA] * t + p[ADHESION_PHASE])
    sine = math.sin(p[OMEGA_MESH] * t + p[STE_PHASE])
    ste = p[STE_AMPLITUDE] * sine
    ste_acc = -p[STE_AMPLITUDE] * p[OMEGA_MESH] * p[OMEGA_MESH] * sine
    if p[ECC_AMPLITUDE] != 0.0:
        ecc = p[ECC_AMPLITUDE] * math.sin(p[ECC_OMEGA] * t + p[ECC_PHASE])
        ste += ecc
        ste_acc -= p[ECC_OMEGA] * p[ECC_OMEGA] * ecc
    terms[0] = k
    terms[1] = arm_pinion
    terms[2] = arm_gear
    terms[3] = p[R1] * drive / p[I1] + p[R2] * adhesion / p[I2]
    terms[4] = ste
    terms[5] = ste_acc


@nb.njit(cache=True, inline="always", error_model="numpy", fastmath=True)
def dynamics(state, terms, p, out):
    """State-dependent part of the right-hand side; returns the mesh force F."""
    x = state[2]
    vx = state[5]
    b = p[HALF_BACKLASH]
    fx = dead_zone(x, b)
    damping = p[CM]
    if p[DAMP_IN_SEPARATION] == 0.0 and fx == 0.0:
        damping = 0.0
    force = terms[0] * fx + damping * vx
    bearing1 = p[K1] * dead_zone(state[0], p[CLEARANCE1])
    bearing2 = p[K2] * dead_zone(state[1], p[CLEARANCE2])
    a1 = (-p[C1] * state[3] - bearing1 - force) / p[M1]
    a2 = (-p[C2] * state[4] - bearing2 + force) / p[M2]
    # R1 theta1'' - R2 theta2'' with the rigid-body rotation eliminated
    relative = terms[3] - force / p[ME]
    if p[FRICTION] != 0.0:
        # pinion: -mu f(x) sum k_i s_i sign_i ; gear: +mu f(x) sum k_i (L - s_i) sign_i
        friction_pinion = -p[FRICTION] * fx * terms[1]
        friction_gear = p[FRICTION] * fx * terms[2]
        relative += p[R1] * friction_pinion / p[I1] - p[R2] * friction_gear / p[I2]
    out[0] = state[3]
    out[1] = state[4]
    out[2] = vx
    out[3] = a1
    out[4] = a2
    out[5] = a1 - a2 + relative - terms[5]
    return force


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def rhs(t, state, t_ref, p, pair_k, period_k, factor_pinion, factor_gear, out):
    """Right-hand side of the 3-DOF model (model.md section 2) plus effect slots.

    ``state`` = (y1, y2, x, y1', y2', x'); writes the derivative into ``out``
    and returns (mesh force F, mesh stiffness k, static transmission error e).
    """
    terms = np.empty(6)
    forcing(t, t_ref, p, pair_k, period_k, factor_pinion, factor_gear, terms)
    force = dynamics(state, terms, p, out)
    return force, terms[0], terms[4]


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def _rk4(t, h, state, first, t_ref, p, pair_k, period_k, fp, fg, work, out):
    """One RK4 step from ``state`` (first stage ``first`` given) into ``out``.

    ``work`` holds rows k2, k3, k4, tmp, terms.
    """
    k2 = work[0]
    k3 = work[1]
    k4 = work[2]
    tmp = work[3]
    terms = work[4]
    forcing(t + 0.5 * h, t_ref, p, pair_k, period_k, fp, fg, terms)
    for j in range(6):
        tmp[j] = state[j] + 0.5 * h * first[j]
    dynamics(tmp, terms, p, k2)
    for j in range(6):
        tmp[j] = state[j] + 0.5 * h * k2[j]
    dynamics(tmp, terms, p, k3)
    forcing(t + h, t_ref, p, pair_k, period_k, fp, fg, terms)
    for j in range(6):
        tmp[j] = state[j] + h * k3[j]
    dynamics(tmp, terms, p, k4)
    for j in range(6):
        out[j] = state[j] + h / 6.0 * (first[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def _crossing_fraction(x0, v0, x1, v1, h, level):
    """Fraction of a step where the cubic Hermite interpolant of x reaches ``level``."""
    lo = 0.0
    hi = 1.0
    g_lo = x0 - level
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        s = mid
        h00 = 2 * s ** 3 - 3 * s ** 2 + 1
        h10 = s ** 3 - 2 * s ** 2 + s
        h01 = -2 * s ** 3 + 3 * s ** 2
        h11 = s ** 3 - s ** 2
        value = h00 * x0 + h10 * h * v0 + h01 * x1 + h11 * h * v1 - level
        if (value > 0.0) == (g_lo > 0.0):
            lo = mid
            g_lo = value
        else:
            hi = mid
    return 0.5 * (lo + hi)


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def _substep(t, h, state, t_ref, p, pair_k, period_k, fp, fg, work, first, trial):
    """Advance ``state`` in place over [t, t+h] (one smooth stiffness branch),
    splitting once at a contact boundary crossing.

    Returns the mesh force, first-stage accelerations of y1 and y2 at ``t``.
    """
    terms = work[4]
    forcing(t, t_ref, p, pair_k, period_k, fp, fg, terms)
    force = dynamics(state, terms, p, first)
    a1 = first[3]
    a2 = first[4]
    _rk4(t, h, state, first, t_ref, p, pair_k, period_k, fp, fg, work, trial)
    b = p[HALF_BACKLASH]
    before = contact_region(state[2], b)
    after = contact_region(trial[2], b)
    if before != after:
        if before == 1 or (before == 0 and after == -1):
            level = b if before == 1 else -b
        else:
            level = -b if before == -1 else b
        theta = _crossing_fraction(state[2], state[5], trial[2], trial[5], h, level)
        if 1e-9 < theta < 1.0 - 1e-9:
            h_a = theta * h
            _rk4(t, h_a, state, first, t_ref, p, pair_k, period_k, fp, fg, work, trial)
            for j in range(6):
                state[j] = trial[j]
            forcing(t + h_a, t_ref, p, pair_k, period_k, fp, fg, terms)
            dynamics(state, terms, p, first)
            _rk4(t + h_a, h - h_a, state, first, t_ref, p, pair_k, period_k, fp, fg, work, trial)
    for j in range(6):
        state[j] = trial[j]
    return force, a1, a2


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def step(t, h, state, p, pair_k, period_k, fp, fg, breakpoints, work, first, trial):
    """Advance one grid step [t, t+h], splitting at known stiffness breakpoints.

    ``breakpoints`` holds mesh phases in (0, 1) where the stiffness or the
    friction direction jumps (phase 0 is a grid point already). Returns the
    mesh force and the accelerations of y1, y2 at ``t`` (first RK4 stage).
    """
    cycles0 = p[OMEGA_MESH] * t / TWO_PI
    base = math.floor(cycles0 + 1e-9)
    u0 = cycles0 - base
    du = p[OMEGA_MESH] * h / TWO_PI
    t_now = t
    remaining_end = t + h
    started = False
    force = 0.0
    a1 = 0.0
    a2 = 0.0
    for bp in breakpoints:
        if u0 + 1e-12 < bp < u0 + du - 1e-12:
            t_break = (base + bp) * TWO_PI / p[OMEGA_MESH]
            f_, b1_, b2_ = _substep(t_now, t_break - t_now, state, 0.5 * (t_now + t_break), p, pair_k,
                                    period_k, fp, fg, work, first, trial)
            if not started:
                force, a1, a2 = f_, b1_, b2_
                started = True
            t_now = t_break
    f_, b1_, b2_ = _substep(t_now, remaining_end - t_now, state, 0.5 * (t_now + remaining_end), p, pair_k,
                            period_k, fp, fg, work, first, trial)
    if not started:
        force, a1, a2 = f_, b1_, b2_
    return force, a1, a2


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def record(t, state, p, pair_k, period_k, fp, fg, deriv):
    """Evaluate derivative and mesh quantities at a grid point (pairs taken just after ``t``)."""
    t_ref = t + 1e-9 * TWO_PI / p[OMEGA_MESH]
    return rhs(t, state, t_ref, p, pair_k, period_k, fp, fg, deriv)


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def integrate_history(state0, p, pair_k, period_k, fp, fg, breakpoints, steps_per_period,
                      n_periods, keep_periods, stride, history, poincare):
    """Integrate one run, storing histories of the kept periods.

    ``history`` has shape (keep_periods * steps_per_period // stride, 12):
    y1, y2, x, v1, v2, vx, a1, a2, F, k, e, contact. ``poincare`` has shape
    (keep_periods, 6): the state at each kept period start.
    """
    state = state0.copy()
    work = np.empty((WORK_ROWS, 6))
    first = np.empty(6)
    trial = np.empty(6)
    deriv = np.empty(6)
    period = TWO_PI / p[OMEGA_MESH]
    h = period / steps_per_period
    first_kept = n_periods - keep_periods
    row = 0
    for n in range(n_periods):
        for j in range(steps_per_period):
            t = (n * steps_per_period + j) * h
            if n >= first_kept:
                if j == 0:
                    for c in range(6):
                        poincare[n - first_kept, c] = state[c]
                if j % stride == 0:
                    force, k, ste = record(t, state, p, pair_k, period_k, fp, fg, deriv)
                    for c in range(6):
                        history[row, c] = state[c]
                    history[row, 6] = deriv[3]
                    history[row, 7] = deriv[4]
                    history[row, 8] = force
                    history[row, 9] = k
                    history[row, 10] = ste
                    history[row, 11] = contact_region(state[2], p[HALF_BACKLASH])
                    row += 1
            step(t, h, state, p, pair_k, period_k, fp, fg, breakpoints, work, first, trial)
    return state


@nb.njit(cache=True, error_model="numpy", fastmath=True)
def _integrate_qoi(state, p, pair_k, period_k, fp, fg, breakpoints, steps_per_period, n_periods,
                   keep_periods, history_stride, acc, poincare, history, lyapunov, scale):
    """Integrate one run keeping only accumulators, Poincare points and decimated histories.

    ``history`` has shape (channels, points): channel 0 is x; with 4 channels
    also te, y1'' and y2'' (the rig's channels).
    """
    work = np.empty((WORK_ROWS, 6))
    first = np.empty(6)
    trial = np.empty(6)
    shadow = np.empty(6)
    period = TWO_PI / p[OMEGA_MESH]
    h = period / steps_per_period
    first_kept = n_periods - keep_periods
    b = p[HALF_BACKLASH]
    acc[Q_X_MIN] = np.inf
    acc[Q_X_MAX] = -np.inf
    acc[Q_F_MAX] = -np.inf
    acc[Q_F_MIN] = np.inf
    separation = 1e-7
    if lyapunov:
        for c in range(6):
            shadow[c] = state[c]
        shadow[2] += separation * scale[2]
    log_growth = 0.0
    row = 0
    for n in range(n_periods):
        kept = n >= first_kept
        if kept:
            poincare[n - first_kept, 0] = state[2]
            poincare[n - first_kept, 1] = state[5]
        for j in range(steps_per_period):
            t = (n * steps_per_period + j) * h
            x = state[2]
            state_y1 = state[0]
            state_y2 = state[1]
            force, a1, a2 = step(t, h, state, p, pair_k, period_k, fp, fg, breakpoints, work, first, trial)
            if kept:
                acc[Q_X_SUM] += x
                acc[Q_X_SQ] += x * x
                if x < acc[Q_X_MIN]:
                    acc[Q_X_MIN] = x
                if x > acc[Q_X_MAX]:
                    acc[Q_X_MAX] = x
                if force > acc[Q_F_MAX]:
                    acc[Q_F_MAX] = force
                if force < acc[Q_F_MIN]:
                    acc[Q_F_MIN] = force
                acc[Q_A1_SQ] += a1 * a1
                acc[Q_A2_SQ] += a2 * a2
                region = contact_region(x, b)
                if region == 1:
                    acc[Q_N_DRIVE] += 1.0
                elif region == 0:
                    acc[Q_N_SEP] += 1.0
                else:
                    acc[Q_N_BACK] += 1.0
                acc[Q_COUNT] += 1.0
                if history_stride > 0 and j % history_stride == 0:
                    history[0, row] = x
                    if history.shape[0] >= 4:
                        # the rig's channels: te = x - y1 + y2 + e, and the bearing accelerations
                        history[1, row] = x - state_y1 + state_y2 + static_transmission_error(t, p)
                        history[2, row] = a1
                        history[3, row] = a2
                    row += 1
            if lyapunov:
                step(t, h, shadow, p, pair_k, period_k, fp, fg, breakpoints, work, first, trial)
        if lyapunov:
            # Benettin renormalisation once per mesh period in scaled coordinates
            distance = 0.0
            for c in range(6):
                distance += ((shadow[c] - state[c]) / scale[c]) ** 2
            distance = math.sqrt(distance)
            if distance > 0.0:
                if kept:
                    log_growth += math.log(distance / separation)
                for c in range(6):
                    shadow[c] = state[c] + (shadow[c] - state[c]) * separation / distance
            else:
                shadow[2] = state[2] + separation * scale[2]
    if lyapunov:
        acc[Q_LYAPUNOV] = log_growth / (keep_periods * period)
    else:
        acc[Q_LYAPUNOV] = np.nan


@nb.njit(cache=True, parallel=True, error_model="numpy", fastmath=True)
def integrate_batch(states, params, pair_tables, period_tables, table_index, factor_pinion,
                    factor_gear, breakpoints, steps_per_period, n_periods, keep_periods,
                    history_stride, lyapunov, scales, accumulators, poincare, history):
    """Integrate many runs in parallel over cores (``prange`` over samples)."""
    n_samples = params.shape[0]
    for i in nb.prange(n_samples):
        state = states[i].copy()
        table = table_index[i]
        _integrate_qoi(state, params[i], pair_tables[table], period_tables[table],
                       factor_pinion[i], factor_gear[i], breakpoints[i], steps_per_period[i],
                       n_periods, keep_periods, history_stride[i], accumulators[i], poincare[i],
                       history[i], lyapunov, scales[i])
