"""`hydrojet-bench diagnose` through the command line: the JSON schema, the report, exit
codes and clear errors. A short plan keeps it quick; the statistics of the verdicts are
tested in tests/analysis/test_analysis_diagnose.py."""

from __future__ import annotations

import json

import pytest

from hydrojet_bench.cli import main
from hydrojet_bench.data.csv_io import write_csv
from hydrojet_bench.params import PARAMETER_NAMES
from hydrojet_bench.params_io import read_parameter_file
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, SetupErrors, TwinConfig


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A short session (20 poses, each jet swept twice in 11 steps) with jet 3 at 85 %."""
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, hidden_effects=("jet_gain",),
                                               hidden_effect_values=(("jet_gain.gain_3", 0.85),), seed=3))
    plan = calibration_plan(20) + validation_sweeps(0.1, steps_up=5, repetitions=2)
    path = tmp_path_factory.mktemp("diagnose") / "twin.csv"
    write_csv(twin.run_plan(plan).to_dataset(profile, "short twin"), path)
    return path


def test_json_and_report_name_the_hidden_jet_gain(recorded, tmp_path, capsys):
    out = tmp_path / "diagnosis.json"
    report = tmp_path / "report"
    assert main(["diagnose", str(recorded), "--model", "cosserat", "--candidate", "jet_gain", "--candidate",
                 "gravity", "--candidate", "sensor_mounting", "--json", str(out), "--report", str(report)]) == 0
    document = json.loads(out.read_text())
    assert document["verdict"] == "jet_gain"
    assert isinstance(document["noise_floor_deg"], float) and document["noise_floor_deg"] > 0.0
    assert [entry["effect"] for entry in document["ranking"]][0] == "jet_gain"
    assert {entry["effect"] for entry in document["ranking"]} == {"jet_gain", "gravity", "sensor_mounting"}
    for entry in document["ranking"]:
        for key in ("heldout_orientation_rmse_deg", "explained_fraction", "score"):
            assert isinstance(entry[key], float), key
    baseline = document["baseline"]
    assert baseline["heldout_orientation_rmse_deg"] > 2.0 * document["noise_floor_deg"]
    assert set(document["evidence"]) == {"loading_unloading", "online_disturbance_correlation",
                                         "residual_correlation", "rmse_by_jet_deg"}
    assert document["noise"]["method"] == "repeatability"
    assert document["split"]["held_out_sweeps"] == [3, 4, 5]
    assert sorted(p.name for p in report.iterdir()) == ["diagnose_ranking.png", "diagnose_signature.png"]
    printed = " ".join(capsys.readouterr().out.split())  # as one line, whatever the terminal's width
    assert "verdict: jet_gain" in printed and "--effect jet_gain -o after.toml" in printed


def test_user_mistakes_give_one_clear_line_and_exit_code_2(recorded, tmp_path, capsys):
    for args, message in (
        (["--effect", "warp_drive"], "unknown effect 'warp_drive'"),
        (["--candidate", "warp_drive"], "unknown effect 'warp_drive'"),
        (["--candidate", f"{tmp_path / 'nowhere.py'}:Effect"], "nowhere.py does not exist"),
        (["--workers", "0"], "--workers must be at least 1"),
        (["--effect", "jet_gain", "--candidate", "jet_gain"], "already a known effect"),
        (["--depth", "0"], "--depth must be at least 1"),
        (["--separating-plan", str(recorded)], "already exists"),
        (["--separating-plan", str(tmp_path / "no" / "plan.toml")], "does not exist"),
        (["--json", str(tmp_path / "same.json"), "--export", str(tmp_path / "same.json")],
         f"{tmp_path / 'same.json'}: named by both --json and --export; give each its own file"),
    ):
        # main() turns a UserError into one line on stderr and exit code 2; anything else
        # would propagate and fail the test.
        assert main(["diagnose", str(recorded), *args]) == 2, args
        error = " ".join(capsys.readouterr().err.split())
        assert message in error, error
    assert main(["diagnose", str(tmp_path / "missing.csv")]) == 2
    assert "missing.csv" in capsys.readouterr().err


def test_the_separating_plan_goes_beside_the_report_and_never_over_an_earlier_one(tmp_path):
    from types import SimpleNamespace

    from hydrojet_bench.analysis.diagnosis.separate import SeparatingPose
    from hydrojet_bench.bench.plan_choice import choose_plan
    from hydrojet_bench.commands.diagnose import _write_separating_plan

    diagnosis = SimpleNamespace(verdict="jet_gain", alternatives=("jet_misalignment",),
                                separating_poses=(SeparatingPose((0.15, 0.0, 0.0), 2.0),
                                                  SeparatingPose((0.0, 0.1, 0.05), 1.0)))
    args = SimpleNamespace(separating_plan=None, report=tmp_path / "report", input=tmp_path / "data.csv")
    (tmp_path / "report").mkdir()
    first = _write_separating_plan(args, diagnosis)
    second = _write_separating_plan(args, diagnosis)
    assert first == tmp_path / "report" / "separating-plan.toml"
    assert second == tmp_path / "report" / "separating-plan-1.toml"
    plan = choose_plan(str(first))
    assert len(plan) == 6 and plan[0].jet_forces_n == (0.15, 0.0, 0.0) and sorted(set(plan.sweeps)) == [0, 1, 2]
    beside_input = _write_separating_plan(SimpleNamespace(separating_plan=None, report=None,
                                                          input=tmp_path / "data.csv"), diagnosis)
    assert beside_input == tmp_path / "separating-plan.toml"


def test_export_writes_the_verdicts_calibrated_parameters_and_never_overwrites(recorded, tmp_path, capsys):
    exported, document = tmp_path / "fitted" / "after.toml", tmp_path / "diagnosis.json"
    assert main(["diagnose", str(recorded), "--candidate", "jet_gain", "--candidate", "gravity",
                 "--export", str(exported), "--json", str(document)]) == 0
    winner = json.loads(document.read_text())["ranking"][0]
    assert winner["effect"] == "jet_gain"
    content = read_parameter_file(exported)
    assert content.model == "cosserat" and content.effects == ("gravity", "jet_gain")
    for name, fitted in winner["parameters"].items():  # the very numbers diagnose scored
        assert content.parameters[name] == fitted["value"]
        assert content.standard_errors[name] == fitted["standard_error"]
    assert set(PARAMETER_NAMES) <= set(content.parameters)
    assert content.calibration["verdict"] == "jet_gain"
    assert content.calibration["heldout_orientation_rmse_deg"] == round(winner["heldout_orientation_rmse_deg"], 4)
    printed = capsys.readouterr().out
    assert f"--params {exported} --baseline before.toml" in printed and "--fit-on all -o before.toml" in printed
    before = exported.read_text()
    assert main(["diagnose", str(recorded), "--candidate", "jet_gain", "--export", str(exported)]) == 2
    assert str(exported) in capsys.readouterr().err and exported.read_text() == before


def test_a_turned_base_sensor_gets_a_corrected_profile_that_leaves_nothing_to_explain(tmp_path, capsys):
    """The corrected profile --export-profile writes, used on the same recording, leaves
    the model at the noise floor: verdict none."""
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, setup=SetupErrors(base_sensor_rotvec_rad=(0.0, 0.0, 0.1)),
                                               seed=6))
    plan = calibration_plan(16, seed=1) + validation_sweeps(0.15, steps_up=4, repetitions=2)
    recording, fixed, first, second = (tmp_path / name for name in ("turned.csv", "fixed.toml", "1.json", "2.json"))
    write_csv(twin.run_plan(plan).to_dataset(profile, "turned base sensor"), recording)
    assert main(["diagnose", str(recording), "--candidate", "sensor_mounting", "--json", str(first),
                 "--export-profile", str(fixed)]) == 0
    document = json.loads(first.read_text())
    assert (document["verdict_kind"], document["verdict"]) == ("setup", "base_sensor_mounting")
    assert document["setup"]["fix"]["profile_key"] == "base_sensor.rotation_in_base"
    printed = " ".join(capsys.readouterr().out.split())
    assert "base_sensor.rotation_in_base = [" in printed
    # Next: the profile just written, not the default name of one to write.
    assert f"check the corrected profile with hydrojet-bench diagnose {recording} --profile {fixed}" in printed
    assert main(["diagnose", str(recording), "--profile", str(fixed), "--candidate", "sensor_mounting",
                 "--json", str(second)]) == 0
    again = json.loads(second.read_text())
    assert (again["verdict_kind"], again["verdict"]) == ("none", "none")
    assert again["baseline"]["heldout_orientation_rmse_deg"] <= 1.2 * again["noise_floor_deg"]


def test_a_setup_verdict_tied_with_physics_asks_for_the_separating_measurement_first():
    """A tracker tilt tied with a tip pull (4 BIC points apart on a hanging rod): writing
    the corrected profile first could write a wrong correction."""
    from argparse import Namespace
    from types import SimpleNamespace

    from rich.console import Console

    from hydrojet_bench.commands.diagnose import print_next_steps

    def next_lines(alternatives):
        diagnosis = SimpleNamespace(verdict="tracker_tilt", verdict_kind="setup", alternatives=alternatives,
                                    model="cosserat", setup_fix=SimpleNamespace(profile_key="gravity.in_tracker_m_s2"))
        console = Console(record=True, width=400)
        print_next_steps(console, diagnosis, Namespace(input="s.csv", profile=None, effect=[], export_profile=None),
                         [], None)
        return " ".join(console.export_text().split())

    assert next_lines(("tip_pull",)).startswith(
        "Next: first tell tracker_tilt from tip_pull (hold the jets off and compare the base IMU's gravity with "
        "the profile's (run's level check)); if it is the setup, write the corrected profile")
    assert next_lines(("base_sensor_mounting",)).startswith("Next: write the corrected profile and check it with")


def test_a_fit_on_its_bound_is_said_in_the_table_and_an_effect_text_prints_as_written(recorded, tmp_path, capsys):
    """The notes of a fit ("[gain_3 at its bound ...]") and a user effect's explanation are
    text, not rich markup: printed as markup, the bracketed note vanished from the table."""
    effect_file = tmp_path / "narrow_gain.py"
    effect_file.write_text(
        "import numpy as np\n"
        "from hydrojet_bench.effects import EffectParameter\n"
        "class NarrowGain:\n"
        "    name = 'narrow_gain'\n"
        "    explanation = 'jet 3 weaker [/notes] [bold]as written[/bold]'\n"
        "    parameters = (EffectParameter('gain_3', 1.0, 0.87, 1.05, '1', 'jet 3 force scale'),)\n"
        "    uses_actuation = False\n"
        "    def apply(self, problem, values):\n"
        "        problem.jet_gains = problem.jet_gains * np.array([1.0, 1.0, values['gain_3']])\n")
    out = tmp_path / "diagnosis.json"
    assert main(["diagnose", str(recorded), "--model", "cosserat", "--candidate", f"{effect_file}:NarrowGain",
                 "--json", str(out)]) == 0
    (entry,) = json.loads(out.read_text())["ranking"]
    assert entry["at_bound"] == ["narrow_gain.gain_3"] and entry["notes"]
    printed = " ".join(capsys.readouterr().out.split())
    assert f"[{entry['notes'][0]}]" in printed
    assert "jet 3 weaker [/notes] [bold]as written[/bold]" in printed


def test_candidates_that_leave_out_the_library_say_so_in_the_verdict(recorded, tmp_path, capsys):
    """Jet 3 at 85 % with the jet gains left out of the candidates: a setup hypothesis
    wins for want of the effect that is there, and the verdict says what was not tried."""
    out = tmp_path / "narrow.json"
    assert main(["diagnose", str(recorded), "--candidate", "tip_pull", "--json", str(out)]) == 0
    document = json.loads(out.read_text())
    assert "jet_gain" in document["untried_library_effects"]
    assert "tip_pull" not in document["untried_library_effects"]
    assert "Only the candidates given were tried" in document["explanation"]
    capsys.readouterr()


def test_an_unexplained_verdict_from_narrowed_candidates_sends_to_the_rest_of_the_library(tmp_path, capsys):
    """A sheared rod (shear_extension hidden at 3) tried against base_hysteresis alone."""
    data = tmp_path / "sheared.csv"
    assert main(["simulate", "-o", str(data), "--hidden", "shear_extension=3"]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(data), "--candidate", "base_hysteresis"]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "verdict: unexplained" in printed
    assert "none of the effects tried removes half of the excess" in printed
    assert "not among the candidates (gravity, jet_gain" in printed and "outside the library" not in printed
    assert f"Next: try the rest of the library (--candidate narrowed the candidates) with hydrojet-bench diagnose " \
           f"{data} --model cosserat" in printed
