"""IMU against EM tracker: how well the cheap IMUs measure the tip relative to the base.

Both sources measure the same two bodies with the same mountings, but in different
reference frames: the EM tracker in its own frame, each fusion filter in its earth frame
(z up, x towards magnetic north). The tip orientation relative to the base, mountings
removed (`Dataset.tip_orientation_in_base`), does not depend on that frame, so the
two are compared directly.

Alignment: the EM tip-in-base orientation is interpolated to each IMU stamp by slerp
between the two EM samples around it, unless a gap separates them: a tracker frame lost
between them (or its pose unusable), so that the tip's motion there is unseen. Gaps are
judged on the tracker's own frame counter when the EM samples come with it: two samples
are a gap when their frame numbers are further apart than 1.5 median steps (one
lost frame at the tracker's full rate). The host stamps a frame when it receives it, and
those stamps jitter (1.7-60 ms apart for a 25 ms period on a simulated rig at x25,
without a frame lost), which a rule on the stamps took for gaps. Without frame numbers,
or with ``max_gap_s`` given, the stamps decide: at most ``max_gap_s`` apart (default:
1.5 median EM periods). IMU stamps before the first or after the last EM sample are
dropped too; `AlignedOrientations.dropped` counts each reason.

Error of one aligned sample: the rotation ``q_imu * conj(q_em)`` that takes the EM
orientation onto the IMU's, as a rotation vector in the base (clamp) frame, degrees.
Its component along "up" (minus gravity, in the base frame, from the EM base sensor) is
the heading error: a rotation about the vertical, which only the magnetometers and the
gyros can see and a magnetic disturbance or gyro drift corrupts. The rest is the tilt
error, which gravity pins. (A left-side error in the base frame is the difference of
the two IMUs' earth-frame errors, seen from the base: a heading error common to both
IMUs cancels.)

Holds: runs of one command (sweep, step and jet forces) lasting at least
``min_hold_s``; their samples after ``settle_s`` from the run's start are settled. Static
accuracy is the mean angle over each hold's settled samples (sensor noise included) and
its bias, the angle between the hold's mean IMU and mean EM orientations (noise averaged
out); drift is the linear trend of the angle (deg/min) within each hold, across the
holds, and over the whole session.

Online estimation: the estimator of eq. 4 is run over the same settled steps twice,
fed by EM and by IMU orientations (gravity in the base frame from the IMU base
orientation then), and both are scored against the EM measurement next to Ref. (the
calibrated, constant disturbance), with `analysis.compare`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config.schema import BaseTable, GravityTable
from ..data.dataset import Dataset, average_quaternions
from ..estimation.online import OnlineSettings
from ..estimation.path import ONLINE, PathPredictor, Predictions
from ..geometry import quat_conjugate, quat_from_rotvec, quat_multiply, rotation_angle_deg, rotvec_from_quat
from ..models.shooting import ShootingModel
from ..params import ModelParameters
from ..profile import RigProfile
from .breakdowns import drift
from .compare import Comparison, compare, compare_methods

# Gravity in the fusion filter's earth frame (z up), m/s^2 (drivers/imu/fusion.py).
IMU_EARTH_GRAVITY_M_S2 = (0.0, 0.0, -9.81)
# EM samples further apart than this many median EM periods (or median steps of the
# tracker's frame number) are not interpolated across: one lost frame (two) is a gap.
MAX_GAP_PERIODS = 1.5
# How `align` judged the gaps: on the tracker's frame numbers, or on the EM stamps.
FRAME_RULE = "tracker frame numbers"
TIME_RULE = "EM sample times"
# A command held this long (s) counts as a static pose.
DEFAULT_MIN_HOLD_S = 10.0
# Settled samples of a hold start this long (s) after its command: five settling time
# constants of the twin (0.5 s) and well past the fusion filter's transient.
DEFAULT_SETTLE_S = 2.5
AXES = ("x", "y", "z")
METHODS = ("ref", "online_em", "online_imu")
METHOD_LABELS = {"ref": "Ref. (constant disturbance)", "online_em": "Proposed, fed by EM",
                 "online_imu": "Proposed, fed by IMU"}


def imu_profile(profile: RigProfile) -> RigProfile:
    """The rig profile for the IMU samples: the same mountings and rod, with gravity where
    it points in the IMU filters' earth frame."""
    # The clamp keeps its orientation: only the frame gravity is expressed in changes.
    return profile.with_tables(gravity=GravityTable(in_tracker_m_s2=IMU_EARTH_GRAVITY_M_S2),
                               base=BaseTable(orientation_in_tracker=profile.base_orientation_in_tracker,
                                              position_in_tracker_m=profile.base_position_in_tracker_m))


def slerp(start: np.ndarray, end: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """Spherical interpolation along the shortest arc between unit quaternions
    ``start`` and ``end`` (n, 4), at ``fraction`` (n,) in [0, 1]; (n, 4)."""
    step = rotvec_from_quat(quat_multiply(quat_conjugate(start), end))  # w >= 0: shortest arc
    return quat_multiply(start, quat_from_rotvec(np.asarray(fraction, dtype=float)[:, None] * step))


@dataclass(frozen=True)
class DroppedSamples:
    """Valid IMU samples `align` left out, by reason: before the first EM sample, after
    the last, and inside a gap between two EM samples (``em_gaps``: how many gaps)."""

    before_em: int
    after_em: int
    in_em_gaps: int
    em_gaps: int

    @property
    def total(self) -> int:
        return self.before_em + self.after_em + self.in_em_gaps

    def describe(self) -> str:
        """One clause, e.g. "12 before the first EM sample, 290 in 18 EM gaps"."""
        parts = [f"{self.before_em} before the first EM sample" if self.before_em else "",
                 f"{self.after_em} after the last" if self.after_em else "",
                 f"{self.in_em_gaps} in {self.em_gaps} EM gap{'s' if self.em_gaps != 1 else ''}"
                 if self.in_em_gaps else ""]
        return ", ".join(part for part in parts if part) or "none"

    def as_dict(self) -> dict:
        return {"before_em": self.before_em, "after_em": self.after_em, "in_em_gaps": self.in_em_gaps,
                "em_gaps": self.em_gaps}


@dataclass(frozen=True)
class AlignedOrientations:
    """IMU and EM tip orientations in the base frame (mountings removed) at the IMU
    stamps where both are known. M rows.

    time_s: (M,) IMU stamps, s. imu, em: (M, 4) unit quaternions (w, x, y, z), tip frame
    -> base frame; em interpolated by slerp. up_in_base: (M, 3) unit vector against
    gravity in the base frame, from the EM base sensor. jet_forces_n (M, 3), sweep (M,),
    step (M,): the IMU samples' labels. gap_rule: what judged the EM gaps (`FRAME_RULE`
    or `TIME_RULE`). max_gap_s: the largest EM interval interpolated across, s (the
    limit under `TIME_RULE`, the longest bridged under `FRAME_RULE`). dropped: the valid
    IMU samples left out, by reason. imu_samples, em_samples: valid samples of each
    source before alignment; imu_rate_hz, em_rate_hz: their mean rates (a host that
    cannot keep up samples the IMUs slower than configured, and the filters then miss
    motion between samples).
    """

    time_s: np.ndarray
    imu: np.ndarray
    em: np.ndarray
    up_in_base: np.ndarray
    jet_forces_n: np.ndarray
    sweep: np.ndarray
    step: np.ndarray
    gap_rule: str
    max_gap_s: float
    dropped: DroppedSamples
    imu_samples: int
    em_samples: int
    imu_rate_hz: float | None
    em_rate_hz: float | None

    def __len__(self) -> int:
        return len(self.time_s)


def bridged_intervals(em_time_s: np.ndarray, max_gap_s: float | None = None,
                      em_frames: np.ndarray | None = None) -> tuple[np.ndarray, str, float]:
    """Which intervals between consecutive EM samples (stamps ``em_time_s``, s, n of
    them) may be interpolated across: (n - 1,) booleans, the rule that said so and the
    longest interval it allows, s. ``em_frames``: the samples' tracker frame numbers,
    which decide unless ``max_gap_s`` (s) is given (see the module docstring). Raises
    ValueError if the rule needs a median EM period and there are not two stamps."""
    intervals = np.diff(em_time_s)
    if max_gap_s is None and em_frames is not None and len(em_frames) > 1:
        steps = np.diff(np.asarray(em_frames, dtype=np.int64))
        forward = steps[steps > 0]
        limit = MAX_GAP_PERIODS * float(np.median(forward)) if len(forward) else 0.0
        # A step back is a tracker that restarted its count: nothing says what was lost.
        bridged = (steps > 0) & (steps <= limit)
        return bridged, FRAME_RULE, float(intervals[bridged].max()) if bridged.any() else 0.0
    if max_gap_s is None:
        periods = intervals[intervals > 0.0]
        if len(periods) == 0:
            raise ValueError("fewer than two EM sample times: give max_gap_s")
        max_gap_s = MAX_GAP_PERIODS * float(np.median(periods))
    return intervals <= max_gap_s, TIME_RULE, float(max_gap_s)


def align(imu: Dataset, em: Dataset, max_gap_s: float | None = None,
          em_frames: np.ndarray | None = None) -> AlignedOrientations:
    """The valid IMU samples with the EM orientation slerped to their stamps (see the
    module docstring). ``em_frames``: the tracker frame number of each row of ``em``
    (None: not known). Raises ValueError if a source has no valid sample or the gap rule
    needs an EM period that fewer than two EM samples cannot give."""
    if em_frames is not None:
        em_frames = np.asarray(em_frames)[em.valid_mask()]
    imu, em = imu.valid_rows(), em.valid_rows()
    if len(imu) == 0 or len(em) == 0:
        raise ValueError(f"no valid {'IMU' if len(imu) == 0 else 'EM'} samples to align")
    em_time = em.time_s
    bridged, rule, max_gap_s = bridged_intervals(em_time, max_gap_s, em_frames)
    lower = np.searchsorted(em_time, imu.time_s, side="right") - 1  # last EM sample at or before
    before, after = lower < 0, imu.time_s > em_time[-1]
    upper = np.minimum(lower + 1, len(em) - 1)
    lower_safe = np.maximum(lower, 0)
    # A stamp on the last EM sample needs no interval; any other, the one it lies in.
    in_gap = ~before & ~after & (lower < len(em) - 1) & ~np.append(bridged, True)[lower_safe]
    inside = ~before & ~after & ~in_gap
    dropped = DroppedSamples(int(before.sum()), int(after.sum()), int(in_gap.sum()), int((~bridged).sum()))
    lower, upper = lower_safe[inside], upper[inside]
    gap = em_time[upper] - em_time[lower]
    time = imu.time_s[inside]
    fraction = np.divide(time - em_time[lower], gap, out=np.zeros(len(time)), where=gap > 0.0)
    em_tip = em.tip_orientation_in_base()
    gravity = em.gravity_in_base_m_s2()[lower]
    return AlignedOrientations(
        time_s=time, imu=imu.tip_orientation_in_base()[inside], em=slerp(em_tip[lower], em_tip[upper], fraction),
        up_in_base=-gravity / np.linalg.norm(gravity, axis=1, keepdims=True),
        jet_forces_n=imu.jet_forces_n[inside], sweep=imu.sweep[inside], step=imu.step[inside], gap_rule=rule,
        max_gap_s=max_gap_s, dropped=dropped, imu_samples=len(imu), em_samples=len(em),
        imu_rate_hz=mean_rate_hz(imu.time_s), em_rate_hz=mean_rate_hz(em_time))


def mean_rate_hz(time_s: np.ndarray) -> float | None:
    """Samples per second over the span of ``time_s`` (None for less than a span)."""
    span = float(time_s[-1] - time_s[0]) if len(time_s) else 0.0
    return (len(time_s) - 1) / span if span > 0 else None


@dataclass(frozen=True)
class OrientationDifference:
    """Per aligned sample: angle_deg (M,) between IMU and EM; rotation_vector_deg (M, 3)
    of ``q_imu * conj(q_em)``, base frame; heading_deg (M,) its signed component about up
    (right-handed); tilt_deg (M,) the norm of the rest."""

    angle_deg: np.ndarray
    rotation_vector_deg: np.ndarray
    heading_deg: np.ndarray
    tilt_deg: np.ndarray


def orientation_difference(aligned: AlignedOrientations) -> OrientationDifference:
    vector = np.degrees(rotvec_from_quat(quat_multiply(aligned.imu, quat_conjugate(aligned.em))))
    heading = np.sum(vector * aligned.up_in_base, axis=1)
    tilt = np.linalg.norm(vector - heading[:, None] * aligned.up_in_base, axis=1)
    return OrientationDifference(rotation_angle_deg(aligned.imu, aligned.em), vector, heading, tilt)


@dataclass(frozen=True)
class AngleSummary:
    """count, RMS, mean and largest angle (deg) of a group of samples."""

    count: int
    rms_deg: float
    mean_deg: float
    max_deg: float

    def as_dict(self) -> dict:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}


def summarise_angles(angle_deg: np.ndarray) -> AngleSummary | None:
    """None for no samples."""
    angle = np.asarray(angle_deg, dtype=float)
    if angle.size == 0:
        return None
    return AngleSummary(int(angle.size), float(np.sqrt(np.mean(angle**2))), float(np.mean(angle)),
                        float(np.max(angle)))


def trend_per_min(values: np.ndarray, time_s: np.ndarray) -> float | None:
    """Least-squares slope of ``values`` against time, units per minute (None if the
    samples span no time)."""
    return drift(np.asarray(values, dtype=float), None, time_s, blocks=1).trend_deg_per_min


@dataclass(frozen=True)
class Hold:
    """One static pose: its labels, command (N), the settled span (s) and what the
    angle (deg) did over it. bias_deg: the angle between the IMU's and the EM's mean
    orientations over the span: the static error with both sensors' noise averaged
    out (the mean angle keeps the noise)."""

    sweep: int
    step: int
    jet_forces_n: tuple[float, float, float]
    start_s: float
    end_s: float
    angle: AngleSummary
    sd_deg: float
    bias_deg: float
    mean_heading_deg: float
    mean_tilt_deg: float
    trend_deg_per_min: float | None
    heading_trend_deg_per_min: float | None

    def as_dict(self) -> dict:
        return {"sweep": self.sweep, "step": self.step, "jet_forces_n": list(self.jet_forces_n),
                "start_s": self.start_s, "end_s": self.end_s, **self.angle.as_dict(), "sd_deg": self.sd_deg,
                "bias_deg": self.bias_deg,
                "mean_heading_deg": self.mean_heading_deg, "mean_tilt_deg": self.mean_tilt_deg,
                "trend_deg_per_min": self.trend_deg_per_min,
                "heading_trend_deg_per_min": self.heading_trend_deg_per_min}


def command_runs(aligned: AlignedOrientations) -> list[tuple[int, int]]:
    """(start, stop) row ranges of constant sweep, step and jet forces."""
    if len(aligned) == 0:
        return []
    change = ((aligned.sweep[1:] != aligned.sweep[:-1]) | (aligned.step[1:] != aligned.step[:-1])
              | np.any(aligned.jet_forces_n[1:] != aligned.jet_forces_n[:-1], axis=1))
    edges = np.concatenate([[0], np.flatnonzero(change) + 1, [len(aligned)]])
    return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]


def settled_holds(aligned: AlignedOrientations, min_hold_s: float = DEFAULT_MIN_HOLD_S,
                  settle_s: float = DEFAULT_SETTLE_S) -> list[np.ndarray]:
    """Row indices of the settled part of each hold, in time order (holds with no sample
    after ``settle_s`` are left out)."""
    holds = []
    for start, stop in command_runs(aligned):
        time = aligned.time_s[start:stop]
        if time[-1] - time[0] >= min_hold_s:
            rows = start + np.flatnonzero(time >= time[0] + settle_s)
            if len(rows):
                holds.append(rows)
    return holds


def describe_hold(rows: np.ndarray, aligned: AlignedOrientations, difference: OrientationDifference) -> Hold:
    time = aligned.time_s[rows]
    angle = difference.angle_deg[rows]
    summary = summarise_angles(angle)
    assert summary is not None
    first = rows[0]
    bias = rotation_angle_deg(average_quaternions(aligned.imu[rows]), average_quaternions(aligned.em[rows]))
    return Hold(int(aligned.sweep[first]), int(aligned.step[first]),
                tuple(float(f) for f in aligned.jet_forces_n[first]), float(time[0]), float(time[-1]), summary,
                float(np.std(angle)), float(bias), float(np.mean(difference.heading_deg[rows])),
                float(np.mean(difference.tilt_deg[rows])), trend_per_min(angle, time),
                trend_per_min(difference.heading_deg[rows], time))


@dataclass(frozen=True)
class AxisErrors:
    """RMS and mean (deg) of each base-frame component of the error rotation vector, of
    the heading (about up) and of the tilt."""

    rms_deg: tuple[float, float, float]
    mean_deg: tuple[float, float, float]
    heading_rms_deg: float
    heading_mean_deg: float
    tilt_rms_deg: float
    tilt_mean_deg: float

    def as_dict(self) -> dict:
        return {"components": {axis: {"rms_deg": self.rms_deg[i], "mean_deg": self.mean_deg[i]}
                               for i, axis in enumerate(AXES)},
                "heading_rms_deg": self.heading_rms_deg, "heading_mean_deg": self.heading_mean_deg,
                "tilt_rms_deg": self.tilt_rms_deg, "tilt_mean_deg": self.tilt_mean_deg}


def axis_errors(difference: OrientationDifference) -> AxisErrors:
    vector = difference.rotation_vector_deg

    def rms(values: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean(values**2, axis=0))

    return AxisErrors(tuple(float(v) for v in rms(vector)), tuple(float(v) for v in np.mean(vector, axis=0)),
                      float(rms(difference.heading_deg)), float(np.mean(difference.heading_deg)),
                      float(rms(difference.tilt_deg)), float(np.mean(difference.tilt_deg)))


@dataclass(frozen=True)
class SensorAgreement:
    """IMU against EM over a session.

    overall: every aligned sample; held: the holds' settled samples; moving: the rest
    (ramps, short steps, settling). axes: per-axis errors over every sample. holds: each
    static pose. trend_deg_per_min and heading_trend_deg_per_min: over the session;
    across_holds_deg_per_min: trend of the holds' mean angles against their mid times;
    within_holds_deg_per_min: mean of the holds' own trends.
    """

    aligned: AlignedOrientations
    difference: OrientationDifference
    overall: AngleSummary
    held: AngleSummary | None
    moving: AngleSummary | None
    axes: AxisErrors
    holds: tuple[Hold, ...]
    hold_rows: tuple[np.ndarray, ...]
    trend_deg_per_min: float | None
    heading_trend_deg_per_min: float | None
    across_holds_deg_per_min: float | None
    within_holds_deg_per_min: float | None
    min_hold_s: float
    settle_s: float

    def as_dict(self) -> dict:
        aligned = self.aligned

        def optional(summary: AngleSummary | None) -> dict | None:
            return None if summary is None else summary.as_dict()

        return {
            "alignment": {"method": "EM slerped to the IMU stamps between the EM samples around each",
                          "gap_rule": aligned.gap_rule, "max_gap_s": aligned.max_gap_s,
                          "imu_samples": aligned.imu_samples, "em_samples": aligned.em_samples,
                          "aligned_samples": len(aligned), "dropped": aligned.dropped.as_dict(),
                          "imu_rate_hz": aligned.imu_rate_hz, "em_rate_hz": aligned.em_rate_hz},
            "overall": self.overall.as_dict(), "held": optional(self.held), "moving": optional(self.moving),
            "per_axis": {"frame": "base (clamp) frame; heading: about up (against gravity)", **self.axes.as_dict()},
            "drift": {"session_deg_per_min": self.trend_deg_per_min,
                      "session_heading_deg_per_min": self.heading_trend_deg_per_min,
                      "across_holds_deg_per_min": self.across_holds_deg_per_min,
                      "within_holds_deg_per_min": self.within_holds_deg_per_min},
            "static": {"min_hold_s": self.min_hold_s, "settle_s": self.settle_s,
                       "mean_angle_deg": None if not self.holds else float(np.mean([h.angle.mean_deg
                                                                                   for h in self.holds])),
                       "holds": [hold.as_dict() for hold in self.holds]},
        }


def sensor_agreement(imu: Dataset, em: Dataset, max_gap_s: float | None = None,
                     min_hold_s: float = DEFAULT_MIN_HOLD_S, settle_s: float = DEFAULT_SETTLE_S,
                     em_frames: np.ndarray | None = None) -> SensorAgreement:
    """Align ``imu`` (samples in the IMU earth frame, with `imu_profile`) to ``em``
    (``em_frames``: its rows' tracker frame numbers, if known) and measure how they
    differ. Raises ValueError when nothing aligns."""
    aligned = align(imu, em, max_gap_s, em_frames)
    if len(aligned) == 0:
        raise ValueError(f"no IMU sample lies between two EM samples without a gap between them (dropped: "
                         f"{aligned.dropped.describe()})")
    difference = orientation_difference(aligned)
    hold_rows = settled_holds(aligned, min_hold_s, settle_s)
    holds = tuple(describe_hold(rows, aligned, difference) for rows in hold_rows)
    held = np.zeros(len(aligned), dtype=bool)
    for rows in hold_rows:
        held[rows] = True
    within = [hold.trend_deg_per_min for hold in holds if hold.trend_deg_per_min is not None]
    across = None
    if len(holds) >= 2:
        across = trend_per_min(np.array([h.angle.mean_deg for h in holds]),
                               np.array([(h.start_s + h.end_s) / 2.0 for h in holds]))
    overall = summarise_angles(difference.angle_deg)
    assert overall is not None
    return SensorAgreement(
        aligned, difference, overall, summarise_angles(difference.angle_deg[held]),
        summarise_angles(difference.angle_deg[~held]), axis_errors(difference), holds, tuple(hold_rows),
        trend_per_min(difference.angle_deg, aligned.time_s), trend_per_min(difference.heading_deg, aligned.time_s),
        across, float(np.mean(within)) if within else None, float(min_hold_s), float(settle_s))


# --- online estimation fed by either source -------------------------------------------


def matched_steps(em_steps: Dataset, imu_steps: Dataset) -> tuple[Dataset, Dataset]:
    """The valid settled steps present in both sources, paired by (sweep, step), in the
    EM order. Raises ValueError if a source labels two steps alike."""
    keys = []
    for name, steps in (("EM", em_steps), ("IMU", imu_steps)):
        labels = list(zip(steps.sweep.tolist(), steps.step.tolist()))
        if len(set(labels)) != len(labels):
            raise ValueError(f"the {name} samples label two separate steps with the same sweep and step")
        keys.append(labels)
    em_valid, imu_valid = em_steps.valid_mask(), imu_steps.valid_mask()
    imu_row = {key: row for row, key in enumerate(keys[1]) if imu_valid[row]}
    em_rows = [row for row, key in enumerate(keys[0]) if em_valid[row] and key in imu_row]
    return em_steps.select(np.array(em_rows, dtype=np.int64)), imu_steps.select(
        np.array([imu_row[keys[0][row]] for row in em_rows], dtype=np.int64))


@dataclass(frozen=True)
class EstimatorComparison:
    """Ref. and the online estimator fed by each source, all scored against the EM
    measurement on ``steps`` (the EM settled steps compared)."""

    steps: Dataset
    results: dict[str, Comparison]

    def gain(self, method: str) -> float:
        """Relative cut in orientation RMSE from Ref. (0.4: 40 % smaller)."""
        reference = self.results["ref"].overall.orientation_rmse_deg
        return 1.0 - self.results[method].overall.orientation_rmse_deg / reference

    def position_gain(self, method: str) -> float | None:
        reference = self.results["ref"].overall.position_rmse_mm
        value = self.results[method].overall.position_rmse_mm
        return None if reference is None or value is None else 1.0 - value / reference

    def as_dict(self) -> dict:
        return {"steps": len(self.steps), **{method: {
            "label": METHOD_LABELS[method], **comparison.as_dict(),
            "orientation_gain": None if method == "ref" else self.gain(method),
            "position_gain": None if method == "ref" else self.position_gain(method),
        } for method, comparison in self.results.items()}}


def compare_estimators(model: ShootingModel, params: ModelParameters, em_steps: Dataset, imu_steps: Dataset,
                       online: OnlineSettings | None = None) -> EstimatorComparison:
    """Ref. and the online estimator fed by EM and by IMU orientations (``imu_steps`` with
    `imu_profile`), over the validation steps (sweep >= 0; all steps if there are none)
    both sources settled. Raises ValueError if no step is common to both."""
    online = online or OnlineSettings()
    em_steps, imu_steps = matched_steps(em_steps, imu_steps)
    if len(em_steps) == 0:
        raise ValueError("no settled step is measured by both the EM tracker and the IMUs")
    validation = em_steps.sweep >= 0
    if validation.any():
        em_steps, imu_steps = em_steps.select(validation), imu_steps.select(validation)
    on_em = compare_methods(model, params, em_steps, online)
    fed_by_imu = Predictions.along(PathPredictor(model, params, online).predict(imu_steps), ONLINE)
    results = {"ref": on_em["ref"], "online_em": on_em["online"], "online_imu": compare(fed_by_imu, em_steps)}
    return EstimatorComparison(em_steps, results)


# --- report ---------------------------------------------------------------------------


def hold_label(hold: Hold) -> str:
    """How figures and tables name a hold: "pose 3" (calibration pose 3), or "sweep 1
    step 4"."""
    return f"pose {hold.step}" if hold.sweep < 0 else f"sweep {hold.sweep} step {hold.step}"
