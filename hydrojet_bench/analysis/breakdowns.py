"""Where the model fails: error breakdowns that point at the missing physics.

Pure functions over the compared steps (a `Dataset`, one row per quasistatic step, in
time order) and the `Comparison` of one prediction method on them. Each breakdown
answers a question a missing effect would leave a mark on:

* by driving jet and by bending direction: a jet delivering the wrong force, a rotated
  jet ring or an anisotropic rod err in some directions only; a calibration absorbs a
  weak jet into E, so each jet's force scale from a per-jet fit (`jet_force_scales`)
  says which jet differs where the per-jet errors cannot;
* loading against unloading: clamp play and friction make the two branches of a sweep
  differ at the same force (the hysteresis gap, judged against what noise alone gives,
  `noise_only_gap`);
* by region of the workspace (bend bin x bending direction): stiffening errs at large
  bends, gravity on one side;
* over time: drift (water uptake, temperature, a sensor slipping on the rod);
* the residual vectors and the online disturbance: the direction of the error, and the
  moment the online estimator had to add to explain the measurements.

Frames: the bending direction is the azimuth, in the base frame's xy plane, of the
measured tip tangent (the tip frame's z axis), degrees in [0, 360) from the base x axis.
The orientation residual is the rotation vector of ``R_pred^T R_meas`` (deg, predicted
tip frame): the rotation that takes the prediction onto the measurement. The position
residual is ``p_pred - p_meas`` (mm, base frame).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.dataset import Dataset
from ..effects import load_effect, qualified_parameter_names
from ..errors import ConvergenceError
from ..estimation.calibration import DEFAULT_NAMES, calibrate, calibration_poses
from ..estimation.path import Predictions
from ..geometry import body_rotation_error, matrix_from_quat
from ..models import make_model
from ..models.shooting import ShootingModel
from ..params import JET_COUNT, ModelParameters
from .compare import Comparison, measured_bend_deg
from .metrics import ErrorSummary, bend_bin_labels, bend_bin_names, breakdown, summarise

SECTOR_WIDTH_DEG = 60.0
# Below this bend the tip tangent's azimuth is dominated by sensor noise (the EM
# tracker's 0.7 deg RMS per sensor): such steps form their own "straight" group.
STRAIGHT_BELOW_DEG = 5.0
STRAIGHT = "straight"
LOADING, UNLOADING, HOLD = "loading", "unloading", "hold"
# Forces of two steps match (for the hysteresis gap, and count as "no change" for
# loading/unloading) within this fraction of the largest jet force in the data: commanded
# forces repeat exactly, measured ones within a fraction of a percent.
FORCE_MATCH_FRACTION = 1e-3
DEFAULT_TIME_BLOCKS = 6
# Steps spanning less time than this have no trend to report; a span near zero also made
# the fit fail to converge (steps 1e-300 s apart).
MIN_TREND_SPAN_S = 1.0
DEFAULT_WORST_COUNT = 10
MISSING_LABEL = "what the model is missing"
# The mean norm of the difference of two independent isotropic 3-D noise vectors, each
# of RMS norm 1: sqrt(2/3) E[chi_3] = 4 / sqrt(3 pi). A hysteresis gap (loading minus
# unloading residual at the same force) of pure noise is this times the noise floor;
# the norm's relative standard deviation is sqrt(3 pi / 8 - 1) ~ 0.42 (chi_3).
NOISE_GAP_PER_FLOOR = 4.0 / np.sqrt(3.0 * np.pi)
NOISE_GAP_RELATIVE_SD = float(np.sqrt(3.0 * np.pi / 8.0 - 1.0))
# A gap beyond this many standard errors of the noise-only mean is not noise.
GAP_SIGNIFICANCE_SE = 3.0
# The per-jet fit starts at the calibrated optimum: a few dozen evaluations settle it,
# and digits beyond 1e-6 of the cost change no scale a reader compares.
JET_SCALE_EVALUATIONS = 40
JET_SCALE_COST_TOLERANCE = 1e-6


@dataclass(frozen=True)
class LoadingSplit:
    """Errors on the loading (jet force rising) and unloading (falling) branches of the
    sweeps, and the hysteresis gap: the mean norm of the difference of the residual
    vectors between an unloading step and the loading step at the same jet forces in the
    same sweep (deg for orientation, mm for position). A model without hysteresis
    predicts the same pose on both branches, so the gap is what the measurements
    differ by; comparing error vectors, not angles, keeps it visible when the model sits
    midway between the branches and errs equally on both. Independent noise alone makes
    the gap about sqrt(2) times the error RMS."""

    loading: ErrorSummary | None
    unloading: ErrorSummary | None
    matched_pairs: int
    hysteresis_gap_deg: float | None
    hysteresis_gap_mm: float | None

    def as_dict(self) -> dict:
        return {"loading": None if self.loading is None else self.loading.as_dict(),
                "unloading": None if self.unloading is None else self.unloading.as_dict(),
                "matched_pairs": self.matched_pairs, "hysteresis_gap_deg": self.hysteresis_gap_deg,
                "hysteresis_gap_mm": self.hysteresis_gap_mm}


@dataclass(frozen=True)
class TimeBlock:
    """Errors of a run of consecutive steps, from ``start_s`` to ``end_s`` (s, the data's clock)."""

    start_s: float
    end_s: float
    summary: ErrorSummary

    def as_dict(self) -> dict:
        return {"start_s": self.start_s, "end_s": self.end_s, **self.summary.as_dict()}


@dataclass(frozen=True)
class Drift:
    """Errors over time: RMS per block of consecutive steps, and the least-squares
    slope of the per-step errors against time (deg/min, mm/min); None when the steps
    span less than `MIN_TREND_SPAN_S`."""

    blocks: tuple[TimeBlock, ...]
    trend_deg_per_min: float | None
    trend_mm_per_min: float | None

    def as_dict(self) -> dict:
        return {"blocks": [block.as_dict() for block in self.blocks],
                "trend_deg_per_min": self.trend_deg_per_min, "trend_mm_per_min": self.trend_mm_per_min}


@dataclass(frozen=True)
class WorstPose:
    """One of the worst-predicted steps. index: row in the compared steps; bend_deg and
    azimuth_deg are measured; jet_forces_n in N."""

    index: int
    sweep: int
    step: int
    time_s: float
    jet_forces_n: tuple[float, float, float]
    bend_deg: float
    azimuth_deg: float
    orientation_error_deg: float
    position_error_mm: float | None

    def as_dict(self) -> dict:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}


@dataclass(frozen=True)
class Breakdowns:
    """Every breakdown of one prediction method on one set of steps.

    by_jet: by the jet driving the step ("jet 1".."jet 3", "none" when all are off).
    by_direction: by bending-direction sector (`direction_labels`).
    by_region: {bend bin (Table II labels): {direction sector: summary}}, cells with data only.
    """

    by_jet: dict[str, ErrorSummary]
    by_direction: dict[str, ErrorSummary]
    by_region: dict[str, dict[str, ErrorSummary]]
    loading: LoadingSplit
    drift: Drift
    worst: tuple[WorstPose, ...]

    def as_dict(self) -> dict:
        return {
            "by_jet": {key: value.as_dict() for key, value in self.by_jet.items()},
            "by_direction": {key: value.as_dict() for key, value in self.by_direction.items()},
            "by_region": {bend: {sector: value.as_dict() for sector, value in row.items()}
                          for bend, row in self.by_region.items()},
            "loading_unloading": self.loading.as_dict(),
            "over_time": self.drift.as_dict(),
            "worst_poses": [pose.as_dict() for pose in self.worst],
        }


def break_down(comparison: Comparison, steps: Dataset, time_blocks: int = DEFAULT_TIME_BLOCKS,
               worst_count: int = DEFAULT_WORST_COUNT) -> Breakdowns:
    """All the breakdowns of ``comparison`` (made on ``steps``)."""
    orientation, position = comparison.orientation_error_deg, comparison.position_error_mm
    bend = measured_bend_deg(steps)
    directions = direction_labels(steps)
    bins = bend_bin_labels(bend)
    region = {}
    for bend_bin in _present(bins, bend_bin_names()):
        rows = bins == bend_bin
        cells = breakdown(orientation[rows], None if position is None else position[rows], directions[rows])
        region[bend_bin] = _ordered(cells, direction_order())
    return Breakdowns(
        by_jet=breakdown(orientation, position, driving_jet_labels(steps)),
        by_direction=_ordered(breakdown(orientation, position, directions), direction_order()),
        by_region=region,
        loading=loading_split(comparison, steps),
        drift=drift(orientation, position, steps.time_s, time_blocks),
        worst=worst_poses(comparison, steps, worst_count),
    )


@dataclass(frozen=True)
class JetScale:
    """One jet's force scale: the factor on its commanded force that, fitted together
    with the other jets' and the calibration's own parameters (E0, EL, L, w_d) on the
    compared steps, best explains them; 1 means it pushes as the model assumes.
    relative: the scale over the mean of the jets' scales, with its standard error: a
    calibration absorbs a scale common to all jets into E, so only differences between
    jets point at one. steps: the steps it drives. convergence: whether the fit of the
    gains converged, in words (`CalibrationResult.convergence`): one not converged gives
    rough scales."""

    steps: int
    scale: float
    standard_error: float
    relative: float
    relative_standard_error: float
    converged: bool = True
    convergence: str = ""

    def as_dict(self) -> dict:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}


@dataclass(frozen=True)
class GapVerdict:
    """A hysteresis gap (deg) against what noise alone gives at a noise floor (deg):
    ``noise_only_deg`` = `NOISE_GAP_PER_FLOOR` x floor; ``limit_deg`` adds
    `GAP_SIGNIFICANCE_SE` standard errors of a mean over the matched pairs;
    ``beyond_noise``: the gap exceeds the limit."""

    gap_deg: float
    floor_deg: float
    noise_only_deg: float
    limit_deg: float
    beyond_noise: bool

    def as_dict(self) -> dict:
        return {key: getattr(self, key) for key in self.__dataclass_fields__}


def noise_only_gap(gap_deg: float, matched_pairs: int, floor_deg: float) -> GapVerdict:
    """Judge a hysteresis gap over ``matched_pairs`` pairs against the noise floor
    ``floor_deg`` (the RMS angle noise alone leaves, as `diagnose` measures it)."""
    noise_only = NOISE_GAP_PER_FLOOR * floor_deg
    limit = noise_only * (1.0 + GAP_SIGNIFICANCE_SE * NOISE_GAP_RELATIVE_SD / np.sqrt(max(matched_pairs, 1)))
    return GapVerdict(gap_deg, floor_deg, float(noise_only), float(limit), bool(gap_deg > limit))


def jet_force_scales(model: ShootingModel, params: ModelParameters, steps: Dataset) -> dict[str, JetScale]:
    """Each driving jet's `JetScale`: the model plus a gain per jet (`jet_gain`), fitted
    from ``params`` on ``steps`` as one path in time order; empty when the fit fails
    (a model that cannot follow the steps has worse problems than a jet)."""
    gains = load_effect("jet_gain")
    own = qualified_parameter_names(gains)
    fitted_model = (model if any(effect.name == gains.name for effect in model.effects)
                    else make_model(model.name, (*model.effects, gains)))
    try:
        result = calibrate(fitted_model, calibration_poses(steps), params, DEFAULT_NAMES + own, follow_path=True,
                           max_evaluations=JET_SCALE_EVALUATIONS, cost_tolerance=JET_SCALE_COST_TOLERANCE)
    except (ConvergenceError, ValueError):
        return {}
    columns = [result.names.index(name) for name in own]
    start = np.array([params.effect_value(name, 1.0) for name in own])
    scale = result.values[columns] / start
    covariance = (result.correlation[np.ix_(columns, columns)]
                  * np.outer(result.standard_errors[columns], result.standard_errors[columns])
                  / np.outer(start, start))
    labels = driving_jet_labels(steps)
    driving = [jet for jet in range(JET_COUNT) if np.any(labels == f"jet {jet + 1}")]
    if not driving:
        return {}
    mean = float(np.mean(scale[driving]))
    table = {}
    for jet in driving:
        # Delta method: d(s_j / mean)/ds_k = (delta_jk - s_j / n) / mean over the driving jets.
        gradient = np.zeros(JET_COUNT)
        gradient[driving] = -scale[jet] / (len(driving) * mean**2)
        gradient[jet] += 1.0 / mean
        table[f"jet {jet + 1}"] = JetScale(int(np.sum(labels == f"jet {jet + 1}")), float(scale[jet]),
                                           float(np.sqrt(covariance[jet, jet])), float(scale[jet] / mean),
                                           float(np.sqrt(max(gradient @ covariance @ gradient, 0.0))),
                                           result.converged, result.convergence)
    return table


# --- residuals -----------------------------------------------------------------------


def orientation_residuals_deg(predictions: Predictions, steps: Dataset) -> np.ndarray:
    """(N, 3) rotation vectors of ``R_pred^T R_meas``, deg, in the predicted tip frame."""
    return np.degrees(body_rotation_error(matrix_from_quat(predictions.tip_orientation_in_base),
                                          matrix_from_quat(steps.tip_orientation_in_base())))


def position_residuals_mm(predictions: Predictions, steps: Dataset) -> np.ndarray | None:
    """(N, 3) ``p_pred - p_meas``, mm, base frame; None without measured positions."""
    measured = steps.tip_position_in_base_m()
    return None if measured is None else (predictions.tip_position_in_base_m - measured) * 1e3


# --- labels --------------------------------------------------------------------------


def driving_jet_labels(steps: Dataset) -> np.ndarray:
    """The jet driving each step: in a validation sweep (sweep >= 0), the jet with the
    largest total force over the sweep, so its zero-force ends count too; elsewhere the
    step's strongest jet. "jet 1".."jet 3", or "none" when no jet pushes."""
    forces = steps.jet_forces_n
    strongest = np.argmax(forces, axis=1)
    active = forces.max(axis=1) > 0.0
    for sweep in steps.sweep_ids():
        rows = steps.sweep == sweep
        totals = forces[rows].sum(axis=0)
        if totals.max() > 0.0:
            strongest[rows], active[rows] = np.argmax(totals), True
    return np.where(active, np.char.add("jet ", (strongest + 1).astype(str)), "none")


def bend_azimuth_deg(steps: Dataset) -> np.ndarray:
    """Azimuth of the measured tip tangent in the base xy plane, deg in [0, 360)."""
    tangent = matrix_from_quat(steps.tip_orientation_in_base())[:, :, 2]
    return np.degrees(np.arctan2(tangent[:, 1], tangent[:, 0])) % 360.0


def direction_order(width_deg: float = SECTOR_WIDTH_DEG) -> list[str]:
    """Sector labels in order ("0-60", "60-120", ... "300-360"), then "straight"."""
    edges = np.arange(0.0, 360.0 + 0.5 * width_deg, width_deg)
    return [f"{low:g}-{high:g}" for low, high in zip(edges[:-1], edges[1:])] + [STRAIGHT]


def direction_labels(steps: Dataset, width_deg: float = SECTOR_WIDTH_DEG,
                     straight_below_deg: float = STRAIGHT_BELOW_DEG) -> np.ndarray:
    """Each step's bending-direction sector, ``width_deg`` wide from azimuth 0 ("0-60",
    "60-120" ... for 60-degree sectors), or "straight" below ``straight_below_deg`` of
    bend. With the jet ring at angle 0, jets 1, 2 and 3 push towards 30, 270 and 150 deg:
    each single-jet bend lies mid-sector, away from the edges where noise would split it."""
    count = round(360.0 / width_deg)
    sector = np.floor(bend_azimuth_deg(steps) / width_deg).astype(int) % count
    labels = np.array(direction_order(width_deg))
    return np.where(measured_bend_deg(steps) < straight_below_deg, STRAIGHT, labels[sector])


def load_phases(steps: Dataset) -> np.ndarray:
    """"loading", "unloading" or "hold" for each step: whether the total jet force rose
    or fell into it within its sweep (rows sharing a sweep label, in time order; -1 rows
    count as one sequence). A step at the same force keeps the phase before it; a
    sweep's first step takes the phase of the sweep's first change (the start of a ramp
    up is loading); a sweep that never changes is "hold"."""
    total = steps.jet_forces_n.sum(axis=1)
    tolerance = _force_tolerance_n(steps)
    phases = np.full(len(steps), HOLD, dtype=object)
    for sweep in np.unique(steps.sweep):
        rows = np.flatnonzero(steps.sweep == sweep)
        change = np.diff(total[rows])
        sign = np.concatenate([[0.0], np.where(np.abs(change) > tolerance, np.sign(change), 0.0)])
        changed = np.flatnonzero(sign)
        if changed.size == 0:
            continue
        sign[0] = sign[changed[0]]
        last_change = np.maximum.accumulate(np.where(sign != 0.0, np.arange(len(rows)), 0))
        phases[rows] = np.where(sign[last_change] > 0.0, LOADING, UNLOADING)
    return phases.astype(str)


# --- breakdowns ----------------------------------------------------------------------


def loading_split(comparison: Comparison, steps: Dataset) -> LoadingSplit:
    """RMS errors on each branch and the hysteresis gap (see `LoadingSplit`)."""
    phases = load_phases(steps)
    orientation, position = comparison.orientation_error_deg, comparison.position_error_mm

    def summary(phase: str) -> ErrorSummary | None:
        rows = phases == phase
        if not rows.any():
            return None
        return summarise(orientation[rows], None if position is None else position[rows])

    pairs = _matched_pairs(steps, phases)
    gap_deg, gap_mm = hysteresis_gaps(comparison.predictions, steps, pairs)
    return LoadingSplit(summary(LOADING), summary(UNLOADING), len(pairs), gap_deg, gap_mm)


def hysteresis_gaps(predictions: Predictions, steps: Dataset,
                    pairs: np.ndarray | None = None) -> tuple[float | None, float | None]:
    """`LoadingSplit`'s hysteresis gaps (deg, mm; None without matched pairs or measured
    positions) over ``pairs`` (default: `_matched_pairs`). Needs only the predictions, not
    a whole `compare`: a diagnosis asks for it once per candidate."""
    if pairs is None:
        pairs = _matched_pairs(steps, load_phases(steps))
    if not len(pairs):
        return None, None
    residual = orientation_residuals_deg(predictions, steps)
    gap_deg = float(np.mean(np.linalg.norm(residual[pairs[:, 0]] - residual[pairs[:, 1]], axis=1)))
    offsets = position_residuals_mm(predictions, steps)
    gap_mm = (None if offsets is None
              else float(np.mean(np.linalg.norm(offsets[pairs[:, 0]] - offsets[pairs[:, 1]], axis=1))))
    return gap_deg, gap_mm


def drift(orientation_deg: np.ndarray, position_mm: np.ndarray | None, time_s: np.ndarray,
          blocks: int = DEFAULT_TIME_BLOCKS) -> Drift:
    """RMS per block of consecutive steps (``blocks`` blocks of nearly equal counts) and
    the linear trend of the errors against time (see `Drift`)."""
    time_s = np.asarray(time_s, dtype=float)
    parts = [rows for rows in np.array_split(np.arange(len(time_s)), min(blocks, len(time_s))) if len(rows)]
    table = tuple(TimeBlock(float(time_s[rows[0]]), float(time_s[rows[-1]]),
                            summarise(orientation_deg[rows], None if position_mm is None else position_mm[rows]))
                  for rows in parts)
    span_s = float(np.ptp(time_s)) if len(time_s) else 0.0

    def slope(errors: np.ndarray | None) -> float | None:
        if errors is None or not span_s >= MIN_TREND_SPAN_S:
            return None
        # Against time centred and scaled to [-0.5, 0.5]: well conditioned at any clock.
        return float(np.polyfit((time_s - time_s.mean()) / span_s, errors, 1)[0]) / (span_s / 60.0)

    return Drift(table, slope(orientation_deg), slope(position_mm))


def worst_poses(comparison: Comparison, steps: Dataset, count: int = DEFAULT_WORST_COUNT) -> tuple[WorstPose, ...]:
    """The ``count`` steps with the largest orientation error, worst first (ties in time
    order)."""
    errors = comparison.orientation_error_deg
    bend, azimuth = measured_bend_deg(steps), bend_azimuth_deg(steps)
    position = comparison.position_error_mm
    return tuple(
        WorstPose(int(i), int(steps.sweep[i]), int(steps.step[i]), float(steps.time_s[i]),
                  tuple(float(f) for f in steps.jet_forces_n[i]), float(bend[i]), float(azimuth[i]),
                  float(errors[i]), None if position is None else float(position[i]))
        for i in np.argsort(-errors, kind="stable")[:count])


def disturbance_by_sweep(predictions: Predictions, steps: Dataset) -> dict:
    """The disturbance moment used at each step, per sweep: what an online estimate had
    to add to explain the measurements ({sweep: {"step", "moment_nm" (n, 3), "norm_nm",
    "mean_norm_nm", "peak_norm_nm"}}, N m, tip frame)."""
    moment = predictions.disturbance_moment_nm
    norm = np.linalg.norm(moment, axis=1)
    result = {}
    for sweep in np.unique(steps.sweep):
        rows = steps.sweep == sweep
        result[int(sweep)] = {"step": steps.step[rows].tolist(), "moment_nm": moment[rows].tolist(),
                              "norm_nm": norm[rows].tolist(), "mean_norm_nm": float(np.mean(norm[rows])),
                              "peak_norm_nm": float(np.max(norm[rows]))}
    return result


def per_step(comparison: Comparison, steps: Dataset) -> dict:
    """Per-step series for plotting elsewhere (lists, JSON-ready): time, labels, measured
    bend and azimuth, errors and residual vectors, the disturbance moment used."""
    position_residual = position_residuals_mm(comparison.predictions, steps)
    return {
        "time_s": steps.time_s.tolist(), "sweep": steps.sweep.tolist(), "step": steps.step.tolist(),
        "bend_deg": measured_bend_deg(steps).tolist(), "azimuth_deg": bend_azimuth_deg(steps).tolist(),
        "orientation_error_deg": comparison.orientation_error_deg.tolist(),
        "orientation_residual_deg": orientation_residuals_deg(comparison.predictions, steps).tolist(),
        "position_error_mm": None if comparison.position_error_mm is None else comparison.position_error_mm.tolist(),
        "position_residual_mm": None if position_residual is None else position_residual.tolist(),
        "disturbance_moment_nm": comparison.predictions.disturbance_moment_nm.tolist(),
    }


# --- helpers -------------------------------------------------------------------------


def _force_tolerance_n(steps: Dataset) -> float:
    return FORCE_MATCH_FRACTION * float(steps.jet_forces_n.max(initial=0.0)) + 1e-12


def _matched_pairs(steps: Dataset, phases: np.ndarray) -> np.ndarray:
    """(k, 2) row pairs (unloading, loading) in the same sweep at the same jet forces."""
    tolerance = _force_tolerance_n(steps)
    pairs = []
    for sweep in np.unique(steps.sweep):
        in_sweep = steps.sweep == sweep
        loading = np.flatnonzero(in_sweep & (phases == LOADING))
        if loading.size == 0:
            continue
        for row in np.flatnonzero(in_sweep & (phases == UNLOADING)):
            distance = np.abs(steps.jet_forces_n[loading] - steps.jet_forces_n[row]).max(axis=1)
            nearest = int(np.argmin(distance))
            if distance[nearest] <= tolerance:
                pairs.append((row, loading[nearest]))
    return np.array(pairs, dtype=int).reshape(-1, 2)


def _present(labels: np.ndarray, order: list[str]) -> list[str]:
    return [label for label in order if np.any(labels == label)]


def _ordered(table: dict, order: list[str]) -> dict:
    """``table`` with its keys in ``order``."""
    return {key: table[key] for key in sorted(table, key=order.index)}
