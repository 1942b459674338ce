"""Body-frame sensitivity of the tip pose to model parameters (paper eqs. 2-3).

Column j is the twist (v, omega) of the tip, in the tip frame, per unit change of
parameter j: ``S_j = log(g^-1 g_j)^vee / h_j``. The paper writes ``(g^-1 (g_j - g) /
h_j)^vee``, which is the same to first order; the logarithm keeps the rotation part
exact when a large step is used on purpose.

Step choice: forward differences carry a truncation error ~ h |g''| / 2 and a noise
~ 2 e / h, where e is how far a solve lands from the exact equilibrium (the shooting
tolerance is 1e-10 in nondimensional units, but what reaches the tip is larger for
weakly excited columns). Measured on the HydroJet rod against central differences:
noise dominates below 1e-5 (the axial tip force column, which barely bends the rod, is
off by 5e-3 relative at h = 1e-6 and 5e-4 at 1e-5) while truncation stays under 1e-4
relative up to h = 1e-4. We use ``relative_step = 1e-4`` times the parameter's
magnitude, or its typical scale when the parameter is zero (a disturbance usually
starts at zero): every column then keeps four significant digits.
``tests/test_sensitivity.py`` checks the agreement across steps and the noise floor
below them. Central differences (two solves per column) are available for checks.

The w_d columns are not differences of solves: w_d enters only the tip wrench, so
`ShootingModel.tip_wrench_columns` gets them by the implicit function theorem at the
nominal tip orientation: for the Cosserat rod exactly, from one shot carrying the
tangents (no step at all); for the PRB chain from single shots (no solver noise; the
step then only sets the truncation error).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .effects import EffectParameter
from .models import kernels
from .models.shooting import (PreparedProblem, ShootingModel, Solution, one_kernel_call, parameters_per_row,
                              template_of)
from .params import (DISTURBANCE_NAMES, PARAMETER_SCALES, ModelParameters, get_parameter,
                     with_parameters)

DEFAULT_RELATIVE_STEP = 1e-4


@dataclass(frozen=True)
class Sensitivity:
    """matrix: (6, k) tip twist (v in m, omega in rad, tip frame) per unit of each parameter.
    names: the parameters, in column order. steps: the finite-difference step of each.
    nominal: the nominal solution, carrying an accurate Jacobian: the best seed for
    solves of nearby problems."""

    matrix: np.ndarray
    names: tuple[str, ...]
    steps: np.ndarray
    nominal: Solution

    @property
    def rotation_rows(self) -> np.ndarray:
        """(3, k): tip rotation (rad, tip frame) per unit parameter: eq. 4's S_wd."""
        return self.matrix[3:]


def effect_parameter(model: ShootingModel, name: str) -> EffectParameter | None:
    """The enabled effect parameter called ``effect.parameter``, if any."""
    effect_name, _, parameter_name = name.partition(".")
    for effect in model.effects:
        if effect.name == effect_name:
            for parameter in effect.parameters:
                if parameter.name == parameter_name:
                    return parameter
    return None


def parameter_scale(model: ShootingModel, name: str) -> float:
    """Typical magnitude of a parameter, for steps and optimiser scaling."""
    if name in PARAMETER_SCALES:
        return PARAMETER_SCALES[name]
    parameter = effect_parameter(model, name)
    if parameter is None:
        raise KeyError(f"parameter {name!r} belongs to no enabled effect of {model!r}")
    return max(abs(parameter.upper - parameter.lower) / 10.0, 1e-12)


def tip_twist(nominal: Solution, perturbed: Solution) -> np.ndarray:
    """Twist (v, omega), in the nominal tip frame, taking the nominal tip pose to the
    perturbed one: ``log(g^-1 g_j)^vee``."""
    twist = np.empty(6)
    kernels.body_twist(nominal.tip_rotation_in_base, nominal.tip_position_in_base_m,
                       perturbed.tip_rotation_in_base, perturbed.tip_position_in_base_m, twist)
    return twist


def disturbance_columns(model: ShootingModel, prepared: PreparedProblem, nominal: Solution,
                        components: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, Solution]:
    """(6, k) sensitivity columns for w_d components (0-2 force in N, 3-5 moment in N m)
    with the given steps, on an already packed problem whose solution is ``nominal``;
    and ``nominal`` carrying an accurate Jacobian, the seed for nearby solves."""
    unit = np.where(components < 3, prepared.force_scale_n, prepared.moment_scale_nm)
    columns, seed = model.tip_wrench_columns(prepared, nominal, components, steps / unit)
    return columns / unit, seed


def disturbance_columns_batch(model: ShootingModel, jet_forces_n: np.ndarray,
                              params: ModelParameters | Sequence[ModelParameters], nominals: Sequence[Solution],
                              components: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, list[Solution]]:
    """`disturbance_columns` at the solutions ``nominals`` of rows of jet forces ((k, 3),
    N) under ``params`` (one set, or one per row): (k, 6, len(components)) columns and the
    seeds, in one kernel call when the rows' packings can share it
    (`shooting.one_kernel_call`), else pose by pose. A clamp's path state is taken at
    rest, as `ShootingModel.prepare` without ``previous`` packs it."""
    row_params = parameters_per_row(params, len(jet_forces_n))
    packing = model.kernel_packing(jet_forces_n, row_params)
    if isinstance(packing, list) and not one_kernel_call(packing):
        pairs = [disturbance_columns(model, model.prepare(jets, row), nominal, components, steps)
                 for jets, row, nominal in zip(jet_forces_n, row_params, nominals)]
        return np.array([columns for columns, _ in pairs]), [seed for _, seed in pairs]
    template = template_of(packing)
    unit = np.where(components < 3, template.force_scale_n, template.moment_scale_nm)
    columns, seeds = model.tip_wrench_columns_batch(packing, jet_forces_n, nominals, components, steps / unit)
    return columns / unit, seeds


def parameter_steps(model: ShootingModel, params: ModelParameters, names: Sequence[str],
                    relative_step: float = DEFAULT_RELATIVE_STEP) -> np.ndarray:
    """The finite-difference step of each parameter: ``relative_step`` times its magnitude,
    or its typical scale when smaller (see the module docstring)."""
    steps = np.empty(len(names))
    for column, name in enumerate(names):
        scale = parameter_scale(model, name)  # raises for a name no enabled effect has
        known = effect_parameter(model, name)
        value = get_parameter(params, name, known.default if known else None)
        steps[column] = relative_step * max(abs(value), scale)
    return steps


def sensitivity(model: ShootingModel, jet_forces_n: Sequence[float], params: ModelParameters,
                names: Sequence[str], *, nominal: Solution | None = None, previous: Solution | None = None,
                relative_step: float = DEFAULT_RELATIVE_STEP, central: bool = False) -> Sensitivity:
    """The (6, len(names)) sensitivity matrix at the given jet forces.

    nominal: the solution at ``params`` if already known (it seeds every perturbed solve).
    previous: the path state for path-dependent effects; each perturbed solve starts from
        the same history as the nominal one.
    """
    if not names:
        raise ValueError("sensitivity needs at least one parameter name")
    prepared = model.prepare(jet_forces_n, params, previous)
    if nominal is None:
        nominal = model.solve_prepared(prepared, previous)
    columns = np.empty((6, len(names)))
    steps = parameter_steps(model, params, names, relative_step)
    # w_d only enters the tip wrench: its columns come from one kernel call on the packed
    # problem, by the implicit function theorem (the online estimator's hot path). The
    # same call gives ``nominal`` an accurate Jacobian: the seed of every other solve.
    batched = [column for column, name in enumerate(names) if name in DISTURBANCE_NAMES and not central]
    components = np.array([DISTURBANCE_NAMES.index(names[c]) for c in batched], dtype=np.int64)
    columns[:, batched], seed = disturbance_columns(model, prepared, nominal, components, steps[batched])
    for column, name in enumerate(names):
        if column in batched:
            continue
        step = steps[column]
        twists = []
        for offset in ((step, -step) if central else (step,)):
            if name in DISTURBANCE_NAMES:
                perturbed_problem = prepared.with_disturbance_offset(DISTURBANCE_NAMES.index(name), offset)
                solution = model.solve_prepared(perturbed_problem, seed)
            else:
                known = effect_parameter(model, name)
                value = get_parameter(params, name, known.default if known else None)
                perturbed = with_parameters(params, {name: value + offset})
                solution = model.solve(jet_forces_n, perturbed, previous=previous, warm_start=seed)
            twists.append(tip_twist(nominal, solution))
        columns[:, column] = (twists[0] - twists[1]) / (2 * step) if central else twists[0] / step
    return Sensitivity(columns, tuple(names), steps, seed)
