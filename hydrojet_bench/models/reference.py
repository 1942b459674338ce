"""An independent Cosserat solution by collocation (`scipy.integrate.solve_bvp`).

Shares nothing with the shooting kernels but the `RodProblem` it reads: its own
right-hand side (vectorised numpy, SI units), its own boundary conditions, a global
collocation method with adaptive mesh instead of shooting with fixed-step RK4. The
validation tests use it as the high-resolution truth and `hydrojet-bench perf` as the
baseline the kernels are timed against.

It covers what those need: any stiffness, curvature, strain compliance and load
profiles, tip follower and dead loads, on a rigid clamp with a linear constitutive law. Clamp compliance and
strain stiffening are refused rather than ignored.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.integrate import solve_bvp

from ..errors import ConvergenceError
from ..effects.problem import RodProblem


def solve_reference(problem: RodProblem, *, tolerance: float = 1e-8, max_nodes: int = 100_000,
                    initial_guess: tuple[np.ndarray, np.ndarray] | None = None, ramp_stages: int = 8):
    """Solve the problem by collocation. Returns ``(mesh_m, states)`` with states of shape
    (18, nodes) in SI units and the base frame: p (m), R (9, row-major), n (N), m (N m).

    initial_guess: ``(mesh_m, states)`` of a nearby solution, from an earlier call (a warm
    start). Without one, the loads are ramped up from the straight rod in
    ``ramp_stages`` stages, the intermediate ones to a looser tolerance.
    """
    if problem.base_compliance_rad_per_nm.any() or problem.cubic_stiffening_m2 != 0.0:
        raise NotImplementedError("the reference solver covers a rigid clamp and a linear constitutive law")
    length = float(problem.arc_length_m[-1])
    # Collocation tolerances are relative to each state's size: work in units where
    # positions, forces and moments are all of order one, as the kernels do.
    stiffness = float(problem.bending_stiffness_x_nm2[0])
    scales = np.concatenate([np.full(3, length), np.ones(9), np.full(3, stiffness / length**2),
                             np.full(3, stiffness / length)])
    if initial_guess is None:
        mesh = np.linspace(0.0, 1.0, 41)
        guess = np.zeros((18, mesh.size))
        guess[2] = mesh
        guess[3:12] = np.eye(3).ravel()[:, None]
        for stage in range(1, ramp_stages):
            mesh, guess = _solve_once(_scaled_loads(problem, stage / ramp_stages), scales, 1e-5, max_nodes,
                                      mesh, guess)
    else:
        mesh = initial_guess[0] / length
        guess = initial_guess[1] / scales[:, None]
    mesh, states = _solve_once(problem, scales, tolerance, max_nodes, mesh, guess)
    return mesh * length, states * scales[:, None]


def _scaled_loads(problem: RodProblem, fraction: float) -> RodProblem:
    return replace(
        problem,
        jet_forces_n=problem.jet_forces_n * fraction,
        intrinsic_curvature_in_body_1_m=problem.intrinsic_curvature_in_body_1_m * fraction,
        distributed_force_in_base_n_m=problem.distributed_force_in_base_n_m * fraction,
        distributed_moment_in_body_nm_m=problem.distributed_moment_in_body_nm_m * fraction,
        tip_follower_force_in_tip_n=problem.tip_follower_force_in_tip_n * fraction,
        tip_follower_moment_in_tip_nm=problem.tip_follower_moment_in_tip_nm * fraction,
        tip_dead_force_in_base_n=problem.tip_dead_force_in_base_n * fraction,
        tip_dead_moment_in_base_nm=problem.tip_dead_moment_in_base_nm * fraction,
        tip_dead_force_arm_m_n=problem.tip_dead_force_arm_m_n * fraction,
    )


def _solve_once(problem: RodProblem, scales: np.ndarray, tolerance: float, max_nodes: int,
                mesh: np.ndarray, guess: np.ndarray):
    """One collocation solve in scaled units (s / L, p / L, n / F0, m / M0)."""
    length = float(problem.arc_length_m[-1])
    force_scale, moment_scale = scales[12], scales[15]
    s_samples = problem.arc_length_m / length
    columns = np.column_stack([
        problem.bending_stiffness_x_nm2 / (moment_scale * length),
        problem.bending_stiffness_y_nm2 / (moment_scale * length),
        problem.torsional_stiffness_nm2 / (moment_scale * length),
        problem.intrinsic_curvature_in_body_1_m * length,
        problem.distributed_force_in_base_n_m * length / force_scale,
        problem.distributed_moment_in_body_nm_m * length / moment_scale,
        problem.strain_compliance_in_body_1_n * force_scale,
    ])
    follower_force = (problem.actuation_matrix() @ problem.jet_forces_n + problem.tip_follower_force_in_tip_n) / force_scale
    follower_moment = problem.tip_follower_moment_in_tip_nm / moment_scale
    dead_force = problem.tip_dead_force_in_base_n / force_scale
    dead_moment = problem.tip_dead_moment_in_base_nm / moment_scale
    arm = problem.tip_dead_force_arm_m_n / moment_scale

    def rhs(s: np.ndarray, y: np.ndarray) -> np.ndarray:
        values = np.stack([np.interp(s, s_samples, columns[:, k]) for k in range(columns.shape[1])], axis=1)
        rotation = y[3:12].T.reshape(-1, 3, 3)
        moment_body = np.einsum("kji,kj->ki", rotation, y[15:18].T)
        curvature = values[:, 3:6] + moment_body / values[:, 0:3]
        d_rotation = np.cross(rotation, curvature[:, None, :])  # row i of R hat(u) is R_i x u
        # p' = R v with the section's strain v = e3 + C R^T n.
        strain = values[:, 12:15] * np.einsum("kji,kj->ki", rotation, y[12:15].T)
        strain[:, 2] += 1.0
        tangent = np.einsum("kij,kj->ki", rotation, strain)
        d_moment = -np.cross(tangent, y[12:15].T) - np.einsum("kij,kj->ki", rotation, values[:, 9:12])
        return np.vstack([tangent.T, d_rotation.reshape(-1, 9).T, -values[:, 6:9].T, d_moment.T])

    def boundary(y0: np.ndarray, y1: np.ndarray) -> np.ndarray:
        rotation_tip = y1[3:12].reshape(3, 3)
        force = rotation_tip @ follower_force + dead_force
        rt = rotation_tip @ arm
        moment = (rotation_tip @ follower_moment + dead_moment
                  + np.array([rt[1, 2] - rt[2, 1], rt[2, 0] - rt[0, 2], rt[0, 1] - rt[1, 0]]))
        return np.concatenate([y0[0:3], y0[3:12] - np.eye(3).ravel(), y1[12:15] - force, y1[15:18] - moment])

    # Trial iterates may overflow before the damped Newton backs off; that is expected.
    with np.errstate(all="ignore"):
        result = solve_bvp(rhs, boundary, mesh, guess, tol=tolerance, max_nodes=max_nodes)
    if not result.success:
        raise ConvergenceError(f"solve_bvp failed: {result.message}")
    return result.x, result.y
