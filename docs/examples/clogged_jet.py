"""An example user effect (and hidden effect for the digital twin): jet 2's nozzle is partly
clogged, so it delivers 60 % of the force the valve is asked for. A user-effect file in
the format `hydrojet_bench.effects.base.Effect` describes; the effect library adds a
calibratable `jet_gain` for this physics."""

from __future__ import annotations

import numpy as np


class CloggedJet:
    name = "clogged_jet"
    explanation = "jet 2 delivers 60 % of its commanded force (a partly clogged nozzle)"
    parameters = ()
    uses_actuation = False

    def apply(self, problem, values):
        problem.jet_gains = problem.jet_gains * np.array([1.0, 0.6, 1.0])
