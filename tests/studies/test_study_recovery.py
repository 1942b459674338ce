"""The recovery table (issue 12, item 6): where an effect was detected, the share of
cells whose true value lies within 2 standard errors."""

from __future__ import annotations

import pandas as pd

from hydrojet_bench.studies.report import recovery_table


def test_coverage_counts_detected_cells_within_two_standard_errors_only():
    rows = pd.DataFrame({
        "parameter": ["a.x"] * 4 + ["b.y"] * 2,
        "detected": [True, True, True, False, True, True],
        "recovery_z": [0.5, -1.9, 2.5, 0.0, None, 3.0],
    })
    table = recovery_table(rows).set_index("parameter")
    # a.x: 2 of its 3 detected cells within 2 SE (the undetected one does not count).
    assert table.loc["a.x", "coverage_2se"] == 2 / 3 and table.loc["a.x", "cells"] == 3
    # b.y: the cell without a fit does not count.
    assert table.loc["b.y", "coverage_2se"] == 0.0 and table.loc["b.y", "cells"] == 1
