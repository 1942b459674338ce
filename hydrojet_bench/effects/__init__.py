"""Effects: physics that both models compose, by canonical name or from a user's file."""

from __future__ import annotations

import importlib.util
import inspect
import sys
from collections.abc import Sequence
from pathlib import Path

from ..errors import UserError
from .base import (CALIBRATION_POSES, SWEEPS, Effect, EffectParameter, effect_values, identifying_rows,
                   qualified_parameter_names)
from .anisotropic_stiffness import AnisotropicStiffness
from .base_compliance import BaseCompliance
from .base_hysteresis import BaseHysteresis
from .gravity import Gravity
from .jet_gain import JetGain
from .jet_misalignment import JetMisalignment
from .nonlinear_elasticity import NonlinearElasticity
from .pressure_stiffening import PressureStiffening
from .sensor_mounting import SensorMounting
from .shear_extension import ShearExtension
from .stiffness_profile import StiffnessProfile
from .tip_pull import TipPull
from .user import CheckedEffect, checked_effect

# Canonical library, in the order users see it: gravity (on by default), then the
# effects a calibration can add to diagnose a rig, grouped by what they act on
# (actuation, constitutive law, clamp, measurement), then a load from outside the rod. Every default leaves the model
# unchanged, so a calibration that adds an effect starts from the nominal model.
LIBRARY: dict[str, type] = {
    effect.name: effect
    for effect in (Gravity, JetGain, JetMisalignment, PressureStiffening, NonlinearElasticity,
                   AnisotropicStiffness, StiffnessProfile, ShearExtension, BaseCompliance, BaseHysteresis,
                   SensorMounting, TipPull)
}

__all__ = ["CALIBRATION_POSES", "Effect", "EffectParameter", "LIBRARY", "SWEEPS", "effect_values",
           "command_line_spec", "identifying_rows", "load_effect", "load_effects", "qualified_parameter_names"]


def load_effect(spec: str) -> Effect:
    """An effect by canonical name (``gravity``) or from a file (``path/to/file.py:ClassName``)."""
    if spec in LIBRARY:
        return LIBRARY[spec]()
    if ":" not in spec:
        raise UserError(f"unknown effect {spec!r}; known effects: {', '.join(LIBRARY)}, "
                        "or give a file as path/to/my_effect.py:ClassName")
    path_text, _, class_name = spec.rpartition(":")
    path = Path(path_text)
    if not path.is_file():
        raise UserError(f"effect {spec!r}: file {path} does not exist")
    module_name = f"hydrojet_user_effect_{abs(hash(path.resolve()))}"
    module_spec = importlib.util.spec_from_file_location(module_name, path)
    if module_spec is None or module_spec.loader is None:
        raise UserError(f"effect {spec!r}: {path} is not a Python file")
    module = importlib.util.module_from_spec(module_spec)
    sys.modules[module_name] = module
    origin = f"{path}:{class_name}"
    try:
        module_spec.loader.exec_module(module)
    except (Exception, SystemExit) as error:  # the user's code: report, don't crash or exit
        raise UserError(f"effect {origin}: importing {path} failed: {_describe(error)}") from None
    cls = getattr(module, class_name, None)
    if cls is None or not inspect.isclass(cls):
        raise UserError(f"effect {origin}: {path} defines no class {class_name!r}")
    try:
        effect = cls()
    except (Exception, SystemExit) as error:
        raise UserError(f"effect {origin}: {class_name}() failed: {_describe(error)}") from None
    return checked_effect(effect, origin, _reserved_names())


def command_line_spec(effect: Effect) -> str:
    """How a command line names ``effect``: a library effect by name, a user's by its file
    (``path/to/file.py:ClassName``), which its bare name does not load."""
    return effect.origin if isinstance(effect, CheckedEffect) else effect.name


def _reserved_names() -> dict[str, object]:
    """Names a user's effect may not take: the library's and the setup hypotheses' (which
    diagnose fits beside the candidates, by name)."""
    from .setup import setup_effects

    return {**LIBRARY, **{effect.name: effect for effect in setup_effects()}}


def load_effects(specs: Sequence[str]) -> tuple[Effect, ...]:
    """`load_effect` of each spec, once each; two specs whose effects share a name (two
    files, one class name) are refused: the name is how fits, tables and parameter files
    tell effects apart."""
    effects: dict[str, tuple[str, Effect]] = {}
    for spec in dict.fromkeys(specs):
        effect = load_effect(spec)
        if effect.name in effects:
            raise UserError(f"effects {effects[effect.name][0]} and {spec} are both named {effect.name!r}; "
                            "give each class its own name")
        effects[effect.name] = (spec, effect)
    return tuple(effect for _, effect in effects.values())


def _describe(error: BaseException) -> str:
    if isinstance(error, SystemExit):
        return f"it called sys.exit({error.code!r})"
    return f"{type(error).__name__}: {error}"
