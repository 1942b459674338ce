"""Benchmark of the fusion filters on the emulator, scored against the plant's truth.

    python -m drivers.imu.fusion_benchmark [--filters madgwick imufusion] [--json]

Each scenario drives one emulated ICM-20948 (our driver, divider 10: 102.3 Hz, DLPF 3,
gyro bias estimated at rest first, as the bench does) through a trajectory of the base
sensor, on a virtual clock. Every filter sees the same samples, from the end of the bias
estimate on (still at rest: each filter seeds itself from gravity and the field). Scores,
from the end of the rest: RMS and max of the total, tilt and heading errors (degrees)
against the plant's orientation, and the filter's cost per update (median microseconds,
this machine).

A disturbance scenario is also run without its disturbance, on the same samples'
noise: the largest difference in tilt error between the two runs is what the
disturbance leaked into tilt ("tilt_leak_deg").
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from drivers.imu.calibration import ImuSample
from drivers.imu.driver import Icm20948
from drivers.imu.emulator import Icm20948BusEmulator
from drivers.imu.fusion import FUSION_NAMES, ImuOrientationFilter
from drivers.plant import SensorTruth
from drivers.rotations import matrix_from_quat, quat_conjugate, quat_from_rotvec, quat_multiply

FIELD_IN_TRACKER_UT = np.array([20.0, 0.0, -45.0])
GRAVITY_IN_TRACKER_M_S2 = np.array([0.0, 0.0, -9.81])
# 15 uT across the horizontal field (20 uT): turns the field's heading by 37 degrees.
DISTURBANCE_UT = (0.0, 15.0, 0.0)
REST_S = 2.5  # at rest first: the driver's gyro-bias estimate, then the filter's seed


@dataclass(frozen=True)
class Scenario:
    """peak_rate_dps: peak body rate of the rotation (three incommensurate sinusoids);
    shake_m_s2: amplitude of a 6 Hz linear acceleration; disturbance: (start, end) s
    after the rest during which DISTURBANCE_UT is added at the sensor."""

    name: str
    duration_s: float
    peak_rate_dps: float
    shake_m_s2: float = 0.0
    disturbance: tuple[float, float] | None = None


SCENARIOS = (
    Scenario("motion to 110 dps", 20.0, 110.0),
    Scenario("3 s 15 uT disturbance", 20.0, 20.0, disturbance=(5.0, 8.0)),
    Scenario("15 s 15 uT disturbance", 30.0, 20.0, disturbance=(5.0, 20.0)),
    Scenario("shaking 0.4 g at 6 Hz", 20.0, 30.0, shake_m_s2=4.0),
)

# Rotation angle (rad) per axis = a_k * (1 - cos(w_k t)): rate a_k w_k sin(w_k t); the
# three frequencies (rad/s) are incommensurate so the axes combine in every direction.
_FREQUENCIES = np.array([1.3, 2.1, 0.7])
_SHAKE_RAD_S = 2 * math.pi * 6.0


class ScenarioPlant:
    """The base sensor on a scenario's trajectory (the tip is not used here)."""

    gravity_in_tracker_m_s2 = GRAVITY_IN_TRACKER_M_S2
    magnetic_field_in_tracker_ut = FIELD_IN_TRACKER_UT

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        # peak per-axis rate a_k w_k; the sum of squares of the three equals the peak
        self._amplitudes = math.radians(scenario.peak_rate_dps) / math.sqrt(3) / _FREQUENCIES

    def orientation(self, t_s: float) -> np.ndarray:
        moving = max(0.0, t_s - REST_S)
        angles = self._amplitudes * (1.0 - np.cos(_FREQUENCIES * moving))
        # about tracker z, then y, then x (body): a yaw-pitch-roll sequence
        q = quat_from_rotvec([0.0, 0.0, angles[2]])
        q = quat_multiply(q, quat_from_rotvec([0.0, angles[1], 0.0]))
        return quat_multiply(q, quat_from_rotvec([angles[0], 0.0, 0.0]))

    def sensor_truth(self, sensor: str, t_s: float) -> SensorTruth:
        h = 1e-5
        before, after = self.orientation(t_s - h), self.orientation(t_s + h)
        delta = quat_multiply(quat_conjugate(before), after)  # body frame
        rate = 2.0 * np.asarray(delta[1:]) * math.copysign(1.0, delta[0]) / (2 * h)
        moving = t_s > REST_S
        shake = self.scenario.shake_m_s2 * math.sin(_SHAKE_RAD_S * (t_s - REST_S)) if moving else 0.0
        acceleration = np.array([shake, 0.5 * shake, 0.0])
        return SensorTruth(self.orientation(t_s), np.zeros(3), rate, acceleration)

    def apply_valve_duties(self, duties_permille: Sequence[int], t_s: float) -> None:
        """No valves on this bus."""


class _Clock:
    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s

    def sleep(self, duration_s: float) -> None:
        self.now_s += duration_s


def record(scenario: Scenario, *, disturbed: bool = True, seed: int = 0) -> tuple[list[ImuSample], list[np.ndarray]]:
    """The driver's samples over the scenario and the plant's orientation at each."""
    clock = _Clock()
    plant = ScenarioPlant(scenario)
    emulator = Icm20948BusEmulator(plant, clock, sensors={0x68: "base"}, seed=seed)  # type: ignore[arg-type]
    imu = Icm20948(emulator, 0x68, clock=clock, sleep=clock.sleep)
    imu.initialize()
    imu.estimate_gyro_bias(round(1.5 * imu.sample_rate_hz))
    samples, truth = [], []
    end = REST_S + scenario.duration_s
    while clock.now_s < end:
        clock.sleep(imu.sample_period_s)
        t_plant = clock.now_s - REST_S
        window = scenario.disturbance
        on = disturbed and window is not None and window[0] <= t_plant < window[1]
        emulator.set_magnetic_disturbance("base", DISTURBANCE_UT if on else (0.0, 0.0, 0.0))
        sample = imu.read_sample()
        samples.append(sample)
        # the chip latched its sample on the grid at or before now: that instant's truth
        truth.append(plant.orientation(sample.t_s))
    return samples, truth


def errors_deg(estimate: np.ndarray, truth: np.ndarray) -> tuple[float, float, float]:
    """(total, tilt, heading) error in degrees. Tilt: angle between the estimated and the
    true 'up' seen in the sensor frame; heading: the rest, about the vertical."""
    error = quat_multiply(quat_conjugate(truth), estimate)
    total = math.degrees(2.0 * math.acos(min(1.0, abs(float(error[0])))))
    up_true = matrix_from_quat(truth).T[:, 2]
    up_est = matrix_from_quat(estimate).T[:, 2]
    tilt = math.degrees(math.acos(float(np.clip(np.dot(up_true, up_est), -1.0, 1.0))))
    true_north = matrix_from_quat(truth)[:, 0]
    est_north = matrix_from_quat(estimate)[:, 0]
    heading = abs(math.degrees(math.atan2(true_north[0] * est_north[1] - true_north[1] * est_north[0],
                                          true_north[0] * est_north[0] + true_north[1] * est_north[1])))
    return total, tilt, heading


@dataclass(frozen=True)
class Score:
    scenario: str
    fusion: str
    total_rms_deg: float
    total_max_deg: float
    tilt_rms_deg: float
    tilt_max_deg: float
    heading_rms_deg: float
    heading_max_deg: float
    tilt_leak_deg: float | None
    update_us: float


def _run_filter(fusion: str, samples: list[ImuSample], rate_hz: float) -> tuple[list[np.ndarray], float]:
    filter_ = ImuOrientationFilter(rate_hz, fusion=fusion)  # type: ignore[arg-type]
    estimates, costs = [], []
    for sample in samples:
        start = time.perf_counter()
        estimates.append(filter_.update(sample))
        costs.append(time.perf_counter() - start)
    return estimates, statistics.median(costs[1:]) * 1e6


def score(scenario: Scenario, fusions: Sequence[str] = FUSION_NAMES, seed: int = 0) -> list[Score]:
    samples, truth = record(scenario, seed=seed)
    clean = record(scenario, disturbed=False, seed=seed) if scenario.disturbance else None
    rate_hz = 1.0 / statistics.median(np.diff([s.t_s for s in samples]))
    first = next(i for i, sample in enumerate(samples) if sample.t_s >= REST_S)
    out = []
    for fusion in fusions:
        estimates, update_us = _run_filter(fusion, samples, rate_hz)
        errors = np.array([errors_deg(e, t) for e, t in zip(estimates, truth)])[first:]
        leak = None
        if clean is not None:
            clean_estimates, _ = _run_filter(fusion, clean[0], rate_hz)
            clean_tilt = np.array([errors_deg(e, t)[1] for e, t in zip(clean_estimates, clean[1])])[first:]
            leak = float(np.max(np.abs(errors[:, 1] - clean_tilt)))
        rms = np.sqrt(np.mean(errors**2, axis=0))
        peak = np.max(errors, axis=0)
        out.append(Score(scenario.name, fusion, *(round(float(v), 2) for v in (
            rms[0], peak[0], rms[1], peak[1], rms[2], peak[2])),
            None if leak is None else round(leak, 2), round(update_us, 1)))
    return out


def markdown(scores: Sequence[Score]) -> str:
    lines = ["| scenario | fusion | total RMS / max (deg) | tilt RMS / max (deg) | heading RMS / max (deg) "
             "| tilt leak (deg) | update (us) |", "|---|---|---|---|---|---|---|"]
    for s in scores:
        leak = "-" if s.tilt_leak_deg is None else f"{s.tilt_leak_deg:.2f}"
        lines.append(f"| {s.scenario} | {s.fusion} | {s.total_rms_deg:.2f} / {s.total_max_deg:.2f} "
                     f"| {s.tilt_rms_deg:.2f} / {s.tilt_max_deg:.2f} | {s.heading_rms_deg:.2f} / "
                     f"{s.heading_max_deg:.2f} | {leak} | {s.update_us:.1f} |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m drivers.imu.fusion_benchmark", description=__doc__.splitlines()[0])
    parser.add_argument("--filters", nargs="+", choices=FUSION_NAMES, default=list(FUSION_NAMES))
    parser.add_argument("--json", action="store_true", help="print the scores as JSON instead of a table")
    args = parser.parse_args(argv)
    scores = [s for scenario in SCENARIOS for s in score(scenario, args.filters)]
    print(json.dumps([asdict(s) for s in scores], indent=2) if args.json else markdown(scores))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
