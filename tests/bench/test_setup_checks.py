"""The pre-protocol checks (`bench.checks`) against the digital twin directly: the wiring
check catches every miswiring and raises no false alarm on correctly wired rigs across
rods, rig tilts and noise; the level check sees a tilted field generator."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from hydrojet_bench.bench.checks import (CheckSettings, check_level, check_wiring, measured_bending_rad,
                                         predicted_bending_rad)
from hydrojet_bench.effects import load_effect
from hydrojet_bench.geometry import quat_from_rotvec, quat_multiply, quat_rotate
from hydrojet_bench.models import make_model
from hydrojet_bench.params import with_parameters
from hydrojet_bench.plans import PlanStep
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import HANGING_BASE_ORIENTATION, DigitalTwin, SensorNoise, SetupErrors, TwinConfig

SETTINGS = CheckSettings()
PROFILE = load_profile("sim")
MODEL = make_model("cosserat", (load_effect("gravity"),))
# Rig tilts: the clamp turned from hanging by up to 90 degrees (a horizontal rod).
TILTS_DEG = ((0.0, 0.0), (30.0, 0.0), (0.0, 60.0), (90.0, 0.0), (45.0, 45.0))
# True rods unlike the profile's nominal one: the check predicts with the nominal model.
RODS = ({}, {"E0": 0.7, "EL": 0.7}, {"E0": 1.3, "EL": 1.5}, {"L": 0.9})
NOISE = (SensorNoise.off(), SensorNoise(), SensorNoise(em_position_rms_m=1e-3, em_orientation_rms_deg=1.5))
WRONG_WIRINGS = [w for w in itertools.permutations((1, 2, 3)) if w != (1, 2, 3)]


def _base_orientation(tilt_deg: tuple[float, float]) -> tuple[float, ...]:
    turn = quat_from_rotvec(np.radians([tilt_deg[0], tilt_deg[1], 0.0]))
    return tuple(quat_multiply(turn, HANGING_BASE_ORIENTATION))


def _true_params(rod: dict[str, float]):
    nominal = PROFILE.model_parameters()
    scales = {"E0": nominal.rod.youngs_modulus_base_pa, "EL": nominal.rod.youngs_modulus_tip_pa,
              "L": nominal.rod.length_m}
    return with_parameters(nominal, {name: factor * scales[name] for name, factor in rod.items()})


def _check(tilt_deg, rod, noise, seed, wiring=(1, 2, 3), sign=1):
    """Play the wiring check on a twin, as the session does: rest, each jet alone."""
    twin = DigitalTwin(TwinConfig.from_profile(
        PROFILE, base_orientation_in_tracker=_base_orientation(tilt_deg), true_params=_true_params(rod),
        noise=noise, seed=seed, setup=SetupErrors(jet_wiring=wiring, jet_force_sign=sign)))
    commands = [(0.0, 0.0, 0.0)] + [tuple(SETTINGS.force_n * (jet == k) for k in range(3)) for jet in range(3)]
    settled = []
    for forces in commands:
        recording = twin.measure_step(PlanStep(forces, 0, 0, SETTINGS.settle_s), record_window_s=SETTINGS.window_s)
        settled.append(recording.to_dataset(PROFILE, "check").quasistatic_steps(window_s=None))
    params = PROFILE.model_parameters(settled[0].base_orientation[0])
    measured = measured_bending_rad(settled[0].tip_orientation_in_base()[0],
                                    np.array([s.tip_orientation_in_base()[0] for s in settled[1:]]))
    return check_wiring(measured, predicted_bending_rad(MODEL, params, SETTINGS.force_n), SETTINGS)


def test_no_false_alarm_in_100_correctly_wired_twins():
    cases = list(itertools.product(TILTS_DEG, RODS, NOISE))
    alarms = []
    for index in range(100):
        tilt, rod, noise = cases[index % len(cases)]
        result = _check(tilt, rod, noise, seed=index)
        if result.failed:
            alarms.append((tilt, rod, result.message))
    assert alarms == []


@pytest.mark.parametrize("wiring", WRONG_WIRINGS)
def test_every_miswiring_is_caught_and_named(wiring):
    for tilt, rod in zip(TILTS_DEG, RODS * 2):
        result = _check(tilt, rod, SensorNoise(), seed=1, wiring=wiring)
        assert result.failed
        swapped = [i + 1 for i, j in enumerate(wiring) if j != i + 1]
        if len(swapped) == 2:
            assert result.message.startswith(f"jets {swapped[0]} and {swapped[1]} appear swapped: tip moved towards "
                                             f"jet {swapped[1]}'s side when jet {swapped[0]} fired")
        else:
            assert result.message.startswith("jets wired one position round")
            assert f"jet 1 towards jet {wiring[0]}" in result.message


def test_reversed_jet_forces_are_named_not_taken_for_a_wiring():
    for seed, (tilt, rod) in enumerate(zip(TILTS_DEG, RODS * 2)):
        result = _check(tilt, rod, SensorNoise(), seed=seed, sign=-1)
        assert result.failed and result.message.startswith("every jet bent the tip the opposite way to the model's"), result


def test_a_dead_jet_is_named():
    measured = np.array([[0.1, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.1, 0.0]])
    result = check_wiring(measured, measured, SETTINGS)
    assert result.failed and result.message.startswith("jet 2 did not move the tip")


def test_level_check_warns_past_two_degrees_with_both_vectors():
    gravity = np.array([0.0, 0.0, 9.81])
    level = check_level(-gravity, gravity, SETTINGS)
    assert level.status == "pass"
    tilted = quat_from_rotvec(np.radians([3.0, 0.0, 0.0]))
    result = check_level(-quat_rotate(tilted, gravity), gravity, SETTINGS)
    assert result.status == "warn" and abs(result.values["angle_deg"] - 3.0) < 1e-6
    assert "base IMU gravity [0.0, -0.51, 9.8]" in result.message and "profile gravity" in result.message
