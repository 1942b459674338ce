"""Self-weight of the soft body and weight of the tip capsule."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .base import CALIBRATION_POSES, EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem


class Gravity:
    name: ClassVar[str] = "gravity"
    explanation: ClassVar[str] = (
        "The elastomer body weighs rho*A*g per unit length and the capsule hangs its weight "
        "m*g at its centre of mass, ahead of the rod tip. Both pull the rod towards the "
        "floor whatever the jets do, so the error they cause depends on how the robot is "
        "oriented relative to gravity: largest when the rod bends across the vertical, "
        "and in the same direction for every jet. weight_scale corrects the nominal "
        "masses (water in the lumens, a heavier capsule)."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("weight_scale", 1.0, 0.0, 3.0, "1",
                        "multiplies the nominal rod and capsule weight",
                        physical_upper=6.0,
                        limit_reason="0: weightless; 6: a rod six times its nominal weight sinks further than "
                                     "water-filled lumens and a lead-filled capsule can make it (3 already "
                                     "doubles the capsule's mass and fills every lumen)"),
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        params = problem.params
        gravity = np.asarray(params.gravity_in_base_m_s2) * values["weight_scale"]
        problem.distributed_force_in_base_n_m = (
            problem.distributed_force_in_base_n_m + params.rod.mass_per_length_kg_m * gravity
        )
        if params.capsule.mass_kg > 0.0:
            problem.add_tip_dead_force(params.capsule.mass_kg * gravity,
                                       np.asarray(params.capsule.center_of_mass_in_tip_m))
