"""The online evidence's moment equivalents, against step-by-step least squares."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from hydrojet_bench.analysis.diagnosis.evidence import OnlineEvidence

# Hundredths from -50 to 50: a sensitivity is rad per N m, tens to thousands, or exactly
# zero; never 1e-160, whose products underflow before any solver sees them.
MATRICES = arrays(float, (5, 3, 3), elements=st.integers(-5000, 5000).map(lambda hundredths: hundredths / 100.0))
ROTATIONS = arrays(float, (5, 3), elements=st.floats(-0.1, 0.1))


def evidence(sensitivity: np.ndarray) -> OnlineEvidence:
    return OnlineEvidence(np.zeros((len(sensitivity), 3)), sensitivity, 0.0)


@settings(max_examples=60, deadline=None)
@given(MATRICES, ROTATIONS, st.integers(0, 4))
def test_equivalent_moments_are_each_step_s_least_squares(sensitivity, rotation, singular):
    # One step's matrix made rank one, as a moment axis that does not turn the sensor
    # would: the minimum-norm answer there, as `lstsq` gives it.
    sensitivity[singular] = np.outer(sensitivity[singular, :, 0], sensitivity[singular, 0])
    expected = np.stack([np.linalg.lstsq(matrix, omega, rcond=None)[0]
                         for matrix, omega in zip(sensitivity, rotation)])
    scale = 1.0 + np.abs(expected).max()
    np.testing.assert_allclose(evidence(sensitivity).equivalent_moment_nm(rotation), expected,
                               atol=1e-9 * scale)


def test_an_invertible_sensitivity_turns_the_equivalent_moment_back_into_the_rotation():
    rng = np.random.default_rng(3)
    sensitivity = rng.normal(size=(20, 3, 3)) * 40.0 + np.eye(3) * 100.0
    rotation = rng.normal(size=(20, 3)) * 0.01
    moments = evidence(sensitivity).equivalent_moment_nm(rotation)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", sensitivity, moments), rotation, atol=1e-14)
