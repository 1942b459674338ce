"""The noise floor: the held-out error a perfect deterministic model would still show.

Primary estimate, repeatability: the paper's protocol sweeps every jet three times, so
each held-out command was also measured 2 more times along the same path. The scatter
of those repeats around their mean is everything no deterministic model can predict:
tracker noise left after averaging a step, jet turbulence, and anything else that does
not repeat. Pooled over groups of m repeats, sum |x_i - mean|^2 / sum (m - 1) estimates
the mean squared error of one step, whatever the noise's spectrum or anisotropy.

A few groups may differ for a physical reason a model can capture: a clamp with play
starts the very first sweep from where the calibration poses left it, not where the
previous sweep did. Groups whose scatter is beyond the 0.999 quantile of what the
robust (median-based) estimate predicts are left out, so such a group cannot inflate
the floor; the count is reported.

Cross-check, within-window scatter: when the raw samples are at hand, the scatter of
the samples inside each step's averaging window, divided by the samples per window,
is the averaged tracker noise alone. It assumes white noise; the tracker's own
filtering or slow jitter make it smaller than the repeatability estimate, which is then
the honest floor. Without repeated sweeps it is the only estimate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ...data.dataset import Dataset, average_quaternions
from ...errors import UserError
from ...geometry import quat_conjugate, quat_multiply, rotvec_from_quat
from .measurements import tip_sensor_position_in_base_m
from .split import sweep_kinds

# A group's scatter beyond this quantile of its chi-square law, scaled by the robust
# estimate, is physics rather than noise (one group in a thousand is cut by chance).
OUTLIER_QUANTILE = 0.999
MIN_REPEAT_DOF = 30


@dataclass(frozen=True)
class NoiseFloor:
    """orientation_deg: RMS angle (deg) between a step's measured orientation and the
    truth. position_mm: the same for the tip sensor's position (mm, see `measurements`),
    None without positions.
    orientation_axis_rad / position_axis_m: the per-axis standard deviations behind
    them (total / sqrt 3), the scale of the likelihood. method: "repeatability" or
    "window". dof: degrees of freedom of the orientation estimate. groups/rejected:
    repeat groups used and left out. window_orientation_deg: the within-window
    estimate when raw samples were given."""

    orientation_deg: float
    position_mm: float | None
    method: str
    dof: int
    groups: int = 0
    rejected: int = 0
    window_orientation_deg: float | None = None

    @property
    def orientation_axis_rad(self) -> float:
        return float(np.radians(self.orientation_deg) / np.sqrt(3.0))

    @property
    def position_axis_m(self) -> float | None:
        return None if self.position_mm is None else self.position_mm * 1e-3 / float(np.sqrt(3.0))

    def as_dict(self) -> dict:
        return {"orientation_deg": self.orientation_deg, "position_mm": self.position_mm, "method": self.method,
                "dof": self.dof, "repeat_groups": self.groups, "rejected_groups": self.rejected,
                "window_orientation_deg": self.window_orientation_deg}


def repeat_groups(steps: Dataset, rows: np.ndarray | None = None) -> list[np.ndarray]:
    """Row indices of the same command at the same place in repetitions of the same
    sweep (see `split.sweep_kinds`), groups of two or more; only ``rows`` (a mask) count."""
    use = steps.valid_mask() if rows is None else rows & steps.valid_mask()
    groups: dict[tuple[int, int], list[int]] = {}
    for sweep, kind in sweep_kinds(steps).items():
        for position, row in enumerate(np.flatnonzero(steps.sweep == sweep)):
            if use[row]:
                groups.setdefault((kind, position), []).append(int(row))
    return [np.array(group) for group in groups.values() if len(group) > 1]


def _pooled_scatter(deviations: Sequence[np.ndarray]) -> tuple[float, int, int]:
    """Per-axis variance pooled over groups of 3-vector deviations from their group
    means, groups beyond `OUTLIER_QUANTILE` left out: (variance, dof, rejected)."""
    sums = np.array([float(np.sum(d**2)) for d in deviations])
    dofs = np.array([3 * (len(d) - 1) for d in deviations])
    robust = float(np.median(sums / chi2.median(dofs)))
    keep = sums <= robust * chi2.ppf(OUTLIER_QUANTILE, dofs) if robust > 0.0 else np.ones(len(sums), bool)
    return float(sums[keep].sum() / dofs[keep].sum()), int(dofs[keep].sum()), int((~keep).sum())


def repeatability_floor(steps: Dataset, rows: np.ndarray | None = None) -> NoiseFloor | None:
    """The floor from repeated commands (None when the repeats give fewer than
    `MIN_REPEAT_DOF` degrees of freedom)."""
    groups = repeat_groups(steps, rows)
    if sum(3 * (len(g) - 1) for g in groups) < MIN_REPEAT_DOF:
        return None
    orientations = steps.tip_orientation_in_base()
    rotation = []
    for group in groups:
        mean = average_quaternions(orientations[group])
        rotation.append(rotvec_from_quat(quat_multiply(quat_conjugate(mean), orientations[group])))
    variance, dof, rejected = _pooled_scatter(rotation)
    positions = tip_sensor_position_in_base_m(steps)
    position_mm = None
    if positions is not None:
        position_variance, _, _ = _pooled_scatter([positions[g] - positions[g].mean(axis=0) for g in groups])
        position_mm = float(np.sqrt(3.0 * position_variance) * 1e3)
    return NoiseFloor(float(np.degrees(np.sqrt(3.0 * variance))), position_mm, "repeatability", dof,
                      len(groups), rejected)


def window_floor(samples: Dataset, window_s: float = 1.0) -> NoiseFloor:
    """The floor from the scatter of raw samples within each step's last ``window_s``
    seconds (the window `Dataset.quasistatic_steps` averages), divided by the samples
    per window: white tracker noise after averaging."""
    valid = samples.valid_mask()
    relative = samples.tip_orientation_in_base()
    positions = tip_sensor_position_in_base_m(samples)
    rotation_sums = position_sums = 0.0
    per_step_variance = []
    dof = 0
    for start, stop in samples.step_runs():
        rows = np.arange(start, stop)
        rows = rows[(samples.time_s[rows] >= samples.time_s[stop - 1] - window_s) & valid[rows]]
        if len(rows) < 2:
            continue
        mean = average_quaternions(relative[rows])
        deviation = rotvec_from_quat(quat_multiply(quat_conjugate(mean), relative[rows]))
        rotation_sums += float(np.sum(deviation**2))
        if positions is not None:
            position_sums += float(np.sum((positions[rows] - positions[rows].mean(axis=0)) ** 2))
        per_step_variance.append(1.0 / len(rows))
        dof += 3 * (len(rows) - 1)
    if dof == 0:
        raise UserError(f"{samples.source or 'the data'}: no step has two valid samples in its last "
                        f"{window_s:g} s; cannot estimate the noise floor")
    # Mean squared error of a step's average: per-sample variance / samples per window.
    shrink = float(np.mean(per_step_variance))
    orientation_deg = float(np.degrees(np.sqrt(rotation_sums / dof * 3.0 * shrink)))
    position_mm = None if positions is None else float(np.sqrt(position_sums / dof * 3.0 * shrink) * 1e3)
    return NoiseFloor(orientation_deg, position_mm, "window", dof, window_orientation_deg=orientation_deg)


def estimate_noise_floor(steps: Dataset, samples: Dataset | None = None, rows: np.ndarray | None = None,
                         window_s: float = 1.0) -> NoiseFloor:
    """Repeatability when the session repeats its sweeps, else the within-window
    scatter of ``samples`` (the raw data); both reported when both are available."""
    window = window_floor(samples, window_s) if samples is not None else None
    repeat = repeatability_floor(steps, rows)
    if repeat is not None:
        if window is None:
            return repeat
        return NoiseFloor(repeat.orientation_deg, repeat.position_mm, repeat.method, repeat.dof, repeat.groups,
                          repeat.rejected, window.orientation_deg)
    if window is not None:
        return window
    raise UserError(f"{steps.source or 'the data'}: cannot estimate the noise floor: no sweep is repeated and "
                    "no raw samples were given")
