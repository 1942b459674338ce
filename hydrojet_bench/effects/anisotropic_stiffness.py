"""A section that bends more easily about one axis than the other."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

from .base import CALIBRATION_POSES, EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem

# At a ratio of 2 (or 1/2) one axis is 41 % stiffer and the other 29 % softer than their
# mean: a section that uneven is a visibly bad part. Symmetric in the logarithm.
# Physical limits 1/5 and 5: one axis 2.2 times stiffer and the other 2.2 times softer
# than the mean, a flat strip rather than a rod with three lumens.
_RATIO_BOUNDS = (0.5, 2.0)
_RATIO_LIMITS = (0.2, 5.0)


class AnisotropicStiffness:
    """EI_x = EI sqrt(ratio), EI_y = EI / sqrt(ratio): the geometric mean, hence E, is
    kept, and over the three jets the first-order change of bending compliance averages
    to zero (jet 2: -d/2, jets 1 and 3: +d/4 each, d = ln ratio), so the ratio does not
    trade off against E. The principal axes are the body x and y axes: `RodProblem`
    holds a diagonal section stiffness only, so a seam at another angle shows only
    through its x/y component (the 45 degree component would need an off-diagonal
    bending stiffness, which three jets could identify but the problem cannot express).

    Identifiability (40 paper poses up to 0.15 N, noise-free, ratio 1.3): fitting E0, EL,
    L and w_d alone leaves 6.2 of its 6.8 deg RMS (rod hanging along gravity).

    The PRB joints apply the section law in the joint's mid-rotation frame: in the distal
    link's frame the chain converged to the Cosserat rod only at first order in the link
    count when an anisotropic section bends off its principal axes (jet 1, ratio 1.5, no
    gravity: 2.4 deg apart at 20 links, halving per doubling); now 0.07 deg at 20 links,
    quartering per doubling, as about a principal axis."""

    name: ClassVar[str] = "anisotropic_stiffness"
    explanation: ClassVar[str] = (
        "The section bends more easily about one axis than the other: a seam, a lumen off "
        "its place, uneven walls (three equal lumens 120 degrees apart keep a round "
        "section isotropic, so only a defect breaks it). stiffness_ratio = EI_x / EI_y "
        "with their geometric mean fixed, so it does not trade off against E; the axes "
        "are the tip frame's x and y, and jet 2 pushes along -y. A ratio above 1 makes "
        "jet 2 bend the rod less than jets 1 and 3, whose bending planes turn towards "
        "the tip x axis in mirror-image senses: the error differs per jet, in size and in "
        "direction, which a jet gain (size only) or a ring misalignment (one sense for "
        "all) cannot reproduce."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = (
        EffectParameter("stiffness_ratio", 1.0, *_RATIO_BOUNDS, "1",
                        "bending stiffness about body x over that about body y, geometric mean kept",
                        *_RATIO_LIMITS,
                        limit_reason="a ratio of 5 (or 1/5) is a flat strip, not a round rod with a defect"),
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        root = math.sqrt(values["stiffness_ratio"])
        problem.bending_stiffness_x_nm2 = problem.bending_stiffness_x_nm2 * root
        problem.bending_stiffness_y_nm2 = problem.bending_stiffness_y_nm2 / root
