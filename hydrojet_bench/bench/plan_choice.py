"""Which plan a session plays: a built-in by name, or a plan file.

Built-ins: ``paper`` (40 calibration poses + the nine sweeps, 229 steps), ``calibration``
or ``calibration:COUNT`` (the 40 poses, or COUNT of them), ``sweeps`` (the nine sweeps),
``imu-vs-em`` (static poses and slow
ramps), ``hold`` or ``hold:SECONDS`` (jets off, held).

Plan files list force steps, one per row, with columns (CSV header) or keys (TOML
``[[step]]`` tables) ``q1, q2, q3`` (N) and optionally ``settle_s``, ``sweep`` and
``step``; rows of sweep -1 are calibration poses. A TOML file may set a top-level
``settle_s`` default::

    settle_s = 5.0
    [[step]]
    q1 = 0.05
    q2 = 0.0
    q3 = 0.0
"""

from __future__ import annotations

import csv
from pathlib import Path

from ..config.loading import read_toml
from ..errors import UserError
from ..plans import (DEFAULT_SETTLE_S, MAX_SETTLE_S, Plan, calibration_plan, hold_plan, imu_versus_em_plan, paper_protocol,
                     plan_from_rows, validation_sweeps)

BUILT_IN = ("paper", "calibration", "sweeps", "imu-vs-em", "hold")
# A plan is made whole before it plays: a count past any session's length only fills memory.
MAX_CALIBRATION_POSES = 100_000


def choose_plan(spec: str, settle_s: float = DEFAULT_SETTLE_S, seed: int = 0) -> Plan:
    """The plan ``spec`` names; every problem is a `UserError` naming the file and row."""
    name, colon, argument = spec.partition(":")
    if colon and name in BUILT_IN and name not in ("calibration", "hold"):
        raise UserError(f"plan {spec!r}: {name} takes no argument (only calibration:COUNT and hold:SECONDS do)")
    if name == "paper":
        return paper_protocol(seed=seed, settle_s=settle_s)
    if name == "calibration":
        if not colon:
            return calibration_plan(seed=seed, settle_s=settle_s)
        # isdigit alone takes "²", which int() refuses.
        if not (argument.isascii() and argument.isdigit()) or not 1 <= int(argument) <= MAX_CALIBRATION_POSES:
            raise UserError(f"plan {spec!r}: calibration:COUNT takes a whole number of poses >= 1 and <= "
                            f"{MAX_CALIBRATION_POSES} (nearly six days at 5 s a pose)")
        return calibration_plan(int(argument), seed=seed, settle_s=settle_s)
    if name == "sweeps":
        return validation_sweeps(settle_s=settle_s)
    if name == "imu-vs-em":
        return imu_versus_em_plan(seed=seed)
    if name == "hold":
        try:
            return hold_plan(duration_s=float(argument) if argument else 60.0)
        except ValueError as error:
            raise UserError(f"plan {spec!r}: hold:SECONDS takes a number of seconds > 0 and at most "
                            f"{MAX_SETTLE_S:g} (one day), got {argument!r} ({error})") from None
    path = Path(spec)
    if not path.is_file():
        raise UserError(f"plan {spec!r}: neither a built-in plan ({', '.join(BUILT_IN)}) nor an existing file")
    try:
        if path.suffix.lower() == ".csv":
            with path.open(newline="", encoding="utf-8-sig") as handle:
                reader = csv.DictReader(line for line in handle if not line.startswith("#"))
                header = [name.strip() for name in reader.fieldnames or ()]
                repeated = next((name for name in header if header.count(name) > 1), None)
                if repeated is not None:
                    raise ValueError(f"{path}: column {repeated!r} appears twice in the header")
                rows = []
                for number, row in enumerate(reader, start=1):
                    if None in row:  # DictReader's key for values past the header's columns
                        raise ValueError(f"{path}, row {number}: more values than the header has columns")
                    rows.append({key.strip(): value for key, value in row.items()})
            return plan_from_rows(rows, str(path), settle_s)
        if path.suffix.lower() == ".toml":
            document = read_toml(path, what="plan file")
            unknown = sorted(set(document) - {"settle_s", "step"})
            if unknown:
                raise ValueError(f"{path}: {unknown[0]} is not a known key; a plan file takes settle_s and "
                                 "[[step]] tables")
            default = document.get("settle_s", settle_s)
            steps = document.get("step")
            if not isinstance(steps, list) or not all(isinstance(row, dict) for row in steps):
                raise ValueError(f"{path}: expected [[step]] tables with q1, q2, q3")
            return plan_from_rows(steps, str(path), default)
    except UnicodeDecodeError as error:
        raise UserError(f"{path}: not UTF-8 text (byte {error.start}); save it as UTF-8") from None
    except ValueError as error:
        raise UserError(str(error) if str(path) in str(error) else f"{path}: {error}") from None
    except OSError as error:
        raise UserError(f"{path}: cannot read: {error.strerror or error}") from None
    raise UserError(f"plan file {path}: expected a .csv or .toml file")
