"""A cable pulling the capsule sideways with a force of fixed direction."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .base import CALIBRATION_POSES, EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem

# Search bounds: a third of one jet's full 0.15 N either way, what a sensor lead or a
# tube draped off the bench plausibly pulls. Physical limits: twice a jet's full force;
# a pull that strong holds the tip against the jets, a fixture rather than a lead.
_FORCE_BOUNDS_N = (-0.05, 0.05)
_FORCE_LIMITS_N = (-0.3, 0.3)
_LIMIT_REASON = "0.3 N is twice one jet's full force: a pull that holds the tip against the jets is a fixture"


class TipPull:
    """A dead force at the rod tip, fixed in the base frame (so in the tracker frame: the
    clamp does not move), across the clamp axis: components along the base x and y axes
    (N). Along the clamp axis a pull only stretches an inextensible rod, and on a
    hanging rod it would be the capsule's weight, which `gravity` already scales."""

    name: ClassVar[str] = "tip_pull"
    explanation: ClassVar[str] = (
        "Something tied to the capsule pulls it sideways with a constant force of fixed "
        "direction: the EM sensor's lead, a supply tube or a safety line anchored off to "
        "the side. Unlike the calibrated disturbance w_d, which turns with the tip, this "
        "force keeps its direction while the rod bends; unlike gravity it acts at the tip "
        "only and need not point down. Every pose shifts the same way, most where the rod "
        "is stiff against it; a tilted tracker (gravity turned sideways) looks much the "
        "same, and the level check of `run` tells them apart."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = tuple(
        EffectParameter(f"force_{axis}_n", 0.0, *_FORCE_BOUNDS_N, "N",
                        f"pull on the tip along the base frame's {axis} axis", *_FORCE_LIMITS_N,
                        limit_reason=_LIMIT_REASON)
        for axis in "xy"
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.add_tip_dead_force(np.array([values["force_x_n"], values["force_y_n"], 0.0]), np.zeros(3))
