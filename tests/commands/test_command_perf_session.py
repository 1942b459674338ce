"""`perf`'s session_protocol section: a plan played on the simulated rig at the physical
rig's rates, reported as wall time, delivered / configured rate per stream and the time
scale the simulated rig kept."""

from __future__ import annotations

import pytest

from hydrojet_bench.commands.perf_session import RIG_PROFILE, session_protocol_figures
from hydrojet_bench.plans import validation_sweeps
from hydrojet_bench.profile import load_profile


def test_session_protocol_reports_wall_time_and_rate_fractions_at_the_rigs_rates():
    plan = validation_sweeps(steps_up=1, repetitions=1, settle_s=5.0)
    figures = session_protocol_figures(plan)["session_protocol"]
    rig = load_profile(RIG_PROFILE).config
    assert figures["steps"] == len(plan)
    assert figures["aborted"] is None and figures["completed_steps"] == len(plan), figures
    assert figures["imu_rate_hz"] == rig.imu.rate_hz and figures["tracker_rate_hz"] == rig.tracker.rate_hz
    assert figures["session_s"] >= plan.duration_s
    # The wall time is at least the session time over the scale; rates are whatever this
    # host delivers, but some of each stream always arrives and never more than asked.
    assert figures["wall_s"] >= plan.duration_s / figures["time_scale"]
    for stream in ("imu", "tracker"):
        assert 0 < figures[f"{stream}_rate_fraction"] <= 1.05, figures
    # The simulated rig's session time waits for a slow host: what it kept is said, and
    # session seconds are the kept scale times the wall seconds from the arming to the end
    # of the plan, less those it waited; all three are taken together.
    assert figures["held_wall_s"] >= 0.0
    assert 0.0 < figures["kept_wall_s"] <= figures["wall_s"] - figures["setup_wall_s"]
    assert figures["time_scale_kept"] == pytest.approx(
        figures["time_scale"] * (1.0 - figures["held_wall_s"] / figures["kept_wall_s"]), rel=0.05), figures
    # Each figure is named as missed exactly when it misses its target.
    below = {"wall_s": figures["wall_s"] > figures["target_wall_s"],
             "imu_rate_fraction": figures["imu_rate_fraction"] < figures["target_rate_fraction"],
             "tracker_rate_fraction": figures["tracker_rate_fraction"] < figures["target_rate_fraction"],
             "time_scale_kept": figures["time_scale_kept"] < figures["target_rate_fraction"] * figures["time_scale"]}
    assert figures["missed"] == [figure for figure, missed in below.items() if missed], figures
    assert figures["met"] is (not figures["missed"])
