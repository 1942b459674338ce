"""The notice every analysis command gives about a session log that is cut or damaged:
one warning line on standard error, and the ``log_damage`` field of its JSON document."""

from __future__ import annotations

from pathlib import Path

from rich.console import Console

from ..logs.condition import log_condition


def warn_if_incomplete(path: Path) -> dict[str, object] | None:
    """For a session log (.mcap) that is truncated or damaged: print what it lost and how
    many plan steps the analysis is missing, and return that for the JSON document. None
    for a whole log or another kind of input."""
    if Path(path).suffix.lower() != ".mcap":
        return None
    condition = log_condition(path)
    if condition.whole:
        return None
    Console(stderr=True).print(f"warning: {condition.notice()}", style="yellow", markup=False, highlight=False,
                               soft_wrap=True)
    return condition.as_dict()
