"""What an analysis command is given: a CSV table with the profile of its rig, or a bench
session log (MCAP) that carries its own profile. Sits above `data` and `logs`, which do
not know each other's formats."""

from __future__ import annotations

from pathlib import Path

from .data import Dataset, read_csv, read_csv_steps
from .errors import UserError
from .files import check_regular_input
from .logs import dataset_from_log
from .profile import RigProfile, load_profile


def load_dataset(path: str | Path, profile: RigProfile | str | Path | None) -> Dataset:
    """Load measurement data for analysis, choosing the reader by suffix.

    path: ``.csv`` (the contract in `hydrojet_bench.data.csv_io`) or ``.mcap`` (a bench
        session log: its EM tracker samples, `hydrojet_bench.logs.dataset_from_log`).
    profile: the rig the data came from, as a `RigProfile`, a TOML path or the name of
        a shipped profile (``"sim"``); a CSV cannot be read without one, a log uses the
        profile embedded in it when None.
    """
    path = Path(path)
    if path.suffix.lower() == ".mcap":
        return dataset_from_log(path, profile)
    return read_csv(path, _csv_profile(path, profile))


def load_steps(path: str | Path, profile: RigProfile | str | Path | None) -> Dataset:
    """``load_dataset(path, profile).quasistatic_steps()``; a CSV table is reduced as it
    is read, so a large one never sits whole in memory."""
    path = Path(path)
    if path.suffix.lower() == ".mcap":
        return dataset_from_log(path, profile).quasistatic_steps()
    return read_csv_steps(path, _csv_profile(path, profile))


def _csv_profile(path: Path, profile: RigProfile | str | Path | None) -> RigProfile:
    """The profile of a CSV table's rig, once ``path`` is known to be a readable table."""
    suffix = path.suffix.lower()
    if suffix != ".csv":
        raise UserError(f"{path}: unknown data format {suffix or '(no suffix)'!r}; expected a .csv file "
                        "(see hydrojet_bench/data/csv_io.py for the columns) with --profile, or a session log (.mcap)")
    if profile is None:
        raise UserError(f"{path}: a CSV table needs a rig profile (--profile FILE.toml or a shipped "
                        "name such as 'sim') for gravity, sensor mountings and the rod")
    if not isinstance(profile, RigProfile):
        profile = load_profile(profile)
    check_regular_input(path)  # a FIFO would block the reader forever
    return profile
