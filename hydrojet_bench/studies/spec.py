"""A study's TOML spec, typed: which scenarios to simulate and diagnose.

::

    name = "smoke"                    # default: the file name without .toml
    profiles = ["sim"]                # rig profiles (shipped names or paths)
    orientations = ["hanging"]        # "hanging" (clamp above, rod down) and/or "horizontal"
    plans = ["short"]                 # "short", "paper", another built-in plan or a plan file
    models = ["cosserat"]             # diagnosing models: "cosserat", "prb"
    seeds = [0, 1, 2]                 # twin noise seeds
    noise_scales = [1.0]              # multiples of the profile's EM noise
    none = true                       # also run every scenario with no hidden effect

    [[effects]]                       # one hidden effect, swept over sizes
    effect = "jet_gain"               # a library name or path/to/file.py:Class (relative to the spec)
    parameter = "gain_1"              # the swept parameter, in the effect's own unit
    sizes = [0.8, 0.9, 1.1]           # or {start = 1e-3, stop = 1e-1, num = 3, scale = "log"}
    values = {}                       # the effect's other parameters, held fixed (default: defaults)

    [[pairs]]                         # two (or more) hidden effects at once, fixed sizes
    effects = ["jet_gain", "base_compliance"]
    values = {"jet_gain.gain_1" = 0.8, "base_compliance.compliance_rad_per_nm" = 20.0}

    [[setup]]                         # a setup error (`twin.SETUP_ERRORS`), physics nominal
    error = "tracker_tilt_deg"        # jet_wiring, tracker_tilt_deg, base_sensor_rotvec, jet_force_sign, jet_force_scale
    sizes = [[2.0, 1.0], [6.0, -3.0]] # each size: the error's values (as simulate --hidden)
    orientations = ["horizontal"]     # optional: only these of the study's orientations

Every size is checked against the effect parameter's bounds, and a study's size against
`MAX_SIZES` per axis, `MAX_NOISE_SCALE` and `MAX_CELLS`; a mistake is a `UserError`
naming the file and the dotted key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import msgspec
import numpy as np

from ..bench.plan_choice import choose_plan
from ..config.loading import convert, read_toml
from ..effects import Effect, load_effect
from ..errors import ConvergenceError, UserError
from ..models import MODELS
from ..plans import Plan, calibration_plan, validation_sweeps
from ..profile import load_profile
from ..twin.hidden import inert_effects
from ..twin.setup_errors import parse_setup_error, setup_error_text

Orientation = Literal["hanging", "horizontal"]

# Sizes on one swept axis: each is a cell per seed, model, ...; 10,000 is already days of
# one worker, and a larger num is a typo that fills memory before a cell runs.
MAX_SIZES = 10_000
# Cells of a study: tens of seconds each, so 100,000 is weeks of one worker or most of a
# day on a 100-worker cluster (the shipped studies have at most 540); more is a typo.
MAX_CELLS = 100_000
# Multiples of the profile's sensor noise: 1000 x the paper's EM noise is 0.5 m and 700
# degrees RMS, readings that say nothing of the rod; far larger ones overflow to inf.
MAX_NOISE_SCALE = 50.0
# The rows keep the seed in an int64 column.
MAX_SEED = 2**63 - 1
# "short": 12 calibration poses and every jet swept twice (5 steps up, 5 down): the
# smallest plan whose split still holds out a repetition of each sweep.
SHORT_POSES, SHORT_STEPS_UP = 12, 5


class SizeRange(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    """``num`` sizes from ``start`` to ``stop`` (both included), evenly spaced on a
    ``log`` or ``linear`` scale, in the parameter's own unit."""

    start: float
    stop: float
    num: int
    scale: Literal["log", "linear"] = "linear"

    def __post_init__(self) -> None:
        # msgspec reports these at the range's key; each message starts with the field.
        if not 1 <= self.num <= MAX_SIZES:
            raise ValueError(f"num must be from 1 to {MAX_SIZES} sizes on one axis, got {self.num}")
        for name in ("start", "stop"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"{name} must be a finite number, got {getattr(self, name)}")
        # Not start * stop > 0: 1e-200 * 1e-200 underflows to 0.
        if self.scale == "log" and (self.start == 0.0 or self.stop == 0.0
                                    or (self.start > 0.0) != (self.stop > 0.0)):
            raise ValueError(f"start and stop of a log scale must be nonzero and of one sign, got "
                             f"{self.start} and {self.stop}")

    def values(self) -> tuple[float, ...]:
        if self.scale == "log":
            return tuple(float(v) for v in np.geomspace(self.start, self.stop, self.num))
        return tuple(float(v) for v in np.linspace(self.start, self.stop, self.num))


class EffectSweep(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    effect: str
    parameter: str
    sizes: list[float] | SizeRange
    values: dict[str, float] = {}


class EffectPair(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    effects: Annotated[list[str], msgspec.Meta(min_length=2)]
    values: dict[str, float] = {}


class SetupSweep(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    error: str
    sizes: Annotated[list[list[float]], msgspec.Meta(min_length=1)]
    orientations: list[Orientation] = []  # the rig orientations it is simulated on (default: the study's)


class StudySpec(msgspec.Struct, forbid_unknown_fields=True, frozen=True):
    name: str = ""
    profiles: Annotated[list[str], msgspec.Meta(min_length=1)] = msgspec.field(default_factory=lambda: ["sim"])
    orientations: Annotated[list[Orientation], msgspec.Meta(min_length=1)] = msgspec.field(default_factory=lambda: ["hanging"])
    plans: Annotated[list[str], msgspec.Meta(min_length=1)] = msgspec.field(default_factory=lambda: ["short"])
    models: Annotated[list[str], msgspec.Meta(min_length=1)] = msgspec.field(default_factory=lambda: ["cosserat"])
    # Their bounds are checked in load_study: msgspec's words for a bad item of a list
    # do not say the bound.
    seeds: Annotated[list[int], msgspec.Meta(min_length=1)] = msgspec.field(default_factory=lambda: [0])
    noise_scales: Annotated[list[float], msgspec.Meta(min_length=1)] = msgspec.field(default_factory=lambda: [1.0])
    none: bool = True
    effects: list[EffectSweep] = []
    pairs: list[EffectPair] = []
    setup: list[SetupSweep] = []


class Study(msgspec.Struct, frozen=True):
    """A checked spec: effect specs resolved to absolute paths, sizes expanded.

    sweeps: (effect spec, "effect.parameter", sizes, the parameter's default, its unit, the
    other parameters' fixed values). pairs: (effect specs, values).
    """

    name: str
    source: str
    profiles: tuple[str, ...]
    orientations: tuple[str, ...]
    plans: tuple[str, ...]
    models: tuple[str, ...]
    seeds: tuple[int, ...]
    noise_scales: tuple[float, ...]
    none: bool
    sweeps: tuple[tuple[str, str, tuple[float, ...], float, str, tuple[tuple[str, float], ...]], ...]
    pairs: tuple[tuple[tuple[str, ...], tuple[tuple[str, float], ...]], ...]
    # (SETUP_ERRORS name, values, orientations: empty for the study's)
    setups: tuple[tuple[str, tuple[float, ...], tuple[str, ...]], ...] = ()


def study_plan(name: str, seed: int) -> Plan:
    """"short" (see `SHORT_POSES`), or any plan `choose_plan` knows (a built-in or a file)."""
    if name == "short":
        return calibration_plan(SHORT_POSES, seed=seed) + validation_sweeps(steps_up=SHORT_STEPS_UP, repetitions=2)
    return choose_plan(name, seed=seed)


def load_study(path: Path) -> Study:
    """The study spec at ``path``, checked (`UserError` naming file and key)."""
    source = str(path)
    spec = convert(read_toml(path, "study spec"), StudySpec, source)
    folder = path.parent
    for index, seed in enumerate(spec.seeds):
        if not 0 <= seed <= MAX_SEED:
            raise UserError(f"{source}: seeds[{index}] must be an integer from 0 to 2**63 - 1 (rows store it as "
                            f"int64), got {seed}")
    for index, scale in enumerate(spec.noise_scales):
        if not 0.0 < scale <= MAX_NOISE_SCALE:
            raise UserError(f"{source}: noise_scales[{index}] must be > 0 and at most {MAX_NOISE_SCALE:g} (times the "
                            f"profile's sensor noise; beyond, the readings say nothing), got {scale}")
    for key in ("profiles", "orientations", "plans", "models", "seeds", "noise_scales"):
        _check_no_repeats(getattr(spec, key), source, key)
    for index, model in enumerate(spec.models):
        if model not in MODELS:
            raise UserError(f"{source}: models[{index}] = {model!r} is no model; known: {', '.join(MODELS)}")
    profiles = tuple(_relative(name, folder, suffix=".toml") for name in spec.profiles)
    plans = tuple(_relative(name, folder) for name in spec.plans)
    # Every cell would fail on a profile or plan that does not load: said here, before any runs.
    for key, names, load in (("profiles", profiles, load_profile),
                             ("plans", plans, lambda name: study_plan(name, 0))):
        files: dict[object, int] = {}
        for index, name in enumerate(names):
            try:
                loaded = load(name)
            except UserError as error:
                raise UserError(f"{source}: {key}[{index}]: {error}") from None
            # A shipped profile's name and its file's path (or two paths to one plan
            # file) differ as text, but their cells would repeat one another.
            same = loaded.path.resolve() if key == "profiles" and loaded.path is not None else name
            if same in files:
                raise UserError(f"{source}: {key}[{index}] = {getattr(spec, key)[index]!r} is the same file as "
                                f"{key}[{files[same]}] = {getattr(spec, key)[files[same]]!r} (its cells would repeat "
                                "that entry's)")
            files[same] = index
            if key == "plans" and not (loaded.sweeps >= 0).any():
                # Every cell would fail in the diagnosis' split, after its simulation.
                raise UserError(f"{source}: plans[{index}] = {spec.plans[index]!r} has no sweep steps (sweep >= 0), "
                                "which diagnose holds out: give a plan with validation sweeps (short, paper, or a "
                                "plan file whose steps include sweeps)")
            hidden = getattr(getattr(loaded, "config", None), "twin", None)
            if hidden is not None and hidden.hidden_effects:
                # Each cell hides what the spec says: the profile's own would be dropped.
                raise UserError(f"{source}: {key}[{index}] = {name!r} hides {', '.join(hidden.hidden_effects)} in its "
                                "[twin] table, which a study replaces in every cell (each cell hides what the spec "
                                "says): give a profile without hidden_effects, and the effect as a sweep or a pair")
    sweeps, sweep_effects = [], []
    for index, sweep in enumerate(spec.effects):
        key = f"effects[{index}]"
        effect_spec = _effect_spec(sweep.effect, folder)
        effect = _load(effect_spec, source, f"{key}.effect")
        parameter = _parameter(effect, sweep.parameter, source, f"{key}.parameter")
        sizes = sweep.sizes.values() if isinstance(sweep.sizes, SizeRange) else tuple(sweep.sizes)
        if not sizes:
            raise UserError(f"{source}: {key}.sizes is empty")
        if len(sizes) > MAX_SIZES:
            raise UserError(f"{source}: {key}.sizes has {len(sizes)} sizes, more than {MAX_SIZES} on one axis")
        _check_no_repeats(sizes, source, f"{key}.sizes")
        for size in sizes:
            _check_bounds(parameter, size, source, f"{key}.sizes")
        fixed = []
        for name, value in sweep.values.items():
            if name == parameter.name:
                # cells.expand would keep one of the two values, replacing some sizes.
                raise UserError(f"{source}: {key}.values.{name}: {name} is the parameter swept ({key}.parameter); "
                                "it cannot also be held fixed")
            other = _parameter(effect, name, source, f"{key}.values.{name}")
            _check_bounds(other, value, source, f"{key}.values.{name}")
            fixed.append((f"{effect.name}.{name}", value))
        qualified = f"{effect.name}.{parameter.name}"
        for earlier, (spec_before, name_before, sizes_before, _, _, fixed_before) in enumerate(sweeps):
            # A value written out at its default is the same scenario as one left out.
            if (spec_before, name_before) == (effect_spec, qualified) and set(sizes_before) & set(sizes) and \
                    _completed([effect], fixed_before) == _completed([effect], fixed):
                raise UserError(f"{source}: {key} repeats sizes of effects[{earlier}] (the same cells: the same "
                                "effect and parameter, the other values the same or at their defaults)")
        sweeps.append((effect_spec, qualified, sizes, parameter.default, parameter.unit, tuple(sorted(fixed))))
        sweep_effects.append(effect)
    pairs, pair_effects = [], []
    for index, pair in enumerate(spec.pairs):
        key = f"pairs[{index}]"
        specs = tuple(_effect_spec(name, folder) for name in pair.effects)
        effects = [_load(s, source, f"{key}.effects[{i}]") for i, s in enumerate(specs)]
        names = [effect.name for effect in effects]
        for number, name in enumerate(names):
            if name in names[:number]:
                raise UserError(f"{source}: {key}.effects[{number}] = {pair.effects[number]!r} repeats "
                                f"{key}.effects[{names.index(name)}]")
        known = {f"{e.name}.{p.name}": p for e in effects for p in e.parameters}
        for name, value in pair.values.items():
            if name not in known:
                raise UserError(f"{source}: {key}.values.{name}: no parameter of {', '.join(e.name for e in effects)}; "
                                f"known: {', '.join(sorted(known))}")
            _check_bounds(known[name], value, source, f"{key}.values.{name}")
        for earlier, (specs_before, values_before) in enumerate(pairs):
            if set(specs_before) == set(specs) and \
                    _completed(effects, values_before) == _completed(effects, pair.values.items()):
                raise UserError(f"{source}: {key} repeats pairs[{earlier}] (the same effects at the same values, in "
                                "another order or with defaults written out: the same scenario)")
        pairs.append((specs, tuple(sorted(pair.values.items()))))
        pair_effects.append(effects)
    setups = []
    where: dict[tuple, list[tuple[str, set[str]]]] = {}  # (error, size) -> [(its key, its orientations)]
    for index, sweep in enumerate(spec.setup):
        _check_no_repeats([tuple(size) for size in sweep.sizes], source, f"setup[{index}].sizes")
        for number, orientation in enumerate(sweep.orientations):
            if orientation not in spec.orientations:
                raise UserError(f"{source}: setup[{index}].orientations[{number}] = {orientation!r} is not among the "
                                f"study's orientations ({', '.join(spec.orientations)})")
        for number, size in enumerate(sweep.sizes):
            try:
                parse_setup_error(setup_error_text(sweep.error, tuple(size)))
            except UserError as error:
                raise UserError(f"{source}: setup[{index}].sizes[{number}]: {error}") from None
            on = set(sweep.orientations or spec.orientations)
            for earlier, orientations in where.get((sweep.error, tuple(size)), []):
                if on & orientations:
                    raise UserError(f"{source}: setup[{index}].sizes[{number}] repeats {earlier} on the "
                                    f"{', '.join(sorted(on & orientations))} rod (cells of the same name, one row "
                                    "hiding the other)")
            where.setdefault((sweep.error, tuple(size)), []).append((f"setup[{index}].sizes[{number}]", on))
            setups.append((sweep.error, tuple(size), tuple(sweep.orientations)))
    _check_cell_count(spec, sum(len(sweep[2]) for sweep in sweeps) + len(pairs), setups, source)
    _check_each_hides_something(sweeps, sweep_effects, pairs, pair_effects, source)
    return Study(name=spec.name or path.stem, source=source, profiles=profiles,
                 orientations=tuple(spec.orientations), plans=plans, models=tuple(spec.models),
                 seeds=tuple(spec.seeds), noise_scales=tuple(spec.noise_scales), none=spec.none,
                 sweeps=tuple(sweeps), pairs=tuple(pairs), setups=tuple(setups))


def _check_each_hides_something(sweeps: list, sweep_effects: list[Effect], pairs: list,
                                 pair_effects: list[list[Effect]], source: str) -> None:
    """Refuse a scenario whose hidden effects leave the twin's rod as it is (`inert_effects`):
    its cells would be none cells scored as the effect's. A probe is a few solves, so a
    sweep is probed at its parameter's default (the usual slip: a gain of 1) and at its
    first size (other values held where the effect does nothing). An effect the probe
    cannot apply is left to its cells, whose rows say why."""
    for index, ((_, qualified, sizes, default, _, fixed), effect) in enumerate(zip(sweeps, sweep_effects)):
        for number, size in enumerate(sizes):
            if (number == 0 or size == default) and _inert([effect], {**dict(fixed), qualified: size}):
                raise UserError(f"{source}: effects[{index}].sizes[{number}] = {size:g}: there {effect.name} leaves "
                                "the twin's rod as it is and hides nothing (the study's none cells are that case)")
    for index, ((_, values), effects) in enumerate(zip(pairs, pair_effects)):
        inert = _inert(effects, dict(values))
        if inert:
            raise UserError(f"{source}: pairs[{index}]: at the values given (defaults where none is), "
                            f"{', '.join(inert)} leave(s) the twin's rod as it is and hide(s) nothing; give "
                            f"pairs[{index}].values a size for each effect")


def _completed(effects: list[Effect], values) -> tuple[tuple[str, float], ...]:
    """``values`` ("effect.parameter" -> value) with every other parameter of ``effects``
    at its default: equal for two spellings of one scenario."""
    completed = {f"{effect.name}.{parameter.name}": parameter.default
                 for effect in effects for parameter in effect.parameters}
    return tuple(sorted({**completed, **dict(values)}.items()))


def _inert(effects: list[Effect], values: dict[str, float]) -> tuple[str, ...]:
    try:
        return inert_effects(effects, values)
    except (UserError, ConvergenceError):
        return ()


def _relative(name: str, folder: Path, suffix: str = "") -> str:
    """A file named relative to the spec's folder as an absolute path; a built-in name as is."""
    candidate = folder / name
    if candidate.is_file() and (not suffix or candidate.suffix == suffix):
        return str(candidate.resolve())
    return name


def _effect_spec(spec: str, folder: Path) -> str:
    path, colon, name = spec.rpartition(":")
    if not colon or Path(path).is_absolute():
        return spec
    return f"{(folder / path).resolve()}:{name}"


def _load(spec: str, source: str, key: str) -> Effect:
    try:
        return load_effect(spec)
    except UserError as error:
        raise UserError(f"{source}: {key}: {error}") from None


def _parameter(effect: Effect, name: str, source: str, key: str):
    for parameter in effect.parameters:
        if parameter.name == name:
            return parameter
    known = ", ".join(p.name for p in effect.parameters) or "none"
    # A key that is the name itself (values.gain_9) is named once, not as its own value.
    named = f"{key}:" if key.endswith(f".{name}") else f"{key} = {name!r} is"
    raise UserError(f"{source}: {named} no parameter of {effect.name}; known: {known}")


def _check_bounds(parameter, value: float, source: str, key: str) -> None:
    if not parameter.lower <= value <= parameter.upper:
        raise UserError(f"{source}: {key}: {value} is outside {parameter.name}'s bounds "
                        f"[{parameter.lower}, {parameter.upper}] {parameter.unit}")


def _check_no_repeats(values, source: str, key: str) -> None:
    """A list entry given twice would make cells of the same name, one result hiding the other."""
    seen = set()
    for index, value in enumerate(values):
        if value in seen:
            raise UserError(f"{source}: {key}[{index}] = {value!r} repeats an earlier entry (cells are named by it)")
        seen.add(value)


def _check_cell_count(spec: StudySpec, scenarios: int, setups: list, source: str) -> None:
    """At most `MAX_CELLS`, counted as `cells.expand` makes them (before it makes them)."""
    per_orientation = len(spec.profiles) * len(spec.plans) * len(spec.models) * len(spec.noise_scales) * len(spec.seeds)
    runs = (int(spec.none) + scenarios) * len(spec.orientations)
    runs += sum(len(orientations) or len(spec.orientations) for _, _, orientations in setups)
    cells = runs * per_orientation
    if cells > MAX_CELLS:
        raise UserError(f"{source}: {cells} cells (scenarios x orientations x profiles x plans x models x "
                        f"noise_scales x seeds) is more than {MAX_CELLS} in one study; split it or shorten a list")
