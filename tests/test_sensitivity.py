"""Sensitivity matrix (eqs. 2-3): step-size agreement, analytic columns, the w_d path."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from hydrojet_bench.effects.setup import BaseSensorMounting
from hydrojet_bench.models import CosseratModel, PrbModel, Solution
from hydrojet_bench.params import DISTURBANCE_NAMES, ModelParameters, with_parameters
from hydrojet_bench.sensitivity import disturbance_columns, disturbance_columns_batch, parameter_steps, sensitivity

PARAMS = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
JETS = [0.05, 0.0, 0.02]
NAMES = ("E0", "EL", "L", "gravity.weight_scale") + DISTURBANCE_NAMES


@pytest.mark.parametrize("model", [CosseratModel(), PrbModel()], ids=["cosserat", "prb"])
def test_columns_agree_across_step_sizes(model):
    # Forward differences: truncation ~ h, solve noise ~ 1 / h. Central differences at
    # 1e-4 are the yardstick (truncation ~ h^2). Around the default step (3e-5..3e-4)
    # every column agrees to 3e-4 of its size (measured: under 1e-4 at 1e-4); at 1e-6 the
    # noise is visible (measured 5e-3 on the axial-force column) but still bounded.
    reference = sensitivity(model, JETS, PARAMS, NAMES, central=True).matrix
    scale = np.abs(reference).max(axis=0)

    def worst(step: float) -> float:
        matrix = sensitivity(model, JETS, PARAMS, NAMES, relative_step=step).matrix
        return float((np.abs(matrix - reference).max(axis=0) / scale).max())

    for step in (3e-5, 1e-4, 3e-4):
        assert worst(step) < 3e-4, step
    assert worst(1e-6) < 2e-2


def test_columns_match_a_large_step_secant():
    # Independent of the fast path: perturb through with_parameters and a cold solve.
    model = CosseratModel()
    S = sensitivity(model, JETS, PARAMS, ("wd_mx", "EL"))
    nominal = model.solve(JETS, PARAMS)
    for column, (name, step) in enumerate((("wd_mx", 1e-7), ("EL", 1.0))):
        value = {"wd_mx": 0.0, "EL": PARAMS.rod.youngs_modulus_tip_pa}[name]
        moved = CosseratModel().solve(JETS, with_parameters(PARAMS, {name: value + step}))
        delta_position = nominal.tip_rotation_in_base.T @ (moved.tip_position_in_base_m - nominal.tip_position_in_base_m)
        np.testing.assert_allclose(delta_position / step, S.matrix[:3, column], rtol=1e-3,
                                   atol=1e-4 * np.abs(S.matrix[:3, column]).max())


def test_a_tip_moment_about_x_turns_the_tip_about_x_first():
    # With no load, a small tip moment about the tip's x bends the rod about x: the
    # rotation column is (C, 0, 0) with C = integral of ds / EI(s) (a compliance).
    params = ModelParameters(gravity_in_base_m_s2=(0.0, 0.0, 0.0))
    S = sensitivity(CosseratModel(effects=()), [0.0, 0.0, 0.0], params, ("wd_mx",))
    rod = params.rod
    s = np.linspace(0.0, rod.length_m, 2001)
    compliance = np.trapezoid(1.0 / (rod.youngs_modulus_pa(s) * rod.second_moment_m4), s)
    np.testing.assert_allclose(S.rotation_rows[:, 0], [compliance, 0.0, 0.0], rtol=1e-5,
                               atol=1e-9 * compliance)


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=["cosserat", "prb"])
def test_the_seed_is_the_nominal_shape_with_a_better_jacobian(model_type):
    # A base sensor off the rod axis: its offset is part of what the solution says, and the
    # seed once came back without it (tip sensor positions then read from the clamp).
    model = model_type(effects=("gravity", BaseSensorMounting((0.014, 0.0, 0.0))))
    nominal = model.solve(JETS, PARAMS)
    seed = sensitivity(model, JETS, PARAMS, ("wd_mx",), nominal=nominal).nominal
    for field in dataclasses.fields(Solution):
        if field.name != "jacobian":
            np.testing.assert_array_equal(getattr(seed, field.name), getattr(nominal, field.name), err_msg=field.name)
    np.testing.assert_array_equal(seed.tip_sensor_position_in_base_sensor_m(np.zeros(3)),
                                  nominal.tip_sensor_position_in_base_sensor_m(np.zeros(3)))


def test_unknown_parameter_is_reported():
    with pytest.raises(KeyError, match="no enabled effect"):
        sensitivity(CosseratModel(), JETS, PARAMS, ("jet_gain.gain_1",))
    with pytest.raises(ValueError, match="at least one"):
        sensitivity(CosseratModel(), JETS, PARAMS, ())


@pytest.mark.parametrize("effects", [("gravity",), ("gravity", "pressure_stiffening")],
                         ids=["shared-packing", "packing-per-pose"])
@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=["cosserat", "prb"])
def test_batched_disturbance_columns_are_each_poses_own_bit_for_bit(model_type, effects):
    model = model_type(effects)
    params = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
    jets = np.random.default_rng(3).uniform(0.0, 0.12, (5, 3))
    nominals = [model.solve(row, params) for row in jets]
    components = np.array([0, 4, 5], dtype=np.int64)
    steps = parameter_steps(model, params, [DISTURBANCE_NAMES[k] for k in components])
    columns, seeds = disturbance_columns_batch(model, jets, params, nominals, components, steps)
    for row, nominal in enumerate(nominals):
        expected, seed = disturbance_columns(model, model.prepare(jets[row], params), nominal, components, steps)
        np.testing.assert_array_equal(columns[row], expected)
        np.testing.assert_array_equal(seeds[row].jacobian, seed.jacobian)
        assert seeds[row].positions_in_base_m is nominal.positions_in_base_m
    # Each pose under its own gravity (a recording's steps): still each pose's own columns.
    row_params = [dataclasses.replace(params, gravity_in_base_m_s2=(-9.81 * np.cos(a), 9.81 * np.sin(a), 0.0))
                  for a in np.linspace(0.0, 1.0, len(jets))]
    nominals = [model.solve(row, row_params[k]) for k, row in enumerate(jets)]
    columns, seeds = disturbance_columns_batch(model, jets, row_params, nominals, components, steps)
    for row, nominal in enumerate(nominals):
        expected, seed = disturbance_columns(model, model.prepare(jets[row], row_params[row]), nominal, components,
                                             steps)
        np.testing.assert_array_equal(columns[row], expected)
        np.testing.assert_array_equal(seeds[row].jacobian, seed.jacobian)
