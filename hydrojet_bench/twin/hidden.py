"""What a twin can hide, by name, and the ``--hidden`` specs that choose it.

`HIDDEN` is the twin's registry: every name a spec may use, mapped to the class that
makes it (the effect library; setup errors join it under their own names). A spec is

* ``NAME`` or ``path/to/file.py:Class``: the effect at the values the profile's
  ``[twin] hidden_effect_values`` give it (its defaults otherwise);
* ``NAME=VALUE``: its one parameter at VALUE, or, comma-separated (``jet_gain=1,0.8,1``),
  each of its parameters in the order it lists them;
* ``NAME:param=VALUE``: one parameter by name (repeat the spec for others).

A hidden effect that leaves the twin's rod exactly as it was (`inert_effects`: every
library default, a clamp with play but no compliance) hides nothing, which a
simulation would otherwise record silently.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..effects import LIBRARY, Effect, load_effect
from ..errors import UserError
from ..params import ModelParameters, with_parameters

HIDDEN: dict[str, type] = dict(LIBRARY)

# The path `inert_effects` solves: each jet loaded and unloaded, so that a clamp with
# play (path state) shows too; forces in N.
_PROBE_FORCES_N = tuple(np.array(forces) for forces in (
    (0.0, 0.0, 0.0), (0.08, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.08, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.08),
    (0.0, 0.0, 0.0), (0.05, 0.05, 0.0)))
# A sensor moved less than this (rad, m) has not moved: the solver's own tolerance.
_INERT_TOLERANCE = 1e-9


@dataclass(frozen=True)
class HiddenChoice:
    """The effects a set of ``--hidden`` specs names (in order, each once) and the
    ``"effect.parameter" -> value`` pairs they set."""

    effects: tuple[Effect, ...]
    values: tuple[tuple[str, float], ...]


def parse_hidden(specs: Sequence[str], option: str = "--hidden") -> HiddenChoice:
    """The effects and values of ``specs`` (see the module docstring); a mistake is a
    UserError naming ``option`` and the spec."""
    effects: dict[str, Effect] = {}
    values: dict[str, float] = {}
    for spec in specs:
        target, equals, value_text = spec.partition("=")
        effect_spec, parameter = _split_parameter(target)
        effect = _lookup(effect_spec, option)
        effects.setdefault(effect.name, effect)
        if not equals:
            continue
        numbers = _numbers(value_text, f"{option} {spec}")
        names = [p.name for p in effect.parameters]
        if parameter is not None:
            if parameter not in names:
                raise UserError(f"{option} {spec}: {effect.name} has no parameter {parameter!r}; "
                                f"it has {', '.join(names) or 'none'}")
            if len(numbers) != 1:
                raise UserError(f"{option} {spec}: {effect.name}.{parameter} takes one number, got {len(numbers)}")
            chosen = {parameter: numbers[0]}
        elif len(numbers) == len(names):
            chosen = dict(zip(names, numbers))
        else:
            raise UserError(f"{option} {spec}: {effect.name} has {len(names)} parameters "
                            f"({', '.join(names) or 'none'}), got {len(numbers)} value(s); give them all, "
                            f"comma-separated in that order, or one as {effect.name}:PARAMETER=VALUE")
        for name, number in chosen.items():
            bounds = next(p for p in effect.parameters if p.name == name)
            if not bounds.lower <= number <= bounds.upper:
                raise UserError(f"{option} {spec}: {effect.name}.{name} = {number:g} is outside "
                                f"[{bounds.lower:g}, {bounds.upper:g}] {bounds.unit}")
            key = f"{effect.name}.{name}"
            if key in values and values[key] != number:
                raise UserError(f"{option} {spec}: {key} is already {values[key]:g} from an earlier {option}; "
                                "give each parameter once")
            values[key] = number
    return HiddenChoice(tuple(effects.values()), tuple(values.items()))


def inert_effects(effects: Sequence[Effect], values: Mapping[str, float],
                  params: ModelParameters | None = None) -> tuple[str, ...]:
    """Names of ``effects`` that, at ``values`` (``"effect.parameter" -> value``, defaults
    for the rest), move neither sensor of the rod at ``params`` (default: nominal) on a
    path that loads and unloads each jet: hidden in a twin, they hide nothing."""
    from ..models import CosseratModel  # the models are the heavy import: only when asked

    base = params if params is not None else ModelParameters()
    gravity = load_effect("gravity")
    reference = _probe(CosseratModel(effects=(gravity,)), base)
    inert = []
    for effect in effects:
        own = {key: value for key, value in values.items() if key.partition(".")[0] == effect.name}
        composed = (effect,) if effect.name == gravity.name else (gravity, effect)
        probed = _probe(CosseratModel(effects=composed), with_parameters(base, own))
        if max(_distance(a, b) for a, b in zip(reference, probed)) <= _INERT_TOLERANCE:
            inert.append(effect.name)
    return tuple(inert)


def _probe(model, params: ModelParameters) -> list[tuple[np.ndarray, np.ndarray]]:
    poses, previous = [], None
    for forces in _PROBE_FORCES_N:
        previous = model.solve(forces, params, previous=previous)
        poses.append((previous.tip_sensor_in_base_sensor(), previous.tip_position_in_base_m))
    return poses


def _distance(first: tuple[np.ndarray, np.ndarray], second: tuple[np.ndarray, np.ndarray]) -> float:
    return max(float(np.max(np.abs(first[0] - second[0]))), float(np.max(np.abs(first[1] - second[1]))))


def _split_parameter(target: str) -> tuple[str, str | None]:
    """``NAME:param`` or ``file.py:Class:param`` -> (effect spec, param); a bare name or
    ``file.py:Class`` -> (it, None)."""
    head, colon, tail = target.rpartition(":")
    if colon and (head in HIDDEN or ":" in head):
        return head, tail
    return target, None


def _lookup(spec: str, option: str) -> Effect:
    if spec in HIDDEN:
        return HIDDEN[spec]()
    if ":" in spec:
        try:
            return load_effect(spec)
        except UserError as error:
            raise UserError(f"{option}: {error}") from None
    raise UserError(f"{option}: unknown hidden effect {spec!r}; known: {', '.join(HIDDEN)}, "
                    "or a file as path/to/my_effect.py:ClassName")


def _numbers(text: str, where: str) -> tuple[float, ...]:
    try:
        numbers = tuple(float(item) for item in text.split(","))
    except ValueError:
        raise UserError(f"{where}: the value must be a number or numbers separated by commas") from None
    if not all(np.isfinite(numbers)):
        raise UserError(f"{where}: the value must be finite")
    return numbers
