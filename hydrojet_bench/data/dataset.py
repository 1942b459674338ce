"""`Dataset`: the one in-memory form of measurement data every analysis command consumes.

A dataset is a time series of samples from one rig. Each sample holds the commanded jet
forces and the measured orientations (and optionally positions) of the base and tip
sensors in the *tracker frame*, labelled with a sweep and a step, plus flags saying what
is wrong with it, if anything. The `RigProfile` it was recorded with travels along: it
says where the sensors sit on their bodies and where gravity points, which is what turns
sensor readings into the model's base-frame quantities (`tip_orientation_in_base`,
`tip_position_in_base_m`, `gravity_in_base_m_s2`).

Labels: ``sweep`` is -1 for calibration (or unlabelled) rows and 0, 1, 2 ... for
validation sweeps; ``step`` numbers the quasistatic commands (one jet-force setting held
for a while). `quasistatic_steps` reduces each step to one settled row.

Flags (`SampleFlag`) are problems, so 0 is a good sample; nothing is ever dropped on
load, and analysis picks its rows with `valid_mask` / `valid_rows`.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..geometry import quat_conjugate, quat_multiply, quat_rotate
from ..params import MAX_PLAUSIBLE_POSITION_M, ModelParameters
from ..profile import RigProfile

# Orientations are unit quaternions to within this (a tracker's or a filter's output,
# perhaps printed with 6 digits); they are renormalised on construction.
QUATERNION_NORM_TOLERANCE = 1e-3

# Plausible magnitudes. A finite value past them is an input error (a unit slip, a
# corrupt cell), and the largest overflow the step averages and frame arithmetic to inf.
# Positions use the profiles' limit, `params.MAX_PLAUSIBLE_POSITION_M`.
MAX_ABS_TIME_S = 1e10  # a Unix time up to the year 2286; session times are far smaller
MAX_JET_FORCE_N = 100.0  # the bench's water jets deliver well under 1 N


class RowError(ValueError):
    """A row of a `Dataset` field that breaks its contract. ``field``, ``row`` (0-based)
    and ``problem`` apart, for a reader whose rows came from elsewhere (a log's
    messages) to name where in its own input the row is."""

    def __init__(self, field: str, row: int, problem: str, separator: str = " ") -> None:
        super().__init__(f"Dataset.{field} row {row}{separator}{problem}")
        self.field, self.row, self.problem, self.separator = field, row, problem, separator


class SampleFlag(enum.IntFlag):
    """What is wrong with one sample; ``SampleFlag(0)`` (``NONE``) is a good sample.

    There is no "VALID" bit: validity is the absence of the problems in `UNUSABLE`
    (see `Dataset.valid_mask`). When a sensor is missing, its pose arrays still hold a
    finite unit quaternion (the last good value, held), so every array stays usable
    by plain numpy code; the flag says not to trust it.

    BASE_MISSING: the base sensor was not seen (tracker dropout, IMU read failure).
    TIP_MISSING: the tip sensor was not seen.
    OUT_OF_VOLUME: the tracker reported a sensor (partly) outside its measurement
        volume; the pose is reported but less accurate.
    SATURATED: a commanded jet force is above the profile's ``max_jet_force_n``: the
        valve clips it, so the force the rod felt is not the one recorded. Derived from
        the profile when a CSV is read.
    UNSETTLED: a row of `Dataset.quasistatic_steps` whose tip was still turning within
        its averaging window (`UNSETTLED_TREND_DEG`): no equilibrium, which a
        quasistatic model reads as its own error. Kept, and said by the analysis
        commands.
    """

    NONE = 0
    BASE_MISSING = 1
    TIP_MISSING = 2
    OUT_OF_VOLUME = 4
    SATURATED = 8
    UNSETTLED = 16


# The last seconds of a step that the analysis averages into its settled state.
STEP_WINDOW_S = 1.0
# `SampleFlag.UNSETTLED`: the tip turned more than this across a step's averaging window
# (a line fitted to its orientation over time), at more than UNSETTLED_SIGNIFICANCE
# standard errors of the samples' scatter. The twin's rod (settling time constant 0.5 s)
# turns some 0.03 deg in the last second of a 5 s hold after a 90 deg change, and 40 %
# of the change in a 0.3 s step; half the turn biases the step's mean.
UNSETTLED_TREND_DEG = 0.25
UNSETTLED_SIGNIFICANCE = 5.0

# Flags that make a sample unfit for calibration and comparison by default.
UNUSABLE = SampleFlag.BASE_MISSING | SampleFlag.TIP_MISSING | SampleFlag.OUT_OF_VOLUME | SampleFlag.SATURATED
_ALL_FLAGS = int(UNUSABLE | SampleFlag.UNSETTLED)


def saturation_flags(jet_forces_n: ArrayLike, profile: RigProfile) -> NDArray[np.int64]:
    """`SampleFlag.SATURATED` where any jet force exceeds the profile's limit, else 0."""
    forces = np.asarray(jet_forces_n, dtype=float)
    over = np.any(forces > np.asarray(profile.max_jet_force_n), axis=-1)
    return np.where(over, int(SampleFlag.SATURATED), 0).astype(np.int64)


def steps_from_runs(sweep: ArrayLike, jet_forces_n: ArrayLike) -> NDArray[np.int64]:
    """Step labels for data without them: a new step starts whenever the sweep label or
    any jet force changes; steps are numbered 0, 1, 2 ... in time order."""
    sweep = np.asarray(sweep)
    forces = np.asarray(jet_forces_n, dtype=float)
    if len(sweep) == 0:
        return np.zeros(0, dtype=np.int64)
    change = (sweep[1:] != sweep[:-1]) | np.any(forces[1:] != forces[:-1], axis=-1)
    return np.concatenate([[0], np.cumsum(change)]).astype(np.int64)


def average_quaternions(quaternions: ArrayLike, weights: ArrayLike | None = None) -> NDArray[np.float64]:
    """Mean rotation of unit quaternions (n, 4) by Markley's method (Markley, Cheng,
    Crassidis, Oshman 2007): the principal eigenvector of ``sum w_i q_i q_i^T``. It is
    blind to the sign of each q_i, as a rotation average must be. The result's sign is
    chosen to agree with the last quaternion."""
    q = np.asarray(quaternions, dtype=float)
    if q.ndim != 2 or q.shape[1] != 4 or len(q) == 0:
        raise ValueError(f"average_quaternions needs an (n, 4) array with n >= 1, got shape {q.shape}")
    w = np.ones(len(q)) if weights is None else np.asarray(weights, dtype=float)
    return _average_groups(q, np.zeros(len(q), dtype=np.int64), 1, w)[0]


def turning_steps(time_s: np.ndarray, orientation: np.ndarray, group: np.ndarray,
                  mean_orientation: np.ndarray) -> np.ndarray:
    """The groups (steps) whose orientation (w, x, y, z) turns over time: a line fitted to
    each sample's rotation from its group's mean (``mean_orientation``, one row per
    group) against time turns more than `UNSETTLED_TREND_DEG` across the group's time
    span, at more than `UNSETTLED_SIGNIFICANCE` standard errors of the line's scatter.
    Groups of fewer than three samples have no scatter to judge and are never turning.
    Returns a boolean mask over the groups."""
    groups = len(mean_orientation)
    count = np.bincount(group, minlength=groups).astype(float)
    # Rotation from the mean, small: twice the vector part of mean^-1 q, w made positive.
    relative = quat_multiply(quat_conjugate(mean_orientation[group]), orientation)
    vector = 2.0 * relative[:, 1:] * np.where(relative[:, :1] < 0.0, -1.0, 1.0)

    def sums(values: np.ndarray) -> np.ndarray:
        return np.bincount(group, weights=values, minlength=groups)

    with np.errstate(invalid="ignore", divide="ignore"):
        centred = time_s - (sums(time_s) / count)[group]
        spread = sums(centred**2)
        slopes = np.stack([sums(centred * vector[:, k]) / spread for k in range(3)], axis=1)
        # Scatter about the lines, pooled over the three components.
        residual = sum(sums(vector[:, k]**2) - slopes[:, k]**2 * spread - sums(vector[:, k])**2 / count
                       for k in range(3))
        variance = np.maximum(residual, 0.0) / (3.0 * (count - 2.0))
        span = np.maximum.reduceat(time_s, _starts(group)) - np.minimum.reduceat(time_s, _starts(group))
        turn = np.linalg.norm(slopes, axis=1) * span
        significant = np.linalg.norm(slopes, axis=1) > UNSETTLED_SIGNIFICANCE * np.sqrt(variance / spread)
    return (count >= 3) & (turn > np.radians(UNSETTLED_TREND_DEG)) & significant


def _starts(group: np.ndarray) -> np.ndarray:
    """The first index of each group in ``group`` (consecutive, sorted, every group present)."""
    return np.flatnonzero(np.r_[True, group[1:] != group[:-1]])


def _average_groups(q: np.ndarray, group: np.ndarray, groups: int, weights: np.ndarray) -> np.ndarray:
    """Markley average per group: q (n, 4), group (n,) in [0, groups) -> (groups, 4).
    The sign of each mean follows the group's last quaternion (continuity in time)."""
    scatter = np.zeros((groups, 4, 4))
    np.add.at(scatter, group, weights[:, None, None] * q[:, :, None] * q[:, None, :])
    _, vectors = np.linalg.eigh(scatter)
    mean = vectors[:, :, -1]
    last = np.zeros((groups, 4))
    last[group] = q  # later rows overwrite earlier ones: the last of each group remains
    sign = np.where(np.sum(mean * last, axis=1) < 0.0, -1.0, 1.0)
    return mean * sign[:, None]


def _float_array(name: str, value: ArrayLike, shape_tail: tuple[int, ...], rows: int | None,
                 limit: float = np.inf, unit: str = "") -> np.ndarray:
    """``value`` as floats of shape (rows,) + ``shape_tail``, finite and within ``limit``
    (in ``unit``) in magnitude, or ValueError naming the field and the first bad row."""
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"Dataset.{name} must be numeric") from None
    expected = ("N",) + shape_tail
    if array.ndim != 1 + len(shape_tail) or array.shape[1:] != shape_tail:
        raise ValueError(f"Dataset.{name} must have shape {expected}, got {array.shape}")
    if rows is not None and len(array) != rows:
        raise ValueError(f"Dataset.{name} has {len(array)} rows, time_s has {rows}")
    # Over every axis but the rows: also right for an empty selection (no calibration poses).
    bad = ~np.isfinite(array).all(axis=tuple(range(1, array.ndim)))
    if np.any(bad):
        raise RowError(name, int(np.argmax(bad)), "is not finite")
    beyond = ~(np.abs(array) <= limit).all(axis=tuple(range(1, array.ndim)))
    if np.any(beyond):
        i = int(np.argmax(beyond))
        raise RowError(name, i, f"holds {np.abs(array[i]).max():g} {unit}, past the plausible {limit:g} {unit} in "
                       "magnitude")
    return array


def _int_array(name: str, value: ArrayLike, rows: int) -> np.ndarray:
    array = np.asarray(value)
    if array.shape != (rows,):
        raise ValueError(f"Dataset.{name} must have shape ({rows},), got {array.shape}")
    if array.dtype.kind == "f":
        bad = ~np.isfinite(array) | (array != np.round(array))
        if np.any(bad):
            raise RowError(name, int(np.argmax(bad)), f"is not an integer: {array[np.argmax(bad)]!r}")
    elif array.dtype.kind not in "iub":
        raise ValueError(f"Dataset.{name} must be integers, got dtype {array.dtype}")
    return array.astype(np.int64)


def _frozen(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Dataset:
    """Measurement samples of one rig, in time order. N rows; every array has N rows.

    time_s: (N,) s, non-decreasing.
    jet_forces_n: (N, 3) commanded jet forces q1, q2, q3, N.
    base_orientation, tip_orientation: (N, 4) sensor orientations in the tracker frame,
        unit quaternions (w, x, y, z) mapping sensor-frame vectors into the tracker frame.
        Accepted within 1e-3 of unit norm and stored renormalised (signs untouched).
    base_position_m, tip_position_m: (N, 3) sensor origins in the tracker frame, m, or
        None when not measured (IMUs measure orientation only).
    sweep: (N,) int, -1 for calibration or unlabelled rows, else a sweep number >= 0.
    step: (N,) int, the quasistatic step; None derives it with `steps_from_runs`.
    flags: (N,) int, bitwise `SampleFlag`; None means all good.
    samples: (N,) int >= 1, how many recorded samples each row averages (set by
        `quasistatic_steps`); None for rows that are samples themselves.
    profile: the rig profile the data was recorded with.
    source: where the data came from (a file name, "twin seed 3", ...).

    Construction validates shapes, finiteness, unit quaternions and time order and
    raises ValueError naming the field and the (0-based) row. Arrays are read-only.
    """

    time_s: NDArray[np.float64]
    jet_forces_n: NDArray[np.float64]
    base_orientation: NDArray[np.float64]
    tip_orientation: NDArray[np.float64]
    profile: RigProfile
    base_position_m: NDArray[np.float64] | None = None
    tip_position_m: NDArray[np.float64] | None = None
    sweep: NDArray[np.int64] | None = None
    step: NDArray[np.int64] | None = None
    flags: NDArray[np.int64] | None = None
    source: str = ""
    samples: NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.profile, RigProfile):
            raise ValueError(f"Dataset.profile must be a RigProfile, got {type(self.profile).__name__}")
        time = _float_array("time_s", self.time_s, (), None, MAX_ABS_TIME_S, "s")
        rows = len(time)
        backwards = np.diff(time) < 0.0
        if np.any(backwards):
            i = int(np.argmax(backwards)) + 1
            raise RowError("time_s", i, f"time goes backwards ({float(time[i])!r} s after {float(time[i - 1])!r} s)",
                           separator=": ")
        arrays: dict[str, np.ndarray | None] = {"time_s": time}
        arrays["jet_forces_n"] = _float_array("jet_forces_n", self.jet_forces_n, (3,), rows, MAX_JET_FORCE_N, "N")
        for name in ("base_orientation", "tip_orientation"):
            q = _float_array(name, getattr(self, name), (4,), rows)
            norm = np.linalg.norm(q, axis=1)
            bad = np.abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE
            if np.any(bad):
                i = int(np.argmax(bad))
                raise RowError(name, i, f"is not a unit quaternion (norm {norm[i]:.6g})")
            # Leave unit-norm data bit-identical (so CSV round trips are exact).
            arrays[name] = q / np.where(np.abs(norm - 1.0) > 1e-12, norm, 1.0)[:, None]
        for name in ("base_position_m", "tip_position_m"):
            value = getattr(self, name)
            arrays[name] = None if value is None else _float_array(name, value, (3,), rows, MAX_PLAUSIBLE_POSITION_M, "m")
        sweep = np.full(rows, -1, dtype=np.int64) if self.sweep is None else _int_array("sweep", self.sweep, rows)
        if np.any(sweep < -1):
            i = int(np.argmax(sweep < -1))
            raise RowError("sweep", i, f"is {sweep[i]}; sweeps are >= 0, or -1 for calibration/unlabelled")
        arrays["sweep"] = sweep
        assert arrays["jet_forces_n"] is not None
        arrays["step"] = (steps_from_runs(sweep, arrays["jet_forces_n"]) if self.step is None
                          else _int_array("step", self.step, rows))
        flags = np.zeros(rows, dtype=np.int64) if self.flags is None else _int_array("flags", self.flags, rows)
        unknown = (flags & ~_ALL_FLAGS) != 0
        if np.any(unknown | (flags < 0)):
            i = int(np.argmax(unknown | (flags < 0)))
            raise RowError("flags", i, f"has unknown bits: {flags[i]} (known: "
                           f"{', '.join(f'{f.name}={f.value}' for f in SampleFlag if f.value)})")
        arrays["flags"] = flags
        if self.samples is not None:
            samples = _int_array("samples", self.samples, rows)
            if np.any(samples < 1):
                i = int(np.argmax(samples < 1))
                raise RowError("samples", i, f"is {samples[i]}; a row averages at least one sample")
            arrays["samples"] = samples
        for name, array in arrays.items():
            object.__setattr__(self, name, None if array is None else _frozen(array))
        object.__setattr__(self, "source", str(self.source))

    # --- size and selection --------------------------------------------------------

    def __len__(self) -> int:
        return len(self.time_s)

    def __repr__(self) -> str:
        return (f"Dataset({len(self)} rows, {len(self.sweep_ids())} sweeps, "
                f"{int(np.sum(self.sweep == -1))} calibration rows, profile {self.profile.name!r}, "
                f"source {self.source!r})")

    @property
    def has_positions(self) -> bool:
        """True when both sensors' positions were measured."""
        return self.base_position_m is not None and self.tip_position_m is not None

    def select(self, rows: ArrayLike) -> Dataset:
        """The rows picked by a boolean mask (N,) or by integer indices (in time order)."""
        index = np.asarray(rows)
        if index.dtype == bool and index.shape != (len(self),):
            raise ValueError(f"select: boolean mask must have shape ({len(self)},), got {index.shape}")
        if index.dtype != bool and index.dtype.kind not in "iu":
            raise ValueError(f"select takes a boolean mask or integer indices, got dtype {index.dtype}")

        def pick(array: np.ndarray | None) -> np.ndarray | None:
            return None if array is None else array[index]

        return replace(self, time_s=self.time_s[index], jet_forces_n=self.jet_forces_n[index],
                       base_orientation=self.base_orientation[index],
                       tip_orientation=self.tip_orientation[index],
                       base_position_m=pick(self.base_position_m), tip_position_m=pick(self.tip_position_m),
                       sweep=self.sweep[index], step=self.step[index], flags=self.flags[index],
                       samples=pick(self.samples))

    @classmethod
    def concatenate(cls, parts: Sequence[Dataset]) -> Dataset:
        """The rows of ``parts`` (same profile, in time order) as one dataset; each
        sensor's positions are kept only if every part has them."""
        if not parts:
            raise ValueError("concatenate needs at least one dataset")

        def join(name: str) -> np.ndarray | None:
            arrays = [getattr(part, name) for part in parts]
            return None if any(array is None for array in arrays) else np.concatenate(arrays)

        return replace(parts[0], time_s=join("time_s"), jet_forces_n=join("jet_forces_n"),
                       base_orientation=join("base_orientation"), tip_orientation=join("tip_orientation"),
                       base_position_m=join("base_position_m"), tip_position_m=join("tip_position_m"),
                       sweep=join("sweep"), step=join("step"), flags=join("flags"), samples=join("samples"))

    def calibration_rows(self) -> Dataset:
        """Rows with sweep -1 (calibration or unlabelled)."""
        return self.select(self.sweep == -1)

    def sweep_ids(self) -> tuple[int, ...]:
        """The validation sweep numbers present (>= 0), ascending."""
        return tuple(int(s) for s in np.unique(self.sweep[self.sweep >= 0]))

    def sweep_rows(self, sweep: int) -> Dataset:
        """Rows of one sweep."""
        if sweep not in self.sweep_ids() and sweep != -1:
            raise KeyError(f"no sweep {sweep} in {self.source or 'dataset'}; sweeps: {self.sweep_ids()}")
        return self.select(self.sweep == sweep)

    def sweeps(self) -> dict[int, Dataset]:
        """Each validation sweep (>= 0) as its own dataset, by sweep number."""
        return {sweep: self.select(self.sweep == sweep) for sweep in self.sweep_ids()}

    def valid_mask(self, exclude: int = UNUSABLE) -> NDArray[np.bool_]:
        """Rows carrying none of the ``exclude`` flags (default: every problem flag)."""
        return (self.flags & int(exclude)) == 0

    def valid_rows(self, exclude: int = UNUSABLE) -> Dataset:
        return self.select(self.valid_mask(exclude))

    def flag_counts(self) -> dict[str, int]:
        """How many rows carry each flag (for reporting what analysis left out)."""
        return {flag.name: int(np.sum((self.flags & flag.value) != 0)) for flag in SampleFlag
                if flag.value and flag.name}

    def step_runs(self) -> Iterator[tuple[int, int]]:
        """(start, stop) row ranges of the contiguous runs of equal (sweep, step)."""
        if len(self) == 0:
            return
        change = (self.sweep[1:] != self.sweep[:-1]) | (self.step[1:] != self.step[:-1])
        edges = np.concatenate([[0], np.flatnonzero(change) + 1, [len(self)]])
        for start, stop in zip(edges[:-1], edges[1:]):
            yield int(start), int(stop)

    # --- frames ----------------------------------------------------------------------

    def tip_relative_to_base(self) -> NDArray[np.float64]:
        """(N, 4) orientation of the tip sensor relative to the base sensor,
        ``conj(q_base) * q_tip``: the raw reading of the paper's eq. 24. It equals a
        model's `Solution.tip_sensor_in_base_sensor()` only if the model's mounting
        rotations are the profile's; to compare with a model that has no mounting
        effect, use `tip_orientation_in_base`, which removes the profile's mountings."""
        return quat_multiply(quat_conjugate(self.base_orientation), self.tip_orientation)

    def clamp_orientation(self) -> NDArray[np.float64]:
        """(N, 4) clamp (base frame) orientation in the tracker frame, from the base sensor
        and the profile's base mounting."""
        return self.profile.clamp_orientation_in_tracker(self.base_orientation)

    def tip_orientation_in_base(self) -> NDArray[np.float64]:
        """(N, 4) orientation of the rod's tip frame in the base frame, the sensors'
        mountings removed: comparable with a model's ``tip_pose_in_base`` rotation.
        ``q = m_base * conj(q_base) * q_tip * conj(m_tip)``."""
        tip_body = self.profile.tip_sensor.body_orientation(self.tip_orientation)
        return quat_multiply(quat_conjugate(self.clamp_orientation()), tip_body)

    def tip_position_in_base_m(self) -> NDArray[np.float64] | None:
        """(N, 3) position of the rod tip (s = L) in the base frame, m, the sensors'
        offsets removed (using the measured orientations); None without positions.
        Comparable with a model's ``tip_pose_in_base`` translation."""
        if not self.has_positions:
            return None
        clamp = self.clamp_orientation()
        clamp_origin = self.profile.base_sensor.body_position_m(self.base_orientation, self.base_position_m)
        tip_origin = self.profile.tip_sensor.body_position_m(self.tip_orientation, self.tip_position_m)
        return quat_rotate(quat_conjugate(clamp), tip_origin - clamp_origin)

    def gravity_in_base_m_s2(self) -> NDArray[np.float64]:
        """(N, 3) gravity in the base frame at each sample, m/s^2, from the measured base
        orientation: what `ModelParameters.gravity_in_base_m_s2` should be for that row
        (``profile.model_parameters(dataset.base_orientation[i])``)."""
        return self.profile.gravity_in_base_m_s2(self.base_orientation)

    def model_parameters(self, row: int, **changes: object) -> ModelParameters:
        """`ModelParameters` for one row: the profile's, with gravity in the base frame
        from that row's base sensor orientation (``changes`` as in
        `RigProfile.model_parameters`)."""
        return self.profile.model_parameters(self.base_orientation[row], **changes)

    # --- quasistatic reduction ---------------------------------------------------------

    def quasistatic_steps(self, window_s: float | None = STEP_WINDOW_S, exclude: int = UNUSABLE) -> Dataset:
        """One row per contiguous (sweep, step) run: its settled state.

        Each step is averaged over the samples in its last ``window_s`` seconds (None:
        all of them), skipping samples with an ``exclude`` flag: orientations by the
        Markley eigenvector mean (`average_quaternions`), forces and positions by the
        arithmetic mean. The row's time is that of the last sample used. If every
        sample in a step's window is flagged, they are all used and the row keeps the
        union of their flags (so `valid_mask` leaves it out); otherwise the row keeps
        the union of the flags of the samples used. ``samples`` counts the recorded
        samples each row averages (the rows' own counts summed, if they are averages).
        A step whose tip was still turning in its window gets `SampleFlag.UNSETTLED`
        (`turning_steps`).
        """
        if window_s is not None and not (np.isfinite(window_s) and window_s >= 0):
            raise ValueError(f"window_s must be >= 0 s or None, got {window_s!r}")
        used: list[np.ndarray] = []
        for start, stop in self.step_runs():
            rows = np.arange(start, stop)
            if window_s is not None:
                rows = rows[self.time_s[rows] >= self.time_s[stop - 1] - window_s]
            good = rows[(self.flags[rows] & int(exclude)) == 0]
            used.append(good if len(good) else rows)
        groups = len(used)
        if groups == 0:
            return self
        index = np.concatenate(used)
        group = np.repeat(np.arange(groups), [len(u) for u in used])
        counts = np.array([len(u) for u in used], dtype=float)
        samples = (counts.astype(np.int64) if self.samples is None
                   else np.bincount(group, weights=self.samples[index], minlength=groups).astype(np.int64))
        last = np.array([u[-1] for u in used])

        def mean(array: np.ndarray | None) -> np.ndarray | None:
            if array is None:
                return None
            total = np.zeros((groups,) + array.shape[1:])
            np.add.at(total, group, array[index])
            return total / counts[:, None]

        weights = np.ones(len(index))
        flags = np.zeros(groups, dtype=np.int64)
        np.bitwise_or.at(flags, group, self.flags[index])
        if self.samples is None:  # samples, not averages: their scatter is the noise
            # The tip relative to the base: a base that moves with the rig is no motion of the rod.
            tip_in_base = quat_multiply(quat_conjugate(self.base_orientation[index]), self.tip_orientation[index])
            turning = turning_steps(self.time_s[index], tip_in_base, group,
                                    _average_groups(tip_in_base, group, groups, weights))
            flags[turning] |= int(SampleFlag.UNSETTLED)
        window = "all samples" if window_s is None else f"last {window_s:g} s"
        return Dataset(
            time_s=self.time_s[last],
            jet_forces_n=mean(self.jet_forces_n),  # type: ignore[arg-type]
            base_orientation=_average_groups(self.base_orientation[index], group, groups, weights),
            tip_orientation=_average_groups(self.tip_orientation[index], group, groups, weights),
            base_position_m=mean(self.base_position_m),
            tip_position_m=mean(self.tip_position_m),
            sweep=self.sweep[last],
            step=self.step[last],
            flags=flags,
            profile=self.profile,
            source=f"{self.source} (quasistatic: {window} of each step)",
            samples=samples,
        )
