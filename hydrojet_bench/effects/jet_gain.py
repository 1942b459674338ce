"""Per-jet force gains: a jet delivering more or less than its valve is asked for."""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .base import CALIBRATION_POSES, EffectParameter

if TYPE_CHECKING:
    from .problem import RodProblem

# 0 is a fully blocked nozzle. 1.5 (half again the commanded force) is already far
# outside any plausible valve-to-force calibration error; a 0.15 N command then gives
# 0.225 N, which the models still solve. Physical limit 3: the models converge up to
# ~0.45 N on one jet, three times the rig's 0.15 N command.
_GAIN_BOUNDS = (0.0, 1.5)
_GAIN_LIMIT = 3.0


class JetGain:
    """Tip-frame jet force = A (gains * q). A gain shared by all three jets trades off
    against E (scaling every jet force scales the bend; only gravity and w_d break the
    tie), so calibrate two gains, or read the three relative to one another.

    Identifiability (40 paper poses up to 0.15 N, noise-free, gain_2 = 0.8): fitting E0,
    EL, L and w_d alone leaves 6.2 of its 13.4 deg RMS (rod hanging along gravity)."""

    name: ClassVar[str] = "jet_gain"
    explanation: ClassVar[str] = (
        "Each jet delivers gain_i times the force its valve is commanded to: a partly "
        "clogged or worn nozzle, a kinked supply line, a mis-scaled valve calibration. "
        "The error appears only in the sweeps and poses that use the affected jet, grows "
        "with that jet's force and lies in its own bending plane: a gain below 1 bends the "
        "rod less than predicted. A gain shared by all three jets looks like a change of E, "
        "so only differences between the jets are sharply identifiable: fit two gains, or "
        "read the three relative to one another."
    )
    parameters: ClassVar[tuple[EffectParameter, ...]] = tuple(
        EffectParameter(f"gain_{jet}", 1.0, *_GAIN_BOUNDS, "1",
                        f"delivered / commanded force of jet {jet}", physical_upper=_GAIN_LIMIT,
                        limit_reason="0: a blocked nozzle; 3: a full command would give 0.45 N, where the "
                                     "models stop solving one jet")
        for jet in (1, 2, 3)
    )
    uses_actuation: ClassVar[bool] = False
    identified_by: ClassVar[str] = CALIBRATION_POSES

    def apply(self, problem: RodProblem, values: Mapping[str, float]) -> None:
        gains = np.array([values["gain_1"], values["gain_2"], values["gain_3"]])
        problem.jet_gains = problem.jet_gains * gains
