"""`hydrojet-bench demo`: both models on a simulated sweep, as a table.

Until the bench session exists this is the model demo: jet 1 ramped from zero to its
maximum and back, solved with the Cosserat rod and the PRB chain at the default HydroJet
parameters (rod hanging under gravity, capsule at the tip), warm-starting each step
from the last as the bench will.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from ..errors import UserError
from ..models import CosseratModel, PrbModel
from ..params import ModelParameters


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("demo", help="solve a jet sweep with both models and print a table")
    parser.add_argument("--max-force", type=float, default=0.15, metavar="N",
                        help="largest jet force of the sweep, N (default 0.15)")
    parser.add_argument("--steps", type=int, default=7, help="steps from zero to the maximum (default 7)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if not (np.isfinite(args.max_force) and args.max_force > 0):
        raise UserError(f"--max-force must be a positive number of newtons, got {args.max_force}")
    if args.steps < 1:
        raise UserError(f"--steps must be at least 1, got {args.steps}")
    console = Console()
    params = ModelParameters()
    models = (CosseratModel(), PrbModel())
    forces = np.linspace(0.0, args.max_force, args.steps + 1)
    sweep = np.concatenate([forces, forces[-2::-1]])
    table = Table(title="Jet 1 swept up and down: HydroJet tip in the base frame (mm)",
                  caption="Cosserat: 20 RK4 steps; PRB: 20 links; gap: distance between the two tips. "
                          "Rod hanging under gravity, 2.5 g capsule.")
    for column in ("step", "q1 N", "bend deg", "Cosserat x y z", "PRB x y z", "gap mm"):
        table.add_column(column, justify="right", no_wrap=True)
    for model in models:  # load the compiled kernels before timing anything
        model.solve([0.0, 0.0, 0.0], params)
    previous = {model.name: None for model in models}
    elapsed = {model.name: 0.0 for model in models}
    for step, force in enumerate(sweep):
        solutions = {}
        for model in models:
            start = time.perf_counter()
            solutions[model.name] = model.solve([force, 0.0, 0.0], params, previous=previous[model.name])
            elapsed[model.name] += time.perf_counter() - start
            previous[model.name] = solutions[model.name]
        cosserat, prb = solutions["cosserat"], solutions["prb"]
        table.add_row(
            str(step), f"{force:.3f}", f"{cosserat.bend_angle_deg:5.1f}",
            " ".join(f"{v:5.1f}" for v in cosserat.tip_position_in_base_m * 1e3),
            " ".join(f"{v:5.1f}" for v in prb.tip_position_in_base_m * 1e3),
            f"{np.linalg.norm(cosserat.tip_position_in_base_m - prb.tip_position_in_base_m) * 1e3:.3f}",
        )
    console.print(table)
    console.print(", ".join(f"{name}: {seconds / len(sweep) * 1e6:.0f} us per step"
                            for name, seconds in elapsed.items()) + ", warm-started from the previous step")
    console.print("Next: [bold]hydrojet-bench perf[/] for the speed benchmarks; the simulated bench session "
                  "(hydrojet-bench run) replaces this demo when the bench lands.")
    return 0
