"""Measurement data: the `Dataset` every analysis command consumes, and its loaders.

`load_dataset(path, profile)` is the one entry point for commands: it picks the reader by
the file's suffix. Today that is the CSV contract (`csv_io`) together with a rig profile
(`hydrojet_bench.profile`); MCAP logs join here when the bench records them.
"""

from __future__ import annotations

from pathlib import Path

from ..errors import UserError
from ..profile import RigProfile, load_profile
from .csv_io import KNOWN_COLUMNS, OPTIONAL_COLUMNS, REQUIRED_COLUMNS, read_csv, write_csv
from .dataset import (UNUSABLE, Dataset, SampleFlag, average_quaternions, saturation_flags,
                      steps_from_runs)

__all__ = [
    "KNOWN_COLUMNS", "OPTIONAL_COLUMNS", "REQUIRED_COLUMNS", "UNUSABLE", "Dataset", "SampleFlag",
    "average_quaternions", "load_dataset", "read_csv", "saturation_flags", "steps_from_runs", "write_csv",
]

SUFFIXES = (".csv", ".mcap")


def load_dataset(path: str | Path, profile: RigProfile | str | Path | None) -> Dataset:
    """Load measurement data for analysis, choosing the reader by suffix.

    path: ``.csv`` (the contract in `hydrojet_bench.data.csv_io`); ``.mcap`` is refused
        with a UserError until MCAP import lands with the bench.
    profile: the rig the data came from, as a `RigProfile`, a TOML path or the name of
        a shipped profile (``"sim"``); a CSV cannot be read without one.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        raise UserError(f"{path}: MCAP import arrives with the bench (the recording issue); until then "
                        "give the data as CSV together with --profile")
    if suffix != ".csv":
        raise UserError(f"{path}: unknown data format {suffix or '(no suffix)'!r}; expected a .csv file "
                        "(see hydrojet_bench/data/csv_io.py for the columns) with --profile")
    if profile is None:
        raise UserError(f"{path}: a CSV table needs a rig profile (--profile FILE.toml or a shipped "
                        "name such as 'sim') for gravity, sensor mountings and the rod")
    if not isinstance(profile, RigProfile):
        profile = load_profile(profile)
    return read_csv(path, profile)
