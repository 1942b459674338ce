"""The setup stage of diagnose: its hypotheses model what the twin's setup errors do,
its verdict puts setup first with ties listed, and its fix lands in the profile."""

from __future__ import annotations

from dataclasses import make_dataclass, replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from hydrojet_bench.analysis.diagnosis import diagnose
from hydrojet_bench.analysis.diagnosis.engine import CandidateResult, _significantly_worse
from hydrojet_bench.analysis.diagnosis.measurements import tip_sensor_offset_in_tip_m, tip_sensor_position_in_base_m
from hydrojet_bench.analysis.diagnosis.setup import SetupFix, corrected_profile_text, with_setup_stage
from hydrojet_bench.config.schema import GravityTable
from hydrojet_bench.effects import load_effect
from hydrojet_bench.effects.setup import BaseSensorMounting, JetWiring, TrackerTilt, tilt_rotation
from hydrojet_bench.geometry import quat_from_rotvec, quat_multiply, rotation_angle_deg
from hydrojet_bench.models import make_model
from hydrojet_bench.params import with_parameters
from hydrojet_bench.plans import calibration_plan, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, SensorNoise, SetupErrors, TwinConfig

REPO = Path(__file__).resolve().parents[2]
PROFILE = load_profile(REPO / "profiles/sim.toml")
PLAN = calibration_plan(6, seed=3)


def _twin_steps(setup: SetupErrors):
    twin = DigitalTwin(TwinConfig.from_profile(PROFILE, setup=setup, noise=SensorNoise.off(),
                                                  settle_time_constant_s=0.0))
    return twin.run_plan(PLAN, record_window_s=0.5, sensors="truth").to_dataset(PROFILE, "t").quasistatic_steps(
        window_s=None)


def _model_errors(steps, effect, values):
    """Per step: orientation error (deg) and tip sensor position error (mm) of the model."""
    model = make_model("cosserat", (load_effect("gravity"),) + ((effect,) if effect is not None else ()))
    measured_positions = tip_sensor_position_in_base_m(steps)
    offset = np.array(tip_sensor_offset_in_tip_m(steps))
    angles, distances = [], []
    for row in range(len(steps)):
        params = with_parameters(steps.model_parameters(row), values)
        solution = model.solve(steps.jet_forces_n[row], params)
        angles.append(rotation_angle_deg(solution.tip_sensor_quaternion(), steps.tip_orientation_in_base()[row]))
        distances.append(1e3 * np.linalg.norm(solution.tip_sensor_position_in_base_sensor_m(offset)
                                              - measured_positions[row]))
    return np.array(angles), np.array(distances)


_BASE_OFFSET_M = PROFILE.base_sensor.offset_in_body_m


@pytest.mark.parametrize("setup, effect, values", [
    (SetupErrors(jet_wiring=(1, 3, 2)), JetWiring((1, 3, 2)), {}),
    (SetupErrors(jet_wiring=(2, 3, 1)), JetWiring((2, 3, 1)), {}),
    # The sim profile's base sensor sits 14 mm off the rod axis: turning it moves the
    # clamp origin read from it, which the hypothesis must carry to the positions too.
    (SetupErrors(base_sensor_rotvec_rad=(0.1, -0.05, 0.3)), BaseSensorMounting(_BASE_OFFSET_M),
     {"base_sensor_mounting.rx_rad": 0.1, "base_sensor_mounting.ry_rad": -0.05, "base_sensor_mounting.rz_rad": 0.3}),
])
def test_a_setup_hypothesis_at_the_true_value_reproduces_the_twin(setup, effect, values):
    assert np.linalg.norm(_BASE_OFFSET_M) > 0.01
    steps = _twin_steps(setup)
    angles, distances = _model_errors(steps, None, {})
    assert np.max(angles) > 5.0 and np.max(distances) > 2.0  # the error is visible...
    angles, distances = _model_errors(steps, effect, values)
    assert np.max(angles) < 1e-3 and np.max(distances) < 1e-3  # ...and the hypothesis explains it exactly


def test_tracker_tilt_turns_gravity_and_nothing_else():
    params = PROFILE.model_parameters()
    rotation = tilt_rotation(np.array(params.gravity_in_base_m_s2), 0.1, -0.04)
    turned = replace(params, gravity_in_base_m_s2=tuple(rotation @ np.array(params.gravity_in_base_m_s2)))
    tilted = make_model("cosserat", (load_effect("gravity"), TrackerTilt()))
    plain = make_model("cosserat", (load_effect("gravity"),))
    forces = (0.02, 0.05, 0.0)
    expected = plain.solve(forces, turned).tip_position_in_base_m
    got = tilted.solve(forces, with_parameters(params, {"tracker_tilt.about_u_rad": 0.1,
                                                        "tracker_tilt.about_v_rad": -0.04})).tip_position_in_base_m
    np.testing.assert_allclose(got, expected, atol=1e-9)
    assert abs(np.degrees(np.arccos(rotation[2, 2])) - np.degrees(np.hypot(0.1, 0.04))) < 1e-9


def _candidate(name, score, qualifies=True, parameters=None):
    return CandidateResult(name, f"{name} explained", parameters or {}, 0.2, 0.9, score, score - 100.0, qualifies,
                           {}, None, 0.0, 0.0, 10)


HELD_OUT_ROWS = np.arange(40) % len(PLAN)  # rows may repeat: only their errors matter here


def _diagnosis(steps, ranking, verdict, errors_deg):
    """A stand-in with the fields with_setup_stage reads and replaces (a full Diagnosis
    takes a minute of fitting); each candidate's fit predicts the held-out steps off by
    ``errors_deg[name]`` (deg, per held-out row)."""
    measured = steps.tip_orientation_in_base()[HELD_OUT_ROWS]
    fits = {}
    for name, errors in errors_deg.items():
        turned = quat_multiply(measured, quat_from_rotvec(np.outer(np.radians(errors), [1.0, 0.0, 0.0])))
        fits[name] = SimpleNamespace(predictions=SimpleNamespace(tip_orientation_in_base=_Rows(turned)))
    cls = make_dataclass("D", [("verdict", str), ("explanation", str), ("ranking", tuple), ("alternatives", tuple),
                               ("remaining_excess", bool), ("at_floor_threshold_deg", float),
                               ("setup_ranking", tuple), ("verdict_kind", str), ("setup_fix", object),
                               ("held_out_rows", np.ndarray), ("candidate_fits", dict)], frozen=True)
    return cls(verdict, "", tuple(ranking), (), False, 0.25, (), "", None, HELD_OUT_ROWS, fits)


class _Rows:
    """Predictions of the held-out rows, indexed by HELD_OUT_ROWS as a whole."""

    def __init__(self, rows):
        self.rows = rows

    def __getitem__(self, index):
        assert index is HELD_OUT_ROWS
        return self.rows


def _worse(errors, best):
    return _significantly_worse(errors, best, 0.01)


def _errors(rms_deg, seed):
    return np.abs(np.random.default_rng(seed).normal(0.0, rms_deg, len(HELD_OUT_ROWS)))


def test_setup_goes_first_unless_physics_is_better():
    steps = _twin_steps(SetupErrors())
    # The physical effect scores 5 better (BIC, less than "very strong") and predicts the
    # held-out steps no better within noise: the setup error is checked first, the
    # physics listed beside it.
    ranking = [_candidate("jet_misalignment", 45.0), _candidate("jet_wiring_132", 50.0), _candidate("gravity", 80.0)]
    errors = {"jet_misalignment": _errors(0.2, 1), "jet_wiring_132": _errors(0.2, 2), "gravity": _errors(3.0, 3)}
    result = with_setup_stage(_diagnosis(steps, ranking, "jet_misalignment", errors), steps, _worse)
    assert (result.verdict_kind, result.verdict) == ("setup", "jet_wiring_132")
    assert result.alternatives == ("jet_misalignment",)
    assert result.setup_fix.action == "swap the valve cables of jets 2 and 3"
    assert "jet_misalignment explains the data as well; to tell them apart: fire each jet alone" in result.explanation
    assert [c.effect for c in result.ranking] == ["jet_misalignment", "gravity"]
    assert [c.effect for c in result.setup_ranking] == ["jet_wiring_132"]
    # The same physics significantly better on the held-out steps takes the verdict, and
    # the setup hypothesis, significantly worse, is no alternative.
    errors["jet_misalignment"] = _errors(0.1, 1)
    errors["jet_wiring_132"] = _errors(0.5, 2)
    result = with_setup_stage(_diagnosis(steps, ranking, "jet_misalignment", errors), steps, _worse)
    assert (result.verdict_kind, result.verdict, result.alternatives) == ("physics", "jet_misalignment", ())
    # So does physics that scores decisively better (by more than 10) and predicts the
    # held-out steps no worse, though within the paired test's noise: the setup
    # hypothesis stays an alternative, and no Fix changes the profile.
    errors = {"jet_misalignment": _errors(0.2, 1), "jet_wiring_132": _errors(0.2, 2), "gravity": _errors(3.0, 3)}
    ranking[0] = _candidate("jet_misalignment", 30.0)
    result = with_setup_stage(_diagnosis(steps, ranking, "jet_misalignment", errors), steps, _worse)
    assert (result.verdict_kind, result.verdict, result.alternatives) == ("physics", "jet_misalignment",
                                                                          ("jet_wiring_132",))
    assert result.setup_fix is None
    assert "jet_wiring_132 explains the data as well; to tell them apart: fire each jet alone" in result.explanation


def test_physics_significantly_better_than_any_setup_hypothesis_keeps_the_verdict():
    steps = _twin_steps(SetupErrors())
    ranking = [_candidate("gravity", 10.0), _candidate("tracker_tilt", 40.0, parameters={
        "tracker_tilt.about_u_rad": (0.01, 0.001), "tracker_tilt.about_v_rad": (0.0, 0.001)})]
    errors = {"gravity": _errors(0.2, 4), "tracker_tilt": _errors(0.6, 5)}
    result = with_setup_stage(_diagnosis(steps, ranking, "gravity", errors), steps, _worse)
    assert (result.verdict_kind, result.verdict, result.setup_fix) == ("physics", "gravity", None)
    unexplained = with_setup_stage(_diagnosis(steps, [_candidate("gravity", 10.0, qualifies=False)], "unexplained",
                                              {}), steps, _worse)
    assert unexplained.verdict_kind == "unexplained"


def test_the_fix_replaces_the_key_in_its_table_or_adds_it():
    text = "[gravity]\nin_tracker_m_s2 = [0.0, 0.0, -9.81]\n\n[base]\nx = 1\n"
    fix = SetupFix("tracker_tilt", "level it", "gravity.in_tracker_m_s2", (0.1, 0.2, -9.8))
    assert corrected_profile_text(text, fix) == ("[gravity]\nin_tracker_m_s2 = [0.1, 0.2, -9.8]  # corrected by "
                                                 "diagnose\n\n[base]\nx = 1\n")
    mounting = SetupFix("base_sensor_mounting", "turn it", "base_sensor.rotation_in_base", (1.0, 0.0, 0.0, 0.0))
    assert corrected_profile_text(text, mounting).endswith("[base_sensor]\nrotation_in_base = [1.0, 0.0, 0.0, 0.0]  "
                                                           "# corrected by diagnose\n")


# --- diagnose end to end on small plans ----------------------------------------------

# Short enough for a unit test (60 steps, a few seconds per fit), with repeated sweeps
# to hold out: the jets' full range, as the paper protocol.
SHORT_PLAN = calibration_plan(16, seed=1) + validation_sweeps(0.15, steps_up=4, repetitions=2)
HORIZONTAL = PROFILE.with_tables(gravity=GravityTable(in_tracker_m_s2=(9.81, 0.0, 0.0)))


def _diagnose_twin(setup: SetupErrors, profile=PROFILE, seed=5, candidates=("sensor_mounting", "jet_misalignment")):
    twin = DigitalTwin(TwinConfig.from_profile(profile, setup=setup, seed=seed))
    steps = twin.run_plan(SHORT_PLAN).to_dataset(profile, f"twin seed {seed}").quasistatic_steps()
    return diagnose(steps, "cosserat", candidates=tuple(load_effect(name) for name in candidates))


def test_diagnose_names_a_turned_base_sensor_and_its_corrected_mounting():
    # About the rod axis and across it; the base sensor 14 mm off the axis moves the clamp
    # origin read from it by 2-3 mm, which the hypothesis must carry to the positions.
    rotvec = (0.15, 0.0, 0.3)
    found = _diagnose_twin(SetupErrors(base_sensor_rotvec_rad=rotvec))
    floor = found.noise_floor_deg
    assert found.baseline_heldout_rmse_deg > 3.0 * floor, "precondition: the error must show"
    assert (found.verdict_kind, found.verdict) == ("setup", "base_sensor_mounting")
    assert found.winner.heldout_orientation_rmse_deg <= 1.2 * floor
    fix = found.setup_fix
    assert fix.profile_key == "base_sensor.rotation_in_base"
    truth = quat_multiply(quat_from_rotvec(np.array(rotvec)), np.array(PROFILE.base_sensor.rotation_in_body))
    assert rotation_angle_deg(np.array(fix.corrected_value), truth) < 0.5


@pytest.mark.parametrize("setup, profile, name, key", [
    (SetupErrors(jet_force_sign=-1), PROFILE, "jet_force_sign", "jets.ring_angle_deg"),
    # Lying horizontal, the rod's weight bends it as much as the jets: jets a tenth as
    # strong are no stiffer rod there.
    (SetupErrors(jet_force_scale=1.0 / 9.80665), HORIZONTAL, "jet_force_unit_times_g", None),
])
def test_diagnose_names_reversed_and_mis_scaled_jet_forces(setup, profile, name, key):
    found = _diagnose_twin(setup, profile, candidates=("jet_gain",))
    assert found.baseline_heldout_rmse_deg > 3.0 * found.noise_floor_deg, "precondition: the error must show"
    assert (found.verdict_kind, found.verdict) == ("setup", name)
    assert found.winner.heldout_orientation_rmse_deg <= 1.2 * found.noise_floor_deg
    assert found.setup_fix.profile_key == key
    if key is None:
        assert "multiply them by 0.101972" in found.setup_fix.action
    else:
        assert found.setup_fix.corrected_value == -180.0  # the profile's ring at 0 deg, turned a half turn
