"""Solver behaviour: warm starts, load ramping, typed failures, problem caching, and the
PRB chain against the paper's eq. 16 written with explicit Jacobians."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import ClassVar

import numpy as np
import pytest

from hydrojet_bench.effects import EffectParameter
from hydrojet_bench.errors import ConvergenceError
from hydrojet_bench.geometry import adjoint, se3, so3_exp, so3_log
from hydrojet_bench.models import CosseratModel, PrbModel, make_model, shooting
from hydrojet_bench.effects.problem import RodProblem
from hydrojet_bench.params import (CapsuleParameters, DisturbanceWrench, ModelParameters, RodParameters,
                                   with_parameters)

ACROSS = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
MODELS = [CosseratModel(), PrbModel()]
IDS = ["cosserat", "prb"]


@pytest.mark.parametrize("model", MODELS, ids=IDS)
def test_warm_start_changes_speed_not_the_answer(model):
    nearby = model.solve([0.05, 0.0, 0.0], ACROSS)
    cold = model.solve([0.052, 0.0, 0.0], ACROSS)
    warm = model.solve([0.052, 0.0, 0.0], ACROSS, warm_start=nearby)
    np.testing.assert_allclose(warm.positions_in_base_m, cold.positions_in_base_m, atol=1e-11)
    np.testing.assert_allclose(warm.rotations_in_base, cold.rotations_in_base, atol=1e-9)


@pytest.mark.parametrize("model", MODELS, ids=IDS)
def test_a_far_away_warm_start_still_finds_the_same_equilibrium(model):
    far = model.solve([0.0, 0.2, 0.0], ACROSS)
    cold = model.solve([0.05, 0.0, 0.01], ACROSS)
    warm = model.solve([0.05, 0.0, 0.01], ACROSS, warm_start=far)
    np.testing.assert_allclose(warm.tip_position_in_base_m, cold.tip_position_in_base_m, atol=1e-11)


@pytest.mark.parametrize("model", MODELS, ids=IDS)
def test_bends_past_150_degrees_follow_the_branch_continued_from_the_straight_rod(model):
    solution = model.solve([0.0, 0.3, 0.0], ACROSS)
    assert solution.bend_angle_deg > 150.0
    # Stepping the load up by hand, warm-starting each step, lands on the same shape.
    previous = None
    for force in np.linspace(0.03, 0.3, 10):
        previous = model.solve([0.0, force, 0.0], ACROSS, warm_start=previous)
    np.testing.assert_allclose(solution.tip_position_in_base_m, previous.tip_position_in_base_m, atol=1e-10)


@pytest.mark.parametrize("model", MODELS, ids=IDS)
def test_the_shape_is_orthonormal_and_starts_at_the_clamp(model):
    solution = model.solve([0.02, 0.04, 0.0], ACROSS)
    np.testing.assert_allclose(solution.positions_in_base_m[0], 0.0, atol=1e-15)
    # The clamp frame is reported exactly (the boundary condition), not as integrated.
    np.testing.assert_array_equal(solution.rotations_in_base[0], np.eye(3))
    for rotation in solution.rotations_in_base:
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-14)
    # Inextensible: consecutive nodes are exactly one step apart along the arc for the
    # rod (chord of a smooth curve) and one link apart for the chain.
    steps = np.linalg.norm(np.diff(solution.positions_in_base_m, axis=0), axis=1)
    assert steps.sum() == pytest.approx(ACROSS.rod.length_m, rel=1e-3)


# A soft-tipped chain across gravity with a large jet force, from a diagnosis of the
# library study: the load path folds, and the chain snaps from about 58 to 98 degrees.
FOLD = ModelParameters(
    rod=RodParameters(length_m=0.0695742, radius_m=0.0045, density_kg_m3=1070.0, poisson_ratio=0.49,
                      youngs_modulus_base_pa=556604.0, youngs_modulus_tip_pa=15841.9),
    disturbance=DisturbanceWrench(force_n=(0.0318636, 0.00192526, 0.0635907),
                                  moment_nm=(2.2427e-05, -4.4956e-04, 4.7793e-06)),
    gravity_in_base_m_s2=(9.809997, -0.0046286, -0.0059968))
FOLD_JETS_N = [0.0, 0.0336843, 0.0803568]


def test_past_a_fold_of_the_load_path_the_solver_finds_the_branch_the_rod_snaps_to(monkeypatch):
    model = PrbModel()
    solution = model.solve(FOLD_JETS_N, FOLD)
    assert solution.residual <= model.tolerance
    assert 90.0 < solution.bend_angle_deg < 110.0
    # Warm-started from the shape it snapped from (the same load, just short of the fold),
    # it lands on the same branch.
    near = model.solve([0.0, 0.0336843, 0.07], FOLD)
    assert near.bend_angle_deg < 70.0
    snapped = model.solve(FOLD_JETS_N, FOLD, warm_start=near)
    np.testing.assert_allclose(snapped.tip_position_in_base_m, solution.tip_position_in_base_m, atol=1e-9)
    # Continuation alone ends at the fold.
    monkeypatch.setattr(shooting, "SNAP_TURNS_DEG", ())
    with pytest.raises(ConvergenceError, match="past a fold"):
        PrbModel().solve(FOLD_JETS_N, FOLD)


# A heavy capsule on a soft-tipped rod held across gravity, under a large compressive w_d
# (where a calibration of such a rod wandered): several equilibria for one load.
HEAVY = ModelParameters(
    rod=RodParameters(length_m=0.068861, radius_m=0.0045, youngs_modulus_base_pa=535249.0,
                      youngs_modulus_tip_pa=75097.0),
    capsule=CapsuleParameters(mass_kg=0.0095),
    disturbance=DisturbanceWrench(force_n=(-0.0498, -0.0039, 0.31), moment_nm=(-7.5e-05, 3.68e-04, -3.5e-05)),
    gravity_in_base_m_s2=(-9.81, 0.0, 0.0))


@pytest.mark.parametrize("model", MODELS, ids=IDS)
@pytest.mark.parametrize("jets", [[0.0, 0.0, 0.0], [0.0, 0.076, 0.05]])
def test_a_cold_start_finds_the_equilibrium_that_loading_the_rod_reaches(model, jets):
    solution = model.solve(jets, HEAVY)
    # Every load (weight, w_d, jets) raised by hand from nearly nothing, each step
    # warm-started from the one before: the rod as it is loaded.
    loaded = None
    for share in np.linspace(0.05, 1.0, 20):
        params = replace(HEAVY, gravity_in_base_m_s2=tuple(share * np.array(HEAVY.gravity_in_base_m_s2)),
                         disturbance=DisturbanceWrench(force_n=tuple(share * np.array(HEAVY.disturbance.force_n)),
                                                       moment_nm=tuple(share * np.array(HEAVY.disturbance.moment_nm))))
        loaded = model.solve(share * np.array(jets), params, warm_start=loaded)
    np.testing.assert_allclose(solution.tip_position_in_base_m, loaded.tip_position_in_base_m, atol=1e-9)
    # A direct shot from the straight rod converges too, on another equilibrium, which
    # every later warm start would have followed.
    prepared = model.prepare(jets, HEAVY)
    work = model.workspace(prepared)
    assert model._run(prepared, prepared.jet_forces_n, np.eye(3), 1.0, work)
    assert model.solution_from(prepared, work).bend_angle_deg > solution.bend_angle_deg + 15.0


class Softening:
    """Test effect: strain softening strong enough that no equilibrium exists for a large
    load (m = EI(k + beta k^3) with beta < 0 saturates at a finite moment)."""

    name: ClassVar[str] = "softening"
    explanation: ClassVar[str] = "test only"
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    uses_actuation: ClassVar[bool] = False

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.cubic_stiffening_m2 = -4e-4


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
def test_impossible_equilibrium_raises_a_typed_error_not_a_shape(model_type):
    model = model_type(effects=(Softening(),))
    model.solve([0.001, 0.0, 0.0], ModelParameters())  # small loads are fine
    with pytest.raises(ConvergenceError, match="did not converge"):
        model.solve([0.5, 0.0, 0.0], ModelParameters())


def test_iteration_budget_exhaustion_is_a_convergence_error():
    model = CosseratModel(max_iterations=1)
    with pytest.raises(ConvergenceError):
        model.solve([0.3, 0.0, 0.0], ACROSS)


def test_cached_packing_follows_parameter_changes():
    model = CosseratModel()
    stiff = with_parameters(ACROSS, {"E0": 6e5, "EL": 4e5})
    first = model.solve([0.05, 0.0, 0.0], ACROSS)
    again = model.solve([0.05, 0.0, 0.0], stiff)
    fresh = CosseratModel().solve([0.05, 0.0, 0.0], stiff)
    np.testing.assert_allclose(again.tip_position_in_base_m, fresh.tip_position_in_base_m, atol=1e-12)
    assert np.linalg.norm(first.tip_position_in_base_m - again.tip_position_in_base_m) > 1e-3


def test_equal_parameters_reuse_the_packing_and_others_do_not():
    # A path predictor and its online estimator each copy the parameters under the step's
    # gravity: equal copies share the packing; the slightest change packs anew.
    from dataclasses import replace

    model = CosseratModel()
    built = []
    build_problem = model.build_problem
    model.build_problem = lambda *args, **kwargs: built.append(1) or build_problem(*args, **kwargs)
    first = model.prepare([0.05, 0.0, 0.0], ACROSS)
    assert model.prepare([0.02, 0.0, 0.01], replace(ACROSS)).profile is first.profile and len(built) == 1
    nudged = replace(ACROSS, gravity_in_base_m_s2=(-9.81, 1e-9, 0.0))
    assert model.prepare([0.02, 0.0, 0.01], nudged).profile is not first.profile and len(built) == 2


def test_bad_jet_forces_and_model_names_are_reported():
    with pytest.raises(ValueError, match="jet_forces_n"):
        CosseratModel().solve([0.1, float("nan"), 0.0], ACROSS)
    with pytest.raises(ValueError, match="jet_forces_n"):
        PrbModel().solve([0.1, 0.0], ACROSS)
    from hydrojet_bench.errors import UserError

    with pytest.raises(UserError, match="unknown model 'beam'"):
        make_model("beam")


@pytest.mark.parametrize("stiffness_ratio", [1.0, 2.0])
def test_prb_equilibrium_satisfies_eq_16_with_explicit_jacobians(stiffness_ratio):
    """K theta = tau_f + tau_a (eqs. 14-16) with the joint torques computed the paper's
    way: one twist per joint axis, transformed by adjoints, dotted with spatial wrenches.
    Independent of the kernel's moment recursion. The anisotropic section (EI_x / EI_y =
    2) is where the frame of the joint's axes matters."""
    params = ModelParameters(gravity_in_base_m_s2=(-9.81, 2.0, 0.0),
                             effect_values={"anisotropic_stiffness.stiffness_ratio": stiffness_ratio})
    links = 8
    model = PrbModel(("gravity", "anisotropic_stiffness"), links=links)
    solution = model.solve([0.03, 0.0, 0.04], params)
    joints = links - 1
    segment = params.rod.length_m / joints
    problem = model.build_problem([0.03, 0.0, 0.04], params)
    positions, rotations = solution.positions_in_base_m, solution.rotations_in_base

    # Loads as spatial wrenches (force, moment about the base origin).
    wrenches = []
    weight_per_length = problem.distributed_force_in_base_n_m[0]
    for a, b in zip(positions[:-1], positions[1:]):  # links run clamp-joint-...-joint-tip
        force = weight_per_length * np.linalg.norm(b - a)
        centre = 0.5 * (a + b)
        wrenches.append(np.concatenate([force, np.cross(centre, force)]))
    tip_rotation = rotations[-1]
    tip_force = tip_rotation @ (problem.actuation_matrix() @ problem.jet_forces_n)
    com = positions[-1] + tip_rotation @ np.asarray(params.capsule.center_of_mass_in_tip_m)
    capsule_weight = problem.tip_dead_force_in_base_n
    wrenches.append(np.concatenate([tip_force, np.cross(positions[-1], tip_force)]))
    wrenches.append(np.concatenate([capsule_weight, np.cross(com, capsule_weight)]))
    # Which loads lie beyond joint j: link j onwards (links 0..joints), the tip loads always.
    for joint in range(1, joints + 1):
        # theta_j from the relative rotation of the links either side.
        theta = so3_log(rotations[joint - 1].T @ rotations[joint])
        # The joint's axes are its mid-rotation frame, halfway between the two links.
        joint_pose = se3(rotations[joint - 1] @ so3_exp(0.5 * theta), positions[joint])
        # Body-frame unit twists of the joint axes, mapped to spatial twists (eq. 12).
        spatial_twists = [adjoint(joint_pose) @ np.concatenate([np.zeros(3), axis]) for axis in np.eye(3)]
        beyond = wrenches[joint:]
        torque = np.array([sum(twist @ wrench for wrench in beyond) for twist in spatial_twists])
        s_joint = (joint - 0.5) * segment
        stiffness = params.rod.youngs_modulus_pa(s_joint) * params.rod.second_moment_m4 / segment
        torsion = params.rod.shear_modulus_pa(s_joint) * params.rod.polar_moment_m4 / segment
        root = np.sqrt(stiffness_ratio)
        elastic = np.array([stiffness * root, stiffness / root, torsion]) * theta
        np.testing.assert_allclose(elastic, torque, rtol=1e-6, atol=1e-12)


def _same_solutions(batch, loop):
    assert len(batch) == len(loop)
    for got, expected in zip(batch, loop):
        np.testing.assert_array_equal(got.positions_in_base_m, expected.positions_in_base_m)
        np.testing.assert_array_equal(got.rotations_in_base, expected.rotations_in_base)
        np.testing.assert_array_equal(got.base_wrench_in_base, expected.base_wrench_in_base)
        np.testing.assert_array_equal(got.base_rotation_vector_rad, expected.base_rotation_vector_rad)
        np.testing.assert_array_equal(got.jacobian, expected.jacobian)
        np.testing.assert_array_equal(got.jet_forces_n, expected.jet_forces_n)
        assert (got.iterations, got.residual) == (expected.iterations, expected.residual)


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
def test_a_warm_solve_on_the_last_packing_is_the_packed_problems_solve_bit_for_bit(model_type):
    # `solve` under the parameters of the last packing goes straight to the kernel; it
    # must be `solve_prepared` on the problem `prepare` packs, and touch neither the
    # seed nor the caller's jets.
    model = model_type()
    seed = model.solve([0.05, 0.0, 0.0], ACROSS)
    seed_rotations, seed_jacobian = seed.rotations_in_base.copy(), seed.jacobian.copy()
    jets = np.array([0.052, 0.004, 0.0])
    direct = model.solve(jets, ACROSS, warm_start=seed)
    packed = model.solve_prepared(model.prepare(jets, ACROSS), seed)
    _same_solutions([direct], [packed])
    np.testing.assert_array_equal(seed.rotations_in_base, seed_rotations)
    np.testing.assert_array_equal(seed.jacobian, seed_jacobian)
    jets[0] = 1.0
    assert direct.jet_forces_n.tolist() == [0.052, 0.004, 0.0]
    # A seed too far for the warm solve's iterations: the full path (cold start,
    # ramping) from the same direct call, as from the packed problem.
    short = model_type(max_iterations=8)
    near = short.solve([0.05, 0.0, 0.0], ACROSS)
    _same_solutions([short.solve([0.0, 0.2, 0.05], ACROSS, warm_start=near)],
                    [short.solve_prepared(short.prepare([0.0, 0.2, 0.05], ACROSS), near)])
    with pytest.raises(ValueError, match="jet_forces_n"):
        model.solve([0.05, float("nan"), 0.0], ACROSS, warm_start=seed)


def _single_solves(model, jets, params, seed=None, warm_starts=None, along_path=False) -> list:
    """What `solve_batch` must equal: one `solve` a row (under ``params``, or row k under
    ``params[k]``), each from its own warm start or else the row before (row 0:
    ``seed``), which is also its path state ``along_path``."""
    loop, previous = [], seed
    for k, row in enumerate(jets):
        own = None if warm_starts is None else warm_starts[k]
        previous = model.solve(row, params if isinstance(params, ModelParameters) else params[k],
                               previous=previous if along_path else None,
                               warm_start=own if own is not None else previous)
        loop.append(previous)
    return loop


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
def test_a_batch_of_solves_is_the_loop_of_single_solves_bit_for_bit(model_type):
    model = model_type()
    rng = np.random.default_rng(7)
    jets = rng.uniform(0.0, 0.12, (12, 3))
    earlier = [model.solve(row * 0.97, ACROSS) for row in jets]
    # Rows 0, 4 and 9 have their own warm start; the others start from the row before.
    warm_starts = [earlier[k] if k in (0, 4, 9) else None for k in range(len(jets))]
    _same_solutions(model.solve_batch(jets, ACROSS, warm_starts), _single_solves(model, jets, ACROSS,
                                                                                 warm_starts=warm_starts))
    # A seed starts row 0 like any other solution before it would.
    seed = model.solve(jets[0] * 1.05, ACROSS)
    _same_solutions(model.solve_batch(jets[:3], ACROSS, [None] * 3, seed),
                    [first := model.solve(jets[0], ACROSS, warm_start=seed),
                     second := model.solve(jets[1], ACROSS, warm_start=first),
                     model.solve(jets[2], ACROSS, warm_start=second)])


def _count_single_solves(model) -> list:
    """The jets of every single `solve` the model makes from now on."""
    single_solves = []
    solve = model.solve

    def counted(*args, **kwargs):
        single_solves.append(list(args[0]))
        return solve(*args, **kwargs)

    model.solve = counted
    return single_solves


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
def test_a_row_the_batched_warm_solve_cannot_finish_takes_the_full_path(model_type):
    # With 8 iterations the warm solve cannot jump from jet 1 to a large jet 2 command;
    # the full path (cold start, ramping) can, and the rows after it resume the batch.
    model = model_type(max_iterations=8)
    jets = np.array([[0.05, 0.0, 0.0], [0.052, 0.0, 0.0], [0.0, 0.2, 0.05], [0.0, 0.21, 0.05]])
    seed = model.solve(jets[0] * 0.9, ACROSS)
    loop = _single_solves(model, jets, ACROSS, seed)
    single_solves = _count_single_solves(model)
    _same_solutions(model.solve_batch(jets, ACROSS, [None] * len(jets), seed), loop)
    assert single_solves == [[0.0, 0.2, 0.05]]


HYSTERESIS = ("base_hysteresis.compliance_rad_per_nm", "base_hysteresis.play_rad")


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
def test_a_batch_along_a_path_with_state_carries_each_rows_clamp_state(model_type):
    params = with_parameters(ACROSS, dict(zip(HYSTERESIS, (50.0, 0.02))))
    model = model_type(effects=("gravity", "base_hysteresis"))
    jets = np.array([[f, 0.0, 0.0] for f in (0.0, 0.05, 0.1, 0.05, 0.0)] + [[0.0, 0.2, 0.05], [0.0, 0.19, 0.05]])
    loop = _single_solves(model, jets, params, along_path=True)
    single_solves = _count_single_solves(model)
    _same_solutions(model.solve_batch(jets, params, [None] * len(jets), along_path=True), loop)
    # The first row has nothing to start from; the others are one kernel call.
    assert single_solves == [[0.0, 0.0, 0.0]]
    # With 12 iterations the warm solve cannot finish some rows (the jump to jet 2
    # among them), which then take the full path with the state the row before left.
    short = model_type(effects=("gravity", "base_hysteresis"), max_iterations=12)
    short_loop = _single_solves(short, jets, params, along_path=True)
    single_solves = _count_single_solves(short)
    _same_solutions(short.solve_batch(jets, params, [None] * len(jets), along_path=True), short_loop)
    assert [0.0, 0.2, 0.05] in single_solves and len(single_solves) < len(jets)
    # Round the path again from where it ended: the first row's clamp starts there too.
    again = _single_solves(model, jets[:5], params, loop[-1], along_path=True)
    _same_solutions(model.solve_batch(jets[:5], params, [None] * 5, loop[-1], along_path=True), again)
    # Without the path every row starts from a clamp at rest, and the loop's way back differs.
    independent = model.solve_batch(jets[:5], params, [None] * 5)
    assert np.linalg.norm(independent[3].base_rotation_vector_rad - loop[3].base_rotation_vector_rad) > 1e-4


class _SwappedJets:
    """Reads the jets: jets 1 and 2 swapped (the packed jets are not the commanded ones)."""

    name: ClassVar[str] = "swapped_jets"
    parameters: ClassVar[tuple] = ()
    uses_actuation: ClassVar[bool] = True

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.jet_forces_n = problem.jet_forces_n[[1, 0, 2]]


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
@pytest.mark.parametrize("effects, values, along_path", [
    (("gravity", "pressure_stiffening"), {"pressure_stiffening.coefficient_1_n": 3.0}, False),
    (("gravity", _SwappedJets()), {}, False),
    (("gravity", "pressure_stiffening", "base_hysteresis"),
     {"pressure_stiffening.coefficient_1_n": -0.8, **dict(zip(HYSTERESIS, (50.0, 0.02)))}, True),
], ids=["stiffening", "swapped", "stiffening-on-a-path"])
def test_rows_packed_apart_are_one_kernel_call_and_the_loop_bit_for_bit(model_type, effects, values, along_path):
    # An effect that reads the jets packs every command apart, once (row 6 repeats row
    # 2's); the rows still share one kernel call, and each is its own single solve's answer.
    params = with_parameters(ACROSS, values)
    model = model_type(effects=effects)
    jets = np.random.default_rng(3).uniform(0.0, 0.1, (8, 3))
    jets[6] = jets[2]
    seed = model.solve(jets[0] * 0.95, params)
    warm_starts = [model.solve(jets[4] * 0.97, params) if k == 4 else None for k in range(len(jets))]
    loop = _single_solves(model, jets, params, seed, warm_starts, along_path)
    single_solves = _count_single_solves(model)
    built = []
    build_problem = model.build_problem
    model.build_problem = lambda *args, **kwargs: built.append(1) or build_problem(*args, **kwargs)
    _same_solutions(model.solve_batch(jets, params, warm_starts, seed, along_path=along_path), loop)
    assert single_solves == [] and len(built) == 7


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
@pytest.mark.parametrize("effects, values, along_path", [
    (("gravity",), {}, False),
    (("gravity", "pressure_stiffening"), {"pressure_stiffening.coefficient_1_n": 3.0}, False),
    (("gravity", "base_hysteresis"), dict(zip(HYSTERESIS, (50.0, 0.02))), True),
], ids=["gravity", "stiffening", "hysteresis-on-a-path"])
def test_rows_under_their_own_parameters_are_one_kernel_call_and_the_loop_bit_for_bit(model_type, effects, values,
                                                                                       along_path):
    # A recording's steps, each under the gravity its base sensor read (rows 3 and 4
    # share one parameters object): each is packed once, all are solved in one kernel
    # call, and each is its own single solve's answer.
    model = model_type(effects=effects)
    rng = np.random.default_rng(5)
    jets = rng.uniform(0.0, 0.1, (8, 3))
    tilts = [with_parameters(ACROSS, values)]
    for _ in range(6):
        tilts.append(replace(tilts[0], gravity_in_base_m_s2=tuple(9.81 * so3_exp(rng.normal(0.0, 0.3, 3))[:, 0])))
    row_params = tilts[:4] + tilts[3:]
    seed = model.solve(jets[0] * 0.95, row_params[0])
    loop = _single_solves(model, jets, row_params, seed, along_path=along_path)
    single_solves = _count_single_solves(model)
    built = []
    build_problem = model.build_problem
    model.build_problem = lambda *args, **kwargs: built.append(1) or build_problem(*args, **kwargs)
    _same_solutions(model.solve_batch(jets, row_params, [None] * len(jets), seed, along_path=along_path), loop)
    packings_made = len(jets) if model.effects[-1].uses_actuation else len(tilts)
    assert single_solves == [] and len(built) == packings_made
    with pytest.raises(ValueError, match="7 parameter sets for 8 rows"):
        model.solve_batch(jets, row_params[1:], [None] * len(jets), seed)


class _JetStiffenedSection:
    """Reads the jets into the section law, which the kernel takes once for all rows."""

    name: ClassVar[str] = "jet_stiffened_section"
    parameters: ClassVar[tuple] = ()
    uses_actuation: ClassVar[bool] = True

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.cubic_stiffening_m2 = 1e-3 * float(np.sum(problem.jet_forces_n))


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
def test_rows_whose_packings_one_kernel_call_cannot_take_are_solved_one_by_one(model_type):
    model = model_type(effects=("gravity", _JetStiffenedSection()))
    jets = np.random.default_rng(5).uniform(0.0, 0.1, (4, 3))
    seed = model.solve(jets[0] * 0.95, ACROSS)
    loop = _single_solves(model, jets, ACROSS, seed)
    single_solves = _count_single_solves(model)
    _same_solutions(model.solve_batch(jets, ACROSS, [None] * len(jets), seed), loop)
    assert single_solves == jets.tolist()


def test_a_batch_names_its_bad_input():
    with pytest.raises(ValueError, match="jet_forces_n must be"):
        CosseratModel().solve_batch(np.zeros((2, 2)), ACROSS, [None, None])
    with pytest.raises(ValueError, match="one warm start per row"):
        CosseratModel().solve_batch(np.zeros((2, 3)), ACROSS, [None])
    with pytest.raises(ValueError, match="finite"):
        CosseratModel().solve_batch(np.array([[0.1, np.nan, 0.0]]), ACROSS, [None])
    assert CosseratModel().solve_batch(np.zeros((0, 3)), ACROSS, []) == []


def test_stacked_tip_sensor_readings_are_each_solutions_own():
    from hydrojet_bench.effects.setup import BaseSensorMounting

    model = CosseratModel(effects=("gravity", BaseSensorMounting((0.014, 0.0, 0.0))))
    params = with_parameters(ACROSS, {"base_sensor_mounting.rx_rad": 0.1, "base_sensor_mounting.rz_rad": -0.2})
    solutions = [model.solve([f, 0.02, 0.0], params) for f in (0.0, 0.05, 0.1)]
    np.testing.assert_allclose(shooting.tip_sensors_in_base_sensor(solutions),
                               [solution.tip_sensor_in_base_sensor() for solution in solutions], atol=1e-15)
    # A point o of the tip frame, read through the base sensor turned by M about its origin c.
    offsets = np.array([[0.0, 0.0, 0.0], [0.001, -0.002, 0.003], [0.0, 0.004, 0.0]])
    expected = [solution.base_sensor_mounting.T @ (solution.tip_position_in_base_m
                                                   + solution.tip_rotation_in_base @ offset
                                                   - solution.base_sensor_offset_m) + solution.base_sensor_offset_m
                for solution, offset in zip(solutions, offsets)]
    np.testing.assert_allclose(shooting.tip_sensor_positions_in_base_sensor_m(solutions, offsets), expected,
                               atol=1e-15)
    assert np.linalg.norm(solutions[0].base_sensor_offset_m) > 0.01
    assert shooting.tip_sensors_in_base_sensor([]).shape == (0, 3, 3)
    assert shooting.tip_sensor_positions_in_base_sensor_m([], np.empty((0, 3))).shape == (0, 3)


@pytest.mark.parametrize("model_type", [CosseratModel, PrbModel], ids=IDS)
def test_a_reused_packing_along_a_path_with_state_is_the_fresh_packing(model_type):
    # The model keeps its packing between solves under the same parameters and only
    # swaps in the clamp's state; a model packing every solve afresh agrees bit for bit.
    names = ("base_hysteresis.compliance_rad_per_nm", "base_hysteresis.play_rad")
    params = with_parameters(ACROSS, dict(zip(names, (50.0, 0.02))))
    reusing = model_type(effects=("gravity", "base_hysteresis"))
    commands = [(0.0, 0.0), (0.05, 0.0), (0.1, 0.02), (0.05, 0.04), (0.0, 0.02), (0.0, 0.0)]
    kept = fresh = None
    for first, second in commands:
        jets = [first, second, 0.0]
        kept = reusing.solve(jets, params, previous=kept)
        fresh = model_type(effects=("gravity", "base_hysteresis")).solve(jets, params, previous=fresh)
        np.testing.assert_array_equal(kept.rotations_in_base, fresh.rotations_in_base)
        np.testing.assert_array_equal(kept.base_rotation_vector_rad, fresh.base_rotation_vector_rad)
    # The clamp did carry state: the last command repeats the first from the other side.
    assert np.linalg.norm(kept.base_rotation_vector_rad
                          - reusing.solve([0.0, 0.0, 0.0], params).base_rotation_vector_rad) > 1e-3
