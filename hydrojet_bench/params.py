"""Physical parameters of the rod and the rig, in SI units.

Frames: the *base frame* is the fixed clamp holder's frame, its z axis along the
undeformed rod and pointing from base to tip (a compliant clamp turns the rod's first
section relative to it; the base sensor sits on the holder); the *tip frame* is the rod's material frame at s = L (z along
the tangent). Jets act in the tip frame's xy plane (paper eq. 5).

Every dataclass is frozen and validates itself: a bad value raises `ValueError` naming
the field. Calibration and sensitivity address parameters by flat names (``E0``, ``EL``,
``L``, ``wd_fx`` ... ``wd_mz``, and ``effect.parameter`` for effect parameters); see
`PARAMETER_NAMES`, `get_parameter` and `with_parameters`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

Vector3 = tuple[float, float, float]

# The HydroJet capsule carries three water jets (paper eq. 5); every per-jet tuple has
# this length.
JET_COUNT = 3
# The most a jet of the capsule plausibly pushes, N: the paper's jets give ~0.1 N, and
# beyond ~10 N the nominal rod has no static equilibrium the models can find (measured:
# 10 N on one jet converges, 20 N does not). A larger limit in a file is a typo.
MAX_PLAUSIBLE_JET_FORCE_N = 10.0
# The farthest a rig point plausibly lies from the tracker's origin, per axis, m: a
# tracker's field is a metre across. Finite yet far larger is a unit slip, and the frame
# arithmetic overflows on the largest.
MAX_PLAUSIBLE_POSITION_M = 10.0


def _check_finite(owner: str, name: str, value: float) -> None:
    if not isinstance(value, (int, float, np.floating, np.integer)) or isinstance(value, bool):
        raise ValueError(f"{owner}.{name} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{owner}.{name} must be finite, got {value!r}")


def _check_positive(owner: str, name: str, value: float) -> None:
    _check_finite(owner, name, value)
    if value <= 0:
        raise ValueError(f"{owner}.{name} must be > 0, got {value!r}")


def _vector3(owner: str, name: str, value: Sequence[float]) -> Vector3:
    try:
        items = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{owner}.{name} must be 3 numbers, got {value!r}") from None
    if len(items) != 3:
        raise ValueError(f"{owner}.{name} must have 3 components, got {len(items)}")
    for axis, item in zip("xyz", items):
        _check_finite(owner, f"{name}[{axis}]", item)
    return items  # type: ignore[return-value]


@dataclass(frozen=True)
class RodParameters:
    """The soft body: a solid elastomer cylinder whose Young's modulus varies linearly from
    ``youngs_modulus_base_pa`` at s = 0 to ``youngs_modulus_tip_pa`` at s = L (paper eq. 10
    and sec. IV-B). Shear modulus G = E / (2 (1 + poisson_ratio))."""

    length_m: float = 0.070
    radius_m: float = 0.0045
    density_kg_m3: float = 1070.0
    poisson_ratio: float = 0.49
    youngs_modulus_base_pa: float = 3.0e5
    youngs_modulus_tip_pa: float = 2.0e5

    def __post_init__(self) -> None:
        owner = "rod"
        for name in ("length_m", "radius_m", "density_kg_m3", "youngs_modulus_base_pa",
                     "youngs_modulus_tip_pa"):
            _check_positive(owner, name, getattr(self, name))
        _check_finite(owner, "poisson_ratio", self.poisson_ratio)
        # Thermodynamic bounds for an isotropic solid; 0.5 is incompressible (elastomers
        # sit just below it).
        if not -1.0 < self.poisson_ratio <= 0.5:
            raise ValueError(f"rod.poisson_ratio must be in (-1, 0.5], got {self.poisson_ratio!r}")

    @property
    def area_m2(self) -> float:
        return math.pi * self.radius_m**2

    @property
    def second_moment_m4(self) -> float:
        """Second moment of area of the circular section about a diameter, m^4."""
        return math.pi * self.radius_m**4 / 4.0

    @property
    def polar_moment_m4(self) -> float:
        return 2.0 * self.second_moment_m4

    @property
    def mass_per_length_kg_m(self) -> float:
        return self.density_kg_m3 * self.area_m2

    def youngs_modulus_pa(self, arc_length_m: np.ndarray | float) -> np.ndarray | float:
        """E(s), Pa, linear from base to tip."""
        fraction = np.asarray(arc_length_m) / self.length_m
        return self.youngs_modulus_base_pa + (self.youngs_modulus_tip_pa - self.youngs_modulus_base_pa) * fraction

    def shear_modulus_pa(self, arc_length_m: np.ndarray | float) -> np.ndarray | float:
        return self.youngs_modulus_pa(arc_length_m) / (2.0 * (1.0 + self.poisson_ratio))


@dataclass(frozen=True)
class CapsuleParameters:
    """The rigid capsule at the tip (camera, jets, sensor): its mass and the position of its
    centre of mass in the tip frame (m). The HydroJet capsule is 9.8 mm x 28 mm."""

    mass_kg: float = 0.0025
    center_of_mass_in_tip_m: Vector3 = (0.0, 0.0, 0.014)

    def __post_init__(self) -> None:
        _check_finite("capsule", "mass_kg", self.mass_kg)
        if self.mass_kg < 0:
            raise ValueError(f"capsule.mass_kg must be >= 0, got {self.mass_kg!r}")
        object.__setattr__(self, "center_of_mass_in_tip_m",
                           _vector3("capsule", "center_of_mass_in_tip_m", self.center_of_mass_in_tip_m))


# Direction of jet 1's force at ring angle 0, in the tip frame (paper eq. 5, first column
# of A: (sin 60, cos 60) = 30 degrees from x). Jets 2 and 3 follow at -120 and -240 degrees.
_JET1_ANGLE_RAD = math.radians(30.0)
_JET_SPACING_RAD = math.radians(120.0)


@dataclass(frozen=True)
class JetLayout:
    """Three water jets spaced 120 degrees apart around the capsule, acting as follower forces
    in the tip frame's xy plane. ``ring_angle_rad`` rotates the whole ring about the tip z
    axis; at 0 the actuation matrix is exactly the paper's eq. 5."""

    ring_angle_rad: float = 0.0

    def __post_init__(self) -> None:
        _check_finite("jets", "ring_angle_rad", self.ring_angle_rad)

    def actuation_matrix(self) -> np.ndarray:
        """3x3 map from jet forces (N) to the tip-frame force (N); its z row is zero."""
        return actuation_matrix(self.ring_angle_rad)


@lru_cache(maxsize=64)
def actuation_matrix(ring_angle_rad: float) -> np.ndarray:
    """Eq. 5's A for a jet ring rotated by ``ring_angle_rad`` about the tip z axis, padded
    with a zero z row; shared and read-only (every packing of a problem asks for it)."""
    angles = _JET1_ANGLE_RAD - _JET_SPACING_RAD * np.arange(JET_COUNT) + ring_angle_rad
    matrix = np.zeros((3, JET_COUNT))
    matrix[0] = np.cos(angles)
    matrix[1] = np.sin(angles)
    matrix.flags.writeable = False
    return matrix


@dataclass(frozen=True)
class DisturbanceWrench:
    """The paper's w_d: a point wrench at the tip, in the tip frame (follows the tip)."""

    force_n: Vector3 = (0.0, 0.0, 0.0)
    moment_nm: Vector3 = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "force_n", _vector3("disturbance", "force_n", self.force_n))
        object.__setattr__(self, "moment_nm", _vector3("disturbance", "moment_nm", self.moment_nm))


@dataclass(frozen=True)
class ModelParameters:
    """Everything a model needs besides the jet forces.

    gravity_in_base_m_s2: gravitational acceleration in the base frame. The default
        (0, 0, 9.81) is a rod hanging straight down from its clamp.
    effect_values: values of effect parameters, keyed ``"effect.parameter"``; an effect
        parameter not listed takes its default.
    """

    rod: RodParameters = field(default_factory=RodParameters)
    capsule: CapsuleParameters = field(default_factory=CapsuleParameters)
    jets: JetLayout = field(default_factory=JetLayout)
    disturbance: DisturbanceWrench = field(default_factory=DisturbanceWrench)
    gravity_in_base_m_s2: Vector3 = (0.0, 0.0, 9.81)
    effect_values: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "gravity_in_base_m_s2",
                           _vector3("model", "gravity_in_base_m_s2", self.gravity_in_base_m_s2))
        values = dict(self.effect_values.items() if isinstance(self.effect_values, Mapping)
                      else self.effect_values)
        for key, value in values.items():
            if "." not in key:
                raise ValueError(f"effect_values key {key!r} must be 'effect.parameter'")
            _check_finite("effect_values", key, value)
        object.__setattr__(self, "effect_values", tuple(sorted((k, float(v)) for k, v in values.items())))

    def effect_value(self, key: str, default: float) -> float:
        for name, value in self.effect_values:
            if name == key:
                return value
        return default


# Flat names used by calibration and sensitivity, mapped to (section, field, component).
_CORE_PARAMETERS: dict[str, tuple[str, str, int | None]] = {
    "E0": ("rod", "youngs_modulus_base_pa", None),
    "EL": ("rod", "youngs_modulus_tip_pa", None),
    "L": ("rod", "length_m", None),
    "wd_fx": ("disturbance", "force_n", 0),
    "wd_fy": ("disturbance", "force_n", 1),
    "wd_fz": ("disturbance", "force_n", 2),
    "wd_mx": ("disturbance", "moment_nm", 0),
    "wd_my": ("disturbance", "moment_nm", 1),
    "wd_mz": ("disturbance", "moment_nm", 2),
}
PARAMETER_NAMES: tuple[str, ...] = tuple(_CORE_PARAMETERS)
# "section.field" of what those set: a parameter file's values replace a profile's there.
FITTED_FIELDS = frozenset(f"{section}.{name}" for section, name, _ in _CORE_PARAMETERS.values())

# Plausible values (low, high, unit) of the flat-named parameters when they come from a
# file: outside them is a unit slip (MPa written for Pa, mm for m) or a typo, not a soft
# continuum robot, and the model would fail or answer nonsense.
_FORCE_RANGE = (-10.0, 10.0, "N")
_MOMENT_RANGE = (-1.0, 1.0, "N m")
PLAUSIBLE_RANGES: dict[str, tuple[float, float, str]] = {
    "E0": (1e3, 1e9, "Pa"), "EL": (1e3, 1e9, "Pa"), "L": (0.005, 1.0, "m"),
    "wd_fx": _FORCE_RANGE, "wd_fy": _FORCE_RANGE, "wd_fz": _FORCE_RANGE,
    "wd_mx": _MOMENT_RANGE, "wd_my": _MOMENT_RANGE, "wd_mz": _MOMENT_RANGE,
}


def check_plausible(name: str, value: float, field_name: str | None = None) -> None:
    """ValueError naming ``field_name`` (default: the flat ``name``), the value and the
    unit when ``value`` is outside ``PLAUSIBLE_RANGES[name]``."""
    check_within(field_name or name, value, *PLAUSIBLE_RANGES[name])


def check_within(field_name: str, value: float, low: float, high: float, unit: str) -> None:
    """ValueError naming ``field_name``, the value and the unit when ``value`` is outside
    [low, high]: a unit slip or a typo rather than a rig."""
    if not low <= value <= high:
        raise ValueError(f"{field_name} = {value:g} {unit} is outside the plausible range "
                         f"{low:g} .. {high:g} {unit} (a unit slip?)")


DISTURBANCE_MOMENT_NAMES: tuple[str, ...] = ("wd_mx", "wd_my", "wd_mz")
DISTURBANCE_NAMES: tuple[str, ...] = ("wd_fx", "wd_fy", "wd_fz") + DISTURBANCE_MOMENT_NAMES

# Typical magnitudes, used to scale finite-difference steps and optimiser variables when
# a parameter's own value is zero (a disturbance usually starts at zero).
PARAMETER_SCALES: dict[str, float] = {
    "E0": 1e5, "EL": 1e5, "L": 0.05,
    "wd_fx": 1e-2, "wd_fy": 1e-2, "wd_fz": 1e-2,
    "wd_mx": 1e-3, "wd_my": 1e-3, "wd_mz": 1e-3,
}


def get_parameter(params: ModelParameters, name: str, default: float | None = None) -> float:
    """Value of a flat-named parameter; effect parameters fall back to ``default``."""
    if name in _CORE_PARAMETERS:
        section, field_name, component = _CORE_PARAMETERS[name]
        value = getattr(getattr(params, section), field_name)
        return float(value if component is None else value[component])
    if "." in name:
        if default is None:
            raise KeyError(f"effect parameter {name!r} has no value and no default was given")
        return params.effect_value(name, default)
    raise KeyError(f"unknown parameter {name!r}; expected one of {', '.join(PARAMETER_NAMES)} "
                   "or 'effect.parameter'")


def with_parameters(params: ModelParameters, values: Mapping[str, float]) -> ModelParameters:
    """A copy of ``params`` with flat-named parameters replaced (validated as usual)."""
    sections: dict[str, dict[str, object]] = {}
    effect_values = dict(params.effect_values)
    for name, value in values.items():
        if name in _CORE_PARAMETERS:
            section, field_name, component = _CORE_PARAMETERS[name]
            changes = sections.setdefault(section, {})
            if component is None:
                changes[field_name] = float(value)
            else:
                current = list(changes.get(field_name, getattr(getattr(params, section), field_name)))
                current[component] = float(value)
                changes[field_name] = tuple(current)
        elif "." in name:
            effect_values[name] = float(value)
        else:
            raise KeyError(f"unknown parameter {name!r}; expected one of {', '.join(PARAMETER_NAMES)} "
                           "or 'effect.parameter'")
    updated = {section: replace(getattr(params, section), **changes) for section, changes in sections.items()}
    return replace(params, **updated, effect_values=tuple(effect_values.items()))

