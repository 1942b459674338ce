"""What a digital twin is made of: true physics, hidden effects, rig geometry, sensor noise.

`TwinConfig` holds the runtime objects a twin is built from (loaded effects, model
parameters, valve responses); it validates itself, a bad value raising `ValueError`
naming the field (``TwinConfig.settle_time_constant_s must be ...``).
`TwinConfig.from_profile` builds one from a rig profile, its ``[twin]`` table included
(the table's format and defaults: `hydrojet_bench.config.schema.TwinTable`).

Frames (see also `hydrojet_bench.params` and `drivers.plant`):

* *tracker*: the EM tracker's frame, in which the twin reports sensor poses;
* *base frame*: the clamp's frame, z along the undeformed rod towards the tip; its pose
  in the tracker frame is ``base_orientation_in_tracker`` / ``base_position_in_tracker_m``;
* body frames at the clamp (s = 0) and the tip (s = L), as the models return them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from drivers.valve.protocol import DUTY_MAX_PERMILLE

from ..config.schema import DEFAULT_MAX_JET_FORCE_N, SensorNoise, TwinTable
from ..effects import Effect, load_effect
from ..errors import UserError
from ..geometry import quat_normalize
from ..params import JET_COUNT, ModelParameters, with_parameters
from ..profile import RigProfile, SensorMounting
from .setup_errors import SetupErrors

_TWIN_DEFAULTS = TwinTable()
# The default rig hangs the rod from its clamp with the tracker's z axis up: the base
# frame's z (towards the tip) is the tracker's -z, a half turn about x.
HANGING_BASE_ORIENTATION = (0.0, 1.0, 0.0, 0.0)
# A plausible mid-latitude Earth field (uT), the same default as `drivers.plant.StaticPlant`.
DEFAULT_MAGNETIC_FIELD_UT = (20.0, 0.0, -45.0)


def _number(owner: str, name: str, value: object) -> float:
    if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool):
        raise ValueError(f"{owner}.{name} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{owner}.{name} must be finite, got {value!r}")
    return float(value)


def _non_negative(owner: str, name: str, value: object) -> float:
    number = _number(owner, name, value)
    if number < 0:
        raise ValueError(f"{owner}.{name} must be >= 0, got {value!r}")
    return number


def _vector(owner: str, name: str, value: object, size: int) -> tuple[float, ...]:
    try:
        items = tuple(value)  # type: ignore[arg-type]
    except TypeError:
        raise ValueError(f"{owner}.{name} must be {size} numbers, got {value!r}") from None
    if len(items) != size:
        raise ValueError(f"{owner}.{name} must have {size} components, got {len(items)}")
    return tuple(_number(owner, f"{name}[{i}]", v) for i, v in enumerate(items))


def _unit_quaternion(owner: str, name: str, value: object) -> tuple[float, float, float, float]:
    q = np.array(_vector(owner, name, value, 4))
    norm = float(np.linalg.norm(q))
    # A typed-in quaternion is rarely normalised to more than 4 digits; anything further
    # off is a mistake (a vector given where a quaternion was meant, a missing sign).
    if abs(norm - 1.0) > 1e-3:
        raise ValueError(f"{owner}.{name} must be a unit quaternion (w, x, y, z), got norm {norm:.6g}")
    return tuple(float(v) for v in quat_normalize(q))  # type: ignore[return-value]


@dataclass(frozen=True)
class JetResponse:
    """Steady jet force (N) produced by a valve duty (per mille): a monotone table,
    interpolated linearly; above its last duty the force stays at its last value, below
    its first duty the jet is off (0 N: a valve opened less than any calibrated duty is
    in its dead band, and a closed valve never pushes).

    duty_permille: strictly increasing integers in 0..1000.
    force_n: force at each duty, finite, >= 0, non-decreasing (a jet never pushes less
        when its valve opens further).
    """

    duty_permille: tuple[int, ...]
    force_n: tuple[float, ...]

    def __post_init__(self) -> None:
        duties = tuple(self.duty_permille)
        for d in duties:
            if isinstance(d, bool) or not isinstance(d, (int, np.integer)) or not 0 <= d <= DUTY_MAX_PERMILLE:
                raise ValueError(f"JetResponse.duty_permille must be integers in 0..{DUTY_MAX_PERMILLE}, "
                                 f"got {self.duty_permille!r}")
        forces = _vector("JetResponse", "force_n", self.force_n, len(self.force_n))
        if len(duties) < 2:
            raise ValueError(f"JetResponse.duty_permille needs at least 2 points, got {len(duties)}")
        if len(forces) != len(duties):
            raise ValueError(f"JetResponse.force_n has {len(forces)} points, duty_permille has {len(duties)}")
        if any(b <= a for a, b in zip(duties, duties[1:])):
            raise ValueError(f"JetResponse.duty_permille must be strictly increasing, got {duties}")
        if any(f < 0.0 for f in forces):
            raise ValueError(f"JetResponse.force_n must be >= 0 N (jets only push), got {forces}")
        if any(b < a for a, b in zip(forces, forces[1:])):
            raise ValueError(f"JetResponse.force_n must be non-decreasing, got {forces}")
        object.__setattr__(self, "duty_permille", tuple(int(d) for d in duties))
        object.__setattr__(self, "force_n", forces)

    @classmethod
    def linear(cls, max_force_n: float) -> "JetResponse":
        """0 per mille -> 0 N up to 1000 per mille -> ``max_force_n``."""
        return cls((0, DUTY_MAX_PERMILLE), (0.0, _non_negative("JetResponse", "max_force_n", max_force_n)))

    @classmethod
    def from_calibration(cls, calibration: object) -> "JetResponse":
        """The inverse of a valve client's `drivers.valve.calibration.JetCalibration`
        (force -> duty), so that a force the client commands comes back out of the twin.
        Needs the calibration's duties strictly increasing."""
        return cls(tuple(calibration.duty_permille), tuple(calibration.force_n))  # type: ignore[attr-defined]

    def force_for_duty(self, duty_permille: float) -> float:
        """Jet force (N) at a valve duty (per mille)."""
        if duty_permille < self.duty_permille[0]:
            return 0.0
        return float(np.interp(duty_permille, self.duty_permille, self.force_n))


@dataclass(frozen=True)
class TwinConfig:
    """A simulated HydroJet rig.

    true_params: the rod's true parameters (the values a calibration should recover).
        Its ``gravity_in_base_m_s2`` is the truth unless ``gravity_in_tracker_m_s2`` is given.
    hidden_effects: effects (instances, library names or ``file.py:Class``) the twin's
        physics includes on top of gravity, which a model under evaluation may lack.
        Gravity is always part of the twin (listing it here is allowed, not needed).
    hidden_effect_values: ``"effect.parameter" -> value`` for the hidden effects (and
        gravity's ``weight_scale``), merged into ``true_params``; unlisted parameters take
        the effect's default.
    noise: `SensorNoise`; `SensorNoise.off()` for exact measurements.
    seed: seeds the twin's own random generator (noise only; the physics is exact).
    base_orientation_in_tracker, base_position_in_tracker_m: the clamp's pose in the tracker
        frame (unit quaternion base -> tracker; m). Default: hanging, tracker z up.
    gravity_in_tracker_m_s2: when given, the truth's gravity, mapped into the base frame
        (replacing ``true_params.gravity_in_base_m_s2``); else gravity in the tracker frame
        follows from the params and the base pose.
    magnetic_field_in_tracker_ut: Earth's field for simulated magnetometers, uT.
    base_sensor, tip_sensor: `hydrojet_bench.profile.SensorMounting`s on the clamp and on
        the rod tip (default: at the body frame's origin with its axes).
    settle_time_constant_s: first-order settling towards a new equilibrium, s (0 jumps).
    max_force_n: full-scale jet force of the default linear valve response, N.
    jet_response: one `JetResponse` per jet, or None for linear 0..1000 -> 0..max_force_n.
    resolution: integration steps of the twin's Cosserat rod.
    setup: `SetupErrors`, a rig wired or described wrongly (default: none).
    """

    true_params: ModelParameters = field(default_factory=ModelParameters)
    hidden_effects: tuple[Effect | str, ...] = ()
    hidden_effect_values: tuple[tuple[str, float], ...] = ()
    noise: SensorNoise = _TWIN_DEFAULTS.noise
    seed: int = _TWIN_DEFAULTS.seed
    base_orientation_in_tracker: tuple[float, float, float, float] = HANGING_BASE_ORIENTATION
    base_position_in_tracker_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    gravity_in_tracker_m_s2: tuple[float, float, float] | None = None
    magnetic_field_in_tracker_ut: tuple[float, float, float] = DEFAULT_MAGNETIC_FIELD_UT
    base_sensor: SensorMounting = field(default_factory=SensorMounting)
    tip_sensor: SensorMounting = field(default_factory=SensorMounting)
    settle_time_constant_s: float = _TWIN_DEFAULTS.settle_time_constant_s
    max_force_n: float = DEFAULT_MAX_JET_FORCE_N
    jet_response: tuple[JetResponse, JetResponse, JetResponse] | None = None
    resolution: int = 20
    setup: SetupErrors = field(default_factory=SetupErrors)

    def __post_init__(self) -> None:
        owner = "TwinConfig"
        if not isinstance(self.true_params, ModelParameters):
            raise ValueError(f"{owner}.true_params must be ModelParameters, got {type(self.true_params).__name__}")
        effects = self.hidden_effects
        if isinstance(effects, (str, bytes)) or not isinstance(effects, Sequence):
            raise ValueError(f"{owner}.hidden_effects must be a sequence of effects or names, got {effects!r}")
        loaded = tuple(load_effect(e) if isinstance(e, str) else e for e in effects)
        for effect in loaded:
            if not isinstance(effect, Effect):
                raise ValueError(f"{owner}.hidden_effects: {effect!r} is not an Effect "
                                 "(see hydrojet_bench.effects.base.Effect)")
        names = [e.name for e in loaded]
        if len(set(names)) != len(names):
            raise ValueError(f"{owner}.hidden_effects lists an effect twice: {names}")
        object.__setattr__(self, "hidden_effects", loaded)
        values = self.hidden_effect_values
        pairs = values.items() if isinstance(values, Mapping) else values
        known = {f"{e.name}.{p.name}": p for e in self.effects for p in e.parameters}
        checked = []
        for key, value in pairs:
            if key not in known:
                raise ValueError(f"{owner}.hidden_effect_values key {key!r} is no parameter of the twin's "
                                 f"effects; known: {', '.join(sorted(known)) or 'none'}")
            number = _number(owner, f"hidden_effect_values[{key!r}]", value)
            parameter = known[key]
            lower, upper = parameter.limits
            if not lower <= number <= upper:
                raise ValueError(f"{owner}.hidden_effect_values[{key!r}] = {number} is outside its physical "
                                 f"limits [{lower}, {upper}] {parameter.unit}")
            checked.append((key, number))
        object.__setattr__(self, "hidden_effect_values", tuple(sorted(checked)))
        if not isinstance(self.noise, SensorNoise):
            raise ValueError(f"{owner}.noise must be a SensorNoise, got {type(self.noise).__name__}")
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"{owner}.seed must be a non-negative integer, got {self.seed!r}")
        object.__setattr__(self, "base_orientation_in_tracker",
                           _unit_quaternion(owner, "base_orientation_in_tracker", self.base_orientation_in_tracker))
        object.__setattr__(self, "base_position_in_tracker_m",
                           _vector(owner, "base_position_in_tracker_m", self.base_position_in_tracker_m, 3))
        if self.gravity_in_tracker_m_s2 is not None:
            object.__setattr__(self, "gravity_in_tracker_m_s2",
                               _vector(owner, "gravity_in_tracker_m_s2", self.gravity_in_tracker_m_s2, 3))
        object.__setattr__(self, "magnetic_field_in_tracker_ut",
                           _vector(owner, "magnetic_field_in_tracker_ut", self.magnetic_field_in_tracker_ut, 3))
        for name in ("base_sensor", "tip_sensor"):
            if not isinstance(getattr(self, name), SensorMounting):
                raise ValueError(f"{owner}.{name} must be a SensorMounting")
        object.__setattr__(self, "settle_time_constant_s",
                           _non_negative(owner, "settle_time_constant_s", self.settle_time_constant_s))
        max_force = _number(owner, "max_force_n", self.max_force_n)
        if max_force <= 0:
            raise ValueError(f"{owner}.max_force_n must be > 0, got {self.max_force_n!r}")
        object.__setattr__(self, "max_force_n", max_force)
        if self.jet_response is not None:
            responses = tuple(self.jet_response)
            if len(responses) != JET_COUNT or not all(isinstance(r, JetResponse) for r in responses):
                raise ValueError(f"{owner}.jet_response must be {JET_COUNT} JetResponse items or None")
            object.__setattr__(self, "jet_response", responses)
        if isinstance(self.resolution, bool) or not isinstance(self.resolution, (int, np.integer)) \
                or self.resolution < 1:
            raise ValueError(f"{owner}.resolution must be an integer >= 1, got {self.resolution!r}")
        if not isinstance(self.setup, SetupErrors):
            raise ValueError(f"{owner}.setup must be SetupErrors, got {type(self.setup).__name__}")

    @classmethod
    def from_profile(cls, profile: RigProfile, **changes: object) -> "TwinConfig":
        """The twin of a rig profile: its gravity (tracker frame), clamp pose, sensor
        mountings, per-jet force limits (linear valve responses up to each limit) and its
        ``[twin]`` table (true parameters from the rod, capsule and jets unless the table
        changes them). ``changes`` are further fields (``hidden_effects=``, ``noise=``,
        ``seed=`` ...): command-line choices win over the file. A mistake in the profile is
        a `UserError` naming its file."""
        if not isinstance(profile, RigProfile):
            raise ValueError(f"profile must be a RigProfile, got {type(profile).__name__}")
        table = profile.config.twin
        try:
            true_params = with_parameters(profile.model_parameters(), table.true_parameters)
        except (KeyError, ValueError) as error:
            raise UserError(f"{profile.source}: twin.true_parameters {error.args[0]}") from None
        try:
            hidden_effects = tuple(load_effect(_effect_spec(spec, profile)) for spec in table.hidden_effects)
        except UserError as error:
            raise UserError(f"{profile.source}: twin.hidden_effects: {error}") from None
        try:
            setup = SetupErrors(table.jet_wiring, table.tracker_tilt_deg, table.base_sensor_rotvec_rad,
                                table.jet_force_sign, table.jet_force_scale)
        except ValueError as error:
            # SetupErrors names its fields as the [twin] table does.
            raise UserError(f"{profile.source}: {str(error).replace('SetupErrors.', 'twin.')}") from None
        values: dict[str, object] = {
            "true_params": true_params,
            "gravity_in_tracker_m_s2": profile.gravity_in_tracker_m_s2,
            "base_orientation_in_tracker": profile.base_orientation_in_tracker,
            "base_position_in_tracker_m": profile.base_position_in_tracker_m,
            "base_sensor": profile.base_sensor,
            "tip_sensor": profile.tip_sensor,
            "max_force_n": max(profile.max_jet_force_n),
            "jet_response": tuple(JetResponse.linear(limit) for limit in profile.max_jet_force_n),
            "hidden_effects": hidden_effects,
            "hidden_effect_values": tuple(table.hidden_effect_values.items()),
            "noise": table.noise,
            "seed": table.seed,
            "settle_time_constant_s": table.settle_time_constant_s,
            "setup": setup,
        }
        values.update(changes)
        try:
            return cls(**values)  # type: ignore[arg-type]
        except ValueError as error:
            raise UserError(f"{profile.source}: [twin] {error}") from None

    @property
    def effects(self) -> tuple[Effect, ...]:
        """The twin's physics beyond the nominal rod: gravity, then the hidden effects."""
        if any(e.name == "gravity" for e in self.hidden_effects):
            return self.hidden_effects
        return (load_effect("gravity"),) + self.hidden_effects

    @property
    def jet_responses(self) -> tuple[JetResponse, ...]:
        """The per-jet valve responses in use (the linear default filled in)."""
        if self.jet_response is not None:
            return self.jet_response
        return (JetResponse.linear(self.max_force_n),) * JET_COUNT


def _effect_spec(spec: str, profile: RigProfile) -> str:
    """An effect file path relative to the profile's folder, made usable from anywhere."""
    path, colon, name = spec.rpartition(":")
    if not colon or profile.path is None or path.startswith("/"):
        return spec
    return f"{profile.path.parent / path}:{name}"
