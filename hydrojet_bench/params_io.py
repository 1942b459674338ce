"""Calibrated parameters as TOML: what `calibrate` writes and `compare` reads.

Layout (SI units, the same names as `hydrojet_bench.params`)::

    model = "cosserat"            # the model they were calibrated for
    effects = ["gravity"]         # the effects that were enabled
    [parameters]                  # flat names: E0, EL, L, wd_fx .. wd_mz, effect.parameter
    E0 = 2.98e5
    ...
    [standard_errors]             # same keys, when calibrated
    [calibration]                 # provenance: data file, poses, RMS before/after

Everything else (geometry, capsule, jets, gravity) comes from the rig profile, so a
parameter file stays valid for any dataset recorded on that rig.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from .errors import UserError
from .params import ModelParameters, with_parameters


@dataclass(frozen=True)
class ParameterFile:
    model: str
    effects: tuple[str, ...]
    parameters: dict[str, float]
    standard_errors: dict[str, float] = field(default_factory=dict)
    calibration: dict[str, object] = field(default_factory=dict)

    def apply(self, params: ModelParameters, source: Path | str = "parameters") -> ModelParameters:
        """``params`` with these values; an invalid value is a UserError naming the key."""
        try:
            return with_parameters(params, self.parameters)
        except (KeyError, ValueError) as error:
            raise UserError(f"{source}: [parameters] {error.args[0]}") from None


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


def write_parameter_file(path: Path, content: ParameterFile) -> None:
    lines = ["# HydroJet Bench calibrated parameters (SI units)",
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
    try:
        data = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise UserError(f"{path}: no such parameter file") from None
    except OSError as error:
        raise UserError(f"{path}: cannot read: {error.strerror}") from None
    except tomllib.TOMLDecodeError as error:
        raise UserError(f"{path}: not valid TOML: {error}") from None
    model = data.get("model")
    if not isinstance(model, str):
        raise UserError(f"{path}: key 'model' must be a string naming the model (cosserat or prb)")
    effects = data.get("effects", [])
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise UserError(f"{path}: key 'effects' must be a list of effect names")
    tables = {}
    for name in ("parameters", "standard_errors"):
        table = data.get(name, {})
        if not isinstance(table, dict):
            raise UserError(f"{path}: [{name}] must be a table of numbers")
        for key, value in table.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise UserError(f"{path}: [{name}] {key} must be a finite number, got {value!r}")
        tables[name] = {key: float(value) for key, value in table.items()}
    if not tables["parameters"]:
        raise UserError(f"{path}: [parameters] is missing or empty")
    calibration = data.get("calibration", {})
    return ParameterFile(model, tuple(effects), tables["parameters"], tables["standard_errors"],
                         calibration if isinstance(calibration, dict) else {})
