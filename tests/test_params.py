"""Bad parameter files give clear errors naming the file, key and allowed range."""

from __future__ import annotations

import pytest

from trackmj.cli import main
from trackmj.model import default_param_path, load_model_params
from trackmj.params import ParameterError


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
    with pytest.raises(ParameterError, match=r"\[chassis\]\.mass_kg: must be finite"):
        load_model_params(path)


def test_malformed_toml_names_file(tmp_path) -> None:
    path = _variant(tmp_path, "[track]", "[track")
    with pytest.raises(ParameterError, match=r"variant\.toml: malformed TOML"):
        load_model_params(path)


def test_unknown_and_missing_keys(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"unknown key.*'pitch_mm'"):
        load_model_params(_variant(tmp_path, "pitch_m =", "pitch_mm ="))
    with pytest.raises(ParameterError, match=r"missing table \[ground\]"):
        load_model_params(_variant(tmp_path, "[ground]", "[grund]"))


def test_wrong_link_count_is_rejected(tmp_path) -> None:
    with pytest.raises(ParameterError, match=r"link_count = 80.*exactly 82"):
        load_model_params(_variant(tmp_path, "link_count = 82", "link_count = 80"))


def test_cli_reports_bad_file_without_traceback(tmp_path, capsys) -> None:
    path = _variant(tmp_path, "pitch_m = 0.075", "pitch_m = 7.5")
    assert main(["model", "generate", "--params", str(path), "--out",
                 str(tmp_path / "x.xml")]) == 2
    err = capsys.readouterr().err
    assert "pitch_m = 7.5" in err and "Traceback" not in err
    assert not (tmp_path / "x.xml").exists()
    assert main(["drive", "--model", str(tmp_path / "missing.xml")]) == 2
    assert "model file not found" in capsys.readouterr().err
