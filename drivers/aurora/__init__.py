"""NDI Aurora electromagnetic tracker (Combined API over serial).

Layers: `crc`, `commands`, `replies`, `frames`, `stream` (pure codec, one error type
`AuroraProtocolError`); `client.AuroraTracker` (async, over any transport URL);
`emulator.AuroraEmulator` (byte-level, driven by a `drivers.plant.Plant`) and
`serve.serve_pty` (the emulator on a pseudo-terminal).
"""

from drivers.aurora.client import AuroraSetupError, AuroraTracker
from drivers.aurora.emulator import AuroraEmulator
from drivers.aurora.errors import (
    AuroraCommandError,
    AuroraConnectionError,
    AuroraError,
    AuroraProtocolError,
    AuroraTimeoutError,
)
from drivers.aurora.poses import ToolStatus, TrackedFrame, TrackedPose

__all__ = [
    "AuroraCommandError",
    "AuroraConnectionError",
    "AuroraEmulator",
    "AuroraError",
    "AuroraProtocolError",
    "AuroraSetupError",
    "AuroraTimeoutError",
    "AuroraTracker",
    "ToolStatus",
    "TrackedFrame",
    "TrackedPose",
]
