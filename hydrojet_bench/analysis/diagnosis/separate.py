"""The experiment that tells tied candidates apart: the jet commands where their
calibrated models predict the most different tip orientations, as a plan to run.

Candidate commands: every combination of the three jets at 0, 1/3, 2/3 and all of each
jet's largest force (63 commands, the zero command left out). Each tied model predicts
the tip sensor's orientation there (a static solve from rest, under the session's mean
gravity); a command separates the candidates by the smallest angle between any two of
their predictions, so a pose is only proposed when it splits every pair, and only
when that angle exceeds the noise floor of one step (candidates no pose separates by
more are equivalent for this rig: no plan is proposed). The best `POSES` commands make
the plan, each swept `REPETITIONS` times (so `diagnose` on the
new session can hold repetitions out and measure its own noise floor).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ...errors import ConvergenceError
from ...files import publish
from ...geometry import quat_from_matrix, rotation_angle_deg
from ...models.shooting import ShootingModel
from ...params import ModelParameters
from ...plans import Plan, PlanStep

LEVELS = (0.0, 1.0 / 3.0, 2.0 / 3.0, 1.0)
POSES = 6
REPETITIONS = 3


@dataclass(frozen=True)
class SeparatingPose:
    """A jet command (N) and the smallest angle (deg) between any two candidates'
    predicted tip orientations there."""

    jet_forces_n: tuple[float, float, float]
    separation_deg: float

    def as_dict(self) -> dict:
        return {"jet_forces_n": list(self.jet_forces_n), "separation_deg": self.separation_deg}


def separating_poses(models: Sequence[tuple[str, ShootingModel, ModelParameters]],
                     max_force_per_jet_n: Sequence[float], gravity_in_base_m_s2: np.ndarray,
                     min_separation_deg: float = 0.0, count: int = POSES) -> tuple[SeparatingPose, ...]:
    """The ``count`` commands that best separate the named calibrated models by more
    than ``min_separation_deg`` (see the module docstring); empty for fewer than two
    models."""
    if len(models) < 2:
        return ()
    limits = np.asarray(max_force_per_jet_n, dtype=float)
    commands = [limits * np.array(levels) for levels in itertools.product(LEVELS, repeat=3) if any(levels)]
    gravity = tuple(float(v) for v in gravity_in_base_m_s2)
    predictions = []
    for _, model, params in models:
        at_gravity = replace(params, gravity_in_base_m_s2=gravity)
        orientations = []
        for command in commands:
            try:
                solution = model.solve(command, at_gravity)
                orientations.append(quat_from_matrix(solution.tip_sensor_in_base_sensor()))
            except (ConvergenceError, ValueError):
                orientations.append(np.full(4, np.nan))
        predictions.append(np.array(orientations))
    separation = np.full(len(commands), np.inf)
    for first, second in itertools.combinations(predictions, 2):
        separation = np.minimum(separation, rotation_angle_deg(first, second))
    separation = np.where(np.isfinite(separation), separation, -np.inf)
    best = np.argsort(-separation)[:count]
    return tuple(SeparatingPose(tuple(float(f) for f in commands[index]), float(separation[index]))
                 for index in best if separation[index] > min_separation_deg)


def separating_plan(poses: Sequence[SeparatingPose], settle_s: float) -> Plan:
    """The poses, from the strongest, swept `REPETITIONS` times (sweeps 0, 1, ...)."""
    return Plan(tuple(PlanStep(pose.jet_forces_n, sweep, step, settle_s)
                      for sweep in range(REPETITIONS) for step, pose in enumerate(poses)))


def write_separating_plan(path: Path, plan: Plan, candidates: Sequence[str], *, overwrite: bool = False) -> Path:
    """Write ``plan`` as a TOML plan file `run --plan` reads (never over an existing file
    unless ``overwrite``); returns ``path``."""
    lines = [f"# Poses that tell {', '.join(candidates)} apart (written by diagnose): their calibrated",
             "# models differ most here. Run it with `hydrojet-bench run --plan THIS_FILE`, then diagnose",
             "# the new session.", ""]
    for step in plan:
        q1, q2, q3 = step.jet_forces_n
        lines += ["[[step]]", f"q1 = {q1!r}", f"q2 = {q2!r}", f"q3 = {q3!r}", f"sweep = {step.sweep}",
                  f"step = {step.step}", f"settle_s = {step.settle_s!r}", ""]
    text = "\n".join(lines)

    def write(partial: Path) -> Path:
        partial.write_text(text, encoding="utf-8")
        return path

    return publish(Path(path), "plan file", write, overwrite=overwrite)
