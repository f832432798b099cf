"""Shared fixtures: the packaged model is loaded once per session where tests only read it."""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest


def pytest_configure(config) -> None:
    """Generated models go to a cache of this test session, not the user's cache (the
    variable is inherited by the executor's worker processes)."""
    os.environ["TRACKMJ_CACHE"] = tempfile.mkdtemp(prefix="trackmj-test-cache-")


def pytest_unconfigure(config) -> None:
    shutil.rmtree(os.environ.pop("TRACKMJ_CACHE", ""), ignore_errors=True)


@pytest.fixture(scope="session")
def model_params():
    from trackmj.track.mechanics import load_model_params

    return load_model_params()


@pytest.fixture
def plant():
    """A fresh plant at the home keyframe (MuJoCo is imported only by tests that use it)."""
    from trackmj.machines.track_plant import load_plant

    return load_plant()
