"""`hydrojet-bench demo`: placeholder until the model demo lands (replaced in this issue)."""

from __future__ import annotations

import argparse


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("demo", help="show the models on a simulated sweep")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    print("demo: models not built yet")
    return 0
