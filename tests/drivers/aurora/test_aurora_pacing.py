"""`FramePacer` against a model device: frames begin every ``period`` s from ``origin``,
the host wakes late by a drawn amount and the reply comes back ``latency`` s after the poll."""

from __future__ import annotations

import math
import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.aurora.pacing import FRAME_NUMBER_MODULUS, FramePacer

PERIOD_S = 0.025


def play(pacer: FramePacer, polls: int, *, origin_s: float, lateness, device_period_s: float = PERIOD_S,
         latency_s: float = 0.0002, first_frame: int = 0, start_s: float = 0.0, command_share: float = 0.1):
    """Poll ``polls`` times; (frame numbers read as new, polls per new frame, last host time).
    The device takes its frame ``command_share`` of the way through the exchange (the
    command is short, the BX reply long)."""
    now = start_s
    new_frames = []
    for _ in range(polls):
        now = max(now, pacer.next_poll_s(now)) + lateness()
        frame = first_frame + math.floor((now + command_share * latency_s - origin_s) / device_period_s)
        received = now + latency_s
        if pacer.observe(now, received, frame % FRAME_NUMBER_MODULUS):
            new_frames.append(frame)
        now = received
    return new_frames, polls / max(len(new_frames), 1), now


@settings(max_examples=40, deadline=None)
@given(origin=st.floats(0.0, PERIOD_S), seed=st.integers(0, 2**32 - 1),
       late_fraction=st.floats(0.0, 0.6))
def test_a_host_late_by_up_to_most_of_a_frame_reads_every_frame_once(origin, seed, late_fraction) -> None:
    rng = random.Random(seed)
    frames, polls_per_frame, _ = play(FramePacer(PERIOD_S), 3000, origin_s=origin,
                                      lateness=lambda: rng.uniform(0.0, late_fraction * PERIOD_S))
    after_lock = frames[5:]
    assert after_lock == list(range(after_lock[0], after_lock[0] + len(after_lock)))
    # Aimed at each frame's start, not sampling twice per frame.
    assert polls_per_frame < 1.5


@pytest.mark.parametrize("exchange_fraction", [0.02, 0.2, 0.5])
def test_a_slow_link_still_reads_every_frame_once(exchange_fraction) -> None:
    """An exchange that takes half a frame (a BX reply at 115200 baud is ~9 ms of the
    Aurora's 25): the bounds can never be narrower than one exchange, and still lock."""
    rng = random.Random(7)
    frames, polls_per_frame, _ = play(FramePacer(PERIOD_S), 3000, origin_s=0.011,
                                      latency_s=exchange_fraction * PERIOD_S,
                                      lateness=lambda: rng.uniform(0.0, 0.2 * PERIOD_S))
    assert frames[5:] == list(range(frames[5], frames[5] + len(frames) - 5))
    assert polls_per_frame < 1.5


def test_free_running_polls_at_the_frame_rate_would_miss_and_repeat_frames() -> None:
    """Why the pacer exists: the same host lateness on a fixed schedule loses frames."""
    rng = random.Random(1)
    now, seen = 0.0, []
    for tick in range(3000):
        now = max(now, tick * PERIOD_S) + rng.uniform(0.0, 0.6 * PERIOD_S)
        seen.append(math.floor((now - 0.3 * PERIOD_S) / PERIOD_S))
    assert len(set(seen)) < 0.8 * (seen[-1] - seen[0])  # 75 % of the frames
    rng = random.Random(1)
    frames, _, _ = play(FramePacer(PERIOD_S), 3000, origin_s=0.3 * PERIOD_S,
                        lateness=lambda: rng.uniform(0.0, 0.6 * PERIOD_S))
    assert len(frames) >= frames[-1] - frames[0]


def test_a_stall_loses_frames_never_repeats_them_and_the_lock_comes_back() -> None:
    rng = random.Random(2)
    stalls = iter([0.0] * 200 + [3.5 * PERIOD_S] + [0.0] * 200)
    frames, _, _ = play(FramePacer(PERIOD_S), 401, origin_s=0.01,
                        lateness=lambda: next(stalls) + rng.uniform(0.0, 0.3 * PERIOD_S))
    assert frames == sorted(set(frames))
    gaps = [b - a for a, b in zip(frames, frames[1:])]
    assert max(gaps) in (4, 5)
    assert sum(gap > 1 for gap in gaps) == 1


@pytest.mark.parametrize("poll_period_s, frames_per_poll", [(2 * PERIOD_S, 2.0), (0.1, 4.0), (PERIOD_S * 4 / 3, 4 / 3)])
def test_a_slower_poll_rate_reads_that_share_of_the_frames(poll_period_s, frames_per_poll) -> None:
    rng = random.Random(3)
    frames, _, now = play(FramePacer(PERIOD_S, poll_period_s), 2000, origin_s=0.004,
                          lateness=lambda: rng.uniform(0.0, 0.5 * PERIOD_S))
    read_rate = len(frames) / (frames[-1] - frames[0]) * frames_per_poll
    assert read_rate == pytest.approx(1.0, abs=0.01)
    assert frames == sorted(set(frames))


def test_a_device_that_restarts_its_count_is_followed() -> None:
    rng = random.Random(4)
    pacer = FramePacer(PERIOD_S)
    before, _, now = play(pacer, 300, origin_s=0.002, lateness=lambda: rng.uniform(0.0, 0.4 * PERIOD_S))
    after, _, _ = play(pacer, 300, origin_s=now - 0.011, start_s=now,
                       lateness=lambda: rng.uniform(0.0, 0.4 * PERIOD_S))
    assert before[-1] > 200 and after[0] < 3
    assert after[3:] == list(range(after[3], after[3] + len(after) - 3))


def test_frame_numbers_wrapping_at_32_bits_are_new_frames() -> None:
    rng = random.Random(5)
    frames, _, _ = play(FramePacer(PERIOD_S), 400, origin_s=0.0, first_frame=FRAME_NUMBER_MODULUS - 100,
                        lateness=lambda: rng.uniform(0.0, 0.4 * PERIOD_S))
    assert frames[-1] > FRAME_NUMBER_MODULUS  # read across the wrap, counted on
    assert frames[5:] == list(range(frames[5], frames[5] + len(frames) - 5))


@pytest.mark.parametrize("rate_error", [-1e-4, 1e-4, -2e-3, 2e-3])
def test_a_device_clock_off_the_nominal_rate_keeps_the_lock(rate_error) -> None:
    """Crystals are off by 1e-4 at most; 2e-3 is far beyond the drift the bounds allow for."""
    rng = random.Random(6)
    frames, polls_per_frame, _ = play(FramePacer(PERIOD_S), 6000, origin_s=0.007,
                                      device_period_s=PERIOD_S * (1 + rate_error),
                                      lateness=lambda: rng.uniform(0.0, 0.4 * PERIOD_S))
    missed = (frames[-1] - frames[0] + 1) - len(frames)
    assert missed <= (0 if abs(rate_error) <= 1e-4 else 0.01 * len(frames))
    assert frames == sorted(set(frames))
    assert polls_per_frame < 1.5


def test_frames_without_a_number_are_new_and_polled_at_the_poll_rate() -> None:
    pacer = FramePacer(PERIOD_S, 0.05)
    assert pacer.observe(1.0, 1.001, None)
    assert pacer.next_poll_s(1.002) == pytest.approx(1.05)
    assert pacer.observe(1.05, 1.051, None)


@pytest.mark.parametrize("frame_period_s, poll_period_s", [(0.0, None), (-1.0, None), (0.025, 0.0), (math.nan, None)])
def test_periods_must_be_positive(frame_period_s, poll_period_s) -> None:
    with pytest.raises(ValueError, match="period_s must be > 0"):
        FramePacer(frame_period_s, poll_period_s)
