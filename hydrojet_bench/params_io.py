"""Calibrated parameters as TOML: what `calibrate` writes and `compare` reads.

Layout (SI units, the same names as `hydrojet_bench.params`)::

    model = "cosserat"            # the model they were calibrated for
    effects = ["gravity", "effects/wall_contact.py:WallContact"]   # the effects that were enabled:
                                  # library names, or a user's file relative to this file
    [parameters]                  # flat names: E0, EL, L, wd_fx .. wd_mz, effect.parameter
    E0 = 2.98e5
    ...
    [standard_errors]             # same keys, when calibrated
    [calibration]                 # provenance: data file, poses, RMS before/after

Everything else (geometry, capsule, jets, gravity) comes from the rig profile, so a
parameter file stays valid for any dataset recorded on that rig.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

import msgspec
import numpy as np

from .config.loading import convert, read_toml
from .effects import Effect
from .effects.user import CheckedEffect
from .config.schema import Finite
from .errors import UserError
from .files import check_replaceable
from .params import (FITTED_FIELDS, PARAMETER_NAMES, PLAUSIBLE_RANGES, ModelParameters, check_plausible,
                     with_parameters)

if TYPE_CHECKING:
    from .data.dataset import Dataset
    from .estimation.calibration import CalibrationResult
    from .profile import RigProfile


class ParameterFile(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A parameter file, as the module docstring lays it out."""

    model: Literal["cosserat", "prb"]
    effects: tuple[str, ...] = ()
    parameters: dict[str, Finite]
    standard_errors: dict[str, Finite] = {}
    calibration: dict[str, Any] = {}

    def __post_init__(self) -> None:
        if not self.parameters:
            raise ValueError("parameters is missing or empty")
        for name, value in self.parameters.items():
            if name in PLAUSIBLE_RANGES:
                check_plausible(name, value, f"parameters.{name}")
        for name, value in self.standard_errors.items():
            if value < 0.0:
                raise ValueError(f"standard_errors.{name} = {value:g} is negative")

    def apply(self, params: ModelParameters, source: Path | str = "parameters") -> ModelParameters:
        """``params`` with these values; an invalid value is a UserError naming the key."""
        try:
            return with_parameters(params, self.parameters)
        except (KeyError, ValueError) as error:
            raise UserError(f"{source}: [parameters] {error.args[0]}") from None


def check_values_for(effects: Sequence[Effect], values: Mapping[str, float], where: str, *,
                     unknown_effects: bool = False) -> None:
    """UserError ``{where}{name} ...`` for a value of ``values`` past its plausible range (the
    flat names) or an effect parameter outside its physical limits, past which the effect
    means nothing and the model may not solve (or overflow). An effect parameter of no
    effect in ``effects`` is refused too, unless ``unknown_effects``."""
    parameters = {f"{effect.name}.{parameter.name}": parameter for effect in effects for parameter in effect.parameters}
    for name, value in values.items():
        if name in PLAUSIBLE_RANGES:
            try:
                check_plausible(name, value, f"{where}{name}")
            except ValueError as error:
                raise UserError(str(error)) from None
        elif name in parameters:
            parameter = parameters[name]
            low, high = parameter.limits
            if not low <= value <= high:
                unit = "" if parameter.unit in ("", "1") else f" {parameter.unit}"
                reason = f" ({parameter.limit_reason})" if parameter.limit_reason else ""
                raise UserError(f"{where}{name} = {value:g}{unit} is outside its physical limits "
                                f"{low:g} .. {high:g}{unit}{reason}")
        elif "." in name and not unknown_effects:
            raise UserError(f"{where}{name}: the model has no such effect parameter (its effects: "
                            f"{', '.join(effect.name for effect in effects)})")


def effect_specs(effects: Sequence[Effect], folder: Path) -> tuple[str, ...]:
    """``effects`` as a parameter file in ``folder`` lists them: library effects by name,
    a user's effect as its file (relative to ``folder``) and class."""
    return tuple(effect.spec_from(folder) if isinstance(effect, CheckedEffect) else effect.name
                 for effect in effects)


def resolve_effect_spec(spec: str, path: Path) -> str:
    """An effect spec read from the parameter file ``path``: a file relative to it made
    usable from anywhere; a name as it is."""
    file, colon, class_name = spec.rpartition(":")
    if not colon or Path(file).is_absolute():
        return spec
    return f"{Path(path).parent / file}:{class_name}"


def _format(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, Sequence):
        return "[" + ", ".join(_format(v) for v in value) + "]"
    raise TypeError(f"cannot write {value!r} to TOML")


def _table(name: str, values: Mapping[str, object]) -> list[str]:
    lines = [f"[{name}]"]
    for key, value in values.items():
        quoted = f'"{key}"' if "." in key else key
        lines.append(f"{quoted} = {_format(value)}")
    return lines + [""]


# The first line of every parameter file the bench writes: what it may replace.
_HEADER = "# HydroJet Bench calibrated parameters (SI units)"


def check_parameter_output(path: Path) -> None:
    """Refuse (`check_replaceable`) to write a parameter file over anything but an earlier one."""
    check_replaceable(path, "parameter file", lambda head: head.startswith(_HEADER.encode()))


def write_parameter_file(path: Path, content: ParameterFile) -> None:
    check_parameter_output(path)
    lines = [_HEADER,
             f"model = {_format(content.model)}", f"effects = {_format(list(content.effects))}", ""]
    lines += _table("parameters", content.parameters)
    if content.standard_errors:
        lines += _table("standard_errors", content.standard_errors)
    if content.calibration:
        lines += _table("calibration", content.calibration)
    try:
        path.write_text("\n".join(lines))
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror}") from None


def read_parameter_file(path: Path) -> ParameterFile:
    """Read and check a parameter file; problems are UserErrors naming the file and key."""
    content = convert(read_toml(path, what="parameter file"), ParameterFile, str(path))
    # `calibrate` always fits these: a file without one was edited, and completing it
    # silently from the profile would hide that.
    missing = [name for name in PARAMETER_NAMES if name not in content.parameters]
    if missing:
        others = f" (and {', '.join(missing[1:])})" if missing[1:] else ""
        raise UserError(f"{path}: parameters.{missing[0]} is missing{others}; a parameter file from calibrate "
                        f"lists {', '.join(PARAMETER_NAMES)}")
    return content


def calibration_parameter_file(model: str, effects: Sequence[str], fit: CalibrationResult, data: Path,
                               profile: RigProfile, fit_on: str, steps: Dataset, rows: np.ndarray) -> ParameterFile:
    """The parameter file of a calibration on ``rows`` of ``steps`` (chosen by
    ``fit_on``), with its provenance (data, profile, rows fitted, RMS orientation error
    before and after, deg). ``effects``: specs as the file lists them (`effect_specs`)."""
    errors = dict(zip(fit.names, map(float, fit.standard_errors)))
    # A standard error the fit could not bound (inf) is no number a reader accepts: the
    # file lists those parameters as undetermined instead.
    undetermined = [name for name, error in errors.items() if not np.isfinite(error)]
    return ParameterFile(
        model=model, effects=tuple(effects),
        parameters=dict(zip(fit.names, map(float, fit.values))),
        standard_errors={name: error for name, error in errors.items() if name not in undetermined},
        calibration={**({"undetermined": undetermined} if undetermined else {}),
                     "data": str(data), "profile": profile.source, "profile_name": profile.name, "fit_on": fit_on,
                     "poses": int(np.sum(rows & (steps.sweep == -1))),
                     "sweep_steps": int(np.sum(rows & (steps.sweep >= 0))),
                     "rms_orientation_deg_before": round(fit.rms_orientation_deg_before, 4),
                     "rms_orientation_deg_after": round(fit.rms_orientation_deg_after, 4),
                     "converged": fit.converged, "convergence": fit.convergence,
                     **({"at_bound": list(fit.at_bound)} if fit.at_bound else {}),
                     # The rig the values belong to, to tell when they are used on another.
                     **{f"{RIG_KEY_PREFIX}{key}": value for key, value in profile.physics().items()}})


# [calibration] keys of the rig's physics tables (`RigProfile.physics`), e.g. "rig.rod.radius_m".
RIG_KEY_PREFIX = "rig."


def calibrated_on_another_rig(parameter_file: ParameterFile, path: Path | str, profile: RigProfile) -> str | None:
    """Why ``parameter_file`` (at ``path``) does not belong to ``profile``'s rig: the
    physics tables it recorded where it was calibrated that differ from ``profile``'s,
    leaving out what its values replace (E0, EL, L). None when they agree or the file
    predates the record."""
    recorded = {key.removeprefix(RIG_KEY_PREFIX): value for key, value in parameter_file.calibration.items()
                if key.startswith(RIG_KEY_PREFIX)}
    if not recorded:
        return None
    here = profile.physics()
    differing = [key for key in sorted(recorded.keys() | here.keys())
                 if key not in FITTED_FIELDS and not np.array_equal(np.asarray(recorded.get(key), dtype=object),
                                                                  np.asarray(here.get(key), dtype=object))]
    if not differing:
        return None
    shown = "; ".join(f"{key} {_format(recorded[key]) if key in recorded else 'unset'} there, "
                      f"{_format(here[key]) if key in here else 'unset'} here" for key in differing[:3])
    more = f" (and {len(differing) - 3} more)" if len(differing) > 3 else ""
    where = parameter_file.calibration.get("profile_name", "another profile")
    return (f"{path} was calibrated on the rig of profile {where!r}, not of profile {profile.name!r} used here: "
            f"{shown}{more}; its "
            "values belong to that rig (calibrate on this one, or give its profile with --profile)")
