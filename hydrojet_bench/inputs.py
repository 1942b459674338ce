"""What an analysis command is given: a CSV table with the profile of its rig, or a bench
session log (MCAP) that carries its own profile. Sits above `data` and `logs`, which do
not know each other's formats."""

from __future__ import annotations

from pathlib import Path

from .data import Dataset, read_csv, read_csv_steps
from .data.csv_io import recorded_profile, recorded_with
from .errors import UserError
from .files import check_regular_input
from .logs import dataset_from_log
from .logs.dataset import rig_profile_of_log
from .logs.reader import read_metadata
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


# The tables that describe the rig an analysis models (not how a session ran).
_RIG_TABLES = ("gravity", "base", "base_sensor", "tip_sensor", "rod", "capsule", "jets")


def recorded_elsewhere(path: Path, profile_given: str | None, profile: RigProfile) -> dict[str, str] | None:
    """When the data may be another rig's than ``profile`` says: a CSV table read with
    the default profile (no ``--profile`` given) whose comments say another profile wrote
    it (`write_csv` notes it), or a session log read with a ``--profile`` whose rig
    (gravity, mountings, rod, capsule, jets) differs from the one the log embeds. None
    otherwise; else ``recorded``, ``used`` and the one-line ``message``."""
    if Path(path).suffix.lower() == ".mcap":
        if profile_given is None:
            return None
        try:
            embedded = rig_profile_of_log(path, None, read_metadata(path))
        except UserError:
            return None  # a log that embeds none: the profile given is all there is
        differ = [table for table in _RIG_TABLES if getattr(embedded.config, table) != getattr(profile.config, table)]
        if not differ:
            return None
        return {"recorded": embedded.name, "used": profile.name, "tables": ", ".join(differ),
                "message": f"{path} embeds rig profile {embedded.name!r} and is read with {profile.name!r} "
                           f"(--profile), whose {', '.join(differ)} differ: the analysis models the profile given"}
    if profile_given is not None:
        return None
    recorded = recorded_profile(path)
    if recorded is None or recorded_with(recorded, profile):
        return None
    return {"recorded": recorded, "used": profile.name,
            "message": f"{path} was recorded with rig profile {recorded} (its comments say so) and is read with "
                       f"{profile.name!r}, the default for a CSV table: give --profile"}
