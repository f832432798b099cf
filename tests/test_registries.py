"""A new machine is its files: dropped into the models folder, it is found by name with no
other edit (the other extension points' one-entry tests live beside what they extend:
controllers in test_cli and test_report, scenarios in test_scenarios, metrics in
test_metrics, elements and architectures in test_element_port, tensioner kinds in
test_tensioner_kinds)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from trackmj.machines import assembly
from trackmj.track.mechanics import models_dir
from trackmj.validator import ParameterError


@pytest.fixture
def models_copy(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A copy of the packaged models folder that the machine lookup reads instead."""
    folder = tmp_path / "models"
    shutil.copytree(models_dir(), folder)
    monkeypatch.setattr(assembly, "models_dir", lambda: folder)
    assembly.shipped.cache_clear()
    yield folder
    assembly.shipped.cache_clear()


def test_a_machine_file_in_the_models_folder_is_a_shipped_machine(models_copy: Path) -> None:
    text = (models_copy / "compact3_machine.toml").read_text()
    (models_copy / "compact3b_machine.toml").write_text(
        text.replace('name = "compact3"', 'name = "compact3b"'))
    assert "compact3b" in assembly.names()
    machine = assembly.resolve("compact3b")
    assert machine.name == "compact3b"
    assert machine.mechanics == (models_copy / "compact3.toml").resolve()
    assert assembly.mechanics(machine) == assembly.mechanics(assembly.resolve("compact3"))


def test_two_machine_files_with_one_name_are_refused(models_copy: Path) -> None:
    shutil.copy(models_copy / "m113_machine.toml", models_copy / "m113_copy_machine.toml")
    with pytest.raises(ParameterError, match="machine name 'm113' is also"):
        assembly.shipped()
