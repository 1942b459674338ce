"""One bench session: play a plan on the rig, estimate live, record everything.

Tasks on one event loop: the EM stream (a frame per tick at its rate in session time) and
the IMU stream (both chips' FIFOs drained every few samples, so a late turn of the loop
costs no sample), each logging raw data and feeding the step recorders, the valve driver's own reader
and heartbeat, the plan task and the estimation task. The plan task commands each step,
holds it for its settle time, averages the end of the step and queues it for the
estimation task, so the next step starts when this one's settle time ends:

* on calibration poses (sweep -1): the plan task collects them; when they end, it waits
  for their estimates and calibrates the model on them (paper sec. V-B) in a worker
  thread while the streams go on;
* on every step: the estimation task, in plan order, predicts it with the calibrated
  constant disturbance ("ref") and, with online estimation on, corrects w_d|m from the
  measurement (eq. 4).

Devices come from `bench.rig.open_rig`. Exit paths: the valve driver sends ALL_OFF (logged
on ``/valves/command``) when its context exits, whatever the reason (plan done, exception, cancellation by
SIGINT/SIGTERM); the firmware's watchdog covers a host that dies without exiting. The
log is finished on every path but a hard kill, after which `hydrojet-bench recover`
salvages it up to its last flushed chunk.
"""

from __future__ import annotations

import asyncio
import contextlib
import gc
import itertools
import json
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import numpy as np

from drivers.aurora.client import FRAME_PERIOD_S, AuroraTracker
from drivers.aurora.errors import AuroraError
from drivers.aurora.pacing import FramePacer
from drivers.imu import ImuError, ImuSample, output_rate_hz, paired_samples
from drivers.imu.registers import FIFO_RECORDS
from drivers.transport.base import TransportError
from drivers.valve.client import ValveController, ValveError

from .. import __version__
from ..data.dataset import Dataset
from ..errors import ConvergenceError, UserError
from ..estimation.calibration import CalibrationResult, calibrate_dataset
from ..estimation.setup_warnings import calibration_warnings
from ..estimation.online import OnlineSettings
from ..estimation.path import PathPredictor, StepPrediction
from ..logs import LogWriter, floats
from ..logs.topics import (Disturbance, EmFrame, EmTool, Event, ImuOrientation, ImuRaw, ModelPrediction,
                           Parameters, Sample, SetupCheck, Step, StreamRate, ValveCommand, ValveReply)
from ..models.shooting import ShootingModel
from ..effects import effect_values
from ..geometry import quat_from_matrix, quat_from_rotvec, quat_multiply
from ..params import PARAMETER_NAMES, ModelParameters, get_parameter
from ..plans import CALIBRATION_SWEEP, Plan, PlanStep
from ..config import RigConfig
from ..profile import RigProfile
from .checks import CheckResult, CheckSettings, predicted_bending_rad, run_setup_checks
from .clock import Clock, PacedClock, ScaledClock
from .recorder import StepRecorder
from .rig import ImuPair, open_rig
from .simulated_rig import SimulatedDevices
from .stream_rates import StreamRateFigure, StreamRateMeter

# Consecutive stream failures after which a device counts as lost and the session stops.
MAX_CONSECUTIVE_FAILURES = 20
# The IMU FIFOs are drained every this many output periods: a quarter of their 22
# records, so a turn of the event loop can come ~17 samples late before one is lost.
FIFO_DRAIN_SAMPLES = 5
# Wall time a log record may arrive after the time it is stamped with (a sample written
# after fusion, a prediction after its solve) and still be logged in time order.
REORDER_WINDOW_WALL_S = 0.25


def _raise_if_cancel_was_swallowed() -> None:
    """Python 3.11's wait_for (inside every driver request) can return a result while
    losing a cancellation that arrived as it completed; the task still counts the
    request, so honour it here rather than play the rest of the plan after Ctrl-C."""
    task = asyncio.current_task()
    if task is not None and task.cancelling():
        raise asyncio.CancelledError


class SessionAborted(UserError):
    """A device failed for good; the session stopped with valves off and its log finished."""


# Failures of the rig rather than of the software: reported as one line, not a traceback.
DEVICE_ERRORS = (AuroraError, ImuError, ValveError, TransportError)


async def _after_due_timers() -> None:
    """Let every task whose timer fell due go before the caller's next piece of work.

    At 25x a tracker frame lasts 1 ms of wall time, and a plan step's end (its settled
    row, the next command and the twin's new equilibrium) takes about 2 ms: done in one
    piece it made the tracker miss a frame at most steps. ``sleep(0)`` is not enough,
    as the caller's own turn is queued ahead of the timers that fell due meanwhile; a
    timer of its own, due after theirs, is queued behind them."""
    await asyncio.sleep(1e-6)


def _first_leaf(error: BaseException) -> BaseException:
    """The first exception inside (nested) exception groups, e.g. from a TaskGroup."""
    while isinstance(error, BaseExceptionGroup):
        error = error.exceptions[0]
    return error


@dataclass(frozen=True)
class SessionRequest:
    """What to run. params: parameters to start from (calibrated earlier, or the
    profile's nominal ones); calibrate: fit them on the plan's calibration poses when
    those end; names: which parameters that calibration fits (effect parameters
    included)."""

    profile: RigProfile
    settings: RigConfig
    plan: Plan
    log_path: Path
    model: ShootingModel
    effects: tuple[str, ...]
    params: ModelParameters
    calibrate: bool = True
    calibration_names: tuple[str, ...] = PARAMETER_NAMES
    seed: int | None = None
    command_line: str = ""
    warnings: tuple[str, ...] = ()  # about the request (say, clipped plan steps): logged as events at the start
    overwrite_log: bool = False  # replace an existing log_path (else refused, see LogWriter)
    setup_checks: bool = True  # the wiring and level checks before the plan (`bench.checks`)


@dataclass
class SessionStatus:
    """What the live view shows; updated in place by the session."""

    step_count: int
    phase: str = "starting"
    step_index: int = -1
    step: PlanStep | None = None
    session_time_s: float = 0.0
    remaining_session_s: float = 0.0
    time_scale_kept: float | None = None  # session seconds per wall second since arming
    ref_error_deg: float | None = None
    online_error_deg: float | None = None
    errors_step_index: int = -1  # the step the two errors are of (estimates trail the plan)
    disturbance_norm_nm: float | None = None
    em_frames: int = 0
    em_missing: int = 0
    imu_samples: int = 0
    imu_errors: int = 0
    imu_overflows: int = 0  # FIFO reads that found samples lost (the host was too late)
    valve_commands: int = 0
    valve_retries: int = 0
    stream_rates: dict[str, StreamRateFigure] = field(default_factory=dict)  # over the last step, by stream
    events: deque = field(default_factory=lambda: deque(maxlen=6))  # (t_s, level, message, source)
    event_count: int = 0  # every event so far: a reader of ``events`` can tell which are new


@dataclass(frozen=True, repr=False)
class SessionResult:
    log_path: Path
    completed_steps: int
    step_count: int
    session_time_s: float
    wall_time_s: float
    params: ModelParameters
    calibration: CalibrationResult | None
    estimates: tuple[StepPrediction, ...]
    steps: Dataset | None
    stream_rates: tuple[StreamRateFigure, ...] = ()  # over the whole session, one per stream that ran
    checks: tuple[CheckResult, ...] = ()  # the setup checks' outcomes (none when skipped)
    # What the calibration's numbers suggest about the setup (`estimation.setup_warnings`).
    calibration_warnings: tuple[str, ...] = ()
    # When the valves were armed (None if they never were): what came before is set-up
    # (devices opened, kernels loaded or, on a fresh checkout, compiled), during which
    # a simulated rig's session clock runs on with nothing commanded.
    armed_session_s: float | None = None
    armed_wall_s: float | None = None
    # Wall seconds a simulated rig's session time waited for a host too slow for its
    # time scale (`PacedClock`); 0 on the rig.
    held_wall_s: float = 0.0
    # Session seconds per wall second from the arming of the valves to the end of the plan
    # (None if they were never armed), and the wall seconds that is over; `held_wall_s`
    # is over the same span.
    time_scale_kept: float | None = None
    kept_wall_s: float = 0.0
    # Why the calibration on the calibration poses failed (None if it did not run or
    # succeeded): the session then estimated with its starting parameters.
    calibration_failure: str | None = None

    def __repr__(self) -> str:
        # Short: Python 3.11's asyncio.run formats its main task, result included, on
        # the way out (signal handler restore): printing every settled row and solution
        # took 0.44 s after a 12-step session (under cProfile), counted in its wall time.
        return (f"SessionResult({str(self.log_path)!r}, {self.completed_steps}/{self.step_count} steps, "
                f"{self.session_time_s:.1f} s session, {self.wall_time_s:.1f} s wall)")


class Session:
    def __init__(self, request: SessionRequest, clock: Clock | None = None,
                 on_update: Callable[[SessionStatus], None] | None = None,
                 on_log_message: Callable[[str, int, bytes], None] | None = None) -> None:
        self.request = request
        self.on_log_message = on_log_message  # every log message as written: see LogWriter's listener
        # A rig of emulators only waits for a host that falls behind rather than losing
        # samples; a real device's time is the wall's.
        self.clock = clock or (PacedClock if request.settings.transports.all_simulated
                               else ScaledClock)(request.settings.session.time_scale)
        # The clock that waits for the host, if this is one: it needs its pacing task,
        # and the time it held back is reported.
        self._paced = self.clock if isinstance(self.clock, PacedClock) else None
        self.status = SessionStatus(len(request.plan))
        self.on_update = on_update or (lambda status: None)
        profile = request.profile
        self.em = StepRecorder(profile, with_positions=True, source="em")
        self.params = request.params
        self.calibration: CalibrationResult | None = None
        self.calibration_warnings: tuple[str, ...] = ()
        self.calibration_failure: str | None = None
        self.estimation: PathPredictor | None = None
        self.estimates: list[StepPrediction] = []
        self.settled_rows: list[Dataset] = []
        self._calibration_rows: list[Dataset] = []
        self._log: LogWriter | None = None
        self._devices: SimulatedDevices | None = None
        self._stopping = False
        # The IMUs' samples are counted as each drain of the FIFOs brings them, a batch
        # of FIFO_DRAIN_SAMPLES: a plan step's window may hold a drain fewer.
        self._rates = {"em": StreamRateMeter("em", request.settings.tracker.rate_hz),
                       "imu": StreamRateMeter("imu", output_rate_hz(request.settings.imu.rate_hz),
                                              quantum=FIFO_DRAIN_SAMPLES)}
        self._rate_warned: set[str] = set()
        # Settled steps waiting for their estimate, in plan order (`_estimate_steps`).
        self._to_estimate: asyncio.Queue[tuple[int, Dataset, float]] = asyncio.Queue()
        self._overall_rates: tuple[StreamRateFigure, ...] = ()
        # The time scale kept over the plan, the wall seconds it was kept over and those
        # session time waited in them, taken together with the rates (`_log_overall_rates`).
        self._kept_over_plan: tuple[float | None, float, float] | None = None
        # While the setup checks run: their own recorder and the base accelerometer's
        # readings; samples then are no protocol data and are not logged as such.
        self._check_recorder: StepRecorder | None = None
        self._check_accel: list[tuple[float, np.ndarray]] | None = None
        self.checks: tuple[CheckResult, ...] = ()
        self._predicted_bending: np.ndarray | None = None
        self._heap_frozen = False  # gc.freeze() while the valves are armed
        self._armed: tuple[float, float] | None = None  # (session time, time.monotonic()) at arming

    # --- public ---------------------------------------------------------------------

    async def run(self) -> SessionResult:
        request = self.request
        started = time.monotonic()
        metadata = {"bench": {
            "software_version": __version__,
            "profile_name": request.profile.name,
            "profile_toml": request.profile.path.read_text() if request.profile.path else "",
            # The profile as the session used it, `extends` resolved: the file's text
            # alone names its parent by a path that may mean another file later.
            "profile_resolved_json": json.dumps(msgspec.to_builtins(request.profile.config)),
            "plan_steps": str(len(request.plan)),
            "model": request.model.name,
            "effects": json.dumps(list(request.effects)),
            "command_line": request.command_line,
            "settings": repr(request.settings),
        }}
        completed = 0
        # The profile's flush period is session time, like its other times; the writer counts wall time.
        flush_interval_wall_s = request.settings.session.flush_interval_s / self.clock.time_scale
        try:
            with LogWriter(request.log_path, metadata=metadata, flush_interval_s=flush_interval_wall_s,
                           overwrite=request.overwrite_log, listener=self.on_log_message,
                           reorder_window_s=REORDER_WINDOW_WALL_S * self.clock.time_scale, background=True) as log:
                self._log = log
                self._write_parameters()
                for warning in request.warnings:
                    self.event("warning", "request", warning)
                try:
                    completed = await self._run_devices()
                except asyncio.CancelledError:
                    self.event("warning", "session", "interrupted: valves closed, log finished")
                    raise
                except Exception as error:
                    cause = _first_leaf(error)
                    self.event("error", "session", f"stopped: {type(cause).__name__}: {cause}")
                    # A twin with no equilibrium for the profile's rod is the user's inputs too.
                    if isinstance(cause, (UserError, ConvergenceError)):
                        raise cause from error
                    if isinstance(cause, DEVICE_ERRORS):
                        raise SessionAborted(f"device failure: {cause}") from error
                    raise
        except (UserError, ConvergenceError) as error:
            # Devices that never opened measured nothing: a log of the request alone would
            # only stand in the way of the retry (its path is taken).
            if self._armed is not None:
                raise
            Path(request.log_path).unlink(missing_ok=True)
            raise type(error)(f"{error} (nothing was measured: no log kept)") from error
        steps = Dataset.concatenate(self.settled_rows) if self.settled_rows else None
        armed = self._armed
        # The figures the log says; an unfinished plan's up to now.
        kept, kept_wall_s, held_wall_s = self._kept_over_plan or self._kept_so_far()
        return SessionResult(request.log_path, completed, len(request.plan), self.clock.now(),
                             time.monotonic() - started, self.params, self.calibration,
                             tuple(self.estimates), steps, self._overall_rates, self.checks,
                             self.calibration_warnings, None if armed is None else armed[0],
                             None if armed is None else armed[1] - started,
                             held_wall_s, kept, kept_wall_s, self.calibration_failure)

    def event(self, level: str, source: str, message: str) -> None:
        t_s = self.clock.now()
        self.status.events.append((t_s, level, message, source))
        self.status.event_count += 1
        if self._log is not None:
            self._log.write(Event(t_s=t_s, level=level, source=source, message=message))

    # --- devices --------------------------------------------------------------------

    async def _run_devices(self) -> int:
        try:
            return await self._run_rig()
        finally:
            if self._heap_frozen:
                gc.unfreeze()
                self._heap_frozen = False

    async def _run_rig(self) -> int:
        request = self.request
        valves = None
        try:
            async with open_rig(request.profile, request.settings, self.clock, seed=request.seed,
                                before_arming=self._load_kernels, on_event=self.event) as rig, \
                    self._all_off_on_record():
                valves = rig.valves
                return await self._run_armed(rig)
        finally:
            if valves is not None:
                self._log_valves_closed(valves)

    async def _run_armed(self, rig) -> int:
        """The plan on the opened, armed rig, its streams beside it."""
        self._devices = rig.simulated
        self._armed = (self.clock.now(), time.monotonic())
        async with asyncio.TaskGroup() as group:
            streams = [group.create_task(self._em_stream(rig.tracker), name="em-stream"),
                       group.create_task(self._estimate_steps(), name="estimation")]
            if self._paced is not None:
                streams.append(group.create_task(self._paced.keep_pace(), name="session-clock"))
            imu_stream = None
            if rig.imus is not None:
                imu_stream = group.create_task(self._imu_stream(rig.imus), name="imu-stream")
                streams.append(imu_stream)
            try:
                completed = await self._play(rig.valves)
                if imu_stream is not None:
                    # Its last drain (within one drain period) before the rates are taken.
                    self._stopping = True
                    await imu_stream
                self._log_overall_rates()
                return completed
            finally:
                # Python 3.11's wait_for can swallow a cancellation that arrives as its
                # inner future completes (the IMU reads complete all the time), so the
                # streams also stop on this flag.
                self._stopping = True
                for task in streams:
                    task.cancel()

    @contextlib.asynccontextmanager
    async def _all_off_on_record(self):
        """Entered right after the rig, so it exits right before the rig closes and its
        valve driver sends ALL_OFF, on every exit path: the log shows the valves closed."""
        try:
            yield
        finally:
            self._log.write(ValveCommand(t_s=self.clock.now(), command="ALL_OFF", duties_permille=(0.0, 0.0, 0.0),
                                         jet_forces_n=(0.0, 0.0, 0.0)))

    def _log_valves_closed(self, valves) -> None:
        """Whether the controller acknowledged the ALL_OFF its driver sent on closing."""
        if valves.all_off_failure is None:
            self.event("info", "valves", "closed: the controller acknowledged ALL_OFF")
        else:
            watchdog_ms = self.request.settings.valves.watchdog_ms
            self.event("warning", "valves", f"ALL_OFF was not acknowledged ({valves.all_off_failure}): the "
                       f"controller's watchdog closes the valves {watchdog_ms:g} ms after the host falls silent")

    async def _load_kernels(self) -> None:
        """Loads the compiled kernels a session will call, before any valve is armed: the
        first call of each loads it (about a second) or, on a fresh checkout, compiles it
        (seconds, far longer on a busy machine), holding the interpreter the valve
        heartbeat needs. A solve and one online estimate (its sensitivity columns and
        step, which the calibration's Jacobian uses too) reach every kernel."""
        await asyncio.to_thread(self._call_every_kernel)
        if self.request.setup_checks:
            # The wiring check's model directions, at the profile's clamp pose: solved
            # here, as no solve may hold up the valve heartbeat once armed.
            self._predicted_bending = await asyncio.to_thread(
                predicted_bending_rad, self.request.model, self.params, CheckSettings().force_n)
        # A full collection walks every live object while holding the interpreter. In a
        # long-lived process (a notebook; the test suite, ~5e5 objects) that held the loop
        # 0.15-0.3 s on a fast machine: the likeliest cause of the one valve-watchdog trip
        # seen mid-session (0.5 s, on a slower machine). What is alive now lives through
        # the session, so the collector skips it while the valves are armed.
        gc.collect()
        gc.freeze()
        self._heap_frozen = True

    def _call_every_kernel(self) -> None:
        rest = self.request.model.solve(np.zeros(3), self.params)
        # A reading 2 degrees off the model's, so the estimator has a step to take.
        reading = quat_multiply(rest.tip_sensor_quaternion(), quat_from_rotvec(np.array([0.035, 0.0, 0.0])))
        warm_up = PathPredictor(self.request.model, self.params, OnlineSettings())
        with contextlib.suppress(ConvergenceError):  # its kernels are loaded all the same
            warm_up.step(np.zeros(3), reading, np.asarray(self.params.gravity_in_base_m_s2))

    # --- streams --------------------------------------------------------------------

    async def _periodic(self, meter: StreamRateMeter, period: float):
        """Yield once per ``period`` s of session time; a stream that falls behind skips
        the missed ticks rather than bursting to catch up (``meter`` then shows it)."""
        next_tick = self.clock.now()
        meter.start(next_tick)
        while not self._stopping:
            next_tick += period
            now = self.clock.now()
            if next_tick < now - period:
                next_tick = now
            if next_tick > now:
                await self.clock.sleep_until(next_tick)
            else:
                # Behind: still give the loop a turn, as a stream whose reads never
                # suspend (emulated IMUs) would otherwise starve the plan and heartbeat.
                await asyncio.sleep(0)
            yield

    async def _em_stream(self, tracker: AuroraTracker) -> None:
        log = self._log
        status = self.status
        failures = 0
        missing_before = False
        meter = self._rates["em"]
        clock = self.clock
        # Polls locked to the tracker's own frames: a frame read twice is no new sample,
        # and the rate meter counts frames, not polls.
        pacer = FramePacer(FRAME_PERIOD_S, 1.0 / meter.configured_hz)
        meter.start(clock.now())
        while not self._stopping:
            poll_s = pacer.next_poll_s(clock.now())
            if poll_s > clock.now():
                await clock.sleep_until(poll_s)
            else:
                await asyncio.sleep(0)  # at once, yet a turn for the others
            sent_s = clock.now()
            try:
                frame = await tracker.read_frame()
                failures = 0
            except (AuroraError, TransportError, TimeoutError) as error:
                failures += 1
                self.event("warning", "tracker", f"frame lost: {error}")
                if failures >= MAX_CONSECUTIVE_FAILURES:
                    raise SessionAborted(f"EM tracker lost: {failures} frames failed in a row ({error})") from error
                continue
            t_s = clock.now()
            if not pacer.observe(sent_s, t_s, frame.frame_number):
                continue
            meter.delivered()
            status.em_frames += 1
            tools = tuple(EmTool(
                name=pose.name, handle=pose.handle, status=pose.status.value, orientation=pose.orientation,
                position_m=None if pose.position_mm is None else tuple(v / 1000.0 for v in pose.position_mm),
                rms_error_mm=pose.rms_error_mm,
            ) for pose in frame.poses)
            log.write(EmFrame(t_s=t_s, frame_number=frame.frame_number,
                              system_status=f"{frame.system_status:#06x}", tools=tools))
            try:
                base, tip = frame["base"], frame["tip"]
            except KeyError:
                continue
            complete = base.has_pose and tip.has_pose and not frame.hardware_failure
            if not complete:
                status.em_missing += 1
                if not missing_before:
                    self.event("warning", "tracker", f"sensor not tracked: base {base.status.name}, tip {tip.status.name}")
                missing_before = True
                continue
            if missing_before:
                self.event("info", "tracker", "both sensors tracked again")
            missing_before = False
            base_p = tuple(v / 1000.0 for v in base.position_mm)
            tip_p = tuple(v / 1000.0 for v in tip.position_mm)
            self.em.add(t_s, base.orientation, tip.orientation, base_p, tip_p)
            if self._check_recorder is not None:
                self._check_recorder.add(t_s, base.orientation, tip.orientation, base_p, tip_p)
            self._write_sample("em", t_s, base.orientation, tip.orientation, base_p, tip_p)

    async def _imu_stream(self, imus: ImuPair) -> None:
        """Drain both FIFOs every `FIFO_DRAIN_SAMPLES` samples until the session stops, then
        once more: the rate meter counts exactly the samples taken while it ran."""
        base_chip, tip_chip = imus.base, imus.tip
        failures = 0
        period_s = base_chip.driver.sample_period_s
        queued: dict[str, deque[ImuSample]] = {"base": deque(), "tip": deque()}

        async def drain() -> None:
            nonlocal failures
            try:
                base_read = await base_chip.read_fifo()
                await asyncio.sleep(0)
                reads = {"base": base_read, "tip": await tip_chip.read_fifo()}
                failures = 0
            except ImuError as error:
                failures += 1
                self.status.imu_errors += 1
                self.event("warning", "imu", f"samples lost: {error}")
                if failures >= MAX_CONSECUTIVE_FAILURES:
                    raise SessionAborted(f"IMUs lost: {failures} reads failed in a row ({error})") from error
                return
            for name, read in reads.items():
                queued[name].extend(read.samples)
                if read.overflowed:
                    self._imu_overflowed(name, period_s)
            for base, tip in paired_samples(queued["base"], queued["tip"], period_s):
                self._imu_pair(imus, base, tip)
                # A turn for the others between pairs: the tracker answers one request per
                # frame, and a whole batch at once would make it miss frames.
                await asyncio.sleep(0)

        # What queued while the kernels loaded, before arming, is not the session's: the
        # FIFOs may even have overflowed then.
        await base_chip.reset_fifo()
        await tip_chip.reset_fifo()
        async for _ in self._periodic(self._rates["imu"], FIFO_DRAIN_SAMPLES * period_s):
            await drain()
        await drain()

    def _imu_overflowed(self, sensor: str, period_s: float) -> None:
        self.status.imu_overflows += 1
        if self.status.imu_overflows == 1:
            depth_s = FIFO_RECORDS * period_s
            self.event("warning", "imu", f"{sensor} IMU's FIFO overflowed: the host read it more than "
                       f"{depth_s:.2f} s of session time late and samples were lost (counted in the IMU rate)")

    def _imu_pair(self, imus: ImuPair, base: ImuSample, tip: ImuSample) -> None:
        """Log, fuse and record one base/tip pair of samples."""
        log = self._log
        self._rates["imu"].delivered()
        self.status.imu_samples += 1
        if self._check_accel is not None:
            self._check_accel.append((base.t_s, np.asarray(base.accel_m_s2, dtype=float)))
        for name, chip, sample in (("base", imus.base, base), ("tip", imus.tip, tip)):
            log.write(ImuRaw(t_s=sample.t_s, sensor=name, address=chip.address,
                             accel_m_s2=floats(sample.accel_m_s2), gyro_rad_s=floats(sample.gyro_rad_s),
                             mag_ut=floats(sample.mag_ut), temperature_c=sample.temperature_degc))
        fusion = imus.fusion
        tip_in_base = fusion.update(base, tip)
        t_s = tip.t_s
        base_q, tip_q = fusion.base.quaternion, fusion.tip.quaternion
        log.write(ImuOrientation(t_s=t_s, base=floats(base_q), tip=floats(tip_q), tip_in_base=floats(tip_in_base)))
        self._write_sample("imu", t_s, base_q, tip_q, None, None)

    def _write_sample(self, source: str, t_s: float, base_q, tip_q, base_p, tip_p) -> None:
        if self._check_recorder is not None:
            return
        step = self.em.step
        self._log.write(Sample(
            t_s=t_s, source=source,
            jet_forces_n=floats(step.jet_forces_n if step is not None else (0.0, 0.0, 0.0)),
            sweep=step.sweep if step is not None else CALIBRATION_SWEEP,
            step=step.step if step is not None else 0,
            base_orientation=floats(base_q), tip_orientation=floats(tip_q),
            base_position_m=floats(base_p), tip_position_m=floats(tip_p)))

    # --- stream rates ---------------------------------------------------------------

    def _write_rate(self, t_s: float, figure: StreamRateFigure, whole_session: bool) -> None:
        self._log.write(StreamRate(t_s=t_s, stream=figure.stream, configured_hz=figure.configured_hz,
                                   delivered_hz=figure.delivered_hz, samples=figure.samples,
                                   interval_s=figure.interval_s, whole_session=whole_session))

    def _log_step_rates(self) -> None:
        """Each stream's rate over the step just played: logged, shown, and the first
        step a stream falls behind in is a warning (once, not at every step)."""
        t_s = self.clock.now()
        for name, meter in self._rates.items():
            if not meter.started:
                continue
            figure = meter.since_mark(t_s)
            meter.mark(t_s)
            self.status.stream_rates[name] = figure
            self._write_rate(t_s, figure, whole_session=False)
            if figure.below_warning and name not in self._rate_warned:
                self._rate_warned.add(name)
                self.event("warning", name, f"falling behind: {figure.describe()}")

    def _log_overall_rates(self) -> None:
        t_s = self.clock.now()
        figures = tuple(meter.overall(t_s) for meter in self._rates.values() if meter.started)
        for figure in figures:
            self._write_rate(t_s, figure, whole_session=True)
            if figure.below_warning:
                self.event("warning", figure.stream, f"below its configured rate: {figure.describe()}")
        self._overall_rates = figures
        self._kept_over_plan = self._kept_so_far()
        kept, _, held_wall_s = self._kept_over_plan
        if held_wall_s > 0.0 and kept is not None:
            # Waiting keeps the emulators' streams whole unless the host still read too late.
            lost = any(figure.below_warning for figure in figures) or self.status.imu_overflows
            self.event("warning" if lost else "info", "session",
                       f"x{kept:.1f} kept of x{self._paced.time_scale:g}: session time waited {held_wall_s:.1f} s "
                       "of wall time for the host, " + (
                           f"and still {self.status.imu_overflows} IMU FIFO overflow(s) or a stream below 95 % of "
                           "its rate lost samples" if lost else "so the emulated devices lost no samples to it"))

    def _time_scale_kept(self) -> float | None:
        """Session seconds per wall second since the valves were armed."""
        return self._kept_so_far()[0]

    def _kept_so_far(self) -> tuple[float | None, float, float]:
        """The time scale kept since the valves were armed (None before), the wall seconds
        since then and the wall seconds session time waited for the host, taken together."""
        held_wall_s = 0.0 if self._paced is None else self._paced.held_wall_s
        if self._armed is None:
            return None, 0.0, held_wall_s
        armed_session_s, armed_wall_s = self._armed
        wall_s = time.monotonic() - armed_wall_s
        kept = (self.clock.now() - armed_session_s) / wall_s if wall_s > 0.0 else None
        return kept, wall_s, held_wall_s

    # --- the plan -------------------------------------------------------------------

    async def _play(self, valves: ValveController) -> int:
        request = self.request
        status = self.status
        timing = request.settings.session
        remaining = request.plan.duration_s
        await self._setup_checks(valves)
        for index, step in enumerate(request.plan):
            if step.sweep != CALIBRATION_SWEEP:
                await self._finish_calibration()
            status.phase = "calibration poses" if step.sweep == CALIBRATION_SWEEP else f"sweep {step.sweep}"
            status.step_index, status.step = index, step
            self.em.begin(step)
            started = self.clock.now()
            await self._command(valves, step.jet_forces_n)
            _raise_if_cancel_was_swallowed()
            end = started + step.settle_s
            await self.clock.sleep_until(end)
            remaining -= step.settle_s
            status.remaining_session_s = remaining
            status.session_time_s = self.clock.now()
            status.time_scale_kept = self._time_scale_kept()
            await self._settle(index, step, self.clock.now(), min(timing.window_s, step.settle_s))
            await _after_due_timers()
            if index + 1 == len(request.plan):
                await self._to_estimate.join()  # the plan is over: show its last step's errors
            self._log_step_rates()
            self.on_update(status)
        await self._finish_calibration()
        await self._to_estimate.join()
        _raise_if_cancel_was_swallowed()
        await self._command(valves, (0.0, 0.0, 0.0))
        status.phase = "done"
        self.on_update(status)
        return len(request.plan)

    async def _setup_checks(self, valves: ValveController) -> None:
        """The wiring and level checks (`bench.checks`), logged; a miswired rig stops here,
        before any protocol data."""
        request = self.request
        if not request.setup_checks:
            for check in ("wiring", "level"):
                self._log.write(SetupCheck(t_s=self.clock.now(), check=check, status="skipped",
                                           message="skipped (--skip-checks)"))
            return
        settings = CheckSettings()
        self.status.phase = "setup checks"
        self._check_recorder = StepRecorder(request.profile, with_positions=True, source="em")
        self._check_accel = []

        async def hold(forces) -> Dataset | None:
            self._check_recorder.begin(PlanStep(forces, CALIBRATION_SWEEP, 0, settings.settle_s))
            self._check_accel.clear()
            await self._command(valves, forces)
            await self.clock.sleep_until(self.clock.now() + settings.settle_s)
            return self._check_recorder.settled(self.clock.now(), settings.window_s)

        def rest_accel():
            recent = [accel for t_s, accel in self._check_accel if t_s >= self.clock.now() - settings.window_s]
            return np.mean(recent, axis=0) if recent else None

        try:
            results = await run_setup_checks(hold, rest_accel, self._predicted_bending, request.profile, settings)
        finally:
            self._check_recorder = self._check_accel = None
        self.checks = tuple(results)
        for result in results:
            self._log.write(SetupCheck(t_s=self.clock.now(), check=result.check, status=result.status,
                                       message=result.message, values=result.values))
            level = {"pass": "info", "fail": "error"}.get(result.status, "warning")
            self.event(level, "setup check", result.message)
        failed = next((result for result in results if result.failed), None)
        if failed is not None:
            raise UserError(f"{failed.message} (skip with --skip-checks)")

    async def _command(self, valves: ValveController, forces) -> None:
        t_s = self.clock.now()
        self._log.write(ValveCommand(t_s=t_s, command="SET_ALL", duties_permille=None, jet_forces_n=floats(forces)))
        try:
            duties = await valves.set_forces_n(forces)
        except ValveError as error:
            t_s = self.clock.now()
            self._log.write(ValveReply(t_s=t_s, command="SET_ALL", ok=False, code=type(error).__name__,
                                       detail=str(error)))
            raise SessionAborted(f"valve controller refused or did not answer: {error}") from error
        t_s = self.clock.now()
        self.status.valve_commands += 1
        self.status.valve_retries = valves.timeouts
        self._log.write(ValveReply(t_s=t_s, command="SET_ALL", ok=True, code=None,
                                   detail=f"duties {list(duties)} per mille"))

    async def _settle(self, index: int, step: PlanStep, end_s: float, window_s: float) -> None:
        settled = self.em.settled(end_s, window_s)
        if settled is None:
            self.event("warning", "plan", f"step {index}: no EM sample in its last {window_s:g} s; not estimated")
            return
        self.settled_rows.append(settled)
        positions = settled.tip_position_in_base_m()
        self._log.write(Step(
            t_s=end_s, index=index, count=len(self.request.plan), sweep=step.sweep, step=step.step,
            jet_forces_n=floats(settled.jet_forces_n[0]), samples=self.em.sample_count,
            tip_in_base_measured=floats(settled.tip_orientation_in_base()[0]),
            tip_position_in_base_m=None if positions is None else floats(positions[0]),
            time_s=float(settled.time_s[0]),
            base_orientation=floats(settled.base_orientation[0]),
            tip_orientation=floats(settled.tip_orientation[0]),
            base_position_m=None if positions is None else floats(settled.base_position_m[0]),
            tip_position_m=None if positions is None else floats(settled.tip_position_m[0]),
            flags=int(settled.flags[0]),
        ))
        if step.sweep == CALIBRATION_SWEEP and self.request.calibrate:
            self._calibration_rows.append(settled)
        self._to_estimate.put_nowait((index, settled, end_s))

    async def _estimate_steps(self) -> None:
        """Estimate each settled step, in plan order, beside the plan: the next step is
        commanded when this one's settle time ends, not after its solves (which held
        every step ~0.24 s of session time longer than planned at x25)."""
        while True:
            index, settled, t_s = await self._to_estimate.get()
            try:
                await self._estimate(index, settled, t_s)
            finally:
                self._to_estimate.task_done()

    async def _estimate(self, index: int, settled: Dataset, t_s: float) -> None:
        if self.estimation is None:
            online = self.request.settings.estimator.online_settings() if self.request.settings.estimator.online else None
            predictor = PathPredictor(self.request.model, self.params, online)
            # A restarted estimator (after the calibration) goes through the rows settled
            # before this one first, as `replay` and `compare` do on the log.
            before = list(itertools.takewhile(lambda row: row is not settled, self.settled_rows))
            if before:
                await asyncio.to_thread(predictor.carry, Dataset.concatenate(before))
            self.estimation = predictor
        try:
            # In a worker thread: a slow solve must never delay the valve heartbeat.
            (estimate,) = await asyncio.to_thread(self.estimation.predict, settled)
        except ConvergenceError as error:
            self.event("warning", "model", f"step {index}: model did not converge ({error})")
            return
        self.estimates.append(estimate)
        log = self._log
        for prediction in (estimate.ref, estimate.online):
            if prediction is None:
                continue
            log.write(ModelPrediction(
                t_s=t_s, index=index, method=prediction.method,
                tip_in_base=floats(prediction.tip_orientation_in_base),
                tip_position_in_base_m=floats(prediction.tip_position_in_base_m), bend_deg=prediction.bend_deg,
                orientation_error_deg=prediction.orientation_error_deg,
                position_error_mm=prediction.position_error_mm))
        best = estimate.best
        if estimate.online is not None:
            moment = estimate.online.disturbance_moment_nm
            log.write(Disturbance(
                t_s=t_s, index=index, force_n=floats(estimate.disturbance_force_n), moment_nm=floats(moment),
                moment_norm_nm=float(np.linalg.norm(moment)),
                orientation_error_deg_before=estimate.error_before_deg,
                orientation_error_deg_after=estimate.online.orientation_error_deg,
                iterations=estimate.iterations))
            self.status.disturbance_norm_nm = float(np.linalg.norm(moment))
            self.status.online_error_deg = estimate.online.orientation_error_deg
        self.status.ref_error_deg = estimate.ref.orientation_error_deg
        self.status.errors_step_index = index
        log.write_transform(t_s, parent="base", child="tip_model",
                            rotation=quat_from_matrix(best.solution.tip_rotation_in_base),
                            translation_m=best.solution.tip_position_in_base_m)
        measured_positions = settled.tip_position_in_base_m()
        if measured_positions is not None:
            log.write_transform(t_s, parent="base", child="tip_measured",
                                rotation=settled.tip_orientation_in_base()[0], translation_m=measured_positions[0])
        log.write_backbone(t_s, positions_in_base_m=best.solution.positions_in_base_m, frame="base")

    async def _finish_calibration(self) -> None:
        if not self._calibration_rows or self.calibration is not None:
            return
        # The calibration poses' own estimates first, on the starting parameters.
        await self._to_estimate.join()
        rows = Dataset.concatenate(self._calibration_rows)
        self._calibration_rows = []
        self.status.phase = "calibrating"
        self.on_update(self.status)
        request = self.request
        self.event("info", "calibration", f"calibrating {len(request.calibration_names)} parameters on {len(rows)} poses")
        try:
            result = await asyncio.to_thread(calibrate_dataset, request.model, rows, self.params,
                                             request.calibration_names)
        except (ConvergenceError, ValueError) as error:
            self.calibration_failure = str(error)
            self.event("error", "calibration", f"failed, keeping the starting parameters: {error}")
            return
        self.calibration = result
        self.params = result.params
        self.estimation = None  # restart estimation from the calibrated parameters
        self.event("info", "calibration", f"RMS orientation error {result.rms_orientation_deg_before:.2f} deg "
                   f"-> {result.rms_orientation_deg_after:.2f} deg")
        self.calibration_warnings = tuple(calibration_warnings(request.model, result))
        for warning in self.calibration_warnings:
            self.event("warning", "calibration", warning)
        self._write_parameters()

    def _write_parameters(self) -> None:
        t_s = self.clock.now()
        calibration = self.calibration
        values = {name: get_parameter(self.params, name) for name in PARAMETER_NAMES}
        # Every parameter of every effect the model has, defaults included, so replay
        # rebuilds exactly the parameters the live estimator used.
        values.update({f"{effect.name}.{name}": value for effect in self.request.model.effects
                       for name, value in effect_values(effect, self.params).items()})
        self._log.write(Parameters(
            t_s=t_s, model=self.request.model.name, effects=tuple(self.request.effects),
            parameters=values,
            calibrated=calibration is not None,
            rms_orientation_deg_before=None if calibration is None else calibration.rms_orientation_deg_before,
            rms_orientation_deg_after=None if calibration is None else calibration.rms_orientation_deg_after,
        ))
