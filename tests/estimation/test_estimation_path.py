"""The path predictor: Ref. defined once, the same whether online estimation runs or
not; a whole dataset predicted as the bench predicts its settled steps one at a time;
and `compare LOG --online` giving a live session's figures bit for bit."""

from __future__ import annotations

import asyncio
import json
from dataclasses import replace

import msgspec
import numpy as np
import pytest

from hydrojet_bench.analysis.metrics import summarise
from hydrojet_bench.bench.replay import logged_steps, read_session
from hydrojet_bench.bench.session import Session, SessionRequest
from hydrojet_bench.cli import main
from hydrojet_bench.model_choice import build_model
from hydrojet_bench.estimation import OnlineSettings
from hydrojet_bench.estimation.path import PathPredictor
from hydrojet_bench.models import CosseratModel
from hydrojet_bench.params import DisturbanceWrench
from hydrojet_bench.params_io import ParameterFile, write_parameter_file
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, TwinConfig

PROFILE = load_profile("sim")


class ClampWithPlay:
    """A compliant clamp with play: each step depends on the path before it."""

    name = "clamp_with_play"
    explanation = "test only"
    parameters = ()
    uses_actuation = False

    def apply(self, problem, values):
        problem.base_compliance_rad_per_nm = np.array([80.0, 80.0, 80.0])
        problem.base_play_rad = 0.05


@pytest.fixture(scope="module")
def steps():
    """Two short sweeps per jet on the twin, one settled row per step."""
    twin = DigitalTwin(TwinConfig.from_profile(PROFILE, seed=3))
    plan = validation_sweeps(steps_up=3, repetitions=1)
    return twin.run_plan(plan, record_window_s=1.0).to_dataset(PROFILE, "twin seed 3").quasistatic_steps()


# A calibrated wrench that is not zero, so that "Ref. uses it" can fail.
PARAMS = replace(PROFILE.model_parameters(), disturbance=DisturbanceWrench((0.002, -0.001, 0.0), (1e-4, 0.0, -5e-5)))


def fields(prediction) -> tuple:
    return (prediction.tip_orientation_in_base, prediction.tip_position_in_base_m, prediction.bend_deg,
            prediction.disturbance_moment_nm, prediction.orientation_error_deg, prediction.position_error_mm)


@pytest.mark.parametrize("gravity", ["per step", "one for all"])
def test_ref_is_the_same_with_online_estimation_on_and_off(steps, gravity):
    model = CosseratModel(["gravity", ClampWithPlay()])
    # One gravity for every step lets the model reuse its packing between Ref. steps when
    # online estimation is off, but not when it is on.
    given = None if gravity == "per step" else np.tile(steps.gravity_in_base_m_s2().mean(axis=0), (len(steps), 1))
    without = PathPredictor(model, PARAMS).predict(steps, given)
    with_online = PathPredictor(model, PARAMS, OnlineSettings()).predict(steps, given)
    assert all(step.online is None for step in without)
    for off, on in zip(without, with_online, strict=True):
        for a, b in zip(fields(off.ref), fields(on.ref), strict=True):
            np.testing.assert_array_equal(a, b)
        # Ref. is the calibrated constant wrench, whatever the online estimate did.
        np.testing.assert_array_equal(on.ref.disturbance_moment_nm, PARAMS.disturbance.moment_nm)
        np.testing.assert_array_equal(on.disturbance_force_n, PARAMS.disturbance.force_n)
    moments = np.array([step.online.disturbance_moment_nm for step in with_online])
    assert np.abs(moments - PARAMS.disturbance.moment_nm).max() > 1e-6  # the estimate did move


def test_online_starts_from_the_calibrated_wrench(steps):
    first = PathPredictor(CosseratModel(), PARAMS, OnlineSettings()).predict(steps.select([0]))[0]
    # Before its first correction the online prediction is Ref.'s.
    assert first.error_before_deg == pytest.approx(first.ref.orientation_error_deg, abs=1e-6)
    assert first.online.orientation_error_deg < first.error_before_deg


def test_a_dataset_is_predicted_as_its_steps_one_at_a_time(steps):
    """What `compare` does (the whole dataset) against what the session does (one settled
    one-row dataset at a time): the same numbers, bit for bit."""
    model = CosseratModel()
    whole = PathPredictor(model, PARAMS, OnlineSettings()).predict(steps)
    live = PathPredictor(model, PARAMS, OnlineSettings())
    for row, offline in enumerate(whole):
        (one,) = live.predict(steps.select([row]))
        assert one.index == offline.index == row
        for method in ("ref", "online"):
            for a, b in zip(fields(getattr(one, method)), fields(getattr(offline, method)), strict=True):
                np.testing.assert_array_equal(a, b)
        assert (one.error_before_deg, one.iterations) == (offline.error_before_deg, offline.iterations)


def test_online_estimation_packs_each_step_once(steps):
    # Each step has its own gravity (the base sensor's), so each is packed: once, shared
    # by Ref. and the online estimate (equal parameters reuse the packing).
    model = CosseratModel()
    built = []
    build_problem = model.build_problem
    model.build_problem = lambda *args, **kwargs: built.append(1) or build_problem(*args, **kwargs)
    PathPredictor(model, PARAMS, OnlineSettings()).predict(steps)
    assert len({tuple(row) for row in steps.gravity_in_base_m_s2()}) == len(steps) == len(built)


# --- a live session against `compare LOG --online` ------------------------------------

SETTLE_S = 3.0


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """A short simulated session (12 calibration poses, one sweep of 5 steps per jet)
    with live calibration and online estimation, and its parameters as a file."""
    folder = tmp_path_factory.mktemp("live")
    settings = PROFILE.config
    settings = msgspec.structs.replace(settings, session=msgspec.structs.replace(settings.session, time_scale=10.0,
                                                                                 window_s=0.5))
    model, _ = build_model("cosserat", [])
    plan = calibration_plan(12, settle_s=SETTLE_S, seed=2) + validation_sweeps(steps_up=2, repetitions=1,
                                                                               settle_s=SETTLE_S)
    request = SessionRequest(profile=PROFILE, settings=settings, plan=plan, log_path=folder / "session.mcap",
                             model=model, effects=(), params=PROFILE.model_parameters(), seed=4)
    result = asyncio.run(Session(request).run())
    assert result.calibration is not None and result.completed_steps == len(plan)
    params_path = folder / "live.toml"
    calibrated = read_session(request.log_path).parameters[-1]
    assert calibrated.calibrated
    write_parameter_file(params_path, ParameterFile(model="cosserat", effects=(), parameters=calibrated.values))
    return folder, request.log_path, params_path, result


def live_figures(result) -> dict:
    """Per-step errors and their RMS of the validation steps, as the session computed them."""
    validation = [estimate for estimate, sweep in zip(result.estimates, result.steps.sweep) if sweep >= 0]
    figures = {}
    for method in ("ref", "online"):
        predictions = [getattr(estimate, method) for estimate in validation]
        orientation = np.array([p.orientation_error_deg for p in predictions])
        position = np.array([p.position_error_mm for p in predictions])
        summary = summarise(orientation, position)
        figures[method] = (orientation.tolist(), position.tolist(), summary.orientation_rmse_deg,
                           summary.position_rmse_mm)
    return figures


def test_compare_on_the_log_gives_the_live_figures_bit_for_bit(session):
    folder, log, params_path, result = session
    assert len(result.estimates) == len(result.steps)
    out = folder / "compare.json"
    assert main(["compare", str(log), "--params", str(params_path), "--online", "--json", str(out)]) == 0
    document = json.loads(out.read_text())
    live = live_figures(result)
    for method in ("ref", "online"):
        orientation, position, orientation_rmse, position_rmse = live[method]
        assert document["per_step"][method]["orientation_error_deg"] == orientation
        assert document["per_step"][method]["position_error_mm"] == position
        assert document["orientation_rmse_deg"][method] == orientation_rmse
        assert document["position_rmse_mm"][method] == position_rmse
    # And both are what the log says the session predicted.
    logged = read_session(log)
    validation = np.flatnonzero(logged.steps.sweep >= 0)
    assert [logged.live_errors[int(logged.plan_index[row]), "online"] for row in validation] == live["online"][0]


def test_compare_uses_the_settled_steps_the_session_logged(session):
    _, log, _, result = session
    steps = logged_steps(log)
    np.testing.assert_array_equal(steps.tip_orientation_in_base(), result.steps.tip_orientation_in_base())
    np.testing.assert_array_equal(steps.gravity_in_base_m_s2(), result.steps.gravity_in_base_m_s2())
