"""`hydrojet-bench diagnose INPUT [--model M] [--effect NAME ...] [--depth N] [--json PATH] [--report DIR]
[--separating-plan PATH]`.

Which physical effect is the model missing? Calibrates the baseline (the model with the
known --effect's) and the baseline plus each candidate effect on part of the session,
scores each on the held-out repetitions against the noise floor measured from the data,
and names the effect that explains the excess error, if one does, then continues on top
of it while excess remains (`hydrojet_bench.analysis.diagnosis`). When candidates tie, a
plan of the poses that tell them apart is written (never over an existing file).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rich.console import Console
from rich.panel import Panel

from ..analysis.diagnosis import NONE, UNDECIDED, UNEXPLAINED, Diagnosis, DiagnosisSettings, diagnose
from ..analysis.diagnosis.engine import DEFAULT_DEPTH, FoundEffect, default_candidates
from ..analysis.diagnosis.evidence import NOISE_GAP_PER_FLOOR
from ..analysis.diagnosis.fitting import scored_as_diagnosed
from ..analysis.diagnosis.noise import repeatability_floor
from ..analysis.diagnosis.separate import separating_plan, write_separating_plan
from ..analysis.diagnosis.setup import SETUP, corrected_profile_text, is_setup, separating_measurement
from ..plans import DEFAULT_SETTLE_S
from ..inputs import load_dataset
from ..data.dataset import Dataset
from ..effects import Effect, load_effect, load_effects
from ..errors import ConvergenceError, UserError
from ..estimation.calibration import ALL_ROWS
from ..files import check_writable_target, create_numbered, make_folder_for, publish
from ..model_choice import COSSERAT, ModelChoice, choose_model, model_choice
from ..params_io import ParameterFile, effect_specs, write_parameter_file
from ..profile import RigProfile
from . import render
from .common import add_input_arguments, add_model_arguments, comparison_steps, load_steps
from .figure_options import add_format_argument
from .log_notice import (warn_if_incomplete, warn_if_recorded_elsewhere, warn_if_unsettled,
                         warn_if_unsettled_steps)
from .next_steps import command, effect_words, input_words, print_next

# Exit code of a diagnosis whose fits could not decide (`UNDECIDED`).
UNDECIDED_EXIT = 3


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
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures to this folder")
    add_format_argument(parser)
    parser.add_argument("--depth", type=int, default=DEFAULT_DEPTH, metavar="N",
                        help=f"name up to N effects, each on top of the ones before (default {DEFAULT_DEPTH})")
    parser.add_argument("--separating-plan", type=Path, metavar="PATH",
                        help="where to write the plan that tells tied candidates apart (default: "
                             "separating-plan.toml in the --report folder, else beside INPUT; never overwritten)")
    parser.add_argument("--export", type=Path, metavar="PARAMS",
                        help="write the verdict's calibrated parameters (the model with the named effect, fitted as "
                             "scored; the baseline's when none is named) as a parameter file (a new file)")
    parser.add_argument("--export-profile", type=Path, metavar="TOML",
                        help="for a setup verdict, write the rig profile with the corrected key (a new file)")
    parser.epilog = ("--effect names effects known to be present: they join the baseline (gravity at its nominal "
                     "weight, E0, EL, L, w_d) and are calibrated with it. Every --candidate is then tried on top.")
    render.add_exit_codes(parser, {UNDECIDED_EXIT: "the verdict is undecided: the fits did not converge (the verdict "
                                                   "says which)"})
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.workers is not None and args.workers < 1:
        raise UserError(f"--workers must be at least 1, got {args.workers}")
    if args.depth < 1:
        raise UserError(f"--depth must be at least 1, got {args.depth}")
    render.check_distinct_outputs({"--json": args.json, "--export": args.export, "--export-profile": args.export_profile,
                                   "--separating-plan": args.separating_plan})
    if args.separating_plan is not None:
        check_writable_target(args.separating_plan, "plan file", overwrite=False)
    choice = model_choice(args)  # validates --effect before the data is read
    load_effects([*choice.effect_specs, *args.candidate])  # one name, one effect: known and candidates alike
    candidates = load_effects(args.candidate) or None
    if args.export is not None:
        make_folder_for(args.export)
        check_writable_target(args.export, "parameter file", overwrite=False)  # before the minutes of fitting
    profile, steps = load_steps(args.input, args.profile)
    if args.export_profile is not None:
        check_writable_target(args.export_profile, "corrected profile", overwrite=False)
        if profile.path is None:
            raise UserError(f"--export-profile needs the profile as a file; {profile.source} has none")
    log_damage = warn_if_incomplete(args.input)
    profile_mismatch = warn_if_recorded_elsewhere(args.input, args.profile, profile)
    single_sample_steps = warn_if_unsettled(args.input, steps, log_damage)
    unsettled_steps = warn_if_unsettled_steps(args.input, steps)
    console = render.console_for(args)
    diagnosis = _diagnose(args, profile, steps, choice, candidates, render.console(stderr=True))
    print_diagnosis(console, diagnosis, args)
    tried = candidates or default_candidates(choice.requested)
    if args.export is not None:
        write_export(args.export, diagnosis, choice, tried, args, profile)
        console.print(f"wrote {render.plain(args.export)}")
    preview = add_step_preview(args, profile, steps, diagnosis, tried)
    print_next_steps(console, diagnosis, args, tried, preview)
    if args.json:
        render.write_json(args.json, {"data": str(args.input), **diagnosis.as_dict(),
                                      "add_step": None if preview is None else preview.as_dict(),
                                      "log_damage": log_damage, "profile_mismatch": profile_mismatch,
                                      "single_sample_steps": single_sample_steps,
                                      "unsettled_steps": unsettled_steps})
    if args.export_profile is not None:
        _export_profile(console, diagnosis, profile, args.export_profile)
    if args.report:
        from ..analysis.diagnosis.plots import write_diagnosis_report

        for path in write_diagnosis_report(args.report, diagnosis, args.figure_format):
            console.print(f"wrote {render.plain(path)}")
    tied = next((stage for stage in (diagnosis, *diagnosis.stages) if stage.alternatives), None)
    if tied is not None and tied.separating_poses:
        path = _write_separating_plan(args, tied)
        console.print(f"wrote {render.plain(path)}: the poses that tell {', '.join(_tied(tied))} apart; "
                      f"run it with `run --plan {render.plain(path)}` and diagnose the new session")
    elif tied is not None:
        console.print(f"No command within the jets' range makes {', '.join(_tied(tied))} differ by more than "
                      "the noise floor: they are equivalent on this rig, so no separating plan is written.")
    return UNDECIDED_EXIT if diagnosis.verdict == UNDECIDED else 0


def _tied(diagnosis: Diagnosis) -> tuple[str, ...]:
    return (diagnosis.verdict, *diagnosis.alternatives)


def _write_separating_plan(args: argparse.Namespace, diagnosis: Diagnosis) -> Path:
    plan = separating_plan(diagnosis.separating_poses, DEFAULT_SETTLE_S)
    if args.separating_plan is not None:
        return write_separating_plan(args.separating_plan, plan, _tied(diagnosis))
    folder = args.report if args.report else Path(args.input).parent
    # The default name takes the next free number instead of replacing an earlier plan.
    path = create_numbered(folder / "separating-plan.toml", "plan file")
    return write_separating_plan(path, plan, _tied(diagnosis), overwrite=True)


def _export_profile(console: Console, diagnosis: Diagnosis, profile, path: Path) -> None:
    fix = diagnosis.setup_fix
    if fix is None or fix.profile_key is None:
        what = f"the fix is at the rig: {fix.action}" if fix is not None else f"the verdict is {diagnosis.verdict}"
        console.print(f"[yellow]no profile written:[/] {render.plain(what)}, not a profile key")
        return
    text = corrected_profile_text(profile.path.read_text(), fix)
    publish(path, "profile", lambda partial: partial.write_text(text))
    console.print(f"wrote {render.plain(path)}: {fix.profile_key} = {fix.value_text()}")


def _diagnose(args: argparse.Namespace, profile, steps, choice: ModelChoice, candidates,
              progress: Console) -> Diagnosis:
    # Without repeated sweeps the raw samples' scatter is the only noise floor left, and
    # only then is the file read a second time for them.
    samples = load_dataset(args.input, profile) if repeatability_floor(steps) is None else None

    def say(message: str) -> None:
        progress.print(f"[dim]{render.plain(message)}[/]", highlight=False)

    try:
        return diagnose(steps, choice.model.name, choice.requested, candidates, samples=samples,
                        settings=DiagnosisSettings(workers=args.workers, depth=args.depth), progress=say)
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
                                 "is better); online: cosine of its signature with the online disturbance estimate; "
                                 "an unconverged fit is never ranked above a converged one")
    table.add_column("fitted parameters")
    for candidate in diagnosis.ranking:
        style = "bold green" if candidate.effect == diagnosis.verdict else ("" if candidate.qualifies else "dim")
        if candidate.error is not None:
            table.add_row(render.plain(candidate.effect), f"{diagnosis.baseline_heldout_rmse_deg:.3f}", "-", "-",
                          "-", "-", render.plain(f"fit failed: {candidate.error}"), style="dim")
            continue
        if not candidate.converged:
            style = "dim red"
        table.add_row(render.plain(candidate.effect), f"{diagnosis.baseline_heldout_rmse_deg:.3f}",
                      f"{candidate.heldout_orientation_rmse_deg:.3f}", f"{candidate.explained_fraction:.0%}",
                      f"{candidate.score_change:+.1f}", f"{candidate.online_correlation:+.2f}",
                      _fitted_text(candidate.parameters, candidate.notes), style=style)
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
    elif diagnosis.verdict in (UNEXPLAINED, UNDECIDED):
        title, style = f"verdict: {diagnosis.verdict}", "yellow"
    else:
        title, style = "verdict: " + " + ".join(found.effect for found in diagnosis.found), "green"
    lines = [diagnosis.explanation, "", "Evidence: " + "; ".join(evidence) + "."]
    for found in diagnosis.found:
        lines.append(f"{found.effect}: {found.share_of_excess:.0%} of the excess, held-out error "
                     f"{found.heldout_orientation_rmse_deg:.3f} deg with it ("
                     f"{_fitted_text(found.parameters, found.notes, markup=False)})")
    for stage in (diagnosis, *diagnosis.stages):
        if stage.alternatives:
            lines.append(f"{stage.verdict} explains the held-out data no better than {', '.join(stage.alternatives)} "
                         f"within noise (paired test at the {DiagnosisSettings().significance:.0%} level): see the separating plan.")
    if diagnosis.final.remaining_excess and diagnosis.found:
        lines.append(_remaining_excess(diagnosis.found[-1]))
    # On a pipe the console is as wide as a table may need: the box fits its text there.
    # Plain text: effect names, explanations and notes ("[not converged]") are not markup.
    console.print(Panel(render.plain("\n".join(lines)), title=render.plain(title), border_style=style,
                        expand=console.is_terminal))


def _fitted_text(parameters: Mapping[str, tuple[float, float]], notes: Sequence[str], *, markup: bool = True) -> str:
    """``name value +- error, ...`` and the fit's notes in brackets (on its bound, not
    converged); made inert for rich markup unless ``markup`` is False (text a caller escapes
    as a whole)."""
    text = ", ".join(f"{name.partition('.')[2]} {value:.4g} +- {error:.2g}"
                     for name, (value, error) in parameters.items())
    if notes:
        text += " [" + "; ".join(notes) + "]"
    return render.plain(text) if markup else text


# A PRB fit on twice the links that leaves at most this share of the held-out error is
# said to show the chain's own error (the error falls with the links only where it is).
CHAIN_SHARE = 0.75


def _remaining_excess(last: FoundEffect) -> str:
    """What the held-out error left above the floor may be: another missing effect, or
    (for a PRB fit that twice the links brings clearly lower) the chain's own error."""
    said = "Even with it the held-out error stays above the noise floor"
    if last.refined_chain is not None:
        links, refined_deg = last.refined_chain
        if refined_deg <= CHAIN_SHARE * last.heldout_orientation_rmse_deg:
            return (f"{said}, and much of that is the PRB chain's own discretization: with {links} links instead "
                    f"of {links // 2} it is {refined_deg:.3f} deg, not {last.heldout_orientation_rmse_deg:.3f} deg "
                    "(`--model cosserat` has no chain to refine). Something else may be missing too.")
    return f"{said}: something else is missing too."


def _found_effects(diagnosis: Diagnosis, candidates: Sequence[Effect]) -> list[Effect]:
    """The effects the diagnosis named, over all its stages, in the order it named them."""
    by_name = {effect.name: effect for effect in candidates}
    return [by_name[found.effect] for found in diagnosis.found if found.effect in by_name]


def write_export(path: Path, diagnosis: Diagnosis, choice: ModelChoice, candidates: Sequence[Effect],
                 args: argparse.Namespace, profile: RigProfile) -> None:
    """The verdict's model and calibrated parameters as a parameter file (`params_io`):
    the last stage's winning fit (it carries every effect named before it in its
    baseline), else that stage's baseline; effects from files are written relative to
    ``path``."""
    final = diagnosis.final
    winner, found = final.winner, _found_effects(diagnosis, candidates)
    if winner is not None and found:
        fitted, heldout = winner.calibrated, winner.heldout_orientation_rmse_deg
    else:
        baseline = final.baseline
        fitted = {name: (float(value), float(error))
                  for name, value, error in zip(baseline.names, baseline.values, baseline.standard_errors)}
        heldout = final.baseline_heldout_rmse_deg
    effects = [*([] if any(e.name == "gravity" for e in choice.requested) else [load_effect("gravity")]),
               *choice.requested]
    effects += [effect for effect in found if all(e.name != effect.name for e in effects)]
    content = ParameterFile(
        model=diagnosis.model, effects=effect_specs(effects, path.parent),
        parameters={name: value for name, (value, _) in fitted.items()},
        standard_errors={name: error for name, (_, error) in fitted.items() if np.isfinite(error)},
        calibration={"data": str(args.input), "profile": profile.source, "fit_on": "diagnose",
                     "rows": diagnosis.split.description, "verdict": diagnosis.verdict,
                     "heldout_orientation_rmse_deg": round(heldout, 4),
                     "noise_floor_deg": round(diagnosis.noise_floor_deg, 4)})
    publish(path, "parameter file", lambda partial: write_parameter_file(partial, content))


@dataclass(frozen=True)
class AddStepPreview:
    """The add step diagnose prints, and what its `compare --baseline` will show on the
    row "all, as diagnose scores" (Ref. orientation RMSE over the validation steps, deg)
    before and after the named effects, each calibrated as the printed commands do: on
    every row, the held-out repetitions too, so "before" reads lower than the held-out
    error the diagnosis promises to remove."""

    commands: tuple[str, ...]
    compare_before_deg: float
    compare_after_deg: float

    def as_dict(self) -> dict:
        return {"commands": list(self.commands), "compare_before_deg": self.compare_before_deg,
                "compare_after_deg": self.compare_after_deg}


def add_step_preview(args: argparse.Namespace, profile: RigProfile, steps: Dataset, diagnosis: Diagnosis,
                     candidates: Sequence[Effect]) -> AddStepPreview | None:
    """The add step's commands and the figures they will show, computed by the code the
    commands run (`api.calibrate`, `scored_as_diagnosed` on `comparison_steps`); None
    when the diagnosis names no effect."""
    found = _found_effects(diagnosis, candidates)
    if diagnosis.verdict_kind == SETUP or not found:
        return None
    from .. import api
    from ..api.results import Measurements

    specs = [next((s for s in args.candidate if ":" in s and load_effect(s).name == effect.name), effect.name)
             for effect in found]
    words, model = input_words(args), ("--model", diagnosis.model, *effect_words(args.effect))
    # Both calibrations fit the poses and the sweeps, as the diagnosis did (its training
    # steps), and the held-out repetitions with them.
    lines = [command("calibrate", *words, *model, "--fit-on", ALL_ROWS, "-o", "before.toml")]
    if args.export is None:
        lines.append(command("calibrate", *words, *model, "--fit-on", ALL_ROWS, *effect_words(specs),
                             "-o", "after.toml"))
    lines.append(command("compare", *words, "--params", args.export or "after.toml", "--baseline", "before.toml",
                         "--online"))
    _, compared, _ = comparison_steps(args.input, args.profile, (profile, steps))
    data = Measurements(Path(args.input), profile, steps, None)

    def shown(effects: list[str]) -> float:
        fitted = api.calibrate(data, model=diagnosis.model, effects=effects, fit_on=ALL_ROWS)
        return scored_as_diagnosed(fitted.model, fitted.fit.params, compared).orientation_rmse_deg

    if args.export is None:
        after = shown(list(args.effect) + specs)
    else:
        exported = choose_model(None, (), args.export)
        after = scored_as_diagnosed(exported.model, exported.parameters(profile.model_parameters()),
                                    compared).orientation_rmse_deg
    return AddStepPreview(tuple(lines), shown(list(args.effect)), after)


def print_next_steps(console: Console, diagnosis: Diagnosis, args: argparse.Namespace,
                     candidates: Sequence[Effect], preview: AddStepPreview | None) -> None:
    """What to run next, as commands that run as printed (one per line, never wrapped)."""
    data = input_words(args)
    known = ("--model", diagnosis.model, *effect_words(args.effect))
    if diagnosis.verdict_kind == SETUP:
        fix = diagnosis.setup_fix
        if fix.profile_key is None:
            print_next(console, f"{fix.action}, then record the session again.", [])
            return
        if args.export_profile is not None:  # written already: only the check is left
            print_next(console, "check the corrected profile with",
                       [command("diagnose", args.input, "--profile", args.export_profile, *known)])
            return
        tied = [name for name in diagnosis.alternatives if not is_setup(name)]
        if tied:
            # Physics explains the data as well: correcting the profile first could
            # write a wrong correction.
            print_next(console, f"first tell {diagnosis.verdict} from {', '.join(tied)} ("
                                f"{separating_measurement(diagnosis.verdict)}); if it is the setup, write the "
                                "corrected profile and check it with", [
                command("diagnose", *data, *known, "--export-profile", "fixed.toml"),
                command("diagnose", args.input, "--profile", "fixed.toml", *known)])
            return
        print_next(console, "write the corrected profile and check it with", [
            command("diagnose", *data, *known, "--export-profile", "fixed.toml"),
            command("diagnose", args.input, "--profile", "fixed.toml", *known)])
        return
    if preview is None:
        calibrate = command("calibrate", *data, *known, "-o", "p.toml")
        likely = next((name for name in diagnosis.training_only if not is_setup(name)), None)
        if diagnosis.verdict == NONE and likely is not None:
            print_next(console, f"no effect shows in the held-out steps, but the training steps favour {likely}: "
                                "calibrate without and with it, and compare its value with its standard error", [
                calibrate, command("calibrate", *data, *known, *effect_words([likely]), "-o", f"p_{likely}.toml")])
            return
        if diagnosis.verdict == NONE:
            print_next(console, "the model is complete for these data; calibrate it with", [calibrate])
            return
        if diagnosis.verdict == UNDECIDED:
            print_next(console, "see how far a calibration gets from the profile's values with", [
                calibrate, command("compare", *data, "--params", "p.toml", "--report", "report")])
            return
        if diagnosis.untried_library:
            print_next(console, "try the rest of the library (--candidate narrowed the candidates) with",
                       [command("diagnose", *data, *known)])
            return
        print_next(console, "see where it fails with", [
            calibrate, command("compare", *data, "--params", "p.toml", "--online", "--report", "report"),
            "then write the missing physics as an effect file (see docs/examples/) and try it with "
            "diagnose --candidate path/to/file.py:Class."])
        return
    found = " + ".join(effect.effect for effect in diagnosis.found)
    print_next(console, f"with {found} the held-out error should fall from {diagnosis.baseline_heldout_rmse_deg:.3f} "
               f"deg to about {diagnosis.found[-1].heldout_orientation_rmse_deg:.3f} deg. These commands fit every "
               f"row, the held-out ones too: compare's row \"all, as diagnose scores\" will show "
               f"{preview.compare_before_deg:.3f} -> {preview.compare_after_deg:.3f} deg", list(preview.commands))


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
            table.add_row(candidate.effect, "-", "-", "-", render.plain(f"fit failed: {candidate.error}"), style="dim")
            continue
        table.add_row(candidate.effect, f"{candidate.heldout_orientation_rmse_deg:.3f}",
                      f"{candidate.explained_fraction:.0%}", f"{candidate.score_change:+.1f}",
                      _fitted_text(candidate.parameters, candidate.notes), style=style)
    console.print(table)
