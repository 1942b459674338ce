"""Each stream's delivered rate over a window, and when it is a stream falling behind."""

from __future__ import annotations

import pytest

from hydrojet_bench.bench.stream_rates import StreamRateFigure, StreamRateMeter


def test_a_short_window_one_sample_short_through_where_it_ends_is_no_warning():
    # The trial's step: 5 samples in 0.528 s of a 10.0446 Hz stream, where 5.3 were due.
    figure = StreamRateFigure("em", 10.0446, samples=5, interval_s=0.528)
    assert figure.fraction == pytest.approx(0.943, abs=1e-3) and not figure.below_warning
    # Two short is no quantisation: 19 of 21.1 due at 40 Hz (90 %).
    assert StreamRateFigure("em", 40.0, samples=19, interval_s=0.528).below_warning


def test_a_stream_counted_in_batches_may_lack_one_batch():
    # The IMUs' 5-sample FIFO drains: a 1.2 s step of a 10 Hz stream holds 10 or 15 of 12.
    assert not StreamRateFigure("imu", 10.0446, samples=10, interval_s=1.2, quantum=5).below_warning
    assert StreamRateFigure("imu", 10.0446, samples=5, interval_s=1.2, quantum=5).below_warning
    meter = StreamRateMeter("imu", 10.0446, quantum=5)
    meter.start(0.0)
    for _ in range(10):
        meter.delivered()
    assert not meter.since_mark(1.2).below_warning and meter.overall(1.2).quantum == 5


def test_real_shortfalls_over_long_windows_still_warn():
    assert StreamRateFigure("em", 40.0, samples=180, interval_s=5.0).below_warning  # 90 %
    assert not StreamRateFigure("em", 40.0, samples=191, interval_s=5.0).below_warning  # 95.5 %
    assert StreamRateFigure("imu", 100.0, samples=90_000, interval_s=1000.0, quantum=5).below_warning
