"""The forward-mode tangent of the Cosserat shot against central differences of the shot
itself, on problems that switch on every term the variational equations carry: cubic
(softening and stiffening) elasticity, intrinsic curvature, distributed force and
moment, a section that shears and stretches, dead tip loads off the tip point, a
compliant clamp with and without play."""

from __future__ import annotations

import numpy as np
import pytest

from hydrojet_bench.models import CosseratModel, kernels
from hydrojet_bench.params import ModelParameters

ACROSS = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
RESOLUTION = 20


def _problem(seed: int, beta: float, compliance: float, play: float, strain: float = 0.0):
    """A packed problem with random extra terms written straight into the kernel arrays;
    ``strain`` the largest (nondimensional) strain compliance, 0: an inextensible rod."""
    rng = np.random.default_rng(seed)
    model = CosseratModel(resolution=RESOLUTION)
    prepared = model.prepare(rng.uniform(0.0, 0.1, 3), ACROSS)
    profile = prepared.profile.copy()
    rows = profile.shape[0]
    profile[:, kernels.INTRINSIC_CURVATURE:kernels.INTRINSIC_CURVATURE + 3] = rng.normal(0.0, 0.3, 3)
    profile[:, kernels.DISTRIBUTED_FORCE:kernels.DISTRIBUTED_FORCE + 3] += rng.normal(0.0, 0.2, (rows, 3))
    profile[:, kernels.DISTRIBUTED_MOMENT:kernels.DISTRIBUTED_MOMENT + 3] = rng.normal(0.0, 0.2, (rows, 3))
    profile[:, kernels.STRAIN_COMPLIANCE:kernels.STRAIN_COMPLIANCE + 3] = rng.uniform(0.0, strain, (rows, 3))
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
                  np.empty((3, 3)), nodes_p, nodes_r)
    return residual


@pytest.mark.parametrize(("seed", "beta", "compliance", "play", "strain"), [
    (1, 0.0, 0.0, 0.0, 0.0), (2, 0.3, 0.0, 0.0, 0.0), (3, -0.01, 0.0, 0.0, 0.0), (4, 0.0, 0.2, 0.0, 0.0),
    (5, 0.2, 0.3, 0.01, 0.0), (6, 0.0, 0.5, 0.05, 0.0), (7, 0.0, 0.0, 0.0, 0.2), (8, 0.2, 0.3, 0.01, 0.1)])
def test_the_tangent_jacobian_is_the_derivative_of_the_discrete_shot(seed, beta, compliance, play, strain):
    profile, tip, base, beta, reference = _problem(seed, beta, compliance, play, strain)
    x = np.random.default_rng(seed + 100).normal(0.0, 0.05, 3)
    residual, jacobian = np.empty(3), np.empty((3, 3))
    nodes_p, nodes_r = np.empty((RESOLUTION + 1, 3)), np.empty((RESOLUTION + 1, 3, 3))
    kernels.shoot_with_jacobian(RESOLUTION, x, reference, profile, tip, base, beta, 1.0, residual, jacobian,
                                np.empty(18), np.empty((3, 3)), nodes_p, nodes_r)
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
                                    y, np.empty((3, 3)), nodes_p, nodes_r)
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
                      np.empty((3, 3)), nodes_p, nodes_r)
        chain[beta] = (residual, y, nodes_p, nodes_r)
    for general, plain in zip(chain[0.0], chain[None]):
        np.testing.assert_allclose(plain, general, rtol=1e-12, atol=1e-14)


def test_a_prepared_problem_takes_the_plain_kernel_only_without_cubic_law_distributed_moment_and_strain():
    model = CosseratModel(resolution=RESOLUTION)
    jets = np.array([0.05, 0.0, 0.0])
    assert model.prepare(jets, ACROSS).beta is None
    problem = model.build_problem(jets, ACROSS)
    problem.distributed_moment_in_body_nm_m[:, 2] = 1e-4
    assert model._pack(problem).beta == 0.0
    problem = model.build_problem(jets, ACROSS)
    problem.cubic_stiffening_m2 = 1e-6
    assert model._pack(problem).beta == pytest.approx(1e-6 / ACROSS.rod.length_m ** 2)
    problem = model.build_problem(jets, ACROSS)
    problem.strain_compliance_in_body_1_n[:, 2] = 0.05
    assert model._pack(problem).beta == 0.0


def _packed_by_numpy(problem, length, force_scale, moment_scale, reference_stiffness):
    """The packing written as whole-array numpy expressions: the oracle for `kernels.pack`."""
    profile = np.empty((len(problem.arc_length_m), kernels.PROFILE_COLUMNS))
    profile[:, kernels.STIFFNESS] = problem.bending_stiffness_x_nm2 / reference_stiffness
    profile[:, kernels.STIFFNESS + 1] = problem.bending_stiffness_y_nm2 / reference_stiffness
    profile[:, kernels.STIFFNESS + 2] = problem.torsional_stiffness_nm2 / reference_stiffness
    profile[:, kernels.INTRINSIC_CURVATURE:kernels.INTRINSIC_CURVATURE + 3] = (
        problem.intrinsic_curvature_in_body_1_m * length)
    profile[:, kernels.DISTRIBUTED_FORCE:kernels.DISTRIBUTED_FORCE + 3] = (
        problem.distributed_force_in_base_n_m * length / force_scale)
    profile[:, kernels.DISTRIBUTED_MOMENT:kernels.DISTRIBUTED_MOMENT + 3] = (
        problem.distributed_moment_in_body_nm_m * length / moment_scale)
    profile[:, kernels.COMPLIANCE:kernels.COMPLIANCE + 3] = 1.0 / profile[:, kernels.STIFFNESS:kernels.STIFFNESS + 3]
    profile[:, kernels.STRAIN_COMPLIANCE:kernels.STRAIN_COMPLIANCE + 3] = (
        problem.strain_compliance_in_body_1_n * force_scale)
    tip = np.concatenate([problem.tip_follower_force_in_tip_n / force_scale,
                          problem.tip_follower_moment_in_tip_nm / moment_scale,
                          problem.tip_dead_force_in_base_n / force_scale,
                          problem.tip_dead_moment_in_base_nm / moment_scale,
                          (problem.tip_dead_force_arm_m_n / moment_scale).ravel(),
                          (problem.actuation_matrix() / force_scale).ravel(), problem.jet_forces_n])
    base = np.concatenate([problem.base_compliance_rad_per_nm * moment_scale, [problem.base_play_rad],
                           problem.previous_base_rotation_vector_rad])
    return profile, tip, base


@pytest.mark.parametrize("seed", range(6))
def test_the_packing_kernel_makes_the_numbers_numpy_makes_for_every_library_effect(seed):
    from hydrojet_bench.effects import LIBRARY
    from hydrojet_bench.params import with_parameters

    rng = np.random.default_rng(seed)
    model = CosseratModel(effects=tuple(LIBRARY), resolution=RESOLUTION)
    values = {}
    for effect in model.effects:
        for parameter in effect.parameters:
            values[f"{effect.name}.{parameter.name}"] = rng.uniform(parameter.lower, parameter.upper) / 4.0
    params = with_parameters(ModelParameters(gravity_in_base_m_s2=tuple(rng.normal(0.0, 5.0, 3))), values)
    problem = model.build_problem(rng.uniform(0.0, 0.12, 3), params)
    problem.previous_base_rotation_vector_rad = rng.normal(0.0, 0.01, 3)
    problem.distributed_moment_in_body_nm_m = rng.normal(0.0, 1e-4, (len(problem.arc_length_m), 3))
    packed = model._pack(problem)
    expected = _packed_by_numpy(problem, packed.length_m, packed.force_scale_n, packed.moment_scale_nm,
                                params.rod.youngs_modulus_base_pa * params.rod.second_moment_m4)
    for name, got, want in zip(("profile", "tip", "base"), (packed.profile, packed.tip, packed.base), expected):
        np.testing.assert_array_equal(got, want, err_msg=name)


def test_a_problem_field_of_the_wrong_shape_is_refused_by_name_and_a_scalar_is_broadcast():
    model = CosseratModel(resolution=RESOLUTION)
    problem = model.build_problem([0.05, 0.0, 0.0], ACROSS)
    problem.torsional_stiffness_nm2 = float(problem.torsional_stiffness_nm2[0])  # an effect setting one value
    packed = model._pack(problem)
    assert np.all(packed.profile[:, kernels.STIFFNESS + 2] == packed.profile[0, kernels.STIFFNESS + 2])
    problem.bending_stiffness_x_nm2 = problem.bending_stiffness_x_nm2[:-1]
    with pytest.raises(ValueError, match=r"RodProblem.bending_stiffness_x_nm2 with shape \(\d+,\), expected"):
        model._pack(problem)


@pytest.mark.parametrize("field, value, message", [
    ("bending_stiffness_y_nm2", -1.0, "non-positive stiffness"),
    ("intrinsic_curvature_in_body_1_m", np.nan, "non-finite profile"),
    ("tip_dead_force_in_base_n", np.inf, "non-finite tip load"),
    ("base_play_rad", np.nan, "clamp parameter"),
    ("strain_compliance_in_body_1_n", -1e-3, "negative strain compliance"),
    ("strain_compliance_in_body_1_n", np.inf, "non-finite profile"),
])
def test_a_non_finite_or_non_positive_packing_is_refused(field, value, message):
    model = CosseratModel(resolution=RESOLUTION)
    problem = model.build_problem([0.05, 0.0, 0.0], ACROSS)
    current = getattr(problem, field)
    setattr(problem, field, value if np.isscalar(current) else np.full_like(current, value))
    with pytest.raises(ValueError, match=message):
        model._pack(problem)
