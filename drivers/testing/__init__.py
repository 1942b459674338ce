"""Test doubles for driver tests; never imported by runtime code (an import-linter
contract in pyproject.toml checks it).

* `ScriptedTransport`: a byte transport that checks the exact bytes a client writes and
  answers scripted replies (`ScriptMismatch` on a departure).
* `FaultyTransport`: wraps any transport to drop, corrupt, delay, split or cut the line.
* `ScriptedBus`: the same idea for an SMBus (I2C) driver, with step builders W/R/B/F.
"""

from drivers.testing.faulty_transport import FaultyTransport
from drivers.testing.scripted_bus import B, F, R, RW, ScriptedBus, W, eio, nack
from drivers.testing.scripted_transport import ScriptedTransport, ScriptMismatch

__all__ = ["B", "F", "FaultyTransport", "R", "RW", "ScriptMismatch", "ScriptedBus", "ScriptedTransport", "W", "eio", "nack"]
