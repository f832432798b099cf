"""Bad parameter files give clear errors naming the file, key and allowed range."""

from __future__ import annotations

import pytest

from trackmj.cli.main import main
from trackmj.track.mechanics import default_param_path, load_model_params
from trackmj.validator import ParameterError


def _variant(tmp_path, old: str, new: str):
    text = default_param_path().read_text()
    assert old in text
    path = tmp_path / "variant.toml"
    path.write_text(text.replace(old, new, 1))
    return path


def test_out_of_range_value_names_key_and_range(tmp_path) -> None:
    path = _variant(tmp_path, "pitch_m = 0.075", "pitch_m = -0.075")
    with pytest.raises(ParameterError, match=r"\[track\]\.pitch_m = -0\.075 .*\(0\.02, 0\.3\]"):
        load_model_params(path)


def test_nan_value_is_rejected(tmp_path) -> None:
    path = _variant(tmp_path, "mass_kg = 1200.0", "mass_kg = nan")
    with pytest.raises(ParameterError, match=r"variant\.toml \[chassis\]\.mass_kg = nan: must be "
                       r"finite"):
        load_model_params(path)


def test_malformed_toml_names_file(tmp_path) -> None:
    path = _variant(tmp_path, "[track]", "[track")
    with pytest.raises(ParameterError, match=r"variant\.toml: malformed TOML"):
        load_model_params(path)


def test_unknown_and_missing_keys(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"variant\.toml \[track\]: unknown key 'pitch_mm'; "
                       r"did you mean 'pitch_m'\?"):
        load_model_params(_variant(tmp_path, "pitch_m =", "pitch_mm ="))
    with pytest.raises(ParameterError, match=r"variant\.toml: unknown table \[grund\]; did you "
                       r"mean 'ground'\?"):
        load_model_params(_variant(tmp_path, "[ground]", "[grund]"))
    with pytest.raises(ParameterError, match=r"variant\.toml \[track\]: missing key 'pitch_m' "
                       r"\(a number, m, range \(0\.02, 0\.3\]\): pin-to-pin distance"):
        load_model_params(_variant(tmp_path, "pitch_m = 0.075", ""))


def test_solver_choices_and_integer_counts(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"\[solver\]\.jacobian = 'fast' is not one of "
                       r"\['dense', 'sparse', 'auto'\]"):
        load_model_params(_variant(tmp_path, 'jacobian = "sparse"', 'jacobian = "fast"'))
    with pytest.raises(ParameterError, match=r"\[track\]\.link_count = 82\.0: expected an "
                       r"integer, got a float"):
        load_model_params(_variant(tmp_path, "link_count = 82", "link_count = 82.0"))
    with pytest.raises(ParameterError, match=r"\[solver\]\.warmstart = 0: expected true or "
                       r"false, got an integer"):
        load_model_params(_variant(tmp_path, "warmstart = false", "warmstart = 0"))


def test_link_count_that_cannot_close_is_rejected(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"variant\.toml \[track\]\.link_count = 60 links × "
                       r"0\.075 m = 4\.500 m; this layout needs .* use 74–94 links"):
        load_model_params(_variant(tmp_path, "link_count = 82", "link_count = 60"))


def test_cross_field_checks_name_file_table_and_key(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"variant\.toml \[road_wheels\]\.x_m = \[-0\.75, .*\] "
                       r"has 6 entries, count = 5"):
        load_model_params(_variant(tmp_path, "count = 6", "count = 5"))
    with pytest.raises(ParameterError, match=r"variant\.toml \[idler\]\.slide_range_m = "
                       r"\[0\.01, 0\.05\] must bracket 0"):
        load_model_params(_variant(tmp_path, "slide_range_m = [-0.05, 0.05]",
                                   "slide_range_m = [0.01, 0.05]"))
    with pytest.raises(ParameterError, match=r"--set model\.simulation\.timestep_s = 0\.0003 must "
                       r"divide the 1 ms coupling step"):
        load_model_params(overrides={"simulation.timestep_s": 3e-4})


def test_cli_reports_bad_file_without_traceback(tmp_path, capsys) -> None:
    path = _variant(tmp_path, "pitch_m = 0.075", "pitch_m = 7.5")
    assert main(["model", "generate", "--model", str(path), "--out",
                 str(tmp_path / "x.xml")]) == 2
    err = capsys.readouterr().err
    assert "pitch_m = 7.5" in err and "Traceback" not in err
    assert not (tmp_path / "x.xml").exists()
    assert main(["drive", "--mjcf", str(tmp_path / "missing.xml")]) == 2
    assert "model file not found" in capsys.readouterr().err
    assert main(["drive", "--model", str(tmp_path / "missing.toml")]) == 2
    assert "missing.toml" in capsys.readouterr().err
