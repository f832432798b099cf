"""Shared fixtures: the packaged model is loaded once per session where tests only read it."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def model_params():
    from trackmj.model import load_model_params

    return load_model_params()


@pytest.fixture
def plant():
    """A fresh plant at the home keyframe (MuJoCo is imported only by tests that use it)."""
    from trackmj.plant import TrackPlant

    return TrackPlant.load()
