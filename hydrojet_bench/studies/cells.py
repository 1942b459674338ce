"""A study expanded into cells: one twin scenario, simulated and diagnosed once.

A cell's id is a hash of its whole definition, so rerunning a spec into the same folder
finds exactly the cells it has already finished, whatever order they are listed in.
"""

from __future__ import annotations

import hashlib
import itertools

import msgspec

from ..effects import load_effect
from ..twin.setup_errors import setup_error_text
from .spec import Study

NONE = "none"


class Cell(msgspec.Struct, frozen=True):
    """One scenario.

    kind: "none", "sweep" (one effect, one size), "pair" or "setup" (a setup error,
    ``setup`` = (`twin.SETUP_ERRORS` name, values), physics nominal). truth: the hidden effects'
    names, "+"-joined ("none" without any). effects: their specs
    (library names or absolute ``file.py:Class``). values: ``"effect.parameter" -> value``
    in the parameter's own unit. parameter/size: the swept parameter and its value (a
    sweep only), the parameter's default (no effect) and unit. noise_scale: multiple of the profile's EM noise. orientation: "hanging"
    or "horizontal".
    """

    profile: str
    orientation: str
    plan: str
    model: str
    seed: int
    noise_scale: float
    kind: str
    truth: str
    effects: tuple[str, ...]
    values: tuple[tuple[str, float], ...]
    parameter: str = ""
    size: float | None = None
    size_default: float | None = None
    unit: str = ""
    setup: tuple[str, tuple[float, ...]] | None = None

    @property
    def id(self) -> str:
        fields = msgspec.to_builtins(self)
        if self.setup is None:
            del fields["setup"]  # cells without one keep the ids they had before setup cells
        return hashlib.sha256(msgspec.json.encode(fields)).hexdigest()[:16]

    @property
    def scenario(self) -> str:
        if self.kind == "sweep":
            return f"{self.parameter}={self.size:.4g}"
        if self.kind == "pair":
            return " + ".join(f"{name}={value:.4g}" for name, value in self.values) or self.truth
        if self.setup is not None:
            return setup_error_text(*self.setup)
        return NONE


def expand(study: Study) -> tuple[Cell, ...]:
    """Every cell of ``study``: scenarios x profiles x orientations x plans x models x
    noise scales x seeds, seeds innermost."""
    scenarios: list[tuple] = []
    if study.none:
        scenarios.append(("none", (), (), "", None, None, ""))
    for spec, parameter, sizes, default, unit, fixed in study.sweeps:
        scenarios.extend(("sweep", (spec,), tuple(sorted(((parameter, size), *fixed))), parameter, size, default, unit)
                         for size in sizes)
    for specs, values in study.pairs:
        scenarios.append(("pair", specs, values, "", None, None, ""))
    names = {spec: load_effect(spec).name for _, specs, *_ in scenarios for spec in specs}
    scenarios.extend(("setup", (), (), "", None, None, "", setup) for setup in study.setups)
    cells = []
    for (kind, effects, values, parameter, size, default, unit, *setup), profile, orientation, plan, model, noise, seed in itertools.product(
            scenarios, study.profiles, study.orientations, study.plans, study.models, study.noise_scales,
            study.seeds):
        if setup and setup[0][2] and orientation not in setup[0][2]:
            continue  # a setup error only on the orientations its [[setup]] names
        cells.append(Cell(profile=profile, orientation=orientation, plan=plan, model=model, seed=seed,
                          noise_scale=noise, kind=kind,
                          truth=setup[0][0] if setup else "+".join(names[s] for s in effects) or NONE,
                          effects=effects, values=values, parameter=parameter, size=size,
                          size_default=default, unit=unit, setup=setup[0][:2] if setup else None))
    return tuple(cells)

