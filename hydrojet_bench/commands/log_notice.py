"""The notices the analysis commands give about their input, each one warning line on
standard error and a field of their JSON documents: a session log that is cut or
damaged (``log_damage``), a CSV table read with the default profile although
another one wrote it, or a log read with a profile of another rig than it embeds
(``profile_mismatch``), and steps of a single sample, which are no
settled equilibria (``single_sample_steps``), nor are steps whose tip still turned
(``unsettled_steps``); and of a parameter file, what of the model it did
not calibrate (`ModelChoice.uncalibrated`) and whether it was fitted on the steps
compared (`warn_if_fitted_on`), or, without one, whether the command's own calibration
was (`warn_if_scored_on_own_fit`)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from rich.console import Console

from ..data.dataset import STEP_WINDOW_S, UNSETTLED_TREND_DEG, Dataset, SampleFlag
from ..estimation.calibration import ALL_ROWS, CALIBRATION_POSES, SWEEPS
from ..inputs import recorded_elsewhere
from ..logs.condition import incomplete_log
from ..model_choice import ModelChoice
from ..profile import RigProfile


def warn(text: str) -> None:
    Console(stderr=True).print(f"warning: {text}", style="yellow", markup=False, highlight=False, soft_wrap=True)


def warn_if_incomplete(path: Path) -> dict[str, object] | None:
    """For a session log (.mcap) that is truncated or damaged: print what it lost and how
    many plan steps the analysis is missing, and return that for the JSON document. None
    for a whole log or another kind of input."""
    condition = incomplete_log(path)
    if condition is None:
        return None
    warn(condition.notice())
    return condition.as_dict()


def warn_if_streams_fell_short(path: Path) -> list[str] | None:
    """For a session log whose closing stream rates (``/bench/stream_rate``, whole
    session) say a stream delivered less than 95 % of its configured rate: print each
    (samples were lost: the figures rest on fewer than configured) and return them for
    the JSON document. None when every stream kept its rate or the log says nothing."""
    from ..bench.stream_rates import StreamRateFigure
    from ..logs import read_log
    from ..logs.topics import StreamRate

    if Path(path).suffix.lower() != ".mcap":
        return None
    figures = [StreamRateFigure(rate.stream, rate.configured_hz, rate.samples, rate.interval_s)
               for rate in read_log(path, topics=[StreamRate.topic]).on(StreamRate) if rate.whole_session]
    short = [figure.describe() for figure in figures if figure.configured_hz > 0 and figure.below_warning]
    for line in short:
        warn(f"{path}: the session's {line}: samples were lost, and what rests on that stream has fewer than "
              "its settings promise")
    return short or None


def warn_if_recorded_elsewhere(path: Path, profile_given: str | None, profile: RigProfile) -> dict[str, str] | None:
    """Print `recorded_elsewhere`'s notice, if any, and return it for the JSON document."""
    notice = recorded_elsewhere(path, profile_given, profile)
    if notice is not None:
        warn(notice["message"])
    return notice


def warn_if_unsettled(path: Path, steps: Dataset, log_damage: dict[str, object] | None) -> dict[str, int] | None:
    """For steps (``steps``, reduced by `Dataset.quasistatic_steps`) of which some
    average a single sample, as when the jets change at every row of a table: print how
    many and return that for the JSON document; None when every step averages more, or
    for a damaged log (``log_damage`` from `warn_if_incomplete`), whose notice already
    says what was cut away, which may leave a step one sample. The models are
    quasistatic, so such a step is taken for a settled equilibrium and a rod still
    moving reads as model error."""
    if steps.samples is None or log_damage is not None:
        return None
    single = int((steps.samples == 1).sum())
    if not single:
        return None
    warn(f"{path}: {single} of {len(steps)} steps average a single sample (the jets changed at the next "
          "row), so they are no settled equilibria, and the quasistatic models take a rod still moving "
          "for model error: label the settled rows (sweep and step columns) or hold each command longer")
    return {"count": single, "steps": len(steps)}


def warn_if_unsettled_steps(path: Path, steps: Dataset,
                            window_s: float | None = STEP_WINDOW_S) -> dict[str, object] | None:
    """For steps whose tip was still turning within their averaging window
    (`SampleFlag.UNSETTLED`: commands held too briefly, or a plan of half-second ramps):
    print how many and return that for the JSON document; None when there are none.
    Their averages are no equilibria, which a quasistatic model reads as its own error:
    on the nominal twin, steps of 0.3 s gave a Table II of 33 deg. window_s: the window
    the steps were averaged over, s (None: a session's own steps, each averaged over
    session.window_s or its hold if shorter)."""
    turning = int(np.count_nonzero(steps.flags & int(SampleFlag.UNSETTLED)))
    if not turning:
        return None
    window = f"the last {window_s:g} s" if window_s is not None else "the end of its hold"
    warn(f"{path}: in {turning} of {len(steps)} steps the tip was still turning (by more than "
          f"{UNSETTLED_TREND_DEG:g} deg) over {window}, which each step's settled state is "
          "averaged over: they are no equilibria, and the quasistatic models read the motion as model error; "
          "hold each command longer (the paper holds 5 s)")
    return {"count": turning, "steps": len(steps), "window_s": window_s, "trend_deg": UNSETTLED_TREND_DEG}


def warn_if_uncalibrated(choice: ModelChoice, profile: RigProfile) -> tuple[str, ...]:
    """Print what of ``choice``'s model its parameter file did not calibrate (a model or an
    effect it was not fitted for, or ``profile``'s rig) and return it for the JSON document."""
    notes = choice.uncalibrated(profile)
    for note in notes:
        warn(note)
    return notes


def warn_if_fitted_on(choice: ModelChoice, path: Path, validation: Dataset) -> str | None:
    """When ``choice``'s parameter file was calibrated on ``path`` itself (its
    ``[calibration] data``) and on the rows compared (``validation``: the sweeps, or every
    step when there are none): print that the errors are training errors and return it
    for the JSON document. None when they are held out or the file does not say."""
    calibration = {} if choice.parameter_file is None else choice.parameter_file.calibration
    data, fit_on = calibration.get("data"), calibration.get("fit_on")
    if not isinstance(data, str) or not _same_file(data, path, Path(choice.parameter_path or ".")):
        return None
    if (validation.sweep >= 0).any():
        if fit_on not in (SWEEPS, ALL_ROWS):
            return None
        what = "the sweep steps compared were fitted"
    elif fit_on in (CALIBRATION_POSES, ALL_ROWS):
        what = _NO_SWEEPS
    else:
        return None
    return _warn_training(f"{choice.parameter_path} was calibrated on {path} (fit_on {fit_on}): {what}")


def warn_if_scored_on_own_fit(path: Path, validation: Dataset) -> str | None:
    """For a command that calibrated the model on the calibration poses of ``path`` itself
    (no parameter file) and compares on ``validation`` (the sweeps, or every step when
    there are none): when there are no sweeps, print that the errors are training
    errors, as `warn_if_fitted_on` says of a parameter file, and return it for the JSON
    document. None when the sweeps compared are held out."""
    if (validation.sweep >= 0).any():
        return None
    return _warn_training(f"the model was calibrated here on the calibration poses of {path}: {_NO_SWEEPS}")


_NO_SWEEPS = "it has no sweeps (sweep >= 0): the steps compared are the calibration poses fitted"


def _warn_training(why: str) -> str:
    """Print and return ``why``, followed by what it makes of the errors."""
    text = f"{why}, so these are training errors, not held-out ones"
    warn(text)
    return text


def _same_file(recorded: str, path: Path, parameter_path: Path) -> bool:
    """Whether ``recorded`` (a data path as `calibrate` was given it: relative to the folder
    it ran in, which is unknown, so tried from here and from the parameter file's folder)
    names ``path``."""
    for candidate in (Path(recorded), parameter_path.parent / recorded):
        try:
            if os.path.samefile(candidate, path):
                return True
        except OSError:
            continue
    return False
