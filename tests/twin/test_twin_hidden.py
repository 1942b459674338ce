"""`--hidden` specs: names from the twin's registry, values scalar, vector or by
parameter, and hidden effects that would hide nothing refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from hydrojet_bench.cli import main
from hydrojet_bench.errors import UserError
from hydrojet_bench.twin.hidden import HIDDEN, inert_effects, parse_hidden

CLOGGED_JET = f"{Path(__file__).resolve().parents[2] / 'docs/examples/clogged_jet.py'}:CloggedJet"


def test_scalar_vector_and_named_values_of_several_effects():
    choice = parse_hidden(["jet_misalignment=0.1", "base_hysteresis=20,0.02", "jet_gain:gain_2=0.8",
                           "jet_gain:gain_3=0.9", CLOGGED_JET])
    assert [effect.name for effect in choice.effects] == ["jet_misalignment", "base_hysteresis", "jet_gain",
                                                          "clogged_jet"]
    assert dict(choice.values) == {"jet_misalignment.ring_angle_rad": 0.1,
                                   "base_hysteresis.compliance_rad_per_nm": 20.0, "base_hysteresis.play_rad": 0.02,
                                   "jet_gain.gain_2": 0.8, "jet_gain.gain_3": 0.9}
    assert set(HIDDEN) >= {"gravity", "jet_gain", "base_hysteresis", "sensor_mounting"}


@pytest.mark.parametrize("spec, message", [
    ("warp_drive=1", "unknown hidden effect 'warp_drive'"),
    ("jet_gain=1,0.8", "jet_gain has 3 parameters (gain_1, gain_2, gain_3), got 2 value(s)"),
    ("jet_gain:gain_9=1", "jet_gain has no parameter 'gain_9'"),
    ("jet_gain:gain_1=0.8,0.9", "jet_gain.gain_1 takes one number, got 2"),
    ("gravity=five", "the value must be a number"),
    ("gravity=nan", "the value must be finite"),
    ("gravity=5", "gravity.weight_scale = 5 is outside [0, 3]"),
])
def test_mistakes_name_the_spec(spec, message):
    with pytest.raises(UserError) as error:
        parse_hidden([spec])
    assert message in str(error.value) and str(error.value).startswith("--hidden")


def test_library_defaults_and_play_without_compliance_hide_nothing():
    every = [HIDDEN[name]() for name in HIDDEN]
    assert set(inert_effects(every, {})) == set(HIDDEN)  # every library default is the identity
    choice = parse_hidden(["base_hysteresis:play_rad=0.02", "base_compliance=20", "gravity=1.5"])
    assert inert_effects(choice.effects, dict(choice.values)) == ("base_hysteresis",)


def test_simulate_refuses_an_effect_that_hides_nothing_in_one_line(tmp_path, capsys):
    assert main(["simulate", "-o", str(tmp_path / "x.csv"), "--hidden", "base_hysteresis"]) == 2
    error = capsys.readouterr().err
    assert "Traceback" not in error and len(error.strip().splitlines()) == 1
    flat = " ".join(error.split())
    assert "--hidden base_hysteresis: at compliance_rad_per_nm 0, play_rad 0 it leaves the twin's rod as it is" in flat
    assert not (tmp_path / "x.csv").exists()
