"""The effect interface: a named piece of physics that both models compose.

An effect edits a `RodProblem` (see `hydrojet_bench.effects.problem` for everything it may
change) given the values of its own parameters. It never touches a solver, so the same
effect works in the Cosserat and the PRB model, and a user can write one in a file of
their own and load it as ``path/to/my_effect.py:ClassName``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, ClassVar, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from .problem import RodProblem
    from ..params import ModelParameters


@dataclass(frozen=True)
class EffectParameter:
    """One calibratable parameter of an effect: default value, bounds and unit (SI).

    lower/upper: the range a fit searches first, the values a rig plausibly shows.
    physical_lower/physical_upper: the physical limits, past which the parameter no
    longer describes the effect (or the model no longer solves); None: the search
    bound is the limit. limit_reason: why the limits sit where they do. A fit that
    ends on a search bound is refitted up to the physical limit (`at_physical_limits`).
    """

    name: str
    default: float
    lower: float
    upper: float
    unit: str
    description: str
    physical_lower: float | None = None
    physical_upper: float | None = None
    limit_reason: str = ""

    def __post_init__(self) -> None:
        for label in ("default", "lower", "upper", "physical_lower", "physical_upper"):
            value = getattr(self, label)
            if value is not None and not math.isfinite(value):
                raise ValueError(f"effect parameter {self.name!r}: {label} must be finite")
        if not self.lower <= self.default <= self.upper:
            raise ValueError(f"effect parameter {self.name!r}: default {self.default} is outside "
                             f"[{self.lower}, {self.upper}]")
        if not self.limits[0] <= self.lower <= self.upper <= self.limits[1]:
            raise ValueError(f"effect parameter {self.name!r}: the physical limits {self.limits} do not "
                             f"contain the bounds [{self.lower}, {self.upper}]")

    @property
    def limits(self) -> tuple[float, float]:
        """The physical limits (the search bounds where none is given)."""
        return (self.lower if self.physical_lower is None else self.physical_lower,
                self.upper if self.physical_upper is None else self.physical_upper)

    def widened(self) -> EffectParameter:
        """This parameter with its search bounds at the physical limits."""
        lower, upper = self.limits
        return replace(self, lower=lower, upper=upper)


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


@dataclass(frozen=True)
class WidenedEffect:
    """An effect whose parameters are searched up to their physical limits: the same
    name, physics and values, only the fit's bounds change (see `at_physical_limits`)."""

    inner: Effect
    parameters: tuple[EffectParameter, ...]

    @property
    def name(self) -> str:  # type: ignore[override]
        return self.inner.name

    @property
    def explanation(self) -> str:  # type: ignore[override]
        return self.inner.explanation

    @property
    def uses_actuation(self) -> bool:  # type: ignore[override]
        return self.inner.uses_actuation

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        self.inner.apply(problem, values)


def at_physical_limits(effect: Effect) -> Effect:
    """``effect`` with every parameter's search bounds widened to its physical limits."""
    inner = effect.inner if isinstance(effect, WidenedEffect) else effect
    return WidenedEffect(inner, tuple(parameter.widened() for parameter in inner.parameters))
