"""The session log's topics: one record type per topic, and the table `TOPICS`.

Frames: "tracker frame" is the EM field generator's; a sensor frame is the sensor's own;
"base frame" is the base sensor's; an IMU filter's orientation is in its own earth frame (z up, x to magnetic north).
Lengths in m, forces in N, moments in N m, angles in deg where a name says ``_deg``.
A field typed ``... | None`` is null when not measured or not a finite number (JSON
cannot carry NaN). Fields with a default may be absent from logs of earlier versions.

The JSON schemas written into a log are generated from these types
(`hydrojet_bench.logs.schemas`); `/tf` and `/scene/backbone` carry Foxglove's own
messages (`hydrojet_bench.logs.foxglove`).
"""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from msgspec import Meta, Struct

from .foxglove import FrameTransform, SceneUpdate
from .log_record import WXYZ, Float3, LogRecord

JetForces = Annotated[Float3, Meta(description="jet forces q1, q2, q3, N")]
Sweep = Annotated[int, Meta(ge=-1, description="-1 for calibration poses, else the validation sweep")]
StepIndex = Annotated[int, Meta(ge=0, description="step index in the plan")]


class Sample(LogRecord, kw_only=True):
    """One row of the CSV contract (hydrojet_bench/data/csv_io.py): commanded forces and
    the raw sensor poses, tracker frame."""

    topic: ClassVar[str] = "/bench/sample"
    source: Annotated[Literal["em", "imu"], Meta(description="which sensors measured the poses")]
    jet_forces_n: JetForces
    sweep: Sweep
    step: Annotated[int, Meta(description="quasistatic step")]
    base_orientation: Annotated[WXYZ, Meta(description="base sensor orientation (w, x, y, z), tracker frame")]
    tip_orientation: Annotated[WXYZ, Meta(description="tip sensor orientation (w, x, y, z), tracker frame")]
    base_position_m: Annotated[Float3 | None, Meta(description="base sensor position, tracker frame, m")]
    tip_position_m: Annotated[Float3 | None, Meta(description="tip sensor position, tracker frame, m")]
    flags: Annotated[int, Meta(ge=0, description="SampleFlag bits (sensor missing, out of volume); SATURATED "
                                                 "is recomputed from the profile on reading, as for CSV")] = 0


class ImuRaw(LogRecord, kw_only=True):
    """One ICM-20948 reading, sensor frame."""

    topic: ClassVar[str] = "/imu/raw"
    sensor: Annotated[Literal["base", "tip"], Meta(description="which IMU")]
    address: Annotated[int, Meta(description="I2C address")]
    accel_m_s2: Annotated[Float3, Meta(description="acceleration, sensor frame, m/s^2")]
    gyro_rad_s: Annotated[Float3, Meta(description="angular rate, sensor frame, rad/s")]
    mag_ut: Annotated[Float3 | None, Meta(description="magnetic field, sensor frame, uT")]
    temperature_c: Annotated[float | None, Meta(description="die temperature, deg C")]


class ImuOrientation(LogRecord, kw_only=True):
    """The orientation filter's output."""

    topic: ClassVar[str] = "/imu/orientation"
    base: Annotated[WXYZ, Meta(description="base IMU orientation (w, x, y, z), the filter's earth frame")]
    tip: Annotated[WXYZ, Meta(description="tip IMU orientation (w, x, y, z), the filter's earth frame")]
    tip_in_base: Annotated[WXYZ, Meta(description="tip IMU orientation (w, x, y, z) in the base IMU frame")]


class EmTool(Struct, frozen=True, kw_only=True):
    """One tracked sensor of an EM frame, tracker frame."""

    name: Annotated[str, Meta(description="sensor name, e.g. base or tip")]
    handle: Annotated[int, Meta(description="port handle")]
    status: Annotated[str, Meta(description='"ok", "missing", "out_of_volume", "disabled", ...')]
    orientation: Annotated[WXYZ | None, Meta(description="sensor orientation (w, x, y, z), tracker frame")]
    position_m: Annotated[Float3 | None, Meta(description="sensor position, tracker frame, m")]
    rms_error_mm: Annotated[float | None, Meta(description="tracker's RMS fit error, mm")]


class EmFrame(LogRecord, kw_only=True):
    """One NDI Aurora frame."""

    topic: ClassVar[str] = "/em/frame"
    frame_number: Annotated[int, Meta(description="tracker frame counter")]
    system_status: Annotated[str, Meta(description="system status word, as the tracker reports it")]
    tools: Annotated[tuple[EmTool, ...], Meta(description="the sensors of this frame")]


class ValveCommand(LogRecord, kw_only=True):
    """A command sent to the valve controller."""

    topic: ClassVar[str] = "/valves/command"
    command: Annotated[str, Meta(description="the command")]
    duties_permille: Annotated[
        Annotated[tuple[Annotated[float, Meta(ge=0, le=1000)], ...], Meta(min_length=3, max_length=3)] | None,
        Meta(description="valve duty cycles, permille")]
    jet_forces_n: Annotated[Float3 | None, Meta(description="jet forces q1, q2, q3, N")]


class ValveReply(LogRecord, kw_only=True):
    """The valve controller's answer."""

    topic: ClassVar[str] = "/valves/reply"
    command: Annotated[str, Meta(description="the command answered")]
    ok: Annotated[bool, Meta(description="accepted")]
    code: Annotated[str | None, Meta(description="error code")]
    detail: Annotated[str | None, Meta(description="error detail")]


class Step(LogRecord, kw_only=True):
    """A finished quasistatic step, averaged over the end of its hold (one row of
    `Dataset.quasistatic_steps`)."""

    topic: ClassVar[str] = "/bench/step"
    index: StepIndex
    count: Annotated[int, Meta(ge=0, description="steps in the plan")]
    sweep: Sweep
    step: Annotated[int, Meta(description="step label")]
    jet_forces_n: JetForces
    samples: Annotated[int, Meta(ge=0, description="samples averaged")]
    tip_in_base_measured: Annotated[WXYZ, Meta(description="measured tip orientation (w, x, y, z), base frame")]
    tip_position_in_base_m: Annotated[Float3 | None, Meta(description="measured tip position in the base frame, m")]
    time_s: Annotated[float | None, Meta(description="time of the last sample averaged, s")] = None
    base_orientation: Annotated[WXYZ | None, Meta(description="averaged base sensor orientation (w, x, y, z), "
                                                              "tracker frame")] = None
    tip_orientation: Annotated[WXYZ | None, Meta(description="averaged tip sensor orientation (w, x, y, z), "
                                                             "tracker frame")] = None
    base_position_m: Annotated[Float3 | None, Meta(description="averaged base sensor position, tracker frame, "
                                                               "m")] = None
    tip_position_m: Annotated[Float3 | None, Meta(description="averaged tip sensor position, tracker frame, m")] = None
    flags: Annotated[int, Meta(ge=0, description="SampleFlag bits of the averaged row (16: the tip still turned "
                                                 "within the averaging window)")] = 0


class ModelPrediction(LogRecord, kw_only=True):
    """The model's tip for a step, base frame."""

    topic: ClassVar[str] = "/model/prediction"
    index: StepIndex
    method: Annotated[Literal["ref", "online"], Meta(
        description='"ref" (calibrated, constant disturbance) or "online" (eq. 4)')] = "ref"
    tip_in_base: Annotated[WXYZ, Meta(description="predicted tip orientation (w, x, y, z), base frame")]
    tip_position_in_base_m: Annotated[Float3, Meta(description="predicted tip position in the base frame, m")]
    bend_deg: Annotated[float, Meta(description="bending angle, deg")]
    orientation_error_deg: Annotated[float, Meta(description="angle between predicted and measured tip "
                                                             "orientation, deg")]
    position_error_mm: Annotated[float | None, Meta(description="distance between predicted and measured tip, mm")]


class Disturbance(LogRecord, kw_only=True):
    """The online disturbance estimate (eq. 4), tip frame."""

    topic: ClassVar[str] = "/estimate/disturbance"
    index: StepIndex
    force_n: Annotated[Float3, Meta(description="disturbance force, tip frame, N")]
    moment_nm: Annotated[Float3, Meta(description="disturbance moment, tip frame, N m")]
    moment_norm_nm: Annotated[float, Meta(description="norm of the moment, N m")]
    orientation_error_deg_before: Annotated[float, Meta(description="orientation error before the update, deg")]
    orientation_error_deg_after: Annotated[float, Meta(description="orientation error after the update, deg")]
    iterations: Annotated[int, Meta(ge=0, description="updates applied")]


class Parameters(LogRecord, kw_only=True):
    """The model parameters in use."""

    topic: ClassVar[str] = "/bench/parameters"
    model: Annotated[str, Meta(description="model name")]
    effects: Annotated[tuple[str, ...], Meta(description="effects enabled")]
    parameters: Annotated[dict[str, float], Meta(
        description="parameter name (E0, EL, L, w_d components, effect.parameter) -> value, SI units")]
    calibrated: Annotated[bool, Meta(description="the values come from a calibration")]
    rms_orientation_deg_before: Annotated[float | None, Meta(description="calibration RMS orientation error "
                                                                         "before, deg")]
    rms_orientation_deg_after: Annotated[float | None, Meta(description="calibration RMS orientation error "
                                                                        "after, deg")]


class Event(LogRecord, kw_only=True):
    """Something worth a line in the session's story."""

    topic: ClassVar[str] = "/events"
    level: Annotated[Literal["info", "warning", "error"], Meta(description="severity")]
    source: Annotated[str, Meta(description="which part of the bench")]
    message: Annotated[str, Meta(description="what happened")]


class StreamRate(LogRecord, kw_only=True):
    """The rate a device stream delivered over ``interval_s`` of session time up to
    ``t_s`` (one plan step, or the whole session when ``whole_session``)."""

    topic: ClassVar[str] = "/bench/stream_rate"
    stream: Annotated[Literal["em", "imu"], Meta(description="which device stream")]
    configured_hz: Annotated[float, Meta(ge=0, description="the rate the stream is set to, Hz of session time")]
    delivered_hz: Annotated[float, Meta(ge=0, description="samples delivered per second of session time, Hz")]
    samples: Annotated[int, Meta(ge=0, description="samples delivered in the interval")]
    interval_s: Annotated[float, Meta(ge=0, description="session time the figure covers, s")]
    whole_session: Annotated[bool, Meta(description="true for the session's closing figure")]


class SetupCheck(LogRecord, kw_only=True):
    """A check run before the protocol (`bench.checks`): the wiring or the level."""

    topic: ClassVar[str] = "/bench/setup_check"
    check: Annotated[Literal["wiring", "level"], Meta(description="which check")]
    status: Annotated[Literal["pass", "fail", "warn", "skipped", "unavailable"], Meta(
        description='"fail" stopped the session; "skipped" by the --skip-checks flag; "unavailable" without the '
                    'sensors it needs')]
    message: Annotated[str, Meta(description="the line shown to the user")]
    values: Annotated[dict[str, float], Meta(description="the figures behind it (bends deg, cosines, gravity "
                                                         "vectors m/s^2, angle deg)")] = {}


TOPICS: dict[str, type[LogRecord]] = {record.topic: record for record in (
    Sample, ImuRaw, ImuOrientation, EmFrame, ValveCommand, ValveReply, Step, ModelPrediction, Disturbance,
    Parameters, Event, StreamRate, FrameTransform, SceneUpdate, SetupCheck)}
