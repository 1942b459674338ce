"""Parameter files (calibrate writes them, compare/run/replay read them): round trip and
one-line errors naming file and key."""

from __future__ import annotations

from pathlib import Path

import pytest

from hydrojet_bench.errors import UserError
from hydrojet_bench.params import PARAMETER_NAMES, ModelParameters, get_parameter
from hydrojet_bench.params_io import ParameterFile, read_parameter_file, write_parameter_file


# What calibrate fits, at the nominal values.
NOMINAL = {name: get_parameter(ModelParameters(), name) for name in PARAMETER_NAMES}
NOMINAL_TEXT = "".join(f"{name} = {value!r}\n" for name, value in NOMINAL.items())


def test_a_written_file_reads_back(tmp_path: Path) -> None:
    written = ParameterFile(model="cosserat", effects=("gravity",),
                            parameters={**NOMINAL, "E0": 2.9e5, "gravity.weight_scale": 1.1},
                            standard_errors={"E0": 1e3},
                            calibration={"data": "run.csv", "poses": 40})
    write_parameter_file(tmp_path / "p.toml", written)
    read = read_parameter_file(tmp_path / "p.toml")
    assert read == written
    assert read.apply(ModelParameters()).rod.youngs_modulus_base_pa == 2.9e5


@pytest.mark.parametrize(("text", "message"), [
    ('effects = []\n[parameters]\nE0 = 1.0\n', "model is required"),
    ('model = "cosserat"\n', "parameters is required"),
    ('model = "cosserat"\n[parameters]\n', "parameters is missing or empty"),
    ('model = "cosserat"\n[parameters]\nE0 = "stiff"\n', "parameters.E0 must be a finite number, got 'stiff'"),
    ('model = "cosserat"\n[parameters]\nE0 = nan\n', "parameters.E0 must be a finite number, got nan"),
    ('model = "cosserat"\neffects = "gravity"\n[parameters]\nE0 = 1.0\n', "effects must be a list of strings"),
    ('model = "cosserat"\n[parameter]\nE0 = 1.0\n', "parameter is not a known key; did you mean parameters?"),
    ('model = "foo"\n[parameters]\nE0 = 1.0\n', "model must be one of 'cosserat', 'prb', got 'foo'"),
])
def test_mistakes_name_file_and_key(tmp_path: Path, text: str, message: str) -> None:
    path = tmp_path / "p.toml"
    path.write_text(text)
    with pytest.raises(UserError) as info:
        read_parameter_file(path)
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


@pytest.mark.parametrize(("name", "value", "message"), [
    ("E0", 0.3, "parameters.E0 = 0.3 Pa is outside the plausible range 1000 .. 1e+09 Pa"),
    ("EL", 1e30, "parameters.EL = 1e+30 Pa is outside the plausible range"),
    ("L", 7.0, "parameters.L = 7 m is outside the plausible range 0.005 .. 1 m"),
    ("L", 70.0, "parameters.L = 70 m is outside"),
    ("wd_fx", 50.0, "parameters.wd_fx = 50 N is outside"),
])
def test_implausible_values_name_the_field_and_the_unit(tmp_path: Path, name: str, value: float,
                                                        message: str) -> None:
    path = tmp_path / "p.toml"
    path.write_text('model = "cosserat"\n[parameters]\n' + NOMINAL_TEXT.replace(f"{name} = {NOMINAL[name]!r}",
                                                                                f"{name} = {value!r}"))
    with pytest.raises(UserError) as info:
        read_parameter_file(path)
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


def test_a_missing_fitted_parameter_is_named_not_taken_from_the_profile(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text('model = "cosserat"\n[parameters]\n' + NOMINAL_TEXT.replace(f"E0 = {NOMINAL['E0']!r}\n", ""))
    with pytest.raises(UserError, match=rf"^{path}: parameters\.E0 is missing; a parameter file from calibrate"):
        read_parameter_file(path)


def test_a_missing_file_is_named(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="no such parameter file"):
        read_parameter_file(tmp_path / "absent.toml")


@pytest.mark.parametrize(("effects", "key", "value", "message"), [
    (["gravity", "jet_gain"], "jet_gain.gain_1", -5.0,
     "parameters.jet_gain.gain_1 = -5 is outside its physical limits 0 .. 3 (0: a blocked nozzle"),
    (["gravity"], "gravity.weight_scale", 1e308, "parameters.gravity.weight_scale = 1e+308 is outside its physical"),
    (["gravity", "sensor_mounting"], "sensor_mounting.rx_rad", 1e308,
     "parameters.sensor_mounting.rx_rad = 1e+308 rad is outside its physical limits -0.8 .. 0.8 rad"),
    (["gravity", "anisotropic_stiffness"], "anisotropic_stiffness.stiffness_ratio", 0.0,
     "parameters.anisotropic_stiffness.stiffness_ratio = 0 is outside"),
    (["gravity"], "foo.bar", 1.0, "parameters.foo.bar: the model has no such effect parameter (its effects: gravity)"),
])
def test_effect_parameters_past_their_physical_limits_name_the_key(tmp_path: Path, effects: list[str], key: str,
                                                                   value: float, message: str) -> None:
    # Such values reached the solver: an overflow, a division by zero or a singular
    # matrix came back as a traceback, or NaN errors with exit 0.
    from hydrojet_bench.model_choice import choose_model

    path = tmp_path / "p.toml"
    path.write_text(f'model = "cosserat"\neffects = {effects!r}\n[parameters]\n'.replace("'", '"')
                    + NOMINAL_TEXT + f'"{key}" = {value!r}\n')
    choice = choose_model(None, [], path)
    with pytest.raises(UserError) as info:
        choice.parameters(ModelParameters())
    assert str(info.value).startswith(f"{path}: {message}"), str(info.value)


def test_a_negative_standard_error_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    path.write_text('model = "cosserat"\n[parameters]\n' + NOMINAL_TEXT + "[standard_errors]\nE0 = -1e308\n")
    with pytest.raises(UserError, match="standard_errors.E0 = -1e[+]308 is negative"):
        read_parameter_file(path)


def test_a_standard_error_the_fit_could_not_bound_is_listed_as_undetermined(tmp_path: Path) -> None:
    # It used to be written as inf, which the reader (rightly) refuses: calibrate wrote a
    # file compare could not read.
    from types import SimpleNamespace

    import numpy as np

    from hydrojet_bench.params_io import calibration_parameter_file
    from hydrojet_bench.profile import load_profile

    fit = SimpleNamespace(names=tuple(NOMINAL), values=np.array(list(NOMINAL.values())),
                          standard_errors=np.array([np.inf] + [1e-3] * (len(NOMINAL) - 1)),
                          rms_orientation_deg_before=2.0, rms_orientation_deg_after=1.0, converged=True,
                          convergence="converged: as stated", at_bound=())
    steps = SimpleNamespace(sweep=np.array([-1, -1, 0]))
    content = calibration_parameter_file("cosserat", ["gravity"], fit, Path("run.csv"), load_profile("sim"),
                                         "calibration", steps, np.array([True, True, False]))
    write_parameter_file(tmp_path / "p.toml", content)
    read = read_parameter_file(tmp_path / "p.toml")
    assert read.calibration["undetermined"] == ["E0"] and "E0" not in read.standard_errors
    assert read.standard_errors["EL"] == 1e-3
