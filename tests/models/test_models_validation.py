"""Validation of the models against analytic mechanics and an independent solver.

Each tolerance is stated with the reason for its size. "RK4 error" refers to the 20-step
classic RK4 of the Cosserat kernel, whose global error is O(h^4): measured at 1.7e-5 mm
for a 40 degree bend of the HydroJet rod and 5e-4 mm at 150 degrees.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

from hydrojet_bench.effects import EffectParameter
from hydrojet_bench.models import CosseratModel, PrbModel
from hydrojet_bench.effects.problem import RodProblem
from hydrojet_bench.models.reference import solve_reference
from hydrojet_bench.params import (CapsuleParameters, DisturbanceWrench, JetLayout, ModelParameters,
                                   RodParameters)

UNIFORM_ROD = RodParameters(youngs_modulus_base_pa=2.5e5, youngs_modulus_tip_pa=2.5e5)
EI = UNIFORM_ROD.youngs_modulus_base_pa * UNIFORM_ROD.second_moment_m4
L = UNIFORM_ROD.length_m
NO_GRAVITY = ModelParameters(rod=UNIFORM_ROD, gravity_in_base_m_s2=(0.0, 0.0, 0.0))


class TipDeadForce:
    """Test effect: a dead (fixed-direction) force at the tip point, base frame."""

    name: ClassVar[str] = "tip_dead_force"
    explanation: ClassVar[str] = "a fixed force applied at the tip, for validation"
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    uses_actuation: ClassVar[bool] = False

    def __init__(self, force_in_base_n: tuple[float, float, float]) -> None:
        self.force = np.asarray(force_in_base_n, dtype=float)

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.add_tip_dead_force(self.force, np.zeros(3))


# --- small loads: Euler-Bernoulli ------------------------------------------------------


@pytest.mark.parametrize("model", [CosseratModel(effects=()), PrbModel(effects=(), links=200)],
                         ids=["cosserat", "prb-200"])
def test_small_dead_tip_load_matches_euler_bernoulli(model):
    # alpha = P L^2 / EI = 1e-3: geometric nonlinearity changes deflection by O(alpha^2),
    # ~1e-6 relative. Cosserat adds RK4 error (negligible); PRB with 200 links adds its
    # O(1/n^2) lumping error, ~1e-5. A 1e-4 relative tolerance covers both with margin.
    force = 1e-3 * EI / L**2
    model = type(model)(effects=(TipDeadForce((force, 0.0, 0.0)),), **(
        {"links": 200} if isinstance(model, PrbModel) else {}))
    solution = model.solve([0.0, 0.0, 0.0], NO_GRAVITY)
    deflection = solution.tip_position_in_base_m[0]
    slope = math.atan2(solution.tip_rotation_in_base[0, 2], solution.tip_rotation_in_base[2, 2])
    assert deflection == pytest.approx(force * L**3 / (3 * EI), rel=1e-4)
    assert slope == pytest.approx(force * L**2 / (2 * EI), rel=1e-4)


@pytest.mark.parametrize("model", [CosseratModel(effects=("shear_extension",)),
                                   PrbModel(effects=("shear_extension",), links=200)], ids=["cosserat", "prb-200"])
def test_a_shearing_stretching_rod_bends_and_stretches_as_timoshenko_says(model):
    # A small dead tip load across a uniform rod: Timoshenko's cantilever, bending plus
    # shear, P L^3 / (3 E I) + P L / (k G A); along it, the rod stretches by P L / (E A).
    # Same size argument as Euler-Bernoulli above (alpha = 1e-3); scale 4 makes the shear
    # 4 % of the deflection, so a missing or doubled term fails by 400 times the 1e-4.
    from hydrojet_bench.effects.shear_extension import cowper_shear_coefficient

    scale = 4.0
    params = ModelParameters(rod=UNIFORM_ROD, gravity_in_base_m_s2=(0.0, 0.0, 0.0),
                                  effect_values={"shear_extension.scale": scale})
    force = 1e-3 * EI / L**2
    area = UNIFORM_ROD.area_m2
    shear_stiffness = (cowper_shear_coefficient(UNIFORM_ROD.poisson_ratio)
                       * UNIFORM_ROD.shear_modulus_pa(0.0) * area / scale)
    axial_stiffness = UNIFORM_ROD.youngs_modulus_base_pa * area / scale
    kind = {"links": 200} if isinstance(model, PrbModel) else {}
    across = type(model)(effects=("shear_extension", TipDeadForce((force, 0.0, 0.0))), **kind)
    deflection = across.solve([0.0, 0.0, 0.0], params).tip_position_in_base_m[0]
    shear_part = force * L / shear_stiffness
    assert shear_part > 0.03 * deflection
    assert deflection == pytest.approx(force * L**3 / (3 * EI) + shear_part, rel=1e-4)
    along = type(model)(effects=("shear_extension", TipDeadForce((0.0, 0.0, 100 * force))), **kind)
    stretch = along.solve([0.0, 0.0, 0.0], params).tip_position_in_base_m[2] - L
    assert stretch == pytest.approx(100 * force * L / axial_stiffness, rel=1e-6)


def test_small_self_weight_sag_matches_euler_bernoulli():
    # A cantilever under its own weight w per length, gravity across the rod:
    # tip deflection w L^4 / (8 EI), tip slope w L^3 / (6 EI). The rod's density is scaled
    # so that w L^3 / EI = 1e-3 (linear regime, as above: 1e-4 relative tolerance).
    weight_per_length = 1e-3 * EI / L**3
    density = weight_per_length / (9.81 * UNIFORM_ROD.area_m2)
    rod = RodParameters(youngs_modulus_base_pa=2.5e5, youngs_modulus_tip_pa=2.5e5, density_kg_m3=density)
    params = ModelParameters(rod=rod, capsule=CapsuleParameters(mass_kg=0.0),
                             gravity_in_base_m_s2=(0.0, -9.81, 0.0))
    solution = CosseratModel(effects=("gravity",)).solve([0.0, 0.0, 0.0], params)
    deflection = -solution.tip_position_in_base_m[1]
    slope = math.atan2(-solution.tip_rotation_in_base[1, 2], solution.tip_rotation_in_base[2, 2])
    assert deflection == pytest.approx(weight_per_length * L**4 / (8 * EI), rel=1e-4)
    assert slope == pytest.approx(weight_per_length * L**3 / (6 * EI), rel=1e-4)


def test_capsule_weight_acts_at_its_centre_of_mass():
    # A massless rod carrying a point mass at offset c along the tip axis: the load is P
    # at the tip plus a moment P c, so (linear theory) deflection = P L^3/3EI + P c L^2/2EI.
    force = 1e-3 * EI / L**2
    offset = 0.014
    rod = RodParameters(youngs_modulus_base_pa=2.5e5, youngs_modulus_tip_pa=2.5e5, density_kg_m3=1e-12)
    params = ModelParameters(rod=rod, capsule=CapsuleParameters(force / 9.81, (0.0, 0.0, offset)),
                             gravity_in_base_m_s2=(9.81, 0.0, 0.0))
    solution = CosseratModel(effects=("gravity",)).solve([0.0, 0.0, 0.0], params)
    expected = force * L**3 / (3 * EI) + force * offset * L**2 / (2 * EI)
    assert solution.tip_position_in_base_m[0] == pytest.approx(expected, rel=1e-4)


# --- uniform moment: a circular arc -----------------------------------------------------


@pytest.mark.parametrize("bend_rad", [0.5, math.pi, 1.5 * math.pi])
def test_uniform_tip_moment_bends_an_exact_circular_arc(bend_rad):
    # A tip moment M about x gives constant curvature M / EI: p(s) = (0, (cos ks - 1)/k,
    # sin(ks)/k). Classic RK4's global error on this rotation ODE is c L (kh)^4 with a
    # measured c of 0.0065-0.0083 over these bends (a 4th-order method: the coefficient
    # is constant while the error spans four decades); we allow c = 0.02.
    curvature = bend_rad / L
    params = ModelParameters(rod=UNIFORM_ROD, gravity_in_base_m_s2=(0.0, 0.0, 0.0),
                             disturbance=DisturbanceWrench(moment_nm=(curvature * EI, 0.0, 0.0)))
    solution = CosseratModel(effects=()).solve([0.0, 0.0, 0.0], params)
    s = solution.arc_length_m
    expected = np.column_stack([np.zeros_like(s), (np.cos(curvature * s) - 1) / curvature,
                                np.sin(curvature * s) / curvature])
    step_turn = curvature * L / 20
    np.testing.assert_allclose(solution.positions_in_base_m, expected, atol=0.02 * L * step_turn**4)
    # The tip frame is the clamp frame turned by the whole bend about x; same error model
    # (orientation errors measured at 0.004-0.038 (kh)^4 rad over these bends).
    c, s_ = math.cos(bend_rad), math.sin(bend_rad)
    expected_tip = np.array([[1.0, 0.0, 0.0], [0.0, c, -s_], [0.0, s_, c]])
    np.testing.assert_allclose(solution.tip_rotation_in_base, expected_tip, atol=0.1 * step_turn**4)


def test_prb_tip_orientation_under_uniform_moment_is_exact():
    # Each of the n joints turns by l_s * M / EI, so the tip turns by exactly L M / EI
    # whatever the link count: only rounding error remains.
    curvature = 1.0 / L
    params = ModelParameters(rod=UNIFORM_ROD, gravity_in_base_m_s2=(0.0, 0.0, 0.0),
                             disturbance=DisturbanceWrench(moment_nm=(curvature * EI, 0.0, 0.0)))
    for links in (3, 20):
        solution = PrbModel(effects=(), links=links).solve([0.0, 0.0, 0.0], params)
        assert solution.bend_angle_deg == pytest.approx(math.degrees(1.0), abs=1e-9)


# --- large deflection: the elastica --------------------------------------------------------


def elastica_tip(alpha: float) -> tuple[float, float, float]:
    """Exact cantilever elastica under a dead tip load P perpendicular to the clamp, with
    alpha = P L^2 / EI: (tip angle rad, deflection / L, axial projection / L).

    From EI theta'' = -P cos(theta), theta(0) = 0, theta'(L) = 0:
      sqrt(alpha) = int_0^tL dtheta / sqrt(2 (sin tL - sin theta)),
      axial / L = sqrt(2 sin tL / alpha),
      deflection / L = int_0^tL sin theta dtheta / sqrt(2 (sin tL - sin theta)) / sqrt(alpha).
    The integrable endpoint singularity is handled with quad's algebraic weight."""

    def integral(tip_angle: float, numerator) -> float:
        # 1/sqrt(sin a - sin t) = (a - t)^-1/2 * sqrt((a - t) / (sin a - sin t)), smooth;
        # sin a - sin t = 2 cos((a + t)/2) sin((a - t)/2) keeps the ratio accurate.
        def smooth(theta: float) -> float:
            gap = tip_angle - theta
            half_sine = math.sin(0.5 * gap) / (0.5 * gap) if gap > 1e-12 else 1.0
            ratio = 1.0 / (math.cos(0.5 * (tip_angle + theta)) * half_sine)
            return numerator(theta) * math.sqrt(ratio / 2.0)

        value, _ = quad(smooth, 0.0, tip_angle, weight="alg", wvar=(0.0, -0.5), epsabs=1e-13, epsrel=1e-12)
        return value

    tip_angle = brentq(lambda a: integral(a, lambda t: 1.0) - math.sqrt(alpha), 1e-6, math.pi / 2 - 1e-4,
                       xtol=1e-14)
    deflection = integral(tip_angle, math.sin) / math.sqrt(alpha)
    axial = math.sqrt(2.0 * math.sin(tip_angle) / alpha)
    return tip_angle, deflection, axial


def test_elastica_reference_matches_the_published_table_values():
    # Bisshopp & Drucker (1945), Q. Appl. Math. 3(3): for P L^2/EI = 1 the tip deflects by
    # 0.302 L; for 2, by 0.494 L (values as tabulated to three figures in their table and
    # reproduced in Gere & Timoshenko's Mechanics of Materials).
    assert elastica_tip(1.0)[1] == pytest.approx(0.302, abs=1e-3)
    assert elastica_tip(2.0)[1] == pytest.approx(0.494, abs=1e-3)


@pytest.mark.parametrize("alpha", [1.0, 3.0, 10.0])
def test_large_dead_tip_load_matches_the_elastica(alpha):
    # alpha = 10 bends the tip by ~80 degrees. RK4 with 20 steps is 4th order: the
    # measured error is below 1e-5 L at alpha = 10; we allow 2e-5 L (1.4 um).
    tip_angle, deflection, axial = elastica_tip(alpha)
    force = alpha * EI / L**2
    solution = CosseratModel(effects=(TipDeadForce((force, 0.0, 0.0)),)).solve([0.0, 0.0, 0.0], NO_GRAVITY)
    assert solution.tip_position_in_base_m[0] / L == pytest.approx(deflection, abs=2e-5)
    assert solution.tip_position_in_base_m[2] / L == pytest.approx(axial, abs=2e-5)
    assert math.radians(solution.bend_angle_deg) == pytest.approx(tip_angle, abs=2e-5)


# --- linear E profile and gravity: independent collocation solution ------------------------


@pytest.mark.parametrize("jets", [[0.05, 0.0, 0.0], [0.0, 0.08, 0.02], [0.1, 0.0, 0.0]])
def test_linear_modulus_with_gravity_matches_independent_collocation(jets):
    # The HydroJet rod (E 3e5 -> 2e5 Pa, capsule, gravity across) against solve_bvp at
    # tol 1e-8 on an adaptive mesh of hundreds of nodes. Bends reach ~120 degrees, where
    # the measured RK4 error is 5e-4 mm; we allow 2e-3 mm, well under the EM tracker's
    # 0.48 mm.
    params = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
    model = CosseratModel()
    solution = model.solve(jets, params)
    mesh, states = solve_reference(model.build_problem(jets, params))
    np.testing.assert_allclose(solution.tip_position_in_base_m, states[0:3, -1], atol=2e-6)
    np.testing.assert_allclose(solution.tip_rotation_in_base, states[3:12, -1].reshape(3, 3), atol=1e-4)
    # The profile matters: a uniform-modulus rod is measurably elsewhere.
    uniform = ModelParameters(rod=RodParameters(youngs_modulus_base_pa=2.5e5, youngs_modulus_tip_pa=2.5e5),
                              gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
    other = model.solve(jets, uniform)
    assert np.linalg.norm(other.tip_position_in_base_m - solution.tip_position_in_base_m) > 1e-4


@pytest.mark.parametrize("jets", [[0.05, 0.0, 0.0], [0.0, 0.1, 0.04]])
def test_a_shearing_stretching_rod_matches_independent_collocation(jets):
    # The HydroJet rod three times as compliant in shear and extension as a solid
    # section, gravity across: the kernel's strain terms (and their RK4 stages) against
    # solve_bvp's own right-hand side. Tolerances as for the inextensible rod above.
    params = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0), effect_values={"shear_extension.scale": 3.0})
    model = CosseratModel(effects=("gravity", "shear_extension"))
    solution = model.solve(jets, params)
    mesh, states = solve_reference(model.build_problem(jets, params))
    np.testing.assert_allclose(solution.tip_position_in_base_m, states[0:3, -1], atol=2e-6)
    np.testing.assert_allclose(solution.tip_rotation_in_base, states[3:12, -1].reshape(3, 3), atol=1e-4)
    inextensible = CosseratModel().solve(jets, params)
    assert np.linalg.norm(inextensible.tip_position_in_base_m - solution.tip_position_in_base_m) > 5e-4
    # The PRB chain's stretched links converge to the same rod.
    chain = PrbModel(effects=("gravity", "shear_extension")).solve(jets, params)
    assert np.linalg.norm(chain.tip_position_in_base_m - solution.tip_position_in_base_m) < 1e-4


# --- PRB converges to Cosserat -----------------------------------------------------------


def test_prb_converges_to_cosserat_at_second_order():
    # Joints at segment midpoints make the chain a midpoint-rule discretisation of the rod,
    # so the tip error should fall as 1/n^2. We fit the rate over 10..160 links and require
    # it above 1.8 (the fit of a clean 2nd-order method lands at 2.0 +- 0.1).
    params = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
    jets = [0.05, 0.0, 0.02]
    truth = CosseratModel(resolution=400).solve(jets, params).tip_position_in_base_m
    links = np.array([10, 20, 40, 80, 160])
    errors = np.array([np.linalg.norm(PrbModel(links=n).solve(jets, params).tip_position_in_base_m - truth)
                       for n in links])
    rate = -np.polyfit(np.log(links), np.log(errors), 1)[0]
    print(f"PRB->Cosserat tip error (mm) by links {dict(zip(links.tolist(), (errors * 1e3).round(5).tolist()))}; "
          f"rate {rate:.2f}")
    assert rate > 1.8
    assert errors[1] < 1e-4  # 20 links: under 0.1 mm, a fifth of the tracker's accuracy


# --- symmetry of the jet ring ------------------------------------------------------------


@pytest.mark.parametrize("model", [CosseratModel(), PrbModel()], ids=["cosserat", "prb"])
def test_rotating_the_jet_ring_by_120_degrees_with_jets_permuted_gives_the_same_shape(model):
    # Jet i at ring angle a + 120 deg points where jet i - 1 pointed at angle a, so
    # feeding jet i the force jet i - 1 had reproduces the same tip force exactly, even
    # with gravity and the capsule: shapes agree to solver tolerance.
    jets = np.array([0.03, 0.01, 0.05])
    base = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0), jets=JetLayout(ring_angle_rad=0.3))
    turned = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0),
                             jets=JetLayout(ring_angle_rad=0.3 + 2 * math.pi / 3))
    first = model.solve(jets, base)
    second = model.solve(np.roll(jets, 1), turned)
    np.testing.assert_allclose(second.positions_in_base_m, first.positions_in_base_m, atol=1e-12)
    # And without the permutation the shape is different.
    assert np.linalg.norm(model.solve(jets, turned).tip_position_in_base_m - first.tip_position_in_base_m) > 1e-3
