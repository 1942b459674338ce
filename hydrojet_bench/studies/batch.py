"""Batch analysis of logs on the study engine: one row per log (CSV or MCAP), any
failure recorded as the row's error. ``diagnose_log`` diagnoses a log as `hydrojet-bench
diagnose` does; ``replay_log`` replays a session log with its live model and
parameters as `hydrojet-bench replay` does."""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass
from pathlib import Path

from ..analysis.diagnosis import DiagnosisSettings, diagnose
from ..errors import UserError
from .cell import trust_columns

DIAGNOSE_COLUMNS: dict[str, str] = {
    "log_id": "string", "log": "string", "model": "string", "steps": "int64", "verdict": "string",
    "alternatives": "string", "baseline_heldout_rmse_deg": "float64", "winner_heldout_rmse_deg": "float64",
    "noise_floor_deg": "float64", "converged": "bool", "unconverged_fits": "int64", "bound_clipped": "bool",
    "log_damage": "string", "profile_mismatch": "string", "seconds": "float64", "error": "string",
}
REPLAY_COLUMNS: dict[str, str] = {
    "log_id": "string", "log": "string", "model": "string", "steps": "int64",
    # Steps scored (the validation sweeps, all when there are none) and left out (the
    # model did not converge there), as `replay` says them.
    "scored_steps": "int64", "skipped_steps": "int64",
    "validation_orientation_rmse_deg": "float64", "live_difference_deg": "float64", "truncated": "bool", "damaged": "bool",
    "log_damage": "string", "seconds": "float64", "error": "string",
}


@dataclass(frozen=True)
class LogTask:
    """One log to analyse: its absolute path, the profile for a CSV file (None: a
    session log's own, "sim" for CSV) and the model to diagnose with."""

    path: str
    profile: str | None = None
    model: str = "cosserat"
    # The file's size and modification time: a log rewritten since is analysed again.
    version: str = ""

    @property
    def id(self) -> str:
        return hashlib.sha256(f"{self.path}|{self.profile}|{self.model}|{self.version}".encode()).hexdigest()[:16]

    @classmethod
    def of(cls, path: Path, profile: str | None = None, model: str = "cosserat") -> LogTask:
        """The task of the file at ``path`` as it is now."""
        stat = path.stat()
        return cls(str(path.resolve()), profile, model, f"{stat.st_size}-{stat.st_mtime_ns}")


def log_row(task: LogTask, columns: dict[str, str], error: str | None = None) -> dict:
    """A row naming ``task``, its figures empty (None)."""
    row = {column: None for column in columns}
    row.update(log_id=task.id, log=task.path, model=task.model, error=error)
    return row


def diagnose_log(task: LogTask) -> dict:
    """One row: the log's diagnosis; never raises."""
    from ..inputs import load_steps, recorded_elsewhere

    started = time.perf_counter()
    row = log_row(task, DIAGNOSE_COLUMNS)
    try:
        profile = task.profile if task.profile is not None or Path(task.path).suffix.lower() == ".mcap" else "sim"
        steps = load_steps(task.path, profile)
        mismatch = recorded_elsewhere(Path(task.path), task.profile, steps.profile)
        row["profile_mismatch"] = None if mismatch is None else mismatch["message"]
        diagnosis = diagnose(steps, task.model, settings=DiagnosisSettings(workers=1))
        winner = diagnosis.winner
        row.update(steps=len(steps), verdict=diagnosis.verdict, alternatives=",".join(diagnosis.alternatives),
                   baseline_heldout_rmse_deg=diagnosis.baseline_heldout_rmse_deg,
                   winner_heldout_rmse_deg=None if winner is None else winner.heldout_orientation_rmse_deg,
                   noise_floor_deg=diagnosis.noise_floor_deg, log_damage=_log_damage(task.path),
                   **trust_columns(diagnosis))
    except Exception as error:  # noqa: BLE001 - one bad log is a row, the batch goes on
        row["error"] = _one_line(error)
    row["seconds"] = time.perf_counter() - started
    return row


def replay_log(task: LogTask) -> dict:
    """One row: the session log replayed with its live model and parameter timeline."""
    from ..analysis.compare import compare_steps
    from ..bench.replay import live_difference_deg, read_session, replay
    from ..logs.condition import log_condition
    from ..model_choice import choose_model

    started = time.perf_counter()
    row = log_row(task, REPLAY_COLUMNS)
    try:
        session = read_session(Path(task.path), task.profile)
        # The live model and effects, as `replay` without options chooses them.
        model = choose_model(None, (), None, session.model_defaults()).model
        estimates = replay(session, model, None, None)
        kept = [i for i, estimate in enumerate(estimates) if estimate is not None]
        validation = [i for i in kept if session.steps.sweep[i] >= 0] or kept
        if not validation:
            raise UserError("the model converged on none of the logged steps")
        results = compare_steps([estimates[i] for i in validation], session.steps.select(validation))
        condition = log_condition(task.path)
        row.update(model=session.model_name, steps=len(session.steps), scored_steps=len(validation),
                   skipped_steps=len(estimates) - len(kept), truncated=condition.truncated,
                   damaged=condition.damage is not None, log_damage=None if condition.whole else condition.notice(),
                   validation_orientation_rmse_deg=float(results["ref"].overall.orientation_rmse_deg),
                   live_difference_deg=live_difference_deg(session, estimates))
    except Exception as error:  # noqa: BLE001
        row["error"] = _one_line(error)
    row["seconds"] = time.perf_counter() - started
    return row


def _log_damage(path: str) -> str | None:
    """What a session log lacks, in one line; None for a whole log or a table."""
    from ..logs.condition import incomplete_log

    condition = incomplete_log(path)
    return None if condition is None else condition.notice()


def _one_line(error: Exception) -> str:
    text = str(error) if isinstance(error, UserError) else f"{type(error).__name__}: {error}"
    return " ".join(text.split()) or type(error).__name__
