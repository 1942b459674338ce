"""`diagnose`: which effect from the library is the model missing?

1. Split the session (`split`): calibration poses and one run of each sweep train, the
   repetitions are held out.
2. Estimate the noise floor from the data (`noise`): the held-out error no deterministic
   model can beat.
3. Fit the baseline (the model with gravity at its nominal weight and the known
   effects; E0, EL, L, w_d and the known effects' parameters) and every candidate
   (baseline + one effect, its parameters freed), and score each on the held-out steps.
4. Decide:

   * ``none`` when the baseline's held-out error is at the floor: an F test of its mean
     square against the floor's (F(3 n_held_out, floor dof), 1 % level), allowing for
     the parameters' own uncertainty, which adds about k / n_training to a prediction's
     mean square;
   * otherwise the candidate with the best score among those whose fit converged,
     that remove at least half of the EXCESS squared error (``explained_fraction`` =
     (baseline^2 - candidate^2) / (baseline^2 - floor^2), on held-out RMSEs) and beat
     the baseline's score; ``unexplained`` when none does. An unconverged fit never
     qualifies and is ranked after every converged one.
   * ``undecided`` instead of a name or ``unexplained`` when the fits cannot tell: the
     baseline's fit did not converge (no candidate can be measured against a baseline
     short of its optimum, unless it brings the held-out error to the floor), or no
     candidate's did, or none qualifies and one that did not would remove the excess
     were its fit to be believed.
   * before a stage says ``unexplained``, its one- and two-parameter candidates get a
     second pass: a profile scan of their parameters with the baseline's re-fitted at
     each point (`fitting.profile_starts`), and the decision is taken again. A stiffening
     effect the baseline has absorbed into E lies in a basin no fit from the baseline's
     optimum reaches.

5. Ties: another qualifying candidate whose held-out errors are not significantly
   larger than the winner's (a one-sided paired t test on the per-step squared errors
   of the held-out steps, at the ``significance`` level) explains the data as well
   within noise: it is listed as an alternative, and `separate` proposes the poses
   where their predictions differ most.
6. Depth: while the winner leaves a held-out error above the at-the-floor threshold,
   the winner joins the baseline (its calibrated parameters the start) and the
   remaining candidates are tried on top of it, up to ``depth`` effects in all; each
   found effect carries its share of the first baseline's excess squared error.

7. Setup before physics (`setup`): in the first stage the setup hypotheses (a wrong
   jet wiring, reversed or mis-scaled jet forces, a tilted tracker, a turned base sensor)
   are fitted beside the physical candidates, moved to their own ranking, and decided
   first (`setup.with_setup_stage`: setup wins unless a physical candidate is
   significantly better by the held-out test of 5., or decisively better by score and
   no worse held out).
   A setup winner joins the baseline like a physical one for the later stages.

Score: BIC on the TRAINING residuals with the noise scale fixed at the measured floor,
chi^2 + k ln(n) (chi^2 = training sum of squares / sigma^2, k fitted parameters, n
residual rows); lower is better. Why training residuals: an information criterion
corrects a fit for the parameters spent on the data it was fitted to; the held-out
error has no such optimism and is reported beside it (explained_fraction), so using
held-out residuals with a penalty would count the parameters twice. Why BIC rather than
AIC: the question is which physical effect is present, not which model predicts best,
and BIC's ln(n) ~ 5.7 per parameter is consistent (it picks the true effect as data
grow), so of two candidates that explain the data alike, the one with fewer parameters
wins. Why sigma fixed: the floor is measured independently of every model, so score
differences are likelihood ratios (a difference above 10 is "very strong" evidence in
Kass and Raftery's scale); candidates whose score is within that of the winner's are
reported as hard to tell apart when the held-out test (5.) cannot separate them.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.stats import f as f_distribution
from scipy.stats import t as t_distribution

from ...data.dataset import Dataset
from ...effects import LIBRARY, Effect, load_effect, qualified_parameter_names
from ...effects.base import at_physical_limits
from ...errors import UserError
from ...estimation.online import OnlineSettings
from ...geometry import rotation_angle_deg
from ...params import ModelParameters
from .evidence import (NOISE_GAP_PER_FLOOR, OnlineEvidence, cosine, hysteresis_gap_deg, online_evidence,
                       rmse_by_jet, rotation_between)
from .fitting import Fit, Problem, fit, fit_candidates, refined_chain, refit_candidates, session_gravity
from .noise import NoiseFloor, estimate_noise_floor
from .separate import SeparatingPose, separating_poses
from .setup import DECISIVE_SCORE_GAP, SetupFix, fit_discrete, hypotheses, with_setup_stage
from .split import Split, split_session

NONE, UNEXPLAINED, UNDECIDED = "none", "unexplained", "undecided"
DEFAULT_DEPTH = 3
AT_BOUND_NOTE = "at its bound: may be larger"


@dataclass(frozen=True)
class DiagnosisSettings:
    """significance: level of the at-the-floor F test. min_explained_fraction: share of
    the excess squared held-out error a winner must remove. workers: processes for the
    candidate fits (None: up to 2). online: the estimator used for the evidence.
    window_s: averaging window of the steps (for the within-window noise estimate).
    depth: most effects named in one diagnosis."""

    significance: float = 0.01
    min_explained_fraction: float = 0.5
    workers: int | None = None
    online: OnlineSettings = field(default_factory=OnlineSettings)
    window_s: float = 1.0
    depth: int = DEFAULT_DEPTH


@dataclass(frozen=True)
class CandidateResult:
    """One candidate: its fitted parameters (name -> (value, standard error)), held-out
    orientation RMSE (deg), explained_fraction (0 when the baseline is already at the
    floor: nothing to explain), score (BIC, lower is better) and its
    difference to the baseline's, whether it passes both tests (``qualifies``), and the
    evidence: held-out RMSE per driving jet, hysteresis gap of its residuals (deg),
    cosine of its signature with the baseline residual and with the online
    disturbance estimate. error: why its fit failed, if it did. converged and
    convergence: whether its fit converged, and why (see `fitting`). at_bound: its
    parameters that ended on a bound (after widening to the physical limits when
    ``widened``): the value may be larger."""

    effect: str
    explanation: str
    parameters: dict[str, tuple[float, float]]
    heldout_orientation_rmse_deg: float
    explained_fraction: float
    score: float
    score_change: float
    qualifies: bool
    rmse_by_jet_deg: dict[str, float]
    hysteresis_gap_deg: float | None
    residual_correlation: float
    online_correlation: float
    evaluations: int
    error: str | None = None
    converged: bool = False
    convergence: str = ""
    at_bound: tuple[str, ...] = ()
    widened: bool = False
    # Every fitted parameter (the baseline's too): what `diagnose --export` writes.
    calibrated: dict[str, tuple[float, float]] = field(default_factory=dict)
    # A PRB winner's discretization error per own parameter, already in its standard
    # errors, and (links, held-out RMSE in deg) of its fit on twice the chain's links
    # (`fitting.refined_chain`): how much of what it leaves is the chain's own.
    discretization: dict[str, float] = field(default_factory=dict)
    refined_chain: tuple[int, float] | None = None

    @property
    def notes(self) -> tuple[str, ...]:
        """What keeps this fit from being final: unconverged, on a bound."""
        notes = [] if self.converged or self.error is not None else ["not converged"]
        notes += [f"{name.partition('.')[2]} {AT_BOUND_NOTE}" for name in self.at_bound]
        return tuple(notes)

    def as_dict(self) -> dict:
        return {
            "effect": self.effect, "converged": self.converged, "convergence": self.convergence,
            "at_bound": list(self.at_bound), "bounds_widened": self.widened, "notes": list(self.notes),
            "heldout_orientation_rmse_deg": _number(self.heldout_orientation_rmse_deg),
            "explained_fraction": _number(self.explained_fraction), "score": _number(self.score),
            "score_change": _number(self.score_change), "qualifies": self.qualifies,
            "parameters": {name: {"value": _number(value), "standard_error": _number(error)}
                           for name, (value, error) in self.parameters.items()},
            "rmse_by_jet_deg": self.rmse_by_jet_deg, "hysteresis_gap_deg": self.hysteresis_gap_deg,
            "residual_correlation": self.residual_correlation, "online_correlation": self.online_correlation,
            "evaluations": self.evaluations, "error": self.error,
            "discretization_error": self.discretization,
            "refined_chain": _chain_document(self.refined_chain),
        }


@dataclass(frozen=True)
class FoundEffect:
    """One effect a diagnosis names: its share of the first baseline's excess squared
    held-out error (over the floor), the held-out RMSE once it is added (deg), its
    fitted parameters (name -> (value, standard error)) and what keeps it from being
    final (`CandidateResult.notes`)."""

    effect: str
    share_of_excess: float
    heldout_orientation_rmse_deg: float
    parameters: dict[str, tuple[float, float]]
    notes: tuple[str, ...]
    refined_chain: tuple[int, float] | None = None  # see `CandidateResult.refined_chain`

    def as_dict(self) -> dict:
        return {"effect": self.effect, "share_of_excess": _number(self.share_of_excess),
                "heldout_orientation_rmse_deg": _number(self.heldout_orientation_rmse_deg),
                "parameters": {name: {"value": _number(value), "standard_error": _number(error)}
                               for name, (value, error) in self.parameters.items()},
                "notes": list(self.notes),
                "refined_chain": _chain_document(self.refined_chain)}


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of `diagnose`; see the module docstring for the rules.

    verdict: "none", "unexplained", "undecided" or the winning effect's name. explanation: the
    winner's physics in words (or why there is none). ranking: the qualifying candidates
    by score (the winner first), then the other converged fits by score, then the
    unconverged ones, then failed fits. alternatives: qualifying candidates the held-out
    test cannot tell from the winner. at_floor_threshold_deg: the largest held-out RMSE
    the F test calls "at the floor". remaining_excess: whether the winner still leaves
    a held-out error above that threshold (more physics missing; always so when the
    verdict is "unexplained", never when it is "none"). stages: the later
    stages (the winner added to the baseline, the rest tried on top). found: every
    effect named, over all stages. separating_poses: where the winner and its
    alternatives differ most (empty without alternatives).
    """

    verdict: str
    explanation: str
    model: str
    known_effects: tuple[str, ...]
    noise: NoiseFloor
    split: Split
    baseline: Fit
    baseline_heldout_rmse_deg: float
    baseline_score: float
    baseline_rmse_by_jet_deg: dict[str, float]
    baseline_hysteresis_gap_deg: float | None
    at_floor_threshold_deg: float
    ranking: tuple[CandidateResult, ...]
    alternatives: tuple[str, ...]
    remaining_excess: bool
    online: OnlineEvidence
    signatures_deg: dict[str, np.ndarray]
    baseline_residual_deg: np.ndarray
    held_out_rows: np.ndarray
    held_out_sweep: np.ndarray
    elapsed_s: float
    stages: tuple[Diagnosis, ...] = ()
    found: tuple[FoundEffect, ...] = ()
    separating_poses: tuple[SeparatingPose, ...] = ()
    candidate_fits: dict[str, Fit] = field(default_factory=dict)
    # The setup stage (`setup`): its hypotheses' results, what kind of verdict this is
    # (setup | physics | none | unexplained | undecided) and, for a setup verdict, what to change.
    setup_ranking: tuple[CandidateResult, ...] = ()
    verdict_kind: str = ""
    setup_fix: SetupFix | None = None
    # With verdict "none": converged candidates that fit the training steps decisively
    # better (`DECISIVE_SCORE_GAP`), an effect below what the held-out steps show.
    training_only: tuple[str, ...] = ()
    # Library effects neither known nor among the candidates (`--candidate` narrowed them).
    untried_library: tuple[str, ...] = ()

    @property
    def winner_fit(self) -> Fit | None:
        return self.candidate_fits.get(self.verdict)

    @property
    def noise_floor_deg(self) -> float:
        return self.noise.orientation_deg

    @property
    def final(self) -> Diagnosis:
        """The last stage (this one when there is no later stage)."""
        return self.stages[-1] if self.stages else self

    @property
    def winner(self) -> CandidateResult | None:
        return next((c for c in self.ranking + self.setup_ranking if c.effect == self.verdict), None)

    def as_dict(self) -> dict:
        return {
            "verdict": self.verdict,
            "verdict_kind": self.verdict_kind,
            "setup": {"fix": None if self.setup_fix is None else self.setup_fix.as_dict(),
                      "ranking": [candidate.as_dict() for candidate in self.setup_ranking]},
            "explanation": self.explanation,
            "noise_floor_deg": self.noise_floor_deg,
            "baseline": {
                "heldout_orientation_rmse_deg": self.baseline_heldout_rmse_deg, "score": self.baseline_score,
                "at_floor_threshold_deg": self.at_floor_threshold_deg,
                "parameters": {name: {"value": _number(value), "standard_error": _number(error)}
                               for name, value, error in zip(self.baseline.names, self.baseline.values,
                                                             self.baseline.standard_errors)},
                "converged": self.baseline.converged, "convergence": self.baseline.convergence,
                "rmse_by_jet_deg": self.baseline_rmse_by_jet_deg,
                "online_heldout_orientation_rmse_deg": self.online.online_rmse_deg,
            },
            "ranking": [candidate.as_dict() for candidate in self.ranking],
            "alternatives": list(self.alternatives),
            "training_only": list(self.training_only),
            "untried_library_effects": list(self.untried_library),
            "remaining_excess": self.remaining_excess,
            "effects": [effect.as_dict() for effect in self.found],
            "final_remaining_excess": self.final.remaining_excess,
            "stages": [{"known_effects": list(stage.known_effects), "verdict": stage.verdict,
                        "baseline_heldout_rmse_deg": stage.baseline_heldout_rmse_deg,
                        "alternatives": list(stage.alternatives), "remaining_excess": stage.remaining_excess,
                        "ranking": [candidate.as_dict() for candidate in stage.ranking]} for stage in self.stages],
            "separating_poses": [pose.as_dict() for pose in self.separating_poses],
            "evidence": {
                "loading_unloading": {
                    "baseline_hysteresis_gap_deg": self.baseline_hysteresis_gap_deg,
                    "noise_only_gap_deg": NOISE_GAP_PER_FLOOR * self.noise_floor_deg,
                    "by_candidate_deg": {c.effect: c.hysteresis_gap_deg for c in self.ranking},
                },
                "online_disturbance_correlation": {c.effect: c.online_correlation for c in self.ranking},
                "residual_correlation": {c.effect: c.residual_correlation for c in self.ranking},
                "rmse_by_jet_deg": {"baseline": self.baseline_rmse_by_jet_deg,
                                    **{c.effect: c.rmse_by_jet_deg for c in self.ranking}},
            },
            "noise": self.noise.as_dict(),
            "split": self.split.as_dict(),
            "model": self.model,
            "known_effects": list(self.known_effects),
            "elapsed_s": self.elapsed_s,
        }


def default_candidates(known: Sequence[Effect]) -> tuple[Effect, ...]:
    """Every library effect not already part of the baseline."""
    names = {effect.name for effect in known}
    return tuple(load_effect(name) for name in LIBRARY if name not in names)


def diagnose(steps: Dataset, model_name: str = "cosserat", known_effects: Sequence[Effect] = (),
             candidates: Sequence[Effect] | None = None, *, samples: Dataset | None = None,
             initial: ModelParameters | None = None, settings: DiagnosisSettings = DiagnosisSettings(),
             progress: Callable[[str], None] | None = None) -> Diagnosis:
    """Diagnose a session's quasistatic steps (recorded order) for a missing effect.

    model_name: "cosserat" or "prb". known_effects: effects already in the baseline,
    their parameters calibrated. candidates: effects to try (default: every library
    effect not known). samples: the raw samples, for the within-window noise estimate.
    initial: starting parameters (default: the steps' profile's). Raises UserError for a
    session that cannot be split or whose noise floor cannot be estimated.
    """
    started = time.perf_counter()
    say = progress or (lambda message: None)
    known = tuple(known_effects)
    candidates = default_candidates(known) if candidates is None else tuple(candidates)
    known_names = {effect.name for effect in known}
    clash = [candidate.name for candidate in candidates if candidate.name in known_names]
    if clash:
        raise UserError(f"candidate {clash[0]!r} is already a known effect of the baseline")
    if not candidates:
        raise UserError("no candidate effects to try")
    split = split_session(steps)
    noise = estimate_noise_floor(steps, samples, window_s=settings.window_s)
    say(f"noise floor {noise.orientation_deg:.3f} deg ({noise.method}); {split.description}")
    # Gravity at its nominal weight is always part of the baseline; its weight_scale is a
    # candidate unless it is known.
    gravity = () if "gravity" in known_names else (load_effect("gravity"),)
    position_sigma = noise.position_axis_m
    problem = Problem(
        steps=steps, split=split, gravity_in_base_m_s2=session_gravity(steps), model_name=model_name,
        baseline_effects=gravity + known,
        known_names=tuple(name for effect in known for name in qualified_parameter_names(effect)),
        initial=initial if initial is not None else steps.profile.model_parameters(),
        orientation_sigma_rad=noise.orientation_axis_rad,
        position_weight_rad_per_m=0.0 if not position_sigma else noise.orientation_axis_rad / position_sigma)
    baseline = fit(problem)
    say(f"baseline calibrated ({baseline.convergence})")
    # Setup hypotheses are fitted beside the physics in the first stage and decided first.
    discrete, setups = hypotheses(problem, baseline)
    first = with_setup_stage(_stage(problem, known, noise, baseline, setups + candidates, settings, started, say,
                                    fitted_first=(discrete, fit_discrete(problem, discrete))),
                             steps, lambda errors, best: _significantly_worse(errors, best, settings.significance))
    tried = discrete + setups + candidates
    first = _with_discretization_errors(problem, first, tried)
    stages, current = [], first
    while (current.verdict not in (NONE, UNEXPLAINED, UNDECIDED) and current.remaining_excess
           and len(stages) + 1 < settings.depth):
        winner = next(c for c in tried if c.name == current.verdict)
        added = at_physical_limits(winner) if current.winner.widened else winner
        remaining = tuple(c for c in candidates if c.name != winner.name
                          and all(c.name != name for name in (current.known_effects + (winner.name,))))
        if not remaining:
            break
        problem = _with_known(problem, (added,))
        known = known + (added,)
        say(f"{winner.name} joins the baseline; trying the rest on top of it")
        current = _with_discretization_errors(
            problem, _stage(problem, known, noise, current.winner_fit, remaining, settings, started, say), tried)
        stages.append(current)
    found = _found(first, stages)
    if first.untried_library and first.verdict not in (NONE, UNEXPLAINED, UNDECIDED):
        # A setup hypothesis or a narrow candidate can win only for want of the effect
        # that is there (a jet at 85 % with the jet gains left out: "tracker_tilt").
        first = replace(first, explanation=f"{first.explanation} Only the candidates given were tried: the "
                                           f"library's other effects ({', '.join(first.untried_library)}) may "
                                           "explain the data as well or better.")
    return replace(first, stages=tuple(stages), found=found, elapsed_s=time.perf_counter() - started)


def _with_discretization_errors(problem: Problem, stage: Diagnosis, tried: Sequence[Effect]) -> Diagnosis:
    """``stage`` with its winner's standard errors widened, in quadrature, by the PRB
    chain's discretization error, and the held-out error of its fit on twice the links
    (`fitting.refined_chain`; none for Cosserat)."""
    winner = stage.winner
    if problem.model_name != "prb" or winner is None or not winner.parameters or stage.winner_fit is None:
        return stage
    effect = next(c for c in tried if c.name == winner.effect)
    refined = refined_chain(problem, at_physical_limits(effect) if winner.widened else effect, stage.winner_fit)
    if refined is None:
        return stage
    errors = refined.errors
    widened = {name: (value, float(np.hypot(error, errors.get(name, 0.0))))
               for name, (value, error) in winner.parameters.items()}
    updated = replace(winner, parameters=widened, calibrated={**winner.calibrated, **widened}, discretization=errors,
                      refined_chain=(refined.links, _heldout_rmse_deg(problem, refined.fit)))

    def swap(candidates: tuple[CandidateResult, ...]) -> tuple[CandidateResult, ...]:
        return tuple(updated if candidate is winner else candidate for candidate in candidates)

    return replace(stage, ranking=swap(stage.ranking), setup_ranking=swap(stage.setup_ranking))


def _heldout_rmse_deg(problem: Problem, result: Fit) -> float:
    """Held-out orientation RMSE (deg) of a fit's predictions."""
    held_out = problem.split.held_out
    errors = rotation_angle_deg(result.predictions.tip_orientation_in_base[held_out],
                                problem.steps.tip_orientation_in_base()[held_out])
    return float(np.sqrt(np.mean(errors**2)))


def _with_known(problem: Problem, effects: Sequence[Effect]) -> Problem:
    """``problem`` with ``effects`` (calibrated from now on) in its baseline. An effect
    already there (gravity, always in at its nominal weight) is replaced, not listed twice."""
    by_name = {effect.name: effect for effect in effects}
    baseline = tuple(by_name.pop(effect.name, effect) for effect in problem.baseline_effects)
    names = tuple(name for effect in effects for name in qualified_parameter_names(effect)
                  if name not in problem.known_names)
    return replace(problem, baseline_effects=baseline + tuple(by_name.values()),
                   known_names=problem.known_names + names)


def _stage(problem: Problem, known: Sequence[Effect], noise: NoiseFloor, baseline: Fit,
           candidates: Sequence[Effect], settings: DiagnosisSettings, started: float,
           say: Callable[[str], None], fitted_first: tuple[Sequence[Effect], Sequence[Fit]] = ((), ())) -> Diagnosis:
    """One round: every candidate on top of ``baseline``, and the decision.
    fitted_first: candidates already fitted another way (the discrete setup hypotheses), with
    their fits."""
    fits = fit_candidates(problem, candidates, baseline, settings.workers,
                          progress=lambda done: say(f"fitted {done.effect} ({done.convergence})"))
    online = online_evidence(problem.model(), baseline.params, problem.steps, problem.split.held_out,
                             problem.gravity_in_base_m_s2, settings.online)
    tried = (*fitted_first[0], *candidates)
    decided = _decide(problem, known, noise, baseline, tried, [*fitted_first[1], *fits], online, settings, started)
    if decided.verdict not in (UNEXPLAINED, UNDECIDED):
        return decided
    # Second pass: a candidate whose effect trades off against E, L or w_d may sit in the
    # wrong basin (see `fitting.profile_starts`). Only where nothing explained the excess:
    # a winner that leaves some is followed by the next stage, on top of it.
    say("nothing explains the excess yet: profile scans of the one- and two-parameter candidates")
    fits = refit_candidates(problem, candidates, baseline, fits, settings.workers,
                            progress=lambda done: say(f"refitted {done.effect} ({done.convergence})"))
    return _decide(problem, known, noise, baseline, tried, [*fitted_first[1], *fits], online, settings, started)


def _found(first: Diagnosis, stages: Sequence[Diagnosis]) -> tuple[FoundEffect, ...]:
    """Each stage's winner with its share of the first baseline's excess."""
    excess = first.baseline_heldout_rmse_deg**2 - first.noise_floor_deg**2
    found, before = [], first.baseline_heldout_rmse_deg
    for stage in (first, *stages):
        winner = stage.winner
        if winner is None:
            break
        share = (before**2 - winner.heldout_orientation_rmse_deg**2) / excess if excess > 0.0 else 0.0
        found.append(FoundEffect(winner.effect, float(share), winner.heldout_orientation_rmse_deg,
                                 winner.parameters, winner.notes, winner.refined_chain))
        before = winner.heldout_orientation_rmse_deg
    return tuple(found)


def _decide(problem: Problem, known: Sequence[Effect], noise: NoiseFloor, baseline: Fit, candidates: Sequence[Effect],
            fits: Sequence[Fit], online: OnlineEvidence, settings: DiagnosisSettings, started: float) -> Diagnosis:
    steps, split = problem.steps, problem.split
    considered = {effect.name for effect in (*known, *candidates)}
    untried = tuple(name for name in LIBRARY if name not in considered)
    held_out = split.held_out
    held_steps = steps.select(held_out)
    measured = steps.tip_orientation_in_base()[held_out]
    floor = noise.orientation_deg

    def heldout_errors(result: Fit) -> np.ndarray:
        return rotation_angle_deg(result.predictions.tip_orientation_in_base[held_out], measured)

    def score(result: Fit) -> float:
        return result.training_chi2 + result.parameter_count * float(np.log(max(result.training_rows, 2)))

    base_rmse = _heldout_rmse_deg(problem, baseline)
    base_score = score(baseline)
    base_held = baseline.predictions.select(held_out)
    residual = rotation_between(base_held.tip_orientation_in_base, measured)
    # Prediction mean square = noise x (1 + k / n) for a correct model; F test on top.
    inflation = 1.0 + baseline.parameter_count / max(baseline.training_rows, 1)
    threshold = floor * float(np.sqrt(inflation * f_distribution.ppf(1.0 - settings.significance,
                                                                     3 * int(held_out.sum()), noise.dof)))
    at_floor = base_rmse <= threshold
    # Nothing to explain at the floor: a share of a difference of two noise estimates
    # would be noise itself.
    excess = 0.0 if at_floor else base_rmse**2 - floor**2
    results, signatures = [], {}
    for candidate, result in zip(candidates, fits):
        own = set(qualified_parameter_names(candidate))
        if result.predictions is None:
            results.append(CandidateResult(candidate.name, candidate.explanation, {}, np.inf, -np.inf, np.inf, np.inf,
                                           False, {}, None, 0.0, 0.0, result.evaluations, result.error,
                                           convergence=f"fit failed: {result.error}"))
            continue
        rmse = _heldout_rmse_deg(problem, result)
        held = result.predictions.select(held_out)
        signature = rotation_between(base_held.tip_orientation_in_base, held.tip_orientation_in_base)
        signatures[candidate.name] = np.degrees(signature)
        explained = (base_rmse**2 - rmse**2) / excess if excess > 0.0 else 0.0
        candidate_score = score(result)
        results.append(CandidateResult(
            effect=candidate.name, explanation=candidate.explanation,
            parameters={name: (float(value), float(error)) for name, value, error
                        in zip(result.names, result.values, result.standard_errors) if name in own},
            heldout_orientation_rmse_deg=rmse, explained_fraction=float(explained), score=candidate_score,
            score_change=candidate_score - base_score,
            qualifies=bool(result.converged and explained >= settings.min_explained_fraction
                           and candidate_score < base_score),
            rmse_by_jet_deg=rmse_by_jet(held, held_steps), hysteresis_gap_deg=hysteresis_gap_deg(held, held_steps),
            residual_correlation=cosine(signature, residual),
            online_correlation=cosine(online.equivalent_moment_nm(signature), online.missing_moment_nm),
            evaluations=result.evaluations, converged=result.converged, convergence=result.convergence,
            at_bound=result.at_bound, widened=result.widened,
            calibrated={name: (float(value), float(error))
                        for name, value, error in zip(result.names, result.values, result.standard_errors)}))
    ranking = tuple(sorted(results, key=lambda c: (c.error is not None, not c.converged, not c.qualifies, c.score)))
    qualifying = [c for c in ranking if c.qualifies]
    alternatives: tuple[str, ...] = ()
    remaining = False
    # An unconverged baseline at the floor is `_undecided`'s: its parameters are no optimum
    # (a soft rod folding over under a heavy capsule showed the floor with them, and 63 deg
    # on another path).
    training_only: tuple[str, ...] = ()
    if at_floor and baseline.converged:
        verdict = NONE
        floor_text = (f"The baseline's held-out error ({base_rmse:.3f} deg) is at the noise floor "
                      f"({floor:.3f} deg; at most {threshold:.3f} deg is noise at the "
                      f"{settings.significance:.0%} level)")
        # The held-out test cannot see an effect below the floor; the training steps can
        # (a clamp compliance of 10 rad/N m on a tilted rig: score 115 lower, 11 standard
        # errors from none, and E biased by 8 % without it).
        training_only = tuple(c.effect for c in ranking if c.converged and c.error is None
                              and c.score_change < -DECISIVE_SCORE_GAP)
        if training_only:
            changes = ", ".join(f"{c.effect} {c.score_change:+.0f}" for c in ranking if c.effect in training_only[:3])
            if len(training_only) > 3:
                changes += f" (and {len(training_only) - 3} more)"
            explanation = (f"{floor_text}: the held-out steps show no missing effect. But the training steps "
                           f"do: {changes} in score (more than {DECISIVE_SCORE_GAP:g} lower is decisive), so an "
                           "effect too small to show in the held-out steps is likely there and biases the "
                           "calibrated values; its fitted values are in the ranking (more steps, or larger "
                           "loads, would tell which).")
        else:
            explanation = f"{floor_text}: no effect is missing that these data can show."
    elif (undecided := _undecided(baseline, ranking, threshold, settings)) is not None:
        verdict, explanation = UNDECIDED, undecided
    elif not qualifying:
        verdict = UNEXPLAINED
        remaining = True
        best = ranking[0]
        above = (f"The baseline's held-out error ({base_rmse:.3f} deg) is above the noise floor "
                 f"({floor:.3f} deg), but no")
        best_text = f"(best: {best.effect}, {best.explained_fraction:.0%})"
        if untried:
            explanation = (f"{above}ne of the effects tried removes half of the excess {best_text}. The library's "
                           f"other effects were not among the candidates ({', '.join(untried)}): try them before "
                           "writing an effect file.")
        else:
            explanation = (f"{above} library effect removes half of the excess {best_text}. The missing physics is "
                           "outside the library: look at the residuals and the online disturbance estimate, and "
                           "write it as an effect file.")
    else:
        winner = qualifying[0]
        verdict = winner.effect
        by_name = dict(zip((c.name for c in candidates), fits))
        winner_errors = heldout_errors(by_name[winner.effect])
        alternatives = tuple(c.effect for c in qualifying[1:]
                             if not _significantly_worse(heldout_errors(by_name[c.effect]), winner_errors,
                                                         settings.significance))
        remaining = winner.heldout_orientation_rmse_deg > threshold
        explanation = winner.explanation
    return Diagnosis(
        verdict=verdict, explanation=explanation, model=problem.model_name,
        known_effects=tuple(effect.name for effect in known),
        noise=noise, split=split, baseline=baseline, baseline_heldout_rmse_deg=base_rmse,
        baseline_score=base_score, baseline_rmse_by_jet_deg=rmse_by_jet(base_held, held_steps),
        baseline_hysteresis_gap_deg=hysteresis_gap_deg(base_held, held_steps), at_floor_threshold_deg=threshold,
        ranking=ranking, alternatives=alternatives, remaining_excess=remaining, online=online,
        training_only=training_only, untried_library=untried,
        signatures_deg=signatures, baseline_residual_deg=np.degrees(residual), held_out_rows=np.flatnonzero(held_out),
        held_out_sweep=steps.sweep[held_out], elapsed_s=time.perf_counter() - started,
        separating_poses=(_separating(problem, candidates, fits, (verdict, *alternatives), floor)
                          if alternatives else ()),
        candidate_fits={candidate.name: result for candidate, result in zip(candidates, fits)})


def _undecided(baseline: Fit, ranking: Sequence[CandidateResult], threshold_deg: float,
               settings: DiagnosisSettings) -> str | None:
    """Why unconverged fits leave the question open (see the module docstring), or None.
    A qualifying candidate that brings the held-out error down to the floor
    (``threshold_deg``) needs no baseline to be measured against."""
    qualifying = [c for c in ranking if c.qualifies]
    if not baseline.converged and not any(c.heldout_orientation_rmse_deg <= threshold_deg for c in qualifying):
        return (f"The baseline's fit is {baseline.convergence}, so no candidate can be measured against it: "
                "undecided. Check the profile's rod, capsule and mounting against the rig (a soft rod "
                "folding over, a wrong capsule mass): calibrate shows how far a fit gets from them.")
    if qualifying:
        return None
    fitted = [c for c in ranking if c.error is None]
    if fitted and not any(c.converged for c in fitted):
        return (f"None of the {len(fitted)} candidates' fits converged, so none can be judged: undecided. Check "
                "the profile's rod, capsule and mounting against the rig.")
    promising = next((c for c in fitted if not c.converged and c.score_change < 0.0
                      and c.explained_fraction >= settings.min_explained_fraction), None)
    if promising is None:
        return None
    return (f"No converged fit explains the excess, but {promising.effect} would remove "
            f"{promising.explained_fraction:.0%} of it were its fit to be believed ({promising.convergence}): "
            "undecided. Try it alone (--candidate) or record more poses.")


def _significantly_worse(errors_deg: np.ndarray, best_errors_deg: np.ndarray, significance: float) -> bool:
    """One-sided paired t test on the held-out steps' squared errors: are ``errors_deg``
    larger than ``best_errors_deg`` beyond what noise gives at ``significance``?"""
    difference = errors_deg**2 - best_errors_deg**2
    spread = float(np.std(difference, ddof=1))
    if spread == 0.0:
        return bool(np.mean(difference) > 0.0)
    statistic = float(np.mean(difference)) / (spread / np.sqrt(len(difference)))
    return statistic > float(t_distribution.ppf(1.0 - significance, len(difference) - 1))


def _separating(problem: Problem, candidates: Sequence[Effect], fits: Sequence[Fit], names: Sequence[str],
                floor_deg: float) -> tuple[SeparatingPose, ...]:
    """Where the tied candidates' calibrated models differ most, by more than the floor."""
    models = []
    for candidate, result in zip(candidates, fits):
        if candidate.name in names and result.params is not None:
            effect = at_physical_limits(candidate) if result.widened else candidate
            models.append((candidate.name, problem.model(effect), result.params))
    return separating_poses(models, problem.steps.profile.max_jet_force_n,
                            problem.gravity_in_base_m_s2.mean(axis=0), floor_deg)


def _chain_document(refined_chain: tuple[int, float] | None) -> dict | None:
    """`CandidateResult.refined_chain` in the JSON."""
    if refined_chain is None:
        return None
    links, rmse_deg = refined_chain
    return {"links": links, "heldout_orientation_rmse_deg": _number(rmse_deg)}


def _number(value: float) -> float | None:
    """JSON has no infinity or NaN: None stands for a failed fit's figures."""
    return float(value) if np.isfinite(value) else None
