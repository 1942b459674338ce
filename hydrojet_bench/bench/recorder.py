"""Samples of the current plan step, and the settled measurement at its end.

The streams add every sample (EM or IMU) with the step that was commanded when it was
taken; at the end of a step the recorder averages the samples of its last ``window_s``
with `Dataset.quasistatic_steps`, the same reduction offline analysis applies to a log or
a CSV file, so the live estimate and a later `compare` see the same kind of row.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence
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

    def add(self, t_s: float, base_orientation: Sequence[float], tip_orientation: Sequence[float],
            base_position_m: Sequence[float] | None = None, tip_position_m: Sequence[float] | None = None) -> None:
        """One sample (session s, quaternions (w, x, y, z), positions in m), taken at or
        after the one added before it."""
        if self.step is None:
            return  # before the first command: logged as raw data, not part of any step
        samples = self._samples
        if samples.time_s and t_s < samples.time_s[-1]:
            raise ValueError(f"{self.source} sample at {t_s} s added after one at {samples.time_s[-1]} s")
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
        # Samples arrive in time order: the window is one run of them, and only its few
        # samples (of a step's hundreds) become arrays.
        first = bisect.bisect_left(samples.time_s, end_s - window_s)
        last = bisect.bisect_right(samples.time_s, end_s)
        if self.step is None or last <= first:
            return None

        count = last - first
        window = Dataset(
            time_s=np.asarray(samples.time_s[first:last]),
            jet_forces_n=np.tile(self.step.jet_forces_n, (count, 1)),
            base_orientation=np.asarray(samples.base_orientation[first:last]),
            tip_orientation=np.asarray(samples.tip_orientation[first:last]),
            base_position_m=np.asarray(samples.base_position_m[first:last]) if self.with_positions else None,
            tip_position_m=np.asarray(samples.tip_position_m[first:last]) if self.with_positions else None,
            sweep=np.full(count, self.step.sweep),
            step=np.full(count, self.step.step),
            profile=self.profile,
            source=self.source,
        )
        return window.quasistatic_steps(window_s=None)
