"""Numba kernels: shooting for the Cosserat rod and the PRB chain, and the Newton solver.

Both models are solved by shooting on the six unknowns at the clamp, the internal force
n(0) and moment m(0) (base frame), and driving the tip boundary residual to zero. They
differ only in how they carry the state from base to tip: the Cosserat rod integrates
eqs. 21 with classic RK4; the PRB chain steps across rigid links and spherical joints.

Everything here is nondimensional: lengths by L, moments by EI_ref / L and forces by
EI_ref / L^2 (EI_ref = E0 * I), so the unknowns and residuals are of order one and a
single tolerance means the same for every rod. `hydrojet_bench.models.shooting` does the
scaling.

State layout (18): p (3), R (9, row-major), n (3), m (3); n and m in the base frame, as
the internal force and moment exerted by the distal part on the proximal part.
"""

from __future__ import annotations

import numpy as np
from numba import njit

COSSERAT = 0
PRB = 1

# Columns of the profile array (one row per sample point, 2N + 1 points for N steps).
STIFFNESS = 0  # kx, ky, kz: bending x, bending y, torsion
INTRINSIC_CURVATURE = 3  # u0 in the body frame
DISTRIBUTED_FORCE = 6  # base frame, per unit length
DISTRIBUTED_MOMENT = 9  # body frame, per unit length
PROFILE_COLUMNS = 12

# Layout of the tip array.
TIP_FOLLOWER_FORCE = 0  # tip frame, besides the jets
TIP_FOLLOWER_MOMENT = 3  # tip frame
TIP_DEAD_FORCE = 6  # base frame
TIP_DEAD_MOMENT = 9  # base frame
TIP_DEAD_ARM = 12  # 3x3 row-major: sum of outer(offset_in_tip, dead_force)
TIP_ACTUATION = 21  # 3x3 row-major: jet forces -> tip-frame force
TIP_JETS = 30  # the commanded jet forces
TIP_SIZE = 33

# Layout of the base array.
BASE_COMPLIANCE = 0  # diagonal, base frame
BASE_PLAY = 3
BASE_PREVIOUS_ROTATION = 4  # rotation vector
BASE_SIZE = 7

# Status codes returned by `solve`.
CONVERGED = 0
MAX_ITERATIONS = 1
STALLED = 2
NOT_FINITE = 3

# Smoothing width of the clamp's play operator relative to the play radius: the
# nonsmooth operator makes Newton chatter at the switch; 5 % rounding is far below
# anything a tracker can see.
_PLAY_SMOOTHING = 0.05


@njit(cache=True, fastmath=False)
def _so3_exp(wx, wy, wz, out):
    theta2 = wx * wx + wy * wy + wz * wz
    theta = np.sqrt(theta2)
    if theta < 1e-6:
        a = 1.0 - theta2 / 6.0
        b = 0.5 - theta2 / 24.0
    else:
        a = np.sin(theta) / theta
        b = (1.0 - np.cos(theta)) / theta2
    out[0, 0] = 1.0 - b * (wy * wy + wz * wz)
    out[0, 1] = -a * wz + b * wx * wy
    out[0, 2] = a * wy + b * wx * wz
    out[1, 0] = a * wz + b * wx * wy
    out[1, 1] = 1.0 - b * (wx * wx + wz * wz)
    out[1, 2] = -a * wx + b * wy * wz
    out[2, 0] = -a * wy + b * wx * wz
    out[2, 1] = a * wx + b * wy * wz
    out[2, 2] = 1.0 - b * (wx * wx + wy * wy)


@njit(cache=True)
def _curvature(profile, row, load_scale, beta, mx, my, mz, u):
    """Invert the constitutive law at a sample point: body moment -> curvature u."""
    kx = profile[row, STIFFNESS]
    ky = profile[row, STIFFNESS + 1]
    kz = profile[row, STIFFNESS + 2]
    vx = mx / kx
    vy = my / ky
    if beta != 0.0:
        # Solve kx (vx + beta |v|^2 vx) = mx (and y alike) by Newton from the linear guess.
        for _ in range(20):
            s = vx * vx + vy * vy
            fx = kx * (vx + beta * s * vx) - mx
            fy = ky * (vy + beta * s * vy) - my
            j00 = kx * (1.0 + beta * (s + 2.0 * vx * vx))
            j11 = ky * (1.0 + beta * (s + 2.0 * vy * vy))
            j01 = kx * 2.0 * beta * vx * vy
            j10 = ky * 2.0 * beta * vx * vy
            det = j00 * j11 - j01 * j10
            dx = (j11 * fx - j01 * fy) / det
            dy = (j00 * fy - j10 * fx) / det
            vx -= dx
            vy -= dy
            if abs(dx) + abs(dy) < 1e-14 * (1.0 + abs(vx) + abs(vy)):
                break
    u[0] = load_scale * profile[row, INTRINSIC_CURVATURE] + vx
    u[1] = load_scale * profile[row, INTRINSIC_CURVATURE + 1] + vy
    u[2] = load_scale * profile[row, INTRINSIC_CURVATURE + 2] + mz / kz


@njit(cache=True)
def _cosserat_derivative(y, profile, row, load_scale, beta, dy, u):
    # Body-frame moment m_b = R^T m.
    mx = y[3] * y[15] + y[6] * y[16] + y[9] * y[17]
    my = y[4] * y[15] + y[7] * y[16] + y[10] * y[17]
    mz = y[5] * y[15] + y[8] * y[16] + y[11] * y[17]
    _curvature(profile, row, load_scale, beta, mx, my, mz, u)
    # p' = R e3 (inextensible, unshearable: the paper's v = e3).
    dy[0] = y[5]
    dy[1] = y[8]
    dy[2] = y[11]
    # R' = R hat(u).
    for i in range(3):
        r0 = y[3 + 3 * i]
        r1 = y[4 + 3 * i]
        r2 = y[5 + 3 * i]
        dy[3 + 3 * i] = r1 * u[2] - r2 * u[1]
        dy[4 + 3 * i] = r2 * u[0] - r0 * u[2]
        dy[5 + 3 * i] = r0 * u[1] - r1 * u[0]
    # n' = -f.
    dy[12] = -load_scale * profile[row, DISTRIBUTED_FORCE]
    dy[13] = -load_scale * profile[row, DISTRIBUTED_FORCE + 1]
    dy[14] = -load_scale * profile[row, DISTRIBUTED_FORCE + 2]
    # m' = -p' x n - R l.
    px, py, pz = dy[0], dy[1], dy[2]
    lx = load_scale * profile[row, DISTRIBUTED_MOMENT]
    ly = load_scale * profile[row, DISTRIBUTED_MOMENT + 1]
    lz = load_scale * profile[row, DISTRIBUTED_MOMENT + 2]
    dy[15] = -(py * y[14] - pz * y[13]) - (y[3] * lx + y[4] * ly + y[5] * lz)
    dy[16] = -(pz * y[12] - px * y[14]) - (y[6] * lx + y[7] * ly + y[8] * lz)
    dy[17] = -(px * y[13] - py * y[12]) - (y[9] * lx + y[10] * ly + y[11] * lz)


@njit(cache=True)
def _base_rotation(x, base, rotation):
    """Clamp rotation from the base moment: compliance, then (optionally) play."""
    cx = base[BASE_COMPLIANCE] * x[3]
    cy = base[BASE_COMPLIANCE + 1] * x[4]
    cz = base[BASE_COMPLIANCE + 2] * x[5]
    play = base[BASE_PLAY]
    if play > 0.0:
        px = base[BASE_PREVIOUS_ROTATION]
        py = base[BASE_PREVIOUS_ROTATION + 1]
        pz = base[BASE_PREVIOUS_ROTATION + 2]
        dx, dy, dz = cx - px, cy - py, cz - pz
        distance = np.sqrt(dx * dx + dy * dy + dz * dz)
        if distance > 0.0:
            # Smoothed ramp max(0, distance - play): the clamp only moves once the
            # demanded rotation leaves the play zone around where it last stopped.
            excess = distance - play
            width = _PLAY_SMOOTHING * play
            moved = 0.5 * (excess + np.sqrt(excess * excess + width * width))
            scale = moved / distance
        else:
            scale = 0.0
        cx, cy, cz = px + scale * dx, py + scale * dy, pz + scale * dz
    _so3_exp(cx, cy, cz, rotation)
    return cx, cy, cz


@njit(cache=True)
def _initial_state(x, base, y):
    rotation = np.empty((3, 3))
    _base_rotation(x, base, rotation)
    y[0] = 0.0
    y[1] = 0.0
    y[2] = 0.0
    for i in range(3):
        for j in range(3):
            y[3 + 3 * i + j] = rotation[i, j]
    for k in range(6):
        y[12 + k] = x[k]


@njit(cache=True)
def _integrate_cosserat(x, steps, profile, base, load_scale, beta, y, nodes_p, nodes_r, store):
    _initial_state(x, base, y)
    h = 1.0 / steps
    k1 = np.empty(18)
    k2 = np.empty(18)
    k3 = np.empty(18)
    k4 = np.empty(18)
    tmp = np.empty(18)
    u = np.empty(3)
    if store:
        _store_node(y, 0, nodes_p, nodes_r)
    for step in range(steps):
        row = 2 * step
        _cosserat_derivative(y, profile, row, load_scale, beta, k1, u)
        for k in range(18):
            tmp[k] = y[k] + 0.5 * h * k1[k]
        _cosserat_derivative(tmp, profile, row + 1, load_scale, beta, k2, u)
        for k in range(18):
            tmp[k] = y[k] + 0.5 * h * k2[k]
        _cosserat_derivative(tmp, profile, row + 1, load_scale, beta, k3, u)
        for k in range(18):
            tmp[k] = y[k] + h * k3[k]
        _cosserat_derivative(tmp, profile, row + 2, load_scale, beta, k4, u)
        for k in range(18):
            y[k] += h / 6.0 * (k1[k] + 2.0 * k2[k] + 2.0 * k3[k] + k4[k])
        if store:
            _store_node(y, step + 1, nodes_p, nodes_r)


@njit(cache=True)
def _store_node(y, index, nodes_p, nodes_r):
    for i in range(3):
        nodes_p[index, i] = y[i]
        for j in range(3):
            nodes_r[index, i, j] = y[3 + 3 * i + j]


@njit(cache=True)
def _rigid_link(y, length, profile, row_a, row_b, load_scale):
    """Carry the state along a rigid link of the given length. Its distributed load is
    lumped at the link's midpoint, with the profile averaged over rows ``row_a`` and
    ``row_b`` (the same row twice for a full link, whose centre is a sample point)."""
    scale = 0.5 * load_scale * length
    fx = scale * (profile[row_a, DISTRIBUTED_FORCE] + profile[row_b, DISTRIBUTED_FORCE])
    fy = scale * (profile[row_a, DISTRIBUTED_FORCE + 1] + profile[row_b, DISTRIBUTED_FORCE + 1])
    fz = scale * (profile[row_a, DISTRIBUTED_FORCE + 2] + profile[row_b, DISTRIBUTED_FORCE + 2])
    lx = scale * (profile[row_a, DISTRIBUTED_MOMENT] + profile[row_b, DISTRIBUTED_MOMENT])
    ly = scale * (profile[row_a, DISTRIBUTED_MOMENT + 1] + profile[row_b, DISTRIBUTED_MOMENT + 1])
    lz = scale * (profile[row_a, DISTRIBUTED_MOMENT + 2] + profile[row_b, DISTRIBUTED_MOMENT + 2])
    # Body-frame moment load into the base frame: R l.
    mlx = y[3] * lx + y[4] * ly + y[5] * lz
    mly = y[6] * lx + y[7] * ly + y[8] * lz
    mlz = y[9] * lx + y[10] * ly + y[11] * lz
    # Equilibrium of everything distal to the link's start, with d the link vector:
    # n_a = F + n_b and m_a = m_b + d x n_b + (d / 2) x F + M.
    dx, dy, dz = length * y[5], length * y[8], length * y[11]
    nbx = y[12] - fx
    nby = y[13] - fy
    nbz = y[14] - fz
    y[15] -= (dy * nbz - dz * nby) + 0.5 * (dy * fz - dz * fy) + mlx
    y[16] -= (dz * nbx - dx * nbz) + 0.5 * (dz * fx - dx * fz) + mly
    y[17] -= (dx * nby - dy * nbx) + 0.5 * (dx * fy - dy * fx) + mlz
    y[12] = nbx
    y[13] = nby
    y[14] = nbz
    y[0] += dx
    y[1] += dy
    y[2] += dz


@njit(cache=True)
def _propagate_prb(x, joints, profile, base, load_scale, beta, y, nodes_p, nodes_r, store):
    """PRB chain: `joints` spherical joints at s = (j - 1/2) / joints, j = 1..joints,
    joined by full links with half links at both ends (joints + 1 links in all). Each
    joint lumps one segment of length 1/joints: its stiffness is K(s_j) / segment, so
    theta_j = segment * u(m), the constitutive law of the rod evaluated at the joint.
    The profile has 2 * joints + 1 rows at s = k / (2 joints): joints sit on odd rows,
    full-link centres on even rows."""
    _initial_state(x, base, y)
    segment = 1.0 / joints
    u = np.empty(3)
    relative = np.empty((3, 3))
    rotation = np.empty((3, 3))
    if store:
        _store_node(y, 0, nodes_p, nodes_r)
    for joint in range(joints):
        if joint == 0:
            _rigid_link(y, 0.5 * segment, profile, 0, 1, load_scale)
        else:
            _rigid_link(y, segment, profile, 2 * joint, 2 * joint, load_scale)
        # Joint: relative rotation from the moment in the proximal link frame.
        row = 2 * joint + 1
        mx = y[3] * y[15] + y[6] * y[16] + y[9] * y[17]
        my = y[4] * y[15] + y[7] * y[16] + y[10] * y[17]
        mz = y[5] * y[15] + y[8] * y[16] + y[11] * y[17]
        _curvature(profile, row, load_scale, beta, mx, my, mz, u)
        _so3_exp(segment * u[0], segment * u[1], segment * u[2], relative)
        for i in range(3):
            for j in range(3):
                rotation[i, j] = (y[3 + 3 * i] * relative[0, j] + y[4 + 3 * i] * relative[1, j]
                                  + y[5 + 3 * i] * relative[2, j])
        for i in range(3):
            for j in range(3):
                y[3 + 3 * i + j] = rotation[i, j]
        if store:
            _store_node(y, joint + 1, nodes_p, nodes_r)
    _rigid_link(y, 0.5 * segment, profile, 2 * joints - 1, 2 * joints, load_scale)
    if store:
        _store_node(y, joints + 1, nodes_p, nodes_r)


@njit(cache=True)
def _tip_residual(y, tip, load_scale, residual):
    """n(L) and m(L) minus the applied tip wrench, base frame."""
    # Follower force in the tip frame: jets through the actuation matrix, plus the rest.
    ffx = tip[TIP_FOLLOWER_FORCE]
    ffy = tip[TIP_FOLLOWER_FORCE + 1]
    ffz = tip[TIP_FOLLOWER_FORCE + 2]
    for j in range(3):
        q = tip[TIP_JETS + j]
        ffx += tip[TIP_ACTUATION + j] * q
        ffy += tip[TIP_ACTUATION + 3 + j] * q
        ffz += tip[TIP_ACTUATION + 6 + j] * q
    fmx = tip[TIP_FOLLOWER_MOMENT]
    fmy = tip[TIP_FOLLOWER_MOMENT + 1]
    fmz = tip[TIP_FOLLOWER_MOMENT + 2]
    # R_tip times the follower wrench.
    force0 = y[3] * ffx + y[4] * ffy + y[5] * ffz + tip[TIP_DEAD_FORCE]
    force1 = y[6] * ffx + y[7] * ffy + y[8] * ffz + tip[TIP_DEAD_FORCE + 1]
    force2 = y[9] * ffx + y[10] * ffy + y[11] * ffz + tip[TIP_DEAD_FORCE + 2]
    moment0 = y[3] * fmx + y[4] * fmy + y[5] * fmz + tip[TIP_DEAD_MOMENT]
    moment1 = y[6] * fmx + y[7] * fmy + y[8] * fmz + tip[TIP_DEAD_MOMENT + 1]
    moment2 = y[9] * fmx + y[10] * fmy + y[11] * fmz + tip[TIP_DEAD_MOMENT + 2]
    # Dead forces off the tip point: sum_i (R r_i) x F_i = eps_abc (R T)_bc, T = sum r_i F_i^T.
    rt = np.empty((3, 3))
    for b in range(3):
        for c in range(3):
            rt[b, c] = (y[3 + 3 * b] * tip[TIP_DEAD_ARM + c] + y[4 + 3 * b] * tip[TIP_DEAD_ARM + 3 + c]
                        + y[5 + 3 * b] * tip[TIP_DEAD_ARM + 6 + c])
    moment0 += rt[1, 2] - rt[2, 1]
    moment1 += rt[2, 0] - rt[0, 2]
    moment2 += rt[0, 1] - rt[1, 0]
    residual[0] = y[12] - load_scale * force0
    residual[1] = y[13] - load_scale * force1
    residual[2] = y[14] - load_scale * force2
    residual[3] = y[15] - load_scale * moment0
    residual[4] = y[16] - load_scale * moment1
    residual[5] = y[17] - load_scale * moment2


@njit(cache=True)
def shoot(kind, resolution, x, profile, tip, base, beta, load_scale, residual, y, nodes_p, nodes_r, store):
    """Propagate from base unknowns ``x`` to the tip; write the tip residual. Returns
    nothing; ``y`` holds the tip state afterwards."""
    if kind == COSSERAT:
        _integrate_cosserat(x, resolution, profile, base, load_scale, beta, y, nodes_p, nodes_r, store)
    else:
        _propagate_prb(x, resolution, profile, base, load_scale, beta, y, nodes_p, nodes_r, store)
    _tip_residual(y, tip, load_scale, residual)


@njit(cache=True)
def _norm6(v):
    total = 0.0
    for k in range(6):
        total += v[k] * v[k]
    return np.sqrt(total)


@njit(cache=True)
def _solve6(matrix, rhs, out):
    """Gaussian elimination with partial pivoting on a 6x6 copy; returns False if singular."""
    a = matrix.copy()
    b = rhs.copy()
    for col in range(6):
        pivot = col
        biggest = abs(a[col, col])
        for row in range(col + 1, 6):
            if abs(a[row, col]) > biggest:
                biggest = abs(a[row, col])
                pivot = row
        if biggest < 1e-300:
            return False
        if pivot != col:
            for k in range(6):
                a[col, k], a[pivot, k] = a[pivot, k], a[col, k]
            b[col], b[pivot] = b[pivot], b[col]
        for row in range(col + 1, 6):
            factor = a[row, col] / a[col, col]
            for k in range(col, 6):
                a[row, k] -= factor * a[col, k]
            b[row] -= factor * b[col]
    for row in range(5, -1, -1):
        acc = b[row]
        for k in range(row + 1, 6):
            acc -= a[row, k] * out[k]
        out[row] = acc / a[row, row]
    return True


@njit(cache=True)
def _finite_difference_jacobian(kind, resolution, x, r, profile, tip, base, beta, load_scale,
                                jacobian, y, nodes_p, nodes_r):
    trial = x.copy()
    r_trial = np.empty(6)
    for j in range(6):
        # sqrt(machine epsilon) relative step: the residual is smooth and cheap.
        h = 1.5e-8 * max(1.0, abs(x[j]))
        trial[j] = x[j] + h
        shoot(kind, resolution, trial, profile, tip, base, beta, load_scale, r_trial, y, nodes_p, nodes_r, False)
        for i in range(6):
            jacobian[i, j] = (r_trial[i] - r[i]) / h
        trial[j] = x[j]


@njit(cache=True)
def solve(kind, resolution, x, jacobian, have_jacobian, profile, tip, base, beta, load_scale,
          tolerance, max_iterations, nodes_p, nodes_r, info):
    """Damped quasi-Newton on the shooting residual, in place on ``x`` and ``jacobian``.

    Starts from ``jacobian`` when ``have_jacobian`` (a warm start: the previous solve's
    matrix is nearly right for a nearby load), else builds it by forward differences.
    Steps are Newton steps with backtracking; after an accepted step the matrix gets a
    Broyden rank-one update, and it is rebuilt by finite differences whenever a step
    fails to reduce the residual. On return ``info`` holds [status, iterations,
    residual norm, jacobian evaluations] and, if converged, the nodes are stored.
    """
    y = np.empty(18)
    r = np.empty(6)
    r_new = np.empty(6)
    step = np.empty(6)
    x_new = np.empty(6)
    shoot(kind, resolution, x, profile, tip, base, beta, load_scale, r, y, nodes_p, nodes_r, False)
    norm = _norm6(r)
    jacobian_evaluations = 0
    fresh = False
    if not have_jacobian:
        _finite_difference_jacobian(kind, resolution, x, r, profile, tip, base, beta, load_scale,
                                    jacobian, y, nodes_p, nodes_r)
        jacobian_evaluations += 1
        fresh = True
    iterations = 0
    status = MAX_ITERATIONS
    while True:
        if not np.isfinite(norm):
            status = NOT_FINITE
            break
        if norm < tolerance:
            status = CONVERGED
            break
        if iterations >= max_iterations:
            status = MAX_ITERATIONS
            break
        iterations += 1
        if not _solve6(jacobian, r, step):
            if fresh:
                status = STALLED
                break
            _finite_difference_jacobian(kind, resolution, x, r, profile, tip, base, beta, load_scale,
                                        jacobian, y, nodes_p, nodes_r)
            jacobian_evaluations += 1
            fresh = True
            continue
        alpha = 1.0
        accepted = False
        new_norm = norm
        for _ in range(10):
            for k in range(6):
                x_new[k] = x[k] - alpha * step[k]
            shoot(kind, resolution, x_new, profile, tip, base, beta, load_scale, r_new, y,
                  nodes_p, nodes_r, False)
            new_norm = _norm6(r_new)
            if np.isfinite(new_norm) and new_norm < (1.0 - 1e-4 * alpha) * norm:
                accepted = True
                break
            alpha *= 0.5
        if not accepted:
            if fresh:
                status = STALLED
                break
            _finite_difference_jacobian(kind, resolution, x, r, profile, tip, base, beta, load_scale,
                                        jacobian, y, nodes_p, nodes_r)
            jacobian_evaluations += 1
            fresh = True
            continue
        # Broyden's "good" update: J += (dr - J dx) dx^T / (dx . dx).
        dx_dot = 0.0
        for k in range(6):
            step[k] = x_new[k] - x[k]
            dx_dot += step[k] * step[k]
        if dx_dot > 0.0:
            for i in range(6):
                predicted = 0.0
                for k in range(6):
                    predicted += jacobian[i, k] * step[k]
                correction = (r_new[i] - r[i] - predicted) / dx_dot
                for k in range(6):
                    jacobian[i, k] += correction * step[k]
        fresh = False
        for k in range(6):
            x[k] = x_new[k]
            r[k] = r_new[k]
        norm = new_norm
    if status == CONVERGED:
        shoot(kind, resolution, x, profile, tip, base, beta, load_scale, r, y, nodes_p, nodes_r, True)
    info[0] = status
    info[1] = iterations
    info[2] = norm
    info[3] = jacobian_evaluations


@njit(cache=True)
def clamp_rotation_vector(x, base):
    """Rotation vector (rad) of the clamp for the clamp wrench ``x``."""
    rotation = np.empty((3, 3))
    return _base_rotation(x, base, rotation)
