"""`hydrojet-bench diagnose INPUT [--model M] [--effect NAME ...] [--json PATH] [--report DIR]`.

Which physical effect is the model missing? Calibrates the baseline (the model with the
known --effect's) and the baseline plus each candidate effect on part of the session,
scores each on the held-out repetitions against the noise floor measured from the data,
and names the effect that explains the excess error, if one does
(`hydrojet_bench.analysis.diagnosis`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from rich.console import Console
from rich.panel import Panel

from ..analysis.diagnosis import NONE, UNEXPLAINED, Diagnosis, DiagnosisSettings, diagnose
from ..analysis.diagnosis.evidence import NOISE_GAP_PER_FLOOR
from ..analysis.diagnosis.noise import repeatability_floor
from ..analysis.diagnosis.setup import SETUP, corrected_profile_text
from ..files import check_writable_target
from ..inputs import load_dataset
from ..effects import load_effect
from ..errors import ConvergenceError, UserError
from ..model_choice import COSSERAT, ModelChoice, model_choice
from . import render
from .common import add_input_arguments, add_model_arguments, load_steps
from .log_notice import warn_if_incomplete


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
    parser.add_argument("--export-profile", type=Path, metavar="TOML",
                        help="for a setup verdict, write the rig profile with the corrected key (a new file)")
    parser.epilog = ("--effect names effects known to be present: they join the baseline (gravity at its nominal "
                     "weight, E0, EL, L, w_d) and are calibrated with it. Every --candidate is then tried on top.")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    choice = model_choice(args)  # validates --effect before the data is read
    candidates = tuple(load_effect(spec) for spec in dict.fromkeys(args.candidate)) or None
    profile, steps = load_steps(args.input, args.profile)
    if args.export_profile is not None:
        check_writable_target(args.export_profile, "corrected profile", overwrite=False)
        if profile.path is None:
            raise UserError(f"--export-profile needs the profile as a file; {profile.source} has none")
    log_damage = warn_if_incomplete(args.input)
    console = render.console_for(args)
    diagnosis = _diagnose(args, profile, steps, choice, candidates, Console(stderr=True))
    print_diagnosis(console, diagnosis, args)
    if args.json:
        render.write_json(args.json, {"data": str(args.input), **diagnosis.as_dict(), "log_damage": log_damage})
    if args.export_profile is not None:
        _export_profile(console, diagnosis, profile, args.export_profile)
    if args.report:
        from ..analysis.diagnosis.plots import write_diagnosis_report

        for path in write_diagnosis_report(args.report, diagnosis):
            console.print(f"wrote {render.plain(path)}")
    return 0


def _export_profile(console: Console, diagnosis: Diagnosis, profile, path: Path) -> None:
    fix = diagnosis.setup_fix
    if fix is None or fix.profile_key is None:
        what = f"the fix is at the rig: {fix.action}" if fix is not None else f"the verdict is {diagnosis.verdict}"
        console.print(f"[yellow]no profile written:[/] {render.plain(what)}, not a profile key")
        return
    path.write_text(corrected_profile_text(profile.path.read_text(), fix))
    console.print(f"wrote {render.plain(path)}: {fix.profile_key} = {list(fix.corrected_value)}")


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
    _print_setup(console, diagnosis)
    gap = diagnosis.baseline_hysteresis_gap_deg
    evidence = []
    if gap is not None:
        noise_gap = NOISE_GAP_PER_FLOOR * diagnosis.noise_floor_deg
        evidence.append(f"loading/unloading gap of the baseline residuals {gap:.3f} deg "
                        f"(noise alone gives {noise_gap:.3f} deg)")
    evidence.append(f"online estimation brings the held-out error to {diagnosis.online.online_rmse_deg:.3f} deg")
    if diagnosis.verdict_kind == SETUP:
        title, style = f"verdict (setup): {diagnosis.verdict}", "magenta"
    elif diagnosis.verdict == NONE:
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
    console.print(_next_steps(diagnosis, args))


def _print_setup(console: Console, diagnosis: Diagnosis) -> None:
    """The setup hypotheses, tried before physics, in their own table."""
    if not diagnosis.setup_ranking:
        return
    table = render.table("Setup hypotheses (tried first): is the rig wired or described wrongly?",
                         labels=("hypothesis",), numbers=("after deg", "explained", "score change"))
    table.add_column("fitted parameters")
    for candidate in diagnosis.setup_ranking:
        style = "bold magenta" if candidate.effect == diagnosis.verdict else ("" if candidate.qualifies else "dim")
        if candidate.error is not None:
            table.add_row(candidate.effect, "-", "-", "-", f"fit failed: {candidate.error}", style="dim")
            continue
        fitted = ", ".join(f"{name.partition('.')[2]} {value:.4g} +- {error:.2g}"
                           for name, (value, error) in candidate.parameters.items())
        table.add_row(candidate.effect, f"{candidate.heldout_orientation_rmse_deg:.3f}",
                      f"{candidate.explained_fraction:.0%}", f"{candidate.score_change:+.1f}", fitted, style=style)
    console.print(table)


def _next_steps(diagnosis: Diagnosis, args: argparse.Namespace) -> str:
    data = str(args.input) + (f" --profile {args.profile}" if args.profile else "")
    options = f" --model {diagnosis.model}" + "".join(f" --effect {spec}" for spec in args.effect)
    if diagnosis.verdict == NONE:
        return f"Next: the model is complete for these data; calibrate it with `calibrate {data}{options} -o p.toml`."
    if diagnosis.verdict_kind == SETUP:
        fix = diagnosis.setup_fix
        if fix.profile_key is not None:
            return (f"Next: `diagnose {data}{options} --export-profile fixed.toml` writes the corrected profile; "
                    f"then `diagnose {args.input} --profile fixed.toml{options}`.")
        return f"Next: {fix.action}, then record the session again."
    if diagnosis.verdict == UNEXPLAINED:
        return (f"Next: see where it fails with `calibrate {data}{options} -o p.toml` and `compare {data} --params "
                "p.toml --online --report DIR`, write the missing physics as an effect file (see docs/examples/), "
                f"and try it with `diagnose {data}{options} --candidate FILE.py:Class`.")
    return (f"Next: `calibrate {data}{options} -o before.toml`, then `calibrate {data}{options} --effect "
            f"{diagnosis.verdict} -o after.toml`, then `compare {data} --params after.toml --baseline before.toml "
            "--online` to watch the error fall.")
