"""`hydrojet-bench emulate aurora|valves [aurora|valves]`: serve device emulators on
pseudo-terminals.

Prints each pty path and runs until Ctrl-C, so that any other program (a script, a
vendor tool, a real client library, `run` with a profile naming the ptys) can be pointed
at it. The emulators' truth is the digital twin of a sim profile (``--profile``, default
``sim``: its rod, clamp pose, sensor mountings and hidden effects), at rest until the
valve emulator opens a jet; or, with ``--static``, a plant whose base sits at the origin
and tip 70 mm below it. Both devices in one command share one twin, so the tracker sees
the tip move when the valves open: two separate commands each have their own.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from collections.abc import Callable

from drivers.valve.protocol import DEFAULT_WATCHDOG_MS

from ..errors import UserError
from . import render

DEVICES = ("aurora", "valves")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("emulate", help="serve device emulators on ptys until Ctrl-C")
    parser.add_argument("device", nargs="+", choices=DEVICES,
                        help="which device(s) to emulate; 'aurora valves' serves both from one twin, so the "
                             "tracker sees the tip move when the valves open")
    parser.add_argument("--watchdog-ms", type=float,
                        help=f"valves: firmware watchdog period in ms, 1..65535 (default {DEFAULT_WATCHDOG_MS})")
    parser.add_argument("--profile", default="sim",
                        help="sim profile whose digital twin drives the emulator (default: sim)")
    parser.add_argument("--static", action="store_true",
                        help="serve a static pose instead of the digital twin")
    # Ctrl-C is how an emulator is meant to stop (it serves until then; `drivers.*.serve`
    # close the valves and the pty on it), so it is no interruption: exit 0, as the
    # scripts and tests that start one and stop it expect.
    render.add_exit_codes(parser, replacing={130: "interrupted (Ctrl-C) before it serves; Ctrl-C while it serves "
                                                  "is its normal end, exit 0 (valves and pty closed)"})
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    console = render.console(stderr=True)
    devices = tuple(dict.fromkeys(args.device))
    if len(devices) < len(args.device):
        raise UserError(f"emulate: a device given twice ({' '.join(args.device)}); each is served once")
    if "valves" not in devices and args.watchdog_ms is not None:
        raise UserError(f"--watchdog-ms is the valve controller's; the {devices[0]} emulator has none")
    servers: list[Callable[[threading.Event], object]] = []
    plant = _plant(args)
    printing = threading.Lock()

    def announce(line: str) -> None:
        with printing:  # two servers announce from two threads: one whole line each
            sys.stdout.write(f"{line}\n")
            sys.stdout.flush()

    if "valves" in devices:
        watchdog_ms = DEFAULT_WATCHDOG_MS if args.watchdog_ms is None else args.watchdog_ms
        # The firmware holds the period in whole milliseconds, 16 bits.
        if not 1 <= watchdog_ms <= 0xFFFF:
            raise UserError(f"--watchdog-ms must be 1..65535 (the firmware's whole milliseconds), got {watchdog_ms:g}")
        from drivers.valve.serve import serve

        servers.append(lambda stop: serve(_ReportingPlant(plant), round(watchdog_ms) / 1000.0, stop=stop,
                                          announce=lambda path: announce(f"valve controller emulator on {path}")))
    if "aurora" in devices:
        from drivers.aurora.serve import serve_pty

        servers.append(lambda stop: serve_pty(plant, announce=announce, stop=stop))
    _serve_together(servers)
    console.print("emulator stopped" if len(servers) == 1 else "emulators stopped")
    return 0


def _serve_together(servers: list[Callable[[threading.Event], object]]) -> None:
    """Run each server (it serves until the event is set, or Ctrl-C in the main thread),
    the last in this thread, where Ctrl-C arrives, the others in threads; when one ends
    (Ctrl-C, or its emulator died) all stop, the valves closing as their server ends. An
    emulator's error is raised here, after every server stopped."""
    stop = threading.Event()
    errors: list[BaseException] = []

    def in_background(server: Callable[[threading.Event], object]) -> None:
        try:
            server(stop)
        except BaseException as error:  # noqa: BLE001 - re-raised in the main thread
            errors.append(error)
        finally:
            stop.set()

    threads = [threading.Thread(target=in_background, args=(server,), name="emulator", daemon=True)
               for server in servers[:-1]]
    for thread in threads:
        thread.start()
    try:
        servers[-1](stop)
    finally:
        stop.set()
        for thread in threads:
            thread.join()
    if errors:
        raise errors[0]


def _plant(args: argparse.Namespace):
    if args.static:
        from drivers.plant import StaticPlant

        return StaticPlant()
    from ..profile import load_profile
    from ..twin import DigitalTwin, TwinConfig

    return DigitalTwin(TwinConfig.from_profile(load_profile(args.profile)))


class _ReportingPlant:
    """Prints every valve change, so a user (or a test) sees the emulator close the valves
    when the host falls silent: ``valves 500 0 0 at monotonic 1234.567 s``. The time is
    the system's monotonic clock, comparable across processes on this machine."""

    def __init__(self, plant) -> None:
        self._plant = plant
        self.gravity_in_tracker_m_s2 = plant.gravity_in_tracker_m_s2
        self.magnetic_field_in_tracker_ut = plant.magnetic_field_in_tracker_ut

    def sensor_truth(self, sensor: str, t_s: float):
        return self._plant.sensor_truth(sensor, t_s)

    def apply_valve_duties(self, duties_permille, t_s: float) -> None:
        print(f"valves {' '.join(str(int(d)) for d in duties_permille)} at monotonic {time.monotonic():.3f} s",
              flush=True)
        self._plant.apply_valve_duties(duties_permille, t_s)
