"""The two kinematic models of the paper, solved by shooting from the tip.

`CosseratModel` is the Kirchhoff-Cosserat rod of eqs. 17-23 (inextensible and
unshearable, v = e3, unless an effect gives the section a strain compliance: then
v = e3 + C n_body, the Reissner rod), integrated with fixed-step RK4. `PrbModel` is the pseudo-rigid-body
chain of eqs. 6-16: n + 1 rigid links and n spherical joints whose stiffness follows
eq. 10 with the linear E profile. Both compose the same effects through `RodProblem`, and
both return a `Solution` with the backbone and the tip pose in the base frame. The
unknown is the tip orientation (three numbers); the tip wrench follows from it and the
residual is the clamp's orientation error (`hydrojet_bench.models.kernels`).

A solve is warm-started from a nearby `Solution` when one is given (its tip orientation
and its solver matrix). A cold start is checked against load ramping (continuation from
the straight rod), whose equilibrium it keeps when the two differ: a direct cold shot
may land on another equilibrium branch, one that no loading of the rod reaches. Cold
starts that fail, and bends past 150 degrees, are ramped outright. When nothing
converges it raises `ConvergenceError`: a model never returns an unconverged shape.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import ClassVar

import numpy as np

from ..effects import Effect, command_line_spec, effect_values, load_effect
from ..errors import ConvergenceError, EffectOutputError
from ..geometry import quat_from_matrix, se3, so3_log
from ..params import ModelParameters, actuation_matrix
from . import kernels
from ..effects.problem import RodProblem

# Shooting residual tolerance (nondimensional, see kernels). 1e-10 of the characteristic
# load puts tip positions within ~1e-11 L of the exact discrete equilibrium, so finite-
# difference sensitivities with relative steps of 1e-5 keep ~5 significant digits.
DEFAULT_TOLERANCE = 1e-10
DEFAULT_MAX_ITERATIONS = 40
# Above this bend a direct cold shot may converge onto a different equilibrium branch
# (a follower-loaded rod curling past a half turn); continuation from the straight rod
# follows the physical branch.
RAMP_BEND_DEG = 150.0
RAMP_SCHEDULES = (4, 16)
# Two converged solves (residual 1e-10) whose tip orientations differ by more than this
# are different equilibria, not one found twice.
SAME_EQUILIBRIUM_RAD = 1e-6
# Past a fold of the load path (a soft tip under gravity and a large jet force) the
# branch that continuation follows ends and the rod snaps to a more bent one, which
# Newton started on the near side cannot reach: the last resort starts further along
# the bend of the nearest solved shape by these angles (degrees).
SNAP_TURNS_DEG = (20.0, 45.0, 90.0)


# Not frozen: a frozen dataclass's __init__ sets each of the 13 fields through
# object.__setattr__, 1 us of a 15 us warm solve; slots make a plain one cost 0.25 us.
@dataclass(slots=True)
class Solution:
    """An equilibrium shape.

    arc_length_m: arc length of each backbone node (Cosserat: integration nodes; PRB: the
        clamp, each joint and the tip).
    positions_in_base_m: (nodes, 3) node positions in the base frame, m.
    rotations_in_base: (nodes, 3, 3) material frames in the base frame (z along the tangent).
    base_wrench_in_base: internal force (N) and moment (N m) at the clamp, base frame.
    base_rotation_vector_rad: how far the clamp itself rotated (nonzero only with a
        compliant clamp); the path state a hysteretic clamp carries to the next solve.
    base_sensor_mounting, tip_sensor_mounting: the mounting rotations effects added
        (sensor orientation = body orientation @ mounting); base_sensor_offset_m: the
        base sensor's origin in the clamp frame, m (`RodProblem.base_sensor_offset_m`).
    """

    model: str
    jet_forces_n: np.ndarray
    arc_length_m: np.ndarray
    positions_in_base_m: np.ndarray
    rotations_in_base: np.ndarray
    base_wrench_in_base: np.ndarray
    base_rotation_vector_rad: np.ndarray
    base_sensor_mounting: np.ndarray
    tip_sensor_mounting: np.ndarray
    iterations: int
    residual: float
    # Solver state for warm starts: Jacobian of the clamp residual w.r.t. the tip rotation.
    jacobian: np.ndarray = field(repr=False)
    base_sensor_offset_m: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @property
    def tip_position_in_base_m(self) -> np.ndarray:
        return self.positions_in_base_m[-1]

    @property
    def tip_rotation_in_base(self) -> np.ndarray:
        return self.rotations_in_base[-1]

    @property
    def tip_pose_in_base(self) -> np.ndarray:
        """4x4 transform of the tip frame in the base frame."""
        return se3(self.tip_rotation_in_base, self.tip_position_in_base_m)

    @property
    def bend_angle_deg(self) -> float:
        """Angle between the clamp axis and the tip tangent, degrees."""
        cosine = np.clip(self.tip_rotation_in_base[2, 2], -1.0, 1.0)
        return float(np.degrees(np.arccos(cosine)))

    def tip_sensor_in_base_sensor(self) -> np.ndarray:
        """Rotation of the tip sensor relative to the base sensor: what two orientation
        sensors measure (paper eq. 24's h), including any mounting rotations. The base
        sensor sits on the fixed holder (the base frame), not on the rod: a compliant
        clamp turns the rod relative to it, which is how such a clamp shows up."""
        return kernels.sensor_rotation(self.base_sensor_mounting, self.rotations_in_base[-1], self.tip_sensor_mounting)

    def with_jacobian(self, jacobian: np.ndarray) -> "Solution":
        """The same shape carrying another solver matrix (`dataclasses.replace` costs more
        than a warm solve)."""
        return Solution(self.model, self.jet_forces_n, self.arc_length_m, self.positions_in_base_m,
                        self.rotations_in_base, self.base_wrench_in_base, self.base_rotation_vector_rad,
                        self.base_sensor_mounting, self.tip_sensor_mounting, self.iterations, self.residual, jacobian,
                        self.base_sensor_offset_m)

    def tip_sensor_position_in_base_sensor_m(self, offset_in_tip_m: np.ndarray) -> np.ndarray:
        """Where a tip sensor at ``offset_in_tip_m`` (tip frame, m) is read in the base
        frame the base sensor's pose gives (m): what a tracker's two positions measure.

        An unstated base mounting M turns the base sensor about its own origin o (clamp
        frame), so the clamp frame read through the profile's mounting is the true one
        turned by M about o: a point p of the true base frame reads M^T (p - o) + o."""
        return tip_sensor_positions_in_base_sensor_m([self], np.asarray(offset_in_tip_m, dtype=float)[np.newaxis])[0]

    def tip_sensor_quaternion(self) -> np.ndarray:
        """`tip_sensor_in_base_sensor` as a quaternion (w, x, y, z)."""
        return quat_from_matrix(self.tip_sensor_in_base_sensor())


def tip_sensors_in_base_sensor(solutions: Sequence[Solution]) -> np.ndarray:
    """(k, 3, 3): `Solution.tip_sensor_in_base_sensor` of each solution, as stacked products
    (a calibration asks for thousands; one call each cost more than its solve's set-up)."""
    if not len(solutions):
        return np.empty((0, 3, 3))
    tip = np.array([solution.rotations_in_base[-1] for solution in solutions])
    return np.swapaxes(_stacked(solutions, "base_sensor_mounting"), -1, -2) @ (
        tip @ _stacked(solutions, "tip_sensor_mounting"))


def _stacked(solutions: Sequence[Solution], name: str) -> np.ndarray:
    """The array field ``name`` (a sensor mounting or offset) of each solution, stacked; or
    the one array when every solution shares it, as the solutions of one problem do (for
    40 solutions the stack cost more than the products it feeds)."""
    first = getattr(solutions[0], name)
    if all(getattr(solution, name) is first for solution in solutions):
        return first
    return np.array([getattr(solution, name) for solution in solutions])


def tip_sensor_positions_in_base_sensor_m(solutions: Sequence[Solution], offsets_in_tip_m: np.ndarray) -> np.ndarray:
    """(k, 3), m: `Solution.tip_sensor_position_in_base_sensor_m` of each solution at its
    row of ``offsets_in_tip_m`` ((k, 3), tip frame, m), as stacked products."""
    if not len(solutions):
        return np.empty((0, 3))
    tip = np.array([solution.positions_in_base_m[-1] for solution in solutions])
    tip_rotation = np.array([solution.rotations_in_base[-1] for solution in solutions])
    base = _stacked(solutions, "base_sensor_mounting")
    origin = _stacked(solutions, "base_sensor_offset_m")
    point = tip + (tip_rotation @ offsets_in_tip_m[:, :, np.newaxis])[:, :, 0]
    return (np.swapaxes(base, -1, -2) @ (point - origin)[:, :, np.newaxis])[:, :, 0] + origin


# slots: a warm solve builds one per call (`with_jets`), and a slots instance costs half.
@dataclass(slots=True)
class PreparedProblem:
    """A `RodProblem` packed for the kernel: nondimensional arrays plus the scales
    (``wrench_scale`` turns a nondimensional force-moment pair into N and N m).

    The disturbance (tip follower wrench) lives only in ``tip``, so sensitivities to w_d
    copy a prepared problem and change two slices instead of rebuilding it."""

    problem: RodProblem
    profile: np.ndarray
    tip: np.ndarray
    base: np.ndarray
    # Cubic section-law coefficient (nondimensional), or None for the plain rod: linear
    # law and no distributed moment (`kernels`).
    beta: float | None
    length_m: float
    force_scale_n: float
    moment_scale_nm: float
    node_arc_length_m: np.ndarray
    wrench_scale: np.ndarray
    # Whether the clamp turns under load (any base compliance): a `Solution` then reports
    # the clamp's rotation, else a shared zero.
    compliant_clamp: bool

    def _replace_tip(self, tip: np.ndarray, base: np.ndarray | None = None) -> "PreparedProblem":
        return PreparedProblem(self.problem, self.profile, tip, self.base if base is None else base, self.beta,
                               self.length_m, self.force_scale_n, self.moment_scale_nm, self.node_arc_length_m,
                               self.wrench_scale, self.compliant_clamp)

    @property
    def jet_forces_n(self) -> np.ndarray:
        """The commanded jet forces (N) packed in ``tip`` (a view)."""
        return self.tip[kernels.TIP_JETS:kernels.TIP_JETS + 3]

    def with_jets(self, jet_forces_n: np.ndarray) -> "PreparedProblem":
        tip = self.tip.copy()
        tip[kernels.TIP_JETS:kernels.TIP_JETS + 3] = jet_forces_n
        return self._replace_tip(tip)

    def with_path_state(self, jet_forces_n: np.ndarray, previous: Solution | None) -> "PreparedProblem":
        """Same problem under other jets (N), the clamp starting from where ``previous``
        left it (at rest without one): what `ShootingModel.build_problem` would pack."""
        tip = self.tip.copy()
        tip[kernels.TIP_JETS:kernels.TIP_JETS + 3] = jet_forces_n
        base = self.base.copy()
        base[kernels.BASE_PREVIOUS_ROTATION:kernels.BASE_PREVIOUS_ROTATION + 3] = (
            0.0 if previous is None else previous.base_rotation_vector_rad)
        return self._replace_tip(tip, base)

    def with_disturbance_moment(self, moment_nm: np.ndarray) -> "PreparedProblem":
        """Same problem with w_d's moment (tip frame, N m) replaced; follower moments that
        effects add are kept (only the change from the parameters' w_d is applied)."""
        tip = self.tip.copy()
        change = np.asarray(moment_nm, dtype=float) - self.problem.params.disturbance.moment_nm
        tip[kernels.TIP_FOLLOWER_MOMENT:kernels.TIP_FOLLOWER_MOMENT + 3] += change / self.moment_scale_nm
        return self._replace_tip(tip)

    def with_disturbance_offset(self, component: int, offset: float) -> "PreparedProblem":
        """Same problem with w_d component ``component`` (0-2 force in N, 3-5 moment in
        N m, tip frame, the order of `DISTURBANCE_NAMES`) increased by ``offset``."""
        tip = self.tip.copy()
        scale = self.force_scale_n if component < 3 else self.moment_scale_nm
        tip[kernels.TIP_FOLLOWER_FORCE + component] += offset / scale
        return self._replace_tip(tip)


class ShootingModel:
    """Shared machinery of the two models; subclasses choose the kernel and the grid.

    effects: effect instances or names (``"gravity"``, ``"path/file.py:Class"``), applied
        in order on top of the nominal problem.
    resolution: Cosserat integration steps, or PRB spherical joints.
    """

    kind: ClassVar[int]
    name: ClassVar[str]

    def __init__(self, effects: Sequence[Effect | str] = ("gravity",), resolution: int = 20,
                 tolerance: float = DEFAULT_TOLERANCE,
                 max_iterations: int = DEFAULT_MAX_ITERATIONS) -> None:
        if resolution < 1:
            raise ValueError(f"resolution must be >= 1, got {resolution}")
        self.effects: tuple[Effect, ...] = tuple(load_effect(e) if isinstance(e, str) else e for e in effects)
        names = [e.name for e in self.effects]
        if len(set(names)) != len(names):
            raise ValueError(f"effects listed twice: {names}")
        self.resolution = resolution
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self._uses_actuation = any(e.uses_actuation for e in self.effects)
        self._cached: PreparedProblem | None = None

    def __repr__(self) -> str:
        return f"{type(self).__name__}(effects={[e.name for e in self.effects]}, resolution={self.resolution})"

    # --- building -----------------------------------------------------------------

    def sample_arc_length_m(self, length_m: float) -> np.ndarray:
        """Where the problem's profiles are sampled: 2 * resolution + 1 points, base to tip."""
        return _even_grid_m(2 * self.resolution + 1, length_m)

    def node_arc_length_m(self, length_m: float) -> np.ndarray:
        raise NotImplementedError

    def build_problem(self, jet_forces_n: Sequence[float], params: ModelParameters,
                      previous: Solution | None = None) -> RodProblem:
        """The nominal problem with every effect applied."""
        jets = np.asarray(jet_forces_n, dtype=float)
        problem = RodProblem.nominal(params, jets, self.sample_arc_length_m(params.rod.length_m))
        if previous is not None:
            problem.previous_base_rotation_vector_rad = previous.base_rotation_vector_rad.copy()
        for effect in self.effects:
            effect.apply(problem, effect_values(effect, params))
        return problem

    def prepare(self, jet_forces_n: Sequence[float], params: ModelParameters,
                previous: Solution | None = None) -> PreparedProblem:
        """Pack the problem for the kernel. The last packing is reused under the same
        parameters unless an effect reads the jet forces: rebuilding costs more than a
        warm solve. A clamp with path state then takes ``previous``'s rotation, which no
        effect reads (`RodProblem.previous_base_rotation_vector_rad`)."""
        jets = _checked_jets(jet_forces_n)
        cached = self._reusable_packing(params)
        if cached is not None:
            if cached.problem.depends_on_previous_state:
                return cached.with_path_state(jets, previous)
            return cached.with_jets(jets)
        prepared = self._pack(self.build_problem(jets, params, previous))
        self._cached = prepared
        return prepared

    def _reusable_packing(self, params: ModelParameters) -> PreparedProblem | None:
        """The last packing, if other jets under ``params`` pack to it with only the jets
        (and a clamp's path state) changed: no effect reads the jets. Equal parameters
        count, not only the same object: a path predictor and its online estimator each
        make their own copy under the step's gravity (0.3 us to compare, a packing ~75)."""
        cached = self._cached
        if (cached is not None and not self._uses_actuation
                and (cached.problem.params is params or cached.problem.params == params)):
            return cached
        return None

    def shares_packing(self, prepared: PreparedProblem) -> bool:
        """Whether other jet forces under the same parameters pack to this problem with
        only the jets changed: no effect reads them and the clamp has no path state."""
        return not self._uses_actuation and not prepared.problem.depends_on_previous_state

    def _pack(self, problem: RodProblem) -> PreparedProblem:
        try:
            return self._pack_checked(problem)
        except EffectOutputError as error:
            raise EffectOutputError(f"{error} (effects: {', '.join(map(command_line_spec, self.effects))})") from None

    def _pack_checked(self, problem: RodProblem) -> PreparedProblem:
        params = problem.params
        length = params.rod.length_m
        reference_stiffness = params.rod.youngs_modulus_base_pa * params.rod.second_moment_m4
        moment_scale = reference_stiffness / length
        force_scale = moment_scale / length
        samples = len(problem.arc_length_m)
        profile = np.empty((samples, kernels.PROFILE_COLUMNS))
        tip = np.empty(kernels.TIP_SIZE)
        base = np.empty(kernels.BASE_SIZE)
        distributed_moment = _floats(problem.distributed_moment_in_body_nm_m, (samples, 3),
                                     "distributed_moment_in_body_nm_m")
        strain_compliance = _floats(problem.strain_compliance_in_body_1_n, (samples, 3),
                                    "strain_compliance_in_body_1_n")
        status = kernels.pack(
            _floats(problem.bending_stiffness_x_nm2, (samples,), "bending_stiffness_x_nm2"),
            _floats(problem.bending_stiffness_y_nm2, (samples,), "bending_stiffness_y_nm2"),
            _floats(problem.torsional_stiffness_nm2, (samples,), "torsional_stiffness_nm2"),
            _floats(problem.intrinsic_curvature_in_body_1_m, (samples, 3), "intrinsic_curvature_in_body_1_m"),
            _floats(problem.distributed_force_in_base_n_m, (samples, 3), "distributed_force_in_base_n_m"),
            distributed_moment,
            strain_compliance,
            _floats(problem.tip_follower_force_in_tip_n, (3,), "tip_follower_force_in_tip_n"),
            _floats(problem.tip_follower_moment_in_tip_nm, (3,), "tip_follower_moment_in_tip_nm"),
            _floats(problem.tip_dead_force_in_base_n, (3,), "tip_dead_force_in_base_n"),
            _floats(problem.tip_dead_moment_in_base_nm, (3,), "tip_dead_moment_in_base_nm"),
            _floats(problem.tip_dead_force_arm_m_n, (3, 3), "tip_dead_force_arm_m_n"),
            actuation_matrix(float(problem.jet_ring_angle_rad)), _floats(problem.jet_gains, (3,), "jet_gains"),
            _floats(problem.jet_forces_n, (3,), "jet_forces_n"),
            _floats(problem.base_compliance_rad_per_nm, (3,), "base_compliance_rad_per_nm"),
            float(problem.base_play_rad),
            _floats(problem.previous_base_rotation_vector_rad, (3,), "previous_base_rotation_vector_rad"),
            reference_stiffness, length, force_scale, moment_scale, profile, tip, base)
        if status == kernels.BAD_PROFILE:
            raise EffectOutputError("effects produced a non-finite profile, a non-positive stiffness or a negative "
                                    "strain compliance")
        if status == kernels.BAD_TIP_OR_CLAMP:
            raise EffectOutputError("effects produced a non-finite tip load or clamp parameter")
        # None selects the kernels' plain-rod specialisation (see `kernels`).
        plain = problem.cubic_stiffening_m2 == 0.0 and not distributed_moment.any() and not strain_compliance.any()
        beta = None if plain else problem.cubic_stiffening_m2 / length**2
        return PreparedProblem(problem, profile, tip, base, beta,
                               length, force_scale, moment_scale, self.node_arc_length_m(length),
                               np.array((force_scale, force_scale, force_scale, moment_scale, moment_scale,
                                         moment_scale)),
                               bool(base[kernels.BASE_COMPLIANCE:kernels.BASE_COMPLIANCE + 3].any()))

    # --- solving ------------------------------------------------------------------

    def solve(self, jet_forces_n: Sequence[float], params: ModelParameters, *,
              previous: Solution | None = None, warm_start: Solution | None = None) -> Solution:
        """Equilibrium for the given jet forces (N).

        previous: the solution before this one along the path; it carries the clamp's
            state (hysteresis) and, unless ``warm_start`` is given, seeds the solver.
        warm_start: a nearby solution used only to seed the solver; it never changes the
            answer, only how fast it is found.
        """
        seed = warm_start if warm_start is not None else previous
        cached = self._reusable_packing(params)
        if cached is not None and self.shares_packing(cached) and seeds_kernel(seed):
            # The usual warm solve, other jets under the same parameters: one kernel call
            # on the last packing, which `prepare` would copy only to change the jets.
            jets = _checked_jets(jet_forces_n)
            work = self.workspace(cached)
            if self._run(cached, jets, seed.tip_rotation_in_base, 1.0, work, seed.jacobian):
                return self.solution_from(cached, work, jets)
            return self._solve_unseeded(cached.with_jets(jets), seed, work)
        return self.solve_prepared(self.prepare(jet_forces_n, params, previous), seed)

    def solve_prepared(self, prepared: PreparedProblem, warm_start: Solution | None = None,
                       predicted_tip_turn_rad: np.ndarray | None = None) -> Solution:
        """Solve a packed problem; see `solve`. ``predicted_tip_turn_rad``: how far the tip
        is expected to turn from ``warm_start``'s (a rotation vector in its tip frame, from
        a sensitivity): the solver then starts there, with ``warm_start``'s Jacobian."""
        work = self.workspace(prepared)
        if seeds_kernel(warm_start):
            rotation = (warm_start.tip_rotation_in_base if predicted_tip_turn_rad is None
                        else kernels.turned(warm_start.tip_rotation_in_base, predicted_tip_turn_rad))
            if self._run(prepared, prepared.jet_forces_n, rotation, 1.0, work, warm_start.jacobian):
                return self.solution_from(prepared, work)
        return self._solve_unseeded(prepared, warm_start, work)

    def _solve_unseeded(self, prepared: PreparedProblem, warm_start: Solution | None, work: Workspace) -> Solution:
        """`solve_prepared` once a warm start is missing or failed: a cold start, then load
        ramping, then a search past a fold."""
        if self._run(prepared, prepared.jet_forces_n, np.eye(3), 1.0, work):
            solution = self.solution_from(prepared, work)
            if solution.bend_angle_deg <= RAMP_BEND_DEG:
                return self._on_loading_branch(prepared, solution)
        nearest = [] if warm_start is None else [warm_start.tip_rotation_in_base]
        for stages in RAMP_SCHEDULES:
            ramped, last_solved = self._ramp(prepared, stages, work)
            if ramped is not None:
                return ramped
            if last_solved is not None:
                nearest.append(last_solved)
        snapped = self._snap(prepared, nearest, work)
        if snapped is not None:
            return snapped
        raise ConvergenceError(
            f"{self.name} model did not converge for jet forces "
            f"{prepared.jet_forces_n.tolist()} N (residual {work.info[2]:.3g} "
            f"after a direct solve, load ramping in up to {RAMP_SCHEDULES[-1]} stages and a search past a fold)")

    def tip_wrench_columns(self, prepared: PreparedProblem, nominal: Solution, components: np.ndarray,
                           steps: np.ndarray) -> tuple[np.ndarray, Solution]:
        """(6, k) tip twists per nondimensional step of tip follower wrench components
        (0-2 force, 3-5 moment) at the converged ``nominal`` solution of ``prepared``, in
        one kernel call (`kernels.tip_wrench_sensitivity`), and ``nominal`` carrying the
        accurate Jacobian computed on the way. Used by `sensitivity`."""
        jacobian = np.empty((kernels.UNKNOWNS, kernels.UNKNOWNS))
        columns = np.empty((6, len(components)))
        if not kernels.tip_wrench_sensitivity(self.kind, self.resolution, nominal.tip_rotation_in_base,
                                              prepared.profile, prepared.tip, prepared.base, prepared.beta,
                                              components, steps, prepared.length_m, jacobian, columns):
            raise ConvergenceError(f"{self.name} model: the shooting Jacobian is singular or a shot diverged "
                                   "at this solution; no sensitivity")
        return columns, nominal.with_jacobian(jacobian)

    def tip_wrench_columns_batch(self, packing: PreparedProblem | list[PreparedProblem], jet_forces_n: np.ndarray,
                                 nominals: Sequence[Solution], components: np.ndarray,
                                 steps: np.ndarray) -> tuple[np.ndarray, list[Solution]]:
        """`tip_wrench_columns` at the solutions ``nominals`` of rows of jet forces ((k, 3),
        N) packed as ``packing`` (`kernel_packing`), in one kernel call: (k, 6,
        len(components)) columns and the seeds. Rows packed apart must share one kernel
        call (`one_kernel_call`)."""
        count = len(jet_forces_n)
        jacobians = np.empty((count, kernels.UNKNOWNS, kernels.UNKNOWNS))
        columns = np.empty((count, 6, len(components)))
        references = np.array([nominal.rotations_in_base[-1] for nominal in nominals])
        template = template_of(packing)
        profiles, tips, bases, _ = _kernel_rows(packing, jet_forces_n)
        if kernels.tip_wrench_sensitivity_batch(self.kind, self.resolution, references, profiles, tips, bases,
                                                template.beta, components, steps, template.length_m, jacobians,
                                                columns) < count:
            raise ConvergenceError(f"{self.name} model: the shooting Jacobian is singular or a shot diverged "
                                   "at one of these solutions; no sensitivity")
        return columns, [nominal.with_jacobian(jacobian) for nominal, jacobian in zip(nominals, jacobians)]

    def solve_batch(self, jet_forces_n: np.ndarray, params: ModelParameters | Sequence[ModelParameters],
                    warm_starts: Sequence[Solution | None], seed: Solution | None = None, *,
                    along_path: bool = False) -> list[Solution]:
        """Equilibria for rows of jet forces ((k, 3), N) under one set of parameters, or
        one per row (a recording's steps each under the gravity its base sensor read): row
        i is ``solve(jet_forces_n[i], params[i], warm_start=...)`` from ``warm_starts[i]``
        or, where that is None, from row i - 1's solution (row 0: ``seed``), bit for
        bit; with ``along_path`` row i - 1's solution (row 0: ``seed``) is also its
        ``previous=`` (path state). The warm solves of a run of rows share one kernel
        call (`kernels.solve_batch`) instead of each paying its own Python set-up, which
        is most of a warm solve's time in a calibration; so do the rows whose packings
        differ (under their own parameters, or an effect that reads the jets: each
        distinct one packed in Python once) and the rows along the path (the clamp's
        state carried in the kernel). A row the warm solve does not finish, or with
        nothing to start from, takes `solve`'s whole path (cold start, ramping); so does
        every row when the rows' packings differ in more than the kernel takes per row
        (`one_kernel_call`)."""
        jets = np.asarray(jet_forces_n, dtype=float)
        if jets.ndim != 2 or jets.shape[1] != 3 or len(warm_starts) != len(jets):
            raise ValueError(f"jet_forces_n must be (k, 3) with one warm start per row, got shape {jets.shape} "
                             f"and {len(warm_starts)} warm starts")
        row_params = parameters_per_row(params, len(jets))
        if len(row_params) != len(jets):
            raise ValueError(f"{len(row_params)} parameter sets for {len(jets)} rows of jet forces")
        if not np.all(np.isfinite(jets)):
            raise ValueError("jet_forces_n must be finite")
        solutions: list[Solution] = []
        if not len(jets):
            return solutions
        packing = self.kernel_packing(jets, row_params)
        packings = packing if isinstance(packing, list) else None
        template = template_of(packing)
        batched = packings is None or one_kernel_call(packings)
        carry = along_path and template.problem.depends_on_previous_state
        previous = seed
        while len(solutions) < len(jets):
            row = len(solutions)
            start = warm_starts[row] if warm_starts[row] is not None else previous
            if not batched or not seeds_kernel(start):
                previous = self.solve(jets[row], row_params[row], previous=previous if along_path else None,
                                      warm_start=start)
                solutions.append(previous)
                continue
            # Rows from here whose own warm start (if any) can seed the kernel.
            end = row + 1
            while end < len(jets) and (warm_starts[end] is None or seeds_kernel(warm_starts[end])):
                end += 1
            run = template if packings is None else packings[row:end]
            solved = self._solve_run(run, jets[row:end], [start, *warm_starts[row + 1:end]],
                                     previous if carry else None, carry)
            solutions.extend(solved)
            if len(solved) < end - row:
                # The kernel stopped at this row: the full path, from the same start.
                failed = len(solutions)
                before = solutions[-1] if failed > row else previous
                if failed > row:
                    start = warm_starts[failed] if warm_starts[failed] is not None else before
                solutions.append(self.solve(jets[failed], row_params[failed],
                                            previous=before if along_path else None, warm_start=start))
            previous = solutions[-1]
        return solutions

    def kernel_packing(self, jets: np.ndarray,
                       row_params: Sequence[ModelParameters]) -> PreparedProblem | list[PreparedProblem]:
        """The packing a kernel call over rows of jet forces ((k, 3), N) under their
        parameters takes: one that every row shares but for its jets (one parameters
        object, no effect reads the jets), else each row's own (`row_packings`)."""
        if self._uses_actuation or any(row is not row_params[0] for row in row_params):
            return self.row_packings(jets, row_params)
        return self.prepare(jets[0], row_params[0])

    def row_packings(self, jets: np.ndarray, row_params: Sequence[ModelParameters]) -> list[PreparedProblem]:
        """Each row's packing for rows of jet forces ((k, 3), N) under their parameters,
        built once per parameters object and, if an effect reads the jets, per command (a
        sweep passes each command on its way up and down, and repeats); other rows under
        the same parameters share its profile and clamp, with their own jets."""
        made: dict[tuple[int, bytes], PreparedProblem] = {}
        packings = []
        for row, params in zip(jets, row_params):
            key = (id(params), row.tobytes() if self._uses_actuation else b"")
            if key not in made:
                made[key] = self.prepare(row, params)
            elif not self._uses_actuation:
                packings.append(made[key].with_jets(row))
                continue
            packings.append(made[key])
        return packings

    def _solve_run(self, packing: PreparedProblem | list[PreparedProblem], jets: np.ndarray,
                   warm_starts: Sequence[Solution | None], previous: Solution | None = None,
                   carry_clamp: bool = False) -> list[Solution]:
        """One `kernels.solve_batch` call over rows of jets; the first row must have a warm
        start. ``packing``: the problem every row shares but for its jets, or each row's
        own (`row_packings`, `one_kernel_call`). With ``carry_clamp`` each row's clamp
        starts where the row before left it, the first row's where ``previous`` did (at
        rest without one). Returns the solutions up to the first row that did not converge."""
        count = len(jets)
        template = template_of(packing)
        profiles, tips, bases, problems = _kernel_rows(packing, jets)
        if carry_clamp:
            bases = bases.copy()
            bases[0, kernels.BASE_PREVIOUS_ROTATION:kernels.BASE_PREVIOUS_ROTATION + 3] = (
                0.0 if previous is None else previous.base_rotation_vector_rad)
        references = np.empty((count, kernels.UNKNOWNS, kernels.UNKNOWNS))
        jacobians = np.empty((count, kernels.UNKNOWNS, kernels.UNKNOWNS))
        seeded = np.zeros(count, dtype=bool)
        for row, start in enumerate(warm_starts):
            if start is not None:
                references[row] = start.rotations_in_base[-1]
                jacobians[row] = start.jacobian
                seeded[row] = True
        nodes = len(template.node_arc_length_m)
        nodes_p = np.empty((count, nodes, 3))
        nodes_r = np.empty((count, nodes, 3, 3))
        base_wrench = np.empty((count, 6))
        clamp_rotation = np.empty((count, 3))
        info = np.empty((count, 4))
        solved = kernels.solve_batch(self.kind, self.resolution, references, jacobians, seeded, profiles, tips, bases,
                                     carry_clamp, template.beta, self.tolerance, self.max_iterations,
                                     template.length_m, template.wrench_scale, nodes_p, nodes_r, base_wrench,
                                     clamp_rotation, info)
        arc_length = template.node_arc_length_m
        # Iterating over the arrays makes each row's views in C: a diagnosis builds some
        # 100,000 of these, and indexing row by row cost half of that again.
        clamps = clamp_rotation[:solved] if template.compliant_clamp else itertools.repeat(_NO_ROTATION)
        return [Solution(self.name, jets, arc_length, positions, rotations, wrench, clamp, problem.base_sensor_mounting,
                         problem.tip_sensor_mounting, int(status[1]), status[2], jacobian,
                         problem.base_sensor_offset_m)
                for jets, positions, rotations, wrench, clamp, status, jacobian, problem in zip(
                    tips[:solved, kernels.TIP_JETS:kernels.TIP_JETS + 3], nodes_p[:solved], nodes_r[:solved],
                    base_wrench[:solved], clamps, info[:solved].tolist(), jacobians[:solved], problems)]

    def _ramp(self, prepared: PreparedProblem, stages: int,
              work: Workspace) -> tuple[Solution | None, np.ndarray | None]:
        """Continuation: scale every load from 1/stages up to 1, each stage seeded by the
        last. Returns the solution, or None and the tip orientation of the last solved
        stage (None if none was)."""
        jets = prepared.jet_forces_n
        rotation, jacobian = np.eye(3), None
        last_solved = None
        for stage in range(1, stages + 1):
            if not self._run(prepared, jets, rotation, stage / stages, work, jacobian):
                return None, last_solved
            # The kernel left the reference at this stage's tip orientation: the next
            # stage starts there, from this stage's matrix.
            last_solved = work.reference.copy()
            rotation, jacobian = work.reference, work.jacobian
        return self.solution_from(prepared, work), None

    def _on_loading_branch(self, prepared: PreparedProblem, direct: Solution) -> Solution:
        """``direct``, a cold shot's equilibrium, or the one that load ramping from the
        straight rod reaches when they differ. Under a large tip load (a heavy capsule on a
        soft horizontal rod, a compressive w_d) there may be several equilibria, and the
        straight seed can land on one that no loading of the rod leads to (c. 110 deg of
        bend where ramping gives 80): every later warm start would follow it."""
        ramped, _ = self._ramp(prepared, RAMP_SCHEDULES[0], self.workspace(prepared))
        if ramped is None:
            return direct
        turn = so3_log(direct.tip_rotation_in_base.T @ ramped.tip_rotation_in_base)
        return direct if float(np.linalg.norm(turn)) < SAME_EQUILIBRIUM_RAD else ramped

    def _snap(self, prepared: PreparedProblem, nearest: Sequence[np.ndarray], work: Workspace) -> Solution | None:
        """Full load, started from each of the ``nearest`` solved tip orientations turned
        further about its own bend axis (`SNAP_TURNS_DEG`): the branch past a fold."""
        for rotation in nearest:
            bend = so3_log(rotation)
            angle = float(np.linalg.norm(bend))
            if angle < 1e-6:
                continue  # straight: no bend to follow
            for turn_deg in SNAP_TURNS_DEG:
                # The bend's rotation vector is the same in the tip frame as in the base's.
                reference = kernels.turned(rotation, bend * (math.radians(turn_deg) / angle))
                if self._run(prepared, prepared.jet_forces_n, reference, 1.0, work):
                    return self.solution_from(prepared, work)
        return None

    def _run(self, prepared: PreparedProblem, jet_forces_n: np.ndarray, seed_rotation: np.ndarray,
             load_scale: float, work: Workspace, seed_jacobian: np.ndarray | None = None) -> bool:
        """`kernels.solve_from`: ``prepared`` under the jets ``jet_forces_n`` (N) and
        ``load_scale`` of every load, from the tip rotation ``seed_rotation`` and the
        matrix ``seed_jacobian`` if given (else built); the seeds are not changed unless
        they are ``work``'s own. Whether it converged."""
        have_jacobian = seed_jacobian is not None
        kernels.solve_from(self.kind, self.resolution, seed_rotation, seed_jacobian if have_jacobian else work.jacobian,
                           have_jacobian, jet_forces_n, prepared.profile, prepared.tip, prepared.base, prepared.beta,
                           load_scale, self.tolerance, self.max_iterations, prepared.length_m, prepared.wrench_scale,
                           work.nodes_p, work.nodes_r, work.base_wrench, work.clamp_rotation, work.reference,
                           work.jacobian, work.info)
        return work.info[0] == kernels.CONVERGED

    @staticmethod
    def workspace(prepared: PreparedProblem) -> Workspace:
        """Fresh output buffers for one solve of ``prepared``."""
        return Workspace(len(prepared.node_arc_length_m))

    def solution_from(self, prepared: PreparedProblem, work: Workspace,
                      jet_forces_n: np.ndarray | None = None) -> Solution:
        """The `Solution` a converged kernel solve of ``prepared`` left in ``work`` (kept,
        not copied), under ``prepared``'s jets or the given ones (N, kept too)."""
        problem = prepared.problem
        if jet_forces_n is None:
            jet_forces_n = prepared.jet_forces_n.copy()
        return Solution(
            self.name, jet_forces_n, prepared.node_arc_length_m, work.nodes_p, work.nodes_r, work.base_wrench,
            work.clamp_rotation if prepared.compliant_clamp else _NO_ROTATION, problem.base_sensor_mounting,
            problem.tip_sensor_mounting, int(work.info[1]), float(work.info[2]), work.jacobian,
            problem.base_sensor_offset_m,
        )


@lru_cache(maxsize=16)
def _even_grid_m(points: int, length_m: float) -> np.ndarray:
    """``points`` evenly spaced arc lengths from 0 to ``length_m`` (m), shared and read-only:
    every packing asks for two, and a diagnosis packs thousands of problems."""
    grid = np.linspace(0.0, length_m, points)
    grid.flags.writeable = False
    return grid


@lru_cache(maxsize=16)
def _prb_nodes_m(joints: int, length_m: float) -> np.ndarray:
    """Arc lengths (m) of the PRB chain's nodes: the clamp, each joint at the middle of
    its segment, the tip; shared and read-only like `_even_grid_m`."""
    nodes = np.concatenate([[0.0], (np.arange(joints) + 0.5) / joints, [1.0]]) * length_m
    nodes.flags.writeable = False
    return nodes


def _floats(values, shape: tuple[int, ...], field_name: str) -> np.ndarray:
    """A `RodProblem` field as the C-contiguous float array of ``shape`` a kernel takes
    (broadcast if an effect left it a scalar or a row): the kernels index without
    bounds checks, so a wrong shape is refused here, by name."""
    array = np.ascontiguousarray(values, dtype=float)
    if array.shape != shape:
        try:
            array = np.ascontiguousarray(np.broadcast_to(array, shape))
        except ValueError:
            raise EffectOutputError(f"effects left RodProblem.{field_name} with shape {array.shape}, "
                                    f"expected {shape}") from None
    return array


def _kernel_rows(packing: PreparedProblem | Sequence[PreparedProblem],
                 jet_forces_n: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, Iterable[RodProblem]]:
    """The kernel's inputs for rows of jet forces ((k, 3), N): profiles and clamps (one row
    when all rows share them, uncopied), tip loads and each row's problem. ``packing``:
    one problem all rows share but for their jets, or each row's own (`row_packings`)."""
    if isinstance(packing, PreparedProblem):
        return (packing.profile[np.newaxis], _tips(packing, jet_forces_n), packing.base[np.newaxis],
                itertools.repeat(packing.problem))
    first = packing[0]
    profiles = (first.profile[np.newaxis] if all(row.profile is first.profile for row in packing)
                else np.array([row.profile for row in packing]))
    bases = (first.base[np.newaxis] if all(row.base is first.base for row in packing)
             else np.array([row.base for row in packing]))
    return profiles, np.array([row.tip for row in packing]), bases, [row.problem for row in packing]


def parameters_per_row(params: ModelParameters | Sequence[ModelParameters], rows: int) -> list[ModelParameters]:
    """One parameter set for each of ``rows`` rows: ``params`` repeated, or as given."""
    return [params] * rows if isinstance(params, ModelParameters) else list(params)


def template_of(packing: PreparedProblem | Sequence[PreparedProblem]) -> PreparedProblem:
    """The packing whose section law, length and scales a kernel call over rows packed as
    ``packing`` (`ShootingModel.kernel_packing`) takes for all of them."""
    return packing if isinstance(packing, PreparedProblem) else packing[0]


def one_kernel_call(packings: Sequence[PreparedProblem]) -> bool:
    """Whether rows packed apart can still share one `kernels.solve_batch` call: the
    kernel takes one section law, one length and one set of scales for all of them."""
    first = packings[0]
    return all(row.beta == first.beta and row.length_m == first.length_m
               and row.compliant_clamp == first.compliant_clamp
               and np.array_equal(row.wrench_scale, first.wrench_scale) for row in packings[1:])


def _tips(template: PreparedProblem, jet_forces_n: np.ndarray) -> np.ndarray:
    """(k, TIP_SIZE): ``template``'s tip loads under each row of jet forces (N)."""
    tips = np.repeat(template.tip[np.newaxis], len(jet_forces_n), axis=0)
    tips[:, kernels.TIP_JETS:kernels.TIP_JETS + 3] = jet_forces_n
    return tips


def _checked_jets(jet_forces_n: Sequence[float]) -> np.ndarray:
    """The jet forces (N) as a new array of 3 floats, or ValueError."""
    jets = np.array(jet_forces_n, dtype=float)
    if jets.shape != (3,) or not all(map(math.isfinite, jets.tolist())):
        raise ValueError(f"jet_forces_n must be 3 finite numbers, got {jet_forces_n!r}")
    return jets


def seeds_kernel(solution: Solution | None) -> bool:
    """Whether a solution can start a warm solve: it carries the solver's matrix."""
    return solution is not None and solution.jacobian.shape == (kernels.UNKNOWNS, kernels.UNKNOWNS)


_NO_ROTATION = np.zeros(3)
_NO_ROTATION.flags.writeable = False


class Workspace:
    """Output buffers of one solve (the kernel writes the shape, the clamp's wrench and
    rotation, its tip frame and its matrix; the `Solution` keeps them)."""

    __slots__ = ("nodes_p", "nodes_r", "base_wrench", "clamp_rotation", "reference", "jacobian", "info")

    def __init__(self, nodes: int) -> None:
        self.nodes_p = np.empty((nodes, 3))
        self.nodes_r = np.empty((nodes, 3, 3))
        self.base_wrench = np.empty(6)
        self.clamp_rotation = np.empty(3)
        self.reference = np.empty((3, 3))
        self.jacobian = np.empty((kernels.UNKNOWNS, kernels.UNKNOWNS))
        self.info = np.empty(4)


class CosseratModel(ShootingModel):
    """Cosserat rod (eqs. 17-23), RK4 with ``resolution`` steps (default 20, as the paper)."""

    kind = kernels.COSSERAT
    name = "cosserat"

    def node_arc_length_m(self, length_m: float) -> np.ndarray:
        return _even_grid_m(self.resolution + 1, length_m)


class PrbModel(ShootingModel):
    """Pseudo-rigid-body chain (eqs. 6-16) of ``links`` rigid links (default 20, the
    paper's choice) joined by ``links - 1`` spherical joints.

    Joint j sits at s = (j - 1/2) L / n, n = links - 1, in the middle of the rod segment it
    lumps; the end links are half links. Its stiffness is eq. 10's, K_j = E(s_j) I / l_s
    with l_s = L / n the lumped length. (Eq. 10 as printed carries a factor 2, 2 E I /
    l_s; with it the chain converges to a rod twice as stiff as the Cosserat model as the
    links multiply, which the paper's near-equal calibrated moduli for the two models
    rule out, so we read it as a typesetting slip.) The spring acts on the joint's
    rotation vector theta_j, with the joint's axes in its mid-rotation frame, halfway
    between the two links (R_j = R_{j-1} exp(theta_j / 2)): theta_j = K_j^-1 R_j^T m_j.
    The joint torque of eqs. 14-15, J^T w, is exactly that moment about the joint's axes,
    so the chain satisfies eq. 16's K theta = tau_f + tau_a (tested against explicit
    Jacobians). The paper only says the axes are attached to the joint; the middle is
    the choice that makes the chain converge to the rod at second order in the link
    count for any section (axes fixed in the distal link give first order once the
    section is anisotropic). Equilibrium is found by the same Newton iteration as the
    Cosserat model, shooting from the tip: three unknowns (the tip orientation) instead
    of 3n joint angles.
    """

    kind = kernels.PRB
    name = "prb"

    def __init__(self, effects: Sequence[Effect | str] = ("gravity",), links: int = 20,
                 tolerance: float = DEFAULT_TOLERANCE, max_iterations: int = DEFAULT_MAX_ITERATIONS) -> None:
        if links < 2:
            raise ValueError(f"links must be >= 2, got {links}")
        super().__init__(effects, resolution=links - 1, tolerance=tolerance, max_iterations=max_iterations)

    @property
    def links(self) -> int:
        return self.resolution + 1

    def __repr__(self) -> str:
        return f"PrbModel(effects={[e.name for e in self.effects]}, links={self.links})"

    def node_arc_length_m(self, length_m: float) -> np.ndarray:
        return _prb_nodes_m(self.resolution, length_m)
