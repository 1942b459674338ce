"""The Aurora emulator's state machine, error codes, poses, noise and fault controls,
driven byte-for-byte without any transport."""

from __future__ import annotations

import numpy as np
import pytest
from aurora_testkit import HANDLES, POSES, set_up_tracking, talk, truth_mm

from drivers.aurora.commands import Command
from drivers.aurora.emulator import AuroraEmulator
from drivers.aurora.frames import HandleStatus, SystemStatus, TrackingFrame, decode_tx_text
from drivers.aurora.replies import (
    DataReply,
    ErrorReply,
    OkayReply,
    PortHandleList,
    PortStatus,
    ResetReply,
    decode_reply,
)
from drivers.aurora.errors import AuroraProtocolError
from drivers.plant import SensorTruth, StaticPlant
from hydrojet_bench.geometry import rotation_angle_deg


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def make(plant, **kwargs) -> AuroraEmulator:
    kwargs.setdefault("tools", HANDLES)
    return AuroraEmulator(plant, **kwargs)


def test_set_up_sequence_and_phsr_listings(plant) -> None:
    emu = make(plant)
    assert emu.mode == "uninitialised"
    assert talk(emu, "PHSR:02") == ErrorReply(0x10)
    assert talk(emu, "INIT") == OkayReply()
    assert talk(emu, "PHSR:01") == DataReply("00")
    assert PortHandleList.from_text(talk(emu, "PHSR:02").text).handles == (0x0A, 0x0B)
    assert talk(emu, "PINIT:0A") == OkayReply()
    assert talk(emu, "PINIT:0a") == OkayReply()  # re-PINIT (lower-case hex, as ndicapi sends)
    assert PortHandleList.from_text(talk(emu, "PHSR:02").text).handles == (0x0B,)
    assert talk(emu, "PENA:0BD") == ErrorReply(0x0E)  # not initialised yet
    assert talk(emu, "PINIT:0B") == OkayReply()
    listing = PortHandleList.from_text(talk(emu, "PHSR:03").text)
    assert listing.handles == (0x0A, 0x0B)
    assert all(e.status == PortStatus.OCCUPIED | PortStatus.INITIALISED for e in listing.entries)
    assert talk(emu, "PENA:0AD") == OkayReply()
    assert PortHandleList.from_text(talk(emu, "PHSR:04").text).handles == (0x0A,)
    assert talk(emu, "PHSR").text == PortHandleList.from_text(talk(emu, "PHSR:00").text).to_text()
    assert talk(emu, "TSTART") == OkayReply()
    assert emu.mode == "tracking"
    frame = talk(emu, "BX:0801")
    assert [(r.handle, r.status) for r in frame.tools] == [(0x0A, HandleStatus.VALID), (0x0B, HandleStatus.DISABLED)]
    assert talk(emu, "TSTOP") == OkayReply()
    assert emu.mode == "setup"


@pytest.mark.parametrize(
    ("setup", "command", "code"),
    [
        ([], "BX:0801", 0x10),
        ([], "PINIT:0A", 0x10),
        (["INIT"], "BX:0801", 0x0C),
        (["INIT"], "TSTOP", 0x0C),
        (["INIT"], "PINIT:FF", 0x08),
        (["INIT"], "PINIT:0", 0x07),
        (["INIT"], "PINIT:0A0", 0x07),
        (["INIT"], "PENA:0A", 0x07),
        (["INIT"], "PENA:0AX", 0x23),
        (["INIT"], "PHSR:09", 0x23),
        (["INIT"], "INIT:1", 0x07),
        (["INIT"], "COMM:9", 0x07),
        (["INIT"], "COMM:90000", 0x23),
        (["INIT"], "FOO", 0x01),
        (["INIT"], "GETINFO:Features.Firmware.Version", 0x01),  # hosts fall back to VER
        (["INIT", "TSTART"], "PHSR:02", 0x0C),
        (["INIT", "TSTART"], "PINIT:0A", 0x0C),
        (["INIT", "TSTART"], "TSTART", 0x0C),
        (["INIT", "TSTART"], "BX:0002", 0x23),  # unsupported reply option
        (["INIT", "TSTART"], "BX:08", 0x07),
    ],
)
def test_error_codes(plant, setup: list[str], command: str, code: int) -> None:
    emu = make(plant)
    for text in setup:
        assert talk(emu, text) == OkayReply()
    assert talk(emu, command) == ErrorReply(code)


def test_bad_crc_and_space_form(plant) -> None:
    emu = make(plant)
    assert decode_reply(emu.receive(b"INIT:E3A6\r")) == ErrorReply(0x04)
    assert decode_reply(emu.receive(b"INIT\r")) == OkayReply()
    assert decode_reply(emu.receive(b"PINIT 0A\r")) == OkayReply()
    assert emu.mode == "setup"


def test_commands_split_across_writes_and_batched(plant) -> None:
    emu = make(plant)
    stream = Command("INIT").encode() + Command("VER", "0").encode()
    out = b"".join(emu.receive(stream[i : i + 3]) for i in range(0, len(stream), 3))
    first, _, rest = out.partition(b"\r")
    assert decode_reply(first) == OkayReply()
    assert "Freeze Tag:" in decode_reply(rest).text


def test_init_after_garbage_recovers_from_any_state(plant) -> None:
    emu = make(plant)
    set_up_tracking(emu)
    # A pty cannot carry a break: a new host's INIT may follow line noise.
    assert decode_reply(emu.receive(b"\x00\xff\x13garbageINIT:E3A5\r")) == OkayReply()
    assert emu.mode == "setup"
    # INIT un-initialises the handles, so the new session finds them in PHSR 02 again.
    assert PortHandleList.from_text(talk(emu, "PHSR:02").text).handles == (0x0A, 0x0B)


def test_break_and_reset_command(plant) -> None:
    emu = make(plant)
    set_up_tracking(emu)
    assert talk(emu, "COMM:50000") == OkayReply()
    assert emu.baud_rate == 115200
    assert decode_reply(emu.on_break()) == ResetReply()
    assert (emu.mode, emu.baud_rate) == ("uninitialised", 9600)
    talk(emu, "INIT")
    talk(emu, "COMM:50000")
    assert talk(emu, "RESET") == ResetReply()
    assert (emu.mode, emu.baud_rate) == ("uninitialised", 9600)


def test_comm_replies_at_old_rate_and_baud_mismatch_garbles(plant) -> None:
    emu = make(plant)
    emu.on_baudrate(9600)
    talk(emu, "INIT")
    assert talk(emu, "COMM:50000") == OkayReply()  # delivered: host still at 9600
    assert emu.receive(Command("VER", "0").encode()) == b""  # device now at 115200
    emu.on_baudrate(115200)
    assert isinstance(talk(emu, "VER:0"), DataReply)
    emu.on_baudrate(9600)  # a new host session starting at the power-up rate
    assert emu.receive(Command("INIT").encode()) == b""
    assert decode_reply(emu.on_break()) == ResetReply()
    assert talk(emu, "INIT") == OkayReply()


def test_beep_and_version(plant) -> None:
    emu = make(plant, version_text="Freeze Tag: AURORA Rev 008")
    assert talk(emu, "BEEP:2") == DataReply("1")
    assert talk(emu, "BEEP:0") == ErrorReply(0x23)
    assert talk(emu, "VER:0") == DataReply("Freeze Tag: AURORA Rev 008")


def test_poses_follow_the_plant_exactly_without_noise(plant) -> None:
    emu = make(plant, position_noise_mm=0.0, orientation_noise_deg=0.0)
    set_up_tracking(emu)
    frame = talk(emu, "BX:0801")
    assert frame.system_status == 0
    for record in frame.tools:
        q, p_mm = truth_mm(plant, HANDLES[record.handle])
        assert record.status is HandleStatus.VALID
        assert record.port_status == PortStatus.OCCUPIED | PortStatus.INITIALISED | PortStatus.ENABLED
        np.testing.assert_allclose(record.transform.quaternion, q, atol=1e-6)
        np.testing.assert_allclose(record.transform.translation_mm, p_mm, atol=1e-4)
    text = talk(emu, "TX:0801").text
    tx = decode_tx_text(text)
    for record in tx.tools:
        q, p_mm = truth_mm(plant, HANDLES[record.handle])
        np.testing.assert_allclose(record.transform.quaternion, q, atol=0.6e-4)
        np.testing.assert_allclose(record.transform.translation_mm, p_mm, atol=0.006)


class SlidingPlant(StaticPlant):
    """Sensors sliding along x at 1 m/s: a pose says the instant it was taken."""

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        truth = super().sensor_truth(sensor, t_s)
        return SensorTruth(truth.orientation_in_tracker, truth.position_in_tracker_m + np.array([t_s, 0.0, 0.0]))


@pytest.mark.parametrize("read_at_fraction", [0.02, 0.5, 0.98])
def test_a_frame_holds_the_pose_at_the_instant_it_began_whenever_it_is_read(read_at_fraction) -> None:
    clock = FakeClock()
    plant = SlidingPlant(POSES)
    start_s = clock.t  # frame 0 begins at power-up
    emu = make(plant, clock=clock, position_noise_mm=0.0, orientation_noise_deg=0.0)
    set_up_tracking(emu)
    clock.t = start_s + (7 + read_at_fraction) * 0.025
    tip = talk(emu, "BX:0801").tool(0x0B)
    assert tip.frame_number == 7
    expected_mm = plant.sensor_truth("tip", start_s + 7 * 0.025).position_in_tracker_m * 1000.0
    np.testing.assert_allclose(tip.transform.translation_mm, expected_mm, atol=1e-3)


def test_noise_has_the_configured_rms_and_frames_count_at_40_hz(plant) -> None:
    clock = FakeClock()
    emu = make(plant, clock=clock, seed=3)
    set_up_tracking(emu)
    q_true, p_true = truth_mm(plant, "tip")
    position_errors, angles, numbers = [], [], []
    first = talk(emu, "BX:0801")
    assert talk(emu, "BX:0801") == first  # same frame, same noise
    for _ in range(400):
        clock.t += 0.025
        frame: TrackingFrame = talk(emu, "BX:0801")
        tip = frame.tool(0x0B)
        numbers.append(tip.frame_number)
        position_errors.append(np.linalg.norm(np.array(tip.transform.translation_mm) - p_true))
        angles.append(float(rotation_angle_deg(tip.transform.quaternion, q_true)))
    assert np.all(np.diff(numbers) == 1)
    rms_position = float(np.sqrt(np.mean(np.square(position_errors))))
    rms_angle = float(np.sqrt(np.mean(np.square(angles))))
    assert 0.40 < rms_position < 0.56
    assert 0.60 < rms_angle < 0.80
    assert first.tool(0x0B).transform.rms_error_mm == pytest.approx(0.48)


def test_missing_and_out_of_volume_faults(plant) -> None:
    emu = make(plant)
    set_up_tracking(emu)
    emu.set_tool_missing("tip")
    frame = talk(emu, "BX:0801")
    assert frame.tool(0x0B).status is HandleStatus.MISSING
    assert frame.tool(0x0A).status is HandleStatus.VALID
    assert "0BMISSING" in talk(emu, "TX:0801").text
    emu.set_tool_missing("tip", False)
    emu.set_out_of_volume(0x0A)
    with_option = talk(emu, "BX:0801").tool(0x0A)
    assert with_option.status is HandleStatus.VALID
    assert with_option.port_status & PortStatus.OUT_OF_VOLUME
    without_option = talk(emu, "BX:0001").tool(0x0A)
    assert without_option.status is HandleStatus.MISSING
    assert without_option.port_status & PortStatus.OUT_OF_VOLUME
    with pytest.raises(KeyError):
        emu.set_tool_missing("elbow")


def test_field_generator_drop(plant) -> None:
    emu = make(plant)
    set_up_tracking(emu)
    emu.set_field_generator_connected(False)
    frame = talk(emu, "BX:0801")
    assert all(r.status is HandleStatus.MISSING for r in frame.tools)
    assert frame.system_status & SystemStatus.HARDWARE_FAILURE
    talk(emu, "INIT")
    assert talk(emu, "PINIT:0A") == ErrorReply(0x13)
    emu.set_field_generator_connected(True)
    set_up_tracking(emu)
    frame = talk(emu, "BX:0801")
    assert frame.system_status == 0 and all(r.status is HandleStatus.VALID for r in frame.tools)


def test_corrupt_next_reply(plant) -> None:
    emu = make(plant)
    set_up_tracking(emu)
    emu.corrupt_next_reply()
    with pytest.raises(AuroraProtocolError):
        talk(emu, "BX:0801")
    assert isinstance(talk(emu, "BX:0801"), TrackingFrame)
    emu.corrupt_next_reply()
    with pytest.raises(AuroraProtocolError):
        talk(emu, "PHSR:00")  # rejected in tracking mode; the ERROR reply is corrupted too
    assert talk(emu, "PHSR:00") == ErrorReply(0x0C)


def test_constructor_validates(plant) -> None:
    with pytest.raises(ValueError):
        AuroraEmulator(plant, tools={0x100: "tip"})
    with pytest.raises(ValueError):
        AuroraEmulator(plant, position_noise_mm=-1)
