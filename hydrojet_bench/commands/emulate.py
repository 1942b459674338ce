"""`hydrojet-bench emulate aurora|valves`: serve a device emulator on a pseudo-terminal.

Prints the pty path and runs until Ctrl-C, so that any other program (a script, a
vendor tool, a real client library) can be pointed at it. The emulator is driven by a
plant at rest: the base sensor at the origin and the tip 70 mm below it. (The digital
twin and rig profiles will drive it once they exist.)
"""

from __future__ import annotations

import argparse

from rich.console import Console

from ..errors import UserError


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("emulate", help="serve a device emulator on a pty until Ctrl-C")
    parser.add_argument("device", choices=("aurora", "valves"), help="which device to emulate")
    parser.add_argument("--watchdog-ms", type=float, default=500.0,
                        help="valves: firmware watchdog period in ms (default 500)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from drivers.plant import StaticPlant

    console = Console(stderr=True)
    plant = StaticPlant()
    if args.device == "valves":
        if not args.watchdog_ms > 0:
            raise UserError(f"--watchdog-ms must be positive, got {args.watchdog_ms}")
        from drivers.valve.serve import serve

        serve(plant, args.watchdog_ms / 1000.0,
              announce=lambda path: print(f"valve controller emulator on {path}", flush=True))
    else:
        from drivers.aurora.serve import serve_pty

        serve_pty(plant, announce=lambda line: print(line, flush=True))
    console.print("emulator stopped")
    return 0
