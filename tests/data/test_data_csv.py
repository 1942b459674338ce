"""The CSV contract: happy paths, one error per problem naming file/line/column, round trips."""

from __future__ import annotations

import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hydrojet_bench.data import (REQUIRED_COLUMNS, Dataset, SampleFlag, csv_io, read_csv, read_csv_steps,
                                 saturation_flags, write_csv)
from hydrojet_bench.params import MAX_PLAUSIBLE_POSITION_M
from hydrojet_bench.errors import UserError
from hydrojet_bench.inputs import load_dataset
from hydrojet_bench.profile import load_profile, profile_from_mapping

PROFILE = profile_from_mapping({"name": "test", "gravity": {"in_tracker_m_s2": [0.0, 0.0, -9.81]},
                                "jets": {"max_force_n": 0.15}})

# A valid table: two comment lines, the header on line 3, data rows on lines 4-7.
HEADER = "tip_qw,tip_qx,tip_qy,tip_qz,t,q1,q2,q3,base_qw,base_qx,base_qy,base_qz,base_x,base_y,base_z,sweep"
ROWS = [
    "1,0,0,0,0.0,0.00,0,0,0,1,0,0,0.01,0.02,0.20,-1",
    "0.9998477,0.0174524,0,0,0.5,0.05,0,0,0,1,0,0,0.01,0.02,0.20,-1",
    "0.9993908,0.0348995,0,0,1.0,0.10,0,0,0,1,0,0,0.01,0.02,0.20,2",
    "0.9986295,0.0523360,0,0,1.5,0.10,0,0,0,1,0,0,0.01,0.02,0.20,2",
]
HEADER_LINE = 3


def table(rows: list[str] | None = None, header: str = HEADER) -> str:
    return "# recorded on the bench\n# operator: test\n" + header + "\n" + "\n".join(ROWS if rows is None else rows) + "\n"


def set_cell(row: int, column: str, value: str) -> str:
    """The valid table with one cell (data row index ``row``) replaced."""
    names = HEADER.split(",")
    rows = [r.split(",") for r in ROWS]
    rows[row][names.index(column)] = value
    return table([",".join(r) for r in rows])


def write(tmp_path: Path, text: str, name: str = "run.csv") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_comments_free_column_order_and_optional_columns(tmp_path: Path) -> None:
    data = read_csv(write(tmp_path, table()), PROFILE)
    assert len(data) == 4 and data.source.endswith("run.csv") and data.profile is PROFILE
    np.testing.assert_array_equal(data.time_s, [0.0, 0.5, 1.0, 1.5])
    np.testing.assert_array_equal(data.jet_forces_n[:, 0], [0.0, 0.05, 0.10, 0.10])
    np.testing.assert_allclose(data.tip_orientation[1], [0.9998477, 0.0174524, 0, 0], atol=1e-6)
    np.testing.assert_array_equal(data.base_orientation, np.tile([0.0, 1.0, 0.0, 0.0], (4, 1)))
    np.testing.assert_array_equal(data.base_position_m, np.tile([0.01, 0.02, 0.20], (4, 1)))
    assert data.tip_position_m is None and not data.has_positions
    np.testing.assert_array_equal(data.sweep, [-1, -1, 2, 2])
    # No step column: a new step whenever the sweep or a force changes.
    np.testing.assert_array_equal(data.step, [0, 1, 2, 2])
    np.testing.assert_array_equal(data.flags, 0)


def test_minimal_columns_bom_blank_lines_and_labels(tmp_path: Path) -> None:
    header = ",".join(REQUIRED_COLUMNS) + ",step,tip_x,tip_y,tip_z"
    rows = ["0,0.1,0.2,0.3,1,0,0,0,1,0,0,0,7,0,0,-0.07", "", "1.0,0.1,0.2,0.3,1,0,0,0,1,0,0,0,8.0,0,0,-0.07"]
    path = tmp_path / "bom.csv"
    path.write_bytes(("\ufeff" + header + "\n" + "\n".join(rows)).encode("utf-8"))  # no final newline
    data = read_csv(path, PROFILE)
    assert len(data) == 2
    np.testing.assert_array_equal(data.sweep, [-1, -1])
    np.testing.assert_array_equal(data.step, [7, 8])
    assert data.base_position_m is None
    np.testing.assert_array_equal(data.tip_position_m[:, 2], [-0.07, -0.07])


def test_forces_above_the_profile_limit_are_flagged_not_dropped(tmp_path: Path) -> None:
    data = read_csv(write(tmp_path, set_cell(2, "q1", "0.2")), PROFILE)
    assert len(data) == 4
    np.testing.assert_array_equal(data.flags, [0, 0, SampleFlag.SATURATED, 0])


@pytest.mark.parametrize(
    ("text", "line", "column", "expected"),
    [
        (table(header=HEADER.replace("tip_qz,", "")), HEADER_LINE, "tip_qz", "required column missing"),
        (table(header=HEADER + ",temperature"), HEADER_LINE, "temperature", "unknown column"),
        (table(header=HEADER.replace("sweep", "t")), HEADER_LINE, "t", "appears twice"),
        (table(header=HEADER.replace("base_z", "step")), HEADER_LINE, "base_z", "complete triplets"),
        (set_cell(2, "q2", ""), 6, "q2", "missing value"),
        (set_cell(1, "base_y", " "), 5, "base_y", "position triplets base_x, base_y, base_z must be complete"),
        (table(ROWS[:1] + [ROWS[1].rsplit(",", 3)[0]] + ROWS[2:]), 5, "base_y", "missing"),
        (table(ROWS[:3] + [ROWS[3] + ",9"]), 7, "17", "the header names only 16 columns"),
        (set_cell(0, "tip_qx", "abc"), 4, "tip_qx", "'abc' is not a number"),
        (set_cell(3, "base_qy", "nan"), 7, "base_qy", "finite number"),
        (set_cell(1, "t", "inf"), 5, "t", "finite number"),
        (set_cell(2, "tip_qw", "1.1"), 6, "tip_qw,tip_qx,tip_qy,tip_qz", "not a unit quaternion"),
        (set_cell(0, "base_qx", "0.5"), 4, "base_qw,base_qx,base_qy,base_qz", "not a unit quaternion"),
        (set_cell(2, "t", "0.4"), 6, "t", "time goes backwards (0.4 s after 0.5 s on line 5)"),
        (table(ROWS[:2] + ROWS[1:]), 6, "t", "time does not advance (a repeated row?"),
        (set_cell(1, "sweep", "1.5"), 5, "sweep", "is not an integer"),
        (set_cell(1, "sweep", "-2"), 5, "sweep", "-1 for calibration"),
        (set_cell(3, "q1", "-0.01"), 7, "q1", "a jet cannot pull"),
        (table(ROWS[:2] + ["# a late comment"] + ROWS[2:]), 6, None, "only allowed before the header"),
        (set_cell(1, "t", "1_000"), 5, "t", "'1_000' is not a number (no '_' separators)"),
        (set_cell(2, "q3", "1e308"), 6, "q3", "1e308 is past the plausible 100 N in magnitude"),
        (set_cell(1, "base_y", "-1e200"), 5, "base_y", "-1e200 is past the plausible 10 m in magnitude"),
        (set_cell(3, "t", "1.7e12"), 7, "t", "1.7e12 is past the plausible 1e+10 s in magnitude"),
    ],
    ids=["missing-required", "unknown", "duplicate", "partial-triplet-header", "empty-cell",
         "partial-triplet-row", "short-row", "long-row", "non-numeric", "nan-quaternion", "inf-time",
         "non-unit-tip", "non-unit-base", "time-backwards", "repeated-row", "fractional-sweep", "sweep-below-minus-one",
         "negative-force", "late-comment", "digit-separator", "absurd-force", "absurd-position",
         "time-in-milliseconds"],
)
@pytest.mark.parametrize("block_rows", [1, 3, 8192], ids=lambda rows: f"blocks-of-{rows}")
@pytest.mark.parametrize("reader", [read_csv, read_csv_steps], ids=lambda reader: reader.__name__)
def test_every_bad_row_names_file_line_and_column(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, text: str,
                                                  line: int, column: str | None, expected: str, block_rows: int,
                                                  reader: Callable[[Path, object], Dataset]) -> None:
    # Blocks of one row put every check on a block boundary (time order, step labels).
    monkeypatch.setattr(csv_io, "_BLOCK_ROWS", block_rows)
    path = write(tmp_path, text)
    with pytest.raises(UserError) as info:
        reader(path, PROFILE)
    message = str(info.value)
    prefix = f"{path}, line {line}" + (f", column {column}:" if column else ":")
    assert message.startswith(prefix), message
    assert expected in message, message


def test_line_numbers_count_every_line_with_crlf_endings(tmp_path: Path) -> None:
    path = tmp_path / "windows.csv"
    path.write_bytes(set_cell(1, "q3", "x").replace("\n", "\r\n").encode())
    with pytest.raises(UserError, match=r"line 5, column q3: 'x' is not a number"):
        read_csv(path, PROFILE)


def test_the_earliest_problem_is_reported(tmp_path: Path) -> None:
    names = HEADER.split(",")
    rows = [r.split(",") for r in ROWS]
    rows[3][names.index("tip_qw")] = "x"      # line 7, first column
    rows[1][names.index("sweep")] = "0.5"     # line 5, last column
    with pytest.raises(UserError, match=r"line 5, column sweep"):
        read_csv(write(tmp_path, table([",".join(r) for r in rows])), PROFILE)


@pytest.mark.parametrize(("text", "expected"), [
    ("", "no header row"),
    ("# only a comment\n\n", "no header row"),
    (f"# c\n{HEADER}\n\n", "followed by no data rows"),
])
def test_files_without_data_are_refused(tmp_path: Path, text: str, expected: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(UserError, match=f"^{path}: .*{expected}"):
        read_csv(path, PROFILE)


def test_unreadable_files_are_user_errors(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="cannot read"):
        read_csv(tmp_path / "absent.csv", PROFILE)
    binary = tmp_path / "binary.csv"
    binary.write_bytes(b"\x89PNG\r\n\x1a\n\xff\xfe")
    with pytest.raises(UserError, match="not UTF-8"):
        read_csv(binary, PROFILE)


def test_load_dataset_dispatches_on_suffix(tmp_path: Path) -> None:
    path = write(tmp_path, table())
    data = load_dataset(path, "sim")
    assert len(data) == 4 and data.profile.name == "sim"
    assert load_dataset(path, load_profile("sim")).profile.name == "sim"
    with pytest.raises(UserError, match="run.mcap"):
        load_dataset(tmp_path / "run.mcap", "sim")
    with pytest.raises(UserError, match="unknown data format '.txt'"):
        load_dataset(tmp_path / "run.txt", "sim")
    with pytest.raises(UserError, match="needs a rig profile"):
        load_dataset(path, None)


def test_write_refuses_flags_the_contract_cannot_hold(tmp_path: Path) -> None:
    data = read_csv(write(tmp_path, table()), PROFILE)
    flags = np.array([0, SampleFlag.TIP_MISSING, 0, SampleFlag.OUT_OF_VOLUME])
    flagged = Dataset(time_s=data.time_s, jet_forces_n=data.jet_forces_n, base_orientation=data.base_orientation,
                      tip_orientation=data.tip_orientation, profile=PROFILE, flags=flags)
    with pytest.raises(ValueError, match="2 rows carry flags.*TIP_MISSING: 1.*OUT_OF_VOLUME: 1"):
        write_csv(flagged, tmp_path / "out.csv")
    assert write_csv(flagged, tmp_path / "out.csv", drop_flagged=True) == 2
    np.testing.assert_array_equal(read_csv(tmp_path / "out.csv", PROFILE).time_s, [0.0, 1.0])


# --- round trip ------------------------------------------------------------------------

finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
position = st.floats(min_value=-MAX_PLAUSIBLE_POSITION_M, max_value=MAX_PLAUSIBLE_POSITION_M)
unit_quaternion = st.tuples(*[st.floats(-1.0, 1.0)] * 4).filter(
    lambda q: np.linalg.norm(q) > 0.1).map(lambda q: np.asarray(q) / np.linalg.norm(q))


@st.composite
def datasets(draw: st.DrawFn) -> Dataset:
    n = draw(st.integers(1, 12))
    times = np.sort(np.array(draw(st.lists(finite, min_size=n, max_size=n, unique=True))))  # one sample per time
    forces = np.array(draw(st.lists(st.tuples(*[st.floats(0.0, 0.2)] * 3), min_size=n, max_size=n)))
    base = np.array(draw(st.lists(unit_quaternion, min_size=n, max_size=n)))
    tip = np.array(draw(st.lists(unit_quaternion, min_size=n, max_size=n)))

    def positions() -> np.ndarray | None:
        if not draw(st.booleans()):
            return None
        return np.array(draw(st.lists(st.tuples(position, position, position), min_size=n, max_size=n)))

    return Dataset(
        time_s=times, jet_forces_n=forces, base_orientation=base, tip_orientation=tip,
        base_position_m=positions(), tip_position_m=positions(),
        sweep=np.array(draw(st.lists(st.integers(-1, 8), min_size=n, max_size=n))),
        step=np.array(draw(st.lists(st.integers(-5, 10**6), min_size=n, max_size=n))),
        flags=saturation_flags(forces, PROFILE), profile=PROFILE, source=draw(st.text(max_size=20)),
    )


@settings(max_examples=60, deadline=None)
@given(datasets())
def test_write_then_read_gives_the_same_dataset(original: Dataset) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "round.csv"
        assert write_csv(original, path) == len(original)
        again = read_csv(path, PROFILE)
        assert csv_io.recorded_with(csv_io.recorded_profile(path), PROFILE)
    for name in ("time_s", "jet_forces_n", "base_orientation", "tip_orientation", "base_position_m",
                 "tip_position_m", "sweep", "step", "flags"):
        expected, actual = getattr(original, name), getattr(again, name)
        if expected is None:
            assert actual is None, name
        else:
            np.testing.assert_array_equal(actual, expected, err_msg=name)


def test_a_selection_without_rows_is_an_empty_dataset(tmp_path: Path) -> None:
    dataset = read_csv(write(tmp_path, table()), PROFILE)
    empty = dataset.select(dataset.sweep == 99)
    assert len(empty) == 0 and len(empty.calibration_rows()) == 0


# --- reduced to steps as it is read ------------------------------------------------------


@st.composite
def stepped_datasets(draw: st.DrawFn) -> Dataset:
    """Runs of a few rows each (a step), some flagged, times rising: what a session records."""
    runs = draw(st.lists(st.tuples(st.integers(1, 12), st.sampled_from([-1, 0, 1]),
                                   st.sampled_from([0.0, 0.05, 0.2])), min_size=1, max_size=8))
    forces = np.concatenate([np.tile([force, 0.0, 0.01], (rows, 1)) for rows, _, force in runs])
    n = len(forces)
    tip = np.array(draw(st.lists(unit_quaternion, min_size=n, max_size=n)))
    return Dataset(time_s=np.cumsum(draw(st.lists(st.sampled_from([0.01, 0.3, 0.7]), min_size=n, max_size=n))),
                   jet_forces_n=forces, base_orientation=np.tile([0.0, 1.0, 0.0, 0.0], (n, 1)), tip_orientation=tip,
                   tip_position_m=np.array(draw(st.lists(st.tuples(position, position, position), min_size=n,
                                                         max_size=n))),
                   sweep=np.concatenate([[sweep] * rows for rows, sweep, _ in runs]),
                   step=np.repeat(np.arange(len(runs)) * draw(st.integers(0, 1)), [rows for rows, _, _ in runs]),
                   flags=saturation_flags(forces, PROFILE), profile=PROFILE, source="steps")


@settings(max_examples=80, deadline=None)
@given(stepped_datasets(), st.integers(1, 6), st.booleans())
def test_steps_read_block_by_block_are_the_steps_of_the_whole_file(original: Dataset, block_rows: int,
                                                                    labelled: bool) -> None:
    """Without a step column, steps are numbered across block boundaries as in one piece;
    a step longer than the 1 s window and than a block is carried as its last second."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "steps.csv"
        write_csv(original, path)
        if not labelled:  # the step column is the last: drop it, the reader numbers the runs
            lines = path.read_text().splitlines()
            path.write_text("\n".join(line if line.startswith("#") else line.rsplit(",", 1)[0] for line in lines))
        rows = read_csv(path, PROFILE)
        whole = rows.quasistatic_steps()
        csv_io._BLOCK_ROWS, default = block_rows, csv_io._BLOCK_ROWS
        try:
            streamed = read_csv_steps(path, PROFILE)
            blocks = read_csv(path, PROFILE)
        finally:
            csv_io._BLOCK_ROWS = default
    assert streamed.source == whole.source
    for name in ("time_s", "jet_forces_n", "base_orientation", "tip_orientation", "base_position_m",
                 "tip_position_m", "sweep", "step", "flags", "samples"):
        expected, actual = getattr(whole, name), getattr(streamed, name)
        if expected is None:
            assert actual is None and getattr(blocks, name) is None, name
        else:
            np.testing.assert_array_equal(actual, expected, err_msg=name)
    np.testing.assert_array_equal(blocks.step, rows.step)


@pytest.mark.parametrize("text, recorded", [
    ("# made by hand\n# rig profile: horiz (/rigs/horiz.toml)\nt,q1\n", "horiz (/rigs/horiz.toml)"),
    ("\ufeff# rig profile: sim\nt,q1\n", "sim"),
    ("# rig profile: \nt,q1\n", None),
    ("t,q1\n# rig profile: late\n", None),  # not a comment of the table's head
    ("# another tool's table\nt,q1\n", None),
    ("", None),
])
def test_the_profile_a_table_was_written_with_is_read_from_its_head(tmp_path: Path, text: str, recorded) -> None:
    path = tmp_path / "t.csv"
    path.write_text(text, encoding="utf-8")
    assert csv_io.recorded_profile(path) == recorded


def test_a_profile_is_recognised_by_its_name_wherever_its_file_is() -> None:
    named = profile_from_mapping({"name": "bench  two", "gravity": {"in_tracker_m_s2": [0.0, 0.0, -9.81]}})
    assert csv_io.recorded_with("bench two (/elsewhere/bench.toml)", named)  # as write_csv spaces it
    assert csv_io.recorded_with("bench two", named)
    assert not csv_io.recorded_with("bench two2 (/x.toml)", named)
    assert not csv_io.recorded_with("bench", named)
