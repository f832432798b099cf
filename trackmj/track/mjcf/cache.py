"""Generated MJCF cached by content hash.

A model generated from parameters that are not a machine's own (an edited copy, ``--set
model.track.link_count=80``, a sweep point over geometry keys) costs a layout and a 3 s
settle (about 1–3 s of wall time). :func:`cached_mjcf` keys it by the SHA-256 of the
validated parameters (their ``repr``: every value, in declaration order; ``source`` texts
excluded), the generator's own source files and the MuJoCo version, and keeps it in the
cache directory (:func:`trackmj.io.cache_dir`: ``$TRACKMJ_CACHE`` if set, else
``$XDG_CACHE_HOME/trackmj``, default ``~/.cache/trackmj``). Files are written atomically,
so concurrent workers at worst generate the same model twice; a corrupt entry cannot be
read half-written.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

import mujoco

from trackmj.io import cache_dir, write_text_atomic
from trackmj.track.mechanics import MODEL_NAME, ModelParams
from trackmj.track.mjcf.generate import generate_mjcf


@functools.cache
def _generator_digest() -> str:
    """SHA-256 over the generator's source files and the MuJoCo version: a change of
    either makes every cached model stale."""
    digest = hashlib.sha256(mujoco.__version__.encode())
    here = Path(__file__).parent
    for path in [*sorted(here.glob("*.py")), here.parent / "terrain.py"]:
        digest.update(path.name.encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def model_key(params: ModelParams) -> str:
    """Content hash of a model: parameters, generator sources and MuJoCo version."""
    return hashlib.sha256((_generator_digest() + repr(params)).encode()).hexdigest()


@functools.cache
def cached_mjcf(params: ModelParams, name: str = MODEL_NAME) -> str:
    """MJCF text (with the settled ``home`` keyframe) of ``params`` for machine ``name``:
    from the cache directory if generated before, else generated and stored there."""
    path = cache_dir() / f"{name}-{model_key(params)[:32]}.xml"
    try:
        return path.read_text()
    except (FileNotFoundError, UnicodeDecodeError):
        pass
    text = generate_mjcf(params, name)
    try:
        write_text_atomic(path, text)
    except OSError:          # a read-only home: generate each time rather than fail
        pass
    return text
