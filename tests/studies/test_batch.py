"""`batch diagnose` and `batch replay` on the study engine: one row per log, a bad log
recorded as its row's error while the others finish."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from hydrojet_bench.data.csv_io import write_csv
from hydrojet_bench.profile import load_profile
from hydrojet_bench.studies.cell import study_plan
from hydrojet_bench.twin import DigitalTwin, TwinConfig


def batch(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "batch", *args], capture_output=True,
                          text=True, timeout=240)


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    folder = tmp_path_factory.mktemp("logs")
    profile = load_profile("sim")
    paths = []
    for name, values in (("plain", ()), ("weak_jet", (("jet_gain.gain_1", 0.7),))):
        config = TwinConfig.from_profile(profile, hidden_effects=("jet_gain",), hidden_effect_values=values)
        recording = DigitalTwin(config).run_plan(study_plan("short", 0), record_window_s=1.0)
        path = folder / f"{name}.csv"
        write_csv(recording.to_dataset(profile, name), path)
        paths.append(path)
    broken = folder / "broken.csv"
    broken.write_text("this is no measurement file\n1,2,3\n")
    return [*paths, broken]


def test_batch_diagnose_gives_one_row_per_log(logs: list[Path], tmp_path: Path):
    out = tmp_path / "rows"
    broken = tmp_path / "broken.csv"
    broken.write_bytes(logs[2].read_bytes())
    logs = [*logs[:2], broken]
    result = batch("diagnose", *map(str, logs), "--json", "-", "-o", str(out))
    assert result.returncode == 1, result.stderr  # one log failed
    rows = json.loads(result.stdout)
    assert [Path(row["log"]).name for row in rows] == ["plain.csv", "weak_jet.csv", "broken.csv"]
    assert [row["verdict"] for row in rows] == ["none", "jet_gain", None]
    assert rows[0]["error"] is None and rows[1]["error"] is None
    assert "broken.csv" in rows[2]["error"] and "Traceback" not in rows[2]["error"]
    assert rows[1]["baseline_heldout_rmse_deg"] > 5 * rows[1]["noise_floor_deg"]
    # What a study's row says of the verdict's fits, a batch's says too.
    assert [(row["converged"], row["bound_clipped"], row["unconverged_fits"]) for row in rows[:2]] == \
        [(True, False, 0), (True, False, 0)]
    assert len(list((out / "rows").glob("*.parquet"))) == 3
    assert "weak_jet.csv" in result.stderr  # the table goes to stderr when JSON takes stdout

    # Rerun into the same folder: a log given twice is analysed once, one unchanged is
    # reused, and one rewritten since (the broken one, now another rig's table read with
    # the default profile) is analysed again and its mismatch said.
    broken.write_text(logs[1].read_text().replace("# rig profile: sim (", "# rig profile: horiz (", 1))
    again = batch("diagnose", str(logs[0]), str(logs[0].parent / ".." / logs[0].parent.name / "plain.csv"),
                  str(broken), "--json", "-", "-o", str(out))
    assert again.returncode == 0, again.stderr
    err = " ".join(again.stderr.split())
    assert "plain.csv is given more than once: analysed once" in err
    assert "1 logs analysed (1 already done" in err
    assert f"warning: {broken} was recorded with rig profile horiz" in err
    plain, rewritten = json.loads(again.stdout)
    assert plain == rows[0] and rewritten["verdict"] == "jet_gain" and rewritten["error"] is None
    assert rewritten["profile_mismatch"].startswith(f"{broken} was recorded with rig profile horiz")


TINY_PLAN = "settle_s = 2.0\n" + "".join(
    f"[[step]]\nq1 = {q1}\nq2 = {q2}\nq3 = 0.0\nsweep = {sweep}\nstep = {step}\n"
    for q1, q2, sweep, step in ((0.02, 0.0, -1, 0), (0.0, 0.03, -1, 1), (0.04, 0.0, 0, 0), (0.0, 0.05, 0, 1)))


def test_batch_replay_reproduces_the_live_estimates_and_says_which_log_was_cut(logs: list[Path], tmp_path: Path):
    plan = tmp_path / "tiny.toml"
    plan.write_text(TINY_PLAN)
    session = tmp_path / "session.mcap"
    run = subprocess.run([sys.executable, "-m", "hydrojet_bench.cli", "run", "--plan", str(plan), "--no-live",
                          "--time-scale", "10", "--log", str(session)], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    cut = tmp_path / "cut.mcap"
    data = session.read_bytes()
    cut.write_bytes(data[:int(0.9 * len(data))])  # the summary and footer gone
    result = batch("replay", str(session), str(cut), "--json", "-", "--workers", "1")
    assert result.returncode == 0, result.stderr
    replayed, truncated = json.loads(result.stdout)
    assert replayed["error"] is None and replayed["steps"] == 4 and replayed["model"] == "cosserat"
    # The plan's one sweep (two steps) scored, none left out, as replay counts them.
    assert (replayed["scored_steps"], replayed["skipped_steps"]) == (2, 0)
    assert replayed["live_difference_deg"] == 0.0 and 0.0 < replayed["validation_orientation_rmse_deg"] < 10.0
    assert replayed["log_damage"] is None and not replayed["truncated"]
    assert truncated["truncated"] and truncated["log_damage"].startswith(f"{cut}: it is truncated")
    assert f"warning: {cut}: it is truncated" in " ".join(result.stderr.split())
    # A table holds no live estimation to replay: refused before any work, in one line.
    refused = batch("replay", str(session), str(logs[0]))
    assert refused.returncode == 2 and refused.stderr.strip() == (
        f"error: {logs[0]}: not an MCAP session log; replay re-runs a session's live estimation, which only its log "
        "holds (batch diagnose takes CSV tables)")


def test_batch_of_a_missing_log_is_one_line(tmp_path: Path):
    result = batch("diagnose", str(tmp_path / "nowhere.csv"))
    assert result.returncode == 2 and "nowhere.csv: no such log" in result.stderr and "Traceback" not in result.stderr


def test_batch_exits_as_the_single_commands_do():
    from hydrojet_bench.commands.batch import exit_code

    diagnosed = {"log": "a.csv", "error": None, "verdict": "none"}
    assert exit_code([diagnosed]) == 0
    # diagnose exits 3 on an undecided verdict; replay 1 on errors that are not finite.
    assert exit_code([diagnosed, {**diagnosed, "verdict": "undecided"}]) == 3
    replayed = {"log": "a.mcap", "error": None, "validation_orientation_rmse_deg": 0.2}
    assert exit_code([replayed]) == 0
    assert exit_code([replayed, {**replayed, "validation_orientation_rmse_deg": None}]) == 1
    assert exit_code([replayed, {**replayed, "validation_orientation_rmse_deg": float("inf")}]) == 1
    # A failed log outranks an undecided one.
    assert exit_code([{**diagnosed, "verdict": "undecided"}, {**diagnosed, "verdict": None, "error": "x"}]) == 1


def test_a_bad_profile_is_refused_before_the_cluster_starts(logs: list[Path]):
    result = batch("diagnose", str(logs[0]), "--profile", "nope")
    assert result.returncode == 2 and result.stdout == ""
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("error: --profile nope: rig profile 'nope'")


def test_rows_stored_before_a_kind_gained_columns_are_kept(tmp_path: Path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    from hydrojet_bench.studies.batch import DIAGNOSE_COLUMNS, LogTask, log_row
    from hydrojet_bench.studies.store import RowStore

    store = RowStore(tmp_path, DIAGNOSE_COLUMNS, "log_id")
    store.rows_folder.mkdir(parents=True, exist_ok=True)
    old = {name: kind for name, kind in DIAGNOSE_COLUMNS.items() if name not in ("converged", "bound_clipped")}
    row = {**log_row(LogTask("/x.csv"), old), "verdict": "none"}
    pq.write_table(pa.Table.from_pylist([row], schema=pa.schema([(n, pa.type_for_alias(k)) for n, k in old.items()])),
                   store.rows_folder / f"{row['log_id']}.parquet")
    table = store.table()
    assert list(table.columns) == list(DIAGNOSE_COLUMNS) and table["verdict"].tolist() == ["none"]
    assert table["converged"].isna().all()
