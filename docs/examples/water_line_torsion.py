"""An example user effect outside the library: the water lines twist the rod.

The three supply tubes run along the rod to the jets. Laid with a slight helix, a
pressurised tube tries to straighten its helix and twists the body it is bonded to, so
the rod feels a twisting moment along its whole length that grows with the pressure
driving the jets (taken as proportional to the total commanded jet force, as the
library's pressure_stiffening does). The tip turns about its own axis, and the jet ring
turns with it, so every bending plane also swings a little, more the harder the jets
push.

No library effect has this shape: sensor_mounting is one fixed rotation, w_d one
constant moment, jet_misalignment one fixed angle of the bending planes; here both the
twist and the swing vanish with the jets off and grow with their force. `diagnose`
should call it "unexplained" (tests/analysis/test_analysis_diagnose.py checks it).

Use it as a hidden effect of the twin (`simulate --hidden
docs/examples/water_line_torsion.py:WaterLineTorsion`; the default is a plausible
preload) or as a candidate once you suspect it (`diagnose DATA --candidate
docs/examples/water_line_torsion.py:WaterLineTorsion`).
"""

from __future__ import annotations

import numpy as np

from hydrojet_bench.effects import EffectParameter

# Torsional stiffness of the HydroJet rod: G J ~ 8e4 Pa x 6.4e-10 m^4 ~ 5e-5 N m^2, so a
# uniform twisting moment mu (N m/m) over L = 70 mm turns the tip by mu L^2 / (2 G J) ~
# 45 mu rad. 5e-3 N m/m per newton of total jet force twists the tip by ~1.3 degrees at
# 0.1 N; 0.05 (13 degrees at 0.1 N) would tear the tubes off.
_DEFAULT_NM_PER_M_PER_N = 5e-3


class WaterLineTorsion:
    name = "water_line_torsion"
    explanation = (
        "The pressurised water lines twist the rod: a twisting moment along its length, "
        "proportional to the total jet force. The tip turns about its own axis and the jet "
        "ring with it, so the bending planes swing; both vanish with the jets off and grow "
        "with their force.")
    parameters = (
        EffectParameter("moment_nm_per_m_per_n", _DEFAULT_NM_PER_M_PER_N, -0.05, 0.05, "N m/(m N)",
                        "twisting moment per unit length per newton of total jet force"),
    )
    uses_actuation = True

    def apply(self, problem, values):
        twist = values["moment_nm_per_m_per_n"] * float(np.sum(problem.jet_forces_n))
        moment = problem.distributed_moment_in_body_nm_m.copy()
        moment[:, 2] += twist
        problem.distributed_moment_in_body_nm_m = moment
