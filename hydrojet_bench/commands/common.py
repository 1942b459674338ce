"""Options and loading shared by the analysis commands: a data file plus its rig
profile, a model, and effects."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..data import load_dataset
from ..data.dataset import Dataset
from ..effects import Effect, load_effect
from ..models import MODELS, make_model
from ..models.shooting import ShootingModel
from ..profile import RigProfile


def add_data_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("data", type=Path, help="measurements: a CSV file (see hydrojet_bench/data/csv_io.py) "
                        "or a bench session log (.mcap)")
    parser.add_argument("--profile", default=None,
                        help="rig profile: a TOML file or a shipped name (default: the profile embedded in "
                             "a session log; sim for a CSV file)")


def add_model_arguments(parser: argparse.ArgumentParser, default_model: str | None = "cosserat") -> None:
    parser.add_argument("--model", choices=tuple(MODELS), default=default_model,
                        help="kinematic model" + (f" (default {default_model})" if default_model else ""))
    parser.add_argument("--effect", action="append", default=[], metavar="NAME",
                        help="enable an effect: a library name or path/to/file.py:Class (repeatable)")


def load_steps(args: argparse.Namespace) -> tuple[RigProfile, Dataset]:
    """The profile and the data reduced to one row per quasistatic step. Without
    ``--profile``, a session log brings its own profile and a CSV file gets "sim"."""
    profile = args.profile
    if profile is None and Path(args.data).suffix.lower() != ".mcap":
        profile = "sim"
    dataset = load_dataset(args.data, profile)
    return dataset.profile, dataset.quasistatic_steps()


def build_model(name: str, effect_specs: list[str]) -> tuple[ShootingModel, tuple[Effect, ...]]:
    """The model with gravity plus the requested effects, and the requested effects
    themselves (whose parameters a calibration fits; gravity stays at its nominal weight
    unless requested)."""
    requested = tuple(load_effect(spec) for spec in dict.fromkeys(effect_specs))
    always = () if any(effect.name == "gravity" for effect in requested) else (load_effect("gravity"),)
    return make_model(name, always + requested), requested
