"""Spec mistakes name the file and the dotted key; cells have stable, distinct ids."""

from __future__ import annotations

from pathlib import Path

import pytest
from study_helpers import TINY, WITH_BOOM, run_study, write_spec

from hydrojet_bench.errors import UserError
from hydrojet_bench.profile import PROFILES_DIR
from hydrojet_bench.studies.cells import expand
from hydrojet_bench.studies.spec import load_study


@pytest.mark.parametrize(("body", "message"), [
    ('seeds = [0]\ncolour = "red"\n', "colour"),
    ('seeds = [0]\n[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [2.0]\n',
     "effects[0].sizes: 2.0 is outside gain_1's bounds [0.0, 1.5]"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_9"\nsizes = [1.0]\n',
     "effects[0].parameter = 'gain_9' is no parameter of jet_gain"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = {start = 0.5, stop = 1.0}\n',
     "effects[0].sizes"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = {start = 0.5, stop = 1.0, num = 3, '
     'scale = "cubic"}\n', "effects[0].sizes.scale"),
    ('[[effects]]\neffect = "nothing_like_it"\nparameter = "x"\nsizes = [1.0]\n',
     "effects[0].effect: unknown effect 'nothing_like_it'"),
    ('models = ["lumped"]\n', "models[0] = 'lumped' is no model"),
    # Every cell would fail on these: refused before any runs.
    ('plans = ["nope"]\n', "plans[0]: plan 'nope': neither a built-in plan"),
    ('profiles = ["nope"]\n', "profiles[0]: rig profile 'nope' not found"),
    ('plans = ["short", "calibration:12"]\n',
     "plans[1] = 'calibration:12' has no sweep steps (sweep >= 0), which diagnose holds out: give a plan with"),
    ('orientations = ["upside-down"]\n', "orientations[0] must be one of 'hanging', 'horizontal', got 'upside-down'"),
    ('seeds = "zero"\n', "seeds must be a list of integers with at least 1 entry, got 'zero'"),
    ('seeds = ["zero"]\n', "seeds[0] must be an integer, got 'zero'"),
    ('[[pairs]]\neffects = ["jet_gain", "base_compliance"]\nvalues = {"jet_gain.gain_1" = 9.0}\n',
     "pairs[0].values.jet_gain.gain_1: 9.0 is outside"),
    ('[[setup]]\nerror = "jet_wiring"\nsizes = [[1, 1, 2]]\n',
     "setup[0].sizes[0]: setup error 'jet_wiring=1,1,2': SetupErrors.jet_wiring must be a permutation"),
    ('[[setup]]\nerror = "tracker_tilt"\nsizes = [[1.0, 2.0]]\n', "setup[0].sizes[0]: setup error 'tracker_tilt=1,2'"),
    ('[[setup]]\nerror = "jet_force_sign"\nsizes = [[-1]]\norientations = ["horizontal"]\n',
     "setup[0].orientations[0] = 'horizontal' is not among the study's orientations (hanging)"),
    ('[[pairs]]\neffects = ["jet_gain"]\n',
     "pairs[0].effects must be a list of strings with at least 2 entries, got ['jet_gain']"),
    # Absurd sizes are refused here, not left to fail (or fill memory) in every cell.
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = {start = 0.0, stop = 1.0, num = 3, '
     'scale = "log"}\n', "effects[0].sizes.start and stop of a log scale must be nonzero and of one sign"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = {start = 0.5, stop = 1.0, num = 10001}\n',
     "effects[0].sizes.num must be from 1 to 10000 sizes on one axis, got 10001"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = {start = nan, stop = 1.0, num = 3}\n',
     "effects[0].sizes.start must be a finite number"),
    ('noise_scales = [1e308]\n', "noise_scales[0] must be > 0 and at most 50"),
    ('seeds = [0, 1, 0]\n', "seeds[2] = 0 repeats an earlier entry"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.7, 0.7]\n',
     "effects[0].sizes[1] = 0.7 repeats an earlier entry"),
    ('noise_scales = [1.0, 0.0]\n', "noise_scales[1] must be > 0"),
    ('seeds = [0, 99999999999999999999]\n', "seeds[1] must be an integer from 0 to 2**63 - 1"),
    ('seeds = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9]\n[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\n'
     'sizes = {start = 0.5, stop = 1.0, num = 10000}\n', "100010 cells (scenarios x orientations"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = ["0.8"]\n',
     "effects[0].sizes[0] must be a number, got '0.8'"),
    ('[[pairs]]\neffects = ["jet_gain", "base_compliance"]\n',
     "pairs[0]: at the values given (defaults where none is), jet_gain, base_compliance leave(s) the twin's rod"),
    ('[[pairs]]\neffects = ["jet_gain", "jet_gain"]\nvalues = {"jet_gain.gain_1" = 0.8}\n',
     "pairs[0].effects[1] = 'jet_gain' repeats pairs[0].effects[0]"),
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.8]\n'
     '[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.8, 0.9]\n',
     "effects[1] repeats sizes of effects[0] (the same cells"),
    # The same scenarios spelled twice: refused as the repeats they are, naming both.
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.7]\n'
     '[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.7]\nvalues = {gain_2 = 1.0}\n',
     "effects[1] repeats sizes of effects[0] (the same cells"),
    ('[[pairs]]\neffects = ["jet_gain", "base_compliance"]\n'
     'values = {"jet_gain.gain_1" = 0.8, "base_compliance.compliance_rad_per_nm" = 20.0}\n'
     '[[pairs]]\neffects = ["base_compliance", "jet_gain"]\n'
     'values = {"jet_gain.gain_1" = 0.8, "base_compliance.compliance_rad_per_nm" = 20.0, "jet_gain.gain_2" = 1.0}\n',
     "pairs[1] repeats pairs[0] (the same effects at the same values"),
    ('[[setup]]\nerror = "tracker_tilt_deg"\nsizes = [[2.0, 1.0]]\n'
     '[[setup]]\nerror = "tracker_tilt_deg"\nsizes = [[6.0, 0.0], [2.0, 1.0]]\n',
     "setup[1].sizes[1] repeats setup[0].sizes[0] on the hanging rod"),
    ('profiles = ["sim", "SHIPPED/sim.toml"]\n',
     "profiles[1] = 'SHIPPED/sim.toml' is the same file as profiles[0] = 'sim'"),
    # Held fixed and swept at once, the fixed value would replace some of the sizes.
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.7, 0.9]\nvalues = {gain_1 = 0.8}\n',
     "effects[0].values.gain_1: gain_1 is the parameter swept (effects[0].parameter); it cannot also be held fixed"),
    # A key naming the parameter is said once; TOML's [table] for [[table]] is named.
    ('[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.9]\nvalues = {gain_9 = 1.0}\n',
     "effects[0].values.gain_9: no parameter of jet_gain; known: gain_1"),
    ('[effects]\neffect = "jet_gain"\nparameter = "gain_1"\nsizes = [0.9]\n',
     "effects must be a list of tables, got a table (write each as a [[effects]] block)"),
    ('[[setup]]\nerror = "jet_wiring"\nsizes = 1\n',
     "setup[0].sizes must be a list of lists of numbers with at least 1 entry, got 1"),
    ('profiles = ["sim-mystery"]\n', "profiles[0] = 'sim-mystery' hides pressure_stiffening in its [twin] table"),
    ('none = false\n[[setup]]\nerror = "tracker_tilt_deg"\nsizes = [[1e308, 0.0]]\n',
     "setup[0].sizes[0]: setup error 'tracker_tilt_deg=1e+308,0': SetupErrors.tracker_tilt_deg must be angles "
     "from -45 to 45 degrees"),
])
def test_spec_mistakes_name_file_and_key(tmp_path: Path, body: str, message: str):
    body, message = (text.replace("SHIPPED", str(PROFILES_DIR)) for text in (body, message))
    spec = write_spec(tmp_path, body, "bad.toml")
    with pytest.raises(UserError) as caught:
        load_study(spec)
    text = str(caught.value)
    assert text.startswith(str(spec)) and message in text and "\n" not in text


def test_a_study_at_its_limits_loads(tmp_path: Path):
    spec = write_spec(tmp_path, 'noise_scales = [50.0]\nseeds = [0, 9223372036854775807]\n'
                                '[[effects]]\neffect = "base_compliance"\nparameter = "compliance_rad_per_nm"\n'
                                'sizes = {start = -1e-200, stop = -1e-190, num = 3, scale = "log"}\n'
                                '[[effects]]\neffect = "jet_gain"\nparameter = "gain_1"\n'
                                'sizes = {start = 0.5, stop = 1.0, num = 10000}\n')
    with pytest.raises(UserError, match="-1e-200 is outside"):  # the range is fine, the parameter's bounds are not
        load_study(spec)
    # Sizes where the effect does nothing are refused (a clamp compliance of 1e-200, a gain of 1).
    spec.write_text(spec.read_text().replace("-1e-200, stop = -1e-190", "1e-200, stop = 1e-190"))
    with pytest.raises(UserError, match=r"effects\[0\].sizes\[0\] = 1e-200: there base_compliance leaves"):
        load_study(spec)
    spec.write_text(spec.read_text().replace("1e-200, stop = 1e-190", "1e-3, stop = 1e2"))
    with pytest.raises(UserError, match=r"effects\[1\].sizes\[9999\] = 1: there jet_gain leaves"):
        load_study(spec)
    spec.write_text(spec.read_text().replace("start = 0.5, stop = 1.0", "start = 0.5, stop = 0.99"))
    study = load_study(spec)
    assert len(expand(study)) == 2 * (1 + 3 + 10000) and study.noise_scales == (50.0,)


def test_a_spec_mistake_on_the_command_line_is_one_line(tmp_path: Path):
    spec = write_spec(tmp_path, 'seeds = [0]\ncolour = "red"\n', "bad.toml")
    result = run_study(str(spec), "-o", str(tmp_path / "out"))
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert str(spec) in " ".join(result.stderr.split())


def test_sizes_as_a_range_in_the_effects_own_units(tmp_path: Path):
    spec = write_spec(tmp_path, 'none = false\n[[effects]]\neffect = "base_compliance"\n'
                                'parameter = "compliance_rad_per_nm"\nsizes = {start = 1, stop = 100, num = 3, '
                                'scale = "log"}\n')
    cells = expand(load_study(spec))
    assert [cell.size for cell in cells] == pytest.approx([1.0, 10.0, 100.0])
    assert {cell.unit for cell in cells} == {"rad/(N m)"} and {cell.size_default for cell in cells} == {0.0}


def test_cell_ids_are_stable_and_distinct(tmp_path: Path):
    spec = write_spec(tmp_path, WITH_BOOM)
    first, second = expand(load_study(spec)), expand(load_study(spec))
    assert [cell.id for cell in first] == [cell.id for cell in second]
    assert len({cell.id for cell in first}) == len(first) == 6
    assert {cell.truth for cell in first} == {"none", "jet_gain", "boom"}
    reordered = write_spec(tmp_path, TINY.replace("seeds = [0, 1]", "seeds = [1, 0]"), "reordered.toml")
    assert {cell.id for cell in expand(load_study(reordered))} == {cell.id for cell in first if cell.truth != "boom"}


def test_the_setup_study_has_every_setup_error_and_the_hypothesis_it_should_name():
    from hydrojet_bench.studies.cell import expected_verdict

    study = load_study(Path(__file__).resolve().parents[2] / "docs/studies/setup.toml")
    cells = expand(study)
    assert len(cells) == 54 and len({cell.id for cell in cells}) == 54
    expected = {(cell.scenario, expected_verdict(cell)) for cell in cells if cell.kind == "setup"}
    assert ("jet_wiring=1,3,2", "jet_wiring_132") in expected and ("jet_wiring=2,3,1", "jet_wiring_231") in expected
    assert ("tracker_tilt_deg=6,-3", "tracker_tilt") in expected
    assert ("base_sensor_rotvec=0,0,0.1", "base_sensor_mounting") in expected
    assert ("jet_force_sign=-1", "jet_force_sign") in expected
    assert ("jet_force_scale=0.101972", "jet_force_unit_times_g") in expected
    assert ("jet_force_scale=0.00980665", "jet_force_unit_gf") in expected
    # A [[setup]] naming orientations runs on those only.
    assert {cell.orientation for cell in cells if cell.setup[0] == "jet_force_scale"} == {"horizontal"}
    assert {cell.orientation for cell in cells if cell.setup[0] != "jet_force_scale"} == {"hanging"}


@pytest.mark.parametrize("name", ["library-quick", "library", "plans", "setup", "smoke"])
def test_the_cell_limit_counts_the_cells_the_study_expands_to(name: str, monkeypatch: pytest.MonkeyPatch):
    # The limit is checked before any cell is made, by a count of its own: it must be
    # the number `expand` makes, or a study at the limit is refused or let through wrongly.
    from hydrojet_bench.studies import spec as spec_module

    path = Path(__file__).parents[2] / "docs" / "studies" / f"{name}.toml"
    cells = len(expand(load_study(path)))
    monkeypatch.setattr(spec_module, "MAX_CELLS", cells)
    load_study(path)
    monkeypatch.setattr(spec_module, "MAX_CELLS", cells - 1)
    with pytest.raises(UserError, match=f"{cells} cells"):
        load_study(path)


def test_a_bad_scheduler_a_row_table_onto_a_folder_and_foreign_rows_are_one_line(tmp_path: Path, capsys):
    from hydrojet_bench.cli import main
    from hydrojet_bench.studies.batch import DIAGNOSE_COLUMNS, LogTask, log_row
    from hydrojet_bench.studies.store import RowStore

    spec, out = write_spec(tmp_path, TINY), tmp_path / "out"
    assert main(["study", str(spec), "-o", str(out), "--scheduler", "garbage"]) == 2
    assert "--scheduler 'garbage' is no scheduler address" in capsys.readouterr().err
    (out / "rows.csv").mkdir(parents=True)
    assert main(["study", str(spec), "-o", str(out), "--csv"]) == 2
    assert f"{out / 'rows.csv'}: is a directory" in capsys.readouterr().err
    # A batch's rows in a folder given as a study's: named, not a traceback.
    (out / "members.json").unlink()  # which the study's first attempt kept
    RowStore(out, DIAGNOSE_COLUMNS, "log_id").append(log_row(LogTask("/x.csv"), DIAGNOSE_COLUMNS, "failed"))
    assert main(["study", "--report-only", str(out)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert "a row of another kind" in err and str(out / "rows") in err
    for part in (out / "rows").glob("*.parquet"):
        part.unlink()
    (out / "rows" / "junk.parquet").write_text("not parquet")
    assert main(["study", "--report-only", str(out)]) == 2
    assert "not a readable row" in capsys.readouterr().err
    # A spec beside --report-only would be ignored: refused instead.
    assert main(["study", str(spec), "--report-only", str(out)]) == 2
    assert "runs no spec; give" in " ".join(capsys.readouterr().err.split())


def test_a_folder_of_another_kind_or_another_specs_study_is_refused_before_anything_is_written(tmp_path: Path,
                                                                                               capsys):
    from hydrojet_bench.cli import main
    from hydrojet_bench.studies.batch import DIAGNOSE_COLUMNS, LogTask, log_row
    from hydrojet_bench.studies.cell import ROW_COLUMNS
    from hydrojet_bench.studies.store import MEMBERS_FILE, RowStore

    spec = write_spec(tmp_path, TINY)
    batch = tmp_path / "batch"
    RowStore(batch, DIAGNOSE_COLUMNS, "log_id").append(log_row(LogTask("/x.csv"), DIAGNOSE_COLUMNS, "failed"))
    assert main(["study", str(spec), "-o", str(batch)]) == 2
    assert "a row of another kind" in capsys.readouterr().err and not (batch / MEMBERS_FILE).exists()
    # Another spec's study: its members (and so its report) would be replaced.
    other = tmp_path / "other"
    RowStore(other, ROW_COLUMNS, "cell_id").claim("/studies/library.toml", {"a", "b"})
    before = (other / MEMBERS_FILE).read_text()
    assert main(["study", str(spec), "-o", str(other)]) == 2
    err = " ".join(capsys.readouterr().err.split())
    assert f"{other}: holds the study of /studies/library.toml (2 cells), not of {spec}" in err
    assert (other / MEMBERS_FILE).read_text() == before and not (other / "report").exists()
    # The same cells, more or fewer, from another file (a copy, a narrowed spec), its own
    # spec edited, and a folder from before members named the spec: the same study.
    store = RowStore(other, ROW_COLUMNS, "cell_id")
    store.claim(str(spec), {"a", "b"})
    store.claim("/elsewhere/copy.toml", {"a", "b"})
    store.claim("/elsewhere/copy.toml", {"a", "b", "c"})
    store.claim("/elsewhere/narrow.toml", {"a"})
    with pytest.raises(UserError, match="holds the study of /elsewhere/narrow.toml"):
        store.claim("/elsewhere/another.toml", {"b"})
    (other / MEMBERS_FILE).write_text('["a"]')
    store.claim(str(spec), {"d"})
    assert store.members() == {"d"}
    fresh = tmp_path / "fresh"
    RowStore(fresh, ROW_COLUMNS, "cell_id")
    assert not fresh.exists()
