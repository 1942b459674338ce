"""The live view of a running session (rich): progress with ETA, the step being played,
the tip error with and without online estimation, the disturbance estimate, the health
of every device stream, and the latest events."""

from __future__ import annotations

import time

from rich.console import Console, Group
from rich.live import Live
from rich.markup import escape
from rich.panel import Panel
from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn
from rich.table import Table

from .session import SessionStatus

_LEVEL_STYLE = {"info": "dim", "warning": "yellow", "error": "bold red"}


def _format(value: float | None, scale: float = 1.0, digits: int = 2) -> str:
    return "-" if value is None else f"{value * scale:.{digits}f}"


class LiveView:
    """Use as a context manager; pass `update` to the session as its ``on_update``."""

    def __init__(self, console: Console, time_scale: float, title: str) -> None:
        self.console = console
        self.time_scale = time_scale
        self.title = title
        self._progress = Progress(TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
                                  TextColumn("ETA {task.fields[eta]}"), console=console)
        self._task = self._progress.add_task("steps", total=1, eta="-")
        self._live = Live(console=console, refresh_per_second=4, transient=False)

    def __enter__(self) -> LiveView:
        self._live.__enter__()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._live.__exit__(*exc_info)  # type: ignore[arg-type]

    def update(self, status: SessionStatus) -> None:
        self._live.update(self.render(status))

    def render(self, status: SessionStatus) -> Panel:
        eta_wall_s = status.remaining_session_s / self.time_scale
        self._progress.update(self._task, total=status.step_count, completed=status.step_index + 1,
                              description=f"step {status.step_index + 1}/{status.step_count}",
                              eta=time.strftime("%M:%S", time.gmtime(max(0.0, eta_wall_s))))
        table = Table.grid(padding=(0, 2))
        table.add_column(style="bold")
        table.add_column()
        step = status.step
        jets = "-" if step is None else "  ".join(f"q{i + 1} {f:.3f}" for i, f in enumerate(step.jet_forces_n))
        where = "-" if step is None else ("calibration pose" if step.sweep < 0 else f"sweep {step.sweep}") + \
            f", step {step.step}"
        table.add_row("phase", f"{status.phase} ({where})")
        table.add_row("jets (N)", jets)
        of = "" if status.errors_step_index < 0 else f"   (step {status.errors_step_index + 1})"
        table.add_row("tip error (deg)",
                      f"ref {_format(status.ref_error_deg)}   online {_format(status.online_error_deg)}{of}")
        table.add_row("disturbance |w_d,m|", f"{_format(status.disturbance_norm_nm, 1e3)} mN m")
        table.add_row("EM tracker", f"{status.em_frames} frames, {status.em_missing} incomplete")
        table.add_row("IMUs", f"{status.imu_samples} samples, {status.imu_errors} errors, "
                      f"{status.imu_overflows} FIFO overflows")
        table.add_row("rates (last step)", "   ".join(
            f"{'[yellow]' if rate.below_warning else ''}{name} {rate.delivered_hz:.1f}/{rate.configured_hz:g} Hz"
            f"{'[/]' if rate.below_warning else ''}" for name, rate in status.stream_rates.items()) or "-")
        table.add_row("valves", f"{status.valve_commands} commands, {status.valve_retries} timeouts")
        kept = "" if status.time_scale_kept is None else f"x{status.time_scale_kept:.1f} kept of "
        table.add_row("session time", f"{status.session_time_s:.0f} s ({kept}x{self.time_scale:g})")
        events = Table.grid()
        for t_s, level, message, _ in status.events:
            events.add_row(f"[{_LEVEL_STYLE.get(level, '')}]{t_s:7.1f} s  {escape(message)}[/]")
        return Panel(Group(self._progress, table, events), title=self.title)
