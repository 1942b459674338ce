"""`hydrojet-bench compare INPUT --params P [--baseline B] [--online] [--json PATH] [--report DIR]`.

Predicts every validation step (sweep >= 0; all steps when there are no sweeps) with the
calibrated, constant disturbance ("Ref.") and, with --online, with online disturbance
estimation ("Proposed"), and reports the errors as the paper's Table II does, then where
the model fails (`hydrojet_bench.analysis.breakdowns`). With --baseline, a second
parameter file (say, calibrated before an effect was added) is predicted on the same
steps and the errors are shown before and after.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console

from ..analysis.breakdowns import (MISSING_LABEL, STRAIGHT, STRAIGHT_BELOW_DEG, Breakdowns, JetScale, break_down,
                                   direction_order, disturbance_by_sweep, jet_force_scales, noise_only_gap,
                                   per_step)
from ..analysis.compare import Comparison, compare_methods, lead_in
from ..analysis.diagnosis import NoiseFloor, estimate_noise_floor
from ..analysis.diagnosis.fitting import scored_as_diagnosed
from ..analysis.metrics import ErrorSummary
from ..data.dataset import STEP_WINDOW_S, Dataset
from ..errors import UserError
from ..model_choice import ModelChoice, choose_model, model_choice
from ..models.shooting import ShootingModel
from . import render
from .common import add_input_arguments, add_model_arguments, comparison_steps
from .figure_options import add_format_argument
from .log_notice import (warn_if_fitted_on, warn_if_incomplete, warn_if_recorded_elsewhere, warn_if_uncalibrated,
                         warn_if_unsettled, warn_if_unsettled_steps)

LABELS = {"ref": "Ref.", "online": "Proposed"}
BREAKDOWN_KEYS = ("by_jet", "by_direction", "by_region", "loading_unloading", "over_time", "worst_poses")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("compare", help="model predictions against measurements (Table II), "
                                   "where the model fails, before/after an added effect")
    add_input_arguments(parser)
    add_model_arguments(parser, default="cosserat", params="the parameters to evaluate", params_required=True)
    parser.add_argument("--baseline", type=Path, metavar="BEFORE",
                        help="a second parameter file (e.g. calibrated without the added effect), "
                             "predicted on the same data with its own model and effects: errors before/after")
    parser.add_argument("--online", action="store_true", help="also run online disturbance estimation")
    render.add_json_argument(parser)
    parser.add_argument("--report", type=Path, metavar="DIR", help="write figures to this folder")
    add_format_argument(parser)
    parser.epilog = ("--effect adds effects to the --params model only; it also names the file of an effect "
                     "that a parameter file lists by name (e.g. one calibrated from path/to/file.py:Class).")
    parser.set_defaults(func=run)


@dataclass(frozen=True)
class Evaluation:
    """One parameter file's model predicted on the compared steps: a Comparison and its
    Breakdowns per method ("ref", "online"); with --baseline also Ref. as `diagnose`
    scores it (``as_diagnosed``: gravity held at the steps' mean when the base is
    static, see `analysis.diagnosis.fitting.session_gravity`), the figure its promise is
    checked against."""

    source: Path
    model: ShootingModel
    results: dict[str, Comparison]
    breakdowns: dict[str, Breakdowns]
    jet_scales: dict[str, JetScale]
    as_diagnosed: ErrorSummary | None = None
    uncalibrated: tuple[str, ...] = ()
    training: str | None = None  # the notice when the parameters were fitted on the steps compared

    @property
    def label(self) -> str:
        return f"{self.source} ({self.model.name}; {', '.join(e.name for e in self.model.effects)})"


def run(args: argparse.Namespace) -> int:
    render.check_json_output(args.json)  # before the work: it may not replace an input
    before_choice = None if args.baseline is None else choose_model(args.model, (), args.baseline,
                                                                    effect_files=args.effect)
    after_choice = model_choice(args)
    # On a session log's own settled steps, Ref. and Proposed are the live figures.
    profile, steps, validation = comparison_steps(args.input, args.profile)
    log_damage = warn_if_incomplete(args.input)
    profile_mismatch = warn_if_recorded_elsewhere(args.input, args.profile, profile)
    single_sample_steps = warn_if_unsettled(args.input, steps, log_damage)
    # A session log's steps are the session's own, each averaged over its session.window_s.
    unsettled_steps = warn_if_unsettled_steps(args.input, validation,
                                              None if Path(args.input).suffix.lower() == ".mcap" else STEP_WINDOW_S)

    def evaluate(choice: ModelChoice) -> Evaluation:
        params = choice.parameters(profile.model_parameters())
        results = compare_methods(choice.model, params, validation, profile.online_settings() if args.online else None,
                                  lead_in(steps))
        # diagnose's promise is checked the way it scored.
        as_diagnosed = None if before_choice is None else scored_as_diagnosed(choice.model, params, steps)
        return Evaluation(choice.parameter_path, choice.model, results,
                          {key: break_down(c, validation) for key, c in results.items()},
                          jet_force_scales(choice.model, params, validation), as_diagnosed,
                          warn_if_uncalibrated(choice, profile), warn_if_fitted_on(choice, args.input, validation))

    after = evaluate(after_choice)
    before = None if before_choice is None else evaluate(before_choice)
    noise = noise_floor(steps)
    console = render.console_for(args)
    print_tables(console, after.results, f"{after.model.name} on {args.input}")
    for evaluation in filter(None, (after, before)):
        if "online" in evaluation.results and evaluation.results["online"].fallbacks:
            render.progress_console().print(f"[yellow]warning:[/] {evaluation.source}: "
                                            f"{render.plain(evaluation.results['online'].fallback_notice())}")
    print_breakdowns(console, after, validation, noise)
    if before is not None:
        print_before_after(console, before, after)
    if args.json:
        write_json(args.json, validation, after, before, log_damage, noise, profile_mismatch, single_sample_steps,
                   unsettled_steps)
    if args.report:
        from ..analysis.report import write_report

        for path in write_report(args.report, after.results, validation, after.model.name,
                                 baseline=None if before is None else before.results,
                                 figure_format=args.figure_format):
            console.print(f"wrote {render.plain(path)}")
    return 0


# --- console -------------------------------------------------------------------------


def _cells(summary: ErrorSummary | None) -> list[str]:
    if summary is None:
        return ["-", "-"]
    return [f"{summary.orientation_rmse_deg:.2f}",
            "-" if summary.position_rmse_mm is None else f"{summary.position_rmse_mm:.2f}"]


def _method_headers(keys) -> list[str]:
    return [f"{LABELS[key]} {quantity}" for key in keys for quantity in ("orient. (deg)", "pos. (mm)")]


def print_tables(console: Console, results: dict[str, Comparison], title: str) -> None:
    table = render.table(f"RMS errors, {title}", labels=("group",), numbers=_method_headers(results),
                         caption="bend bins in degrees, as the paper's Table II")
    reference = results["ref"]

    def row(label: str, pick: Callable[[Comparison], ErrorSummary]) -> None:
        table.add_row(label, *[cell for comparison in results.values() for cell in _cells(pick(comparison))])

    row("all", lambda c: c.overall)
    for sweep in reference.by_sweep:
        row(f"sweep {sweep}", lambda c, s=sweep: c.by_sweep[s])
    for bend in reference.by_bend:
        row(f"bend {_bend_label(bend)}", lambda c, b=bend: c.by_bend[b])
    console.print(table)


def noise_floor(steps: Dataset) -> NoiseFloor | None:
    """The noise floor `diagnose` measures (repeatability of repeated sweeps), or None
    when no sweep repeats."""
    try:
        return estimate_noise_floor(steps)
    except UserError:
        return None


def print_breakdowns(console: Console, evaluation: Evaluation, steps: Dataset, noise: NoiseFloor | None) -> None:
    """Compact tables of where the model fails; the full series go to JSON and plots."""
    parts = evaluation.breakdowns
    reference = parts["ref"]
    table = render.table(f"Where the model fails: RMS errors by physical grouping ({evaluation.model.name})",
                         labels=("group",), numbers=["n", *_method_headers(parts)],
                         caption="direction: azimuth of the measured tip tangent in the base frame; hysteresis "
                                 "gap: mean norm of the difference of the error vectors at equal forces, "
                                 "judged below against the noise floor")

    def across(cells: Callable[[Breakdowns], list[str]]) -> list[str]:
        return [cell for part in parts.values() for cell in cells(part)]

    def rows(label: str, pick: Callable[[Breakdowns], dict[str, ErrorSummary]], name: Callable[[str], str]) -> None:
        for key, summary in pick(reference).items():
            table.add_row(f"{label} {name(key)}", str(summary.count), *across(lambda b: _cells(pick(b).get(key))))
        table.add_section()

    rows("driven by", lambda b: b.by_jet, str)
    rows("bending", lambda b: b.by_direction,
         lambda key: f"straight (< {STRAIGHT_BELOW_DEG:g} deg)" if key == STRAIGHT else f"to {key} deg")
    for phase in ("loading", "unloading"):
        summary = getattr(reference.loading, phase)
        if summary is not None:
            table.add_row(phase, str(summary.count), *across(lambda b: _cells(getattr(b.loading, phase))))
    if reference.loading.matched_pairs:
        table.add_row("hysteresis gap", str(reference.loading.matched_pairs), *across(
            lambda b: [_number(b.loading.hysteresis_gap_deg), _number(b.loading.hysteresis_gap_mm)]))
    table.add_section()
    start = steps.time_s[0]
    for index, block in enumerate(reference.drift.blocks):
        table.add_row(f"{(block.start_s - start) / 60:.1f}-{(block.end_s - start) / 60:.1f} min",
                      str(block.summary.count), *across(lambda b: _cells(b.drift.blocks[index].summary)))
    table.add_row("trend per min", "", *across(lambda b: [_number(b.drift.trend_deg_per_min, signed=True),
                                                          _number(b.drift.trend_mm_per_min, signed=True)]))
    console.print(table)
    print_jet_scales(console, evaluation)
    if reference.loading.hysteresis_gap_deg is not None:
        console.print(_gap_line(reference, noise), highlight=False)
    print_region(console, reference, evaluation.model.name)
    print_worst(console, evaluation)
    if "online" in evaluation.results:
        console.print(_missing_line(evaluation.results["online"], steps))


def print_jet_scales(console: Console, evaluation: Evaluation) -> None:
    if not evaluation.jet_scales:
        return
    table = render.table(f"Force scale of each jet, from a fit of one gain per jet ({evaluation.model.name})",
                         labels=("jet",), numbers=("steps", "scale", "+-", "relative", "+-"),
                         caption="scale: a gain on each jet's commanded force, fitted with E0, EL, L and w_d on "
                                 "the compared steps (1: as the model assumes); relative: over the jets' mean. A "
                                 "calibration absorbs a weak jet into E, so its per-jet error need not stand out; "
                                 "a relative scale below 1 by several standard errors does")
    for label, scale in evaluation.jet_scales.items():
        table.add_row(label, str(scale.steps), f"{scale.scale:.3f}", f"{scale.standard_error:.3f}",
                      f"{scale.relative:.3f}", f"{scale.relative_standard_error:.3f}")
    console.print(table)
    unconverged = next((scale for scale in evaluation.jet_scales.values() if not scale.converged), None)
    if unconverged is not None:
        render.progress_console().print(f"[yellow]warning:[/] the fit of the jets' scales is "
                                        f"{render.plain(unconverged.convergence)}: read them as rough")


def _gap_line(reference: Breakdowns, noise: NoiseFloor | None) -> str:
    loading = reference.loading
    gap = f"Hysteresis gap of Ref. {loading.hysteresis_gap_deg:.3f} deg over {loading.matched_pairs} pairs"
    if noise is None:
        return f"{gap}: no noise floor to judge it by (no sweep repeats)."
    verdict = noise_only_gap(loading.hysteresis_gap_deg, loading.matched_pairs, noise.orientation_deg)
    judged = ("beyond noise: the branches differ (clamp play, friction, or a rod with several shapes under one "
              "load?)" if verdict.beyond_noise
              else "within noise")
    return (f"{gap}; noise alone gives {verdict.noise_only_deg:.3f} deg (up to {verdict.limit_deg:.3f} deg) at the "
            f"noise floor of {noise.orientation_deg:.3f} deg ({noise.method}, as diagnose measures it): {judged}.")


def _bend_label(bend_bin: str) -> str:
    """A Table II bin label ("25", ">75") as a bound: "<=25", ">75"."""
    return bend_bin if str(bend_bin).startswith(">") else f"<={bend_bin}"


def _number(value: float | None, signed: bool = False) -> str:
    return "-" if value is None else f"{value:+.3f}" if signed else f"{value:.2f}"


def print_region(console: Console, reference: Breakdowns, model_name: str) -> None:
    directions = [d for d in direction_order() if any(d in row for row in reference.by_region.values())]
    table = render.table(f"Ref. orientation RMSE (deg) by region of the workspace ({model_name})",
                         labels=("bend (deg)",), numbers=directions,
                         caption="rows: measured bend bin (Table II); columns: bending direction (azimuth, deg)")
    for bend, row in reference.by_region.items():
        table.add_row(_bend_label(bend),
                      *[f"{row[d].orientation_rmse_deg:.2f}" if d in row else "" for d in directions])
    console.print(table)


def print_worst(console: Console, evaluation: Evaluation) -> None:
    worst = evaluation.breakdowns["ref"].worst
    online = evaluation.results.get("online")
    table = render.table(f"Worst poses of Ref. ({evaluation.model.name})",
                         labels=("row", "sweep", "step", "q1, q2, q3"),
                         numbers=["bend", "Ref. orient.", "Ref. pos.",
                                  *(["Proposed orient."] if online is not None else [])],
                         caption="row: index among the compared steps; q in mN; bend as measured, deg; "
                                 "errors in deg and mm (azimuths in the JSON)")
    for pose in worst:
        cells = [str(pose.index), str(pose.sweep), str(pose.step),
                 ", ".join(f"{force * 1e3:.0f}" for force in pose.jet_forces_n), f"{pose.bend_deg:.1f}",
                 f"{pose.orientation_error_deg:.2f}", _number(pose.position_error_mm)]
        if online is not None:
            cells.append(f"{online.orientation_error_deg[pose.index]:.2f}")
        table.add_row(*cells)
    console.print(table)


def _missing_line(online: Comparison, steps: Dataset) -> str:
    norm_mnm = _moment_norm_nm(online) * 1e3
    peak = int(np.argmax(norm_mnm))
    return (f"{MISSING_LABEL.capitalize()} (online disturbance moment): mean norm {norm_mnm.mean():.3f} mN m, "
            f"largest {norm_mnm[peak]:.3f} mN m at sweep {steps.sweep[peak]} step {steps.step[peak]}; "
            "per-sweep series in the JSON and the report.")


def print_before_after(console: Console, before: Evaluation, after: Evaluation) -> None:
    console.print(f"before: {before.label}\nafter:  {after.label}")
    for key in after.results:
        old, new = before.results[key], after.results[key]
        table = render.table(f"{LABELS[key]} RMS errors before -> after", labels=("group",),
                             numbers=[f"{quantity} {column}" if column == "before" else column
                                      for quantity in ("orient. (deg)", "pos. (mm)")
                                      for column in ("before", "after", "change")])

        def row(label: str, pick: Callable[[Comparison], ErrorSummary]) -> None:
            first, second = pick(old), pick(new)
            cells = []
            for name in ("orientation_rmse_deg", "position_rmse_mm"):
                a, b = getattr(first, name), getattr(second, name)
                cells += [_number(a), _number(b), _change(a, b)]
            table.add_row(label, *cells)

        row("all", lambda c: c.overall)
        if key == "ref" and after.as_diagnosed is not None and before.as_diagnosed is not None:
            row("all, as diagnose scores", lambda c: (after if c is new else before).as_diagnosed)
        for sweep in new.by_sweep:
            row(f"sweep {sweep}", lambda c, s=sweep: c.by_sweep[s])
        if key == "ref":
            table.caption = ("as diagnose scores: gravity held at the steps' mean (a clamped base), as diagnose "
                             "fits and scores; compare this row with the errors diagnose promised")
        console.print(table)
    if "online" in after.results:
        means = [float(_moment_norm_nm(e.results["online"]).mean()) for e in (before, after)]
        console.print(f"{MISSING_LABEL.capitalize()} (online disturbance moment, mean norm): "
                      f"{means[0] * 1e3:.3f} mN m before, {means[1] * 1e3:.3f} mN m after ({_change(*means)})")


def _change(before: float | None, after: float | None) -> str:
    if before is None or after is None:
        return "-"
    return f"{(after - before) / before:+.0%}" if before > 0 else f"{after - before:+.2f}"


def _moment_norm_nm(online: Comparison) -> np.ndarray:
    return np.linalg.norm(online.predictions.disturbance_moment_nm, axis=1)


# --- JSON ----------------------------------------------------------------------------


def figures(evaluation: Evaluation, steps: Dataset) -> dict:
    """The JSON document of one evaluation: Table II figures keyed by method (the keys
    `compare` has always written), the breakdowns, per-step series, the missing wrench
    (with online estimation) and which parameters were evaluated."""
    results = evaluation.results
    tables = {key: comparison.as_dict() for key, comparison in results.items()}
    document = {name: {key: value[name] for key, value in tables.items()}
                for name in ("orientation_rmse_deg", "position_rmse_mm", "by_sweep", "by_bend")}
    details = {key: part.as_dict() for key, part in evaluation.breakdowns.items()}
    document.update({name: {key: value[name] for key, value in details.items()} for name in BREAKDOWN_KEYS})
    document["per_step"] = {key: per_step(comparison, steps) for key, comparison in results.items()}
    if "online" in results:
        document["online_fallbacks"] = [{"step": index, "what": what} for index, what in results["online"].fallbacks]
    if "online" in results:
        document["missing_wrench"] = {
            "label": MISSING_LABEL, "quantity": "online disturbance estimate, moment part, N m, tip frame",
            "by_sweep": {str(s): v for s, v in disturbance_by_sweep(results["online"].predictions, steps).items()}}
    document["jet_force_scale"] = {label: scale.as_dict() for label, scale in evaluation.jet_scales.items()}
    if evaluation.as_diagnosed is not None:
        document["as_diagnosed"] = {**evaluation.as_diagnosed.as_dict(),
                                    "gravity": "the steps' mean when the base is static, as diagnose scores"}
    document["parameters"] = {"file": str(evaluation.source), "model": evaluation.model.name,
                              "effects": [effect.name for effect in evaluation.model.effects],
                              "uncalibrated": list(evaluation.uncalibrated),
                              "held_out": evaluation.training is None, "training_notice": evaluation.training}
    return document


def write_json(path: Path, steps: Dataset, evaluation: Evaluation, baseline: Evaluation | None = None,
               log_damage: dict | None = None, noise: NoiseFloor | None = None,
               profile_mismatch: dict | None = None, single_sample_steps: dict | None = None,
               unsettled_steps: dict | None = None) -> None:
    document = figures(evaluation, steps)
    document["log_damage"] = log_damage
    document["profile_mismatch"] = profile_mismatch
    document["single_sample_steps"] = single_sample_steps
    document["unsettled_steps"] = unsettled_steps
    document["noise_floor"] = None if noise is None else noise.as_dict()
    gap = evaluation.breakdowns["ref"].loading
    document["hysteresis_gap_vs_noise"] = (None if noise is None or gap.hysteresis_gap_deg is None else
                                           noise_only_gap(gap.hysteresis_gap_deg, gap.matched_pairs,
                                                          noise.orientation_deg).as_dict())
    if baseline is not None:
        document["baseline"] = figures(baseline, steps)
    render.write_json(path, document)
