"""How every command shows its results: rich tables on the console, JSON documents in a
file or on standard output (``--json -``, which moves the tables to standard error).

Results go to standard output, progress and warnings to standard error. On a pipe or a
file, tables keep their natural width, so no name is ever cut short ("…") or wrapped,
and text lines are not wrapped either: ``grep`` and ``cut`` see whole lines."""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console
from rich.markup import escape
from rich.table import Table

from ..errors import UserError
from ..files import check_replaceable

STDOUT = "-"
# The width of a console that is not a terminal: a table is printed at its natural width
# below it, and no table here comes near it.
PIPE_WIDTH = 1000

EXIT_CODES = {0: "done", 1: "internal error (a bug: it prints a traceback)",
              2: "a mistake in the command line or its inputs (one line on standard error naming the file "
                 "and field)", 130: "interrupted (Ctrl-C)",
              141: "standard output closed before the end (a reader such as `head` stopped early)"}


def file_path(text: str) -> Path:
    """An argparse type for a file to write: a path ending in a separator names a folder
    (``Path`` would drop it, and a file named like the folder would be written)."""
    if text.endswith(("/", os.sep)):
        raise argparse.ArgumentTypeError(f"{text!r} ends in {text[-1]!r}, a folder; give a file name")
    return Path(text)


def add_json_argument(parser: argparse.ArgumentParser, what: str = "the figures") -> None:
    parser.add_argument("--json", type=Path, metavar="PATH",
                        help=f"write {what} as JSON to PATH (- for standard output)")


def add_exit_codes(parser: argparse.ArgumentParser, codes: dict[int, str] | None = None,
                   replacing: dict[int, str] | None = None) -> None:
    """State the exit codes at the end of ``parser``'s help: the common ones and, in
    ``codes``, those the command adds (or another meaning of a common one); in
    ``replacing``, what a common one means instead for this command."""
    described = {**EXIT_CODES, **(replacing or {})}
    for code, meaning in (codes or {}).items():
        described[code] = f"{described[code]}, or {meaning}" if code in described else meaning
    text = "exit codes: " + "; ".join(f"{code} {described[code]}" for code in sorted(described)) + "."
    parser.epilog = f"{parser.epilog} {text}" if parser.epilog else text


def console(stderr: bool = False) -> Console:
    """A console on standard output (or error) that, when it is not a terminal, never
    cuts or wraps (see the module docstring)."""
    result = Console(stderr=stderr)
    # rich exits with 1, the code of a bug, when the reader of a pipe goes away: raised
    # instead, for the command line to exit as a shell does on SIGPIPE.
    result.on_broken_pipe = _raise_broken_pipe
    if not result.is_terminal:
        result.width = PIPE_WIDTH
        result.soft_wrap = True  # titles and text lines whole too, never cropped
    return result


def console_for(args: argparse.Namespace) -> Console:
    """The console for the results: standard output unless the JSON document goes there."""
    return console(stderr=_is_stdout(getattr(args, "json", None)))


def progress_console() -> Console:
    """Where progress, notes and warnings go: standard error."""
    return console(stderr=True)


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


def json_row(row: dict) -> dict:
    """A pandas record as JSON-ready values: numpy scalars as Python ones, NaN and
    missing figures as None."""
    values = {key: value.item() if hasattr(value, "item") else value for key, value in row.items()}
    return {key: None if isinstance(value, float) and math.isnan(value) else value for key, value in values.items()}


def check_distinct_outputs(outputs: dict[str, Path | None]) -> None:
    """Refuse two options (``--json``, ``-o`` ...) naming one file: the second write would
    replace the first, after the work, or be refused then."""
    seen: dict[Path, str] = {}
    for option, path in outputs.items():
        if path is None or _is_stdout(path):
            continue
        resolved = Path(path).resolve()
        if resolved in seen:
            raise UserError(f"{path}: named by both {seen[resolved]} and {option}; give each its own file")
        seen[resolved] = option


def check_json_output(path: Path | None) -> None:
    """Refuse (`check_replaceable`) to write a JSON document over anything but an earlier
    one; standard output and no path pass."""
    if path is not None and not _is_stdout(path):
        check_replaceable(Path(path), "JSON document", lambda head: head.lstrip()[:1] in (b"{", b"["))


def write_json(path: Path, document: object) -> None:
    """``document`` as indented JSON to ``path`` (``-``: standard output); a path that
    cannot be written is a `UserError`."""
    text = json.dumps(document, indent=2) + "\n"
    if _is_stdout(path):
        sys.stdout.write(text)
        return
    check_json_output(path)
    try:
        Path(path).write_text(text)
    except OSError as error:
        raise UserError(f"cannot write {path}: {error.strerror}") from None


def _raise_broken_pipe() -> None:
    raise BrokenPipeError("standard output closed")


def _is_stdout(path: Path | None) -> bool:
    return path is not None and str(path) == STDOUT
