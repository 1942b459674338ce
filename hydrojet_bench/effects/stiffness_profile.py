"""A Young's modulus that is not linear along the rod."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

from .base import CALIBRATION_POSES, EffectParameter, scale_modulus

if TYPE_CHECKING:
    from .problem import RodProblem

# -0.5 halves E at mid-span, +0.5 adds half: an elastomer mixed or cured that unevenly
# along 70 mm is a bad batch; it also keeps E well above zero everywhere.
# Physical limits: -0.9 leaves a tenth of E at mid-span (at -1 the rod has a hinge
# there); +2 triples it, a sleeve or a second material rather than a curing gradient.
_AMPLITUDE_BOUNDS = (-0.5, 0.5)
_AMPLITUDE_LIMITS = (-0.9, 2.0)


class StiffnessProfile:
    """E(s) = E_lin(s) (1 + a 4 (s/L) (1 - s/L)), E_lin the linear E0 -> EL profile;
    bending and torsion alike. The bump is zero at both ends, so E0 and EL keep their
    meaning (moduli at base and tip), and it is the lowest-order shape a linear profile
    cannot represent.

    Identifiability (40 paper poses up to 0.15 N, noise-free, a = 0.2): fitting E0, EL,
    L and w_d leaves 0.000 deg RMS of its 5.7 deg (hanging rod) and 0.05 of 8.1 deg
    (gravity across) in orientations; with tip positions it is recovered exactly.
    Other shapes (x^2, an antisymmetric cubic, localised bumps) fare no better: any
    smooth change of E along the rod is absorbed in orientations."""

    name: ClassVar[str] = "stiffness_profile"
    explanation: ClassVar[str] = (
        "The modulus does not vary linearly along the rod: uneven mixing or curing, or a "
        "sleeve over part of it, makes the middle stiffer (a > 0) or softer (a < 0) than "
        "the straight line from E0 to EL, E(s) = E_lin(s) (1 + a 4 (s/L)(1 - s/L)), "
        "untouched at both ends. The error lies in the bending plane and is alike for "
        "every jet; it changes how a tip force (lever arm L - s) and the rod's weight "
        "(arm ~ (L - s)^2) bend the rod relative to each other, and how far the tip "
        "travels for a given tip angle. E0, EL and L redistribute compliance along the rod "
        "too and absorb nearly all of it in orientations: diagnose it from measured tip "
        "positions."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("mid_span_amplitude", 0.0, *_AMPLITUDE_BOUNDS, "1",
                        "relative change of E at mid-span over the linear profile", *_AMPLITUDE_LIMITS,
                        limit_reason="-0.9 leaves a tenth of E at mid-span (-1 is a hinge); +2 triples it, a "
                                     "sleeve rather than a curing gradient"),
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        fraction = problem.arc_length_m / problem.params.rod.length_m
        scale_modulus(problem, 1.0 + values["mid_span_amplitude"] * 4.0 * fraction * (1.0 - fraction))
