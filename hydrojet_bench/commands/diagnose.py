"""`hydrojet-bench diagnose INPUT [--model M] [--effect NAME ...] [--json PATH] [--report DIR]`.

Which physical effect is the model missing? Calibrates the baseline (the model with the
known --effect's) and the baseline plus each candidate effect on part of the session,
scores each on the held-out repetitions against the noise floor measured from the data,
and names the effect that explains the excess error, if one does
(`hydrojet_bench.analysis.diagnosis`).
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from rich.console import Console
from rich.panel import Panel

from ..analysis.diagnosis import NONE, UNEXPLAINED, Diagnosis, DiagnosisSettings, diagnose
from ..analysis.diagnosis.engine import default_candidates
from ..analysis.diagnosis.evidence import NOISE_GAP_PER_FLOOR
from ..analysis.diagnosis.noise import repeatability_floor
from ..inputs import load_dataset
from ..effects import Effect, load_effect
from ..errors import ConvergenceError, UserError
from ..estimation.calibration import ALL_ROWS
from ..files import check_writable_target, make_folder_for, publish
from ..model_choice import COSSERAT, ModelChoice, model_choice
from ..params_io import ParameterFile, effect_specs, write_parameter_file
from ..profile import RigProfile
from . import render
from .common import add_input_arguments, add_model_arguments, load_steps
from .log_notice import warn_if_incomplete
from .next_steps import command, effect_words, input_words, print_next


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("diagnose", help="which effect is the model missing? (cross-validated)")
    add_input_arguments(parser)
    add_model_arguments(parser, default=COSSERAT.model)
    parser.add_argument("--candidate", action="append", default=[], metavar="NAME",
                        help="an effect to try (library name or path/to/file.py:Class; repeatable; "
                             "default: every library effect not given with --effect)")
    parser.add_argument("--workers", type=int, default=None,
                        help="processes for the candidate fits (default: up to 2)")
    render.add_json_argument(parser, "the diagnosis")
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures (PNG) to this folder")
    parser.add_argument("--export", type=Path, metavar="PARAMS",
                        help="write the verdict's calibrated parameters (the model with the named effect, fitted as "
                             "scored; the baseline's when none is named) as a parameter file (a new file)")
    parser.epilog = ("--effect names effects known to be present: they join the baseline (gravity at its nominal "
                     "weight, E0, EL, L, w_d) and are calibrated with it. Every --candidate is then tried on top.")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    choice = model_choice(args)  # validates --effect before the data is read
    candidates = tuple(load_effect(spec) for spec in dict.fromkeys(args.candidate)) or None
    if args.export is not None:
        make_folder_for(args.export)
        check_writable_target(args.export, "parameter file", overwrite=False)  # before the minutes of fitting
    profile, steps = load_steps(args.input, args.profile)
    log_damage = warn_if_incomplete(args.input)
    console = render.console_for(args)
    diagnosis = _diagnose(args, profile, steps, choice, candidates, Console(stderr=True))
    print_diagnosis(console, diagnosis, args)
    tried = candidates or default_candidates(choice.requested)
    if args.export is not None:
        write_export(args.export, diagnosis, choice, tried, args, profile)
        console.print(f"wrote {render.plain(args.export)}")
    print_next_steps(console, diagnosis, args, tried)
    if args.json:
        render.write_json(args.json, {"data": str(args.input), **diagnosis.as_dict(), "log_damage": log_damage})
    if args.report:
        from ..analysis.diagnosis.plots import write_diagnosis_report

        for path in write_diagnosis_report(args.report, diagnosis):
            console.print(f"wrote {render.plain(path)}")
    return 0


def _diagnose(args: argparse.Namespace, profile, steps, choice: ModelChoice, candidates,
              progress: Console) -> Diagnosis:
    # Without repeated sweeps the raw samples' scatter is the only noise floor left, and
    # only then is the file read a second time for them.
    samples = load_dataset(args.input, profile) if repeatability_floor(steps) is None else None

    def say(message: str) -> None:
        progress.print(f"[dim]{render.plain(message)}[/]", highlight=False)

    try:
        return diagnose(steps, choice.model.name, choice.requested, candidates, samples=samples,
                        settings=DiagnosisSettings(workers=args.workers), progress=say)
    except ConvergenceError as error:
        raise UserError(f"{args.input}: the baseline {choice.model.name} model cannot follow these data ({error}); "
                        "check --profile and the units of the jet forces") from None


def print_diagnosis(console: Console, diagnosis: Diagnosis, args: argparse.Namespace) -> None:
    noise = diagnosis.noise
    window = ("" if noise.window_orientation_deg is None
              else f"; within-window scatter gives {noise.window_orientation_deg:.3f} deg")
    console.print(f"{diagnosis.model} on {render.plain(args.input)}: {diagnosis.split.description}.")
    console.print(f"Noise floor {diagnosis.noise_floor_deg:.3f} deg ({noise.method}, {noise.dof} dof{window}); "
                  f"the baseline's held-out error is {diagnosis.baseline_heldout_rmse_deg:.3f} deg "
                  f"(at the floor up to {diagnosis.at_floor_threshold_deg:.3f} deg).")
    table = render.table("Candidates, best score first: held-out orientation RMSE before (baseline) and after",
                         labels=("effect",),
                         numbers=("before deg", "after deg", "explained", "score change", "online"),
                         caption="explained: share of the baseline's excess squared error over the floor it "
                                 "removes; score: BIC on the training residuals, change from the baseline (lower "
                                 "is better); online: cosine of its signature with the online disturbance estimate")
    table.add_column("fitted parameters")
    for candidate in diagnosis.ranking:
        style = "bold green" if candidate.effect == diagnosis.verdict else ("" if candidate.qualifies else "dim")
        if candidate.error is not None:
            table.add_row(candidate.effect, f"{diagnosis.baseline_heldout_rmse_deg:.3f}", "-", "-", "-", "-",
                          f"fit failed: {candidate.error}", style="dim")
            continue
        fitted = ", ".join(f"{name.partition('.')[2]} {value:.4g} +- {error:.2g}"
                           for name, (value, error) in candidate.parameters.items())
        table.add_row(candidate.effect, f"{diagnosis.baseline_heldout_rmse_deg:.3f}",
                      f"{candidate.heldout_orientation_rmse_deg:.3f}", f"{candidate.explained_fraction:.0%}",
                      f"{candidate.score_change:+.1f}", f"{candidate.online_correlation:+.2f}", fitted, style=style)
    console.print(table)
    gap = diagnosis.baseline_hysteresis_gap_deg
    evidence = []
    if gap is not None:
        noise_gap = NOISE_GAP_PER_FLOOR * diagnosis.noise_floor_deg
        evidence.append(f"loading/unloading gap of the baseline residuals {gap:.3f} deg "
                        f"(noise alone gives {noise_gap:.3f} deg)")
    evidence.append(f"online estimation brings the held-out error to {diagnosis.online.online_rmse_deg:.3f} deg")
    if diagnosis.verdict == NONE:
        title, style = "verdict: none", "green"
    elif diagnosis.verdict == UNEXPLAINED:
        title, style = "verdict: unexplained", "yellow"
    else:
        title, style = f"verdict: {diagnosis.verdict}", "green"
    lines = [diagnosis.explanation, "", "Evidence: " + "; ".join(evidence) + "."]
    if diagnosis.alternatives:
        lines.append(f"Hard to tell apart from: {', '.join(diagnosis.alternatives)} (score within 10).")
    if diagnosis.remaining_excess:
        lines.append("Even with it the held-out error stays above the noise floor: something else is missing too.")
    console.print(Panel("\n".join(lines), title=title, border_style=style))


def _verdict_effect(diagnosis: Diagnosis, candidates: Sequence[Effect]) -> Effect | None:
    return next((effect for effect in candidates if effect.name == diagnosis.verdict), None)


def write_export(path: Path, diagnosis: Diagnosis, choice: ModelChoice, candidates: Sequence[Effect],
                 args: argparse.Namespace, profile: RigProfile) -> None:
    """The verdict's model and calibrated parameters as a parameter file (`params_io`):
    the winner's fit when an effect is named, else the baseline's; effects from files are
    written relative to ``path``."""
    winner, effect = diagnosis.winner, _verdict_effect(diagnosis, candidates)
    if winner is not None and effect is not None:
        fitted, heldout = winner.calibrated, winner.heldout_orientation_rmse_deg
    else:
        baseline = diagnosis.baseline
        fitted = {name: (float(value), float(error))
                  for name, value, error in zip(baseline.names, baseline.values, baseline.standard_errors)}
        heldout, effect = diagnosis.baseline_heldout_rmse_deg, None
    effects = [*([] if any(e.name == "gravity" for e in choice.requested) else [load_effect("gravity")]),
               *choice.requested]
    if effect is not None and all(e.name != effect.name for e in effects):
        effects.append(effect)
    content = ParameterFile(
        model=diagnosis.model, effects=effect_specs(effects, path.parent),
        parameters={name: value for name, (value, _) in fitted.items()},
        standard_errors={name: error for name, (_, error) in fitted.items() if np.isfinite(error)},
        calibration={"data": str(args.input), "profile": profile.source, "fit_on": "diagnose",
                     "rows": diagnosis.split.description, "verdict": diagnosis.verdict,
                     "heldout_orientation_rmse_deg": round(heldout, 4),
                     "noise_floor_deg": round(diagnosis.noise_floor_deg, 4)})
    publish(path, "parameter file", lambda partial: write_parameter_file(partial, content))


def print_next_steps(console: Console, diagnosis: Diagnosis, args: argparse.Namespace,
                     candidates: Sequence[Effect]) -> None:
    """What to run next, as commands that run as printed (one per line, never wrapped)."""
    data = input_words(args)
    known = ("--model", diagnosis.model, *effect_words(args.effect))
    effect = _verdict_effect(diagnosis, candidates)
    if effect is None:
        calibrate = command("calibrate", *data, *known, "-o", "p.toml")
        if diagnosis.verdict == NONE:
            print_next(console, "the model is complete for these data; calibrate it with", [calibrate])
            return
        print_next(console, "see where it fails with", [
            calibrate, command("compare", *data, "--params", "p.toml", "--online", "--report", "report"),
            "then write the missing physics as an effect file (see docs/examples/) and try it with "
            "diagnose --candidate path/to/file.py:Class."])
        return
    spec = next((s for s in args.candidate if ":" in s and load_effect(s).name == effect.name), effect.name)
    # Both calibrations fit the poses and the sweeps, as the diagnosis did (its training
    # steps), so that compare shows what was promised.
    fit_on = ("--fit-on", ALL_ROWS)
    lines = [command("calibrate", *data, *known, *fit_on, "-o", "before.toml")]
    if args.export is None:
        lines.append(command("calibrate", *data, *known, *fit_on, "--effect", spec, "-o", "after.toml"))
    lines.append(command("compare", *data, "--params", args.export or "after.toml", "--baseline", "before.toml",
                         "--online"))
    print_next(console, f"with {effect.name} the held-out error should fall from "
               f"{diagnosis.baseline_heldout_rmse_deg:.3f} deg to about "
               f"{diagnosis.winner.heldout_orientation_rmse_deg:.3f} deg; watch it with", lines)
