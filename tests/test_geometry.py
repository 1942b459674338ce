"""Geometry: property tests of the SO(3)/SE(3) helpers and the error measures."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hydrojet_bench import geometry as g

finite = st.floats(-1.0, 1.0, allow_nan=False)
vectors = st.tuples(finite, finite, finite).map(np.array)
# Rotation vectors with angles in [0, pi - 1e-6]: log is single-valued there. The axis
# is drawn away from zero: one near 1e-160, whose squares are subnormal, normalised
# to a length 1.00003 (hypothesis found it).
axes = vectors.filter(lambda v: np.linalg.norm(v) > 1e-3)
rotation_vectors = st.tuples(axes, st.floats(0.0, math.pi - 1e-6)).map(
    lambda pair: pair[0] / np.linalg.norm(pair[0]) * pair[1])
SETTINGS = settings(max_examples=200, deadline=None)


@SETTINGS
@given(rotation_vectors)
def test_so3_exp_and_log_are_inverse_and_agree_with_quaternions(w):
    rotation = g.so3_exp(w)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    np.testing.assert_allclose(g.so3_log(rotation), w, atol=1e-7)
    q = g.quat_from_rotvec(w)
    np.testing.assert_allclose(g.matrix_from_quat(q), rotation, atol=1e-12)
    np.testing.assert_allclose(g.quat_from_matrix(rotation), g.quat_normalize(q), atol=1e-9)


@SETTINGS
@given(vectors, vectors)
def test_hat_is_the_cross_product_and_vee_inverts_it(a, b):
    np.testing.assert_allclose(g.hat(a) @ b, np.cross(a, b), atol=1e-15)
    np.testing.assert_allclose(g.vee(g.hat(a)), a)


@SETTINGS
@given(vectors, rotation_vectors)
def test_se3_exp_log_round_trip_and_adjoint(v, w):
    twist = np.concatenate([v, w])
    transform = g.se3_exp(twist)
    np.testing.assert_allclose(g.se3_log(transform), twist, atol=1e-6)
    np.testing.assert_allclose(g.se3_inverse(transform) @ transform, np.eye(4), atol=1e-12)
    other = np.concatenate([w, v])
    # Ad_g xi = (g xi^ g^-1)^vee.
    np.testing.assert_allclose(g.adjoint(transform) @ other,
                               g.twist_vee(transform @ g.twist_hat(other) @ g.se3_inverse(transform)), atol=1e-12)


@SETTINGS
@given(rotation_vectors, rotation_vectors, vectors)
def test_quaternion_product_composes_rotations(a, b, v):
    qa, qb = g.quat_from_rotvec(a), g.quat_from_rotvec(b)
    np.testing.assert_allclose(g.matrix_from_quat(g.quat_multiply(qa, qb)),
                               g.so3_exp(a) @ g.so3_exp(b), atol=1e-12)
    np.testing.assert_allclose(g.quat_rotate(qa, v), g.so3_exp(a) @ v, atol=1e-12)
    np.testing.assert_allclose(g.quat_multiply(qa, g.quat_conjugate(qa)), [1, 0, 0, 0], atol=1e-12)


@SETTINGS
@given(rotation_vectors, rotation_vectors)
def test_error_measures_agree_with_the_relative_angle(a, b):
    qa, qb = g.quat_from_rotvec(a), g.quat_from_rotvec(b)
    relative = g.so3_exp(a).T @ g.so3_exp(b)
    angle = math.degrees(np.linalg.norm(g.so3_log(relative)))
    assert g.rotation_angle_deg(qa, qb) == pytest.approx(angle, abs=1e-5)
    assert g.rotation_angle_deg(qa, -qb) == pytest.approx(angle, abs=1e-5)  # q and -q agree
    metric = g.quaternion_inner_product_metric(qa, qb)
    assert metric == pytest.approx(1.0 - math.cos(math.radians(angle) / 2.0), abs=1e-9)
    np.testing.assert_allclose(np.linalg.norm(g.body_rotation_error(g.so3_exp(a), g.so3_exp(b))),
                               math.radians(angle), atol=1e-7)


def test_known_values_and_stacks():
    assert g.rotation_angle_deg([1, 0, 0, 0], [0, 1, 0, 0]) == pytest.approx(180.0)
    assert g.quaternion_inner_product_metric([1, 0, 0, 0], [0, 0, 0, 1]) == pytest.approx(1.0)
    quarter_turn_z = g.so3_exp([0, 0, math.pi / 2])
    np.testing.assert_allclose(quarter_turn_z @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    stack = np.array([[0.1, 0, 0], [0, 0.2, 0], [0, 0, 3.1]])
    np.testing.assert_allclose(g.so3_log(g.so3_exp(stack)), stack, atol=1e-9)
    # Near a half turn the log stays accurate (the trace formula would not).
    np.testing.assert_allclose(g.so3_log(g.so3_exp([0, math.pi - 1e-9, 0])), [0, math.pi - 1e-9, 0], atol=1e-8)


def test_quaternions_of_stacks_match_one_by_one_and_every_largest_component():
    # Half turns about x, y and z make x, y or z the largest component (Shepperd's three
    # diagonal cases); the identity and a small turn take the trace case.
    vectors = np.array([[math.pi, 0, 0], [0, math.pi, 0], [0, 0, math.pi], [0, 0, 0], [0.1, -0.2, 0.3],
                        [2.0, 1.0, -0.5]])
    rotations = g.so3_exp(vectors).reshape(2, 3, 3, 3)
    stacked = g.quat_from_matrix(rotations)
    assert stacked.shape == (2, 3, 4)
    for rotation, quaternion in zip(rotations.reshape(-1, 3, 3), stacked.reshape(-1, 4)):
        np.testing.assert_allclose(quaternion, g.quat_from_matrix(rotation), atol=0)
        np.testing.assert_allclose(g.matrix_from_quat(quaternion), rotation, atol=1e-12)
        assert quaternion[0] >= 0.0 and np.linalg.norm(quaternion) == pytest.approx(1.0)
