"""Bad inputs through the command line: mutated CSV tables, profiles, parameter files,
plan files and effect files, from small valid seeds.

The invariant, for every input: the command exits 0, or exits 2 with one line that names
the mutated file; it never prints a traceback (an exception escaping `main`), never exits
otherwise, and never changes an input file. Commands run in-process for speed.

Set HYDROJET_FUZZ_COUNTS=path.json to get the counts (inputs tried, clean errors,
successes) per target; run with -s to see them printed.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
from collections import Counter
from collections.abc import Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hydrojet_bench.cli import main
from hydrojet_bench.config.loading import PROFILES_DIR
from hydrojet_bench.data.csv_io import write_csv
from hydrojet_bench.params_io import read_parameter_file
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig

COUNTS: dict[str, Counter] = {}

# Values a user (or a corrupted file) puts where a number or a name belongs.
TOML_VALUES = ["1e308", "-1e308", "1e-308", "0", "-1", "nan", "inf", "-inf", '"x"', "true", "[]", "[1.0, 2.0]",
               "1_000", '"[/x]"', '"[bold]y"', "{}", "0.3", "7.0", "1e30", '"tcp://h:1"', '"serial:///dev/x?baud=fast"']
CSV_CELLS = ["1e308", "1e-308", "nan", "inf", "-1", "", "abc", "1_000", "[/x]", "0x10", "1,2", "-0", "2", "0.3"]
BYTES = [b"\xff", b"\xe9", b"\x00", b"[/x]", b"[bold]", b"\r", b"\n\n", b"=", b"[[step]]\n", b'"']

EFFECT = '''import numpy as np
from hydrojet_bench.effects import EffectParameter


class WaterLineTwist:
    name = "water_line_twist"
    explanation = "the water lines twist the rod"
    parameters = (EffectParameter("moment_nm_m", 0.0, -0.1, 0.1, "N m/m", "twist per length"),)
    uses_actuation = False

    def apply(self, problem, values):
        problem.distributed_moment_in_body_nm_m[:, 2] += values["moment_nm_m"] * 0.5
'''
EFFECT_VALUES = ["5", "None", "np.nan", "1 / 0", '"gravity"', "()", "[1, 2]", "sys.exit(3)", "lambda: 0",
                 "problem.no_such_field", "values", "raise ValueError('[/x]')", "np.inf * values['moment_nm_m']"]


@pytest.fixture(scope="module")
def seeds() -> Iterator[Path]:
    """A folder with small valid inputs: data.csv (12 calibration poses, 6 sweep steps),
    params.toml calibrated on it, rig.toml (the sim profile), plan.toml and plan.csv
    (two short steps), effect.py."""
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        profile = load_profile("sim")
        twin = DigitalTwin(TwinConfig.from_profile(profile))
        plan = calibration_plan(12, settle_s=5.0) + validation_sweeps(steps_up=2, repetitions=1, settle_s=5.0)
        write_csv(twin.run_plan(plan, sample_rate_hz=10.0, record_window_s=0.3).to_dataset(profile, "fuzz seed"),
                  folder / "data.csv")
        outcome = invoke(["calibrate", str(folder / "data.csv"), "-o", str(folder / "params.toml")])
        assert outcome[0] == 0, outcome
        (folder / "rig.toml").write_text((PROFILES_DIR / "sim.toml").read_text())
        (folder / "plan.toml").write_text("[[step]]\nq1 = 0.05\nq2 = 0.0\nq3 = 0.0\nsettle_s = 2.0\n"
                                          "[[step]]\nq1 = 0.0\nq2 = 0.05\nq3 = 0.0\nsettle_s = 2.0\n")
        (folder / "plan.csv").write_text("q1,q2,q3,settle_s\n0.05,0,0,2.0\n0,0.05,0,2.0\n")
        (folder / "effect.py").write_text(EFFECT)
        yield folder
    if COUNTS:
        report = {target: dict(counts) for target, counts in COUNTS.items()}
        report["total"] = dict(sum(COUNTS.values(), Counter()))
        print("\nfuzz counts:", json.dumps(report))
        if destination := os.environ.get("HYDROJET_FUZZ_COUNTS"):
            Path(destination).write_text(json.dumps(report, indent=2) + "\n")


def invoke(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main(argv)
        except SystemExit as exit_:  # an effect's sys.exit reaching main is a failure too
            raise AssertionError(f"{argv}: SystemExit({exit_.code!r}) escaped main") from exit_
    return code, out.getvalue(), err.getvalue()


# --- mutations -------------------------------------------------------------------------


@st.composite
def mutation(draw, cells: bool) -> tuple:
    kind = draw(st.sampled_from(["delete", "duplicate", "value", "value", "value", "bytes", "truncate", "empty"]))
    where = draw(st.floats(0.0, 1.0))
    if kind == "value":
        return kind, where, draw(st.floats(0.0, 1.0)), draw(st.sampled_from(CSV_CELLS if cells else TOML_VALUES))
    if kind == "bytes":
        return kind, where, draw(st.sampled_from(BYTES))
    return kind, where


def mutations(cells: bool = False):
    return st.lists(mutation(cells), min_size=1, max_size=3)


def mutate(seed: bytes, steps: list[tuple], cells: bool) -> bytes:
    data = seed
    for kind, where, *rest in steps:
        lines = data.split(b"\n")
        line = min(int(where * len(lines)), len(lines) - 1)
        if kind == "delete":
            del lines[line]
        elif kind == "duplicate":
            lines.insert(line, lines[line])
        elif kind == "value":
            column, value = rest
            lines[line] = _replace_value(lines[line], column, value.encode(), cells)
        elif kind == "bytes":
            position = int(where * len(data))
            data = data[:position] + rest[0] + data[position:]
            continue
        elif kind == "truncate":
            data = data[:int(where * len(data))]
            continue
        else:
            data = b""
            continue
        data = b"\n".join(lines)
    return data


def _replace_value(line: bytes, column: float, value: bytes, cells: bool) -> bytes:
    if cells:
        fields = line.split(b",")
        fields[min(int(column * len(fields)), len(fields) - 1)] = value
        return b",".join(fields)
    key, equals, _ = line.partition(b"=")
    return key + b"= " + value if equals else line


# --- the invariant -----------------------------------------------------------------------


def check(target: str, argv: list[str], mutated: Path, inputs: list[Path], success_shows: str) -> int:
    """Run ``argv``; assert the invariant for ``mutated`` (the file that was changed); a
    success must print ``success_shows`` (its result)."""
    before = {path: path.read_bytes() for path in inputs}
    code, out, err = invoke(argv)
    counts = COUNTS.setdefault(target, Counter())
    counts["tried"] += 1
    assert "Traceback" not in err, err
    assert code in (0, 2), (code, err)
    if code == 2:
        lines = err.strip("\n").split("\n")
        assert len(lines) == 1 and lines[0].startswith("error: "), err
        assert mutated.name in lines[0], f"the message does not name {mutated.name}: {lines[0]}"
        counts["clean errors"] += 1
    else:
        assert success_shows in " ".join(out.split()), out
        counts["successes"] += 1
    for path, content in before.items():
        assert path.read_bytes() == content, f"{path} was changed"
    return code


def fuzz_settings(examples: int):
    return settings(max_examples=examples, deadline=None, database=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def write_mutated(folder: Path, name: str, seed: Path, steps: list[tuple], cells: bool = False) -> Path:
    path = folder / name
    path.write_bytes(mutate(seed.read_bytes(), steps, cells))
    return path


# --- the targets -------------------------------------------------------------------------


@fuzz_settings(120)
@given(steps=mutations(cells=True))
def test_csv_tables_through_compare(seeds: Path, steps: list[tuple]) -> None:
    with tempfile.TemporaryDirectory() as name:
        data = write_mutated(Path(name), "data.csv", seeds / "data.csv", steps, cells=True)
        check("csv/compare", ["compare", str(data), "--params", str(seeds / "params.toml")], data,
              [data, seeds / "params.toml"], "RMS errors")


@fuzz_settings(8)
@given(steps=mutations(cells=True))
def test_csv_tables_through_calibrate(seeds: Path, steps: list[tuple]) -> None:
    with tempfile.TemporaryDirectory() as name:
        data = write_mutated(Path(name), "data.csv", seeds / "data.csv", steps, cells=True)
        output = Path(name) / "out.toml"
        if check("csv/calibrate", ["calibrate", str(data), "-o", str(output), "--model", "prb"], data, [data],
                 "RMS orientation error on the calibration poses") == 0:
            assert read_parameter_file(output).model == "prb"


@fuzz_settings(120)
@given(steps=mutations())
def test_profiles_through_compare(seeds: Path, steps: list[tuple]) -> None:
    with tempfile.TemporaryDirectory() as name:
        profile = write_mutated(Path(name), "rig.toml", seeds / "rig.toml", steps)
        check("profile/compare", ["compare", str(seeds / "data.csv"), "--profile", str(profile),
                                  "--params", str(seeds / "params.toml")], profile, [profile, seeds / "data.csv"],
              "RMS errors")


@fuzz_settings(30)
@given(steps=mutations())
def test_profiles_through_run(seeds: Path, steps: list[tuple]) -> None:
    with tempfile.TemporaryDirectory() as name:
        profile = write_mutated(Path(name), "rig.toml", seeds / "rig.toml", steps)
        # x100 instead of the profile's x25: a session's 34 s of set-up and plan in 0.3 s of
        # wall time, not 1.4 (a time scale the mutation made invalid is still refused).
        check("profile/run", ["run", "--profile", str(profile), "--plan", str(seeds / "plan.toml"), "--no-live",
                              "--no-calibration", "--time-scale", "100", "--log", str(Path(name) / "x.mcap")], profile,
              [profile, seeds / "plan.toml"], "session done: 2/2 steps")


@fuzz_settings(120)
@given(steps=mutations())
def test_parameter_files_through_compare(seeds: Path, steps: list[tuple]) -> None:
    with tempfile.TemporaryDirectory() as name:
        params = write_mutated(Path(name), "params.toml", seeds / "params.toml", steps)
        check("params/compare", ["compare", str(seeds / "data.csv"), "--params", str(params)], params,
              [params, seeds / "data.csv"], "RMS errors")


@fuzz_settings(40)
@given(steps=mutations(), suffix=st.sampled_from(["toml", "csv"]))
def test_plan_files_through_run(seeds: Path, steps: list[tuple], suffix: str) -> None:
    with tempfile.TemporaryDirectory() as name:
        plan = write_mutated(Path(name), f"plan.{suffix}", seeds / f"plan.{suffix}", steps, cells=suffix == "csv")
        check("plan/run", ["run", "--plan", str(plan), "--no-live", "--no-calibration", "--time-scale", "20",
                           "--log", str(Path(name) / "x.mcap")], plan, [plan], "session done")


@fuzz_settings(60)
@given(line=st.integers(0, EFFECT.count("\n") - 1), value=st.sampled_from(EFFECT_VALUES),
       steps=st.lists(mutation(False), max_size=1))
def test_effect_files_through_compare(seeds: Path, line: int, value: str, steps: list[tuple]) -> None:
    lines = EFFECT.split("\n")
    key, equals, _ = lines[line].partition("=")
    lines[line] = f"{key}= {value}" if equals else (lines[line] + f"\n        {value}" if "def apply" in lines[line]
                                                     else lines[line])
    with tempfile.TemporaryDirectory() as name:
        effect = Path(name) / "effect.py"
        effect.write_bytes(mutate("\n".join(lines).encode(), steps, cells=False))
        check("effect/compare", ["compare", str(seeds / "data.csv"), "--params", str(seeds / "params.toml"),
                                 "--effect", f"{effect}:WaterLineTwist"], effect, [effect, seeds / "data.csv"],
              "RMS errors")


@fuzz_settings(4)
@given(steps=mutations(cells=True))
def test_csv_tables_through_diagnose(seeds: Path, steps: list[tuple]) -> None:
    with tempfile.TemporaryDirectory() as name:
        data = write_mutated(Path(name), "data.csv", seeds / "data.csv", steps, cells=True)
        check("csv/diagnose", ["diagnose", str(data), "--candidate", "jet_gain", "--workers", "1"], data, [data],
              "verdict")
