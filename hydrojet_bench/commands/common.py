"""Options shared by the commands: the input file and its rig profile, and the model
(resolved by `hydrojet_bench.model_choice`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import UserError
from .. import inputs
from ..data.dataset import Dataset
from ..models import MODELS
from ..profile import RigProfile

ANY_INPUT = "a CSV file (see hydrojet_bench/data/csv_io.py) or a session log (.mcap)"
SESSION_LOG = "a session log (.mcap) from `hydrojet-bench run`"


def add_input_arguments(parser: argparse.ArgumentParser, what: str = ANY_INPUT) -> None:
    """The positional INPUT (``what``: the kinds of file the command reads) and --profile."""
    parser.add_argument("input", type=Path, metavar="INPUT", help=f"measurements: {what}")
    parser.add_argument("--profile", default=None,
                        help="rig profile: a TOML file or a shipped name (default: the profile embedded in "
                             "a session log; sim for a CSV file)")


def add_model_arguments(parser: argparse.ArgumentParser, default: str, params: str | None = None,
                        params_required: bool = False) -> None:
    """--model and --effect; --params too when ``params`` (its help) is given. default:
    what the command runs without a parameter file or --model, for the help."""
    fallback = (default if params is None else "the parameter file's" if params_required
                else f"the parameter file's, else {default}")
    parser.add_argument("--model", choices=tuple(MODELS), default=None, help=f"kinematic model (default: {fallback})")
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="add an effect to the model: a library name or path/to/file.py:Class (repeatable)")
    if params is not None:
        parser.add_argument("--params", type=Path, required=params_required, metavar="FILE",
                            help=f"parameter file from `calibrate`: {params}; it brings its model and effects, "
                                 "--model and --effect on the command line win")


def check_seed(seed: int | None) -> None:
    """--seed, when given, is a noise seed: an integer >= 0 (numpy's rule)."""
    if seed is not None and seed < 0:
        raise UserError(f"--seed must be an integer >= 0, got {seed}")


def load_steps(path: Path, profile: str | None) -> tuple[RigProfile, Dataset]:
    """The profile and the data reduced to one row per quasistatic step. Without a
    profile, a session log brings its own and a CSV file gets "sim"."""
    if profile is None and Path(path).suffix.lower() != ".mcap":
        profile = "sim"
    steps = inputs.load_steps(path, profile)
    return steps.profile, steps


def comparison_steps(path: Path, profile: str | None,
                     loaded: tuple[RigProfile, Dataset] | None = None) -> tuple[RigProfile, Dataset, Dataset]:
    """What `compare` predicts: the profile, the steps (a session log's own settled steps,
    the rows its live estimator predicted; else `load_steps`, or ``loaded`` when the
    caller has them) and the validation steps among them (sweep >= 0; all of them when
    there are no sweeps)."""
    from ..analysis.compare import validation_rows
    from ..bench.replay import logged_steps

    logged = logged_steps(path, profile) if Path(path).suffix.lower() == ".mcap" else None
    profile_used, steps = ((logged.profile, logged) if logged is not None
                           else loaded if loaded is not None else load_steps(path, profile))
    validation = steps.select(validation_rows(steps))
    if len(validation) == 0:
        raise UserError(f"{path}: no steps to compare")
    return profile_used, steps, validation
