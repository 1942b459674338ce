"""The [twin] table of a sim profile."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from hydrojet_bench.errors import UserError
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin.profile_table import twin_config

REPO = Path(__file__).resolve().parents[2]


def profile_with(tmp_path, twin_table: str):
    shutil.copy(REPO / "docs/examples/clogged_jet.py", tmp_path / "clogged_jet.py")
    text = (REPO / "profiles/sim.toml").read_text() + "\n" + twin_table
    path = tmp_path / "sim-test.toml"
    path.write_text(text)
    return load_profile(path)


def test_twin_table_sets_hidden_effects_truth_noise_and_seed(tmp_path):
    profile = profile_with(tmp_path, """
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
""")
    config = twin_config(profile)
    assert config.seed == 42 and config.settle_time_constant_s == 0.2
    assert [e.name for e in config.hidden_effects] == ["clogged_jet"]
    assert config.true_params.rod.youngs_modulus_base_pa == 2.8e5
    assert config.noise.em_orientation_rms_deg == 0.35
    assert dict(config.hidden_effect_values)["gravity.weight_scale"] == 1.1
    # Command-line choices win over the file.
    assert twin_config(profile, seed=3).seed == 3


def test_profiles_without_a_twin_table_give_the_plain_twin():
    config = twin_config(load_profile("sim"))
    assert config.hidden_effects == () and config.seed == 0
    np.testing.assert_allclose(config.true_params.rod.length_m, 0.070)


@pytest.mark.parametrize("table, message", [
    ("[twin]\nseeds = 3\n", "twin.seeds is not a known key"),
    ("[twin]\nseed = 'x'\n", "twin.seed must be an integer"),
    ("[twin.true_parameters]\nE0 = -1.0\n", "twin.true_parameters rod.youngs_modulus_base_pa must be > 0"),
    ("[twin.noise]\nem_jitter = 1.0\n", "twin.noise.em_jitter is not a known key"),
    ("[twin]\nhidden_effects = ['warp_drive']\n", "unknown effect 'warp_drive'"),
])
def test_twin_table_errors_name_the_file_and_key(tmp_path, table, message):
    profile = profile_with(tmp_path, table)
    with pytest.raises(UserError, match=message) as error:
        twin_config(profile)
    if "warp" not in message:
        assert "sim-test.toml" in str(error.value)
