"""The notices the analysis commands give about their input, each one warning line on
standard error and a field of their JSON documents: a session log that is cut or
damaged (``log_damage``), a CSV table read with the default profile although
another one wrote it (``profile_mismatch``), and steps of a single sample, which are no
settled equilibria (``single_sample_steps``)."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from ..data.csv_io import recorded_profile, recorded_with
from ..data.dataset import Dataset
from ..logs.condition import incomplete_log
from ..profile import RigProfile


def _warn(text: str) -> None:
    Console(stderr=True).print(f"warning: {text}", style="yellow", markup=False, highlight=False, soft_wrap=True)


def warn_if_incomplete(path: Path) -> dict[str, object] | None:
    """For a session log (.mcap) that is truncated or damaged: print what it lost and how
    many plan steps the analysis is missing, and return that for the JSON document. None
    for a whole log or another kind of input."""
    condition = incomplete_log(path)
    if condition is None:
        return None
    _warn(condition.notice())
    return condition.as_dict()


def warn_if_recorded_elsewhere(path: Path, profile_given: str | None, profile: RigProfile) -> dict[str, str] | None:
    """For a CSV table read with the default ``profile`` (no ``--profile`` given) whose
    comments say another profile wrote it (`write_csv` notes it): gravity, mountings and
    rod may all be another rig's. Print so and return it for the JSON document; None
    otherwise."""
    if profile_given is not None or Path(path).suffix.lower() == ".mcap":
        return None
    recorded = recorded_profile(path)
    if recorded is None or recorded_with(recorded, profile):
        return None
    _warn(f"{path} was recorded with rig profile {recorded} (its comments say so) and is read with "
          f"{profile.name!r}, the default for a CSV table: give --profile")
    return {"recorded": recorded, "used": profile.name}


def warn_if_unsettled(path: Path, steps: Dataset, log_damage: dict[str, object] | None) -> dict[str, int] | None:
    """For steps (``steps``, reduced by `Dataset.quasistatic_steps`) of which some
    average a single sample, as when the jets change at every row of a table: print how
    many and return that for the JSON document; None when every step averages more, or
    for a damaged log (``log_damage`` from `warn_if_incomplete`), whose notice already
    says what was cut away, which may leave a step one sample. The models are
    quasistatic, so such a step is taken for a settled equilibrium and a rod still
    moving reads as model error."""
    if steps.samples is None or log_damage is not None:
        return None
    single = int((steps.samples == 1).sum())
    if not single:
        return None
    _warn(f"{path}: {single} of {len(steps)} steps average a single sample (the jets changed at the next "
          "row), so they are no settled equilibria, and the quasistatic models take a rod still moving "
          "for model error: label the settled rows (sweep and step columns) or hold each command longer")
    return {"count": single, "steps": len(steps)}
