"""Issue 12's "right" verdict of a study cell (`studies.cell.right_verdict`), on
diagnoses written out by hand: which answers count for a pair, an effect outside the
library and "none"."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from hydrojet_bench.geometry import matrix_from_quat
from hydrojet_bench.studies.cell import base_orientation, right_verdict
from hydrojet_bench.studies.cells import Cell

FLOOR, THRESHOLD = 0.157, 0.179


def cell(kind: str, truth: str, effects: tuple[str, ...]) -> Cell:
    return Cell(profile="sim", orientation="hanging", plan="paper", model="cosserat", seed=0, noise_scale=1.0,
                kind=kind, truth=truth, effects=effects, values=())


def stage(verdict: str, alternatives: tuple[str, ...] = (), remaining: bool = False):
    return SimpleNamespace(verdict=verdict, alternatives=alternatives, remaining_excess=remaining)


def diagnosis(stages: list, found: list[str], baseline_deg: float = 1.0):
    """A diagnosis whose stages are ``stages`` (the first one first) and which named ``found``."""
    first, later = stages[0], stages[1:]
    return SimpleNamespace(verdict=first.verdict, alternatives=first.alternatives, stages=tuple(later),
                           final=(later or [first])[-1], found=tuple(SimpleNamespace(effect=e) for e in found),
                           baseline_heldout_rmse_deg=baseline_deg, at_floor_threshold_deg=THRESHOLD)


PAIR = cell("pair", "jet_gain+base_compliance", ("jet_gain", "base_compliance"))


def test_a_pair_is_right_with_both_named():
    both = diagnosis([stage("jet_gain", remaining=True), stage("base_compliance")], ["jet_gain", "base_compliance"])
    assert right_verdict(PAIR, both)


def test_a_pair_is_right_when_the_one_named_leaves_the_floor_the_other_below_detection():
    # jet_gain brings the held-out error to the floor; the next stage finds nothing more.
    one = diagnosis([stage("jet_gain", remaining=True), stage("none")], ["jet_gain"])
    assert right_verdict(PAIR, one)
    alone = diagnosis([stage("jet_gain")], ["jet_gain"])
    assert right_verdict(PAIR, alone)


def test_a_pair_is_wrong_when_excess_remains_or_another_effect_is_named():
    short = diagnosis([stage("jet_gain", remaining=True), stage("unexplained", remaining=True)], ["jet_gain"])
    assert not right_verdict(PAIR, short)
    other = diagnosis([stage("gravity")], ["gravity"])
    assert not right_verdict(PAIR, other)
    # ... unless the other effect is tied with one of the pair (an equivalent explanation).
    tied = diagnosis([stage("gravity", alternatives=("jet_gain",))], ["gravity"])
    assert right_verdict(PAIR, tied)


def test_none_is_right_only_at_the_floor_and_outside_effects_want_unexplained():
    single = cell("sweep", "gravity", ("gravity",))
    assert right_verdict(single, diagnosis([stage("none")], [], baseline_deg=FLOOR))
    assert not right_verdict(single, diagnosis([stage("none")], [], baseline_deg=2 * THRESHOLD))
    outside = cell("sweep", "tether", ("/studies/effects/tether.py:Tether",))
    assert right_verdict(outside, diagnosis([stage("unexplained", remaining=True)], []))
    assert not right_verdict(outside, diagnosis([stage("tracker_tilt")], ["tracker_tilt"]))


@pytest.mark.parametrize("gravity_in_tracker", [(0.0, 0.0, -9.81), (9.81, 0.0, 0.0), (3.0, 4.0, -8.0)])
def test_a_cell_hangs_or_lays_the_rod_whatever_the_profile_gives(gravity_in_tracker):
    # A profile whose tracker lies on its side, or whose clamp is already turned: the
    # study's orientation decides where gravity falls in the base frame.
    magnitude = float(np.linalg.norm(gravity_in_tracker))
    for orientation, expected in (("hanging", (0.0, 0.0, magnitude)), ("horizontal", (magnitude, 0.0, 0.0))):
        rotation = matrix_from_quat(base_orientation(orientation, gravity_in_tracker))
        np.testing.assert_allclose(rotation.T @ np.array(gravity_in_tracker), expected, atol=1e-12)
