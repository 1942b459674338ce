"""How every command shows its results: rich tables on the console, JSON documents in a
file or on standard output (``--json -``, which moves the tables to standard error)."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from ..errors import UserError

STDOUT = "-"


def add_json_argument(parser: argparse.ArgumentParser, what: str = "the figures") -> None:
    parser.add_argument("--json", type=Path, metavar="PATH",
                        help=f"write {what} as JSON to PATH (- for standard output)")


def console_for(args: argparse.Namespace) -> Console:
    """The console for the tables: standard output unless the JSON document goes there."""
    return Console(stderr=_is_stdout(getattr(args, "json", None)))


def plain(value: object) -> str:
    """User text (a path, a profile name, a CSV cell) made inert for rich markup, so that
    ``[bold]x.csv`` or ``[/x]`` prints as written instead of styling or failing."""
    return escape(str(value))


def table(title: str, labels: Sequence[str], numbers: Sequence[str], caption: str | None = None) -> Table:
    """A table (its title printed as written, no markup) whose label columns
    (left-aligned, never wrapped) come before its number
    columns (right-aligned)."""
    result = Table(title=plain(title), caption=caption)
    for header in labels:
        result.add_column(header, no_wrap=True)
    for header in numbers:
        result.add_column(header, justify="right")
    return result


def write_json(path: Path, document: object) -> None:
    """``document`` as indented JSON to ``path`` (``-``: standard output); a path that
    cannot be written is a `UserError`."""
    text = json.dumps(document, indent=2) + "\n"
    if _is_stdout(path):
        sys.stdout.write(text)
        return
    try:
        Path(path).write_text(text)
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror}") from None


def _is_stdout(path: Path | None) -> bool:
    return path is not None and str(path) == STDOUT
