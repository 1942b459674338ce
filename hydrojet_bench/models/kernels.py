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

The Cosserat shot can also carry tangents (forward mode): the derivatives of the RK4
map itself, stage by stage, along any tip-orientation or tip-load direction, so one
pass gives the residual and its exact Jacobian, or the exact w_d sensitivities. The
small functions of the RK4 step are inlined into the loops (numba ``inline="always"``):
left as calls, the 18-number state went through memory at every stage and a shot
cost twice as much.

The argument ``beta`` says which section law and loads a kernel carries: a float is the
general rod (cubic coefficient beta of the section law, possibly 0, any distributed
moment and any strain compliance in the profile: a section that shears and stretches,
v = e3 + C n_body), None the plain rod (linear section law, no distributed moment,
inextensible and unshearable).
Numba compiles a kernel per argument type and drops the branches a None rules out, so
the plain rod, every library effect but nonlinear elasticity and shear_extension, gets
a shot without the Newton solve of the section law, the distributed-moment products and
the strain: a fifth less time per shot (2.0 -> 1.55 us, before the strain) than the
general kernel, which tests for them at every RK4 stage, and a tenth less per tangent
shot.

Every shot stores its nodes, even one whose shape nobody reads (a Jacobian's): a flag
saying whether to store cost 2-4 % of a warm solve as a run-time test in the RK4 loop,
and as a literal doubled every kernel above the loop (numba compiles a callee once per
literal argument value, and each copy of a solver-sized kernel costs seconds of
compiling). Flags that remain between kernels are written ``np.bool_(True)`` for the
same reason.

Everything here is nondimensional: lengths by L, moments by EI_ref / L and forces by
EI_ref / L^2 (EI_ref = E0 * I), so the unknowns and residuals are of order one and a
single tolerance means the same for every rod. `hydrojet_bench.models.shooting` does the
scaling.

Every kernel releases the interpreter lock (``nogil``): a session calibrates and
estimates on worker threads beside its event loop, and kernels holding the lock during
the 40-pose calibration stalled that loop for 0.1 s (the paper protocol at x25), long
enough for the emulated IMUs' FIFOs to overflow. Kernels write only into arrays their
caller made for the call, so two threads may run them at once.

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
STRAIN_COMPLIANCE = 15  # body frame: shear x, shear y, extension per unit internal force
PROFILE_COLUMNS = 18

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

# Newton steps a PRB joint gets to find its mid-rotation frame (`_joint_curvature`);
# they converge quadratically from a start within about |theta| / 2 of the answer, and
# a joint that still has not solved makes the shot NaN, which the solver reports.
JOINT_NEWTON_STEPS = 8

# Status codes returned by `solve`.
CONVERGED = 0
MAX_ITERATIONS = 1
STALLED = 2
NOT_FINITE = 3

# Smoothing width of the clamp's play operator relative to the play radius: the
# nonsmooth operator makes Newton chatter at the switch; 5 % rounding is far below
# anything a tracker can see.
_PLAY_SMOOTHING = 0.05


@njit(cache=True, nogil=True, fastmath=False)
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


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _curvature(profile, row, load_scale, beta, mx, my, mz):
    """Invert the constitutive law at a sample point: body moment -> curvature u."""
    vx = mx * profile[row, COMPLIANCE]
    vy = my * profile[row, COMPLIANCE + 1]
    if beta is not None and beta != 0.0:
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


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _moment_load(profile, row, load_scale, beta):
    """The scaled body-frame distributed moment at a sample point; None on the plain rod."""
    if beta is None:
        return None
    return (load_scale * profile[row, DISTRIBUTED_MOMENT], load_scale * profile[row, DISTRIBUTED_MOMENT + 1],
            load_scale * profile[row, DISTRIBUTED_MOMENT + 2])


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _strain(e, r00, r01, r02, r10, r11, r12, r20, r21, r22, nx, ny, nz):
    """The section's strain v = e3 + C_se R^T n under the internal force n (base frame),
    and p' = R v: ``(vx, vy, vz, tx, ty, tz)``. ``e`` is the strain compliance C_se
    (body frame: shear x, shear y, extension; `_strain_compliance`), None on the plain rod,
    which is inextensible and unshearable (the paper's v = e3)."""
    if e is not None:
        ex, ey, ez = e
        vx = ex * (r00 * nx + r10 * ny + r20 * nz)
        vy = ey * (r01 * nx + r11 * ny + r21 * nz)
        vz = 1.0 + ez * (r02 * nx + r12 * ny + r22 * nz)
        return (vx, vy, vz, r00 * vx + r01 * vy + r02 * vz, r10 * vx + r11 * vy + r12 * vz,
                r20 * vx + r21 * vy + r22 * vz)
    return 0.0, 0.0, 1.0, r02, r12, r22


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _strain_compliance(profile, row, beta):
    """The strain compliance C_se at a sample point; None on the plain rod."""
    if beta is None:
        return None
    return profile[row, STRAIN_COMPLIANCE], profile[row, STRAIN_COMPLIANCE + 1], profile[row, STRAIN_COMPLIANCE + 2]


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _cosserat_derivative(y, profile, row, load_scale, beta):
    """Right-hand side of eqs. 21 in the base frame, on the state as an 18-tuple, and the
    curvature u it used. Tuples stay in registers; with arrays numba cannot prove the
    state and its derivative distinct and reloads after every store, which made the
    integrator 3-4x slower."""
    (px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, nx, ny, nz, gx, gy, gz) = y
    # Body-frame moment m_b = R^T m, then the curvature from the constitutive law.
    ux, uy, uz = _curvature(profile, row, load_scale, beta,
                            r00 * gx + r10 * gy + r20 * gz,
                            r01 * gx + r11 * gy + r21 * gz,
                            r02 * gx + r12 * gy + r22 * gz)
    fx = load_scale * profile[row, DISTRIBUTED_FORCE]
    fy = load_scale * profile[row, DISTRIBUTED_FORCE + 1]
    fz = load_scale * profile[row, DISTRIBUTED_FORCE + 2]
    # p' = R v: the general rod may shear and stretch.
    _, _, _, tx, ty, tz = _strain(_strain_compliance(profile, row, beta),
                                  r00, r01, r02, r10, r11, r12, r20, r21, r22, nx, ny, nz)
    # m' = -p' x n - R l; the plain rod (beta None) has no l.
    mx = -(ty * nz - tz * ny)
    my = -(tz * nx - tx * nz)
    mz = -(tx * ny - ty * nx)
    if beta is not None:
        lx, ly, lz = _moment_load(profile, row, load_scale, beta)
        mx -= r00 * lx + r01 * ly + r02 * lz
        my -= r10 * lx + r11 * ly + r12 * lz
        mz -= r20 * lx + r21 * ly + r22 * lz
    return (
        tx, ty, tz,
        # R' = R hat(u).
        r01 * uz - r02 * uy, r02 * ux - r00 * uz, r00 * uy - r01 * ux,
        r11 * uz - r12 * uy, r12 * ux - r10 * uz, r10 * uy - r11 * ux,
        r21 * uz - r22 * uy, r22 * ux - r20 * uz, r20 * uy - r21 * ux,
        # n' = -f.
        -fx, -fy, -fz,
        mx, my, mz,
    ), (ux, uy, uz)


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _curvature_compliance(profile, row, load_scale, beta, u):
    """du/dm_b at a sample point where the curvature is ``u``: the inverse of the
    constitutive law's Jacobian, (a00, a01, a10, a11) for bending and the torsional
    compliance; the linear law's compliances when beta is 0 or None."""
    cx = profile[row, COMPLIANCE]
    cy = profile[row, COMPLIANCE + 1]
    cz = profile[row, COMPLIANCE + 2]
    if beta is None or beta == 0.0:
        return cx, 0.0, 0.0, cy, cz
    vx = u[0] - load_scale * profile[row, INTRINSIC_CURVATURE]
    vy = u[1] - load_scale * profile[row, INTRINSIC_CURVATURE + 1]
    kx = profile[row, STIFFNESS]
    ky = profile[row, STIFFNESS + 1]
    s = vx * vx + vy * vy
    j00 = kx * (1.0 + beta * (s + 2.0 * vx * vx))
    j11 = ky * (1.0 + beta * (s + 2.0 * vy * vy))
    j01 = kx * 2.0 * beta * vx * vy
    j10 = ky * 2.0 * beta * vx * vy
    det = j00 * j11 - j01 * j10
    return j11 / det, -j01 / det, -j10 / det, j00 / det, cz


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _tangent_rates(t, u, c, l, e, start, a, previous, dn, out):
    """The variational equation of eqs. 21 at an RK4 stage: ``out[:, d]`` = the derivative
    of the tangent start[:, d] + a * previous[:, d] (15 rows: dp, dR row-major, dm; one
    column per direction) at the stage state ``t`` (18-tuple), whose curvature is ``u``
    and local compliance ``c`` (`_curvature_compliance`); ``l`` the row's scaled
    body-frame distributed moment and ``e`` its strain compliance (both None on the plain
    rod). dn (3, D) is constant along the rod: the distributed force does not depend on
    the state. Directions are columns so the loop runs over contiguous memory."""
    (px, py, pz, r00, r01, r02, r10, r11, r12, r20, r21, r22, nx, ny, nz, gx, gy, gz) = t
    ux, uy, uz = u
    vx, vy, vz, tx, ty, tz = _strain(e, r00, r01, r02, r10, r11, r12, r20, r21, r22, nx, ny, nz)
    for d in range(start.shape[1]):
        d00 = start[3, d] + a * previous[3, d]
        d01 = start[4, d] + a * previous[4, d]
        d02 = start[5, d] + a * previous[5, d]
        d10 = start[6, d] + a * previous[6, d]
        d11 = start[7, d] + a * previous[7, d]
        d12 = start[8, d] + a * previous[8, d]
        d20 = start[9, d] + a * previous[9, d]
        d21 = start[10, d] + a * previous[10, d]
        d22 = start[11, d] + a * previous[11, d]
        dgx = start[12, d] + a * previous[12, d]
        dgy = start[13, d] + a * previous[13, d]
        dgz = start[14, d] + a * previous[14, d]
        dnx = dn[0, d]
        dny = dn[1, d]
        dnz = dn[2, d]
        # d(m_b) = dR^T m + R^T dm, then du = (du/dm_b) d(m_b).
        dbx = d00 * gx + d10 * gy + d20 * gz + r00 * dgx + r10 * dgy + r20 * dgz
        dby = d01 * gx + d11 * gy + d21 * gz + r01 * dgx + r11 * dgy + r21 * dgz
        dbz = d02 * gx + d12 * gy + d22 * gz + r02 * dgx + r12 * dgy + r22 * dgz
        dux = c[0] * dbx + c[1] * dby
        duy = c[2] * dbx + c[3] * dby
        duz = c[4] * dbz
        # dp' = dR v + R dv, dv = C_se (dR^T n + R^T dn); dR e3 on the plain rod.
        dtx = d02
        dty = d12
        dtz = d22
        if e is not None:
            ex, ey, ez = e
            dvx = ex * (d00 * nx + d10 * ny + d20 * nz + r00 * dnx + r10 * dny + r20 * dnz)
            dvy = ey * (d01 * nx + d11 * ny + d21 * nz + r01 * dnx + r11 * dny + r21 * dnz)
            dvz = ez * (d02 * nx + d12 * ny + d22 * nz + r02 * dnx + r12 * dny + r22 * dnz)
            dtx = d00 * vx + d01 * vy + d02 * vz + r00 * dvx + r01 * dvy + r02 * dvz
            dty = d10 * vx + d11 * vy + d12 * vz + r10 * dvx + r11 * dvy + r12 * dvz
            dtz = d20 * vx + d21 * vy + d22 * vz + r20 * dvx + r21 * dvy + r22 * dvz
        out[0, d] = dtx
        out[1, d] = dty
        out[2, d] = dtz
        # dR' = dR hat(u) + R hat(du).
        out[3, d] = d01 * uz - d02 * uy + r01 * duz - r02 * duy
        out[4, d] = d02 * ux - d00 * uz + r02 * dux - r00 * duz
        out[5, d] = d00 * uy - d01 * ux + r00 * duy - r01 * dux
        out[6, d] = d11 * uz - d12 * uy + r11 * duz - r12 * duy
        out[7, d] = d12 * ux - d10 * uz + r12 * dux - r10 * duz
        out[8, d] = d10 * uy - d11 * ux + r10 * duy - r11 * dux
        out[9, d] = d21 * uz - d22 * uy + r21 * duz - r22 * duy
        out[10, d] = d22 * ux - d20 * uz + r22 * dux - r20 * duz
        out[11, d] = d20 * uy - d21 * ux + r20 * duy - r21 * dux
        # dm' = -(dp' x n + p' x dn) - dR l.
        out[12, d] = -(dty * nz - dtz * ny + ty * dnz - tz * dny)
        out[13, d] = -(dtz * nx - dtx * nz + tz * dnx - tx * dnz)
        out[14, d] = -(dtx * ny - dty * nx + tx * dny - ty * dnx)
        if l is not None:
            lx, ly, lz = l
            out[12, d] -= d00 * lx + d01 * ly + d02 * lz
            out[13, d] -= d10 * lx + d11 * ly + d12 * lz
            out[14, d] -= d20 * lx + d21 * ly + d22 * lz


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True, inline="always")
def _arm(rotation, tip, b, c):
    """(R T)_bc for the 9 row-major entries of R and the tip's dead-force arm T."""
    return (rotation[3 * b] * tip[TIP_DEAD_ARM + c] + rotation[3 * b + 1] * tip[TIP_DEAD_ARM + 3 + c]
            + rotation[3 * b + 2] * tip[TIP_DEAD_ARM + 6 + c])


@njit(cache=True, nogil=True)
def _tip_wrench(rotation, tip, load_scale, dead, out):
    """Tip wrench (n, m in the base frame) into ``out`` (6) for a tip orientation given as
    the 9 row-major entries ``rotation``; it is linear in them, which is also how the
    tangent seeds use it (a rotation tangent, ``dead`` False: the dead loads are
    constants)."""
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
    constant = 1.0 if dead else 0.0
    for i in range(3):
        r0 = rotation[3 * i]
        r1 = rotation[3 * i + 1]
        r2 = rotation[3 * i + 2]
        out[i] = load_scale * (r0 * ffx + r1 * ffy + r2 * ffz + constant * tip[TIP_DEAD_FORCE + i])
        out[3 + i] = load_scale * (r0 * fmx + r1 * fmy + r2 * fmz + constant * tip[TIP_DEAD_MOMENT + i])
    # Dead forces off the tip point: sum_i (R r_i) x F_i = eps_abc (R T)_bc, T = sum r_i F_i^T.
    out[3] += load_scale * (_arm(rotation, tip, 1, 2) - _arm(rotation, tip, 2, 1))
    out[4] += load_scale * (_arm(rotation, tip, 2, 0) - _arm(rotation, tip, 0, 2))
    out[5] += load_scale * (_arm(rotation, tip, 0, 1) - _arm(rotation, tip, 1, 0))


@njit(cache=True, nogil=True)
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
    _tip_wrench(y[3:12], tip, load_scale, np.bool_(True), y[12:18])


@njit(cache=True, nogil=True, inline="always")
def _store_node(y, index, nodes_p, nodes_r):
    """Store a node's position and frame as integrated (``y``: the state, an array or an
    18-tuple); `_finish_nodes` tidies the last shot's nodes once, after the solve."""
    nodes_p[index, 0] = y[0]
    nodes_p[index, 1] = y[1]
    nodes_p[index, 2] = y[2]
    nodes_r[index, 0, 0] = y[3]
    nodes_r[index, 0, 1] = y[4]
    nodes_r[index, 0, 2] = y[5]
    nodes_r[index, 1, 0] = y[6]
    nodes_r[index, 1, 1] = y[7]
    nodes_r[index, 1, 2] = y[8]
    nodes_r[index, 2, 0] = y[9]
    nodes_r[index, 2, 1] = y[10]
    nodes_r[index, 2, 2] = y[11]


@njit(cache=True, nogil=True)
def _orthonormalise(rotation):
    """Re-orthonormalise a frame in place (Gram-Schmidt from the tangent): RK4 lets R drift
    off SO(3) by ~1e-6 over a large bend, which users should not see."""
    zx, zy, zz = rotation[0, 2], rotation[1, 2], rotation[2, 2]
    norm = np.sqrt(zx * zx + zy * zy + zz * zz)
    zx, zy, zz = zx / norm, zy / norm, zz / norm
    xx, xy, xz = rotation[0, 0], rotation[1, 0], rotation[2, 0]
    dot = xx * zx + xy * zy + xz * zz
    xx, xy, xz = xx - dot * zx, xy - dot * zy, xz - dot * zz
    norm = np.sqrt(xx * xx + xy * xy + xz * xz)
    xx, xy, xz = xx / norm, xy / norm, xz / norm
    rotation[0, 0], rotation[1, 0], rotation[2, 0] = xx, xy, xz
    rotation[0, 1] = zy * xz - zz * xy
    rotation[1, 1] = zz * xx - zx * xz
    rotation[2, 1] = zx * xy - zy * xx
    rotation[0, 2], rotation[1, 2], rotation[2, 2] = zx, zy, zz


@njit(cache=True, nogil=True)
def _finish_nodes(clamp_state, base, length, wrench_scale, nodes_p, nodes_r, base_wrench, clamp_rotation):
    """Turn the last shot's nodes into the shape users see: positions shifted so the clamp
    is at the origin (the shot starts with the tip there) and scaled to metres, frames
    re-orthonormalised, node 0 exactly the clamp frame (the integrated one matches it
    only to the solver tolerance plus RK4's drift off SO(3), ~1e-7 rad, and every user
    of the base frame should agree). Also writes the clamp wrench (N, N m) and the
    clamp's rotation vector (rad)."""
    for index in range(nodes_p.shape[0]):
        for k in range(3):
            nodes_p[index, k] = (nodes_p[index, k] - clamp_state[k]) * length
        if index > 0:
            _orthonormalise(nodes_r[index])
    if base[BASE_COMPLIANCE] == 0.0 and base[BASE_COMPLIANCE + 1] == 0.0 and base[BASE_COMPLIANCE + 2] == 0.0:
        # A rigid clamp does not turn, whatever play it is given.
        cx = cy = cz = 0.0
        _so3_exp(0.0, 0.0, 0.0, nodes_r[0])
    else:
        cx, cy, cz = _clamp(clamp_state[15], clamp_state[16], clamp_state[17], base, nodes_r[0])
    clamp_rotation[0] = cx
    clamp_rotation[1] = cy
    clamp_rotation[2] = cz
    for k in range(6):
        base_wrench[k] = clamp_state[12 + k] * wrench_scale[k]


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _axpy18(y, a, k):
    return (y[0] + a * k[0], y[1] + a * k[1], y[2] + a * k[2], y[3] + a * k[3], y[4] + a * k[4], y[5] + a * k[5], y[6] + a * k[6], y[7] + a * k[7], y[8] + a * k[8], y[9] + a * k[9], y[10] + a * k[10], y[11] + a * k[11], y[12] + a * k[12], y[13] + a * k[13], y[14] + a * k[14], y[15] + a * k[15], y[16] + a * k[16], y[17] + a * k[17])


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _rk4_sum18(y, sixth, k1, k2, k3, k4):
    return (y[0] + sixth * (k1[0] + 2.0 * (k2[0] + k3[0]) + k4[0]), y[1] + sixth * (k1[1] + 2.0 * (k2[1] + k3[1]) + k4[1]), y[2] + sixth * (k1[2] + 2.0 * (k2[2] + k3[2]) + k4[2]), y[3] + sixth * (k1[3] + 2.0 * (k2[3] + k3[3]) + k4[3]), y[4] + sixth * (k1[4] + 2.0 * (k2[4] + k3[4]) + k4[4]), y[5] + sixth * (k1[5] + 2.0 * (k2[5] + k3[5]) + k4[5]), y[6] + sixth * (k1[6] + 2.0 * (k2[6] + k3[6]) + k4[6]), y[7] + sixth * (k1[7] + 2.0 * (k2[7] + k3[7]) + k4[7]), y[8] + sixth * (k1[8] + 2.0 * (k2[8] + k3[8]) + k4[8]), y[9] + sixth * (k1[9] + 2.0 * (k2[9] + k3[9]) + k4[9]), y[10] + sixth * (k1[10] + 2.0 * (k2[10] + k3[10]) + k4[10]), y[11] + sixth * (k1[11] + 2.0 * (k2[11] + k3[11]) + k4[11]), y[12] + sixth * (k1[12] + 2.0 * (k2[12] + k3[12]) + k4[12]), y[13] + sixth * (k1[13] + 2.0 * (k2[13] + k3[13]) + k4[13]), y[14] + sixth * (k1[14] + 2.0 * (k2[14] + k3[14]) + k4[14]), y[15] + sixth * (k1[15] + 2.0 * (k2[15] + k3[15]) + k4[15]), y[16] + sixth * (k1[16] + 2.0 * (k2[16] + k3[16]) + k4[16]), y[17] + sixth * (k1[17] + 2.0 * (k2[17] + k3[17]) + k4[17]))


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _rk4_stages(y, h, profile, row, load_scale, beta):
    """One classic RK4 step of length h (negative: towards the clamp) from sample row
    ``row``; the midpoint and end use rows row -/+ 1 and 2 in the step's direction.
    Returns the new state, the stage states 2-4 and the curvature at each stage (what
    the tangent step linearises about)."""
    direction = 1 if h > 0.0 else -1
    half = 0.5 * h
    k1, u1 = _cosserat_derivative(y, profile, row, load_scale, beta)
    t2 = _axpy18(y, half, k1)
    k2, u2 = _cosserat_derivative(t2, profile, row + direction, load_scale, beta)
    t3 = _axpy18(y, half, k2)
    k3, u3 = _cosserat_derivative(t3, profile, row + direction, load_scale, beta)
    t4 = _axpy18(y, h, k3)
    k4, u4 = _cosserat_derivative(t4, profile, row + 2 * direction, load_scale, beta)
    return _rk4_sum18(y, h / 6.0, k1, k2, k3, k4), t2, t3, t4, u1, u2, u3, u4


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _rk4_step(y, h, profile, row, load_scale, beta):
    return _rk4_stages(y, h, profile, row, load_scale, beta)[0]


@njit(cache=True, nogil=True)
def _integrate_cosserat(steps, profile, load_scale, beta, y, nodes_p, nodes_r):
    """RK4 from the tip (s = 1) back to the clamp (s = 0); the state array ``y`` is read
    at the tip and overwritten with the clamp state."""
    h = -1.0 / steps
    state = (y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7], y[8], y[9], y[10], y[11], y[12], y[13], y[14], y[15], y[16], y[17])
    _store_node(y, steps, nodes_p, nodes_r)
    for step in range(steps - 1, -1, -1):
        state = _rk4_step(state, h, profile, 2 * step + 2, load_scale, beta)
        _store_node(state, step, nodes_p, nodes_r)
    for k in range(18):
        y[k] = state[k]


@njit(cache=True, nogil=True, fastmath=_HOT)
def _integrate_cosserat_tangent(steps, profile, load_scale, beta, y, tangents, dn, nodes_p, nodes_r):
    """`_integrate_cosserat` carrying tangents along: ``tangents`` (15, D: dp, dR, dm per
    direction) is read at the tip and overwritten at the clamp; ``dn`` (3, D) is constant
    along the rod. The tangents go through the very stages of each RK4 step, so they are
    the exact derivatives of the discrete shot (forward mode), to rounding."""
    h = -1.0 / steps
    half = 0.5 * h
    sixth = h / 6.0
    directions = tangents.shape[1]
    k1 = np.empty((15, directions))
    k2 = np.empty((15, directions))
    k3 = np.empty((15, directions))
    k4 = np.empty((15, directions))
    state = (y[0], y[1], y[2], y[3], y[4], y[5], y[6], y[7], y[8], y[9], y[10], y[11], y[12], y[13], y[14], y[15], y[16], y[17])
    _store_node(state, steps, nodes_p, nodes_r)
    for step in range(steps - 1, -1, -1):
        row = 2 * step + 2
        new, t2, t3, t4, u1, u2, u3, u4 = _rk4_stages(state, h, profile, row, load_scale, beta)
        middle = _moment_load(profile, row - 1, load_scale, beta)
        middle_strain = _strain_compliance(profile, row - 1, beta)
        _tangent_rates(state, u1, _curvature_compliance(profile, row, load_scale, beta, u1),
                       _moment_load(profile, row, load_scale, beta), _strain_compliance(profile, row, beta),
                       tangents, 0.0, tangents, dn, k1)
        _tangent_rates(t2, u2, _curvature_compliance(profile, row - 1, load_scale, beta, u2), middle,
                       middle_strain, tangents, half, k1, dn, k2)
        _tangent_rates(t3, u3, _curvature_compliance(profile, row - 1, load_scale, beta, u3), middle,
                       middle_strain, tangents, half, k2, dn, k3)
        _tangent_rates(t4, u4, _curvature_compliance(profile, row - 2, load_scale, beta, u4),
                       _moment_load(profile, row - 2, load_scale, beta), _strain_compliance(profile, row - 2, beta),
                       tangents, h, k3, dn, k4)
        for k in range(15):
            for d in range(directions):
                tangents[k, d] += sixth * (k1[k, d] + 2.0 * (k2[k, d] + k3[k, d]) + k4[k, d])
        state = new
        _store_node(state, step, nodes_p, nodes_r)
    for k in range(18):
        y[k] = state[k]


@njit(cache=True, nogil=True)
def _rigid_link(y, length, profile, row_a, row_b, load_scale, beta):
    """Carry the state back along a link, rigid in bending (distal end -> proximal end). Its
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
    nbx, nby, nbz = y[12], y[13], y[14]
    # The link shears and stretches under its mean internal force, d = length R v (the
    # general rod; the plain one, beta None, is inextensible).
    tx, ty, tz = y[5], y[8], y[11]
    if beta is not None:
        strain = (0.5 * (profile[row_a, STRAIN_COMPLIANCE] + profile[row_b, STRAIN_COMPLIANCE]),
                  0.5 * (profile[row_a, STRAIN_COMPLIANCE + 1] + profile[row_b, STRAIN_COMPLIANCE + 1]),
                  0.5 * (profile[row_a, STRAIN_COMPLIANCE + 2] + profile[row_b, STRAIN_COMPLIANCE + 2]))
        _, _, _, tx, ty, tz = _strain(strain, y[3], y[4], y[5], y[6], y[7], y[8], y[9], y[10], y[11],
                                      nbx + 0.5 * fx, nby + 0.5 * fy, nbz + 0.5 * fz)
    dx, dy, dz = length * tx, length * ty, length * tz
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


@njit(cache=True, nogil=True, fastmath=_HOT, inline="always")
def _joint_curvature(profile, row, load_scale, beta, segment, mx, my, mz):
    """The section law at a joint, theta = segment * u(m_mid), applied in the joint's
    mid-rotation frame R_mid = R_distal exp(-theta / 2), where the moment reads
    m_mid = exp(theta / 2) m_distal (``mx, my, mz``: m_distal); NaN if it does not solve.

    In the distal link's frame the chain converges to the rod only at first order in the
    link count once the section law is not a multiple of the identity (an anisotropic
    section bent off its principal axes: 2.4 deg apart at 20 links, halving per
    doubling); in the symmetric frame it is second order (0.07 deg). theta is implicit:
    fixed-point passes gain only a factor of about |theta| / 2 each, so Newton on u
    solves it, d m_mid / du = -(segment / 2) [m_mid]x J_l(theta / 2) with J_l the left
    Jacobian of SO(3). It starts from the distal frame's answer, which is exact for an
    isotropic section with no twist, and stops at 1e-13 rad, where the steps are
    quadratic and the shot stays smooth for the solver's differences."""
    ux, uy, uz = _curvature(profile, row, load_scale, beta, mx, my, mz)
    half = 0.5 * segment
    for _ in range(JOINT_NEWTON_STEPS):
        hx, hy, hz = half * ux, half * uy, half * uz
        angle2 = hx * hx + hy * hy + hz * hz
        # exp(h) = I + a [h]x + b [h]x^2 and J_l(h) = I + b [h]x + c [h]x^2; series below
        # 0.2 rad (error < 1e-11) spare the trigonometry in the common case.
        if angle2 < 0.04:
            a = 1.0 - angle2 * (1.0 / 6.0 - angle2 * (1.0 / 120.0 - angle2 / 5040.0))
            b = 0.5 - angle2 * (1.0 / 24.0 - angle2 * (1.0 / 720.0 - angle2 / 40320.0))
            c = 1.0 / 6.0 - angle2 * (1.0 / 120.0 - angle2 * (1.0 / 5040.0 - angle2 / 362880.0))
        else:
            angle = np.sqrt(angle2)
            a = np.sin(angle) / angle
            b = (1.0 - np.cos(angle)) / angle2
            c = (1.0 - a) / angle2
        cx, cy, cz = hy * mz - hz * my, hz * mx - hx * mz, hx * my - hy * mx
        ccx, ccy, ccz = hy * cz - hz * cy, hz * cx - hx * cz, hx * cy - hy * cx
        px, py, pz = mx + a * cx + b * ccx, my + a * cy + b * ccy, mz + a * cz + b * ccz
        vx, vy, vz = _curvature(profile, row, load_scale, beta, px, py, pz)
        fx, fy, fz = ux - vx, uy - vy, uz - vz
        if segment * max(abs(fx), abs(fy), abs(fz)) < 1e-13:
            return vx, vy, vz
        a00, a01, a10, a11, a22 = _curvature_compliance(profile, row, load_scale, beta, (vx, vy, vz))
        # M = [p]x J_l(h) = e [p]x + b (h p^T - (p.h) I) + c (p x h) h^T, with
        # J_l(h) = e I + b [h]x + c h h^T and e = 1 - c |h|^2.
        e = 1.0 - c * angle2
        ph = px * hx + py * hy + pz * hz
        wx, wy, wz = py * hz - pz * hy, pz * hx - px * hz, px * hy - py * hx
        m00 = b * (hx * px - ph) + c * wx * hx
        m01 = -e * pz + b * hx * py + c * wx * hy
        m02 = e * py + b * hx * pz + c * wx * hz
        m10 = e * pz + b * hy * px + c * wy * hx
        m11 = b * (hy * py - ph) + c * wy * hy
        m12 = -e * px + b * hy * pz + c * wy * hz
        m20 = -e * py + b * hz * px + c * wz * hx
        m21 = e * px + b * hz * py + c * wz * hy
        m22 = b * (hz * pz - ph) + c * wz * hz
        # dF/du = I + (segment / 2) A M, A = du/dm_b.
        j00 = 1.0 + half * (a00 * m00 + a01 * m10)
        j01 = half * (a00 * m01 + a01 * m11)
        j02 = half * (a00 * m02 + a01 * m12)
        j10 = half * (a10 * m00 + a11 * m10)
        j11 = 1.0 + half * (a10 * m01 + a11 * m11)
        j12 = half * (a10 * m02 + a11 * m12)
        j20 = half * a22 * m20
        j21 = half * a22 * m21
        j22 = 1.0 + half * a22 * m22
        # Cramer's rule: the 3x3 is within O(theta) of the identity.
        c00 = j11 * j22 - j12 * j21
        c01 = j12 * j20 - j10 * j22
        c02 = j10 * j21 - j11 * j20
        det = j00 * c00 + j01 * c01 + j02 * c02
        ux -= (fx * c00 + fy * (j02 * j21 - j01 * j22) + fz * (j01 * j12 - j02 * j11)) / det
        uy -= (fx * c01 + fy * (j00 * j22 - j02 * j20) + fz * (j02 * j10 - j00 * j12)) / det
        uz -= (fx * c02 + fy * (j01 * j20 - j00 * j21) + fz * (j00 * j11 - j01 * j10)) / det
    return np.nan, np.nan, np.nan


@njit(cache=True, nogil=True)
def _propagate_prb(joints, profile, load_scale, beta, y, work, nodes_p, nodes_r):
    """PRB chain from the tip back to the clamp. ``joints`` spherical joints sit at
    s = (j - 1/2) / joints, j = 1..joints, joined by full links with half links at both
    ends (joints + 1 links in all). Each joint lumps one rod segment of length
    1/joints: its stiffness is K(s_j) / segment, so theta_j = segment * u(m), the rod's
    constitutive law at the joint, with the moment in the joint's mid-rotation frame
    (`_joint_curvature`). The profile has 2 * joints + 1 rows at s = k / (2 joints):
    joints on odd rows, full-link centres on even rows."""
    segment = 1.0 / joints
    relative = work
    rotation = np.empty((3, 3))
    _store_node(y, joints + 1, nodes_p, nodes_r)
    _rigid_link(y, 0.5 * segment, profile, 2 * joints, 2 * joints - 1, load_scale, beta)
    for joint in range(joints - 1, -1, -1):
        _store_node(y, joint + 1, nodes_p, nodes_r)
        row = 2 * joint + 1
        mx = y[3] * y[15] + y[6] * y[16] + y[9] * y[17]
        my = y[4] * y[15] + y[7] * y[16] + y[10] * y[17]
        mz = y[5] * y[15] + y[8] * y[16] + y[11] * y[17]
        ux, uy, uz = _joint_curvature(profile, row, load_scale, beta, segment, mx, my, mz)
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
            _rigid_link(y, segment, profile, 2 * joint, 2 * joint, load_scale, beta)
        else:
            _rigid_link(y, 0.5 * segment, profile, 1, 0, load_scale, beta)
    _store_node(y, 0, nodes_p, nodes_r)


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def shoot(kind, resolution, x, reference, profile, tip, base, beta, load_scale, residual, y,
          work, nodes_p, nodes_r):
    """From the tip unknown ``x`` back to the clamp; write the clamp residual. ``y`` holds
    the clamp state afterwards (positions relative to the tip)."""
    _tip_state(x, reference, tip, load_scale, y, work)
    if kind == COSSERAT:
        _integrate_cosserat(resolution, profile, load_scale, beta, y, nodes_p, nodes_r)
    else:
        _propagate_prb(resolution, profile, load_scale, beta, y, work, nodes_p, nodes_r)
    _clamp_residual(y, base, residual, work)


@njit(cache=True, nogil=True)
def _orientation_seeds(y, tip, load_scale, tangents, dn, wrench):
    """Tangents at the tip for the three right perturbations of the tip orientation,
    R_L exp(e_d): dR = R_L hat(e_d), the follower wrench turning with it, p fixed."""
    seed = np.empty(9)
    for d in range(3):
        # Column b of R hat(e_d) is e_d x e_b expressed by R: +/- one column of R, or zero.
        a1 = (d + 1) % 3
        a2 = (d + 2) % 3
        for i in range(3):
            seed[3 * i + d] = 0.0
            seed[3 * i + a1] = y[3 + 3 * i + a2]
            seed[3 * i + a2] = -y[3 + 3 * i + a1]
        _tip_wrench(seed, tip, load_scale, np.bool_(False), wrench)
        tangents[0, d] = tangents[1, d] = tangents[2, d] = 0.0
        for k in range(9):
            tangents[3 + k, d] = seed[k]
        for k in range(3):
            dn[k, d] = wrench[k]
            tangents[12 + k, d] = wrench[3 + k]


@njit(cache=True, nogil=True)
def _clamp_tangent(m0x, m0y, m0z, dmx, dmy, dmz, base):
    """Derivative of `_clamp`'s rotation vector along a change (dmx, dmy, dmz) of the base moment."""
    dx = base[BASE_COMPLIANCE] * dmx
    dy = base[BASE_COMPLIANCE + 1] * dmy
    dz = base[BASE_COMPLIANCE + 2] * dmz
    play = base[BASE_PLAY]
    if play > 0.0:
        ex = base[BASE_COMPLIANCE] * m0x - base[BASE_PREVIOUS_ROTATION]
        ey = base[BASE_COMPLIANCE + 1] * m0y - base[BASE_PREVIOUS_ROTATION + 1]
        ez = base[BASE_COMPLIANCE + 2] * m0z - base[BASE_PREVIOUS_ROTATION + 2]
        distance = np.sqrt(ex * ex + ey * ey + ez * ez)
        if distance == 0.0:
            return 0.0, 0.0, 0.0
        excess = distance - play
        width = _PLAY_SMOOTHING * play
        root = np.sqrt(excess * excess + width * width)
        scale = 0.5 * (excess + root) / distance
        scale_rate = (0.5 * (1.0 + excess / root) * distance - 0.5 * (excess + root)) / (distance * distance)
        distance_rate = (ex * dx + ey * dy + ez * dz) / distance
        return (scale * dx + scale_rate * distance_rate * ex, scale * dy + scale_rate * distance_rate * ey,
                scale * dz + scale_rate * distance_rate * ez)
    return dx, dy, dz


@njit(cache=True, nogil=True)
def _residual_tangents(y, base, tangents, work, out):
    """Derivatives of `_clamp_residual` along each tangent (columns of ``tangents``) into the
    columns of ``out`` (3, D): the chain rule through the clamp (compliance, play) and
    the quaternion logarithm the residual uses."""
    cx, cy, cz = _clamp(y[15], y[16], y[17], base, work)
    m = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            m[i, j] = work[0, i] * y[3 + j] + work[1, i] * y[6 + j] + work[2, i] * y[9 + j]
    one_plus_trace = 1.0 + m[0, 0] + m[1, 1] + m[2, 2]
    if one_plus_trace <= 0.04:
        # `_clamp_residual` is constant out there.
        out[:, :] = 0.0
        return
    w = 0.5 * np.sqrt(one_plus_trace)
    vx = (m[2, 1] - m[1, 2]) / (4.0 * w)
    vy = (m[0, 2] - m[2, 0]) / (4.0 * w)
    vz = (m[1, 0] - m[0, 1]) / (4.0 * w)
    sine = np.sqrt(vx * vx + vy * vy + vz * vz)
    small = sine < 1e-6
    scale = 2.0 / w if small else 2.0 * np.arctan2(sine, w) / sine
    # The clamp's right Jacobian J_r(c): dR_clamp = R_clamp hat(J_r(c) dc).
    theta2 = cx * cx + cy * cy + cz * cz
    if theta2 < 1e-12:
        first, second = 0.5, 1.0 / 6.0
    else:
        theta = np.sqrt(theta2)
        first = (1.0 - np.cos(theta)) / theta2
        second = (theta - np.sin(theta)) / (theta2 * theta)
    dm = np.empty((3, 3))
    for d in range(tangents.shape[1]):
        dcx, dcy, dcz = _clamp_tangent(y[15], y[16], y[17], tangents[12, d], tangents[13, d], tangents[14, d], base)
        # phi = J_r(c) dc = dc - first c x dc + second c x (c x dc).
        ax, ay, az = cy * dcz - cz * dcy, cz * dcx - cx * dcz, cx * dcy - cy * dcx
        bx, by, bz = cy * az - cz * ay, cz * ax - cx * az, cx * ay - cy * ax
        fx = dcx - first * ax + second * bx
        fy = dcy - first * ay + second * by
        fz = dcz - first * az + second * bz
        # dM = -hat(phi) M + R_clamp^T dR(0).
        for i in range(3):
            for j in range(3):
                dm[i, j] = (work[0, i] * tangents[3 + j, d] + work[1, i] * tangents[6 + j, d]
                            + work[2, i] * tangents[9 + j, d])
        for j in range(3):
            hx = fy * m[2, j] - fz * m[1, j]
            hy = fz * m[0, j] - fx * m[2, j]
            hz = fx * m[1, j] - fy * m[0, j]
            dm[0, j] -= hx
            dm[1, j] -= hy
            dm[2, j] -= hz
        dw = (dm[0, 0] + dm[1, 1] + dm[2, 2]) / (8.0 * w)
        dvx = (dm[2, 1] - dm[1, 2]) / (4.0 * w) - vx * dw / w
        dvy = (dm[0, 2] - dm[2, 0]) / (4.0 * w) - vy * dw / w
        dvz = (dm[1, 0] - dm[0, 1]) / (4.0 * w) - vz * dw / w
        if small:
            # scale = 2 atan2(s, w) / s = (2 / w) (1 + O(s^2)).
            dscale = -2.0 * dw / (w * w)
        else:
            dsine = (vx * dvx + vy * dvy + vz * dvz) / sine
            dangle = 2.0 * (w * dsine - sine * dw) / (sine * sine + w * w)
            dscale = (dangle - scale * dsine) / sine
        out[0, d] = dscale * vx + scale * dvx
        out[1, d] = dscale * vy + scale * dvy
        out[2, d] = dscale * vz + scale * dvz


@njit(cache=True, nogil=True)
def _shoot_tangents(resolution, profile, tip, base, beta, load_scale, residual, derivatives, y, tangents, dn, work,
                    nodes_p, nodes_r):
    """A Cosserat `shoot` from the tip state in ``y`` (`_tip_state`) that carries tangents
    along: columns 0-2 of ``tangents``/``dn`` are seeded here with the tip orientation's
    right perturbations, R_L exp(e_d); columns from 3 on are the caller's (other tip loads).
    ``derivatives`` (3, D) gets dr along each tangent: its first three columns are the
    Jacobian of the residual in the unknown re-anchored at this shot's tip,
    d r / d x' for R_L exp(x'). ``tangents`` holds the clamp state's derivatives after."""
    _orientation_seeds(y, tip, load_scale, tangents, dn, np.empty(6))
    _integrate_cosserat_tangent(resolution, profile, load_scale, beta, y, tangents, dn, nodes_p, nodes_r)
    _clamp_residual(y, base, residual, work)
    _residual_tangents(y, base, tangents, work, derivatives)


@njit(cache=True, nogil=True)
def shoot_with_jacobian(resolution, x, reference, profile, tip, base, beta, load_scale, residual, jacobian, y,
                        work, nodes_p, nodes_r):
    """`shoot` for the Cosserat rod that also writes the exact Jacobian of the residual in
    the right perturbation of this shot's tip orientation (see `_shoot_tangents`)."""
    tangents = np.empty((15, 3))
    dn = np.empty((3, 3))
    _tip_state(x, reference, tip, load_scale, y, work)
    _shoot_tangents(resolution, profile, tip, base, beta, load_scale, residual, jacobian, y, tangents, dn, work,
                    nodes_p, nodes_r)


@njit(cache=True, nogil=True)
def _norm3(v):
    return np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


@njit(cache=True, nogil=True)
def solve3(a, b, out):
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


@njit(cache=True, nogil=True)
def _finite_difference_jacobian(kind, resolution, x, reference, r, profile, tip, base, beta, load_scale,
                                jacobian, y, work, nodes_p, nodes_r):
    trial = x.copy()
    r_trial = np.empty(3)
    for j in range(3):
        # sqrt(machine epsilon): the residual is smooth and evaluated to rounding error.
        h = 1.5e-8 * max(1.0, abs(x[j]))
        trial[j] = x[j] + h
        shoot(kind, resolution, trial, reference, profile, tip, base, beta, load_scale, r_trial, y,
              work, nodes_p, nodes_r)
        for i in range(3):
            jacobian[i, j] = (r_trial[i] - r[i]) / h
        trial[j] = x[j]


@njit(cache=True, nogil=True)
def _reanchor(reference, x, work, scratch):
    """reference <- reference exp(x): later unknowns are small rotations about it."""
    _so3_exp(x[0], x[1], x[2], work)
    for i in range(3):
        for j in range(3):
            scratch[i, j] = reference[i, 0] * work[0, j] + reference[i, 1] * work[1, j] + reference[i, 2] * work[2, j]
    for i in range(3):
        for j in range(3):
            reference[i, j] = scratch[i, j]


@njit(cache=True, nogil=True)
def turned(rotation, rotation_vector):
    """rotation exp(rotation_vector), as a new matrix: a rotation turned in its own frame."""
    out = rotation.copy()
    _reanchor(out, rotation_vector, np.empty((3, 3)), np.empty((3, 3)))
    return out


@njit(cache=True, nogil=True)
def solve(kind, resolution, reference, jacobian, have_jacobian, profile, tip, base, beta, load_scale,
          tolerance, max_iterations, length, wrench_scale, nodes_p, nodes_r, base_wrench, clamp_rotation, info):
    """Damped quasi-Newton on the shooting residual; the unknown is a small rotation of
    the tip about ``reference``, which is re-anchored after every accepted step (in
    place), and ``jacobian`` is updated in place.

    Starts from ``jacobian`` when ``have_jacobian`` (a warm start: the previous solve's
    matrix is nearly right for a nearby load), else builds it: exactly, from one shot
    carrying the tangents, for the Cosserat rod (`shoot_with_jacobian`); by forward
    differences for the PRB chain. Steps are Newton steps with backtracking; after an
    accepted step the matrix gets a Broyden rank-one update, and it is rebuilt whenever
    a step fails to reduce the residual. (Exact Newton, a tangent shot at every step,
    takes 3 steps instead of 6 on a 4 % load change but is slower: a shot carrying three
    tangents costs about four plain shots. Broyden's steps each gain ~30x there, exact
    matrix at the start or not: one secant a step leaves the other directions' error. The
    matrix needs no change of coordinates when the reference turns: shots perturb the
    tip about the iterate itself.) On return ``info`` holds [status,
    iterations, residual norm, jacobian evaluations]; if converged, the nodes hold the
    shape, ``base_wrench`` and ``clamp_rotation`` the clamp's (`_finish_nodes`).
    """
    y = np.empty(18)
    work = np.empty((3, 3))
    scratch = np.empty((3, 3))
    x = np.zeros(3)
    r = np.empty(3)
    r_new = np.empty(3)
    step = np.empty(3)
    x_new = np.empty(3)
    clamp_state = np.empty(18)
    # Every shot stores its nodes, and the last shot before convergence is the accepted
    # step's (a Jacobian is only built before a step), so its shape is in place at the end.
    shoot(kind, resolution, x, reference, profile, tip, base, beta, load_scale, r, y, work,
          nodes_p, nodes_r)
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
            if kind == COSSERAT:
                shoot_with_jacobian(resolution, x, reference, profile, tip, base, beta, load_scale, r_new, jacobian,
                                    y, work, nodes_p, nodes_r)
            else:
                _finite_difference_jacobian(kind, resolution, x, reference, r, profile, tip, base, beta,
                                            load_scale, jacobian, y, work, nodes_p, nodes_r)
            jacobian_evaluations += 1
            have_jacobian = True
            fresh = True
        iterations += 1
        accepted = False
        new_norm = norm
        if solve3(jacobian, r, step):
            alpha = 1.0
            for _ in range(10):
                for k in range(3):
                    x_new[k] = -alpha * step[k]
                shoot(kind, resolution, x_new, reference, profile, tip, base, beta, load_scale, r_new, y,
                      work, nodes_p, nodes_r)
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
    if status == CONVERGED:
        _finish_nodes(clamp_state, base, length, wrench_scale, nodes_p, nodes_r, base_wrench, clamp_rotation)
    info[0] = status
    info[1] = iterations
    info[2] = norm
    info[3] = jacobian_evaluations


@njit(cache=True, nogil=True)
def solve_from(kind, resolution, seed_rotation, seed_jacobian, have_jacobian, jet_forces, profile, tip, base, beta,
               load_scale, tolerance, max_iterations, length, wrench_scale, nodes_p, nodes_r, base_wrench,
               clamp_rotation, reference, jacobian, info):
    """`solve` of ``tip`` under the jets ``jet_forces`` (N), started at the tip rotation
    ``seed_rotation`` and, when ``have_jacobian``, from the matrix ``seed_jacobian``. The
    seeds are only read (a continuation passes ``reference`` and ``jacobian`` themselves);
    the solve turns ``reference`` and updates ``jacobian`` as `solve` does. The one entry
    for single solves: the copies cost a few tenths of a microsecond each in Python, a
    warm solve about fifteen, and a second compiled entry about 3 MB when loaded."""
    for i in range(3):
        for j in range(3):
            reference[i, j] = seed_rotation[i, j]
            if have_jacobian:
                jacobian[i, j] = seed_jacobian[i, j]
    loads = tip.copy()
    for k in range(3):
        loads[TIP_JETS + k] = jet_forces[k]
    solve(kind, resolution, reference, jacobian, have_jacobian, profile, loads, base, beta, load_scale, tolerance,
          max_iterations, length, wrench_scale, nodes_p, nodes_r, base_wrench, clamp_rotation, info)


@njit(cache=True, nogil=True)
def solve_batch(kind, resolution, references, jacobians, seeded, profiles, tips, bases, carry_clamp, beta, tolerance,
                max_iterations, length, wrench_scale, nodes_p, nodes_r, base_wrench, clamp_rotation, info):
    """Warm `solve` of k problems that differ in their tip loads (``tips``, one row
    each) and possibly in their profiles and clamps (``profiles``, ``bases``: one row
    shared by all, or one row each), in order and in one call: each problem's output
    arrays are the k-th slices of ``references`` ... ``info``. A problem not ``seeded``
    starts from the one before it: its tip frame as that solution reports it and its
    updated matrix, as a sequence of single warm solves would. With ``carry_clamp`` each
    problem after the first starts its clamp where the one before left it (the path
    state `ShootingModel.prepare` takes from ``previous``). The first problem must be
    seeded. Stops at the first problem that does not converge and returns how many did."""
    last = nodes_p.shape[1] - 1
    base = np.empty(BASE_SIZE)
    for k in range(tips.shape[0]):
        if not seeded[k]:
            for i in range(3):
                for j in range(3):
                    references[k, i, j] = nodes_r[k - 1, last, i, j]
                    jacobians[k, i, j] = jacobians[k - 1, i, j]
        row_base = bases[0] if bases.shape[0] == 1 else bases[k]
        for i in range(BASE_SIZE):
            base[i] = row_base[i]
        if carry_clamp and k > 0:
            for i in range(3):
                base[BASE_PREVIOUS_ROTATION + i] = clamp_rotation[k - 1, i]
        profile = profiles[0] if profiles.shape[0] == 1 else profiles[k]
        solve(kind, resolution, references[k], jacobians[k], np.bool_(True), profile, tips[k], base, beta, 1.0,
              tolerance, max_iterations, length, wrench_scale, nodes_p[k], nodes_r[k], base_wrench[k],
              clamp_rotation[k], info[k])
        if info[k, 0] != CONVERGED:
            return k
    return tips.shape[0]


@njit(cache=True, nogil=True)
def sensor_rotation(base_mounting, rotation, tip_mounting):
    """base_mounting^T rotation tip_mounting, as a new matrix: what two orientation sensors
    mounted so on the base and the tip read."""
    return base_mounting.T @ (rotation @ tip_mounting)


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def tip_wrench_sensitivity(kind, resolution, reference, profile, tip, base, beta, components, steps, length,
                           jacobian, columns):
    """Sensitivity of the tip pose to tip follower wrench components (w_d: 0-2 force, 3-5
    moment, tip frame) at the converged tip orientation ``reference``, all columns in one
    call and no solve.

    By the implicit function theorem the tip rotation moves by dx = -J^-1 dr/dw, where
    J = dr/dx is the shooting Jacobian and dr/dw the residual's change at a fixed tip
    orientation; the tip, relative to the clamp, moves by -(dP/dx dx + dP/dw), P the
    clamp position of a shot started with the tip at the origin. The Cosserat rod gets
    every partial exactly from one shot carrying 3 + k tangents (`_shoot_tangents`);
    the PRB chain from 3 + k + 1 single shots by forward differences (``steps``: the
    nondimensional step per component), which are deterministic to rounding, unlike
    differences of solves. Writes ``jacobian`` (J at ``reference``: the matrix for
    solves near this one) and ``columns`` (6, k): body twists (v in units of
    ``length``, omega) per unit of each component. Returns False when J is singular or
    a shot is not finite."""
    count = components.shape[0]
    y = np.empty(18)
    work = np.empty((3, 3))
    x = np.zeros(3)
    residual = np.empty(3)
    # The shots store their nodes (cheaper than a test per step); nobody reads them here.
    nodes = resolution + 1 if kind == COSSERAT else resolution + 2
    nodes_p = np.empty((nodes, 3))
    nodes_r = np.empty((nodes, 3, 3))
    # Partials: residual (rows 0-2) and clamp position (rows 3-5) per unit of each
    # tip-orientation direction (columns 0-2) and each component (columns 3 on).
    partials = np.empty((6, 3 + count))
    if kind == COSSERAT:
        tangents = np.zeros((15, 3 + count))
        dn = np.zeros((3, 3 + count))
        _tip_state(x, reference, tip, 1.0, y, work)
        for column in range(count):
            component = components[column]
            # A follower load turns with the tip: its base-frame direction is a column of R_L.
            for i in range(3):
                if component < 3:
                    dn[i, 3 + column] = y[3 + 3 * i + component]
                else:
                    tangents[12 + i, 3 + column] = y[3 + 3 * i + component - 3]
        _shoot_tangents(resolution, profile, tip, base, beta, 1.0, residual, partials[:3], y, tangents, dn, work,
                        nodes_p, nodes_r)
        partials[3:] = tangents[:3]
    else:
        r = np.empty(3)
        shoot(kind, resolution, x, reference, profile, tip, base, beta, 1.0, residual, y, work, nodes_p, nodes_r)
        p0x, p0y, p0z = y[0], y[1], y[2]
        perturbed_tip = tip.copy()
        for column in range(3 + count):
            if column < 3:
                # sqrt(machine epsilon): the residual is smooth and evaluated to rounding error.
                step = 1.5e-8
                x[column] = step
                shoot(kind, resolution, x, reference, profile, tip, base, beta, 1.0, r, y, work, nodes_p, nodes_r)
                x[column] = 0.0
            else:
                index = TIP_FOLLOWER_FORCE + components[column - 3]
                step = steps[column - 3]
                perturbed_tip[index] = tip[index] + step
                shoot(kind, resolution, x, reference, profile, perturbed_tip, base, beta, 1.0, r, y, work,
                      nodes_p, nodes_r)
                perturbed_tip[index] = tip[index]
            for i in range(3):
                partials[i, column] = (r[i] - residual[i]) / step
            partials[3, column] = (y[0] - p0x) / step
            partials[4, column] = (y[1] - p0y) / step
            partials[5, column] = (y[2] - p0z) / step
    jacobian[:, :] = partials[:3, :3]
    rotation_rate = np.empty(3)
    moved = np.empty(3)
    for column in range(count):
        for i in range(3):
            residual[i] = -partials[i, 3 + column]
        if not solve3(jacobian, residual, rotation_rate):
            return False
        for i in range(3):
            moved[i] = -(partials[3 + i, 3 + column] + partials[3 + i, 0] * rotation_rate[0]
                         + partials[3 + i, 1] * rotation_rate[1] + partials[3 + i, 2] * rotation_rate[2])
        for k in range(3):
            columns[k, column] = length * (reference[0, k] * moved[0] + reference[1, k] * moved[1]
                                           + reference[2, k] * moved[2])
            columns[3 + k, column] = rotation_rate[k]
        for k in range(6):
            if not np.isfinite(columns[k, column]):
                return False
    return True


@njit(cache=True, nogil=True)
def tip_wrench_sensitivity_batch(kind, resolution, references, profiles, tips, bases, beta, components, steps, length,
                                 jacobians, columns):
    """`tip_wrench_sensitivity` at k solutions of problems that differ in their tip loads
    (``tips``, one row each) and possibly in their profiles and clamps (``profiles``,
    ``bases``: one row shared by all, or one row each), in one call; each solution's
    inputs and outputs are the k-th slices. Stops at the first that fails and returns
    how many succeeded."""
    for k in range(tips.shape[0]):
        profile = profiles[0] if profiles.shape[0] == 1 else profiles[k]
        base = bases[0] if bases.shape[0] == 1 else bases[k]
        if not tip_wrench_sensitivity(kind, resolution, references[k], profile, tips[k], base, beta, components, steps,
                                      length, jacobians[k], columns[k]):
            return k
    return tips.shape[0]


PACKED = 0
BAD_PROFILE = 1
BAD_TIP_OR_CLAMP = 2


@njit(cache=True, nogil=True)
def pack(bending_x, bending_y, torsion, intrinsic_curvature, distributed_force, distributed_moment,
         strain_compliance, follower_force, follower_moment, dead_force, dead_moment, dead_arm, ring_actuation, jet_gains, jets,
         base_compliance, base_play, previous_base_rotation, reference_stiffness, length, force_scale,
         moment_scale, profile, tip, base):
    """Fill ``profile``, ``tip`` and ``base`` (layouts above) from a rod problem's SI
    arrays, nondimensional, with the same operations as numpy on the whole arrays would
    make (the same numbers to the bit): one call instead of two dozen numpy calls on
    arrays of a few dozen numbers, which cost more than a warm solve. Returns PACKED, or
    BAD_PROFILE (a non-finite profile entry, a non-positive stiffness or a negative strain
    compliance) or
    BAD_TIP_OR_CLAMP (a non-finite tip load or clamp parameter)."""
    status = PACKED
    for row in range(profile.shape[0]):
        profile[row, STIFFNESS] = bending_x[row] / reference_stiffness
        profile[row, STIFFNESS + 1] = bending_y[row] / reference_stiffness
        profile[row, STIFFNESS + 2] = torsion[row] / reference_stiffness
        for k in range(3):
            profile[row, INTRINSIC_CURVATURE + k] = intrinsic_curvature[row, k] * length
            profile[row, DISTRIBUTED_FORCE + k] = distributed_force[row, k] * length / force_scale
            profile[row, DISTRIBUTED_MOMENT + k] = distributed_moment[row, k] * length / moment_scale
            profile[row, STRAIN_COMPLIANCE + k] = strain_compliance[row, k] * force_scale
            if not profile[row, STRAIN_COMPLIANCE + k] >= 0.0 or not np.isfinite(profile[row, STRAIN_COMPLIANCE + k]):
                status = BAD_PROFILE
        for column in range(COMPLIANCE):
            if not np.isfinite(profile[row, column]):
                status = BAD_PROFILE
        for k in range(3):
            if not profile[row, STIFFNESS + k] > 0.0:
                status = BAD_PROFILE
            profile[row, COMPLIANCE + k] = 1.0 / profile[row, STIFFNESS + k]
    for k in range(3):
        tip[TIP_FOLLOWER_FORCE + k] = follower_force[k] / force_scale
        tip[TIP_FOLLOWER_MOMENT + k] = follower_moment[k] / moment_scale
        tip[TIP_DEAD_FORCE + k] = dead_force[k] / force_scale
        tip[TIP_DEAD_MOMENT + k] = dead_moment[k] / moment_scale
        tip[TIP_JETS + k] = jets[k]
        for j in range(3):
            tip[TIP_DEAD_ARM + 3 * k + j] = dead_arm[k, j] / moment_scale
            tip[TIP_ACTUATION + 3 * k + j] = ring_actuation[k, j] * jet_gains[j] / force_scale
        base[BASE_COMPLIANCE + k] = base_compliance[k] * moment_scale
        base[BASE_PREVIOUS_ROTATION + k] = previous_base_rotation[k]
    base[BASE_PLAY] = base_play
    if status == PACKED:
        for k in range(TIP_SIZE):
            if not np.isfinite(tip[k]):
                status = BAD_TIP_OR_CLAMP
        for k in range(BASE_SIZE):
            if not np.isfinite(base[k]):
                status = BAD_TIP_OR_CLAMP
    return status
