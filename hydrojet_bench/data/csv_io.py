"""Measurement tables in CSV: the stable contract, its reader and its writer.

The CSV contract (stable: change it only by adding optional columns)
--------------------------------------------------------------------
* UTF-8 text (a byte-order mark is allowed), comma-separated, one sample per line.
* Lines starting with ``#`` are comments and are allowed only before the header; blank
  lines are ignored anywhere.
* A header row is required. Column order is free. Names are matched exactly (case
  sensitive), after stripping surrounding spaces.
* Required columns:

  ========================================  =====================================
  ``t``                                     time, s; increasing row to row
  ``q1``, ``q2``, ``q3``                    commanded jet forces, N, >= 0
  ``base_qw, base_qx, base_qy, base_qz``    base sensor orientation, tracker frame
  ``tip_qw, tip_qx, tip_qy, tip_qz``        tip sensor orientation, tracker frame
  ========================================  =====================================

  Orientations are unit quaternions, scalar first, mapping sensor-frame vectors into
  the tracker frame; they must be within 1e-3 of unit norm.
* Optional columns:

  ===============================  ===================================================
  ``base_x, base_y, base_z``       base sensor position, tracker frame, m (all three)
  ``tip_x, tip_y, tip_z``          tip sensor position, tracker frame, m (all three)
  ``sweep``                        integer; -1 for calibration or unlabelled rows
                                   (the default when the column is absent)
  ``step``                         integer quasistatic step; when absent, a new step
                                   starts whenever ``sweep`` or any jet force changes
  ===============================  ===================================================

* Any other column is an error (it would otherwise be silently ignored).
* Every listed cell of every row must hold a finite number (integers for ``sweep`` and
  ``step``, where ``3.0`` counts as 3): nothing is filled in and nothing is dropped.
* Everything else about the rig (gravity, sensor mountings, rod, jets) comes from the
  rig profile given with the table (`hydrojet_bench.profile`).

Every problem raises `UserError` naming the file, the line (1-based, counting every
line of the file) and the column, e.g.
``run.csv, line 12, column tip_qx: 'abc' is not a number``.

On reading, a row whose jet force exceeds the profile's ``jets.max_force_n`` gets the
`SampleFlag.SATURATED` flag (it is kept). `write_csv` writes the same contract, with
every column in a fixed order and floats at full precision, so write -> read gives the
same dataset back.
"""

from __future__ import annotations

import array
import csv
import itertools
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TextIO

import numpy as np

from ..errors import UserError
from ..profile import RigProfile
from ..params import MAX_PLAUSIBLE_POSITION_M
from .dataset import (MAX_ABS_TIME_S, MAX_JET_FORCE_N, QUATERNION_NORM_TOLERANCE, Dataset, SampleFlag,
                      saturation_flags, steps_from_runs)

REQUIRED_COLUMNS: tuple[str, ...] = (
    "t", "q1", "q2", "q3",
    "base_qw", "base_qx", "base_qy", "base_qz",
    "tip_qw", "tip_qx", "tip_qy", "tip_qz",
)
POSITION_COLUMNS: dict[str, tuple[str, str, str]] = {
    "base": ("base_x", "base_y", "base_z"),
    "tip": ("tip_x", "tip_y", "tip_z"),
}
LABEL_COLUMNS: tuple[str, ...] = ("sweep", "step")
OPTIONAL_COLUMNS: tuple[str, ...] = POSITION_COLUMNS["base"] + POSITION_COLUMNS["tip"] + LABEL_COLUMNS
KNOWN_COLUMNS: tuple[str, ...] = REQUIRED_COLUMNS + OPTIONAL_COLUMNS
_QUATERNIONS = {"base": REQUIRED_COLUMNS[4:8], "tip": REQUIRED_COLUMNS[8:12]}

# Flags the contract can carry: SATURATED is recomputed from the profile on reading.
_DERIVED_FLAGS = int(SampleFlag.SATURATED)


class _Problem:
    """The earliest problem found so far: (row index, column order) decides."""

    def __init__(self) -> None:
        self.key: tuple[int, int] | None = None
        self.message = ""

    def offer(self, row: int, column_order: int, message: str) -> None:
        if self.key is None or (row, column_order) < self.key:
            self.key, self.message = (row, column_order), message


def _is_comment(line: str) -> bool:
    return "#" in line and line.lstrip().startswith("#")


_PROFILE_COMMENT = "# rig profile: "


def recorded_profile(path: str | Path) -> str | None:
    """The rig profile `write_csv` noted in the table's comments: its name, then its file
    in parentheses if it had one (``"horiz (/rigs/horiz.toml)"``); None when the table
    has no such comment (a table from elsewhere)."""
    with Path(path).open(encoding="utf-8-sig", errors="replace") as handle:
        for line in handle:
            if not _is_comment(line):
                return None
            if line.startswith(_PROFILE_COMMENT):
                return line[len(_PROFILE_COMMENT):].strip() or None
    return None


def recorded_with(recorded: str, profile: RigProfile) -> bool:
    """Whether `recorded_profile`'s text names ``profile`` (by name: its file may sit
    elsewhere on another machine)."""
    name = " ".join(profile.name.split())
    return recorded == name or recorded.startswith(f"{name} (")


def _parse_header(fields: list[str], where: str) -> list[str]:
    names = [name.strip() for name in fields]
    seen: set[str] = set()
    for number, name in enumerate(names, start=1):
        if not name:
            raise UserError(f"{where}, column {number}: header cell is empty; every column needs a name")
        if name in seen:
            raise UserError(f"{where}, column {name}: appears twice in the header")
        seen.add(name)
        if name not in KNOWN_COLUMNS:
            raise UserError(f"{where}, column {name}: unknown column; the contract allows "
                            f"{', '.join(KNOWN_COLUMNS)} (see hydrojet_bench/data/csv_io.py)")
    missing = [name for name in REQUIRED_COLUMNS if name not in seen]
    if missing:
        raise UserError(f"{where}, column {missing[0]}: required column missing from the header "
                        f"(missing: {', '.join(missing)})")
    for triplet in POSITION_COLUMNS.values():
        present = [name for name in triplet if name in seen]
        if present and len(present) != 3:
            absent = [name for name in triplet if name not in seen]
            raise UserError(f"{where}, column {absent[0]}: missing; position columns come in complete "
                            f"triplets ({', '.join(triplet)}), the header has only {', '.join(present)}")
    return names


def read_csv(path: str | Path, profile: RigProfile) -> Dataset:
    """Read a measurement table following the contract above (see the module docstring).

    The file is streamed in blocks of rows, each parsed to numbers before the next is
    read: holding every cell as a Python string at once cost ~8x the file's size."""
    return Dataset.concatenate(list(_checked_blocks(Path(path), profile)))


def read_csv_steps(path: str | Path, profile: RigProfile, window_s: float | None = 1.0) -> Dataset:
    """``read_csv(path, profile).quasistatic_steps(window_s)``, the same rows and the same
    errors, holding only one block and the last ``window_s`` of the step it ends in (the
    whole step if ``window_s`` is None): a calibration needs only the settled steps, and
    a file of 229,000 rows held whole took half again its size in memory on top of the
    interpreter's 200 MB."""
    reduced: list[Dataset] = []
    pending: Dataset | None = None
    for block in _checked_blocks(Path(path), profile):
        rows = block if pending is None else Dataset.concatenate([pending, block])
        # The last run of the block may go on in the next one: carried, not reduced yet.
        last_run = _last_run_start(rows)
        if last_run:
            reduced.append(rows.select(np.arange(last_run)).quasistatic_steps(window_s))
        pending = rows.select(np.arange(last_run, len(rows)))
        if window_s is not None:
            # Only the run's last window_s can be averaged: a long step (a hold of
            # minutes) is carried as its last second, not re-copied whole every block.
            pending = pending.select(pending.time_s >= pending.time_s[-1] - window_s)
    assert pending is not None  # _checked_blocks refuses a file without data rows
    reduced.append(pending.quasistatic_steps(window_s))
    return Dataset.concatenate(reduced)


def _last_run_start(rows: Dataset) -> int:
    """The first row of the last contiguous (sweep, step) run."""
    change = np.flatnonzero((rows.sweep[1:] != rows.sweep[:-1]) | (rows.step[1:] != rows.step[:-1]))
    return int(change[-1]) + 1 if len(change) else 0


def _checked_blocks(path: Path, profile: RigProfile) -> Iterator[Dataset]:
    """The file's rows as datasets of up to _BLOCK_ROWS rows, in order, each checked. A
    problem in the numbers stops the blocks; the rest of the file is still checked for
    structure, then the earliest problem is raised (`UserError`)."""
    name = str(path)
    try:
        with path.open(encoding="utf-8-sig") as handle:
            yield from _BlockReader(handle, path, profile).blocks()
    except UnicodeDecodeError:
        raise UserError(f"{name}: not UTF-8 text (byte {_first_undecodable_byte(path)}): "
                        "is it really a CSV file?") from None
    except OSError as error:
        raise UserError(f"{name}: cannot read: {error.strerror or error}") from None


class _BlockReader:
    """Parses and checks one file block by block, carrying across blocks what the checks
    and the step labels need from the row before."""

    def __init__(self, handle: TextIO, path: Path, profile: RigProfile) -> None:
        self.handle, self.path, self.name, self.profile = handle, path, str(path), profile
        self.problem = _Problem()
        self.first_row = 0  # of the current block, counting every data row of the file
        self.previous: Dataset | None = None  # the last row of the previous block
        self.previous_line = 0

    def blocks(self) -> Iterator[Dataset]:
        lines = _lines(self.handle)
        header_line = 0
        header = None
        for header_line, line in enumerate(lines, start=1):
            if line.strip() and not _is_comment(line):
                header = line
                break
        if header is None:
            raise UserError(f"{self.name}: no header row; expected a line naming the columns "
                            f"({', '.join(REQUIRED_COLUMNS)}, ...)")
        self.columns = _parse_header(next(csv.reader([header])), f"{self.name}, line {header_line}")
        self.order = {column: i for i, column in enumerate(self.columns)}
        for block, line_numbers in self._row_blocks(lines, header_line + 1):
            dataset = self._dataset(block, line_numbers)
            del block  # its strings go before the next block's are read
            if dataset is not None:
                yield dataset
        if self.first_row == 0:
            raise UserError(f"{self.name}: the header (line {header_line}) is followed by no data rows")
        if self.problem.key is not None:
            raise UserError(self.problem.message)

    def _row_blocks(self, lines: Iterator[str], first_line: int) -> Iterator[tuple[list[list[str]], array.array]]:
        """The data rows' fields and line numbers, _BLOCK_ROWS rows at a time (the last
        block may be shorter). Structural problems raise at once, wherever they are."""
        width = len(self.columns)
        block: list[list[str]] = []
        line_numbers = array.array("q")
        for number, line in enumerate(lines, start=first_line):
            if not line.strip():
                continue
            if _is_comment(line):
                raise UserError(f"{self.name}, line {number}: comment lines (#) are only allowed before the header row")
            fields = _fields(line)
            if len(fields) < width:
                raise UserError(f"{self.name}, line {number}, column {self.columns[len(fields)]}: missing (the row has "
                                f"{len(fields)} fields, the header {width} columns)")
            if len(fields) > width:
                raise UserError(f"{self.name}, line {number}, column {width + 1}: the row has {len(fields)} fields "
                                f"but the header names only {width} columns")
            block.append(fields)
            line_numbers.append(number)
            if len(block) == _BLOCK_ROWS:
                yield block, line_numbers
                block, line_numbers = [], array.array("q")
        if block:
            yield block, line_numbers

    def _dataset(self, block: list[list[str]], line_numbers: array.array) -> Dataset | None:
        """The block as a checked dataset; None once a problem was found."""
        first_row = self.first_row
        self.first_row += len(block)
        if self.problem.key is not None:
            # Later rows cannot hold an earlier problem: only the structure is still checked.
            return None
        problem, order = self.problem, self.order

        def where(row: int, column: str) -> str:
            """``row`` counts from the block's first row."""
            return f"{self.name}, line {line_numbers[row]}, column {column}"

        def cell(row: int, column: str) -> str:
            """The cell's text as written (messages quote it): read again, only for a message."""
            return _fields(_line(self.path, line_numbers[row]))[order[column]].strip()

        def where_in_file(row: int, column: str) -> str:
            return where(row - first_row, column)

        values = {}
        for j, strings in enumerate(zip(*block)):
            column = self.columns[j]
            parsed = _parse_numbers(strings, column, problem, j, where_in_file, first_row,
                                    integer=column in LABEL_COLUMNS)
            if parsed is not None:
                values[column] = parsed
        if problem.key is not None:
            return None
        # Checks on whole rows, again reporting the earliest.
        forces = _stacked(values, ("q1", "q2", "q3"))
        for j, column in enumerate(("q1", "q2", "q3")):
            negative = np.flatnonzero(forces[:, j] < 0.0)
            if len(negative):
                i = int(negative[0])
                problem.offer(first_row + i, order[column], f"{where(i, column)}: jet force must be >= 0 N "
                                                            f"(a jet cannot pull), got {cell(i, column)}")
        orientations = {}
        for sensor, quaternion_columns in _QUATERNIONS.items():
            q = _stacked(values, quaternion_columns)
            with np.errstate(over="ignore"):  # a 1e308 component: its norm is inf, reported below
                norm = np.linalg.norm(q, axis=1)
            bad = np.flatnonzero(~(np.abs(norm - 1.0) <= QUATERNION_NORM_TOLERANCE))
            if len(bad):
                i = int(bad[0])
                first = min(order[c] for c in quaternion_columns)
                problem.offer(first_row + i, first, f"{where(i, ','.join(quaternion_columns))}: not a unit "
                                                    f"quaternion (norm {norm[i]:.6g}; expected within "
                                                    f"{QUATERNION_NORM_TOLERANCE:g} of 1)")
            orientations[sensor] = q
        time = values["t"]
        before = self.previous.time_s[-1:] if self.previous is not None else time[:0]
        # A repeated time is a duplicated row, or a table without real times: either way
        # the steps' settled windows (their last second) would be wrong without a word.
        steps_s = np.diff(np.concatenate([before, time]))  # steps_s[k] leads to row k + 1 - len(before)
        not_forward = np.flatnonzero(steps_s <= 0.0)
        if len(not_forward):
            i = int(not_forward[0]) + 1 - len(before)
            if i > 0:
                earlier, earlier_line = cell(i - 1, "t"), line_numbers[i - 1]
            else:
                earlier = _fields(_line(self.path, self.previous_line))[order["t"]].strip()
                earlier_line = self.previous_line
            went = ("goes backwards" if steps_s[not_forward[0]] < 0.0
                    else "does not advance (a repeated row? each row is one sample at its own time)")
            problem.offer(first_row + i, order["t"], f"{where(i, 't')}: time {went} ({cell(i, 't')} s "
                                                     f"after {earlier} s on line {earlier_line})")
        rows = len(time)
        sweep = values.get("sweep", np.full(rows, -1, dtype=np.int64))
        low = np.flatnonzero(sweep < -1)
        if len(low):
            i = int(low[0])
            problem.offer(first_row + i, order["sweep"], f"{where(i, 'sweep')}: must be >= 0, or -1 for "
                                                         f"calibration or unlabelled rows, got {cell(i, 'sweep')}")
        if problem.key is not None:
            return None
        step = values["step"] if "step" in values else self._steps_from_runs(sweep, forces)
        positions = {sensor: (_stacked(values, triplet) if triplet[0] in values else None)
                     for sensor, triplet in POSITION_COLUMNS.items()}
        try:
            dataset = Dataset(
                time_s=time, jet_forces_n=forces,
                base_orientation=orientations["base"], tip_orientation=orientations["tip"],
                base_position_m=positions["base"], tip_position_m=positions["tip"],
                sweep=sweep, step=step, flags=saturation_flags(forces, self.profile),
                profile=self.profile, source=self.name,
            )
        except ValueError as error:  # the checks above should leave nothing for Dataset to find
            raise UserError(f"{self.name}: {error}") from None
        self.previous, self.previous_line = dataset.select([-1]), line_numbers[-1]
        return dataset

    def _steps_from_runs(self, sweep: np.ndarray, forces: np.ndarray) -> np.ndarray:
        """`steps_from_runs` numbering continued from the previous block's last row."""
        steps = steps_from_runs(sweep, forces)
        previous = self.previous
        if previous is None:
            return steps
        goes_on = sweep[0] == previous.sweep[-1] and np.array_equal(forces[0], previous.jet_forces_n[-1])
        return steps + previous.step[-1] + (0 if goes_on else 1)


def _stacked(values: dict[str, np.ndarray], columns: tuple[str, ...]) -> np.ndarray:
    """The columns side by side, taken out of ``values``: the copies alone stay in memory."""
    return np.column_stack([values.pop(column) for column in columns])


# Rows parsed per block: big enough that numpy's per-call cost vanishes (blocks of 1024
# and 2048 rows read the perf CSV equally fast), small enough that the block's strings
# (~60 bytes a cell, ~3 MB) stay small beside the interpreter: 8192 held 10 MB more.
_BLOCK_ROWS = 2048


def _fields(line: str) -> list[str]:
    # Plain numbers need no CSV quoting rules; a quoted cell takes the csv module.
    return line.split(",") if '"' not in line else next(csv.reader([line]))


def _lines(handle: TextIO) -> Iterator[str]:
    """The file's lines without their newline. Text mode has already turned \\r\\n and \\r
    into \\n, and only \\n ends a line (not form feeds and the like, as splitlines
    would), so the numbers match editors' line numbers."""
    for line in handle:
        yield line[:-1] if line.endswith("\n") else line


def _line(path: Path, number: int) -> str:
    """Line ``number`` (1-based) of the file."""
    with path.open(encoding="utf-8-sig") as handle:
        return next(itertools.islice(_lines(handle), number - 1, None))


def _first_undecodable_byte(path: Path) -> int:
    try:
        path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as error:
        return error.start
    raise AssertionError("a decoding error that decoding the whole file does not repeat")  # pragma: no cover


# Magnitude and unit of each measured column (`Dataset`'s limits, checked here to name
# the line).
_PLAUSIBLE = {"t": (MAX_ABS_TIME_S, "s"), **{q: (MAX_JET_FORCE_N, "N") for q in ("q1", "q2", "q3")},
              **{column: (MAX_PLAUSIBLE_POSITION_M, "m") for triplet in POSITION_COLUMNS.values() for column in triplet}}


def _parse_numbers(strings: tuple[str, ...], column: str, problem: _Problem, column_order: int,
                   where: Callable[[int, str], str], first_row: int, *, integer: bool) -> np.ndarray | None:
    """One block of a column's cells as numbers (``strings[0]`` is row ``first_row``);
    problems go to ``problem`` (None returned)."""
    if "_" in "".join(strings):
        # float() reads "1_000" as 1000: a digit-group separator is more likely a typo
        # (a merged cell, a mistyped decimal point) than data, so refuse it.
        i = next(i for i, text in enumerate(strings) if "_" in text)
        problem.offer(first_row + i, column_order, f"{where(first_row + i, column)}: {strings[i].strip()!r} is not a number "
                                       "(no '_' separators)")
        return None
    try:
        array = np.array(strings, dtype=float)  # fast path; same grammar as float()
    except ValueError:
        array = None
    if array is None:
        for i, text in enumerate(strings):
            cell = text.strip()
            if not cell:
                problem.offer(first_row + i, column_order, f"{where(first_row + i, column)}: missing value{_triplet_hint(column)}")
                return None
            try:
                float(cell)
            except ValueError:
                problem.offer(first_row + i, column_order, f"{where(first_row + i, column)}: {cell!r} is not a number")
                return None
        raise AssertionError("numpy rejected a column that float() accepts")  # pragma: no cover
    bad = np.flatnonzero(~np.isfinite(array))
    if len(bad):
        i = int(bad[0])
        problem.offer(first_row + i, column_order, f"{where(first_row + i, column)}: must be a finite number, got {strings[i].strip()}")
        return None
    limit = _PLAUSIBLE.get(column)
    if limit is not None:
        beyond = np.flatnonzero(np.abs(array) > limit[0])
        if len(beyond):
            i = int(beyond[0])
            problem.offer(first_row + i, column_order, f"{where(first_row + i, column)}: {strings[i].strip()} is past "
                                                       f"the plausible {limit[0]:g} {limit[1]} in magnitude")
            return None
    if integer:
        # Labels, not measurements: beyond 2**53 a float no longer holds every integer.
        fractional = np.flatnonzero((array != np.round(array)) | (np.abs(array) > 2.0**53))
        if len(fractional):
            i = int(fractional[0])
            problem.offer(first_row + i, column_order, f"{where(first_row + i, column)}: {strings[i].strip()!r} is not an integer")
            return None
        return array.astype(np.int64)
    return array


def _triplet_hint(column: str) -> str:
    for triplet in POSITION_COLUMNS.values():
        if column in triplet:
            return f" (position triplets {', '.join(triplet)} must be complete in every row)"
    return ""


def write_csv(dataset: Dataset, path: str | Path, *, drop_flagged: bool = False) -> int:
    """Write ``dataset`` as a CSV following the contract; returns the number of rows.

    The contract has no flags column: SATURATED is recomputed from the profile when the
    file is read, but other flags (missing sensors, out of volume) cannot be stored.
    Rows carrying them raise ValueError unless ``drop_flagged`` is True, in which case
    they are left out. The profile is not written: read the file back with the same
    ``--profile``.
    """
    keep = (dataset.flags & ~_DERIVED_FLAGS) == 0
    if not np.all(keep):
        if not drop_flagged:
            counts = {flag: count for flag, count in dataset.flag_counts().items()
                      if count and flag != SampleFlag.SATURATED.name}
            raise ValueError(f"{int(np.sum(~keep))} rows carry flags the CSV contract cannot hold "
                             f"({', '.join(f'{k}: {v}' for k, v in counts.items())}); pass "
                             "drop_flagged=True to leave them out")
        dataset = dataset.select(keep)
    columns: list[str] = list(REQUIRED_COLUMNS)
    blocks: list[np.ndarray] = [dataset.time_s[:, None], dataset.jet_forces_n,
                                dataset.base_orientation, dataset.tip_orientation]
    for sensor, triplet in POSITION_COLUMNS.items():
        positions = getattr(dataset, f"{sensor}_position_m")
        if positions is not None:
            columns.extend(triplet)
            blocks.append(positions)
    floats = np.hstack(blocks) if len(dataset) else np.zeros((0, len(columns)))
    source = " ".join(dataset.source.split())
    profile_name = dataset.profile.name + (f" ({dataset.profile.path})" if dataset.profile.path else "")
    with Path(path).open("w", encoding="utf-8", newline="") as handle:
        handle.write("# HydroJet Bench measurement table (contract: hydrojet_bench/data/csv_io.py)\n")
        handle.write(f"# source: {source}\n{_PROFILE_COMMENT}{' '.join(profile_name.split())}\n")
        handle.write(",".join(columns + list(LABEL_COLUMNS)) + "\n")
        # repr gives the shortest string that reads back to the same float.
        handle.writelines(",".join(map(repr, values)) + f",{sweep},{step}\n"
                          for values, sweep, step in zip(floats.tolist(), dataset.sweep.tolist(),
                                                         dataset.step.tolist()))
    return len(dataset)
