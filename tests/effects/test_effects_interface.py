"""The effect interface: loading users' effects from files, and every kind of hook the
analysis library needs (loads, tip wrench, constitutive law, actuation map, base
boundary with memory, measurement), each working in both models."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from hydrojet_bench.cli import main
from hydrojet_bench.effects import LIBRARY, load_effect, load_effects
from hydrojet_bench.errors import UserError
from hydrojet_bench.geometry import so3_exp
from hydrojet_bench.models import CosseratModel, PrbModel
from hydrojet_bench.params import ModelParameters

USER_EFFECT = textwrap.dedent('''
    import numpy as np
    from hydrojet_bench.effects import EffectParameter

    class TorsionalPreload:
        """A twisting moment from the water lines, per unit length."""
        name = "torsional_preload"
        explanation = "the water lines twist the rod"
        parameters = (EffectParameter("moment_per_length_nm_m", 0.0, -0.1, 0.1, "N m/m", "twist"),)
        uses_actuation = False

        def apply(self, problem, values):
            problem.distributed_moment_in_body_nm_m[:, 2] += values["moment_per_length_nm_m"]
    ''')

MODELS = [CosseratModel, PrbModel]
IDS = ["cosserat", "prb"]
PARAMS = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))


def write(tmp_path, text):
    path = tmp_path / "my_effect.py"
    path.write_text(text)
    return path


def test_library_names_load_and_explain_themselves():
    gravity = load_effect("gravity")
    assert gravity.name == "gravity" and "gravity" in LIBRARY
    assert len(gravity.explanation) > 100
    assert [p.name for p in gravity.parameters] == ["weight_scale"]


@pytest.mark.parametrize("model_type", MODELS, ids=IDS)
def test_a_users_effect_from_a_file_changes_the_shape(tmp_path, model_type):
    effect = load_effect(f"{write(tmp_path, USER_EFFECT)}:TorsionalPreload")
    assert effect.name == "torsional_preload"
    model = model_type(effects=("gravity", effect))
    plain = model_type().solve([0.05, 0.0, 0.0], PARAMS)
    twisted_params = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0),
                                     effect_values={"torsional_preload.moment_per_length_nm_m": 0.002})
    same = model.solve([0.05, 0.0, 0.0], PARAMS)  # default 0: no change
    twisted = model.solve([0.05, 0.0, 0.0], twisted_params)
    np.testing.assert_allclose(same.tip_position_in_base_m, plain.tip_position_in_base_m, atol=1e-12)
    assert np.linalg.norm(twisted.tip_position_in_base_m - plain.tip_position_in_base_m) > 1e-3


@pytest.mark.parametrize("spec_suffix, text, message", [
    ("Missing", USER_EFFECT, "defines no class 'Missing'"),
    ("Broken", "raise RuntimeError('boom')\n", "importing .* failed: RuntimeError: boom"),
    ("Bare", "class Bare:\n    pass\n", "lacks name, explanation, parameters, uses_actuation, apply"),
    ("TorsionalPreload", "import sys\nsys.exit(3)\n", r"importing .* failed: it called sys.exit\(3\)"),
    ("TorsionalPreload", USER_EFFECT.replace("def apply(self, problem, values)", "def apply(self, problem)"),
     r"my_effect.py:TorsionalPreload: apply must take \(problem, values\), not \(problem\)"),
    ("TorsionalPreload", USER_EFFECT.replace("parameters = (EffectParameter", "parameters = 5 or (EffectParameter"),
     "my_effect.py:TorsionalPreload: parameters must be a tuple of EffectParameter, got 5"),
    ("TorsionalPreload", USER_EFFECT.replace('name = "torsional_preload"', 'name = "gravity"'),
     "my_effect.py:TorsionalPreload: name 'gravity' is a library effect's"),
    ("TorsionalPreload", USER_EFFECT.replace('+= values["moment_per_length_nm_m"]', '+= 1 / 0'),
     r"my_effect.py:TorsionalPreload: apply failed at jet forces \(0, 0, 0\) N with values "
     r"\{'moment_per_length_nm_m': [^}]*\}: ZeroDivisionError"),
    ("TorsionalPreload", USER_EFFECT.replace('+= values["moment_per_length_nm_m"]', '+= np.nan'),
     r"my_effect.py:TorsionalPreload: apply left a non-finite value \(NaN or inf\) in "
     "problem.distributed_moment_in_body_nm_m"),
    ("TorsionalPreload", USER_EFFECT.replace('problem.distributed_moment_in_body_nm_m[:, 2] +=',
                                             'problem.distributed_moment_nm_m ='),
     r"my_effect.py:TorsionalPreload: apply uses problem.distributed_moment_nm_m, which RodProblem does not have"),
    ("TorsionalPreload", USER_EFFECT.replace('values["moment_per_length_nm_m"]', 'values.get("moment_nm_m", 0.0)'),
     "my_effect.py:TorsionalPreload: parameter 'moment_per_length_nm_m' changes nothing apply sets"),
    ("TorsionalPreload", USER_EFFECT.replace('name = "torsional_preload"', 'name = "gravity"'),
     "my_effect.py:TorsionalPreload: name 'gravity' is a library effect's"),
    ("TorsionalPreload", USER_EFFECT.replace("0.0, -0.1, 0.1,", "0.0, 0.0, 0.0,"),
     "my_effect.py:TorsionalPreload: parameter 'moment_per_length_nm_m' has no range to fit"),
    # diagnose fits the setup hypotheses beside the candidates, by name.
    ("TorsionalPreload", USER_EFFECT.replace('name = "torsional_preload"', 'name = "tracker_tilt"'),
     "my_effect.py:TorsionalPreload: name 'tracker_tilt' is a library effect's or a setup hypothesis's"),
    ("TorsionalPreload", USER_EFFECT.replace('parameters = (EffectParameter("moment_per_length_nm_m", 0.0, -0.1, 0.1, '
                                             '"N m/m", "twist"),)', 'parameters = ()').replace(
        'problem.distributed_moment_in_body_nm_m[:, 2] += values["moment_per_length_nm_m"]', 'pass'),
     "my_effect.py:TorsionalPreload: it has no parameters and apply changes nothing in the problem"),
    # Unflagged, a model would reuse one packing for every jet force: stale jets.
    ("TorsionalPreload", USER_EFFECT.replace('+= values["moment_per_length_nm_m"]',
                                             '+= values["moment_per_length_nm_m"] * (1 + problem.jet_forces_n[0])'),
     "my_effect.py:TorsionalPreload: apply changes the problem with the jet forces but uses_actuation is False"),
])
def test_bad_effect_files_give_clear_errors(tmp_path, spec_suffix, text, message):
    with pytest.raises(UserError, match=message):
        load_effect(f"{write(tmp_path, text)}:{spec_suffix}")


@pytest.mark.parametrize("edit, message", [
    (('name = "torsional_preload"', 'name = "jet_gain"'), "name 'jet_gain' is a library effect's"),
    (('+= values["moment_per_length_nm_m"]', '+= np.nan'), "apply left a non-finite value (NaN or inf)"),
    (('+= values["moment_per_length_nm_m"]', '+= 1 / 0'), ": ZeroDivisionError: division by zero"),
    (('problem.distributed_moment_in_body_nm_m[:, 2] +=', 'problem.tip_moment ='),
     "apply uses problem.tip_moment, which RodProblem does not have"),
])
def test_a_bad_effect_file_is_one_line_and_exit_2_from_any_command(tmp_path, capsys, edit, message):
    effect = f"{write(tmp_path, USER_EFFECT.replace(*edit))}:TorsionalPreload"
    for argv in (["calibrate", str(tmp_path / "unread.csv"), "--effect", effect, "-o", str(tmp_path / "p.toml")],
                 ["simulate", "-o", str(tmp_path / "x.csv"), "--hidden", effect],
                 ["diagnose", str(tmp_path / "unread.csv"), "--candidate", effect]):
        assert main(argv) == 2, argv
        error = capsys.readouterr().err
        assert error.count("\n") == 1 and "Traceback" not in error, error
        assert f"effect {effect}" in error and message in error, error


def test_an_effect_that_fails_only_on_some_forces_is_named_when_it_fails(tmp_path):
    text = USER_EFFECT.replace('uses_actuation = False', 'uses_actuation = True').replace(
        '+= values["moment_per_length_nm_m"]',
        '+= values["moment_per_length_nm_m"] + (0.0 if problem.jet_forces_n[0] < 0.07 else np.inf)')
    # Beyond the forces it is tried at when loaded (0.05 N per jet).
    model = CosseratModel(effects=(load_effect(f"{write(tmp_path, text)}:TorsionalPreload"),))
    model.solve([0.0, 0.0, 0.0], PARAMS)
    with pytest.raises(UserError, match="my_effect.py:TorsionalPreload: apply left a non-finite value"):
        model.solve([0.08, 0.0, 0.0], PARAMS)


def test_two_files_whose_effects_share_a_name_are_refused_wherever_effects_are_listed(tmp_path, capsys):
    first = write(tmp_path, USER_EFFECT)
    second = tmp_path / "other.py"
    second.write_text(USER_EFFECT.replace("[:, 2]", "[:, 0]"))
    specs = [f"{first}:TorsionalPreload", f"{second}:TorsionalPreload"]
    with pytest.raises(UserError, match="are both named 'torsional_preload'; give each class its own name"):
        load_effects(specs)
    assert [effect.name for effect in load_effects([specs[0], specs[0], "jet_gain"])] == ["torsional_preload",
                                                                                         "jet_gain"]
    unread = str(tmp_path / "unread.csv")
    for argv in (["calibrate", unread, "--effect", specs[0], "--effect", specs[1], "-o", str(tmp_path / "p.toml")],
                 ["diagnose", unread, "--candidate", specs[0], "--candidate", specs[1]],
                 ["diagnose", unread, "--effect", specs[0], "--candidate", specs[1]]):
        assert main(argv) == 2, argv
        assert "are both named 'torsional_preload'" in capsys.readouterr().err


def test_a_problem_an_effect_leaves_unsolvable_is_a_user_error_naming_the_effect(tmp_path, capsys):
    text = USER_EFFECT.replace('problem.distributed_moment_in_body_nm_m[:, 2] += values["moment_per_length_nm_m"]',
                               'problem.distributed_moment_in_body_nm_m = np.full((7, 3), values["moment_per_length_nm_m"])')
    spec = f"{write(tmp_path, text)}:TorsionalPreload"
    with pytest.raises(UserError, match=r"RodProblem.distributed_moment_in_body_nm_m with shape \(7, 3\), expected "
                                        r".* \(effects: gravity, .*my_effect.py:TorsionalPreload\)"):
        CosseratModel(effects=("gravity", load_effect(spec))).solve([0.05, 0.0, 0.0], PARAMS)
    assert main(["simulate", "-o", str(tmp_path / "x.csv"), "--hidden", f"{spec}=0.01"]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "my_effect.py:TorsionalPreload" in error, error


def test_unknown_names_and_missing_files_are_user_errors(tmp_path):
    with pytest.raises(UserError, match="unknown effect 'gravty'; known effects: gravity"):
        load_effect("gravty")
    with pytest.raises(UserError, match="does not exist"):
        load_effect(f"{tmp_path}/nope.py:Thing")


class Hook:
    """A test effect whose `apply` is a given function of (problem, values)."""

    explanation = "test hook"
    parameters = ()

    def __init__(self, name, function, uses_actuation=False):
        self.name, self.function, self.uses_actuation = name, function, uses_actuation

    def apply(self, problem, values):
        self.function(problem)


def solve(model_type, hook, jets=(0.05, 0.0, 0.0), **kwargs):
    return model_type(effects=("gravity", hook)).solve(jets, PARAMS, **kwargs)


@pytest.mark.parametrize("model_type", MODELS, ids=IDS)
def test_constitutive_hooks_stiffen_the_rod(model_type):
    base = model_type().solve([0.05, 0.0, 0.0], PARAMS).bend_angle_deg

    def stiffer_near_tip(problem):  # a stiffness profile along s
        factor = 1.0 + problem.arc_length_m / problem.arc_length_m[-1]
        problem.bending_stiffness_x_nm2 = problem.bending_stiffness_x_nm2 * factor
        problem.bending_stiffness_y_nm2 = problem.bending_stiffness_y_nm2 * factor

    def strain_stiffening(problem):  # a law depending on curvature
        problem.cubic_stiffening_m2 = 1e-3

    def pressure_stiffening(problem):  # a law depending on actuation
        factor = 1.0 + 10.0 * problem.jet_forces_n.sum()
        problem.bending_stiffness_x_nm2 = problem.bending_stiffness_x_nm2 * factor
        problem.bending_stiffness_y_nm2 = problem.bending_stiffness_y_nm2 * factor

    for hook in (Hook("profile", stiffer_near_tip), Hook("cubic", strain_stiffening),
                 Hook("pressure", pressure_stiffening, uses_actuation=True)):
        assert solve(model_type, hook).bend_angle_deg < base - 1.0, hook.name
    # An actuation-dependent effect is re-applied for every jet command.
    model = model_type(effects=("gravity", Hook("pressure", pressure_stiffening, uses_actuation=True)))
    low, high = (model.solve([q, 0.0, 0.0], PARAMS) for q in (0.02, 0.1))
    fresh_high = model_type(effects=("gravity", Hook("pressure", pressure_stiffening, uses_actuation=True)))
    np.testing.assert_allclose(high.tip_position_in_base_m,
                               fresh_high.solve([0.1, 0.0, 0.0], PARAMS).tip_position_in_base_m, atol=1e-12)


@pytest.mark.parametrize("model_type", MODELS, ids=IDS)
def test_actuation_map_hooks(model_type):
    def clogged_jet_1(problem):
        problem.jet_gains = np.array([0.5, 1.0, 1.0])

    clogged = solve(model_type, Hook("gain", clogged_jet_1))
    halved = model_type().solve([0.025, 0.0, 0.0], PARAMS)
    np.testing.assert_allclose(clogged.tip_position_in_base_m, halved.tip_position_in_base_m, atol=1e-12)


@pytest.mark.parametrize("model_type", MODELS, ids=IDS)
def test_tip_wrench_hook_matches_the_disturbance_parameter(model_type):
    def push(problem):
        problem.tip_follower_force_in_tip_n = problem.tip_follower_force_in_tip_n + [0.0, 0.01, 0.0]

    pushed = solve(model_type, Hook("push", push))
    from hydrojet_bench.params import with_parameters

    disturbed = model_type().solve([0.05, 0.0, 0.0], with_parameters(PARAMS, {"wd_fy": 0.01}))
    np.testing.assert_allclose(pushed.tip_position_in_base_m, disturbed.tip_position_in_base_m, atol=1e-12)


@pytest.mark.parametrize("model_type", MODELS, ids=IDS)
def test_base_boundary_hooks_compliance_and_hysteresis(model_type):
    def compliant(problem):
        problem.base_compliance_rad_per_nm = np.array([20.0, 20.0, 20.0])

    rigid = model_type().solve([0.05, 0.0, 0.0], PARAMS)
    soft = solve(model_type, Hook("compliant", compliant))
    assert np.linalg.norm(soft.base_rotation_vector_rad) > 0.01
    np.testing.assert_allclose(so3_exp(soft.base_rotation_vector_rad), soft.rotations_in_base[0], atol=1e-6)
    assert soft.bend_angle_deg > rigid.bend_angle_deg

    def play(problem):
        compliant(problem)
        problem.base_play_rad = 0.02

    model = model_type(effects=("gravity", Hook("play", play)))
    up, down, previous = {}, {}, None
    for q in (0.0, 0.02, 0.04, 0.06, 0.04, 0.02, 0.0):
        previous = model.solve([q, 0.0, 0.0], PARAMS, previous=previous)
        (down if q in up else up)[q] = previous
    # Loading and unloading through the same force leave the clamp (and tip) elsewhere.
    gap = np.linalg.norm(up[0.02].tip_position_in_base_m - down[0.02].tip_position_in_base_m)
    assert gap > 1e-4
    # Without a history the result is the loading branch from rest.
    fresh = model.solve([0.02, 0.0, 0.0], PARAMS)
    assert np.linalg.norm(fresh.base_rotation_vector_rad) < np.linalg.norm(down[0.02].base_rotation_vector_rad) + 0.05


@pytest.mark.parametrize("model_type", MODELS, ids=IDS)
def test_measurement_hook_rotates_the_sensor_not_the_body(model_type):
    mounting = so3_exp([0.0, 0.0, 0.2])

    def mounted(problem):
        problem.tip_sensor_mounting = mounting

    plain = model_type().solve([0.05, 0.0, 0.0], PARAMS)
    measured = solve(model_type, Hook("mount", mounted))
    np.testing.assert_allclose(measured.positions_in_base_m, plain.positions_in_base_m, atol=1e-12)
    np.testing.assert_allclose(measured.tip_sensor_in_base_sensor(), plain.tip_sensor_in_base_sensor() @ mounting,
                               atol=1e-12)


class _DoublesStiffnessInPlace:
    """Edits the problem's arrays in place, as the interface allows."""

    name = "doubles_stiffness_in_place"
    parameters = ()
    uses_actuation = False

    def apply(self, problem, values):
        problem.bending_stiffness_x_nm2 *= 2.0
        problem.tip_sensor_mounting[:] = so3_exp(np.array([0.0, 0.0, 0.1]))


def test_an_effect_editing_arrays_in_place_changes_its_own_problem_only():
    # The nominal stiffness is shared between problems of one rod (a recording's steps are
    # each packed under their own gravity): an in-place edit must not reach the next one.
    model = CosseratModel(effects=(_DoublesStiffnessInPlace(),))
    params = ModelParameters()
    plain = CosseratModel().build_problem(np.zeros(3), params)
    for _ in range(3):
        problem = model.build_problem(np.zeros(3), params)
        np.testing.assert_array_equal(problem.bending_stiffness_x_nm2, 2.0 * plain.bending_stiffness_x_nm2)
        np.testing.assert_array_equal(problem.bending_stiffness_y_nm2, plain.bending_stiffness_y_nm2)
        np.testing.assert_array_equal(problem.tip_sensor_mounting, so3_exp(np.array([0.0, 0.0, 0.1])))
    np.testing.assert_array_equal(CosseratModel().build_problem(np.zeros(3), params).tip_sensor_mounting, np.eye(3))


def test_hints_name_a_users_effect_by_its_file_which_is_what_loads_it(tmp_path, capsys):
    spec = f"{write(tmp_path, USER_EFFECT)}:TorsionalPreload"
    assert main(["simulate", "-o", str(tmp_path / "x.csv"), "--hidden", f"{spec}=0"]) == 2
    assert f"e.g. --hidden {spec}=VALUE" in capsys.readouterr().err
