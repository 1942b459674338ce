"""Out-of-library effect for studies: a tether pulls the tip sideways.

A cable (the tracker's sensor lead, a safety line) tied to the capsule and anchored off
to the side pulls the tip with a constant force of fixed direction in the tracker frame,
here along the base frame's x axis (the clamp is fixed in the tracker frame, so fixed in
one is fixed in the other). Unlike w_d, a follower load that turns with the tip, this
force keeps its direction while the rod bends; unlike gravity it is sideways.
"""

from __future__ import annotations

import numpy as np

from hydrojet_bench.effects import EffectParameter


class Tether:
    name = "tether"
    explanation = "A tether pulls the tip sideways with a constant force of fixed direction (base x)."
    parameters = (
        EffectParameter("force_n", 0.0, 0.0, 0.1, "N", "tether pull along the base frame's x axis"),
    )
    uses_actuation = False

    def apply(self, problem, values):
        problem.add_tip_dead_force(np.array([values["force_n"], 0.0, 0.0]), np.zeros(3))
