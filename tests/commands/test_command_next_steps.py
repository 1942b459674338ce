"""Every command a command prints as the next step runs as printed.

One twin recording with a user's effect hidden (a clogged jet, from a file in a folder
of its own): `simulate` suggests `diagnose`, which suggests the calibrations and the
compare of the add step, and `calibrate` suggests `compare`; a parameter file written
to another folder must still find the effect file.
Each printed command is collected and run, in the folder the user would be in,
expecting exit 0; so is every command those print, until none is new.
"""

from __future__ import annotations

import json
import shlex
import shutil
from pathlib import Path

import pytest

from hydrojet_bench.cli import main

EXAMPLE = Path(__file__).resolve().parents[2] / "docs/examples/clogged_jet.py"


def printed_commands(output: str) -> list[list[str]]:
    """The argument lists of the lines a command printed as ``hydrojet-bench ...``."""
    return [shlex.split(line, comments=True)[1:] for line in output.splitlines()
            if line.strip().startswith("hydrojet-bench ")]


def run_all_printed(first: list[str], capsys, json_of: tuple[str, ...] = ()) -> list[list[str]]:
    """Run ``first`` and every command printed by it or by those it leads to; returns
    every command run, in order. The commands named in ``json_of`` also write their
    JSON, to ``<name>-<k>.json`` for the k-th command run (what they print is the same)."""
    pending, done = [first], []
    while pending:
        argv = pending.pop(0)
        if argv in done:
            continue
        capsys.readouterr()
        code = main([*argv, *(["--json", f"{argv[0]}-{len(done)}.json"] if argv[0] in json_of else [])])
        captured = capsys.readouterr()
        assert code == 0, (argv, captured.err)
        done.append(argv)
        pending += [command for command in printed_commands(captured.out) if command not in done]
    return done


def test_every_printed_next_command_runs_as_printed(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "effects").mkdir()
    shutil.copy(EXAMPLE, tmp_path / "effects" / "clogged_jet.py")
    effect = "effects/clogged_jet.py:CloggedJet"
    # Each command runs once (a diagnosis takes most of this test), its JSON written on the way.
    ran = run_all_printed(["simulate", "-o", "data.csv", "--hidden", effect, "--seed", "2"], capsys,
                          ("diagnose", "compare"))
    names = [argv[0] for argv in ran]
    assert names[:2] == ["simulate", "diagnose"]
    # diagnose names an effect: both calibrations of the add step, the compare, and the
    # compare each calibration suggests.
    assert names.count("calibrate") == 2 and names.count("compare") >= 2, ran
    assert any("--baseline" in argv for argv in ran)

    # The add step shows what diagnose said it would: the figures diagnose computed for
    # the printed compare are the ones that compare prints.
    preview = json.loads((tmp_path / "diagnose-1.json").read_text())["add_step"]
    compared = next(k for k, argv in enumerate(ran) if argv[0] == "compare" and "--baseline" in argv)
    shown = json.loads((tmp_path / f"compare-{compared}.json").read_text())
    assert shown["baseline"]["as_diagnosed"]["orientation_rmse_deg"] == pytest.approx(preview["compare_before_deg"],
                                                                                      rel=1e-6)
    assert shown["as_diagnosed"]["orientation_rmse_deg"] == pytest.approx(preview["compare_after_deg"], rel=1e-6)

    # A parameter file written to another folder finds the user's effect file relative
    # to itself, so the compare calibrate prints runs from where the user is.
    ran = run_all_printed(["calibrate", "data.csv", "--effect", effect, "-o", "out/p.toml"], capsys)
    assert 'effects = ["gravity", "../effects/clogged_jet.py:CloggedJet"]' in (tmp_path / "out/p.toml").read_text()
    assert [argv[0] for argv in ran] == ["calibrate", "compare"]
