"""The Python API (`hydrojet_bench.api`, re-exported at the top level): the README
tutorial as a script, the per-step tables, that a calibration in memory is the parameter
file it saves, and that mistakes raise `UserError` rather than exiting."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from matplotlib.figure import Figure

import hydrojet_bench as hj
from hydrojet_bench.api import StudyResult
from hydrojet_bench.cli import main
from hydrojet_bench.data.csv_io import write_csv
from hydrojet_bench.errors import UserError
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig

TUTORIAL = Path(__file__).resolve().parents[1] / "docs/examples/notebook_tutorial.py"


@pytest.fixture(scope="module")
def mystery(tmp_path_factory) -> Path:
    """A short session on the tutorial's rig (20 poses, each jet swept twice in 11 steps)."""
    profile = load_profile("sim-mystery")
    plan = calibration_plan(20) + validation_sweeps(0.1, steps_up=5, repetitions=2)
    path = tmp_path_factory.mktemp("api") / "mystery.csv"
    write_csv(DigitalTwin(TwinConfig.from_profile(profile)).run_plan(plan).to_dataset(profile, "mystery"), path)
    return path


def test_the_notebook_tutorial_finds_the_effect_and_the_error_falls(mystery, tmp_path):
    figures = tmp_path / "figures"
    result = subprocess.run([sys.executable, "-W", "error", str(TUTORIAL), str(mystery), "sim-mystery", str(figures)],
                            capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "verdict: pressure_stiffening" in result.stdout
    last = result.stdout.strip().splitlines()[-1]
    old, new = (float(word) for word in last.split() if word.replace(".", "").isdigit())
    assert new < 0.2 * old, last
    assert sorted(path.name for path in figures.iterdir()) == ["compare.png", "diagnose.png"]


def test_per_step_tables_hold_commands_poses_and_errors(mystery, tmp_path):
    data = hj.load(mystery, "sim-mystery")
    measured = data.to_pandas()
    assert len(measured) == len(data.steps) == 86
    np.testing.assert_array_equal(measured[["q1_n", "q2_n", "q3_n"]].to_numpy(), data.steps.jet_forces_n)
    np.testing.assert_array_equal(measured[["measured_qw", "measured_qx", "measured_qy", "measured_qz"]].to_numpy(),
                                  data.steps.tip_orientation_in_base())

    calibration = hj.calibrate(data, effects=["pressure_stiffening"])
    saved = calibration.save(tmp_path / "after.toml")
    in_memory = hj.compare(data, calibration, online=True)
    from_file = hj.compare(data, saved, online=True)
    assert in_memory.model.name == from_file.model.name == "cosserat"
    assert [e.name for e in in_memory.model.effects] == [e.name for e in from_file.model.effects]
    table = in_memory.to_pandas()
    np.testing.assert_array_equal(table.drop(columns="method").to_numpy(),
                                  from_file.to_pandas().drop(columns="method").to_numpy())
    assert list(table["method"].unique()) == ["ref", "online"] and len(table) == 2 * len(in_memory.steps)
    for method, comparison in in_memory.results.items():
        rows = table[table["method"] == method]
        np.testing.assert_array_equal(rows["orientation_error_deg"], comparison.orientation_error_deg)
        np.testing.assert_array_equal(rows["position_error_mm"], comparison.position_error_mm)
        np.testing.assert_array_equal(rows[["predicted_x_mm", "predicted_y_mm", "predicted_z_mm"]].to_numpy(),
                                      comparison.predictions.tip_position_in_base_m * 1e3)
    overall = in_memory.table_ii().set_index(["method", "group"])
    assert overall.loc[("ref", "all"), "orientation_rmse_deg"] == in_memory.results["ref"].overall.orientation_rmse_deg
    # as_dict holds the figures compare --json writes.
    document = tmp_path / "compare.json"
    assert main(["compare", str(mystery), "--profile", "sim-mystery", "--params", str(saved), "--online", "--json",
                 str(document)]) == 0
    written, as_dict = json.loads(document.read_text()), json.loads(json.dumps(in_memory.as_dict()))
    for figure in ("orientation_rmse_deg", "position_rmse_mm", "by_sweep", "by_bend"):
        assert as_dict[figure] == written[figure], figure

    # pressure_stiffening shows only over the sweeps' range of forces: fitted on poses and sweeps.
    fitted = calibration.to_pandas()
    assert calibration.parameter_file.calibration["fit_on"] == "all"
    assert (fitted["sweep"] == -1).sum() == 20 and (fitted["sweep"] >= 0).sum() == len(fitted) - 20 > 0
    assert np.sqrt(np.mean(fitted["orientation_error_deg"] ** 2)) < 2 * calibration.fit.rms_orientation_deg_after + 0.1
    poses = hj.calibrate(data).to_pandas()
    assert (poses["sweep"] == -1).all() and len(poses) == 20
    for figure in (data.plot(), calibration.plot(), in_memory.plot()):
        assert isinstance(figure, Figure)
        assert figure.get_suptitle() or figure.axes[0].get_title()
        assert all(axes.get_ylabel() for axes in figure.axes)


@pytest.mark.parametrize(("call", "message"), [
    (lambda data, tmp: hj.load(tmp / "missing.csv"), "missing.csv"),
    (lambda data, tmp: hj.load(tmp / "data.txt"), "unknown data format"),
    (lambda data, tmp: hj.calibrate(data, effects=["warp_drive"]), "unknown effect 'warp_drive'"),
    (lambda data, tmp: hj.calibrate(data, position_weight_rad_per_m=-1.0),
     "position_weight_rad_per_m must be a finite number >= 0, got -1.0"),
    (lambda data, tmp: hj.calibrate(data, position_weight_rad_per_m="1"), "position_weight_rad_per_m must be"),
    (lambda data, tmp: hj.calibrate(data, position_weight_rad_per_m=float("inf")), "position_weight_rad_per_m"),
    (lambda data, tmp: hj.compare(data, tmp / "none.toml"), "no such parameter file"),
    (lambda data, tmp: hj.diagnose(data, workers=0), "workers must be at least 1"),
    (lambda data, tmp: hj.diagnose(data, workers="2"), "workers must be a whole number of processes, got '2'"),
    (lambda data, tmp: hj.study(tmp / "none.toml", tmp / "out", workers=1.5), "workers must be a whole number"),
    (lambda data, tmp: hj.replay(tmp / "none.mcap"), "none.mcap"),
    (lambda data, tmp: hj.study(tmp / "none.toml"), "none.toml"),
    (lambda data, tmp: hj.study(report_only=True), "give output=DIR"),
    (lambda data, tmp: hj.study(tmp / "none.toml", tmp, report_only=True), "give spec or report_only, not both"),
])
def test_mistakes_raise_user_error_naming_the_file_or_argument(mystery, tmp_path, call, message):
    (tmp_path / "data.txt").write_text("t,q1\n")
    with pytest.raises(UserError, match=message.replace(".", r"\.").replace("(", r"\(")):
        call(mystery, tmp_path)
    assert not (tmp_path / "out").exists()  # refused before anything is written


def test_a_study_result_tables_and_plots_its_confusion(tmp_path):
    rows = pd.DataFrame({"truth": ["none", "jet_gain", "jet_gain", "boom"], "verdict": ["none", "jet_gain", "none", None],
                         "error": [None, None, None, "boom inside the twin"]})
    result = StudyResult("tiny", tmp_path, rows, None)
    confusion = result.confusion()
    assert confusion.loc["jet_gain", "jet_gain"] == 1 and confusion.loc["jet_gain", "none"] == 1
    assert "boom" not in confusion.index  # failed cells have no verdict to count
    figure = result.plot()
    assert figure.axes[0].get_xlabel() == "verdict" and figure.axes[0].get_ylabel() == "hidden truth"
    assert result.to_pandas() is not rows and result.to_pandas().equals(rows)


def test_the_diagnosis_table_says_what_the_command_table_says_of_each_fit(mystery):
    """Whether each fit converged, why, and what sits on a bound: an unconverged fit
    ranks last, and the table says why, as `diagnose` prints it."""
    result = hj.diagnose(mystery, workers=1)
    table = result.to_pandas()
    ranking = result.diagnosis.ranking
    assert list(table["effect"]) == [c.effect for c in ranking]
    assert list(table["converged"]) == [c.converged for c in ranking]
    assert list(table["convergence"]) == [c.convergence for c in ranking]
    assert list(table["at_bound"]) == [", ".join(c.at_bound) for c in ranking]
    winner = table.iloc[0]
    assert winner["effect"] == "pressure_stiffening" and winner["converged"]
    assert set(winner["parameters"]) == set(ranking[0].parameters)


def test_a_study_without_diagnosed_cells_has_nothing_to_plot(tmp_path):
    rows = pd.DataFrame({"truth": ["boom"], "verdict": [None], "error": ["boom inside the twin"]})
    with pytest.raises(UserError, match="study tiny: no diagnosed cells in .*, nothing to plot"):
        StudyResult("tiny", tmp_path, rows, None).plot()


def test_a_study_called_by_a_worker_importing_the_script_asks_for_the_main_guard(monkeypatch, tmp_path):
    import multiprocessing

    # How multiprocessing marks a spawned child while it imports the parent's script.
    monkeypatch.setattr(multiprocessing.current_process(), "_inheriting", True, raising=False)
    with pytest.raises(UserError, match='put the call under `if __name__ == "__main__":`'):
        hj.study(tmp_path / "spec.toml", tmp_path / "out")
    assert not (tmp_path / "out").exists()
