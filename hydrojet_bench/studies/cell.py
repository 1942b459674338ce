"""Running one cell: the twin with the hidden effect(s) at their sizes plays the plan,
the recording is diagnosed as `hydrojet-bench diagnose` would, and the outcome is one
flat row (see `ROW_COLUMNS`). Runs in a Dask worker; any exception becomes a row with
the error text, so one bad scenario never stops a study.
"""

from __future__ import annotations

import json
import math
import time
import traceback

from ..analysis.diagnosis import UNEXPLAINED, Diagnosis, DiagnosisSettings, diagnose
from ..effects import load_effect
from ..geometry import quat_multiply
from ..profile import hanging_orientation, load_profile
from ..analysis.diagnosis.setup import setup_hypothesis
from ..twin import DigitalTwin, TwinConfig, parse_setup_error, setup_error_text
from .cells import NONE, Cell
from .spec import study_plan

# From hanging to lying across gravity: a half turn about the base frame's (x + z) axis
# takes its z to where its x was, so gravity falls along the base x axis (w, x, y, z).
# Under the default tracker (z up) the rod then lies along the tracker's x axis.
HANGING_TO_HORIZONTAL = (0.0, math.sqrt(0.5), 0.0, math.sqrt(0.5))
# The diagnosis averages each step over its last second: nothing earlier is recorded.
RECORD_WINDOW_S = 1.0

# Column name -> pyarrow type name (see `store`); every row has all of them.
ROW_COLUMNS: dict[str, str] = {
    "cell_id": "string", "scenario": "string", "kind": "string", "truth": "string", "truth_values": "string",
    "parameter": "string", "size": "float64", "size_default": "float64", "unit": "string", "profile": "string", "orientation": "string", "plan": "string",
    "model": "string", "seed": "int64", "noise_scale": "float64", "verdict": "string", "detected": "bool",
    "alternatives": "string", "baseline_heldout_rmse_deg": "float64", "winner_heldout_rmse_deg": "float64",
    "noise_floor_deg": "float64", "fitted": "string", "fitted_value": "float64",
    "fitted_standard_error": "float64", "recovery_z": "float64", "converged": "bool", "seconds": "float64",
    "error": "string", "found": "string", "final_heldout_rmse_deg": "float64", "at_floor_threshold_deg": "float64",
    "unconverged_fits": "int64", "bound_clipped": "bool", "right": "bool",
}


def expected_verdict(cell: Cell) -> str | None:
    """The verdict a perfect diagnosis gives: "none", the one library effect hidden, or
    "unexplained" for an effect outside the library; None for a pair (any one of them
    is a partial answer, see the report)."""
    if cell.kind == "pair":
        return None
    if cell.setup is not None:
        return setup_hypothesis(parse_setup_error(setup_error_text(*cell.setup)))
    if cell.kind == NONE:
        return NONE
    from_file = ":" in cell.effects[0]  # library effects go by name, others by path/to/file.py:Class
    return UNEXPLAINED if from_file else cell.truth


def right_verdict(cell: Cell, diagnosis: Diagnosis) -> bool:
    """Issue 12's "right": the hidden effect (every hidden one for a pair) named or
    listed as an alternative; or "none" where the baseline's held-out error is at the
    floor (the effect below detection); "unexplained" for an effect outside the library.

    A pair is also right when every effect named is one of the pair (or tied with one)
    and the named ones leave the held-out error at the floor: the other is then below
    detection on these data, the rule that makes "none" right for a single effect,
    applied to what the first effect leaves."""
    stages = (diagnosis, *diagnosis.stages)
    named = {found.effect for found in diagnosis.found}
    named |= {alternative for stage in stages for alternative in stage.alternatives}
    if diagnosis.verdict == NONE:
        return diagnosis.baseline_heldout_rmse_deg <= diagnosis.at_floor_threshold_deg
    expected = expected_verdict(cell)
    if expected is None:
        truth = set(cell.truth.split("+"))
        if truth <= named:
            return True
        tied = {stage.verdict: {stage.verdict, *stage.alternatives} for stage in stages}
        return (bool(diagnosis.found) and not diagnosis.final.remaining_excess
                and all(tied.get(found.effect, {found.effect}) & truth for found in diagnosis.found))
    if expected == UNEXPLAINED:
        return diagnosis.verdict == UNEXPLAINED
    return expected in named


def cell_row(cell: Cell, error: str | None = None) -> dict:
    """The row's columns that describe ``cell``, the outcome's left empty (None)."""
    row = {column: None for column in ROW_COLUMNS}
    row.update(cell_id=cell.id, scenario=cell.scenario, kind=cell.kind, truth=cell.truth,
               truth_values=json.dumps(dict(cell.values)), parameter=cell.parameter or None, size=cell.size,
               size_default=cell.size_default, unit=cell.unit or None,
               profile=cell.profile, orientation=cell.orientation, plan=cell.plan, model=cell.model, seed=cell.seed,
               noise_scale=cell.noise_scale, error=error)
    return row


def run_cell(cell: Cell) -> dict:
    """One row for ``cell``; never raises."""
    started = time.perf_counter()
    row = cell_row(cell)
    try:
        row.update(_diagnosis_columns(cell, _simulate_and_diagnose(cell)))
    except Exception as error:  # noqa: BLE001 - a cell's failure is data, the study goes on
        last = traceback.extract_tb(error.__traceback__)[-1]
        row["error"] = f"{type(error).__name__}: {error} ({last.filename.rpartition('/')[2]}:{last.lineno})"
    row["seconds"] = time.perf_counter() - started
    return row


def _simulate_and_diagnose(cell: Cell) -> Diagnosis:
    profile = load_profile(cell.profile)
    changes: dict[str, object] = {
        "hidden_effects": tuple(load_effect(spec) for spec in cell.effects),
        "hidden_effect_values": cell.values,
        "seed": cell.seed,
    }
    noise = profile.config.twin.noise
    changes["noise"] = type(noise)(**{field: getattr(noise, field) * cell.noise_scale
                                      for field in noise.__struct_fields__})
    # The orientation is the study's, whatever clamp orientation the profile gives.
    changes["base_orientation_in_tracker"] = base_orientation(cell.orientation, profile.gravity_in_tracker_m_s2)
    if cell.setup is not None:
        changes["setup"] = parse_setup_error(setup_error_text(*cell.setup))
    config = TwinConfig.from_profile(profile, **changes)
    recording = DigitalTwin(config).run_plan(study_plan(cell.plan, cell.seed), record_window_s=RECORD_WINDOW_S)
    steps = recording.to_dataset(profile, f"study cell {cell.id}").quasistatic_steps()
    # The study's engine already runs one cell per worker: no pool inside a cell.
    return diagnose(steps, cell.model, settings=DiagnosisSettings(workers=1))


def base_orientation(orientation: str, gravity_in_tracker_m_s2) -> tuple[float, float, float, float]:
    """The clamp orientation in the tracker frame (w, x, y, z) of a study's rig
    orientation under a profile's gravity (m/s^2, tracker frame): "hanging", the rod
    straight down along gravity (`hanging_orientation`); "horizontal", gravity along the
    base x axis, across the rod."""
    hanging = hanging_orientation(gravity_in_tracker_m_s2)
    if orientation == "hanging":
        return hanging
    turned = quat_multiply(hanging, HANGING_TO_HORIZONTAL)
    return tuple(float(value) for value in (turned if turned[0] >= 0.0 else -turned))  # type: ignore[return-value]


def trust_columns(diagnosis: Diagnosis) -> dict:
    """How far a verdict's fits can be trusted, as a study's and a batch's rows say it:
    converged, the fits it rests on (the baseline's and the winner's); unconverged_fits,
    every fit's count; bound_clipped, a named effect left on a bound."""
    winner = diagnosis.winner
    return {
        "converged": bool(diagnosis.baseline.converged and (winner is None or winner.converged)),
        "unconverged_fits": sum(not c.converged for stage in (diagnosis, *diagnosis.stages) for c in stage.ranking)
                            + (not diagnosis.baseline.converged),
        "bound_clipped": any(found.notes for found in diagnosis.found),
    }


def _diagnosis_columns(cell: Cell, diagnosis: Diagnosis) -> dict:
    winner = diagnosis.winner
    expected = expected_verdict(cell)
    if expected is None:
        detected = diagnosis.verdict in cell.truth.split("+")
    else:
        detected = diagnosis.verdict == expected
    columns = {
        "verdict": diagnosis.verdict, "detected": detected, "alternatives": ",".join(diagnosis.alternatives),
        "baseline_heldout_rmse_deg": diagnosis.baseline_heldout_rmse_deg,
        "winner_heldout_rmse_deg": None if winner is None else winner.heldout_orientation_rmse_deg,
        "noise_floor_deg": diagnosis.noise_floor_deg,
        "fitted": json.dumps({c.effect: {name: [value, error] for name, (value, error) in c.parameters.items()}
                              for c in diagnosis.ranking if c.error is None}),
        **trust_columns(diagnosis),
        "found": ",".join(found.effect for found in diagnosis.found),
        "final_heldout_rmse_deg": diagnosis.found[-1].heldout_orientation_rmse_deg if diagnosis.found else None,
        "at_floor_threshold_deg": diagnosis.at_floor_threshold_deg,
        "right": right_verdict(cell, diagnosis),
    }
    if cell.kind == "sweep":
        # The fit of the hidden effect where the diagnosis named it (possibly at a later
        # stage, on top of another), else its first-stage fit.
        stages = (diagnosis, *diagnosis.stages)
        own = next((c for stage in stages if stage.verdict == cell.truth for c in stage.ranking
                    if c.effect == cell.truth), None)
        own = own or next((c for c in diagnosis.ranking if c.effect == cell.truth and c.error is None), None)
        if own is not None and cell.parameter in own.parameters:
            value, error = own.parameters[cell.parameter]
            columns.update(fitted_value=value, fitted_standard_error=error,
                           recovery_z=(value - cell.size) / error if error > 0 and math.isfinite(error) else None)
    return columns
