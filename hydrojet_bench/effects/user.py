"""Effects from a user's file, checked when loaded and guarded when applied.

A user's effect is their code inside our solves: a wrong signature, a ``parameters`` that
is not a tuple of `EffectParameter`, a name that shadows a library effect, an ``apply``
that raises or leaves NaN in the problem would otherwise surface as a traceback deep in a
model (or, for a shadowed name, as a silently different model). `checked_effect` turns
each into a `UserError` naming the file and the class.
"""

from __future__ import annotations

import inspect
import os
import re
from collections.abc import Mapping
from dataclasses import fields
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..params import ModelParameters
from .base import CALIBRATION_POSES, SWEEPS, Effect, EffectParameter, effect_values, identifying_rows
from .problem import RodProblem

# Sample points of the trial problems an effect is applied to when it is loaded, and
# their jet forces (N): at rest, then each jet alone (an effect may act only when the
# jets push, or push one way).
_TRIAL_SAMPLES = 5
_TRIAL_FORCES_N = (np.zeros(3), *(0.05 * np.eye(3)))
_PROBLEM_FIELDS = frozenset(item.name for item in fields(RodProblem))
_MISSING_ATTRIBUTE = re.compile(r"'RodProblem' object has no attribute '(\w+)'")


class CheckedEffect:
    """A user's effect whose ``apply`` failures and non-finite results are `UserError`s
    naming ``origin`` (``path/to/file.py:ClassName``)."""

    def __init__(self, effect: Effect, origin: str) -> None:
        self.effect = effect
        self.origin = origin
        path, _, self.class_name = origin.rpartition(":")
        self.file = Path(path).resolve()
        self.name: str = effect.name
        self.explanation: str = effect.explanation
        self.parameters: tuple[EffectParameter, ...] = tuple(effect.parameters)
        self.uses_actuation: bool = effect.uses_actuation
        self.identified_by: str = identifying_rows(effect)

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        try:
            self.effect.apply(problem, values)
        except AttributeError as error:
            # Assigning a misspelt attribute raises without .name (slots): read it from the text.
            missing = _MISSING_ATTRIBUTE.fullmatch(str(error))
            if missing is not None and missing.group(1) not in _PROBLEM_FIELDS:
                raise UserError(f"effect {self.origin}: apply uses problem.{missing.group(1)}, which RodProblem "
                                "does not have (see hydrojet_bench/effects/problem.py)") from None
            raise UserError(f"effect {self.origin}: apply failed: AttributeError: {error}") from None
        except (Exception, SystemExit) as error:
            # The loads it failed at: an effect file may fail only at some (a formula
            # that breaks above some force), which the data's other rows do not show.
            jets = ", ".join(f"{force:.4g}" for force in np.asarray(problem.jet_forces_n, dtype=float).ravel())
            raise UserError(f"effect {self.origin}: apply failed at jet forces ({jets}) N with values "
                            f"{dict(values)}: {type(error).__name__}: {error}") from None
        for item in fields(problem):
            value = getattr(problem, item.name)
            if isinstance(value, (float, np.ndarray)) and not np.all(np.isfinite(value)):
                raise UserError(f"effect {self.origin}: apply left a non-finite value (NaN or inf) in "
                                f"problem.{item.name}")

    def spec_from(self, folder: Path) -> str:
        """This effect as ``path/to/file.py:ClassName`` with the path relative to ``folder``
        (where a parameter file that names it lives), so that both can move together."""
        return f"{Path(os.path.relpath(self.file, Path(folder).resolve())).as_posix()}:{self.class_name}"

    def __repr__(self) -> str:
        return f"{self.origin} ({self.name})"


def checked_effect(effect: object, origin: str, reserved_names: Mapping[str, object]) -> CheckedEffect:
    """``effect`` (an instance of a user's class) checked against the `Effect` interface
    and applied once to the nominal rod; ``reserved_names`` are the library's names, which
    a user's effect may not take."""
    missing = [attr for attr in ("name", "explanation", "parameters", "uses_actuation", "apply")
               if not hasattr(effect, attr)]
    if missing:
        raise UserError(f"effect {origin}: the class lacks {', '.join(missing)} "
                        "(see hydrojet_bench.effects.base.Effect)")
    name = effect.name  # type: ignore[attr-defined]
    if not isinstance(name, str) or not name.isidentifier():
        raise UserError(f"effect {origin}: name must be an identifier such as 'my_effect', got {name!r}")
    if name in reserved_names:
        raise UserError(f"effect {origin}: name {name!r} is a library effect's or a setup hypothesis's; give the "
                        "class its own name")
    parameters = effect.parameters  # type: ignore[attr-defined]
    if not isinstance(parameters, (tuple, list)) or not all(isinstance(p, EffectParameter) for p in parameters):
        raise UserError(f"effect {origin}: parameters must be a tuple of EffectParameter, got {parameters!r}")
    if len({p.name for p in parameters}) != len(parameters):
        raise UserError(f"effect {origin}: two parameters share a name")
    for parameter in parameters:
        if not parameter.lower < parameter.upper:
            raise UserError(f"effect {origin}: parameter {parameter.name!r} has no range to fit (lower = upper = "
                            f"{parameter.lower:g}); give it bounds lower < upper")
    if not isinstance(effect.uses_actuation, bool):  # type: ignore[attr-defined]
        raise UserError(f"effect {origin}: uses_actuation must be True or False")
    if identifying_rows(effect) not in (CALIBRATION_POSES, SWEEPS):  # type: ignore[arg-type]
        raise UserError(f"effect {origin}: identified_by must be {CALIBRATION_POSES!r} or {SWEEPS!r}, "
                        f"got {effect.identified_by!r}")  # type: ignore[attr-defined]
    apply = effect.apply  # type: ignore[attr-defined]
    try:
        inspect.signature(apply).bind(None, {})
    except (TypeError, ValueError):
        raise UserError(f"effect {origin}: apply must take (problem, values), not {_signature(apply)}") from None
    checked = CheckedEffect(effect, origin)  # type: ignore[arg-type]
    nominal = ModelParameters()
    defaults = effect_values(checked, nominal)
    plain = [_trial(checked, nominal, forces, defaults) for forces in _TRIAL_FORCES_N]
    if not parameters and all(_same(trial, _nominal_trial(nominal, forces))
                              for trial, forces in zip(plain, _TRIAL_FORCES_N)):
        # Nothing to fit and nothing changed: a calibration "with" it is the one without.
        raise UserError(f"effect {origin}: it has no parameters and apply changes nothing in the problem")
    _check_actuation_flag(checked, plain)
    for parameter in parameters:
        # A parameter apply never reads (a misspelt key read with .get, a value written to
        # a local) would be calibrated to noise and reported as if it were physics. One
        # whose apply fails at the moved value reads it too: the failure is reported when
        # a solve meets it (a study records it as that cell's error).
        moved = parameter.upper if parameter.upper != parameter.default else parameter.lower
        trials = _trials_or_none(checked, nominal, {**defaults, parameter.name: moved})
        if trials is None:
            continue
        if all(_same(trial, unchanged) for trial, unchanged in zip(trials, plain)):
            raise UserError(f"effect {origin}: parameter {parameter.name!r} changes nothing apply sets "
                            f"(from {parameter.default:g} to {moved:g}); apply must use values[{parameter.name!r}]")
        _check_actuation_flag(checked, trials)
    return checked


def _nominal_trial(params: ModelParameters, jet_forces_n: np.ndarray) -> RodProblem:
    return RodProblem.nominal(params, jet_forces_n, np.linspace(0.0, params.rod.length_m, _TRIAL_SAMPLES))


def _trial(effect: CheckedEffect, params: ModelParameters, jet_forces_n: np.ndarray,
           values: Mapping[str, float]) -> RodProblem:
    """The nominal rod's problem at ``jet_forces_n`` with ``effect`` applied at ``values``."""
    problem = _nominal_trial(params, jet_forces_n)
    effect.apply(problem, values)
    return problem


def _check_actuation_flag(effect: CheckedEffect, trials: list[RodProblem]) -> None:
    """A model packs a problem once and reuses it for other jet forces unless an effect
    reads them: one that does with uses_actuation False would be solved with stale jets.
    ``trials``: the effect's problems at every trial jet force, one set of values."""
    if not effect.uses_actuation and not all(_same(trials[0], trial, but="jet_forces_n") for trial in trials[1:]):
        raise UserError(f"effect {effect.origin}: apply changes the problem with the jet forces but "
                        "uses_actuation is False; set uses_actuation = True")


def _trials_or_none(effect: CheckedEffect, params: ModelParameters,
                    values: Mapping[str, float]) -> list[RodProblem] | None:
    """The trial problems at every trial jet force, or None where apply fails at
    ``values``."""
    try:
        return [_trial(effect, params, forces, values) for forces in _TRIAL_FORCES_N]
    except UserError:
        return None


def _same(first: RodProblem, second: RodProblem, but: str = "") -> bool:
    """Whether two problems hold the same values in every field (``but`` one)."""
    return all(np.array_equal(getattr(first, item.name), getattr(second, item.name))
               if isinstance(getattr(first, item.name), np.ndarray)
               else getattr(first, item.name) == getattr(second, item.name)
               for item in fields(first) if item.name != but)


def _signature(function: object) -> str:
    try:
        return str(inspect.signature(function))  # type: ignore[arg-type]
    except (TypeError, ValueError):
        return "an unknown signature"
