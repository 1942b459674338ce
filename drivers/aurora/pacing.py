"""When to poll a tracker that counts its frames, so that each poll reads a new frame.

The Aurora measures at its own fixed rate (40 Hz) and BX answers with the newest frame
and its number. A host polling on its own free-running schedule at the same rate reads
some frames twice (two polls inside one frame) and misses their neighbours, even when
it is never late: its polls drift through the device's frame phase. `FramePacer` locks
the polls to that phase instead. Every reply bounds the instant the device's frame 0
began: the reply to a command sent at s and received at r, numbered n, says
s - (n + 1) T < origin <= r - n T. The pacer keeps the intersection of these bounds and
polls each frame at its estimated start, which leaves most of a frame period for the
host to be late before a frame is missed. A poll that comes too early reads the
previous frame again; that repeat narrows the bounds, and the next poll goes at once.

Pure arithmetic on host times (seconds, any single clock, any origin): no I/O, no sleep.
"""

from __future__ import annotations

import math

# The pacer aims each poll early by the host's usual lateness: this quantile of how late
# its polls went out after the instant aimed at (a 25x simulated rig is late by tenths
# of a frame; a real host at 40 Hz by a few hundredths). Earlier, most polls would come
# too early and be repeated; later, a late host would lose the end of each frame.
LATENESS_QUANTILE = 0.1
# Step of the running quantile estimate, as a fraction of the frame period per poll.
LATENESS_STEP_FRACTION = 0.01
# How fast the bounds loosen, as a fraction of the elapsed time: the device's and the
# host's clocks drift apart (crystals: 1e-4 at most), and a bound held forever would
# end up wrong by the accumulated drift.
CLOCK_DRIFT_FRACTION = 1e-4
# Bounds wider than this fraction of a frame, beyond the shortest exchange seen (they can
# never be narrower than one: the device takes its frame somewhere inside it), do not
# say where a frame begins (at first, after a restart of the count or once they
# loosened): the pacer then polls at once until a change of frame number narrows them.
LOCK_WIDTH_FRACTION = 0.5
# Frame numbers are 32-bit and wrap.
FRAME_NUMBER_MODULUS = 1 << 32


class FramePacer:
    """Poll times for a device numbering its frames at ``frame_period_s`` (s), to read
    one frame every ``poll_period_s`` (s, at least the frame period; default: every frame)."""

    def __init__(self, frame_period_s: float, poll_period_s: float | None = None) -> None:
        if not frame_period_s > 0:
            raise ValueError(f"frame_period_s must be > 0, got {frame_period_s!r}")
        poll_period_s = frame_period_s if poll_period_s is None else poll_period_s
        if not poll_period_s > 0:
            raise ValueError(f"poll_period_s must be > 0, got {poll_period_s!r}")
        self.frame_period_s = float(frame_period_s)
        # Frames per poll: 1 at the device's own rate, more to read every k-th frame.
        self._frames_per_poll = max(1.0, poll_period_s / frame_period_s)
        self._origin_low_s = -math.inf
        self._origin_high_s = math.inf
        self._bounded_at_s = 0.0
        self._last_frame: int | None = None
        self._due_frame = 0.0  # the frame the schedule wants next (fractional when k is)
        self._poll_period_s = float(poll_period_s)
        self._unnumbered_next_s: float | None = None
        self._usual_lateness_s = 0.0
        self._shortest_exchange_s = math.inf
        self._aimed_s: float | None = None  # the instant the last poll was aimed at

    def locked(self, now_s: float) -> bool:
        """Whether the replies so far say where the device's frames begin."""
        width = self._origin_high_s - self._origin_low_s + 2.0 * self._loosening(now_s)
        return width <= LOCK_WIDTH_FRACTION * self.frame_period_s + self._shortest_exchange_s

    def next_poll_s(self, now_s: float) -> float:
        """The host time to send the next poll; ``now_s`` or earlier means at once."""
        if self._unnumbered_next_s is not None:
            return self._unnumbered_next_s
        if self._last_frame is None or not self.locked(now_s):
            return now_s
        period = self.frame_period_s
        target = max(math.ceil(self._due_frame - 1e-9), self._last_frame + 1)
        # The middle of the bounds: a poll that comes too early reads the frame before
        # again and raises the lower bound; one that comes late lowers the upper bound.
        begins = 0.5 * (self._origin_low_s + self._origin_high_s) + target * period
        aim = begins - self._usual_lateness_s
        # Only a poll that waits for its instant says how late the host wakes.
        self._aimed_s = aim if aim > now_s else None
        return aim

    def observe(self, sent_s: float, received_s: float, frame_number: int | None) -> bool:
        """Take one reply: the poll was sent at ``sent_s`` and its frame ``frame_number``
        received at ``received_s`` (host seconds). True if no earlier poll read this frame.
        A frame without a number (no tools reported) is new, and the next poll is one
        poll period after this one."""
        if frame_number is None:
            self._unnumbered_next_s = sent_s + self._poll_period_s
            return True
        self._unnumbered_next_s = None
        period = self.frame_period_s
        self._shortest_exchange_s = min(self._shortest_exchange_s, received_s - sent_s)
        if self._aimed_s is not None:
            late = sent_s - self._aimed_s
            gain = LATENESS_STEP_FRACTION * period
            self._usual_lateness_s += gain * (LATENESS_QUANTILE - (late < self._usual_lateness_s))
            self._usual_lateness_s = min(max(self._usual_lateness_s, 0.0), 0.5 * period)
            self._aimed_s = None
        last = self._last_frame
        step = None if last is None else (frame_number - last) % FRAME_NUMBER_MODULUS
        if step is not None and step > FRAME_NUMBER_MODULUS // 2:
            # Numbered before the last one: the device restarted its count. Start over.
            self._origin_low_s, self._origin_high_s, last, step = -math.inf, math.inf, None, None
        frame = frame_number if last is None else last + step
        low = max(self._origin_low_s - self._loosening(sent_s), sent_s - (frame + 1) * period)
        high = min(self._origin_high_s + self._loosening(sent_s), received_s - frame * period)
        if low > high:
            # Bounds that contradict the new reply: the clocks drifted more than allowed
            # for. This reply alone is the truth now.
            low, high = sent_s - (frame + 1) * period, received_s - frame * period
        self._origin_low_s, self._origin_high_s, self._bounded_at_s = low, high, sent_s
        if step == 0:
            return False
        if last is None or frame > math.ceil(self._due_frame - 1e-9):
            # The first frame, or a late poll that skipped frames: the schedule goes on
            # from the frame read.
            self._due_frame = float(frame)
        self._due_frame += self._frames_per_poll
        self._last_frame = frame
        return True

    def _loosening(self, now_s: float) -> float:
        return CLOCK_DRIFT_FRACTION * max(0.0, now_s - self._bounded_at_s)
