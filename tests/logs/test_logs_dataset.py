"""dataset_from_log: a log's samples mean what the same rows mean in CSV; the analysis
commands' loaders accept logs and their embedded profiles."""

from __future__ import annotations

from pathlib import Path

import msgspec
import numpy as np
import pytest
from log_examples import EXAMPLES
from mcap.reader import make_reader
from mcap.writer import Writer

from hydrojet_bench.commands.common import load_steps
from hydrojet_bench.data import Dataset, SampleFlag, read_csv, saturation_flags, write_csv
from hydrojet_bench.inputs import load_dataset
from hydrojet_bench.errors import UserError
from hydrojet_bench.geometry import quat_normalize
from hydrojet_bench.logs import LogWriter, dataset_from_log, floats, read_log, recover_log
from hydrojet_bench.logs.condition import log_condition
from hydrojet_bench.logs.format import LOG_METADATA_NAME
from hydrojet_bench.logs.topics import Sample
from hydrojet_bench.profile import PROFILES_DIR, load_profile

SIM = load_profile("sim")
SIM_METADATA = {"bench": {"profile_name": "sim", "profile_toml": (PROFILES_DIR / "sim.toml").read_text()}}
ARRAYS = ("time_s", "jet_forces_n", "base_orientation", "tip_orientation", "base_position_m", "tip_position_m",
          "sweep", "step", "flags")


def recorded_rows(rows: int = 60, seed: int = 3) -> Dataset:
    """Calibration rows then two sweeps, with positions; one row over the jet limit."""
    rng = np.random.default_rng(seed)
    forces = np.repeat(rng.uniform(0.0, 0.12, (rows // 5, 3)), 5, axis=0)
    forces[7, 1] = 0.2  # above sim's 0.15 N: SATURATED, recomputed from the profile on reading
    sweep = np.repeat([-1, 0, 1], rows // 3)
    return Dataset(time_s=np.arange(rows) * 0.025, jet_forces_n=forces,
                   base_orientation=quat_normalize(rng.normal(size=(rows, 4))),
                   tip_orientation=quat_normalize(rng.normal(size=(rows, 4))),
                   base_position_m=rng.normal(0.0, 0.1, (rows, 3)), tip_position_m=rng.normal(0.0, 0.1, (rows, 3)),
                   sweep=sweep, step=np.arange(rows) // 5, flags=saturation_flags(forces, SIM), profile=SIM,
                   source="hand-made")


def sample(dataset: Dataset, i: int, source: str = "em", t_s: float | None = None) -> Sample:
    """Row ``i`` as the bench logs it, at its own time unless ``t_s`` is given."""
    has_positions = source == "em"
    return Sample(t_s=float(dataset.time_s[i] if t_s is None else t_s), source=source,
                  jet_forces_n=floats(dataset.jet_forces_n[i]), sweep=int(dataset.sweep[i]), step=int(dataset.step[i]),
                  base_orientation=floats(dataset.base_orientation[i]),
                  tip_orientation=floats(dataset.tip_orientation[i]),
                  base_position_m=floats(dataset.base_position_m[i]) if has_positions else None,
                  tip_position_m=floats(dataset.tip_position_m[i]) if has_positions else None)


def write_session(path: Path, dataset: Dataset, metadata=SIM_METADATA, imu: bool = True) -> Path:
    """The rows as the bench logs them: EM samples among IMU samples and other topics."""
    with LogWriter(path, metadata=metadata) as log:
        for i, t_s in enumerate(dataset.time_s):
            log.write(msgspec.structs.replace(EXAMPLES["/em/frame"], t_s=t_s))
            log.write(sample(dataset, i))
            if imu:
                log.write(sample(dataset, i, "imu"))
    return path


def assert_same(left: Dataset, right: Dataset) -> None:
    for name in ARRAYS:
        assert np.array_equal(getattr(left, name), getattr(right, name)), name


def test_log_samples_equal_the_same_rows_read_from_csv(tmp_path: Path) -> None:
    rows = recorded_rows()
    write_csv(rows, tmp_path / "rows.csv")
    from_csv = read_csv(tmp_path / "rows.csv", SIM)
    from_log = dataset_from_log(write_session(tmp_path / "run.mcap", rows), SIM)
    assert_same(from_log, from_csv)  # exactly: both formats carry floats at full precision
    assert from_log.flags[7] == SampleFlag.SATURATED and np.count_nonzero(from_log.flags) == 1
    assert from_log.source == str(tmp_path / "run.mcap")

    imu = dataset_from_log(tmp_path / "run.mcap", SIM, source="imu")
    assert imu.base_position_m is None and imu.tip_position_m is None
    assert np.array_equal(imu.tip_orientation, from_csv.tip_orientation)


def test_the_embedded_profile_is_used_unless_one_is_given(tmp_path: Path) -> None:
    path = write_session(tmp_path / "run.mcap", recorded_rows(), imu=False)
    embedded = dataset_from_log(path).profile
    for field in ("name", "gravity_in_tracker_m_s2", "base_orientation_in_tracker", "base_sensor", "tip_sensor",
                  "rod", "capsule", "jets", "max_jet_force_n"):
        assert getattr(embedded, field) == getattr(SIM, field), field
    assert dataset_from_log(path, "hydrojet-v1").profile.name == "hydrojet-v1"
    # The analysis commands' loaders: load_dataset, and load_steps without --profile.
    assert load_dataset(path, None).profile.name == "sim"
    profile, steps = load_steps(path, None)
    assert profile.name == "sim" and len(steps) == 60 // 5
    csv = tmp_path / "rows.csv"
    write_csv(recorded_rows(), csv)
    assert load_steps(csv, None)[0].name == "sim"  # CSV keeps its default


@pytest.mark.parametrize("last_step_finished", [True, False])
def test_a_truncated_log_gives_the_samples_before_the_cut(tmp_path: Path, last_step_finished: bool) -> None:
    """...less those of a step the cut interrupted: rows 35-39 are step 7, whose
    /bench/step record (written once it settled, as for the steps before) is there or
    not."""
    path = tmp_path / "run.mcap"
    rows = recorded_rows()
    log = LogWriter(path, metadata=SIM_METADATA, flush_interval_s=1e6)
    for i in range(40):
        log.write(sample(rows, i))
        if i % 5 == 4 and (i < 39 or last_step_finished):
            log.write(msgspec.structs.replace(EXAMPLES["/bench/step"], t_s=float(rows.time_s[i]),
                                              sweep=int(rows.sweep[i]), step=int(rows.step[i])))
    log.flush()
    log.write(sample(rows, 40))  # never flushed: lost
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes())
    log.close()
    assert read_log(cut).truncated
    assert_same(dataset_from_log(cut), rows.select(np.arange(40 if last_step_finished else 35)))


def test_a_step_a_stopped_session_left_unfinished_is_not_analysed(tmp_path: Path) -> None:
    """A session stopped by Ctrl-C or SIGTERM finishes its log, untruncated, but the step
    it was holding has no /bench/step record: its samples (rows 35-37 of step 7, cut
    during its hold) are no equilibrium. `calibrate` once fitted such a pose: 1.05 deg
    RMS after, against 0.15 without it."""
    rows = recorded_rows()
    with LogWriter(tmp_path / "stopped.mcap", metadata=SIM_METADATA) as log:
        for i in range(38):
            log.write(sample(rows, i))
            if i % 5 == 4:
                log.write(msgspec.structs.replace(EXAMPLES["/bench/step"], t_s=float(rows.time_s[i]),
                                                  sweep=int(rows.sweep[i]), step=int(rows.step[i])))
    assert not read_log(tmp_path / "stopped.mcap").truncated
    assert_same(dataset_from_log(tmp_path / "stopped.mcap"), rows.select(np.arange(35)))


def test_a_step_whose_end_a_damaged_chunk_took_is_not_analysed(tmp_path: Path) -> None:
    """A flipped byte costs its chunk: a step whose end (and /bench/step record) was in
    it keeps only samples from before, the rod still moving; only finished steps count."""
    rows = recorded_rows()
    with LogWriter(tmp_path / "damaged.mcap", metadata=SIM_METADATA) as log:
        for i in range(60):
            log.write(sample(rows, i))
            if i % 5 == 4 and not 20 <= i < 30:  # the records of steps 4 and 5 lost with their chunk
                log.write(msgspec.structs.replace(EXAMPLES["/bench/step"], t_s=float(rows.time_s[i]),
                                                  sweep=int(rows.sweep[i]), step=int(rows.step[i])))
    assert_same(dataset_from_log(tmp_path / "damaged.mcap"), rows.select(np.r_[0:20, 30:60]))


def test_log_problems_name_the_file(tmp_path: Path) -> None:
    rows = recorded_rows()
    no_profile = write_session(tmp_path / "bare.mcap", rows, metadata={}, imu=False)
    with pytest.raises(UserError, match="bare.mcap: no /bench/sample samples from source 'imu': it has samples "
                                        "from em only"):
        dataset_from_log(no_profile, SIM, source="imu")
    broken = write_session(tmp_path / "broken.mcap", rows, metadata={"bench": {"profile_toml": "[rod\n"}}, imu=False)
    with pytest.raises(UserError, match="broken.mcap, metadata bench.profile_toml: not valid TOML"):
        dataset_from_log(broken)
    wrong = write_session(tmp_path / "wrong.mcap", rows,
                          metadata={"bench": {"profile_toml": "[rod]\nlength_m = -1.0\n"}}, imu=False)
    with pytest.raises(UserError, match="wrong.mcap, metadata bench.profile_toml: gravity.in_tracker_m_s2 is required"):
        dataset_from_log(wrong)

    with LogWriter(tmp_path / "mixed.mcap") as log:
        log.write(sample(rows, 0, t_s=0.0))
        log.write(msgspec.structs.replace(sample(rows, 1, t_s=0.1), tip_position_m=None))
    with pytest.raises(UserError, match=r"mixed.mcap, message at t_s=0.1 s: /bench/sample.tip_position_m is null"):
        dataset_from_log(tmp_path / "mixed.mcap", SIM)
    with LogWriter(tmp_path / "backwards.mcap") as log:
        log.write(sample(rows, 0, t_s=1.0))
        log.write(sample(rows, 1, t_s=0.5))
    # Where the log has the problem, not the row of a Dataset the user never sees.
    with pytest.raises(UserError, match=r"backwards.mcap, message at t_s=0.5 s: /bench/sample.t_s: time goes "
                                        r"backwards \(0.5 s after 1.0 s\)$"):
        dataset_from_log(tmp_path / "backwards.mcap", SIM)
    with LogWriter(tmp_path / "unnormalised.mcap") as log:
        log.write(sample(rows, 0, t_s=0.0))
        log.write(msgspec.structs.replace(sample(rows, 1, t_s=0.1), tip_orientation=(2.0, 0.0, 0.0, 0.0)))
    with pytest.raises(UserError, match=r"unnormalised.mcap, message at t_s=0.1 s: /bench/sample.tip_orientation is "
                                        r"not a unit quaternion \(norm 2\)$"):
        dataset_from_log(tmp_path / "unnormalised.mcap", SIM)
    with LogWriter(tmp_path / "pulling.mcap") as log:
        log.write(msgspec.structs.replace(sample(rows, 0, t_s=0.0), jet_forces_n=(0.0, -0.01, 0.0)))
    with pytest.raises(UserError, match="pulling.mcap, message at t_s=0.0 s: .*jet forces must be >= 0 N"):
        dataset_from_log(tmp_path / "pulling.mcap", SIM)
    (tmp_path / "notes.mcap").write_text("t,q1\n")
    with pytest.raises(UserError, match="notes.mcap: not an MCAP file"):
        load_dataset(tmp_path / "notes.mcap", None)


def test_a_log_without_its_rig_profile_says_why(tmp_path: Path) -> None:
    rows = recorded_rows(rows=15)
    session = write_session(tmp_path / "session.mcap", rows, imu=False)
    with session.open("rb") as handle:
        reader = make_reader(handle)
        indexes = {index.name: index for index in reader.get_summary().metadata_indexes}
        schema, channel, _ = next(reader.iter_messages(topics=[Sample.topic]))
        messages = [message for _, _, message in reader.iter_messages(topics=[Sample.topic])]
    # Another program's copy of the samples, without a metadata record.
    with (tmp_path / "none.mcap").open("wb") as handle:
        writer = Writer(handle)
        writer.start()
        samples = writer.register_channel(channel.topic, channel.message_encoding,
                                          writer.register_schema(schema.name, schema.encoding, schema.data))
        for message in messages:
            writer.add_message(samples, message.log_time, message.data, message.publish_time, message.sequence)
        writer.finish()
    with pytest.raises(UserError,
                       match=r"none.mcap: no metadata at all \(\d+ bytes\).*give its rig profile with --profile"):
        dataset_from_log(tmp_path / "none.mcap")
    for name, metadata, held in (("bare.mcap", {}, "only the log's start time"),
                                 ("operator.mcap", {"operator": {"name": "A"}}, "metadata operator only")):
        write_session(tmp_path / name, rows, metadata=metadata, imu=False)
        with pytest.raises(UserError, match=f"{name}: no bench metadata record \\(its metadata holds {held}\\): the "
                                            "rig profile, plan and model of the session are not in the log; give "
                                            "--profile"):
            dataset_from_log(tmp_path / name)

    def damaged(name: str) -> Path:
        data = bytearray(session.read_bytes())
        data[indexes[name].offset + indexes[name].length // 2] ^= 0xFF
        path = tmp_path / f"damaged_{name}.mcap"
        path.write_bytes(bytes(data))
        return path

    lost = damaged("bench")
    with pytest.raises(UserError, match="damaged_bench.mcap: its metadata record is damaged: the rig profile it "
                                        "held is lost; give --profile"):
        dataset_from_log(lost)
    assert_same(dataset_from_log(lost, SIM), dataset_from_log(session, SIM))
    damage = read_log(lost).damage
    assert damage is not None and damage.metadata_lost == ("bench",)
    said = (f"damaged metadata record(s) 'bench' skipped ({damage.skipped_bytes} bytes): the rig profile, plan and "
            "model the session ran are lost with it")
    assert damage.describe() == said
    assert recover_log(lost, tmp_path / "recovered.mcap").damage.describe() == said
    # A damaged start time does not cost the rig profile after it.
    start_lost = damaged(LOG_METADATA_NAME)
    assert dataset_from_log(start_lost).profile.name == "sim"
    assert read_log(start_lost).damage.metadata_lost == (LOG_METADATA_NAME,)


def test_a_log_keeps_the_profile_its_session_used_whatever_its_parent_becomes(tmp_path: Path, monkeypatch) -> None:
    """A profile extending a sibling file names it by a relative path: read back from
    the log's text, it was found from the working directory, or edited since."""
    from hydrojet_bench.cli import main

    (tmp_path / "parent.toml").write_text('extends = "sim"\n[rod]\nlength_m = 0.08\n')
    (tmp_path / "child.toml").write_text('extends = "parent.toml"\n[capsule]\nmass_kg = 0.003\n')
    plan = tmp_path / "plan.toml"
    plan.write_text("settle_s = 2.0\n[[step]]\nq1 = 0.02\nq2 = 0.0\nq3 = 0.0\n")
    log = tmp_path / "child.mcap"
    assert main(["run", "--profile", str(tmp_path / "child.toml"), "--plan", str(plan), "--no-live",
                 "--no-calibration", "--time-scale", "10", "--log", str(log)]) == 0
    (tmp_path / "parent.toml").write_text('extends = "sim"\n[rod]\nlength_m = 0.05\n')
    monkeypatch.chdir(tmp_path.parent)
    recorded = dataset_from_log(log).profile
    assert (recorded.name, recorded.config.rod.length_m, recorded.config.capsule.mass_kg) == ("child", 0.08, 0.003)


def test_frames_that_share_a_stamp_give_their_samples_their_numbers_in_order(tmp_path: Path) -> None:
    """A busy host catching up reads several frames in one instant of a simulated rig's
    paced session time: each sample still gets its own frame's number."""
    from hydrojet_bench.logs.dataset import em_frame_numbers

    rows = recorded_rows()
    stamps = [0.0, 0.025, 0.025, 0.025, 0.1, 0.125]  # frames 1-3 read in one held instant
    numbers = [10, 11, 12, 13, 14, 16]
    path = tmp_path / "held.mcap"
    with LogWriter(path, metadata=SIM_METADATA) as log:
        for i, (t_s, number) in enumerate(zip(stamps, numbers)):
            log.write(msgspec.structs.replace(EXAMPLES["/em/frame"], t_s=t_s, frame_number=number))
            log.write(sample(rows, i, t_s=t_s))
    contents = read_log(path, topics=["/em/frame"])
    np.testing.assert_array_equal(em_frame_numbers(contents, np.array(stamps)), numbers)
    # A sample without its frame's record: the log cannot say, and the caller falls back.
    assert em_frame_numbers(contents, np.array([*stamps, 0.15])) is None


def test_without_step_records_the_notice_counts_the_steps_the_samples_give(tmp_path: Path) -> None:
    """A log whose /bench/step records are gone (a tool that dropped the topic) is
    analysed on its samples' labels; the notice once said "analysing the 0 logged" while
    calibrate fitted every pose."""
    rows = recorded_rows()
    metadata = {"bench": {**SIM_METADATA["bench"], "plan_steps": "12"}}
    path = write_session(tmp_path / "no_steps.mcap", rows, metadata=metadata, imu=False)
    analysed = dataset_from_log(path)
    assert_same(analysed, dataset_from_log(path, SIM))
    labels = set(zip(analysed.sweep.tolist(), analysed.step.tolist()))
    condition = log_condition(path)
    assert not condition.whole and condition.steps_missing == 0 and condition.steps_from_samples == len(labels) == 12
    assert condition.notice() == (f"{path}: it holds no /bench/step records (settled steps): the steps are taken "
                                  "from the samples' sweep/step labels; 0 of 12 planned steps missing; analysing the "
                                  f"12 labelled in the samples ({sum(sweep == -1 for sweep, _ in labels)} calibration "
                                  "poses)")
