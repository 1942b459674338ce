"""`dataset_from_log`: a session log's samples as the `Dataset` the analysis commands use.

Each ``/bench/sample`` message (a `Sample` record) is one row of the CSV contract
(`hydrojet_bench.data.csv_io`), with the same meaning; rows are taken in file order.
The rig profile is the one given, else the one the bench embedded in the log's metadata:
``bench.profile_resolved_json``, the profile as the session used it (``extends``
resolved), or in logs written before it, ``bench.profile_toml`` (the file's text) and
``bench.profile_name``.
"""

from __future__ import annotations

import json
import tomllib
from collections import defaultdict, deque
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from mcap.records import Metadata

from ..data.dataset import Dataset, RowError, SampleFlag, saturation_flags
from ..errors import UserError
from ..profile import RigProfile, load_profile, profile_from_mapping
from .format import LOG_METADATA_NAME
from .log_record import LogRecord
from .reader import LogContents, damage_of, read_log
from .records import RecordScanner
from .topics import EmFrame, Sample, Step

SAMPLE_TOPIC = Sample.topic


def dataset_from_log(path: str | Path, profile: RigProfile | str | Path | None = None,
                     source: str = "em") -> Dataset:
    """The ``/bench/sample`` messages of one ``source`` ("em" or "imu") as a `Dataset`.

    profile: a `RigProfile`, a TOML path or a shipped profile's name; None uses the
        profile embedded in the log.
    A truncated, interrupted or damaged log gives the samples of the steps that
    finished (those with a /bench/step record; without any, all but the run the cut
    interrupted). Raises `UserError` naming the file
    if there are no samples of that source, a sample is malformed or breaks the CSV
    contract, or no profile is to be had.
    """
    path = Path(path)
    contents = read_log(path, topics=[SAMPLE_TOPIC, Step.topic])
    samples = contents.on(Sample)
    finished = {(step.sweep, step.step) for step in contents.on(Step)}
    rows = analysed_samples([sample for sample in samples if sample.source == source], finished, contents.truncated)
    if not rows:
        raise UserError(no_samples_message(path, samples, source, len(finished), contents.truncated))
    rig = rig_profile_of_log(path, profile, contents.metadata)

    def column(key: str) -> np.ndarray:
        return np.array([getattr(row, key) for row in rows], dtype=float)

    forces = column("jet_forces_n")
    negative = np.flatnonzero(np.any(forces < 0.0, axis=1))
    if len(negative):
        i = int(negative[0])
        raise UserError(f"{path}, message at t_s={rows[i].t_s!r} s: {SAMPLE_TOPIC}.jet_forces_n: jet forces must "
                        f"be >= 0 N (a jet cannot pull), got {list(rows[i].jet_forces_n)}")
    # SATURATED comes from the profile, as for CSV; the other flags are the bench's.
    logged_flags = np.array([row.flags for row in rows], dtype=np.int64) & ~int(SampleFlag.SATURATED)
    try:
        return Dataset(
            time_s=column("t_s"), jet_forces_n=forces,
            base_orientation=column("base_orientation"), tip_orientation=column("tip_orientation"),
            base_position_m=_positions(path, rows, "base_position_m"),
            tip_position_m=_positions(path, rows, "tip_position_m"),
            sweep=column("sweep"), step=column("step"),
            flags=logged_flags | saturation_flags(forces, rig),
            profile=rig, source=str(path),
        )
    except RowError as error:
        raise message_error(path, SAMPLE_TOPIC, rows, error, {"time_s": "t_s"}) from None
    except ValueError as error:
        raise UserError(f"{path}: {SAMPLE_TOPIC} ({source}): {error}") from None


def message_error(path: Path, topic: str, records: Sequence[LogRecord], error: RowError,
                  fields: Mapping[str, str] | None = None) -> UserError:
    """A `Dataset` row's problem said where the log has it: the message's session time
    and its field. records: the messages, one a row; fields: Dataset fields whose
    message field is named otherwise."""
    field = (fields or {}).get(error.field, error.field)
    return UserError(f"{path}, message at t_s={records[error.row].t_s!r} s: {topic}.{field}{error.separator}"
                     f"{error.problem}")


def analysed_samples(samples: list[Sample], finished: set[tuple[int, int]], truncated: bool) -> list[Sample]:
    """The ``samples`` (of a log, in file order) an analysis takes: those of the steps
    ``finished`` ((sweep, step) of its /bench/step records) names; without any, all but
    the run of one step a cut interrupted in a ``truncated`` log."""
    # A step cut while it settled (a session stopped by Ctrl-C or SIGTERM, a truncated
    # log, a damaged chunk that took its end) is no equilibrium, and would be fitted as
    # one: only steps a /bench/step record says finished are kept.
    if finished:
        return [sample for sample in samples if (sample.sweep, sample.step) in finished]
    rows = list(samples)
    if truncated and rows:
        last = (rows[-1].sweep, rows[-1].step)
        while rows and (rows[-1].sweep, rows[-1].step) == last:
            rows.pop()
    return rows


def em_frame_numbers(contents: LogContents, time_s: np.ndarray) -> np.ndarray | None:
    """The tracker frame number of each EM sample at session times ``time_s`` (s; rows
    of a `dataset_from_log` of ``contents``' log): the ``/em/frame`` record the bench wrote
    at the same time (it stamps a frame and its sample alike). None when the log does not
    say for every sample (read without /em/frame, written by an earlier version, or the
    frame's chunk damaged away).

    Frames may share a stamp: a simulated rig's session time stands still while a busy
    host catches up (`bench.clock.PacedClock`), and the frames it then reads all get that
    time. The bench writes each frame's record and its sample in the order it reads them,
    so the samples of one stamp take that stamp's frame numbers in order."""
    frames: dict[float, deque[int]] = defaultdict(deque)
    for frame in contents.on(EmFrame):
        frames[frame.t_s].append(frame.frame_number)
    numbers = []
    for t_s in np.asarray(time_s, dtype=float).tolist():
        same_stamp = frames.get(t_s)
        if not same_stamp:
            return None
        numbers.append(same_stamp.popleft())
    if not numbers:
        return None
    return np.array(numbers, dtype=np.int64)


def no_samples_message(path: Path, samples: list[Sample], source: str, finished_steps: int, truncated: bool) -> str:
    """Why a log (``samples``: all its /bench/sample records) gives no sample of
    ``source``, in one line: it has none, or has some but none in a step that finished
    (``finished_steps``: /bench/step records; none, in a ``truncated`` log, means its
    samples all lie in the step the cut interrupted)."""
    own = sum(sample.source == source for sample in samples)
    cut = " (the log is truncated)" if truncated else ""
    if own:
        # Listing the sources would name this one too ("no samples from 'em': it has
        # samples from em, imu only"): what is missing is a finished step.
        where = (f"all {own} lie in the step the cut interrupted, which did not finish" if not finished_steps
                 else f"none of its {own} lies in one of the {finished_steps} steps the log says finished")
        return f"{path}: no {SAMPLE_TOPIC} samples from source {source!r} in a finished step: {where}{cut}"
    sources = sorted({sample.source for sample in samples})
    found = f"it has samples from {', '.join(sources)} only" if sources else f"it has no {SAMPLE_TOPIC} messages"
    return f"{path}: no {SAMPLE_TOPIC} samples from source {source!r}: {found}{empty_note(path) or cut}"


def _positions(path: Path, rows: list[Sample], key: str) -> np.ndarray | None:
    """A sensor's positions: all rows have them, or none (None), as for a CSV column."""
    missing = [getattr(row, key) is None for row in rows]
    if all(missing):
        return None
    if any(missing):
        i = missing.index(not missing[0])
        raise UserError(f"{path}, message at t_s={rows[i].t_s!r} s: {SAMPLE_TOPIC}.{key} is "
                        f"{'null' if missing[i] else 'given'} but was {'given' if missing[i] else 'null'} in the "
                        "samples before; a source measures a sensor's position in every sample or in none")
    return np.array([getattr(row, key) for row in rows], dtype=float)


def rig_profile_of_log(path: Path, profile: RigProfile | str | Path | None,
                 metadata: dict[str, dict[str, str]]) -> RigProfile:
    if isinstance(profile, RigProfile):
        return profile
    if profile is not None:
        return load_profile(profile)
    bench = metadata.get("bench", {})
    resolved = bench.get("profile_resolved_json")
    if resolved:
        where = f"{path}, metadata bench.profile_resolved_json"
        try:
            document = json.loads(resolved)
        except json.JSONDecodeError as error:
            raise UserError(f"{where}: not valid JSON: {error}") from None
        if not isinstance(document, dict):
            raise UserError(f"{where}: not a JSON object of profile tables (it is a {type(document).__name__})")
        return profile_from_mapping(document, source=where)
    # Logs written before the resolved profile was embedded: the file's own text.
    text = bench.get("profile_toml")
    if not text:
        raise UserError(_why_no_profile(path, bench))
    where = f"{path}, metadata bench.profile_toml"
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise UserError(f"{where}: not valid TOML: {error}") from None
    name = bench.get("profile_name")
    if name and "name" not in document:
        document = {**document, "name": name}
    return profile_from_mapping(document, source=where)


def _why_no_profile(path: Path, bench: dict[str, str]) -> str:
    """Why a log gives no rig profile, in one line. Only this error reads what the
    metadata the readers keep leaves out: the log's own start-time record, and the
    metadata records damage took."""
    if bench or empty_note(path):
        return f"{path}: the log embeds no rig profile (metadata bench.profile_toml){empty_note(path)}; give one with --profile"
    scanner = RecordScanner(path, open_chunks=False)
    names = {record.name for record in scanner if isinstance(record, Metadata)}
    damage = damage_of(scanner, 0, None)
    if damage is not None and damage.lost_metadata("bench"):
        return f"{path}: its metadata record is damaged: the rig profile it held is lost; give --profile"
    if names:
        others = sorted(names - {LOG_METADATA_NAME})
        held = f"metadata {', '.join(others)} only" if others else "only the log's start time"
        return (f"{path}: no bench metadata record (its metadata holds {held}): the rig profile, plan and model of "
                "the session are not in the log; give --profile")
    # The session's metadata comes right after the header: a log without any was cut
    # before it (or written by another program).
    return (f"{path}: no metadata at all ({Path(path).stat().st_size} bytes): the log was cut before the session "
            "wrote its metadata, or another program wrote it (give its rig profile with --profile if it holds a "
            "session's samples)")


def logged_model(path: str | Path, metadata: dict[str, dict[str, str]]) -> tuple[str, tuple[str, ...]]:
    """The model name and the effect specs the session ran (metadata ``bench.model`` and
    ``bench.effects``, a JSON list; a log without them ran the plain Cosserat model)."""
    bench = metadata.get("bench", {})
    text = bench.get("effects", "[]")
    where = f"{path}, metadata bench.effects"
    try:
        effects = json.loads(text)
    except json.JSONDecodeError as error:
        raise UserError(f"{where}: not valid JSON ({error}): {text!r}") from None
    if not isinstance(effects, list) or not all(isinstance(spec, str) for spec in effects):
        raise UserError(f"{where}: {text!r} is not a JSON list of effect names")
    return bench.get("model", "cosserat"), tuple(effects)


def empty_note(path: str | Path) -> str:
    """" (an empty file: 0 bytes)" for a log of no bytes at all, which reads as a log cut
    before its first record (a session stopped before writing anything); else ""."""
    try:
        return " (an empty file: 0 bytes)" if Path(path).stat().st_size == 0 else ""
    except OSError:
        return ""
