"""Strain stiffening or softening of the elastomer at large curvature."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

from .base import CALIBRATION_POSES, EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem

# The surface strain of the section is k r (13 % at 30 1/m for r = 4.5 mm), and a
# hyperelastic or fibre-laden section changes its tangent stiffness by a factor of order
# (k r)^2, so beta's natural scale is r^2 = 2e-5 m^2.
# Upper, 10 r^2: +18 % moment at 30 1/m, +72 % at the ~60 1/m of a 0.15 N jet.
# Lower, -r^2: softening makes the section's moment peak at |k|^2 = 1 / (3 |beta|), past
# which the kernel has no curvature (NaN); a 0.15 N single jet with gravity across
# stops solving at about -4.5e-5 m^2 (measured, both models), so -2e-5 keeps a factor
# of two for a calibrated E below nominal and bends past the ~130 degrees of a sweep.
# Physical limits: -4e-5 m^2, just short of where the models stop solving; 2e-3 m^2
# (100 r^2): the section's moment nine times the linear one at the ~60 1/m of a 0.15 N
# jet, the stiffening of a fibre-laden section pulled taut, beyond any elastomer.
_BETA_BOUNDS_M2 = (-2e-5, 2e-4)
_BETA_LIMITS_M2 = (-4e-5, 2e-3)


class NonlinearElasticity:
    """Bending law m = EI (k + beta |k|^2 k) on the bending components (k measured from
    the intrinsic curvature); torsion stays linear.

    Identifiability (40 paper poses up to 0.15 N, noise-free, beta = 5e-5 m^2): fitting
    E0, EL, L and w_d alone leaves 0.001 deg RMS of its 2.1 deg when the rod hangs along
    gravity, 0.79 of 4.0 deg with gravity across; with tip positions it is recovered
    exactly in both."""

    name: ClassVar[str] = "nonlinear_elasticity"
    explanation: ClassVar[str] = (
        "The elastomer's moment-curvature law is not linear at large bends: m = EI (k + "
        "beta |k|^2 k); beta > 0 stiffens (lumen walls and fibres pulled taut), beta < 0 "
        "softens. The relative change is beta k^2, so small bends are untouched and the "
        "error grows like the cube of the curvature, in the bending plane and the same "
        "for every jet: the model overshoots (softening: undershoots) the largest bends of "
        "every sweep while the small ones stay right. With the rod hanging along gravity "
        "the calibration largely absorbs it: a round rod's poses then lie on one curve, "
        "bend against net jet force, which E0, EL, L and w_d reshape freely; gravity "
        "across the rod, or measured tip positions, expose it. In single-jet sweeps it "
        "resembles pressure_stiffening, which poses with two jets at once tell apart."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("beta_m2", 0.0, *_BETA_BOUNDS_M2, "m^2",
                        "cubic stiffening coefficient (negative: softening)", *_BETA_LIMITS_M2,
                        limit_reason="-4e-5 m^2: softer sections stop solving at a 0.15 N bend; 2e-3 m^2: nine "
                                     "times the linear moment at 60 1/m, past any fibre-laden elastomer"),
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        problem.cubic_stiffening_m2 = problem.cubic_stiffening_m2 + values["beta_m2"]
