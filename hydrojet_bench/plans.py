"""Measurement plans: ordered quasistatic steps of jet forces, as in the paper.

A `Plan` is what the bench (or the digital twin) plays: each `PlanStep` commands three
jet forces (N) and holds them for ``settle_s`` seconds, long enough for the rod to reach
equilibrium before it is measured. Every step carries a ``sweep`` label (-1 for
calibration poses, 0.. for validation sweeps) and a ``step`` index within that sweep,
which end up as the ``sweep``/``step`` columns of the recorded data.

Builders reproduce the paper's protocol (Campisano et al. 2020, sec. V):

* `calibration_plan`: 40 random equilibrium poses distributed over the workspace;
* `validation_sweeps`: one jet at a time ramped from zero to the maximum force and back,
  3 jets x 3 repetitions = nine sweeps, 5 s per command;
* `paper_protocol`: both, calibration first (40 + 9 x 21 = 229 steps).

Jets only push: every force is >= 0 N.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation

import numpy as np

from .params import JET_COUNT, actuation_matrix

CALIBRATION_SWEEP = -1
# The paper holds each command 5 s, "higher than the settling time of the body".
DEFAULT_SETTLE_S = 5.0
# Default peak jet force (N). On the default HydroJet rod hanging from its clamp, 0.1 N
# on one jet bends the tip about 80 degrees, just past Table II's largest bin (75 deg).
DEFAULT_MAX_FORCE_N = 0.1
PAPER_CALIBRATION_POSES = 40
# The longest a step may hold its command, s. The paper's protocol holds 5 s and a rest
# or warm-up recording a few minutes; a step held for more than a day is a typo (a
# unit, a stray exponent), and would keep the jets on and the session going forever.
MAX_SETTLE_S = 86400.0
# Sweep and step labels stay below 2**53: they are written to the log's JSON messages,
# which Foxglove and other JavaScript readers hold as doubles, exact only up to there,
# and they must fit the recorded data's int64 columns with room to count on.
LABEL_LIMIT = 2**53


def _is_int(value: object) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _check_force_limit(name: str, value: float) -> float:
    if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool):
        raise ValueError(f"{name} must be a number of newtons, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a finite force > 0 N, got {value!r}")
    return float(value)


def _check_settle(name: str, value: float) -> float:
    if not isinstance(value, (int, float, np.integer, np.floating)) or isinstance(value, bool):
        raise ValueError(f"{name} must be a number of seconds, got {value!r}")
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"{name} must be a finite time > 0 s, got {value!r}")
    if value > MAX_SETTLE_S:
        raise ValueError(f"{name} must be at most {MAX_SETTLE_S:g} s (one day), got {value!r}")
    return float(value)


@dataclass(frozen=True)
class PlanStep:
    """One quasistatic command.

    jet_forces_n: forces (q1, q2, q3) of the three jets, N, each finite and >= 0.
    sweep: -1 for calibration poses, else the validation sweep's id (>= 0), < 2**53.
    step: index of this command within its sweep (or calibration set), >= 0, < 2**53.
    settle_s: how long the command is held before the next one, s (> 0, at most a day).
    """

    jet_forces_n: tuple[float, float, float]
    sweep: int
    step: int
    settle_s: float = DEFAULT_SETTLE_S

    def __post_init__(self) -> None:
        try:
            forces = tuple(float(f) for f in self.jet_forces_n)
        except (TypeError, ValueError):
            raise ValueError(f"PlanStep.jet_forces_n must be 3 numbers, got {self.jet_forces_n!r}") from None
        if len(forces) != JET_COUNT:
            raise ValueError(f"PlanStep.jet_forces_n must have {JET_COUNT} forces, got {len(forces)}")
        for jet, force in enumerate(forces, start=1):
            if not math.isfinite(force) or force < 0.0:
                raise ValueError(f"PlanStep.jet_forces_n[q{jet}] must be finite and >= 0 N "
                                 f"(jets only push), got {force!r}")
        object.__setattr__(self, "jet_forces_n", forces)
        if not _is_int(self.sweep) or not CALIBRATION_SWEEP <= self.sweep < LABEL_LIMIT:
            raise ValueError(f"PlanStep.sweep must be an integer >= -1 and < 2**53, got {self.sweep!r}")
        if not _is_int(self.step) or not 0 <= self.step < LABEL_LIMIT:
            raise ValueError(f"PlanStep.step must be an integer >= 0 and < 2**53, got {self.step!r}")
        object.__setattr__(self, "sweep", int(self.sweep))
        object.__setattr__(self, "step", int(self.step))
        object.__setattr__(self, "settle_s", _check_settle("PlanStep.settle_s", self.settle_s))


@dataclass(frozen=True)
class Plan:
    """An ordered sequence of `PlanStep`s (played first to last). Plans concatenate with
    ``+``."""

    steps: tuple[PlanStep, ...]

    def __post_init__(self) -> None:
        steps = tuple(self.steps)
        for index, step in enumerate(steps):
            if not isinstance(step, PlanStep):
                raise ValueError(f"Plan.steps[{index}] must be a PlanStep, got {type(step).__name__}")
        object.__setattr__(self, "steps", steps)

    def __len__(self) -> int:
        return len(self.steps)

    def __iter__(self) -> Iterator[PlanStep]:
        return iter(self.steps)

    def __getitem__(self, index: int) -> PlanStep:
        return self.steps[index]

    def __add__(self, other: "Plan") -> "Plan":
        if not isinstance(other, Plan):
            return NotImplemented
        return Plan(self.steps + other.steps)

    @property
    def jet_forces_n(self) -> np.ndarray:
        """(steps, 3) commanded forces, N."""
        return np.array([s.jet_forces_n for s in self.steps], dtype=float).reshape(-1, JET_COUNT)

    @property
    def sweeps(self) -> np.ndarray:
        return np.array([s.sweep for s in self.steps], dtype=int)

    @property
    def step_indices(self) -> np.ndarray:
        return np.array([s.step for s in self.steps], dtype=int)

    @property
    def duration_s(self) -> float:
        """Total time the plan takes to play, s."""
        return float(sum(s.settle_s for s in self.steps))

    def clipped(self, max_force_per_jet_n: tuple[float, float, float]) -> tuple["Plan", tuple[int, ...]]:
        """This plan with every force above its jet's limit (N) lowered to the limit, as
        the valves apply it, and the indices of the steps that changed."""
        limits = np.asarray(max_force_per_jet_n, dtype=float)
        steps, changed = [], []
        for index, step in enumerate(self.steps):
            forces = np.minimum(step.jet_forces_n, limits)
            if np.any(forces < step.jet_forces_n):
                changed.append(index)
                limited = tuple(float(f) for f in forces)
                step = PlanStep(limited, step.sweep, step.step, step.settle_s)  # type: ignore[arg-type]
            steps.append(step)
        return Plan(tuple(steps)), tuple(changed)


def _steps_named(indices: Sequence[int]) -> str:
    """"N step(s) of the plan (a, b, ...)": the first five, 1-based."""
    shown = ", ".join(str(index + 1) for index in indices[:5]) + (", ..." if len(indices) > 5 else "")
    return f"{len(indices)} step(s) of the plan ({shown})"


def clipped_warning(clipped: tuple[int, ...], limits: tuple[float, ...]) -> str:
    """What `Plan.clipped` changed, in words ("" for nothing): the steps (1-based) and
    the valves' limits (N per jet)."""
    if not clipped:
        return ""
    return (f"{_steps_named(clipped)} ask more than the valves give "
            f"({', '.join(f'{limit:g}' for limit in limits)} N per jet): they are played, logged and predicted "
            "at the clipped force")


def short_steps_warning(plan: Plan, window_s: float) -> str:
    """The plan's steps that hold no longer than the session's averaging window, in words
    ("" for none): their settled states take in the rod still moving after the jets
    changed (a plan of 0.3 s steps on the nominal twin: Table II 33 deg)."""
    short = [index for index, step in enumerate(plan.steps) if step.settle_s <= window_s]
    if not short:
        return ""
    return (f"{_steps_named(short)} hold no longer than the {window_s:g} s each step's settled state is averaged "
            "over (session.window_s): their errors take in the rod still moving, which the quasistatic models "
            "read as model error; hold each command longer")


def _resultant_to_jets(resultant_xy_n: np.ndarray) -> np.ndarray:
    """Non-negative jet forces whose resultant (eq. 5, ring angle 0) is the given tip-frame
    force: the two jets flanking the force's direction share it, the third stays off.
    Any in-plane force is such a combination of the two jets 120 degrees apart around it.
    """
    directions = actuation_matrix(0.0)[:2]  # column j: unit direction of jet j
    out = np.zeros(JET_COUNT)
    for first in range(JET_COUNT):
        second = (first + 1) % JET_COUNT
        pair = directions[:, [first, second]]
        coefficients = np.linalg.solve(pair, resultant_xy_n)
        if np.all(coefficients >= -1e-15):
            out[[first, second]] = np.maximum(coefficients, 0.0)
            return out
    raise AssertionError("three jets 120 degrees apart span every direction")  # pragma: no cover


def calibration_plan(count: int = PAPER_CALIBRATION_POSES, max_force_n: float = DEFAULT_MAX_FORCE_N,
                     seed: int = 0, settle_s: float = DEFAULT_SETTLE_S) -> Plan:
    """The paper's calibration set: ``count`` random equilibrium poses over the workspace.

    Sampling. With each jet in [0, max_force_n], the reachable resultant tip-frame force
    (eq. 5) is a regular hexagon of circumradius ``max_force_n``: its corners lie on the
    jet axes (one jet at the limit) and midway between them (two jets at the limit). A
    pose is drawn as a random direction, uniform in [0, 2 pi), and a random magnitude
    ``sqrt(u) * r(direction)``, u uniform in [0, 1), where r is the hexagon's extent in
    that direction: the unit disc mapped radially onto the hexagon, so equal areas are
    about equally likely, large bends are not under-sampled, and every bending direction
    reaches the workspace's edge. The force is then split onto the two jets flanking its
    direction (the third jet is off), which keeps every jet force in [0, max_force_n].
    Steps are labelled sweep -1, step 0..count-1. Deterministic for a given ``seed``.
    """
    if not _is_int(count) or count < 1:
        raise ValueError(f"count must be an integer >= 1, got {count!r}")
    max_force_n = _check_force_limit("max_force_n", max_force_n)
    settle_s = _check_settle("settle_s", settle_s)
    if not _is_int(seed) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(seed)
    angle_rad = rng.uniform(0.0, 2.0 * math.pi, count)
    radius_fraction = np.sqrt(rng.uniform(0.0, 1.0, count))
    steps = []
    for index in range(count):
        unit_jets = _resultant_to_jets(np.array([math.cos(angle_rad[index]), math.sin(angle_rad[index])]))
        # The hexagon's extent in this direction: where the larger jet reaches the limit.
        forces = unit_jets * (radius_fraction[index] * max_force_n / unit_jets.max())
        # Rounding can push a force a few ulps past the limit; the limit is a promise.
        forces = np.minimum(forces, max_force_n)
        steps.append(PlanStep(tuple(forces), CALIBRATION_SWEEP, index, settle_s))
    return Plan(tuple(steps))


def validation_sweeps(max_force_n: float = DEFAULT_MAX_FORCE_N, steps_up: int = 10, repetitions: int = 3,
                      settle_s: float = DEFAULT_SETTLE_S) -> Plan:
    """The paper's validation: each jet alone ramped from 0 to ``max_force_n`` in
    ``steps_up`` equal steps and back down to 0 (2 * steps_up + 1 commands per sweep,
    21 by default), the other jets off.

    Order: repetition by repetition, jets 1, 2, 3 within each, so sweep id =
    3 * repetition + jet index (0-based): with 3 repetitions, ids 0..8 and id % 3 is
    the jet. ``step`` counts the commands within a sweep from 0.
    """
    max_force_n = _check_force_limit("max_force_n", max_force_n)
    if not _is_int(steps_up) or steps_up < 1:
        raise ValueError(f"steps_up must be an integer >= 1, got {steps_up!r}")
    if not _is_int(repetitions) or repetitions < 1:
        raise ValueError(f"repetitions must be an integer >= 1, got {repetitions!r}")
    settle_s = _check_settle("settle_s", settle_s)
    up = np.linspace(0.0, max_force_n, steps_up + 1)
    ramp = np.concatenate([up, up[-2::-1]])
    steps = []
    for repetition in range(repetitions):
        for jet in range(JET_COUNT):
            sweep = JET_COUNT * repetition + jet
            for index, force in enumerate(ramp):
                forces = [0.0] * JET_COUNT
                forces[jet] = float(force)
                steps.append(PlanStep(tuple(forces), sweep, index, settle_s))  # type: ignore[arg-type]
    return Plan(tuple(steps))


def paper_protocol(max_force_n: float = DEFAULT_MAX_FORCE_N, seed: int = 0,
                   settle_s: float = DEFAULT_SETTLE_S) -> Plan:
    """The paper's whole experiment: 40 random calibration poses (sweep -1), then the nine
    validation sweeps (ids 0..8), ``settle_s`` per command: 40 + 9 x 21 = 229 steps."""
    return (calibration_plan(PAPER_CALIBRATION_POSES, max_force_n, seed, settle_s)
            + validation_sweeps(max_force_n, settle_s=settle_s))


def imu_versus_em_plan(max_force_n: float = DEFAULT_MAX_FORCE_N, static_poses: int = 8, hold_s: float = 20.0,
                       ramp_steps: int = 40, ramp_step_s: float = 0.5, seed: int = 0) -> Plan:
    """For comparing IMU and EM orientations: ``static_poses`` random poses held
    ``hold_s`` each (static accuracy, and drift within a hold), labelled sweep -1 like
    calibration poses, then one slow ramp per jet, 0 -> max -> 0 in ``2 ramp_steps`` short
    steps of ``ramp_step_s`` (dynamic agreement while the tip keeps moving), sweeps 0..2."""
    poses = calibration_plan(static_poses, max_force_n, seed, hold_s)
    ramps = validation_sweeps(max_force_n, steps_up=ramp_steps, repetitions=1, settle_s=ramp_step_s)
    return poses + ramps


def hold_plan(jet_forces_n: tuple[float, float, float] = (0.0, 0.0, 0.0), duration_s: float = 60.0) -> Plan:
    """One command held for ``duration_s`` (a rest recording, sensor warm-up, a check)."""
    return Plan((PlanStep(jet_forces_n, 0, 0, duration_s),))


def _cell_number(value: object, key: str) -> float:
    """A plan cell as a number: a TOML number, or CSV text in plain decimal notation
    (``1_000``, which Python's float() reads as 1000, is refused as a likely typo)."""
    if isinstance(value, str) and "_" not in value:
        try:
            return float(value)
        except ValueError:
            pass
    elif _is_int(value) or isinstance(value, (float, np.floating)):
        return float(value)  # type: ignore[arg-type]
    raise ValueError(f"{key} must be a number, got {value!r}")


def _cell_integer(value: object, key: str, minimum: int) -> int:
    """A plan cell as an exact integer label in [minimum, 2**53): ``5`` or ``5.0``, but not
    ``5.5``. CSV text is read as a decimal, not a float, so that 9007199254740993 is not
    quietly read as its float neighbour."""
    number = _cell_number(value, key)
    exact: int | float | Decimal = int(value) if _is_int(value) else number  # type: ignore[call-overload]
    if isinstance(value, str):
        try:
            exact = Decimal(value.strip())
        except InvalidOperation:
            exact = math.nan
    if isinstance(exact, Decimal):
        integral = exact.is_finite() and exact == exact.to_integral_value()
    else:
        integral = math.isfinite(exact) and float(exact).is_integer()
    if not integral:
        raise ValueError(f"{key} must be an integer, got {value!r}")
    # Compared before int(): 1e999999999 is a valid decimal with a billion digits.
    if not minimum <= exact < LABEL_LIMIT:
        raise ValueError(f"{key} must be an integer >= {minimum} and < 2**53, got {value!r}")
    return int(exact)


def plan_from_rows(rows: list[dict[str, object]], source: str, default_settle_s: float = DEFAULT_SETTLE_S) -> Plan:
    """A plan from table rows with keys q1, q2, q3 (N), and optionally settle_s (s), sweep
    and step; ``source`` names the file in errors ("plan.csv, row 3: ...").
    ``default_settle_s`` holds the rows without settle_s (a plan file's own default)."""
    try:
        default_settle_s = _check_settle("settle_s", _cell_number(default_settle_s, "settle_s"))
    except ValueError as error:
        # Not a row's fault: a TOML plan's top-level settle_s.
        raise ValueError(f"{source}: {error}") from None
    steps = []
    counters: dict[int, int] = {}
    rows_by_label: dict[tuple[int, int], int] = {}
    for number, row in enumerate(rows, start=1):
        unknown = sorted(set(row) - {"q1", "q2", "q3", "settle_s", "sweep", "step"})
        if unknown:
            raise ValueError(f"{source}, row {number}: unknown column {unknown[0]!r}; a plan takes q1, q2, q3, "
                             "settle_s, sweep, step")
        missing = [key for key in ("q1", "q2", "q3") if key not in row]
        if missing:
            raise ValueError(f"{source}, row {number}: missing {', '.join(missing)} (jet forces, N)")
        try:
            sweep = _cell_integer(row.get("sweep", 0), "sweep", CALIBRATION_SWEEP)
            step = _cell_integer(row.get("step", counters.get(sweep, 0)), "step", 0)
            counters[sweep] = step + 1
            forces = tuple(_cell_number(row[key], key) for key in ("q1", "q2", "q3"))
            settle_s = _check_settle("settle_s", _cell_number(row.get("settle_s", default_settle_s), "settle_s"))
            steps.append(PlanStep(forces, sweep, step, settle_s))  # type: ignore[arg-type]
        except (TypeError, ValueError) as error:
            raise ValueError(f"{source}, row {number}: {error}") from None
        # A recording's steps are told apart by these labels: two rows under one would
        # be read back as a single step.
        earlier = rows_by_label.setdefault((sweep, step), number)
        if earlier != number:
            raise ValueError(f"{source}, row {number}: sweep {sweep} step {step} is already row {earlier}'s; "
                             "each (sweep, step) pair names one step (leave step out to number a sweep's rows)")
    if not steps:
        raise ValueError(f"{source}: the plan has no steps")
    return Plan(tuple(steps))


__all__ = ["CALIBRATION_SWEEP", "DEFAULT_MAX_FORCE_N", "DEFAULT_SETTLE_S", "LABEL_LIMIT", "MAX_SETTLE_S",
           "PAPER_CALIBRATION_POSES", "Plan", "PlanStep", "calibration_plan", "clipped_warning", "hold_plan",
           "imu_versus_em_plan", "paper_protocol", "plan_from_rows", "validation_sweeps"]
