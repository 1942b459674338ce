"""The truth the emulators speak about: a small plant interface.

An emulator never invents motion. It asks a `Plant` where each sensor is and tells it
what the valves are doing. The digital twin implements this interface on the physical
model; `StaticPlant` holds sensors still, for tests and standalone emulators.

Frames: "tracker" is the EM tracker's frame, the lab frame of every emulator. Orientations are unit quaternions
(w, x, y, z) mapping sensor-frame vectors into the tracker frame (see
`drivers.rotations`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from drivers.rotations import quat_normalize

VALVE_COUNT = 3


@dataclass(frozen=True)
class SensorTruth:
    """Exact state of one sensor at one instant (from `sensor_truths`: at n instants,
    every field stacked over them, (n, 4) and (n, 3)).

    orientation_in_tracker: unit quaternion (w, x, y, z), sensor frame -> tracker frame.
    position_in_tracker_m: sensor origin in the tracker frame, metres.
    angular_velocity_in_sensor_rad_s: body-frame angular rate, rad/s.
    linear_acceleration_in_tracker_m_s2: acceleration of the sensor origin (not including
        gravity), tracker frame, m/s^2. Zero for quasistatic motion.
    """

    orientation_in_tracker: np.ndarray
    position_in_tracker_m: np.ndarray
    angular_velocity_in_sensor_rad_s: np.ndarray = field(default_factory=lambda: np.zeros(3))
    linear_acceleration_in_tracker_m_s2: np.ndarray = field(default_factory=lambda: np.zeros(3))


@runtime_checkable
class Plant(Protocol):
    """What every emulator needs from the physics (the digital twin, or a fixed pose).

    gravity_in_tracker_m_s2: gravitational acceleration vector in the tracker frame (m/s^2),
        e.g. (0, 0, -9.81) when the tracker's z axis points up.
    magnetic_field_in_tracker_ut: Earth's field in the tracker frame, microtesla.
    """

    gravity_in_tracker_m_s2: np.ndarray
    magnetic_field_in_tracker_ut: np.ndarray

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        """Exact pose of sensor ``"base"`` or ``"tip"`` at plant time ``t_s`` (s)."""
        ...

    def apply_valve_duties(self, duties_permille: Sequence[int], t_s: float) -> None:
        """The valve emulator reports the duty (0-1000 per mille) of each of the three
        valves whenever it changes, including the watchdog closing them all."""
        ...


@runtime_checkable
class BatchPlant(Plant, Protocol):
    """A plant that answers a run of instants in one call (the digital twin does)."""

    def sensor_truths(self, sensor: str, t_s: np.ndarray) -> SensorTruth:
        """`sensor_truth` at each of ``t_s`` (1-D, s), every field stacked over them:
        (n, 4) orientations and (n, 3) vectors."""
        ...


def truths_at_instants(plant: Plant) -> Callable[[str, np.ndarray], SensorTruth]:
    """``(sensor, t_s) -> SensorTruth`` over a 1-D array of instants for any plant: its own
    `BatchPlant.sensor_truths` where it has one, else its `sensor_truth` one instant at a
    time. Asked once (an isinstance check on a Protocol costs ~20 us)."""
    if isinstance(plant, BatchPlant):
        return plant.sensor_truths

    def one_at_a_time(sensor: str, t_s: np.ndarray) -> SensorTruth:
        states = [plant.sensor_truth(sensor, float(t)) for t in np.asarray(t_s, dtype=float)]

        def stacked(field_name: str, size: int) -> np.ndarray:
            rows = [np.asarray(getattr(state, field_name), dtype=float) for state in states]
            return np.array(rows).reshape(len(states), size)

        return SensorTruth(stacked("orientation_in_tracker", 4), stacked("position_in_tracker_m", 3),
                           stacked("angular_velocity_in_sensor_rad_s", 3),
                           stacked("linear_acceleration_in_tracker_m_s2", 3))

    return one_at_a_time


class StaticPlant:
    """Sensors that never move; records every valve change (thread-safe, since emulators
    may run on their own threads)."""

    def __init__(
        self,
        poses: Mapping[str, tuple[Sequence[float], Sequence[float]]] | None = None,
        gravity_in_tracker_m_s2: Sequence[float] = (0.0, 0.0, -9.81),
        magnetic_field_in_tracker_ut: Sequence[float] = (20.0, 0.0, -45.0),
    ) -> None:
        """poses: sensor name -> (orientation (w, x, y, z), position in m). Defaults put the
        base at the origin and the tip 70 mm along -z (the rod hanging straight down)."""
        poses = poses or {
            "base": ((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
            "tip": ((1.0, 0.0, 0.0, 0.0), (0.0, 0.0, -0.070)),
        }
        self._truth = {
            name: SensorTruth(quat_normalize(q), np.asarray(p, dtype=float))
            for name, (q, p) in poses.items()
        }
        self.gravity_in_tracker_m_s2 = np.asarray(gravity_in_tracker_m_s2, dtype=float)
        self.magnetic_field_in_tracker_ut = np.asarray(magnetic_field_in_tracker_ut, dtype=float)
        self._lock = threading.Lock()
        self.valve_history: list[tuple[float, tuple[int, ...]]] = []

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        try:
            return self._truth[sensor]
        except KeyError:
            raise KeyError(f"plant has no sensor {sensor!r}; known: {sorted(self._truth)}") from None

    def apply_valve_duties(self, duties_permille: Sequence[int], t_s: float) -> None:
        with self._lock:
            self.valve_history.append((t_s, tuple(int(d) for d in duties_permille)))

    @property
    def valve_duties_permille(self) -> tuple[int, ...]:
        with self._lock:
            return self.valve_history[-1][1] if self.valve_history else (0,) * VALVE_COUNT
