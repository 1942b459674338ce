"""The study summary's words when nothing could be diagnosed."""

from __future__ import annotations

import pandas as pd

from hydrojet_bench.studies.report import summary_markdown


def test_a_study_whose_cells_all_failed_says_so_without_a_nan_average():
    rows = pd.DataFrame({"error": ["ValueError: x", "ValueError: y"], "seconds": [1.0, 2.0],
                         "kind": ["sweep", "none"], "detected": [None, None], "scenario": ["a", "b"],
                         "seed": [0, 0], "plan": ["short", "short"], "model": ["cosserat", "cosserat"]})
    text = summary_markdown(rows)
    assert "2 cells: 0 diagnosed, 2 failed." in text
    assert "nan" not in text.lower()
