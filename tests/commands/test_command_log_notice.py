"""The notices the analysis commands give about a session log's streams."""

from __future__ import annotations

from hydrojet_bench.commands.log_notice import warn_if_streams_fell_short
from hydrojet_bench.logs import LogWriter
from hydrojet_bench.logs.topics import StreamRate


def test_a_stream_that_delivered_less_than_95_percent_over_the_session_is_said(tmp_path, capsys):
    """An IMU set to 1125 Hz that the host drained at 52 Hz: `sensors` printed its figures
    from 4.6 % of the samples without a word."""
    log = tmp_path / "s.mcap"
    with LogWriter(log) as writer:
        # A step's figure below the rate, then the closing figures: only those count.
        writer.write(StreamRate(t_s=5.0, stream="em", configured_hz=40.0, delivered_hz=30.0, samples=150,
                                interval_s=5.0, whole_session=False))
        writer.write(StreamRate(t_s=29.2, stream="em", configured_hz=40.0, delivered_hz=39.8, samples=1162,
                                interval_s=29.2, whole_session=True))
        writer.write(StreamRate(t_s=29.2, stream="imu", configured_hz=1125.0, delivered_hz=52.1, samples=1521,
                                interval_s=29.2, whole_session=True))
    assert warn_if_streams_fell_short(log) == ["imu stream delivered 52.1 of its 1125 Hz (4.6 %) over 29.2 s of "
                                               "session time"]
    assert "s.mcap: the session's imu stream delivered 52.1 of its 1125 Hz" in capsys.readouterr().err
    whole = tmp_path / "whole.mcap"
    with LogWriter(whole) as writer:
        writer.write(StreamRate(t_s=29.2, stream="imu", configured_hz=100.0, delivered_hz=99.9, samples=2917,
                                interval_s=29.2, whole_session=True))
    assert warn_if_streams_fell_short(whole) is None and capsys.readouterr().err == ""
