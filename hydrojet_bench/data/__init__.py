"""Measurement data: the `Dataset` every analysis command consumes, and its loaders.

`load_dataset(path, profile)` is the one entry point for commands: it picks the reader by
the file's suffix: the CSV contract (`csv_io`) together with a rig profile
(`hydrojet_bench.profile`), or a bench session log (MCAP, `hydrojet_bench.logs`), which
carries its own profile.
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

    path: ``.csv`` (the contract in `hydrojet_bench.data.csv_io`) or ``.mcap`` (a bench
        session log: its EM tracker samples, `hydrojet_bench.logs.dataset_from_log`).
    profile: the rig the data came from, as a `RigProfile`, a TOML path or the name of
        a shipped profile (``"sim"``); a CSV cannot be read without one, a log uses the
        profile embedded in it when None.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".mcap":
        from ..logs import dataset_from_log  # here, not at the top: the logs package imports this one

        return dataset_from_log(path, profile)
    if suffix != ".csv":
        raise UserError(f"{path}: unknown data format {suffix or '(no suffix)'!r}; expected a .csv file "
                        "(see hydrojet_bench/data/csv_io.py for the columns) with --profile, or a session log (.mcap)")
    if profile is None:
        raise UserError(f"{path}: a CSV table needs a rig profile (--profile FILE.toml or a shipped "
                        "name such as 'sim') for gravity, sensor mountings and the rod")
    if not isinstance(profile, RigProfile):
        profile = load_profile(profile)
    return read_csv(path, profile)
