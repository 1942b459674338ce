"""One valid message per log topic, as the session runner writes them (numpy included),
and a small multi-chunk log built from them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from hydrojet_bench.logs import TOPICS, LogWriter

START_TIME_UNIX_S = 1_700_000_000.25
METADATA = {"bench": {"profile_name": "sim", "software_version": "test"}, "operator": {"name": "A. N. Other"}}
QUATERNION = np.array([0.9238795325112867, 0.0, 0.3826834323650898, 0.0])

EXAMPLES: dict[str, dict] = {
    "/bench/sample": {"source": "em", "jet_forces_n": np.array([0.05, 0.0, 0.0]), "sweep": 2, "step": 7,
                      "base_orientation": QUATERNION, "tip_orientation": (1.0, 0.0, 0.0, 0.0),
                      "base_position_m": np.array([0.012, 0.0, 0.192]), "tip_position_m": None},
    "/imu/raw": {"sensor": "tip", "address": 0x69, "accel_m_s2": np.array([0.1, -9.8, 0.2], dtype=np.float32),
                 "gyro_rad_s": [np.float64(0.001), 0.0, -0.002], "mag_ut": None, "temperature_c": np.float32(24.5)},
    "/imu/orientation": {"base": QUATERNION, "tip": QUATERNION, "tip_in_base": [1.0, 0.0, 0.0, 0.0]},
    "/em/frame": {"frame_number": np.int64(1234), "system_status": "0x0000", "tools": [
        {"name": "base", "handle": 10, "status": "ok", "orientation": QUATERNION,
         "position_m": [0.0, 0.0, 0.2], "rms_error_mm": 0.31},
        {"name": "tip", "handle": 11, "status": "missing", "orientation": None, "position_m": None,
         "rms_error_mm": float("nan")}]},
    "/valves/command": {"command": "SET_ALL", "duties_permille": [500, 0, 250.5], "jet_forces_n": None},
    "/valves/reply": {"command": "SET_ALL", "ok": False, "code": "E04", "detail": "bad checksum"},
    "/bench/step": {"index": 3, "count": 229, "sweep": -1, "step": 3, "jet_forces_n": (0.0, 0.02, 0.01),
                    "samples": 200, "tip_in_base_measured": QUATERNION, "tip_position_in_base_m": None},
    "/model/prediction": {"index": 3, "tip_in_base": QUATERNION, "tip_position_in_base_m": [0.01, 0.0, 0.068],
                          "bend_deg": 45.0, "orientation_error_deg": 1.5, "position_error_mm": None,
                          "method": "ref"},
    "/estimate/disturbance": {"index": 3, "force_n": np.zeros(3), "moment_nm": np.array([1e-4, -2e-4, 0.0]),
                              "moment_norm_nm": 2.236e-4, "orientation_error_deg_before": 3.0,
                              "orientation_error_deg_after": 0.5, "iterations": 2},
    "/bench/parameters": {"model": "cosserat", "effects": ["gravity"], "parameters": {"E0": 3e5, "EL": 2e5},
                          "calibrated": True, "rms_orientation_deg_before": 9.0, "rms_orientation_deg_after": None},
    "/events": {"level": "warning", "source": "tracker", "message": "sensor not tracked: tip MISSING"},
}
# The two Foxglove topics are written by their own methods.
FOXGLOVE_TOPICS = ("/tf", "/scene/backbone")
assert set(EXAMPLES) | set(FOXGLOVE_TOPICS) == set(TOPICS)


def write_all_topics(log: LogWriter, t_s: float) -> float:
    """Every topic once, at t_s, t_s + 0.01, ...; returns the next free time."""
    for topic, message in EXAMPLES.items():
        log.write(topic, message, t_s=t_s)
        t_s += 0.01
    log.write_transform(t_s, parent="base", child="tip", rotation=QUATERNION, translation_m=[0.01, 0.0, 0.068])
    t_s += 0.01
    log.write_backbone(t_s, positions_in_base_m=np.linspace([0, 0, 0], [0.01, 0.0, 0.068], 5))
    return t_s + 0.01


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
                log.write("/events", {"level": "info", "source": "test", "message": f"{chunk}.{index}"},
                          t_s=chunk + 0.1 * index)
            log.flush()
    return path


def cut_inside_chunk(log: Path, chunk: int, destination: Path) -> Path:
    """A copy of a finished log cut off inside its chunk number `chunk` (0-based), as a
    crash while that chunk was being written leaves it."""
    with log.open("rb") as handle:
        index = make_reader(handle).get_summary().chunk_indexes[chunk]
    destination.write_bytes(log.read_bytes()[:index.chunk_start_offset + index.chunk_length // 2])
    return destination
