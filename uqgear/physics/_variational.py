"""The Poincare map of the gear model over whole mesh periods, with its Jacobian (the monodromy matrix).

One compiled pass integrates the state with the fast path's RK4 scheme (the same sub-steps, split at
the stiffness breakpoints of :func:`~uqgear.physics._kernels.build_schedule` and at the contact
boundaries |x| = b, each part of a split step on its own side's mesh damping as in
:func:`~uqgear.physics._stepper._split_at_contact`) and, alongside, the variational equation
Phi' = J(t, s) Phi from Phi(0) = I.
Each RK4 stage of Phi uses the Jacobian at that stage's state, so Phi is the derivative of the
discrete RK4 map within every smooth piece. Across a switching surface the variational solution
jumps by the saltation matrix

    S = I + (f+ - f-) grad(h)^T / (grad(h) . f-)

where f- and f+ are the vector fields just before and after the switch and h = 0 the surface:

* contact boundaries h = x -+ b: with the classical mesh force k(t) f(x) + c_m x' the vector field
  is continuous across |x| = b (f is), so f+ = f- and S = I; only the Jacobian changes, which the
  stage Jacobians take up. With ``damping_in_separation=False`` the damping force c_m x' switches
  off at |x| = b, f+ - f- = (0, 0, 0, -dF/m1, dF/m2, -dF (1/m1 + 1/m2 + 1/m_e)) with dF = dc x',
  and grad(h) . f- = x', so S adds -dc/m1, dc/m2 and -dc (1/m1 + 1/m2 + 1/m_e) times row x of Phi
  to the acceleration rows (x' cancels: no division by a small velocity at a grazing crossing);
* stiffness jumps of the raw Ishikawa curve (a pair enters or leaves) and the friction reversal at
  the pitch point happen at fixed mesh phases: h = t - t_s with grad_s(h) = 0, so S = I whatever
  the jump in the vector field (a perturbed orbit switches at the same time).

``tests/test_shooting.py`` checks every case against finite-difference monodromy of the fast
integrator. The model must repeat every mesh period (no run-out, tooth damage, torque ripple or
adhesion oscillation, no pitch errors): the caller checks that.

The compile options and the right-hand side's building blocks are those of
:mod:`uqgear.physics._kernels`: one kernel family, one set of compile options.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from ._kernels import (
    C1,
    C2,
    CLEARANCE1,
    CLEARANCE2,
    DAMP_IN_SEPARATION,
    HALF_BACKLASH,
    INLINED,
    JIT_OPTIONS,
    K1,
    K2,
    M1,
    M2,
    ME,
    OMEGA_MESH,
    TWO_PI,
    _shifted,
    build_schedule,
    coefficients,
    contact_region,
    crossed_boundary,
    crossing_fraction,
    dead_zone,
    derivative,
    divided,
    forcing,
    mesh_damping,
    rk4_combine_weighted,
    rk4_stages,
    side_derivative,
    splits_step,
)

#: Bisection steps of a contact crossing in the variational pass (the fast path: ``BISECTIONS``, 40).
CROSSING_BISECTIONS = 50

# layout of the orbit measures a pass returns
(
    O_X_MIN,
    O_X_MAX,
    O_F_MAX,
    O_F_MIN,
    O_N_DRIVE,
    O_N_SEP,
    O_N_BACK,
    O_COUNT,
    O_X_MIN_CURVE,
    O_CROSSINGS,
    O_X_RMS_SUM,
    O_X_SUM,
) = range(12)
#: Number of orbit measures.
N_MEASURES = 12
#: Names of the orbit measures, in order.
MEASURE_NAMES = (
    "x_min",
    "x_max",
    "force_max",
    "force_min",
    "n_drive",
    "n_separation",
    "n_back",
    "n_grid",
    "x_min_curve",
    "crossings",
    "x_square_sum",
    "x_sum",
)


@nb.njit(**INLINED)
def _slope(value, half_width):
    """d f / d value of the dead zone: 1 outside the clearance, 0 inside (1 everywhere without one)."""
    if half_width == 0.0:
        return 1.0
    return 1.0 if abs(value) > half_width else 0.0


@nb.njit(**INLINED)
def _mesh_damping(x, p):
    """The mesh damping coefficient acting at DTE ``x`` (:func:`~uqgear.physics._rhs.mesh_damping`)."""
    return mesh_damping(coefficients(p), dead_zone(x, p[HALF_BACKLASH]) == 0.0)


@nb.njit(**INLINED)
def _stage(s, terms, p, side):
    """ds/dt and F at a stage: :func:`derivative`, with the mesh damping of contact region ``side``
    unless ``side`` is 2 (the state's own; see :func:`~uqgear.physics._rhs.side_derivative`)."""
    if side == 2:
        return derivative(s, terms, p)
    return side_derivative(s, terms[0], terms[1], terms[2], terms[4], coefficients(p), side)


@nb.njit(**JIT_OPTIONS)
def _jacobian_times(s, terms, p, phi, out, region, side):
    """out = J(t, s) phi for the 6 x 6 ``phi``; J = [[0, I], [A, C]] of :func:`derivative`.

    The contact region of the mesh terms is the state's own when ``region`` is 2, else ``region``
    (1, 0, -1: the smooth piece a split step is on, whatever side of the boundary round-off puts
    a stage state). ``side`` (2: as ``region`` says) sets the mesh damping alone, as the stage's
    :func:`_stage` does.
    """
    k = terms[0]
    x = s[2]
    if region != 2:
        x = p[HALF_BACKLASH] * (2.0 * region) if region != 0 else 0.0
    slope_x = _slope(x, p[HALF_BACKLASH])
    damping = _mesh_damping(x, p)
    if side != 2:
        damping = mesh_damping(coefficients(p), side == 0)
    stiff = k * slope_x
    m1 = p[M1]
    m2 = p[M2]
    me = p[ME]
    # rows of A (d acceleration / d position) and C (d acceleration / d velocity)
    a1_y1 = -p[K1] * _slope(s[0], p[CLEARANCE1]) / m1
    a1_x = -stiff / m1
    a1_v1 = -p[C1] / m1
    a1_vx = -damping / m1
    a2_y2 = -p[K2] * _slope(s[1], p[CLEARANCE2]) / m2
    a2_x = stiff / m2
    a2_v2 = -p[C2] / m2
    a2_vx = damping / m2
    ax_x = a1_x - a2_x - stiff / me - slope_x * terms[1]
    ax_vx = a1_vx - a2_vx - damping / me
    for col in range(6):
        out[0, col] = phi[3, col]
        out[1, col] = phi[4, col]
        out[2, col] = phi[5, col]
        d1 = a1_y1 * phi[0, col] + a1_x * phi[2, col] + a1_v1 * phi[3, col] + a1_vx * phi[5, col]
        d2 = a2_y2 * phi[1, col] + a2_x * phi[2, col] + a2_v2 * phi[4, col] + a2_vx * phi[5, col]
        out[3, col] = d1
        out[4, col] = d2
        out[5, col] = (
            a1_y1 * phi[0, col]
            - a2_y2 * phi[1, col]
            + ax_x * phi[2, col]
            + a1_v1 * phi[3, col]
            - a2_v2 * phi[4, col]
            + ax_vx * phi[5, col]
        )


@nb.njit(**INLINED)
def _stage_field(s, terms, context, divide):
    """:func:`_stage` as a field of :func:`~uqgear.physics._stepper.rk4_stages`: ``context`` (parameters, side)."""
    p, side = context
    d, _ = _stage(s, terms, p, side)
    return d, True


@nb.njit(**JIT_OPTIONS)
def _rk4_variational(s, h, start, mid, end, p, phi, with_matrix, work, region, side):
    """One RK4 step of the state tuple ``s`` and, with ``with_matrix``, of ``phi`` in place.

    ``work`` holds five 6 x 6 scratch matrices (four stage slopes and a stage matrix); ``region``
    and ``side`` as in :func:`_jacobian_times` (``side`` also sets the stages' damping).
    """
    d1, _ = _stage(s, start, p, side)
    d2, d3, d4, _ = rk4_stages(_stage_field, divided, s, h, d1, mid, end, (p, side))
    w = h / 6.0
    new = rk4_combine_weighted(s, w, d1, d2, d3, d4)
    if with_matrix:
        # the stage states again, for the Jacobians at them (the same operations: the same numbers)
        s2 = _shifted(s, 0.5 * h, d1)
        s3 = _shifted(s, 0.5 * h, d2)
        s4 = _shifted(s, h, d3)
        k1 = work[0]
        k2 = work[1]
        k3 = work[2]
        k4 = work[3]
        stage = work[4]
        _jacobian_times(s, start, p, phi, k1, region, side)
        for r in range(6):
            for c in range(6):
                stage[r, c] = phi[r, c] + 0.5 * h * k1[r, c]
        _jacobian_times(s2, mid, p, stage, k2, region, side)
        for r in range(6):
            for c in range(6):
                stage[r, c] = phi[r, c] + 0.5 * h * k2[r, c]
        _jacobian_times(s3, mid, p, stage, k3, region, side)
        for r in range(6):
            for c in range(6):
                stage[r, c] = phi[r, c] + h * k3[r, c]
        _jacobian_times(s4, end, p, stage, k4, region, side)
        for r in range(6):
            for c in range(6):
                phi[r, c] += w * (k1[r, c] + 2.0 * k2[r, c] + 2.0 * k3[r, c] + k4[r, c])
    return new


@nb.njit(**JIT_OPTIONS)
def _curve_minimum(x0, v0, x1, v1, h):
    """Smallest value of the cubic Hermite interpolant of x over a step (its ends included)."""
    best = min(x0, x1)
    if not (v0 < 0.0 < v1):
        return best
    # p'(theta) = a theta^2 + b theta + c
    a = 6.0 * x0 + 3.0 * h * v0 - 6.0 * x1 + 3.0 * h * v1
    b = -6.0 * x0 - 4.0 * h * v0 + 6.0 * x1 - 2.0 * h * v1
    c = h * v0
    roots = np.empty(2)
    count = 0
    if abs(a) < 1e-300:
        if b != 0.0:
            roots[0] = -c / b
            count = 1
    else:
        disc = b * b - 4.0 * a * c
        if disc >= 0.0:
            root = math.sqrt(disc)
            roots[0] = (-b - root) / (2.0 * a)
            roots[1] = (-b + root) / (2.0 * a)
            count = 2
    for i in range(count):
        theta = roots[i]
        if 0.0 < theta < 1.0:
            t2 = theta * theta
            t3 = t2 * theta
            value = (
                (2 * t3 - 3 * t2 + 1) * x0
                + (t3 - 2 * t2 + theta) * h * v0
                + (-2 * t3 + 3 * t2) * x1
                + (t3 - t2) * h * v1
            )
            if value < best:
                best = value
    return best


@nb.njit(**INLINED)
def _jump_in_damping(before, after, p):
    """Change of the mesh damping coefficient from region ``before`` to ``after`` (0 with it always on)."""
    c = coefficients(p)
    return mesh_damping(c, after == 0) - mesh_damping(c, before == 0)


@nb.njit(**JIT_OPTIONS)
def _saltation(phi, jump, p):
    """phi <- S phi at a contact boundary where the damping coefficient jumps by ``jump``."""
    f1 = -jump / p[M1]
    f2 = jump / p[M2]
    fx = -jump * (1.0 / p[M1] + 1.0 / p[M2] + 1.0 / p[ME])
    for col in range(6):
        row_x = phi[2, col]
        phi[3, col] += f1 * row_x
        phi[4, col] += f2 * row_x
        phi[5, col] += fx * row_x


@nb.njit(**JIT_OPTIONS)
def _two_parts(
    s, t, h, theta, t_ref, start, end, p, pair_k, period_k, fp, fg, with_matrix, phi, work, regions, sides, jump
):
    """The step from ``s`` over [t, t + h] in two RK4 steps split at fraction ``theta``.

    Each part's stages take the mesh damping of its side of the boundary (``sides``, a pair), as
    the fast path's split step does. With ``with_matrix`` ``phi`` is carried along with the
    Jacobians of ``regions`` (a pair, see :func:`_jacobian_times`), times the saltation matrix of
    a damping jump ``jump`` (N s/m) between the parts. Returns (state at the split, state at the
    end).
    """
    h_a = theta * h
    h_b = h - h_a
    middle = forcing(t + h_a, t_ref, p, pair_k, period_k, fp, fg)
    part = _rk4_variational(
        s,
        h_a,
        start,
        forcing(t + 0.5 * h_a, t_ref, p, pair_k, period_k, fp, fg),
        middle,
        p,
        phi,
        with_matrix,
        work,
        regions[0],
        sides[0],
    )
    if with_matrix and jump != 0.0:
        _saltation(phi, jump, p)
    new = _rk4_variational(
        part,
        h_b,
        middle,
        forcing(t + h_a + 0.5 * h_b, t_ref, p, pair_k, period_k, fp, fg),
        end,
        p,
        phi,
        with_matrix,
        work,
        regions[1],
        sides[1],
    )
    return part, new


@nb.njit(**JIT_OPTIONS)
def _hermite_weights(theta):
    """The cubic Hermite basis h00, h10, h01, h11 at ``theta`` and their derivatives."""
    t2 = theta * theta
    t3 = t2 * theta
    values = (2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + theta, -2 * t3 + 3 * t2, t3 - t2)
    slopes = (6 * t2 - 6 * theta, 3 * t2 - 4 * theta + 1, -6 * t2 + 6 * theta, 3 * t2 - 2 * theta)
    return values, slopes


@nb.njit(**JIT_OPTIONS)
def _crossing_sensitivity(
    s,
    t,
    h,
    theta,
    t_ref,
    start,
    end,
    p,
    pair_k,
    period_k,
    fp,
    fg,
    x0,
    v0,
    x1,
    v1,
    phi,
    work,
    phi_start,
    trial_x,
    trial_v,
    sides,
):
    """Add to ``phi`` the term of the discrete map's derivative that comes from moving the split point.

    The split fraction theta solves H(theta) = level on the Hermite interpolant of the unsplit
    step, whose ends depend on the start state: d theta = -(dH/dx0 dx0 + ... + dH/dv1 dv1) / H'.
    The end state's sensitivity to theta is a central difference of :func:`_two_parts`.
    """
    values, slopes = _hermite_weights(theta)
    slope = slopes[0] * x0 + slopes[1] * h * v0 + slopes[2] * x1 + slopes[3] * h * v1
    if slope == 0.0:
        return
    delta = min(1e-7, 0.5 * theta, 0.5 * (1.0 - theta))
    _, plus = _two_parts(
        s, t, h, theta + delta, t_ref, start, end, p, pair_k, period_k, fp, fg, False, phi, work, (2, 2), sides, 0.0
    )
    _, minus = _two_parts(
        s, t, h, theta - delta, t_ref, start, end, p, pair_k, period_k, fp, fg, False, phi, work, (2, 2), sides, 0.0
    )
    for col in range(6):
        d_theta = (
            -(
                values[0] * phi_start[2, col]
                + values[1] * h * phi_start[5, col]
                + values[2] * trial_x[col]
                + values[3] * h * trial_v[col]
            )
            / slope
        )
        for row in range(6):
            phi[row, col] += (plus[row] - minus[row]) / (2.0 * delta) * d_theta


@nb.njit(**JIT_OPTIONS)
def _substep(s, t, h, t_ref, p, pair_k, period_k, fp, fg, with_matrix, discrete, phi, work, measures):
    """One sub-step on one smooth stiffness branch, split where it crosses a contact boundary."""
    start = forcing(t, t_ref, p, pair_k, period_k, fp, fg)
    mid = forcing(t + 0.5 * h, t_ref, p, pair_k, period_k, fp, fg)
    end = forcing(t + h, t_ref, p, pair_k, period_k, fp, fg)
    backup = work[5]
    if with_matrix:
        for r in range(6):
            for c in range(6):
                backup[r, c] = phi[r, c]
    trial = _rk4_variational(s, h, start, mid, end, p, phi, with_matrix, work, 2, 2)
    b = p[HALF_BACKLASH]
    before = contact_region(s[2], b)
    after = contact_region(trial[2], b)
    if before == after:
        measures[O_X_MIN_CURVE] = min(measures[O_X_MIN_CURVE], _curve_minimum(s[2], s[5], trial[2], trial[5], h))
        return trial
    level, entered = crossed_boundary(before, after, b)
    if p[DAMP_IN_SEPARATION] == 0.0:
        # as the fast path: the crossing is located on the step with the first side's damping throughout
        if with_matrix:
            for r in range(6):
                for c in range(6):
                    phi[r, c] = backup[r, c]
        trial = _rk4_variational(s, h, start, mid, end, p, phi, with_matrix, work, 2, before)
    # located more finely than the fast path's split: the discrete map's derivative is taken at this
    # fraction (_crossing_sensitivity) and moves with it
    theta = crossing_fraction(s[2], s[5], trial[2], trial[5], h, level, CROSSING_BISECTIONS)
    measures[O_CROSSINGS] += 1.0
    if not splits_step(theta):
        measures[O_X_MIN_CURVE] = min(measures[O_X_MIN_CURVE], _curve_minimum(s[2], s[5], trial[2], trial[5], h))
        return trial
    # redo the step in two parts, the first ending on the boundary
    trial_rows = work[6]
    if with_matrix:
        for c in range(6):
            trial_rows[0, c] = phi[2, c]
            trial_rows[1, c] = phi[5, c]
            for r in range(6):
                phi[r, c] = backup[r, c]
    # discrete: the derivative of the discrete map (stage regions as the state's); else the flow's
    # variational equation on each smooth piece and the saltation matrix between them
    regions = (2, 2) if discrete else (before, entered)
    jump = 0.0 if discrete else _jump_in_damping(before, entered, p)
    sides = (before, entered)
    part, new = _two_parts(
        s, t, h, theta, t_ref, start, end, p, pair_k, period_k, fp, fg, with_matrix, phi, work, regions, sides, jump
    )
    if with_matrix and discrete:
        _crossing_sensitivity(
            s,
            t,
            h,
            theta,
            t_ref,
            start,
            end,
            p,
            pair_k,
            period_k,
            fp,
            fg,
            s[2],
            s[5],
            trial[2],
            trial[5],
            phi,
            work,
            backup,
            trial_rows[0],
            trial_rows[1],
            sides,
        )
    measures[O_X_MIN_CURVE] = min(
        measures[O_X_MIN_CURVE],
        _curve_minimum(s[2], s[5], part[2], part[5], theta * h),
        _curve_minimum(part[2], part[5], new[2], new[5], h - theta * h),
    )
    return new


@nb.njit(**JIT_OPTIONS, nogil=True)
def orbit_pass(
    state0, n_periods, p, pair_k, period_k, fp, fg, breakpoints, steps_per_period, with_matrix, discrete, phi, measures
):
    """Integrate ``n_periods`` mesh periods from ``state0`` at t = 0; return the end state.

    With ``with_matrix`` also the monodromy matrix d(end state)/d(state0) into ``phi`` (6 x 6).
    ``measures`` (:data:`N_MEASURES`) receives the orbit's extremes and contact counts: DTE and mesh
    force at the grid points as in the batch kernel's QoIs, the contact region at each grid point,
    the smallest DTE on the cubic Hermite interpolant of every step (``x_min_curve``, for grazing)
    and the number of contact-boundary crossings.
    """
    schedule = build_schedule(p, pair_k, period_k, breakpoints, steps_per_period)
    first_sub = schedule[0]
    offsets = schedule[1]
    widths = schedule[2]
    refs = schedule[3]
    period = TWO_PI / p[OMEGA_MESH]
    work = np.zeros((7, 6, 6))
    for r in range(6):
        for c in range(6):
            phi[r, c] = 1.0 if r == c else 0.0
    measures[:] = 0.0
    measures[O_X_MIN] = np.inf
    measures[O_X_MAX] = -np.inf
    measures[O_F_MAX] = -np.inf
    measures[O_F_MIN] = np.inf
    measures[O_X_MIN_CURVE] = np.inf
    b = p[HALF_BACKLASH]
    s = (state0[0], state0[1], state0[2], state0[3], state0[4], state0[5])
    for n in range(n_periods):
        base = n * period
        for j in range(steps_per_period):
            for sub in range(first_sub[j], first_sub[j + 1]):
                t = base + offsets[sub]
                if sub == first_sub[j]:
                    _, force = derivative(s, forcing(t, base + refs[sub], p, pair_k, period_k, fp, fg), p)
                    x = s[2]
                    measures[O_X_MIN] = min(measures[O_X_MIN], x)
                    measures[O_X_MAX] = max(measures[O_X_MAX], x)
                    measures[O_F_MAX] = max(measures[O_F_MAX], force)
                    measures[O_F_MIN] = min(measures[O_F_MIN], force)
                    measures[O_X_SUM] += x
                    measures[O_X_RMS_SUM] += x * x
                    region = contact_region(x, b)
                    if region == 1:
                        measures[O_N_DRIVE] += 1.0
                    elif region == 0:
                        measures[O_N_SEP] += 1.0
                    else:
                        measures[O_N_BACK] += 1.0
                    measures[O_COUNT] += 1.0
                s = _substep(
                    s,
                    t,
                    widths[sub],
                    base + refs[sub],
                    p,
                    pair_k,
                    period_k,
                    fp,
                    fg,
                    with_matrix,
                    discrete,
                    phi,
                    work,
                    measures,
                )
    out = np.empty(6)
    for c in range(6):
        out[c] = s[c]
    return out
