"""Measurement plans: the paper's calibration poses and validation sweeps."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hydrojet_bench.bench.plan_choice import choose_plan
from hydrojet_bench.errors import UserError
from hydrojet_bench.params import actuation_matrix
from hydrojet_bench.plans import (CALIBRATION_SWEEP, DEFAULT_MAX_FORCE_N, Plan, PlanStep, _resultant_to_jets,
                                  calibration_plan, paper_protocol, validation_sweeps)


def test_calibration_plan_is_forty_labelled_poses_within_the_force_limits():
    plan = calibration_plan(max_force_n=0.08, seed=3)
    forces = plan.jet_forces_n
    assert len(plan) == 40
    assert np.all(plan.sweeps == CALIBRATION_SWEEP)
    assert plan.step_indices.tolist() == list(range(40))
    assert np.all(forces >= 0.0) and np.all(forces <= 0.08)
    # The flanking-pair split leaves at least one jet off in every pose.
    assert np.all(np.sum(forces > 0.0, axis=1) <= 2)
    assert all(step.settle_s == 5.0 for step in plan)


def test_calibration_poses_cover_every_bending_direction_and_reach_the_edge():
    forces = calibration_plan(seed=0).jet_forces_n
    resultant = (actuation_matrix(0.0) @ forces.T).T[:, :2]
    angle_deg = np.degrees(np.arctan2(resultant[:, 1], resultant[:, 0])) % 360.0
    sectors = np.unique((angle_deg // 60.0).astype(int))
    assert sectors.tolist() == [0, 1, 2, 3, 4, 5]
    # Some pose puts a jet near its limit (area-uniform radius: P(all < 0.8) ~ 0.64^40).
    assert forces.max() > 0.8 * DEFAULT_MAX_FORCE_N
    # ...and the radii spread over the workspace rather than sitting at the edge.
    largest_jet = forces.max(axis=1) / DEFAULT_MAX_FORCE_N
    assert largest_jet.min() < 0.4 and np.median(largest_jet) < 0.9


@pytest.mark.parametrize("angle_deg", [0.0, 17.0, 30.0, 60.0, 90.0, 149.0, 150.0, 210.0, 269.0, 330.0, 359.9])
def test_resultant_split_is_exact_and_non_negative(angle_deg):
    resultant = 0.05 * np.array([math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))])
    jets = _resultant_to_jets(resultant)
    assert np.all(jets >= 0.0)
    np.testing.assert_allclose(actuation_matrix(0.0)[:2] @ jets, resultant, atol=1e-15)


def test_calibration_plan_is_deterministic_per_seed():
    assert calibration_plan(seed=7) == calibration_plan(seed=7)
    assert not np.array_equal(calibration_plan(seed=7).jet_forces_n, calibration_plan(seed=8).jet_forces_n)


def test_validation_sweeps_ramp_one_jet_up_and_back_down():
    plan = validation_sweeps(max_force_n=0.09)
    assert len(plan) == 9 * 21
    assert sorted(set(plan.sweeps.tolist())) == list(range(9))
    up = np.linspace(0.0, 0.09, 11)
    for sweep in range(9):
        rows = plan.sweeps == sweep
        forces = plan.jet_forces_n[rows]
        assert plan.step_indices[rows].tolist() == list(range(21))
        jet = sweep % 3
        others = [j for j in range(3) if j != jet]
        assert np.all(forces[:, others] == 0.0)
        ramp = forces[:, jet]
        np.testing.assert_allclose(ramp[:11], up, rtol=0, atol=1e-15)
        np.testing.assert_allclose(ramp[10:], up[::-1], rtol=0, atol=1e-15)
        assert np.all(np.diff(ramp[:11]) > 0) and np.all(np.diff(ramp[10:]) < 0)
        assert ramp[0] == ramp[-1] == 0.0 and ramp[10] == 0.09
    # Repetition by repetition: jets 1, 2, 3, then again.
    first_active = [int(np.argmax(plan.jet_forces_n[plan.sweeps == s].max(axis=0))) for s in range(9)]
    assert first_active == [0, 1, 2] * 3


def test_sweep_shape_follows_steps_and_repetitions():
    plan = validation_sweeps(0.05, steps_up=4, repetitions=2, settle_s=2.5)
    assert len(plan) == 3 * 2 * 9
    assert plan.sweeps.max() == 5
    assert plan.duration_s == pytest.approx(54 * 2.5)


def test_paper_protocol_is_calibration_then_nine_sweeps():
    plan = paper_protocol()
    assert len(plan) == 229
    assert np.all(plan.sweeps[:40] == -1) and np.all(plan.sweeps[40:] >= 0)
    assert plan.duration_s == pytest.approx(229 * 5.0)
    assert plan == calibration_plan() + validation_sweeps()


@pytest.mark.parametrize("call, argument", [
    (lambda: calibration_plan(count=0), "count"),
    (lambda: calibration_plan(count=2.5), "count"),
    (lambda: calibration_plan(max_force_n=0.0), "max_force_n"),
    (lambda: calibration_plan(max_force_n=float("nan")), "max_force_n"),
    (lambda: calibration_plan(max_force_n="big"), "max_force_n"),
    (lambda: calibration_plan(seed=-1), "seed"),
    (lambda: calibration_plan(settle_s=0.0), "settle_s"),
    (lambda: validation_sweeps(max_force_n=-0.1), "max_force_n"),
    (lambda: validation_sweeps(steps_up=0), "steps_up"),
    (lambda: validation_sweeps(repetitions=0), "repetitions"),
    (lambda: validation_sweeps(settle_s=float("inf")), "settle_s"),
    (lambda: paper_protocol(max_force_n=0), "max_force_n"),
])
def test_bad_builder_arguments_are_named(call, argument):
    with pytest.raises(ValueError, match=argument):
        call()


@pytest.mark.parametrize("kwargs, message", [
    ({"jet_forces_n": (0.1, -0.01, 0.0)}, r"jet_forces_n\[q2\] must be finite and >= 0"),
    ({"jet_forces_n": (0.1, 0.0)}, "must have 3 forces"),
    ({"jet_forces_n": (0.1, float("nan"), 0.0)}, r"jet_forces_n\[q2\]"),
    ({"sweep": -2}, "sweep must be an integer >= -1"),
    ({"sweep": True}, "sweep must be an integer"),
    ({"step": -1}, "step must be an integer >= 0"),
    ({"settle_s": 0.0}, "settle_s"),
])
def test_bad_plan_steps_name_their_field(kwargs, message):
    values = {"jet_forces_n": (0.0, 0.0, 0.0), "sweep": 0, "step": 0, "settle_s": 5.0} | kwargs
    with pytest.raises(ValueError, match=message):
        PlanStep(**values)


def test_plan_holds_only_steps_and_steps_are_frozen():
    with pytest.raises(ValueError, match=r"Plan\.steps\[1\] must be a PlanStep"):
        Plan((PlanStep((0.0, 0.0, 0.0), 0, 0), (0.0, 0.0, 0.0)))
    step = PlanStep([0.01, 0, 0], 0, 0)
    assert step.jet_forces_n == (0.01, 0.0, 0.0)
    with pytest.raises(AttributeError):
        step.sweep = 3  # type: ignore[misc]


def test_steps_above_the_valves_limits_are_clipped_to_them_and_listed():
    plan = Plan((PlanStep((0.05, 0.0, 0.0), 0, 0), PlanStep((0.3, 0.0, 5.0), 0, 1), PlanStep((0.0, 0.2, 0.0), 0, 2)))
    clipped, changed = plan.clipped((0.15, 0.15, 0.15))
    assert changed == (1, 2)
    np.testing.assert_allclose(clipped.jet_forces_n, [[0.05, 0.0, 0.0], [0.15, 0.0, 0.15], [0.0, 0.15, 0.0]])
    assert [(s.sweep, s.step, s.settle_s) for s in clipped] == [(s.sweep, s.step, s.settle_s) for s in plan]
    assert plan.clipped((5.0, 5.0, 5.0)) == (plan, ())


@pytest.mark.parametrize(("spec", "steps"), [("calibration", 40), ("calibration:5", 5), ("hold:2", 1)])
def test_built_in_plans_honour_their_argument(spec, steps):
    assert len(choose_plan(spec)) == steps


@pytest.mark.parametrize(("spec", "message"), [
    ("calibration:five", "calibration:COUNT takes a whole number of poses >= 1"),
    ("calibration:0", "calibration:COUNT takes a whole number"),
    # Allocated before a single pose was played (7.5 GiB for 999999999).
    ("calibration:999999999", r"calibration:COUNT takes a whole number of poses >= 1 and <= 100000"),
    ("paper:3", "paper takes no argument"),
    ("sweeps:2", "sweeps takes no argument"),
])
def test_a_built_in_plans_argument_is_never_ignored(spec, message):
    with pytest.raises(UserError, match=message):
        choose_plan(spec)


@pytest.mark.parametrize(("name", "content", "message"), [
    ("plan.csv", "q1,q2,q3\n0.05,0,0\n1_000,0,0\n", r"plan.csv, row 2: q1 must be a number, got '1_000'"),
    ("plan.csv", "q1,q2,q3,sweep\n0.05,0,0,1.5\n", r"plan.csv, row 1: sweep must be an integer, got '1.5'"),
    ("plan.toml", "[[step]]\nq1 = true\nq2 = 0\nq3 = 0\n", r"plan.toml, row 1: q1 must be a number, got True"),
    ("plan.csv", "q1,q2,q3\n0.05,0,0\n# caf\xe9\n", r"plan.csv: not UTF-8 text \(byte \d+\)"),
    ("plan.toml", "# caf\xe9\n[[step]]\nq1 = 0\nq2 = 0\nq3 = 0\n", r"plan.toml: not UTF-8 text \(byte \d+\)"),
    # Read silently once: a misspelt default settle time, a value past the header, a column twice.
    ("plan.toml", "setle_s = 2.0\n[[step]]\nq1 = 0\nq2 = 0\nq3 = 0\n",
     r"plan.toml: setle_s is not a known key; a plan file takes settle_s and \[\[step\]\] tables"),
    ("plan.csv", "q1,q2,q3\n0.05,0,0,99\n", r"plan.csv, row 1: more values than the header has columns"),
    ("plan.csv", "q1,q1,q2,q3\n0.05,0.01,0,0\n", r"plan.csv: column 'q1' appears twice in the header"),
    # Two rows under one label were read back from the recording as one step.
    ("plan.csv", "q1,q2,q3,sweep,step\n0.05,0,0,-1,0\n0.03,0.03,0,0,0\n0,0.03,0.03,0,0\n",
     r"plan.csv, row 3: sweep 0 step 0 is already row 2's; each \(sweep, step\) pair names one step"),
    ("plan.toml", "[[step]]\nq1 = 0\nq2 = 0\nq3 = 0\n[[step]]\nq1 = 0.01\nq2 = 0\nq3 = 0\nstep = 0\n",
     r"plan.toml, row 2: sweep 0 step 0 is already row 1's"),
])
def test_plan_file_mistakes_name_the_file_and_row(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_bytes(content.encode("latin-1"))
    with pytest.raises(UserError, match=message):
        choose_plan(str(path))


@pytest.mark.parametrize(("name", "content", "message"), [
    # A settle time of 1e300 s held the first command forever.
    ("plan.csv", "q1,q2,q3,settle_s,sweep,step\n0.05,0,0,1e300,0,0\n",
     r"plan.csv, row 1: settle_s must be at most 86400 s \(one day\), got 1e\+300"),
    ("plan.csv", "q1,q2,q3,settle_s\n0.05,0,0,5\n0.05,0,0,86400.5\n", r"plan.csv, row 2: settle_s must be at most"),
    ("plan.csv", "q1,q2,q3,settle_s\n0.05,0,0,0\n", r"plan.csv, row 1: settle_s must be a finite time > 0 s"),
    # The file's default is not a row's fault.
    ("plan.toml", "settle_s = 1e300\n[[step]]\nq1 = 0.05\nq2 = 0\nq3 = 0\n",
     r"plan.toml: settle_s must be at most 86400 s \(one day\), got 1e\+300"),
    # Labels beyond int64 crashed the recorder after the jets were commanded.
    ("plan.csv", "q1,q2,q3,sweep\n0.05,0,0,1e300\n", r"plan.csv, row 1: sweep must be an integer >= -1 and < 2\*\*53"),
    ("plan.csv", "q1,q2,q3,sweep\n0.05,0,0,9223372036854775808\n", r"plan.csv, row 1: sweep must be an integer >= -1"),
    ("plan.csv", "q1,q2,q3,step\n0.05,0,0,100000000000000000000\n",
     r"plan.csv, row 1: step must be an integer >= 0 and < 2\*\*53, got '100000000000000000000'"),
    ("plan.csv", "q1,q2,q3,step\n0.05,0,0,1e999999999\n", r"plan.csv, row 1: step must be an integer >= 0"),
    ("plan.toml", "[[step]]\nq1 = 0.05\nq2 = 0\nq3 = 0\nsweep = 9223372036854775807\n",
     r"plan.toml, row 1: sweep must be an integer >= -1 and < 2\*\*53, got 9223372036854775807"),
    ("plan.toml", "[[step]]\nq1 = 0.05\nq2 = 0\nq3 = 0\nstep = 1e300\n", r"plan.toml, row 1: step must be an integer"),
    # Read as a float, these were quietly taken for their neighbour ...992 or ...496.
    ("plan.csv", "q1,q2,q3,step\n0.05,0,0,9007199254740993\n", r"plan.csv, row 1: step must be an integer >= 0"),
    ("plan.toml", "[[step]]\nq1 = 0.05\nq2 = 0\nq3 = 0\nstep = 9007199254740993\n", r"plan.toml, row 1: step must"),
    ("plan.csv", "q1,q2,q3,step\n0.05,0,0,4503599627370496.5\n",
     r"plan.csv, row 1: step must be an integer, got '4503599627370496.5'"),
    ("plan.csv", "q1,q2,q3,step\n0.05,0,0,nan\n", r"plan.csv, row 1: step must be an integer, got 'nan'"),
])
def test_implausible_settle_times_and_labels_name_the_file_row_and_field(tmp_path, name, content, message):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(UserError, match=message):
        choose_plan(str(path))


def test_whole_labels_are_read_exactly_and_written_decimals_still_count(tmp_path):
    path = tmp_path / "plan.csv"
    path.write_text("q1,q2,q3,sweep,step,settle_s\n0.05,0,0,5.0,3.0,86400\n0.05,0,0,-1,1e3,5\n0.05,0,0,-1.0,1001,5\n"
                    "0.05,0,0,9007199254740991,4503599627370497,5\n")
    plan = choose_plan(str(path))
    assert [(s.sweep, s.step) for s in plan] == [(5, 3), (-1, 1000), (-1, 1001), (2**53 - 1, 2**52 + 1)]
    assert plan[0].settle_s == 86400.0
    toml = tmp_path / "plan.toml"
    toml.write_text("[[step]]\nq1 = 0.05\nq2 = 0\nq3 = 0\nsweep = 5.0\nstep = 2.0\n"
                    "[[step]]\nq1 = 0.05\nq2 = 0\nq3 = 0\nsweep = 5\n")
    assert [(s.sweep, s.step) for s in choose_plan(str(toml))] == [(5, 2), (5, 3)]


@pytest.mark.parametrize("call, message", [
    (lambda: PlanStep((0.0, 0.0, 0.0), 2**53, 0), r"PlanStep.sweep must be an integer >= -1 and < 2\*\*53"),
    (lambda: PlanStep((0.0, 0.0, 0.0), 0, 2**63), r"PlanStep.step must be an integer >= 0 and < 2\*\*53"),
    (lambda: PlanStep((0.0, 0.0, 0.0), 0, 0, 1e300), r"PlanStep.settle_s must be at most 86400 s"),
    (lambda: calibration_plan(settle_s=86401.0), "settle_s must be at most 86400 s"),
    (lambda: validation_sweeps(settle_s=1e300), "settle_s must be at most 86400 s"),
    (lambda: choose_plan("hold:1e300"), r"plan 'hold:1e300': .*settle_s must be at most 86400 s"),
])
def test_steps_built_in_code_have_the_same_bounds(call, message):
    with pytest.raises((ValueError, UserError), match=message):
        call()
