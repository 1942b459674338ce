"""The effect interface: a named piece of physics that both models compose.

An effect edits a `RodProblem` (see `hydrojet_bench.effects.problem` for everything it may
change) given the values of its own parameters. It never touches a solver, so the same
effect works in the Cosserat and the PRB model, and a user can write one in a file of
their own and load it as ``path/to/my_effect.py:ClassName``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from .problem import RodProblem
    from ..params import ModelParameters


@dataclass(frozen=True)
class EffectParameter:
    """One calibratable parameter of an effect: default value, bounds and unit (SI)."""

    name: str
    default: float
    lower: float
    upper: float
    unit: str
    description: str

    def __post_init__(self) -> None:
        for label in ("default", "lower", "upper"):
            if not math.isfinite(getattr(self, label)):
                raise ValueError(f"effect parameter {self.name!r}: {label} must be finite")
        if not self.lower <= self.default <= self.upper:
            raise ValueError(f"effect parameter {self.name!r}: default {self.default} is outside "
                             f"[{self.lower}, {self.upper}]")


@runtime_checkable
class Effect(Protocol):
    """name: canonical identifier (``gravity``, ``jet_gain``, ...).
    explanation: one paragraph on the physics, shown to the user.
    parameters: the effect's own parameters; their values live in
        `ModelParameters.effect_values` under ``"<name>.<parameter>"``.
    uses_actuation: True when `apply` reads ``problem.jet_forces_n`` (the model then
        rebuilds the problem for every jet command instead of reusing it).
    identified_by: the rows a calibration needs to see the effect: `CALIBRATION_POSES`
        (the static poses alone) or `SWEEPS` (the poses and the sweeps: an effect that
        acts through the path, or through how hard the jets push, which the poses
        sample too sparsely). Optional for a user's effect (`identifying_rows`).
    """

    name: ClassVar[str]
    explanation: ClassVar[str]
    parameters: ClassVar[tuple[EffectParameter, ...]]
    uses_actuation: ClassVar[bool]

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        """Edit ``problem`` in place; ``values`` maps each parameter name to its value."""
        ...


# What `Effect.identified_by` may say; also `calibrate --fit-on`'s choices, with "all".
CALIBRATION_POSES, SWEEPS = "calibration", "sweeps"


def identifying_rows(effect: Effect) -> str:
    """``effect.identified_by``; for a user's effect that does not say, `SWEEPS` when it
    reads the jet forces, else `CALIBRATION_POSES`."""
    return getattr(effect, "identified_by", SWEEPS if effect.uses_actuation else CALIBRATION_POSES)


def effect_values(effect: Effect, params: ModelParameters) -> dict[str, float]:
    """The effect's parameter values from ``params``, defaults filled in."""
    return {p.name: params.effect_value(f"{effect.name}.{p.name}", p.default) for p in effect.parameters}


def qualified_parameter_names(effect: Effect) -> tuple[str, ...]:
    return tuple(f"{effect.name}.{p.name}" for p in effect.parameters)


def scale_modulus(problem: RodProblem, factor: float | np.ndarray) -> None:
    """Multiply the section's bending and torsional stiffness by ``factor`` (a scalar or
    one value per sample point): a change of E, which carries G = E / (2 (1 + nu)) along.
    Assigns new arrays, so arrays shared with another problem are left alone."""
    problem.bending_stiffness_x_nm2 = problem.bending_stiffness_x_nm2 * factor
    problem.bending_stiffness_y_nm2 = problem.bending_stiffness_y_nm2 * factor
    problem.torsional_stiffness_nm2 = problem.torsional_stiffness_nm2 * factor
