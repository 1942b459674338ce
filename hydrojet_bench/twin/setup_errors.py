"""Setup errors a twin can simulate: a rig wired or described wrongly, physics nominal.

`SetupErrors` is one frozen struct of the mistakes a careful experimenter lists first:

* ``jet_wiring``: the valve cable of commanded jet i drives physical jet
  ``jet_wiring[i]`` (1-based), so (1, 2, 3) is correct, (2, 1, 3) has the cables of
  jets 1 and 2 swapped, (2, 3, 1) is wired one position round;
* ``tracker_tilt_deg``: the EM field generator is not level: true gravity in the tracker
  frame is the profile's turned about the tracker's x axis, then its y axis, by these
  angles (degrees);
* ``base_sensor_rotvec_rad``: the base sensor sits in the clamp turned by this rotation
  vector (rad, clamp frame) on top of the mounting the profile states;
* ``jet_force_sign``: -1 when every jet pulls where the profile's convention has it
  push (the force reversed);
* ``jet_force_scale``: every jet produces this multiple of the force commanded (the
  valve calibration's forces in another unit than N: 1/9.80665 for newtons multiplied
  by g as if they were kilograms, 9.80665e-3 for gram-force read as N).

Each physical jet force is sign x scale x the commanded force of the jet its cable
reaches.

`SETUP_ERRORS` maps the names ``simulate --hidden NAME=VALUE`` accepts to the field each
sets, and `parse_setup_error` reads one such value (a user mistake is a `UserError`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from ..errors import UserError
from ..geometry import so3_exp
from ..params import JET_COUNT

CORRECT_WIRING = (1, 2, 3)
# Limits of a rig set up wrongly, not of another rig; `effects.setup` fits its setup
# errors within 0.8 rad (46 degrees) alike, and past them the diagnosing models stop
# solving (measured on the short plan: study cells at the limits below run; a 90 degree
# tilt, a half-turn base sensor or a doubled jet force on the hanging rod fail).
# A field generator on a 45 degree ramp, about either axis:
TILT_LIMIT_DEG = 45.0
# A base sensor turned in its clamp, per component of the rotation vector:
ROTVEC_LIMIT_RAD = 0.8
# Millinewtons entered as N (the smallest slip of `effects.setup.FORCE_UNIT_MISTAKES`) up
# to half again the command; the valves clip a table in a larger unit rather than push more.
JET_FORCE_SCALE_LIMITS = (1e-3, 1.5)


@dataclass(frozen=True)
class SetupErrors:
    """See the module docstring; the defaults are a correctly set-up rig."""

    jet_wiring: tuple[int, int, int] = CORRECT_WIRING
    tracker_tilt_deg: tuple[float, float] = (0.0, 0.0)
    base_sensor_rotvec_rad: tuple[float, float, float] = (0.0, 0.0, 0.0)
    jet_force_sign: int = 1
    jet_force_scale: float = 1.0

    def __post_init__(self) -> None:
        if self.jet_force_sign not in (1, -1) or isinstance(self.jet_force_sign, bool):
            raise ValueError(f"SetupErrors.jet_force_sign must be 1 or -1, got {self.jet_force_sign!r}")
        object.__setattr__(self, "jet_force_sign", int(self.jet_force_sign))
        scale = float(self.jet_force_scale)
        if not (math.isfinite(scale) and scale > 0.0):
            raise ValueError(f"SetupErrors.jet_force_scale must be a finite number > 0, got {self.jet_force_scale!r}")
        low, high = JET_FORCE_SCALE_LIMITS
        if not low <= scale <= high:
            raise ValueError(f"SetupErrors.jet_force_scale must be from {low:g} (millinewtons entered as N) to "
                             f"{high:g} (half again the command), got {self.jet_force_scale!r}")
        object.__setattr__(self, "jet_force_scale", scale)
        wiring = tuple(self.jet_wiring)
        if sorted(wiring) != list(CORRECT_WIRING) or any(isinstance(j, bool) for j in wiring):
            raise ValueError(f"SetupErrors.jet_wiring must be a permutation of 1, 2, 3, got {self.jet_wiring!r}")
        object.__setattr__(self, "jet_wiring", tuple(int(j) for j in wiring))
        for name, size in (("tracker_tilt_deg", 2), ("base_sensor_rotvec_rad", 3)):
            values = tuple(float(v) for v in getattr(self, name))
            if len(values) != size or not all(math.isfinite(v) for v in values):
                raise ValueError(f"SetupErrors.{name} must be {size} finite numbers, got {getattr(self, name)!r}")
            object.__setattr__(self, name, values)
        if any(abs(v) > TILT_LIMIT_DEG for v in self.tracker_tilt_deg):
            raise ValueError(f"SetupErrors.tracker_tilt_deg must be angles from {-TILT_LIMIT_DEG:g} to "
                             f"{TILT_LIMIT_DEG:g} degrees (a field generator on a ramp; more is another rig), "
                             f"got {self.tracker_tilt_deg!r}")
        if any(abs(v) > ROTVEC_LIMIT_RAD for v in self.base_sensor_rotvec_rad):
            raise ValueError(f"SetupErrors.base_sensor_rotvec_rad must be 3 components from {-ROTVEC_LIMIT_RAD:g} to "
                             f"{ROTVEC_LIMIT_RAD:g} rad (46 degrees; more is another rig, or degrees typed as "
                             f"radians), got {self.base_sensor_rotvec_rad!r}")

    @property
    def any(self) -> bool:
        return self != SetupErrors()

    def physical_jet_forces_n(self, commanded_n: np.ndarray) -> np.ndarray:
        """The forces (N) the physical jets 1..3 produce for forces commanded per cable."""
        physical = np.empty(JET_COUNT)
        physical[np.array(self.jet_wiring) - 1] = self.jet_force_sign * self.jet_force_scale * np.asarray(commanded_n)
        return physical

    def tilt_rotation(self) -> np.ndarray:
        """True gravity in the tracker frame = this matrix @ the profile's."""
        about_x, about_y = np.radians(self.tracker_tilt_deg)
        return so3_exp([0.0, about_y, 0.0]) @ so3_exp([about_x, 0.0, 0.0])

    def base_mounting_rotation(self) -> np.ndarray:
        """The base sensor's unknown extra rotation, clamp frame (applied before the
        profile's stated mounting)."""
        return so3_exp(self.base_sensor_rotvec_rad)


# simulate --hidden NAME=VALUE: NAME -> (field, number of comma-separated values).
SETUP_ERRORS: dict[str, tuple[str, int]] = {
    "jet_wiring": ("jet_wiring", JET_COUNT),
    "tracker_tilt_deg": ("tracker_tilt_deg", 2),
    "base_sensor_rotvec": ("base_sensor_rotvec_rad", 3),
    "jet_force_sign": ("jet_force_sign", 1),
    "jet_force_scale": ("jet_force_scale", 1),
}


def setup_error_text(name: str, values: tuple[float, ...]) -> str:
    """``name=v1,v2,...``: how `parse_setup_error` (and ``simulate --hidden``) takes it."""
    return f"{name}=" + ",".join(f"{v:g}" for v in values)


def parse_setup_error(text: str, errors: SetupErrors = SetupErrors()) -> SetupErrors:
    """``errors`` with one ``NAME=v1,v2,...`` applied (NAME from `SETUP_ERRORS`)."""
    name, equals, values = text.partition("=")
    if not equals or name not in SETUP_ERRORS:
        raise UserError(f"setup error {text!r}: a setup error is NAME=VALUES with NAME one of {', '.join(SETUP_ERRORS)}")
    field_name, size = SETUP_ERRORS[name]
    wanted = "one number" if size == 1 else f"{size} comma-separated numbers"
    try:
        numbers = tuple(float(v) for v in values.split(","))
    except ValueError:
        raise UserError(f"setup error {text!r}: {name} takes {wanted}") from None
    if len(numbers) != size:
        raise UserError(f"setup error {text!r}: {name} takes {wanted}, got {len(numbers)}")
    value: object = numbers[0] if size == 1 else numbers
    if field_name in ("jet_wiring", "jet_force_sign"):
        if not all(v == int(v) for v in numbers):
            raise UserError(f"setup error {text!r}: {name} takes integers")
        value = int(numbers[0]) if size == 1 else tuple(int(v) for v in numbers)
    changes = {f.name: getattr(errors, f.name) for f in fields(SetupErrors)}
    changes[field_name] = value
    try:
        result = SetupErrors(**changes)  # type: ignore[arg-type]
    except ValueError as error:
        raise UserError(f"setup error {text!r}: {error}") from None
    if getattr(result, field_name) == getattr(SetupErrors(), field_name):
        raise UserError(f"setup error {text!r}: that is the rig as the profile describes it and would hide "
                        f"nothing; give {name} another value")
    return result
