"""What the notebook API returns: frozen results that keep the library's own objects
(`Dataset`, `analysis.compare.Comparison`, `analysis.diagnosis.Diagnosis`, ...) and add
``to_pandas()`` (a table, columns named with their units, see `api.tables`),
``plot()`` (a matplotlib `Figure`) and, where a command writes JSON, ``as_dict()`` (the
same document)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import pandas as pd
from matplotlib.figure import Figure

from ..analysis.compare import Comparison, compare_methods
from ..analysis.diagnosis import Diagnosis
from ..data.dataset import Dataset
from ..errors import UserError
from ..estimation.calibration import CalibrationResult
from ..models.shooting import ShootingModel
from ..params_io import ParameterFile, effect_specs, write_parameter_file
from ..profile import RigProfile
from ..studies.engine import Outcome
from ..studies.report import confusion_table
from . import figures
from .tables import measured_steps_table, predicted_steps_table


@dataclass(frozen=True)
class Measurements:
    """A CSV file or session log as the analyses see it. steps: one row per quasistatic
    step (the window averages `calibrate` and `diagnose` fit); log_damage: what a cut
    or damaged session log lacks (None when whole)."""

    path: Path
    profile: RigProfile
    steps: Dataset
    log_damage: dict | None = None

    def to_pandas(self) -> pd.DataFrame:
        """One row per step: time_s, sweep, step, q1_n..q3_n, the measured tip pose, bend."""
        return measured_steps_table(self.steps)

    def plot(self) -> Figure:
        return figures.measured_bend_figure(self.to_pandas(), f"measured bend per step, {self.path.name}")


@dataclass(frozen=True)
class CalibrateResult:
    """A calibration (the paper's eq. 24) on ``fitted_rows`` (the calibration poses of
    sweep -1 by default; the sweeps too for an effect only sweeps identify).
    parameter_file: what `save` writes (and `calibrate -o` writes); fit: the optimiser's
    outcome (standard errors, correlations, RMS before and after)."""

    model: ShootingModel
    effect_specs: tuple[str, ...]
    fitted_rows: Dataset
    fit: CalibrationResult
    parameter_file: ParameterFile

    @property
    def parameters(self) -> dict[str, float]:
        """The fitted values, SI units (E0, EL in Pa, L in m, w_d in N and N m, effects' own)."""
        return dict(self.parameter_file.parameters)

    @property
    def standard_errors(self) -> dict[str, float]:
        return dict(self.parameter_file.standard_errors)

    def save(self, path: str | Path) -> Path:
        """Write the parameter file (TOML) that `compare --params` and `run --params` read."""
        path = Path(path)
        # A user's effect file is listed relative to where the parameter file lands.
        write_parameter_file(path, msgspec.structs.replace(
            self.parameter_file, effects=effect_specs(self.model.effects, path.parent)))
        return path

    def as_dict(self) -> dict:
        """The parameter file's content, the pairs not separately identifiable and the
        number of model evaluations: `calibrate --json`'s document."""
        return {**msgspec.to_builtins(self.parameter_file),
                "unidentifiable": [{"first": a, "second": b, "correlation": float(c)}
                                   for a, b, c in self.fit.unidentifiable],
                "evaluations": self.fit.evaluations}

    def parameters_table(self) -> pd.DataFrame:
        """name, value and standard error of every fitted parameter (SI units)."""
        return pd.DataFrame({"name": list(self.parameters), "value": list(self.parameters.values()),
                             "standard_error": [self.standard_errors.get(name) for name in self.parameters]})

    def to_pandas(self) -> pd.DataFrame:
        """The fitted rows predicted with the calibrated parameters ("ref", constant
        disturbance), as `api.tables.predicted_steps_table`."""
        return predicted_steps_table(compare_methods(self.model, self.fit.params, self.fitted_rows), self.fitted_rows)

    def plot(self) -> Figure:
        return figures.step_errors_figure(self.to_pandas(), f"{self.model.name} on the {len(self.fitted_rows)} "
                                          "steps it was fitted on, calibrated parameters")


@dataclass(frozen=True)
class CompareResult:
    """Model against measurements on the validation steps (``steps``): ``results``
    per method ("ref"; "online" with online estimation), each an
    `analysis.compare.Comparison` (errors, Table II by sweep and bend). baseline: the
    same for the baseline parameters, when given."""

    model: ShootingModel
    parameters_source: str
    steps: Dataset
    results: dict[str, Comparison]
    baseline: dict[str, Comparison] | None = None
    log_damage: dict | None = None

    def table_ii(self) -> pd.DataFrame:
        """RMS errors per method: overall, per sweep and per bend bin (deg and mm)."""
        return _table_ii(self.results)

    def to_pandas(self) -> pd.DataFrame:
        """One row per step and method: q1..q3, measured and predicted poses, errors."""
        return predicted_steps_table(self.results, self.steps)

    def plot(self) -> Figure:
        return figures.step_errors_figure(self.to_pandas(), f"{self.model.name}: error of every validation step")

    def as_dict(self) -> dict:
        """Table II per method, as `compare --json` writes it (its figures; the command
        adds its breakdowns), for these parameters and the baseline's when given."""
        return {"model": self.model.name, "effects": [effect.name for effect in self.model.effects],
                "parameters": self.parameters_source, **_tables_document(self.results), "steps": len(self.steps),
                "baseline": None if self.baseline is None else _tables_document(self.baseline),
                "log_damage": self.log_damage}


@dataclass(frozen=True)
class ReplayResult:
    """A session's estimation re-run offline (`bench.replay`) on its settled steps
    (``steps``, the validation sweeps when it has any). live_difference_deg: the largest
    difference from the live estimates when replayed with the live settings (0:
    identical; None otherwise or without live predictions). calibration: the fit on the
    ``calibration_poses`` logged calibration poses when another model had no params.
    skipped: steps where the model did not converge, left out. uncalibrated: what of the
    model ``params`` did not calibrate (`ModelChoice.uncalibrated`). live_steps_compared:
    of the ``logged_steps``, those whose live predictions the log holds (with the live
    settings; a cut log may hold the steps but not all their predictions)."""

    model: ShootingModel
    steps: Dataset
    results: dict[str, Comparison]
    live_settings: bool
    live_difference_deg: float | None = None
    calibration: CalibrationResult | None = None
    calibration_poses: int = 0
    skipped: int = 0
    log_damage: dict | None = None
    uncalibrated: tuple[str, ...] = ()
    live_steps_compared: int | None = None
    logged_steps: int = 0

    def table_ii(self) -> pd.DataFrame:
        return _table_ii(self.results)

    def as_dict(self) -> dict:
        """`replay --json`'s document: Table II per method (as `compare` writes it), the
        live difference, the calibration (whether it converged) and the skipped steps."""
        document = _tables_document(self.results)
        calibration = None if self.calibration is None else {
            "poses": self.calibration_poses, "rms_orientation_deg_before": self.calibration.rms_orientation_deg_before,
            "rms_orientation_deg_after": self.calibration.rms_orientation_deg_after,
            "parameters": dict(zip(self.calibration.names, map(float, self.calibration.values))),
            "converged": self.calibration.converged, "convergence": self.calibration.convergence,
            "at_bound": list(self.calibration.at_bound)}
        return {"model": self.model.name, "effects": [effect.name for effect in self.model.effects], **document,
                "steps": len(self.steps), "skipped_steps": self.skipped, "live_settings": self.live_settings,
                "live_difference_deg": self.live_difference_deg, "live_steps_compared": self.live_steps_compared,
                "logged_steps": self.logged_steps, "calibration": calibration,
                "uncalibrated": list(self.uncalibrated), "log_damage": self.log_damage}

    def to_pandas(self) -> pd.DataFrame:
        return predicted_steps_table(self.results, self.steps)

    def plot(self) -> Figure:
        return figures.step_errors_figure(self.to_pandas(), f"{self.model.name} replayed: error of every step")


@dataclass(frozen=True)
class DiagnoseResult:
    """Which effect is the model missing (`analysis.diagnosis`): ``diagnosis`` holds the
    verdict, the noise floor, the baseline and every candidate."""

    diagnosis: Diagnosis
    source: Path
    log_damage: dict | None = None

    @property
    def verdict(self) -> str:
        """"none", "unexplained" or the name of the effect that explains the excess error."""
        return self.diagnosis.verdict

    def as_dict(self) -> dict:
        """`diagnose --json`'s document."""
        return {"data": str(self.source), **self.diagnosis.as_dict(), "log_damage": self.log_damage}

    def to_pandas(self) -> pd.DataFrame:
        """One row per candidate, best score first: held-out orientation RMSE (deg), the
        share of the excess error explained, the score change (BIC), whether it
        qualifies, the cosine with the online estimate, whether its fit converged (and
        why), the fitted values on a bound (comma-separated), the fitted parameters
        (name -> (value, standard error)) and why a fit failed: what the command's table
        says, so that an unconverged fit ranked last says why here too."""
        columns = ["effect", "heldout_orientation_rmse_deg", "explained_fraction", "score_change", "qualifies",
                   "online_correlation", "converged", "convergence", "at_bound", "parameters", "error"]
        return pd.DataFrame([{
            "effect": c.effect, "heldout_orientation_rmse_deg": c.heldout_orientation_rmse_deg,
            "explained_fraction": c.explained_fraction, "score_change": c.score_change, "qualifies": c.qualifies,
            "online_correlation": c.online_correlation, "converged": c.converged, "convergence": c.convergence,
            "at_bound": ", ".join(c.at_bound), "parameters": dict(c.parameters), "error": c.error}
            for c in self.diagnosis.ranking], columns=columns)

    def plot(self) -> Figure:
        return figures.ranking_figure(self.to_pandas(), self.diagnosis.baseline_heldout_rmse_deg,
                                      self.diagnosis.noise_floor_deg,
                                      f"{self.diagnosis.model}: candidates (verdict: {self.verdict})")


@dataclass(frozen=True)
class StudyResult:
    """A study's rows (one per cell: truth, verdict, sizes, timings; see
    `studies.cell.ROW_COLUMNS`), where they are stored, the run's outcome (None when
    only the report was rebuilt) and the report files written. left_out: rows stored in
    the folder for cells the spec does not have (not in ``rows`` or the report)."""

    name: str
    folder: Path
    rows: pd.DataFrame
    outcome: Outcome | None
    report: tuple[Path, ...] = field(default=())
    csv: Path | None = None
    left_out: int = 0

    def to_pandas(self) -> pd.DataFrame:
        return self.rows.copy()

    def confusion(self) -> pd.DataFrame:
        """Cell counts by hidden truth (rows) and verdict (columns), finished cells only."""
        return confusion_table(self.rows[self.rows["error"].isna()])

    def plot(self) -> Figure:
        confusion = self.confusion()
        if confusion.empty:  # matplotlib would draw empty axes and warn of singular limits
            raise UserError(f"study {self.name}: no diagnosed cells in {self.folder}, nothing to plot")
        return figures.confusion_figure(confusion, f"study {self.name}: verdict against hidden truth")


def _table_ii(results: dict[str, Comparison]) -> pd.DataFrame:
    rows = []
    for method, comparison in results.items():
        groups = {"all": comparison.overall, **{f"sweep {s}": v for s, v in comparison.by_sweep.items()},
                  **{f"bend {b}": v for b, v in comparison.by_bend.items()}}
        rows += [{"method": method, "group": group, "count": summary.count,
                  "orientation_rmse_deg": summary.orientation_rmse_deg,
                  "position_rmse_mm": summary.position_rmse_mm} for group, summary in groups.items()]
    return pd.DataFrame(rows)


def _tables_document(results: dict[str, Comparison]) -> dict:
    """Table II of each method ("ref", "online"), as `compare --json` nests it: each
    figure, then the methods."""
    tables = {key: comparison.as_dict() for key, comparison in results.items()}
    return {name: {key: value[name] for key, value in tables.items()}
            for name in ("orientation_rmse_deg", "position_rmse_mm", "by_sweep", "by_bend")}
