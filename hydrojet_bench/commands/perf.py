"""`hydrojet-bench perf`: speed benchmarks of the hot paths, as JSON.

Medians over many runs after a warm-up, on the HydroJet-like problem of the kinematics
issue: L 70 mm, radius 4.5 mm, E 3e5 -> 2e5 Pa, gravity across the rod, a 0.05 N jet.
Targets are reported beside each figure; a miss is reported, never hidden. Timings are
for this machine at this moment: shared machines are noisy, which is why no unit test
asserts a time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..errors import UserError
from . import render

TARGETS_US = {
    "cosserat_warm_solve": 10.0,
    "cosserat_cold_solve": 500.0,
    "prb_warm_solve": 300.0,
    "sensitivity_6_columns": 100.0,
    "online_update_cosserat": 50.0,
}
IMU_FUSION_TARGET_US = 10.0
CALIBRATION_TARGETS_S = {"cosserat": 0.1, "prb": 5.0}
DIAGNOSE_TARGET_S = 2.0
SPEEDUP_TARGET = 300.0
# The memory figure: a CSV of the paper protocol's size at 200 Hz (229 steps x 5 s),
# calibrated within this multiple of the file's size.
CSV_ROWS = 229_000
CSV_MEMORY_TARGET_RATIO = 3.0


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("perf", help="benchmark the model kernels (JSON)")
    render.add_json_argument(parser, "the printed figures")
    parser.add_argument("--runs", type=int, default=500, help="timed runs per figure (default 500, min 200)")
    parser.add_argument("--no-session", action="store_true",
                        help="skip session_protocol (the paper protocol on the simulated rig, ~1 min)")
    parser.set_defaults(func=run)


def _median_us(function: Callable[[], object], runs: int, warmup: int = 50) -> float:
    for _ in range(warmup):
        function()
    samples = []
    for _ in range(runs):
        start = time.perf_counter()
        function()
        samples.append(time.perf_counter() - start)
    return statistics.median(samples) * 1e6


def benchmark(runs: int) -> dict:
    started = time.perf_counter()
    # Imported here so the first-import (numba cache load or compile) cost is measured.
    from ..models import CosseratModel, PrbModel
    from ..models.reference import solve_reference
    from ..params import DISTURBANCE_NAMES, ModelParameters
    from ..sensitivity import sensitivity

    params = ModelParameters(gravity_in_base_m_s2=(-9.81, 0.0, 0.0))
    jets = np.array([0.05, 0.0, 0.0])
    jets_changed = jets * 1.04
    cosserat, prb = CosseratModel(), PrbModel()
    first_solve_started = time.perf_counter()
    nominal = cosserat.solve(jets, params)
    first_solve_s = time.perf_counter() - first_solve_started
    prb_nominal = prb.solve(jets, params)
    sensitivity(cosserat, jets, params, DISTURBANCE_NAMES, nominal=nominal)
    import_and_first_solve_s = time.perf_counter() - started

    figures = {
        "cosserat_warm_solve": _median_us(lambda: cosserat.solve(jets_changed, params, warm_start=nominal), runs),
        "cosserat_cold_solve": _median_us(lambda: cosserat.solve(jets_changed, params), runs),
        "prb_warm_solve": _median_us(lambda: prb.solve(jets_changed, params, warm_start=prb_nominal), runs),
        "sensitivity_6_columns": _median_us(
            lambda: sensitivity(cosserat, jets, params, DISTURBANCE_NAMES, nominal=nominal), runs),
    }
    figures["online_update_cosserat"] = _online_update_us(cosserat, params, runs)
    warm = cosserat.solve(jets_changed, params, warm_start=nominal)

    # The same problem by collocation: cold (ramped from the straight rod) and warm
    # (seeded with the collocation solution for the previous load).
    reference_runs = max(5, runs // 50)
    previous_mesh = solve_reference(cosserat.build_problem(jets, params))
    problem = cosserat.build_problem(jets_changed, params)
    mesh, states = solve_reference(problem, initial_guess=previous_mesh)
    reference_warm_us = _median_us(lambda: solve_reference(problem, initial_guess=previous_mesh),
                                   reference_runs, warmup=1)
    reference_cold_us = _median_us(lambda: solve_reference(problem), max(3, reference_runs // 3), warmup=0)
    tip_difference_mm = float(np.linalg.norm(warm.tip_position_in_base_m - states[0:3, -1]) * 1e3)

    results = {
        name: {"median_us": round(value, 2), "target_us": TARGETS_US[name], "met": value <= TARGETS_US[name]}
        for name, value in figures.items()
    }
    speedup = reference_warm_us / figures["cosserat_warm_solve"]
    results["solve_bvp_comparison"] = {
        "solve_bvp_warm_us": round(reference_warm_us, 1),
        "solve_bvp_cold_us": round(reference_cold_us, 1),
        "solve_bvp_nodes": int(mesh.size),
        "tip_difference_mm": tip_difference_mm,
        "tip_difference_target_mm": 0.01,
        "speedup_warm": round(speedup, 1),
        "speedup_target": SPEEDUP_TARGET,
        "met": bool(tip_difference_mm <= 0.01 and speedup >= SPEEDUP_TARGET),
    }
    results["imu_fusion"] = _imu_fusion_figure(runs)
    results["calibration_40_poses_9_parameters"] = _calibration_figures(params)
    profile, session = _twin_session()
    results["diagnose_229_steps"] = _diagnose_figure(session.quasistatic_steps())
    # Every kernel figure also relative to collocation timed in this very run, so figures
    # from runs under different machine load can be compared.
    for name in figures:
        results[name]["ratio_to_solve_bvp"] = round(figures[name] / reference_warm_us, 6)
    for figure in results["calibration_40_poses_9_parameters"].values():
        figure["ratio_to_solve_bvp"] = round(figure["median_s"] * 1e6 / reference_warm_us, 3)
    diagnose_figure = results["diagnose_229_steps"]
    diagnose_figure["ratio_to_solve_bvp"] = round(diagnose_figure["seconds"] * 1e6 / reference_warm_us, 2)
    results["calibrate_csv"] = _calibrate_csv_memory_figure(profile, session)
    results["numba"] = {
        "import_and_first_solves_s": round(import_and_first_solve_s, 3),
        "first_cosserat_solve_s": round(first_solve_s, 3),
        "note": "kernels are compiled with cache=True, once, by `hydrojet-bench warmup` (part of the "
                "make set-up); later runs load the cache from __pycache__",
    }
    results["setup"] = {
        "runs": runs, "jet_forces_n": jets.tolist(), "warm_start_load_change": 0.04,
        "rod": "L 70 mm, radius 4.5 mm, E 3e5 -> 2e5 Pa, capsule 2.5 g, gravity across",
        "python": sys.version.split()[0], "cpus": os.cpu_count(),
    }
    return results


def _online_update_us(model, params, runs: int) -> float:
    """One estimator update (solve, sensitivity, step, re-solve) on a steady 0.7 degree
    discrepancy: the estimate is reset each time so every run does the same work."""
    from ..estimation import OnlineDisturbanceEstimator, OnlineSettings
    from ..geometry import so3_exp

    jets = np.array([0.05, 0.0, 0.02])
    measured = model.solve(jets, params).tip_sensor_in_base_sensor() @ so3_exp(np.radians([0.5, 0.5, 0.0]))
    estimator = OnlineDisturbanceEstimator(model, params, OnlineSettings(iterations=1, tolerance_deg=0.0))
    warm = model.solve(jets, params)

    def update() -> None:
        estimator.reset(params, previous=warm)  # a step of a running session: warm, not cold
        estimator.update(jets, measured)

    return _median_us(update, runs)


def _imu_fusion_figure(runs: int) -> dict:
    """One orientation-filter update (gyro, accel and magnetometer) of each fusion choice on
    a noisy 100 Hz stream; update_us is the default's (the `[imu] fusion` key)."""
    from drivers.imu import ImuOrientationFilter, ImuSample
    from drivers.imu.fusion import DEFAULT_FUSION, FUSION_NAMES

    rng = np.random.default_rng(100)
    stream = [ImuSample(0.0, tuple(rng.normal((0.0, 0.0, 9.81), 0.02)), tuple(rng.normal(0.0, 0.002, 3)),
                        tuple(rng.normal((20.0, 0.0, -45.0), 0.3)), 30.0, True) for _ in range(64)]
    per_fusion = {}
    for fusion in FUSION_NAMES:
        filter_ = ImuOrientationFilter(100.0, fusion=fusion)
        count = 0

        def update() -> None:
            nonlocal count
            count += 1
            sample = stream[count % len(stream)]
            filter_.update(ImuSample(count * 0.01, sample.accel_m_s2, sample.gyro_rad_s, sample.mag_ut,
                                     sample.temperature_degc, True))

        per_fusion[fusion] = round(_median_us(update, runs), 2)
    update_us = per_fusion[DEFAULT_FUSION]
    return {"update_us": update_us, "target_us": IMU_FUSION_TARGET_US, "met": update_us <= IMU_FUSION_TARGET_US,
            "fusion": DEFAULT_FUSION, "update_us_by_fusion": per_fusion}


def calibration_benchmark_poses(params) -> list:
    """The calibration figure's 40 poses: random jets on a known rod (E0 2.7e5, EL 1.7e5
    Pa, L 71 mm, wd_mz 2e-4 N m, else ``params``), orientations only, 0.7 deg of noise."""
    from ..estimation.calibration import CalibrationPose
    from ..geometry import so3_exp
    from ..models import CosseratModel
    from ..params import with_parameters

    truth = with_parameters(params, {"E0": 2.7e5, "EL": 1.7e5, "L": 0.071, "wd_mz": 2e-4})
    rng = np.random.default_rng(40)
    poses = []
    for _ in range(40):
        jets = rng.uniform(0.0, 0.12, 3)
        shape = CosseratModel().solve(jets, truth)
        noise = so3_exp(rng.normal(0.0, np.radians(0.7) / np.sqrt(3), 3))
        poses.append(CalibrationPose(jets, shape.tip_sensor_in_base_sensor() @ noise, params.gravity_in_base_m_s2))
    return poses


def _calibration_figures(params) -> dict:
    """Calibrate E0, EL, L and w_d on 40 random noisy poses of a known rod, per model."""
    from ..estimation.calibration import calibrate
    from ..models import CosseratModel, PrbModel

    poses = calibration_benchmark_poses(params)
    figures = {}
    for model in (CosseratModel(), PrbModel()):
        runs = []
        for _ in range(3):
            start = time.perf_counter()
            result = calibrate(model, poses, params)
            runs.append(time.perf_counter() - start)
        seconds = statistics.median(runs)
        figures[model.name] = {"median_s": round(seconds, 3), "target_s": CALIBRATION_TARGETS_S[model.name],
                               "met": seconds <= CALIBRATION_TARGETS_S[model.name],
                               "rms_orientation_deg_after": round(result.rms_orientation_deg_after, 3)}
    return figures


def _twin_session():
    """The paper's 229-step session on the twin with a jet at 90 % of its force hidden:
    the profile and the recorded dataset."""
    from ..plans import paper_protocol
    from ..profile import load_profile
    from ..twin import DigitalTwin, TwinConfig

    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, hidden_effects=("jet_gain",),
                                               hidden_effect_values=(("jet_gain.gain_2", 0.9),), seed=1))
    return profile, twin.run_plan(paper_protocol()).to_dataset(profile)


def _diagnose_figure(steps) -> dict:
    """One `diagnose` of the twin session's 229 steps: every library candidate (twelve), the default
    worker processes. A single run, not a median: it takes seconds, and perf must stay
    short. After a first run, whose time is warmup_s: the candidates' kernels that no
    other figure calls load in the worker processes then, or, on a cold cache, compile
    there (77 s instead of 2.7 s on the slow 2-core machine, after a change to the
    kernels' module)."""
    from ..analysis.diagnosis import diagnose
    from ..analysis.diagnosis.fitting import default_workers

    start = time.perf_counter()
    diagnose(steps, "cosserat")
    warmup_s = time.perf_counter() - start
    start = time.perf_counter()
    diagnosis = diagnose(steps, "cosserat")
    seconds = time.perf_counter() - start
    return {"seconds": round(seconds, 2), "target_s": DIAGNOSE_TARGET_S, "met": seconds <= DIAGNOSE_TARGET_S,
            "steps": len(steps), "candidates": len(diagnosis.ranking), "verdict": diagnosis.verdict,
            "workers": default_workers(), "warmup_s": round(warmup_s, 2)}


# Runs `calibrate` in a fresh interpreter and prints its peak resident set (MB) from the
# kernel's high-water mark, which starts afresh at exec; ru_maxrss would not (Linux
# carries it over from the forking parent, this process).
_PEAK_RSS_CHILD = (
    "import sys\n"
    "from hydrojet_bench.cli import main\n"
    "code = main(sys.argv[1:])\n"
    "with open('/proc/self/status') as status:\n"
    "    print(next(int(line.split()[1]) for line in status if line.startswith('VmHWM:')) / 1024.0)\n"
    "sys.exit(code)\n"
)


def _peak_rss_mb(arguments: list[str]) -> float:
    import subprocess

    done = subprocess.run([sys.executable, "-c", _PEAK_RSS_CHILD, *arguments], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"perf: `hydrojet-bench {' '.join(arguments)}` failed: {done.stderr.strip()}")
    return float(done.stdout.split()[-1])


def _calibrate_csv_memory_figure(profile, session) -> dict:
    """Peak memory of `hydrojet-bench calibrate` on a CSV of CSV_ROWS rows (the twin
    session repeated back to back), against the file's size. ``baseline_rss_mb`` is the
    same command on the session's 229 quasistatic steps: the interpreter, its imports and
    the compiled kernels, which no reader can avoid; ``data_ratio`` is what the rows add,
    per byte of file."""
    import tempfile
    from dataclasses import replace

    from ..data import Dataset
    from ..data.csv_io import write_csv

    copies = -(-CSV_ROWS // len(session))
    span_s = float(session.time_s[-1] - session.time_s[0]) + 1.0
    steps = int(session.step.max()) + 1
    big = Dataset.concatenate([replace(session, time_s=session.time_s + k * span_s, step=session.step + k * steps)
                               for k in range(copies)]).select(np.arange(CSV_ROWS))
    with tempfile.TemporaryDirectory() as directory:
        folder = Path(directory)
        started = time.perf_counter()
        write_csv(big, folder / "big.csv")
        write_seconds = time.perf_counter() - started
        write_csv(session.quasistatic_steps(), folder / "steps.csv")
        file_mb = (folder / "big.csv").stat().st_size / 2**20
        common = ["--profile", str(profile.path), "-o", str(folder / "params.toml")]
        started = time.perf_counter()
        peak = _peak_rss_mb(["calibrate", str(folder / "big.csv"), *common])
        seconds = time.perf_counter() - started
        baseline = _peak_rss_mb(["calibrate", str(folder / "steps.csv"), *common])
    ratio = peak / file_mb
    return {"rows": CSV_ROWS, "file_mb": round(file_mb, 1), "peak_rss_mb": round(peak, 1),
            "ratio_to_file": round(ratio, 2), "target_ratio": CSV_MEMORY_TARGET_RATIO,
            "met": ratio <= CSV_MEMORY_TARGET_RATIO, "baseline_rss_mb": round(baseline, 1),
            "data_ratio": round((peak - baseline) / file_mb, 2), "calibrate_s": round(seconds, 1),
            "write_csv_s": round(write_seconds, 1)}


def run(args: argparse.Namespace) -> int:
    if args.runs < 200:
        raise UserError(f"--runs must be at least 200 (got {args.runs}): medians of fewer are noise")
    results = benchmark(args.runs)
    if not args.no_session:
        from .perf_session import session_protocol_figures

        results.update(session_protocol_figures())
    render.write_json(Path(render.STDOUT), results)
    if args.json and str(args.json) != render.STDOUT:
        render.write_json(args.json, results)
    return 0
