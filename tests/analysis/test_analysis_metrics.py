"""Error metrics and breakdowns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hydrojet_bench.analysis.metrics import bend_bin_labels, breakdown, summarise
from hydrojet_bench.geometry import position_error_mm, quat_from_rotvec, rotation_angle_deg


def test_orientation_and_position_errors():
    measured = quat_from_rotvec(np.zeros((3, 3)))
    predicted = quat_from_rotvec(np.array([[math.radians(2), 0, 0], [0, math.radians(5), 0], [0, 0, 0]]))
    np.testing.assert_allclose(rotation_angle_deg(predicted, measured), [2.0, 5.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(position_error_mm([[0, 0, 0.001]], [[0, 0, 0]]), [1.0])
    assert position_error_mm([0.003, 0.0, 0.0], [0.0, 0.004, 0.0]) == pytest.approx(5.0)


def test_summary_is_rms_and_sd():
    summary = summarise(np.array([3.0, 4.0]), np.array([1.0, 1.0]))
    assert summary.orientation_rmse_deg == pytest.approx(math.sqrt(12.5))
    assert summary.orientation_sd_deg == pytest.approx(0.5)
    assert summary.position_rmse_mm == pytest.approx(1.0) and summary.position_sd_mm == pytest.approx(0.0)
    assert summarise(np.array([1.0])).position_rmse_mm is None
    with pytest.raises(ValueError, match="no samples"):
        summarise(np.array([]))


def test_bend_bins_follow_table_2():
    labels = bend_bin_labels(np.array([0.0, 10.0, 10.1, 25.0, 49.9, 75.0, 120.0]))
    assert labels.tolist() == ["10", "10", "25", "25", "50", "75", ">75"]


def test_breakdown_groups_by_label():
    orientation = np.array([1.0, 3.0, 5.0])
    table = breakdown(orientation, None, np.array([0, 1, 1]))
    assert list(table) == [0, 1]
    assert table[1].count == 2 and table[1].orientation_rmse_deg == pytest.approx(math.sqrt(17.0))
