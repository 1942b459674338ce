"""`hydrojet-bench simulate`: record the paper's protocol on the digital twin, as CSV.

The twin is the Cosserat rod at the profile's parameters plus any hidden effects, with
EM-tracker noise; the recording follows the CSV contract, so every analysis command
reads it as it would read data from the rig. The output is a new file (missing folders
are created, as for `run --log`); an existing one is replaced only with --overwrite.
"""

from __future__ import annotations

import argparse

from ..data.csv_io import write_csv
from ..effects import command_line_spec
from ..errors import UserError
from ..files import check_writable_target, make_folder_for, publish
from ..plans import clipped_warning, paper_protocol
from ..profile import load_profile
from ..twin import SETUP_ERRORS, DigitalTwin, SetupErrors, TwinConfig, parse_setup_error
from ..twin.hidden import HIDDEN, inert_effects, parse_hidden
from . import render
from .common import check_seed
from .next_steps import command, print_next


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("simulate", help="record the paper's protocol on the digital twin (CSV)")
    parser.add_argument("-o", "--output", type=render.file_path, required=True, help="CSV file to write (a new file)")
    parser.add_argument("--overwrite", action="store_true", help="replace the output file if it exists")
    parser.add_argument("--profile", default="sim", help="rig profile (default: sim)")
    parser.add_argument("--hidden", action="append", default=[], metavar="EFFECT[=VALUE]",
                        help="physics the twin has and the models may not: NAME=VALUE (a vector comma-separated, "
                             "in the order of its parameters), NAME:PARAMETER=VALUE, or path/to/file.py:Class "
                             f"(repeatable; replaces the profile's [twin] hidden_effects). Names: {', '.join(HIDDEN)}; "
                             "setup errors (the rig described wrongly): "
                             + ", ".join(f"{name}=..." for name in SETUP_ERRORS))
    parser.add_argument("--seed", type=int, default=None, help="noise seed (default: the profile's, else 0)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    check_seed(args.seed)
    if args.output.suffix.lower() != ".csv" and not args.output.is_dir():
        # The analyses read a file by its suffix: x.mcap of CSV text is "not an MCAP file".
        raise UserError(f"{args.output}: simulate writes a CSV table; name it with .csv (every command reads a "
                        "file by its suffix)")
    make_folder_for(args.output)
    check_writable_target(args.output, "recording", overwrite=args.overwrite)  # before minutes of simulation
    profile = load_profile(args.profile)
    changes: dict[str, object] = {}
    setup_specs = [spec for spec in args.hidden if spec.partition("=")[0] in SETUP_ERRORS]
    physics_specs = [spec for spec in args.hidden if spec not in setup_specs]
    setup = SetupErrors()
    for spec in setup_specs:
        setup = parse_setup_error(spec, setup)
    if setup.any:
        changes["setup"] = setup
    if physics_specs:
        choice = parse_hidden(physics_specs)
        names = {effect.name for effect in choice.effects}
        # The profile's values still hold for the effects named here; the command line wins.
        kept = {key: value for key, value in profile.config.twin.hidden_effect_values.items()
                if key.partition(".")[0] in names}
        changes["hidden_effects"] = choice.effects
        changes["hidden_effect_values"] = tuple({**kept, **dict(choice.values)}.items())
    if args.seed is not None:
        changes["seed"] = args.seed
    config = TwinConfig.from_profile(profile, **changes)
    hidden = config.hidden_effects
    inert = inert_effects(hidden, dict(config.hidden_effect_values), config.true_params)
    if inert:
        effect = next(e for e in hidden if e.name == inert[0])
        values = dict(config.hidden_effect_values)
        at = ", ".join(f"{p.name} {values.get(f'{effect.name}.{p.name}', p.default):g}" for p in effect.parameters)
        spec = command_line_spec(effect)
        raise UserError(f"--hidden {spec}: at {at or 'its only setting'} it leaves the twin's rod as it is "
                        f"(its identity) and would hide nothing; give it a size, e.g. --hidden {spec}=VALUE "
                        f"or {spec}:PARAMETER=VALUE")
    twin = DigitalTwin(config)
    # The profile's valves give what they can, as on the rig (`run`).
    limits = tuple(table.max_force_n for table in profile.config.valve_calibrations())
    plan, clipped = paper_protocol().clipped(limits)
    recording = twin.run_plan(plan)
    dataset = recording.to_dataset(profile, f"twin seed {config.seed}")
    rows = publish(args.output, "recording", lambda partial: write_csv(dataset, partial), overwrite=args.overwrite)
    hidden_names = ", ".join([effect.name for effect in hidden] + setup_specs) or "none"
    console = render.console()
    if clipped:
        render.console(stderr=True).print(f"warning: {clipped_warning(clipped, limits)} ({profile.source}: "
                                          "[jets] max_force_n)", markup=False)
    console.print(f"wrote {rows} samples (229 steps: 40 calibration poses, 9 sweeps) to {args.output}; "
                  f"hidden effects: {hidden_names}", markup=False)
    # A CSV file is read with the "sim" profile unless told otherwise.
    profile_words = () if args.profile == "sim" else ("--profile", args.profile)
    print_next(console, "which effect is hidden? Ask with", [command("diagnose", args.output, *profile_words)])
    return 0
