"""`hydrojet-bench recover INPUT [-o OUT]`: rewrite a session log that a crash left
unfinished (or any damaged MCAP file) into a valid, finished one.

Every intact chunk is kept (a damaged one is skipped, and the command says what it
held); the output opens in any MCAP reader and in Foxglove or Lichtblick. It never
replaces an existing file unless --overwrite. Every analysis command also reads an
unfinished or damaged log directly.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import UserError
from ..logs import recover_log, recovered_path
from . import render


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("recover", help="rewrite an unfinished or damaged session log into a valid one")
    parser.add_argument("input", type=Path, metavar="INPUT", help="a session log (.mcap), possibly cut off by a crash")
    parser.add_argument("-o", "--output", type=render.file_path, default=None,
                        help="where to write (default: INPUT with .recovered.mcap instead of .mcap)")
    parser.add_argument("--overwrite", action="store_true", help="replace the output file if it exists")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.input.is_file() and args.input.stat().st_size == 0:
        raise UserError(f"{args.input}: empty file (0 bytes): nothing to recover (a session that stopped before "
                        "writing anything, or not a session log)")
    output = args.output or recovered_path(args.input)
    report = recover_log(args.input, output, overwrite=args.overwrite)
    if report.first_t_s is None or report.last_t_s is None:
        span = "no messages"
    else:
        span = (f"{report.messages} messages, t = {report.first_t_s:.3f} s to {report.last_t_s:.3f} s "
                f"({report.last_t_s - report.first_t_s:.3f} s)")
    state = ("was truncated (unfinished); kept everything before the cut" if report.truncated
             else "ended properly" if report.damage is not None else "was complete")
    console = render.console()
    console.print(f"{args.input} {state}", highlight=False, soft_wrap=True, markup=False)
    if report.damage is not None:
        render.console(stderr=True).print(f"warning: {args.input} is damaged: {report.damage.describe()}; kept every "
                                          "intact chunk", highlight=False, soft_wrap=True, markup=False)
    console.print(f"wrote {output}: {span}", highlight=False, soft_wrap=True, markup=False)
    if report.truncated or report.damage is not None:
        console.print(f"(the copy records what {args.input} lost: every analysis of it says so)", highlight=False,
                      soft_wrap=True, markup=False)
    return 0
