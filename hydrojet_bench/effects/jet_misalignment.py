"""The jet ring turned about the tip axis relative to where the model puts it."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

from .base import CALIBRATION_POSES, EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem

# Jets sit 120 degrees apart: past +-60 degrees (the physical limit) a misalignment is
# a relabelling of the jets, not a misalignment. +-30 degrees covers a capsule glued
# on, or a rod clamped, rotated by eye with room to spare.
_LIMIT_RAD = math.pi / 6.0
_RELABELLING_RAD = math.pi / 3.0


class JetMisalignment:
    """Adds ``ring_angle_rad`` to the profile's jet ring angle (about the tip z axis,
    right-handed). For an isotropic rod, clamping the rod rotated about its own axis by
    the same angle is the same physics, so this covers both.

    Identifiability (40 paper poses up to 0.15 N, noise-free, 0.1 rad): fitting E0, EL, L
    and w_d alone leaves 5.6 of its 6.9 deg RMS (rod hanging along gravity)."""

    name: ClassVar[str] = "jet_misalignment"
    explanation: ClassVar[str] = (
        "The jet ring sits turned about the tip axis by ring_angle_rad from where the model "
        "puts it: the capsule glued on with a roll error, or the rod clamped rotated about "
        "its own axis (for a round rod the same thing). Every jet then pushes in a "
        "direction turned by that angle, so every bending plane turns by it, in the same "
        "sense for all three jets: the error is sideways to the bend and grows with it. A "
        "constant wrench cannot mimic it (it scales with the jet forces), and a rotated "
        "tip sensor twists the reading about the tip axis instead of moving the tip "
        "sideways."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("ring_angle_rad", 0.0, -_LIMIT_RAD, _LIMIT_RAD, "rad",
                        "rotation of the jet ring about the tip z axis, added to the profile's",
                        physical_lower=-_RELABELLING_RAD, physical_upper=_RELABELLING_RAD,
                        limit_reason="past 60 degrees the ring is closer to the next jet's place: a "
                                     "relabelling of the jets"),
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.jet_ring_angle_rad = problem.jet_ring_angle_rad + values["ring_angle_rad"]
