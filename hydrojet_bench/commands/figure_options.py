"""`--format png|svg|pdf`: the file format of the figures a command writes with `--report`
(kept apart from `analysis.figures` so that building the parser never imports matplotlib)."""

from __future__ import annotations

import argparse

FIGURE_FORMATS = ("png", "svg", "pdf")


def add_format_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--format", dest="figure_format", choices=FIGURE_FORMATS, default="png",
                        help="file format of the --report figures: png (default), or svg / pdf for print")
