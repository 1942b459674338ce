"""The add step, measured: for every library effect hidden in the twin at a clearly
detectable size, what `diagnose` promises and what the commands it prints then show.

diagnose promises two things: the held-out error before and after the effect (fits on
the training steps, scored on the held-out repetitions), and what the printed compare
will show on its row "as diagnose scores" (``add_step`` in its JSON: both calibrations
fit every row, the held-out ones too). The table gives compare against both.

    python docs/studies/add_step.py [--model cosserat] [--folder add-step] [--json add_step.json]

For each effect: `simulate --hidden ...` (the paper's protocol, seed 1; the rod hanging,
or horizontal where noted), `diagnose --json`
(the promise: the baseline's and the verdict's held-out orientation RMSE), then every
command diagnose printed, run as printed (its compare with `--json` added), and the
Ref. orientation RMSE compare reports for the baseline and for the added effect "as
diagnose scores" (gravity at the steps' mean; Table II's per-step figure beside it). The
table gives each ratio compare / promise; the add step holds when both are within 10 %.
Runs the command line in subprocesses, as a user would, from ``--folder`` (created).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

# A clearly detectable size of each library effect: the middle size of
# docs/studies/library.toml (the clamp with play at its compliance there), or its largest
# where the middle one is below what the paper's protocol detects (diagnose: none). The
# rod hangs (profile sim) except where the effect acts through its sag: there it is
# horizontal (HORIZONTAL), where the hanging rod leaves even the largest size unseen.
HORIZONTAL = str(Path(__file__).resolve().parent / "sim-horizontal.toml")
PROFILES = {"nonlinear_elasticity": HORIZONTAL, "stiffness_profile": HORIZONTAL}
HIDDEN = {
    "gravity": "gravity=1.5",
    "jet_gain": "jet_gain:gain_1=0.8",
    "jet_misalignment": "jet_misalignment=0.1",
    "pressure_stiffening": "pressure_stiffening=0.63",
    "nonlinear_elasticity": "nonlinear_elasticity=2e-4",
    "anisotropic_stiffness": "anisotropic_stiffness=1.3",
    "stiffness_profile": "stiffness_profile=0.5",
    "base_compliance": "base_compliance=100",
    "base_hysteresis": "base_hysteresis=20,0.01",
    "sensor_mounting": "sensor_mounting:rx_rad=0.03",
    "tip_pull": "tip_pull:force_x_n=0.01",
}
PROGRAM = [sys.executable, "-m", "hydrojet_bench.cli"]


def run(words: list[str], folder: Path) -> str:
    done = subprocess.run(PROGRAM + words, cwd=folder, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(words)} exited {done.returncode}: {done.stderr.strip()}")
    return done.stdout


def printed_commands(output: str) -> list[list[str]]:
    """The commands a command printed: the lines that start with ``hydrojet-bench``."""
    return [shlex.split(line, comments=True)[1:] for line in output.splitlines()
            if line.strip().startswith("hydrojet-bench ")]


def measure(effect: str, spec: str, model: str, folder: Path) -> dict:
    work = folder / effect
    work.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    profile = ["--profile", PROFILES[effect]] if effect in PROFILES else []
    run(["simulate", "-o", "data.csv", "--overwrite", "--hidden", spec, "--seed", "1", *profile], work)
    diagnosis_output = run(["diagnose", "data.csv", *profile, "--model", model, "--json", "diagnosis.json"], work)
    diagnosis = json.loads((work / "diagnosis.json").read_text())
    winner = next((c for c in diagnosis["ranking"] if c["effect"] == diagnosis["verdict"]), None)
    row = {"effect": effect, "hidden": spec, "rig": Path(PROFILES.get(effect, "sim")).stem,
           "verdict": diagnosis["verdict"],
           "noise_floor_deg": diagnosis["noise_floor_deg"],
           "promised_before_deg": diagnosis["baseline"]["heldout_orientation_rmse_deg"],
           "promised_after_deg": None if winner is None else winner["heldout_orientation_rmse_deg"]}
    preview = diagnosis.get("add_step") or {}
    row["preview_before_deg"] = preview.get("compare_before_deg")
    row["preview_after_deg"] = preview.get("compare_after_deg")
    commands = printed_commands(diagnosis_output)
    row["commands"] = [" ".join(shlex.quote(word) for word in words) for words in commands]
    for words in commands:
        if words[0] == "compare":
            words = words + ["--json", "compare.json"]
        run(words, work)
    if (work / "compare.json").exists() and winner is not None:
        figures = json.loads((work / "compare.json").read_text())
        row["compare_before_deg"] = figures["baseline"]["as_diagnosed"]["orientation_rmse_deg"]
        row["compare_after_deg"] = figures["as_diagnosed"]["orientation_rmse_deg"]
        row["table_ii_before_deg"] = figures["baseline"]["orientation_rmse_deg"]["ref"]
        row["table_ii_after_deg"] = figures["orientation_rmse_deg"]["ref"]
        row["before_ratio"] = row["compare_before_deg"] / row["promised_before_deg"]
        row["after_ratio"] = row["compare_after_deg"] / row["promised_after_deg"]
        if row["preview_before_deg"] is not None:
            row["preview_before_ratio"] = row["compare_before_deg"] / row["preview_before_deg"]
            row["preview_after_ratio"] = row["compare_after_deg"] / row["preview_after_deg"]
    row["elapsed_s"] = time.perf_counter() - started
    (work / "compare.json").unlink(missing_ok=True)
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="cosserat", choices=("cosserat", "prb"))
    parser.add_argument("--folder", type=Path, default=Path("add-step"))
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--effect", action="append", default=[], choices=tuple(HIDDEN),
                        help="only these effects (repeatable; default: all)")
    args = parser.parse_args()
    os.environ.setdefault("PYTHONPATH", str(Path(__file__).resolve().parents[2]))
    rows = []
    print("| effect | hidden | rig | verdict | floor | held-out promise before -> after (deg) "
          "| add-step promise before -> after (deg) | compare before -> after (deg) "
          "| ratio to held-out before, after | ratio to add-step promise before, after "
          "| Table II all, before -> after (deg) | s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for effect in args.effect or HIDDEN:
        row = measure(effect, HIDDEN[effect], args.model, args.folder)
        rows.append(row)

        def number(key: str, digits: str = ".3f") -> str:
            value = row.get(key)
            return "-" if value is None else format(value, digits)

        print(f"| {effect} | `{row['hidden']}` | {row['rig']} | {row['verdict']} | {number('noise_floor_deg')} "
              f"| {number('promised_before_deg')} -> {number('promised_after_deg')} "
              f"| {number('preview_before_deg')} -> {number('preview_after_deg')} "
              f"| {number('compare_before_deg')} -> {number('compare_after_deg')} "
              f"| {number('before_ratio', '.2f')}, {number('after_ratio', '.2f')} "
              f"| {number('preview_before_ratio', '.3f')}, {number('preview_after_ratio', '.3f')} "
              f"| {number('table_ii_before_deg')} -> {number('table_ii_after_deg')} | {number('elapsed_s', '.0f')} |",
              flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
