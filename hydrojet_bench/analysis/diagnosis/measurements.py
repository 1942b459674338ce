"""Where the tip sensor itself was: the position diagnose compares.

`Dataset.tip_position_in_base_m` gives the rod tip, found by stepping back from the
tip sensor's origin along the sensor's measured orientation. An unknown rotation of the
sensor in its capsule (the library's sensor_mounting) turns that step and moves the
reconstructed tip although nothing moved, so a model of the mounting could never fit
those positions. The sensor's origin in the base frame is what the tracker measured,
untouched by its orientation; a model predicts it with
`Solution.tip_sensor_position_in_base_sensor_m`, the offset from the rig profile.
"""

from __future__ import annotations

import numpy as np

from ...data.dataset import Dataset
from ...geometry import quat_rotate


def tip_sensor_offset_in_tip_m(data: Dataset) -> tuple[float, float, float]:
    """The tip sensor's origin in the tip frame (m), from the rig profile."""
    return tuple(float(v) for v in data.profile.tip_sensor.offset_in_body_m)  # type: ignore[return-value]


def tip_sensor_position_in_base_m(data: Dataset) -> np.ndarray | None:
    """(N, 3) tip sensor origin in the base frame (m), None without positions."""
    tip = data.tip_position_in_base_m()
    if tip is None:
        return None
    # Undo the dataset's step back from the sensor to the rod tip, exactly.
    return tip + quat_rotate(data.tip_orientation_in_base(), np.array(tip_sensor_offset_in_tip_m(data)))
