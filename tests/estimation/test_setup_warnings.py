"""Calibrated values that smell of a setup error get a warning naming the likely mistake."""

from __future__ import annotations

import math

from hydrojet_bench.estimation.calibration import CORE_BOUNDS
from hydrojet_bench.estimation.setup_warnings import setup_warnings


def _bounds(name):
    return CORE_BOUNDS[name]


def test_nominal_values_raise_no_warning():
    names = ("E0", "EL", "gravity.weight_scale", "jet_misalignment.ring_angle_rad")
    assert setup_warnings(names, (3e5, 2e5, 1.1, math.radians(5.0)), _bounds) == []


def test_each_smell_names_its_mistake():
    (ring,) = setup_warnings(("jet_misalignment.ring_angle_rad",), (math.radians(-29.0),), _bounds)
    assert "wired one position round" in ring and "-29.0 deg" in ring
    (weight,) = setup_warnings(("gravity.weight_scale",), (2.4,), _bounds)
    assert "weight scale 2.40" in weight and "unit" in weight
    (modulus,) = setup_warnings(("E0", "EL"), (1.05e3, 2e5), _bounds)
    assert modulus.startswith("E0 = 1050 Pa sits on its bound")
