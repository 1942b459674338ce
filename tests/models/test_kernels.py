"""The forward-mode tangent of the Cosserat shot against central differences of the shot
itself, on problems that switch on every term the variational equations carry: cubic
(softening and stiffening) elasticity, intrinsic curvature, distributed force and
moment, dead tip loads off the tip point, a compliant clamp with and without play."""

from __future__ import annotations

import numpy as np
import pytest

from hydrojet_bench.models import CosseratModel, kernels
from hydrojet_bench.params import ModelParameters

ACROSS = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
RESOLUTION = 20


def _problem(seed: int, beta: float, compliance: float, play: float):
    """A packed problem with random extra terms written straight into the kernel arrays."""
    rng = np.random.default_rng(seed)
    model = CosseratModel(resolution=RESOLUTION)
    prepared = model.prepare(rng.uniform(0.0, 0.1, 3), ACROSS)
    profile = prepared.profile.copy()
    rows = profile.shape[0]
    profile[:, kernels.INTRINSIC_CURVATURE:kernels.INTRINSIC_CURVATURE + 3] = rng.normal(0.0, 0.3, 3)
    profile[:, kernels.DISTRIBUTED_FORCE:kernels.DISTRIBUTED_FORCE + 3] += rng.normal(0.0, 0.2, (rows, 3))
    profile[:, kernels.DISTRIBUTED_MOMENT:kernels.DISTRIBUTED_MOMENT + 3] = rng.normal(0.0, 0.2, (rows, 3))
    tip = prepared.tip.copy()
    tip[kernels.TIP_FOLLOWER_MOMENT:kernels.TIP_FOLLOWER_MOMENT + 3] = rng.normal(0.0, 0.3, 3)
    tip[kernels.TIP_DEAD_MOMENT:kernels.TIP_DEAD_MOMENT + 3] = rng.normal(0.0, 0.3, 3)
    tip[kernels.TIP_DEAD_ARM:kernels.TIP_DEAD_ARM + 9] = rng.normal(0.0, 0.1, 9)
    base = np.zeros(kernels.BASE_SIZE)
    base[kernels.BASE_COMPLIANCE:kernels.BASE_COMPLIANCE + 3] = compliance * np.array([1.0, 0.7, 0.2])
    base[kernels.BASE_PLAY] = play
    base[kernels.BASE_PREVIOUS_ROTATION:kernels.BASE_PREVIOUS_ROTATION + 3] = rng.normal(0.0, 0.02, 3)
    reference = kernels.turned(np.eye(3), rng.normal(0.0, 0.4, 3))
    return profile, tip, base, beta, reference


def _shot(x, reference, profile, tip, base, beta):
    residual, y = np.empty(3), np.empty(18)
    nodes_p, nodes_r = np.empty((RESOLUTION + 1, 3)), np.empty((RESOLUTION + 1, 3, 3))
    kernels.shoot(kernels.COSSERAT, RESOLUTION, x, reference, profile, tip, base, beta, 1.0, residual, y,
                  np.empty((3, 3)), nodes_p, nodes_r, False)
    return residual


@pytest.mark.parametrize(("seed", "beta", "compliance", "play"), [
    (1, 0.0, 0.0, 0.0), (2, 0.3, 0.0, 0.0), (3, -0.01, 0.0, 0.0), (4, 0.0, 0.2, 0.0), (5, 0.2, 0.3, 0.01),
    (6, 0.0, 0.5, 0.05)])
def test_the_tangent_jacobian_is_the_derivative_of_the_discrete_shot(seed, beta, compliance, play):
    profile, tip, base, beta, reference = _problem(seed, beta, compliance, play)
    x = np.random.default_rng(seed + 100).normal(0.0, 0.05, 3)
    residual, jacobian = np.empty(3), np.empty((3, 3))
    nodes_p, nodes_r = np.empty((RESOLUTION + 1, 3)), np.empty((RESOLUTION + 1, 3, 3))
    kernels.shoot_with_jacobian(RESOLUTION, x, reference, profile, tip, base, beta, 1.0, residual, jacobian,
                                np.empty(18), np.empty((3, 3)), nodes_p, nodes_r, False)
    assert np.all(np.isfinite(residual))
    np.testing.assert_allclose(residual, _shot(x, reference, profile, tip, base, beta), rtol=1e-12, atol=1e-14)
    # The Jacobian is in the unknown re-anchored at the shot's tip: R_L exp(x').
    anchored = kernels.turned(reference, x)
    step = 1e-6
    differences = np.empty((3, 3))
    for column in range(3):
        offset = np.zeros(3)
        offset[column] = step
        differences[:, column] = (_shot(offset, anchored, profile, tip, base, beta)
                                  - _shot(-offset, anchored, profile, tip, base, beta)) / (2 * step)
    assert np.all(np.isfinite(jacobian))
    np.testing.assert_allclose(jacobian, differences, atol=1e-7 * np.abs(differences).max())


@pytest.mark.parametrize("seed", [11, 12, 13])
def test_the_plain_rod_kernel_is_the_general_kernel_without_its_terms(seed):
    """beta None compiles the shot without the section-law Newton solve and the
    distributed moment: on a problem with neither it must give the general kernel's
    residual, tangents and shape, to rounding."""
    profile, tip, base, _, reference = _problem(seed, 0.0, 0.3, 0.0)
    profile[:, kernels.DISTRIBUTED_MOMENT:kernels.DISTRIBUTED_MOMENT + 3] = 0.0
    x = np.random.default_rng(seed).normal(0.0, 0.05, 3)
    shots = {}
    for beta in (0.0, None):
        residual, jacobian, y = np.empty(3), np.empty((3, 3)), np.empty(18)
        nodes_p, nodes_r = np.empty((RESOLUTION + 1, 3)), np.empty((RESOLUTION + 1, 3, 3))
        kernels.shoot_with_jacobian(RESOLUTION, x, reference, profile, tip, base, beta, 1.0, residual, jacobian,
                                    y, np.empty((3, 3)), nodes_p, nodes_r, True)
        shots[beta] = (residual, jacobian, y, nodes_p, nodes_r)
    for general, plain in zip(shots[0.0], shots[None]):
        np.testing.assert_allclose(plain, general, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(_shot(x, reference, profile, tip, base, None), shots[0.0][0], rtol=1e-12, atol=1e-14)
    # The PRB chain's joints use the same section law.
    chain = {}
    for beta in (0.0, None):
        residual, y = np.empty(3), np.empty(18)
        nodes_p, nodes_r = np.empty((RESOLUTION + 2, 3)), np.empty((RESOLUTION + 2, 3, 3))
        kernels.shoot(kernels.PRB, RESOLUTION, x, reference, profile, tip, base, beta, 1.0, residual, y,
                      np.empty((3, 3)), nodes_p, nodes_r, True)
        chain[beta] = (residual, y, nodes_p, nodes_r)
    for general, plain in zip(chain[0.0], chain[None]):
        np.testing.assert_allclose(plain, general, rtol=1e-12, atol=1e-14)


def test_a_prepared_problem_takes_the_plain_kernel_only_without_cubic_law_and_distributed_moment():
    model = CosseratModel(resolution=RESOLUTION)
    jets = np.array([0.05, 0.0, 0.0])
    assert model.prepare(jets, ACROSS).beta is None
    problem = model.build_problem(jets, ACROSS)
    problem.distributed_moment_in_body_nm_m[:, 2] = 1e-4
    assert model._pack(problem).beta == 0.0
    problem = model.build_problem(jets, ACROSS)
    problem.cubic_stiffening_m2 = 1e-6
    assert model._pack(problem).beta == pytest.approx(1e-6 / ACROSS.rod.length_m ** 2)
