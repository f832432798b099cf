"""A run's **identity** (:func:`identity`): everything that determines its result, and the
keys hashed from it that the campaigns (:mod:`trackmj.study.campaign`) and ``trackmj run``
know a run by.

The identity holds the scenario (validated, after overrides, events as they will run), the
machine files' content (the validated model, hydraulic and control parameters after
overrides and the variant's scaling; the packaged machine's files,
:func:`machine_files_hash`; a tensioner file's content and its FMU file's SHA-256; a
controller FMU's file hash), the machine (its name and files, :func:`machine_identity`), the
architecture, controller, estimator, seed, variant, duration, the measured log a run is
compared with (its file name and SHA-256; ``trackmj run --measured``) and the SHA-256 of the
*source* of the trackmj, trackmj.hydraulics and trackmj.control packages (:func:`source_hash`).
:func:`run_key` hashes all of it; :func:`inputs_key` the same without the source (what
``trackmj run`` compares before replacing a folder: the same inputs run by other code may
replace their old result, other inputs may not).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib
import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from trackmj.results.store import Result
from trackmj.track.mjcf.builders import read_mjcf

if TYPE_CHECKING:
    from trackmj.results.measured import MeasuredLog

SOURCE_PACKAGES = ("trackmj", "trackmj.hydraulics", "trackmj.control")
"""Packages whose source (every ``.py`` file below them) is part of a run's identity."""
MODELS_PACKAGE = "trackmj.models"
"""The packaged machine's files (:func:`machine_files_hash`)."""


def _package_dir(name: str) -> Path:
    """The directory of the (regular, imported here) package ``name``."""
    file = importlib.import_module(name).__file__
    if file is None:
        raise RuntimeError(f"{name}: a namespace package, no directory of its own to hash")
    return Path(file).parent


@functools.cache
def source_hash() -> str:
    """SHA-256 (hex) of the source of :data:`SOURCE_PACKAGES`: every ``.py`` file under each
    package's directory, by relative path and content. Computed once per process."""
    digest = hashlib.sha256()
    for name in SOURCE_PACKAGES:
        root = _package_dir(name)
        for path in sorted(root.rglob("*.py")):
            digest.update(f"{name}/{path.relative_to(root).as_posix()}\0".encode())
            digest.update(path.read_bytes())
            digest.update(b"\0")
    return digest.hexdigest()


@functools.cache
def machine_files_hash() -> str:
    """SHA-256 (hex) of the packaged machine's files (``trackmj.models``: the committed MJCF,
    the parameter files and the identified idler), by name and content: the packaged runs
    read the MJCF and the idler from them, not from the validated parameters."""
    root = _package_dir(MODELS_PACKAGE)
    digest = hashlib.sha256()
    for path in sorted(p for p in root.iterdir() if p.suffix in (".xml", ".toml")):
        digest.update(f"{path.name}\0".encode() + path.read_bytes() + b"\0")
    return digest.hexdigest()


def machine_identity(machine: Any) -> str:
    """A machine's name and the content of the files its runs read besides the validated
    parameters: the identified idler and the reference MJCF (scene joined with its machine
    part), as SHA-256."""
    text = machine.name
    if machine.idler is not None:
        text += _file_hash(machine.idler)
    if machine.reference_mjcf is not None:
        text += hashlib.sha256(read_mjcf(machine.reference_mjcf).encode()).hexdigest()
    return text


def _file_hash(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def identity(setup: Any, log: MeasuredLog | None = None) -> dict[str, Any]:
    """Everything that determines the run of ``setup`` (a :class:`trackmj.sim.setup.RunSetup`)
    compared with measured ``log`` (if any) as a JSON-ready mapping; see the module
    docstring. ``source`` is :func:`source_hash`."""
    scenario = {f.name: repr(getattr(setup.scenario, f.name))
                for f in dataclasses.fields(setup.scenario) if f.name != "source"}
    ident: dict[str, Any] = {
        "architecture": setup.architecture, "controller": setup.controller,
        "estimator": setup.estimator, "seed": setup.seed, "duration_s": repr(setup.duration_s),
        "variant": repr(setup.variant), "model": repr(setup.model),
        "hydraulics": repr(setup.hydraulics), "control": repr(setup.control),
        "scenario": scenario, "machine_files": machine_files_hash(), "source": source_hash()}
    if setup.tensioner is not None:
        ident["tensioner"] = setup.tensioner.identity()
    ident["machine"] = machine_identity(setup.machine)
    if log is not None:
        ident["measured_log"] = {"file": log.file, "sha256": log.sha256}
    if setup.controller_file is not None:
        ident["controller_file"] = repr(setup.controller_file)
        described = setup.controller_file.description
        if described is not None:
            ident["controller_fmu"] = _file_hash(described.path)
    return ident


def _hash(ident: Mapping[str, Any]) -> str:
    return hashlib.sha256(json.dumps(ident, sort_keys=True).encode()).hexdigest()[:20]


def run_key(setup: Any, log: MeasuredLog | None = None) -> str:
    """Hash (20 hex digits) of the run's :func:`identity`: inputs and code."""
    return _hash(identity(setup, log))


def inputs_key(setup: Any, log: MeasuredLog | None = None) -> str:
    """Hash (20 hex digits) of the run's inputs alone (its identity without the source)."""
    return _hash({k: v for k, v in identity(setup, log).items() if k != "source"})


def stamped(result: Result, **keys: str) -> Result:
    """``result`` with ``keys`` (e.g. ``run_key=...``) added to its table metadata."""
    meta = dict(result.timeseries.schema.metadata or {})
    meta |= {k.encode(): v.encode() for k, v in keys.items()}
    return Result(result.timeseries.replace_schema_metadata(meta), result.metrics)
