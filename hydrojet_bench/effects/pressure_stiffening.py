"""Stiffness that rises with the water pressure driving the jets."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .base import EffectParameter, SWEEPS, scale_modulus

if TYPE_CHECKING:
    from .problem import RodProblem

# The total commanded jet force stands in for the lumen pressure (thrust ~ pressure x
# nozzle area). Upper 4 /N: EI x 1.6 at one jet's full 0.15 N, x 2.8 with all three at
# full force, a pressurised elastomer tube far stiffer than its wall. Lower -1 /N (EI
# x 0.85 at 0.15 N, x 0.55 at 0.45 N): physically the lumens stiffen, but a bound
# below zero lets a fit of an absent effect scatter around 0 instead of piling up on
# a bound, and keeps the stiffness positive for any command the jets can reach.
# Physical limits: -2 /N keeps EI positive with all three jets at full force (x 0.1 at
# 0.45 N); 20 /N makes a lumen at full force ten times stiffer than its wall, a rigid
# tube rather than a pressurised elastomer.
_COEFFICIENT_BOUNDS_1_N = (-1.0, 4.0)
_COEFFICIENT_LIMITS_1_N = (-2.0, 20.0)


class PressureStiffening:
    """EI and GJ times (1 + c sum(q)), q the commanded jet forces (N).

    Identifiability (40 paper poses up to 0.15 N, noise-free, c = 1 /N): fitting E0, EL,
    L and w_d alone leaves 1.1 of its 8.0 deg RMS (rod hanging along gravity), 1.6 of
    10.4 deg with gravity across: well above a ~0.15 deg noise floor."""

    name: ClassVar[str] = "pressure_stiffening"
    explanation: ClassVar[str] = (
        "The jets are driven by water under pressure in the rod's lumens, and a "
        "pressurised lumen stiffens the body: bending and torsional stiffness become "
        "EI (1 + c sum(q)), growing with the total commanded jet force. The error is zero "
        "with the jets off (gravity-only poses are untouched) and grows with force, the "
        "same for every jet: the rod bends less at high force than a linear model "
        "predicts, and with several jets firing at once it is stiffer than their net "
        "force alone suggests. E scales every pose alike and w_d is constant, so neither "
        "absorbs it; in single-jet sweeps it resembles nonlinear_elasticity, which "
        "multi-jet poses separate."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("coefficient_1_n", 0.0, *_COEFFICIENT_BOUNDS_1_N, "1/N",
                        "relative stiffness increase per newton of total jet force",
                        *_COEFFICIENT_LIMITS_1_N,
                        limit_reason="-2: EI stays positive with every jet at 0.15 N; 20: a lumen ten times "
                                     "stiffer than its wall at full force is a rigid tube"),
    )
    uses_actuation: ClassVar[bool] = True
    identified_by: ClassVar[str] = SWEEPS

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        scale_modulus(problem, 1.0 + values["coefficient_1_n"] * float(np.sum(problem.jet_forces_n)))
