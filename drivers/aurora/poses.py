"""What the Aurora client hands to the bench: named, timestamped tool poses.

Frames: poses are in the tracker frame of the field generator; orientation is
a unit quaternion (w, x, y, z) mapping sensor-frame vectors into the tracker frame (the
convention of `drivers.rotations`), position in millimetres.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

from drivers.aurora.frames import HandleStatus, SystemStatus, ToolRecord
from drivers.aurora.replies import PortStatus


# A plain int: an IntFlag operation costs microseconds, and every frame tests each tool.
_OUT_OF_VOLUME = int(PortStatus.OUT_OF_VOLUME)


class ToolStatus(str, Enum):
    """Tracking state of one sensor in one frame."""

    VALID = "valid"
    MISSING = "missing"  # no solution this frame (distortion, field generator down ...)
    DISABLED = "disabled"  # port handle not enabled
    OUT_OF_VOLUME = "out_of_volume"  # outside the characterised volume (pose may be given)


@dataclass(frozen=True)
class TrackedPose:
    """One sensor in one frame.

    orientation: (w, x, y, z), sensor -> tracker frame; None unless the device gave a
        transform (VALID, or OUT_OF_VOLUME with reply option 0x0800).
    position_mm: sensor origin in the tracker frame, mm; None like ``orientation``.
    rms_error_mm: the device's RMS fit error (quality; lower is better), mm.
    frame_number: the device's 40 Hz frame counter (None for a disabled handle).
    port_status: raw port status bits (`drivers.aurora.replies.PortStatus`).
    host_time_s: host clock (the client's ``clock``) when the reply arrived, s.
    """

    name: str
    handle: int
    status: ToolStatus
    orientation: tuple[float, float, float, float] | None
    position_mm: tuple[float, float, float] | None
    rms_error_mm: float | None
    frame_number: int | None
    port_status: int | None
    host_time_s: float

    @property
    def has_pose(self) -> bool:
        return self.orientation is not None

    @property
    def broken_coil(self) -> bool:
        return bool((self.port_status or 0) & PortStatus.BROKEN_COIL)

    @classmethod
    def from_record(cls, name: str, record: ToolRecord, host_time_s: float) -> TrackedPose:
        if record.status is HandleStatus.DISABLED:
            status = ToolStatus.DISABLED
        elif (record.port_status or 0) & _OUT_OF_VOLUME:
            status = ToolStatus.OUT_OF_VOLUME
        elif record.status is HandleStatus.MISSING:
            status = ToolStatus.MISSING
        else:
            status = ToolStatus.VALID
        t = record.transform
        return cls(
            name=name,
            handle=record.handle,
            status=status,
            orientation=tuple(map(float, t.quaternion)) if t else None,  # type: ignore[arg-type]
            position_mm=tuple(map(float, t.translation_mm)) if t else None,  # type: ignore[arg-type]
            rms_error_mm=float(t.rms_error_mm) if t else None,
            frame_number=record.frame_number,
            port_status=record.port_status,
            host_time_s=host_time_s,
        )


@dataclass(frozen=True)
class TrackedFrame:
    """All named sensors of one BX/TX reply; ``system_status`` bits are
    `drivers.aurora.frames.SystemStatus`."""

    poses: tuple[TrackedPose, ...]
    frame_number: int | None
    system_status: int
    host_time_s: float

    def __getitem__(self, name: str) -> TrackedPose:
        for pose in self.poses:
            if pose.name == name:
                return pose
        raise KeyError(f"no tool named {name!r} in frame; have {[p.name for p in self.poses]}")

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.poses)

    @property
    def hardware_failure(self) -> bool:
        """True while the system reports a hardware failure (e.g. field generator off)."""
        return bool(self.system_status & SystemStatus.HARDWARE_FAILURE)
