"""Rig profiles: the shipped ones load, defaults, frames, and every error names file + key."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hydrojet_bench.errors import UserError
from hydrojet_bench.geometry import matrix_from_quat, quat_from_rotvec, quat_multiply
from hydrojet_bench.params import ModelParameters
from hypothesis import given, settings
from hypothesis import strategies as st

from hydrojet_bench.config.schema import TwinTable
from hydrojet_bench.profile import (PROFILES_DIR, SensorMounting, hanging_orientation, load_profile,
                                    profile_from_mapping)
from hydrojet_bench.twin import TwinConfig

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


def test_shipped_profile_by_name_and_its_typed_bench_tables() -> None:
    profile = load_profile("hydrojet-v1")
    assert profile.path == PROFILES_DIR / "hydrojet-v1.toml"
    transports = profile.config.transports
    assert transports.valves == "serial:///dev/ttyUSB0?baud=115200"
    assert transports.tracker.startswith("serial://")
    assert transports.imu_bus == 1 and not transports.simulated
    assert profile.config.twin == TwinTable()


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
        ("[gravity]\nin_tracker_m_s2 = [0, 9.81]\n", "gravity.in_tracker_m_s2",
         "a list of 3 finite numbers, got [0, 9.81]"),
        ("[gravity]\nin_tracker_m_s2 = [0, 0, 0]\n", "gravity.in_tracker_m_s2", "must not be zero"),
        ("[gravity]\nin_tracker_m_s2 = [0, 'down', 0]\n", "gravity.in_tracker_m_s2[1]", "finite number"),
        ("[gravity]\nin_tracker_m_s2 = [0, nan, 0]\n", "gravity.in_tracker_m_s2[1]", "finite number"),
        (MINIMAL + "[rod]\nlength_m = -0.07\n", "rod.length_m", "must be a finite number > 0, got -0.07"),
        (MINIMAL + "[rod]\nlength_m = '70 mm'\n", "rod.length_m", "must be a finite number > 0, got '70 mm'"),
        (MINIMAL + "[rod]\nlenght_m = 0.07\n", "rod.lenght_m", "not a known key"),
        (MINIMAL + "[rod]\npoisson_ratio = 0.7\n", "rod.poisson_ratio", "> -1 and <= 0.5, got 0.7"),
        (MINIMAL + "[rod]\nradius_m = inf\n", "rod.radius_m", "must be a finite number > 0, got inf"),
        (MINIMAL + "[capsule]\nmass_kg = -1\n", "capsule.mass_kg", ">= 0"),
        (MINIMAL + "[capsule]\ncenter_of_mass_in_tip_m = 0.014\n", "capsule.center_of_mass_in_tip_m",
         "a list of 3 finite numbers, got 0.014"),
        # Finite yet absurd: the rod's or the capsule's weight overflowed inside the model.
        (MINIMAL + "[capsule]\nmass_kg = 1e308\n", "capsule.mass_kg", "= 1e+308 kg is outside the plausible range"),
        (MINIMAL + "[capsule]\ncenter_of_mass_in_tip_m = [0, 0, 14]\n", "capsule.center_of_mass_in_tip_m (z)",
         "= 14 m is outside the plausible range -1 .. 1 m"),
        (MINIMAL + "[rod]\nradius_m = 4.5\n", "rod.radius_m", "= 4.5 m is outside the plausible range"),
        (MINIMAL + "[base]\nposition_in_tracker_m = [0, 0, 200]\n", "base.position_in_tracker_m (z)",
         "= 200 m is outside the plausible range -10 .. 10 m"),
        (MINIMAL + "[base_sensor]\noffset_in_base_m = [1e308, 0, 0]\n", "base_sensor.offset_in_base_m (x)",
         "= 1e+308 m is outside"),
        (MINIMAL + "[tip_sensor]\noffset_in_tip_m = [0, -12, 0]\n", "tip_sensor.offset_in_tip_m (y)",
         "= -12 m is outside the plausible range -1 .. 1 m"),
        (MINIMAL + "[rod]\ndensity_kg_m3 = 1.07\n", "rod.density_kg_m3", "= 1.07 kg/m^3 is outside"),
        ("[gravity]\nin_tracker_m_s2 = [0.0, 0.0, -981.0]\n", "gravity.in_tracker_m_s2 (its length)",
         "= 981 m/s^2 is outside the plausible range 0 .. 100 m/s^2"),
        (MINIMAL + "[jets]\nmax_force_n = 0\n", "jets.max_force_n", "a finite number > 0 or a list"),
        (MINIMAL + "[jets]\nmax_force_n = [0.1, -0.1, 0.1]\n", "jets.max_force_n[1]", "> 0, got -0.1"),
        (MINIMAL + "[jets]\nmax_force_n = [0.1, 0.1]\n", "jets.max_force_n", "a number or a list of 3"),
        (MINIMAL + "[jets]\nring_angle_deg = true\n", "jets.ring_angle_deg", "must be a number >= -360 and <= 360, "
                                                                          "got True"),
        (MINIMAL + "[jets]\nring_angle_deg = 1e300\n", "jets.ring_angle_deg", "<= 360, got 1e+300"),
        (MINIMAL + "[base]\norientation_in_tracker = [1, 1, 0, 0]\n", "base.orientation_in_tracker",
         "unit quaternion"),
        (MINIMAL + "[base_sensor]\nrotation_in_base = [1, 0, 0]\n", "base_sensor.rotation_in_base",
         "unit quaternion"),
        (MINIMAL + "[tip_sensor]\noffset_in_tip_m = [0, 0]\n", "tip_sensor.offset_in_tip_m",
         "a list of 3 finite numbers"),
        ("rod = 3\n" + MINIMAL, "rod", "must be a table"),
        ("answer = 42\n" + MINIMAL, "answer", "is not a known key (the top level takes name, "),
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


@pytest.mark.parametrize(("text", "key", "suggestion"), [
    ('[transport]\nvalves = "sim"\n', "transport", "transports"),
    ("[sesion]\nsettle_s = 5.0\n", "sesion", "session"),
    ("[valve]\nwatchdog_ms = 500\n", "valve", "valves"),
    ("[rood]\nlength_m = 0.07\n", "rood", "rod"),
    ("[session]\nsetle_s = 5.0\n", "session.setle_s", "settle_s"),
    ("[twin]\nseeds = 3\n", "twin.seeds", "seed"),
    ("[twin.noise]\nem_position_rms = 0.0\n", "twin.noise.em_position_rms", "em_position_rms_m"),
    ("[imu.base]\nmag_hard_iron = [0, 0, 0]\n", "imu.base.mag_hard_iron", "mag_hard_iron_ut"),
])
def test_misspelt_tables_and_keys_are_refused_with_the_close_match(tmp_path: Path, text: str, key: str,
                                                                    suggestion: str) -> None:
    path = write(tmp_path, MINIMAL + text)
    with pytest.raises(UserError) as info:
        load_profile(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key} is not a known key; did you mean {suggestion}?"), message
    assert "\n" not in message


def test_the_shipped_physical_rig_with_a_misspelt_table_does_not_load(tmp_path: Path) -> None:
    text = (PROFILES_DIR / "hydrojet-v1.toml").read_text().replace("[transports]", "[transport]")
    with pytest.raises(UserError, match=r"hydrojet-v1\.toml: transport is not a known key; did you mean transports\?"):
        load_profile(write(tmp_path, text, "hydrojet-v1.toml"))


@pytest.mark.parametrize(("text", "key", "expected"), [
    ("[session]\nsettle_s = 1.0\nwindow_s = 2.0\n", "session.window_s", "must not exceed session.settle_s"),
    ("[session]\nwindow_s = 1e-9\n", "session.window_s",
     "= 1e-09 s holds fewer than two samples of the slowest stream (imu.rate_hz = 40): make it at least 0.05 s"),
    ('[transports]\nvalves = "COM3"\n', "transports.valves", 'must be "sim", "pty" or a transport URL'),
    ('[transports]\nvalves = "tcp://10.0.0.2:5000"\n', "transports.valves",
     "is not a usable transport URL: unsupported transport scheme 'tcp'"),
    ('[transports]\ntracker = "serial:///dev/ttyUSB1?baud=fast"\n', "transports.tracker",
     "baud must be a positive integer, got 'fast'"),
    ("[rod]\nyoungs_modulus_base_pa = 0.3\n", "rod.youngs_modulus_base_pa",
     "= 0.3 Pa is outside the plausible range 1000 .. 1e+09 Pa"),
    ("[rod]\nlength_m = 70.0\n", "rod.length_m", "= 70 m is outside the plausible range 0.005 .. 1 m"),
    ("[jets]\nmax_force_n = 100.0\n", "jets.max_force_n", "= 100 N is outside the plausible range 0 .. 10 N"),
    ("[session]\ntime_scale = 1e9\n", "session.time_scale", "<= 1000"),
    ("[session]\ntime_scale = 1e-300\n", "session.time_scale", "must be a number >= 1 and <= 1000, got 1e-300"),
    ("[session]\ntime_scale = 0.5\n", "session.time_scale", "must be a number >= 1 and <= 1000, got 0.5"),
    ("[session]\nsettle_s = 1e300\n", "session.settle_s", "must be a number > 0 and <= 86400, got 1e+300"),
    ("[session]\nflush_interval_s = 1e9\n", "session.flush_interval_s", "must be a number > 0 and <= 60, got 1000000000.0"),
    ("[transports]\nimu_bus = -1\n", "transports.imu_bus", "I2C bus number"),
    # A real device keeps wall time: a faster session clock would cut every hold short.
    ('[transports]\nvalves = "pty:///dev/pts/9"\n[session]\ntime_scale = 25.0\n', "transports.valves",
     "= 'pty:///dev/pts/9' is a real device, and a rig with any real device runs on wall time, but "
     "session.time_scale = 25: set time_scale = 1 under [session]"),
    ("[transports]\nimu_bus = 1\n[session]\ntime_scale = 2.0\n", "transports.imu_bus",
     "= 1 is a real device, and a rig with any real device runs on wall time, but session.time_scale = 2"),
    ('[tracker]\ntools = ["base", "base"]\n', "tracker.tools", 'each of "base" and "tip" once'),
    ("[imu]\nbase_address = 0x69\n", "imu.tip_address", "must differ from imu.base_address"),
    ("[imu]\nbase_address = 0x70\n", "imu.base_address", "must be 0x68 or 0x69 (the ICM-20948's AD0 pin low or "
     "high), got 0x70"),
    ("[imu]\ntip_address = 'x'\n", "imu.tip_address", "must be an integer, got 'x'"),
    ("[valves]\nheartbeat_ms = 300\n", "valves.heartbeat_ms", "below half of valves.watchdog_ms"),
    # The firmware counts its watchdog in 16 bits of milliseconds.
    ("[valves]\nwatchdog_ms = 100000\n", "valves.watchdog_ms", "must be a number >= 1 and <= 65535, got 100000"),
    # The Aurora measures at 40 Hz: a faster poll would be a stream forever "behind".
    ("[tracker]\nrate_hz = 60\n", "tracker.rate_hz", "must be a number > 0 and <= 40, got 60"),
    ('[tracker]\ntools = ["tip", "base", "probe"]\n', "tracker.tools",
     "names 'probe', but the simulated tracker (transports.tracker = 'sim') has the base and tip sensors only"),
    ("[valves.calibration]\njet4 = { force_n = [0, 1], duty_permille = [0, 1000] }\n",
     "valves.calibration.jet4", "is not a known key"),
    ("[valves.calibration]\njet1 = { force_n = [0.1, 0.0], duty_permille = [0, 1000] }\n",
     "valves.calibration.jet1.force_n", "is not a valid calibration table"),
    ('[estimator]\nmodel = "fem"\n', "estimator.model", "must be one of cosserat, prb"),
    ("[estimator]\ngain = 2.0\n", "estimator.gain", "must be in (0, 1]"),
    ("[twin]\nseed = 'x'\n", "twin.seed", "must be an integer >= 0, got 'x'"),
    ("[twin.noise]\nem_orientation_rms_deg = -1.0\n", "twin.noise.em_orientation_rms_deg", ">= 0, got -1.0"),
    ("[twin.noise]\nem_position_rms_m = 0.48\n", "twin.noise.em_position_rms_m", "= 0.48 is past 0.05"),
    ('[twin.hidden_effect_values]\n"gravity.weight_scale" = "big"\n',
     'twin.hidden_effect_values."gravity.weight_scale"', "must be a finite number, got 'big'"),
])
def test_bench_and_twin_tables_name_file_and_key(tmp_path: Path, text: str, key: str, expected: str) -> None:
    path = write(tmp_path, MINIMAL + text)
    with pytest.raises(UserError) as info:
        load_profile(path)
    message = str(info.value)
    assert message.startswith(f"{path}: {key} "), message
    assert expected in message


def test_extends_merges_the_child_over_the_parent_key_by_key(tmp_path: Path) -> None:
    write(tmp_path, MINIMAL + "[rod]\nlength_m = 0.08\nradius_m = 0.005\n[session]\nsettle_s = 4.0\n",
          "parent.toml")
    child = load_profile(write(tmp_path, 'extends = "parent.toml"\n[rod]\nlength_m = 0.09\n', "child.toml"))
    assert child.name == "child"  # a child never inherits its parent's name
    assert child.rod.length_m == 0.09 and child.rod.radius_m == 0.005
    assert child.config.session.settle_s == 4.0
    shipped = load_profile(write(tmp_path, 'extends = "sim"\n[twin]\nseed = 5\n', "mine.toml"))
    assert shipped.config.twin.seed == 5
    assert shipped.config.transports == load_profile("sim").config.transports
    assert shipped.base_sensor == load_profile("sim").base_sensor


def test_sim_mystery_is_sim_plus_its_hidden_effect() -> None:
    sim, mystery = load_profile("sim"), load_profile("sim-mystery")
    assert mystery.name == "sim-mystery"
    assert mystery.config.twin.hidden_effects == ("pressure_stiffening",)
    for table in ("gravity", "base", "base_sensor", "tip_sensor", "rod", "capsule", "jets", "transports",
                  "tracker", "imu", "valves", "session", "estimator"):
        assert getattr(mystery.config, table) == getattr(sim.config, table), table


@pytest.mark.parametrize(("files", "expected"), [
    ({"a.toml": 'extends = "b.toml"\n' + MINIMAL, "b.toml": 'extends = "a.toml"\n'}, "makes a cycle"),
    ({"a.toml": 'extends = "a.toml"\n' + MINIMAL}, "makes a cycle"),
    ({"a.toml": 'extends = "absent.toml"\n' + MINIMAL}, "extends rig profile 'absent.toml' not found"),
    ({"a.toml": "extends = 3\n" + MINIMAL}, "extends must be a profile name or a relative path"),
    ({"a.toml": 'extends = "b.toml"\n', "b.toml": "[gravity\n"}, "b.toml: not valid TOML"),
])
def test_extends_errors(tmp_path: Path, files: dict[str, str], expected: str) -> None:
    for name, text in files.items():
        write(tmp_path, text, name)
    with pytest.raises(UserError) as info:
        load_profile(tmp_path / "a.toml")
    assert expected in str(info.value)
    assert "\n" not in str(info.value)


_SCALARS = st.one_of(st.none(), st.booleans(), st.integers(-3, 1000), st.floats(allow_nan=True),
                     st.text(max_size=4), st.sampled_from(["sim", "pty", "cosserat", "base", "tip"]))
_VALUES = st.recursive(_SCALARS.filter(lambda v: v is not None),
                       lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner,
                                                                                    max_size=3),
                       max_leaves=8)
_KEYS = st.sampled_from(["in_tracker_m_s2", "length_m", "max_force_n", "settle_s", "window_s", "seed", "noise",
                         "tools", "imu_bus", "valves", "calibration", "jet1", "force_n", "model", "extends",
                         "orientation_in_tracker", "true_parameters", "hidden_effect_values", "base", "tip"])
_TABLES = st.sampled_from(["gravity", "base", "rod", "jets", "transports", "tracker", "imu", "valves", "session",
                           "estimator", "twin", "rood", "name", "extends"])


@given(st.dictionaries(_TABLES, st.dictionaries(_KEYS, _VALUES, max_size=3) | _VALUES, max_size=4))
@settings(max_examples=150, deadline=None)
def test_any_profile_document_loads_or_is_a_user_error(document: dict) -> None:
    document = {"gravity": {"in_tracker_m_s2": [0.0, 0.0, -9.81]}, **document}
    try:
        profile = profile_from_mapping(document, source="fuzz.toml")
        profile.model_parameters()
        TwinConfig.from_profile(profile)  # the [twin] table's effects and parameters
    except UserError as error:
        assert "\n" not in str(error)
        assert str(error).startswith("fuzz.toml: "), error


def test_gravity_in_base_follows_the_measured_base_orientation() -> None:
    mounting = SensorMounting(rotation_in_body=tuple(quat_from_rotvec([0.1, -0.4, 1.2])))
    profile = profile_from_mapping({"gravity": {"in_tracker_m_s2": [0.0, 0.0, -9.81]},
                                    "base_sensor": {"rotation_in_base": list(mounting.rotation_in_body)}})
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


def test_a_profile_that_is_not_utf8_is_one_line_naming_it(tmp_path: Path) -> None:
    path = tmp_path / "latin1.toml"
    path.write_bytes(MINIMAL.encode() + "# réglé\n".encode("latin-1"))
    with pytest.raises(UserError, match=rf"^{path}: not UTF-8 text \(byte \d+\); save it as UTF-8$"):
        load_profile(path)


def test_a_profile_with_a_byte_order_mark_loads_as_without(tmp_path: Path) -> None:
    """Some Windows editors start UTF-8 files with a byte-order mark; TOML has none."""
    marked = tmp_path / "marked.toml"
    marked.write_bytes(b"\xef\xbb\xbf" + (MINIMAL + "[jets]\nring_angle_deg = 5.0\n").encode())
    assert load_profile(marked).config.jets.ring_angle_deg == 5.0


@pytest.mark.parametrize(("parent", "child", "expected"), [
    ("[imu]\nbogus = 1\n", "", "{parent} (extended by {child}): imu.bogus is not a known key"),
    ("[rod]\nlength_m = -1.0\n", "[rod]\nradius_m = 0.003\n",
     "{parent} (extended by {child}): rod.length_m must be a finite number > 0"),
    ("[valves]\nheartbeat_ms = 300\n", "", "{parent} (extended by {child}): valves.heartbeat_ms must be below"),
    ("[session]\nwindow_s = 0.01\n", "", "{parent} (extended by {child}): session.window_s = 0.01 s holds"),
    # The child's own value is the child's mistake, whatever the parent holds.
    ("[imu]\nrate_hz = 0.0\n", "[imu]\nrate_hz = 2000.0\n", "{child}: imu.rate_hz must be a number"),
    ("[rod]\nlength_m = -1.0\n", "[rod]\nlength_m = 0.08\n[imu]\nbogus = 1\n", "{child}: imu.bogus"),
])
def test_a_mistake_in_a_parent_profile_names_the_parent(tmp_path: Path, parent: str, child: str,
                                                        expected: str) -> None:
    write(tmp_path, MINIMAL + parent, "parent.toml")
    path = write(tmp_path, 'extends = "parent.toml"\n' + child, "child.toml")
    with pytest.raises(UserError) as info:
        load_profile(path)
    assert str(info.value).startswith(expected.format(parent=tmp_path / "parent.toml", child=path)), str(info.value)
