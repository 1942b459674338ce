"""Cut and damaged session logs through every command that reads logs.

One short session is recorded per module (about ten chunks). Its variants: the log cut
at every chunk boundary, and the log with one flipped byte in each chunk (a seeded
position). The invariant, for every command: exit 0 with a right result (and, for a cut
or damaged log, a notice saying so), or exit 2 with one line naming the file; never a
traceback (an exception other than `UserError` escapes `main` and fails the test); never
a changed input file.

Each command runs on a seeded sample of the variants (`SAMPLE_PER_COMMAND`) to keep the
suite fast; ``HYDROJET_FUZZ_ALL=1`` runs every variant through every command.
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import os
import random
from dataclasses import dataclass
from pathlib import Path

import pytest
from mcap.reader import make_reader
from msgspec.structs import replace

from hydrojet_bench.bench.session import Session, SessionRequest
from hydrojet_bench.cli import main
from hydrojet_bench.logs import read_log
from hydrojet_bench.logs.condition import log_condition
from hydrojet_bench.model_choice import build_model
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile

SEED = 13
SAMPLE_PER_COMMAND = 3
EVERY_VARIANT = os.environ.get("HYDROJET_FUZZ_ALL") == "1"
# Ten calibration poses and two short sweeps: enough steps for diagnose (10 training
# steps); a flush every 8 s of session time, about ten chunks.
FLUSH_INTERVAL_S = 8.0


@dataclass(frozen=True)
class Variant:
    name: str
    path: Path
    damaged: bool  # else cut


@dataclass(frozen=True)
class Recorded:
    log: Path
    params: Path
    variants: tuple[Variant, ...]


def record_session(path: Path) -> None:
    profile = load_profile("sim")
    session = replace(profile.config.session, time_scale=10.0, window_s=0.5, flush_interval_s=FLUSH_INTERVAL_S)
    model, _ = build_model("cosserat", [])
    plan = calibration_plan(10, settle_s=3.0, seed=2) + validation_sweeps(steps_up=2, repetitions=1, settle_s=3.0)
    request = SessionRequest(profile=profile, settings=replace(profile.config, session=session), plan=plan,
                             log_path=path, model=model, effects=(), params=profile.model_parameters(), seed=4)
    asyncio.run(Session(request).run())


def chunk_spans(log: Path) -> list[tuple[int, int]]:
    with log.open("rb") as handle:
        return [(index.chunk_start_offset, index.chunk_start_offset + index.chunk_length)
                for index in make_reader(handle).get_summary().chunk_indexes]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory) -> Recorded:
    folder = tmp_path_factory.mktemp("fuzz")
    log = folder / "session.mcap"
    record_session(log)
    params = folder / "params.toml"
    assert main(["calibrate", str(log), "-o", str(params)]) == 0
    data = log.read_bytes()
    spans = chunk_spans(log)
    assert len(spans) >= 6, "the session log should span several chunks"
    rng = random.Random(SEED)
    variants = []
    for number, (start, end) in enumerate(spans):
        cut = folder / f"cut-before-chunk-{number}.mcap"
        cut.write_bytes(data[:start])
        variants.append(Variant(cut.name, cut, damaged=False))
        flipped = bytearray(data)
        flipped[rng.randrange(start, end)] ^= 1 << rng.randrange(8)
        damaged = folder / f"flipped-in-chunk-{number}.mcap"
        damaged.write_bytes(bytes(flipped))
        variants.append(Variant(damaged.name, damaged, damaged=True))
    return Recorded(log, params, tuple(variants))


def test_every_variant_reads_as_a_part_of_the_whole(recorded: Recorded) -> None:
    full = read_log(recorded.log).messages
    kept = []
    for variant in recorded.variants:
        contents = read_log(variant.path)
        messages = contents.messages
        if not variant.damaged:
            assert contents.truncated and contents.damage is None, variant.name
            assert messages == full[:len(messages)], variant.name
            continue
        assert not contents.truncated, variant.name  # the file still ends properly
        # Every kept message is one of the log's, in order.
        remaining = iter(full)
        assert all(any(message == other for other in remaining) for message in messages), variant.name
        if len(messages) < len(full):
            assert contents.damage is not None and contents.damage.messages_lost == len(full) - len(messages)
        kept.append(len(messages) / len(full))
    # One flipped byte costs its own chunk at most, about 1/n of the messages.
    assert min(kept) >= 1 - 2.5 / len(chunk_spans(recorded.log))


def sample(recorded: Recorded, command: str) -> list[Variant]:
    """Every variant, or a seeded sample holding damaged and cut logs both."""
    if EVERY_VARIANT:
        return list(recorded.variants)
    rng = random.Random(f"{SEED}-{command}")
    damaged = [variant for variant in recorded.variants if variant.damaged]
    cut = [variant for variant in recorded.variants if not variant.damaged]
    return rng.sample(damaged, SAMPLE_PER_COMMAND - 1) + rng.sample(cut, 1)


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


COMMANDS = {
    "recover": lambda v, out, r: ["recover", str(v.path), "-o", str(out / "recovered.mcap")],
    "replay": lambda v, out, r: ["replay", str(v.path)],
    "calibrate": lambda v, out, r: ["calibrate", str(v.path), "-o", str(out / "params.toml"), "--json",
                                    str(out / "out.json")],
    "compare": lambda v, out, r: ["compare", str(v.path), "--params", str(r.params), "--json", str(out / "out.json")],
    "sensors": lambda v, out, r: ["sensors", str(v.path), "--json", str(out / "out.json")],
    # One candidate: the log's damage reaches a diagnosis through its steps, whatever it fits.
    "diagnose": lambda v, out, r: ["diagnose", str(v.path), "--workers", "1", "--candidate", "jet_gain", "--json",
                                   str(out / "out.json")],
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_commands_on_cut_and_damaged_logs(recorded: Recorded, command: str, tmp_path: Path, capsys) -> None:
    for number, variant in enumerate(sample(recorded, command)):
        out = tmp_path / str(number)
        out.mkdir()
        before = digest(variant.path)
        code = main(COMMANDS[command](variant, out, recorded))
        captured = capsys.readouterr()
        assert digest(variant.path) == before, (command, variant.name)
        assert "Traceback" not in captured.err + captured.out, (command, variant.name)
        if code == 2:
            # One error line naming the file, last, after the notices about the log (what it
            # lost, and what that did to the steps left, such as a step cut while settling).
            lines = captured.err.strip().splitlines()
            errors = [line for line in lines if line.startswith("error: ")]
            assert len(errors) == 1 and variant.name in errors[0], (command, variant.name, captured.err)
            assert lines[-1] == errors[0] and all(line.startswith("warning: ") for line in lines[:-1]), captured.err
            continue
        # A calibration on what is left may be short of poses to converge or pin a value on
        # its bound: it says so and exits 3 (its warnings are not the log's).
        assert code == 0 or (command == "calibrate" and code == 3), (command, variant.name, code)
        condition = log_condition(variant.path)
        assert not condition.whole, variant.name
        if command == "recover":
            assert read_log(out / "recovered.mcap").messages == read_log(variant.path).messages
            assert ("was truncated" in captured.out) if not variant.damaged else True
            assert (f"warning: {variant.path} is damaged" in captured.err) == (condition.damage is not None)
            # The recovered log ends properly, but still lacks what the cut took: analyses say so.
            recovered = log_condition(out / "recovered.mcap")
            assert recovered.steps_missing == condition.steps_missing, variant.name
            assert recovered.whole == condition.whole, variant.name  # the copy says what its source lost
            continue
        # One warning line about the log, first, naming what the analysis is missing (a
        # calibration on what is left may add its own, as above).
        warnings = [line for line in captured.err.splitlines() if line.startswith("warning: ")]
        notice = f"warning: {condition.notice()}"
        assert warnings[:1] == [notice] and warnings.count(notice) == 1, (command, variant.name, captured.err)
        if (out / "out.json").exists():
            assert json.loads((out / "out.json").read_text())["log_damage"] == condition.as_dict()


def test_a_whole_log_gets_no_notice(recorded: Recorded, tmp_path: Path, capsys) -> None:
    assert main(["compare", str(recorded.log), "--params", str(recorded.params), "--json",
                 str(tmp_path / "out.json")]) == 0
    assert "warning:" not in capsys.readouterr().err
    assert json.loads((tmp_path / "out.json").read_text())["log_damage"] is None
