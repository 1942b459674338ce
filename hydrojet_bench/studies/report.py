"""A study's report: figures (PNG) and ``summary.md`` from its rows.

* confusion matrix, hidden truth x verdict, one panel per plan;
* detection power against effect size per swept effect parameter: the share of cells
  (seeds) whose verdict is right, one line per setting (`setting_columns`),
  log x when the sizes span a decade or more; the smallest size detected in at least
  `POWER_LEVEL` of the cells is the protocol's detection limit;
* parameter recovery: fitted minus true over the fit's standard error (a z score) of the
  swept parameter, per effect, when the diagnosis fitted it; the recovery table gives,
  per effect, the share of cells where the effect was detected whose true value lies
  within 2 standard errors (`COVERAGE_Z`), the coverage honest errors give ~95 %;
* plans side by side: the share of verdicts naming the hidden effect per truth and plan
  (and profile and noise level where the study has several).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.ticker import NullFormatter  # noqa: E402

from ..analysis.figures import save as _save  # noqa: E402
from ..errors import UserError  # noqa: E402

POWER_LEVEL = 0.9
COVERAGE_Z = 2.0
# Sizes spanning this ratio or more are plotted on a log axis.
LOG_SPAN = 10.0
SETTING = ["plan", "model", "orientation"]
# Also part of a setting where the rows hold more than one: a share pooled over noise
# levels or rigs answers none of the questions such a study asks.
VARIED = ["profile", "noise_scale"]
# Names of the setting's columns in legends and axis labels.
LEGEND_TITLES = {"truth": "hidden truth", "plan": "plan", "model": "model", "orientation": "rod",
                 "profile": "profile", "noise_scale": "noise"}
MARKERS = ("o", "s", "^", "D", "v", "P")
DASHES = ("-", "--", ":", "-.")


def write_report(rows: pd.DataFrame, folder: Path) -> list[Path]:
    """Write the figures and ``summary.md`` into ``folder``; returns their paths."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UserError(f"cannot create report folder {folder}: {error.strerror}") from None
    finished = rows[rows["error"].isna()]
    paths = []
    if len(finished):
        paths += [_confusion(folder, finished), _plans(folder, finished)]
        sweeps = finished[finished["kind"] == "sweep"]
        if len(sweeps):
            paths.append(_power(folder, sweeps))
        if sweeps["recovery_z"].notna().any():
            paths.append(_recovery(folder, sweeps))
    summary = folder / "summary.md"
    summary.write_text(summary_markdown(rows))
    return paths + [summary]


def confusion_table(rows: pd.DataFrame) -> pd.DataFrame:
    """Counts of cells by hidden truth (rows) and verdict (columns)."""
    return pd.crosstab(rows["truth"], rows["verdict"])


def setting_columns(rows: pd.DataFrame) -> list[str]:
    """What tells one setting's cells from another's: `SETTING`, and each of `VARIED`
    that takes more than one value in ``rows``."""
    return SETTING + [column for column in VARIED if column in rows and rows[column].nunique() > 1]


def detection_limits(sweeps: pd.DataFrame) -> pd.DataFrame:
    """Per swept parameter and setting: the detection rate at each size and the
    smallest size detected in at least `POWER_LEVEL` of the cells (NaN: never)."""
    setting = setting_columns(sweeps)
    power = (sweeps.groupby(["truth", "parameter", *setting, "size"])["detected"].agg(["mean", "count"])
             .reset_index())
    limits = []
    for key, group in power.groupby(["truth", "parameter", *setting]):
        reached = group[group["mean"] >= POWER_LEVEL]
        default = sweeps[sweeps["parameter"] == key[1]]["size_default"].iloc[0]
        limits.append((*key, _smallest(reached["size"], default), len(group), int(group["count"].sum())))
    return pd.DataFrame(limits, columns=["truth", "parameter", *setting, "smallest_detected", "sizes", "cells"])


def plans_table(rows: pd.DataFrame) -> pd.DataFrame:
    """The share of verdicts naming the hidden effect (single effects and none), per
    truth (and profile and noise level where they vary, `setting_columns`) and plan."""
    single = rows[rows["kind"] != "pair"]
    index = ["truth", *(column for column in setting_columns(single) if column in VARIED)]
    return single.pivot_table(index=index, columns="plan", values="detected", aggfunc="mean")


def recovery_table(sweeps: pd.DataFrame) -> pd.DataFrame:
    """Per swept parameter, over the cells where its effect was detected and fitted: the
    share whose true value lies within `COVERAGE_Z` standard errors, the median z and
    the count."""
    detected = sweeps[sweeps["detected"] & sweeps["recovery_z"].notna()]
    return (detected.groupby("parameter")["recovery_z"]
            .agg(coverage_2se=lambda z: float((z.abs() <= COVERAGE_Z).mean()), median_z="median", cells="count")
            .reset_index())


def _smallest(sizes: pd.Series, default: float) -> float:
    """The size closest to the parameter's default (its "no effect" value)."""
    if sizes.empty:
        return float("nan")
    return float(sizes.loc[(sizes - default).abs().idxmin()])


def summary_markdown(rows: pd.DataFrame) -> str:
    failed = rows[rows["error"].notna()]
    finished = rows[rows["error"].isna()]
    timing = (f"; {finished['seconds'].mean():.1f} s per cell on average (one worker's time)" if len(finished)
              else "")
    lines = ["# Study summary", "", f"{len(rows)} cells: {len(finished)} diagnosed, {len(failed)} failed{timing}.", ""]
    if len(finished):
        right = finished[finished["kind"] != "pair"]["detected"].mean()
        lines += [f"Verdicts naming the hidden effect itself (single effects and none; an effect below detection "
                  f"counts as missed): {right:.0%}.", ""]
        if "right" in finished and finished["right"].notna().any():
            lines += [_issue_figures(finished), ""]
        lines += [
                  "## Confusion matrix (cells; rows: hidden truth, columns: verdict)", "",
                  _markdown(confusion_table(finished).reset_index()), ""]
        sweeps = finished[finished["kind"] == "sweep"]
        if len(sweeps):
            limits = detection_limits(sweeps)
            lines += [f"## Detection limits (smallest size detected in >= {POWER_LEVEL:.0%} of the cells; "
                      "sizes in the parameter's own unit, NaN: never)", "", _markdown(limits), ""]
            recovered = sweeps[sweeps["recovery_z"].notna()]
            if len(recovered):
                stats = recovered.groupby("parameter")["recovery_z"].agg(
                    median="median", share_within_2=lambda z: float((z.abs() <= 2).mean()),
                    cells="count").reset_index()
                lines += ["## Parameter recovery ((fitted - true) / standard error)", "", _markdown(stats), ""]
                table = recovery_table(sweeps)
                if len(table):
                    covered = (sweeps["detected"] & (sweeps["recovery_z"].abs() <= COVERAGE_Z)).sum()
                    fitted = (sweeps["detected"] & sweeps["recovery_z"].notna()).sum()
                    lines += [f"## Recovery table: where the effect was detected, the true value within "
                              f"{COVERAGE_Z:g} standard errors ({covered} of {fitted} cells, "
                              f"{covered / fitted:.0%})", "", _markdown(table), ""]
        lines += ["## Plans side by side (share of verdicts naming the hidden effect)", "",
                  _markdown(plans_table(finished).reset_index()), ""]
    if len(failed):
        lines += ["## Failed cells", "", _markdown(failed[["scenario", "seed", "plan", "model", "error"]]), ""]
    return "\n".join(lines)


def _issue_figures(finished: pd.DataFrame) -> str:
    """Issue 12's figures: right verdicts (the hidden effect named or an alternative,
    every one of a pair, "none" at the floor), the named effects' held-out error over
    the floor, fits left unconverged or on a bound."""
    right = finished["right"].astype(bool)
    named = finished[finished["final_heldout_rmse_deg"].notna()]
    ratio = named["final_heldout_rmse_deg"] / named["noise_floor_deg"]
    return (f"Right verdicts (the hidden effect named or listed as an alternative, every effect of a pair, none "
            f"where the effect leaves the held-out error at the floor): {int(right.sum())} of {len(finished)} "
            f"({right.mean():.0%}). Held-out error "
            f"with the named effect(s) over the noise floor: median {ratio.median():.2f}, "
            f"{int((ratio <= 1.2).sum())} of {len(ratio)} cells within 1.2x. Fits left unconverged: "
            f"{int(finished['unconverged_fits'].sum())} (in {int((finished['unconverged_fits'] > 0).sum())} cells); "
            f"named effects on a bound: {int(finished['bound_clipped'].astype(bool).sum())} cells.")


def _markdown(table: pd.DataFrame) -> str:
    def text(value: object) -> str:
        if isinstance(value, float):
            return "NaN" if np.isnan(value) else f"{value:.4g}"
        return str(value).replace("|", "\\|")

    header = "| " + " | ".join(str(c) for c in table.columns) + " |"
    rule = "|" + "---|" * len(table.columns)
    body = ["| " + " | ".join(text(v) for v in row) + " |" for row in table.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def _confusion(folder: Path, rows: pd.DataFrame) -> Path:
    plans = sorted(rows["plan"].unique())
    truths = sorted(rows["truth"].unique())
    verdicts = sorted(rows["verdict"].unique())
    size = (3.5 + 0.9 * len(verdicts) * len(plans), 2.5 + 0.45 * len(truths))
    figure, axes = plt.subplots(1, len(plans), figsize=size, squeeze=False, layout="constrained")
    for axis, plan in zip(axes[0], plans):
        counts = pd.crosstab(rows[rows["plan"] == plan]["truth"], rows[rows["plan"] == plan]["verdict"]) \
            .reindex(index=truths, columns=verdicts, fill_value=0)
        share = counts.div(counts.sum(axis=1).replace(0, 1), axis=0)
        image = axis.imshow(share.to_numpy(), cmap="Blues", vmin=0.0, vmax=1.0, aspect="auto")
        for (i, j), count in np.ndenumerate(counts.to_numpy()):
            if count:
                axis.text(j, i, str(count), ha="center", va="center",
                          color="white" if share.iat[i, j] > 0.6 else "black", fontsize=8)
        axis.set_xticks(range(len(verdicts)), verdicts, rotation=45, ha="right")
        axis.set_yticks(range(len(truths)), truths)
        axis.set_xlabel("verdict")
        axis.set_ylabel("hidden truth")
        axis.set_title(f"plan {Path(plan).name}")
    figure.colorbar(image, ax=axes[0].tolist(), label="share of the truth's cells")
    figure.suptitle("Diagnosis: hidden truth x verdict (cell counts)")
    return _save(figure, folder / "confusion.png")


def _power(folder: Path, sweeps: pd.DataFrame) -> Path:
    parameters = sorted(sweeps["parameter"].unique())
    setting = setting_columns(sweeps)  # of the whole study: every panel's legend alike
    columns = min(3, len(parameters))
    lines = (len(parameters) + columns - 1) // columns
    figure, axes = plt.subplots(lines, columns, figsize=(4.5 * columns, 3.4 * lines), squeeze=False,
                                layout="constrained")
    for axis, parameter in zip(axes.flat, parameters):
        group = sweeps[sweeps["parameter"] == parameter]
        for line, (values, part) in enumerate(group.groupby(setting)):
            rate = part.groupby("size")["detected"].mean()
            # Settings often agree: markers and dashes that differ keep every line visible.
            axis.plot(rate.index, rate.to_numpy(), marker=MARKERS[line % len(MARKERS)],
                      linestyle=DASHES[line % len(DASHES)], markersize=8 - 1.5 * (line % 3),
                      label=_setting_label(setting, values))
        sizes = group["size"].abs()
        positive = sizes[sizes > 0]
        if len(positive) and (group["size"] > 0).all() and positive.max() / positive.min() >= LOG_SPAN:
            axis.set_xscale("log")
            axis.xaxis.set_minor_formatter(NullFormatter())
        axis.axhline(POWER_LEVEL, color="0.5", linestyle=":", linewidth=0.8)
        axis.set_ylim(-0.05, 1.05)
        axis.set_xlabel(f"{parameter} ({group['unit'].iloc[0]})")
        axis.set_ylabel("share detected")
        axis.set_title(group["truth"].iloc[0])
        axis.legend(fontsize=7, title=" / ".join(LEGEND_TITLES[column] for column in setting), title_fontsize=7)
    for axis in list(axes.flat)[len(parameters):]:
        axis.set_visible(False)
    figure.suptitle(f"Detection power against effect size (dotted: {POWER_LEVEL:.0%})")
    return _save(figure, folder / "power.png")


def _setting_label(columns: list[str], values: tuple) -> str:
    return " / ".join(f"x{value:g}" if column == "noise_scale" else Path(str(value)).name
                      for column, value in zip(columns, values))


def _recovery(folder: Path, sweeps: pd.DataFrame) -> Path:
    recovered = sweeps[sweeps["recovery_z"].notna()]
    parameters = sorted(recovered["parameter"].unique())
    figure, axis = plt.subplots(figsize=(max(6.5, 1.4 * len(parameters) + 2), 4.5), layout="constrained")
    data = [recovered[recovered["parameter"] == p]["recovery_z"].clip(-20, 20).to_numpy() for p in parameters]
    axis.boxplot(data, showfliers=True)
    axis.set_xticks(range(1, len(parameters) + 1), parameters, rotation=30, ha="right", fontsize=8)
    axis.axhspan(-2.0, 2.0, color="C2", alpha=0.15, label="|z| <= 2")
    axis.axhline(0.0, color="k", linewidth=0.8)
    axis.set_ylabel("(fitted - true) / standard error")
    axis.set_title("Recovery of the swept parameter (z clipped at +-20)")
    axis.legend(fontsize=8)
    return _save(figure, folder / "recovery.png")


def _plans(folder: Path, rows: pd.DataFrame) -> Path:
    table = plans_table(rows)
    labels = [_setting_label(["truth", *table.index.names[1:]], key if isinstance(key, tuple) else (key,))
              for key in table.index]
    figure, axis = plt.subplots(figsize=(max(6.0, 0.8 * len(table) + 2), 4.0), layout="constrained")
    width = 0.8 / max(len(table.columns), 1)
    for index, plan in enumerate(table.columns):
        axis.bar(np.arange(len(table)) + index * width, table[plan].to_numpy(), width, label=Path(plan).name)
    axis.set_xticks(np.arange(len(table)) + 0.4 - width / 2, labels, rotation=30, ha="right")
    axis.set_ylim(0, 1.05)
    axis.set_ylabel("share naming the hidden effect")
    axis.set_xlabel(" / ".join(LEGEND_TITLES[name] for name in ["truth", *table.index.names[1:]]))
    axis.set_title("Plans side by side: verdicts naming the hidden effect")
    axis.legend(title="plan", fontsize=8)
    return _save(figure, folder / "plans.png")
