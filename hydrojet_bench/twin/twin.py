"""The digital twin: a simulated HydroJet that the bench, the emulators and the tests use.

Physics: the Cosserat rod at the twin's own *true* parameters, with gravity and any hidden
effects (`TwinConfig`), solved by the twin's own `CosseratModel` instance. Nothing is
shared with a model under evaluation: the twin builds its own parameters object and
model, so a calibration or an online estimator cannot change (or read) the truth except
through the measurements.

Motion is quasistatic. When the commanded jet forces change at time t_c, the twin solves
the new equilibrium once (warm-started from the previous one, which also carries any
path-dependent clamp state) and each sensor's pose then relaxes towards its new
equilibrium pose with a first-order settling law:

    R(t) = R_eq exp(e(t) phi),   p(t) = p_eq + e(t) (p_c - p_eq),   e(t) = exp(-(t - t_c) / tau)

where (R_c, p_c) is the sensor's pose at t_c (possibly still settling from the previous
command) and phi = log(R_eq^T R_c) (a slerp along the shortest arc). This is a
*kinematic* settling model, not dynamics: no inertia, no overshoot, no damping of the
water jets; it only makes samples taken soon after a command differ from the equilibrium,
as on the rig, where the paper holds each command 5 s, longer than the settling time. Its
angular velocity, d/dt e * phi in the sensor frame, and acceleration, e/tau^2 (p_c - p_eq),
are exact derivatives of that law and are what `sensor_truth` reports to IMU emulators.

Sensors. Truth (`sensor_truth`, `sensor_poses`) is exact; `measure_em` and `measure_imu`
add the twin's seeded noise (`SensorNoise`). The Aurora emulator adds its own noise to
`sensor_truth`, so a twin behind emulators is never noisy twice.

Setup errors (`TwinConfig.setup`, see `setup_errors`): the twin's jets receive the commanded
forces through the wiring permutation, its gravity is turned by the tracker tilt, and the
base sensor's mounting gains the unknown rotation; recordings keep the commanded forces.

A sensor's orientation in the tracker frame is R_base_pose R_body M_effect M_mount: the body frame
(clamp at s = 0 or rod tip at s = L) in the tracker frame, then the mounting rotation a hidden
effect may add (the `Solution`'s ``*_sensor_mounting``), then the rig's known mounting
(`TwinConfig.base_sensor`/`tip_sensor`). In that order the rig's known mountings cancel
exactly from a measured tip-relative-to-base rotation by conjugation, whatever the hidden
effects do. Sensor origins sit at ``offset_in_body_m`` in the body frame.
"""

from __future__ import annotations

import math
import threading
from bisect import bisect_right
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from drivers.plant import SensorTruth
from drivers.valve.protocol import DUTY_MAX_PERMILLE

from ..geometry import (matrix_from_quat, quat_conjugate, quat_from_matrix, quat_from_rotvec, quat_multiply,
                        quat_normalize, rotvec_from_quat)
from ..models import CosseratModel, Solution
from ..params import JET_COUNT, ModelParameters, with_parameters
from ..plans import Plan, PlanStep
from .config import TwinConfig
from .recording import TwinRecording
from .settling import settling_state, settling_states_into

SENSORS = ("base", "tip")
SENSOR_CHOICES = ("em", "imu", "truth")
DEFAULT_SAMPLE_RATE_HZ = 40.0  # the Aurora's frame rate
# Command segments kept for queries about the past; a bench driving the valves for hours
# must not grow without bound. Queries older than the oldest kept segment raise.
DEFAULT_HISTORY_LIMIT = 4096


@dataclass(frozen=True)
class SensorMeasurement:
    """Poses of both sensors at ``time_s`` (scalar or (n,)), tracker frame.

    *_orientation: unit quaternions (w, x, y, z), sensor -> tracker, shape (..., 4).
    *_position_m: sensor origins, m, shape (..., 3); None for IMU measurements.
    """

    time_s: np.ndarray
    base_orientation: np.ndarray
    tip_orientation: np.ndarray
    base_position_m: np.ndarray | None
    tip_position_m: np.ndarray | None


@dataclass(frozen=True)
class _Segment:
    """The twin's motion from one command on: settling from ``start_*`` to ``target_*``.
    Arrays are indexed by sensor (0 base, 1 tip)."""

    start_s: float
    jet_forces_n: np.ndarray
    solution: Solution
    target_orientation: np.ndarray  # (2, 4) sensor -> tracker at equilibrium
    target_position_m: np.ndarray  # (2, 3)
    rotation_offset_rad: np.ndarray  # (2, 3) phi = log(R_eq^T R_start), sensor frame
    position_offset_m: np.ndarray  # (2, 3) p_start - p_eq


def _as_times(t_s: float | Sequence[float] | np.ndarray, name: str = "t_s") -> np.ndarray:
    times = np.asarray(t_s, dtype=float)
    if times.ndim > 1:
        raise ValueError(f"{name} must be a time or a 1-D array of times, got shape {times.shape}")
    if not np.all(np.isfinite(times)):
        raise ValueError(f"{name} must be finite, got {t_s!r}")
    return times


class DigitalTwin:
    """A simulated HydroJet; implements `drivers.plant.Plant`.

    Time is whatever clock drives it (seconds; virtual time for plans, the emulators'
    clock behind them); commands must come in non-decreasing time. Thread-safe: emulators
    call it from their own threads.

    Attributes: ``config``; ``true_params`` (the truth, hidden-effect values and gravity
    merged in); ``model`` (the twin's private `CosseratModel`); ``gravity_in_tracker_m_s2``
    and ``magnetic_field_in_tracker_ut`` (the `Plant` attributes).
    """

    def __init__(self, config: TwinConfig | None = None, history_limit: int = DEFAULT_HISTORY_LIMIT) -> None:
        self.config = config if config is not None else TwinConfig()
        if not isinstance(self.config, TwinConfig):
            raise ValueError(f"config must be a TwinConfig, got {type(self.config).__name__}")
        if isinstance(history_limit, bool) or not isinstance(history_limit, int) or history_limit < 2:
            raise ValueError(f"history_limit must be an integer >= 2, got {history_limit!r}")
        self._history_limit = history_limit
        cfg = self.config
        self._base_rotation = matrix_from_quat(cfg.base_orientation_in_tracker)
        self._base_position_m = np.array(cfg.base_position_in_tracker_m)
        params = cfg.true_params
        if cfg.gravity_in_tracker_m_s2 is not None:
            params = replace(params, gravity_in_base_m_s2=tuple(
                self._base_rotation.T @ np.array(cfg.gravity_in_tracker_m_s2)))
        if cfg.setup.tracker_tilt_deg != (0.0, 0.0):
            # A tilted field generator turns gravity as the tracker sees it; the clamp's
            # pose in the tracker frame is measured, so it stays.
            gravity_in_tracker = self._base_rotation @ np.array(params.gravity_in_base_m_s2)
            params = replace(params, gravity_in_base_m_s2=tuple(
                self._base_rotation.T @ cfg.setup.tilt_rotation() @ gravity_in_tracker))
        if cfg.hidden_effect_values:
            params = with_parameters(params, dict(cfg.hidden_effect_values))
        # A fresh object even when nothing changed: models cache packed problems by the
        # identity of their params, and the truth must never alias a caller's object.
        self.true_params: ModelParameters = replace(params)
        self.model = CosseratModel(effects=cfg.effects, resolution=cfg.resolution)
        self.gravity_in_tracker_m_s2 = self._base_rotation @ np.array(self.true_params.gravity_in_base_m_s2)
        self.magnetic_field_in_tracker_ut = np.array(cfg.magnetic_field_in_tracker_ut)
        base_mounting = cfg.setup.base_mounting_rotation() @ matrix_from_quat(cfg.base_sensor.rotation_in_body)
        self._mount_rotation = np.stack([base_mounting, matrix_from_quat(cfg.tip_sensor.rotation_in_body)])
        self._mount_offset_m = np.array([cfg.base_sensor.offset_in_body_m, cfg.tip_sensor.offset_in_body_m])
        self._tau_s = cfg.settle_time_constant_s
        self._responses = cfg.jet_responses
        em_seed, imu_seed = np.random.SeedSequence(cfg.seed).spawn(2)
        # Separate streams, so simulating IMUs does not change the EM noise and vice versa.
        self._em_rng = np.random.default_rng(em_seed)
        self._imu_rng = np.random.default_rng(imu_seed)
        self._imu_drift_rad = np.zeros((2, 3))
        self._imu_last_s: float | None = None
        self._lock = threading.RLock()
        self._plan_clock_s = 0.0
        rest = self.model.solve(np.zeros(JET_COUNT), self.true_params)
        orientation, position = self._equilibrium_poses(rest)
        # At rest since forever: the first segment starts at -inf with nothing to settle.
        self._segments: list[_Segment] = [_Segment(-math.inf, np.zeros(JET_COUNT), rest, orientation, position,
                                                   np.zeros((2, 3)), np.zeros((2, 3)))]
        self._starts: list[float] = [-math.inf]

    def __repr__(self) -> str:
        names = [e.name for e in self.config.hidden_effects]
        return f"DigitalTwin(hidden_effects={names}, seed={self.config.seed})"

    # --- commands -------------------------------------------------------------------

    @property
    def jet_forces_n(self) -> np.ndarray:
        """The jet forces (N) commanded last."""
        with self._lock:
            return self._segments[-1].jet_forces_n.copy()

    @property
    def last_command_s(self) -> float:
        """Time of the last command (-inf before the first)."""
        with self._lock:
            return self._segments[-1].start_s

    def command_jet_forces(self, jet_forces_n: Sequence[float], t_s: float) -> Solution:
        """Command the jet forces (q1, q2, q3), N (finite, >= 0: jets only push), from time
        ``t_s`` on; returns the new equilibrium (a `Solution` in the base frame). The rod
        settles towards it from wherever it is at ``t_s``."""
        forces = np.asarray(jet_forces_n, dtype=float)
        if forces.shape != (JET_COUNT,):
            raise ValueError(f"jet_forces_n must be {JET_COUNT} forces, got {jet_forces_n!r}")
        if not np.all(np.isfinite(forces)) or np.any(forces < 0.0):
            raise ValueError(f"jet_forces_n must be finite and >= 0 N (jets only push), got {jet_forces_n!r}")
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        with self._lock:
            last = self._segments[-1]
            if t < last.start_s:
                raise ValueError(f"t_s {t} s precedes the last command at {last.start_s} s; "
                                 "commands must come in time order")
            solution = self.model.solve(self.config.setup.physical_jet_forces_n(forces), self.true_params,
                                        previous=last.solution)
            orientation, position = self._equilibrium_poses(solution)
            start_orientation, start_position = self._poses_in_segment(last, np.array([t]))
            rotation_offset = rotvec_from_quat(quat_multiply(quat_conjugate(orientation), start_orientation[:, 0]))
            position_offset = start_position[:, 0] - position
            self._segments.append(_Segment(t, forces.copy(), solution, orientation, position,
                                           rotation_offset, position_offset))
            self._starts.append(t)
            if len(self._segments) > self._history_limit:
                del self._segments[0]
                del self._starts[0]
            return solution

    def duties_to_forces(self, duties_permille: Sequence[int]) -> np.ndarray:
        """Jet forces (N) the valves produce at these duties (per mille), through each
        jet's `JetResponse`."""
        duties = tuple(duties_permille)
        if len(duties) != JET_COUNT:
            raise ValueError(f"duties_permille must be {JET_COUNT} duties, got {duties_permille!r}")
        for duty in duties:
            if isinstance(duty, bool) or not isinstance(duty, (int, np.integer)) \
                    or not 0 <= duty <= DUTY_MAX_PERMILLE:
                raise ValueError(f"duties_permille must be integers in 0..{DUTY_MAX_PERMILLE}, "
                                 f"got {duties_permille!r}")
        return np.array([response.force_for_duty(duty) for response, duty in zip(self._responses, duties)])

    def apply_valve_duties(self, duties_permille: Sequence[int], t_s: float) -> None:
        """`Plant` hook: the valve emulator reports new duties (0..1000 per mille). Duties
        that produce the forces already commanded change nothing (no re-solve, no new
        settling)."""
        forces = self.duties_to_forces(duties_permille)
        with self._lock:
            if np.array_equal(forces, self._segments[-1].jet_forces_n):
                return
            self.command_jet_forces(forces, t_s)

    # --- truth ----------------------------------------------------------------------

    def equilibrium(self, t_s: float) -> Solution:
        """The equilibrium the rod is settling towards at ``t_s`` (base frame)."""
        with self._lock:
            return self._segment_at(float(t_s)).solution

    def sensor_poses(self, sensor: str, t_s: float | Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact orientation (w, x, y, z; sensor -> tracker) and position (m, tracker frame) of
        sensor ``"base"`` or ``"tip"`` at time(s) ``t_s``; vectorised over a 1-D array."""
        index = self._sensor_index(sensor)
        times = _as_times(t_s)
        orientation, position = self._poses(times.reshape(-1))
        return (orientation[index].reshape(times.shape + (4,)), position[index].reshape(times.shape + (3,)))

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        """`Plant` hook: exact state of sensor ``"base"`` or ``"tip"`` at ``t_s``, with the
        settling law's angular velocity (sensor frame) and linear acceleration (tracker frame)."""
        index = self._sensor_index(sensor)
        t = float(t_s)
        if not math.isfinite(t):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        with self._lock:
            segment = self._segment_at(t)
        decay = math.exp(-max(t - segment.start_s, 0.0) / self._tau_s) if self._tau_s > 0.0 else 0.0
        orientation, position, angular_velocity, acceleration = settling_state(
            segment.target_orientation, segment.rotation_offset_rad, segment.target_position_m,
            segment.position_offset_m, index, decay, self._tau_s)
        return SensorTruth(orientation, position, angular_velocity, acceleration)

    def sensor_truths(self, sensor: str, t_s: np.ndarray) -> SensorTruth:
        """`BatchPlant` hook: `sensor_truth` at each of ``t_s`` (1-D, s) at once, every
        field stacked over them ((n, 4) and (n, 3)); bit for bit the single-instant
        answers. An emulated IMU's FIFO asks a run of sample instants at each look."""
        index = self._sensor_index(sensor)
        times = np.asarray(t_s, dtype=float)
        # Checked on a list: numpy's isfinite and all cost more than the whole batch.
        instants = times.tolist()
        if times.ndim != 1 or not all(map(math.isfinite, instants)):
            raise ValueError(f"t_s must be a 1-D array of finite times, got {t_s!r}")
        count = len(instants)
        orientations, positions = np.empty((count, 4)), np.empty((count, 3))
        angular_velocities, accelerations = np.empty((count, 3)), np.empty((count, 3))
        tau_s = self._tau_s
        with self._lock:
            segments = list(map(self._segment_at, instants))
        start = 0
        while start < count:  # runs of instants in one segment: usually the whole batch
            segment = segments[start]
            stop = start + 1
            while stop < count and segments[stop] is segment:
                stop += 1
            # Each decay as `sensor_truth` computes it (math.exp, not np.exp: bit for bit).
            decays = np.array([math.exp(-max(t - segment.start_s, 0.0) / tau_s) if tau_s > 0.0 else 0.0
                               for t in instants[start:stop]])
            settling_states_into(segment.target_orientation, segment.rotation_offset_rad, segment.target_position_m,
                                 segment.position_offset_m, index, decays, tau_s, orientations[start:stop],
                                 positions[start:stop], angular_velocities[start:stop], accelerations[start:stop])
            start = stop
        return SensorTruth(orientations, positions, angular_velocities, accelerations)

    # --- measurements ---------------------------------------------------------------

    def measure_em(self, t_s: float | Sequence[float] | np.ndarray) -> SensorMeasurement:
        """EM tracker poses of both sensors at time(s) ``t_s`` (scalar or 1-D array): the
        truth plus white noise drawn from the twin's generator; the orientation error is a
        body-frame rotation (as the Aurora emulator's)."""
        times = _as_times(t_s)
        flat = times.reshape(-1)
        orientation, position = self._poses(flat)
        noise = self.config.noise
        position_sigma = noise.em_position_rms_m / math.sqrt(3.0)
        rotation_sigma = math.radians(noise.em_orientation_rms_deg) / math.sqrt(3.0)
        with self._lock:
            position_noise = self._em_rng.normal(0.0, 1.0, (2, flat.size, 3)) * position_sigma
            rotation_noise = self._em_rng.normal(0.0, 1.0, (2, flat.size, 3)) * rotation_sigma
        orientation = quat_normalize(quat_multiply(orientation, quat_from_rotvec(rotation_noise)))
        position = position + position_noise
        return SensorMeasurement(times.copy(), orientation[0].reshape(times.shape + (4,)),
                                 orientation[1].reshape(times.shape + (4,)),
                                 position[0].reshape(times.shape + (3,)), position[1].reshape(times.shape + (3,)))

    def measure_imu(self, t_s: float | Sequence[float] | np.ndarray) -> SensorMeasurement:
        """IMU-fused orientations of both sensors at time(s) ``t_s``, non-decreasing and not
        before the previous call's last time (the drift is a random walk in time):
        R_meas = exp(d(t)) R_true exp(n), d a per-IMU tracker-side random walk of the drift
        rotation vector, n white body-frame noise. No positions (IMUs give none)."""
        times = _as_times(t_s)
        flat = times.reshape(-1)
        if flat.size and np.any(np.diff(flat) < 0.0):
            raise ValueError("t_s must be non-decreasing for IMU measurements")
        noise = self.config.noise
        drift_sigma = math.radians(noise.imu_drift_deg_per_sqrt_s) / math.sqrt(3.0)
        white_sigma = math.radians(noise.imu_orientation_rms_deg) / math.sqrt(3.0)
        orientation, _ = self._poses(flat)
        with self._lock:
            if flat.size and self._imu_last_s is not None and flat[0] < self._imu_last_s:
                raise ValueError(f"t_s {flat[0]} s precedes the previous IMU measurement at {self._imu_last_s} s")
            previous = flat[0] if self._imu_last_s is None and flat.size else self._imu_last_s
            steps_s = np.diff(np.concatenate([[previous], flat])) if flat.size else flat
            increments = self._imu_rng.normal(0.0, 1.0, (2, flat.size, 3)) * (drift_sigma * np.sqrt(steps_s))[:, None]
            drift = self._imu_drift_rad[:, None, :] + np.cumsum(increments, axis=1)
            white = self._imu_rng.normal(0.0, 1.0, (2, flat.size, 3)) * white_sigma
            if flat.size:
                self._imu_drift_rad = drift[:, -1].copy()
                self._imu_last_s = float(flat[-1])
        measured = quat_normalize(quat_multiply(quat_multiply(quat_from_rotvec(drift), orientation),
                                                quat_from_rotvec(white)))
        return SensorMeasurement(times.copy(), measured[0].reshape(times.shape + (4,)),
                                 measured[1].reshape(times.shape + (4,)), None, None)

    # --- plans ----------------------------------------------------------------------

    @property
    def plan_clock_s(self) -> float:
        """When the next plan step will start (s): after the last step played, and never
        before the last command."""
        with self._lock:
            return max(self._plan_clock_s, self._segments[-1].start_s)

    def measure_step(self, step: PlanStep, sample_rate_hz: float = DEFAULT_SAMPLE_RATE_HZ,
                     record_window_s: float | None = None, sensors: str = "em") -> TwinRecording:
        """Play one plan step: command its forces at `plan_clock_s`, sample at
        ``sample_rate_hz`` for ``settle_s``, and advance the plan clock.

        record_window_s: keep only samples in the last ``record_window_s`` seconds of the
            step (the settled part); None keeps every sample.
        sensors: ``"em"`` (noisy poses with positions), ``"imu"`` (noisy, drifting
            orientations, no positions) or ``"truth"`` (exact poses).
        Samples fall at t0 + k / rate, strictly inside [t0, t0 + settle_s)."""
        if not isinstance(step, PlanStep):
            raise ValueError(f"step must be a PlanStep, got {type(step).__name__}")
        rate = _check_rate(sample_rate_hz)
        if record_window_s is not None and (not math.isfinite(record_window_s) or record_window_s <= 0):
            raise ValueError(f"record_window_s must be a finite time > 0 s or None, got {record_window_s!r}")
        if sensors not in SENSOR_CHOICES:
            raise ValueError(f"sensors must be one of {', '.join(SENSOR_CHOICES)}, got {sensors!r}")
        with self._lock:
            start_s = self.plan_clock_s
            self.command_jet_forces(step.jet_forces_n, start_s)
            # Tolerance: 5 s at 40 Hz is 200 samples, not 201 from rounding.
            count = max(1, math.ceil(step.settle_s * rate - 1e-9))
            times = start_s + np.arange(count) / rate
            if record_window_s is not None:
                times = times[times >= start_s + step.settle_s - record_window_s - 1e-12]
            self._plan_clock_s = start_s + step.settle_s
            if sensors == "em":
                sample = self.measure_em(times)
            elif sensors == "imu":
                sample = self.measure_imu(times)
            else:
                base_q, base_p = self.sensor_poses("base", times)
                tip_q, tip_p = self.sensor_poses("tip", times)
                sample = SensorMeasurement(times, base_q, tip_q, base_p, tip_p)
        n = times.size
        return TwinRecording(
            time_s=times,
            jet_forces_n=np.tile(np.array(step.jet_forces_n), (n, 1)),
            base_orientation=sample.base_orientation,
            tip_orientation=sample.tip_orientation,
            base_position_m=sample.base_position_m,
            tip_position_m=sample.tip_position_m,
            sweep=np.full(n, step.sweep, dtype=np.int64),
            step=np.full(n, step.step, dtype=np.int64),
            flags=np.zeros(n, dtype=np.uint32),
        )

    def run_plan(self, plan: Plan, sample_rate_hz: float = DEFAULT_SAMPLE_RATE_HZ,
                 record_window_s: float | None = None, sensors: str = "em") -> TwinRecording:
        """Play a whole plan in virtual time from `plan_clock_s` (see `measure_step`)."""
        if not isinstance(plan, Plan):
            raise ValueError(f"plan must be a Plan, got {type(plan).__name__}")
        if len(plan) == 0:
            raise ValueError("plan has no steps")
        with self._lock:
            parts = [self.measure_step(step, sample_rate_hz, record_window_s, sensors) for step in plan]
        return TwinRecording.concatenate(parts)

    # --- internals ------------------------------------------------------------------

    @staticmethod
    def _sensor_index(sensor: str) -> int:
        try:
            return SENSORS.index(sensor)
        except ValueError:
            raise KeyError(f"plant has no sensor {sensor!r}; known: {list(SENSORS)}") from None

    def _equilibrium_poses(self, solution: Solution) -> tuple[np.ndarray, np.ndarray]:
        """(2, 4) orientations and (2, 3) positions of the sensors on this equilibrium."""
        # The base sensor sits on the fixed holder (the base frame), not on the rod's first
        # section, which a compliant clamp turns.
        body_rotation = np.stack([np.eye(3), solution.rotations_in_base[-1]])
        body_position = np.stack([np.zeros(3), solution.positions_in_base_m[-1]])
        effect_mounting = np.stack([solution.base_sensor_mounting, solution.tip_sensor_mounting])
        rotation = self._base_rotation @ body_rotation @ effect_mounting @ self._mount_rotation
        position = self._base_position_m + (self._base_rotation @ (
            body_position + np.einsum("kij,kj->ki", body_rotation, self._mount_offset_m)).T).T
        return quat_from_matrix(rotation), position

    def _decay(self, elapsed_s: np.ndarray) -> np.ndarray:
        """e(t) of the settling law: 1 at the command, tending to 0."""
        if self._tau_s == 0.0:
            return np.zeros_like(elapsed_s)
        return np.exp(-np.maximum(elapsed_s, 0.0) / self._tau_s)

    def _segment_at(self, t_s: float) -> _Segment:
        index = bisect_right(self._starts, t_s) - 1
        if index < 0:
            raise ValueError(f"t_s {t_s} s precedes the twin's kept history (from {self._starts[0]} s)")
        return self._segments[index]

    def _poses_in_segment(self, segment: _Segment, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(2, n, 4) orientations and (2, n, 3) positions during one segment."""
        decay = self._decay(times - segment.start_s)
        rotation = quat_from_rotvec(decay[None, :, None] * segment.rotation_offset_rad[:, None, :])
        orientation = quat_normalize(quat_multiply(segment.target_orientation[:, None, :], rotation))
        position = segment.target_position_m[:, None, :] + decay[None, :, None] * segment.position_offset_m[:, None, :]
        return orientation, position

    def _poses(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exact (2, n, 4) orientations and (2, n, 3) positions at any times."""
        orientation = np.empty((2, times.size, 4))
        position = np.empty((2, times.size, 3))
        with self._lock:
            starts = np.array(self._starts)
            indices = np.searchsorted(starts, times, side="right") - 1
            if times.size and indices.min() < 0:
                raise ValueError(f"t_s {times.min()} s precedes the twin's kept history (from {starts[0]} s)")
            for index in np.unique(indices):
                rows = indices == index
                orientation[:, rows], position[:, rows] = self._poses_in_segment(self._segments[index], times[rows])
        return orientation, position


def _check_rate(sample_rate_hz: float) -> float:
    if isinstance(sample_rate_hz, bool) or not isinstance(sample_rate_hz, (int, float, np.integer, np.floating)):
        raise ValueError(f"sample_rate_hz must be a number, got {sample_rate_hz!r}")
    if not math.isfinite(sample_rate_hz) or sample_rate_hz <= 0:
        raise ValueError(f"sample_rate_hz must be a finite rate > 0 Hz, got {sample_rate_hz!r}")
    return float(sample_rate_hz)
