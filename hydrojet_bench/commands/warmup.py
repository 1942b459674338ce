"""`hydrojet-bench warmup`: compile every numba kernel now, once, instead of at first use.

Kernels are compiled with ``cache=True``: the first process that calls one compiles it
and writes it under ``__pycache__``; every later process loads it in milliseconds. Each
kernel exists in two variants (the plain rod, and the general rod that effects such as
nonlinear elasticity or a distributed moment need, see `models.kernels`), so a user
who has run the demo still waited over a minute in the first `diagnose`, its worker
processes compiling the general variants, silently. `make demo` and `make test` run this
command as part of the set-up, where waiting is expected.

It runs, in this one process, what reaches every kernel: the paper's protocol on the
twin, then a diagnosis of its steps with both models and every library effect (solves,
sensitivities, calibration, online estimation), and a few emulated IMU and tracker
frames. One process, because numba's cache index is not safe against two processes
adding different variants of one kernel at the same moment.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from . import render


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "warmup", help="compile the model and emulator kernels now (once per checkout; else at first use)")
    parser.set_defaults(func=run)


def compile_kernels(say=lambda message: None) -> None:
    """Call every kernel with each argument type the commands use (see the module)."""
    from ..analysis.diagnosis import DiagnosisSettings, diagnose
    from ..plans import paper_protocol
    from ..profile import load_profile
    from ..twin import DigitalTwin, TwinConfig

    profile = load_profile("sim")
    twin = DigitalTwin(TwinConfig.from_profile(profile, seed=1))
    say("the twin and its settling law")
    steps = twin.run_plan(paper_protocol()).to_dataset(profile).quasistatic_steps()
    for model_name in ("cosserat", "prb"):
        say(f"the {model_name} model with every library effect")
        diagnose(steps, model_name, settings=DiagnosisSettings(workers=1))
        _sensitivities_and_online_updates(model_name)
    say("the IMU and tracker emulators")
    _emulate_devices(twin)


def _sensitivities_and_online_updates(model_name: str) -> None:
    """What a session and `compare` call that a diagnosis does not: the disturbance
    sensitivities and the online estimator's update, on the plain rod and on the general
    one (the diagnosis estimates online on its baseline only, a plain rod)."""
    from ..effects import load_effect
    from ..estimation import OnlineDisturbanceEstimator, OnlineSettings
    from ..models import make_model
    from ..params import DISTURBANCE_NAMES, ModelParameters, with_parameters
    from ..sensitivity import sensitivity

    jet_forces_n = np.array([0.05, 0.0, 0.02])
    for effects, values in (((), {}), (("nonlinear_elasticity",), {"nonlinear_elasticity.beta_m2": 1e-4})):
        model = make_model(model_name, tuple(load_effect(name) for name in ("gravity", *effects)))
        params = with_parameters(ModelParameters(), values)
        nominal = model.solve(jet_forces_n, params)
        sensitivity(model, jet_forces_n, params, (*DISTURBANCE_NAMES, "E0"), nominal=nominal)
        estimator = OnlineDisturbanceEstimator(model, params, OnlineSettings())
        # The first update solves from nothing; the second is the one-kernel update.
        for _ in range(2):
            estimator.update(jet_forces_n, nominal.tip_sensor_in_base_sensor())


def _emulate_devices(twin) -> None:
    """A tenth of a second of both IMUs through their driver, and one BX frame."""
    from drivers.aurora.emulator import AuroraEmulator
    from drivers.aurora.frames import encode_bx
    from drivers.imu.driver import Icm20948, sample_rate_divider_for
    from drivers.imu.emulator import Icm20948BusEmulator

    now_s = [0.0]

    def clock() -> float:
        return now_s[0]

    def sleep(seconds: float) -> None:
        now_s[0] += seconds

    bus = Icm20948BusEmulator(twin, clock, seed=1)
    for address in (0x68, 0x69):
        chip = Icm20948(bus, address, clock=clock, sample_rate_divider=sample_rate_divider_for(100.0), sleep=sleep)
        chip.initialize()
        chip.enable_fifo()
        sleep(0.1)
        chip.read_fifo()
    encode_bx(AuroraEmulator(twin, clock, {0x0A: "base", 0x0B: "tip"}, seed=1).frame())


def run(args: argparse.Namespace) -> int:
    console = render.console(stderr=True)
    started = time.perf_counter()
    console.print("compiling the kernels (once per checkout: a few minutes on a 2-core machine, "
                  "seconds when already compiled)", highlight=False, soft_wrap=True)
    compile_kernels(lambda message: console.print(f"  {message}", highlight=False, soft_wrap=True))
    console.print(f"kernels ready in {time.perf_counter() - started:.0f} s", highlight=False)
    return 0
