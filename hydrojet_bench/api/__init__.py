"""The bench from Python (a notebook, a script): the analysis commands as functions.

    import hydrojet_bench as hj

    data = hj.load("sessions/mystery.mcap")          # or a CSV file (profile "sim" by default)
    found = hj.diagnose(data)                         # which effect is missing?
    before = hj.calibrate(data)
    after = hj.calibrate(data, effects=[found.verdict])
    result = hj.compare(data, after, baseline=before, online=True)
    result.to_pandas()                                # one row per step and method
    result.plot()

Each function does what the command of the same name does, on the same library code
(`inputs`, `model_choice`, `estimation`, `analysis`, `bench.replay`, `studies`), and
returns a typed result (`api.results`) with ``to_pandas()`` and ``plot()``. Models and
effects are chosen by the commands' rule (`model_choice`): ``params`` (a parameter file,
or a `CalibrateResult`) brings its model and effects, ``model`` replaces the model and
``effects`` are added. A mistake in the inputs raises `hydrojet_bench.errors.UserError`
naming the file and field; nothing here prints (progress, when asked for, goes to a
``progress`` callback) or exits.
"""

from __future__ import annotations

import math
import multiprocessing
from collections.abc import Callable, Sequence
from pathlib import Path

from ..analysis.compare import compare_methods, compare_steps, lead_in, validation_rows
from ..analysis.diagnosis import DiagnosisSettings, diagnose as run_diagnosis
from ..analysis.diagnosis.noise import repeatability_floor
from ..bench.replay import (live_difference_deg, live_steps_compared, logged_steps, read_session,
                           replay as replay_session)
from ..effects import load_effects
from ..errors import ConvergenceError, UserError
from ..estimation.calibration import (DEFAULT_POSITION_WEIGHT_RAD_PER_M, FIT_ON, calibrate_dataset,
                                      calibrate_widening, fit_mask, rows_that_identify)
from ..files import check_writable_target
from ..inputs import load_dataset, load_steps
from ..logs.condition import log_condition
from ..model_choice import COSSERAT, ModelChoice, ModelDefaults, choose_model
from ..params_io import calibration_parameter_file, effect_specs
from ..profile import RigProfile
from .results import (CalibrateResult, CompareResult, DiagnoseResult, Measurements, ReplayResult, StudyResult)

__all__ = ["CalibrateResult", "CompareResult", "DiagnoseResult", "Measurements", "ReplayResult", "StudyResult",
           "calibrate", "calibration_parameter_file", "compare", "diagnose", "load", "replay", "study"]

Data = str | Path | Measurements
Profile = RigProfile | str | Path | None
Params = str | Path | CalibrateResult | None


def load(path: str | Path, profile: Profile = None) -> Measurements:
    """Read measurements: a CSV file (`hydrojet_bench.data.csv_io`'s columns) recorded on
    ``profile`` (a `RigProfile`, a TOML path or a shipped name; default ``"sim"``), or a
    session log (.mcap) that carries its own profile (``profile`` overrides it)."""
    path = Path(path)
    if profile is None and path.suffix.lower() != ".mcap":
        profile = "sim"
    steps = load_steps(path, profile)
    return Measurements(path, steps.profile, steps, _log_damage(path))


def calibrate(data: Data, *, model: str | None = None, effects: Sequence[str] = (), params: Params = None,
              fit_on: str | None = None, position_weight_rad_per_m: float = DEFAULT_POSITION_WEIGHT_RAD_PER_M,
              profile: Profile = None) -> CalibrateResult:
    """Fit E0, EL, L, w_d and the parameters of ``effects``, as `hydrojet-bench
    calibrate`, on the rows that identify them (``fit_on``: "calibration", the paper's
    sec. V-B poses of sweep -1; "sweeps"; "all"; default: the poses, and all when an
    effect is identified only by sweeps, `Effect.identified_by`). ``params`` only
    chooses the model and effects here; the fit starts from the profile's values.
    `CalibrateResult.save(path)` writes the parameter file."""
    _check_number(position_weight_rad_per_m, "position_weight_rad_per_m", minimum=0.0)
    if fit_on is not None and fit_on not in FIT_ON:
        raise UserError(f"fit_on must be one of {', '.join(FIT_ON)}, got {fit_on!r}")
    measurements = _measurements(data, profile)
    choice = _choice(model, effects, params)
    steps = measurements.steps
    fit_on = fit_on or rows_that_identify(choice.requested)
    rows = fit_mask(steps, fit_on)
    if not rows.any():
        raise UserError(f"{measurements.path}: no rows to fit on with fit_on={fit_on!r}; record calibration poses "
                        "with `hydrojet-bench run --plan calibration` and sweeps with `--plan sweeps`")
    try:
        fit = calibrate_widening(choice.model, choice.requested, steps, measurements.profile.model_parameters(),
                                 choice.calibration_names, fit_on=fit_on,
                                 position_weight_rad_per_m=position_weight_rad_per_m).result
    except ValueError as error:
        raise UserError(f"{measurements.path}: {error}") from None
    content = calibration_parameter_file(choice.model.name, effect_specs(choice.model.effects, Path.cwd()), fit,
                                         measurements.path, measurements.profile, fit_on, steps, rows)
    return CalibrateResult(choice.model, choice.effect_specs, steps.select(rows), fit, content)


def compare(data: Data, params: Params, *, baseline: Params = None, online: bool = False, model: str | None = None,
            effects: Sequence[str] = (), profile: Profile = None) -> CompareResult:
    """Predict every validation step (sweep >= 0; all steps when there are no sweeps)
    with ``params`` ("ref": calibrated, constant disturbance; with ``online``, also
    "online": online disturbance estimation) and compare with the measurements, as
    `hydrojet-bench compare`. ``baseline``: second parameters predicted on the same
    steps with their own model and effects (``effects`` name their effect files)."""
    path = _path(data)
    profile = _profile(data, profile)
    # A session log's own settled steps are the rows its live estimator predicted.
    logged = logged_steps(path, profile) if path.suffix.lower() == ".mcap" else None
    steps = logged if logged is not None else _measurements(data, profile).steps
    validation = steps.select(validation_rows(steps))
    if len(validation) == 0:
        raise UserError(f"{path}: no steps to compare")
    settings = steps.profile.online_settings() if online else None

    def evaluate(choice: ModelChoice):
        return compare_methods(choice.model, choice.parameters(steps.profile.model_parameters()), validation, settings,
                               lead_in(steps))

    after_choice = _choice(model, effects, params)
    before = None if baseline is None else evaluate(_choice(model, (), baseline, effect_files=effects))
    return CompareResult(after_choice.model, _source(params), validation, evaluate(after_choice), before,
                         _log_damage(path))


def diagnose(data: Data, *, model: str | None = None, effects: Sequence[str] = (), candidates: Sequence[str] = (),
             workers: int | None = None, profile: Profile = None,
             progress: Callable[[str], None] | None = None) -> DiagnoseResult:
    """Which physical effect is the model missing? As `hydrojet-bench diagnose`: the
    baseline (``model`` with the known ``effects``) and the baseline plus each of
    ``candidates`` (default: every library effect not known) calibrated on part of the
    steps and scored on the held-out repetitions against the noise floor."""
    if workers is not None:
        workers = _checked_workers(workers)
    choice = _choice(model, effects, None)
    _check_specs(candidates, "candidates")
    load_effects([*choice.effect_specs, *candidates])  # one name, one effect: known and candidates alike
    tried = load_effects(candidates) or None
    measurements = _measurements(data, profile)
    # Without repeated sweeps the raw samples' scatter is the only noise floor left.
    samples = (load_dataset(measurements.path, measurements.profile)
               if repeatability_floor(measurements.steps) is None else None)
    try:
        diagnosis = run_diagnosis(measurements.steps, choice.model.name, choice.requested, tried, samples=samples,
                                  settings=DiagnosisSettings(workers=workers), progress=progress)
    except ConvergenceError as error:
        raise UserError(f"{measurements.path}: the baseline {choice.model.name} model cannot follow these data "
                        f"({error}); check the profile and the units of the jet forces") from None
    return DiagnoseResult(diagnosis, measurements.path, measurements.log_damage)


def replay(log: str | Path, *, model: str | None = None, effects: Sequence[str] = (), params: Params = None,
           online: bool = False, profile: Profile = None) -> ReplayResult:
    """Re-run a session log's estimation offline, as `hydrojet-bench replay`. With the
    live model and parameters (the default) it reproduces the live estimates
    (``live_difference_deg`` 0); another model or effects without ``params`` are first
    calibrated on the logged calibration poses."""
    session = read_session(Path(log), profile)
    choice = _choice(model, effects, params, session.model_defaults())
    nominal = session.profile.model_parameters()
    values = None if params is None else choice.parameters(nominal)
    live_settings = values is None and choice.model.name == session.model_name and not effects
    calibration = None
    if values is None and not live_settings:
        try:
            calibration = calibrate_dataset(choice.model, session.steps, nominal, choice.calibration_names)
        except (ValueError, ConvergenceError) as error:
            raise UserError(f"{log}: cannot calibrate {choice.model.name} on the logged calibration poses: "
                            f"{error}") from None
        values = calibration.params
    estimates = replay_session(session, choice.model, session.profile.online_settings() if online else None, values)
    kept = [i for i, estimate in enumerate(estimates) if estimate is not None]
    validation = [i for i in kept if session.steps.sweep[i] >= 0] or kept
    if not validation:
        raise UserError(f"{log}: the model converged on none of the logged steps")
    steps = session.steps.select(validation)
    results = compare_steps([estimates[i] for i in validation], steps)
    difference = live_difference_deg(session, estimates) if live_settings else None
    compared = live_steps_compared(session, estimates) if live_settings else None
    return ReplayResult(choice.model, steps, results, live_settings, difference, calibration,
                        len(session.steps.calibration_rows()), len(estimates) - len(kept), _log_damage(Path(log)),
                        choice.uncalibrated(session.profile), compared, len(session.steps))


def study(spec: str | Path | None = None, output: str | Path | None = None, *, workers: int = 2,
          scheduler: str | None = None, csv: bool = False, report_only: bool = False,
          progress: Callable[[str], None] | None = None) -> StudyResult:
    """Run a study spec (`studies.spec`) on Dask, as `hydrojet-bench study`: every cell
    simulated on the twin and diagnosed, rows stored under ``output`` (default
    ``study-<name>``; a rerun skips the finished cells), then the report written to
    ``output/report``. ``report_only``: rebuild the report from the rows stored in
    ``output`` without running anything. ``progress`` receives one line on start.

    In a script, call it under ``if __name__ == "__main__":``: each local worker process
    starts by importing the script, which without the guard would run the study again.
    """
    from ..studies.cell import ROW_COLUMNS, cell_row, run_cell
    from ..studies.cells import expand
    from ..studies.engine import dask_client, run_tasks
    from ..studies.report import write_report
    from ..studies.spec import load_study
    from ..studies.store import RowStore

    # multiprocessing's own mark of a child importing the parent's main module.
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise UserError("study: called while a worker process starts, by the script it imports: put the call under "
                        "`if __name__ == \"__main__\":` in the script")
    if report_only:
        if output is None:
            raise UserError("study: report_only rebuilds the report of a result folder: give output=DIR")
        if spec is not None:
            raise UserError(f"study: report_only rebuilds {output}'s report from its stored rows and runs no spec; "
                            f"give spec or report_only, not both")
        if not (Path(output) / "rows").is_dir():
            raise UserError(f"{output}: no study results here (no rows/ folder)")
        store = RowStore(Path(output), ROW_COLUMNS, "cell_id")
        # The cells of the spec last run here; rows of cells it no longer had stay out.
        members = store.members()
        rows = store.table(members)
        return StudyResult(Path(output).name, store.folder, rows, None,
                           tuple(write_report(rows, store.folder / "report")),
                           left_out=0 if members is None else len(store.stored() - members))
    if spec is None:
        raise UserError("study: give a SPEC.toml (or report_only with the result folder)")
    workers = _checked_workers(workers)
    plan = load_study(Path(spec))
    cells = expand(plan)
    if not cells:
        raise UserError(f"{spec}: the spec has no cells (none = false and no effects or pairs)")
    store = RowStore(Path(output) if output is not None else Path(f"study-{plan.name}"), ROW_COLUMNS, "cell_id")
    if csv and store.folder.is_dir():  # refused before the cells run, not after (a new folder holds none)
        check_writable_target(store.folder / "rows.csv", "row table", overwrite=True)
    ids = {cell.id for cell in cells}
    store.claim(str(Path(spec).resolve()), ids)
    if progress is not None:
        where = scheduler or f"a local cluster of {workers} worker{'s' if workers != 1 else ''}"
        progress(f"study {plan.name}: {len(cells)} cells on {where}, rows in {store.rows_folder}")
    outcome = run_tasks(lambda: dask_client(scheduler, workers), run_cell, cells, [cell.id for cell in cells],
                        store, error_row=cell_row, label="cells")
    # Rows of cells this spec no longer has (it was edited, or an effect file moved) stay
    # stored but are no part of this study's tables and report.
    left_out = len(store.stored() - ids)
    written_csv = store.write_csv(ids) if csv else None
    rows = store.table(ids)
    return StudyResult(plan.name, store.folder, rows, outcome, tuple(write_report(rows, store.folder / "report")),
                       written_csv, left_out)


# --- inputs --------------------------------------------------------------------------


def _path(data: Data) -> Path:
    return data.path if isinstance(data, Measurements) else Path(data)


def _profile(data: Data, profile: Profile) -> Profile:
    return data.profile if isinstance(data, Measurements) and profile is None else profile


def _measurements(data: Data, profile: Profile) -> Measurements:
    if isinstance(data, Measurements) and profile is None:
        return data
    return load(_path(data), profile)


def _log_damage(path: Path) -> dict | None:
    if path.suffix.lower() != ".mcap":
        return None
    condition = log_condition(path)
    return None if condition.whole else condition.as_dict()


def _choice(model: str | None, effects: Sequence[str], params: Params, defaults: ModelDefaults = COSSERAT, *,
            effect_files: Sequence[str] | None = None) -> ModelChoice:
    """The commands' model rule; a `CalibrateResult` brings its model and effects as its
    parameter file would (its effect files among them)."""
    _check_specs(effects, "effects")
    if not isinstance(params, CalibrateResult):
        return choose_model(model, tuple(effects), None if params is None else Path(params), defaults,
                            effect_files=effect_files)
    files = [*params.effect_specs, *(effects if effect_files is None else effect_files)]
    return choose_model(model, tuple(effects), _source(params), defaults, effect_files=files,
                        parameter_file=params.parameter_file)


def _checked_workers(workers: object) -> int:
    """A whole number of processes, at least one (2.0 is read as 2; 1.5 and "2" are refused
    here rather than deep inside Dask or a comparison)."""
    if isinstance(workers, bool) or not isinstance(workers, (int, float)) or not float(workers).is_integer():
        raise UserError(f"workers must be a whole number of processes, got {workers!r}")
    if workers < 1:
        raise UserError(f"workers must be at least 1, got {workers}")
    return int(workers)


def _check_number(value: object, argument: str, *, minimum: float) -> None:
    """A finite number >= ``minimum`` (an infinite weight makes every residual infinite)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value < minimum:
        raise UserError(f"{argument} must be a finite number >= {minimum:g}, got {value!r}")


def _check_specs(specs: Sequence[str], argument: str) -> None:
    """A single string would be read letter by letter as effect names."""
    if isinstance(specs, str):
        raise UserError(f"{argument} takes a list of effect names or files, got the string {specs!r}: "
                        f"write {argument}=[{specs!r}]")


def _source(params: Params) -> str:
    if isinstance(params, CalibrateResult):
        return f"the calibration on {params.parameter_file.calibration.get('data', 'its data')}"
    return str(params)
