"""Calibrated numbers that smell of a setup error rather than of the rod.

A calibration absorbs a miswired or misdescribed rig into whatever parameter can take
it: a ring angle pushed to its limit (the jets wired one position round are a
120-degree turn of the ring), a weight scale far from 1 (a wrong capsule mass, forces in
the wrong unit), a stiffness on its bound. `setup_warnings` names the likely mistake.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ..models.shooting import ShootingModel
from .calibration import CalibrationResult, parameter_bounds

# A modulus within this share of its (logarithmic) range from a bound sits on it.
ON_BOUND_SHARE = 0.02
# A weight outside this range is no longer water in the lumens or glue on the capsule.
PLAUSIBLE_WEIGHT_SCALE = (0.7, 1.5)
# A ring turned by more than this is closer to a relabelling of the jets than to a
# capsule glued on askew.
RING_ANGLE_SUSPECT_DEG = 25.0
# The parameters whose place on a bound these warnings explain (a wider margin than
# `calibration.BOUND_SHARE`, with the likely setup error).
BOUND_CHECKED = ("E0", "EL")


def setup_warnings(names: tuple[str, ...], values: tuple[float, ...],
                   bounds: Callable[[str], tuple[float, float]]) -> list[str]:
    """One line per suspicious fitted value; ``bounds(name)`` gives a parameter's bounds."""
    fitted = dict(zip(names, values))
    warnings = []
    ring = fitted.get("jet_misalignment.ring_angle_rad")
    if ring is not None and abs(math.degrees(ring)) >= RING_ANGLE_SUSPECT_DEG:
        warnings.append(f"jet ring angle {math.degrees(ring):+.1f} deg, near its limit: the jets may be wired one "
                        "position round (a 120 deg turn of the ring); run's wiring check or diagnose names the "
                        "wiring")
    weight = fitted.get("gravity.weight_scale")
    if weight is not None and not PLAUSIBLE_WEIGHT_SCALE[0] <= weight <= PLAUSIBLE_WEIGHT_SCALE[1]:
        warnings.append(f"weight scale {weight:.2f}, far from 1: check capsule.mass_kg and rod.density_kg_m3, "
                        "the jet forces' unit (N), and whether the tracker is level (gravity.in_tracker_m_s2)")
    for name in BOUND_CHECKED:
        if name in fitted:
            lower, upper = bounds(name)
            # Moduli span decades: their bounds are judged on a log scale.
            share = math.log(max(fitted[name], lower) / lower) / math.log(upper / lower)
            if share <= ON_BOUND_SHARE or share >= 1.0 - ON_BOUND_SHARE:
                warnings.append(f"{name} = {fitted[name]:.4g} Pa sits on its bound: the jet forces may be in the "
                                "wrong unit, or the jets miswired; diagnose names setup errors")
    return warnings


def calibration_warnings(model: ShootingModel, result: CalibrationResult) -> list[str]:
    """What ``model``'s calibration ``result`` must not keep quiet (what `calibrate` and a
    session's own calibration show): too few poses, an unconverged fit, a value on its
    bound, and `setup_warnings`."""
    warnings = []
    if 0 < result.poses < len(result.names):
        # Each pose adds a few residual rows, but poses alike (one jet at a time) pin few
        # directions: two poses for nine parameters ended with E0 on its bound.
        warnings.append(f"only {result.poses} poses for {len(result.names)} parameters: too few to tell them apart "
                        "(the paper fits 40), so what follows may be that alone")
    if not result.converged:
        warnings.append(f"the fit is {result.convergence}: these values are not an optimum; check the profile's "
                        "starting values, or diagnose the data")
    for name, value in zip(result.names, result.values):
        if name in result.at_bound and name not in BOUND_CHECKED:
            lower, upper = parameter_bounds(model, name)
            warnings.append(f"{name} = {value:.6g} sits on its bound ({lower:g} to {upper:g}): the data push it past "
                            "what it may take, so the model misses something it was made to absorb; diagnose looks "
                            "for it")
    return warnings + setup_warnings(result.names, tuple(result.values), lambda name: parameter_bounds(model, name))
