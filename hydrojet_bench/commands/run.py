"""`hydrojet-bench run`: a bench session, on the simulated rig by default.

Plays a plan (default: the paper's protocol, 40 calibration poses then nine sweeps),
calibrates on the calibration poses when they end, estimates the disturbance live,
records everything to an MCAP log, shows a live view, and at the end prints the paper's
Table II for the session (optionally a report folder of plots) and the commands to try
next. Ctrl-C, SIGTERM or SIGHUP (its terminal or ssh connection closed) stop it cleanly:
valves off, log finished.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import shlex
import signal
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

import msgspec
import numpy as np
from rich.console import Console

from ..config.schema import MAX_TIME_SCALE, MIN_TIME_SCALE
from ..errors import UserError
from ..estimation.calibration import determinable
from ..files import check_writable_target, create_numbered, make_folder_for
from ..model_choice import ModelDefaults, model_choice
from ..plans import clipped_warning, short_steps_warning
from ..profile import load_profile
from . import render
from .calibrate import UNTRUSTED
from .common import add_model_arguments, check_seed
from .figure_options import add_format_argument
from .next_steps import command

if TYPE_CHECKING:
    from ..bench.foxglove_live import FoxgloveLive

DEFAULT_LOG_DIR = Path("sessions")
# Signals that stop a session as Ctrl-C does (valves closed, log finished), exiting with
# 128 + the signal's number as a shell reports a process it ended: SIGTERM (kill, a
# service manager) and SIGHUP (the terminal or ssh connection closed).
STOP_SIGNALS = (signal.SIGTERM, signal.SIGHUP)
FOXGLOVE_PORT = 8765  # Foxglove's and Lichtblick's default for a WebSocket connection


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("run", help="run a bench session (simulated rig by default)")
    parser.add_argument("--profile", default="sim", help="rig profile: a TOML file or a shipped name (default: sim)")
    parser.add_argument("--plan", default="paper",
                        help="paper (default), calibration[:COUNT], sweeps, imu-vs-em, hold[:SECONDS], or a .csv/.toml "
                             "plan file")
    parser.add_argument("--log", type=Path, metavar="FILE",
                        help=f"MCAP log to write, a new file (default: {DEFAULT_LOG_DIR}/<profile>-<time>.mcap, "
                             "with -1, -2... added if a session started in the same second)")
    parser.add_argument("--overwrite", action="store_true", help="replace the --log file if it exists")
    add_model_arguments(parser, default="the profile's [estimator] model",
                        params="start from these calibrated parameters (default: the profile's nominal ones)")
    parser.add_argument("--no-calibration", action="store_true",
                        help="do not calibrate on the plan's calibration poses")
    parser.add_argument("--time-scale", type=float, metavar="X",
                        help="session seconds per wall second on the simulated rig (default: the profile's)")
    parser.add_argument("--seed", type=int, help="digital twin noise seed (default: the profile's)")
    parser.add_argument("--report", type=Path, metavar="DIR", help="write the session's figures to this folder")
    add_format_argument(parser)
    parser.add_argument("--no-live", action="store_true", help="no live view (plain progress lines)")
    parser.add_argument("--foxglove", nargs="?", const=str(FOXGLOVE_PORT), metavar="[HOST:]PORT",
                        help="stream the session to Foxglove or Lichtblick over their WebSocket protocol on "
                             f"ws://HOST:PORT (default 127.0.0.1:{FOXGLOVE_PORT}; port 0: any free one, printed; "
                             "the server has no authentication: another HOST opens the session to that network)")
    parser.epilog = ("Progress (the live view, or a line per sweep) and warnings go to standard error; what runs, "
                     "its Table II and the next commands to standard output.")
    parser.add_argument("--skip-checks", action="store_true",
                        help="skip the wiring and level checks before the plan (the log records the skip)")
    render.add_exit_codes(parser, {UNTRUSTED: "the session's calibration failed, did not converge or left a value on "
                                              "a bound (the session ran on; its warnings say which, and its Table II "
                                              "is not that of a calibrated model)",
                                   128 + signal.SIGHUP: "stopped by SIGHUP: its terminal or ssh connection "
                                                        "closed (valves closed, log finished)",
                                   128 + signal.SIGTERM: "stopped by SIGTERM (valves closed, log finished)"})
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # The server first: a taken port stops the command before a log file is reserved.
    with _foxglove(args.foxglove) as server:
        return _run(args, server)


def _run(args: argparse.Namespace, server: FoxgloveLive | None) -> int:
    from ..bench.plan_choice import choose_plan
    from ..bench.session import SessionRequest

    check_seed(args.seed)
    profile = load_profile(args.profile)
    settings = profile.config
    if args.time_scale is not None:
        if not MIN_TIME_SCALE <= args.time_scale <= MAX_TIME_SCALE:
            raise UserError(f"--time-scale must be at least {MIN_TIME_SCALE:g} (real time: the devices' timeouts "
                            f"are wall time) and at most {MAX_TIME_SCALE:g} (the simulated rig cannot keep up "
                            f"beyond), got {args.time_scale}")
        real = settings.transports.real_devices()
        if real and args.time_scale != 1.0:
            # The clock runs on wall time with any real device (`Session`): the same rule
            # as the profile's [session] time_scale.
            raise UserError(f"--time-scale {args.time_scale:g}: {profile.source} drives a real device ({real[0]}), "
                            "and a rig with any real device runs on wall time (only the fully simulated rig "
                            "takes --time-scale)")
        settings = msgspec.structs.replace(settings, session=msgspec.structs.replace(settings.session,
                                                                                     time_scale=args.time_scale))
    limits = tuple(table.max_force_n for table in settings.valve_calibrations())
    plan, clipped = choose_plan(args.plan, settle_s=settings.session.settle_s).clipped(limits)
    clip_warning = clipped_warning(clipped, limits)
    plan_warnings = tuple(filter(None, (clip_warning, short_steps_warning(plan, settings.session.window_s))))
    choice = model_choice(args, ModelDefaults(settings.estimator.model, tuple(settings.estimator.effects),
                                              origin=f"{profile.source} (estimator.effects)"))
    model, requested = choice.model, choice.requested
    if args.log is not None:
        # Refused here, before the session starts; the log writer's exclusive create
        # settles a race with another process.
        make_folder_for(args.log)
        check_writable_target(args.log, "session log", overwrite=args.overwrite)
        log_path, overwrite = args.log, args.overwrite
    else:
        # Reserved (created empty, exclusively) so that a session started in the same
        # second gets another name; the session then writes its reservation.
        log_path = create_numbered(DEFAULT_LOG_DIR / f"{profile.name}-{time.strftime('%Y%m%d-%H%M%S')}.mcap",
                                   "session log")
        overwrite = True
    request = SessionRequest(profile=profile, settings=settings, plan=plan, log_path=log_path, model=model,
                             effects=choice.effect_specs, params=choice.parameters(profile.model_parameters()),
                             calibrate=not args.no_calibration, calibration_names=choice.calibration_names,
                             seed=args.seed, warnings=plan_warnings
                             # The session's own calibration fits what the file did not.
                             + (choice.uncalibrated(profile) if args.no_calibration else ()),
                             command_line=shlex.join(["hydrojet-bench", *sys.argv[1:]]), overwrite_log=overwrite,
                             setup_checks=not args.skip_checks)
    console = render.console_for(args)
    progress = render.progress_console()
    rig = ("simulated rig" if settings.transports.all_simulated
           else "rig, some devices emulated" if settings.transports.simulated else "rig")
    console.print(f"session on [bold]{render.plain(profile.name)}[/] ({rig}): "
                  f"{len(plan)} steps, {plan.duration_s:.0f} s of session time at x{settings.session.time_scale:g}, "
                  f"model {model.name}{' + ' + ', '.join(e.name for e in requested) if requested else ''}; "
                  f"log {render.plain(log_path)}", highlight=False)
    for warning in plan_warnings:
        progress.print(f"[yellow]warning:[/] {render.plain(warning)}")
    if server is not None:
        progress.print(f"Foxglove: open a connection to {server.url} (layout: docs/foxglove/hydrojet.json)",
                       highlight=False, markup=False)
    from ..bench.event_loop import run_session

    try:
        result = run_session(_run_session(request, progress, live=not args.no_live and progress.is_terminal,
                                          clipped=frozenset(clipped), on_log_message=server and server.publish))
    except KeyboardInterrupt:
        # The session has closed the valves and finished its log on the way out.
        progress.print(f"[yellow]interrupted:[/] valves closed, log finished: {render.plain(log_path)}")
        _say_no_report(progress, args, log_path)
        return 130
    if isinstance(result, signal.Signals):
        progress.print(f"[yellow]stopped by {result.name}:[/] valves closed, log finished: {render.plain(log_path)}")
        _say_no_report(progress, args, log_path)
        return 128 + result
    _print_outcome(console, progress, result, model.name, len(choice.calibration_names), args)
    return 0 if _calibration_trusted(result) else UNTRUSTED


def _calibration_trusted(result) -> bool:
    """Whether the session's calibration, if it ran, left parameters to trust: it did
    not fail and, as `calibrate` and `replay` judge theirs, its fit converged with no
    value on a bound."""
    calibration = result.calibration
    return result.calibration_failure is None and (calibration is None
                                                   or (calibration.converged and not calibration.at_bound))


def _say_no_report(progress: Console, args: argparse.Namespace, log_path: Path) -> None:
    """A stopped session writes no ``--report`` (it is the finished session's): say so,
    and, when the log holds finished sweep steps to report on, the command that writes
    it from the log (replay with the live settings reproduces the live estimates)."""
    if args.report is None:
        return
    line = f"no report written to {args.report}: the session was stopped before its end"
    if _has_sweep_steps(log_path):
        format_words = () if args.figure_format == "png" else ("--format", args.figure_format)
        line += (f"; {command('replay', log_path, '--online', '--report', args.report, *format_words)} writes it "
                 "from the log's finished steps")
    else:
        line += ", and its log holds no finished sweep step to report on"
    progress.print(f"[yellow]warning:[/] {render.plain(line)}", highlight=False, soft_wrap=True)


def _has_sweep_steps(log_path: Path) -> bool:
    """Whether the session log holds a finished step of a sweep (what a report is of)."""
    from ..logs import read_log
    from ..logs.topics import Step

    try:
        return any(step.sweep >= 0 for step in read_log(log_path, topics=[Step.topic]).on(Step))
    except (UserError, OSError):  # no log, or one cut before it held anything
        return False


def _foxglove(address: str | None) -> contextlib.AbstractContextManager:
    """The live Foxglove server of ``--foxglove [HOST:]PORT`` (None without the option)."""
    if address is None:
        return contextlib.nullcontext()
    from ..bench.foxglove_live import LOOPBACK, FoxgloveLive

    host, _, port = address.rpartition(":")
    if not port.isdigit() or not 0 <= int(port) <= 65535:
        raise UserError(f"--foxglove {address}: expected [HOST:]PORT, a port 0 to 65535")
    return FoxgloveLive(int(port), host or LOOPBACK)


async def _run_session(request, console: Console, live: bool, clipped: frozenset[int], on_log_message=None):
    from ..bench.live_view import LiveView
    from ..bench.session import Session

    stopped_by: signal.Signals | None = None
    task = asyncio.current_task()
    loop = asyncio.get_running_loop()
    terminals = _terminals()

    def on_signal(number: signal.Signals) -> None:
        nonlocal stopped_by
        if number == signal.SIGHUP:
            _away_from_lost_terminal(terminals)
        if stopped_by is None:  # cancelled once: a second signal changes nothing
            stopped_by = number
            task.cancel()

    for number in STOP_SIGNALS:
        loop.add_signal_handler(number, on_signal, number)
    view_context = LiveView(console, request.settings.session.time_scale, f"HydroJet bench: {request.profile.name}") \
        if live else contextlib.nullcontext()
    try:
        with view_context as view:
            on_update = view.update if live else _printer(console, clipped)
            session = Session(request, on_update=on_update, on_log_message=on_log_message)
            return await session.run()
    except asyncio.CancelledError:
        if stopped_by is not None:
            task.uncancel()
            return stopped_by
        raise
    finally:
        for number in STOP_SIGNALS:
            loop.remove_signal_handler(number)


def _terminals() -> list[int]:
    """The descriptors of standard output and error that are a terminal, taken before any
    hangup: after one, ``isatty`` says no more."""
    found = []
    for stream in (sys.stdout, sys.stderr):
        try:
            fd = stream.fileno()
        except (AttributeError, OSError, ValueError):  # replaced by an object without one (a test's capture)
            continue
        if os.isatty(fd):
            found.append(fd)
    return found


def _away_from_lost_terminal(terminals: list[int]) -> None:
    """Point these descriptors (standard output and error that were a terminal) at
    /dev/null: a write to a hung-up terminal fails (EIO), and the live view's or the
    summary's would stop the way out halfway (the valves' ALL_OFF, the log's end)."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        for fd in terminals:
            os.dup2(devnull, fd)
    finally:
        os.close(devnull)


# Event sources whose warnings the command prints itself, before the session or in its
# end report: printed live too, they would be said twice.
_SAID_ELSEWHERE = ("request", "calibration", "setup check")


def _printer(console: Console, clipped: frozenset[int]):
    last = [-1]
    events_seen = [0]

    def update(status) -> None:
        # Without the live view its warnings (a FIFO overflow, a stream falling behind, a
        # step not estimated) would be only in the log.
        new = min(status.event_count - events_seen[0], len(status.events))
        events_seen[0] = status.event_count
        for t_s, level, message, source in list(status.events)[len(status.events) - new:]:
            if level != "info" and source not in _SAID_ELSEWHERE:
                console.print(f"[yellow]{level}:[/] {render.plain(message)} ({t_s:.1f} s)", highlight=False)
        # One line per sweep (and per 10 calibration poses, and per clipped step) keeps a
        # log file readable.
        step = status.step
        if step is None or status.step_index == last[0]:
            return
        last[0] = status.step_index
        if (status.phase == "done" or step.step % 10 == 0 or status.step_index + 1 == status.step_count
                or status.step_index in clipped):
            online = "-" if status.online_error_deg is None else f"{status.online_error_deg:.2f}"
            ref = "-" if status.ref_error_deg is None else f"{status.ref_error_deg:.2f}"
            flag = " (clipped to the valves' limit)" if status.step_index in clipped else ""
            errors_of = status.errors_step_index
            of = "" if errors_of in (-1, status.step_index) else f" (step {errors_of + 1})"
            console.print(f"step {status.step_index + 1}/{status.step_count} {status.phase}{flag}: "
                          f"tip error ref {ref} deg, "
                          f"online {online} deg{of}; EM {status.em_frames} frames, IMU {status.imu_samples} samples",
                          highlight=False, markup=False)

    return update


def _diagnosable(steps) -> bool:
    """Whether `diagnose` can split these steps (sweeps to hold out, enough to train on):
    a plan of short ramps has sweeps but too few training steps, and "next" promises
    commands that run."""
    from ..analysis.diagnosis.split import split_session

    try:
        split_session(steps)
    except UserError:
        return False
    return True


def _timing(result) -> str:
    """Session and wall time from the arming of the valves, then the set-up before it:
    a first run compiles the kernels (seconds of wall time, and on a simulated rig
    time_scale times that of session time in which nothing was commanded)."""
    if result.armed_session_s is None:
        return f"{result.session_time_s:.0f} s session time in {result.wall_time_s:.1f} s wall time"
    waited = (f" (x{result.time_scale_kept:.1f}: session time waited {result.held_wall_s:.1f} s for the host)"
              if result.held_wall_s > 0.0 and result.time_scale_kept is not None else "")
    return (f"{result.session_time_s - result.armed_session_s:.0f} s session time in "
            f"{result.wall_time_s - result.armed_wall_s:.1f} s wall time{waited}, after {result.armed_wall_s:.1f} s of "
            "set-up (devices, kernels)")


def _print_outcome(console: Console, warnings: Console, result, model_name: str, calibrated_parameters: int,
                   args: argparse.Namespace) -> None:
    """The session's report on ``console`` (standard output); its warnings on
    ``warnings`` (standard error, as the command's help says), so that a report sent to a
    file does not hide them."""
    from ..analysis.compare import compare_steps
    from .compare import print_tables
    from .log_notice import warn_if_unsettled_steps

    for check in result.checks:
        if check.status != "pass":
            warnings.print(f"[yellow]warning:[/] {render.plain(check.message)}")
    console.print(f"session done: {result.completed_steps}/{result.step_count} steps, {_timing(result)}")
    if result.calibration is not None:
        console.print(f"calibration on the calibration poses: RMS {result.calibration.rms_orientation_deg_before:.2f} deg "
                      f"-> {result.calibration.rms_orientation_deg_after:.2f} deg")
    if result.calibration_failure is not None:
        warnings.print(f"[yellow]warning:[/] the calibration on the calibration poses failed: "
                       f"{render.plain(result.calibration_failure)}; the session predicted and estimated with its "
                       "starting parameters, so its errors are not those of a calibrated model", highlight=False)
    for warning in result.calibration_warnings:
        warnings.print(f"[yellow]warning:[/] {render.plain(warning)}")
    for rate in result.stream_rates:
        if rate.below_warning:
            warnings.print(f"[yellow]warning: {rate.describe()}[/]", highlight=False)
        else:
            console.print(f"[dim]{rate.describe()}[/]", highlight=False)
    estimates = result.estimates
    steps = result.steps
    if steps is not None:
        warn_if_unsettled_steps(result.log_path, steps, None)
    if steps is None or not estimates or len(estimates) != len(steps):
        warnings.print("[yellow]warning: no complete set of estimated steps to compare[/]")
    else:
        validation = steps.sweep >= 0
        if validation.any():
            rows = np.flatnonzero(validation)
            validation_steps = steps.select(rows)
            results = compare_steps([estimates[i] for i in rows], validation_steps)
            print_tables(console, results, f"{model_name}, live session")
            if args.report:
                from ..analysis.report import write_report

                for path in write_report(args.report, results, validation_steps, model_name,
                                                 figure_format=args.figure_format):
                    console.print(f"wrote {render.plain(path)}")
        elif args.report:
            warnings.print(f"[yellow]warning:[/] no report written to {render.plain(args.report)}: it holds the "
                           "sweeps' Table II and figures, and this session has no sweep steps")
    log = result.log_path
    console.print("\nnext:")
    # Only what runs on this log: calibrate needs enough calibration poses (also when the
    # session did not calibrate: --no-calibration), diagnose sweeps too; poses the
    # session's own calibration failed on fail `calibrate` the same way.
    poses = (steps is not None and result.calibration_failure is None
             and determinable(int((steps.sweep == -1).sum()), calibrated_parameters, steps.tip_position_m is not None))
    diagnosable = steps is not None and _diagnosable(steps)
    for line in (f"{command('replay', log, '--online')}  # re-run the estimation offline",
                 *([f"{command('calibrate', log, '-o', 'p.toml')}  # calibrate on the logged poses",
                    f"{command('compare', log, '--params', 'p.toml', '--online')}  # Table II from the log"]
                   if poses else []),
                 *([f"{command('diagnose', log, '--model', model_name)}  # which physical effect is missing?"]
                   if diagnosable else []),
                 f"{command('sensors', log, '--report', 'sensors/')}  # IMU versus EM tracker"):
        console.print(f"  {line}", highlight=False, markup=False, soft_wrap=True)
