"""The ``[twin]`` table of a sim profile: what the digital twin hides and how it measures.

    [twin]
    seed = 0
    hidden_effects = ["gravity", "effects/clogged_jet.py:CloggedJet"]  # names or file:Class
    settle_time_constant_s = 0.5
    [twin.hidden_effect_values]          # "effect.parameter" = value
    "gravity.weight_scale" = 1.1
    [twin.true_parameters]               # flat names: E0, EL, L, wd_fx .. wd_mz
    E0 = 2.8e5
    [twin.noise]                         # SensorNoise fields
    em_orientation_rms_deg = 0.7

Relative effect file paths are resolved from the profile's folder. Every problem is a
UserError naming the profile file and the key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import fields
from typing import Any

from ..effects import load_effect
from ..errors import UserError
from ..params import with_parameters
from ..profile import RigProfile
from .config import SensorNoise, TwinConfig

_KEYS = ("seed", "hidden_effects", "settle_time_constant_s", "hidden_effect_values", "true_parameters", "noise")


def twin_config(profile: RigProfile, **changes: object) -> TwinConfig:
    """`TwinConfig.from_profile` with the profile's ``[twin]`` table applied, then
    ``changes`` (command-line choices win over the file)."""
    table = profile.table("twin")
    where = str(profile.path) if profile.path is not None else f"profile {profile.name}"

    def fail(key: str, message: str) -> UserError:
        return UserError(f"{where}: twin.{key} {message}")

    unknown = sorted(set(table) - set(_KEYS))
    if unknown:
        raise fail(unknown[0], f"is not a known key; [twin] takes {', '.join(_KEYS)}")
    values: dict[str, object] = {}
    if "seed" in table:
        if isinstance(table["seed"], bool) or not isinstance(table["seed"], int):
            raise fail("seed", f"must be an integer, got {table['seed']!r}")
        values["seed"] = table["seed"]
    if "settle_time_constant_s" in table:
        values["settle_time_constant_s"] = _number(table["settle_time_constant_s"], fail, "settle_time_constant_s")
    if "hidden_effects" in table:
        specs = table["hidden_effects"]
        if not isinstance(specs, list) or not all(isinstance(spec, str) for spec in specs):
            raise fail("hidden_effects", "must be a list of effect names or file.py:Class strings")
        values["hidden_effects"] = tuple(load_effect(_resolve(spec, profile)) for spec in specs)
    if "hidden_effect_values" in table:
        values["hidden_effect_values"] = tuple(
            (key, _number(value, fail, f"hidden_effect_values.{key}"))
            for key, value in _table(table["hidden_effect_values"], fail, "hidden_effect_values").items())
    if "true_parameters" in table:
        true_values = {key: _number(value, fail, f"true_parameters.{key}")
                       for key, value in _table(table["true_parameters"], fail, "true_parameters").items()}
        try:
            values["true_params"] = with_parameters(profile.model_parameters(), true_values)
        except (KeyError, ValueError) as error:
            raise fail("true_parameters", str(error.args[0])) from None
    if "noise" in table:
        noise = _table(table["noise"], fail, "noise")
        allowed = {f.name for f in fields(SensorNoise)}
        for key in noise:
            if key not in allowed:
                raise fail(f"noise.{key}", f"is not a known key; [twin.noise] takes {', '.join(sorted(allowed))}")
        try:
            values["noise"] = SensorNoise(**{key: _number(value, fail, f"noise.{key}") for key, value in noise.items()})
        except ValueError as error:
            raise fail("noise", str(error)) from None
    values.update(changes)
    try:
        return TwinConfig.from_profile(profile, **values)
    except ValueError as error:
        raise UserError(f"{where}: [twin] {error}") from None


def _resolve(spec: str, profile: RigProfile) -> str:
    path, colon, name = spec.rpartition(":")
    if not colon or profile.path is None or path.startswith("/"):
        return spec
    return f"{profile.path.parent / path}:{name}"


def _number(value: Any, fail, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(key, f"must be a number, got {value!r}")
    return float(value)


def _table(value: Any, fail, key: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise fail(key, f"must be a table, got {value!r}")
    return value
