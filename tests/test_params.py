"""Parameters validate themselves and name the field at fault."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hydrojet_bench.params import (CapsuleParameters, DisturbanceWrench, JetLayout, ModelParameters,
                                   RodParameters, actuation_matrix, get_parameter, with_parameters)


@pytest.mark.parametrize("field, value, message", [
    ("length_m", -0.07, "rod.length_m must be > 0"),
    ("radius_m", 0.0, "rod.radius_m must be > 0"),
    ("youngs_modulus_base_pa", float("nan"), "rod.youngs_modulus_base_pa must be finite"),
    ("youngs_modulus_tip_pa", float("inf"), "rod.youngs_modulus_tip_pa must be finite"),
    ("poisson_ratio", 0.7, "rod.poisson_ratio must be in"),
    ("density_kg_m3", "heavy", "rod.density_kg_m3 must be a number"),
])
def test_bad_rod_values_name_their_field(field, value, message):
    with pytest.raises(ValueError, match=message.replace(".", r"\.")):
        RodParameters(**{field: value})


def test_bad_vectors_name_their_field_and_component():
    with pytest.raises(ValueError, match=r"disturbance\.force_n\[y\] must be finite"):
        DisturbanceWrench(force_n=(0.0, float("nan"), 0.0))
    with pytest.raises(ValueError, match=r"model\.gravity_in_base_m_s2 must have 3 components"):
        ModelParameters(gravity_in_base_m_s2=(0.0, 9.81))
    with pytest.raises(ValueError, match=r"capsule\.mass_kg must be >= 0"):
        CapsuleParameters(mass_kg=-1.0)
    with pytest.raises(ValueError, match="effect.parameter"):
        ModelParameters(effect_values={"weight_scale": 1.0})


def test_actuation_matrix_is_the_papers_eq_5_at_ring_angle_zero():
    s60, c60 = math.sin(math.pi / 3), math.cos(math.pi / 3)
    np.testing.assert_allclose(JetLayout().actuation_matrix(),
                               [[s60, 0, -s60], [c60, -1, c60], [0, 0, 0]], atol=1e-15)
    # Rotating the ring rotates every column about z.
    turned = actuation_matrix(0.25)
    rotation = np.array([[math.cos(0.25), -math.sin(0.25), 0], [math.sin(0.25), math.cos(0.25), 0], [0, 0, 1]])
    np.testing.assert_allclose(turned, rotation @ actuation_matrix(0.0), atol=1e-15)


def test_flat_parameter_names_read_and_write_the_right_fields():
    params = ModelParameters()
    changed = with_parameters(params, {"E0": 4e5, "L": 0.08, "wd_my": 1e-3, "gravity.weight_scale": 1.5})
    assert changed.rod.youngs_modulus_base_pa == 4e5
    assert changed.rod.length_m == 0.08
    assert changed.disturbance.moment_nm == (0.0, 1e-3, 0.0)
    assert get_parameter(changed, "gravity.weight_scale", 1.0) == 1.5
    assert get_parameter(params, "gravity.weight_scale", 1.0) == 1.0
    assert params.rod.length_m == 0.070  # the original is untouched
    with pytest.raises(KeyError, match="unknown parameter 'E1'"):
        with_parameters(params, {"E1": 1.0})
    with pytest.raises(ValueError, match=r"rod\.length_m must be > 0"):
        with_parameters(params, {"L": -1.0})


def test_linear_modulus_profile():
    rod = RodParameters(youngs_modulus_base_pa=3e5, youngs_modulus_tip_pa=2e5)
    np.testing.assert_allclose(rod.youngs_modulus_pa(np.array([0.0, 0.035, 0.07])), [3e5, 2.5e5, 2e5])
    assert rod.shear_modulus_pa(0.0) == pytest.approx(3e5 / (2 * 1.49))
