"""What the twin records while playing a plan: plain arrays, one row per sample.

The field names are those of the bench's measurement dataset (the CSV contract of issue
3: ``t``, ``q1..q3``, base/tip quaternions in the tracker frame, optional positions,
``sweep``, ``step``), so converting to it is a renaming-free copy.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..data.dataset import Dataset
    from ..profile import RigProfile


@dataclass(frozen=True)
class TwinRecording:
    """Samples of a twin run, all arrays with one row per sample, read-only.

    time_s: (n,) sample times, s, non-decreasing (strictly increasing within a plan).
    jet_forces_n: (n, 3) commanded jet forces q1..q3, N.
    base_orientation, tip_orientation: (n, 4) sensor orientations in the tracker
        frame, unit quaternions (w, x, y, z), sensor -> tracker.
    base_position_m, tip_position_m: (n, 3) sensor positions in the tracker frame, m; None
        when the sensors give no positions (IMUs).
    sweep: (n,) plan sweep id, -1 for calibration poses. step: (n,) index within the sweep.
    flags: (n,) per-sample flag bits; the twin sets none (it never drops or corrupts a
        sample), so all zero.
    """

    time_s: np.ndarray
    jet_forces_n: np.ndarray
    base_orientation: np.ndarray
    tip_orientation: np.ndarray
    base_position_m: np.ndarray | None
    tip_position_m: np.ndarray | None
    sweep: np.ndarray
    step: np.ndarray
    flags: np.ndarray

    def __post_init__(self) -> None:
        n = np.asarray(self.time_s).shape[0] if np.ndim(self.time_s) == 1 else -1
        if n < 0:
            raise ValueError(f"TwinRecording.time_s must be 1-D, got shape {np.shape(self.time_s)}")
        if (self.base_position_m is None) != (self.tip_position_m is None):
            raise ValueError("TwinRecording.base_position_m and tip_position_m must both be given or both None")
        shapes = {"time_s": (n,), "jet_forces_n": (n, 3), "base_orientation": (n, 4), "tip_orientation": (n, 4),
                  "base_position_m": (n, 3), "tip_position_m": (n, 3), "sweep": (n,), "step": (n,), "flags": (n,)}
        for name, shape in shapes.items():
            value = getattr(self, name)
            if value is None:
                continue
            kind = np.int64 if name in ("sweep", "step") else np.uint32 if name == "flags" else float
            array = np.array(value, dtype=kind)
            if array.shape != shape:
                raise ValueError(f"TwinRecording.{name} must have shape {shape}, got {array.shape}")
            array.flags.writeable = False
            object.__setattr__(self, name, array)

    def __len__(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def has_positions(self) -> bool:
        return self.base_position_m is not None

    @classmethod
    def concatenate(cls, parts: Sequence["TwinRecording"]) -> "TwinRecording":
        """One recording of several, in order (all with positions or all without)."""
        if not parts:
            raise ValueError("nothing to concatenate")
        if len({p.has_positions for p in parts}) > 1:
            raise ValueError("cannot concatenate recordings with and without positions")
        values = {}
        for f in fields(cls):
            items = [getattr(p, f.name) for p in parts]
            values[f.name] = None if items[0] is None else np.concatenate(items)
        return cls(**values)

    def to_dataset(self, profile: "RigProfile", source: str = "digital twin") -> "Dataset":
        """The bench's measurement `Dataset` of these samples, recorded on the rig that
        ``profile`` describes (give the profile the twin was built from, see
        `TwinConfig.from_profile`, so that mountings and gravity agree)."""
        from ..data.dataset import Dataset

        return Dataset(time_s=self.time_s, jet_forces_n=self.jet_forces_n, base_orientation=self.base_orientation,
                       tip_orientation=self.tip_orientation, profile=profile, base_position_m=self.base_position_m,
                       tip_position_m=self.tip_position_m, sweep=self.sweep, step=self.step,
                       flags=self.flags.astype(np.int64), source=source)
