"""`study` on a LocalCluster of 2 workers: every cell diagnosed, a failing cell recorded
with its error while the others finish, the report written and rebuilt."""

from __future__ import annotations

import json
from pathlib import Path

from study_helpers import TINY, run_study, stored_rows, write_spec


def test_local_cluster_records_every_cell_and_the_failing_one(spec_with_boom: Path, tmp_path: Path):
    out = tmp_path / "out"
    result = run_study(str(spec_with_boom), "-o", str(out), "--workers", "2", "--csv")
    assert result.returncode == 1, result.stderr  # a cell failed: no whole answer
    assert "warning: 2 of 6 cells failed" in " ".join(result.stderr.split())
    rows = stored_rows(out)
    assert len(rows) == 6 and rows["cell_id"].is_unique
    failed = rows[rows["error"].notna()]
    assert sorted(failed["truth"]) == ["boom", "boom"]
    assert all("boom inside the twin" in text for text in failed["error"])
    good = rows[rows["error"].isna()]
    assert set(good["truth"]) == {"none", "jet_gain"}
    assert good["verdict"].notna().all() and (good["seconds"] > 0).all()
    # A 30 % weaker jet is far above the noise: the short plan finds it, and names nothing without it.
    assert (good[good["truth"] == "jet_gain"]["verdict"] == "jet_gain").all()
    assert (good[good["truth"] == "none"]["verdict"] == "none").all()
    assert "6 cells run (0 already done), 2 failed" in " ".join(result.stdout.split())
    assert "study " in result.stderr and "study " not in result.stdout  # progress on standard error
    assert (out / "rows.csv").read_text().count("\n") == 7
    report = out / "report"
    for name in ("confusion.png", "power.png", "plans.png", "summary.md"):
        assert (report / name).stat().st_size > 0
    summary = (report / "summary.md").read_text()
    assert "| jet_gain | 2 | 0 |" in summary and "boom inside the twin" in summary

    (report / "summary.md").unlink()
    rebuilt = run_study("--report-only", str(out), "--json", "-")
    assert rebuilt.returncode == 1, rebuilt.stderr
    assert (report / "summary.md").read_text() == summary
    document = json.loads(rebuilt.stdout)  # the JSON alone on standard output
    assert document["outcome"] is None and len(document["rows"]) == 6
    assert str(report / "summary.md") in document["files"] and f"wrote {report / 'summary.md'}" in rebuilt.stderr

    # The spec without its failing effect: its 4 cells are done, and the 2 rows of cells it
    # no longer has are said to be left out, not reported as its own.
    without_boom = write_spec(tmp_path, TINY, name="without_boom.toml")
    rerun = run_study(str(without_boom), "-o", str(out), "--json", "-")
    assert rerun.returncode == 0, rerun.stderr
    document = json.loads(rerun.stdout)
    assert document["outcome"]["skipped"] == 4 and document["rows_left_out"] == 2
    assert {row["truth"] for row in document["rows"]} == {"none", "jet_gain"} and len(document["rows"]) == 4
    assert "warning: 2 row(s) under" in " ".join(rerun.stderr.split())
    assert "boom" not in (report / "summary.md").read_text()
    # Rebuilt without the spec, the report still leaves them out.
    rebuilt = run_study("--report-only", str(out), "--json", "-")
    assert rebuilt.returncode == 0, rebuilt.stderr
    assert len(json.loads(rebuilt.stdout)["rows"]) == 4 and "boom" not in (report / "summary.md").read_text()
    assert "warning: 2 row(s) under" in " ".join(rebuilt.stderr.split())
    # The failed cells are tried again when their spec runs again.
    again = run_study(str(spec_with_boom), "-o", str(out))
    assert again.returncode == 1
    assert "2 cells run (4 already done), 2 failed" in " ".join(again.stdout.split())
