"""Rig profiles: the shipped ones load, defaults, frames, and every error names file + key."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hydrojet_bench.errors import UserError
from hydrojet_bench.geometry import matrix_from_quat, quat_from_rotvec, quat_multiply
from hydrojet_bench.params import ModelParameters
from hydrojet_bench.profile import (PROFILES_DIR, RigProfile, SensorMounting, hanging_orientation,
                                    load_profile)

MINIMAL = "[gravity]\nin_tracker_m_s2 = [0.0, 0.0, -9.81]\n"


def write(tmp_path: Path, text: str, name: str = "rig.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.mark.parametrize("name", ["sim", "hydrojet-v1"])
def test_shipped_profiles_load_and_make_model_parameters(name: str) -> None:
    profile = load_profile(PROFILES_DIR / f"{name}.toml")
    assert profile.name == name
    params = profile.model_parameters()
    assert isinstance(params, ModelParameters)
    # Both rigs hang the rod from its clamp: gravity along +z of the base frame.
    np.testing.assert_allclose(params.gravity_in_base_m_s2, (0.0, 0.0, 9.81), atol=1e-12)
    assert params.rod.length_m == pytest.approx(0.070)
    assert all(f > 0 for f in profile.max_jet_force_n)


def test_shipped_profile_by_name_and_transports_kept_raw() -> None:
    profile = load_profile("hydrojet-v1")
    assert profile.path == PROFILES_DIR / "hydrojet-v1.toml"
    transports = profile.table("transports")
    assert transports["valves"] == "serial:///dev/ttyUSB0?baud=115200"
    assert transports["tracker"].startswith("serial://")
    assert transports["imu_bus"] == 1
    assert profile.table("twin") == {}


def test_minimal_profile_takes_hydrojet_defaults(tmp_path: Path) -> None:
    profile = load_profile(write(tmp_path, MINIMAL))
    assert profile.name == "rig"
    defaults = ModelParameters()
    params = profile.model_parameters()
    assert params.rod == defaults.rod and params.capsule == defaults.capsule and params.jets == defaults.jets
    assert profile.base_sensor == SensorMounting() and profile.tip_sensor == SensorMounting()
    # Default clamp: hanging along gravity.
    np.testing.assert_allclose(params.gravity_in_base_m_s2, (0.0, 0.0, 9.81), atol=1e-12)


def test_values_reach_model_parameters(tmp_path: Path) -> None:
    text = MINIMAL + """
[rod]
length_m = 0.08
youngs_modulus_base_pa = 4e5
[capsule]
mass_kg = 0.003
center_of_mass_in_tip_m = [0.0, 0.001, 0.012]
[jets]
ring_angle_deg = 90
max_force_n = [0.1, 0.2, 0.3]
[tip_sensor]
rotation_in_tip = [0.7071, 0.7071, 0.0, 0.0]
offset_in_tip_m = [0.0, 0.0, 0.01]
"""
    profile = load_profile(write(tmp_path, text))
    params = profile.model_parameters(disturbance=ModelParameters().disturbance)
    assert params.rod.length_m == 0.08 and params.rod.youngs_modulus_base_pa == 4e5
    assert params.capsule.mass_kg == 0.003 and params.capsule.center_of_mass_in_tip_m == (0.0, 0.001, 0.012)
    assert params.jets.ring_angle_rad == pytest.approx(math.pi / 2)
    assert profile.max_jet_force_n == (0.1, 0.2, 0.3)
    # A 4-digit quaternion is accepted and stored renormalised.
    assert np.linalg.norm(profile.tip_sensor.rotation_in_body) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize(
    ("text", "key", "expected"),
    [
        ("", "gravity.in_tracker_m_s2", "is required"),
        ("[gravity]\nin_tracker_m_s2 = [0, 9.81]\n", "gravity.in_tracker_m_s2", "list of 3 numbers"),
        ("[gravity]\nin_tracker_m_s2 = [0, 0, 0]\n", "gravity.in_tracker_m_s2", "must not be zero"),
        ("[gravity]\nin_tracker_m_s2 = [0, 'down', 0]\n", "gravity.in_tracker_m_s2[1]", "finite number"),
        ("[gravity]\nin_tracker_m_s2 = [0, nan, 0]\n", "gravity.in_tracker_m_s2[1]", "finite number"),
        (MINIMAL + "[rod]\nlength_m = -0.07\n", "rod.length_m", "must be > 0"),
        (MINIMAL + "[rod]\nlength_m = '70 mm'\n", "rod.length_m", "must be a number"),
        (MINIMAL + "[rod]\nlenght_m = 0.07\n", "rod.lenght_m", "not a known key"),
        (MINIMAL + "[rod]\npoisson_ratio = 0.7\n", "rod.poisson_ratio", "(-1, 0.5]"),
        (MINIMAL + "[rod]\nradius_m = inf\n", "rod.radius_m", "must be finite"),
        (MINIMAL + "[capsule]\nmass_kg = -1\n", "capsule.mass_kg", ">= 0"),
        (MINIMAL + "[capsule]\ncenter_of_mass_in_tip_m = 0.014\n", "capsule.center_of_mass_in_tip_m",
         "list of 3 numbers"),
        (MINIMAL + "[jets]\nmax_force_n = 0\n", "jets.max_force_n", "must be > 0"),
        (MINIMAL + "[jets]\nmax_force_n = [0.1, -0.1, 0.1]\n", "jets.max_force_n[1]", "must be > 0"),
        (MINIMAL + "[jets]\nmax_force_n = [0.1, 0.1]\n", "jets.max_force_n", "a number or a list of 3"),
        (MINIMAL + "[jets]\nring_angle_deg = true\n", "jets.ring_angle_deg", "must be a number"),
        (MINIMAL + "[base]\norientation_in_tracker = [1, 1, 0, 0]\n", "base.orientation_in_tracker",
         "unit quaternion"),
        (MINIMAL + "[base_sensor]\nrotation_in_base = [1, 0, 0]\n", "base_sensor.rotation_in_base",
         "unit quaternion"),
        (MINIMAL + "[tip_sensor]\noffset_in_tip_m = [0, 0]\n", "tip_sensor.offset_in_tip_m", "3 numbers"),
        ("rod = 3\n" + MINIMAL, "rod", "must be a table"),
        ("answer = 42\n" + MINIMAL, "answer", "not a known top-level key"),
        (MINIMAL + "name = 7\n", "gravity.name", "not a known key"),
        ("name = 7\n" + MINIMAL, "name", "must be a string"),
    ],
)
def test_errors_name_file_and_key(tmp_path: Path, text: str, key: str, expected: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(UserError) as info:
        load_profile(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key} ") or message.startswith(f"{path}: {key}["), message
    assert expected in message


def test_toml_syntax_and_missing_file_are_user_errors(tmp_path: Path) -> None:
    path = write(tmp_path, "[gravity\n")
    with pytest.raises(UserError, match=rf"{path}: not valid TOML"):
        load_profile(path)
    with pytest.raises(UserError, match="not found.*sim"):
        load_profile(tmp_path / "absent.toml")
    with pytest.raises(UserError, match="not found"):
        load_profile("no-such-shipped-profile")


def test_unknown_tables_are_kept_raw(tmp_path: Path) -> None:
    text = MINIMAL + '[twin]\nseed = 3\nhidden = ["gravity"]\n[estimator.online]\ngain = 0.4\n'
    profile = load_profile(write(tmp_path, text))
    assert profile.table("twin") == {"seed": 3, "hidden": ["gravity"]}
    assert profile.table("estimator") == {"online": {"gain": 0.4}}
    assert set(profile.extra_tables) == {"twin", "estimator"}


def test_gravity_in_base_follows_the_measured_base_orientation() -> None:
    mounting = SensorMounting(rotation_in_body=tuple(quat_from_rotvec([0.1, -0.4, 1.2])))
    profile = RigProfile(gravity_in_tracker_m_s2=(0.0, 0.0, -9.81), base_sensor=mounting)
    rng = np.random.default_rng(4)
    clamp = quat_from_rotvec(rng.normal(size=(20, 3)))
    sensor = quat_multiply(clamp, mounting.rotation_in_body)  # R_sensor = R_clamp R_mount
    gravity = profile.gravity_in_base_m_s2(sensor)
    expected = np.einsum("nji,j->ni", matrix_from_quat(clamp), [0.0, 0.0, -9.81])  # R^T g
    np.testing.assert_allclose(gravity, expected, atol=1e-12)
    np.testing.assert_allclose(profile.model_parameters(sensor[3]).gravity_in_base_m_s2, expected[3], atol=1e-12)
    with pytest.raises(ValueError, match="one base sensor orientation"):
        profile.model_parameters(sensor)


@pytest.mark.parametrize("gravity", [(0, 0, -9.81), (0, 0, 9.81), (9.81, 0, 0), (1.0, -2.0, 3.0)])
def test_hanging_orientation_points_the_rod_along_gravity(gravity: tuple[float, float, float]) -> None:
    rod_axis = matrix_from_quat(hanging_orientation(gravity))[:, 2]
    np.testing.assert_allclose(rod_axis, np.asarray(gravity) / np.linalg.norm(gravity), atol=1e-12)


def test_sim_profile_sensor_poses_round_trip_through_mountings() -> None:
    profile = load_profile("sim")
    # At rest the tip sits L below the clamp; the tip sensor 10 mm further down.
    straight = np.eye(4)
    straight[2, 3] = profile.rod.length_m
    poses = profile.sensor_poses_in_tracker(straight)
    clamp_z = profile.base_position_in_tracker_m[2]
    np.testing.assert_allclose(poses.tip_position_m, [0.0, 0.0, clamp_z - 0.070 - 0.010], atol=1e-12)
    # Base sensor 8 mm above the clamp face (base -z is tracker +z), 12 mm off axis.
    np.testing.assert_allclose(poses.base_position_m, [0.012, 0.0, clamp_z + 0.008], atol=1e-12)
    np.testing.assert_allclose(profile.clamp_orientation_in_tracker(poses.base_orientation),
                               profile.base_orientation_in_tracker, atol=1e-12)
