"""The [twin] table of a sim profile: it configures the twin and the emulators behind it."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from drivers.aurora.client import AuroraTracker
from hydrojet_bench.bench.clock import ScaledClock
from hydrojet_bench.bench.simulated_rig import simulated_devices
from hydrojet_bench.errors import UserError
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import TwinConfig

REPO = Path(__file__).resolve().parents[2]


def profile_path(tmp_path: Path, twin_table: str) -> Path:
    shutil.copy(REPO / "docs/examples/clogged_jet.py", tmp_path / "clogged_jet.py")
    path = tmp_path / "sim-test.toml"
    path.write_text('extends = "sim"\n' + twin_table)
    return path


def test_twin_table_sets_hidden_effects_truth_noise_and_seed(tmp_path):
    profile = load_profile(profile_path(tmp_path, """
[twin]
seed = 42
hidden_effects = ["clogged_jet.py:CloggedJet"]
settle_time_constant_s = 0.2
[twin.true_parameters]
E0 = 2.8e5
[twin.hidden_effect_values]
"gravity.weight_scale" = 1.1
[twin.noise]
em_orientation_rms_deg = 0.35
"""))
    config = TwinConfig.from_profile(profile)
    assert config.seed == 42 and config.settle_time_constant_s == 0.2
    assert [e.name for e in config.hidden_effects] == ["clogged_jet"]
    assert config.true_params.rod.youngs_modulus_base_pa == 2.8e5
    assert config.noise.em_orientation_rms_deg == 0.35
    assert config.noise.em_position_rms_m == profile.config.twin.noise.em_position_rms_m  # the default
    assert dict(config.hidden_effect_values)["gravity.weight_scale"] == 1.1
    # Command-line choices win over the file.
    assert TwinConfig.from_profile(profile, seed=3).seed == 3


def test_profiles_without_a_twin_table_give_the_plain_twin():
    config = TwinConfig.from_profile(load_profile("sim"))
    assert config.hidden_effects == () and config.seed == 0
    np.testing.assert_allclose(config.true_params.rod.length_m, 0.070)


@pytest.mark.parametrize("table, message", [
    ("[twin]\nseeds = 3\n", "twin.seeds is not a known key; did you mean seed?"),
    ("[twin]\nseed = 'x'\n", "twin.seed must be an integer >= 0, got 'x'"),
    ("[twin.noise]\nem_jitter = 1.0\n", "twin.noise.em_jitter is not a known key"),
])
def test_twin_table_mistakes_are_refused_on_load(tmp_path, table, message):
    path = profile_path(tmp_path, table)
    with pytest.raises(UserError) as error:
        load_profile(path)
    assert str(error.value).startswith(f"{path}: {message}")


@pytest.mark.parametrize("table, message", [
    ("[twin.true_parameters]\nE0 = -1.0\n", "twin.true_parameters rod.youngs_modulus_base_pa must be > 0"),
    ("[twin.true_parameters]\nE9 = 1.0\n", "twin.true_parameters"),
    ("[twin]\nhidden_effects = ['warp_drive']\n", "twin.hidden_effects: unknown effect 'warp_drive'"),
    ('[twin.hidden_effect_values]\n"gravity.mass" = 1.0\n', "[twin] TwinConfig.hidden_effect_values key"),
])
def test_twin_table_values_the_twin_refuses_name_file_and_key(tmp_path, table, message):
    path = profile_path(tmp_path, table)
    profile = load_profile(path)
    with pytest.raises(UserError) as error:
        TwinConfig.from_profile(profile)
    assert str(error.value).startswith(f"{path}: {message}")


@pytest.mark.parametrize("noise_off", [True, False])
def test_twin_noise_reaches_the_emulated_tracker(tmp_path, run_async, noise_off):
    noise = "em_position_rms_m = 0.0\nem_orientation_rms_deg = 0.0\n" if noise_off else "em_position_rms_m = 2e-3\n"
    profile = load_profile(profile_path(tmp_path, "[twin.noise]\n" + noise))

    async def read_tip():
        async with simulated_devices(profile, profile.config, ScaledClock()) as devices:
            async with AuroraTracker(devices.tracker_url, list(profile.config.tracker.tools)) as tracker:
                frame = (await tracker.read_frame())["tip"]
                # The rod rests: the truth is the same at every instant.
                truth = devices.twin.sensor_truth("tip", 0.0)
                return frame, truth

    frame, truth = run_async(read_tip, timeout_s=30.0)
    error_mm = np.linalg.norm(np.subtract(frame.position_mm, truth.position_in_tracker_m * 1e3))
    if noise_off:
        assert error_mm < 1e-3  # float32 frame resolution
        np.testing.assert_allclose(np.abs(np.dot(frame.orientation, truth.orientation_in_tracker)), 1.0, atol=1e-6)
    else:
        assert error_mm > 0.05  # 2 mm RMS from the profile, not the emulator's own 0.48 mm default
