"""Numba kernels: shooting for the Cosserat rod and the PRB chain, and the Newton solver.

Both models are solved by shooting *from the tip*: the unknown is the tip orientation
R_L (three numbers, a rotation vector about a reference), the tip wrench follows from it
(the jets and w_d follow the tip, the capsule's weight does not), and the state is
carried back to the clamp, where the residual is the clamp's orientation error. Two
facts make this cheaper and better conditioned than the textbook shooting on the six
clamp loads: every load the bench models is invariant under translation, so the tip
position drops out (the shape is shifted to put the clamp at the origin afterwards); and
a pure follower load makes the map from R_L to the clamp orientation an exact rotation,
so Newton converges in a step or two and only gravity and clamp compliance add
nonlinearity. The two models differ only in how they carry the state: the Cosserat rod
integrates eqs. 21 with classic RK4; the PRB chain steps across rigid links and
spherical joints.

Everything here is nondimensional: lengths by L, moments by EI_ref / L and forces by
EI_ref / L^2 (EI_ref = E0 * I), so the unknowns and residuals are of order one and a
single tolerance means the same for every rod. `hydrojet_bench.models.shooting` does the
scaling.

State layout (18): p (3), R (9, row-major), n (3), m (3); n and m in the base frame, as
the internal force and moment exerted by the distal part on the proximal part. The
unknown x is the rotation vector of R_ref^T R_L (right perturbation of a reference).
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
COMPLIANCE = 12  # 1 / stiffness: multiplications, not divisions, in the hot loop
PROFILE_COLUMNS = 15

# Fast-math flags for the innermost arithmetic only: fused multiply-add and reciprocal
# multiplication change results in the last bit; no flag that assumes away NaN or inf,
# so a diverging shot is still caught by the solver's finiteness check.
_HOT = {"contract", "arcp"}

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

UNKNOWNS = 3

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


@njit(cache=True, fastmath=_HOT)
def _curvature(profile, row, load_scale, beta, mx, my, mz):
    """Invert the constitutive law at a sample point: body moment -> curvature u."""
    vx = mx * profile[row, COMPLIANCE]
    vy = my * profile[row, COMPLIANCE + 1]
    if beta != 0.0:
        kx = profile[row, STIFFNESS]
        ky = profile[row, STIFFNESS + 1]
        # Solve kx (vx + beta |v|^2 vx) = mx (and y alike) by Newton from the linear guess.
        # Softening (beta < 0) caps the moment a section can carry; past the cap there is
        # no curvature at all, and NaN makes the solver say so instead of guessing.
        converged = False
        for _ in range(30):
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
                converged = True
                break
        if not converged or (1.0 + 3.0 * beta * (vx * vx + vy * vy)) <= 0.0:
            vx = vy = np.nan
    return (load_scale * profile[row, INTRINSIC_CURVATURE] + vx,
            load_scale * profile[row, INTRINSIC_CURVATURE + 1] + vy,
            load_scale * profile[row, INTRINSIC_CURVATURE + 2] + mz * profile[row, COMPLIANCE + 2])


@njit(cache=True, fastmath=_HOT)
def _cosserat_derivative(y, profile, row, load_scale, beta):
    """Right-hand side of eqs. 21 in the base frame, on the state as an 18-tuple. Tuples
    stay in registers; with arrays numba cannot prove the state and its derivative
    distinct and reloads after every store, which made the integrator 3-4x slower."""
    (px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, nx, ny, nz, gx, gy, gz) = y
    # Body-frame moment m_b = R^T m, then the curvature from the constitutive law.
    ux, uy, uz = _curvature(profile, row, load_scale, beta,
                            r00 * gx + r10 * gy + r20 * gz,
                            r01 * gx + r11 * gy + r21 * gz,
                            r02 * gx + r12 * gy + r22 * gz)
    fx = load_scale * profile[row, DISTRIBUTED_FORCE]
    fy = load_scale * profile[row, DISTRIBUTED_FORCE + 1]
    fz = load_scale * profile[row, DISTRIBUTED_FORCE + 2]
    lx = load_scale * profile[row, DISTRIBUTED_MOMENT]
    ly = load_scale * profile[row, DISTRIBUTED_MOMENT + 1]
    lz = load_scale * profile[row, DISTRIBUTED_MOMENT + 2]
    return (
        # p' = R e3 (inextensible, unshearable: the paper's v = e3).
        r02, r12, r22,
        # R' = R hat(u).
        r01 * uz - r02 * uy, r02 * ux - r00 * uz, r00 * uy - r01 * ux,
        r11 * uz - r12 * uy, r12 * ux - r10 * uz, r10 * uy - r11 * ux,
        r21 * uz - r22 * uy, r22 * ux - r20 * uz, r20 * uy - r21 * ux,
        # n' = -f.
        -fx, -fy, -fz,
        # m' = -p' x n - R l.
        -(r12 * nz - r22 * ny) - (r00 * lx + r01 * ly + r02 * lz),
        -(r22 * nx - r02 * nz) - (r10 * lx + r11 * ly + r12 * lz),
        -(r02 * ny - r12 * nx) - (r20 * lx + r21 * ly + r22 * lz),
    )


@njit(cache=True)
def _clamp(m0x, m0y, m0z, base, rotation):
    """Clamp rotation from the base moment: compliance, then (optionally) play. Writes the
    rotation matrix and returns its rotation vector."""
    cx = base[BASE_COMPLIANCE] * m0x
    cy = base[BASE_COMPLIANCE + 1] * m0y
    cz = base[BASE_COMPLIANCE + 2] * m0z
    play = base[BASE_PLAY]
    if play > 0.0:
        px = base[BASE_PREVIOUS_ROTATION]
        py = base[BASE_PREVIOUS_ROTATION + 1]
        pz = base[BASE_PREVIOUS_ROTATION + 2]
        dx, dy, dz = cx - px, cy - py, cz - pz
        distance = np.sqrt(dx * dx + dy * dy + dz * dz)
        scale = 0.0
        if distance > 0.0:
            # Smoothed ramp max(0, distance - play): the clamp only moves once the
            # demanded rotation leaves the play zone around where it last stopped.
            excess = distance - play
            width = _PLAY_SMOOTHING * play
            scale = 0.5 * (excess + np.sqrt(excess * excess + width * width)) / distance
        cx, cy, cz = px + scale * dx, py + scale * dy, pz + scale * dz
    _so3_exp(cx, cy, cz, rotation)
    return cx, cy, cz


@njit(cache=True)
def _tip_state(x, reference, tip, load_scale, y, work):
    """Tip state for the unknown x: p = 0, R_L = reference exp(x), n and m = tip wrench."""
    _so3_exp(x[0], x[1], x[2], work)
    for i in range(3):
        for j in range(3):
            y[3 + 3 * i + j] = (reference[i, 0] * work[0, j] + reference[i, 1] * work[1, j]
                                + reference[i, 2] * work[2, j])
    y[0] = 0.0
    y[1] = 0.0
    y[2] = 0.0
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
    for i in range(3):
        r0 = y[3 + 3 * i]
        r1 = y[4 + 3 * i]
        r2 = y[5 + 3 * i]
        y[12 + i] = load_scale * (r0 * ffx + r1 * ffy + r2 * ffz + tip[TIP_DEAD_FORCE + i])
        y[15 + i] = load_scale * (r0 * fmx + r1 * fmy + r2 * fmz + tip[TIP_DEAD_MOMENT + i])
    # Dead forces off the tip point: sum_i (R r_i) x F_i = eps_abc (R T)_bc, T = sum r_i F_i^T.
    for b in range(3):
        for c in range(3):
            work[b, c] = (y[3 + 3 * b] * tip[TIP_DEAD_ARM + c] + y[4 + 3 * b] * tip[TIP_DEAD_ARM + 3 + c]
                          + y[5 + 3 * b] * tip[TIP_DEAD_ARM + 6 + c])
    y[15] += load_scale * (work[1, 2] - work[2, 1])
    y[16] += load_scale * (work[2, 0] - work[0, 2])
    y[17] += load_scale * (work[0, 1] - work[1, 0])


@njit(cache=True)
def _store_node(y, index, nodes_p, nodes_r):
    """Store a node, its frame re-orthonormalised (Gram-Schmidt from the tangent): RK4
    lets R drift off SO(3) by ~1e-6 over a large bend, which users should not see."""
    for i in range(3):
        nodes_p[index, i] = y[i]
    zx, zy, zz = y[5], y[8], y[11]
    norm = np.sqrt(zx * zx + zy * zy + zz * zz)
    zx, zy, zz = zx / norm, zy / norm, zz / norm
    xx, xy, xz = y[3], y[6], y[9]
    dot = xx * zx + xy * zy + xz * zz
    xx, xy, xz = xx - dot * zx, xy - dot * zy, xz - dot * zz
    norm = np.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx / norm, xy / norm, xz / norm
    nodes_r[index, 0, 0], nodes_r[index, 1, 0], nodes_r[index, 2, 0] = xx, xy, xz
    nodes_r[index, 0, 1] = zy * xz - zz * xy
    nodes_r[index, 1, 1] = zz * xx - zx * xz
    nodes_r[index, 2, 1] = zx * xy - zy * xx
    nodes_r[index, 0, 2], nodes_r[index, 1, 2], nodes_r[index, 2, 2] = zx, zy, zz


@njit(cache=True, fastmath=_HOT)
def _rk4_step(y, h, profile, row, load_scale, beta):
    """One classic RK4 step of length h (negative: towards the clamp) from sample row
    ``row``; the midpoint and end use rows row -/+ 1 and 2 in the step's direction."""
    direction = 1 if h > 0.0 else -1
    half = 0.5 * h
    k1 = _cosserat_derivative(y, profile, row, load_scale, beta)
    t = (y[0] + half * k1[0], y[1] + half * k1[1], y[2] + half * k1[2], y[3] + half * k1[3], y[4] + half * k1[4], y[5] + half * k1[5], y[6] + half * k1[6], y[7] + half * k1[7], y[8] + half * k1[8], y[9] + half * k1[9], y[10] + half * k1[10], y[11] + half * k1[11], y[12] + half * k1[12], y[13] + half * k1[13], y[14] + half * k1[14], y[15] + half * k1[15], y[16] + half * k1[16], y[17] + half * k1[17])
    k2 = _cosserat_derivative(t, profile, row + direction, load_scale, beta)
    t = (y[0] + half * k2[0], y[1] + half * k2[1], y[2] + half * k2[2], y[3] + half * k2[3], y[4] + half * k2[4], y[5] + half * k2[5], y[6] + half * k2[6], y[7] + half * k2[7], y[8] + half * k2[8], y[9] + half * k2[9], y[10] + half * k2[10], y[11] + half * k2[11], y[12] + half * k2[12], y[13] + half * k2[13], y[14] + half * k2[14], y[15] + half * k2[15], y[16] + half * k2[16], y[17] + half * k2[17])
    k3 = _cosserat_derivative(t, profile, row + direction, load_scale, beta)
    t = (y[0] + h * k3[0], y[1] + h * k3[1], y[2] + h * k3[2], y[3] + h * k3[3], y[4] + h * k3[4], y[5] + h * k3[5], y[6] + h * k3[6], y[7] + h * k3[7], y[8] + h * k3[8], y[9] + h * k3[9], y[10] + h * k3[10], y[11] + h * k3[11], y[12] + h * k3[12], y[13] + h * k3[13], y[14] + h * k3[14], y[15] + h * k3[15], y[16] + h * k3[16], y[17] + h * k3[17])
    k4 = _cosserat_derivative(t, profile, row + 2 * direction, load_scale, beta)
    sixth = h / 6.0
    return (y[0] + sixth * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]), y[1] + sixth * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]), y[2] + sixth * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]), y[3] + sixth * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]), y[4] + sixth * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4]), y[5] + sixth * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5]), y[6] + sixth * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6]), y[7] + sixth * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7]), y[8] + sixth * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8]), y[9] + sixth * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9]), y[10] + sixth * (k1[10] + 2.0 * (k2[10] + k3[10]) + k4[10]), y[11] + sixth * (k1[11] + 2.0 * (k2[11] + k3[11]) + k4[11]), y[12] + sixth * (k1[12] + 2.0 * (k2[12] + k3[12]) + k4[12]), y[13] + sixth * (k1[13] + 2.0 * (k2[13] + k3[13]) + k4[13]), y[14] + sixth * (k1[14] + 2.0 * (k2[14] + k3[14]) + k4[14]), y[15] + sixth * (k1[15] + 2.0 * (k2[15] + k3[15]) + k4[15]), y[16] + sixth * (k1[16] + 2.0 * (k2[16] + k3[16]) + k4[16]), y[17] + sixth * (k1[17] + 2.0 * (k2[17] + k3[17]) + k4[17]))


@njit(cache=True)
def _integrate_cosserat(steps, profile, load_scale, beta, y, nodes_p, nodes_r, store):
    """RK4 from the tip (s = 1) back to the clamp (s = 0); the state array ``y`` is read
    at the tip and overwritten with the clamp state."""
    h = -1.0 / steps
    state = (y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7], y[8], y[9], y[10], y[11], y[12], y[13], y[14], y[15], y[16], y[17])
    if store:
        _store_node(y, steps, nodes_p, nodes_r)
    for step in range(steps - 1, -1, -1):
        state = _rk4_step(state, h, profile, 2 * step + 2, load_scale, beta)
        if store:
            for k in range(18):
                y[k] = state[k]
            _store_node(y, step, nodes_p, nodes_r)
    for k in range(18):
        y[k] = state[k]


@njit(cache=True)
def _rigid_link(y, length, profile, row_a, row_b, load_scale):
    """Carry the state back along a rigid link (distal end -> proximal end). Its
    distributed load is lumped at the link's midpoint, with the profile averaged over
    rows ``row_a`` and ``row_b`` (the same row twice for a full link, whose centre is a
    sample point). Equilibrium of everything distal to the proximal end, with d the link
    vector: n_a = n_b + F and m_a = m_b + d x n_b + (d / 2) x F + M."""
    scale = 0.5 * load_scale * length
    fx = scale * (profile[row_a, DISTRIBUTED_FORCE] + profile[row_b, DISTRIBUTED_FORCE])
    fy = scale * (profile[row_a, DISTRIBUTED_FORCE + 1] + profile[row_b, DISTRIBUTED_FORCE + 1])
    fz = scale * (profile[row_a, DISTRIBUTED_FORCE + 2] + profile[row_b, DISTRIBUTED_FORCE + 2])
    lx = scale * (profile[row_a, DISTRIBUTED_MOMENT] + profile[row_b, DISTRIBUTED_MOMENT])
    ly = scale * (profile[row_a, DISTRIBUTED_MOMENT + 1] + profile[row_b, DISTRIBUTED_MOMENT + 1])
    lz = scale * (profile[row_a, DISTRIBUTED_MOMENT + 2] + profile[row_b, DISTRIBUTED_MOMENT + 2])
    dx, dy, dz = length * y[5], length * y[8], length * y[11]
    nbx, nby, nbz = y[12], y[13], y[14]
    # Body-frame moment load into the base frame: R l.
    y[15] += (dy * nbz - dz * nby) + 0.5 * (dy * fz - dz * fy) + y[3] * lx + y[4] * ly + y[5] * lz
    y[16] += (dz * nbx - dx * nbz) + 0.5 * (dz * fx - dx * fz) + y[6] * lx + y[7] * ly + y[8] * lz
    y[17] += (dx * nby - dy * nbx) + 0.5 * (dx * fy - dy * fx) + y[9] * lx + y[10] * ly + y[11] * lz
    y[12] = nbx + fx
    y[13] = nby + fy
    y[14] = nbz + fz
    y[0] -= dx
    y[1] -= dy
    y[2] -= dz


@njit(cache=True)
def _propagate_prb(joints, profile, load_scale, beta, y, work, nodes_p, nodes_r, store):
    """PRB chain from the tip back to the clamp. ``joints`` spherical joints sit at
    s = (j - 1/2) / joints, j = 1..joints, joined by full links with half links at both
    ends (joints + 1 links in all). Each joint lumps one rod segment of length
    1/joints: its stiffness is K(s_j) / segment, so theta_j = segment * u(m), the rod's
    constitutive law at the joint, with the moment in the distal link's frame. The
    profile has 2 * joints + 1 rows at s = k / (2 joints): joints on odd rows, full-link
    centres on even rows."""
    segment = 1.0 / joints
    relative = work
    rotation = np.empty((3, 3))
    if store:
        _store_node(y, joints + 1, nodes_p, nodes_r)
    _rigid_link(y, 0.5 * segment, profile, 2 * joints, 2 * joints - 1, load_scale)
    for joint in range(joints - 1, -1, -1):
        if store:
            _store_node(y, joint + 1, nodes_p, nodes_r)
        row = 2 * joint + 1
        mx = y[3] * y[15] + y[6] * y[16] + y[9] * y[17]
        my = y[4] * y[15] + y[7] * y[16] + y[10] * y[17]
        mz = y[5] * y[15] + y[8] * y[16] + y[11] * y[17]
        ux, uy, uz = _curvature(profile, row, load_scale, beta, mx, my, mz)
        # R_proximal = R_distal exp(theta)^T.
        _so3_exp(segment * ux, segment * uy, segment * uz, relative)
        for i in range(3):
            for j in range(3):
                rotation[i, j] = (y[3 + 3 * i] * relative[j, 0] + y[4 + 3 * i] * relative[j, 1]
                                  + y[5 + 3 * i] * relative[j, 2])
        for i in range(3):
            for j in range(3):
                y[3 + 3 * i + j] = rotation[i, j]
        if joint > 0:
            _rigid_link(y, segment, profile, 2 * joint, 2 * joint, load_scale)
        else:
            _rigid_link(y, 0.5 * segment, profile, 1, 0, load_scale)
    if store:
        _store_node(y, 0, nodes_p, nodes_r)


@njit(cache=True)
def _clamp_residual(y, base, residual, work):
    """Orientation error of the shape's base against the clamp: the rotation vector of
    R_clamp^T R(0). The exact logarithm matters: with it, and the reference re-anchored
    after every step, a Newton step is exact for a pure follower load."""
    _clamp(y[15], y[16], y[17], base, work)
    m00 = m01 = m02 = m10 = m11 = m12 = m20 = m21 = m22 = 0.0
    # M = R_clamp^T R(0).
    for k in range(3):
        m00 += work[k, 0] * y[3 + 3 * k]
        m01 += work[k, 0] * y[4 + 3 * k]
        m02 += work[k, 0] * y[5 + 3 * k]
        m10 += work[k, 1] * y[3 + 3 * k]
        m11 += work[k, 1] * y[4 + 3 * k]
        m12 += work[k, 1] * y[5 + 3 * k]
        m20 += work[k, 2] * y[3 + 3 * k]
        m21 += work[k, 2] * y[4 + 3 * k]
        m22 += work[k, 2] * y[5 + 3 * k]
    one_plus_trace = 1.0 + m00 + m11 + m22
    if one_plus_trace <= 0.04:
        # Over ~160 degrees off: no Newton step will be trusted from here; a large
        # residual makes the line search back off.
        residual[0] = residual[1] = residual[2] = 10.0
        return
    w = 0.5 * np.sqrt(one_plus_trace)
    vx = (m21 - m12) / (4.0 * w)
    vy = (m02 - m20) / (4.0 * w)
    vz = (m10 - m01) / (4.0 * w)
    sine = np.sqrt(vx * vx + vy * vy + vz * vz)
    scale = 2.0 / w if sine < 1e-12 else 2.0 * np.arctan2(sine, w) / sine
    residual[0] = scale * vx
    residual[1] = scale * vy
    residual[2] = scale * vz


@njit(cache=True)
def shoot(kind, resolution, x, reference, profile, tip, base, beta, load_scale, residual, y,
          work, nodes_p, nodes_r, store):
    """From the tip unknown ``x`` back to the clamp; write the clamp residual. ``y`` holds
    the clamp state afterwards (positions relative to the tip)."""
    _tip_state(x, reference, tip, load_scale, y, work)
    if kind == COSSERAT:
        _integrate_cosserat(resolution, profile, load_scale, beta, y, nodes_p, nodes_r, store)
    else:
        _propagate_prb(resolution, profile, load_scale, beta, y, work, nodes_p, nodes_r, store)
    _clamp_residual(y, base, residual, work)


@njit(cache=True)
def _norm3(v):
    return np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(cache=True)
def _solve3(a, b, out):
    """Cramer's rule on a 3x3 system; returns False when (nearly) singular."""
    c00 = a[1, 1] * a[2, 2] - a[1, 2] * a[2, 1]
    c01 = a[1, 2] * a[2, 0] - a[1, 0] * a[2, 2]
    c02 = a[1, 0] * a[2, 1] - a[1, 1] * a[2, 0]
    det = a[0, 0] * c00 + a[0, 1] * c01 + a[0, 2] * c02
    size = 0.0
    for i in range(3):
        for j in range(3):
            size = max(size, abs(a[i, j]))
    if not np.isfinite(det) or abs(det) <= 1e-14 * size * size * size:
        return False
    inv00 = c00 / det
    inv01 = (a[0, 2] * a[2, 1] - a[0, 1] * a[2, 2]) / det
    inv02 = (a[0, 1] * a[1, 2] - a[0, 2] * a[1, 1]) / det
    inv10 = c01 / det
    inv11 = (a[0, 0] * a[2, 2] - a[0, 2] * a[2, 0]) / det
    inv12 = (a[0, 2] * a[1, 0] - a[0, 0] * a[1, 2]) / det
    inv20 = c02 / det
    inv21 = (a[0, 1] * a[2, 0] - a[0, 0] * a[2, 1]) / det
    inv22 = (a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]) / det
    out[0] = inv00 * b[0] + inv01 * b[1] + inv02 * b[2]
    out[1] = inv10 * b[0] + inv11 * b[1] + inv12 * b[2]
    out[2] = inv20 * b[0] + inv21 * b[1] + inv22 * b[2]
    return True


@njit(cache=True)
def _finite_difference_jacobian(kind, resolution, x, reference, r, profile, tip, base, beta, load_scale,
                                jacobian, y, work, nodes_p, nodes_r):
    trial = x.copy()
    r_trial = np.empty(3)
    for j in range(3):
        # sqrt(machine epsilon): the residual is smooth and evaluated to rounding error.
        h = 1.5e-8 * max(1.0, abs(x[j]))
        trial[j] = x[j] + h
        shoot(kind, resolution, trial, reference, profile, tip, base, beta, load_scale, r_trial, y,
              work, nodes_p, nodes_r, False)
        for i in range(3):
            jacobian[i, j] = (r_trial[i] - r[i]) / h
        trial[j] = x[j]


@njit(cache=True)
def _reanchor(reference, x, work, scratch):
    """reference <- reference exp(x): later unknowns are small rotations about it."""
    _so3_exp(x[0], x[1], x[2], work)
    for i in range(3):
        for j in range(3):
            scratch[i, j] = reference[i, 0] * work[0, j] + reference[i, 1] * work[1, j] + reference[i, 2] * work[2, j]
    for i in range(3):
        for j in range(3):
            reference[i, j] = scratch[i, j]


@njit(cache=True)
def turned(rotation, rotation_vector):
    """rotation exp(rotation_vector), as a new matrix: a rotation turned in its own frame."""
    out = rotation.copy()
    _reanchor(out, rotation_vector, np.empty((3, 3)), np.empty((3, 3)))
    return out


@njit(cache=True)
def solve(kind, resolution, reference, jacobian, have_jacobian, profile, tip, base, beta, load_scale,
          tolerance, max_iterations, nodes_p, nodes_r, clamp_state, info):
    """Damped quasi-Newton on the shooting residual; the unknown is a small rotation of
    the tip about ``reference``, which is re-anchored after every accepted step (in
    place), and ``jacobian`` is updated in place.

    Starts from ``jacobian`` when ``have_jacobian`` (a warm start: the previous solve's
    matrix is nearly right for a nearby load), else builds it by forward differences.
    Steps are Newton steps with backtracking; after an accepted step the matrix gets a
    Broyden rank-one update, and it is rebuilt by finite differences whenever a step
    fails to reduce the residual. On return ``info`` holds [status, iterations,
    residual norm, jacobian evaluations]; if converged, the nodes hold the shape and
    ``clamp_state`` the state (18) at the clamp.
    """
    y = np.empty(18)
    work = np.empty((3, 3))
    scratch = np.empty((3, 3))
    x = np.zeros(3)
    r = np.empty(3)
    r_new = np.empty(3)
    step = np.empty(3)
    x_new = np.empty(3)
    # Every shot but the finite-difference ones stores its nodes, so the last accepted
    # shot's shape is already in place when the iteration stops.
    shoot(kind, resolution, x, reference, profile, tip, base, beta, load_scale, r, y, work,
          nodes_p, nodes_r, True)
    for k in range(18):
        clamp_state[k] = y[k]
    norm = _norm3(r)
    jacobian_evaluations = 0
    fresh = False
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
        if not have_jacobian:
            _finite_difference_jacobian(kind, resolution, x, reference, r, profile, tip, base, beta,
                                        load_scale, jacobian, y, work, nodes_p, nodes_r)
            jacobian_evaluations += 1
            have_jacobian = True
            fresh = True
        iterations += 1
        accepted = False
        new_norm = norm
        if _solve3(jacobian, r, step):
            alpha = 1.0
            for _ in range(10):
                for k in range(3):
                    x_new[k] = -alpha * step[k]
                shoot(kind, resolution, x_new, reference, profile, tip, base, beta, load_scale, r_new, y,
                      work, nodes_p, nodes_r, True)
                new_norm = _norm3(r_new)
                if np.isfinite(new_norm) and new_norm < (1.0 - 1e-4 * alpha) * norm:
                    accepted = True
                    break
                alpha *= 0.5
        if not accepted:
            if fresh:
                status = STALLED
                break
            have_jacobian = False
            continue
        # Broyden's "good" update: J += (dr - J dx) dx^T / (dx . dx).
        dx_dot = x_new[0] * x_new[0] + x_new[1] * x_new[1] + x_new[2] * x_new[2]
        for i in range(3):
            predicted = jacobian[i, 0] * x_new[0] + jacobian[i, 1] * x_new[1] + jacobian[i, 2] * x_new[2]
            correction = (r_new[i] - r[i] - predicted) / dx_dot
            for k in range(3):
                jacobian[i, k] += correction * x_new[k]
        fresh = False
        _reanchor(reference, x_new, work, scratch)
        for k in range(3):
            r[k] = r_new[k]
        for k in range(18):
            clamp_state[k] = y[k]
        norm = new_norm
    info[0] = status
    info[1] = iterations
    info[2] = norm
    info[3] = jacobian_evaluations


@njit(cache=True)
def clamp_rotation_vector(moment, base):
    """Rotation vector (rad) of the clamp under the (nondimensional) clamp moment."""
    rotation = np.empty((3, 3))
    return _clamp(moment[0], moment[1], moment[2], base, rotation)


@njit(cache=True)
def relative_rotation_vector(rotation_a, rotation_b, out):
    """Rotation vector (rad, in frame a) of R_a^T R_b, through its quaternion so it is
    accurate for small and large angles alike; returns the angle."""
    rel = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            rel[i, j] = rotation_a[0, i] * rotation_b[0, j] + rotation_a[1, i] * rotation_b[1, j] + rotation_a[2, i] * rotation_b[2, j]
    w = 0.5 * np.sqrt(max(1.0 + rel[0, 0] + rel[1, 1] + rel[2, 2], 0.0))
    if w < 1e-6:
        raise ValueError("relative_rotation_vector: relative rotation too close to a half turn")
    vx = (rel[2, 1] - rel[1, 2]) / (4.0 * w)
    vy = (rel[0, 2] - rel[2, 0]) / (4.0 * w)
    vz = (rel[1, 0] - rel[0, 1]) / (4.0 * w)
    sine = np.sqrt(vx * vx + vy * vy + vz * vz)
    theta = 2.0 * np.arctan2(sine, w)
    scale = 2.0 / w if sine < 1e-12 else theta / sine
    out[0] = scale * vx
    out[1] = scale * vy
    out[2] = scale * vz
    return theta


@njit(cache=True)
def body_twist(rotation_a, position_a, rotation_b, position_b, out):
    """Twist (v, omega) in frame a with exp(twist) = g_a^-1 g_b: se(3) logarithm of the
    relative pose, for poses given as rotation matrices and positions."""
    omega = np.empty(3)
    theta = relative_rotation_vector(rotation_a, rotation_b, omega)
    ox, oy, oz = omega[0], omega[1], omega[2]
    dp0 = position_b[0] - position_a[0]
    dp1 = position_b[1] - position_a[1]
    dp2 = position_b[2] - position_a[2]
    t0 = rotation_a[0, 0] * dp0 + rotation_a[1, 0] * dp1 + rotation_a[2, 0] * dp2
    t1 = rotation_a[0, 1] * dp0 + rotation_a[1, 1] * dp1 + rotation_a[2, 1] * dp2
    t2 = rotation_a[0, 2] * dp0 + rotation_a[1, 2] * dp1 + rotation_a[2, 2] * dp2
    # v = J_l(omega)^-1 t, with J_l^-1 = I - hat(w)/2 + c hat(w)^2.
    if theta < 1e-6:
        c = 1.0 / 12.0
    else:
        half = 0.5 * theta
        c = (1.0 - half * np.cos(half) / np.sin(half)) / (theta * theta)
    cx = oy * t2 - oz * t1
    cy = oz * t0 - ox * t2
    cz = ox * t1 - oy * t0
    ccx = oy * cz - oz * cy
    ccy = oz * cx - ox * cz
    ccz = ox * cy - oy * cx
    out[0] = t0 - 0.5 * cx + c * ccx
    out[1] = t1 - 0.5 * cy + c * ccy
    out[2] = t2 - 0.5 * cz + c * ccz
    out[3] = ox
    out[4] = oy
    out[5] = oz


@njit(cache=True)
def tip_wrench_sensitivity(kind, resolution, reference, profile, tip, base, beta, components, steps, length,
                           jacobian, columns):
    """Sensitivity of the tip pose to tip follower wrench components (w_d: 0-2 force, 3-5
    moment, tip frame) at the converged tip orientation ``reference``, all columns from
    3 + k + 1 shots and no solve.

    By the implicit function theorem the tip rotation moves by dx = -J^-1 dr/dw, where
    J = dr/dx is the shooting Jacobian and dr/dw the residual's change at a fixed tip
    orientation; the tip, relative to the clamp, moves by -(dP/dx dx + dP/dw), P the
    clamp position of a shot started with the tip at the origin. Both partials are
    forward differences of single shots, which are deterministic to rounding, not of
    solves, which land anywhere within the solver tolerance. ``steps``: nondimensional
    step per component. Writes ``jacobian`` (J at ``reference``: an accurate matrix for
    solves near this one) and ``columns`` (6, k): body twists (v in units of ``length``,
    omega) per unit of each component. Returns False when J is singular or a shot is not
    finite."""
    y = np.empty(18)
    work = np.empty((3, 3))
    x = np.zeros(3)
    r0 = np.empty(3)
    r = np.empty(3)
    rotation_rate = np.empty(3)
    position_rate = np.empty(3)
    moved = np.empty(3)
    nodes_p = np.empty((1, 3))
    nodes_r = np.empty((1, 3, 3))
    position_by_x = np.empty((3, 3))
    shoot(kind, resolution, x, reference, profile, tip, base, beta, 1.0, r0, y, work, nodes_p, nodes_r, False)
    p0x, p0y, p0z = y[0], y[1], y[2]
    for j in range(3):
        # sqrt(machine epsilon): the residual is smooth and evaluated to rounding error.
        h = 1.5e-8
        x[j] = h
        shoot(kind, resolution, x, reference, profile, tip, base, beta, 1.0, r, y, work, nodes_p, nodes_r, False)
        x[j] = 0.0
        for i in range(3):
            jacobian[i, j] = (r[i] - r0[i]) / h
        position_by_x[0, j] = (y[0] - p0x) / h
        position_by_x[1, j] = (y[1] - p0y) / h
        position_by_x[2, j] = (y[2] - p0z) / h
    perturbed_tip = tip.copy()
    for column in range(components.shape[0]):
        index = TIP_FOLLOWER_FORCE + components[column]
        step = steps[column]
        perturbed_tip[index] = tip[index] + step
        shoot(kind, resolution, x, reference, profile, perturbed_tip, base, beta, 1.0, r, y, work,
              nodes_p, nodes_r, False)
        perturbed_tip[index] = tip[index]
        for i in range(3):
            r[i] = -(r[i] - r0[i]) / step
        if not _solve3(jacobian, r, rotation_rate):
            return False
        position_rate[0] = (y[0] - p0x) / step
        position_rate[1] = (y[1] - p0y) / step
        position_rate[2] = (y[2] - p0z) / step
        for i in range(3):
            moved[i] = -(position_rate[i] + position_by_x[i, 0] * rotation_rate[0]
                         + position_by_x[i, 1] * rotation_rate[1] + position_by_x[i, 2] * rotation_rate[2])
        for k in range(3):
            columns[k, column] = length * (reference[0, k] * moved[0] + reference[1, k] * moved[1]
                                           + reference[2, k] * moved[2])
            columns[3 + k, column] = rotation_rate[k]
        for k in range(6):
            if not np.isfinite(columns[k, column]):
                return False
    return True
