"""The `hydrojet-bench` command line.

Each subcommand lives in `hydrojet_bench.commands.<name>` and exposes
`register(subparsers)`, which adds its parser and sets `func`; the commands share their
options (`commands.common`), their model rule (`hydrojet_bench.model_choice`) and their
output (`commands.render`). A `UserError` is printed as one clear line with exit code 2,
never as a traceback; every help ends with the exit codes (`render.EXIT_CODES`, and
those a command adds).
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import threading
from pathlib import Path

from rich.console import Console
from rich.markup import escape

from . import __version__
from .commands import render
from .errors import ConvergenceError, UserError
from .files import check_folder_target, check_writable_target

# Order is the order shown in --help.
COMMAND_MODULES = ("run", "replay", "sensors", "simulate", "calibrate", "compare", "diagnose", "study", "batch",
                   "perf", "warmup", "emulate", "recover")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The parser of every command, or, given the arguments of one command (``argv``
    starting with its name), of that command alone: importing every command loads
    every command's dependencies (plotting, data frames, task scheduling, drivers),
    which a `calibrate` of a large file then carries in memory for nothing."""
    parser = argparse.ArgumentParser(
        prog="hydrojet-bench",
        description="Hardware-in-the-loop bench for the HydroJet soft continuum robot.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    first = next((word for word in argv or () if not word.startswith("-")), None)
    for name in (first,) if first in COMMAND_MODULES else COMMAND_MODULES:
        importlib.import_module(f"{__package__}.commands.{name}").register(subparsers)
    render.add_exit_codes(parser, {1: "a result that is no answer (replay: errors not finite; batch, study: a log or cell failed)",
                                   129: "run stopped by SIGHUP (terminal closed; valves closed, log finished)",
                                   143: "run stopped by SIGTERM (valves closed, log finished)"})
    for command in _all_subparsers(parser):
        if "exit codes:" not in (command.epilog or ""):
            render.add_exit_codes(command)
    return parser


def _all_subparsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """Every command's parser, and the parsers of its own subcommands (`batch diagnose`)."""
    found = []
    for action in parser._subparsers._group_actions if parser._subparsers else ():
        for child in dict.fromkeys(action.choices.values()):
            found += [child, *_all_subparsers(child)]
    return found


class Terminated(KeyboardInterrupt):
    """SIGTERM (kill, a scheduler's time limit) in a command that sets the default
    ``stops_on_sigterm`` (`study`, `batch`; `run` handles its own stop signals around the
    valves), raised where Ctrl-C would be, so that the same clean-up runs: a study's
    cluster closes, the rows stored so far stay."""


def _raise_terminated(number: int, frame: object) -> None:
    raise Terminated


def main(argv: list[str] | None = None) -> int:
    try:
        # Ctrl-C while the command's modules load (numba's take seconds) is no bug either.
        parser = build_parser(sys.argv[1:] if argv is None else argv)
    except KeyboardInterrupt:
        Console(stderr=True).print("interrupted")
        return 130
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    on_sigterm = getattr(args, "stops_on_sigterm", False) and threading.current_thread() is threading.main_thread()
    previous_sigterm = signal.signal(signal.SIGTERM, _raise_terminated) if on_sigterm else None
    try:
        json_path = getattr(args, "json", None)
        if isinstance(json_path, Path) and str(json_path) != render.STDOUT:
            # Said now, not after the minutes of work whose figures it would hold.
            check_writable_target(json_path, "JSON figures", overwrite=True)
        if isinstance(report := getattr(args, "report", None), Path):
            check_folder_target(report, "report folder")
        return int(args.func(args) or 0)
    except UserError as error:
        _print_error(str(error))
        return 2
    except ConvergenceError as error:
        # Parameters or forces the rod cannot carry (a tip load that buckles it, a huge
        # jet force): the user's inputs, not a bug, so one line naming them.
        _print_error(f"{error}; check the parameters and forces in {_input_files(args)}")
        return 2
    except Terminated:
        Console(stderr=True).print("terminated (SIGTERM)")
        return 128 + signal.SIGTERM
    except KeyboardInterrupt:
        Console(stderr=True).print("interrupted")
        return 130
    except BrokenPipeError:
        # The reader stopped early (`| head`): no one to tell. Standard output goes to
        # /dev/null so that flushing it at exit does not fail again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141
    finally:
        if previous_sigterm is not None:
            signal.signal(signal.SIGTERM, previous_sigterm)


def _input_files(args: argparse.Namespace) -> str:
    files = [str(value) for option in ("params", "baseline", "profile", "plan", "input")
             if (value := getattr(args, option, None)) is not None]
    effect_files = [spec for option in ("effect", "hidden") for spec in getattr(args, option, None) or ()
                    if ":" in spec]
    return ", ".join(effect_files + files) or "the command's inputs"


def _print_error(message: str) -> None:
    # The message quotes the user's file names, keys and cells: escaped, "[rod]" stays "[rod]".
    Console(stderr=True).print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True, emoji=False)


if __name__ == "__main__":
    sys.exit(main())
