"""One valid record per log topic, as the session runner writes them, and a small
multi-chunk log built from them."""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np
from mcap.reader import make_reader

from hydrojet_bench.logs import TOPICS, LogRecord, LogWriter, floats
from hydrojet_bench.logs.topics import (Disturbance, EmFrame, EmTool, Event, ImuOrientation, ImuRaw, ModelPrediction,
                                        Parameters, Sample, SetupCheck, Step, StreamRate, ValveCommand, ValveReply)

START_TIME_UNIX_S = 1_700_000_000.25
METADATA = {"bench": {"profile_name": "sim", "software_version": "test"}, "operator": {"name": "A. N. Other"}}
QUATERNION = np.array([0.9238795325112867, 0.0, 0.3826834323650898, 0.0])
Q = floats(QUATERNION)

# Each at t_s = 0; `write_all_topics` writes them at other times. numpy scalars where the
# session's sources give them (frame counters, float32 IMU readings).
EXAMPLES: dict[str, LogRecord] = {record.topic: record for record in (
    Sample(t_s=0.0, source="em", jet_forces_n=floats(np.array([0.05, 0.0, 0.0])), sweep=2, step=7,
           base_orientation=Q, tip_orientation=(1.0, 0.0, 0.0, 0.0),
           base_position_m=floats([0.012, 0.0, 0.192]), tip_position_m=None),
    ImuRaw(t_s=0.0, sensor="tip", address=0x69, accel_m_s2=floats(np.array([0.1, -9.8, 0.2], dtype=np.float32)),
           gyro_rad_s=(0.001, 0.0, -0.002), mag_ut=None, temperature_c=np.float32(24.5)),
    ImuOrientation(t_s=0.0, base=Q, tip=Q, tip_in_base=(1.0, 0.0, 0.0, 0.0)),
    EmFrame(t_s=0.0, frame_number=np.int64(1234), system_status="0x0000", tools=(
        EmTool(name="base", handle=10, status="ok", orientation=Q, position_m=(0.0, 0.0, 0.2), rms_error_mm=0.31),
        EmTool(name="tip", handle=11, status="missing", orientation=None, position_m=None,
               rms_error_mm=float("nan")))),
    ValveCommand(t_s=0.0, command="SET_ALL", duties_permille=(500.0, 0.0, 250.5), jet_forces_n=None),
    ValveReply(t_s=0.0, command="SET_ALL", ok=False, code="E04", detail="bad checksum"),
    Step(t_s=0.0, index=3, count=229, sweep=-1, step=3, jet_forces_n=(0.0, 0.02, 0.01), samples=200,
         tip_in_base_measured=Q, tip_position_in_base_m=None),
    ModelPrediction(t_s=0.0, index=3, tip_in_base=Q, tip_position_in_base_m=(0.01, 0.0, 0.068), bend_deg=45.0,
                    orientation_error_deg=1.5, position_error_mm=None, method="ref"),
    Disturbance(t_s=0.0, index=3, force_n=floats(np.zeros(3)), moment_nm=floats(np.array([1e-4, -2e-4, 0.0])),
                moment_norm_nm=2.236e-4, orientation_error_deg_before=3.0, orientation_error_deg_after=0.5,
                iterations=2),
    Parameters(t_s=0.0, model="cosserat", effects=("gravity",), parameters={"E0": 3e5, "EL": 2e5}, calibrated=True,
               rms_orientation_deg_before=9.0, rms_orientation_deg_after=None),
    Event(t_s=0.0, level="warning", source="tracker", message="sensor not tracked: tip MISSING"),
    StreamRate(t_s=0.0, stream="imu", configured_hz=100.0, delivered_hz=97.5, samples=195, interval_s=2.0,
               whole_session=False),
    SetupCheck(t_s=0.0, check="wiring", status="fail", message="jets 2 and 3 appear swapped",
               values={"cable2_drives_jet": 3.0}),
)}
# The two Foxglove topics are written by their own methods.
FOXGLOVE_TOPICS = ("/tf", "/scene/backbone")
# Topics added since tests/logs/data/format1_all_topics.mcap was written.
ADDED_AFTER_FORMAT_1 = ("/bench/stream_rate", "/bench/setup_check")
# The topics in the order `write_all_topics` writes them.
WRITE_ORDER = ([topic for topic in EXAMPLES if topic not in ADDED_AFTER_FORMAT_1] + list(FOXGLOVE_TOPICS)
               + list(ADDED_AFTER_FORMAT_1))
assert set(EXAMPLES) | set(FOXGLOVE_TOPICS) == set(TOPICS)


def write_all_topics(log: LogWriter, t_s: float) -> float:
    """Every topic once, at t_s, t_s + 0.01, ...; returns the next free time."""
    for record in EXAMPLES.values():
        if record.topic not in ADDED_AFTER_FORMAT_1:
            log.write(msgspec.structs.replace(record, t_s=t_s))
            t_s += 0.01
    log.write_transform(t_s, parent="base", child="tip", rotation=QUATERNION, translation_m=[0.01, 0.0, 0.068])
    t_s += 0.01
    log.write_backbone(t_s, positions_in_base_m=np.linspace([0, 0, 0], [0.01, 0.0, 0.068], 5))
    t_s += 0.01
    # Last, so a log of these examples starts as the format-1 log of the same examples did.
    for topic in ADDED_AFTER_FORMAT_1:
        log.write(msgspec.structs.replace(EXAMPLES[topic], t_s=t_s))
        t_s += 0.01
    return t_s


def small_log(path: Path, chunks: int = 3) -> Path:
    """A finished log of `chunks` chunks, each holding every topic once."""
    with LogWriter(path, metadata=METADATA, start_time_unix_s=START_TIME_UNIX_S, flush_interval_s=1e6) as log:
        t_s = 0.0
        for _ in range(chunks):
            t_s = write_all_topics(log, t_s)
            log.flush()
    return path


def events_log(path: Path, chunks: int = 3, per_chunk: int = 4) -> Path:
    """A finished log of `chunks` chunks of `per_chunk` short /events messages: small
    enough to cut at every byte."""
    with LogWriter(path, metadata=METADATA, start_time_unix_s=START_TIME_UNIX_S, flush_interval_s=1e6) as log:
        for chunk in range(chunks):
            for index in range(per_chunk):
                log.write(Event(t_s=chunk + 0.1 * index, level="info", source="test", message=f"{chunk}.{index}"))
            log.flush()
    return path


def cut_inside_chunk(log: Path, chunk: int, destination: Path) -> Path:
    """A copy of a finished log cut off inside its chunk number `chunk` (0-based), as a
    crash while that chunk was being written leaves it."""
    with log.open("rb") as handle:
        index = make_reader(handle).get_summary().chunk_indexes[chunk]
    destination.write_bytes(log.read_bytes()[:index.chunk_start_offset + index.chunk_length // 2])
    return destination
