"""Out-of-library effect for studies: a constant twisting moment along the whole rod.

A sleeve moulded with a slight helix, or a cable wound around it, twists the rod with a
moment per unit length about its own axis, present with the jets off. The tip turns
about its axis by mu L^2 / (2 G J); the bending planes of the jets swing with it. A
sensor mounting (one fixed rotation) or a jet ring angle (one fixed angle) mimic parts of
it, never both the twist and the way it grows along the bent rod.
"""

from __future__ import annotations

from hydrojet_bench.effects import EffectParameter


class DistributedTwist:
    name = "distributed_twist"
    explanation = "A constant twisting moment per unit length along the rod (a helical sleeve or cable)."
    parameters = (
        EffectParameter("moment_nm_per_m", 0.0, -2e-3, 2e-3, "N m/m", "twisting moment per unit length"),
    )
    uses_actuation = False

    def apply(self, problem, values):
        moment = problem.distributed_moment_in_body_nm_m.copy()
        moment[:, 2] += values["moment_nm_per_m"]
        problem.distributed_moment_in_body_nm_m = moment
