"""The setup stage of `diagnose`: is the rig wired or described wrongly?

The hypotheses (`effects.setup`: five wrong jet wirings, the jet forces' sign reversed,
four force unit mistakes, a tracker tilt, a base sensor mounting; a discrete one only
when it beats the stated rig at the baseline, see `hypotheses`)
are fitted and scored exactly as the physical candidates, then taken out of the physics
ranking into their own. They are tried first: the best qualifying setup hypothesis
takes the verdict unless a physical candidate is significantly better on the held-out
steps (the one-sided paired t test on their squared errors that decides the physical
candidates' ties), or scores decisively better (`DECISIVE_SCORE_GAP`) and predicts them
no worse; candidates not significantly worse than the winner, setup or
physics, are listed as alternatives, with the measurement that tells a setup error
from the physics it ties with.

A setup verdict says what to change: the profile key and its corrected value (written
by ``diagnose --export-profile``), or which valve cables to swap.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from ...data.dataset import Dataset
from ...effects.setup import (BaseSensorMounting, JetForceSign, JetForceUnit, TrackerTilt, setup_effects,
                              tilt_rotation)
from ...geometry import matrix_from_quat, quat_from_matrix, quat_multiply, rotation_angle_deg, so3_exp
from .fitting import Fit, Problem, fit, training_cost

SETUP, PHYSICS = "setup", "physics"
# What separates a setup error from the physics it ties with: shown beside the tie.
SEPARATING_MEASUREMENT = {
    "tracker_tilt": "hold the jets off and compare the base IMU's gravity with the profile's (run's level check)",
    "base_sensor_mounting": "remount the base sensor turned a known angle in the clamp and diagnose again: a "
                            "base sensor error changes by that angle, a physical effect (a turned jet ring or "
                            "tip sensor) does not",
    "jet_wiring": "fire each jet alone and watch which side the tip moves to (run's wiring check)",
    "jet_force_sign": "fire each jet alone and watch which side the tip moves to (run's wiring check)",
    "jet_force_unit": "measure one jet's force at a known duty with a force gauge and compare it with the valve "
                      "calibration table",
}


@dataclass(frozen=True)
class SetupFix:
    """What to change for a setup verdict. profile_key/corrected_value: the TOML key
    (``table.key``) and its new value (None when the fix is a cable, not the profile).
    action: one line for the user."""

    hypothesis: str
    action: str
    profile_key: str | None = None
    corrected_value: tuple[float, ...] | float | None = None

    def as_dict(self) -> dict:
        value = self.corrected_value
        return {"hypothesis": self.hypothesis, "action": self.action, "profile_key": self.profile_key,
                "corrected_value": list(value) if isinstance(value, tuple) else value}

    def value_text(self) -> str:
        """The corrected value as TOML (a number, or an array)."""
        value = self.corrected_value
        if isinstance(value, tuple):
            return f"[{', '.join(repr(float(v)) for v in value)}]"
        return repr(float(value))  # type: ignore[arg-type]


def hypotheses(problem: Problem, baseline: Fit) -> tuple[tuple, tuple]:
    """The setup hypotheses worth a fit, as (discrete, others): the tilt and the base
    mounting always; a discrete one (a wrong wiring, the reversed force sign, a force
    unit: no parameter to fit) only when, at the initial (profile) parameters, it fits
    the training steps better than the calibrated baseline does (a wrong permutation or
    unit of a correctly set-up rig is tens of degrees off, and nine fits of them would
    double diagnose's time)."""
    discrete, others = [], []
    for effect in setup_effects(problem.steps.profile.base_sensor.offset_in_body_m):
        if effect.parameters:
            others.append(effect)
            continue
        # Along the solved prefix only: the held-out steps after it do not count here.
        if training_cost(problem, problem.model(effect), problem.initial,
                         stop_above=baseline.training_chi2) < baseline.training_chi2:
            discrete.append(effect)
    return tuple(discrete), tuple(others)


def fit_discrete(problem: Problem, discrete: tuple) -> list[Fit]:
    """Fit each discrete hypothesis from the initial parameters: the baseline's optimum
    on miswired data is a rod bent to fit the wrong jets, a bad start (solves fail from
    there)."""
    return [fit(problem, hypothesis, start=problem.initial) for hypothesis in discrete]


def is_setup(name: str) -> bool:
    return name in {effect.name for effect in setup_effects()}


def wiring_action(wiring: tuple[int, ...]) -> str:
    wrong = [(i + 1, j) for i, j in enumerate(wiring) if j != i + 1]
    if len(wrong) == 2:
        return f"swap the valve cables of jets {wrong[0][0]} and {wrong[1][0]}"
    moves = ", ".join(f"the cable on jet {j} to jet {i}" for i, j in wrong)
    return f"the jets are wired one position round: move {moves}"


def setup_fix(name: str, parameters: dict[str, tuple[float, float]], steps: Dataset) -> SetupFix:
    """The fix a fitted setup hypothesis names (parameters: qualified name -> (value, se))."""
    values = {key.partition(".")[2]: value for key, (value, _) in parameters.items()}
    profile = steps.profile
    if name.startswith("jet_wiring_"):
        wiring = tuple(int(c) for c in name.removeprefix("jet_wiring_"))
        return SetupFix(name, wiring_action(wiring))
    if name == JetForceSign.name:
        # A half turn of the ring reverses every jet's (tip-plane) force exactly.
        ring = (profile.config.jets.ring_angle_deg + 180.0 + 180.0) % 360.0 - 180.0
        return SetupFix(name, "the jets pull where the profile's convention has them push: check which way the "
                              "nozzles point, or set "
                              f"jets.ring_angle_deg = {ring:g} (a half turn of the ring reverses every jet)",
                        "jets.ring_angle_deg", round(ring, 6))
    unit = next((effect for effect in setup_effects() if isinstance(effect, JetForceUnit) and effect.name == name),
                None)
    if unit is not None:
        return SetupFix(name, f"the jets push {unit.ratio:.4g} times the force commanded: the valve calibration's "
                              f"forces (valves.calibration force_n, or jets.max_force_n without tables) look like "
                              f"{unit.mistake}; multiply them by {unit.ratio:.6g}")
    if name == TrackerTilt.name:
        gravity_in_base = steps.gravity_in_base_m_s2().mean(axis=0)
        turned = tilt_rotation(gravity_in_base, values["about_u_rad"], values["about_v_rad"]) @ gravity_in_base
        # The base is static in a session diagnose can split (see fitting.session_gravity).
        clamps = profile.clamp_orientation_in_tracker(steps.base_orientation)
        clamp_q = (clamps * np.sign(clamps @ clamps[0])[:, None]).mean(axis=0)  # q and -q are one rotation
        clamp = matrix_from_quat(clamp_q / np.linalg.norm(clamp_q))
        corrected = tuple(round(float(v), 4) for v in clamp @ turned)
        angle = float(np.degrees(np.hypot(values["about_u_rad"], values["about_v_rad"])))
        return SetupFix(name, f"gravity in the tracker frame is {angle:.1f} deg off the profile's: level the field "
                              f"generator, or set gravity.in_tracker_m_s2 = {list(corrected)}",
                        "gravity.in_tracker_m_s2", corrected)
    if name == BaseSensorMounting.name:
        rotation = so3_exp([values["rx_rad"], values["ry_rad"], values["rz_rad"]])
        corrected_q = quat_multiply(quat_from_matrix(rotation), np.asarray(profile.base_sensor.rotation_in_body))
        corrected = tuple(round(float(v), 6) for v in corrected_q * np.sign(corrected_q[0] or 1.0))
        angle = float(np.degrees(np.linalg.norm([values["rx_rad"], values["ry_rad"], values["rz_rad"]])))
        return SetupFix(name, f"the base sensor sits {angle:.1f} deg turned in the clamp: set "
                              f"base_sensor.rotation_in_base = {list(corrected)}", "base_sensor.rotation_in_base", corrected)
    raise ValueError(f"{name!r} is no setup hypothesis")


def setup_hypothesis(errors) -> str:
    """The hypothesis a perfect diagnosis names for a twin's `SetupErrors` with one error."""
    if errors.jet_wiring != (1, 2, 3):
        return "jet_wiring_" + "".join(str(j) for j in errors.jet_wiring)
    if errors.jet_force_sign != 1:
        return JetForceSign.name
    if errors.jet_force_scale != 1.0:
        # The unit mistake whose ratio this is (a scale that is none is no setup hypothesis).
        units = [effect for effect in setup_effects() if isinstance(effect, JetForceUnit)]
        nearest = min(units, key=lambda unit: abs(np.log(unit.ratio / errors.jet_force_scale)))
        return nearest.name if abs(np.log(nearest.ratio / errors.jet_force_scale)) < 0.02 else "unexplained"
    if errors.tracker_tilt_deg != (0.0, 0.0):
        return TrackerTilt.name
    return BaseSensorMounting.name


def separating_measurement(name: str) -> str:
    return SEPARATING_MEASUREMENT[next((family for family in ("jet_wiring", "jet_force_unit")
                                        if name.startswith(family + "_")), name)]


def heldout_errors_deg(diagnosis, steps: Dataset) -> dict[str, np.ndarray]:
    """Each fitted candidate's orientation error (deg) on the held-out steps."""
    rows = diagnosis.held_out_rows
    measured = steps.tip_orientation_in_base()[rows]
    return {name: rotation_angle_deg(result.predictions.tip_orientation_in_base[rows], measured)
            for name, result in diagnosis.candidate_fits.items() if result.predictions is not None}


# A score (BIC) lower by more than this is "very strong" evidence (Kass and Raftery).
DECISIVE_SCORE_GAP = 10.0


def _physics_better(physics, setup, errors: dict[str, np.ndarray],
                    significantly_worse: Callable[[np.ndarray, np.ndarray], bool]) -> bool:
    """Whether a physical candidate beats the setup hypothesis that would otherwise win:
    significantly better held out, or a decisively better score and no worse held out.
    A tip sensor turned 0.015 rad scored 142 better than a turned base sensor and
    predicted the held-out steps better (0.162 against 0.173 deg), within the paired
    test's noise: the verdict was the base sensor, and its Fix would have turned a right
    profile wrong."""
    if significantly_worse(errors[setup.effect], errors[physics.effect]):
        return True
    return (physics.score < setup.score - DECISIVE_SCORE_GAP
            and physics.heldout_orientation_rmse_deg <= setup.heldout_orientation_rmse_deg)


def with_setup_stage(diagnosis, steps: Dataset, significantly_worse: Callable[[np.ndarray, np.ndarray], bool]):
    """``diagnosis`` (ranked over physics and setup hypotheses together) with the setup
    hypotheses moved to ``setup_ranking`` and the verdict decided setup first.

    significantly_worse(errors, best_errors): the held-out paired test the physical
    candidates' ties use (held-out errors in deg, per step). The best qualifying setup
    hypothesis wins unless the best qualifying physical candidate is better than it
    (`_physics_better`); every qualifying candidate not significantly worse than the
    winner is an alternative, and a tie across setup and physics names what separates
    them."""
    setup_ranking = tuple(c for c in diagnosis.ranking if is_setup(c.effect))
    physics = tuple(c for c in diagnosis.ranking if not is_setup(c.effect))
    if diagnosis.verdict in ("none", "unexplained", "undecided"):
        return replace(diagnosis, ranking=physics, setup_ranking=setup_ranking, verdict_kind=diagnosis.verdict)
    errors = heldout_errors_deg(diagnosis, steps)
    qualifying = sorted((c for c in diagnosis.ranking if c.qualifies), key=lambda c: c.score)
    best_setup = next((c for c in qualifying if is_setup(c.effect)), None)
    best_physics = next((c for c in qualifying if not is_setup(c.effect)), None)
    if best_setup is not None and (best_physics is None or not _physics_better(best_physics, best_setup, errors,
                                                                               significantly_worse)):
        winner, kind = best_setup, SETUP
    else:
        winner, kind = best_physics, PHYSICS
    alternatives = tuple(c.effect for c in qualifying if c is not winner
                         and not significantly_worse(errors[c.effect], errors[winner.effect]))
    fix = setup_fix(winner.effect, winner.parameters, steps) if kind == SETUP else None
    explanation = winner.explanation
    if fix is not None:
        explanation += f"\nFix: {fix.action}."
    for name in alternatives:
        if is_setup(name) != is_setup(winner.effect):
            explanation += (f"\n{name} explains the data as well; to tell them apart: "
                            f"{separating_measurement(winner.effect if kind == SETUP else name)}.")
    remaining = winner.heldout_orientation_rmse_deg > diagnosis.at_floor_threshold_deg
    return replace(diagnosis, verdict=winner.effect, explanation=explanation, ranking=physics,
                   setup_ranking=setup_ranking, alternatives=alternatives, remaining_excess=remaining,
                   verdict_kind=kind, setup_fix=fix)


__all__ = ["PHYSICS", "SETUP", "SetupFix", "corrected_profile_text", "fit_discrete", "heldout_errors_deg", "hypotheses", "is_setup", "setup_fix", "setup_hypothesis", "with_setup_stage"]


def corrected_profile_text(text: str, fix: SetupFix) -> str:
    """The profile's TOML text with the fix's key set to its corrected value (the line
    replaced in its table, else added to the table, else the table appended)."""
    if fix.profile_key is None or fix.corrected_value is None:
        raise ValueError(f"{fix.hypothesis}: the fix is at the rig, not in the profile")
    table, _, key = fix.profile_key.partition(".")
    line = f"{key} = {fix.value_text()}  # corrected by diagnose"
    lines = text.splitlines()
    header = next((i for i, row in enumerate(lines) if row.strip() == f"[{table}]"), None)
    if header is None:
        return text.rstrip("\n") + f"\n\n[{table}]\n{line}\n"
    end = next((i for i in range(header + 1, len(lines)) if lines[i].lstrip().startswith("[")), len(lines))
    for i in range(header + 1, end):
        if re.match(rf"\s*{re.escape(key)}\s*=", lines[i]):
            lines[i] = line
            break
    else:
        lines.insert(header + 1, line)
    return "\n".join(lines) + "\n"
