"""`calibrate` fits an effect on the rows that identify it: clamp play shows only along a
path that loads and unloads, so `base_hysteresis` gets the calibration poses and the
sweeps by default; `--fit-on` chooses; the command says which rows it used."""

from __future__ import annotations

import json

import pytest

from hydrojet_bench.cli import main
from hydrojet_bench.data.csv_io import write_csv
from hydrojet_bench.effects import CALIBRATION_POSES, LIBRARY, SWEEPS, identifying_rows
from hydrojet_bench.estimation.calibration import ALL_ROWS, rows_that_identify
from hydrojet_bench.params_io import read_parameter_file
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig

PLAY_RAD, COMPLIANCE_RAD_PER_NM = 0.02, 20.0


@pytest.fixture(scope="module")
def hysteretic(tmp_path_factory):
    """20 calibration poses, then each jet swept up and down once in 11 steps, on a
    clamp with play."""
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(
        profile, hidden_effects=("base_hysteresis",), seed=6,
        hidden_effect_values=(("base_hysteresis.compliance_rad_per_nm", COMPLIANCE_RAD_PER_NM),
                              ("base_hysteresis.play_rad", PLAY_RAD))))
    plan = calibration_plan(20, seed=6) + validation_sweeps(steps_up=5, repetitions=1)
    path = tmp_path_factory.mktemp("calibrate") / "hysteresis.csv"
    write_csv(twin.run_plan(plan, record_window_s=1.0).to_dataset(profile, "short twin"), path)
    return path


def test_every_library_effect_says_which_rows_identify_it():
    rows = {name: identifying_rows(effect()) for name, effect in LIBRARY.items()}
    assert set(rows.values()) <= {CALIBRATION_POSES, SWEEPS}
    assert {name for name, value in rows.items() if value == SWEEPS} == {"base_hysteresis", "pressure_stiffening"}
    assert rows_that_identify([LIBRARY["jet_gain"]()]) == CALIBRATION_POSES
    assert rows_that_identify([LIBRARY["jet_gain"](), LIBRARY["base_hysteresis"]()]) == ALL_ROWS


def test_clamp_play_is_fitted_on_poses_and_sweeps_by_default(hysteretic, tmp_path, capsys):
    output = tmp_path / "after.toml"
    assert main(["calibrate", str(hysteretic), "--effect", "base_hysteresis", "-o", str(output)]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "fitted on 20 calibration poses and 33 steps of 3 sweeps (base_hysteresis cannot be identified" in printed
    content = read_parameter_file(output)
    assert content.calibration["fit_on"] == ALL_ROWS
    assert (content.calibration["poses"], content.calibration["sweep_steps"]) == (20, 33)
    assert content.parameters["base_hysteresis.play_rad"] == pytest.approx(PLAY_RAD, rel=0.15)
    assert content.parameters["base_hysteresis.compliance_rad_per_nm"] == pytest.approx(COMPLIANCE_RAD_PER_NM,
                                                                                         rel=0.15)


@pytest.mark.parametrize("fit_on, said, poses, sweep_steps", [
    ("calibration", "fitted on 20 calibration poses (--fit-on calibration)", 20, 0),
    ("sweeps", "fitted on 33 steps of 3 sweeps (--fit-on sweeps)", 0, 33),
])
def test_fit_on_chooses_the_rows(hysteretic, tmp_path, capsys, fit_on, said, poses, sweep_steps):
    output = tmp_path / "p.toml"
    assert main(["calibrate", str(hysteretic), "--fit-on", fit_on, "-o", str(output)]) == 0
    assert said in " ".join(capsys.readouterr().out.split())
    content = read_parameter_file(output)
    assert (content.calibration["fit_on"], content.calibration["poses"],
            content.calibration["sweep_steps"]) == (fit_on, poses, sweep_steps)


def test_a_table_recorded_with_another_profile_is_read_with_the_default_and_a_warning(hysteretic, tmp_path,
                                                                                       capsys):
    elsewhere = tmp_path / "elsewhere.csv"
    elsewhere.write_text(hysteretic.read_text().replace("# rig profile: sim (", "# rig profile: horiz (", 1))
    recorded = f"horiz ({load_profile('sim').path})"
    for table, warned in ((hysteretic, False), (elsewhere, True)):
        document = tmp_path / f"{table.stem}.json"
        assert main(["calibrate", str(table), "-o", str(tmp_path / f"{table.stem}.toml"), "--json",
                     str(document)]) == 0
        err = " ".join(capsys.readouterr().err.split())
        warning = (f"warning: {table} was recorded with rig profile {recorded} (its comments say so) and is read "
                   "with 'sim', the default for a CSV table: give --profile")
        assert (warning in err) == warned, err
        mismatch = json.loads(document.read_text())["profile_mismatch"]
        assert mismatch == ({"recorded": recorded, "used": "sim", "message": warning.removeprefix("warning: ")}
                            if warned else None)
    assert main(["calibrate", str(elsewhere), "--profile", "sim", "-o", str(tmp_path / "chosen.toml")]) == 0
    assert "recorded with rig profile" not in capsys.readouterr().err


def test_steps_of_a_single_sample_are_warned_in_the_output_and_the_json(hysteretic, tmp_path, capsys):
    """A table keeping one row per step (a trajectory logged while the jets move, say) is
    still fitted, but every command that takes its steps for equilibria says how many
    are one sample; the twin's settled table says nothing."""
    from hydrojet_bench.data.csv_io import read_csv

    rows = read_csv(hysteretic, load_profile("sim"))
    single = tmp_path / "single.csv"
    write_csv(rows.select([stop - 1 for _, stop in rows.step_runs()]), single)
    steps = len(list(rows.step_runs()))
    warning = (f"warning: {single}: {steps} of {steps} steps average a single sample (the jets changed at the "
               "next row)")
    for table, warned in ((hysteretic, False), (single, True)):
        params, document = tmp_path / f"{table.stem}.toml", tmp_path / f"{table.stem}.json"
        assert main(["calibrate", str(table), "-o", str(params), "--json", str(document)]) == 0
        assert (warning in " ".join(capsys.readouterr().err.split())) == warned
        expected = {"count": steps, "steps": steps} if warned else None
        assert json.loads(document.read_text())["single_sample_steps"] == expected
        assert main(["compare", str(table), "--params", str(params), "--json", str(document)]) == 0
        assert (warning in " ".join(capsys.readouterr().err.split())) == warned
        assert json.loads(document.read_text())["single_sample_steps"] == expected


def test_steps_whose_tip_still_turned_are_warned_in_the_output_and_the_json(hysteretic, tmp_path, capsys):
    """Commands held 0.4 s, shorter than the rod takes to settle: each step's average
    takes in the rod still moving. calibrate, compare and diagnose say how many; the
    twin's settled table says nothing."""
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, seed=6))
    brief = tmp_path / "brief.csv"
    write_csv(twin.run_plan(calibration_plan(12, seed=6, settle_s=0.4)).to_dataset(profile, "brief twin"), brief)
    warning = (f"warning: {brief}: in 12 of 12 steps the tip was still turning (by more than 0.25 deg) over the "
               "last 1 s")
    for table, warned in ((hysteretic, False), (brief, True)):
        params, document = tmp_path / f"{table.stem}.toml", tmp_path / f"{table.stem}.json"
        main(["calibrate", str(table), "-o", str(params), "--json", str(document)])
        assert (warning in " ".join(capsys.readouterr().err.split())) == warned
        expected = {"count": 12, "steps": 12, "window_s": 1.0, "trend_deg": 0.25} if warned else None
        assert json.loads(document.read_text())["unsettled_steps"] == expected
    assert main(["compare", str(brief), "--params", str(tmp_path / "brief.toml"), "--json",
                 str(tmp_path / "c.json")]) == 0
    assert warning in " ".join(capsys.readouterr().err.split())
    assert json.loads((tmp_path / "c.json").read_text())["unsettled_steps"] == expected


def test_a_value_pushed_onto_its_bound_is_refitted_to_its_limits_or_warned_written_and_exits_3(tmp_path, capsys):
    """A jet 60 % stronger than nominal. Fitted with the library's gains (searched to 1.5,
    physically up to 3), the fit ends on the search bound and is refitted with the search
    widened, as diagnose fits its candidates: exit 0, the gain found. Fitted with a gain
    whose search bound is its physical limit, the file is written, but the command says
    the value sits on its bound and exits 3, not 0."""
    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, hidden_effects=("jet_gain",), seed=3,
                                               hidden_effect_values=(("jet_gain.gain_2", 1.6),)))
    table = tmp_path / "strong.csv"
    write_csv(twin.run_plan(calibration_plan(20, seed=3), record_window_s=1.0).to_dataset(profile, "strong jet"),
              table)
    widened = tmp_path / "widened.toml"
    assert main(["calibrate", str(table), "--effect", "jet_gain", "-o", str(widened)]) == 0
    printed = " ".join(capsys.readouterr().out.split())
    assert "jet_gain.gain_2 ended on its search bound: refitted with the search widened" in printed
    content = read_parameter_file(widened)
    assert content.parameters["jet_gain.gain_2"] == pytest.approx(1.6, abs=0.05)
    assert content.calibration["converged"] is True and "at_bound" not in content.calibration

    capped = tmp_path / "capped_gain.py"
    capped.write_text(
        "import numpy as np\n"
        "from hydrojet_bench.effects import EffectParameter\n"
        "class CappedGain:\n"
        "    name = 'capped_gain'\n"
        "    explanation = 'jet 2 stronger or weaker, at most 1.5 times'\n"
        "    parameters = (EffectParameter('gain_2', 1.0, 0.0, 1.5, '1', 'jet 2 force scale'),)\n"
        "    uses_actuation = False\n"
        "    def apply(self, problem, values):\n"
        "        problem.jet_gains = problem.jet_gains * np.array([1.0, values['gain_2'], 1.0])\n")
    output, document = tmp_path / "p.toml", tmp_path / "p.json"
    assert main(["calibrate", str(table), "--effect", f"{capped}:CappedGain", "-o", str(output),
                 "--json", str(document)]) == 3
    printed = capsys.readouterr()
    warning = "warning: capped_gain.gain_2 = 1.5 sits on its bound (0 to 1.5)"
    assert warning in " ".join(printed.err.split()) and warning not in " ".join(printed.out.split())
    content = read_parameter_file(output)
    assert content.calibration["at_bound"] == ["capped_gain.gain_2"]
    assert json.loads(document.read_text())["calibration"]["at_bound"] == ["capped_gain.gain_2"]


def test_a_converged_fit_says_so_in_the_file(hysteretic, tmp_path):
    output = tmp_path / "p.toml"
    assert main(["calibrate", str(hysteretic), "-o", str(output)]) == 0
    calibration = read_parameter_file(output).calibration
    assert calibration["converged"] is True and "at_bound" not in calibration
    assert calibration["convergence"].startswith("converged: ")
