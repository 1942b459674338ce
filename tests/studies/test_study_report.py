"""The study summary's words when nothing could be diagnosed."""

from __future__ import annotations

import pandas as pd
import pytest

from hydrojet_bench.studies.report import summary_markdown


def test_a_study_whose_cells_all_failed_says_so_without_a_nan_average():
    rows = pd.DataFrame({"error": ["ValueError: x", "ValueError: y"], "seconds": [1.0, 2.0],
                         "kind": ["sweep", "none"], "detected": [None, None], "scenario": ["a", "b"],
                         "seed": [0, 0], "plan": ["short", "short"], "model": ["cosserat", "cosserat"]})
    text = summary_markdown(rows)
    assert "2 cells: 0 diagnosed, 2 failed." in text
    assert "nan" not in text.lower()


def _noise_study_rows() -> pd.DataFrame:
    """A 0.9 jet gain, two seeds at 1x the EM noise (found) and two at 20x (missed)."""
    cells = [(noise, seed, noise == 1.0) for noise in (1.0, 20.0) for seed in (0, 1)]
    return pd.DataFrame({
        "error": [None] * 4, "seconds": [1.0] * 4, "kind": ["sweep"] * 4, "truth": ["jet_gain"] * 4,
        "verdict": ["jet_gain" if found else "none" for _, _, found in cells],
        "detected": [found for _, _, found in cells], "parameter": ["jet_gain.gain_1"] * 4, "size": [0.9] * 4,
        "size_default": [1.0] * 4, "unit": ["1"] * 4, "plan": ["short"] * 4, "model": ["cosserat"] * 4,
        "orientation": ["hanging"] * 4, "profile": ["sim"] * 4, "noise_scale": [noise for noise, _, _ in cells],
        "seed": [seed for _, seed, _ in cells], "recovery_z": [None] * 4})


def test_the_report_keeps_noise_levels_apart(tmp_path, monkeypatch):
    from hydrojet_bench.studies import report

    rows = _noise_study_rows()
    limits = report.detection_limits(rows)
    # Pooled, the 50 % share hid that 1x detects the gain in every seed and 20x never.
    assert limits[["noise_scale", "smallest_detected", "cells"]].to_dict("records") == [
        {"noise_scale": 1.0, "smallest_detected": 0.9, "cells": 2},
        {"noise_scale": 20.0, "smallest_detected": pytest.approx(float("nan"), nan_ok=True), "cells": 2}]
    assert report.plans_table(rows).reset_index().to_dict("records") == [
        {"truth": "jet_gain", "noise_scale": 1.0, "short": 1.0}, {"truth": "jet_gain", "noise_scale": 20.0, "short": 0.0}]
    text = report.summary_markdown(rows)
    assert "| jet_gain | 1 | 1 |" in text and "| jet_gain | 20 | 0 |" in text
    figures = {}
    monkeypatch.setattr(report, "_save", lambda figure, path: figures.setdefault(path.name, figure) and path)
    report.write_report(rows, tmp_path)
    legend = figures["power.png"].axes[0].get_legend()
    assert legend.get_title().get_text() == "plan / model / rod / noise"
    assert [label.get_text() for label in legend.get_texts()] == ["short / cosserat / hanging / x1",
                                                                  "short / cosserat / hanging / x20"]
    ticks = [label.get_text() for label in figures["plans.png"].axes[0].get_xticklabels()]
    assert ticks == ["jet_gain / x1", "jet_gain / x20"]
    # One noise level: the tables stay as they were, without a constant column.
    single = rows[rows["noise_scale"] == 1.0]
    assert "noise_scale" not in report.detection_limits(single) and "noise_scale" not in report.plans_table(single).index.names
