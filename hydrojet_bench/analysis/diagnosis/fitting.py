"""Fitting one model (the baseline, or the baseline plus a candidate effect) to the
training steps of a session and predicting every step along the recorded path.

Both fits and predictions follow the session in recorded order, each solve carrying the
path state of the one before (`calibrate(..., follow_path=True)`, `predict_path`), so a
clamp with play sees loading and unloading as the rig did.

Gravity: on a clamped base the per-step gravity the base sensor gives (`Dataset.
gravity_in_base_m_s2`) differs from step to step only by that sensor's noise. A model
fed that per-step gravity bends with the noise and so "predicts" part of it, which would
put the held-out error of a correct model below the measured noise floor. When every
step lies within `STATIC_BASE_DEG` of their mean, the mean is used for all of them.

Residual rows: the orientation rotation vector (rad) and, when positions were measured,
the error of the tip sensor's position (m, see `measurements`) times
``position_weight_rad_per_m`` = sigma_orientation / sigma_position per axis, the ratio
of the measured noise floors. Every row then carries the same noise, so the
least-squares fit is the maximum-likelihood one and the sum of squares over sigma^2 is
the chi-square a score can use.

Candidates are fitted in worker processes (``workers``, forked by Dask's process
scheduler, so effects loaded from user files travel along); each starts from the calibrated baseline with its own
parameters at their defaults (which leave the model unchanged), so it only has to move
away from an optimum it already shares.

Convergence: the solver works in parameters scaled by their typical magnitude, and a
fit has converged when the projected gradient of chi^2 per parameter scale is at most
`GRADIENT_TOLERANCE` (a Newton step then gains less than 0.25 in chi^2 for any
parameter the data see by at least the noise per scale unit: a fortieth of the ln n ~ 6
the score charges per parameter), whatever stopped the solver. chi^2 here takes the larger of the noise
variance and the fit's own residual variance: a model far from the data carries
residuals many times the noise, and with them finite-difference noise in its gradient
that no further step removes; a fit that ran out of evaluations first is
continued once with a larger budget and otherwise reported unconverged. The cost is
not convex in every effect's parameters (a mounting about the wrong axis, a gain on
the wrong side of E's trade-off), so after fitting a candidate from the baseline a
coarse scan of its own parameters, the baseline's held fixed (a grid for one or two
parameters, a step either way along each axis for more), looks for a better basin: a
scan point whose chi^2 beats that fit's (with every parameter free) lies in another
basin, and the candidate is fitted from there too, the better fit kept. That scan
cannot see a basin that needs the baseline's parameters elsewhere (a stiffening effect
the baseline absorbed into E); before a stage calls the excess unexplained, a profile
scan (`profile_starts`: the baseline's parameters re-fitted at each point) gives the
one- and two-parameter candidates another start (`refit_candidates`).

Bounds: a fit that ends on a search bound of its effect (one that is not the
parameter's no-effect default) is refitted with the bounds widened to the physical
limits (`EffectParameter.limits`); a fit still on a bound is flagged (``at_bound``).

Standard errors: from the scaled Jacobian at the optimum with the noise variance the
diagnosis measured (not the fit's own residual variance, which a missing effect would
inflate). A PRB chain is not the rod: a named effect's errors also carry the chain's
discretization error (`refined_chain`, added by the engine).
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import dask
import dask.local
import dask.multiprocessing
import numpy as np
from dask.callbacks import Callback

from ...data.dataset import Dataset
from ...effects import Effect, qualified_parameter_names
from ...effects.base import at_physical_limits
from ...errors import ConvergenceError
from ...estimation.calibration import (DEFAULT_NAMES, GRADIENT_TOLERANCE, CalibrationPose, calibrate,
                                       calibration_poses, on_bound)
from ...estimation.path import REF, PathPredictor, Predictions
from ...geometry import body_rotation_error, matrix_from_quat
from ...models import make_model
from ...models.shooting import PrbModel, ShootingModel, tip_sensor_positions_in_base_sensor_m
from ...params import ModelParameters, with_parameters
from ..compare import compare, validation_rows
from ..metrics import ErrorSummary
from .measurements import tip_sensor_offset_in_tip_m, tip_sensor_position_in_base_m
from .split import Split

# A candidate starts at the baseline's optimum: a few dozen evaluations converge it; a
# fit still unconverged then gets `CONTINUATION_EVALUATIONS` more once.
CANDIDATE_MAX_EVALUATIONS = 40
BASELINE_MAX_EVALUATIONS = 100
CONTINUATION_EVALUATIONS = 60
# The solver may also stop once a step gains less than this fraction of the cost (1e-6
# of chi^2 ~ 600 is far below any score difference); the gradient test then judges.
COST_TOLERANCE = 1e-9
# The coarse scan: grid points per parameter for one- and two-parameter effects, and
# the step along each axis (share of the bounds' span) for more.
SCAN_POINTS = {1: 5, 2: 3}
SCAN_AXIS_SHARE = 0.25
# The profile scan (`profile_starts`), for one- and two-parameter effects: the shares of
# the way from the default to each bound it tries per parameter (their grid, or only its
# axes through the default when the grid has more than `PROFILE_MAX_POINTS`), and the
# evaluations the baseline's parameters get at each point.
PROFILE_AXIS_SHARES = {1: (0.1, 0.3, 1.0), 2: (0.25, 1.0)}
PROFILE_MAX_POINTS = 12
PROFILE_EVALUATIONS = 8
# `training_cost` predicts the path in this many pieces, to stop once it is lost.
COST_CHUNKS = 4
# A base that tilts less than this over a session is clamped (tracker noise is ~0.7 deg
# per sample, ~0.1 deg per averaged step).
STATIC_BASE_DEG = 2.0


@dataclass(frozen=True)
class Fit:
    """One model fitted to the training steps.

    effect: the candidate's name, None for the baseline. names/values/standard_errors:
    the fitted parameters. params: the calibrated parameters. predictions: every step of
    the session along its path; sensor_positions_m: the tip sensor's predicted position
    there (N, 3), base frame. training_chi2: sum of squared training residual rows over
    the per-axis noise variance; training_rows: their number. error: why the fit failed
    (then predictions is None and the candidate is ranked last).
    """

    effect: str | None
    names: tuple[str, ...]
    values: np.ndarray
    standard_errors: np.ndarray
    params: ModelParameters | None
    predictions: Predictions | None
    sensor_positions_m: np.ndarray | None
    training_chi2: float
    training_rows: int
    evaluations: int
    unidentifiable: tuple[tuple[str, str, float], ...] = ()
    error: str | None = None
    converged: bool = False
    stop_reason: str = ""
    scaled_gradient: float = float("nan")
    at_bound: tuple[str, ...] = ()
    widened: bool = False
    starts: int = 1

    @property
    def parameter_count(self) -> int:
        return len(self.names)

    @property
    def convergence(self) -> str:
        """Why the fit is (or is not) taken as converged, in words."""
        verdict = "converged" if self.converged else "NOT converged"
        return (f"{verdict}: {self.stop_reason} after {self.evaluations} evaluations, scaled gradient "
                f"{self.scaled_gradient:.2g} (tolerance {GRADIENT_TOLERANCE:g}), {self.starts} start(s)"
                + (", bounds widened to the physical limits" if self.widened else ""))


@dataclass(frozen=True)
class Problem:
    """Everything a fit needs: the session's steps, the split, gravity in the base frame
    per step (m/s^2, see `session_gravity`), the model family and the baseline's effects,
    the initial parameters, the residual weighting."""

    steps: Dataset
    split: Split
    gravity_in_base_m_s2: np.ndarray
    model_name: str
    baseline_effects: tuple[Effect, ...]
    known_names: tuple[str, ...]
    initial: ModelParameters
    orientation_sigma_rad: float
    position_weight_rad_per_m: float
    # PRB links when not the model's default (`refined_chain` doubles them).
    prb_links: int | None = None

    def model(self, candidate: Effect | None = None) -> ShootingModel:
        """The baseline's model, plus ``candidate`` when it is not already part of it."""
        effects = self.baseline_effects
        if candidate is not None and all(effect.name != candidate.name for effect in effects):
            effects = effects + (candidate,)
        if self.prb_links is not None:
            return PrbModel(effects, links=self.prb_links)
        return make_model(self.model_name, effects)

    def names(self, candidate: Effect | None = None) -> tuple[str, ...]:
        extra = () if candidate is None else qualified_parameter_names(candidate)
        return DEFAULT_NAMES + self.known_names + tuple(name for name in extra if name not in self.known_names)


def session_gravity(steps: Dataset) -> np.ndarray:
    """(N, 3) gravity in the base frame for each step: their mean when the base is static
    (see the module docstring), else each step's own."""
    gravity = steps.gravity_in_base_m_s2()
    mean = gravity.mean(axis=0)
    cosine = gravity @ mean / (np.linalg.norm(gravity, axis=1) * np.linalg.norm(mean))
    if np.degrees(np.arccos(np.clip(cosine.min(), -1.0, 1.0))) <= STATIC_BASE_DEG:
        return np.tile(mean, (len(steps), 1))
    return gravity


def predict_path(model: ShootingModel, params: ModelParameters, steps: Dataset,
                 gravity_in_base_m_s2: np.ndarray) -> tuple[Predictions, np.ndarray]:
    """Ref. at every step in recorded order, each solve carrying the previous one's path
    state (`PathPredictor` with the given gravity). Also returns the tip sensor's
    position (N, 3) as read in the measured base frame, m
    (`Solution.tip_sensor_position_in_base_sensor_m`)."""
    return _predicted(PathPredictor(model, params), steps, gravity_in_base_m_s2)


def _predicted(predictor: PathPredictor, steps: Dataset,
               gravity_in_base_m_s2: np.ndarray) -> tuple[Predictions, np.ndarray]:
    """`predict_path` by ``predictor``, which continues the path from its last step."""
    offset = np.array(tip_sensor_offset_in_tip_m(steps))
    path = predictor.predict(steps, gravity_in_base_m_s2)
    sensor_positions = tip_sensor_positions_in_base_sensor_m([step.ref.solution for step in path],
                                                             np.tile(offset, (len(path), 1)))
    return Predictions.along(path, REF), sensor_positions


def scored_as_diagnosed(model: ShootingModel, params: ModelParameters, steps: Dataset) -> ErrorSummary:
    """Ref.'s errors on the validation steps (sweep >= 0; all steps without sweeps) as a
    diagnosis scores them: along the whole path of ``steps`` in recorded order, gravity
    held at the steps' mean when the base is static (`session_gravity`). Per-step gravity
    would let a model follow the base sensor's noise, below the floor diagnose measures."""
    predictions, _ = predict_path(model, params, steps, session_gravity(steps))
    rows = validation_rows(steps)
    return compare(predictions.select(rows), steps.select(rows)).overall


def training_poses(problem: Problem) -> list[CalibrationPose]:
    """The solved prefix of the session as calibration poses, with the session's gravity
    and the tip sensor's own position."""
    steps = problem.steps
    rows = np.flatnonzero(problem.split.solved)
    positions = tip_sensor_position_in_base_m(steps)
    offset = tip_sensor_offset_in_tip_m(steps)
    return [replace(pose, gravity_in_base_m_s2=tuple(problem.gravity_in_base_m_s2[row]),
                    tip_position_in_base_sensor_m=None if positions is None else positions[row],
                    position_offset_in_tip_m=offset)
            for pose, row in zip(calibration_poses(steps.select(rows)), rows)]


def fit(problem: Problem, candidate: Effect | None = None, start: ModelParameters | None = None,
        max_evaluations: int = BASELINE_MAX_EVALUATIONS) -> Fit:
    """Calibrate the baseline (or baseline + ``candidate``) on the training steps from
    ``start`` (default: the initial parameters), then predict the whole session; an
    unconverged fit is continued once (`CONTINUATION_EVALUATIONS`)."""
    result = _fit_once(problem, candidate, start or problem.initial, max_evaluations)
    if result.error is None and not result.converged:
        more = _fit_once(problem, candidate, result.params, CONTINUATION_EVALUATIONS)
        if more.error is None and more.training_chi2 <= result.training_chi2:
            result = replace(more, evaluations=result.evaluations + more.evaluations)
    return result


def _fit_once(problem: Problem, candidate: Effect | None, start: ModelParameters, max_evaluations: int) -> Fit:
    model = problem.model(candidate)
    names = problem.names(candidate)
    label = None if candidate is None else candidate.name
    sigma2 = problem.orientation_sigma_rad**2
    try:
        result = calibrate(model, training_poses(problem), start, names,
                           position_weight_rad_per_m=problem.position_weight_rad_per_m,
                           max_evaluations=max_evaluations, follow_path=True, cost_tolerance=COST_TOLERANCE,
                           gradient_tolerance=GRADIENT_TOLERANCE / 2.0, variance_floor=sigma2,
                           fitted=split_training_rows(problem))
        predictions, sensor_positions = predict_path(model, result.params, problem.steps,
                                                     problem.gravity_in_base_m_s2)
    except (ConvergenceError, ValueError) as error:
        # A candidate pushed to where the model cannot solve explains nothing; the baseline
        # failing is the caller's problem.
        if candidate is None:
            raise
        nothing = np.full(len(names), np.nan)
        return Fit(label, names, nothing, nothing, None, None, None, np.inf, 0, 0, error=str(error))
    chi2, rows = training_chi2(problem, predictions, sensor_positions)
    # calibrate scales its covariance by the residual variance, chi2 sigma^2 / dof; the
    # measured noise variance is sigma^2.
    standard_errors = result.standard_errors * np.sqrt(max(rows - len(names), 1) / max(chi2, 1e-300))
    # Of chi^2 (see the module docstring), per parameter scale.
    gradient = 2.0 * result.scaled_gradient_norm / (sigma2 * max(1.0, chi2 / rows))
    return Fit(label, names, result.values, standard_errors, result.params, predictions, sensor_positions,
               chi2, rows, result.evaluations, result.unidentifiable,
               converged=gradient <= GRADIENT_TOLERANCE and not result.off_branch,
               stop_reason=result.stop_reason + result.branch_note,
               scaled_gradient=gradient,
               at_bound=_at_bound(candidate, dict(zip(names, result.values))))


def _at_bound(candidate: Effect | None, values: dict[str, float]) -> tuple[str, ...]:
    """The candidate's parameters that sit on a search bound other than their default."""
    if candidate is None:
        return ()
    names = [f"{candidate.name}.{parameter.name}" for parameter in candidate.parameters]
    return tuple(name for name, parameter in zip(names, candidate.parameters)
                 if on_bound(values[name], parameter.lower, parameter.upper, parameter.default))


def fit_candidate(problem: Problem, candidate: Effect, baseline: ModelParameters,
                  max_evaluations: int | None = None) -> Fit:
    """Fit ``candidate`` on top of the calibrated ``baseline``: from the baseline with the
    candidate at its defaults and, when the coarse scan finds a better basin, from there
    too (the better fit is kept); then, if it ends on a search bound, again with the
    bounds widened to the physical limits (see the module docstring)."""
    max_evaluations = max_evaluations or CANDIDATE_MAX_EVALUATIONS
    fits = [fit(problem, candidate, baseline, max_evaluations)]
    starts = scan_starts(problem, candidate, baseline, fits[0].training_chi2)
    fits += [fit(problem, candidate, start, max_evaluations) for start in starts]
    if not any(result.converged for result in fits):
        # The baseline may have bent far from the truth to absorb the candidate's effect,
        # into a valley the fit with it cannot leave: a jet ring turned 0.3 rad made the
        # baseline's tip 40 times too soft (EL 5 kPa), and the ring's fit from there
        # stalled at 1.1 deg where one from the profile's start reaches the floor.
        fits.append(fit(problem, candidate, None, max_evaluations))
    return _best_of(problem, candidate, fits, max_evaluations)


@dataclass(frozen=True)
class ChainRefinement:
    """A PRB fit repeated with twice the links (`refined_chain`): each of the candidate's
    own parameters' discretization error estimate (name -> error, its unit) and the
    refined fit."""

    links: int
    errors: dict[str, float]
    fit: Fit


def refined_chain(problem: Problem, candidate: Effect, result: Fit) -> ChainRefinement | None:
    """For a PRB fit, the fit repeated with twice the links from ``result``; None for the
    Cosserat rod or when that fit fails.

    A chain of n links is not the rod: its fitted parameters carry a bias that no noise
    estimate contains (1 to 3 % on a rod bent across gravity, against standard errors of
    0.1 %), and so do its predictions. The chain converges to the rod at second order in
    the links, so the n-link bias is about 4/3 of the change from n to 2n links; twice
    the change bounds it with room for a chain not yet in that regime."""
    if problem.model_name != "prb" or result.params is None:
        return None
    links = 2 * (problem.prb_links or make_model("prb", problem.baseline_effects).links)
    finer = fit(replace(problem, prb_links=links), candidate, result.params, CANDIDATE_MAX_EVALUATIONS)
    if finer.error is not None:
        return None
    own = set(qualified_parameter_names(candidate))
    errors = {name: 2.0 * abs(float(fine) - float(value)) for name, value, fine
              in zip(result.names, result.values, finer.values) if name in own}
    return ChainRefinement(links, errors, finer)


def refit_from_profile(problem: Problem, candidate: Effect, baseline: ModelParameters, first: Fit,
                       max_evaluations: int | None = None) -> Fit:
    """``first`` (the candidate's fit by `fit_candidate`), or a fit from the best point of
    the profile scan (`profile_starts`) when that point beats it: the second pass of a
    diagnosis whose first pass left the excess unexplained."""
    max_evaluations = max_evaluations or CANDIDATE_MAX_EVALUATIONS
    if first.error is not None or len(candidate.parameters) not in PROFILE_AXIS_SHARES:
        return first
    starts = profile_starts(problem, candidate, baseline, first.training_chi2)
    if not starts:
        return first
    again = _best_of(problem, candidate, [fit(problem, candidate, start, max_evaluations) for start in starts],
                     max_evaluations)
    kept = again if _preference(again) < _preference(first) else first
    return replace(kept, starts=first.starts + again.starts, evaluations=first.evaluations + again.evaluations)


def _best_of(problem: Problem, candidate: Effect, fits: list[Fit], max_evaluations: int) -> Fit:
    """The preferred of ``fits`` (`_preference`), refitted with its bounds widened to the
    physical limits when it ends on a search bound."""
    best = min(fits, key=_preference)
    if best.error is None and best.at_bound:
        widened_effect = at_physical_limits(candidate)
        if widened_effect.parameters != candidate.parameters:
            wider = fit(problem, widened_effect, best.params, max_evaluations)
            # The widened fit answers the honest question; keep the narrow one only when
            # the widened one failed, or neither converged nor improved on it.
            if wider.error is None and (wider.converged or wider.training_chi2 <= best.training_chi2):
                best = replace(wider, widened=True)
    return replace(best, starts=len(fits), evaluations=sum(f.evaluations for f in fits)
                   + (best.evaluations if best.widened else 0))


def _preference(result: Fit) -> tuple[bool, float]:
    """Converged fits before unconverged ones, then the lower training chi^2."""
    return (not result.converged, result.training_chi2)


def scan_starts(problem: Problem, candidate: Effect, baseline: ModelParameters,
                fitted_chi2: float) -> list[ModelParameters]:
    """The best point of a coarse scan of the candidate's own parameters (the
    baseline's held fixed) as another start, when its chi^2 beats ``fitted_chi2`` (the
    fit from the defaults) by more than one; else none."""
    parameters = candidate.parameters
    names = qualified_parameter_names(candidate)
    if len(parameters) in SCAN_POINTS:
        axes = [np.linspace(p.lower, p.upper, SCAN_POINTS[len(parameters)]) for p in parameters]
        points = [dict(zip(names, values)) for values in itertools.product(*axes)]
    else:
        points = []
        for parameter, name in zip(parameters, names):
            step = SCAN_AXIS_SHARE * (parameter.upper - parameter.lower)
            points += [{name: value} for value in (parameter.default - step, parameter.default + step)
                       if parameter.lower <= value <= parameter.upper]
    defaults = {name: p.default for name, p in zip(names, parameters)}
    model = problem.model(candidate)
    best, best_cost = None, fitted_chi2 - 1.0
    for point in points:
        trial = with_parameters(baseline, {**defaults, **point})
        cost = training_cost(problem, model, trial, stop_above=best_cost)
        if cost < best_cost:
            best, best_cost = trial, cost
    return [] if best is None else [best]


def profile_starts(problem: Problem, candidate: Effect, baseline: ModelParameters,
                   fitted_chi2: float) -> list[ModelParameters]:
    """The best point of a profile scan of the candidate's own parameters, as another
    start, when its chi^2 beats ``fitted_chi2`` by more than one; else none.

    Unlike `scan_starts`, the baseline's parameters are re-fitted at every point (a few
    evaluations, `PROFILE_EVALUATIONS`): an effect that trades off against E, L or w_d
    (a stiffening one wants a softer rod beside it, a compliant clamp a stiffer one)
    shows its basin only once they have moved out of its way, and a scan that holds the
    baseline's optimum fixed sees every point of that basin as worse than none."""
    names = qualified_parameter_names(candidate)
    axes = [_profile_axis(parameter, PROFILE_AXIS_SHARES[len(names)]) for parameter in candidate.parameters]
    defaults = tuple(parameter.default for parameter in candidate.parameters)
    grid = [values for values in itertools.product(*axes) if values != defaults]
    if len(grid) > PROFILE_MAX_POINTS:
        grid = [values for values in grid if sum(v != d for v, d in zip(values, defaults)) == 1]
    points = [dict(zip(names, values)) for values in grid]
    model, poses, rows = problem.model(candidate), training_poses(problem), split_training_rows(problem)
    best, best_cost = None, fitted_chi2 - 1.0
    for point in points:
        try:
            result = calibrate(model, poses, with_parameters(baseline, point), problem.names(),
                               position_weight_rad_per_m=problem.position_weight_rad_per_m,
                               max_evaluations=PROFILE_EVALUATIONS, follow_path=True, cost_tolerance=COST_TOLERANCE,
                               fitted=rows)
        except (ConvergenceError, ValueError):
            continue
        cost = training_cost(problem, model, result.params, stop_above=best_cost)
        if cost < best_cost:
            best, best_cost = result.params, cost
    return [] if best is None else [best]


def _profile_axis(parameter, shares: tuple[float, ...]) -> list[float]:
    """The default, then ``shares`` of the way from it to each search bound."""
    return [parameter.default] + [parameter.default + share * (bound - parameter.default)
                                  for bound in (parameter.lower, parameter.upper) if bound != parameter.default
                                  for share in shares]


def split_training_rows(problem: Problem) -> np.ndarray:
    """Which of the solved prefix's steps a fit is fitted on (the others carry the path)."""
    return problem.split.training[problem.split.solved]


def training_cost(problem: Problem, model: ShootingModel, params: ModelParameters,
                  stop_above: float = np.inf) -> float:
    """Training chi^2 of ``params`` along the solved prefix (inf when a solve fails).

    The path is predicted in `COST_CHUNKS` pieces. chi^2 only grows along it, so once the
    pieces so far exceed ``stop_above`` their sum is returned: a lower bound, enough to
    say that the point loses to ``stop_above`` (most points of a scan do, well before the
    path's end). Otherwise the whole sum, the same as in one piece."""
    prefix = np.flatnonzero(problem.split.solved)
    predictor = PathPredictor(model, params)
    pieces, cost = [], 0.0
    try:
        for rows in np.array_split(prefix, min(COST_CHUNKS, len(prefix))):
            predictions, positions = _predicted(predictor, problem.steps.select(rows),
                                                problem.gravity_in_base_m_s2[rows])
            pieces.append(residual_rows(problem, predictions, positions, problem.split.training[rows], rows[0]))
            cost += float(np.sum(pieces[-1]**2) / problem.orientation_sigma_rad**2)
            if cost > stop_above:
                return cost
    except (ConvergenceError, ValueError):
        return float("inf")
    return float(np.sum(np.vstack(pieces)**2) / problem.orientation_sigma_rad**2)


def residual_rows(problem: Problem, predictions: Predictions, sensor_positions_m: np.ndarray,
                  mask: np.ndarray, start: int = 0) -> np.ndarray:
    """(n, 3 or 6) residual rows of the masked steps: orientation rotation vectors (rad),
    then weighted tip sensor position errors when measured (see the module docstring).
    The predictions may cover a stretch of the session only, from step ``start``;
    ``mask`` then covers it too."""
    steps = problem.steps
    stretch = slice(start, start + len(mask))
    rotation = body_rotation_error(matrix_from_quat(predictions.tip_orientation_in_base[mask]),
                                   matrix_from_quat(steps.tip_orientation_in_base()[stretch][mask]))
    measured = tip_sensor_position_in_base_m(steps)
    if measured is None or problem.position_weight_rad_per_m == 0.0:
        return rotation
    offset = sensor_positions_m[mask] - measured[stretch][mask]
    return np.hstack([rotation, problem.position_weight_rad_per_m * offset])


def training_chi2(problem: Problem, predictions: Predictions, sensor_positions_m: np.ndarray) -> tuple[float, int]:
    rows = residual_rows(problem, predictions, sensor_positions_m, problem.split.training)
    return float(np.sum(rows**2) / problem.orientation_sigma_rad**2), int(rows.size)


# --- candidates, in parallel ----------------------------------------------------------

# What the worker processes run, by candidate index: set before they are forked, so they
# inherit it (effects loaded from user files included) instead of receiving it pickled.
_WORK: Callable[[int], Fit] | None = None


def _run_work(index: int) -> Fit:
    assert _WORK is not None
    return _WORK(index)


def default_workers() -> int:
    """Processes for the candidate fits: up to 2, the CPUs there are (the bench machine
    has two; more would only contend with the bench itself)."""
    return min(2, os.cpu_count() or 1)


def fit_candidates(problem: Problem, candidates: Sequence[Effect], baseline: Fit, workers: int | None = None,
                   progress: Callable[[Fit], None] | None = None) -> list[Fit]:
    """Fit every candidate from the baseline's calibration (`fit_candidate`); returns the
    fits in candidate order.

    workers: processes (default `default_workers`); 1 fits in this process, as does a
    platform without fork. The fits run on Dask, the engine studies run on: its local
    process scheduler here, whose forked pool starts in milliseconds (a distributed
    `LocalCluster` takes seconds, as long as the whole diagnosis).
    """
    start = _baseline_params(baseline)
    return _in_parallel(candidates, lambda index: fit_candidate(problem, candidates[index], start), workers, progress)


def refit_candidates(problem: Problem, candidates: Sequence[Effect], baseline: Fit, fits: Sequence[Fit],
                     workers: int | None = None, progress: Callable[[Fit], None] | None = None) -> list[Fit]:
    """Each candidate's fit, or a better one from its profile scan (`refit_from_profile`),
    in candidate order; ``workers`` as `fit_candidates`."""
    start = _baseline_params(baseline)
    return _in_parallel(candidates, lambda index: refit_from_profile(problem, candidates[index], start, fits[index]),
                        workers, progress)


def _baseline_params(baseline: Fit) -> ModelParameters:
    if baseline.params is None:
        raise ValueError("the baseline fit failed; no candidate can start from it")
    return baseline.params


def _in_parallel(candidates: Sequence[Effect], work: Callable[[int], Fit], workers: int | None,
                 progress: Callable[[Fit], None] | None) -> list[Fit]:
    """``work(index)`` for every candidate, on Dask (see `fit_candidates`), in candidate order."""
    global _WORK
    count = len(candidates)
    workers = min(count, workers if workers is not None else default_workers())
    parallel = workers > 1 and "fork" in multiprocessing.get_all_start_methods()
    graph, order = fit_graph(candidates)

    def finished(key, result, graph, state, worker) -> None:
        if progress and isinstance(result, Fit):
            progress(result)

    _WORK = work
    try:
        with Callback(posttask=finished):
            if parallel:
                with dask.config.set({"multiprocessing.context": "fork"}):
                    # One fit per dispatch: Dask's default batches of 6 would leave a
                    # worker idle while the other works through its batch.
                    fits = dask.multiprocessing.get(graph, list(graph), num_workers=workers, chunksize=1)
            else:
                fits = dask.local.get_sync(graph, list(graph))
    finally:
        _WORK = None
    results: list[Fit | None] = [None] * count
    for index, result in zip(order, fits):
        results[index] = result
    return results  # type: ignore[return-value]


def fit_graph(candidates: Sequence[Effect]) -> tuple[dict, list[int]]:
    """The Dask graph of the candidates' fits, one task each, and the candidate of each
    task in the graph's order. The fewest-parameter fits start first: the slowest have
    one parameter (nonlinear elasticity, pressure stiffening: 0.4-0.6 s, three-parameter
    fits 0.2-0.3 s). Dask orders independent tasks by key, the highest first
    (`dask.order`), so the first to run gets the highest."""
    count = len(candidates)
    order = sorted(range(count), key=lambda index: len(candidates[index].parameters))
    return {f"candidate-{count - 1 - rank:04d}": (_run_work, index) for rank, index in enumerate(order)}, order
