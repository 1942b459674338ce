"""`diagnose` names the effect the digital twin hides (issue 6, items 3, 5, 7).

For every library effect, on two rigs, the twin hides it at a magnitude drawn from a
range (each case its own seed and draw: no single tuned draw), records the paper's
protocol over the rig's full jet range, and diagnose must (1) find the baseline's held-out error at
least twice the noise floor (the precondition: asserted, so a range that stops meeting
it fails loudly instead of testing nothing), (2) name the effect, and (3) bring the
held-out error within 1.5x the floor by adding it. Without a hidden effect the verdict
is "none"; with physics outside the library (docs/examples/water_line_torsion.py) it is
"unexplained". Run with -s to print the figures.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hydrojet_bench.analysis.diagnosis import NONE, UNEXPLAINED, diagnose, estimate_noise_floor, split_session
from hydrojet_bench.analysis.diagnosis.evidence import NOISE_GAP_PER_FLOOR
from hydrojet_bench.config.schema import GravityTable
from hydrojet_bench.effects import LIBRARY, load_effect
from hydrojet_bench.errors import UserError
from hydrojet_bench.plans import calibration_plan, paper_protocol, validation_sweeps
from hydrojet_bench.profile import load_profile
from hydrojet_bench.twin import DigitalTwin, SensorNoise, TwinConfig

REPO = Path(__file__).resolve().parents[2]
PROFILE = load_profile(REPO / "profiles/sim.toml")
# The rig's full jet range (profiles/sim.toml allows 0.15 N per jet; bends reach ~130
# degrees). At the protocol's default 0.1 N the smooth effects (a heavier rod, strain
# stiffening, a soft clamp) stay inside what E0, EL, L and w_d absorb: strain stiffening
# at its bound leaves 1.06x the floor there, against ~2-3x at 0.15 N.
PLAN = paper_protocol(max_force_n=0.15)
# Two rigs: the sim profile's, the rod hanging from its clamp, and the same rig turned so
# that the rod lies horizontal (gravity across it), where its weight bends it even with
# the jets off.
RIGS = {"hanging": PROFILE,
        "horizontal": PROFILE.with_tables(gravity=GravityTable(in_tracker_m_s2=(9.81, 0.0, 0.0)))}
# A hanging rod's strain stiffening stays mostly inside what E0, EL, L and w_d absorb:
# at the top of its range (1.9e-4 to 2e-4 m^2) it left 1.98 to 2.23x the floor over six
# draws (1.5e-4: 1.77x), not reliably twice, so that case cannot test diagnose (which
# named it every time); lying horizontal, 1e-4 already leaves 13x.
CASES = [(effect, rig) for effect in LIBRARY for rig in RIGS if (effect, rig) != ("nonlinear_elasticity", "hanging")]
TORSION = f"{REPO / 'docs/examples/water_line_torsion.py'}:WaterLineTorsion"
# The twin's EM noise, 0.7 deg RMS per sensor and sample, averaged over the 41 samples
# of each step's last second (40 Hz, both ends included), on two sensors.
TWIN_FLOOR_DEG = np.sqrt(2.0) * 0.7 / np.sqrt(41.0)


def _sign(rng):
    return rng.choice([-1.0, 1.0])


# Hidden magnitudes: ranges whose weakest end still doubles the baseline's held-out
# error over the floor on this plan and both rigs (the tests assert it for every draw).
MAGNITUDES = {
    "gravity": lambda rng: {"gravity.weight_scale": rng.uniform(1.5, 2.0)},
    "jet_gain": lambda rng: {f"jet_gain.gain_{rng.integers(1, 4)}": rng.uniform(0.85, 0.93)},
    "jet_misalignment": lambda rng: {"jet_misalignment.ring_angle_rad": _sign(rng) * rng.uniform(0.04, 0.1)},
    "pressure_stiffening": lambda rng: {"pressure_stiffening.coefficient_1_n": rng.uniform(1.0, 2.5)},
    "nonlinear_elasticity": lambda rng: {"nonlinear_elasticity.beta_m2": rng.uniform(1e-4, 2e-4)},
    "anisotropic_stiffness": lambda rng: {
        "anisotropic_stiffness.stiffness_ratio": float(np.exp(_sign(rng) * rng.uniform(np.log(1.15), np.log(1.35))))},
    "stiffness_profile": lambda rng: {"stiffness_profile.mid_span_amplitude": rng.uniform(-0.5, -0.35)},
    # Shear shows mostly in positions, which the held-out score does not read: at a
    # solid section's own compliance (1) the hanging rod stays at the floor; at 3, 2.7x.
    "shear_extension": lambda rng: {"shear_extension.scale": rng.uniform(2.5, 4.0)},
    "base_compliance": lambda rng: {"base_compliance.compliance_rad_per_nm": rng.uniform(60.0, 95.0)},
    "base_hysteresis": lambda rng: {"base_hysteresis.compliance_rad_per_nm": rng.uniform(40.0, 70.0),
                                    "base_hysteresis.play_rad": rng.uniform(0.015, 0.03)},
    "sensor_mounting": lambda rng: {f"sensor_mounting.r{axis}_rad": _sign(rng) * rng.uniform(0.02, 0.06)
                                    for axis in "xyz"},
    "tip_pull": lambda rng: {f"tip_pull.force_{axis}_n": _sign(rng) * rng.uniform(0.004, 0.01) for axis in "xy"},
}
# A pull on the tip and gravity turned sideways (a tracker that is not level, a setup
# hypothesis tried first) load the rod alike within noise at these sizes: either may
# take the verdict as long as the other is listed beside it.
EQUIVALENT = {"tip_pull": "tracker_tilt"}


def case(effect: str, rig: str) -> tuple[dict[str, float], int]:
    """The hidden values and the twin's noise seed for one case: its own generator, so a
    draw does not depend on which other cases run."""
    index, rig_index = list(LIBRARY).index(effect), list(RIGS).index(rig)
    values = MAGNITUDES[effect](np.random.default_rng([2020, index, rig_index]))
    return {key: float(value) for key, value in values.items()}, 300 + 20 * rig_index + index


def record(hidden=(), values=None, seed=0, plan=PLAN, profile=PROFILE):
    """The twin's raw samples and quasistatic steps for a plan, on a rig."""
    twin = DigitalTwin(TwinConfig.from_profile(profile, hidden_effects=hidden,
                                               hidden_effect_values=tuple((values or {}).items()), seed=seed))
    samples = twin.run_plan(plan).to_dataset(profile, f"twin seed {seed}")
    return samples, samples.quasistatic_steps()


def summary(label, diagnosis) -> str:
    lines = [f"{label}: verdict {diagnosis.verdict}, floor {diagnosis.noise_floor_deg:.3f} deg, baseline "
             f"{diagnosis.baseline_heldout_rmse_deg:.3f} deg, {diagnosis.elapsed_s:.1f} s"]
    lines += [f"    {c.effect:22s} {c.heldout_orientation_rmse_deg:.3f} deg, explains {c.explained_fraction:6.1%}, "
              f"score {c.score_change:+10.1f}, online {c.online_correlation:+.2f}" for c in diagnosis.ranking[:3]]
    return "\n".join(lines)


@pytest.fixture(scope="module")
def quiet_session():
    """A session without hidden effects, shared by the tests that need one."""
    return record(seed=11)


@pytest.mark.parametrize(("effect", "rig"), CASES, ids=[f"{effect}-{rig}" for effect, rig in CASES])
def test_diagnose_names_the_hidden_library_effect(effect, rig):
    values, seed = case(effect, rig)
    _, steps = record((load_effect(effect),), values, seed, profile=RIGS[rig])
    diagnosis = diagnose(steps, "cosserat")
    print(summary(f"{effect} on the {rig} rig, {values}, seed {seed}", diagnosis))
    floor = diagnosis.noise_floor_deg
    assert diagnosis.baseline_heldout_rmse_deg >= 2.0 * floor, "precondition: the hidden effect must show"
    if diagnosis.verdict == EQUIVALENT.get(effect):
        assert effect in diagnosis.alternatives
    else:
        assert diagnosis.verdict == effect
        assert diagnosis.explanation == diagnosis.winner.explanation == LIBRARY[effect].explanation
    assert diagnosis.winner.heldout_orientation_rmse_deg <= 1.5 * floor
    if effect == "base_hysteresis":
        # The path dependence shows in the evidence: loading and unloading residuals at the
        # same force differ by far more than noise (the mean norm of a difference of ~60
        # pairs is within ~6 % of its expectation, one sigma), and no longer once fitted.
        noise_gap = NOISE_GAP_PER_FLOOR * floor
        assert diagnosis.baseline_hysteresis_gap_deg > 1.5 * noise_gap
        assert diagnosis.winner.hysteresis_gap_deg < 1.25 * noise_gap


def test_without_a_hidden_effect_the_verdict_is_none(quiet_session):
    samples, steps = quiet_session
    diagnosis = diagnose(steps, "cosserat", samples=samples)
    print(summary("no hidden effect", diagnosis))
    assert diagnosis.verdict == NONE
    # Both noise estimates find the twin's known floor: 378 degrees of freedom put the
    # RMS within ~4 % (one sigma) of it, so 15 % is a four-sigma band.
    assert diagnosis.noise_floor_deg == pytest.approx(TWIN_FLOOR_DEG, rel=0.15)
    assert diagnosis.noise.window_orientation_deg == pytest.approx(TWIN_FLOOR_DEG, rel=0.05)
    assert diagnosis.baseline_heldout_rmse_deg <= diagnosis.at_floor_threshold_deg
    assert not any(c.qualifies for c in diagnosis.ranking)
    assert diagnosis.baseline_hysteresis_gap_deg == pytest.approx(NOISE_GAP_PER_FLOOR * diagnosis.noise_floor_deg,
                                                                  rel=0.25)


def test_the_noise_only_hysteresis_gap():
    # Two independent isotropic 3-D errors of RMS norm 1 differ by 4 / sqrt(3 pi) on average.
    rng = np.random.default_rng(1)
    first, second = rng.normal(size=(2, 200_000, 3)) / np.sqrt(3.0)
    assert np.mean(np.linalg.norm(first - second, axis=1)) == pytest.approx(NOISE_GAP_PER_FLOOR, rel=0.01)


def test_physics_outside_the_library_is_unexplained():
    # A twist of 3e-3 to 6e-3 N m/m per newton of jet force: 0.8 to 1.6 deg at 0.1 N.
    moment = float(np.random.default_rng([2020, 99]).uniform(3e-3, 6e-3))
    _, steps = record((load_effect(TORSION),), {"water_line_torsion.moment_nm_per_m_per_n": moment}, seed=17)
    diagnosis = diagnose(steps, "cosserat")
    print(summary(f"water-line torsion {moment:.2e} N m/(m N)", diagnosis))
    assert diagnosis.baseline_heldout_rmse_deg >= 2.0 * diagnosis.noise_floor_deg, "precondition"
    assert diagnosis.verdict == UNEXPLAINED and diagnosis.remaining_excess
    assert diagnosis.as_dict()["final_remaining_excess"] is True
    # No library effect removes even half of the excess error, not even after the
    # profile scans of the second pass.
    assert max(c.explained_fraction for c in diagnosis.ranking) < 0.5
    # ...and the effect itself, offered as a candidate (starting from its own default,
    # not the hidden value), does.
    found = diagnose(steps, "cosserat", candidates=(load_effect(TORSION),))
    assert found.verdict == "water_line_torsion"
    assert found.winner.heldout_orientation_rmse_deg <= 1.5 * found.noise_floor_deg


def test_the_split_holds_out_repeated_sweeps_and_the_floor_follows_the_noise(quiet_session):
    samples, steps = quiet_session
    split = split_session(steps)
    assert (int(split.training.sum()), int(split.held_out.sum())) == (103, 126)
    assert split.held_out_sweeps == (3, 4, 5, 6, 7, 8)
    assert split.solved[:103].all() and not split.solved[103:].any()
    # Without repetitions every sweep is held out and the raw samples give the floor.
    single = steps.select(steps.sweep < 3)
    assert split_session(single).held_out_sweeps == (0, 1, 2)
    with pytest.raises(UserError, match="no sweep is repeated"):
        estimate_noise_floor(single)
    window = estimate_noise_floor(single, samples.select(samples.sweep < 3))
    assert window.method == "window"
    assert window.orientation_deg == pytest.approx(TWIN_FLOOR_DEG, rel=0.05)
    with pytest.raises(UserError, match="no validation sweeps"):
        split_session(steps.calibration_rows())


def test_the_floor_follows_the_tracker_noise():
    # Tracker noise doubled (and fresh noise): the repeatability floor follows the
    # sqrt(2) * noise / sqrt(41) of averaged steps. 198 degrees of freedom each (33
    # groups of 3 repeats on this short plan) put an estimate within ~5 % (one sigma).
    plan = calibration_plan(10) + validation_sweeps(0.1, steps_up=5, repetitions=3)
    for noise_deg, seed in ((0.7, 5), (1.4, 6)):
        twin = DigitalTwin(TwinConfig.from_profile(PROFILE, seed=seed,
                                                   noise=SensorNoise(em_orientation_rms_deg=noise_deg)))
        steps = twin.run_plan(plan).to_dataset(PROFILE).quasistatic_steps()
        floor = estimate_noise_floor(steps)
        assert floor.dof >= 190  # a group or so may be left out as an outlier
        assert floor.orientation_deg == pytest.approx(np.sqrt(2.0) * noise_deg / np.sqrt(41.0), rel=0.15)
