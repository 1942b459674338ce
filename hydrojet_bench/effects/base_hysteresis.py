"""Friction and play at the clamp: loading and unloading follow different branches."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

from .base import SWEEPS, EffectParameter
from .base_compliance import (COMPLIANCE_BOUNDS_RAD_PER_NM, COMPLIANCE_LIMIT_RAD_PER_NM, COMPLIANCE_LIMIT_REASON,
                              add_clamp_bending_compliance)

if TYPE_CHECKING:
    from .problem import RodProblem

# 0.05 rad (3 degrees) of play is a visibly loose clamp; the EM tracker resolves 0.7
# degrees, so plays from ~0.01 rad up are measurable. Physical limit 0.3 rad (17
# degrees): the rod would flop in a clamp that loose instead of being held.
_PLAY_BOUNDS_RAD = (0.0, 0.05)
_PLAY_LIMIT_RAD = 0.3


class BaseHysteresis:
    """A compliant clamp (as `BaseCompliance`) whose rotation only follows the demanded
    compliance x moment once it leaves a ball of radius ``play_rad`` around where the
    clamp last stopped. The clamp's state travels with ``previous=`` in `solve`; a solve
    without one starts from a clamp at rest (a dead zone, not a loop)."""

    name: ClassVar[str] = "base_hysteresis"
    explanation: ClassVar[str] = (
        "Friction or play in the clamp: the rod's end turns with the clamp moment as in "
        "base_compliance, but it only moves once the demanded turn leaves a play zone of "
        "play_rad around where it last stopped, so loading and unloading follow different "
        "branches. The signature is path dependence: the same jet forces read differently "
        "going up and coming down a sweep (up to about twice the play, in the bending "
        "plane), and the rod does not come back to its start at zero force. A constant "
        "wrench or any elastic effect gives one answer per force and cannot show it; only "
        "data solved along its recorded path can identify the play. Its compliance is "
        "base_compliance's, which orientations alone cannot tell from a longer rod."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("compliance_rad_per_nm", 0.0, *COMPLIANCE_BOUNDS_RAD_PER_NM, "rad/(N m)",
                        "clamp rotation per unit bending moment at the clamp, outside the play",
                        physical_upper=COMPLIANCE_LIMIT_RAD_PER_NM, limit_reason=COMPLIANCE_LIMIT_REASON),
        EffectParameter("play_rad", 0.0, *_PLAY_BOUNDS_RAD, "rad",
                        "radius of the play zone the demanded clamp rotation must leave",
                        physical_upper=_PLAY_LIMIT_RAD,
                        limit_reason="0.3 rad (17 degrees) of play: the rod flops in the clamp instead of "
                                     "being held"),
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = SWEEPS

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        add_clamp_bending_compliance(problem, values["compliance_rad_per_nm"])
        problem.base_play_rad = problem.base_play_rad + values["play_rad"]
