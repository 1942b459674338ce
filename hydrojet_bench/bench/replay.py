"""Re-run a session's estimation offline from its log.

A log holds every settled step (``/bench/step``: the averaged sensor poses, as
`Dataset.quasistatic_steps` rows), the parameters the live estimator used and when
(``/bench/parameters``: the starting ones, then the calibrated ones) and the live
predictions (``/model/prediction``). `replay` feeds the steps through a `PathPredictor` as
the session did, switching parameters at the same points, so with the live model and
settings it reproduces the live estimates exactly; with another model, effects or
parameters it answers "what would this model have done on that session".
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..data.dataset import Dataset, RowError, SampleFlag
from ..errors import ConvergenceError, UserError
from ..estimation.online import OnlineSettings
from ..estimation.path import PathPredictor, StepPrediction
from ..logs import read_log
from ..logs.dataset import logged_model, message_error, rig_profile_of_log
from ..logs.topics import ModelPrediction, Parameters, Step
from ..model_choice import ModelDefaults
from ..models.shooting import ShootingModel
from ..params import ModelParameters, with_parameters
from ..params_io import check_values_for
from ..profile import RigProfile

STEP_TOPIC = Step.topic
PARAMETERS_TOPIC = Parameters.topic
PREDICTION_TOPIC = ModelPrediction.topic


class NoSettledSteps(UserError):
    """The log holds no settled steps: it was not written by a bench session."""


@dataclass(frozen=True)
class ParameterRecord:
    t_s: float
    values: dict[str, float]
    calibrated: bool


@dataclass(frozen=True)
class LoggedSession:
    """What replay needs from a log. steps: the settled steps in order; plan_index: each
    step's index in the plan; live_errors: (plan index, method) -> orientation error, deg,
    as the live session computed it."""

    path: Path
    profile: RigProfile
    model_name: str
    effects: tuple[str, ...]
    steps: Dataset
    plan_index: np.ndarray
    step_times_s: np.ndarray
    parameters: tuple[ParameterRecord, ...]
    live_errors: dict[tuple[int, str], float]

    def model_defaults(self) -> ModelDefaults:
        """The model the session ran, named by the log in errors."""
        return ModelDefaults(self.model_name, self.effects, origin=f"{self.path}, metadata bench.model/effects")


def read_session(path: Path, profile: RigProfile | str | Path | None = None) -> LoggedSession:
    """The settled steps, parameter timeline and live predictions of a session log."""
    contents = read_log(path, topics=[STEP_TOPIC, PARAMETERS_TOPIC, PREDICTION_TOPIC])
    rig = rig_profile_of_log(path, profile, contents.metadata)
    records = contents.on(Step)
    if not records:
        cut = " (it is truncated: the session may have stopped before its first step settled)" \
            if contents.truncated else "; was it written by `hydrojet-bench run`?"
        raise NoSettledSteps(f"{path}: no settled steps ({STEP_TOPIC}) in this log{cut}")
    with_positions = all(row.base_position_m is not None for row in records)

    def column(key: str) -> np.ndarray:
        values = [getattr(row, key) for row in records]
        if any(value is None for value in values):
            raise ValueError(f"{STEP_TOPIC}.{key} is missing")
        return np.array(values, dtype=float)

    try:
        steps = Dataset(time_s=column("time_s"), jet_forces_n=column("jet_forces_n"),
                        base_orientation=column("base_orientation"), tip_orientation=column("tip_orientation"),
                        base_position_m=column("base_position_m") if with_positions else None,
                        tip_position_m=column("tip_position_m") if with_positions else None,
                        sweep=np.array([row.sweep for row in records]), step=np.array([row.step for row in records]),
                        # The live estimator used every row; of its flags only whether the tip
                        # still turned says something the analysis must repeat.
                        flags=np.array([row.flags for row in records], dtype=np.int64) & int(SampleFlag.UNSETTLED),
                        profile=rig, source=str(path))
    except RowError as error:
        raise message_error(path, STEP_TOPIC, records, error) from None
    except ValueError as error:
        raise UserError(f"{path}: {STEP_TOPIC} messages are not complete settled steps ({error})") from None
    model_name, effects = logged_model(path, contents.metadata)
    parameters = tuple(ParameterRecord(message.t_s, dict(message.parameters), message.calibrated)
                       for message in contents.on(Parameters))
    live = {(m.index, m.method): m.orientation_error_deg for m in contents.on(ModelPrediction)}
    return LoggedSession(Path(path), rig, model_name, effects,
                         steps, np.array([row.index for row in records]), np.array([r.t_s for r in records]),
                         parameters, live)


def logged_steps(path: Path, profile: RigProfile | str | Path | None = None) -> Dataset | None:
    """The settled steps of a session log, the rows its live estimator predicted (None
    when the log has none)."""
    try:
        return read_session(path, profile).steps
    except NoSettledSteps:
        return None


def replay(session: LoggedSession, model: ShootingModel, online: OnlineSettings | None,
           params: ModelParameters | None = None) -> list[StepPrediction | None]:
    """Predictions of every settled step (None where the model did not converge, as live).

    params: fixed parameters for every step; None follows the log's parameter timeline
    (a fresh predictor whenever the live one was restarted with new parameters)."""
    base = session.profile.model_parameters()
    predicted: list[StepPrediction | None] = []
    predictor: PathPredictor | None = None
    current: ParameterRecord | None = None
    for row in range(len(session.steps)):
        if params is None:
            record = _record_at(session, session.step_times_s[row])
            if record is not current:
                current, predictor = record, None
        if predictor is None:
            if params is None:
                # Effects the log names but this model leaves out are not the log's error.
                check_values_for(model.effects, current.values, f"{session.path}: {PARAMETERS_TOPIC} at "
                                 f"{current.t_s:.3f} s: ", unknown_effects=True)
            row_params = params if params is not None else with_parameters(base, current.values)
            predictor = PathPredictor(model, row_params, online)
            predictor.carry(session.steps.select(np.arange(row)))  # as the live session restarted it
        try:
            # One settled step at a time, as the session hands them over.
            predicted.extend(predictor.predict(session.steps.select([row])))
        except ConvergenceError:
            predicted.append(None)
    return predicted


def _record_at(session: LoggedSession, t_s: float) -> ParameterRecord:
    earlier = [record for record in session.parameters if record.t_s <= t_s]
    if not earlier:
        raise UserError(f"{session.path}: no {PARAMETERS_TOPIC} record before the step at {t_s:.1f} s; "
                        "give --params")
    return earlier[-1]


def _live_differences(session: LoggedSession, estimates: list[StepPrediction | None]):
    """(plan index, |replayed - live| orientation error, deg) of every step and method the
    log holds a live prediction of."""
    for index, estimate in zip(session.plan_index, estimates):
        if estimate is None:
            continue
        for prediction in (estimate.ref, estimate.online):
            if prediction is not None and (int(index), prediction.method) in session.live_errors:
                yield int(index), abs(prediction.orientation_error_deg - session.live_errors[int(index),
                                                                                             prediction.method])


def live_difference_deg(session: LoggedSession, estimates: list[StepPrediction | None]) -> float | None:
    """Largest |replayed - live| orientation error over every step and method, deg (None
    if the log holds no live predictions to compare with)."""
    return max((difference for _, difference in _live_differences(session, estimates)), default=None)


def live_steps_compared(session: LoggedSession, estimates: list[StepPrediction | None]) -> int:
    """How many steps `live_difference_deg` compared: a log cut before the live
    predictions of its last steps were written holds the steps but not their predictions."""
    return len({index for index, _ in _live_differences(session, estimates)})
