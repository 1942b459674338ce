"""`hydrojet-bench simulate`: record the paper's protocol on the digital twin, as CSV.

The twin is the Cosserat rod at the profile's parameters plus any hidden effects, with
EM-tracker noise; the recording follows the CSV contract, so every analysis command
reads it as it would read data from the rig. The output is a new file (missing folders
are created, as for `run --log`); an existing one is replaced only with --overwrite.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console

from ..data.csv_io import write_csv
from ..effects import load_effect
from ..files import check_writable_target, make_folder_for, publish
from ..plans import paper_protocol
from ..profile import load_profile
from ..twin import SETUP_ERRORS, DigitalTwin, SetupErrors, TwinConfig, parse_setup_error
from .common import check_seed


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("simulate", help="record the paper's protocol on the digital twin (CSV)")
    parser.add_argument("-o", "--output", type=Path, required=True, help="CSV file to write (a new file)")
    parser.add_argument("--overwrite", action="store_true", help="replace the output file if it exists")
    parser.add_argument("--profile", default="sim", help="rig profile (default: sim)")
    parser.add_argument("--hidden", action="append", default=[], metavar="EFFECT",
                        help="physics the twin has and the models may not: a library name or "
                             "path/to/file.py:Class (repeatable; replaces the profile's [twin] hidden_effects), "
                             "or a setup error NAME=VALUES: " + ", ".join(f"{name}=..." for name in SETUP_ERRORS))
    parser.add_argument("--seed", type=int, default=None, help="noise seed (default: the profile's, else 0)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    check_seed(args.seed)
    make_folder_for(args.output)
    check_writable_target(args.output, "recording", overwrite=args.overwrite)  # before minutes of simulation
    profile = load_profile(args.profile)
    changes: dict[str, object] = {}
    setup = SetupErrors()
    effects = []
    for spec in args.hidden:
        if spec.partition("=")[0] in SETUP_ERRORS:
            setup = parse_setup_error(spec, setup)
        else:
            effects.append(load_effect(spec))
    if effects:
        changes["hidden_effects"] = tuple(effects)
    if setup.any:
        changes["setup"] = setup
    if args.seed is not None:
        changes["seed"] = args.seed
    config = TwinConfig.from_profile(profile, **changes)
    hidden = config.hidden_effects
    twin = DigitalTwin(config)
    recording = twin.run_plan(paper_protocol())
    dataset = recording.to_dataset(profile, f"twin seed {config.seed}")
    rows = publish(args.output, "recording", lambda partial: write_csv(dataset, partial), overwrite=args.overwrite)
    hidden_names = ", ".join([effect.name for effect in hidden]
                             + [spec for spec in args.hidden if spec.partition("=")[0] in SETUP_ERRORS]) or "none"
    Console().print(f"wrote {rows} samples (229 steps: 40 calibration poses, 9 sweeps) to {args.output}; "
                    f"hidden effects: {hidden_names}", markup=False)
    return 0
