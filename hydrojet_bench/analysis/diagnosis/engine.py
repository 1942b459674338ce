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
   * otherwise the candidate with the best score among those that remove at least
     half of the EXCESS squared error (``explained_fraction`` = (baseline^2 -
     candidate^2) / (baseline^2 - floor^2), on held-out RMSEs) and beat the baseline's
     score; ``unexplained`` when none does.

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
reported as hard to tell apart.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import f as f_distribution

from ...data.dataset import Dataset
from ...effects import LIBRARY, Effect, load_effect, qualified_parameter_names
from ...errors import UserError
from ...estimation.online import OnlineSettings
from ...geometry import rotation_angle_deg
from ...params import ModelParameters
from .evidence import (NOISE_GAP_PER_FLOOR, OnlineEvidence, cosine, hysteresis_gap_deg, online_evidence,
                       rmse_by_jet, rotation_between)
from .fitting import Fit, Problem, fit, fit_candidates, session_gravity
from .noise import NoiseFloor, estimate_noise_floor
from .setup import SetupFix, fit_wirings, hypotheses, with_setup_stage
from .split import Split, split_session

NONE, UNEXPLAINED = "none", "unexplained"
# Kass and Raftery (1995): a BIC difference above 10 is very strong evidence.
AMBIGUITY_SCORE = 10.0


@dataclass(frozen=True)
class DiagnosisSettings:
    """significance: level of the at-the-floor F test. min_explained_fraction: share of
    the excess squared held-out error a winner must remove. workers: processes for the
    candidate fits (None: up to 2). online: the estimator used for the evidence.
    window_s: averaging window of the steps (for the within-window noise estimate)."""

    significance: float = 0.01
    min_explained_fraction: float = 0.5
    workers: int | None = None
    online: OnlineSettings = field(default_factory=OnlineSettings)
    window_s: float = 1.0


@dataclass(frozen=True)
class CandidateResult:
    """One candidate: its fitted parameters (name -> (value, standard error)), held-out
    orientation RMSE (deg), explained_fraction (0 when the baseline is already at the
    floor: nothing to explain), score (BIC, lower is better) and its
    difference to the baseline's, whether it passes both tests (``qualifies``), and the
    evidence: held-out RMSE per driving jet, hysteresis gap of its residuals (deg),
    cosine of its signature with the baseline residual and with the online
    disturbance estimate. error: why its fit failed, if it did."""

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

    def as_dict(self) -> dict:
        return {
            "effect": self.effect, "heldout_orientation_rmse_deg": _number(self.heldout_orientation_rmse_deg),
            "explained_fraction": _number(self.explained_fraction), "score": _number(self.score),
            "score_change": _number(self.score_change), "qualifies": self.qualifies,
            "parameters": {name: {"value": _number(value), "standard_error": _number(error)}
                           for name, (value, error) in self.parameters.items()},
            "rmse_by_jet_deg": self.rmse_by_jet_deg, "hysteresis_gap_deg": self.hysteresis_gap_deg,
            "residual_correlation": self.residual_correlation, "online_correlation": self.online_correlation,
            "evaluations": self.evaluations, "error": self.error,
        }


@dataclass(frozen=True)
class Diagnosis:
    """The outcome of `diagnose`; see the module docstring for the rules.

    verdict: "none", "unexplained" or the winning effect's name. explanation: the
    winner's physics in words (or why there is none). ranking: the qualifying candidates
    by score (the winner first), then the others by score, then failed fits. alternatives: qualifying candidates within
    `AMBIGUITY_SCORE` of the winner. at_floor_threshold_deg: the largest held-out RMSE
    the F test calls "at the floor". remaining_excess: whether the winner still leaves
    a held-out error above that threshold (more physics missing).
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
    # The setup stage (`setup`): its hypotheses' results, what kind of verdict this is
    # (setup | physics | none | unexplained) and, for a setup verdict, what to change.
    setup_ranking: tuple[CandidateResult, ...] = ()
    verdict_kind: str = ""
    setup_fix: SetupFix | None = None

    @property
    def noise_floor_deg(self) -> float:
        return self.noise.orientation_deg

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
                "rmse_by_jet_deg": self.baseline_rmse_by_jet_deg,
                "online_heldout_orientation_rmse_deg": self.online.online_rmse_deg,
            },
            "ranking": [candidate.as_dict() for candidate in self.ranking],
            "alternatives": list(self.alternatives),
            "remaining_excess": self.remaining_excess,
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
    say(f"baseline calibrated ({baseline.evaluations} evaluations)")
    # Setup hypotheses are tried with the physics and decided first (`setup`).
    wirings, setups = hypotheses(problem, baseline)
    fits = fit_wirings(problem, wirings) + fit_candidates(problem, setups + candidates, baseline, settings.workers,
                                                          progress=lambda done: say(f"fitted {done.effect}"))
    candidates = wirings + setups + candidates
    online = online_evidence(problem.model(), baseline.params, steps, split.held_out, problem.gravity_in_base_m_s2,
                             settings.online)
    diagnosis = _decide(problem, known, noise, baseline, candidates, fits, online, settings, started)
    return with_setup_stage(diagnosis, steps, AMBIGUITY_SCORE)


def _decide(problem: Problem, known: Sequence[Effect], noise: NoiseFloor, baseline: Fit, candidates: Sequence[Effect],
            fits: Sequence[Fit], online: OnlineEvidence, settings: DiagnosisSettings, started: float) -> Diagnosis:
    steps, split = problem.steps, problem.split
    held_out = split.held_out
    held_steps = steps.select(held_out)
    measured = steps.tip_orientation_in_base()[held_out]
    floor = noise.orientation_deg

    def heldout_rmse(result: Fit) -> float:
        errors = rotation_angle_deg(result.predictions.tip_orientation_in_base[held_out], measured)
        return float(np.sqrt(np.mean(errors**2)))

    def score(result: Fit) -> float:
        return result.training_chi2 + result.parameter_count * float(np.log(max(result.training_rows, 2)))

    base_rmse = heldout_rmse(baseline)
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
                                           False, {}, None, 0.0, 0.0, result.evaluations, result.error))
            continue
        rmse = heldout_rmse(result)
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
            qualifies=bool(explained >= settings.min_explained_fraction and candidate_score < base_score),
            rmse_by_jet_deg=rmse_by_jet(held, held_steps), hysteresis_gap_deg=hysteresis_gap_deg(held, held_steps),
            residual_correlation=cosine(signature, residual),
            online_correlation=cosine(online.equivalent_moment_nm(signature), online.missing_moment_nm),
            evaluations=result.evaluations))
    ranking = tuple(sorted(results, key=lambda c: (c.error is not None, not c.qualifies, c.score)))
    qualifying = [c for c in ranking if c.qualifies]
    alternatives: tuple[str, ...] = ()
    remaining = False
    if at_floor:
        verdict = NONE
        explanation = (f"The baseline's held-out error ({base_rmse:.3f} deg) is at the noise floor "
                       f"({floor:.3f} deg; at most {threshold:.3f} deg is noise at the "
                       f"{settings.significance:.0%} level): no effect is missing that these data can show.")
    elif not qualifying:
        verdict = UNEXPLAINED
        best = ranking[0]
        explanation = (f"The baseline's held-out error ({base_rmse:.3f} deg) is above the noise floor "
                       f"({floor:.3f} deg), but no library effect removes half of the excess (best: {best.effect}, "
                       f"{best.explained_fraction:.0%}). The missing physics is outside the library: look at the "
                       "residuals and the online disturbance estimate, and write it as an effect file.")
    else:
        winner = qualifying[0]
        verdict = winner.effect
        alternatives = tuple(c.effect for c in qualifying[1:] if c.score - winner.score < AMBIGUITY_SCORE)
        remaining = winner.heldout_orientation_rmse_deg > threshold
        explanation = winner.explanation
    return Diagnosis(
        verdict=verdict, explanation=explanation, model=problem.model_name,
        known_effects=tuple(effect.name for effect in known),
        noise=noise, split=split, baseline=baseline, baseline_heldout_rmse_deg=base_rmse,
        baseline_score=base_score, baseline_rmse_by_jet_deg=rmse_by_jet(base_held, held_steps),
        baseline_hysteresis_gap_deg=hysteresis_gap_deg(base_held, held_steps), at_floor_threshold_deg=threshold,
        ranking=ranking, alternatives=alternatives, remaining_excess=remaining, online=online,
        signatures_deg=signatures, baseline_residual_deg=np.degrees(residual), held_out_rows=np.flatnonzero(held_out),
        held_out_sweep=steps.sweep[held_out], elapsed_s=time.perf_counter() - started)


def _number(value: float) -> float | None:
    """JSON has no infinity or NaN: None stands for a failed fit's figures."""
    return float(value) if np.isfinite(value) else None
