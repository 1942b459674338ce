"""The digital twin: a simulated HydroJet rig (true physics, hidden effects, sensor noise).

`DigitalTwin` implements `drivers.plant.Plant`, so the device emulators take their truth
from it, and plays measurement plans (`hydrojet_bench.plans`) in virtual time into a
`TwinRecording`. Configure it with a frozen `TwinConfig`.
"""

from __future__ import annotations

from .config import HANGING_BASE_ORIENTATION, JetResponse, SensorNoise, TwinConfig
from ..profile import SensorMounting
from .recording import TwinRecording
from .setup_errors import SETUP_ERRORS, SetupErrors, parse_setup_error, setup_error_text
from .twin import DEFAULT_SAMPLE_RATE_HZ, SENSORS, DigitalTwin, SensorMeasurement

__all__ = ["DEFAULT_SAMPLE_RATE_HZ", "HANGING_BASE_ORIENTATION",
           "SENSORS", "SETUP_ERRORS", "DigitalTwin", "JetResponse", "SensorMeasurement", "SensorMounting", "SensorNoise",
           "SetupErrors", "TwinConfig", "TwinRecording", "parse_setup_error",
           "setup_error_text"]
