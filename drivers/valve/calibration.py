"""Jet force -> valve duty: a per-jet calibration curve given as data.

Each jet's steady tip force grows monotonically with its valve's PWM duty, but not
linearly (solenoid dead band, pressure drop). A bench calibration measures a table of
(force_n, duty_permille) points; `JetCalibration` interpolates it linearly and clamps to
its ends, so a request beyond the table gets the table's limit, never an extrapolated
duty.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Iterable
from dataclasses import dataclass

from drivers.valve.protocol import DUTY_MAX_PERMILLE


@dataclass(frozen=True)
class JetCalibration:
    """force_n: jet force at the tip (N), strictly increasing, finite, >= 0.
    duty_permille: the valve duty (0..1000) producing each force, non-decreasing.

    Raises ValueError naming the offending field.
    """

    force_n: tuple[float, ...]
    duty_permille: tuple[int, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "force_n", tuple(float(f) for f in self.force_n))
        object.__setattr__(self, "duty_permille", tuple(self.duty_permille))
        if len(self.force_n) < 2:
            raise ValueError(f"JetCalibration.force_n needs at least 2 points, got {len(self.force_n)}")
        if len(self.duty_permille) != len(self.force_n):
            raise ValueError(
                f"JetCalibration.duty_permille has {len(self.duty_permille)} points, "
                f"force_n has {len(self.force_n)}"
            )
        if not all(math.isfinite(f) and f >= 0.0 for f in self.force_n):
            raise ValueError(f"JetCalibration.force_n must be finite and >= 0 N, got {self.force_n}")
        if any(b <= a for a, b in zip(self.force_n, self.force_n[1:])):
            raise ValueError(f"JetCalibration.force_n must be strictly increasing, got {self.force_n}")
        for d in self.duty_permille:
            if isinstance(d, bool) or not isinstance(d, int) or not 0 <= d <= DUTY_MAX_PERMILLE:
                raise ValueError(
                    f"JetCalibration.duty_permille must be ints in 0..{DUTY_MAX_PERMILLE}, "
                    f"got {self.duty_permille}"
                )
        if any(b < a for a, b in zip(self.duty_permille, self.duty_permille[1:])):
            raise ValueError(
                f"JetCalibration.duty_permille must be non-decreasing, got {self.duty_permille}"
            )

    @classmethod
    def from_points(cls, points: Iterable[tuple[float, int]]) -> JetCalibration:
        """Build from (force_n, duty_permille) pairs, in increasing force order."""
        pairs = list(points)
        return cls(tuple(f for f, _ in pairs), tuple(d for _, d in pairs))

    @property
    def max_force_n(self) -> float:
        return self.force_n[-1]

    def duty_for_force(self, force_n: float) -> int:
        """Duty (per mille) for a jet force (N): linear between points, clamped to the
        table's first and last duty outside it. NaN raises ValueError."""
        if math.isnan(force_n):
            raise ValueError("force_n is NaN")
        forces, duties = self.force_n, self.duty_permille
        if force_n <= forces[0]:
            return duties[0]
        if force_n >= forces[-1]:
            return duties[-1]
        i = bisect_right(forces, force_n) - 1
        f0, f1, d0, d1 = forces[i], forces[i + 1], duties[i], duties[i + 1]
        return round(d0 + (d1 - d0) * (force_n - f0) / (f1 - f0))
