"""How many samples per second each device stream delivers, against what it is set to.

A stream that falls behind skips ticks (`Session._periodic`) or frames (the tracker's
polls follow its frame count, `drivers.aurora.pacing`), so a slow host or a slow link
shows only as fewer samples: this is where that becomes a number and a warning, on the
rig and on the simulated rig alike. The tracker's samples are frames read for the first
time (a frame polled twice counts once); the IMUs' are FIFO records, each its own sample
instant. Rates are per second of session time.

A window's count is judged with the slack of where its ends fall: 5 samples in 0.528 s
of a 10.04 Hz stream, where 5.3 were due, is 94 % and no stream falling behind. A stream
counted in batches (the IMUs', a FIFO drain of 5 samples at a time) may lack a whole
batch that way.
"""

from __future__ import annotations

from dataclasses import dataclass

# Below this fraction of its configured rate a stream is reported as falling behind.
RATE_WARNING_FRACTION = 0.95


@dataclass(frozen=True)
class StreamRateFigure:
    """Samples delivered over ``interval_s`` of session time; rates in Hz. ``quantum``:
    the samples a window may lack through where its ends fall alone (1 for a stream
    counted sample by sample, a batch for one counted in batches)."""

    stream: str
    configured_hz: float
    samples: int
    interval_s: float
    quantum: int = 1

    @property
    def delivered_hz(self) -> float:
        return self.samples / self.interval_s if self.interval_s > 0 else 0.0

    @property
    def fraction(self) -> float:
        return self.delivered_hz / self.configured_hz

    @property
    def below_warning(self) -> bool:
        """Short of `RATE_WARNING_FRACTION` of the samples due by more than the window's
        quantisation: on a short window the fraction alone warns for a stream on time."""
        due = self.configured_hz * self.interval_s
        return self.samples + self.quantum < RATE_WARNING_FRACTION * due

    def describe(self) -> str:
        return (f"{self.stream} stream delivered {self.delivered_hz:.1f} of its {self.configured_hz:g} Hz "
                f"({100 * self.fraction:.1f} %) over {self.interval_s:.1f} s of session time")


class StreamRateMeter:
    """Counts one stream's deliveries; `since_mark` covers the time since the last
    `mark` (a plan step), `overall` the time since the stream started."""

    def __init__(self, stream: str, configured_hz: float, quantum: int = 1) -> None:
        self.stream = stream
        self.configured_hz = float(configured_hz)
        self.quantum = quantum  # see `StreamRateFigure`
        self._started_s: float | None = None
        self._samples = 0
        self._mark_s: float | None = None
        self._mark_samples = 0

    def start(self, t_s: float) -> None:
        """The stream's first tick, session s."""
        self._started_s = self._mark_s = t_s
        self._samples = self._mark_samples = 0

    def delivered(self) -> None:
        self._samples += 1

    @property
    def started(self) -> bool:
        return self._started_s is not None

    def since_mark(self, t_s: float) -> StreamRateFigure:
        mark = self._mark_s if self._mark_s is not None else t_s
        return StreamRateFigure(self.stream, self.configured_hz, self._samples - self._mark_samples, t_s - mark,
                                self.quantum)

    def mark(self, t_s: float) -> None:
        self._mark_s, self._mark_samples = t_s, self._samples

    def overall(self, t_s: float) -> StreamRateFigure:
        start = self._started_s if self._started_s is not None else t_s
        return StreamRateFigure(self.stream, self.configured_hz, self._samples, t_s - start, self.quantum)
