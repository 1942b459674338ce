"""Solenoid valve controller of the three water jets: protocol, client, emulator.

See `drivers.valve.protocol` for the wire protocol and firmware behaviour,
``drivers/valve/firmware/valve_controller.ino`` for the Arduino implementation.
"""

from drivers.valve.calibration import JetCalibration
from drivers.valve.client import (
    ValveController,
    ValveError,
    ValveFaultError,
    ValveNakError,
    ValveTimeoutError,
)
from drivers.valve.protocol import NakCode, StatusReport, ValveProtocolError

__all__ = [
    "JetCalibration",
    "NakCode",
    "StatusReport",
    "ValveController",
    "ValveError",
    "ValveFaultError",
    "ValveNakError",
    "ValveProtocolError",
    "ValveTimeoutError",
]
