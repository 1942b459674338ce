"""Which model a command runs, with which effects and parameters: one rule for all.

A parameter file (``--params``, written by `calibrate`) brings the model it was
calibrated for and its effects, in place of the command's defaults (a profile's
``[estimator]``, a session log's live model, or plain Cosserat); the command line wins:
``--model`` replaces the model and every ``--effect`` is added to the effects.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from .effects import LIBRARY, Effect, command_line_spec, load_effect, load_effects, qualified_parameter_names
from .errors import UserError
from .estimation.calibration import DEFAULT_NAMES
from .models import make_model
from .models.shooting import ShootingModel
from .params import ModelParameters
from .params_io import (ParameterFile, calibrated_on_another_rig, check_values_for, read_parameter_file,
                        resolve_effect_spec)

if TYPE_CHECKING:
    from .profile import RigProfile


@dataclass(frozen=True)
class ModelDefaults:
    """What a command runs when neither a parameter file nor ``--model`` says: a model
    name and effect specs (library names or path/to/file.py:Class); ``origin`` names
    where they were read (a profile's ``[estimator]``), for errors."""

    model: str
    effects: tuple[str, ...] = ()
    origin: str = ""


# The default of the commands that have no profile or session log to ask.
COSSERAT = ModelDefaults("cosserat")


@dataclass(frozen=True)
class ModelChoice:
    """The model (gravity always included) and, among its effects, the ``requested`` ones
    whose parameters a calibration fits; ``parameter_file`` was read from
    ``parameter_path`` when one was given."""

    model: ShootingModel
    requested: tuple[Effect, ...]
    effect_specs: tuple[str, ...]
    parameter_file: ParameterFile | None = None
    parameter_path: Path | str | None = None

    @property
    def calibration_names(self) -> tuple[str, ...]:
        """E0, EL, L, w_d and the parameters of every requested effect."""
        return DEFAULT_NAMES + tuple(name for effect in self.requested for name in qualified_parameter_names(effect))

    def parameters(self, nominal: ModelParameters) -> ModelParameters:
        """``nominal`` (a profile's parameters) with the parameter file's values applied."""
        if self.parameter_file is None:
            return nominal
        check_values_for(self.model.effects, self.parameter_file.parameters, f"{self.parameter_path}: parameters.")
        return self.parameter_file.apply(nominal, self.parameter_path)

    def uncalibrated(self, profile: RigProfile | None = None) -> tuple[str, ...]:
        """What runs without the parameter file having calibrated it, one sentence each: a
        ``--model`` other than the file's, an effect (added by ``--effect``, or listed by a
        hand-edited file) whose values the file lacks, so that they stay at their no-effect
        defaults, and ``profile``'s rig when the file was calibrated on another
        (`calibrated_on_another_rig`). Gravity is exempt: every model has it at its nominal
        weight unless a calibration fitted it. Empty without a parameter file."""
        if self.parameter_file is None:
            return ()
        path, file = self.parameter_path, self.parameter_file
        notes = []
        elsewhere = None if profile is None else calibrated_on_another_rig(file, path, profile)
        if elsewhere is not None:
            notes.append(elsewhere)
        if self.model.name != file.model:
            notes.append(f"{path} was calibrated for the {file.model} model; the {self.model.name} model runs "
                         f"with its values, uncalibrated (calibrate with --model {self.model.name})")
        for effect in self.model.effects:
            names = qualified_parameter_names(effect)
            missing = [name for name in names if name not in file.parameters]
            if effect.name == "gravity" or not missing:
                continue
            which = "has no values" if len(missing) == len(names) else f"lacks {', '.join(missing)}"
            notes.append(f"effect {effect.name} {which} in {path}: it runs at its defaults, uncalibrated "
                         f"(calibrate with --effect {command_line_spec(effect)} to fit it)")
        return tuple(notes)


def build_model(name: str, effect_specs: Sequence[str]) -> tuple[ShootingModel, tuple[Effect, ...]]:
    """The model with gravity plus the requested effects, and the requested effects
    themselves (whose parameters a calibration fits; gravity stays at its nominal weight
    unless requested)."""
    requested = load_effects(effect_specs)
    always = () if any(effect.name == "gravity" for effect in requested) else (load_effect("gravity"),)
    return make_model(name, always + requested), requested


def choose_model(model: str | None, effects: Sequence[str], parameter_path: Path | str | None,
                 defaults: ModelDefaults = COSSERAT, *, effect_files: Sequence[str] | None = None,
                 parameter_file: ParameterFile | None = None) -> ModelChoice:
    """The model per the rule above. An effect the parameter file names that is not in
    the library is looked up by name among ``effect_files`` (default: ``effects``), the
    path/to/file.py:Class specs of the command line. ``parameter_file``: parameters
    already in memory (a calibration just made), named ``parameter_path`` in errors."""
    if parameter_path is None:
        parameter_file = None
        name, base_specs = model or defaults.model, list(defaults.effects)
    else:
        parameter_file = parameter_file or read_parameter_file(Path(parameter_path))
        name, base_specs = model or parameter_file.model, _file_effect_specs(
            parameter_file, parameter_path, effects if effect_files is None else effect_files)
    specs = tuple(dict.fromkeys([*base_specs, *effects]))
    if parameter_path is None and defaults.origin:
        try:
            built, requested = build_model(name, specs)
        except UserError as error:
            raise UserError(f"{defaults.origin}: {error}") from None
    else:
        built, requested = build_model(name, specs)
    return ModelChoice(built, requested, specs, parameter_file, parameter_path)


def model_choice(args: argparse.Namespace, defaults: ModelDefaults = COSSERAT) -> ModelChoice:
    """`choose_model` on the options of `commands.common.add_model_arguments`."""
    return choose_model(args.model, args.effect, getattr(args, "params", None), defaults)


def _same_effect_file(first: str, second: str) -> bool:
    """Whether two path/to/file.py:Class specs name the same class of the same file."""
    (first_path, _, first_class), (second_path, _, second_class) = first.rpartition(":"), second.rpartition(":")
    return first_class == second_class and Path(first_path).resolve() == Path(second_path).resolve()


def _file_effect_specs(parameter_file: ParameterFile, path: Path | str, effect_files: Sequence[str]) -> list[str]:
    """The parameter file's effects as specs: a file it names relative to itself (an
    effect file of the command line of the same name must be that file: the values were
    fitted to its physics); a name outside the library, from an older file, is looked up
    among those effect files."""
    named_files = {load_effect(spec).name: spec for spec in effect_files}
    specs = []
    for spec in parameter_file.effects:
        if ":" in spec:
            resolved = resolve_effect_spec(spec, path)
            try:
                name = load_effect(resolved).name
            except UserError as error:
                raise UserError(f"{path}: effects: {error}") from None
            given = named_files.get(name, resolved)
            if not _same_effect_file(given, resolved):
                raise UserError(f"{path}: effect {name!r} was calibrated with {resolved}; {given} is another "
                                "file of the same name: give the one it was calibrated with, or calibrate again")
            specs.append(given)
            continue
        specs.append(named_files.get(spec, spec))
    for spec in specs:
        if spec not in LIBRARY and ":" not in spec:
            raise UserError(f"{path}: effect {spec!r} is not in the library ({', '.join(sorted(LIBRARY))}); "
                            "if it comes from a file, give that file with --effect path/to/file.py:ClassName")
    return specs
