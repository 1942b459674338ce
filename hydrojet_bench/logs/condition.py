"""`log_condition`: whether a session log is whole, and if not, what the analysis of it
is missing: the damage the readers skipped, and the plan steps it does not hold."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..plans import CALIBRATION_SWEEP
from .format import RECOVERY_METADATA_NAME
from .dataset import analysed_samples
from .reader import LogDamage, read_log
from .topics import Sample, Step


@dataclass(frozen=True)
class LogCondition:
    """path: the log. truncated: it does not end properly (the session was killed, or
    the file cut). damage: what damage inside it cost (None if none). steps_planned: the
    plan's step count, from the log's metadata (None if it does not say); steps_logged:
    settled steps (``/bench/step``) it holds; steps_from_samples: without any, the steps
    the analyses take from its samples' sweep/step labels instead (None: it has step
    records, or no samples); calibration_poses_logged: the steps analysed on
    calibration poses (sweep -1)."""

    path: Path
    truncated: bool
    damage: LogDamage | None
    steps_planned: int | None
    steps_logged: int
    calibration_poses_logged: int
    # For a copy `recover_log` wrote: what its source lost (one line), None otherwise or
    # when the source was whole.
    recovered_loss: str | None = None
    steps_from_samples: int | None = None

    @property
    def whole(self) -> bool:
        """Nothing to say: it ends properly, nothing inside is damaged, it holds every step
        of its plan (a log recovered from a cut file ends properly but does not), and it is
        no copy of a log that lost something."""
        return (not self.truncated and self.damage is None and not self.steps_missing
                and self.recovered_loss is None and self.steps_from_samples is None)

    @property
    def steps_analysed(self) -> int:
        return self.steps_logged if self.steps_from_samples is None else self.steps_from_samples

    @property
    def steps_missing(self) -> int | None:
        return None if self.steps_planned is None else max(self.steps_planned - self.steps_analysed, 0)

    def notice(self) -> str:
        """One line: what is wrong with the log and what the analysis is missing."""
        problems = (["it is truncated (the session did not finish, or the file was cut)"] if self.truncated else [])
        if self.damage is not None:
            problems.append(f"it is damaged: {self.damage.describe()}")
        if self.recovered_loss is not None:
            problems.append(f"it was recovered from a log that {self.recovered_loss}")
        if self.steps_from_samples is not None:
            problems.append(f"it holds no {Step.topic} records (settled steps): the steps are taken from the "
                            "samples' sweep/step labels")
        if not problems:
            problems.append("it ends before its plan did (the session was stopped, or the log was recovered from a "
                            "cut file)")
        missing = self.steps_missing
        what = "settled steps" if self.steps_from_samples is None else "steps labelled in the samples"
        steps = (f"{self.steps_analysed} {what} ({self.calibration_poses_logged} calibration poses)"
                 if missing is None else
                 f"{missing} of {self.steps_planned} planned steps missing; analysing the {self.steps_analysed} "
                 f"{'logged' if self.steps_from_samples is None else 'labelled in the samples'} "
                 f"({self.calibration_poses_logged} calibration poses)")
        return f"{self.path}: {'; '.join(problems)}; {steps}"

    def as_dict(self) -> dict[str, object]:
        return {"truncated": self.truncated, "damage": None if self.damage is None else self.damage.as_dict(),
                "steps_planned": self.steps_planned, "steps_logged": self.steps_logged,
                "steps_missing": self.steps_missing, "calibration_poses_logged": self.calibration_poses_logged,
                "recovered_loss": self.recovered_loss, "steps_from_samples": self.steps_from_samples}


def log_condition(path: str | Path) -> LogCondition:
    """The condition of a session log (see `LogCondition`); reads its samples and steps."""
    contents = read_log(path, topics=[Step.topic, Sample.topic])
    steps = contents.on(Step)
    try:
        planned: int | None = int(contents.metadata.get("bench", {})["plan_steps"])
    except (KeyError, ValueError):
        planned = steps[0].count if steps else None
    labels = {(step.sweep, step.step) for step in steps}
    from_samples = None
    if not steps and contents.on(Sample):
        # What `dataset_from_log` falls back to, so that the notice counts what is analysed.
        labels = {(sample.sweep, sample.step) for sample in analysed_samples(contents.on(Sample), set(),
                                                                             contents.truncated)}
        from_samples = len(labels)
    return LogCondition(Path(path), contents.truncated, contents.damage, planned, len(steps),
                        sum(sweep == CALIBRATION_SWEEP for sweep, _ in labels),
                        _recovered_loss(contents.metadata.get(RECOVERY_METADATA_NAME)), from_samples)


def _recovered_loss(recovery: dict[str, str] | None) -> str | None:
    """What the source of a recovered copy lost, in words (None: not a copy, or whole)."""
    if recovery is None:
        return None
    lost = (["was truncated"] if recovery.get("truncated") == "true" else []) + (
        [f"was damaged ({recovery['damage']})"] if recovery.get("damage") else [])
    return " and ".join(lost) or None


def incomplete_log(path: str | Path) -> LogCondition | None:
    """The condition of a session log (.mcap) that is not whole; None for a whole log or
    another kind of input (what every analysis warns about)."""
    if Path(path).suffix.lower() != ".mcap":
        return None
    condition = log_condition(path)
    return None if condition.whole else condition
