"""`hydrojet-bench run`: a bench session, on the simulated rig by default.

Plays a plan (default: the paper's protocol, 40 calibration poses then nine sweeps),
calibrates on the calibration poses when they end, estimates the disturbance live,
records everything to an MCAP log, shows a live view, and at the end prints the paper's
Table II for the session (optionally a report folder of plots) and the commands to try
next. Ctrl-C or SIGTERM stop it cleanly: valves off, log finished.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import shlex
import signal
import sys
import time
from pathlib import Path

import msgspec
import numpy as np
from rich.console import Console

from ..config.schema import MAX_TIME_SCALE
from ..errors import UserError
from ..files import check_writable_target, create_numbered, make_folder_for
from ..model_choice import ModelDefaults, model_choice
from ..profile import load_profile
from . import render
from .common import add_model_arguments, check_seed

DEFAULT_LOG_DIR = Path("sessions")


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
    parser.add_argument("--no-live", action="store_true", help="no live view (plain progress lines)")
    parser.add_argument("--skip-checks", action="store_true",
                        help="skip the wiring and level checks before the plan (the log records the skip)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..bench.plan_choice import choose_plan
    from ..bench.session import SessionRequest

    check_seed(args.seed)
    profile = load_profile(args.profile)
    settings = profile.config
    if args.time_scale is not None:
        if not 0 < args.time_scale <= MAX_TIME_SCALE:
            raise UserError(f"--time-scale must be > 0 and at most {MAX_TIME_SCALE:g} (the simulated rig "
                            f"cannot keep up beyond), got {args.time_scale}")
        if not settings.transports.simulated and args.time_scale != 1.0:
            raise UserError("--time-scale applies to the simulated rig only; this profile drives real devices")
        settings = msgspec.structs.replace(settings, session=msgspec.structs.replace(settings.session,
                                                                                     time_scale=args.time_scale))
    limits = tuple(table.max_force_n for table in settings.valve_calibrations())
    plan, clipped = choose_plan(args.plan, settle_s=settings.session.settle_s).clipped(limits)
    clipped_warning = _clipped_warning(clipped, limits)
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
                             seed=args.seed, warnings=(clipped_warning,) if clipped_warning else (),
                             command_line=shlex.join(["hydrojet-bench", *sys.argv[1:]]), overwrite_log=overwrite,
                             setup_checks=not args.skip_checks)
    console = render.console_for(args)
    rig = "simulated rig" if settings.transports.simulated else "rig"
    console.print(f"session on [bold]{render.plain(profile.name)}[/] ({rig}): "
                  f"{len(plan)} steps, {plan.duration_s:.0f} s of session time at x{settings.session.time_scale:g}, "
                  f"model {model.name}{' + ' + ', '.join(e.name for e in requested) if requested else ''}; "
                  f"log {render.plain(log_path)}", highlight=False)
    if clipped_warning:
        console.print(f"[yellow]warning:[/] {clipped_warning}")
    result = asyncio.run(_run_session(request, console, live=not args.no_live and console.is_terminal,
                                      clipped=frozenset(clipped)))
    if result is None:
        console.print(f"[yellow]stopped by signal:[/] valves closed, log finished: {render.plain(log_path)}")
        return 143
    _print_outcome(console, result, model.name, args)
    return 0


def _clipped_warning(clipped: tuple[int, ...], limits: tuple[float, ...]) -> str:
    if not clipped:
        return ""
    shown = ", ".join(str(index + 1) for index in clipped[:5]) + (", ..." if len(clipped) > 5 else "")
    return (f"{len(clipped)} step(s) of the plan ({shown}) ask more than the valves give "
            f"({', '.join(f'{limit:g}' for limit in limits)} N per jet): they are played, logged and predicted "
            "at the clipped force")


async def _run_session(request, console: Console, live: bool, clipped: frozenset[int]):
    from ..bench.live_view import LiveView
    from ..bench.session import Session

    terminated = False
    task = asyncio.current_task()
    loop = asyncio.get_running_loop()

    def on_sigterm() -> None:
        nonlocal terminated
        terminated = True
        task.cancel()

    loop.add_signal_handler(signal.SIGTERM, on_sigterm)
    view_context = LiveView(console, request.settings.session.time_scale, f"HydroJet bench: {request.profile.name}") \
        if live else contextlib.nullcontext()
    try:
        with view_context as view:
            on_update = view.update if live else _printer(console, clipped)
            session = Session(request, on_update=on_update)
            return await session.run()
    except asyncio.CancelledError:
        if terminated:
            task.uncancel()
            return None
        raise
    finally:
        loop.remove_signal_handler(signal.SIGTERM)


def _printer(console: Console, clipped: frozenset[int]):
    last = [-1]

    def update(status) -> None:
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
            console.print(f"step {status.step_index + 1}/{status.step_count} {status.phase}{flag}: "
                          f"tip error ref {ref} deg, "
                          f"online {online} deg; EM {status.em_frames} frames, IMU {status.imu_samples} samples",
                          highlight=False, markup=False)

    return update


def _print_outcome(console: Console, result, model_name: str, args: argparse.Namespace) -> None:
    from ..analysis.compare import compare_steps
    from .compare import print_tables

    for check in result.checks:
        if check.status != "pass":
            console.print(f"[yellow]warning:[/] {render.plain(check.message)}")
    console.print(f"session done: {result.completed_steps}/{result.step_count} steps, "
                  f"{result.session_time_s:.0f} s session time in {result.wall_time_s:.1f} s wall time")
    if result.calibration is not None:
        console.print(f"calibration on the calibration poses: RMS {result.calibration.rms_orientation_deg_before:.2f} deg "
                      f"-> {result.calibration.rms_orientation_deg_after:.2f} deg")
    estimates = result.estimates
    steps = result.steps
    if steps is None or not estimates or len(estimates) != len(steps):
        console.print("[yellow]no complete set of estimated steps to compare[/]")
    else:
        validation = steps.sweep >= 0
        if validation.any():
            rows = np.flatnonzero(validation)
            validation_steps = steps.select(rows)
            results = compare_steps([estimates[i] for i in rows], validation_steps)
            print_tables(console, results, f"{model_name}, live session")
            if args.report:
                from ..analysis.report import write_report

                for path in write_report(args.report, results, validation_steps, model_name):
                    console.print(f"wrote {render.plain(path)}")
    log = result.log_path
    console.print("\nnext:")
    for line in (f"hydrojet-bench replay {log} --online            # re-run the estimation offline",
                 f"hydrojet-bench compare {log} --params P.toml --online  # Table II from the log",
                 f"hydrojet-bench diagnose {log} --model {model_name}     # which physical effect is missing?",
                 f"hydrojet-bench sensors {log} --report sensors/  # IMU versus EM tracker"):
        console.print(f"  {render.plain(line)}", highlight=False)
