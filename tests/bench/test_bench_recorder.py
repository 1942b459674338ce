"""The step recorder: which samples make a step's settled row, and what it refuses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hydrojet_bench.bench.recorder import StepRecorder
from hydrojet_bench.plans import PlanStep
from hydrojet_bench.profile import load_profile

PROFILE = load_profile("sim")
STEP = PlanStep((0.05, 0.0, 0.02), 1, 3, 5.0)


def _turned(angle_rad: float) -> tuple[float, float, float, float]:
    return (float(np.cos(angle_rad / 2)), float(np.sin(angle_rad / 2)), 0.0, 0.0)


def _recorder_with(times_s: list[float]) -> StepRecorder:
    """Samples whose tip turns about x by as many mrad as their time in s, and whose tip
    sits at x = their time in m: a window's average says which samples it took."""
    recorder = StepRecorder(PROFILE, with_positions=True, source="em")
    recorder.begin(STEP)
    for t_s in times_s:
        recorder.add(t_s, (1.0, 0.0, 0.0, 0.0), _turned(1e-3 * t_s), (0.0, 0.0, 0.0), (t_s, 0.0, 0.0))
    return recorder


@given(st.lists(st.floats(0.0, 10.0), min_size=1, max_size=60).map(sorted),
       st.floats(3.0, 10.0), st.floats(0.1, 3.0))
def test_the_settled_row_averages_exactly_the_samples_inside_the_closed_window(times_s, end_s, window_s):
    recorder = _recorder_with(times_s)
    inside = [t_s for t_s in times_s if end_s - window_s <= t_s <= end_s]
    settled = recorder.settled(end_s, window_s)
    if not inside:
        assert settled is None
        return
    assert len(settled) == 1
    assert settled.tip_position_m[0, 0] == pytest.approx(np.mean(inside), abs=1e-12)
    assert settled.time_s[0] == inside[-1]  # the row's time: its last sample's
    assert settled.tip_orientation[0] == pytest.approx(_turned(1e-3 * np.mean(inside)), abs=1e-9)
    assert settled.jet_forces_n[0] == pytest.approx(STEP.jet_forces_n, abs=1e-15)
    assert (settled.sweep[0], settled.step[0]) == (STEP.sweep, STEP.step)


def test_samples_before_the_first_step_and_of_an_earlier_step_are_not_in_its_row():
    recorder = StepRecorder(PROFILE, with_positions=True, source="em")
    recorder.add(0.5, (1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (9.0, 0.0, 0.0))
    assert recorder.sample_count == 0
    recorder.begin(STEP)
    recorder.add(1.0, (1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (7.0, 0.0, 0.0))
    recorder.begin(STEP)
    recorder.add(2.0, (1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (2.0, 0.0, 0.0))
    assert recorder.settled(2.0, 5.0).tip_position_m[0, 0] == 2.0


def test_a_sample_older_than_the_one_before_it_is_refused():
    recorder = _recorder_with([1.0, 2.0])
    with pytest.raises(ValueError, match="em sample at 1.5 s added after one at 2.0 s"):
        recorder.add(1.5, (1.0, 0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
