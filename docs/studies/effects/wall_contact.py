"""Out-of-library effect for studies: the rod leans on a wall part-way along its length.

A wall beside the rod, on the base frame's +y side, touches it between 40 % and 60 % of
its length whenever the jets push the rod towards it; the wall then takes back a share
of that push as a line load on the touching segment. A static model has no contact
geometry here, so the share follows the commanded push (the jets' resultant along +y),
not the rod's actual position: contact happens on one side only, and grows with the
push, which no library effect does.
"""

from __future__ import annotations

import numpy as np

from hydrojet_bench.effects import EffectParameter

SEGMENT = (0.4, 0.6)  # fraction of the rod's length in contact


class WallContact:
    name = "wall_contact"
    explanation = "A wall on the +y side takes back part of the jets' push between 40 % and 60 % of the rod."
    parameters = (
        EffectParameter("share", 0.0, 0.0, 0.9, "1", "share of the jets' push towards the wall the wall takes"),
    )
    uses_actuation = True

    def apply(self, problem, values):
        push_n = float((problem.actuation_matrix() @ problem.jet_forces_n)[1])
        if push_n <= 0.0 or values["share"] == 0.0:
            return
        length = float(problem.arc_length_m[-1])
        inside = (problem.arc_length_m >= SEGMENT[0] * length) & (problem.arc_length_m <= SEGMENT[1] * length)
        line_load = values["share"] * push_n / ((SEGMENT[1] - SEGMENT[0]) * length)
        force = problem.distributed_force_in_base_n_m.copy()
        force[inside, 1] -= line_load
        problem.distributed_force_in_base_n_m = force
