"""Every command that takes a model takes the same model arguments and resolves them by
one rule (`hydrojet_bench.model_choice`): a parameter file brings its model and effects
in place of the command's defaults; --model and --effect on the command line win."""

from __future__ import annotations

import argparse
import inspect
import re
from pathlib import Path

import pytest

from hydrojet_bench import api, commands
from hydrojet_bench.cli import COMMAND_MODULES, build_parser
from hydrojet_bench.errors import UserError
from hydrojet_bench.model_choice import ModelDefaults, choose_model
from hydrojet_bench.models import MODELS
from hydrojet_bench.params import PARAMETER_NAMES, ModelParameters, get_parameter
from hydrojet_bench.params_io import ParameterFile, write_parameter_file

MODEL_COMMANDS = {"run", "replay", "sensors", "calibrate", "compare", "diagnose"}
INPUT_COMMANDS = {"replay", "sensors", "calibrate", "compare", "diagnose", "recover"}
CLOGGED_JET = f"{Path(__file__).resolve().parents[2] / 'docs/examples/clogged_jet.py'}:CloggedJet"


def subparsers() -> dict[str, argparse.ArgumentParser]:
    action = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def option(parser: argparse.ArgumentParser, flag: str) -> argparse.Action | None:
    return next((a for a in parser._actions if flag in a.option_strings), None)


def signature(action: argparse.Action) -> tuple:
    """What a user can tell apart on the command line (the help text may differ, and
    compare requires --params)."""
    default = tuple(action.default) if isinstance(action.default, list) else action.default
    return (type(action), tuple(action.option_strings), action.dest, action.nargs, default, action.type,
            action.choices if action.choices is None else tuple(action.choices), action.metavar)


def test_every_command_that_takes_a_model_takes_the_same_model_arguments():
    parsers = subparsers()
    assert {name for name, parser in parsers.items() if option(parser, "--model")} == MODEL_COMMANDS
    for flag in ("--model", "--effect", "--params"):
        found = {name: signature(action) for name in MODEL_COMMANDS
                 if (action := option(parsers[name], flag)) is not None}
        assert len(set(found.values())) == 1, (flag, found)
    assert {name for name in MODEL_COMMANDS if option(parsers[name], "--params")} == {"run", "replay", "sensors",
                                                                                       "compare"}
    assert tuple(option(parsers["run"], "--model").choices) == tuple(MODELS)
    # Every command that reads measurements calls its input INPUT.
    for name, parser in parsers.items():
        positional = [a for a in parser._actions if not a.option_strings and a.dest != "help"]
        if name in INPUT_COMMANDS:
            assert [(a.dest, a.metavar) for a in positional][:1] == [("input", "INPUT")], name
        else:
            assert all(a.dest != "input" for a in positional), name


def test_no_command_resolves_a_model_itself():
    # A command resolves its model with model_choice, or hands its options to the Python
    # API, which resolves them with choose_model.
    assert "read_parameter_file" not in inspect.getsource(api) and "build_model" not in inspect.getsource(api)
    assert "choose_model(" in inspect.getsource(api)
    for name in COMMAND_MODULES:
        source = inspect.getsource(__import__(f"{commands.__name__}.{name}", fromlist=["run"]))
        assert "read_parameter_file" not in source and "build_model" not in source, name
        if name in MODEL_COMMANDS:
            assert "model_choice(" in source or "from ..api import" in source, name


# A parameter file lists everything calibrate fits; these are the nominal values.
NOMINAL = {name: get_parameter(ModelParameters(), name) for name in PARAMETER_NAMES}


@pytest.fixture
def parameter_file(tmp_path) -> Path:
    path = tmp_path / "p.toml"
    write_parameter_file(path, ParameterFile(model="prb", effects=("gravity", "jet_gain"),
                                             parameters={**NOMINAL, "E0": 4.0e5, "jet_gain.gain_2": 0.7}))
    return path


DEFAULTS = ModelDefaults("cosserat", ("base_compliance",))


def names(effects) -> list[str]:
    return [effect.name for effect in effects]


def test_without_a_parameter_file_the_defaults_hold_and_the_command_line_wins():
    choice = choose_model(None, [], None, DEFAULTS)
    assert choice.model.name == "cosserat" and names(choice.model.effects) == ["gravity", "base_compliance"]
    assert choice.parameters(ModelParameters()) == ModelParameters()
    choice = choose_model("prb", ["jet_gain"], None, DEFAULTS)
    assert choice.model.name == "prb"
    assert names(choice.model.effects) == ["gravity", "base_compliance", "jet_gain"]
    assert names(choice.requested) == ["base_compliance", "jet_gain"]
    assert "jet_gain.gain_2" in choice.calibration_names and "E0" in choice.calibration_names


def test_a_parameter_file_brings_its_model_effects_and_values_and_the_command_line_wins(parameter_file):
    choice = choose_model(None, [], parameter_file, DEFAULTS)
    assert choice.model.name == "prb"
    assert names(choice.model.effects) == ["gravity", "jet_gain"]  # in place of the defaults' effects
    params = choice.parameters(ModelParameters())
    assert params != ModelParameters() and params.rod.youngs_modulus_base_pa == 4.0e5
    choice = choose_model("cosserat", ["pressure_stiffening"], parameter_file, DEFAULTS)
    assert choice.model.name == "cosserat"
    assert names(choice.model.effects) == ["gravity", "jet_gain", "pressure_stiffening"]


def test_a_file_effect_in_a_parameter_file_is_found_by_its_name_among_the_effect_files(tmp_path):
    path = tmp_path / "clogged.toml"
    write_parameter_file(path, ParameterFile(model="cosserat", effects=("gravity", "clogged_jet"),
                                             parameters={**NOMINAL, "E0": 4.0e5}))
    with pytest.raises(UserError, match=f"{re.escape(str(path))}: effect 'clogged_jet' is not in the library"):
        choose_model(None, [], path, DEFAULTS)
    choice = choose_model(None, [], path, DEFAULTS, effect_files=[CLOGGED_JET])
    assert names(choice.model.effects) == ["gravity", "clogged_jet"]
    assert names(choose_model(None, [CLOGGED_JET], path, DEFAULTS).model.effects) == ["gravity", "clogged_jet"]


def test_a_parameter_file_keeps_the_effect_file_it_was_calibrated_with(tmp_path):
    """The command line's file of the same name wins over a file that moved, not over one
    still there: its parameters were fitted to that file's physics."""
    other = tmp_path / "other_clogged.py"
    other.write_text(Path(CLOGGED_JET.rpartition(":")[0]).read_text())
    path = tmp_path / "clogged.toml"
    write_parameter_file(path, ParameterFile(model="cosserat", effects=("gravity", CLOGGED_JET),
                                             parameters={**NOMINAL, "E0": 4.0e5}))
    assert names(choose_model(None, [CLOGGED_JET], path, DEFAULTS).model.effects) == ["gravity", "clogged_jet"]
    with pytest.raises(UserError, match=f"{re.escape(str(path))}: effect 'clogged_jet' was calibrated with "
                                        f".*; {re.escape(str(other))}:CloggedJet is another file of the same name"):
        choose_model(None, [f"{other}:{CLOGGED_JET.rpartition(':')[2]}"], path, DEFAULTS)
