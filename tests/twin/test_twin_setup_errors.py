"""Setup errors the twin simulates: what each does to the measurements, and how
`simulate --hidden NAME=VALUES` reads them."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from hydrojet_bench.errors import UserError
from hydrojet_bench.geometry import rotation_angle_deg
from hydrojet_bench.plans import calibration_plan
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, SensorNoise, SetupErrors, TwinConfig, parse_setup_error

PROFILE = load_profile("sim")


def _twin(**setup) -> DigitalTwin:
    return DigitalTwin(TwinConfig.from_profile(PROFILE, noise=SensorNoise.off(), settle_time_constant_s=0.0,
                                               setup=SetupErrors(**setup)))


def test_a_swapped_pair_fires_the_other_jet():
    correct, swapped = _twin(), _twin(jet_wiring=(1, 3, 2))
    for jet, physical in ((0, 0), (1, 2), (2, 1)):
        forces = np.eye(3)[jet] * 0.03
        other = np.eye(3)[physical] * 0.03
        np.testing.assert_allclose(swapped.command_jet_forces(forces, 1.0 + jet).tip_rotation_in_base,
                                   correct.command_jet_forces(other, 1.0 + jet).tip_rotation_in_base, atol=1e-12)


def test_reversed_jets_pull_and_mis_scaled_jets_push_a_multiple_of_the_command():
    correct, reversed_, scaled = _twin(), _twin(jet_force_sign=-1), _twin(jet_force_scale=0.1)
    forces = np.array([0.03, 0.01, 0.0])
    pulled = reversed_.command_jet_forces(forces, 1.0)
    pushed = correct.command_jet_forces(forces, 1.0)
    lateral = pushed.tip_position_in_base_m[:2]
    assert np.linalg.norm(lateral) > 5e-3
    # Reversed: the tip swings to the other side by the same amount (hanging, gravity along the axis).
    np.testing.assert_allclose(pulled.tip_position_in_base_m[:2], -lateral, atol=1e-9)
    np.testing.assert_allclose(scaled.command_jet_forces(forces, 1.0).tip_position_in_base_m,
                               correct.command_jet_forces(0.1 * forces, 2.0).tip_position_in_base_m, atol=1e-12)
    # The recording keeps the commanded forces, as the rig's log would.
    recording = scaled.run_plan(calibration_plan(2, seed=0), record_window_s=0.1, sensors="truth")
    assert np.all(recording.jet_forces_n >= 0.0) and recording.jet_forces_n.max() > 0.01


def test_a_tilted_tracker_turns_gravity_and_a_turned_base_sensor_turns_its_reading():
    tilted = _twin(tracker_tilt_deg=(3.0, 4.0))
    angle = np.degrees(np.arccos(-tilted.gravity_in_tracker_m_s2[2] / np.linalg.norm(tilted.gravity_in_tracker_m_s2)))
    assert angle == pytest.approx(5.0, abs=0.01)  # 3 and 4 degrees about two axes: ~5 degrees
    base_q, _ = _twin().sensor_poses("base", 0.0)
    turned_q, _ = _twin(base_sensor_rotvec_rad=(0.0, 0.0, 0.2)).sensor_poses("base", 0.0)
    assert rotation_angle_deg(base_q, turned_q) == pytest.approx(np.degrees(0.2), abs=1e-9)


def test_setup_errors_parse_as_simulate_takes_them():
    errors = parse_setup_error("tracker_tilt_deg=2,-1", parse_setup_error("jet_wiring=2,3,1"))
    assert errors == SetupErrors(jet_wiring=(2, 3, 1), tracker_tilt_deg=(2.0, -1.0))
    assert parse_setup_error("jet_force_sign=-1") == SetupErrors(jet_force_sign=-1)
    assert parse_setup_error("jet_force_scale=0.00980665").jet_force_scale == 0.00980665
    for text, message in (("jet_wiring=1,1,2", "must be a permutation of 1, 2, 3"),
                          ("jet_force_sign=0.5", "takes integers"),
                          ("jet_force_sign=2", "must be 1 or -1"),
                          ("jet_force_scale=-0.1", "must be a finite number > 0"),
                          ("jet_force_scale=1,2", "takes one number, got 2"),
                          # Each at its identity describes the rig as the profile does.
                          ("jet_force_sign=1", "would hide nothing; give jet_force_sign another value"),
                          ("jet_force_scale=1", "would hide nothing; give jet_force_scale another value"),
                          ("jet_wiring=1,2,3", "would hide nothing; give jet_wiring another value"),
                          ("base_sensor_rotvec=0,0", "takes 3 comma-separated numbers, got 2"),
                          ("tracker_tilt_deg=a,b", "takes 2 comma-separated numbers"),
                          # Finite but past a rig set up wrongly: gravity or the readings turned nan, or the
                          # diagnosing models stopped solving.
                          ("tracker_tilt_deg=1e308,0", "tracker_tilt_deg must be angles from -45 to 45 degrees"),
                          ("tracker_tilt_deg=0,-90", "tracker_tilt_deg must be angles from -45 to 45 degrees"),
                          ("base_sensor_rotvec=1e308,0,0", "base_sensor_rotvec_rad must be 3 components from -0.8 "
                                                           "to 0.8 rad"),
                          ("base_sensor_rotvec=0,0,-3.14", "base_sensor_rotvec_rad must be 3 components"),
                          ("jet_force_scale=2", r"jet_force_scale must be from 0.001 .* to 1.5 "),
                          ("jet_force_scale=1e-4", "jet_force_scale must be from 0.001")):
        with pytest.raises(UserError, match=message):
            parse_setup_error(text)
    # The limits themselves are rigs set up wrongly.
    assert SetupErrors(tracker_tilt_deg=(45.0, -45.0)).tracker_tilt_deg == (45.0, -45.0)
    assert SetupErrors(base_sensor_rotvec_rad=(0.8, -0.8, 0.8)).any
    assert SetupErrors(jet_force_scale=1e-3).any and SetupErrors(jet_force_scale=1.5).any


@pytest.mark.parametrize(("hidden", "message"), [
    ("jet_wiring=1,2,2", "SetupErrors.jet_wiring must be a permutation of 1, 2, 3, got (1, 2, 2)"),
    # Finite, but it turned gravity nan deep in the twin (a traceback, exit 1).
    ("tracker_tilt_deg=1e308,0", "SetupErrors.tracker_tilt_deg must be angles from -45 to 45 degrees (a field "
                                 "generator on a ramp; more is another rig), got (1e+308, 0.0)"),
])
def test_simulate_refuses_a_bad_setup_error_in_one_line(tmp_path, hidden: str, message: str):
    done = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "simulate", "-o", str(tmp_path / "x.csv"),
                           "--hidden", hidden], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.strip().splitlines() == [f"error: setup error {hidden!r}: {message}"]
