"""A fixed rotation between the tip sensor and the capsule it sits in."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

from ..geometry import so3_exp
from .base import CALIBRATION_POSES, EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem

# 0.25 rad (14 degrees) per axis: a coil or IMU glued into the 9.8 mm capsule by eye is
# off by a few degrees; anything near the bound is an assembly fault you can see.
# Physical limit 0.8 rad (46 degrees) per axis: past it the sensor lies across its
# capsule's bore, which it cannot fit in.
_LIMIT_RAD = 0.25
_PHYSICAL_LIMIT_RAD = 0.8


class SensorMounting:
    """Tip sensor orientation = tip frame @ exp(r), r = (rx, ry, rz) in the tip frame.

    Why the tip side: the measurement is the tip sensor relative to the base sensor, B^T
    R_tip M. A base mounting error B is the rotation R (R^T B^T R) on the tip side,
    nearly the same constant rotation at the bends of tens of degrees where most poses
    lie, so fitting both (six numbers) would be ill-conditioned, while the tip sensor is
    the one glued by hand into a small capsule. For a round rod hanging along gravity, a
    base error about the rod axis is exactly a tip mounting rz plus a turn of every
    bending plane, which jet_misalignment models.

    Identifiability (40 paper poses up to 0.15 N, linearised, 0.05 rad): fitting E0, EL,
    L and w_d leaves 17 % of the rx or ry signal (0.48 of 2.9 deg, hanging rod), 91 % of
    rz's.

    Calibration caveat: `calibrate` builds its Jacobian from the tip-pose sensitivity,
    to which a mounting contributes nothing, so these parameters need a Jacobian column
    of their own there (the reading changes by the mounting rotation itself)."""

    name: ClassVar[str] = "sensor_mounting"
    explanation: ClassVar[str] = (
        "The tip sensor sits in the capsule turned by a small fixed rotation (rx, ry, rz, "
        "tip frame): a coil or IMU glued in by eye, or a capsule seated askew. It changes "
        "the reading, not the shape: every measured tip orientation is off by the same "
        "rotation in the tip frame whatever the jets do, and tip positions are untouched. "
        "rx and ry look much like a constant tip moment (w_d's moment bends the rod by a "
        "nearly constant angle), which absorbs most of them; what remains grows with the "
        "bend, and tip positions (the moment moves the tip, the mounting does not) "
        "separate the two. rz, a roll about the tip axis, stays distinct. A misaligned "
        "base sensor is nearly the same constant rotation, so this one stands for both."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = tuple(
        EffectParameter(f"r{axis}_rad", 0.0, -_LIMIT_RAD, _LIMIT_RAD, "rad",
                        f"{axis} component of the mounting rotation vector, tip frame",
                        -_PHYSICAL_LIMIT_RAD, _PHYSICAL_LIMIT_RAD,
                        limit_reason="past 0.8 rad (46 degrees) the sensor lies across the capsule's bore")
        for axis in "xyz"
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        rotation = so3_exp([values["rx_rad"], values["ry_rad"], values["rz_rad"]])
        problem.tip_sensor_mounting = problem.tip_sensor_mounting @ rotation
