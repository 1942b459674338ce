"""drivers.rotations agrees with the bench's geometry module (one convention, two packages)."""

from __future__ import annotations

import numpy as np
import pytest

from drivers import rotations
from hydrojet_bench import geometry

rng = np.random.default_rng(7)
QUATERNIONS = [np.array([1.0, 0.0, 0.0, 0.0]), np.array([-0.2, 0.9, 0.1, -0.3]), *rng.normal(size=(20, 4))]
ROTATION_VECTORS = [np.zeros(3), np.array([1e-8, 0.0, -2e-8]), np.array([np.pi, 0.0, 0.0]), *rng.normal(size=(20, 3))]


@pytest.mark.parametrize("name", ["quat_normalize", "quat_conjugate", "matrix_from_quat"])
def test_one_quaternion_functions_match_geometry(name: str) -> None:
    for q in QUATERNIONS:
        np.testing.assert_allclose(getattr(rotations, name)(q), getattr(geometry, name)(q), atol=1e-15)


def test_quat_multiply_matches_geometry() -> None:
    for a, b in zip(QUATERNIONS, QUATERNIONS[1:]):
        np.testing.assert_allclose(rotations.quat_multiply(a, b), geometry.quat_multiply(a, b), atol=1e-15)


def test_quat_from_rotvec_matches_geometry() -> None:
    for v in ROTATION_VECTORS:
        np.testing.assert_allclose(rotations.quat_from_rotvec(v), geometry.quat_from_rotvec(v), atol=1e-15)


def test_quat_from_matrix_inverts_matrix_from_quat_in_every_shepperd_case() -> None:
    # Rotations by pi about each axis make each of the four Shepperd cases the largest.
    cases = [np.array([1.0, 0, 0, 0]), np.array([0, 1.0, 0, 0]), np.array([0, 0, 1.0, 0]), np.array([0, 0, 0, 1.0])]
    for q in [*cases, *QUATERNIONS]:
        m = rotations.matrix_from_quat(q)
        np.testing.assert_allclose(rotations.quat_from_matrix(m), rotations.quat_normalize(q), atol=1e-12)
        np.testing.assert_allclose(rotations.quat_from_matrix(m), geometry.quat_from_matrix(m), atol=1e-15)
