"""The commands a command suggests next, written so that they run as printed: every
word shell-quoted, the rig profile carried along when one was given."""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Sequence
from pathlib import Path

from rich.console import Console

PROGRAM = "hydrojet-bench"


def command(*words: object) -> str:
    """``hydrojet-bench WORD ...`` as a shell line; None words are left out, so optional
    parts can be given inline."""
    return " ".join([PROGRAM, *(shlex.quote(str(word)) for word in words if word is not None)])


def input_words(args: argparse.Namespace) -> tuple[object, ...]:
    """The command's INPUT and, when it was given, ``--profile`` with its value."""
    profile = getattr(args, "profile", None)
    return (Path(args.input),) + (("--profile", profile) if profile else ())


def effect_words(specs: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """``--effect SPEC`` for each spec."""
    return tuple(word for spec in specs for word in ("--effect", spec))


def print_next(console: Console, intro: str, lines: Sequence[str]) -> None:
    """``Next: intro``, then each line; a command (``hydrojet-bench ...``) indented on a
    line of its own and never wrapped, so that it can be copied (or collected) whole."""
    console.print(f"Next: {intro}", soft_wrap=True, highlight=False, markup=False)
    for line in lines:
        console.print(f"  {line}" if line.startswith(f"{PROGRAM} ") else line,
                      soft_wrap=True, highlight=False, markup=False)
