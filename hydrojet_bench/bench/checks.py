"""Checks run before a protocol: is the rig wired and described as the profile says?

Wiring check: each jet fired alone at a small force; the tip's measured bending (the
rotation vector of R_fired R_rest^T, base frame) is compared with the bending the model
predicts for each jet. Jets sit 120 degrees apart, so the predicted directions of two
different jets have a cosine near -0.5 and the right one near 1: the jet whose
predicted direction the tip followed is the one the cable drives. Anything but
(1, 2, 3) stops the session, with one line naming the jets; every jet bending the tip
against its own prediction names reversed jet forces instead.

Level check: at rest the base IMU's accelerometer reads the specific force -g in its
own frame; carried into the clamp frame by the profile's base mounting it is gravity as
the rig has it, while the profile's gravity (tracker frame) carried through the EM
tracker's base pose is gravity as the model will have it. A difference above
``level_limit_deg`` warns: a field generator that is not level, or a wrong ``[gravity]``.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import numpy as np

from ..data.dataset import Dataset
from ..geometry import matrix_from_quat, so3_log
from ..models.shooting import ShootingModel
from ..params import JET_COUNT, ModelParameters
from ..profile import RigProfile

WIRING, LEVEL = "wiring", "level"


@dataclass(frozen=True)
class CheckSettings:
    """force_n: each jet's force in the wiring check, N (small: a few degrees of bend).
    settle_s / window_s: hold of each check command and the averaged end of it, session s.
    min_cosine: the least cosine between measured and predicted bending that counts as
    "towards that jet" (neighbouring jets are at -0.5). min_bend_deg: a jet that bends
    the tip less than this did not fire. level_limit_deg: the level check's tolerance."""

    force_n: float = 0.01
    settle_s: float = 2.0
    window_s: float = 1.0
    min_cosine: float = 0.5
    min_bend_deg: float = 0.5
    level_limit_deg: float = 2.0


@dataclass(frozen=True)
class CheckResult:
    """One check's outcome. status: "pass", "fail" (stops the session), "warn".
    message: one line for the user. values: the figures behind it (logged)."""

    check: str
    status: str  # "pass", "fail", "warn" or "unavailable" (the sensors it needs are missing)
    message: str
    values: dict[str, float]

    @property
    def failed(self) -> bool:
        return self.status == "fail"


def predicted_bending_rad(model: ShootingModel, params: ModelParameters, force_n: float) -> np.ndarray:
    """(3, 3): row j is the model's tip bending (rotation vector, base frame, rad) when
    jet j+1 alone pushes ``force_n``, from rest."""
    rest = model.solve(np.zeros(JET_COUNT), params).tip_rotation_in_base
    rows = []
    for jet in range(JET_COUNT):
        forces = np.zeros(JET_COUNT)
        forces[jet] = force_n
        fired = model.solve(forces, params).tip_rotation_in_base
        rows.append(so3_log(fired @ rest.T))
    return np.array(rows)


def measured_bending_rad(rest_tip_in_base: np.ndarray, fired_tip_in_base: np.ndarray) -> np.ndarray:
    """(3, 3) measured tip bending per jet (rotation vectors, base frame, rad) from the
    settled tip orientation in the base frame at rest (4,) and with each jet alone (3, 4)."""
    rest = matrix_from_quat(rest_tip_in_base)
    return np.array([so3_log(matrix_from_quat(q) @ rest.T) for q in fired_tip_in_base])


def check_wiring(measured_rad: np.ndarray, predicted_rad: np.ndarray,
                 settings: CheckSettings = CheckSettings()) -> CheckResult:
    """Compare measured and predicted bending per jet (see the module docstring)."""
    bends_deg = np.degrees(np.linalg.norm(measured_rad, axis=1))
    unit_measured = measured_rad / np.maximum(np.linalg.norm(measured_rad, axis=1, keepdims=True), 1e-12)
    unit_predicted = predicted_rad / np.maximum(np.linalg.norm(predicted_rad, axis=1, keepdims=True), 1e-12)
    cosines = unit_measured @ unit_predicted.T  # [fired cable, predicted jet]
    values = {f"bend_jet{i + 1}_deg": float(b) for i, b in enumerate(bends_deg)}
    values.update({f"cos_cable{i + 1}_jet{k + 1}": float(cosines[i, k])
                   for i in range(JET_COUNT) for k in range(JET_COUNT)})
    still = [i + 1 for i in range(JET_COUNT) if bends_deg[i] < settings.min_bend_deg]
    if still:
        jets = " and ".join(str(j) for j in still)
        return CheckResult(WIRING, "fail", f"jet {jets} did not move the tip (less than {settings.min_bend_deg:g} "
                           f"deg when fired alone at {settings.force_n:g} N): valve, cable or jet not working", values)
    # Every jet bending the tip the opposite way to its own prediction (a wrong wiring
    # leaves a cosine of -0.5 at most): the forces' sign, not the cables.
    if np.all(np.diag(cosines) <= -(1.0 + settings.min_cosine) / 2.0):
        return CheckResult(WIRING, "fail", "every jet bent the tip the opposite way to the model's: the jet forces' "
                           "sign is reversed (the jets pull where the profile has them push); check which way the "
                           "nozzles point, or the profile's jets.ring_angle_deg", values)
    followed = [int(np.argmax(row)) + 1 if row.max() >= settings.min_cosine else 0 for row in cosines]
    values.update({f"cable{i + 1}_drives_jet": float(j) for i, j in enumerate(followed)})
    if followed == list(range(1, JET_COUNT + 1)):
        return CheckResult(WIRING, "pass", "wiring check passed: each jet bent the tip its own way", values)
    return CheckResult(WIRING, "fail", wiring_message(followed), values)


def wiring_message(followed: list[int]) -> str:
    """One line naming the miswired jets; ``followed[i]`` is the jet whose side the tip
    moved towards when jet i+1 fired (0: none)."""
    lost = [i + 1 for i, j in enumerate(followed) if j == 0]
    if lost:
        return (f"jet {lost[0]}: the tip moved towards no jet's side when it fired (check its valve cable "
                "and the jet ring angle in the profile)")
    wrong = [(i + 1, j) for i, j in enumerate(followed) if j != i + 1]
    if sorted(followed) != list(range(1, JET_COUNT + 1)):
        fired, towards = wrong[0]
        return f"jets miswired: tip moved towards jet {towards}'s side when jet {fired} fired"
    if len(wrong) == 2:
        (a, b), _ = wrong
        return f"jets {a} and {b} appear swapped: tip moved towards jet {b}'s side when jet {a} fired"
    moves = ", ".join(f"jet {i} towards jet {j}" for i, j in wrong)
    return f"jets wired one position round ({moves}): move each valve cable to the jet its tip motion named"


def check_level(accel_in_clamp_m_s2: np.ndarray, gravity_in_clamp_m_s2: np.ndarray,
                settings: CheckSettings = CheckSettings()) -> CheckResult:
    """Compare gravity from the base IMU (``-accel``, clamp frame, m/s^2, at rest) with
    the profile's gravity carried through the tracker's base pose (clamp frame, m/s^2)."""
    measured = -np.asarray(accel_in_clamp_m_s2, dtype=float)
    expected = np.asarray(gravity_in_clamp_m_s2, dtype=float)
    cosine = measured @ expected / (np.linalg.norm(measured) * np.linalg.norm(expected))
    angle_deg = math.degrees(math.acos(float(np.clip(cosine, -1.0, 1.0))))
    values = {"angle_deg": angle_deg, **{f"imu_gravity_{a}_m_s2": float(v) for a, v in zip("xyz", measured)},
              **{f"profile_gravity_{a}_m_s2": float(v) for a, v in zip("xyz", expected)}}
    vectors = (f"base IMU gravity {np.round(measured, 2).tolist()} m/s^2, profile gravity through the tracker's "
               f"base pose {np.round(expected, 2).tolist()} m/s^2 (clamp frame)")
    if angle_deg > settings.level_limit_deg:
        return CheckResult(LEVEL, "warn", f"level check: gravity differs by {angle_deg:.1f} deg (> "
                           f"{settings.level_limit_deg:g}): is the field generator level and gravity.in_tracker_m_s2 right? "
                           + vectors, values)
    return CheckResult(LEVEL, "pass", f"level check passed ({angle_deg:.2f} deg): " + vectors, values)


async def run_setup_checks(hold: Callable[[tuple[float, float, float]], Awaitable[Dataset | None]],
                           rest_accel_m_s2: Callable[[], np.ndarray | None], predicted_rad: np.ndarray,
                           profile: RigProfile, settings: CheckSettings = CheckSettings()) -> list[CheckResult]:
    """Run the level and wiring checks on a rig.

    hold(forces): command these jet forces (N), hold them ``settings.settle_s`` and return
    the settled EM row (a one-row `Dataset`), None when the tracker gave nothing.
    rest_accel_m_s2(): the base IMU's mean accelerometer reading (sensor frame, m/s^2)
    over the settled end of the last hold, None without IMUs.
    predicted_rad: `predicted_bending_rad` at the profile's nominal clamp pose, computed
    before the valves are armed (solves must not hold up the valve heartbeat)."""
    rest = await hold((0.0, 0.0, 0.0))
    if rest is None:
        return [CheckResult(WIRING, "unavailable", "setup checks skipped: the tracker gave no pose at rest", {})]
    gravity_in_clamp = profile.gravity_in_base_m_s2(rest.base_orientation[0])
    results = []
    accel = rest_accel_m_s2()
    if accel is None:
        results.append(CheckResult(LEVEL, "unavailable", "level check needs a base IMU; this rig has none", {}))
    else:
        mounting = matrix_from_quat(profile.base_sensor.rotation_in_body)
        results.append(check_level(mounting @ accel, gravity_in_clamp, settings))
    fired = []
    for jet in range(JET_COUNT):
        forces = tuple(settings.force_n if k == jet else 0.0 for k in range(JET_COUNT))
        row = await hold(forces)  # type: ignore[arg-type]
        if row is None:
            results.append(CheckResult(WIRING, "unavailable", f"wiring check: no tracker pose with jet {jet + 1} "
                                       "fired", {}))
            return results
        fired.append(row.tip_orientation_in_base()[0])
    await hold((0.0, 0.0, 0.0))
    measured = measured_bending_rad(rest.tip_orientation_in_base()[0], np.array(fired))
    results.append(check_wiring(measured, predicted_rad, settings))
    return results
