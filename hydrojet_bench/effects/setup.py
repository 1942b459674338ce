"""Setup errors as effects: a rig wired or described wrongly, written so a model can fit them.

They are not physics and not in the library: `analysis.diagnosis.setup` tries them
before any physical effect, and a fit of one says which profile key or cable to change.
Each default leaves the model unchanged, like a library effect's.

* `JetWiring`: one of the five wrong permutations of the valve cables (no parameter).
* `TrackerTilt`: gravity turned by two angles about axes perpendicular to it (a field
  generator that is not level, or a wrong ``[gravity]``).
* `BaseSensorMounting`: the base sensor turned in the clamp by a rotation vector; it turns
  the frame every measurement is expressed in, gravity included.
* `JetForceSign`: every jet force reversed (the jets pull where the convention pushes).
* `JetForceUnit`: every jet force scaled by a unit ratio (`FORCE_UNIT_MISTAKES`: the
  valve calibration's forces in gf or mN, or multiplied by g, not in N).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from ..geometry import so3_exp
from .base import EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem

# Wider than any library effect: a setup error is not small by nature (a clamp put on a
# quarter turn off, a field generator on a ramp). Past 0.8 rad (46 degrees) a
# rotation is no longer an error of mounting but another rig.
_ROTATION_LIMIT_RAD = 0.8


def rotate_gravity_load(problem: RodProblem, rotation: np.ndarray) -> None:
    """Turn the weight of rod and capsule from the parameters' gravity g to ``rotation @ g``
    by adding the difference (the gravity effect has added m g already)."""
    params = problem.params
    gravity = np.asarray(params.gravity_in_base_m_s2)
    change = rotation @ gravity - gravity
    problem.distributed_force_in_base_n_m = (problem.distributed_force_in_base_n_m
                                             + params.rod.mass_per_length_kg_m * change)
    if params.capsule.mass_kg > 0.0:
        problem.add_tip_dead_force(params.capsule.mass_kg * change, np.asarray(params.capsule.center_of_mass_in_tip_m))


def tilt_axes(gravity_in_base_m_s2: np.ndarray) -> np.ndarray:
    """(2, 3) unit axes perpendicular to gravity (base frame) that `TrackerTilt` turns it
    about: the first also perpendicular to the base x axis (or y, if gravity is along x)."""
    down = np.asarray(gravity_in_base_m_s2, dtype=float)
    down = down / np.linalg.norm(down)
    reference = np.array([1.0, 0.0, 0.0]) if abs(down[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    first = np.cross(down, reference)
    first /= np.linalg.norm(first)
    return np.array([first, np.cross(down, first)])


def tilt_rotation(gravity_in_base_m_s2: np.ndarray, about_u_rad: float, about_v_rad: float) -> np.ndarray:
    """The rotation `TrackerTilt` applies to gravity (base frame)."""
    return so3_exp(np.array([about_u_rad, about_v_rad]) @ tilt_axes(gravity_in_base_m_s2))


class TrackerTilt:
    name: ClassVar[str] = "tracker_tilt"
    explanation: ClassVar[str] = (
        "Gravity in the tracker frame is not the profile's: the EM field generator stands "
        "tilted, or the profile's gravity.in_tracker_m_s2 is wrong. The weight then pulls the rod "
        "sideways to where the model expects, by the same amount whatever the jets do, "
        "most where the rod bends across gravity."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = tuple(
        EffectParameter(f"about_{axis}_rad", 0.0, -_ROTATION_LIMIT_RAD, _ROTATION_LIMIT_RAD, "rad",
                        f"turn of gravity about the {label} axis perpendicular to it (see effects.setup.tilt_axes)")
        for axis, label in (("u", "first"), ("v", "second"))
    )
    uses_actuation: ClassVar[bool] = False

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        rotate_gravity_load(problem, tilt_rotation(problem.params.gravity_in_base_m_s2, values["about_u_rad"],
                                                   values["about_v_rad"]))


class BaseSensorMounting:
    """The measured clamp frame is the true one turned by M = exp(r) about the base
    sensor's origin o (``sensor_offset_in_clamp_m``, the profile's
    ``base_sensor.offset_in_base_m``): the tip orientation in the base frame reads
    M^T R_tip, a tip position reads M^T (p - o) + o, and gravity from the base pose
    reads M^T g."""

    name: ClassVar[str] = "base_sensor_mounting"
    explanation: ClassVar[str] = (
        "The base sensor sits in the clamp turned by a rotation (rx, ry, rz, clamp frame) "
        "that the profile's base_sensor.rotation_in_base does not state. Every tip pose is then read "
        "in a turned frame, and gravity carried through the base pose is turned alike: "
        "about the rod axis it looks like a turned jet ring (jet_misalignment), across it "
        "like a tilted tracker plus a tip-sensor mounting."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = tuple(
        EffectParameter(f"r{axis}_rad", 0.0, -_ROTATION_LIMIT_RAD, _ROTATION_LIMIT_RAD, "rad",
                        f"{axis} component of the base sensor's unknown rotation vector, clamp frame")
        for axis in "xyz"
    )
    uses_actuation: ClassVar[bool] = False

    def __init__(self, sensor_offset_in_clamp_m: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.sensor_offset_in_clamp_m = np.array(sensor_offset_in_clamp_m, dtype=float)

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        rotation = so3_exp([values["rx_rad"], values["ry_rad"], values["rz_rad"]])
        rotate_gravity_load(problem, rotation)
        problem.base_sensor_mounting = problem.base_sensor_mounting @ rotation
        problem.base_sensor_offset_m = self.sensor_offset_in_clamp_m


class JetWiring:
    """The valve cable of commanded jet i drives physical jet ``wiring[i]`` (1-based)."""

    explanation: ClassVar[str] = (
        "The valve cables are not on the jets the profile says: a command for one jet "
        "fires another. Each jet's bend then points towards another jet's side (120 "
        "degrees off), which no physical effect within its limits can mimic."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    uses_actuation: ClassVar[bool] = True

    def __init__(self, wiring: tuple[int, int, int]) -> None:
        self.wiring = tuple(wiring)
        self.name = "jet_wiring_" + "".join(str(j) for j in self.wiring)

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        physical = np.empty(3)
        physical[np.array(self.wiring) - 1] = problem.jet_forces_n
        problem.jet_forces_n = physical


WRONG_WIRINGS: tuple[tuple[int, int, int], ...] = tuple(
    w for w in itertools.permutations((1, 2, 3)) if w != (1, 2, 3))  # type: ignore[misc]


class JetForceSign:
    """Every jet pulls where the profile's convention has it push: each force reversed."""

    name: ClassVar[str] = "jet_force_sign"
    explanation: ClassVar[str] = (
        "The jet forces act opposite to the profile's sign convention (the jets pull where it "
        "has them push): each jet bends the tip 180 degrees from where the model expects, "
        "which no physical effect within its limits can mimic."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    uses_actuation: ClassVar[bool] = True

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.jet_forces_n = -problem.jet_forces_n


G_N_PER_KGF = 9.80665
# Valve calibration forces typed in another unit than N (see drivers.valve.calibration):
# (name suffix, physical force / commanded force, the mistake). A table whose numbers
# are c times the true newtons makes the jets push 1/c times the command. Mistakes the
# other way (kilogram-force entered as N) are not listed: the valves clip every command
# past the table's end, so the rig plays its full force at nearly every step.
FORCE_UNIT_MISTAKES: tuple[tuple[str, float, str], ...] = (
    ("times_g", 1.0 / G_N_PER_KGF, "newtons multiplied by g as if they were kilograms"),
    ("gf", G_N_PER_KGF / 1000.0, "gram-force (a scale's g) entered as N"),
    ("mn", 1e-3, "millinewtons entered as N"),
)


class JetForceUnit:
    """Every jet produces ``ratio`` times the commanded force: the valve calibration's
    forces in another unit than N (one of `FORCE_UNIT_MISTAKES`)."""

    parameters: ClassVar[tuple[EffectParameter, ...]] = ()
    uses_actuation: ClassVar[bool] = True

    def __init__(self, unit: str, ratio: float, mistake: str) -> None:
        self.unit, self.ratio, self.mistake = unit, float(ratio), mistake
        self.name = f"jet_force_unit_{unit}"
        self.explanation = (f"The jets push {self.ratio:.4g} times the force commanded: the valve calibration's "
                            f"forces look like {mistake}. Every bend the jets make scales alike while the rod's "
                            "weight stays: where gravity bends the rod (a tilted rig) no stiffness mimics that; "
                            "on a hanging rod a stiffer rod does.")

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.jet_forces_n = self.ratio * problem.jet_forces_n


def setup_effects(base_sensor_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> tuple[object, ...]:
    """Every setup hypothesis: the five wrong wirings, the reversed force sign, the force
    unit mistakes, the tracker tilt, the base mounting (turning about the base sensor's
    origin in the clamp frame, m: the profile's ``base_sensor.offset_in_base_m``)."""
    return (tuple(JetWiring(w) for w in WRONG_WIRINGS) + (JetForceSign(),)
            + tuple(JetForceUnit(*mistake) for mistake in FORCE_UNIT_MISTAKES)
            + (TrackerTilt(), BaseSensorMounting(base_sensor_offset_m)))
