"""Samples of the current plan step, and the settled measurement at its end.

The streams add every sample (EM or IMU) with the step that was commanded when it was
taken; at the end of a step the recorder averages the samples of its last ``window_s``
with `Dataset.quasistatic_steps`, the same reduction offline analysis applies to a log or
a CSV file, so the live estimate and a later `compare` see the same kind of row.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data.dataset import Dataset
from ..plans import PlanStep
from ..profile import RigProfile


@dataclass
class _Samples:
    time_s: list[float] = field(default_factory=list)
    base_orientation: list[np.ndarray] = field(default_factory=list)
    tip_orientation: list[np.ndarray] = field(default_factory=list)
    base_position_m: list[np.ndarray] = field(default_factory=list)
    tip_position_m: list[np.ndarray] = field(default_factory=list)

    def clear(self) -> None:
        for values in vars(self).values():
            values.clear()


class StepRecorder:
    """Collects one source's samples (``"em"`` with positions, ``"imu"`` without) for the
    step in progress. Not thread-safe: the session's tasks share one event loop."""

    def __init__(self, profile: RigProfile, with_positions: bool, source: str) -> None:
        self.profile = profile
        self.with_positions = with_positions
        self.source = source
        self.step: PlanStep | None = None
        self._samples = _Samples()

    def begin(self, step: PlanStep) -> None:
        self.step = step
        self._samples.clear()

    def add(self, t_s: float, base_orientation: np.ndarray, tip_orientation: np.ndarray,
            base_position_m: np.ndarray | None = None, tip_position_m: np.ndarray | None = None) -> None:
        if self.step is None:
            return  # before the first command: logged as raw data, not part of any step
        samples = self._samples
        samples.time_s.append(t_s)
        samples.base_orientation.append(base_orientation)
        samples.tip_orientation.append(tip_orientation)
        if self.with_positions:
            samples.base_position_m.append(base_position_m)
            samples.tip_position_m.append(tip_position_m)

    @property
    def sample_count(self) -> int:
        return len(self._samples.time_s)

    def settled(self, end_s: float, window_s: float) -> Dataset | None:
        """The step's settled state as a one-row `Dataset` (averaged over samples in
        [end_s - window_s, end_s]), or None when no sample fell in the window."""
        samples = self._samples
        times = np.asarray(samples.time_s)
        rows = np.flatnonzero((times >= end_s - window_s) & (times <= end_s))
        if self.step is None or len(rows) == 0:
            return None

        count = len(rows)
        window = Dataset(
            time_s=times[rows],
            jet_forces_n=np.tile(self.step.jet_forces_n, (count, 1)),
            base_orientation=np.asarray(samples.base_orientation)[rows],
            tip_orientation=np.asarray(samples.tip_orientation)[rows],
            base_position_m=np.asarray(samples.base_position_m)[rows] if self.with_positions else None,
            tip_position_m=np.asarray(samples.tip_position_m)[rows] if self.with_positions else None,
            sweep=np.full(count, self.step.sweep),
            step=np.full(count, self.step.step),
            profile=self.profile,
            source=self.source,
        )
        return window.quasistatic_steps(window_s=None)
